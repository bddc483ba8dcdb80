//! The choice stage's formulas (eq. 9–15 and the interaction terms of `choice`) against
//! hand-computed values: profiles, preferences, occupancy margins, imposed braking,
//! efficiency, the expected wait, the scene state and the history.
use concord_core::choice::{
    choose, conflict_risk, cosine, efficiency, expected_wait, idm_follower_decel, imposed_decel,
    preferences, proceeding_interval, profile, state_features, toward, ChoiceHistory,
    ChoiceOutcome, EgoContext, Maneuver, Profile, STATE_FEATURES,
};
use concord_core::intent::{ImplicitIntent, Stated};
use concord_core::opm::{ConflictPair, ConflictSet, IntentPair, Leader, OpmTriplet};
use concord_core::params::{ChoiceParams, Follower, InteractionParams, OpmParams};
use concord_core::scene::{ConflictKind, ExplicitIntent, IntentAction, Rated, Style, Task, Turn};

const EPS: f64 = 1e-9;

fn close(got: f64, want: f64) {
    assert!((got - want).abs() < EPS, "got {got}, want {want}");
}

/// Holding `v` m/s.
fn keep(v: f64) -> Profile {
    Profile {
        target_speed: v,
        duration: 3.0,
        ..Profile::default()
    }
}

/// A conflict with the ego's passage at `ego` and the other's at `other` (distances from
/// their centres, m), the other at `v` m/s, 2 s from its point.
fn pair(ego: [f64; 2], other: [f64; 2], v: f64) -> ConflictPair {
    ConflictPair {
        ego_pass_m: ego,
        agent_pass_m: other,
        ego_zone_m: ego,
        agent_zone_m: other,
        agent_speed_mps: v,
        agent_ttc_s: 2.0,
        ..ConflictPair::default()
    }
}

/// Planning bounds wide enough that no clamp hides a duration.
fn wide(speed: f64) -> EgoContext {
    EgoContext {
        speed,
        speed_cap: 20.0,
        yield_distance: f64::INFINITY,
        goal_distance: 30.0,
        max_brake: 6.0,
        min_duration: 1.0,
        max_duration: 20.0,
        yield_check_s: 1.0,
        ..EgoContext::default()
    }
}

#[test]
fn a_profile_ramps_to_its_target_speed_and_holds_it() {
    // From 2 m/s at +2 m/s² towards 6 m/s: 2 s of ramp.
    let up = Profile {
        accel: 2.0,
        target_speed: 6.0,
        ..keep(6.0)
    };
    close(up.speed_at(2.0, 0.5), 3.0);
    close(up.speed_at(2.0, 1.5), 5.0);
    close(up.speed_at(2.0, 2.0), 6.0);
    close(up.speed_at(2.0, 3.0), 6.0);
    // Already above its target: at the target at once.
    close(up.speed_at(8.0, 0.5), 6.0);
    // From 6 m/s at −2 m/s² towards 2 m/s: 2 s of ramp.
    let down = Profile {
        accel: -2.0,
        target_speed: 2.0,
        ..keep(2.0)
    };
    close(down.speed_at(6.0, 1.0), 4.0);
    close(down.speed_at(6.0, 2.5), 2.0);
    // No acceleration: the start speed, whatever the target says.
    let flat = keep(2.0);
    close(flat.speed_at(4.0, 1.0), 4.0);
    close(flat.speed_at(4.0, 10.0), 4.0);
}

#[test]
fn toward_a_far_target_lasts_its_whole_ramp() {
    let p = ChoiceParams {
        accelerate_mps2: 2.0,
        decelerate_mps2: 2.0,
        maneuver_horizon_s: 3.0,
        ..ChoiceParams::default()
    };
    // 2 → 12 m/s at 2 m/s²: 5 s, longer than the 3 s horizon.
    let up = toward(12.0, &wide(2.0), &p);
    close(up.accel, 2.0);
    close(up.target_speed, 12.0);
    close(up.duration, 5.0);
    // 14 → 0 m/s at 2 m/s²: 7 s.
    let down = toward(0.0, &wide(14.0), &p);
    close(down.accel, -2.0);
    close(down.duration, 7.0);
    // A short ramp lasts the horizon; none at all, too.
    close(toward(3.0, &wide(2.0), &p).duration, 3.0);
    let hold = toward(5.0, &wide(5.0), &p);
    close(hold.accel, 0.0);
    close(hold.duration, 3.0);
}

#[test]
fn decelerate_approaches_stops_or_slows_by_where_its_yield_point_is() {
    // decelerate 2 m/s², horizon 3 s, desired 13.9 m/s
    let p = ChoiceParams::default();
    let at = |v0: f64, d: f64, max_duration: f64| {
        let ctx = EgoContext {
            yield_distance: d,
            max_duration,
            ..wide(v0)
        };
        profile(Maneuver::Decelerate, &ctx, &p)
    };
    // Slower than the approach speed 20 m ahead: v_a·τ + v_a²/2b = 20 with τ = 1 s, b = 2:
    // v_a = 2(√21 − 1).
    let approach = at(4.0, 20.0, 20.0);
    close(approach.target_speed, 2.0 * (21f64.sqrt() - 1.0));
    close(approach.accel, p.accelerate_mps2);
    close(approach.stop_m, 20.0);
    // Faster than the approach speed but too far for one stopping polynomial (2d = 120 m
    // against 15 m/s × 5 s): approach at v_a = 2(√61 − 1).
    let far = at(15.0, 60.0, 5.0);
    close(far.target_speed, 2.0 * (61f64.sqrt() - 1.0));
    close(far.stop_m, 60.0);
    // Within reach: stop there, braking v²/2d on average over T = 2d/v.
    let stop = at(10.0, 15.0, 20.0);
    close(stop.target_speed, 0.0);
    close(stop.accel, -100.0 / 30.0);
    close(stop.duration, 3.0);
    close(stop.stop_m, 15.0);
    // A longer check time τ = 2 s, 12 m ahead: 2v_a + v_a²/4 = 12, v_a = 2(√16 − 2) = 4.
    let slow_check = profile(
        Maneuver::Decelerate,
        &EgoContext {
            yield_distance: 12.0,
            yield_check_s: 2.0,
            ..wide(1.0)
        },
        &p,
    );
    close(slow_check.target_speed, 4.0);
    // Exactly at the approach speed (3 m ahead: v_a = 2(√4 − 1) = 2): a stop, not an approach.
    close(at(2.0, 3.0, 20.0).target_speed, 0.0);
    // Exactly reachable with one stopping polynomial (2d = 30 m = 10 m/s × 3 s): a stop.
    let reach = at(10.0, 15.0, 3.0);
    close(reach.target_speed, 0.0);
    close(reach.duration, 3.0);
    // Exactly `CREEP_FROM_M` (1 m) short of the point is near it: a stop, not an approach.
    let near = at(0.5, 1.0, 20.0);
    close(near.target_speed, 0.0);
    close(near.stop_m, 1.0);
    close(near.duration, 4.0);
    // At 0.1 m/s or slower the stop takes the shortest duration.
    close(at(0.1, 0.5, 20.0).duration, 1.0);
    // Nothing to stop for, or already at the point: slow at the nominal rate over the horizon.
    for d in [f64::INFINITY, 0.0] {
        let slow = at(10.0, d, 20.0);
        close(slow.target_speed, 10.0 - 2.0 * 3.0);
        close(slow.accel, -2.0);
        assert!(!slow.yields(), "{d}: {slow:?}");
    }
}

fn rated<T>(value: T) -> Option<Rated<T>> {
    Some(Rated {
        value,
        confidence: 0.9,
    })
}

#[test]
fn each_stated_intent_adds_its_own_gain_to_its_own_preference() {
    let opm = OpmParams::default();
    // Distinct gains, so that each term is seen in the sums.
    let p = ChoiceParams {
        ego_style_safety: [0.11, 0.13, 0.17],
        ego_style_efficiency: [0.19, 0.23, 0.29],
        ego_task_efficiency: [0.31, 0.37, 0.41, 0.43],
        ego_hurry_efficiency: 0.47,
        other_task_safety: [0.53, 0.59, 0.61, 0.67],
        other_aggressive_safety: 0.71,
        other_proceeds_safety: 0.73,
        other_yields_efficiency: 0.79,
        conflict_intensity_safety: 0.83,
        ..ChoiceParams::default()
    };
    let mut triplet = OpmTriplet {
        ego_intent: ExplicitIntent {
            style: rated(Style::Conservative),
            action: rated(IntentAction::Proceed),
            task: rated(Task::Emergency),
        },
        ..OpmTriplet::default()
    };
    triplet.intents[0] = IntentPair {
        agent: 1,
        intent: ExplicitIntent {
            style: rated(Style::Aggressive),
            action: rated(IntentAction::Yield),
            task: rated(Task::Official),
        },
    };
    triplet.n_intents = 1;
    let conflicts = ConflictSet::of(&[ConflictPair {
        agent: 1,
        ..ConflictPair::default()
    }]);
    let (ws, we) = preferences(&triplet, &conflicts, &opm, &p);
    close(ws, 1.0 + 0.17 + 0.61 + 0.71);
    close(we, 1.0 + 0.29 + 0.37 + 0.47 + 0.79);
    // The other proceeding instead, a balanced commuting ego that asks nothing.
    triplet.ego_intent = ExplicitIntent {
        style: rated(Style::Balanced),
        action: None,
        task: rated(Task::Commute),
    };
    triplet.intents[0].intent = ExplicitIntent {
        action: rated(IntentAction::Proceed),
        ..ExplicitIntent::UNKNOWN
    };
    let (ws, we) = preferences(&triplet, &conflicts, &opm, &p);
    close(ws, 1.0 + 0.13 + 0.73);
    close(we, 1.0 + 0.23 + 0.31);
}

#[test]
fn a_road_user_that_cannot_speed_up_is_timed_at_its_speed() {
    // With no acceleration to assume, 30 m at 10 m/s take 3 s to enter, 40 m 4 s to leave.
    let ip = InteractionParams {
        proceed_accel_mps2: 0.0,
        ..InteractionParams::default()
    };
    let (t_in, t_out) = proceeding_interval(&pair([0.0, 1.0], [30.0, 40.0], 10.0), &ip);
    close(t_in, 3.0);
    close(t_out, 4.0);
}

#[test]
fn the_risk_of_a_short_margin_is_the_gaussian_of_its_shortfall_times_the_share_that_goes_on() {
    // pet_go 2 s (σ = 1 s), pet_behind 1.8 s
    let ip = InteractionParams::default();
    // The other at the top speed, 14 m/s, occupies [1, 2] s; the ego at 10 m/s [3, 4] s.
    let c = pair([30.0, 40.0], [14.0, 28.0], 14.0);
    let (a_in, a_out) = proceeding_interval(&c, &ip);
    close(a_in, 1.0);
    close(a_out, 2.0);
    // Behind by 1 s: 0.8 s short of pet_behind_s; going first would be 5 s short.
    let r = 1.0 - (-0.8f64 * 0.8 / 2.0).exp();
    close(conflict_risk(&keep(10.0), 10.0, &c, 0.0, &ip), r);
    close(conflict_risk(&keep(10.0), 10.0, &c, 0.25, &ip), 0.75 * r);
    // With pet_go_s 4 s, σ is 2 s.
    let wider = InteractionParams {
        pet_go_s: 4.0,
        ..ip
    };
    close(
        conflict_risk(&keep(10.0), 10.0, &c, 0.0, &wider),
        1.0 - (-0.8f64 * 0.8 / 8.0).exp(),
    );
}

#[test]
fn going_first_imposes_the_braking_that_keeps_the_other_behind_and_nothing_when_it_is_first() {
    // reaction 0.5 s, pet_behind 1.8 s, trust 0.8
    let ip = InteractionParams::default();
    // The ego at 10 m/s crosses its passage [5, 10] m in [0.5, 1] s; the other at 10 m/s is
    // 20 m from its passage. After 0.5 s it has D = 15 m and T = 1 + 1.8 − 0.5 = 2.3 s:
    // b = 2(vT − D)/T².
    let c = pair([5.0, 10.0], [20.0, 30.0], 10.0);
    let b = 2.0 * (10.0 * 2.3 - 15.0) / (2.3 * 2.3);
    close(imposed_decel(&keep(10.0), 10.0, &c, 0.0, &ip), b);
    // One already yielding (at least trust_yield) is imposed only what it does not brake
    // already.
    let yielding = ConflictPair {
        intent: ImplicitIntent {
            required_decel_mps2: 1.0,
            ..ImplicitIntent::default()
        },
        ..c
    };
    close(
        imposed_decel(&keep(10.0), 10.0, &yielding, 0.9, &ip),
        b - 1.0,
    );
    close(imposed_decel(&keep(10.0), 10.0, &yielding, 0.5, &ip), b);
    // The other 3 m from its passage: it would be there first (enter 0.29 s, leave 0.6 s,
    // against the ego's 0.4 and 0.8 s): nothing is imposed, the risk speaks.
    let first = pair([4.0, 8.0], [3.0, 6.0], 10.0);
    assert_eq!(imposed_decel(&keep(10.0), 10.0, &first, 0.0, &ip), 0.0);
    assert!(conflict_risk(&keep(10.0), 10.0, &first, 0.0, &ip) > 0.5);
    // The ego leaving its passage as the other, 3 m from its own, reacts: it cannot stop.
    let late = pair([-3.0, 0.5], [3.0, 6.0], 10.0);
    assert!(imposed_decel(&keep(10.0), 10.0, &late, 0.0, &ip).is_infinite());
}

#[test]
fn an_idm_follower_closing_on_a_slower_ego_that_merged_ahead_brakes_once_it_has_closed_in() {
    let ip = InteractionParams {
        follower: Follower::Idm,
        ..InteractionParams::default()
    };
    // The ego merges 60 m ahead of the other at 6 m/s and drives on for 10 s; the other at
    // 10 m/s first sees a free gap (the IDM does not brake) and brakes once it has closed in.
    let merge = ConflictPair {
        kind: ConflictKind::Merging,
        ..pair([0.0, 100.0], [60.0, 160.0], 10.0)
    };
    let slow = keep(6.0);
    let worst = idm_follower_decel(&slow, 6.0, &merge, (0.0, 10.0), &ip);
    let idm = concord_core::choice::Idm {
        max_accel_mps2: ip.follower_max_accel_mps2,
        comfort_decel_mps2: ip.follower_comfort_decel_mps2,
        min_gap_m: ip.follower_min_gap_m,
        headway_s: ip.follower_headway_s,
        desired_speed_mps: ip.proceed_top_speed_mps,
    };
    assert!(idm.accel(10.0, 60.0, 4.0) > 0.0, "no braking at first");
    assert!(worst > 0.3, "{worst}");
    // The ego as fast as the other keeps the gap: hardly any braking.
    let same = idm_follower_decel(&keep(10.0), 10.0, &merge, (0.0, 10.0), &ip);
    assert!(same < 0.5 * worst, "{same} against {worst}");
    // A standing ego across its lane 15 m ahead for 1 s: the first look brakes hardest, and the
    // other stops well short of it.
    let cross = pair([0.0, 5.0], [15.0, 20.0], 8.0);
    let first = -idm.accel(8.0, 15.0, 8.0);
    let hardest = idm_follower_decel(&keep(0.0), 0.0, &cross, (0.0, 1.0), &ip);
    assert!(hardest.is_finite(), "{hardest}");
    assert!(
        hardest >= first - EPS && hardest < first + 3.0,
        "{hardest}, first {first}"
    );
}

#[test]
fn the_efficiency_of_a_yield_counts_the_wait_and_the_restart_and_is_full_at_the_goal() {
    // reference 10 m/s, accelerate 1.5 m/s²
    let p = ChoiceParams::default();
    let ctx = EgoContext {
        yield_distance: 10.0,
        goal_distance: 30.0,
        speed_cap: 10.0,
        ..wide(5.0)
    };
    let stop = Profile {
        accel: -1.25,
        target_speed: 0.0,
        duration: 3.0,
        stop_m: 10.0,
    };
    // Waits 5 s (longer than its 3 s stop), then 20 m from rest at 1.5 m/s² (within the ramp
    // to 10 m/s): √(2·20/1.5) s. Free: 30 m at 10 m/s, 3 s.
    let taken = 5.0 + (40.0f64 / 1.5).sqrt();
    close(efficiency(&stop, &ctx, 5.0, &p), 3.0 / taken);
    // At the goal there is nothing left to take time: the largest efficiency.
    let there = EgoContext {
        goal_distance: 0.0,
        ..ctx
    };
    close(efficiency(&keep(5.0), &there, 0.0, &p), 1.5);
}

#[test]
fn the_expected_wait_is_the_longest_of_the_arriving_road_users_whose_passage_is_ahead() {
    let opm = OpmParams::default();
    // deadlock_wait 5 s
    let ip = InteractionParams::default();
    // Leaves at the latest at 30 m / 10 m/s = 3 s.
    let arriving = pair([5.0, 10.0], [20.0, 30.0], 10.0);
    let (_, a_out) = proceeding_interval(&arriving, &ip);
    close(a_out, 3.0);
    // A passage the ego is already in, or exactly at, and road users at or beyond the TTC
    // cap, count for nothing, however long they would take.
    let slow = [200.0, 300.0];
    let entered = pair([-1.0, 3.0], slow, 10.0);
    let at_entry = pair([0.0, 3.0], slow, 10.0);
    let far = ConflictPair {
        agent_ttc_s: opm.ttc_max_s + 1.0,
        ..pair([5.0, 10.0], slow, 10.0)
    };
    let at_cap = ConflictPair {
        agent_ttc_s: opm.ttc_max_s,
        ..far
    };
    let wait = expected_wait(
        &[entered, arriving, at_entry, far, at_cap],
        &[0.0, 0.25, 0.0, 0.0, 0.0],
        &opm,
        &ip,
    );
    close(wait, 0.75 * 3.0 + 0.25 * 5.0);
}

#[test]
fn the_scene_state_places_a_passed_conflict_and_counts_the_risky_ones() {
    let opm = OpmParams::default();
    let p = ChoiceParams::default();
    let mut triplet = OpmTriplet::default();
    // One risky conflict whose point the ego passed 5 m ago (|ΔTTC| 1 s), no leader.
    triplet.conflicts[0] = ConflictPair {
        ego_dist_m: -5.0,
        delta_ttc_s: 1.0,
        ego_ttc_s: 1.0,
        agent_ttc_s: 2.0,
        agent_zone_m: [3.0, 8.0],
        ..ConflictPair::default()
    };
    triplet.n_conflicts = 1;
    let ctx = EgoContext {
        accel: 1.5,
        ..wide(5.0)
    };
    let x = state_features(&triplet, &ctx, &opm, &p);
    let want: [f64; STATE_FEATURES] = [
        5.0 / 10.0 - 1.0,
        1.5 / 3.0,
        1.0 / opm.delta_ttc_threshold_s - 0.5,
        -5.0 / 25.0 - 1.0,
        50.0 / 25.0 - 1.0,
        1.0 / 2.0 - 0.5,
    ];
    for (got, want) in x.iter().zip(want) {
        close(*got, want);
    }
}

#[test]
fn the_history_samples_every_tenth_of_a_second_and_keeps_each_maneuvers_closest_state() {
    let mut h = ChoiceHistory::default();
    let s = |a: f64, b: f64| [a, b, 0.0, 0.0, 0.0, 0.0];
    h.record(0.0, s(-1.0, 0.0), Maneuver::KeepSpeed);
    h.record(0.05, s(0.0, 1.0), Maneuver::Decelerate);
    h.record(0.1, s(0.0, 1.0), Maneuver::KeepSpeed);
    h.record(0.2, s(-1.0, 0.0), Maneuver::Accelerate);
    assert_eq!(h.records().len(), 3, "{:?}", h.records());
    assert_eq!(h.previous, Some(Maneuver::Accelerate));
    // Keep speed was executed in states at 135° and then 45° from the query: the closer
    // counts. Accelerate only at 135°: its similarity is −√½, not "never".
    let d = h.d_prev(&s(1.0, 1.0));
    close(d[Maneuver::KeepSpeed.index()], 0.5f64.sqrt());
    close(d[Maneuver::Accelerate.index()], -(0.5f64.sqrt()));
    close(d[Maneuver::Decelerate.index()], 0.0);
}

#[test]
fn cosine_similarity_of_unequal_vectors_and_of_a_zero_one() {
    let a = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
    let b = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    close(cosine(&a, &b), 0.5f64.sqrt());
    close(cosine(&a, &[0.0; STATE_FEATURES]), 0.0);
    close(cosine(&[0.0; STATE_FEATURES], &b), 0.0);
}

/// The choice stage for one conflict with `yields` 0, the given context, nothing stated, no
/// history.
fn choose_one(
    conflicts: &[ConflictPair],
    triplet: &OpmTriplet,
    ctx: &EgoContext,
    p: &ChoiceParams,
) -> ChoiceOutcome {
    let set = ConflictSet::of(conflicts);
    let yields = [0.0; 8];
    let mut out = ChoiceOutcome::default();
    choose(
        triplet,
        &set,
        &yields[..conflicts.len()],
        ctx,
        &ChoiceHistory::default(),
        &OpmParams::default(),
        &InteractionParams::default(),
        p,
        &mut out,
    );
    out
}

#[test]
fn a_maneuver_that_goes_is_judged_at_the_slower_timing_that_lets_the_other_pass_first() {
    let p = ChoiceParams::default();
    // The ego at 10 m/s (its cap) is 20 m from its passage; the other at 10 m/s leaves its
    // own at 2 s at the latest. Keeping 10 m/s enters at 2 s (1.8 s short of the margin
    // behind); at 0.6 × 10 m/s it enters at 2.67 s (1.13 s short), which outweighs the
    // efficiency it costs.
    let c = pair([20.0, 28.0], [12.0, 20.0], 10.0);
    let ctx = EgoContext {
        speed_cap: 10.0,
        yield_distance: 14.0,
        goal_distance: 28.0,
        ..wide(10.0)
    };
    let out = choose_one(&[c], &OpmTriplet::default(), &ctx, &p);
    let k = Maneuver::KeepSpeed.index();
    close(out.profiles[k].target_speed, 6.0);
    let r = 1.0 - (-(1.8f64 - 2.0 / 3.0).powi(2) / 2.0).exp();
    close(out.safety[k], 1.0 - r);
    // Each attribute is its degree times its preference, and the utility is βᵀx (eq. 9).
    for i in 0..5 {
        let x = out.attributes[i];
        close(x[1], out.safety_preference * out.safety[i]);
        close(x[2], out.efficiency_preference * out.efficiency[i]);
        let u: f64 = p.beta.iter().zip(x).map(|(b, x)| b * x).sum();
        close(out.utility[i], u);
    }
}

#[test]
fn among_equally_good_timings_the_nominal_one_stands_and_a_crawl_has_no_other() {
    let p = ChoiceParams::default();
    // At the goal with nothing around, every timing of "accelerate" (0 → 4.5 m/s over the
    // 3 s horizon, or 0.8 and 0.6 of it) is equally good: the nominal stands.
    let at_goal = EgoContext {
        goal_distance: 0.0,
        ..wide(0.0)
    };
    let out = choose_one(&[], &OpmTriplet::default(), &at_goal, &p);
    close(out.profiles[Maneuver::Accelerate.index()].target_speed, 4.5);
    // The scene of the slower-timing test at a crawl (0.9 m/s, 1.8 m from its passage):
    // below 1 m/s a maneuver is judged at its nominal timing only.
    let c = pair([1.8, 5.0], [12.0, 20.0], 10.0);
    let crawl = EgoContext {
        speed_cap: 10.0,
        yield_distance: 1.0,
        goal_distance: 28.0,
        ..wide(0.9)
    };
    let out = choose_one(&[c], &OpmTriplet::default(), &crawl, &p);
    close(out.profiles[Maneuver::KeepSpeed.index()].target_speed, 0.9);
}

#[test]
fn the_matching_degree_penalises_a_turn_off_the_route_and_slowing_behind_a_leader_that_drives_on() {
    let p = ChoiceParams::default();
    // A leader 80 m ahead at 10 m/s (IDM speeds the ego up), nothing to yield to, the route
    // straight on.
    let triplet = OpmTriplet {
        leader: Some(Leader {
            agent: 1,
            gap_m: 80.0,
            speed_mps: 10.0,
        }),
        ..OpmTriplet::default()
    };
    let ctx = EgoContext {
        route: Turn::Straight,
        speed_cap: 8.0,
        ..wide(8.0)
    };
    let out = choose_one(&[], &triplet, &ctx, &p);
    let matching = |m: Maneuver| out.attributes[m.index()][0];
    close(matching(Maneuver::Decelerate), 1.0 - p.idle_penalty);
    close(matching(Maneuver::TurnRight), 1.0 - p.navigation_penalty);
    close(matching(Maneuver::KeepSpeed), 1.0);
}

#[test]
fn stated_yields_of_a_road_user_whose_motion_contradicts_them_add_no_efficiency() {
    let opm = OpmParams::default();
    let p = ChoiceParams::default();
    let mut triplet = OpmTriplet::default();
    triplet.intents[0] = IntentPair {
        agent: 2,
        intent: ExplicitIntent {
            action: rated(IntentAction::Stop),
            ..ExplicitIntent::UNKNOWN
        },
    };
    triplet.n_intents = 1;
    let with = |stated: Stated| {
        let set = ConflictSet::of(&[ConflictPair {
            agent: 2,
            intent: ImplicitIntent {
                stated,
                ..ImplicitIntent::default()
            },
            ..ConflictPair::default()
        }]);
        preferences(&triplet, &set, &opm, &p).1
    };
    close(with(Stated::Yield), 1.0 + p.other_yields_efficiency);
    close(with(Stated::Contradicted), 1.0);
}
