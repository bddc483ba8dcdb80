//! The bad-input campaign: random and mutated inputs from every untrusted source, through the
//! same decoding and checks the processes run.
//!
//! * 10⁶ byte patterns of `SceneFrame`, `WireAdvice` and `IntentText` (whole random messages,
//!   bit flips, random bytes, and special numbers written over 8-byte words of a valid
//!   message): no panic, every pattern counted under exactly one outcome, every outcome seen.
//!   One pattern in 500 also goes through a full core step.
//! * The same kinds of frames and advice through a running core process over iceoryx2: its
//!   counters add up, and the good frames that follow are decided again (no stuck state). A
//!   corrupt frame is refused for its content and never makes the good frames after it out of
//!   order.
//! * Random TOML for `concord run`'s and the sidecar's configuration: an error that names the
//!   key, never a panic; what passes builds a core and steps it.
//!
//! It prints the counts (`cargo test --test bad_input_campaign -- --nocapture`).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use concord_core::scene::{AgentState, Scene, Vec2};
use concord_core::{DecisionCore, Params};
use concord_ipc::clock::now_ns;
use concord_ipc::core_service::{self, Geometry, RunConfig, ServiceConfig, StopAfter};
use concord_ipc::system::RealtimeConfig;
use concord_ipc::wire::{CoreStats, FrameReject, IntentText, SceneFrame, TextSource, WireAdvice};
use concord_ipc::{iox, services};
use concord_map::paper;
use concord_sidecar::config::SidecarConfig;
use concord_sidecar::ledger::Ledger;
use concord_sidecar::untrusted::{normalise, words};
use rand::rngs::SmallRng;

#[path = "support/toml_paths.rs"]
mod toml_paths;
#[path = "support/wire_samples.rs"]
mod wire_samples;

use rand::{Rng, RngCore, SeedableRng};
use wire_samples::known_intent;

/// Byte patterns per message type.
const SCENES: usize = 400_000;
const ADVICE: usize = 400_000;
const TEXTS: usize = 200_000;

/// Numbers written over 8-byte words: non-finite, absurd, and edge values.
const SPECIAL: [f64; 9] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    1e300,
    -1e300,
    f64::MIN_POSITIVE / 2.0,
    -0.0,
    1e12,
    -1.0,
];

/// The bytes of a wire message.
fn bytes_of<T: Copy>(v: &T) -> Vec<u8> {
    // SAFETY: wire messages are `#[repr(C)]` plain data; reading their bytes is sound (padding
    // bytes are zero, since every message is built from a zeroed default or by field).
    unsafe { std::slice::from_raw_parts(v as *const T as *const u8, size_of::<T>()) }.to_vec()
}

/// A wire message from any bytes.
fn from_bytes<T: Copy>(b: &[u8]) -> T {
    assert_eq!(b.len(), size_of::<T>());
    // SAFETY: every field of a wire message is an integer, a float or an array of them, so
    // every bit pattern is a value of the type; the read is unaligned.
    unsafe { std::ptr::read_unaligned(b.as_ptr() as *const T) }
}

/// One pattern from the valid message `good`.
fn mutate(good: &[u8], rng: &mut SmallRng) -> Vec<u8> {
    let mut b = good.to_vec();
    match rng.random_range(0..8) {
        0 => rng.fill_bytes(&mut b),
        1 | 2 => {
            for _ in 0..rng.random_range(1..=8) {
                let i = rng.random_range(0..b.len() * 8);
                b[i / 8] ^= 1 << (i % 8);
            }
        }
        3 | 4 => {
            for _ in 0..rng.random_range(1..=16) {
                let i = rng.random_range(0..b.len());
                b[i] = rng.random();
            }
        }
        _ => {
            for _ in 0..rng.random_range(1..=3) {
                let at = rng.random_range(0..b.len() / 8) * 8;
                let v = SPECIAL[rng.random_range(0..SPECIAL.len())];
                // f32 fields sit at 4-byte offsets: write either half as an f32 too.
                if rng.random_bool(0.3) {
                    let half = at + 4 * rng.random_range(0..2);
                    b[half..half + 4].copy_from_slice(&(v as f32).to_ne_bytes());
                } else {
                    b[at..at + 8].copy_from_slice(&v.to_ne_bytes());
                }
            }
        }
    }
    b
}

/// The paper's junction with four road users and known intents.
fn good_frame(sequence: u64, stamp_ns: u64) -> SceneFrame {
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), std::f64::consts::PI, 8.0);
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    for k in 0..4 {
        let x = -40.0 + 8.0 * k as f64;
        scene.push(AgentState::moving(k + 1, Vec2::new(x, -5.0), 0.0, 8.0));
    }
    let mut f = SceneFrame::from_scene(sequence, stamp_ns, &scene);
    f.ego.intent = known_intent();
    for a in f.agents.iter_mut().take(4) {
        a.intent = known_intent();
    }
    f
}

fn good_advice(request_id: u64, published_ns: u64) -> WireAdvice {
    wire_samples::advice(request_id, published_ns, 3)
}

fn paper_core() -> Box<DecisionCore> {
    let mut p = Params::default();
    p.trajectory.samples = 64;
    Box::new(DecisionCore::new(p, Geometry::PaperIntersection.morphology()).unwrap())
}

fn report(title: &str, n: usize, outcomes: &BTreeMap<String, usize>) {
    eprintln!("{title}: {n} patterns: {outcomes:?}");
    assert_eq!(
        outcomes.values().sum::<usize>(),
        n,
        "{title}: counts add up"
    );
}

#[test]
fn a_million_byte_patterns_are_each_refused_with_a_reason_or_taken() {
    let mut rng = SmallRng::seed_from_u64(0xBAD1);
    let mut core = paper_core();
    let limits = Params::default().limits;
    let lanes = Geometry::PaperIntersection.morphology().lanes().len();

    let good = bytes_of(&good_frame(7, 1_000_000_000));
    let mut outcomes = BTreeMap::new();
    for k in 0..SCENES {
        let f: SceneFrame = from_bytes(&mutate(&good, &mut rng));
        let outcome = match f.to_scene() {
            Err(e) => format!("bad_code {}", e.field),
            Ok(s) => {
                let checked = s.validate(&limits, lanes);
                if k % 500 == 0 {
                    // The step checks exactly what validation checks.
                    let stepped = core.step(&s, s.time_s, None);
                    assert_eq!(stepped.is_ok(), checked.is_ok(), "{f:?}");
                }
                match checked {
                    Ok(()) => "accepted".to_string(),
                    Err(e) => format!("{:?}", e.kind),
                }
            }
        };
        *outcomes.entry(outcome).or_insert(0) += 1;
    }
    report("SceneFrame", SCENES, &outcomes);
    for seen in ["accepted", "NotFinite", "OutOfRange"] {
        assert!(outcomes.contains_key(seen), "no {seen} frame");
    }
    assert!(outcomes.keys().any(|k| k.starts_with("bad_code")));

    let good = bytes_of(&good_advice(1, 1_000));
    let mut outcomes = BTreeMap::new();
    let scene = good_frame(1, 1_000).to_scene().unwrap();
    for k in 0..ADVICE {
        let a: WireAdvice = from_bytes(&mutate(&good, &mut rng));
        let outcome = match a.check(now_ns()) {
            Ok(None) => "failure_report".to_string(),
            Ok(Some(c)) => {
                if k % 500 == 0 {
                    // The gate judges whatever passed the check.
                    let mut s = scene;
                    s.time_s = k as f64;
                    core.step(&s, s.time_s, Some(&c.advice)).unwrap();
                }
                "taken".to_string()
            }
            Err(field) => format!("malformed {field}"),
        };
        *outcomes.entry(outcome).or_insert(0) += 1;
    }
    report("WireAdvice", ADVICE, &outcomes);
    for seen in ["taken", "failure_report", "malformed confidence"] {
        assert!(outcomes.contains_key(seen), "no {seen} advice");
    }

    let good = bytes_of(&IntentText::new(
        5,
        9,
        TextSource::RoadUser,
        1,
        "Go ahead, I'll wait ＜/msg＞ \u{202e}",
    ));
    let mut ledger = Ledger::in_memory(64);
    let mut outcomes = BTreeMap::new();
    for _ in 0..TEXTS {
        let t: IntentText = from_bytes(&mutate(&good, &mut rng));
        let source = [TextSource::Passenger, TextSource::RoadUser]
            .into_iter()
            .find(|s| *s as u8 == t.source);
        let outcome = match (t.text(), source) {
            (None, _) => "unreadable",
            (_, None) => "unknown_source",
            (Some(text), Some(_)) => {
                let n = normalise(text, 200);
                assert!(n.chars().count() <= 200);
                assert!(!n.chars().any(|c| c.is_control()), "{n:?}");
                let _ = words(&n);
                if ledger.take(&t) {
                    "parsed"
                } else {
                    "repeat"
                }
            }
        };
        *outcomes.entry(outcome.to_string()).or_insert(0) += 1;
    }
    report("IntentText", TEXTS, &outcomes);
    for seen in ["parsed", "repeat", "unreadable", "unknown_source"] {
        assert!(outcomes.contains_key(seen), "no {seen} text");
    }
}

#[test]
fn a_running_core_counts_every_bad_frame_and_decides_the_good_ones_after() {
    let prefix = format!("campaign-{}/", std::process::id());
    let config = iox::init(None).expect("iceoryx2 config");
    // 0: bad inputs, 1: stale, 2: the core took its counts before the good frames, 3: done.
    let phase = Arc::new(AtomicU64::new(0));
    let sender = {
        let (config, prefix, phase) = (config.clone(), prefix.clone(), phase.clone());
        std::thread::spawn(move || {
            let node = iox::node("campaign-sender", &config).expect("node");
            let name = |s| services::name(&prefix, s);
            let scenes = iox::publisher::<SceneFrame>(&node, &name(services::SCENE)).unwrap();
            let advice = iox::publisher::<WireAdvice>(&node, &name(services::ADVICE)).unwrap();
            let mut rng = SmallRng::seed_from_u64(0xBAD2);
            std::thread::sleep(Duration::from_millis(300));
            for k in 0..2000u64 {
                let good = bytes_of(&good_frame(k + 1, now_ns()));
                let f: SceneFrame = from_bytes(&mutate(&good, &mut rng));
                iox::send(&scenes, &f).unwrap();
                if k % 2 == 0 {
                    let good = bytes_of(&good_advice(k, now_ns()));
                    iox::send(&advice, &from_bytes::<WireAdvice>(&mutate(&good, &mut rng)))
                        .unwrap();
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            // The worst frame a barrage can end with: valid, with a far sequence number and a
            // stamp a minute ahead. Every older frame is out of order until the scene is stale.
            let far = good_frame(1 << 40, now_ns() + 60_000_000_000);
            iox::send(&scenes, &far).unwrap();
            std::thread::sleep(Duration::from_secs_f64(STALENESS_S + 0.1));
            phase.store(1, Ordering::SeqCst);
            let asked = std::time::Instant::now();
            while phase.load(Ordering::SeqCst) < 2 && asked.elapsed() < Duration::from_secs(5) {
                std::thread::sleep(Duration::from_millis(1));
            }
            for k in 0..40 {
                iox::send(&scenes, &good_frame(k + 1, now_ns())).unwrap();
                std::thread::sleep(Duration::from_millis(50));
            }
            phase.store(3, Ordering::SeqCst);
        })
    };
    let mut at_good = None;
    let stats = run_paper_core(prefix, &config, 15.0, |s| {
        if phase.load(Ordering::SeqCst) == 1 && at_good.is_none() {
            at_good = Some(*s);
            phase.store(2, Ordering::SeqCst);
        }
    });
    sender.join().unwrap();
    assert_eq!(
        phase.load(Ordering::SeqCst),
        3,
        "the sender finished within the run"
    );
    let rejected: u64 = stats.frames_rejected.iter().sum();
    eprintln!(
        "core process: {} frames in, {} superseded, {} decided, rejected {:?} (bad code, not finite, out of range, duplicate, out of order), {} restarts; advice {} in, verdicts {:?}, {} superseded, {} pending",
        stats.frames_received,
        stats.frames_superseded,
        stats.frames_accepted,
        stats.frames_rejected,
        stats.publisher_restarts,
        stats.advice_received,
        stats.advice_verdicts,
        stats.advice_superseded,
        stats.advice_pending
    );
    assert_eq!(
        stats.advice_received,
        stats.advice_verdicts.iter().sum::<u64>() + stats.advice_superseded + stats.advice_pending,
        "every advice is judged, superseded or pending"
    );
    assert_eq!(
        stats.frames_received,
        stats.frames_superseded + stats.frames_accepted + rejected,
        "every frame is superseded, decided or rejected under one reason"
    );
    for r in [
        FrameReject::NotFinite,
        FrameReject::OutOfRange,
        FrameReject::BadCode,
    ] {
        assert!(stats.frames_rejected[r as usize] > 0, "no {r:?} frame");
    }
    // The good frames come once the scene is stale, so each starts the source over or follows
    // in order: none is refused, and each is decided unless a stalled tick let the next one
    // replace it. Without the stale recovery every one of them is out of order.
    let before = at_good.expect("the good phase was seen");
    let good_rejected =
        stats.frames_rejected.iter().sum::<u64>() - before.frames_rejected.iter().sum::<u64>();
    let good_decided = stats.frames_accepted - before.frames_accepted;
    let good_superseded = stats.frames_superseded - before.frames_superseded;
    assert_eq!(good_rejected, 0, "good frames refused after the barrage");
    assert_eq!(
        good_decided + good_superseded,
        40,
        "every good frame after the barrage is decided or superseded"
    );
    assert!(
        good_decided >= 30,
        "{good_decided} of 40 good frames decided after the barrage"
    );
}

#[test]
fn a_corrupt_frame_is_refused_for_its_content_and_does_not_reorder_the_source() {
    let prefix = format!("campaign-order-{}/", std::process::id());
    let config = iox::init(None).expect("iceoryx2 config");
    let sender = {
        let (config, prefix) = (config.clone(), prefix.clone());
        std::thread::spawn(move || {
            let node = iox::node("order-sender", &config).expect("node");
            let scenes =
                iox::publisher::<SceneFrame>(&node, &services::name(&prefix, services::SCENE))
                    .unwrap();
            std::thread::sleep(Duration::from_millis(300));
            iox::send(&scenes, &good_frame(1, now_ns())).unwrap();
            std::thread::sleep(Duration::from_millis(50));
            // Not finite, with a far sequence number and a stamp a minute ahead.
            let mut bad = good_frame(1 << 40, now_ns() + 60_000_000_000);
            bad.agents[0].x = f64::NAN;
            iox::send(&scenes, &bad).unwrap();
            for k in 2..=20 {
                std::thread::sleep(Duration::from_millis(50));
                iox::send(&scenes, &good_frame(k, now_ns())).unwrap();
            }
        })
    };
    let stats = run_paper_core(prefix, &config, 1.8, |_| {});
    sender.join().unwrap();
    let mut refused = [0; 5];
    refused[FrameReject::NotFinite as usize] = 1;
    assert_eq!(stats.frames_received, 21);
    assert_eq!(
        stats.frames_rejected, refused,
        "only the corrupt frame is refused"
    );
    assert_eq!(stats.frames_accepted + stats.frames_superseded, 20);
    assert_eq!(stats.publisher_restarts, 0);
}

/// The core's staleness window in the running-core tests, s.
const STALENESS_S: f64 = 0.3;

/// Runs the core process on the paper's junction at 200 Hz under `prefix` for `duration_s`,
/// `observe` seeing its counters each tick: its final counters.
fn run_paper_core(
    prefix: String,
    config: &iceoryx2::config::Config,
    duration_s: f64,
    observe: impl FnMut(&CoreStats),
) -> CoreStats {
    let cfg = ServiceConfig {
        prefix,
        rate_hz: 200.0,
        print_period_s: 0.0,
        staleness_s: STALENESS_S,
        ..ServiceConfig::default()
    };
    core_service::run_observed(
        &mut paper_core(),
        &cfg,
        None,
        &RealtimeConfig::default(),
        config,
        StopAfter {
            ticks: None,
            duration_s: Some(duration_s),
        },
        observe,
    )
    .expect("the loop runs")
}

fn random_value(rng: &mut SmallRng) -> toml::Value {
    use toml::Value::*;
    match rng.random_range(0..9) {
        0 => Float(SPECIAL[rng.random_range(0..SPECIAL.len())]),
        1 => Float(rng.random_range(-3.0..3.0f64) * 10f64.powi(rng.random_range(-6..12))),
        2 => Integer(rng.random_range(-5..5)),
        3 => Integer(rng.random()),
        4 => String(
            [
                "",
                "x",
                "nan",
                "1e9",
                "paper_intersection",
                "http://127.0.0.1:1/v1",
            ][rng.random_range(0..6)]
            .into(),
        ),
        5 => Boolean(rng.random()),
        6 => Array(
            (0..rng.random_range(0..12))
                .map(|_| Float(rng.random_range(-10.0..10.0)))
                .collect(),
        ),
        7 => Float(rng.random_range(0.0..2.0)),
        _ => Table(Default::default()),
    }
}

/// Sets dotted `path` in `doc`, creating tables on the way.
fn put(doc: &mut toml::Value, path: &str, v: toml::Value) {
    let mut at = doc;
    let parts: Vec<_> = path.split('.').collect();
    for p in &parts[..parts.len() - 1] {
        let t = at.as_table_mut().unwrap();
        at = t
            .entry(p.to_string())
            .or_insert(toml::Value::Table(Default::default()));
        if !at.is_table() {
            *at = toml::Value::Table(Default::default());
        }
    }
    at.as_table_mut()
        .unwrap()
        .insert(parts[parts.len() - 1].to_string(), v);
}

/// `n` random documents over the keys of `defaults` through `parse`: each error must name a
/// key the document set.
fn toml_campaign(
    title: &str,
    defaults: toml::Value,
    n: usize,
    seed: u64,
    parse: impl Fn(&str) -> Result<(), String>,
) {
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut keys: Vec<String> = toml_paths::leaves(&defaults)
        .iter()
        .map(|p| p.split('[').next().unwrap().to_string())
        .collect();
    keys.dedup();
    let (mut refused, mut passed, mut syntax) = (0, 0, 0);
    for _ in 0..n {
        let mut doc = toml::Value::Table(Default::default());
        let mut named = Vec::new();
        for _ in 0..rng.random_range(1..=4) {
            let key = if rng.random_bool(0.1) {
                format!(
                    "{}.bogus_key",
                    keys[rng.random_range(0..keys.len())]
                        .rsplit_once('.')
                        .map_or("x", |k| k.0)
                )
            } else {
                keys[rng.random_range(0..keys.len())].clone()
            };
            put(&mut doc, &key, random_value(&mut rng));
            named.extend(key.split('.').map(str::to_string));
        }
        let mut text = toml::to_string(&doc).unwrap();
        let broken = rng.random_bool(0.05);
        if broken {
            text.truncate(rng.random_range(0..text.len().max(1)));
            text.push_str("= =");
        }
        match parse(&text) {
            Ok(()) => passed += 1,
            Err(e) if broken => {
                syntax += 1;
                assert!(!e.is_empty());
            }
            Err(e) => {
                refused += 1;
                assert!(
                    named.iter().any(|k| e.contains(k.as_str())),
                    "{title}: the error names none of {named:?}: {e}\n{text}"
                );
            }
        }
    }
    eprintln!("{title}: {n} random documents: {refused} refused naming a key, {syntax} broken refused, {passed} passed");
    assert!(
        refused > n / 2 && passed > 0,
        "{refused} refused, {passed} passed"
    );
}

#[test]
fn random_configuration_files_are_refused_by_key_or_run() {
    toml_campaign(
        "concord run configuration",
        toml::Value::try_from(RunConfig::default()).unwrap(),
        20_000,
        0xBAD3,
        |text| {
            let cfg: RunConfig = toml::from_str(text).map_err(|e| e.to_string())?;
            cfg.validate()?;
            let mut core = Box::new(
                DecisionCore::new(cfg.core, cfg.service.geometry.morphology())
                    .map_err(|e| e.to_string())?,
            );
            let s = good_frame(1, 1_000_000_000).to_scene().unwrap();
            let _ = core.step(&s, s.time_s, None);
            Ok(())
        },
    );
    toml_campaign(
        "sidecar configuration",
        toml::Value::try_from(SidecarConfig::default()).unwrap(),
        20_000,
        0xBAD4,
        |text| SidecarConfig::parse(text).map(|_| ()),
    );
}
