//! A thread that plays perception for the core process's tests: it publishes a scene on the
//! `scene` service under a prefix at a fixed period until told to stop, and notifies
//! `scene_ready` after each (what wakes a core deciding on arrival).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use concord_core::Scene;
use concord_ipc::clock::now_ns;
use concord_ipc::wire::SceneFrame;
use concord_ipc::{iox, services};
use iceoryx2::config::Config;

/// Publishes `scene_at(t)`, t = k · `period_s` for k = 1, 2, …, every `period_s` until `stop`,
/// from a node called `node`.
pub fn spawn(
    node: &'static str,
    prefix: &str,
    config: &Config,
    stop: &Arc<AtomicBool>,
    period_s: f64,
    scene_at: impl Fn(f64) -> Scene + Send + 'static,
) -> JoinHandle<()> {
    let (prefix, config, stop) = (prefix.to_string(), config.clone(), stop.clone());
    std::thread::spawn(move || {
        let node = iox::node(node, &config).expect("node");
        let publisher =
            iox::publisher::<SceneFrame>(&node, &services::name(&prefix, services::SCENE))
                .expect("publisher");
        let ready = iox::notifier(&node, &services::name(&prefix, services::SCENE_READY))
            .expect("notifier");
        let mut seq = 0;
        while !stop.load(Ordering::Relaxed) {
            seq += 1;
            let scene = scene_at(seq as f64 * period_s);
            iox::send(&publisher, &SceneFrame::from_scene(seq, now_ns(), &scene)).expect("send");
            ready.notify().expect("notify");
            std::thread::sleep(Duration::from_secs_f64(period_s));
        }
    })
}
