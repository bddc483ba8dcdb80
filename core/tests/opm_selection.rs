//! Object selection of §3.1 and the triplet of eq. 6 on the paper's junction: the ego's
//! process state, the leader, conflicts the ego has passed, the candidate count and the
//! ranking of risky and near objects.
mod common;

use common::{before_the_paper_crossing, paper_core};
use concord_core::opm::{ConflictPair, ConflictSet};
use concord_core::params::OpmParams;
use concord_core::scene::{
    AgentState, ExplicitIntent, IntentAction, Rated, Scene, Vec2, MAX_AGENTS,
};
use concord_core::Params;
use concord_map::paper;

/// A road user `id` at `speed` m/s on the ego's lane (`paper::CAV_LEFT`), `s` m along it and
/// `l` m to its left.
fn on_the_ego_lane(id: u32, s: f64, l: f64, speed: f64) -> AgentState {
    let m = concord_map::BuiltIn::PaperIntersection.morphology();
    let (pos, heading, _) = m.lane(paper::CAV_LEFT).pose_at(s, 0);
    let left = Vec2::new(-heading.sin(), heading.cos());
    AgentState::moving(id, pos.plus(left.scale(l)), heading, speed)
}

#[test]
fn is_risky_needs_a_delta_ttc_strictly_below_the_threshold_and_an_arrival_strictly_below_the_cap() {
    let p = OpmParams::default(); // ΔT_th 4 s, TTC cap 30 s
    let c = ConflictPair {
        delta_ttc_s: 1.0,
        ego_ttc_s: 5.0,
        agent_ttc_s: 6.0,
        agent_zone_m: [2.0, 8.0],
        ..ConflictPair::default()
    };
    assert!(c.is_risky(&p));
    let at_threshold = ConflictPair {
        delta_ttc_s: p.delta_ttc_threshold_s,
        ..c
    };
    assert!(!at_threshold.is_risky(&p));
    let at_cap = ConflictPair {
        ego_ttc_s: p.ttc_max_s,
        agent_ttc_s: p.ttc_max_s,
        delta_ttc_s: 0.0,
        ..c
    };
    assert!(!at_cap.is_risky(&p));
    let left = ConflictPair {
        agent_zone_m: [-8.0, -1e-9],
        ..c
    };
    assert!(!left.is_risky(&p));
}

#[test]
fn a_conflict_set_keeps_the_first_max_agents_pairs() {
    let pairs: Vec<ConflictPair> = (0..MAX_AGENTS + 5)
        .map(|k| ConflictPair {
            agent: k as u8,
            ..ConflictPair::default()
        })
        .collect();
    let set = ConflictSet::of(&pairs);
    assert_eq!(set.pairs().len(), MAX_AGENTS);
    assert_eq!(set.pairs()[MAX_AGENTS - 1].agent as usize, MAX_AGENTS - 1);
}

#[test]
fn the_triplet_carries_the_egos_process_state_and_the_passengers_intent() {
    let mut core = paper_core(Params::default());
    let mut ego = on_the_ego_lane(0, 20.0, 0.4, 6.0);
    ego.intent = ExplicitIntent {
        action: Some(Rated {
            value: IntentAction::Yield,
            confidence: 0.9,
        }),
        ..ExplicitIntent::UNKNOWN
    };
    let scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    core.step(&scene, 0.0, None).unwrap();
    let t = core.triplet();
    let lane = core.morphology().lane(paper::CAV_LEFT);
    assert_eq!(t.ego.lane, Some(paper::CAV_LEFT));
    assert!((t.ego.s_m - 20.0).abs() < 0.01, "{}", t.ego.s_m);
    assert!((t.ego.l_m - 0.4).abs() < 0.01, "{}", t.ego.l_m);
    assert!((t.ego.dist_to_stop_m - (lane.stop_s - t.ego.s_m)).abs() < 1e-12);
    assert!(t.ego.dist_to_stop_m > 0.0);
    assert_eq!(t.ego_intent, ego.intent);
}

#[test]
fn the_leader_is_the_nearest_car_ahead_within_half_a_metre_of_the_lane_and_ties_keep_the_first() {
    let lead = |others: &[AgentState]| {
        let mut core = paper_core(Params::default());
        let mut scene = Scene::new(0.0, on_the_ego_lane(0, 10.0, 0.0, 6.0), paper::CAV_LEFT);
        for a in others {
            scene.push(*a);
        }
        core.step(&scene, 0.0, None).unwrap();
        core.triplet().leader.map(|l| (l.agent, l.gap_m))
    };
    let half = concord_map::BuiltIn::PaperIntersection
        .morphology()
        .lane(paper::CAV_LEFT)
        .half_width;
    // 0.25 m beyond the lane's edge still leads; 0.75 m beyond does not.
    let (agent, gap) = lead(&[on_the_ego_lane(1, 25.0, half + 0.25, 5.0)]).expect("a leader");
    assert_eq!(agent, 0);
    assert!((gap - 15.0).abs() < 0.01, "{gap}");
    assert_eq!(lead(&[on_the_ego_lane(1, 25.0, half + 0.75, 5.0)]), None);
    // Level with the ego is not ahead of it.
    assert_eq!(lead(&[on_the_ego_lane(1, 10.0, 0.0, 5.0)]), None);
    // Two at the same gap: the first in scene order leads; the nearer leads in any order.
    let a = on_the_ego_lane(1, 25.0, 0.0, 5.0);
    let b = on_the_ego_lane(2, 25.0, 0.0, 5.0);
    assert_eq!(lead(&[a, b]).map(|l| l.0), Some(0));
    let near = on_the_ego_lane(3, 18.0, 0.0, 5.0);
    assert_eq!(lead(&[a, near]).map(|l| l.0), Some(1));
}

#[test]
fn a_crossing_the_ego_has_passed_is_no_conflict() {
    // The ego 15 m past the crossing point, a car 10 m before it at 8 m/s.
    let mut core = paper_core(Params::default());
    let ego = before_the_paper_crossing(0, paper::CAV_LEFT, -15.0, 6.0);
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    scene.push(before_the_paper_crossing(1, paper::HDV_STRAIGHT, 10.0, 8.0));
    core.step(&scene, 0.0, None).unwrap();
    assert!(core.conflicts().pairs().is_empty());
    // Before it, the same car is in conflict.
    let mut scene = Scene::new(
        0.0,
        before_the_paper_crossing(0, paper::CAV_LEFT, 15.0, 6.0),
        paper::CAV_LEFT,
    );
    scene.push(before_the_paper_crossing(1, paper::HDV_STRAIGHT, 10.0, 8.0));
    let mut core = paper_core(Params::default());
    core.step(&scene, 0.0, None).unwrap();
    assert_eq!(core.conflicts().pairs().len(), 1);
}

#[test]
fn risky_conflicts_rank_before_near_objects_which_rank_by_distance_and_ties_keep_scene_order() {
    // The ego 30 m before the crossing at 6 m/s (TTC 5 s); a car on the crossing lane 28 m
    // before it at 8 m/s (TTC 3.5 s, |ΔTTC| 1.5 s): risky. Near objects on the ego's lane rank
    // at ΔT_th + distance: 0.3 m, 12 m and 6 m behind the ego, and two level 20 m ahead and
    // 20 m behind.
    let mut core = paper_core(Params::default());
    let ego = before_the_paper_crossing(0, paper::CAV_LEFT, 30.0, 6.0);
    let s0 = core.morphology().lane(paper::CAV_LEFT).project(ego.pos).s;
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    scene.push(on_the_ego_lane(10, s0 - 12.0, 0.0, 6.0));
    scene.push(on_the_ego_lane(11, s0 - 0.3, 0.0, 6.0));
    scene.push(before_the_paper_crossing(
        12,
        paper::HDV_STRAIGHT,
        28.0,
        8.0,
    ));
    scene.push(on_the_ego_lane(13, s0 + 20.0, 0.0, 6.0));
    scene.push(on_the_ego_lane(14, s0 - 20.0, 0.0, 6.0));
    scene.push(on_the_ego_lane(15, s0 - 6.0, 0.0, 6.0));
    core.step(&scene, 0.0, None).unwrap();
    let t = core.triplet();
    let ids: Vec<u32> = t.objects().iter().map(|o| o.id).collect();
    assert_eq!(ids, vec![12, 11, 15, 10, 13, 14]);
    assert_eq!(t.n_candidates, 6);
    assert!(t.conflicts[0].is_risky(&core.params().opm));
}

#[test]
fn every_qualifying_agent_is_counted_also_beyond_the_slots() {
    // Twelve cars on the ego's lane 2–24 m behind it, all near: twelve candidates, eight kept,
    // the nearest first.
    let mut core = paper_core(Params::default());
    let ego = on_the_ego_lane(0, 40.0, 0.0, 6.0);
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    for k in (0..12).rev() {
        scene.push(on_the_ego_lane(1 + k, 38.0 - 2.0 * k as f64, 0.0, 6.0));
    }
    core.step(&scene, 0.0, None).unwrap();
    let t = core.triplet();
    assert_eq!(t.n_candidates, 12);
    let ids: Vec<u32> = t.objects().iter().map(|o| o.id).collect();
    assert_eq!(ids, (1..=8).collect::<Vec<u32>>());
}
