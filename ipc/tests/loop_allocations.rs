//! Concord's code in the core process's loop does not allocate. Counted per thread by a
//! counting global allocator, between tick 200 and tick 2200 of one run at 200 Hz, while
//! another thread publishes scenes at 50 Hz. What does allocate there is iceoryx2 0.10 itself:
//! `Publisher::loan_uninit` creates a 48-byte shared state for every sample, so the loop may
//! allocate at most once per published sample (decisions, advice requests, statistics).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use concord_core::scene::{paper, AgentState, Scene, Vec2};
use concord_core::{DecisionCore, Params};
use concord_ipc::clock::now_ns;
use concord_ipc::core_service::{self, Geometry, ServiceConfig, StopAfter};
use concord_ipc::system::RealtimeConfig;
use concord_ipc::wire::{CoreStats, SceneFrame};
use concord_ipc::{iox, services};

#[path = "../../core/tests/counting_allocator/mod.rs"]
mod counting_allocator;

use counting_allocator::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Samples the loop has published so far.
fn published(s: &CoreStats) -> u64 {
    s.decisions.iter().sum::<u64>() + s.advice_requests + s.uptime_ns / 1_000_000_000 + 1
}

#[test]
fn ticks_allocate_nothing_but_iceoryx2s_per_sample_state() {
    let prefix = format!("alloc-{}/", std::process::id());
    let config = iox::init(None).expect("iceoryx2 config");
    let stop = Arc::new(AtomicBool::new(false));
    let feeder = {
        let (stop, config, prefix) = (stop.clone(), config.clone(), prefix.clone());
        std::thread::spawn(move || {
            let node = iox::node("alloc-feeder", &config).expect("node");
            let publisher =
                iox::publisher::<SceneFrame>(&node, &services::name(&prefix, services::SCENE))
                    .expect("publisher");
            let mut seq = 0;
            while !stop.load(Ordering::Relaxed) {
                seq += 1;
                let t = seq as f64 * 0.02;
                let ego = AgentState::moving(
                    0,
                    Vec2::new(40.0 - (8.0 * t) % 30.0, 5.0),
                    std::f64::consts::PI,
                    8.0,
                );
                let mut scene = Scene::new(t, ego, paper::CAV_LEFT);
                scene.push(AgentState::moving(
                    1,
                    Vec2::new(-40.0 + (8.0 * t) % 30.0, -5.0),
                    0.0,
                    8.0,
                ));
                iox::send(&publisher, &SceneFrame::from_scene(seq, now_ns(), &scene))
                    .expect("send");
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    let cfg = ServiceConfig {
        prefix,
        rate_hz: 200.0,
        print_period_s: 0.0,
        geometry: Geometry::PaperIntersection,
        ..ServiceConfig::default()
    };
    let mut core = Box::new(
        DecisionCore::new(Params::default(), cfg.geometry.morphology()).expect("valid params"),
    );
    let mut marks: Vec<(u64, u64, u64)> = Vec::with_capacity(2);
    let stats = core_service::run_observed(
        &mut core,
        &cfg,
        &RealtimeConfig::default(),
        &config,
        StopAfter {
            ticks: Some(2200),
            duration_s: None,
        },
        |s| {
            if s.ticks == 200 || s.ticks == 2200 {
                marks.push((allocations(), published(s), s.frames_accepted));
            }
        },
    )
    .expect("the loop runs");
    stop.store(true, Ordering::Relaxed);
    feeder.join().expect("feeder");
    let [(a0, p0, d0), (a1, p1, d1)] = marks[..] else {
        panic!("marks at ticks 200 and 2200: {marks:?}")
    };
    let (allocated, samples) = (a1 - a0, p1 - p0);
    eprintln!(
        "ticks 200..2200: {allocated} allocations, {samples} samples published, {} frames decided",
        d1 - d0
    );
    assert!(d1 - d0 > 400, "too few frames decided: {stats:?}");
    assert!(
        allocated <= samples,
        "{allocated} allocations for {samples} published samples over 2000 ticks"
    );
}
