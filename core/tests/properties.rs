//! Property tests of the core's invariants.
mod common;

use common::*;
use concord_core::advice::{gate, Advice, AdviceVerdict, GateContext, RequestLog, MAX_PENDING};
use concord_core::choice::Maneuver;
use concord_core::opm::{delta_ttc, guarded_ttc};
use concord_core::params::{AdviceParams, OpmParams};
use concord_core::scene::{
    AgentState, ExplicitIntent, IntentAction, Rated, Style, Task, Turn, Vec2,
};
use concord_core::trajectory::{predict, Quartic, Quintic};
use concord_core::{DecisionSource, Params, Scene};
use concord_map::paper;
use proptest::prelude::*;

/// (lane, s along it, speed, longitudinal accel, intent confidence)
type AgentSpec = (u8, f64, f64, f64, f64);

fn agent_on_lane(core: &concord_core::DecisionCore, id: u32, spec: AgentSpec) -> AgentState {
    let (lane, s, v, a, conf) = spec;
    let lane = core.morphology().lane(lane);
    let (pos, tangent, _) = lane.to_cartesian(s, 0.0, 0);
    let mut agent = AgentState::moving(id, pos, tangent, v);
    agent.acc = Vec2::from_angle(tangent).scale(a);
    agent.intent = ExplicitIntent {
        style: Some(Rated {
            value: Style::Aggressive,
            confidence: conf,
        }),
        action: Some(Rated {
            value: IntentAction::Proceed,
            confidence: conf,
        }),
        task: Some(Rated {
            value: Task::Commute,
            confidence: conf,
        }),
    };
    agent
}

fn scene_from(core: &concord_core::DecisionCore, ego: AgentSpec, agents: &[AgentSpec]) -> Scene {
    let e = agent_on_lane(core, 0, (paper::CAV_LEFT, ego.1, ego.2, ego.3, ego.4));
    let mut scene = Scene::new(0.0, e, paper::CAV_LEFT);
    for (i, a) in agents.iter().enumerate() {
        scene.push(agent_on_lane(core, i as u32 + 1, *a));
    }
    scene
}

fn agent_spec() -> impl Strategy<Value = AgentSpec> {
    (
        0u8..8,
        0.0..80.0f64,
        0.0..15.0f64,
        -3.0..2.0f64,
        0.0..1.0f64,
    )
}

fn ego_spec() -> impl Strategy<Value = AgentSpec> {
    (
        Just(paper::CAV_LEFT),
        0.0..60.0f64,
        0.0..14.0f64,
        -2.0..1.5f64,
        0.0..1.0f64,
    )
}

/// Separating-axis overlap test of two oriented rectangles (centre, heading, length, width).
fn rectangles_overlap(a: (Vec2, f64), b: (Vec2, f64), length: f64, width: f64) -> bool {
    let axes = |h: f64| {
        [
            Vec2::from_angle(h),
            Vec2::from_angle(h + std::f64::consts::FRAC_PI_2),
        ]
    };
    let half = [length / 2.0, width / 2.0];
    let d = b.0.minus(a.0);
    for axis in axes(a.1).into_iter().chain(axes(b.1)) {
        let ra: f64 = axes(a.1)
            .iter()
            .zip(half)
            .map(|(u, h)| h * u.dot(axis).abs())
            .sum();
        let rb: f64 = axes(b.1)
            .iter()
            .zip(half)
            .map(|(u, h)| h * u.dot(axis).abs())
            .sum();
        if d.dot(axis).abs() > ra + rb {
            return false;
        }
    }
    true
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn probabilities_are_finite_and_sum_to_one(ego in ego_spec(), agents in prop::collection::vec(agent_spec(), 0..32)) {
        let mut core = paper_core(Params::default());
        let scene = scene_from(&core, ego, &agents);
        let d = core.step(&scene, 0.0, None).unwrap();
        for p in [d.p_logit, d.p_corrected] {
            prop_assert!(p.iter().all(|v| v.is_finite() && *v >= 0.0));
            prop_assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn polynomial_boundary_conditions_hold(s0 in -100.0..100.0f64, v0 in 0.0..30.0f64, a0 in -6.0..4.0f64, vt in 0.0..30.0f64, at in -3.0..3.0f64,
                                           l0 in -3.0..3.0f64, dl0 in -2.0..2.0f64, ddl0 in -2.0..2.0f64, lt in -3.0..3.0f64, dlt in -1.0..1.0f64, ddlt in -1.0..1.0f64,
                                           t in 0.5..8.0f64) {
        let q = Quartic::fit(s0, v0, a0, vt, at, t);
        let tol = 1e-9 * (1.0 + s0.abs());
        prop_assert!((q.pos(0.0) - s0).abs() < tol && (q.vel(0.0) - v0).abs() < 1e-9 && (q.acc(0.0) - a0).abs() < 1e-9);
        prop_assert!((q.vel(t) - vt).abs() < 1e-9 && (q.acc(t) - at).abs() < 1e-9);
        let l = Quintic::fit(l0, dl0, ddl0, lt, dlt, ddlt, t);
        prop_assert!((l.pos(0.0) - l0).abs() < 1e-9 && (l.vel(0.0) - dl0).abs() < 1e-9 && (l.acc(0.0) - ddl0).abs() < 1e-9);
        prop_assert!((l.pos(t) - lt).abs() < 1e-9 && (l.vel(t) - dlt).abs() < 1e-9 && (l.acc(t) - ddlt).abs() < 1e-9);
    }

    #[test]
    fn delta_ttc_is_finite_as_speed_goes_to_zero(d_i in -50.0..500.0f64, d_j in -50.0..500.0f64, exp_i in -300i32..1, exp_j in -300i32..1) {
        let p = OpmParams::default();
        let (v_i, v_j) = (10f64.powi(exp_i), 10f64.powi(exp_j));
        for (a, b) in [(v_i, v_j), (0.0, v_j), (v_i, 0.0), (0.0, 0.0)] {
            let dt = delta_ttc(d_i, a, d_j, b, &p);
            prop_assert!(dt.is_finite() && dt >= 0.0 && dt <= p.ttc_max_s);
            prop_assert!(guarded_ttc(d_i, a, &p).is_finite());
        }
    }

    #[test]
    fn non_finite_input_is_rejected_with_a_reason(ego in ego_spec(), agents in prop::collection::vec(agent_spec(), 1..8),
                                                  which in 0usize..8, field in 0usize..6, bad in prop::sample::select(vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300])) {
        let mut core = paper_core(Params::default());
        let good = scene_from(&core, ego, &agents);
        let mut scene = good;
        let target = if which == 0 || which > agents.len() { &mut scene.ego } else { &mut scene.agents[which - 1] };
        match field {
            0 => target.pos.x = bad,
            1 => target.vel.y = bad,
            2 => target.acc.x = bad,
            3 => target.heading = bad,
            4 => target.intent.task = Some(Rated { value: Task::Emergency, confidence: bad }),
            _ => scene.time_s = bad,
        }
        let err = core.step(&scene, 0.0, None);
        prop_assert!(err.is_err(), "accepted a frame with {bad} in field {field}");
        // The core is unharmed and decides on the next good frame.
        prop_assert!(core.step(&good, 0.0, None).is_ok());
    }

}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4096, failure_persistence: None, ..ProptestConfig::default() })]

    /// Each condition holds in most cases, so that every single one failing alone is common;
    /// ids are fresh and stale in equal shares.
    #[test]
    fn gate_accepts_exactly_when_every_condition_holds(
        latest in 1u64..500, stride in 1u64..4, fresh: bool, back in 0u64..1000,
        conf in prop_oneof![3 => 0.7..=1.0f64, 1 => -0.2..1.2f64],
        delay in prop_oneof![1 => 0.0..1.5f64, 1 => -1.0..3.0f64],
        maneuver in 0u8..5, route in 0u8..3, safe in prop::bool::weighted(0.85),
        nan in prop::bool::weighted(0.1), first_look: bool,
        wait in prop_oneof![6 => 0.0..3.0f64, 1 => -0.5..0.0f64],
        pn in prop_oneof![3 => 0.1..1.0f64, 1 => 0.0..0.3f64],
    ) {
        let p = AdviceParams::default();
        // Requests every `stride` cycles; the log keeps the newest MAX_PENDING of them.
        let window = MAX_PENDING as u64;
        let mut log = RequestLog::default();
        for c in 1..=latest { log.issue(c * stride, c as f64 * 0.05); }
        // Fresh and stale ids in equal shares; stale: never issued (0, later, or between two
        // requests) or pushed out of the log.
        let c = if fresh {
            latest - back % window.min(latest)
        } else {
            match back % 4 { 0 => 0, 1 => latest + 1 + back, 2 => latest.saturating_sub(window + back % 100), _ => latest - back % latest }
        };
        let id = if !fresh && back % 4 == 3 && stride > 1 { c * stride - 1 } else { c * stride };
        let fresh = fresh || (back % 4 == 3 && stride == 1 && latest - c < window);
        prop_assert_eq!(fresh, c >= 1 && c <= latest && latest - c < window && id % stride == 0);
        let route = [Turn::Straight, Turn::Left, Turn::Right][route as usize];
        let m = Maneuver::try_from(maneuver).unwrap();
        let mut pc = [0.2; 5];
        pc[m.index()] = pn;
        let issued = c as f64 * 0.05;
        let advice = Advice { request_id: id, maneuver: m, confidence: if nan { f64::NAN } else { conf }, published_at_s: issued + delay };
        let now = advice.published_at_s + wait;
        let g = GateContext { log: &log, route, now, first_look, p_corrected: &pc };
        let (applied, verdict) = gate(Some(&advice), &g, &p, |_| safe);
        let well_formed = !nan && (0.0..=1.0).contains(&conf) && wait >= 0.0 && delay >= 0.0;
        let expired = !first_look && now > issued + p.deadline_s;
        let expected = well_formed && fresh && !expired && conf >= p.confidence_min && delay <= p.deadline_s
            && m.consistent_with(route) && pn >= p.prune_below && safe;
        prop_assert_eq!(verdict == AdviceVerdict::Accepted, expected);
        prop_assert_eq!(applied, if expected { Some(m) } else { None });
        if fresh && !nan && (0.0..=1.0).contains(&conf) && (wait < 0.0 || delay < 0.0) {
            prop_assert_eq!(verdict, AdviceVerdict::Malformed, "a stamp in the future or before its request");
        }
    }

}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn planned_speeds_never_go_negative(ego in ego_spec(), agents in prop::collection::vec(agent_spec(), 0..8), steps in 1usize..6) {
        let mut core = paper_core(Params::default());
        let mut scene = scene_from(&core, ego, &agents);
        // A few steps, the ego following its plan, so stops and restarts are planned too.
        for k in 0..steps {
            let d = core.step(&scene, k as f64 * 0.1, None).unwrap();
            for pt in d.trajectory.points() {
                prop_assert!(pt.speed >= 0.0, "{} m/s at {} s ({:?})", pt.speed, pt.t, d.maneuver);
            }
            // Nor does the path: a polynomial speed below zero would move the car backwards.
            for w in d.trajectory.points().windows(2) {
                prop_assert!(w[1].s >= w[0].s - 1e-9, "backwards from {} to {} m at {} s ({:?})", w[0].s, w[1].s, w[1].t, d.maneuver);
            }
            let next = d.trajectory.sample(0.1).unwrap();
            let dir = Vec2::from_angle(next.heading);
            scene.time_s = (k + 1) as f64 * 0.1;
            scene.ego.pos = Vec2::new(next.x, next.y);
            scene.ego.vel = dir.scale(next.speed);
            scene.ego.acc = dir.scale(next.accel);
            scene.ego.heading = next.heading;
        }
    }

    #[test]
    fn chosen_trajectory_is_collision_free_when_a_feasible_candidate_exists(ego in ego_spec(), agents in prop::collection::vec(agent_spec(), 1..12)) {
        let params = Params::default();
        let mut core = paper_core(params);
        let scene = scene_from(&core, ego, &agents);
        let d = core.step(&scene, 0.0, None).unwrap();
        prop_assume!(d.plan.feasible > 0);
        prop_assert!(d.source != DecisionSource::MinimumRisk);
        let tp = params.trajectory;
        let lane = core.morphology().lane(scene.ego_lane);
        let ego_f = lane.project(scene.ego.pos);
        for (j, agent) in scene.agents().iter().enumerate() {
            // The planner leaves followers in its own lane to keep their distance.
            let f = lane.project(agent.pos);
            let along = Vec2::from_angle(f.tangent).dot(agent.direction()) > 0.5;
            if f.s < ego_f.s && f.l.abs() < lane.half_width && along { continue; }
            let process = core.processes()[j];
            let mut hint = 0;
            for pt in d.trajectory.points().iter().skip(1) {
                let other = predict(agent, &process, &core.forecasts()[j], core.morphology(), pt.t, tp.max_speed_mps, &mut hint);
                prop_assert!(!rectangles_overlap((Vec2::new(pt.x, pt.y), pt.heading), other, tp.vehicle_length_m, tp.vehicle_width_m),
                    "collision with agent {} at t = {:.1} s", j, pt.t);
            }
        }
    }
}

/// Found by the property above: a leader whose predicted path runs past the end of the lane's
/// polyline must still block the ego.
#[test]
fn a_leader_beyond_the_lane_end_still_blocks() {
    let mut core = paper_core(Params::default());
    let scene = scene_from(
        &core,
        (paper::CAV_LEFT, 59.8, 2.83, 1.33, 0.0),
        &[(paper::EAST_RIGHT, 61.7, 12.37, -2.86, 0.0)],
    );
    let d = core.step(&scene, 0.0, None).unwrap();
    assert!(
        d.plan.collision_rejects > 0,
        "the braking leader rejected no candidate"
    );
    let agent = scene.agents[0];
    let mut hint = 0;
    for pt in d.trajectory.points() {
        let (other, _) = predict(
            &agent,
            &core.processes()[0],
            &core.forecasts()[0],
            core.morphology(),
            pt.t,
            20.0,
            &mut hint,
        );
        assert!(
            other.minus(Vec2::new(pt.x, pt.y)).norm() > 4.8,
            "gap closed at t = {:.1} s",
            pt.t
        );
    }
}
