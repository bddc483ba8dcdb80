//! What the core process does with the advice it receives, over real iceoryx2 services: a
//! malformed advice or a failure report installs nothing (the scenes after it are decided as
//! before), and the deadline is judged by the advice's publish stamp, to the millisecond, at
//! 20, 50 and 100 Hz; deciding on arrival at 1000 frames a second, requests are issued at
//! most every 25 ms and one 1.2 s old is still answered in time; the intents a valid advice
//! carries reach the core's scenes until they expire; every advice received is counted once;
//! a configured route replaces the lane the frames name. A test thread plays the sidecar.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use concord_core::scene::{AgentState, IntentAction, Scene, Task, Turn, Vec2};
use concord_core::{AdviceVerdict, DecisionCore, FallbackReason, Maneuver, Params};
use concord_ipc::clock::now_ns;
use concord_ipc::core_service::{self, DecideOn, ServiceConfig, StopAfter};
use concord_ipc::system::RealtimeConfig;
use concord_ipc::wire::{
    AdviceRequest, CoreStats, WireAdvice, WireAgentIntent, WireIntent, UNKNOWN, WIRE_OBJECTS,
};
use concord_ipc::{iox, services};
use concord_map::paper;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

#[path = "support/scene_feeder.rs"]
mod scene_feeder;

type Requests = Subscriber<ipc::Service, AdviceRequest, ()>;
type AdviceOut = Publisher<ipc::Service, WireAdvice, ()>;

/// Track id of the road user the feeder adds with `hdv`.
const HDV: u32 = 7;

/// The ego on the paper's approach at `t` s, with `hdv` a car on the priority road about as far
/// from the junction in time (a risky conflict, so an object of every request).
fn scene_at(t: f64, hdv: bool) -> Scene {
    let x = 60.0 - (8.0 * t) % 30.0;
    let ego = AgentState::moving(0, Vec2::new(x, 5.0), std::f64::consts::PI, 8.0);
    let mut scene = Scene::new(t, ego, paper::CAV_LEFT);
    if hdv {
        scene.push(AgentState::moving(
            HDV,
            Vec2::new(-5.0 - x / 2.0, -5.0),
            0.0,
            4.0,
        ));
    }
    scene
}

/// The core process's configuration for a test under `prefix` at `rate_hz`.
fn service(prefix: &str, rate_hz: f64) -> ServiceConfig {
    ServiceConfig {
        prefix: prefix.to_string(),
        rate_hz,
        print_period_s: 0.0,
        ..ServiceConfig::default()
    }
}

/// Runs the core as `cfg` says for `seconds` beside the feeder (with the car `hdv`, a frame
/// every 50 ms) and `sidecar`, which gets the request subscriber and the advice publisher on
/// its own thread; returns the final counters, after checking that every advice received is
/// counted once. The advice deadline is 0.3 s.
fn run(
    cfg: ServiceConfig,
    hdv: bool,
    seconds: f64,
    sidecar: impl FnOnce(&Requests, &AdviceOut) + Send + 'static,
) -> CoreStats {
    run_fed(cfg, hdv, seconds, 0.05, 0.3, sidecar)
}

/// [`run`] with a frame every `frame_period_s` and an advice deadline of `deadline_s`.
fn run_fed(
    cfg: ServiceConfig,
    hdv: bool,
    seconds: f64,
    frame_period_s: f64,
    deadline_s: f64,
    sidecar: impl FnOnce(&Requests, &AdviceOut) + Send + 'static,
) -> CoreStats {
    let prefix = cfg.prefix.as_str();
    let config = iox::init(None).expect("iceoryx2 config");
    let stop = Arc::new(AtomicBool::new(false));
    let feed = scene_feeder::spawn(
        "intake-feeder",
        prefix,
        &config,
        &stop,
        frame_period_s,
        move |t| scene_at(t, hdv),
    );
    let side = {
        let (config, prefix) = (config.clone(), prefix.to_string());
        std::thread::spawn(move || {
            let node = iox::node("intake-sidecar", &config).expect("node");
            let name = |s| services::name(&prefix, s);
            let requests = iox::subscriber(&node, &name(services::ADVICE_REQUEST), 1).expect("sub");
            let advice = iox::publisher(&node, &name(services::ADVICE)).expect("publisher");
            sidecar(&requests, &advice);
        })
    };
    let mut params = Params::default();
    params.trajectory.samples = 128;
    params.advice.deadline_s = deadline_s;
    let road = cfg.road().expect("the map loads");
    let mut core = Box::new(DecisionCore::new(params, road.map.morphology()).unwrap());
    let stats = core_service::run(
        &mut core,
        &cfg,
        road.route,
        &RealtimeConfig::default(),
        &config,
        StopAfter {
            ticks: None,
            duration_s: Some(seconds),
        },
    )
    .expect("the loop runs");
    stop.store(true, Ordering::Relaxed);
    feed.join().expect("feeder");
    side.join().expect("sidecar");
    assert_eq!(
        stats.advice_received,
        stats.advice_verdicts.iter().sum::<u64>() + stats.advice_superseded + stats.advice_pending,
        "every advice is judged, superseded or pending: {stats:?}"
    );
    stats
}

/// The newest request issued after `after_ns`, waiting for it (at most 5 s).
fn next_request(requests: &Requests, after_ns: u64) -> AdviceRequest {
    let give_up = now_ns() + 5_000_000_000;
    loop {
        assert!(now_ns() < give_up, "no advice request for 5 s");
        if let (Some(r), _) = iox::newest(requests).expect("receive") {
            if r.issued_ns > after_ns {
                return r;
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// A confident answer to `r`: the corrected logit's own choice, so plausible and safe.
fn answer(r: &AdviceRequest) -> WireAdvice {
    let best = (0..5)
        .max_by(|&a, &b| r.p_corrected[a].total_cmp(&r.p_corrected[b]))
        .unwrap();
    WireAdvice {
        request_id: r.request_id,
        published_ns: 0,
        confidence: 0.95,
        ego_intent: WireIntent::from_intent(&Default::default()),
        agent_intents: [WireAgentIntent {
            intent: WireIntent::from_intent(&Default::default()),
            agent_id: 0,
            reserved: [0; 4],
        }; WIRE_OBJECTS],
        maneuver: Maneuver::ALL[best] as u8,
        valid: 1,
        n_agent_intents: 0,
        failure: 0,
        reserved: [0; 4],
    }
}

#[test]
fn malformed_advice_and_failure_reports_install_nothing() {
    let prefix = format!("intake-bad-{}/", std::process::id());
    let stats = run(service(&prefix, 20.0), false, 2.5, |requests, out| {
        let nan_intent = WireIntent {
            style: 0,
            style_confidence: f32::NAN,
            ..WireIntent::from_intent(&Default::default())
        };
        let r = next_request(requests, 0);
        let mut bad = Vec::new();
        // A parsed intent with a NaN confidence (the passenger's, then a road user's).
        bad.push(WireAdvice {
            ego_intent: nan_intent,
            ..answer(&r)
        });
        let mut a = answer(&r);
        a.n_agent_intents = 1;
        a.agent_intents[0].intent = nan_intent;
        bad.push(a);
        // An intent code, a maneuver code and a count out of range; a confidence above 1.
        let mut a = answer(&r);
        a.ego_intent.task = 200;
        bad.push(a);
        bad.push(WireAdvice {
            maneuver: 9,
            ..answer(&r)
        });
        bad.push(WireAdvice {
            n_agent_intents: WIRE_OBJECTS as u8 + 1,
            ..answer(&r)
        });
        bad.push(WireAdvice {
            confidence: 1.5,
            ..answer(&r)
        });
        // A stamp from the future.
        bad.push(WireAdvice {
            published_ns: now_ns() + 60_000_000_000,
            ..answer(&r)
        });
        // A failure report (a timeout) that carries a NaN intent as well.
        bad.push(WireAdvice {
            valid: 0,
            maneuver: UNKNOWN,
            ego_intent: nan_intent,
            ..answer(&r)
        });
        for mut a in bad {
            if a.published_ns == 0 {
                a.published_ns = now_ns();
            }
            iox::send(out, &a).expect("send");
            std::thread::sleep(Duration::from_millis(150));
        }
    });
    let rejected: u64 = stats.frames_rejected.iter().sum();
    assert_eq!(
        rejected, 0,
        "good scenes rejected after bad advice: {stats:?}"
    );
    assert!(stats.frames_accepted >= 35, "{stats:?}");
    assert_eq!(stats.fallbacks[FallbackReason::StaleScene as usize], 0);
    assert_eq!(stats.advice_verdicts[AdviceVerdict::Malformed as usize], 7);
    assert_eq!(stats.advice_verdicts[AdviceVerdict::NoAdvice as usize], 1);
    assert_eq!(stats.advice_failures[0], 1, "the timeout is counted");
    assert_eq!(stats.advice_verdicts[AdviceVerdict::Accepted as usize], 0);
}

/// Three answers published 1 ms before their deadline, then three 1 ms after it.
fn publish_around_the_deadline(rate_hz: f64) {
    const MS: u64 = 1_000_000;
    let prefix = format!("intake-deadline-{rate_hz}-{}/", std::process::id());
    let stats = run(service(&prefix, rate_hz), false, 6.0, |requests, out| {
        let mut after = 0;
        for offset in [-1i64, -1, -1, 1, 1, 1] {
            loop {
                let r = next_request(requests, after);
                after = r.issued_ns;
                let target = r.deadline_ns.saturating_add_signed(offset * MS as i64);
                if now_ns() + 5 * MS > target {
                    continue; // too little time left to aim: take a newer request
                }
                std::thread::sleep(Duration::from_nanos(target - now_ns() - 2 * MS));
                while now_ns() < target {
                    std::hint::spin_loop();
                }
                let mut a = answer(&r);
                a.published_ns = now_ns();
                let margin = a.published_ns as i64 - r.deadline_ns as i64;
                if offset < 0 && margin > -(MS as i64) / 2 {
                    continue; // preempted past the aim: try again
                }
                iox::send(out, &a).expect("send");
                // Let the core judge it before the next one.
                std::thread::sleep(Duration::from_millis(200));
                after = now_ns();
                break;
            }
        }
    });
    let v = |x: AdviceVerdict| stats.advice_verdicts[x as usize];
    assert_eq!(v(AdviceVerdict::Accepted), 3, "at {rate_hz} Hz: {stats:?}");
    assert_eq!(v(AdviceVerdict::Late), 3, "at {rate_hz} Hz: {stats:?}");
}

/// Deciding on each of a frame every millisecond, the core issues an advice request at most
/// every 0.5 × `request_period_s` (25 ms), so its log of 256 requests spans 6.4 s whatever
/// the rate: an answer to a request 1.2 s (about 1200 decisions) old, within its 1.5 s
/// deadline, is accepted. (A log of the last 256 cycles had forgotten it after 0.26 s.)
#[test]
fn the_request_log_spans_the_deadline_at_a_thousand_decisions_a_second() {
    let prefix = format!("intake-fast-{}/", std::process::id());
    let cfg = ServiceConfig {
        decide_on: DecideOn::Arrival,
        ..service(&prefix, 1000.0)
    };
    let gaps = Arc::new(std::sync::Mutex::new(Vec::new()));
    let seen = gaps.clone();
    let stats = run_fed(cfg, false, 3.0, 0.001, 1.5, move |requests, out| {
        let first = next_request(requests, 0);
        let mut last = first.issued_ns;
        let mut ids = vec![first.request_id];
        while now_ns() < first.issued_ns + 1_200_000_000 {
            if let (Some(r), _) = iox::newest(requests).expect("receive") {
                if r.issued_ns > last {
                    seen.lock().unwrap().push(r.issued_ns - last);
                    last = r.issued_ns;
                    ids.push(r.request_id);
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let mut a = answer(&first);
        a.published_ns = now_ns();
        iox::send(out, &a).expect("send");
        assert!(
            ids.windows(2).all(|w| w[1] > w[0]),
            "request ids grow: {ids:?}"
        );
    });
    let gaps = gaps.lock().unwrap();
    assert!(gaps.len() >= 15, "{} requests in 1.2 s", gaps.len());
    let close = gaps.iter().filter(|&&g| g < 25_000_000).count();
    assert_eq!(
        close,
        0,
        "{close} of {} requests closer than 25 ms to the one before (the closest {} ns)",
        gaps.len(),
        gaps.iter().min().unwrap()
    );
    assert!(
        stats.frames_accepted > 1500,
        "too few decisions for the test: {stats:?}"
    );
    assert_eq!(
        stats.advice_verdicts[AdviceVerdict::Accepted as usize],
        1,
        "{stats:?}"
    );
}

#[test]
fn an_answer_published_1_ms_before_its_deadline_is_accepted_at_20_hz_and_1_ms_after_never() {
    publish_around_the_deadline(20.0);
}

#[test]
fn an_answer_published_1_ms_before_its_deadline_is_accepted_at_50_hz_and_1_ms_after_never() {
    publish_around_the_deadline(50.0);
}

#[test]
fn an_answer_published_1_ms_before_its_deadline_is_accepted_at_100_hz_and_1_ms_after_never() {
    publish_around_the_deadline(100.0);
}

/// The car's intent in `r`'s objects.
fn hdv_intent(r: &AdviceRequest) -> WireIntent {
    r.objects[..r.n_objects as usize]
        .iter()
        .find(|o| o.state.id == HDV)
        .unwrap_or_else(|| panic!("the car is not among the objects of {r:?}"))
        .state
        .intent
}

#[test]
fn the_intents_of_an_advice_reach_the_scenes_until_they_expire() {
    let prefix = format!("intake-intents-{}/", std::process::id());
    let cfg = ServiceConfig {
        intent_hold_s: 1.0,
        ..service(&prefix, 20.0)
    };
    run(cfg, true, 4.0, |requests, out| {
        let r = next_request(requests, 0);
        assert_eq!(
            r.ego_intent,
            WireIntent::default(),
            "no intent before the advice"
        );
        assert_eq!(hdv_intent(&r), WireIntent::default());
        // The passenger is in a hurry to a hospital; the car said it gives way; a road user
        // that is not in the scene said it proceeds.
        let emergency = WireIntent {
            task: Task::Emergency as u8,
            task_confidence: 0.9,
            ..WireIntent::default()
        };
        let gives_way = WireIntent {
            action: IntentAction::Yield as u8,
            action_confidence: 0.9,
            ..WireIntent::default()
        };
        let mut a = WireAdvice {
            ego_intent: emergency,
            n_agent_intents: 2,
            published_ns: now_ns(),
            ..answer(&r)
        };
        a.agent_intents[0].agent_id = HDV;
        a.agent_intents[0].intent = gives_way;
        a.agent_intents[1].agent_id = HDV + 1;
        a.agent_intents[1].intent = WireIntent {
            action: IntentAction::Proceed as u8,
            ..gives_way
        };
        iox::send(out, &a).expect("send");
        let sent = now_ns();
        let r = next_request(requests, sent + 100_000_000);
        assert_eq!(
            r.ego_intent, emergency,
            "the passenger's intent is in the scene"
        );
        assert_eq!(
            hdv_intent(&r),
            gives_way,
            "the car's intent is in the scene"
        );
        let r = next_request(requests, sent + 1_200_000_000);
        assert_eq!(
            r.ego_intent,
            WireIntent::default(),
            "held past intent_hold_s"
        );
        assert_eq!(
            hdv_intent(&r),
            WireIntent::default(),
            "held past intent_hold_s"
        );
    });
}

/// With `service.route` set, the core decides on that lane whatever the frames name: the
/// feeder's frames name the left turn, the route is the straight lane beside it, and every
/// request carries the straight lane's turn.
#[test]
fn a_configured_route_replaces_the_lane_the_frames_name() {
    for (route, turn) in [(None, Turn::Left), (Some("west_straight"), Turn::Straight)] {
        let cfg = ServiceConfig {
            route: route.map(str::to_string),
            ..service(
                &format!("intake-route-{}-{route:?}/", std::process::id()),
                20.0,
            )
        };
        run(cfg, true, 1.0, move |requests, _| {
            let first = next_request(requests, 0);
            let later = next_request(requests, first.issued_ns);
            for r in [first, later] {
                assert_eq!(r.route_turn, turn as u8, "route {route:?}");
            }
        });
    }
    let unknown = ServiceConfig {
        route: Some("nowhere".into()),
        ..ServiceConfig::default()
    };
    let e = unknown.road().unwrap_err();
    assert!(e.contains("service.route") && e.contains("cav_left"), "{e}");
}
