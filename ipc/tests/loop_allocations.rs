//! Concord's code in the core process's loop does not allocate, deciding on its tick or on
//! each scene's arrival. Counted per thread by a counting global allocator, between tick 200
//! and tick 2200 of one run at 200 Hz, while another thread publishes scenes at 50 Hz. What does allocate there is iceoryx2 0.10 itself:
//! `Publisher::loan_uninit` creates a 48-byte shared state for every sample, and a WaitSet
//! woken by a notification (a scene's arrival) collects the triggered file descriptors in two
//! `Vec`s. So the loop may allocate at most once per published sample (decisions, advice
//! requests, statistics) and, deciding on arrival, twice per frame received.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use concord_core::scene::{AgentState, Scene, Vec2};
use concord_core::{DecisionCore, Params};
use concord_ipc::core_service::{self, DecideOn, Geometry, ServiceConfig, StopAfter};
use concord_ipc::iox;
use concord_ipc::system::RealtimeConfig;
use concord_ipc::wire::CoreStats;
use concord_map::paper;

#[path = "../../core/tests/counting_allocator/mod.rs"]
mod counting_allocator;
#[path = "support/scene_feeder.rs"]
mod scene_feeder;

use counting_allocator::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Samples the loop has published so far.
fn published(s: &CoreStats) -> u64 {
    s.decisions.iter().sum::<u64>() + s.advice_requests + s.uptime_ns / 1_000_000_000 + 1
}

#[test]
fn ticks_allocate_nothing_but_iceoryx2s_per_sample_state() {
    allocations_per_sample(DecideOn::Tick);
}

#[test]
fn decisions_on_arrival_allocate_nothing_but_iceoryx2s_per_sample_state() {
    allocations_per_sample(DecideOn::Arrival);
}

fn allocations_per_sample(decide_on: DecideOn) {
    let prefix = format!("alloc-{}-{decide_on:?}/", std::process::id());
    let config = iox::init(None).expect("iceoryx2 config");
    let stop = Arc::new(AtomicBool::new(false));
    let feeder_name = match decide_on {
        DecideOn::Tick => "alloc-feeder-tick",
        DecideOn::Arrival => "alloc-feeder-arrival",
    };
    let feeder = scene_feeder::spawn(feeder_name, &prefix, &config, &stop, 0.02, |t| {
        let x = (8.0 * t) % 30.0;
        let ego = AgentState::moving(0, Vec2::new(40.0 - x, 5.0), std::f64::consts::PI, 8.0);
        let mut scene = Scene::new(t, ego, paper::CAV_LEFT);
        scene.push(AgentState::moving(1, Vec2::new(-40.0 + x, -5.0), 0.0, 8.0));
        scene
    });
    let cfg = ServiceConfig {
        prefix,
        rate_hz: 200.0,
        decide_on,
        print_period_s: 0.0,
        geometry: Geometry::PaperIntersection,
        ..ServiceConfig::default()
    };
    let mut core = Box::new(
        DecisionCore::new(Params::default(), cfg.geometry.morphology()).expect("valid params"),
    );
    let mut marks: Vec<(u64, u64, u64, u64)> = Vec::with_capacity(2);
    let stats = core_service::run_observed(
        &mut core,
        &cfg,
        None,
        &RealtimeConfig::default(),
        &config,
        StopAfter {
            ticks: Some(2200),
            duration_s: None,
        },
        |s| {
            if s.ticks == 200 || s.ticks == 2200 {
                marks.push((
                    allocations(),
                    published(s),
                    s.frames_accepted,
                    s.frames_received,
                ));
            }
        },
    )
    .expect("the loop runs");
    stop.store(true, Ordering::Relaxed);
    feeder.join().expect("feeder");
    let [(a0, p0, d0, r0), (a1, p1, d1, r1)] = marks[..] else {
        panic!("marks at ticks 200 and 2200: {marks:?}")
    };
    let (allocated, samples) = (a1 - a0, p1 - p0);
    eprintln!(
        "ticks 200..2200 ({decide_on:?}): {allocated} allocations, {samples} samples published, \
         {} frames decided",
        d1 - d0
    );
    // 2000 passes: 10 s of 200 Hz ticks, or 8 s of ticks and 50 Hz arrivals.
    assert!(d1 - d0 > 300, "too few frames decided: {stats:?}");
    let waitset = match decide_on {
        DecideOn::Tick => 0,
        DecideOn::Arrival => 2 * (r1 - r0),
    };
    assert!(
        allocated <= samples + waitset,
        "{allocated} allocations for {samples} published samples and {waitset} of the WaitSet"
    );
}
