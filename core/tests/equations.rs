//! Each equation of the method against hand-computed values.
mod common;

use common::*;
use concord_core::advice::{gate, Advice, AdviceVerdict, GateContext, RequestLog};
use concord_core::choice::{argmax, correct, cosine, idm_accel, ChoiceHistory, Maneuver, Profile};
use concord_core::opm::{delta_ttc, guarded_ttc, MAX_SELECTED};
use concord_core::params::{AdviceParams, ChoiceParams, OpmParams, Params, TrajectoryParams};
use concord_core::saliency::{attend, softmax, Saliency, FEATURES};
use concord_core::scene::{AgentState, Morphology, ProcessState, Scene, Turn, Vec2, MAX_AGENTS};
use concord_core::trajectory::{
    travel, Forecast, FrenetState, Hit, Planner, Quartic, Quintic, Reject, Trajectory,
};
use concord_core::DecisionCore;
use concord_map::{paper, BuiltIn};

const EPS: f64 = 1e-9;

#[test]
fn eq2_paper_geometry_has_the_conflict_point_at_minus_five_minus_five() {
    let m = BuiltIn::PaperIntersection.morphology();
    let (s_cav, s_hdv) = m
        .conflict_between(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .expect("the routes cross");
    // CAV: 35 m straight, then a quarter circle of radius 10 m sampled as 16 chords.
    let chord = 2.0 * 10.0 * (std::f64::consts::FRAC_PI_2 / 32.0).sin();
    assert!(
        (s_cav - (35.0 + 16.0 * chord)).abs() < 1e-6,
        "s on CAV lane {s_cav}"
    );
    assert!((s_hdv - 35.0).abs() < 1e-6, "s on HDV lane {s_hdv}");
    // Lanes of one approach diverge, so they do not conflict.
    assert!(m
        .conflict_between(paper::CAV_LEFT, paper::WEST_STRAIGHT)
        .is_none());
}

#[test]
fn eq3_process_state_of_the_hdv() {
    let m = BuiltIn::PaperIntersection.morphology();
    let hdv = AgentState::moving(1, Vec2::new(-40.0, -5.0), 0.0, 8.0);
    let p = ProcessState::of(&hdv, &m, 1.0);
    assert_eq!(p.lane, Some(paper::HDV_STRAIGHT));
    assert!((p.dist_to_stop_m - 30.0).abs() < EPS);
    assert!((p.speed_mps - 8.0).abs() < EPS);
    assert!(p.theta_v.abs() < EPS && p.l_m.abs() < EPS);
    // A vehicle heading the wrong way matches no lane of its position.
    let wrong = AgentState::moving(2, Vec2::new(-40.0, -5.0), std::f64::consts::PI, 8.0);
    assert_eq!(ProcessState::of(&wrong, &m, 1.0).lane, None);
}

#[test]
fn frenet_projection_round_trips_on_the_turn() {
    let m = BuiltIn::PaperIntersection.morphology();
    let lane = m.lane(paper::CAV_LEFT);
    for s in [5.0, 36.0, 42.0, 49.0, 60.0] {
        for l in [-1.0, 0.0, 1.5] {
            let (p, _, _) = lane.to_cartesian(s, l, 0);
            let f = lane.project(p);
            // Exact on the centre line; off it, the polyline's piecewise frames differ by the
            // chord turn angle (1/10 rad on this arc) at vertices.
            let tol = 1e-6 + l.abs() * 0.1;
            assert!(
                (f.s - s).abs() < tol && (f.l - l).abs() < tol,
                "({s}, {l}) -> ({}, {})",
                f.s,
                f.l
            );
        }
    }
}

#[test]
fn eq4_delta_ttc_with_its_standstill_guard() {
    let p = OpmParams::default();
    // |30/10 − 20/5| = 1 s, and in either order; |30/10 − 10/4| = 0.5 s.
    assert!((delta_ttc(30.0, 10.0, 20.0, 5.0, &p) - 1.0).abs() < EPS);
    assert!((delta_ttc(20.0, 5.0, 30.0, 10.0, &p) - 1.0).abs() < EPS);
    assert!((delta_ttc(30.0, 10.0, 10.0, 4.0, &p) - 0.5).abs() < EPS);
    // v below the floor uses the floor: 10 m / 0.5 m/s = 20 s.
    assert!((guarded_ttc(10.0, 0.0, &p) - 20.0).abs() < EPS);
    // Capped at ttc_max, and never negative.
    assert_eq!(guarded_ttc(1000.0, 0.0, &p), p.ttc_max_s);
    assert_eq!(guarded_ttc(-5.0, 3.0, &p), 0.0);
}

#[test]
fn eq4_to_6_paper_scene_selects_the_hdv_as_a_risky_conflict() {
    let mut core = paper_core(Params::default());
    let d = core.step(&paper_scene(0.0, 8.0, 8.0), 0.0, None).unwrap();
    let t = core.triplet();
    assert_eq!(t.n_objects, 1);
    assert_eq!(t.n_conflicts, 1);
    let c = t.conflicts[0];
    let (s_cav, s_hdv) = core
        .morphology()
        .conflict_between(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .unwrap();
    assert!((c.ego_ttc_s - s_cav / 8.0).abs() < 1e-9);
    assert!((c.agent_ttc_s - s_hdv / 8.0).abs() < 1e-9);
    assert!((c.delta_ttc_s - (s_cav - s_hdv) / 8.0).abs() < 1e-9);
    assert!(c.is_risky(&core.params().opm));
    assert!(
        (t.objects[0].saliency - 1.0).abs() < EPS,
        "a single object takes all attention"
    );
    assert_eq!(d.cycle, 1);
}

#[test]
fn eq7_attention_matches_a_hand_computed_softmax() {
    let mut q = [[0.0; FEATURES]; 2];
    q[0][0] = 1.0;
    let mut key = [0.0; FEATURES];
    key[0] = 2.0;
    let mut out = Saliency::default();
    attend(&q, &key, &mut out);
    let z = 2.0 / (FEATURES as f64).sqrt();
    let a0 = z.exp() / (z.exp() + 1.0);
    assert!((out.weights[0] - a0).abs() < EPS);
    assert!((out.weights[1] - (1.0 - a0)).abs() < EPS);
    assert!(
        (out.context[0] - a0).abs() < EPS,
        "V = Q: the context is Σ αᵢ qᵢ"
    );
}

#[test]
fn eq9_and_11_utility_and_logit() {
    let mut p = [0.0; 2];
    softmax(&[0.0, 2f64.ln()], &mut p);
    assert!((p[0] - 1.0 / 3.0).abs() < EPS && (p[1] - 2.0 / 3.0).abs() < EPS);
    // Large utilities do not overflow.
    softmax(&[1000.0, 1000.0], &mut p);
    assert!((p[0] - 0.5).abs() < EPS);
}

#[test]
fn eq12_and_14_corrected_utility() {
    let p = ChoiceParams {
        gamma: 0.5,
        lambda: 0.25,
        ..ChoiceParams::default()
    };
    let v = correct(
        &[1.0; 5],
        &[1.0, 0.0, 0.5, 0.0, 0.0],
        Some(Maneuver::Accelerate),
        &p,
    );
    assert_eq!(v, [1.5, 0.75, 1.0, 0.75, 0.75]);
    // No previous maneuver: no switch penalty.
    assert_eq!(correct(&[0.0; 5], &[0.0; 5], None, &p), [0.0; 5]);
    assert_eq!(
        argmax(&[0.1, 0.3, 0.3, 0.2, 0.1]),
        Maneuver::Decelerate,
        "ties go to the lower index"
    );
    assert_eq!(
        argmax(&[f64::NAN, 0.1, 0.3, f64::NAN, 0.2]),
        Maneuver::KeepSpeed,
        "a NaN is never the largest"
    );
}

#[test]
fn eq13_history_consistency_is_the_max_cosine_over_matching_records() {
    let mut h = ChoiceHistory::default();
    h.record(0.0, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0], Maneuver::Accelerate);
    h.record(0.1, [0.0, 1.0, 0.0, 0.0, 0.0, 0.0], Maneuver::Accelerate);
    h.record(0.2, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0], Maneuver::Decelerate);
    // < 0.1 s later: not stored (its state is not orthogonal to the query, so it would show).
    h.record(0.25, [1.0, 0.0, 0.0, 1.0, 0.0, 0.0], Maneuver::TurnLeft);
    let d = h.d_prev(&[3.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
    assert!((d[0] - 3.0 / 10f64.sqrt()).abs() < EPS);
    assert_eq!(d[1], 0.0);
    assert_eq!(
        d[3], 0.0,
        "the 0.25 s record was within 0.1 s of the last one"
    );
    assert_eq!(
        h.previous,
        Some(Maneuver::TurnLeft),
        "i_prev is the latest executed maneuver"
    );
    assert!(
        (cosine(
            &[1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            &[-1.0, -1.0, 0.0, 0.0, 0.0, 0.0]
        ) + 1.0)
            .abs()
            < EPS
    );
}

#[test]
fn idm_penalty_input_free_road_and_close_leader() {
    let p = ChoiceParams::default();
    // From rest with a far leader: about the maximum acceleration.
    assert!((idm_accel(0.0, 1e6, 0.0, &p) - p.idm_max_accel_mps2).abs() < 1e-6);
    // Fast and closing on a near leader: strong braking.
    assert!(idm_accel(10.0, 5.0, 5.0, &p) < -5.0);
    // At the desired speed on a free road: none; above it, braking.
    assert!(idm_accel(p.desired_speed_mps, f64::INFINITY, 0.0, &p).abs() < 1e-3);
    assert!(idm_accel(1.2 * p.desired_speed_mps, f64::INFINITY, 0.0, &p) < -1.0);
}

#[test]
fn a_proceeding_road_user_enters_when_accelerating_and_leaves_at_its_slowest() {
    let ip = concord_core::params::InteractionParams::default();
    // From 2 m/s at `proceed_accel_mps2` (1.5) towards 14 m/s: 10 m take
    // (−2 + √(4 + 2·1.5·10)) / 1.5 s; it leaves 20 m away at the latest at 2 m/s, after 10 s.
    let c = concord_core::opm::ConflictPair {
        agent_speed_mps: 2.0,
        agent_pass_m: [10.0, 20.0],
        ..Default::default()
    };
    let (t_in, t_out) = concord_core::choice::proceeding_interval(&c, &ip);
    assert!((t_in - (34f64.sqrt() - 2.0) / 1.5).abs() < EPS, "{t_in}");
    assert!((t_out - 10.0).abs() < EPS, "{t_out}");
    // Already at the top speed, 100 m ahead: 100 / 14 s.
    let fast = concord_core::opm::ConflictPair {
        agent_speed_mps: 14.0,
        agent_pass_m: [100.0, 110.0],
        ..c
    };
    let (t_in, _) = concord_core::choice::proceeding_interval(&fast, &ip);
    assert!((t_in - 100.0 / 14.0).abs() < EPS, "{t_in}");
    // Past the ramp: 8 s to reach 14 m/s over 64 m, then 36 m at 14 m/s.
    let long = concord_core::opm::ConflictPair {
        agent_pass_m: [100.0, 110.0],
        ..c
    };
    let (t_in, _) = concord_core::choice::proceeding_interval(&long, &ip);
    assert!((t_in - (8.0 + 36.0 / 14.0)).abs() < EPS, "{t_in}");
}

#[test]
fn profile_arrival_times() {
    let keep = Profile {
        accel: 0.0,
        target_speed: 10.0,
        duration: 3.0,
        stop_m: f64::INFINITY,
    };
    assert!((keep.arrival_time(10.0, 50.0) - 5.0).abs() < EPS);
    // Accelerate 2 m/s² from 0 to 4 m/s (2 s, 4 m), then 4 m/s: 12 m takes 2 + 8/4 = 4 s.
    let acc = Profile {
        accel: 2.0,
        target_speed: 4.0,
        duration: 3.0,
        stop_m: f64::INFINITY,
    };
    assert!((acc.arrival_time(0.0, 12.0) - 4.0).abs() < EPS);
    // Braking 2 m/s² from 4 m/s stops after 4 m: 5 m is never reached.
    let stop = Profile {
        accel: -2.0,
        target_speed: 0.0,
        duration: 3.0,
        stop_m: 4.0,
    };
    assert!(stop.arrival_time(4.0, 5.0).is_infinite());
    // Up to the stop point it is reached: exactly at 4 m after 2 s.
    assert!((stop.arrival_time(4.0, 4.0) - 2.0).abs() < 1e-6);
    // From 2 m/s at 1 m/s² to 6 m/s (4 s, 16 m): 10 m while accelerating, 2t + t²/2 = 10, and
    // 26 m after 4 s + 10 m at 6 m/s.
    let rolling = Profile {
        accel: 1.0,
        target_speed: 6.0,
        duration: 3.0,
        stop_m: f64::INFINITY,
    };
    assert!((rolling.arrival_time(2.0, 10.0) - (24f64.sqrt() - 2.0)).abs() < EPS);
    assert!((rolling.arrival_time(2.0, 26.0) - (4.0 + 10.0 / 6.0)).abs() < EPS);
    // Standing and not accelerating, it never arrives.
    assert!(keep.arrival_time(0.0, 5.0).is_infinite());
}

#[test]
fn maneuver_names_are_distinct_snake_case() {
    let names: std::collections::BTreeSet<_> = Maneuver::ALL.iter().map(|m| m.name()).collect();
    assert_eq!(names.len(), Maneuver::ALL.len());
    for (i, m) in Maneuver::ALL.iter().enumerate() {
        assert_eq!(m.index(), i);
        assert!(
            m.name().chars().all(|c| c.is_ascii_lowercase() || c == '_'),
            "{m:?}"
        );
    }
    assert_eq!(Maneuver::Accelerate.name(), "accelerate");
}

#[test]
fn eq16_gate_checks_in_order() {
    let p = AdviceParams::default();
    let mut log = RequestLog::default();
    for cycle in 1..=300 {
        log.issue(cycle, cycle as f64 * 0.05);
    }
    let advice = |id, conf, at| Advice {
        request_id: id,
        maneuver: Maneuver::Accelerate,
        confidence: conf,
        published_at_s: at,
    };
    // P_n of accelerate 0.2, of decelerate 0.05: only decelerate is implausible.
    let pc = [0.2, 0.05, 0.25, 0.25, 0.25];
    let judge = |a: Option<&Advice>, now, first_look, safe: bool| {
        let g = GateContext {
            log: &log,
            route: Turn::Left,
            now,
            first_look,
            p_corrected: &pc,
        };
        gate(a, &g, &p, |_| safe)
    };
    let verdict = |a: &Advice, now| judge(Some(a), now, true, true).1;
    assert_eq!(judge(None, 2.5, true, true).1, AdviceVerdict::NoAdvice);
    assert_eq!(
        judge(Some(&advice(45, 0.9, 2.5)), 2.5, true, true),
        (Some(Maneuver::Accelerate), AdviceVerdict::Accepted)
    );
    let unknown = AdviceVerdict::UnknownRequest;
    assert_eq!(
        verdict(&advice(44, 0.9, 2.5), 2.5),
        unknown,
        "pushed out of the log by 256 newer requests"
    );
    assert_eq!(
        verdict(&advice(301, 0.9, 2.5), 2.5),
        unknown,
        "not issued yet"
    );
    assert_eq!(
        verdict(&advice(45, 0.69, 2.5), 2.5),
        AdviceVerdict::LowConfidence
    );
    // Request 45 was issued at 2.25 s; its deadline is 3.75 s. The publish stamp decides,
    // not the cycle that reads it.
    assert_eq!(
        verdict(&advice(45, 0.9, 3.74), 3.9),
        AdviceVerdict::Accepted
    );
    assert_eq!(verdict(&advice(45, 0.9, 3.76), 3.9), AdviceVerdict::Late);
    let malformed = AdviceVerdict::Malformed;
    assert_eq!(verdict(&advice(45, f64::NAN, 2.5), 2.5), malformed);
    assert_eq!(
        verdict(&advice(45, 1.5, 2.5), 2.5),
        malformed,
        "confidence > 1"
    );
    assert_eq!(verdict(&advice(45, 0.9, f64::NAN), 2.5), malformed);
    assert_eq!(
        verdict(&advice(45, 0.9, 2.6), 2.5),
        malformed,
        "stamped in the future"
    );
    assert_eq!(
        verdict(&advice(45, 0.9, 2.2), 2.5),
        malformed,
        "before its request"
    );
    let right = Advice {
        maneuver: Maneuver::TurnRight,
        ..advice(45, 0.9, 2.5)
    };
    assert_eq!(verdict(&right, 2.5), AdviceVerdict::NavigationInconsistent);
    let implausible = Advice {
        maneuver: Maneuver::Decelerate,
        ..advice(45, 0.9, 2.5)
    };
    assert_eq!(verdict(&implausible, 2.5), AdviceVerdict::Implausible);
    assert_eq!(
        judge(Some(&advice(45, 0.9, 2.5)), 2.5, true, false),
        (None, AdviceVerdict::Unsafe)
    );
    // Each bound is inclusive: confidence exactly 0.7, published exactly at the issue or the
    // deadline, judged exactly at the deadline, P_n exactly `prune_below`.
    let issued = 45.0 * 0.05;
    let deadline = issued + p.deadline_s;
    let accepted = AdviceVerdict::Accepted;
    assert_eq!(verdict(&advice(45, p.confidence_min, 2.5), 2.5), accepted);
    assert_eq!(verdict(&advice(45, 0.9, issued), 2.5), accepted);
    assert_eq!(verdict(&advice(45, 0.9, deadline), 3.9), accepted);
    assert_eq!(
        verdict(&advice(45, 0.9, 3.0), 3.0),
        accepted,
        "published at now"
    );
    assert_eq!(
        judge(Some(&advice(45, 0.9, 3.0)), deadline, false, true).1,
        accepted,
        "judged again exactly at the deadline"
    );
    let at_the_bound = Advice {
        maneuver: Maneuver::KeepSpeed,
        ..advice(45, 0.9, 2.5)
    };
    let pc_bound = [0.2, 0.05, p.prune_below, 0.25, 0.25];
    let g = GateContext {
        log: &log,
        route: Turn::Left,
        now: 2.5,
        first_look: true,
        p_corrected: &pc_bound,
    };
    assert_eq!(gate(Some(&at_the_bound), &g, &p, |_| true).1, accepted);
    // Accepted advice applies until its request's deadline (3.75 s), then expires; the first
    // cycle to see it judges it even after the deadline.
    let a = advice(45, 0.9, 3.7);
    assert_eq!(
        judge(Some(&a), 3.74, false, true).1,
        AdviceVerdict::Accepted
    );
    assert_eq!(judge(Some(&a), 3.76, false, true).1, AdviceVerdict::Expired);
    assert_eq!(judge(Some(&a), 3.76, true, true).1, AdviceVerdict::Accepted);
}

#[test]
fn eq17_and_19_20_quartic_hand_solution() {
    // s0 = v0 = a0 = 0, v_T = 1, a_T = 0, T = 1: s(t) = t³ − t⁴/2.
    let q = Quartic::fit(0.0, 0.0, 0.0, 1.0, 0.0, 1.0);
    assert!((q.c[3] - 1.0).abs() < EPS && (q.c[4] + 0.5).abs() < EPS);
}

#[test]
fn eq18_and_21_22_quintic_hand_solution() {
    // Rest to rest over a unit offset in unit time: 10t³ − 15t⁴ + 6t⁵.
    let q = Quintic::fit(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0);
    assert!(
        (q.c[3] - 10.0).abs() < EPS && (q.c[4] + 15.0).abs() < EPS && (q.c[5] - 6.0).abs() < EPS
    );
}

#[test]
fn eq23_samples_are_bounded_and_seeded() {
    let mut core = paper_core(Params::default());
    let scene = paper_scene(0.0, 8.0, 8.0);
    let a = core.step(&scene, 0.0, None).unwrap();
    let mut again = paper_core(Params::default());
    let b = again.step(&scene, 0.0, None).unwrap();
    assert_eq!(a, b, "same seed and inputs: the same decision");
    let p = core.params().trajectory;
    for pt in a.trajectory.points() {
        assert!(
            pt.speed <= p.max_speed_mps + 1e-6
                && pt.accel <= p.max_accel_mps2 + 1e-6
                && pt.accel >= -p.max_brake_mps2 - 1e-6
        );
        assert!(pt.l.abs() <= p.max_lateral_offset_m + 1e-6);
    }
}

#[test]
fn table2_score_of_a_constant_speed_candidate() {
    // A lone ego at 10 m/s on the straight westbound lane: holding speed has no jerk, so
    // S = c_e · (goal / v) / T_ref with the goal the reference distance (no conflict).
    let p = Params::default();
    let mut core =
        concord_core::DecisionCore::new(p, BuiltIn::PaperIntersection.morphology()).unwrap();
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), std::f64::consts::PI, 10.0);
    let scene = concord_core::Scene::new(0.0, ego, paper::WEST_STRAIGHT);
    core.step(&scene, 0.0, None).unwrap();
    let c = core
        .planner()
        .evaluate(3.0, 10.0, 0.0, &p.trajectory)
        .expect("feasible");
    let goal = p.choice.reference_speed_mps * p.trajectory.t_ref_s;
    let expected = p.trajectory.c_efficiency * (goal / 10.0) / p.trajectory.t_ref_s;
    assert!(
        (c.score - expected).abs() < 1e-9,
        "{} vs {expected}",
        c.score
    );
}

#[test]
fn a_plan_started_with_lateral_velocity_stays_within_the_lateral_bound() {
    // The ego's course is 0.15 rad off its lane (1.5 m/s sideways at 10 m/s): a quintic from
    // that state overshoots any terminal offset unless its whole path is checked.
    let p = Params::default();
    let mut core =
        concord_core::DecisionCore::new(p, BuiltIn::PaperIntersection.morphology()).unwrap();
    let course = std::f64::consts::PI - 0.15;
    let mut ego = AgentState::moving(0, Vec2::new(40.0, 5.0), course, 10.0);
    ego.heading = std::f64::consts::PI;
    let scene = concord_core::Scene::new(0.0, ego, paper::WEST_STRAIGHT);
    let d = core.step(&scene, 0.0, None).unwrap();
    assert_eq!(d.source, concord_core::DecisionSource::Logit, "{d:?}");
    assert!(core.planner().start.dl.abs() > 1.0);
    for pt in d.trajectory.points() {
        assert!(
            pt.l.abs() <= p.trajectory.max_lateral_offset_m + 1e-6,
            "l = {} at t = {}",
            pt.l,
            pt.t
        );
    }
}

/// The paper's CAV `cav_before` m before its crossing with the HDV's lane at `cav_speed`
/// m/s, and the HDV `hdv_before` m before the same point at 10 m/s.
fn crossing_scene(
    m: &Morphology,
    cav_before: f64,
    cav_speed: f64,
    hdv_before: f64,
) -> concord_core::Scene {
    crossing_scene_on(m, paper::HDV_STRAIGHT, cav_before, cav_speed, hdv_before)
}

/// [`crossing_scene`] with the HDV on lane `hdv_lane`, measured from its crossing with the
/// CAV's lane.
fn crossing_scene_on(
    m: &Morphology,
    hdv_lane: u8,
    cav_before: f64,
    cav_speed: f64,
    hdv_before: f64,
) -> concord_core::Scene {
    let (s_cav, s_hdv) = m.conflict_between(paper::CAV_LEFT, hdv_lane).unwrap();
    let (cav, h_cav, _) = m.lane(paper::CAV_LEFT).pose_at(s_cav - cav_before, 0);
    let (hdv, h_hdv, _) = m.lane(hdv_lane).pose_at(s_hdv - hdv_before, 0);
    let mut scene = concord_core::Scene::new(
        0.0,
        AgentState::moving(0, cav, h_cav, cav_speed),
        paper::CAV_LEFT,
    );
    scene.push(AgentState::moving(1, hdv, h_hdv, 10.0));
    scene
}

/// The CAV 45 m before the crossing at 10 m/s (able to stop comfortably before the junction)
/// and the HDV `hdv_before` m before it: the planner sampled for "decelerate" after one step,
/// and its best candidate.
fn decelerate_towards_the_crossing(
    hdv_before: f64,
) -> (
    concord_core::trajectory::Planner,
    concord_core::trajectory::Candidate,
) {
    let p = Params::default();
    let mut core = paper_core(p);
    let scene = crossing_scene(core.morphology(), 45.0, 10.0, hdv_before);
    core.step(&scene, 0.0, None).unwrap();
    let profile = core.choice().profiles[Maneuver::Decelerate.index()];
    assert!(profile.yields(), "{profile:?}");
    let mut planner = *core.planner();
    planner.sample(&profile, p.trajectory.samples, 1, &p.trajectory);
    let mut stats = concord_core::trajectory::PlanStats::default();
    let best = planner
        .run(p.trajectory.samples, &p.trajectory, &mut stats)
        .expect("a feasible decelerate candidate");
    (planner, best)
}

/// Arc length and speed of candidate `c` at time `t`, holding its terminal speed after its
/// duration.
fn along(c: &concord_core::trajectory::Candidate, t: f64) -> (f64, f64) {
    if t <= c.duration {
        (c.s.pos(t), c.s.vel(t))
    } else {
        let v = c.s.vel(c.duration);
        (c.s.pos(c.duration) + v * (t - c.duration), v)
    }
}

#[test]
fn decelerating_behind_a_car_that_will_have_passed_rolls_on_instead_of_stopping() {
    // The merge: the CAV 40 m before the join at 10 m/s, the main-lane car 5 m before it: it
    // is through long before the CAV arrives, so "decelerate" slows and merges behind it.
    use concord_map::merge;
    let p = Params::default();
    let m = BuiltIn::Merge.morphology();
    let (s_main, s_ramp) = m.conflict_between(merge::MAIN, merge::RAMP).unwrap();
    let (cav, h_cav, _) = m.lane(merge::RAMP).pose_at(s_ramp - 40.0, 0);
    let (hdv, h_hdv, _) = m.lane(merge::MAIN).pose_at(s_main - 5.0, 0);
    let mut scene =
        concord_core::Scene::new(0.0, AgentState::moving(0, cav, h_cav, 10.0), merge::RAMP);
    scene.push(AgentState::moving(1, hdv, h_hdv, 10.0));
    let mut core = DecisionCore::new(p, m).unwrap();
    core.step(&scene, 0.0, None).unwrap();
    let profile = core.choice().profiles[Maneuver::Decelerate.index()];
    assert!(profile.yields(), "{profile:?}");
    let mut planner = *core.planner();
    planner.sample(&profile, p.trajectory.samples, 1, &p.trajectory);
    let mut stats = concord_core::trajectory::PlanStats::default();
    let best = planner
        .run(p.trajectory.samples, &p.trajectory, &mut stats)
        .expect("a feasible decelerate candidate");
    let v_end = best.s.vel(best.duration);
    assert!(v_end > 1.0, "the best decelerate candidate stops: {best:?}");
}

#[test]
fn a_rolling_decelerate_candidate_can_always_still_stop_before_the_zone() {
    // The HDV arrives at the crossing when the CAV would at its speed: the CAV must not commit.
    // Replanned every cycle, it must still be able to stop at the yield check time.
    let p = Params::default().trajectory;
    let (planner, best) = decelerate_towards_the_crossing(30.0);
    let start = planner.start;
    let stop_limit = start.s + planner.yield_distance + 1e-6;
    let stopping = |v: f64| v * v / (2.0 * p.max_brake_mps2 / 1.5);
    let (s_h, v_h) = along(&best, p.yield_check_s);
    assert!(
        s_h + stopping(v_h) <= stop_limit,
        "commits to the crossing: s {s_h:.1}, v {v_h:.1}, stop at {stop_limit:.1}"
    );
    // Not only the best: no feasible yielding candidate over a grid of terminal states that
    // has not cleared the zone at the horizon is past stopping at the check time; and none
    // that can still stop is refused for committing.
    let mut feasible = 0;
    let mut can_stop = 0;
    for i in 0..=20 {
        for j in 0..=24 {
            let (t_end, v_end) = (1.0 + 0.25 * i as f64, 0.5 * j as f64);
            let plan = concord_core::trajectory::Candidate {
                s: Quartic::fit(start.s, start.ds, start.dds, v_end, 0.0, t_end),
                duration: t_end,
                ..Default::default()
            };
            let (s_p, v_p) = along(&plan, p.yield_check_s);
            if v_end > 0.0
                && along(&plan, p.horizon_s).0 < start.s + planner.clear_distance
                && s_p + stopping(v_p) <= stop_limit - 0.05
            {
                assert_ne!(
                    planner.evaluate(t_end, v_end, 0.0, &p),
                    Err(Reject::Commits),
                    "T {t_end}, v_T {v_end}: stops at {:.1}, before {stop_limit:.1}",
                    s_p + stopping(v_p)
                );
                can_stop += 1;
            }
            let Ok(c) = planner.evaluate(t_end, v_end, 0.0, &p) else {
                continue;
            };
            feasible += 1;
            if along(&c, p.horizon_s).0 >= start.s + planner.clear_distance {
                continue;
            }
            let (s_c, v_c) = along(&c, p.yield_check_s);
            let stop_at = if v_end > 0.0 {
                s_c + stopping(v_c)
            } else {
                c.s.pos(t_end)
            };
            assert!(
                stop_at <= stop_limit,
                "T {t_end}, v_T {v_end}: stops at {stop_at:.1}, past {stop_limit:.1}"
            );
        }
    }
    assert!(feasible > 0, "no feasible candidate on the grid");
    assert!(
        can_stop > 0,
        "no rolling candidate that can stop on the grid"
    );
}

#[test]
fn inside_the_junction_the_fallback_drives_on_rather_than_brake_into_contact() {
    // The CAV inside the junction, just before its crossing with the HDV's lane, and the HDV
    // (which does not give way to a car standing in its path) arriving at every distance:
    // when braking is predicted to be hit (the footprints overlapping), the fallback drives
    // on whenever a drive-on
    // candidate is within the limits, also where its contact would come sooner; and it never
    // stands inside a conflict zone when a plan that clears it free of contact exists. Also
    // at its first crossing (the northbound lane, where its turn begins), just past its stop
    // line, where it has passed no zone yet.
    fallback_inside_the_junction(paper::HDV_STRAIGHT, &[0.0, 2.0, 4.0, 6.0]);
    fallback_inside_the_junction(paper::NORTH_STRAIGHT, &[0.0, 1.0, 2.0, 3.0]);
}

/// The body of [`inside_the_junction_the_fallback_drives_on_rather_than_brake_into_contact`]
/// for an HDV on `hdv_lane` and the CAV `cav_befores` m before that crossing.
fn fallback_inside_the_junction(hdv_lane: u8, cav_befores: &[f64]) {
    let p = Params::default();
    let n = p.trajectory.later_samples();
    let (mut hit, mut sooner) = (0, 0);
    for &cav_before in cav_befores {
        for hdv_before in (2..30).map(|d| d as f64) {
            let mut core = paper_core(p);
            let scene = crossing_scene_on(core.morphology(), hdv_lane, cav_before, 6.0, hdv_before);
            let d = core.step(&scene, 0.0, None).unwrap();
            if d.source != concord_core::DecisionSource::MinimumRisk {
                continue;
            }
            let lane = *core.morphology().lane(paper::CAV_LEFT);
            let planner = *core.planner();
            let drive_on = [Maneuver::KeepSpeed, Maneuver::Accelerate].map(|m| {
                let mut probe = planner;
                let prof = core.choice().profiles[m.index()];
                probe.sample(&prof, n, d.cycle, &p.trajectory);
                probe.latest_contact(n, &p.trajectory).map(|(_, t)| t)
            });
            if d.trajectory
                .points()
                .last()
                .is_some_and(|q| planner.in_zone(q.s))
            {
                assert!(
                    !drive_on.iter().flatten().any(|t| t.is_infinite()),
                    "CAV {cav_before} m, HDV {hdv_before} m: stands in a zone though a plan clears it"
                );
            }
            let mut braking = concord_core::Trajectory::default();
            planner.minimum_risk(planner.yield_distance, &lane, &p.trajectory, &mut braking);
            let (Some(t_brake), Some(t_drive)) = (
                planner.first_collision(&braking),
                drive_on.into_iter().flatten().reduce(f64::max),
            ) else {
                continue;
            };
            hit += 1;
            sooner += usize::from(t_drive < t_brake);
            assert_ne!(
                d.maneuver,
                Maneuver::Decelerate,
                "CAV {cav_before} m, HDV {hdv_before} m: braked into contact at {t_brake} s"
            );
        }
    }
    assert!(
        hit > 0 && sooner > 0,
        "lane {hdv_lane}: {hit} hit, {sooner} sooner"
    );
}

#[test]
fn inside_the_junction_the_fallback_does_not_drive_on_into_a_car_standing_ahead() {
    // As above, with a car standing in the CAV's lane 10 m ahead of it (5 m between bumpers):
    // where driving on would run into it more than three planning steps before the HDV would
    // hit the braking CAV, the fallback brakes.
    let p = Params::default();
    let t = p.trajectory;
    let mut refused = 0;
    for cav_before in [0.0, 2.0, 4.0, 6.0] {
        for hdv_before in (2..30).map(|d| d as f64) {
            let mut core = paper_core(p);
            let mut scene = crossing_scene(core.morphology(), cav_before, 6.0, hdv_before);
            let lane = *core.morphology().lane(paper::CAV_LEFT);
            let s_cav = lane.project(scene.ego.pos).s;
            let (pos, h, _) = lane.pose_at(s_cav + 10.0, 0);
            scene.push(AgentState::moving(2, pos, h, 0.0));
            let d = core.step(&scene, 0.0, None).unwrap();
            if d.source != concord_core::DecisionSource::MinimumRisk {
                continue;
            }
            let planner = *core.planner();
            let mut braking = concord_core::Trajectory::default();
            // Where the core's fallback brakes to: before the zone or behind its leader.
            let room = planner.yield_distance.min(core.leader_stop_distance());
            planner.minimum_risk(room, &lane, &t, &mut braking);
            let Some(t_brake) = planner.first_collision(&braking) else {
                continue;
            };
            let taken = planner.first_collision(&d.trajectory);
            assert!(
                taken.is_none_or(|hit| hit + 3.0 * t.dt_s >= t_brake),
                "CAV {cav_before} m, HDV {hdv_before} m: {:?} collides at {taken:?} s, braking at {t_brake} s",
                d.maneuver
            );
            refused += usize::from(d.maneuver == Maneuver::Decelerate);
        }
    }
    assert!(
        refused > 0,
        "no scene where braking was hit and driving on refused"
    );
}

#[test]
fn the_minimum_risk_stop_brakes_just_enough_within_its_bounds() {
    // From 10 m/s: stopping within 20 m needs 2.5 m/s², so it brakes at the 5 m/s² floor;
    // within 8 m, 6.25 m/s²; within 2 m (or with nothing to stop for), at the 8 m/s²
    // emergency rate.
    let p = Params::default().trajectory;
    let core = lone_ego(10.0);
    let lane = *core.morphology().lane(paper::WEST_STRAIGHT);
    for (room, decel) in [(20.0, 5.0), (8.0, 6.25), (2.0, 8.0), (f64::INFINITY, 8.0)] {
        let mut out = Trajectory::default();
        core.planner().minimum_risk(room, &lane, &p, &mut out);
        let a = out.points()[0].accel;
        assert!((a + decel).abs() < 1e-9, "stop within {room} m: {a} m/s²");
    }
}

#[test]
fn stale_scene_fallback_brakes_from_where_the_last_plan_puts_the_ego() {
    let mut core = paper_core(Params::default());
    assert!(
        core.stale_fallback(1.0).is_none(),
        "nothing to continue before the first decision"
    );
    let d = core.step(&paper_scene(0.0, 8.0, 8.0), 0.0, None).unwrap();
    let f = core
        .stale_fallback(0.5)
        .expect("a fallback after a decision");
    assert_eq!(f.source, concord_core::DecisionSource::MinimumRisk);
    assert_eq!(f.fallback, concord_core::FallbackReason::StaleScene);
    let start = d.trajectory.sample(0.5).unwrap();
    assert!(
        (f.trajectory.points[0].s - start.s).abs() < 1e-9,
        "starts where the last plan had the ego"
    );
    let speeds: Vec<f64> = f.trajectory.points().iter().map(|p| p.speed).collect();
    assert!(
        speeds.windows(2).all(|w| w[1] <= w[0] + 1e-12),
        "speed never rises"
    );
    assert!(
        speeds.last().unwrap().abs() < 1e-9,
        "it comes to a stop within the horizon"
    );
}

#[test]
fn merge_geometry_conflicts_where_the_ramp_joins() {
    use concord_map::merge;
    let m = BuiltIn::Merge.morphology();
    let (s_main, s_ramp) = m
        .conflict_between(merge::MAIN, merge::RAMP)
        .expect("the ramp joins the main lane");
    assert!(
        (s_main - 150.0).abs() < 1e-6,
        "joins at the origin, 150 m along the main lane"
    );
    let taper = (60f64.powi(2) + 12f64.powi(2)).sqrt();
    assert!((s_ramp - (90.0 + taper)).abs() < 1e-6);
    // A ramp ego and a main-lane car arriving together form a risky conflict.
    let mut core = concord_core::DecisionCore::new(Params::default(), m).unwrap();
    let (pos, tangent, _) = m.lane(merge::RAMP).to_cartesian(s_ramp - 40.0, 0.0, 0);
    let mut scene =
        concord_core::Scene::new(0.0, AgentState::moving(0, pos, tangent, 10.0), merge::RAMP);
    scene.push(AgentState::moving(1, Vec2::new(-40.0, 0.0), 0.0, 10.0));
    core.step(&scene, 0.0, None).unwrap();
    assert_eq!(core.triplet().n_conflicts, 1);
    assert!(core.triplet().conflicts[0].delta_ttc_s < 1e-6);
}

/// A lone ego at `speed` on the paper's straight westbound lane, after one step.
fn lone_ego(speed: f64) -> Box<DecisionCore> {
    let mut core = paper_core(Params::default());
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), std::f64::consts::PI, speed);
    let scene = concord_core::Scene::new(0.0, ego, paper::WEST_STRAIGHT);
    core.step(&scene, 0.0, None).unwrap();
    core
}

#[test]
fn table2_the_jerk_limit_rejects_a_candidate_only_it_forbids() {
    // From 10 m/s, +1.8 m/s in 1 s: the quartic peaks at 1.5·1.8 = 2.7 m/s² (within the
    // 3 m/s² limit) with 6·1.8 = 10.8 m/s³ of jerk at its ends (limit 10); over 1.5 s the
    // jerk is 4.8 m/s³.
    let p = Params::default().trajectory;
    let core = lone_ego(10.0);
    let planner = core.planner();
    assert_eq!(
        planner.evaluate(1.0, 11.8, 0.0, &p),
        Err(concord_core::trajectory::Reject::Limits)
    );
    assert!(planner.evaluate(1.5, 11.8, 0.0, &p).is_ok());
}

#[test]
fn table2_a_start_at_the_acceleration_limit_is_within_it() {
    // Every candidate starts with the ego's own acceleration. From exactly the 3 m/s² limit,
    // easing off to 13 m/s in 2 s (acceleration falling linearly to 0) is feasible; so is the
    // same from 0.1 m/s² above it (the limit follows the start); rising above the start is not.
    let p = Params::default().trajectory;
    let mut planner = *lone_ego(10.0).planner();
    planner.start.dds = p.max_accel_mps2;
    assert!(planner.evaluate(2.0, 13.0, 0.0, &p).is_ok());
    planner.start.dds = p.max_accel_mps2 + 0.1;
    assert!(planner.evaluate(2.0, 13.0, 0.0, &p).is_ok());
    assert_eq!(
        planner.evaluate(2.0, 17.0, 0.0, &p),
        Err(concord_core::trajectory::Reject::Limits)
    );
}

#[test]
fn table2_the_lateral_jerk_limit_holds_between_the_ends() {
    // A lateral quintic from a moving start can peak in jerk between its ends (l⃛ is a
    // quadratic, eq. 18): candidates whose only excess is such an interior peak are rejected,
    // and they are feasible once the jerk limit is lifted. (With the default 4 m/s² lateral
    // acceleration limit that limit binds first; it is raised to 20 here.)
    let p = TrajectoryParams {
        max_lateral_accel_mps2: 20.0,
        ..Params::default().trajectory
    };
    let lifted = TrajectoryParams {
        max_jerk_mps3: 1e3,
        ..p
    };
    let mut lone = *lone_ego(10.0).planner();
    lone.start.l = 0.5;
    let j_max = p.max_jerk_mps3;
    let mut interior = 0;
    for dl in (-4..=4).map(f64::from) {
        for ddl in (-4..=4).map(|a| 2.0 * f64::from(a)) {
            for l_end in [-0.9, -0.7, -0.5, 0.0, 0.5, 0.9] {
                for t_end in [1.0, 1.5] {
                    let q = Quintic::fit(0.5, dl, ddl, l_end, 0.0, 0.0, t_end);
                    let ends = q.jerk(0.0).abs().max(q.jerk(t_end).abs());
                    let peak = (0..=1000)
                        .map(|i| q.jerk(t_end * f64::from(i) / 1000.0).abs())
                        .fold(0.0, f64::max);
                    let mut planner = lone;
                    planner.start.dl = dl;
                    planner.start.ddl = ddl;
                    if ends > 0.9 * j_max
                        || peak < 1.1 * j_max
                        || planner.evaluate(t_end, 10.0, l_end, &lifted).is_err()
                    {
                        continue;
                    }
                    assert_eq!(
                        planner.evaluate(t_end, 10.0, l_end, &p),
                        Err(concord_core::trajectory::Reject::Limits),
                        "l̇ {dl}, l̈ {ddl}, l_T {l_end}, T {t_end}: jerk {ends:.1} at the ends, {peak:.1} inside"
                    );
                    interior += 1;
                }
            }
        }
    }
    assert!(interior > 0, "no candidate whose jerk peaks only inside");
    // One whose jerk exceeds the limit only near its vertex, t = −24·c₄/(120·c₅) = 0.3 s
    // (12 m/s³ there, 6 at the ends): the vertex must be where the check looks.
    let q = Quintic::fit(0.5, -3.0, 6.0, -0.3, 0.0, 0.0, 1.0);
    let vertex = -24.0 * q.c[4] / (120.0 * q.c[5]);
    assert!(
        (q.jerk(vertex).abs() - 12.0).abs() < 1e-6,
        "{}",
        q.jerk(vertex)
    );
    let mut planner = lone;
    planner.start.dl = -3.0;
    planner.start.ddl = 6.0;
    assert!(planner.evaluate(1.0, 10.0, -0.3, &lifted).is_ok());
    assert_eq!(
        planner.evaluate(1.0, 10.0, -0.3, &p),
        Err(concord_core::trajectory::Reject::Limits)
    );
}

#[test]
fn table2_score_weighs_time_longitudinal_and_lateral_jerk_and_the_offset() {
    // S_k = c_e·T_n/T_ref + c_s·(∫|s⃛| + ∫|l⃛|)/J_max + c_l·|l_T|/l_max, each integral
    // computed here numerically from the candidate's polynomials; from a start at rest
    // acceleration and from one already accelerating at 1 m/s².
    let p = Params::default().trajectory;
    let core = lone_ego(10.0);
    let mut planner = *core.planner();
    let s0 = planner.start.s;
    let goal = s0 + Params::default().choice.reference_speed_mps * p.t_ref_s;
    for (a0, t_end, v_end, l_end) in [
        (0.0, 3.0, 12.0, 0.0),
        (0.0, 3.0, 12.0, 0.5),
        (0.0, 2.5, 8.0, -0.4),
        (1.0, 3.0, 12.0, 0.0),
        (1.0, 2.0, 11.0, 0.3),
    ] {
        planner.start.dds = a0;
        let c = planner.evaluate(t_end, v_end, l_end, &p).expect("feasible");
        let n = 100_000;
        let dt = t_end / n as f64;
        let (mut js, mut jl) = (0.0, 0.0);
        for k in 0..n {
            let t = (k as f64 + 0.5) * dt;
            js += c.s.jerk(t).abs() * dt;
            jl += c.l.jerk(t).abs() * dt;
        }
        // T_n: when s reaches the goal (past the polynomial at v_end).
        let s_end = c.s.pos(t_end);
        let t_n = if s_end >= goal {
            let (mut lo, mut hi) = (0.0, t_end);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if c.s.pos(mid) < goal {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            hi
        } else {
            t_end + (goal - s_end) / v_end
        };
        let expected = p.c_efficiency * t_n / p.t_ref_s
            + p.c_smoothness * (js + jl) / p.j_max_norm
            + p.c_lateral * l_end.abs() / p.max_lateral_offset_m;
        assert!(
            (c.score - expected).abs() < 2e-3,
            "a₀ {a0}, ({t_end}, {v_end}, {l_end}): {} vs {expected} (jerk {js:.3} + {jl:.3})",
            c.score
        );
        if l_end != 0.0 {
            assert!(jl > 0.05, "the lateral move has jerk");
        }
        assert!(js > 0.05, "the speed change has jerk");
    }
}

#[test]
fn eq4_an_agent_is_selected_by_its_delta_ttc_or_its_closeness_only() {
    // CAV 50.7 m from the crossing at 10 m/s (TTC 5.1 s); HDV 35 m from it.
    let selected = |hdv_speed: f64, hdv_before: f64| {
        let mut core = paper_core(Params::default());
        let mut scene = paper_scene(0.0, 10.0, 0.0);
        scene.agents[0] = before_the_paper_crossing(1, paper::HDV_STRAIGHT, hdv_before, hdv_speed);
        core.step(&scene, 0.0, None).unwrap();
        core.triplet().n_objects
    };
    // At 8 m/s (TTC 4.4 s, |ΔTTC| 0.7 s): a risky conflict.
    assert_eq!(selected(8.0, 35.0), 1);
    // At 3 m/s (TTC 11.7 s, |ΔTTC| 6.6 s) and 85 m away along the paths: not selected.
    assert_eq!(selected(3.0, 35.0), 0);
}

#[test]
fn eq4_more_risky_agents_than_slots_keep_the_lowest_delta_ttcs_in_order() {
    // The CAV at 5 m/s 18.7 m before the crossing (TTC 3.7 s); eleven HDVs at 8 m/s on the
    // straight lane, 1, 7, …, 61 m before it, listed nearest first: every one is a risky
    // conflict (|ΔTTC| 0.1–3.9 s), three more than the triplet holds. It keeps
    // the eight lowest |ΔTTC|, sorted, whatever their order in the scene.
    let mut core = paper_core(Params::default());
    let cav = before_the_paper_crossing(0, paper::CAV_LEFT, 18.7, 5.0);
    let mut scene = Scene::new(0.0, cav, paper::CAV_LEFT);
    for k in 0..11 {
        let before = 1.0 + 6.0 * k as f64;
        scene.push(before_the_paper_crossing(
            1 + k,
            paper::HDV_STRAIGHT,
            before,
            8.0,
        ));
    }
    core.step(&scene, 0.0, None).unwrap();
    let mut by_risk: Vec<(f64, u32)> = core
        .conflicts()
        .pairs()
        .iter()
        .map(|c| (c.delta_ttc_s, scene.agents[c.agent as usize].id))
        .collect();
    assert_eq!(by_risk.len(), 11);
    by_risk.sort_by(|a, b| a.0.total_cmp(&b.0));
    let expected: Vec<u32> = by_risk.iter().take(MAX_SELECTED).map(|r| r.1).collect();
    let kept: Vec<u32> = core.triplet().objects().iter().map(|o| o.id).collect();
    assert_eq!(kept, expected, "{by_risk:?}");
    assert!(!kept.contains(&1), "the nearest, |ΔTTC| 3.6 s, is left out");
}

#[test]
fn eq12_to_15_the_choice_follows_its_history_when_utilities_tie() {
    // A lone ego turning left: accelerate and turn left have the same profile and utility,
    // and a tie goes to the lower index (accelerate). With a history of turning left in the
    // same situation, the corrected logit turns left.
    let p = Params::default();
    let mut core = paper_core(p);
    let scene = paper_scene(0.0, 8.0, 0.0);
    let mut lone = scene;
    lone.n_agents = 0;
    core.step(&lone, 0.0, None).unwrap();
    let first = *core.choice();
    let (a, l) = (Maneuver::Accelerate.index(), Maneuver::TurnLeft.index());
    assert!((first.utility[a] - first.utility[l]).abs() < 1e-9);
    let mut history = ChoiceHistory::default();
    for k in 0..10 {
        history.record(k as f64 * 0.1, first.state, Maneuver::TurnLeft);
    }
    let d = history.d_prev(&first.state);
    assert!((d[l] - 1.0).abs() < 1e-9);
    let v = correct(&first.utility, &d, history.previous, &p.choice);
    assert!(v[l] > v[a]);
    // The core does the same with its own history: having accelerated (the tie), it keeps
    // accelerating: the tie in P_n (eq. 11) is broken in the corrected P_n (eq. 15).
    for k in 1..5 {
        let mut again = lone;
        again.time_s = k as f64 * 0.1;
        let d = core.step(&again, again.time_s, None).unwrap();
        let ch = core.choice();
        assert_eq!(d.maneuver, Maneuver::Accelerate);
        assert!((ch.p_logit[a] - ch.p_logit[l]).abs() < 1e-9);
        assert!(
            ch.p_corrected[a] > ch.p_corrected[l] + 0.05,
            "{:?}",
            ch.p_corrected
        );
    }
}

#[test]
fn fallback_samples_must_be_a_usable_count_and_later_plans_use_at_most_samples() {
    let mut p = Params::default();
    p.trajectory.fallback_samples = 0;
    assert_eq!(p.validate().unwrap_err().key, "trajectory.fallback_samples");
    p.trajectory.fallback_samples = 1025;
    assert_eq!(p.validate().unwrap_err().key, "trajectory.fallback_samples");
    p.trajectory.fallback_samples = 512;
    p.trajectory.samples = 128;
    assert!(p.validate().is_ok());
    assert_eq!(p.trajectory.later_samples(), 128);
}

#[test]
fn every_advice_verdict_has_its_code_and_its_own_snake_case_name() {
    let mut names = std::collections::BTreeSet::new();
    for (code, v) in AdviceVerdict::ALL.iter().enumerate() {
        assert_eq!(*v as usize, code);
        assert_eq!(AdviceVerdict::try_from(code as u8), Ok(*v));
        let name = v.name();
        assert!(
            !name.is_empty() && name.chars().all(|c| c.is_ascii_lowercase() || c == '_'),
            "{v:?}: {name:?}"
        );
        assert!(names.insert(name), "{name} twice");
    }
    assert_eq!(
        AdviceVerdict::try_from(AdviceVerdict::ALL.len() as u8),
        Err(10)
    );
}

#[test]
fn only_decelerate_gives_way_and_only_a_turn_against_the_route_is_inconsistent() {
    for m in Maneuver::ALL {
        assert_eq!(m.gives_way(), m == Maneuver::Decelerate, "{m:?}");
        for route in [Turn::Straight, Turn::Left, Turn::Right] {
            let against = matches!(
                (m, route),
                (Maneuver::TurnLeft, Turn::Straight | Turn::Right)
                    | (Maneuver::TurnRight, Turn::Straight | Turn::Left)
            );
            assert_eq!(m.consistent_with(route), !against, "{m:?} on {route:?}");
        }
    }
}

#[test]
fn a_car_ahead_in_the_lane_corridor_is_the_leader_also_off_centre() {
    // 12 m ahead on the ego's lane, 1.5 m off its centre line (within half a lane width plus
    // 0.5 m): the car-following leader. 4 m off centre: not in the corridor.
    for (offset, leads) in [(0.0, true), (1.5, true), (4.0, false)] {
        let mut core = paper_core(Params::default());
        let mut scene = paper_scene(0.0, 8.0, 8.0);
        scene.push(AgentState::moving(
            2,
            Vec2::new(28.0, 5.0 + offset),
            core::f64::consts::PI,
            8.0,
        ));
        core.step(&scene, 0.0, None).unwrap();
        assert_eq!(core.triplet().leader.is_some(), leads, "offset {offset} m");
    }
}

#[test]
fn the_leader_is_the_nearest_car_ahead_in_any_order_and_never_one_behind() {
    // On the ego's lane (heading −x at y = 5): 12 m ahead, 22 m ahead and 10 m behind, pushed
    // in every order. The leader is the one 12 m ahead.
    let at = [28.0, 18.0, 50.0];
    for order in [[0, 1, 2], [1, 0, 2], [2, 1, 0], [1, 2, 0]] {
        let mut core = paper_core(Params::default());
        let mut scene = paper_scene(0.0, 8.0, 8.0);
        for (k, &i) in order.iter().enumerate() {
            let pos = Vec2::new(at[i], 5.0);
            scene.push(AgentState::moving(
                2 + k as u32,
                pos,
                core::f64::consts::PI,
                8.0,
            ));
        }
        core.step(&scene, 0.0, None).unwrap();
        let leader = core.triplet().leader.expect("a car ahead leads");
        assert!(
            (leader.gap_m - 12.0).abs() < 0.5,
            "{order:?}: gap {}",
            leader.gap_m
        );
    }
}

/// The nominal "decelerate" profile at `speed` m/s with the yield point `yield_distance` m
/// ahead (yield check time 1 s, braking limit 5 m/s², durations 1–6 s).
fn decelerate_towards(speed: f64, yield_distance: f64, p: &ChoiceParams) -> Profile {
    let ctx = concord_core::choice::EgoContext {
        speed,
        speed_cap: 13.9,
        yield_distance,
        goal_distance: 100.0,
        max_brake: 5.0,
        min_duration: 1.0,
        max_duration: 6.0,
        yield_check_s: 1.0,
        ..Default::default()
    };
    concord_core::choice::profile(Maneuver::Decelerate, &ctx, p)
}

#[test]
fn decelerate_stops_at_the_yield_point_braking_at_v0_squared_over_2d() {
    // 10 m/s, 20 m to the yield point: faster than the approach speed 2(√21 − 1) m/s, so one
    // stopping polynomial: −v0²/(2d) = −2.5 m/s² over T = 2d/v0 = 4 s.
    let p = ChoiceParams::default();
    let d = decelerate_towards(10.0, 20.0, &p);
    assert!((d.accel + 2.5).abs() < EPS, "{d:?}");
    assert!((d.duration - 4.0).abs() < EPS && d.stop_m == 20.0 && d.target_speed == 0.0);
}

#[test]
fn decelerate_far_from_the_yield_point_approaches_at_the_speed_that_still_stops_there() {
    // 2 m/s, 30 m to the point: slower than the approach speed v_a, which holding it for the
    // yield check time τ = 1 s and then braking at b = 2 m/s² stops exactly at the point:
    // v_a·τ + v_a²/(2b) = 30, v_a = 2(√31 − 1) ≈ 9.14 m/s.
    let p = ChoiceParams::default();
    let d = decelerate_towards(2.0, 30.0, &p);
    let (b, tau, v) = (p.decelerate_mps2, 1.0, d.target_speed);
    assert!((v * tau + v * v / (2.0 * b) - 30.0).abs() < 1e-6, "{d:?}");
    assert!(
        (v - 2.0 * (31f64.sqrt() - 1.0)).abs() < 1e-6 && d.stop_m == 30.0,
        "{d:?}"
    );
}

#[test]
fn each_risky_conflict_adds_the_intensity_gain_to_the_safety_preference() {
    // The paper's start at 8 m/s, no stated intents: the safety preference is 1 plus the
    // intensity gain per risky conflict.
    let mut core = paper_core(Params::default());
    core.step(&paper_scene(0.0, 8.0, 8.0), 0.0, None).unwrap();
    let risky = core.triplet().risky_conflicts(&core.params().opm).count();
    assert!(risky > 0);
    let gain = ChoiceParams::default().conflict_intensity_safety;
    let expected = 1.0 + gain * risky as f64;
    assert!(
        (core.choice().safety_preference - expected).abs() < EPS,
        "{} != {expected}",
        core.choice().safety_preference
    );
}

/// The safety preference at the paper's start at 8 m/s, with the HDV's explicit intent as
/// `state` sets it.
fn safety_preference_with(state: impl FnOnce(&mut concord_core::scene::ExplicitIntent)) -> f64 {
    let mut core = paper_core(Params::default());
    let mut scene = paper_scene(0.0, 8.0, 8.0);
    state(&mut scene.agents[0].intent);
    core.step(&scene, 0.0, None).unwrap();
    core.choice().safety_preference
}

#[test]
fn a_road_user_stating_it_proceeds_adds_its_gain_to_the_safety_preference() {
    use concord_core::scene::{IntentAction, Rated};
    let plain = safety_preference_with(|_| {});
    let stated = safety_preference_with(|i| {
        i.action = Some(Rated {
            value: IntentAction::Proceed,
            confidence: 0.9,
        })
    });
    let gain = ChoiceParams::default().other_proceeds_safety;
    assert!(
        (stated - (plain + gain)).abs() < EPS,
        "{plain} + {gain} != {stated}"
    );
}

#[test]
fn a_stated_yield_adds_its_efficiency_gain_unless_the_motion_contradicts_it() {
    use concord_core::intent::Stated;
    use concord_core::scene::{IntentAction, Rated};
    // The CAV 10 m before the junction; the HDV 15 m before the crossing (so both near, and
    // the HDV an object of the triplet), standing (its motion agrees with a yield) or at
    // 10 m/s and accelerating at 2 m/s² (it proceeds: a stated yield is contradicted).
    let run = |speed: f64, accel: f64, says_yield: bool| {
        let mut core = paper_core(Params::default());
        let mut scene = paper_scene(0.0, 8.0, speed);
        scene.ego.pos = Vec2::new(10.0, 5.0);
        scene.agents[0].pos = Vec2::new(-12.0, -5.0);
        scene.agents[0].acc = Vec2::new(accel, 0.0);
        if says_yield {
            scene.agents[0].intent.action = Some(Rated {
                value: IntentAction::Yield,
                confidence: 0.9,
            });
        }
        core.step(&scene, 0.0, None).unwrap();
        let stated = core.conflicts().pairs().first().map(|c| c.intent.stated);
        (core.choice().efficiency_preference, stated)
    };
    let gain = ChoiceParams::default().other_yields_efficiency;
    let (plain, _) = run(0.0, 0.0, false);
    let (agreed, stated) = run(0.0, 0.0, true);
    assert_eq!(stated, Some(Stated::Yield));
    assert!(
        (agreed - (plain + gain)).abs() < EPS,
        "{plain} + {gain} != {agreed}"
    );
    let (plain, _) = run(10.0, 2.0, false);
    let (contradicted, stated) = run(10.0, 2.0, true);
    assert_eq!(stated, Some(Stated::Contradicted));
    assert!(
        (contradicted - plain).abs() < EPS,
        "{contradicted} != {plain}"
    );
}

#[test]
fn accelerate_aims_at_the_speed_plus_its_acceleration_over_the_horizon() {
    // From 5 m/s under a 13.9 m/s cap, a = 1 m/s² over h = 4 s: v0 + a·h = 9 m/s, reached
    // at a (a + h, v0 · a · h and the others differ).
    let ctx = concord_core::choice::EgoContext {
        speed: 5.0,
        speed_cap: 13.9,
        min_duration: 1.0,
        max_duration: 6.0,
        ..Default::default()
    };
    let p = ChoiceParams {
        accelerate_mps2: 1.0,
        maneuver_horizon_s: 4.0,
        ..ChoiceParams::default()
    };
    let a = concord_core::choice::profile(Maneuver::Accelerate, &ctx, &p);
    let target = 5.0 + p.accelerate_mps2 * p.maneuver_horizon_s;
    assert!((a.target_speed - target).abs() < EPS, "{a:?}");
    assert!((a.accel - p.accelerate_mps2).abs() < EPS, "{a:?}");
}

#[test]
fn braking_less_than_idm_behind_a_close_leader_costs_matching_by_the_excess_over_comfort() {
    // 10 m/s, closing on a leader 10 m ahead at 4 m/s: IDM brakes harder than "decelerate"
    // does, and the matching attribute loses gain · (a − a_IDM) / idm_comfort_decel_mps2.
    let p = Params::default();
    let mut core = paper_core(p);
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), core::f64::consts::PI, 10.0);
    let mut scene = concord_core::Scene::new(0.0, ego, paper::CAV_LEFT);
    scene.push(AgentState::moving(
        2,
        Vec2::new(30.0, 5.0),
        core::f64::consts::PI,
        4.0,
    ));
    core.step(&scene, 0.0, None).unwrap();
    let leader = core.triplet().leader.expect("the car ahead leads");
    let c = p.choice;
    let a_idm = idm_accel(10.0, leader.gap_m, 10.0 - leader.speed_mps, &c);
    let i = Maneuver::Decelerate.index();
    let excess = core.choice().profiles[i].accel - a_idm;
    assert!(excess > 0.0, "IDM brakes harder: {a_idm}");
    let expected = 1.0 - c.idm_penalty_gain * excess / c.idm_comfort_decel_mps2;
    let matching = core.choice().attributes[i][0];
    assert!(
        (matching - expected).abs() < EPS,
        "{matching} != {expected}"
    );
}

#[test]
fn eq13_state_features_of_an_empty_scene() {
    // Speed over the reference minus 1, acceleration over 3, and with nothing around: the
    // ΔTTC, conflict and leader terms at their caps, no risky conflict.
    let ctx = concord_core::choice::EgoContext {
        speed: 8.0,
        accel: 1.5,
        ..Default::default()
    };
    let f = concord_core::choice::state_features(
        &Default::default(),
        &ctx,
        &OpmParams::default(),
        &ChoiceParams::default(),
    );
    let expected = [8.0 / 10.0 - 1.0, 0.5, 0.5, 1.0, 1.0, -0.5];
    for (k, (a, b)) in f.iter().zip(expected).enumerate() {
        assert!((a - b).abs() < EPS, "feature {k}: {a} != {b}");
    }
}

#[test]
fn through_the_turn_the_plan_keeps_the_lateral_acceleration_limit() {
    // Approaching the left turn fast, the plan slows for the curve: v²κ, with κ from the
    // heading change of the planned points, stays within `max_lateral_accel_mps2` (10 %).
    let p = Params::default();
    for (x, v) in [(30.0, 12.0), (40.0, 13.0), (25.0, 10.0)] {
        let mut core = paper_core(p);
        let ego = AgentState::moving(0, Vec2::new(x, 5.0), core::f64::consts::PI, v);
        let scene = concord_core::Scene::new(0.0, ego, paper::CAV_LEFT);
        let d = core.step(&scene, 0.0, None).unwrap();
        assert_ne!(
            d.source,
            concord_core::DecisionSource::MinimumRisk,
            "x {x}, v {v}"
        );
        let pts = d.trajectory.points();
        let mut worst: f64 = 0.0;
        for w in pts.windows(3) {
            let ds = w[2].s - w[0].s;
            if ds < 0.5 {
                continue;
            }
            let dh = (w[2].heading - w[0].heading + core::f64::consts::PI)
                .rem_euclid(2.0 * core::f64::consts::PI)
                - core::f64::consts::PI;
            let lateral = w[1].speed * w[1].speed * dh.abs() / ds;
            worst = worst.max(lateral);
        }
        assert!(
            worst <= p.trajectory.max_lateral_accel_mps2 * 1.1,
            "x {x}, v {v}: {worst}"
        );
    }
}

/// A planner on the paper's left-turn lane with `agents`, the ego `s` m along it at `v` m/s and
/// `a` m/s².
fn planner_with(agents: &[AgentState], s: f64, v: f64, a: f64) -> (Planner, Morphology) {
    let morph = BuiltIn::PaperIntersection.morphology();
    let start = FrenetState {
        s,
        ds: v,
        dds: a,
        ..FrenetState::default()
    };
    (prepared(&morph, paper::CAV_LEFT, start, agents), morph)
}

/// A planner on lane `lane` of `morph` from `start` with `agents` (no process states or
/// forecasts: each is predicted straight on at its speed).
fn prepared(morph: &Morphology, lane: u8, start: FrenetState, agents: &[AgentState]) -> Planner {
    let mut planner = Planner::default();
    planner.prepare(
        lane,
        start,
        100.0,
        agents,
        &[ProcessState::default(); MAX_AGENTS],
        &[Forecast::default(); MAX_AGENTS],
        morph,
        &Params::default().trajectory,
    );
    planner
}

/// A road user on the centre line of the paper's left-turn lane, `s` m along it, at `v` m/s.
fn car_on_the_turn(s: f64, v: f64) -> AgentState {
    let morph = BuiltIn::PaperIntersection.morphology();
    let (pos, heading, _) = morph.lane(paper::CAV_LEFT).pose_at(s, 0);
    AgentState::moving(1, pos, heading, v)
}

/// [`planner_with`] no other road user, unaccelerated.
fn empty_road_planner(s: f64, v: f64) -> (Planner, Morphology) {
    planner_with(&[], s, v, 0.0)
}

#[test]
fn a_footprint_overlapping_another_is_kept_and_a_point_in_it_is_a_contact() {
    // Two standing cars in the ego's lane, 22 and 19 m ahead, on the straight before the
    // turn: the second's box reaches 3 m further back than the first's and is not inside it,
    // so both block; a point in either is a contact.
    let car = |ahead: f64| car_on_the_turn(ahead, 0.0);
    let (planner, _) = planner_with(&[car(22.0), car(19.0)], 0.0, 5.0, 0.0);
    let boxes: Vec<_> = planner.occupancy.boxes(0).collect();
    assert_eq!(boxes.len(), 2, "{boxes:?}");
    let back = boxes.iter().map(|b| b.0).fold(f64::INFINITY, f64::min);
    assert!(back < 19.0 - 2.25, "{boxes:?}");
    assert_eq!(planner.occupancy.hit(0, back + 0.1, 0.0), Hit::Contact);
    assert_eq!(planner.occupancy.hit(0, 20.5, 0.0), Hit::Contact);
    assert_eq!(planner.occupancy.hit(0, 10.0, 0.0), Hit::Free);
    // Each box is the Minkowski sum of two cars aligned with the lane, with the clearance,
    // the other's length grown for the first step (t = dt): half-extents length + clearance +
    // growth along, width + clearance across.
    let p = Params::default().trajectory;
    let grown = p.margin_growth_mps * p.dt_s;
    for (s_lo, s_hi, l_lo, l_hi) in boxes {
        let along = p.vehicle_length_m + p.safety_margin_m + grown;
        assert!(((s_hi - s_lo) / 2.0 - along).abs() < 1e-6);
        assert!(((l_hi - l_lo) / 2.0 - (p.vehicle_width_m + p.safety_margin_m)).abs() < 1e-6);
    }
}

/// A planner on highway-env's left turn with the ego standing at the end of its approach
/// (x = 2, y = 11, heading −y), where the turn begins, and `agents` standing still.
fn standing_at_the_turn(agents: &[AgentState]) -> Planner {
    use concord_map::highway_env_intersection::EGO_LEFT;
    let morph = BuiltIn::HighwayEnvIntersection.morphology();
    // The approach ends at the stop line.
    let approach_m = morph.lane(EGO_LEFT).stop_s;
    let start = FrenetState {
        s: approach_m,
        ..FrenetState::default()
    };
    prepared(&morph, EGO_LEFT, start, agents)
}

#[test]
fn a_car_beside_the_start_of_a_turn_in_the_opposite_lane_is_no_contact() {
    // Oncoming (x = −2, heading +y) beside the ego's front, 4 m ahead of its centre: 2 m of
    // road between their sides. In the turning lane's frame its box is inflated (it projects
    // onto the arc, at a slant) and covers the ego's centre; the rectangles do not touch, so
    // it is no contact. A car with its corner over the ego's front is one.
    let down = core::f64::consts::FRAC_PI_2;
    let beside = AgentState::moving(1, Vec2::new(-2.0, 7.0), down, 0.0);
    let planner = standing_at_the_turn(&[beside]);
    let s0 = planner.start.s;
    assert!(
        planner
            .occupancy
            .boxes(0)
            .any(|b| b.0 <= s0 && s0 <= b.1 && b.2 <= 0.0 && 0.0 <= b.3),
        "the broad box covers the ego's centre"
    );
    assert_eq!(planner.occupancy.hit(0, s0, 0.0), Hit::Free);
    let stand = planner.evaluate(1.0, 0.0, 0.0, &Params::default().trajectory);
    assert!(stand.is_ok(), "standing at the turn: {stand:?}");

    let over = AgentState::moving(1, Vec2::new(0.5, 8.0), down, 0.0);
    let planner = standing_at_the_turn(&[over]);
    assert_eq!(planner.occupancy.hit(0, s0, 0.0), Hit::Contact);
}

#[test]
fn a_footprint_inside_another_footprints_box_still_blocks() {
    // The car beside the turn has a large box; a second car, 3 m to the left of the turn
    // 5.5 m into it, has its box inside that one. Where the ego would touch only the second
    // car, the point is a contact with both present: the covered box's rectangle is not lost.
    use concord_map::highway_env_intersection::EGO_LEFT;
    let morph = BuiltIn::HighwayEnvIntersection.morphology();
    // The approach ends at the stop line.
    let approach_m = morph.lane(EGO_LEFT).stop_s;
    let down = core::f64::consts::FRAC_PI_2;
    let beside = AgentState::moving(1, Vec2::new(-2.0, 7.0), down, 0.0);
    let (s_b, l_b) = (approach_m + 5.5, -3.0);
    let (pos, heading, _) = morph.lane(EGO_LEFT).to_cartesian(s_b, l_b, 0);
    let inside = AgentState::moving(2, pos, heading, 0.0);
    let (s, l) = (s_b - 4.0, l_b + 2.0);
    let only_beside = standing_at_the_turn(&[beside]);
    let big = only_beside.occupancy.boxes(0).next().expect("a box");
    let both = standing_at_the_turn(&[beside, inside]);
    let small = standing_at_the_turn(&[inside])
        .occupancy
        .boxes(0)
        .next()
        .unwrap();
    assert!(
        big.0 <= small.0 && small.1 <= big.1 && big.2 <= small.2 && small.3 <= big.3,
        "{small:?} inside {big:?}"
    );
    assert_eq!(only_beside.occupancy.hit(0, s, l), Hit::Free);
    assert_eq!(both.occupancy.hit(0, s, l), Hit::Contact);
}

#[test]
fn an_ego_drifting_out_at_its_lateral_bound_still_has_a_plan() {
    // Leaving the turn at 10 m/s with 0.97 m offset, drifting outwards at 0.3 m/s: no
    // quintic can hold 1 m, but the quickest correction overshoots by only 16/81·u·T, which
    // the bound allows; the ego steers back instead of braking for nothing.
    // The same on the other side of the lane.
    let p = Params::default().trajectory;
    for side in [1.0, -1.0] {
        let (mut planner, _) = empty_road_planner(60.0, 10.0);
        planner.start.l = 0.97 * side;
        planner.start.dl = 0.3 * side;
        let back = planner.evaluate(2.0, 10.0, 0.0, &p);
        assert!(back.is_ok(), "side {side}: {back:?}");
        // A slow correction drifts further and stays refused.
        assert!(matches!(
            planner.evaluate(4.0, 10.0, 0.97 * side, &p),
            Err(Reject::Limits)
        ));
    }
}

#[test]
fn slowing_from_a_hard_braking_start_every_sample_keeps_its_speed_between_its_ends() {
    // 8 m/s braking at 5 m/s², slowing to a stop over a nominal 6 s: a quartic that long would
    // undershoot below 0 m/s; each sample's T is cut to 3 · 8 / 5 = 4.8 s, so none breaks a
    // limit.
    let p = Params::default().trajectory;
    let (mut planner, _) = planner_with(&[], 0.0, 8.0, -5.0);
    let slowing = Profile {
        accel: -2.0,
        target_speed: 0.0,
        duration: 6.0,
        stop_m: f64::INFINITY,
    };
    planner.sample(&slowing, 256, 0, &p);
    let mut stats = concord_core::trajectory::PlanStats::default();
    assert!(planner.run(256, &p, &mut stats).is_some());
    assert_eq!(stats.limit_rejects, 0, "{stats:?}");
}

#[test]
fn a_yielding_plan_must_still_be_able_to_stop_at_the_yield_check_time() {
    // 6 m/s, yielding at a point 9.5 m ahead. Rolling on at 6 m/s, the ego is 6 m on at the
    // yield check time (1 s) and needs 36 / (2 · b / 1.5) more to stop: past the point, so the
    // plan commits, although its polynomial ends (9 m, T = 1.5 s) before the point.
    let p = Params::default().trajectory;
    let (mut planner, _) = empty_road_planner(0.0, 6.0);
    planner.yield_distance = 9.5;
    planner.clear_distance = 60.0;
    let yielding = Profile {
        accel: -2.0,
        target_speed: 0.0,
        duration: 3.0,
        stop_m: 9.5,
    };
    planner.sample(&yielding, 1, 0, &p);
    assert_eq!(
        planner.evaluate(1.5, 6.0, 0.0, &p).err(),
        Some(Reject::Commits)
    );
    // Stopping at the point is a plan.
    assert!(planner.evaluate(19.0 / 6.0, 0.0, 0.0, &p).is_ok());
}

#[test]
fn an_ego_too_fast_for_the_turn_that_does_not_brake_has_no_plan() {
    // 13 m/s 20 m before the turn: holding 13 m/s into the curve exceeds its speed cap and
    // is not on a braking curve from the start.
    let p = Params::default().trajectory;
    let (mut planner, _) = empty_road_planner(20.0, 13.0);
    assert_eq!(
        planner.evaluate(2.0, 13.0, 0.0, &p).err(),
        Some(Reject::Limits)
    );
    // Sampled around that, every candidate is counted under one outcome.
    let holding = Profile {
        accel: 0.0,
        target_speed: 13.0,
        duration: 3.0,
        stop_m: f64::INFINITY,
    };
    planner.sample(&holding, 64, 0, &p);
    let mut s = concord_core::trajectory::PlanStats::default();
    planner.run(64, &p, &mut s);
    assert!(s.limit_rejects > 0, "{s:?}");
    assert_eq!(
        s.evaluated,
        s.feasible + s.limit_rejects + s.collision_rejects + s.zone_rejects + s.score_rejects,
        "{s:?}"
    );
}

#[test]
fn a_lateral_shift_too_sharp_for_the_speed_breaks_the_curvature_bound() {
    // At 2.5 m/s a 1 m shift over 2 s needs |l̈| up to 5.77 / 4 m/s², within the lateral
    // acceleration limit, but |l̈| / ṡ² plus the turn's curvature ahead exceeds
    // `max_curvature`; holding the lane centre is a plan.
    let p = Params::default().trajectory;
    let (planner, _) = empty_road_planner(0.0, 2.5);
    assert_eq!(
        planner.evaluate(2.0, 2.5, 1.0, &p).err(),
        Some(Reject::Limits)
    );
    assert!(planner.evaluate(2.0, 2.5, 0.0, &p).is_ok());
}

#[test]
fn the_minimum_risk_fallback_brakes_evenly_until_it_stands() {
    // From 8 m/s with nothing to stop for: `emergency_brake_mps2` until v = 0, then 0.
    let p = Params::default().trajectory;
    let (planner, morph) = empty_road_planner(0.0, 8.0);
    let mut out = Trajectory::default();
    planner.minimum_risk(f64::INFINITY, morph.lane(paper::CAV_LEFT), &p, &mut out);
    let t_stop = 8.0 / p.emergency_brake_mps2;
    for pt in out.points() {
        let expected = if pt.t < t_stop {
            -p.emergency_brake_mps2
        } else {
            0.0
        };
        assert!(
            (pt.accel - expected).abs() < EPS,
            "at {} s: {}",
            pt.t,
            pt.accel
        );
        assert!((pt.speed - (8.0 - p.emergency_brake_mps2 * pt.t).max(0.0)).abs() < EPS);
    }
    assert!(out.points().last().unwrap().t > t_stop);
}

/// Forecast distances (m): accelerating from 0 at 1 m/s² to a 2 m/s top speed covers 2 m in
/// the first 2 s and 2 m/s after, 18 m in 10 s; braking evenly to stop in 10 m from 10 m/s
/// (5 m/s²) covers the 10 m and no more.
#[test]
fn forecast_travel_saturates_at_the_top_speed_and_stops_at_its_stop_distance() {
    assert!((travel(0.0, 1.0, 10.0, 2.0) - 18.0).abs() < EPS);
    assert!((travel(10.0, -5.0, 1.0, 20.0) - 7.5).abs() < EPS);
    let stopping = Forecast {
        stop_in_m: 10.0,
        ..Forecast::default()
    };
    assert!((stopping.travel(10.0, 1.0, 20.0) - 7.5).abs() < EPS);
    assert!((stopping.travel(10.0, 5.0, 20.0) - 10.0).abs() < EPS);
}

/// The fallback's drive-on search keeps the candidate whose first contact comes latest: over
/// more samples that time never falls, and in some scene it rises past the first sample's.
#[test]
fn the_drive_on_search_keeps_the_latest_contact() {
    let p = Params::default();
    let n = p.trajectory.later_samples();
    let mut rose = 0;
    for cav_before in [0.0, 2.0, 4.0, 6.0] {
        for hdv_before in (2..30).map(|d| d as f64) {
            let mut core = paper_core(p);
            let scene = crossing_scene(core.morphology(), cav_before, 6.0, hdv_before);
            let d = core.step(&scene, 0.0, None).unwrap();
            if d.source != concord_core::DecisionSource::MinimumRisk {
                continue;
            }
            let mut probe = *core.planner();
            let prof = core.choice().profiles[Maneuver::KeepSpeed.index()];
            probe.sample(&prof, n, d.cycle, &p.trajectory);
            let latest: Vec<f64> = [1, n / 4, n / 2, n]
                .iter()
                .filter_map(|&k| probe.latest_contact(k, &p.trajectory).map(|(_, t)| t))
                .collect();
            assert!(
                latest.windows(2).all(|w| w[1] >= w[0]),
                "CAV {cav_before} m, HDV {hdv_before} m: {latest:?}"
            );
            if latest.len() == 4 && latest[3] > latest[0] && latest[3].is_finite() {
                rose += 1;
            }
        }
    }
    assert!(
        rose > 0,
        "no scene where a later sample's contact came later"
    );
}

#[test]
fn keeping_a_speed_too_fast_for_the_turn_breaks_its_curve_cap() {
    // 13 m/s towards the left turn with room to brake for it: holding the speed for 4 s
    // reaches the curve above its cap and faster than braking at the limit would leave the
    // ego, so it breaks a limit (only a speed the ego cannot shed in time is let through).
    let p = Params::default().trajectory;
    for s in [0.0, 10.0, 20.0] {
        let (planner, _) = empty_road_planner(s, 13.0);
        assert_eq!(
            planner.evaluate(4.0, 13.0, 0.0, &p).err(),
            Some(Reject::Limits),
            "s {s}"
        );
    }
}

#[test]
fn a_follower_in_the_egos_lane_puts_no_box_in_its_way_but_a_car_ahead_does() {
    // A car 8 m behind the ego in its lane, as fast, is its follower's business (it keeps its
    // own gap): no box at any step. The same car 20 m ahead blocks.
    let car = |s: f64| car_on_the_turn(s, 8.0);
    let (behind, _) = planner_with(&[car(2.0)], 10.0, 8.0, 0.0);
    assert!((0..50).all(|step| behind.occupancy.boxes(step).next().is_none()));
    let (ahead, _) = planner_with(&[car(30.0)], 10.0, 8.0, 0.0);
    assert!(ahead.occupancy.boxes(0).next().is_some());
}

/// True when rectangles centred at `a` and `b` with headings `ha`, `hb` (rad) and half
/// extents (length, width) overlap: the separating-axis test, written out independently.
fn rectangles_meet(a: Vec2, ha: f64, ea: (f64, f64), b: Vec2, hb: f64, eb: (f64, f64)) -> bool {
    let corners = |c: Vec2, h: f64, (hl, hw): (f64, f64)| {
        let (u, n) = (
            Vec2::from_angle(h),
            Vec2::from_angle(h + std::f64::consts::FRAC_PI_2),
        );
        [(1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0)]
            .map(|(i, j)| c.plus(u.scale(i * hl)).plus(n.scale(j * hw)))
    };
    let (pa, pb) = (corners(a, ha, ea), corners(b, hb, eb));
    let axes = [
        ha,
        ha + std::f64::consts::FRAC_PI_2,
        hb,
        hb + std::f64::consts::FRAC_PI_2,
    ];
    axes.iter().all(|&h| {
        let axis = Vec2::from_angle(h);
        let span = |pts: &[Vec2; 4]| {
            let d = pts.map(|q| q.dot(axis));
            (
                d.iter().cloned().fold(f64::INFINITY, f64::min),
                d.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            )
        };
        let ((a_lo, a_hi), (b_lo, b_hi)) = (span(&pa), span(&pb));
        a_lo <= b_hi && b_lo <= a_hi
    })
}

#[test]
fn a_standing_car_blocks_exactly_where_the_egos_rectangle_would_meet_its_own() {
    // A standing car before, in and after the paper's left turn (a 10 m arc) and right turn
    // (5 m), on the centre line and up to 7 m to either side, at five headings to the lane:
    // see `assert_contacts_exact`. The ego may plan up to 3 m off its lane here.
    let p = TrajectoryParams {
        max_lateral_offset_m: 3.0,
        ..Params::default().trajectory
    };
    let morph = BuiltIn::PaperIntersection.morphology();
    let mut checked = [0usize; 2];
    // Each lane with arc lengths before, in and after its turn.
    for (id, cars) in [
        (paper::CAV_LEFT, [30.0, 38.0, 43.0, 48.0, 53.0]),
        (paper::WEST_RIGHT, [32.0, 36.0, 39.0, 42.0, 45.0]),
    ] {
        for s_car in cars {
            for l_car in [-7.0, -4.5, -2.0, 0.0, 2.0, 4.5, 7.0] {
                for turn in [0.0, 0.3, 0.79, 1.2, 1.57] {
                    assert_contacts_exact(&morph, id, 20.0, (s_car, l_car, turn), &p, &mut checked);
                }
            }
        }
    }
    assert!(checked[0] > 10_000 && checked[1] > 10_000, "{checked:?}");
}

#[test]
fn far_along_a_lane_a_standing_car_on_its_bend_blocks_exactly_where_the_rectangles_meet() {
    // The same check 1 km along a lane, where its 10 m bend begins: the planner's frame
    // spans the window the ego can reach from there, not the lane from its start.
    let p = TrajectoryParams {
        max_lateral_offset_m: 3.0,
        ..Params::default().trajectory
    };
    let mut points = vec![Vec2::new(0.0, 0.0)];
    points.extend((0..=18).map(|k| {
        let a = k as f64 * std::f64::consts::FRAC_PI_2 / 18.0;
        Vec2::new(1000.0 + 10.0 * a.sin(), 10.0 - 10.0 * a.cos())
    }));
    points.push(Vec2::new(1010.0, 60.0));
    let bend = concord_core::scene::Lane::new(&points, 1.75, 15.0, Turn::Left).expect("a lane");
    let morph = Morphology::new(&[bend]).expect("a map");
    let mut checked = [0usize; 2];
    for s_car in [1003.0, 1008.0, 1014.0] {
        for l_car in [-2.0, 0.0, 2.0] {
            for turn in [0.0, 0.79] {
                assert_contacts_exact(&morph, 0, 995.0, (s_car, l_car, turn), &p, &mut checked);
            }
        }
    }
    assert!(checked[0] > 1_000 && checked[1] > 1_000, "{checked:?}");
}

/// For a car standing at (s, l) of `lane`, turned `turn` rad from it, and the ego at `s_ego`:
/// at every point of a 0.2 m grid around the car, the ego's reference point is in contact
/// where the ego's rectangle there meets the car's with its clearance and first-step growth
/// (by more than 6 cm), and free where they stay more than 6 cm apart, whether the core tests
/// the car's box alone (where the box is exact) or its rectangle (where the lane bends, a box
/// in the lane's frame is not the Minkowski sum, and the rectangles' reach is). 6 cm: the
/// planner's tabulated frame places the ego up to 5 cm from the lane's own conversion 3 m
/// inside a 5 m arc. Counts the points checked in contact and free in `checked`.
fn assert_contacts_exact(
    morph: &Morphology,
    lane_id: u8,
    s_ego: f64,
    (s_car, l_car, turn): (f64, f64, f64),
    p: &TrajectoryParams,
    checked: &mut [usize; 2],
) {
    let lane = morph.lane(lane_id);
    let (hl, hw) = (0.5 * p.vehicle_length_m, 0.5 * p.vehicle_width_m);
    let clear = p.safety_margin_m;
    let other = (hl + p.margin_growth_mps * p.dt_s + clear, hw + clear);
    let grow = |d: f64| (other.0 + d, other.1 + d);
    let start = FrenetState {
        s: s_ego,
        ..FrenetState::default()
    };
    let (pos, tangent, _) = lane.to_cartesian(s_car, l_car, 0);
    let h_car = tangent + turn;
    let car = AgentState::moving(1, pos, h_car, 0.0);
    let mut planner = Planner::default();
    let none = [ProcessState::default(); MAX_AGENTS];
    let straight_on = [Forecast::default(); MAX_AGENTS];
    planner.prepare(lane_id, start, 100.0, &[car], &none, &straight_on, morph, p);
    for i in 0..=80 {
        for j in 0..=30 {
            let (s, l) = (s_car - 8.0 + 0.2 * i as f64, -3.0 + 0.2 * j as f64);
            let (ego, h, _) = lane.to_cartesian(s, l, 0);
            let meets = rectangles_meet(ego, h, (hl, hw), pos, h_car, grow(-0.06));
            let near = rectangles_meet(ego, h, (hl, hw), pos, h_car, grow(0.06));
            let hit = planner.occupancy.hit(0, s, l);
            let at = || {
                format!("lane {lane_id}: car at ({s_car}, {l_car}) turned {turn}, ego at ({s:.1}, {l:.1})")
            };
            if meets {
                assert_eq!(hit, Hit::Contact, "{}", at());
                checked[0] += 1;
            } else if !near {
                assert_ne!(hit, Hit::Contact, "{}", at());
                checked[1] += 1;
            }
        }
    }
}

/// The request log holds requests, not cycles: ids between two requests are unknown, and a
/// request is due after half of `request_period_s` (or when the clock goes back).
#[test]
fn request_log_keeps_requests_by_time() {
    let mut log = RequestLog::default();
    assert!(log.due(0.0, 0.05));
    for cycle in [1, 4, 7] {
        log.issue(cycle, cycle as f64 * 0.01);
    }
    assert_eq!(log.issued_at(4), Some(0.04));
    assert_eq!(log.issued_at(7), Some(0.07));
    for never in [0, 3, 5, 8] {
        assert_eq!(log.issued_at(never), None, "request {never}");
    }
    assert!(!log.due(0.07 + 0.024, 0.05));
    assert!(log.due(0.07 + 0.026, 0.05));
    assert!(log.due(0.01, 0.05), "the clock went back");
    // Due at exactly half the period.
    log.issue(9, 1.0);
    assert!(!log.due(1.25, 1.0));
    assert!(log.due(1.5, 1.0));
}

#[test]
fn eq2_a_lane_branching_off_another_is_no_conflict_one_starting_across_it_is() {
    use concord_core::scene::{ConflictKind, Lane};
    let lane = |pts: &[(f64, f64)]| {
        let pts: Vec<Vec2> = pts.iter().map(|&(x, y)| Vec2::new(x, y)).collect();
        Lane::new(&pts, 2.5, 10.0, Turn::Straight).unwrap()
    };
    let main = lane(&[(0.0, 0.0), (100.0, 0.0)]);
    // Starts 40 m along the main lane, runs along it for 20 m, then turns off: a branch.
    let branch = lane(&[(40.0, 0.0), (60.0, 0.0), (70.0, 20.0)]);
    // Starts on the main lane's line too, but heading across it (60° off): it crosses there.
    let across = lane(&[(50.0, 0.0), (60.0, 17.3)]);
    let m = Morphology::new(&[main, branch, across]).unwrap();
    assert!(m.conflict(0, 1).is_none(), "{:?}", m.conflict(0, 1));
    let c = m
        .conflict(0, 2)
        .expect("a lane starting across the main lane conflicts");
    assert_eq!(c.kind, ConflictKind::Crossing);
    assert!((c.s_a - 50.0).abs() < 1e-6, "{}", c.s_a);
}

#[test]
fn toward_a_target_accelerates_or_brakes_at_the_nominal_rates_and_holds_at_it() {
    use concord_core::choice::{toward, EgoContext};
    let p = ChoiceParams::default();
    let ctx = EgoContext {
        speed: 8.0,
        speed_cap: 13.9,
        min_duration: 1.0,
        max_duration: 6.0,
        ..Default::default()
    };
    let down = toward(5.0, &ctx, &p);
    assert_eq!((down.accel, down.target_speed), (-p.decelerate_mps2, 5.0));
    let up = toward(10.0, &ctx, &p);
    assert_eq!((up.accel, up.target_speed), (p.accelerate_mps2, 10.0));
    let hold = toward(8.0, &ctx, &p);
    assert_eq!((hold.accel, hold.target_speed), (0.0, 8.0));
    // Above the speed cap, the target is the cap.
    assert_eq!(toward(20.0, &ctx, &p).target_speed, 13.9);
}

#[test]
fn a_road_user_stating_an_emergency_adds_its_task_gain_to_the_safety_preference() {
    use concord_core::scene::{Rated, Task};
    let plain = safety_preference_with(|_| {});
    let stated = safety_preference_with(|i| {
        i.task = Some(Rated {
            value: Task::Emergency,
            confidence: 0.9,
        })
    });
    let gain = ChoiceParams::default().other_task_safety[Task::Emergency as usize];
    assert!(gain > 0.0);
    assert!(
        (stated - (plain + gain)).abs() < EPS,
        "{plain} + {gain} != {stated}"
    );
}

#[test]
fn a_trajectory_sample_interpolates_between_its_points_heading_included() {
    use concord_core::TrajectoryPoint;
    let mut tr = Trajectory::default();
    tr.points[0] = TrajectoryPoint {
        t: 0.0,
        s: 0.0,
        speed: 4.0,
        heading: 3.1,
        ..Default::default()
    };
    tr.points[1] = TrajectoryPoint {
        t: 1.0,
        s: 5.0,
        speed: 6.0,
        // Across ±π: the turn is the short way, 0.2 rad.
        heading: 3.3 - std::f64::consts::TAU,
        ..Default::default()
    };
    tr.n = 2;
    let q = tr.sample(0.25).unwrap();
    assert!(
        (q.s - 1.25).abs() < EPS && (q.speed - 4.5).abs() < EPS,
        "{q:?}"
    );
    assert!((q.heading - 3.15).abs() < 1e-9, "{q:?}");
    assert_eq!(
        tr.sample(2.0).unwrap().s,
        5.0,
        "past the end: the last point"
    );
}

#[test]
fn the_rendered_trajectory_covers_the_whole_horizon() {
    let p = Params::default().trajectory;
    let core = lone_ego(10.0);
    let points = core.last_decision().trajectory.points();
    assert_eq!(points.len(), (p.horizon_s / p.dt_s).round() as usize + 1);
    assert!((points.last().unwrap().t - p.horizon_s).abs() < 1e-9);
}
