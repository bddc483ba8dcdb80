//! iceoryx2 plumbing shared by every Concord process: configuration, nodes, "latest sample
//! wins" publish–subscribe services, and removal of what dead processes left behind.

use std::fmt::Debug;
use std::path::Path;

use iceoryx2::config::Config;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

/// Any iceoryx2 failure, with what was being done.
#[derive(Debug)]
pub struct IpcError(pub String);

impl std::fmt::Display for IpcError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for IpcError {}

fn err(what: impl std::fmt::Display, e: impl Debug) -> IpcError {
    IpcError(format!("{what}: {e:?}"))
}

/// Largest number of publishers, subscribers and nodes per service.
const MAX_PUBLISHERS: usize = 4;
const MAX_SUBSCRIBERS: usize = 16;
const MAX_NODES: usize = 32;
/// Largest subscriber buffer a service allows; each subscriber picks its own.
pub const MAX_BUFFER: usize = 256;

/// Loads the iceoryx2 configuration from `path` (the deployment's `deploy/iceoryx2.toml`), or
/// uses iceoryx2's defaults without looking for files when `path` is `None`. Either way
/// iceoryx2 logs only warnings and errors. Call once, before the first node.
pub fn init(path: Option<&Path>) -> Result<Config, IpcError> {
    set_log_level(LogLevel::Warn);
    match path {
        Some(p) => {
            let file = FilePath::new(p.to_string_lossy().as_bytes())
                .map_err(|e| err(format!("iceoryx2 config path {}", p.display()), e))?;
            Config::setup_global_config_from_file(&file)
                .cloned()
                .map_err(|e| err(format!("iceoryx2 config {}", p.display()), e))
        }
        None => Ok(Config::default()),
    }
}

/// A node named `name` with configuration `config`.
pub fn node(name: &str, config: &Config) -> Result<Node<ipc::Service>, IpcError> {
    let node_name = NodeName::new(name).map_err(|e| err(format!("node name {name:?}"), e))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(config)
        .create::<ipc::Service>()
        .map_err(|e| err(format!("creating node {name:?}"), e))
}

/// Removes the resources of dead Concord nodes (crashed or killed processes) so that their
/// services and ports can be reused. Returns how many dead nodes were cleaned.
pub fn remove_dead_nodes(config: &Config) -> Result<usize, IpcError> {
    let mut cleaned = 0;
    Node::<ipc::Service>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            if view.try_remove_stale_resources().is_ok() {
                cleaned += 1;
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| err("listing nodes", e))?;
    Ok(cleaned)
}

/// Opens or creates the publish–subscribe service `name` for `T` with Concord's settings:
/// safe overflow (a full buffer drops its oldest sample), history of one sample for late
/// subscribers, and room for many readers.
pub fn service<T: Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<PortFactory<ipc::Service, T, ()>, IpcError> {
    let service_name =
        ServiceName::new(name).map_err(|e| err(format!("service name {name:?}"), e))?;
    node.service_builder(&service_name)
        .publish_subscribe::<T>()
        .enable_safe_overflow(true)
        .history_size(1)
        .subscriber_max_buffer_size(MAX_BUFFER)
        .subscriber_max_borrowed_samples(2)
        .max_publishers(MAX_PUBLISHERS)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| err(format!("opening service {name:?}"), e))
}

/// A publisher on `name`.
pub fn publisher<T: Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<Publisher<ipc::Service, T, ()>, IpcError> {
    service::<T>(node, name)?
        .publisher_builder()
        .create()
        .map_err(|e| err(format!("publisher on {name:?}"), e))
}

/// A subscriber on `name` keeping the newest `buffer` samples (1: latest sample wins).
pub fn subscriber<T: Debug + ZeroCopySend + 'static>(
    node: &Node<ipc::Service>,
    name: &str,
    buffer: usize,
) -> Result<Subscriber<ipc::Service, T, ()>, IpcError> {
    service::<T>(node, name)?
        .subscriber_builder()
        .buffer_size(buffer.clamp(1, MAX_BUFFER))
        .create()
        .map_err(|e| err(format!("subscriber on {name:?}"), e))
}

/// A listener on the event service `name` (iceoryx2's default event settings).
pub fn listener(node: &Node<ipc::Service>, name: &str) -> Result<Listener<ipc::Service>, IpcError> {
    event(node, name)?
        .listener_builder()
        .create()
        .map_err(|e| err(format!("listener on {name:?}"), e))
}

/// A notifier on the event service `name` (iceoryx2's default event settings).
pub fn notifier(node: &Node<ipc::Service>, name: &str) -> Result<Notifier<ipc::Service>, IpcError> {
    event(node, name)?
        .notifier_builder()
        .create()
        .map_err(|e| err(format!("notifier on {name:?}"), e))
}

fn event(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, IpcError> {
    let service_name =
        ServiceName::new(name).map_err(|e| err(format!("service name {name:?}"), e))?;
    node.service_builder(&service_name)
        .event()
        .open_or_create()
        .map_err(|e| err(format!("opening event service {name:?}"), e))
}

/// Publishes a copy of `value`.
pub fn send<T: Debug + ZeroCopySend + Copy>(
    publisher: &Publisher<ipc::Service, T, ()>,
    value: &T,
) -> Result<(), IpcError> {
    let sample = publisher
        .loan_uninit()
        .map_err(|e| err("loaning a sample", e))?;
    sample
        .write_payload(*value)
        .send()
        .map_err(|e| err("sending a sample", e))?;
    Ok(())
}

/// Drains `subscriber` and returns the newest sample with the number received.
pub fn newest<T: Debug + ZeroCopySend + Copy>(
    subscriber: &Subscriber<ipc::Service, T, ()>,
) -> Result<(Option<T>, u64), IpcError> {
    let mut latest = None;
    let mut count = 0;
    while let Some(sample) = subscriber.receive().map_err(|e| err("receiving", e))? {
        latest = Some(*sample);
        count += 1;
    }
    Ok((latest, count))
}
