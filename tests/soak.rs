//! Hardware-in-the-loop soak across real processes over real iceoryx2: `concord run` at
//! 100 Hz, and three `concord feed` runs of dense traffic at 20 Hz one after the other: the
//! first and last inject every fault in turn, the middle one is killed with SIGKILL (a crashed
//! publisher). `concord sidecar` answers advice requests from a loopback LLM server that cycles
//! through good answers, late answers, garbage, unknown enums, HTTP 500 and dropped
//! connections; it is killed with SIGKILL during the middle feed and started again. This
//! process watches every decision and the core's statistics.
//!
//! Runs 60 s by default; `CONCORD_SOAK_SECS=3600 cargo test --release --test soak` soaks for
//! an hour.

use std::collections::HashSet;
use std::process::Stdio;
use std::time::{Duration, Instant};

use concord_core::{DecisionSource, FallbackReason};
use concord_ipc::clock::now_ns;
use concord_ipc::feed::Fault;
use concord_ipc::wire::{AdviceFailure, CoreStats, FrameReject, WireDecision};
use concord_ipc::{iox, services};

#[path = "support/fault_llm.rs"]
mod fault_llm;
#[path = "support/proc.rs"]
mod proc;

use fault_llm::{FaultLlm, Mode};
use proc::Proc;

/// A feed's summary line, as numbers by key.
fn summary(out: &str) -> std::collections::HashMap<String, u64> {
    let line = out
        .lines()
        .find(|l| l.starts_with("feed summary:"))
        .unwrap_or_else(|| panic!("no feed summary in {out:?}"));
    line["feed summary:".len()..]
        .split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.parse().expect("a count")))
        .collect()
}

#[test]
fn soak_feed_core_with_faults_and_a_crashed_publisher() {
    let total: f64 = std::env::var("CONCORD_SOAK_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60.0);
    let prefix = format!("soak-{}/", std::process::id());
    let iox_cfg = iox::init(None).expect("iceoryx2 config");
    let node = iox::node("concord-soak-observer", &iox_cfg).expect("observer node");
    let decisions = iox::subscriber::<WireDecision>(
        &node,
        &services::name(&prefix, services::DECISION),
        iox::MAX_BUFFER,
    )
    .expect("decision subscriber");
    let stats = iox::subscriber::<CoreStats>(&node, &services::name(&prefix, services::STATS), 1)
        .expect("stats subscriber");

    let core = Proc::start(
        &[
            "run",
            "--prefix",
            &prefix,
            "--rate",
            "100",
            "--duration",
            &(total + 6.0).to_string(),
        ]
        .map(String::from),
        Stdio::null(),
    );
    let mut core = core;
    // Wait for the core to publish statistics: it is up.
    let t0 = Instant::now();
    let mut last_stats = None;
    while last_stats.is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the core never came up"
        );
        std::thread::sleep(Duration::from_millis(50));
        last_stats = iox::newest(&stats).unwrap().0;
    }

    let llm = FaultLlm::start(Mode::yielding());
    let log = std::env::temp_dir().join(format!("concord-soak-{}.jsonl", std::process::id()));
    let sidecar = || {
        Proc::start(
            &[
                "sidecar",
                "--prefix",
                &prefix,
                "--llm-url",
                &llm.url(),
                "--log",
                &log.display().to_string(),
            ]
            .map(String::from),
            Stdio::null(),
        )
    };
    let mut sidecar_a = sidecar();
    // The LLM server's behaviour, switched every 2.5 s.
    let modes = [
        Mode::yielding(),
        Mode::Late(Duration::from_secs(4)),
        Mode::Malformed,
        Mode::yielding(),
        Mode::UnknownEnum,
        Mode::ServerError,
        Mode::Close,
    ];
    let soak_started = Instant::now();
    let set_mode = || {
        let i = (soak_started.elapsed().as_secs_f64() / 2.5) as usize % modes.len();
        llm.set(modes[i].clone());
    };

    let faults = Fault::ALL.map(|f| f.name()).join(",");
    let feed = |secs: f64, with_faults: bool| -> Proc {
        let mut args = vec![
            "feed",
            "--scenario",
            "dense",
            "--repeat",
            "--rate",
            "20",
            "--prefix",
            &prefix,
            "--duration",
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        args.push(format!("{secs}"));
        if with_faults {
            args.extend([
                "--faults".into(),
                faults.clone(),
                "--fault-every".into(),
                "25".into(),
            ]);
        }
        Proc::start(&args, Stdio::piped())
    };

    let mut seen: HashSet<(u64, u64)> = HashSet::new();
    let mut answered = 0u64;
    let mut stale = 0u64;
    let mut per_feed = [0u64; 3];
    let mut windows: Vec<(u64, u64)> = Vec::new();
    let mut observe = |until: Instant, core: &mut Proc, seen: &mut HashSet<(u64, u64)>| {
        while Instant::now() < until {
            std::thread::sleep(Duration::from_millis(10));
            set_mode();
            assert!(core.alive(), "the core died");
            while let Some(d) = decisions.receive().unwrap() {
                if d.fallback == FallbackReason::StaleScene as u8 {
                    stale += 1;
                    continue;
                }
                answered += 1;
                assert!(
                    seen.insert((d.scene_stamp_ns, d.scene_sequence)),
                    "scene {} answered twice",
                    d.scene_sequence
                );
                assert!(d.n_points > 1, "a decision without trajectory");
            }
        }
    };

    // Phase A: faults; phase B: killed mid-run; phase C: faults.
    let a_secs = (total * 0.45).max(10.0);
    let c_secs = (total - a_secs - 5.0).max(10.0);
    let start_a = now_ns();
    let a = feed(a_secs, true);
    observe(
        Instant::now() + Duration::from_secs_f64(a_secs + 1.5),
        &mut core,
        &mut seen,
    );
    let (a_ok, a_out) = a.finish(Duration::from_secs(10));
    assert!(a_ok, "feed A failed: {a_out}");
    windows.push((start_a, now_ns()));

    let start_b = now_ns();
    let b = feed(60.0, false);
    observe(
        Instant::now() + Duration::from_secs(3),
        &mut core,
        &mut seen,
    );
    b.signal(libc::SIGKILL);
    let _ = b.finish(Duration::from_secs(5));
    assert!(sidecar_a.alive(), "the sidecar died");
    sidecar_a.signal(libc::SIGKILL);
    let _ = sidecar_a.finish(Duration::from_secs(5));
    let before_restart = iox::newest(&stats).unwrap().0.or(last_stats);
    let mut sidecar_b = sidecar();
    observe(
        Instant::now() + Duration::from_secs(1),
        &mut core,
        &mut seen,
    );
    windows.push((start_b, now_ns()));

    let start_c = now_ns();
    let c = feed(c_secs, true);
    observe(
        Instant::now() + Duration::from_secs_f64(c_secs + 1.5),
        &mut core,
        &mut seen,
    );
    let (c_ok, c_out) = c.finish(Duration::from_secs(10));
    assert!(c_ok, "feed C failed: {c_out}");
    windows.push((start_c, now_ns()));
    observe(
        Instant::now() + Duration::from_millis(1500),
        &mut core,
        &mut seen,
    );

    for (stamp, _) in &seen {
        if let Some(i) = windows.iter().position(|(s, e)| stamp >= s && stamp <= e) {
            per_feed[i] += 1;
        }
    }
    let last_stats = iox::newest(&stats)
        .unwrap()
        .0
        .or(last_stats)
        .expect("statistics");
    assert!(sidecar_b.alive(), "the restarted sidecar died");
    sidecar_b.signal(libc::SIGTERM);
    let (sidecar_ok, _) = sidecar_b.finish(Duration::from_secs(10));
    assert!(sidecar_ok, "the sidecar did not exit cleanly on SIGTERM");
    let (core_ok, _) = core.finish(Duration::from_secs(15));
    assert!(core_ok, "the core did not exit cleanly");
    let _ = std::fs::remove_file(&log);

    let (sa, sc) = (summary(&a_out), summary(&c_out));
    eprintln!("A: {sa:?}\nC: {sc:?}\nanswered {answered} (per feed {per_feed:?}), stale {stale}\n{last_stats:?}");
    let s = last_stats;
    // Every valid scene is answered by exactly one decision.
    assert_eq!(
        per_feed[0], sa["valid"],
        "feed A: valid scenes vs decisions"
    );
    assert_eq!(
        per_feed[2], sc["valid"],
        "feed C: valid scenes vs decisions"
    );
    assert!(per_feed[1] > 0, "the core decided nothing while feed B ran");
    assert_eq!(answered, s.frames_accepted, "decisions vs accepted frames");
    // Faults are rejected and counted.
    let injected = |k: &str| sa[k] + sc[k];
    assert_eq!(
        s.frames_rejected[FrameReject::NotFinite as usize],
        injected("nan")
    );
    assert_eq!(
        s.frames_rejected[FrameReject::OutOfRange as usize],
        injected("jump")
    );
    assert_eq!(
        s.frames_rejected[FrameReject::Duplicate as usize],
        injected("duplicate")
    );
    assert_eq!(
        s.frames_rejected[FrameReject::OutOfOrder as usize],
        injected("reorder")
    );
    assert_eq!(s.frames_rejected[FrameReject::BadCode as usize], 0);
    assert!(
        injected("stall") > 0 && stale > 0,
        "stalls must bring the stale-scene fallback"
    );
    // Restart faults plus the two new feeds (B and C start their sequences at 0).
    assert_eq!(s.publisher_restarts, injected("restart") + 2);
    // The counters add up.
    assert_eq!(
        s.frames_received,
        s.frames_accepted + s.frames_superseded + s.frames_rejected.iter().sum::<u64>()
    );
    assert_eq!(
        s.decisions.iter().sum::<u64>(),
        s.frames_accepted + s.fallbacks[FallbackReason::StaleScene as usize]
    );
    assert_eq!(
        s.fallbacks.iter().sum::<u64>(),
        s.decisions.iter().sum::<u64>()
    );
    assert_eq!(
        s.advice_requests, s.frames_accepted,
        "one advice request per decision by default"
    );
    // The sidecar's answers and failures reached the core, before and after its restart, and
    // each fault of the LLM server shows as its own reason.
    let before = before_restart.expect("statistics before the sidecar restart");
    assert!(
        s.advice_received > before.advice_received,
        "no advice after the restart"
    );
    for f in AdviceFailure::ALL {
        assert!(
            s.advice_failures[f as usize] > 0,
            "no {} failure counted",
            f.name()
        );
    }
    let valid_verdicts: u64 = s.advice_verdicts.iter().skip(1).sum();
    assert!(valid_verdicts > 0, "no answer was weighed by the gate");
    assert_eq!(
        s.advice_received,
        s.advice_verdicts.iter().sum::<u64>() + s.advice_superseded + s.advice_pending,
        "every advice is judged, superseded or pending"
    );
    assert!(
        s.decisions[DecisionSource::Advice as usize] > 0,
        "confident safe advice was never applied"
    );
}
