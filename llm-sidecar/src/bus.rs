//! The sidecar's iceoryx2 side, on its own thread (iceoryx2 ports are not `Send`): every
//! 10 ms it takes the newest advice request and decision, every intent text and scene frame,
//! hands them to the async side, and publishes the advice and eHMI messages the async side
//! produced. It also tells systemd it is ready and pings the watchdog while it runs.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc as std_mpsc, Arc, Mutex};
use std::time::Duration;

use concord_ipc::clock::now_ns;
use concord_ipc::iox::{self, IpcError};
use concord_ipc::services;
use concord_ipc::system::Notifier;
use concord_ipc::wire::{
    AdviceRequest, EhmiMessage, IntentText, SceneFrame, WireAdvice, WireDecision,
};
use iceoryx2::config::Config;
use iceoryx2::prelude::*;
use tokio::sync::{mpsc, watch};

/// Poll period of the bus thread.
const PERIOD: Duration = Duration::from_millis(10);
/// Intent texts buffered per subscriber; more arriving within one period are lost (counted).
const TEXT_BUFFER: usize = 64;

/// What the async side publishes.
pub enum Outbound {
    Advice(WireAdvice),
    Ehmi(EhmiMessage),
}

/// Recent scene frames, oldest first, for the Raw rendering.
pub type History = Arc<Mutex<VecDeque<SceneFrame>>>;

/// The channels between the bus thread and the async side.
pub struct Inbound {
    pub requests: watch::Sender<Option<AdviceRequest>>,
    pub decisions: watch::Sender<Option<WireDecision>>,
    pub texts: mpsc::Sender<IntentText>,
    pub history: History,
    /// Texts lost because the async side was full.
    pub texts_dropped: Arc<AtomicU64>,
}

/// Runs the bus until SIGINT/SIGTERM; `ready` gets the start-up result once the ports exist.
pub fn run(
    config: &Config,
    prefix: &str,
    history_s: f64,
    inbound: Inbound,
    outbound: std_mpsc::Receiver<Outbound>,
    ready: std_mpsc::Sender<Result<(), String>>,
) -> Result<(), IpcError> {
    let started = (|| {
        let cleaned = iox::remove_dead_nodes(config)?;
        if cleaned > 0 {
            eprintln!("concord sidecar: removed the resources of {cleaned} dead node(s)");
        }
        let node = iox::node("concord-sidecar", config)?;
        let name = |s| services::name(prefix, s);
        Ok::<_, IpcError>((
            iox::subscriber::<AdviceRequest>(&node, &name(services::ADVICE_REQUEST), 1)?,
            iox::subscriber::<WireDecision>(&node, &name(services::DECISION), 1)?,
            iox::subscriber::<IntentText>(&node, &name(services::INTENT_TEXT), TEXT_BUFFER)?,
            iox::subscriber::<SceneFrame>(&node, &name(services::SCENE), 64)?,
            iox::publisher::<WireAdvice>(&node, &name(services::ADVICE))?,
            iox::publisher::<EhmiMessage>(&node, &name(services::EHMI))?,
            node,
        ))
    })();
    let (requests, decisions, texts, scenes, advice, ehmi, _node) = match started {
        Ok(p) => {
            let _ = ready.send(Ok(()));
            p
        }
        Err(e) => {
            let _ = ready.send(Err(e.to_string()));
            return Err(e);
        }
    };
    let notifier = Notifier::from_env();
    notifier.ready();
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| IpcError(format!("creating the WaitSet: {e:?}")))?;
    let tick = waitset
        .attach_interval(PERIOD)
        .map_err(|e| IpcError(format!("attaching the interval: {e:?}")))?;
    let history_ns = (history_s * 1e9) as u64;
    let mut failure = None;
    let mut last_watchdog = std::time::Instant::now();
    let result = waitset.wait_and_process(|id| {
        if !id.has_event_from(&tick) {
            return CallbackProgression::Continue;
        }
        let step = || -> Result<bool, IpcError> {
            if let (Some(r), _) = iox::newest(&requests)? {
                inbound.requests.send_replace(Some(r));
            }
            if let (Some(d), _) = iox::newest(&decisions)? {
                inbound.decisions.send_replace(Some(d));
            }
            while let Some(t) = texts.receive().map_err(|e| IpcError(format!("{e:?}")))? {
                if inbound.texts.try_send(*t).is_err() {
                    inbound.texts_dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
            {
                let mut h = inbound.history.lock().expect("history lock");
                while let Some(f) = scenes.receive().map_err(|e| IpcError(format!("{e:?}")))? {
                    if h.back().is_some_and(|b| f.stamp_ns < b.stamp_ns) {
                        h.clear();
                    }
                    h.push_back(*f);
                }
                let newest = h.back().map_or(0, |f| f.stamp_ns);
                while h
                    .front()
                    .is_some_and(|f| newest - f.stamp_ns > history_ns + PERIOD.as_nanos() as u64)
                {
                    h.pop_front();
                }
            }
            loop {
                match outbound.try_recv() {
                    Ok(Outbound::Advice(mut a)) => {
                        // The core judges the deadline by this stamp.
                        a.published_ns = now_ns();
                        iox::send(&advice, &a)?
                    }
                    Ok(Outbound::Ehmi(m)) => iox::send(&ehmi, &m)?,
                    Err(std_mpsc::TryRecvError::Empty) => return Ok(true),
                    Err(std_mpsc::TryRecvError::Disconnected) => return Ok(false),
                }
            }
        };
        match step() {
            Ok(true) => {
                if let Some(ns) = notifier.watchdog_interval_ns {
                    if last_watchdog.elapsed() >= Duration::from_nanos(ns) {
                        last_watchdog = std::time::Instant::now();
                        notifier.watchdog();
                    }
                }
                CallbackProgression::Continue
            }
            Ok(false) => CallbackProgression::Stop,
            Err(e) => {
                failure = Some(e);
                CallbackProgression::Stop
            }
        }
    });
    notifier.stopping();
    if let Some(e) = failure {
        return Err(e);
    }
    result
        .map(|_| ())
        .map_err(|e| IpcError(format!("WaitSet: {e:?}")))
}
