//! Every number that enters the core, field by field: each non-finite or absurd value in a
//! scene frame, an advice or the configuration is refused with the field named, and the core
//! decides on the next good input as before.

use concord_core::scene::{AgentState, Scene, Vec2};
use concord_core::DecisionCore;
use concord_ipc::clock::now_ns;
use concord_ipc::core_service::RunConfig;
use concord_ipc::wire::{SceneFrame, WireAdvice, WireAgent, WireIntent};
use concord_map::paper;

#[path = "../../tests/support/toml_paths.rs"]
mod toml_paths;
#[path = "../../tests/support/wire_samples.rs"]
mod wire_samples;

use wire_samples::known_intent;

const BAD: [f64; 4] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300];

/// Every float of a wire agent, by name.
type SetAgent = fn(&mut WireAgent, f64);
type SetIntent = fn(&mut WireIntent, f64);

const AGENT_FIELDS: [(&str, SetAgent); 10] = [
    ("x", |a, v| a.x = v),
    ("y", |a, v| a.y = v),
    ("vx", |a, v| a.vx = v),
    ("vy", |a, v| a.vy = v),
    ("ax", |a, v| a.ax = v),
    ("ay", |a, v| a.ay = v),
    ("heading", |a, v| a.heading = v),
    ("intent.style_confidence", |a, v| {
        a.intent.style_confidence = v as f32
    }),
    ("intent.action_confidence", |a, v| {
        a.intent.action_confidence = v as f32
    }),
    ("intent.task_confidence", |a, v| {
        a.intent.task_confidence = v as f32
    }),
];

/// Every float of an intent, by name.
const INTENT_FIELDS: [(&str, SetIntent); 3] = [
    ("style_confidence", |i, v| i.style_confidence = v as f32),
    ("action_confidence", |i, v| i.action_confidence = v as f32),
    ("task_confidence", |i, v| i.task_confidence = v as f32),
];

fn good_frame(sequence: u64) -> SceneFrame {
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), std::f64::consts::PI, 8.0);
    let mut scene = Scene::new(sequence as f64 * 0.05, ego, paper::CAV_LEFT);
    scene.push(AgentState::moving(1, Vec2::new(-40.0, -5.0), 0.0, 8.0));
    let mut f = SceneFrame::from_scene(sequence, sequence * 50_000_000, &scene);
    f.ego.intent = known_intent();
    f.agents[0].intent = known_intent();
    f
}

#[test]
fn every_float_of_a_scene_frame_is_checked() {
    let mut params = concord_core::Params::default();
    params.trajectory.samples = 16;
    let morph = concord_ipc::core_service::Geometry::PaperIntersection.morphology();
    let mut core = DecisionCore::new(params, morph).unwrap();
    let mut seq = 1;
    for (name, set) in AGENT_FIELDS {
        for bad in BAD {
            for whose in ["ego", "agent"] {
                seq += 1;
                let mut f = good_frame(seq);
                set(
                    if whose == "ego" {
                        &mut f.ego
                    } else {
                        &mut f.agents[0]
                    },
                    bad,
                );
                let decided = f.to_scene().map(|s| core.step(&s, s.time_s, None));
                assert!(
                    !matches!(decided, Ok(Ok(_))),
                    "{whose}.{name} = {bad} was decided on"
                );
                seq += 1;
                let s = good_frame(seq).to_scene().unwrap();
                assert!(
                    core.step(&s, s.time_s, None).is_ok(),
                    "after {whose}.{name}"
                );
            }
        }
    }
}

fn good_advice() -> WireAdvice {
    wire_samples::advice(1, 1, concord_ipc::wire::WIRE_OBJECTS as u8)
}

#[test]
fn every_float_of_an_advice_is_checked() {
    let now = now_ns();
    assert!(good_advice().check(now).unwrap().is_some());
    let mut cases: Vec<(String, WireAdvice)> = Vec::new();
    for bad in BAD.into_iter().chain([-0.1, 1.01]) {
        cases.push((
            format!("confidence = {bad}"),
            WireAdvice {
                confidence: bad,
                ..good_advice()
            },
        ));
        for (name, set) in INTENT_FIELDS {
            let mut a = good_advice();
            set(&mut a.ego_intent, bad);
            cases.push((format!("ego_intent.{name} = {bad}"), a));
            for k in 0..concord_ipc::wire::WIRE_OBJECTS {
                let mut a = good_advice();
                set(&mut a.agent_intents[k].intent, bad);
                cases.push((format!("agent_intents[{k}].{name} = {bad}"), a));
            }
        }
    }
    for (what, a) in cases {
        assert!(a.check(now).is_err(), "{what} was taken");
    }
}

/// The value at dotted `path` (array elements as `key[i]`).
fn at<'a>(v: &'a mut toml::Value, path: &str) -> &'a mut toml::Value {
    path.split('.')
        .fold(v, |at, part| match part.split_once('[') {
            Some((key, index)) => {
                &mut at[key][index.trim_end_matches(']').parse::<usize>().unwrap()]
            }
            None => &mut at[part],
        })
}

/// Integer keys where every value of the type is allowed (`request_every = 0`: never).
const ANY_INTEGER: [&str; 2] = ["core.trajectory.seed", "service.request_every"];

#[test]
fn every_number_of_the_configuration_is_checked_and_the_error_names_it() {
    let defaults = toml::Value::try_from(RunConfig::default()).unwrap();
    let paths: Vec<_> = toml_paths::leaves(&defaults)
        .into_iter()
        .filter(|p| {
            at(&mut defaults.clone(), p).is_float() || at(&mut defaults.clone(), p).is_integer()
        })
        .collect();
    assert!(paths.len() > 100, "{} numbers", paths.len());
    for path in &paths {
        let key = path
            .trim_start_matches("core.")
            .split('[')
            .next()
            .unwrap()
            .to_string();
        let values = if at(&mut defaults.clone(), path).is_float() {
            BAD.iter()
                .map(|&b| toml::Value::Float(b))
                .collect::<Vec<_>>()
        } else if ANY_INTEGER.contains(&path.as_str()) {
            continue;
        } else {
            vec![
                toml::Value::Integer(0),
                toml::Value::Integer(i64::from(u32::MAX)),
            ]
        };
        for bad in values {
            let mut doc = defaults.clone();
            *at(&mut doc, path) = bad.clone();
            let text = toml::to_string(&doc).unwrap();
            let outcome = toml::from_str::<RunConfig>(&text)
                .map_err(|e| e.to_string())
                .and_then(|c| c.validate());
            match outcome {
                Ok(()) => panic!("{path} = {bad} passed"),
                Err(e) => assert!(
                    e.contains(&key) || e.contains(path.rsplit('.').next().unwrap()),
                    "{path} = {bad}: the error does not name it: {e}"
                ),
            }
        }
    }
}

/// Values that once passed `concord params --check` and broke the step.
#[test]
fn values_that_used_to_pass_and_break_the_step_are_refused() {
    type Break = fn(&mut RunConfig);
    let cases: [(&str, Break); 7] = [
        ("max_lateral_offset_m", |c| {
            c.core.trajectory.max_lateral_offset_m = 0.0
        }),
        ("j_max_norm", |c| c.core.trajectory.j_max_norm = 0.0),
        ("t_ref_s", |c| c.core.trajectory.t_ref_s = 0.0),
        ("reference_speed_mps", |c| {
            c.core.choice.reference_speed_mps = 0.0
        }),
        ("delta_ttc_threshold_s", |c| {
            c.core.opm.delta_ttc_threshold_s = 0.0
        }),
        ("intent_hold_s", |c| c.service.intent_hold_s = 1e11),
        ("prune_below", |c| c.core.advice.prune_below = 1.5),
    ];
    for (key, break_it) in cases {
        let mut c = RunConfig::default();
        break_it(&mut c);
        let e = c.validate().expect_err(key);
        assert!(e.contains(key), "{key}: {e}");
    }
}
