//! The interaction rules: implicit intents, post-encroachment margins, right of way, courtesy,
//! where to stand, the deadlock negotiation, and the planner's forecasts and margins. Each
//! test sets up a scene where its rule decides the outcome.
mod common;

use common::*;
use concord_core::choice::{
    choose, conflict_risk, efficiency, expected_wait, imposed_decel, ChoiceHistory, ChoiceOutcome,
    EgoContext, Maneuver, Profile,
};
use concord_core::intent::{current_accel, infer, Motion, Stated};
use concord_core::negotiation::{EgoState, EhmiDisplay, Negotiation, Phase};
use concord_core::opm::{ConflictPair, ConflictSet, OpmTriplet};
use concord_core::params::{ChoiceParams, Follower, InteractionParams, OpmParams, Params};
use concord_core::scene::{
    AgentState, ConflictKind, ExplicitIntent, History, IntentAction, Morphology, ProcessState,
    Rated, RightOfWay, Vec2, MAX_AGENTS,
};
use concord_core::trajectory::{Forecast, FrenetState, Hit, PlanStats, Planner, Reject};
use concord_core::{DecisionCore, Scene};
use concord_map::{paper, BuiltIn};

/// A conflict with the ego's and the other's passages at `ego` and `other` (distances from
/// their centres, m) and the other at `v` m/s.
fn pair(ego: [f64; 2], other: [f64; 2], v: f64) -> ConflictPair {
    ConflictPair {
        ego_pass_m: ego,
        agent_pass_m: other,
        ego_zone_m: ego,
        agent_zone_m: other,
        agent_speed_mps: v,
        agent_ttc_s: other[0] / v.max(0.5),
        ..ConflictPair::default()
    }
}

/// Holding `v` m/s.
fn keep(v: f64) -> Profile {
    Profile {
        target_speed: v,
        duration: 3.0,
        ..Profile::default()
    }
}

#[test]
fn passing_behind_a_car_that_will_have_left_is_safe_and_going_first_needs_its_margin() {
    let ip = InteractionParams::default();
    // The other at 10 m/s leaves its passage [10, 20] m at 2 s at the latest.
    let other = [10.0, 20.0];
    // Behind: entering at 4 s leaves 2 s ≥ pet_behind_s (1.6 s).
    assert_eq!(
        conflict_risk(
            &keep(10.0),
            10.0,
            &pair([40.0, 50.0], other, 10.0),
            0.0,
            &ip
        ),
        0.0
    );
    // Entering at 2.5 s leaves 0.5 s: risky.
    let close = conflict_risk(
        &keep(10.0),
        10.0,
        &pair([25.0, 35.0], other, 10.0),
        0.0,
        &ip,
    );
    assert!(close > 0.3, "{close}");
    // First: out at 0.5 s; the other enters [35, 45] at 2.9 s at the earliest (accelerating
    // at 1.5 m/s²): 2.4 s ≥ pet_go_s (2 s). Its passage at [20, 30]: 1.3 s is too little.
    let ego = [0.0, 5.0];
    assert_eq!(
        conflict_risk(&keep(10.0), 10.0, &pair(ego, [35.0, 45.0], 10.0), 0.0, &ip),
        0.0
    );
    let short = conflict_risk(&keep(10.0), 10.0, &pair(ego, [20.0, 30.0], 10.0), 0.0, &ip);
    assert!(short > 0.1, "{short}");
    // Unless the other lets the ego go first.
    assert_eq!(
        conflict_risk(&keep(10.0), 10.0, &pair(ego, [20.0, 30.0], 10.0), 1.0, &ip),
        0.0
    );
    // A profile that stops before the passage does not enter it.
    let stop = Profile {
        stop_m: 20.0,
        ..keep(10.0)
    };
    assert_eq!(
        conflict_risk(&stop, 10.0, &pair([25.0, 35.0], other, 10.0), 0.0, &ip),
        0.0
    );
}

#[test]
fn arriving_together_with_a_proceeding_car_going_at_speed_is_unsafe_and_the_choice_keeps_the_margin(
) {
    // The paper's scene with both cars 30 m from the crossing at 8 m/s: holding speed they
    // would meet there. The choice either yields or times its turn to pass behind.
    let mut core = paper_core(Params::default());
    let ip = core.params().interaction;
    let cav = before_the_paper_crossing(0, paper::CAV_LEFT, 30.0, 8.0);
    let mut scene = Scene::new(0.0, cav, paper::CAV_LEFT);
    scene.push(before_the_paper_crossing(1, paper::HDV_STRAIGHT, 30.0, 8.0));
    let d = core.step(&scene, 0.0, None).unwrap();
    let c = core.conflicts().pairs()[0];
    let y = core.yields()[0];
    assert!(conflict_risk(&keep(8.0), 8.0, &c, y, &ip) > 0.5);
    let chosen = core.choice().profiles[d.logit_maneuver.index()];
    assert!(
        conflict_risk(&chosen, 8.0, &c, y, &ip) < 0.05,
        "{:?} {chosen:?}",
        d.logit_maneuver
    );
    assert!(core.choice().safety[d.logit_maneuver.index()] > 0.95);
}

fn motion(speed: f64, decel: f64, accel: f64) -> Motion {
    Motion {
        speed,
        decel,
        accel,
        standing_s: 0.0,
    }
}

fn stated(action: IntentAction, confidence: f64) -> ExplicitIntent {
    ExplicitIntent {
        action: Some(Rated {
            value: action,
            confidence,
        }),
        ..ExplicitIntent::UNKNOWN
    }
}

#[test]
fn implicit_intent_from_braking_speed_trend_standing_and_the_point_of_no_return() {
    let ip = InteractionParams::default();
    let none = ExplicitIntent::UNKNOWN;
    let sum = |i: &concord_core::intent::ImplicitIntent| i.yielding + i.proceeding + i.undecided;
    // 8 m/s, 20 m to its zone: stopping needs 1.6 m/s²; braking at that is yielding.
    let y = infer(&motion(8.0, 1.6, -1.6), 20.0, &none, 0.7, &ip);
    assert!(y.yielding > 0.85 && !y.committed, "{y:?}");
    assert!((y.required_decel_mps2 - 1.6).abs() < 1e-9);
    // Not braking: undecided, may proceed; accelerating: proceeding.
    let c = infer(&motion(8.0, 0.0, 0.0), 20.0, &none, 0.7, &ip);
    assert!(c.yielding == 0.0 && c.undecided > 0.5, "{c:?}");
    let a = infer(&motion(8.0, 0.0, 1.2), 20.0, &none, 0.7, &ip);
    assert!(a.proceeding > 0.85, "{a:?}");
    // 10 m/s, 10 m before the zone: 5 m/s² needed, more than comfortable: committed.
    let k = infer(&motion(10.0, 1.0, -1.0), 10.0, &none, 0.7, &ip);
    assert!(k.committed && k.proceeding > 0.9, "{k:?}");
    // Standing before its zone: yielding; moving off: proceeding.
    let s = infer(&motion(0.0, 0.0, 0.0), 5.0, &none, 0.7, &ip);
    assert_eq!(s.yielding, ip.standing_yield);
    let off = infer(&motion(0.2, 0.0, 1.0), 5.0, &none, 0.7, &ip);
    assert!(off.proceeding > 0.5, "{off:?}");
    // In its zone: in the way, whatever it intends.
    let inside = infer(&motion(3.0, 0.0, 0.0), -1.0, &none, 0.7, &ip);
    assert!(inside.committed && inside.proceeding == 1.0);
    for i in [y, c, a, k, s, off, inside] {
        assert!((sum(&i) - 1.0).abs() < 1e-9, "{i:?}");
    }
}

#[test]
fn a_stated_yield_counts_only_while_the_motion_does_not_say_proceeding() {
    let ip = InteractionParams::default();
    let go_ahead = stated(IntentAction::Yield, 0.9);
    // Cruising: it resolves the undecided share towards yielding.
    let c = infer(&motion(8.0, 0.0, 0.0), 20.0, &go_ahead, 0.7, &ip);
    assert_eq!(c.stated, Stated::Yield);
    assert!(c.yielding > 0.6, "{c:?}");
    // Accelerating into the conflict: ignored, it is proceeding.
    let a = infer(&motion(8.0, 0.0, 1.2), 20.0, &go_ahead, 0.7, &ip);
    assert_eq!(a.stated, Stated::Contradicted);
    assert!(a.yielding < 0.05 && a.proceeding > 0.85, "{a:?}");
    // Committed: ignored.
    let k = infer(&motion(10.0, 0.0, 0.0), 10.0, &go_ahead, 0.7, &ip);
    assert_eq!(k.stated, Stated::Contradicted);
    // Weak: not counted at all.
    let weak = infer(
        &motion(8.0, 0.0, 0.0),
        20.0,
        &stated(IntentAction::Yield, 0.5),
        0.7,
        &ip,
    );
    assert_eq!(weak.stated, Stated::Nothing);
    assert_eq!(weak.yielding, 0.0);
    // A stated proceed is the cautious reading: it always counts.
    let p = infer(
        &motion(0.0, 0.0, 0.0),
        5.0,
        &stated(IntentAction::Proceed, 0.9),
        0.7,
        &ip,
    );
    assert_eq!(p.stated, Stated::Proceed);
    assert!(p.proceeding > 0.2, "{p:?}");
}

#[test]
fn motion_reads_the_speed_trend_when_no_acceleration_is_reported() {
    // A car braking from 10 to 8 m/s over 1 s whose source reports no acceleration.
    let ip = InteractionParams::default();
    let mut h = History::default();
    for k in 0..=10 {
        let t = k as f64 * 0.1;
        let v = 10.0 - 2.0 * t;
        h.record(t, &[AgentState::moving(7, Vec2::new(0.0, 0.0), 0.0, v)]);
    }
    let now = AgentState::moving(7, Vec2::new(0.0, 0.0), 0.0, 8.0);
    let m = Motion::of(&now, h.track(7), 1.0, &ip);
    assert!((m.decel - 2.0).abs() < 1e-6, "{m:?}");
    // A report of braking that the trend does not confirm yet counts only as far as both.
    let mut reported = now;
    reported.acc = Vec2::new(-4.0, 0.0);
    let r = Motion::of(&reported, h.track(7), 1.0, &ip);
    assert!((r.decel - 2.0).abs() < 1e-6, "{r:?}");
}

/// The paper's CAV on its left turn `cav_before` m before the stop line at `v` m/s, and a car on
/// the minor road (northbound) `minor_before` m before its crossing with the turn at `mv`
/// m/s, braking at `md` m/s².
fn priority_scene(v: f64, minor_before: f64, mv: f64, md: f64) -> (Box<DecisionCore>, Scene) {
    let core = paper_core(Params::default());
    let m = *core.morphology();
    let (s_cav, s_minor) = m
        .conflict_between(paper::CAV_LEFT, paper::NORTH_STRAIGHT)
        .unwrap();
    let (cav, h_cav, _) = m.lane(paper::CAV_LEFT).pose_at(s_cav - 25.0, 0);
    let (car, h_car, _) = m
        .lane(paper::NORTH_STRAIGHT)
        .pose_at(s_minor - minor_before, 0);
    let mut scene = Scene::new(0.0, AgentState::moving(0, cav, h_cav, v), paper::CAV_LEFT);
    let mut other = AgentState::moving(1, car, h_car, mv);
    other.acc = Vec2::from_angle(h_car).scale(-md);
    scene.push(other);
    (core, scene)
}

#[test]
fn with_the_right_of_way_the_ego_counts_on_the_other_yielding_until_it_is_committed() {
    // The minor-road car 30 m away at 8 m/s can still stop comfortably (1.3 m/s²): the ego,
    // on the major road, counts it as yielding.
    let (mut core, scene) = priority_scene(8.0, 30.0, 8.0, 0.0);
    core.step(&scene, 0.0, None).unwrap();
    let c = core.conflicts().pairs()[0];
    assert_eq!(c.right_of_way, RightOfWay::A);
    assert!(!c.intent.committed);
    assert_eq!(core.yields()[0], 1.0);
    // 6 m away at 8 m/s it cannot: its motion decides (not yielding).
    let (mut core, scene) = priority_scene(8.0, 6.0, 8.0, 0.0);
    core.step(&scene, 0.0, None).unwrap();
    let c = core.conflicts().pairs()[0];
    assert!(c.intent.committed);
    assert!(core.yields()[0] < 0.1, "{:?}", core.yields());
}

#[test]
fn the_paper_junction_gives_the_hdv_priority_over_the_left_turn_and_the_turn_over_the_minor_road() {
    let m = BuiltIn::PaperIntersection.morphology();
    let hdv = m.conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT).unwrap();
    assert_eq!(hdv.right_of_way, RightOfWay::B);
    let minor = m.conflict(paper::CAV_LEFT, paper::NORTH_STRAIGHT).unwrap();
    assert_eq!(minor.right_of_way, RightOfWay::A);
    // Seen from the other lane, the same relation.
    let back = m.conflict(paper::HDV_STRAIGHT, paper::CAV_LEFT).unwrap();
    assert_eq!(back.right_of_way, RightOfWay::A);
}

#[test]
fn courtesy_refuses_a_plan_that_makes_the_other_brake_hard() {
    let ip = InteractionParams::default();
    // The ego leaves its passage after 1 s; the other, 15 m before its passage at 10 m/s,
    // would have to stop within 10 m after its reaction time: 5 m/s².
    let c = pair([0.0, 10.0], [15.0, 25.0], 10.0);
    let b = imposed_decel(&keep(10.0), 10.0, &c, 0.0, &ip);
    assert!((b - 5.0).abs() < 1e-9, "{b}");
    // Far enough away, nothing is imposed; passing behind imposes nothing either.
    assert_eq!(
        imposed_decel(
            &keep(10.0),
            10.0,
            &pair([0.0, 10.0], [60.0, 70.0], 10.0),
            0.0,
            &ip
        ),
        0.0
    );
    assert_eq!(
        imposed_decel(
            &keep(10.0),
            10.0,
            &pair([60.0, 70.0], [15.0, 25.0], 10.0),
            0.0,
            &ip
        ),
        0.0
    );
    // A car that stands is imposed nothing, also one standing 1 m into its passage, in front
    // of which the ego would go first (its risk is the collision check's).
    for pass in [[15.0, 25.0], [-1.0, 9.0]] {
        let b = imposed_decel(&keep(10.0), 10.0, &pair([0.0, 10.0], pass, 0.0), 0.0, &ip);
        assert_eq!(b, 0.0, "standing, passage {pass:?}");
    }
    // In the choice: the ego about to cross, the other 12 m before its passage at 10 m/s and
    // undecided (counted as letting the ego go first with probability 0.5): going first is
    // refused, and counted; yielding is not.
    let close = ConflictPair {
        agent_ttc_s: 1.2,
        ..pair([1.0, 8.0], [12.0, 22.0], 10.0)
    };
    let out = choose_with(&[close], &[0.5], 8.0);
    for m in [
        Maneuver::Accelerate,
        Maneuver::KeepSpeed,
        Maneuver::TurnLeft,
    ] {
        assert!(
            out.courtesy_rejected[m.index()],
            "{m:?}: {:?}",
            out.imposed_decel
        );
    }
    assert!(!out.courtesy_rejected[Maneuver::Decelerate.index()]);
    assert!(out.imposed_decel[Maneuver::TurnLeft.index()] > ip.max_imposed_decel_mps2);
    assert_eq!(out.choice, Maneuver::Decelerate);
}

#[test]
fn an_idm_follower_brakes_for_a_crossing_ego_as_for_a_standing_leader_and_for_a_merging_one_by_its_speed(
) {
    // highway-env's intersection traffic: s₀ 7 m centre to centre (3.5 m from its front to
    // the ego's passage), T 1.5 s, a 6 m/s², b 3 m/s², lanes at 10 m/s; the kinematic rule
    // keeps 1.6 s behind the ego.
    let ip = InteractionParams {
        follower: Follower::Idm,
        pet_behind_s: 1.6,
        follower_min_gap_m: 3.5,
        follower_headway_s: 1.5,
        follower_max_accel_mps2: 6.0,
        follower_comfort_decel_mps2: 3.0,
        proceed_top_speed_mps: 10.0,
        ..InteractionParams::default()
    };
    // The ego crosses in 1 s, 15 m ahead of the other at 8 m/s: it appears as a standing
    // leader inside the IDM's desired gap (23 m) and the other brakes at over 9 m/s², where
    // the kinematic rule asks 2.6 m/s² (within courtesy).
    let crossing = pair([0.0, 10.0], [15.0, 25.0], 8.0);
    let idm = imposed_decel(&keep(10.0), 10.0, &crossing, 0.0, &ip);
    assert!(idm > 9.0, "{idm}");
    let kinematic = InteractionParams {
        follower: Follower::Kinematic,
        ..ip
    };
    let b = imposed_decel(&keep(10.0), 10.0, &crossing, 0.0, &kinematic);
    assert!((b - 2.63).abs() < 0.01, "{b}");
    // Committed (it could not stop comfortably) or not, the IDM brakes for its leader; the
    // kinematic rule leaves a committed car to the PET margins.
    let mut committed = crossing;
    committed.intent.committed = true;
    assert!(imposed_decel(&keep(10.0), 10.0, &committed, 0.0, &ip) > 9.0);
    assert_eq!(
        imposed_decel(&keep(10.0), 10.0, &committed, 0.0, &kinematic),
        0.0
    );
    // 60 m away it only eases off its acceleration.
    let far = pair([0.0, 10.0], [60.0, 70.0], 8.0);
    assert_eq!(imposed_decel(&keep(10.0), 10.0, &far, 0.0, &ip), 0.0);
    // Merging 15 m ahead of it: at 10 m/s, pulling away, the ego makes it brake at 1.4 m/s²
    // at most; at 4 m/s, which it closes on, at over 6.
    let merge = ConflictPair {
        kind: ConflictKind::Merging,
        ..crossing
    };
    let ahead = imposed_decel(&keep(10.0), 10.0, &merge, 0.0, &ip);
    assert!(ahead > 1.0 && ahead < 1.6, "{ahead}");
    let slow = imposed_decel(&keep(4.0), 4.0, &merge, 0.0, &ip);
    assert!(slow > 6.0, "{slow}");
    // 3 m away, it cannot stop before the ego's passage even at 9 m/s²: no braking does.
    let reached = pair([0.0, 10.0], [3.0, 13.0], 8.0);
    assert_eq!(
        imposed_decel(&keep(10.0), 10.0, &reached, 0.0, &ip),
        f64::INFINITY
    );
}

/// The choice stage on the paper's turn, at `speed` m/s, with the given conflicts and
/// probabilities that each other lets the ego go first.
fn choose_with(pairs: &[ConflictPair], yields: &[f64], speed: f64) -> ChoiceOutcome {
    choose_with_params(pairs, yields, speed, 0.5, &Params::default())
}

/// [`choose_with`] with its yield point `yield_m` m ahead, under `p`.
fn choose_with_params(
    pairs: &[ConflictPair],
    yields: &[f64],
    speed: f64,
    yield_m: f64,
    p: &Params,
) -> ChoiceOutcome {
    let ctx = EgoContext {
        speed,
        speed_cap: 10.0,
        yield_distance: yield_m,
        goal_distance: pairs[0].ego_zone_m[1],
        route: concord_core::scene::Turn::Left,
        max_brake: p.trajectory.max_brake_mps2,
        min_duration: p.trajectory.min_duration_s,
        max_duration: p.trajectory.max_duration_s,
        yield_check_s: p.trajectory.yield_check_s,
        ..EgoContext::default()
    };
    let mut out = ChoiceOutcome::default();
    choose(
        &OpmTriplet::default(),
        &ConflictSet::of(pairs),
        yields,
        &ctx,
        &ChoiceHistory::default(),
        &p.opm,
        &p.interaction,
        &p.choice,
        &mut out,
    );
    out
}

#[test]
fn yielding_to_a_car_that_waits_itself_costs_the_deadlock_wait() {
    let ip = InteractionParams::default();
    let opm = OpmParams::default();
    let p = ChoiceParams::default();
    let c = pair([10.0, 20.0], [5.0, 15.0], 8.0);
    let moving = expected_wait(&[c], &[0.0], &opm, &ip);
    let waiting = expected_wait(&[c], &[1.0], &opm, &ip);
    assert!((waiting - ip.deadlock_wait_s).abs() < 1e-9);
    assert!(moving < 2.0, "{moving}");
    let (ctx, stop) = braking_to_the_yield_point(5.0, 8.0, 20.0);
    assert!(efficiency(&stop, &ctx, waiting, &p) < efficiency(&stop, &ctx, moving, &p));
}

/// An ego at `speed` m/s whose yield point is `yield_m` m ahead and whose goal distance is
/// `goal_m`, and the stop at 1.6 m/s² that ends at that point.
fn braking_to_the_yield_point(speed: f64, yield_m: f64, goal_m: f64) -> (EgoContext, Profile) {
    let ctx = EgoContext {
        speed,
        speed_cap: 10.0,
        yield_distance: yield_m,
        goal_distance: goal_m,
        min_duration: 1.0,
        max_duration: 6.0,
        yield_check_s: 1.0,
        ..EgoContext::default()
    };
    let stop = Profile {
        accel: -1.6,
        duration: speed / 1.6,
        stop_m: yield_m,
        ..Profile::default()
    };
    (ctx, stop)
}

#[test]
fn a_goal_at_the_yield_point_is_reached_when_the_stop_is_whatever_the_wait() {
    // From 8 m/s, braking at 1.6 m/s² stops in 5 s exactly at the yield point, 20 m ahead,
    // where the goal distance ends too: waiting there afterwards delays nothing.
    let p = ChoiceParams::default();
    let (ctx, stop) = braking_to_the_yield_point(8.0, 20.0, 20.0);
    let free = 20.0 / p.reference_speed_mps;
    for wait in [0.0, 10.0] {
        assert!(
            (efficiency(&stop, &ctx, wait, &p) - free / 5.0).abs() < 1e-9,
            "wait {wait}"
        );
    }
}

#[test]
fn the_waiting_point_keeps_the_footprint_outside_every_crossing_lane() {
    // Far enough back to stop comfortably, the CAV yields to the HDV at the stop line, not
    // inside the junction, where its footprint would be in the north-south lanes.
    let p = Params::default();
    let mut core = paper_core(p);
    let d = core.step(&paper_scene(0.0, 8.0, 8.0), 0.0, None).unwrap();
    assert!(core.choice().profiles[Maneuver::Decelerate.index()].yields());
    let planner = core.planner();
    let stop = planner.start.s + planner.yield_distance;
    let m = core.morphology();
    for z in m.zones_on(paper::CAV_LEFT) {
        assert!(
            stop <= z[0] - p.trajectory.stop_margin_m + 1e-9 || stop >= z[1],
            "stop at {stop:.2} in zone {z:?}"
        );
    }
    assert!(stop < m.lane(paper::CAV_LEFT).stop_s, "stop at {stop:.2}");
    assert!(d.trajectory.points().iter().all(|q| q.speed >= 0.0));
}

#[test]
fn a_zone_the_ego_can_no_longer_stop_before_comfortably_is_one_it_clears() {
    // At 10 m/s, 8 m before the stop line: stopping there needs 6 m/s².
    let p = Params::default();
    let mut core = paper_core(p);
    let m = *core.morphology();
    let lane = m.lane(paper::CAV_LEFT);
    let (pos, h, _) = lane.pose_at(lane.stop_s - 8.0, 0);
    let mut scene = Scene::new(0.0, AgentState::moving(0, pos, h, 10.0), paper::CAV_LEFT);
    // A car on the minor road, so there is something to yield to at the first crossing.
    let minor = m.lane(paper::NORTH_STRAIGHT);
    let (q, hq, _) = minor.pose_at(20.0, 0);
    scene.push(AgentState::moving(1, q, hq, 6.0));
    core.step(&scene, 0.0, None).unwrap();
    let planner = core.planner();
    let first = m
        .zones_on(paper::CAV_LEFT)
        .map(|z| z[0])
        .fold(f64::INFINITY, f64::min);
    assert!(
        planner.start.s + planner.yield_distance > first,
        "yields at {:.1}, before the first zone at {first:.1}",
        planner.start.s + planner.yield_distance
    );
}

#[test]
fn no_candidate_ends_standing_inside_a_conflict_zone() {
    // The CAV slow inside the junction: a stop candidate would stand in the north-south
    // lanes' zones.
    let p = Params::default();
    let mut core = paper_core(p);
    let lane = *core.morphology().lane(paper::CAV_LEFT);
    let (pos, h, _) = lane.pose_at(33.0, 0);
    let scene = Scene::new(0.0, AgentState::moving(0, pos, h, 2.0), paper::CAV_LEFT);
    core.step(&scene, 0.0, None).unwrap();
    let planner = core.planner();
    assert!(planner.in_zone(33.0));
    assert_eq!(
        planner.evaluate(2.0, 0.0, 0.0, &p.trajectory),
        Err(Reject::StandsInZone)
    );
    // Driving on is fine.
    assert!(planner.evaluate(3.0, 6.0, 0.0, &p.trajectory).is_ok());
}

#[test]
fn conflict_zones_come_from_the_footprint_and_the_lane_widths() {
    let m = BuiltIn::PaperIntersection.morphology();
    let c = m.conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT).unwrap();
    assert_eq!(c.kind, ConflictKind::Crossing);
    // The HDV's lane is straight and the CAV's crosses it at a right angle: the HDV is in the
    // CAV's band (half-width 2.5 m) while its centre is within 2.5 + 4.8 / 2 m of the point.
    // (On the exit side the CAV's lane bends towards the HDV's, so the zone ends a little
    // later.)
    assert!((c.zone_b[0] - (c.s_b - 4.9)).abs() < 0.01, "{c:?}");
    assert!(
        c.zone_b[1] >= c.s_b + 4.9 - 0.01 && c.zone_b[1] < c.s_b + 5.5,
        "{c:?}"
    );
    // On the CAV's turn: at the zone's entry a corner of its footprint touches the HDV's
    // band (y ∈ [−7.5, −2.5]); just before, none does.
    let lane = m.lane(paper::CAV_LEFT);
    let corners = |s: f64| {
        let (p, t, _) = lane.pose_at(s, 0);
        let (f, n) = (
            Vec2::from_angle(t),
            Vec2::from_angle(t + std::f64::consts::FRAC_PI_2),
        );
        [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)]
            .map(|(a, b)| p.plus(f.scale(2.4 * a)).plus(n.scale(1.0 * b)))
    };
    let in_band = |q: Vec2| (q.y + 5.0).abs() <= 2.5 && q.x.abs() < 40.0;
    assert!(corners(c.zone_a[0] + 0.02).into_iter().any(in_band));
    assert!(!corners(c.zone_a[0] - 0.02).into_iter().any(in_band));
    // The turn joins the southbound lane: a merge.
    let merge = m.conflict(paper::CAV_LEFT, paper::SOUTH_STRAIGHT).unwrap();
    assert_eq!(merge.kind, ConflictKind::Merging);
    assert!((merge.pass_a[1] - merge.pass_a[0] - 4.8).abs() < 1e-9);
}

#[test]
fn the_planner_keeps_the_post_encroachment_margin_behind_a_crossing_car() {
    // The HDV just through the crossing at 10 m/s; the CAV arrives behind it: holding 6 m/s
    // on the turn it would enter its passage 0.9 s after the HDV left, less than pet_behind_s.
    let run = |p: Params| {
        let mut core = paper_core(p);
        let m = *core.morphology();
        let c = m.conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT).unwrap();
        let (cav, h_cav, _) = m.lane(paper::CAV_LEFT).pose_at(c.zone_a[0] - 6.0, 0);
        let (hdv, h_hdv, _) = m.lane(paper::HDV_STRAIGHT).pose_at(c.zone_b[1] - 1.0, 0);
        let mut scene = Scene::new(0.0, AgentState::moving(0, cav, h_cav, 6.0), paper::CAV_LEFT);
        scene.push(AgentState::moving(1, hdv, h_hdv, 10.0));
        core.step(&scene, 0.0, None).unwrap();
        let t = p.trajectory;
        core.planner().evaluate(2.0, 6.0, 0.0, &t)
    };
    let r = run(Params::default());
    assert!(matches!(r, Err(Reject::Collision(_))), "{r:?}");
    let mut no_margin = Params::default();
    no_margin.interaction.pet_behind_s = 0.0;
    no_margin.interaction.pet_go_s = 0.0;
    assert!(run(no_margin).is_ok());
}

#[test]
fn the_planner_sees_a_car_that_arrives_at_the_crossing_with_the_ego() {
    // Both 10 m before the crossing's zone at 6 m/s, the HDV from the west: holding 6 m/s the
    // ego meets it there (its boxes lie west of and below the ego's lane, near the edges of
    // the region the planner considers).
    let mut core = paper_core(Params::default());
    let m = *core.morphology();
    let c = m.conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT).unwrap();
    let (cav, h_cav, _) = m.lane(paper::CAV_LEFT).pose_at(c.zone_a[0] - 10.0, 0);
    let (hdv, h_hdv, _) = m.lane(paper::HDV_STRAIGHT).pose_at(c.zone_b[0] - 10.0, 0);
    let mut scene = Scene::new(0.0, AgentState::moving(0, cav, h_cav, 6.0), paper::CAV_LEFT);
    scene.push(AgentState::moving(1, hdv, h_hdv, 6.0));
    core.step(&scene, 0.0, None).unwrap();
    let t = Params::default().trajectory;
    let r = core.planner().evaluate(2.0, 6.0, 0.0, &t);
    assert!(matches!(r, Err(Reject::Collision(_))), "{r:?}");
}

#[test]
fn the_planner_keeps_the_margins_in_the_egos_passage_of_the_zone_only() {
    // The ego 10 m along its lane at 6 m/s; a car 20 m ahead of it in that lane at 4 m/s, in
    // its passage of a zone for the whole horizon; the ego's passage of that zone is 25–35 m
    // ahead. The margin lies there, not along the car's whole path, and holds all along.
    let morph = BuiltIn::PaperIntersection.morphology();
    let p = Params::default().trajectory;
    let s0 = 10.0;
    let (pos, heading, _) = morph.lane(paper::CAV_LEFT).pose_at(s0 + 20.0, 0);
    let agents = [AgentState::moving(1, pos, heading, 4.0)];
    let mut processes = [ProcessState::default(); MAX_AGENTS];
    processes[0] = ProcessState::of(&agents[0], &morph, 1.0);
    let mut forecasts = [Forecast::default(); MAX_AGENTS];
    forecasts[0] = Forecast {
        pet_s: [1.6, 2.0],
        pass_m: [0.0, 1000.0],
        ego_pass_m: [25.0, 35.0],
        ..Forecast::default()
    };
    let start = FrenetState {
        s: s0,
        ds: 6.0,
        ..FrenetState::default()
    };
    let mut planner = Planner::default();
    planner.prepare(
        paper::CAV_LEFT,
        start,
        100.0,
        &agents,
        &processes,
        &forecasts,
        &morph,
        &p,
    );
    let margins = planner.margins();
    assert_eq!(margins.len(), 1, "the car gets a margin: {margins:?}");
    // In its passage from now (before now it was behind the passage's start, at its speed)
    // for the whole horizon: from the margin ahead before now until past the horizon and the
    // margin behind.
    let m = margins[0];
    assert_eq!(m.s, [s0 + 25.0, s0 + 35.0]);
    assert!((m.t[0] + 2.0).abs() < 1e-9, "{m:?}");
    assert!(m.t[1] > p.horizon_s + 1.6, "{m:?}");
}

#[test]
fn a_yielding_car_is_forecast_to_stop_so_the_ego_can_go_first() {
    // The minor-road car 25 m before its crossing at 8 m/s: braking to stop before its zone
    // it is forecast to stop there; cruising, it is forecast to drive on.
    let (mut braking, scene) = priority_scene(8.0, 25.0, 8.0, 1.6);
    braking.step(&scene, 0.0, None).unwrap();
    assert!(braking.forecasts()[0].stop_in_m.is_finite());
    let mut equal = Params::default();
    // Without the right of way (so its motion alone decides), a cruising car drives on.
    equal.interaction.trust_yield = 0.8;
    let mut core =
        Box::new(DecisionCore::new(equal, BuiltIn::PaperIntersection.morphology()).unwrap());
    let (_, scene) = priority_scene(8.0, 25.0, 8.0, 0.0);
    let mut s = scene;
    // Put the cruising car on the major road instead (it then has the right of way).
    s.agents[0] = before_the_paper_crossing(1, paper::HDV_STRAIGHT, 25.0, 8.0);
    core.step(&s, 0.0, None).unwrap();
    assert!(core.forecasts()[0].stop_in_m.is_infinite());
}

/// A conflict where the other waits `d` m before its zone and the ego waits `e` m before its.
fn waiting(e: f64, d: f64, v: f64, a: f64) -> ConflictPair {
    ConflictPair {
        ego_zone_m: [e, e + 10.0],
        agent_zone_m: [d, d + 10.0],
        agent_speed_mps: v,
        agent_accel_mps2: a,
        ..ConflictPair::default()
    }
}

/// The ego at `speed` m/s, starting at 1.5 m/s², after a decision that did not give way.
fn ego(speed: f64) -> EgoState {
    EgoState {
        speed_mps: speed,
        accel_mps2: 1.5,
        gives_way: false,
    }
}

#[test]
fn a_deadlock_is_announced_watched_and_broken() {
    let ip = InteractionParams::default();
    let id = |_| 42;
    let mut n = Negotiation::default();
    let both = [waiting(2.0, 3.0, 0.0, 0.0)];
    n.update(&both, id, &ego(0.0), 0.0, &ip);
    assert_eq!(n.phase, Phase::Waiting);
    n.update(&both, id, &ego(0.0), 0.4, &ip);
    assert_eq!(n.phase, Phase::Waiting);
    n.update(&both, id, &ego(0.0), ip.deadlock_after_s + 0.01, &ip);
    assert_eq!(n.phase, Phase::Announced);
    assert!(n.announces() && !n.yielded(42));
    let announced = ip.deadlock_after_s + 0.01;
    n.update(&both, id, &ego(0.0), announced + 0.5 * ip.watch_s, &ip);
    assert_eq!(n.phase, Phase::Announced);
    n.update(&both, id, &ego(0.0), announced + ip.watch_s + 0.01, &ip);
    assert_eq!(n.phase, Phase::Going);
    assert!(n.yielded(42));
    // Once the ego has left the zone, it is over.
    n.update(&[waiting(-11.0, 3.0, 0.0, 0.0)], id, &ego(5.0), 10.0, &ip);
    assert_eq!(n.phase, Phase::Idle);
}

#[test]
fn a_deadlock_negotiation_ends_when_the_other_takes_the_way() {
    let ip = InteractionParams::default();
    let id = |_| 42;
    let mut n = Negotiation::default();
    let both = [waiting(2.0, 3.0, 0.0, 0.0)];
    n.update(&both, id, &ego(0.0), 0.0, &ip);
    n.update(&both, id, &ego(0.0), 1.0, &ip);
    assert_eq!(n.phase, Phase::Announced);
    // It moves off after the announcement: the ego gives way again.
    n.update(&[waiting(2.0, 2.8, 0.6, 1.2)], id, &ego(0.0), 1.2, &ip);
    assert_eq!(n.phase, Phase::Idle);
    // Only both waiting is a deadlock: an ego still rolling is not waiting.
    n.update(&both, id, &ego(3.0), 2.0, &ip);
    assert_eq!(n.phase, Phase::Idle);
}

/// The ego waiting 5 m before its zone; another car `d` m before its own at `v` m/s, braking
/// as one that yields with probability `y`, each with a 15 m passage.
fn approaching(d: f64, v: f64, y: f64) -> ConflictPair {
    let mut c = waiting(5.0, d, v, 0.0);
    c.ego_pass_m = [5.0, 20.0];
    c.agent_pass_m = [d, d + 15.0];
    c.intent.yielding = y;
    c.intent.undecided = 1.0 - y;
    c
}

/// A waiting ego that has just asked car 7, 40 m out at 8 m/s, to let it go first (at t = 0):
/// it would stop at 0.89 m/s² after its reaction, gentle enough to ask, and it would reach
/// the crossing before the ego could have crossed with pet_go_s to spare.
fn asked(ip: &InteractionParams) -> Negotiation {
    let mut n = Negotiation::default();
    n.update(&[approaching(40.0, 8.0, 0.0)], |_| 7, &ego(0.0), 0.0, ip);
    assert_eq!(n.phase, Phase::Announced);
    n
}

#[test]
fn a_waiting_ego_asks_a_car_that_can_stop_gently_and_goes_once_it_brakes() {
    let ip = InteractionParams::default();
    let id = |_| 7;
    let mut n = asked(&ip);
    assert!(n.announces() && !n.yielded(7));
    // Watched for less than watch_s, it has not answered yet.
    n.update(&[approaching(36.0, 8.0, 0.0)], id, &ego(0.0), 0.5, &ip);
    assert_eq!(n.phase, Phase::Announced);
    // It brakes as one that yields: the ego goes.
    n.update(&[approaching(32.0, 6.5, 0.9)], id, &ego(0.0), 1.1, &ip);
    assert_eq!(n.phase, Phase::Going);
    assert!(n.yielded(7));
    // Braking less near its line is no break-off; speeding up again is.
    n.update(&[approaching(20.0, 4.0, 0.3)], id, &ego(2.0), 2.0, &ip);
    assert_eq!(n.phase, Phase::Going);
    n.update(&[approaching(17.0, 4.6, 0.0)], id, &ego(3.0), 2.5, &ip);
    assert_eq!(n.phase, Phase::Idle);
    // It refused: it is not asked again.
    n.update(&[approaching(40.0, 8.0, 0.0)], id, &ego(0.0), 3.0, &ip);
    assert_eq!(n.phase, Phase::Idle);
}

#[test]
fn a_car_that_keeps_coming_after_the_request_is_let_through_and_not_asked_again() {
    let ip = InteractionParams::default();
    let id = |_| 7;
    let mut n = asked(&ip);
    // After watch_s at its speed it could no longer stop gently: it has answered no.
    n.update(&[approaching(24.0, 8.0, 0.0)], id, &ego(0.0), 2.0, &ip);
    assert_eq!(n.phase, Phase::Idle);
    assert!(!n.announces());
    n.update(&[approaching(40.0, 8.0, 0.0)], id, &ego(0.0), 2.1, &ip);
    assert_eq!(n.phase, Phase::Idle);
}

#[test]
fn a_car_that_slows_after_the_request_complies_even_if_it_brakes_later_than_asked() {
    let ip = InteractionParams::default();
    let id = |_| 7;
    let mut n = asked(&ip);
    // 2 s later, 14 m out at 6.5 m/s: it needs 1.96 m/s² after its reaction, but it has slowed
    // by 0.75 m/s² on average since the request (a driver's IDM brakes harder near its line).
    n.update(&[approaching(14.0, 6.5, 0.0)], id, &ego(0.0), 2.0, &ip);
    assert_eq!(n.phase, Phase::Announced);
    // Slowed by less than 0.3 m/s² on average: it keeps coming.
    let mut n = asked(&ip);
    n.update(&[approaching(14.0, 7.5, 0.0)], id, &ego(0.0), 2.0, &ip);
    assert_eq!(n.phase, Phase::Idle);
}

#[test]
fn the_ehmi_shows_a_change_once_it_has_held_and_the_negotiations_at_once() {
    use concord_core::Announcement::{GivingWay, GoingFirst};
    let ip = InteractionParams::default();
    assert_eq!(ip.announce_settle_s, 0.3);
    let mut shown = EhmiDisplay::default();
    let mut show = |meant, t, negotiated| shown.show(meant, t, negotiated, &ip);
    // The first is shown at once.
    assert_eq!(show(GivingWay, 0.0, false), GivingWay);
    // One cycle's "going first" between two "please go ahead" is not shown.
    assert_eq!(show(GoingFirst, 0.05, false), GivingWay);
    assert_eq!(show(GivingWay, 0.1, false), GivingWay);
    // Held from 0.2 s: shown from 0.5 s on.
    assert_eq!(show(GoingFirst, 0.2, false), GivingWay);
    assert_eq!(show(GoingFirst, 0.45, false), GivingWay);
    assert_eq!(show(GoingFirst, 0.5, false), GoingFirst);
    assert_eq!(show(GivingWay, 0.55, false), GoingFirst);
    // The negotiation's announcement is a request: shown at once.
    assert_eq!(show(GivingWay, 1.0, false), GivingWay);
    assert_eq!(show(GoingFirst, 1.05, true), GoingFirst);
    // With no settling time the display follows the plan.
    let instant = InteractionParams {
        announce_settle_s: 0.0,
        ..ip
    };
    let mut shown = EhmiDisplay::default();
    assert_eq!(shown.show(GivingWay, 0.0, false, &instant), GivingWay);
    assert_eq!(shown.show(GoingFirst, 0.05, false, &instant), GoingFirst);
}

#[test]
fn going_first_is_not_shown_while_passing_behind_one_it_would_ask_to_brake_hard() {
    use concord_core::Announcement::{GivingWay, GoingFirst};
    // The CAV 20 m before its crossing at 6 m/s; on the priority road, car 1 15 m before the
    // crossing at 7 m/s (9.75 m before its zone: it could stop, but at 3.9 m/s² after its
    // reaction) and car 2 55 m back.
    let announce = |cars: &[(u32, f64)]| {
        let cav = before_the_paper_crossing(0, paper::CAV_LEFT, 20.0, 6.0);
        let mut scene = Scene::new(0.0, cav, paper::CAV_LEFT);
        for &(id, before) in cars {
            scene.push(before_the_paper_crossing(
                id,
                paper::HDV_STRAIGHT,
                before,
                7.0,
            ));
        }
        let d = paper_core(Params::default())
            .step(&scene, 0.0, None)
            .unwrap();
        (d.announce, d.maneuver)
    };
    // Car 2 alone: the plan goes before it, and the eHMI says so.
    assert_eq!(announce(&[(2, 55.0)]).0, GoingFirst);
    // Behind car 1 and before car 2, "going first" would ask car 1 to brake hard: the eHMI
    // tells everyone to go ahead, and the plan, which keeps its margins against car 2
    // proceeding, does not change.
    let (shown, maneuver) = announce(&[(1, 15.0), (2, 55.0)]);
    assert_eq!(shown, GivingWay, "{maneuver:?}");
}

#[test]
fn nobody_is_asked_to_brake_hard_or_without_need() {
    let ip = InteractionParams::default();
    let ask = |pairs: &[ConflictPair], ip: &InteractionParams, e: EgoState| {
        let mut n = Negotiation::default();
        n.update(pairs, |k| k as u32 + 1, &e, 0.0, ip);
        n.phase
    };
    let far = approaching(40.0, 8.0, 0.0);
    assert_eq!(ask(&[far], &ip, ego(0.0)), Phase::Announced);
    // 22 m out at 8 m/s it needs 2.0 m/s² after its reaction: not asked, and while it could
    // still stop that way, no one behind it is asked either.
    let near = approaching(22.0, 8.0, 0.0);
    assert_eq!(ask(&[near], &ip, ego(0.0)), Phase::Idle);
    assert_eq!(ask(&[near, far], &ip, ego(0.0)), Phase::Idle);
    // One past its point of no return passes first; the one behind it is asked.
    let mut committed = near;
    committed.intent.committed = true;
    assert_eq!(ask(&[committed, far], &ip, ego(0.0)), Phase::Announced);
    // Far enough for the ego to cross before it with pet_go_s to spare: no need to ask.
    assert_eq!(
        ask(&[approaching(90.0, 8.0, 0.0)], &ip, ego(0.0)),
        Phase::Idle
    );
    // An ego still rolling without giving way asks no one; one slowing to give way does.
    assert_eq!(ask(&[far], &ip, ego(5.0)), Phase::Idle);
    let slowing = EgoState {
        gives_way: true,
        ..ego(5.0)
    };
    assert_eq!(ask(&[far], &ip, slowing), Phase::Announced);
    // request_decel_mps2 = 0: traffic that does not read the eHMI is never asked.
    let silent = InteractionParams {
        request_decel_mps2: 0.0,
        ..ip
    };
    assert_eq!(ask(&[far], &silent, ego(0.0)), Phase::Idle);
}

/// At time `t`, the paper's CAV standing 1.5 m before its stop line, an HDV (id 1) standing 3 m
/// before its zone on the priority road, and, for each (m before the zone, speed) of `behind`,
/// another car on that lane (ids 2, 3, ...).
fn standoff(core: &DecisionCore, t: f64, behind: &[(f64, f64)]) -> Scene {
    let m = core.morphology();
    let zone = m
        .conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .unwrap()
        .zone_b[0];
    let lane = m.lane(paper::CAV_LEFT);
    let (cav, h_cav, _) = lane.pose_at(lane.stop_s - 1.5, 0);
    let mut scene = Scene::new(t, AgentState::moving(0, cav, h_cav, 0.0), paper::CAV_LEFT);
    let hdv_lane = m.lane(paper::HDV_STRAIGHT);
    for (id, &(before, v)) in (1..).zip([(3.0, 0.0)].iter().chain(behind)) {
        let (pos, h, _) = hdv_lane.pose_at(zone - before, 0);
        scene.push(AgentState::moving(id, pos, h, v));
    }
    scene
}

/// Index of the conflict with the road user `id` of `scene`, after a step on it.
fn conflict_of(core: &DecisionCore, scene: &Scene, id: u32) -> Option<usize> {
    core.conflicts()
        .pairs()
        .iter()
        .position(|p| scene.agents()[p.agent as usize].id == id)
}

#[test]
fn the_core_announces_going_first_in_a_deadlock_and_then_goes() {
    // The CAV and the HDV (which has priority) both standing before their zones: the core
    // announces, watches and goes.
    let mut core = paper_core(Params::default());
    let mut phases = Vec::new();
    let mut announced_then_went = false;
    for k in 0..60 {
        let t = k as f64 * 0.05;
        let d = core.step(&standoff(&core, t, &[]), t, None).unwrap();
        phases.push(d.negotiation);
        if d.negotiation == Phase::Going && d.maneuver != Maneuver::Decelerate {
            announced_then_went = true;
        }
        if d.negotiation == Phase::Announced {
            assert_eq!(d.announce, concord_core::Announcement::GoingFirst);
        }
    }
    assert!(phases.contains(&Phase::Announced), "{phases:?}");
    assert!(announced_then_went, "{phases:?}");
}

#[test]
fn the_fallback_clears_a_zone_rather_than_standing_in_it() {
    // Slow inside the junction with nobody around: braking would stand in the north-south
    // lanes; the fallback drives on instead.
    let p = Params::default();
    let mut core = paper_core(p);
    let lane = *core.morphology().lane(paper::CAV_LEFT);
    let (pos, h, _) = lane.pose_at(33.0, 0);
    let scene = Scene::new(0.0, AgentState::moving(0, pos, h, 3.0), paper::CAV_LEFT);
    core.step(&scene, 0.0, None).unwrap();
    let mut planner = *core.planner();
    let mut braking = concord_core::Trajectory::default();
    planner.minimum_risk(f64::INFINITY, &lane, &p.trajectory, &mut braking);
    assert!(planner.in_zone(braking.points().last().unwrap().s));
    let profiles = core.choice().profiles;
    let drive_on = [
        profiles[Maneuver::KeepSpeed.index()],
        profiles[Maneuver::Accelerate.index()],
    ];
    let mut out = concord_core::Trajectory::default();
    let taken = planner.fallback(f64::INFINITY, &lane, &drive_on, 1, &p.trajectory, &mut out);
    assert!(taken.is_some());
    let end = out.points().last().unwrap();
    assert!(!planner.in_zone(end.s) || end.speed > 1.0, "{end:?}");
}

#[test]
fn the_fallback_does_not_drive_into_a_car_to_leave_a_zone() {
    // As above, but a car stands in the ego's lane 12 m ahead, past the zone: every drive-on
    // would hit it, braking hits nothing, so the fallback brakes (standing in the zone).
    let p = Params::default();
    let mut core = paper_core(p);
    let lane = *core.morphology().lane(paper::CAV_LEFT);
    let (pos, h, _) = lane.pose_at(33.0, 0);
    let mut scene = Scene::new(0.0, AgentState::moving(0, pos, h, 3.0), paper::CAV_LEFT);
    let (ahead, h_ahead, _) = lane.pose_at(45.0, 0);
    scene.push(AgentState::moving(1, ahead, h_ahead, 0.0));
    core.step(&scene, 0.0, None).unwrap();
    let mut planner = *core.planner();
    let profiles = core.choice().profiles;
    let drive_on = [
        profiles[Maneuver::KeepSpeed.index()],
        profiles[Maneuver::Accelerate.index()],
    ];
    let mut out = concord_core::Trajectory::default();
    let taken = planner.fallback(f64::INFINITY, &lane, &drive_on, 1, &p.trajectory, &mut out);
    assert_eq!(taken, None);
    assert!(planner.in_zone(out.points().last().unwrap().s));
    assert_eq!(planner.first_contact(&out), None);
}

#[test]
fn a_car_queued_behind_one_that_waits_for_the_ego_waits_too() {
    // The deadlock of the test above with a second car standing 10 m behind the first: once
    // the first counts as yielding, the one behind it cannot arrive first either, so the core
    // goes (it stood for good when only the first one's intent counted).
    let mut core = paper_core(Params::default());
    let mut went = false;
    for k in 0..80 {
        let t = k as f64 * 0.05;
        let scene = standoff(&core, t, &[(13.0, 0.0)]);
        let d = core.step(&scene, t, None).unwrap();
        let of = |id| conflict_of(&core, &scene, id).map(|k| core.yields()[k]);
        if let (Some(y1), Some(y2)) = (of(1), of(2)) {
            assert!(y2 >= y1 - 1e-12, "behind {y2} < ahead {y1}");
        }
        went |= d.negotiation == Phase::Going && d.maneuver != Maneuver::Decelerate;
    }
    assert!(went, "the core never went");
}

#[test]
fn a_moving_car_behind_a_waiting_one_counts_as_yielding_as_surely() {
    // The first car stands before its zone; the second rolls up behind it at 4 m/s without
    // braking (its own motion says "not yielding").
    let mut core = paper_core(Params::default());
    let scene = standoff(&core, 0.0, &[(25.0, 4.0)]);
    core.step(&scene, 0.0, None).unwrap();
    let k1 = conflict_of(&core, &scene, 1).unwrap();
    let k2 = conflict_of(&core, &scene, 2).unwrap();
    let second = core.conflicts().pairs()[k2].intent;
    assert!(second.yielding < 0.1, "{second:?}");
    assert!(core.yields()[k1] >= 0.5, "{:?}", core.yields());
    assert_eq!(core.yields()[k2], core.yields()[k1]);
}

#[test]
fn a_road_user_with_priority_is_expected_to_yield_only_as_far_as_its_weight_says() {
    // The HDV (priority road) stands before its zone: its motion says "yielding". With
    // `priority_yield_weight` 0 the core never counts on it (before announcing anything).
    let expected = |weight: f64| {
        let mut p = Params::default();
        p.interaction.priority_yield_weight = weight;
        let mut core = paper_core(p);
        let scene = standoff(&core, 0.0, &[]);
        core.step(&scene, 0.0, None).unwrap();
        let k = conflict_of(&core, &scene, 1).unwrap();
        let pair = core.conflicts().pairs()[k];
        assert_eq!(pair.right_of_way, RightOfWay::B);
        (pair.intent.yielding, core.yields()[k])
    };
    let (implicit, full) = expected(1.0);
    assert!(implicit >= 0.5 && full == implicit, "{implicit} {full}");
    assert_eq!(expected(0.5).1, 0.5 * implicit);
    assert_eq!(expected(0.0).1, 0.0);
    let mut p = Params::default();
    p.interaction.priority_yield_weight = 1.5;
    assert_eq!(
        p.validate().unwrap_err().key,
        "interaction.priority_yield_weight"
    );
}

#[test]
fn the_minimum_risk_stop_ends_behind_a_standing_leader() {
    // The CAV at 10 m/s, 14 m (centre to centre) behind a car standing in its lane, an HDV on
    // the priority road ahead of the junction: stopping behind the car takes 6.1 m/s², more
    // than any candidate may brake, and more than stopping at the yield point would take.
    let p = Params::default();
    let mut core = paper_core(p);
    let m = *core.morphology();
    let lane = *m.lane(paper::CAV_LEFT);
    let (ego, h, _) = lane.pose_at(5.0, 0);
    let (leader, hl, _) = lane.pose_at(19.0, 0);
    let mut scene = Scene::new(0.0, AgentState::moving(0, ego, h, 10.0), paper::CAV_LEFT);
    scene.push(AgentState::moving(1, leader, hl, 0.0));
    let zone = m
        .conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .unwrap()
        .zone_b[0];
    let (hdv, hh, _) = m.lane(paper::HDV_STRAIGHT).pose_at(zone - 20.0, 0);
    scene.push(AgentState::moving(2, hdv, hh, 8.0));
    let d = core.step(&scene, 0.0, None).unwrap();
    assert_eq!(d.source, concord_core::DecisionSource::MinimumRisk);
    assert!(
        core.planner().yield_distance > 10.0,
        "{}",
        core.planner().yield_distance
    );
    let end = d.trajectory.points().last().unwrap();
    assert!(end.speed < 1e-9, "{end:?}");
    assert!(end.s <= 19.0 - p.trajectory.vehicle_length_m, "{end:?}");
}

/// Two straight lanes crossing at the origin: the ego's along +x from (−60, 0), 4 m wide,
/// and a narrow one along +y from (0, −60), 2.4 m wide (a 2 m car in it keeps 0.2 m of its
/// band on each side), each with its stop line 50 m in.
fn plain_crossing() -> Morphology {
    use concord_core::scene::{Lane, Turn};
    let lane = |from: Vec2, to: Vec2, half_width: f64| {
        Lane::builder(from)
            .line_to(to)
            .build(half_width, 50.0, Turn::Straight)
            .unwrap()
    };
    Morphology::new(&[
        lane(Vec2::new(-60.0, 0.0), Vec2::new(60.0, 0.0), 2.0),
        lane(Vec2::new(0.0, -60.0), Vec2::new(0.0, 60.0), 1.2),
    ])
    .unwrap()
}

/// A planner on [`plain_crossing`]'s first lane, the ego standing with its centre at `x`,
/// with `agents` (predicted straight on at their speeds) and `forecasts`.
fn standing_at(x: f64, agents: &[AgentState], forecasts: &[Forecast; MAX_AGENTS]) -> Planner {
    rolling_at(x, 0.0, agents, forecasts)
}

/// [`rolling_at`] 10 m before the crossing (the ego's passage ±6 m around it) at `v` m/s, with
/// a car crossing northwards from y = `car_y` at `car_speed` m/s, in its passage over
/// `pass_m` of its path, and the default margins.
fn before_a_crossing_car(v: f64, car_y: f64, car_speed: f64, pass_m: [f64; 2]) -> Planner {
    let ip = Params::default().interaction;
    let car = AgentState::moving(
        1,
        Vec2::new(0.0, car_y),
        core::f64::consts::FRAC_PI_2,
        car_speed,
    );
    let mut forecasts = [Forecast::default(); MAX_AGENTS];
    let x = -10.0;
    forecasts[0] = Forecast {
        pet_s: [ip.pet_behind_s, ip.pet_go_s],
        pass_m,
        ego_pass_m: [-6.0 - x, 6.0 - x],
        ..Forecast::default()
    };
    rolling_at(x, v, &[car], &forecasts)
}

/// [`standing_at`], the ego at `v` m/s.
fn rolling_at(
    x: f64,
    v: f64,
    agents: &[AgentState],
    forecasts: &[Forecast; MAX_AGENTS],
) -> Planner {
    let morph = plain_crossing();
    let mut planner = Planner::default();
    planner.prepare(
        0,
        FrenetState {
            s: 60.0 + x,
            ds: v,
            ..FrenetState::default()
        },
        50.0,
        agents,
        &[ProcessState::default(); MAX_AGENTS],
        forecasts,
        &morph,
        &Params::default().trajectory,
    );
    planner
}

/// The ego's front `gap` m from the side of a car driving along the crossing lane at 8 m/s,
/// passing the ego after `t` s.
fn beside_a_passing_car(gap: f64, t: f64) -> (f64, [AgentState; 1]) {
    let p = Params::default().trajectory;
    let x = -(0.5 * p.vehicle_width_m + gap + 0.5 * p.vehicle_length_m);
    let car = AgentState::moving(
        1,
        Vec2::new(0.0, -8.0 * t),
        core::f64::consts::FRAC_PI_2,
        8.0,
    );
    (x, [car])
}

/// A profile that does not yield: `accel` m/s² towards `target_speed` m/s over 3 s.
fn drive_on(accel: f64, target_speed: f64) -> Profile {
    Profile {
        accel,
        target_speed,
        duration: 3.0,
        stop_m: f64::INFINITY,
    }
}

/// [`Planner::fallback`] for the ego standing at `x` among `cars` on [`plain_crossing`]'s first
/// lane, stopping at once: the profile taken and the first footprint collision of the
/// trajectory it gives, s.
fn fallback_standing_at(
    x: f64,
    cars: &[AgentState],
    drive_on: &[Profile],
) -> (Option<usize>, Option<f64>) {
    let p = Params::default().trajectory;
    let lane = *plain_crossing().lane(0);
    let mut planner = standing_at(x, cars, &[Forecast::default(); MAX_AGENTS]);
    let mut out = concord_core::Trajectory::default();
    let taken = planner.fallback(0.0, &lane, drive_on, 1, &p, &mut out);
    (taken, planner.first_collision(&out))
}

#[test]
fn a_car_waiting_beside_a_crossing_lane_stays_out_of_its_traffics_way() {
    // The ego's front 0.9 m from the side of the crossing lane's car (outside its lane's
    // band), which passes after 2.5 s: more than the 0.5 m clearance. The uncertainty that grows with prediction time
    // is the car's place along its lane, not across it, so standing there is no contact at
    // any step (grown across as well, it would be from 2 s on).
    let (x, car) = beside_a_passing_car(0.9, 2.5);
    let planner = standing_at(x, &car, &[Forecast::default(); MAX_AGENTS]);
    let p = Params::default().trajectory;
    let stand = planner.evaluate(1.0, 0.0, 0.0, &p);
    assert!(stand.is_ok(), "{stand:?}");
    let steps = (p.horizon_s / p.dt_s) as usize;
    let s = planner.start.s;
    assert!((0..steps).all(|k| planner.occupancy.hit(k, s, 0.0) == Hit::Free));
}

#[test]
fn the_fallback_drives_on_only_when_braking_itself_would_be_hit() {
    // The ego standing with its front 0.3 m from a crossing car's side (outside its lane's
    // band, inside the clearance around the car, not touching) as the car passes after 4 s:
    // braking is a contact only by
    // the clearance, so the fallback keeps braking instead of driving out ahead of the car
    // (which a contact-free candidate could). With the footprints overlapping it drives on.
    let p = Params::default().trajectory;
    let lane = *plain_crossing().lane(0);
    let fallback = |gap: f64| {
        let (x, car) = beside_a_passing_car(gap, 4.0);
        let planner = standing_at(x, &car, &[Forecast::default(); MAX_AGENTS]);
        let mut braking = concord_core::Trajectory::default();
        planner.minimum_risk(f64::INFINITY, &lane, &p, &mut braking);
        let (taken, _) = fallback_standing_at(x, &car, &[drive_on(3.0, 10.0)]);
        (
            taken,
            (
                planner.first_contact(&braking),
                planner.first_collision(&braking),
            ),
        )
    };
    let (taken, (contact, collision)) = fallback(0.3);
    assert!(
        contact.is_some() && collision.is_none(),
        "{contact:?} {collision:?}"
    );
    assert_eq!(taken, None, "kept braking");
    let (taken, (_, collision)) = fallback(-0.3);
    assert!(collision.is_some());
    assert_eq!(taken, Some(0), "drove on");
}

#[test]
fn the_margins_keep_the_ego_out_of_its_whole_passage() {
    // A car crossing at 8 m/s leaves its passage (±4 m around the crossing) after 1 s. The
    // ego's passage is ±6 m around it; the ego entering its first metre 1 s after the car
    // left (less than pet_behind_s) is refused, though the car's own box does not reach
    // there; entering 2 s after the car left is allowed.
    let planner = before_a_crossing_car(0.0, -4.0, 8.0, [0.0, 8.0]);
    let p = Params::default().trajectory;
    // From standing, a quartic to v over T (no acceleration at either end) covers v·T/2: with
    // v = 9/T it is at −5.5 m, in its passage, at T.
    let reaching = |t_end: f64| planner.evaluate(t_end, 9.0 / t_end, 0.0, &p);
    let early = reaching(2.5); // in the passage from about 2.4 s; the car left at 1 s
    assert!(matches!(early, Err(Reject::Collision(_))), "{early:?}");
    let late = reaching(3.2); // from about 3.1 s
    assert!(late.is_ok(), "{late:?}");
}

#[test]
fn the_egos_comfortable_stop_ramps_its_braking_at_the_jerk_limit() {
    // From 1.9 m/s at a = 0, braking ramps to 3 m/s² over 0.3 s at 10 m/s³ (0.525 m, down to
    // 1.45 m/s), then stops in 0.350 m: 0.875 m, where v²/2b gives 0.60 m. Already braking at
    // 3 m/s², no ramp: v²/2b. Slow enough to stop within the ramp: v at rest after
    // t = √(2v/J), having covered v·t − J·t³/6.
    let p = Params::default();
    let ramped = 1.9 * 0.3 - 10.0 * 0.027 / 6.0 + 1.45 * 1.45 / 6.0;
    assert!((p.ego_comfort_stop_m(1.9, 0.0) - ramped).abs() < 1e-9);
    assert!((p.ego_comfort_stop_m(1.9, -3.0) - 1.9 * 1.9 / 6.0).abs() < 1e-9);
    let t = (2.0f64 * 0.2 / 10.0).sqrt();
    assert!((p.ego_comfort_stop_m(0.2, 0.0) - (0.2 * t - 10.0 * t * t * t / 6.0)).abs() < 1e-9);
    // Accelerating, it needs more.
    assert!(p.ego_comfort_stop_m(1.9, 1.0) > ramped);
}

#[test]
fn an_ego_that_no_planned_stop_keeps_out_of_its_passage_is_not_held_to_the_margin_behind() {
    // The paper's HDV left its passage 0.5 s ago at 10 m/s. The CAV at 1.9 m/s 0.7 m before
    // its own: v²/2b (0.60 m) says it could still stop, no braking ramped at the jerk limit
    // can (0.88 m), so it is committed and no longer in conflict (held to the margin, it had
    // no feasible plan). 1.0 m before, it can stop, and the margin behind the HDV holds.
    let m = BuiltIn::PaperIntersection.morphology();
    let c = m.conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT).unwrap();
    let hdv_passage = c.zone_b[1] - c.zone_b[0];
    let in_conflict = |cav_before: f64| {
        let (mut core, scene) = before_the_crossing(cav_before, 1.9, -(hdv_passage + 5.0));
        core.step(&scene, 0.0, None).unwrap();
        !core.conflicts().pairs().is_empty()
    };
    assert!(!in_conflict(0.7));
    assert!(in_conflict(1.0));
}

#[test]
fn a_slow_ego_creeping_towards_its_yield_point_can_stop_there_when_the_traffic_leaves_no_gap() {
    // The ego 4 m before its passage at 1.9 m/s, below the low-speed threshold, yielding 1 m
    // before it; a car crossing at 6 m/s is in its passage from 1 s to 2.33 s, so the
    // margins hold the ego's passage until past 4 s. Creeping on at the approach speed, every
    // candidate reaches the passage within the margins; the samples that stop at the yield
    // point keep the ego out of it (without them no plan was feasible, and the fallback
    // braked at 5 m/s² where a gentle stop would do).
    let p = Params::default().trajectory;
    let mut planner = before_a_crossing_car(1.9, -10.0, 6.0, [6.0, 14.0]);
    planner.yield_distance = 3.0;
    planner.clear_distance = 16.0;
    let creep = Profile {
        accel: 1.5,
        target_speed: 2.0,
        duration: 3.0,
        stop_m: 3.0,
    };
    planner.sample(&creep, p.samples, 1, &p);
    let mut stats = PlanStats::default();
    let best = planner.run(p.samples, &p, &mut stats);
    let best = best.unwrap_or_else(|| panic!("no feasible plan: {stats:?}"));
    let stop = best.s.pos(best.duration);
    assert!(
        stop <= planner.start.s + 3.0 + 1e-6,
        "the plan goes {:.2} m, past the yield point",
        stop - planner.start.s
    );
}

#[test]
fn a_margin_longer_than_the_planners_search_for_passages_is_refused() {
    // The planner looks for a passage 47 steps (4.7 s at 0.1 s) before now and past its
    // horizon: a car that left its passage 4.9 s ago is not found, so a 5 s margin behind it
    // would end early.
    let mut p = Params::default();
    p.interaction.pet_behind_s = 4.7;
    assert!(p.validate().is_ok());
    p.interaction.pet_behind_s = 5.0;
    assert_eq!(p.validate().unwrap_err().key, "interaction.pet_behind_s");
    p.trajectory.dt_s = 0.125;
    p.trajectory.horizon_s = 5.0;
    assert!(p.validate().is_ok(), "47 steps of 0.125 s cover it");
    let mut q = Params::default();
    q.interaction.pet_go_s = 4.8;
    assert_eq!(q.validate().unwrap_err().key, "interaction.pet_go_s");
}

#[test]
fn the_margin_behind_ends_where_it_says_wherever_the_planners_steps_fall() {
    // The car above leaves its passage at 1 s, so the margin behind it ends at 1 s +
    // `pet_behind_s`. A candidate entering the ego's passage 10–85 ms after that is taken,
    // and one entering 10–85 ms before it refused, at every phase of the planner's 0.1 s
    // steps: where the steps fall used to add up to 0.3 s to the margin, so that a plan
    // passed and failed on alternate 50 ms cycles (each half a step apart), and a cycle
    // where none passed braked at the fallback's rate.
    let planner = before_a_crossing_car(0.0, -4.0, 8.0, [0.0, 8.0]);
    let (ip, p) = (Params::default().interaction, Params::default().trajectory);
    // From standing, a quartic to v over T with no acceleration at either end is at
    // v·T·(τ³ − τ⁴/2), τ = t/T: entering the passage, 4 m ahead, at τ = 0.9 when T = t/0.9.
    let entering_at = |t: f64| {
        let t_end = t / 0.9;
        let v = 4.0 / (t_end * (0.9f64.powi(3) - 0.5 * 0.9f64.powi(4)));
        planner.evaluate(t_end, v, 0.0, &p)
    };
    let end = 1.0 + ip.pet_behind_s;
    for offset in [0.01, 0.025, 0.04, 0.055, 0.07, 0.085] {
        let after = entering_at(end + offset);
        assert!(after.is_ok(), "{offset} s after: {after:?}");
        let before = entering_at(end - offset);
        assert!(
            matches!(before, Err(Reject::Collision(_))),
            "{offset} s before: {before:?}"
        );
    }
}

/// The paper's CAV `cav_before` m before its crossing with the HDV's lane at `cav_speed`
/// m/s (its centre relative to the start of its passage, the zone), the HDV `hdv_before` m
/// before its own passage at 10 m/s.
fn before_the_crossing(
    cav_before: f64,
    cav_speed: f64,
    hdv_before: f64,
) -> (Box<DecisionCore>, Scene) {
    let core = paper_core(Params::default());
    let m = *core.morphology();
    let c = m.conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT).unwrap();
    let (cav, h_cav, _) = m.lane(paper::CAV_LEFT).pose_at(c.zone_a[0] - cav_before, 0);
    let (hdv, h_hdv, _) = m
        .lane(paper::HDV_STRAIGHT)
        .pose_at(c.zone_b[0] - hdv_before, 0);
    let mut scene = Scene::new(
        0.0,
        AgentState::moving(0, cav, h_cav, cav_speed),
        paper::CAV_LEFT,
    );
    scene.push(AgentState::moving(1, hdv, h_hdv, 10.0));
    (core, scene)
}

#[test]
fn the_ehmi_says_going_first_only_when_the_plan_goes_before_the_other() {
    use concord_core::Announcement;
    // The HDV at its passage now, the CAV 25 m back at 8 m/s: whatever it does, it passes
    // behind, so it tells the HDV to go ahead, also when it does not slow down.
    let (mut core, scene) = before_the_crossing(25.0, 8.0, 1.0);
    let d = core.step(&scene, 0.0, None).unwrap();
    assert!(!d.maneuver.gives_way(), "{:?}", d.maneuver);
    assert_eq!(d.announce, Announcement::GivingWay, "{:?}", d.maneuver);
    // The CAV 3 m before its passage at 8 m/s, the HDV 30 m away: the CAV goes first.
    let (mut core, scene) = before_the_crossing(3.0, 8.0, 30.0);
    let d = core.step(&scene, 0.0, None).unwrap();
    assert_eq!(d.announce, Announcement::GoingFirst, "{:?}", d.maneuver);
}

#[test]
fn an_ego_that_crept_just_past_its_waiting_point_waits_there() {
    // Creeping at 0.1 m/s, the CAV's centre 0.6 m before its passage (0.4 m past the point
    // the stop margin puts 1 m before it), the HDV 8 m before its own: the CAV still has a
    // point to yield at, where it is, and waits (it does not take the zone in front of the
    // HDV as one it must clear).
    let (mut core, scene) = before_the_crossing(0.6, 0.1, 8.0);
    let d = core.step(&scene, 0.0, None).unwrap();
    assert_eq!(core.planner().yield_distance, 0.0);
    assert_eq!(d.source, concord_core::DecisionSource::Logit, "{d:?}");
    // The HDV clears its passage after about 1.9 s; the CAV keeps out of its own until then
    // and pet_behind_s after.
    let c = core
        .morphology()
        .conflict(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .unwrap();
    let wait = 1.9 + Params::default().interaction.pet_behind_s;
    for q in d.trajectory.points().iter().filter(|q| q.t <= wait) {
        assert!(
            q.s < c.zone_a[0],
            "at {} m after {} s, the zone from {} m",
            q.s,
            q.t,
            c.zone_a[0]
        );
    }
}

/// The choice of a moving ego on a free road (nothing to yield to, no leader) at `speed` m/s,
/// under `choice`, whose last 2 s were all `held` in the same state (eq. 12–14).
fn held_on_a_free_road(
    held: Maneuver,
    speed: f64,
    speed_cap: f64,
    goal_m: f64,
    choice: ChoiceParams,
) -> ChoiceOutcome {
    let p = Params {
        choice,
        ..Params::default()
    };
    let ctx = EgoContext {
        speed,
        speed_cap,
        yield_distance: f64::INFINITY,
        goal_distance: goal_m,
        route: concord_core::scene::Turn::Straight,
        max_brake: p.trajectory.max_brake_mps2,
        min_duration: p.trajectory.min_duration_s,
        max_duration: p.trajectory.max_duration_s,
        yield_check_s: p.trajectory.yield_check_s,
        ..EgoContext::default()
    };
    let triplet = OpmTriplet::default();
    let state = concord_core::choice::state_features(&triplet, &ctx, &p.opm, &p.choice);
    let mut history = ChoiceHistory::default();
    for k in 0..20 {
        history.record(0.1 * k as f64, state, held);
    }
    let mut out = ChoiceOutcome::default();
    choose(
        &triplet,
        &ConflictSet::of(&[]),
        &[],
        &ctx,
        &history,
        &p.opm,
        &p.interaction,
        &p.choice,
        &mut out,
    );
    out
}

/// The merge of highway-env's merge-v0 after the merging car has joined ahead: the ego, at
/// 11 m/s after slowing for it, has nothing left to yield to and no leader it would brake
/// for, on a road whose desired speed is 30 m/s; the history favours "decelerate".
fn after_the_merge(idle_penalty: f64) -> ChoiceOutcome {
    let choice = ChoiceParams {
        desired_speed_mps: 30.0,
        reference_speed_mps: 20.0,
        idle_penalty,
        ..ChoiceParams::default()
    };
    held_on_a_free_road(Maneuver::Decelerate, 11.0, 30.0, 100.0, choice)
}

#[test]
fn a_moving_ego_stops_slowing_once_nothing_holds_it_back() {
    let out = after_the_merge(ChoiceParams::default().idle_penalty);
    assert_ne!(out.choice, Maneuver::Decelerate, "{:?}", out.p_corrected);
    // Only "decelerate" slows it: the maneuvers that keep or gain speed are not penalised.
    let free = after_the_merge(0.0);
    for m in [Maneuver::Accelerate, Maneuver::KeepSpeed] {
        assert_eq!(out.utility[m.index()], free.utility[m.index()], "{m:?}");
    }
    assert!(out.utility[Maneuver::Decelerate.index()] < free.utility[Maneuver::Decelerate.index()]);
    // Without the penalty the history holds it in "decelerate", which takes it to a standstill.
    assert_eq!(free.choice, Maneuver::Decelerate, "{:?}", free.p_corrected);
}

#[test]
fn a_car_that_has_left_its_passage_holds_the_margin_behind_it_until_it_has_run_out() {
    let ip = InteractionParams::default();
    // It left its passage 3.3 m ago at 6.6 m/s: 0.5 s ago.
    let left = pair([0.0, 0.0], [-13.3, -3.3], 6.6);
    let (enter, exit) = concord_core::choice::proceeding_interval(&left, &ip);
    assert!(
        (exit + 0.5).abs() < 1e-9 && (enter + 13.3 / 6.6).abs() < 1e-9,
        "{enter} {exit}"
    );
    // Entering at 0.8 s is 1.3 s behind it, short of pet_behind_s (1.8 s); at 1.4 s, 1.9 s.
    let at = |d: f64| {
        conflict_risk(
            &keep(10.0),
            10.0,
            &pair([d, d + 10.0], [-13.3, -3.3], 6.6),
            0.0,
            &ip,
        )
    };
    assert!(at(8.0) > 0.01, "{}", at(8.0));
    assert_eq!(at(14.0), 0.0);

    // In the core: the paper's HDV 1 m past its passage at 8 m/s (0.125 s ago) is still a
    // conflict, though no longer a risky one (its TTC is 0, the ego's 2.5 s: ΔTTC is below
    // ΔT_th); 16 m past (2 s ago, more than pet_behind_s), none.
    // The conflict with the paper's HDV `before` m before the crossing at 8 m/s, the CAV 20 m
    // before it at 8 m/s.
    let conflict_at = |before: f64| {
        let mut core = paper_core(Params::default());
        let cav = before_the_paper_crossing(0, paper::CAV_LEFT, 20.0, 8.0);
        let mut scene = Scene::new(0.0, cav, paper::CAV_LEFT);
        scene.push(before_the_paper_crossing(
            1,
            paper::HDV_STRAIGHT,
            before,
            8.0,
        ));
        core.step(&scene, 0.0, None).unwrap();
        core.conflicts().pairs().first().copied()
    };
    // Where the HDV leaves its passage, as a distance before the crossing, seen from 20 m
    // before it.
    let pass_exit = 20.0
        - conflict_at(20.0)
            .expect("a conflict before the crossing")
            .agent_pass_m[1];
    let past = |beyond: f64| conflict_at(pass_exit - beyond);
    let just_left = past(1.0).expect("still in conflict 0.125 s after it left");
    assert!((just_left.agent_pass_m[1] + 1.0).abs() < 1e-6);
    assert!(!just_left.is_risky(&OpmParams::default()));
    assert!(past(16.0).is_none());
}

/// `held_on_a_free_road` at the defaults (desired speed 13.9 m/s) with `idle_penalty`.
fn held_in(held: Maneuver, speed: f64, idle_penalty: f64) -> ChoiceOutcome {
    let choice = ChoiceParams {
        idle_penalty,
        ..ChoiceParams::default()
    };
    held_on_a_free_road(held, speed, 13.9, 50.0, choice)
}

#[test]
fn an_ego_creeping_with_nothing_to_wait_for_speeds_up() {
    // At 0.5 m/s "keep speed" is a creep (below creep_speed_mps, 1 m/s): penalised like a
    // wait, so the history no longer holds it there.
    let crawl = held_in(
        Maneuver::KeepSpeed,
        0.5,
        ChoiceParams::default().idle_penalty,
    );
    assert_ne!(crawl.choice, Maneuver::KeepSpeed, "{:?}", crawl.p_corrected);
    let held = held_in(Maneuver::KeepSpeed, 0.5, 0.0);
    assert_eq!(held.choice, Maneuver::KeepSpeed, "{:?}", held.p_corrected);
    // At 8 m/s keeping speed is driving, not waiting: not penalised.
    let driving = held_in(
        Maneuver::KeepSpeed,
        8.0,
        ChoiceParams::default().idle_penalty,
    );
    let free = held_in(Maneuver::KeepSpeed, 8.0, 0.0);
    let k = Maneuver::KeepSpeed.index();
    assert_eq!(driving.utility[k], free.utility[k]);
}

#[test]
fn a_crawl_that_passes_behind_everyone_does_not_make_the_way_free() {
    // At 1.2 m/s, 20 m before its passage, with a car arriving at its own: holding the crawl
    // passes behind it, speeding up or turning does not. That is no reason to stop waiting:
    // "decelerate" is not penalised.
    let c = pair([20.0, 30.0], [20.0, 30.0], 8.0);
    let judged = |idle_penalty: f64| {
        let p = Params {
            choice: ChoiceParams {
                idle_penalty,
                ..ChoiceParams::default()
            },
            ..Params::default()
        };
        choose_with_params(&[c], &[0.0], 1.2, 19.0, &p)
    };
    let with = judged(ChoiceParams::default().idle_penalty);
    let without = judged(0.0);
    let (k, d) = (Maneuver::KeepSpeed.index(), Maneuver::Decelerate.index());
    assert_eq!(with.safety[k], 1.0, "the crawl passes behind");
    assert!(with.safety[Maneuver::TurnLeft.index()] < 0.99);
    assert_eq!(with.utility[d], without.utility[d]);
}

/// The CAV at 8 m/s on the paper's left turn behind a car that brakes at 2.5 m/s² from 6 m/s,
/// 21 m ahead at 0 s, whose source reports no acceleration (exactly 0, as highway-env's
/// observations): scenes every 0.1 s up to 1 s, when the car is at 3.5 m/s, 16.25 m ahead.
/// Returns the core, the last scene and where the car then stops, m along the lane.
fn behind_a_leader_braking_unreported() -> (Box<DecisionCore>, Scene, f64) {
    let mut core = paper_core(Params::default());
    let m = *core.morphology();
    let lane = *m.lane(paper::CAV_LEFT);
    let (s_cross, _) = m
        .conflict_between(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .unwrap();
    let s0 = s_cross - 45.0;
    let at = |t: f64| {
        let (ego, h, _) = lane.pose_at(s0 + 8.0 * t, 0);
        let leader_s = s0 + 21.0 + 6.0 * t - 1.25 * t * t;
        let (car, hc, _) = lane.pose_at(leader_s, 0);
        let mut scene = Scene::new(t, AgentState::moving(0, ego, h, 8.0), paper::CAV_LEFT);
        scene.push(AgentState::moving(1, car, hc, 6.0 - 2.5 * t));
        (scene, leader_s)
    };
    for k in 0..10 {
        let t = k as f64 * 0.1;
        core.step(&at(t).0, t, None).unwrap();
    }
    let (scene, leader_s) = at(1.0);
    (core, scene, leader_s + 3.5 * 3.5 / 5.0)
}

#[test]
fn a_leader_whose_source_reports_no_acceleration_is_forecast_at_its_speed_trend() {
    let (mut core, scene, _) = behind_a_leader_braking_unreported();
    core.step(&scene, 1.0, None).unwrap();
    let f = core.forecasts()[0];
    assert!((f.accel + 2.5).abs() < 0.05, "{f:?}");
    assert!((f.stop_distance(3.5) - 2.45).abs() < 0.05, "{f:?}");
    // A trend's speeding up is not extrapolated; a reported acceleration is taken as is.
    let mut h = History::default();
    for k in 0..=10 {
        let t = k as f64 * 0.1;
        h.record(
            t,
            &[AgentState::moving(
                7,
                Vec2::new(0.0, 0.0),
                0.0,
                5.0 + 2.0 * t,
            )],
        );
    }
    let mut car = AgentState::moving(7, Vec2::new(0.0, 0.0), 0.0, 7.0);
    assert_eq!(current_accel(&car, h.track(7), 1.0), 0.0);
    car.acc = Vec2::new(1.5, 0.0);
    assert_eq!(current_accel(&car, h.track(7), 1.0), 1.5);
    let braking = Forecast {
        accel: -5.0,
        ..Forecast::default()
    };
    assert!((braking.stop_distance(5.0) - 2.5).abs() < 1e-12);
    assert!(Forecast::default().stop_distance(5.0).is_infinite());
    assert_eq!(braking.stop_distance(0.0), 0.0);
    let yielding = Forecast {
        stop_in_m: 3.0,
        ..braking
    };
    assert_eq!(yielding.stop_distance(5.0), 3.0);
}

#[test]
fn decelerating_behind_a_leader_that_brakes_to_a_stop_stops_behind_it() {
    let (mut core, mut scene, leader_stop) = behind_a_leader_braking_unreported();
    let p = Params::default();
    let t = &p.trajectory;
    let d = core.step(&scene, 1.0, None).unwrap();
    let start = d.trajectory.points()[0].s;
    // "decelerate" stops the car length and the stop margin behind where the leader stops.
    let stop = core.choice().profiles[Maneuver::Decelerate.index()].stop_m;
    let expected = leader_stop - t.vehicle_length_m - t.stop_margin_m - start;
    assert!((stop - expected).abs() < 0.2, "{stop} vs {expected}");
    assert_eq!(d.source, concord_core::DecisionSource::Logit, "{d:?}");
    assert_eq!(d.maneuver, Maneuver::Decelerate);
    // The plan stays behind it, and can still stop behind it at the horizon.
    let end = d.trajectory.points().last().unwrap();
    let stops_at = end.s + end.speed * end.speed / (2.0 * p.choice.decelerate_mps2);
    assert!(
        stops_at <= leader_stop - t.vehicle_length_m,
        "{end:?}, {leader_stop}"
    );
    // Far behind the same leader, the ego has time to slow: no stop is planned yet.
    let (ego, h, _) = core
        .morphology()
        .lane(paper::CAV_LEFT)
        .pose_at(start - 40.0, 0);
    scene.ego = AgentState::moving(0, ego, h, 8.0);
    core.step(&scene, 1.0, None).unwrap();
    assert!(core.choice().profiles[Maneuver::Decelerate.index()]
        .stop_m
        .is_infinite());
}

#[test]
fn the_fallback_takes_the_drive_on_that_postpones_contact_longest_the_first_among_equals() {
    // The ego's footprint in the crossing car's path (as in the test above): creeping on at
    // 1 m/s is hit about when braking is, which inside the junction still beats standing, but
    // driving off at 5 or 10 m/s is hit by nothing: the fallback takes the later contact, and
    // of two without any, the first (gentler) profile.
    let (creep, brisk, fast) = (drive_on(0.5, 1.0), drive_on(2.0, 5.0), drive_on(3.0, 10.0));
    let taken = |profiles: &[Profile]| {
        let (x, car) = beside_a_passing_car(-0.3, 4.0);
        fallback_standing_at(x, &car, profiles)
    };
    let (k, hit) = taken(&[creep]);
    assert_eq!(k, Some(0));
    assert!(hit.is_some(), "creeping is hit too");
    assert_eq!(taken(&[creep, fast]), (Some(1), None));
    assert_eq!(taken(&[brisk, fast]), (Some(0), None));
}

#[test]
fn outside_the_junction_the_fallback_brakes_rather_than_meet_an_oncoming_car_sooner() {
    // A car coming head-on along the ego's lane at 8 m/s, 20 m away: braking is hit at about
    // 1.9 s, creeping on a little sooner. Before the stop line and past the crossing, braking
    // stands; inside the junction, where standing blocks the crossing lane, the ego drives on
    // (its own hit is within DRIVE_ON_STEPS of the braking's).
    let taken = |x: f64| {
        let car = AgentState::moving(1, Vec2::new(x + 20.0, 0.0), core::f64::consts::PI, 8.0);
        let (k, hit) = fallback_standing_at(x, &[car], &[drive_on(0.5, 1.0)]);
        (k, hit.is_some())
    };
    assert_eq!(taken(-30.0), (None, true), "before the stop line");
    assert_eq!(taken(20.0), (None, true), "past the crossing");
    assert_eq!(taken(-3.0).0, Some(0), "inside the junction");
}

#[test]
fn the_post_encroachment_check_is_its_definition_on_the_step_grid() {
    // The ego rolling at 8 m/s towards its passage (4–16 m ahead), a car crossing after it
    // whose margin keeps the ego out of the passage from 2.5 s on: each of 9600 candidates,
    // braking or not, is refused exactly when it is in the passage at some moment of the
    // margin's window, the moments between steps interpolated (entering and leaving where the
    // straight line between two steps crosses the passage's ends, the step that crosses the
    // end deciding, not a line from the step before). Some are refused only by that
    // interpolation: at no step inside after the window opens, out less than 10 ms after it.
    let p = Params::default().trajectory;
    let planner = before_a_crossing_car(8.0, -40.0, 8.0, [36.0, 44.0]);
    let m = planner.margins()[0];
    let (dt, steps) = (p.dt_s, (p.horizon_s / p.dt_s).round() as usize);
    let s0 = planner.start.s;
    let (mut refused, mut kept, mut at_the_edge) = (0, 0, 0);
    for i in 0..400 {
        for j in 0..24 {
            let (t_end, v_end) = (1.0 + 0.01 * i as f64, 0.5 * j as f64);
            let q = concord_core::trajectory::Quartic::fit(s0, 8.0, 0.0, v_end, 0.0, t_end);
            let s_at = |t: f64| {
                if t <= t_end {
                    q.pos(t)
                } else {
                    q.pos(t_end) + v_end * (t - t_end)
                }
            };
            let (mut enters, mut leaves, mut inside_late) = (f64::INFINITY, f64::INFINITY, false);
            let (mut prev_t, mut prev_s) = (0.0, s0);
            for k in 1..=steps {
                let t = k as f64 * dt;
                let s = s_at(t);
                let at = |x: f64| prev_t + (x - prev_s) / (s - prev_s) * (t - prev_t);
                if prev_s < m.s[0] && s >= m.s[0] {
                    enters = at(m.s[0]);
                }
                if prev_s < m.s[1] && s >= m.s[1] && enters.is_finite() {
                    leaves = at(m.s[1]);
                    inside_late |= prev_t > m.t[0];
                }
                (prev_t, prev_s) = (t, s);
            }
            let last = steps as f64 * dt;
            let violates = enters < m.t[1] && leaves.min(last) > m.t[0];
            match planner.evaluate(t_end, v_end, 0.0, &p) {
                Err(Reject::Collision(_)) => {
                    assert!(
                        violates,
                        "T {t_end} v {v_end}: in at {enters}, out at {leaves}, {m:?}"
                    );
                    refused += 1;
                    if leaves.is_finite() && !inside_late && leaves - m.t[0] < 0.01 {
                        at_the_edge += 1;
                    }
                }
                Ok(_) => {
                    assert!(
                        !violates,
                        "T {t_end} v {v_end}: in at {enters}, out at {leaves}, {m:?}"
                    );
                    kept += 1;
                }
                Err(_) => {}
            }
        }
    }
    assert!(
        refused > 0 && kept > 0 && at_the_edge > 0,
        "refused {refused}, kept {kept}, at the edge {at_the_edge}"
    );
}
