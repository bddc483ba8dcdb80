//! A newer advice request of another situation while a call is in flight, against a loopback
//! server that answers after 400 ms: with `advice.cancel_superseded` the call in flight is
//! cancelled and only the newer request is answered; without, both are answered, in order.

#[path = "../../tests/support/fault_llm.rs"]
mod fault_llm;
#[path = "../../tests/support/in_process_sidecar.rs"]
mod in_process_sidecar;

use std::time::Duration;

use concord_core::scene::{AgentState, Scene, Vec2};
use concord_core::{DecisionCore, Params};
use concord_ipc::clock::now_ns;
use concord_ipc::wire::AdviceRequest;
use concord_map::{paper, BuiltIn};
use concord_sidecar::bus::Outbound;
use concord_sidecar::config::SidecarConfig;
use fault_llm::{FaultLlm, Mode};

/// An advice request on the paper's junction whose corrected P_n favours maneuver `favourite`
/// (so two requests with different favourites describe different situations).
fn request(id: u64, favourite: usize) -> AdviceRequest {
    let ego = AgentState::moving(0, Vec2::new(20.0, 5.0), std::f64::consts::PI, 8.0);
    let mut scene = Scene::new(10.0, ego, paper::CAV_LEFT);
    scene.push(AgentState::moving(1, Vec2::new(-20.0, -5.0), 0.0, 8.0));
    let mut core =
        DecisionCore::new(Params::default(), BuiltIn::PaperIntersection.morphology()).unwrap();
    let d = core.step(&scene, scene.time_s, None).unwrap();
    let mut r = AdviceRequest::from_core(id, id, now_ns(), 0, &d, &core, scene.ego_lane);
    r.deadline_ns = now_ns() + 5_000_000_000;
    r.p_corrected = [0.1; 5];
    r.p_corrected[favourite] = 0.6;
    r
}

/// The request ids answered and the calls cancelled when request 2 (another favourite) comes
/// 100 ms after request 1.
fn answered(cancel_superseded: bool) -> (Vec<u64>, u64) {
    let server = FaultLlm::start(Mode::Answer {
        maneuver: "decelerate",
        p: 0.9,
        ehmi: "I am slowing down; please go ahead.",
        action: "yield",
        delay: Duration::from_millis(400),
    });
    let mut cfg = SidecarConfig::default();
    cfg.llm.base_url = server.url();
    cfg.advice.cancel_superseded = cancel_superseded;
    cfg.advice.settled_margin = 2.0;
    cfg.intent.parsed_file = Default::default();
    cfg.log.path = std::env::temp_dir().join(format!(
        "concord-superseding-{}-{cancel_superseded}.jsonl",
        std::process::id()
    ));
    let log_path = cfg.log.path.clone();
    let (sidecar, out_rx) = in_process_sidecar::start(cfg);
    let (req_tx, req_rx) = tokio::sync::watch::channel(None);
    let driver = async {
        req_tx.send_replace(Some(request(1, 1)));
        tokio::time::sleep(Duration::from_millis(100)).await;
        req_tx.send_replace(Some(request(2, 0)));
        tokio::time::sleep(Duration::from_millis(1500)).await;
        drop(req_tx);
    };
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(async { tokio::join!(sidecar.advice_worker(req_rx), driver) });
    let ids = out_rx
        .try_iter()
        .filter_map(|o| match o {
            Outbound::Advice(a) if a.valid == 1 => Some(a.request_id),
            _ => None,
        })
        .collect();
    let cancelled = sidecar.counters().cancelled;
    let _ = std::fs::remove_file(&log_path);
    (ids, cancelled)
}

#[test]
fn a_call_in_flight_is_cancelled_only_when_configured() {
    assert_eq!(answered(true), (vec![2], 1));
    assert_eq!(answered(false), (vec![1, 2], 0));
}
