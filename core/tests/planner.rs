//! The planner's public parts (Table 2, eq. 17–24) at their edges: the longest horizon, the
//! distance helpers of the forecasts, trajectory sampling and the fallbacks.
use concord_core::choice::Profile;
use concord_core::params::Params;
use concord_core::scene::{AgentState, Morphology, ProcessState, MAX_AGENTS};
use concord_core::trajectory::{
    travel, Forecast, FrenetState, PlanStats, Planner, Trajectory, TrajectoryPoint, MAX_POINTS,
    MAX_STEPS,
};
use concord_map::{paper, BuiltIn};

const EPS: f64 = 1e-9;

/// A planner on the paper's left-turn lane, the ego `s` m along it at `v` m/s, nobody else,
/// with trajectory parameters `p`.
fn planner_on_the_turn(
    s: f64,
    v: f64,
    p: &concord_core::params::TrajectoryParams,
) -> (Planner, Morphology) {
    planner_among(s, v, &[], &[Forecast::default(); MAX_AGENTS], p)
}

/// [`planner_on_the_turn`] with `agents` and their `forecasts` (no process states: each is
/// predicted straight on).
fn planner_among(
    s: f64,
    v: f64,
    agents: &[AgentState],
    forecasts: &[Forecast; MAX_AGENTS],
    p: &concord_core::params::TrajectoryParams,
) -> (Planner, Morphology) {
    let morph = BuiltIn::PaperIntersection.morphology();
    let mut planner = Planner::default();
    let start = FrenetState {
        s,
        ds: v,
        ..FrenetState::default()
    };
    planner.prepare(
        paper::CAV_LEFT,
        start,
        100.0,
        agents,
        &[ProcessState::default(); MAX_AGENTS],
        forecasts,
        &morph,
        p,
    );
    (planner, morph)
}

#[test]
fn a_horizon_longer_than_the_step_table_is_planned_and_rendered_over_every_step() {
    // 10 s at 0.1 s is more than the table's 64 steps: the horizon is cut to 64 steps, and a
    // plan and the minimum-risk braking both hold t = 0 and all 64 steps.
    let mut p = Params::default().trajectory;
    p.horizon_s = 10.0;
    let (mut planner, morph) = planner_on_the_turn(5.0, 4.0, &p);
    let cruise = Profile {
        accel: 0.0,
        target_speed: 4.0,
        duration: 3.0,
        stop_m: f64::INFINITY,
    };
    planner.sample(&cruise, 16, 1, &p);
    let mut stats = PlanStats::default();
    let best = planner
        .run(16, &p, &mut stats)
        .expect("an empty road has a plan");
    let lane = morph.lane(paper::CAV_LEFT);
    let mut out = Trajectory::default();
    planner.render(&best, lane, &mut out);
    assert_eq!(MAX_POINTS, MAX_STEPS + 1);
    assert_eq!(out.points().len(), MAX_STEPS + 1);
    assert!((out.points()[MAX_STEPS].t - 6.4).abs() < EPS);
    planner.minimum_risk(f64::INFINITY, lane, &p, &mut out);
    assert_eq!(out.points().len(), MAX_STEPS + 1);
    assert!((out.points()[MAX_STEPS].t - 6.4).abs() < EPS);
}

#[test]
fn free_travel_brakes_to_a_stop_and_speeds_up_only_to_the_top_speed() {
    // Braking at 2 m/s² from 10 m/s stops after 25 m and stays there; speeding up at 2 m/s²
    // from 10 m/s to a top speed of 14 m/s takes 2 s (24 m), then 8 s at 14 m/s (112 m); at or
    // above the top speed, or unaccelerated, the ego keeps its speed.
    assert!((travel(10.0, -2.0, 10.0, 20.0) - 25.0).abs() < EPS);
    assert!((travel(10.0, -2.0, 2.0, 20.0) - 16.0).abs() < EPS);
    assert!((travel(10.0, 2.0, 10.0, 14.0) - 136.0).abs() < EPS);
    assert!((travel(10.0, 2.0, 1.0, 14.0) - 11.0).abs() < EPS);
    assert!((travel(16.0, 2.0, 3.0, 14.0) - 48.0).abs() < EPS);
    assert!((travel(10.0, 0.0, 3.0, 14.0) - 30.0).abs() < EPS);
}

#[test]
fn a_forecast_stops_where_it_says_and_otherwise_as_its_braking_allows() {
    let driving = Forecast {
        accel: 1.0,
        ..Forecast::default()
    };
    let braking = Forecast {
        accel: -2.0,
        ..Forecast::default()
    };
    let stopping = Forecast {
        stop_in_m: 12.0,
        ..Forecast::default()
    };
    let stopped_short = Forecast {
        stop_in_m: -3.0,
        ..Forecast::default()
    };
    assert_eq!(driving.stop_distance(10.0), f64::INFINITY);
    assert_eq!(Forecast::default().stop_distance(10.0), f64::INFINITY);
    assert!((braking.stop_distance(10.0) - 25.0).abs() < EPS);
    assert_eq!(braking.stop_distance(0.0), 0.0);
    assert_eq!(driving.stop_distance(0.0), 0.0);
    // Below 1e-6 m/s a road user stands; at it, it still moves.
    assert_eq!(driving.stop_distance(1e-6), f64::INFINITY);
    assert!(stopping.travel(1e-6, 1.0, 20.0) > 0.0);
    assert_eq!(stopping.stop_distance(10.0), 12.0);
    assert_eq!(stopping.stop_distance(0.0), 12.0);
    assert_eq!(stopped_short.stop_distance(10.0), 0.0);
    // Travel: a stop forecast brakes evenly to its stop (v² / 2d = 100 / 24 m/s²) and stays;
    // one already at its stop, or standing, does not move; otherwise at its acceleration up
    // to the top speed.
    assert!((stopping.travel(10.0, 10.0, 20.0) - 12.0).abs() < EPS);
    let half = 10.0 * 1.0 - 0.5 * (100.0 / 24.0) * 1.0;
    assert!((stopping.travel(10.0, 1.0, 20.0) - half).abs() < EPS);
    assert_eq!(stopping.travel(0.0, 5.0, 20.0), 0.0);
    assert_eq!(stopped_short.travel(10.0, 5.0, 20.0), 0.0);
    assert_eq!(
        Forecast {
            stop_in_m: 0.0,
            ..Forecast::default()
        }
        .travel(10.0, 5.0, 20.0),
        0.0
    );
    assert!((driving.travel(10.0, 2.0, 11.0) - (10.5 + 11.0)).abs() < EPS);
    assert!((braking.travel(10.0, 10.0, 20.0) - 25.0).abs() < EPS);
}

fn point(t: f64, s: f64, heading: f64, speed: f64) -> TrajectoryPoint {
    TrajectoryPoint {
        t,
        s,
        l: 0.1 * s,
        x: 2.0 * s,
        y: -s,
        heading,
        speed,
        accel: -speed,
    }
}

#[test]
fn a_trajectory_is_sampled_between_its_points_and_held_at_its_ends() {
    // Three points 0.1 s apart: before the start (or NaN) gives the first point, past the end
    // the last; between points every field is interpolated from the two around t, and the
    // heading turns along the shorter arc (3.0 → −3.0 rad passes π, not 0).
    let mut tr = Trajectory::default();
    assert_eq!(tr.sample(0.0), None);
    tr.points[0] = point(0.0, 0.0, 0.0, 4.0);
    tr.points[1] = point(0.1, 1.0, 3.0, 6.0);
    tr.points[2] = point(0.2, 3.0, -3.0, 2.0);
    tr.n = 3;
    assert_eq!(tr.sample(-1.0), Some(tr.points[0]));
    assert_eq!(tr.sample(0.0), Some(tr.points[0]));
    assert_eq!(tr.sample(f64::NAN), Some(tr.points[0]));
    assert_eq!(tr.sample(0.5), Some(tr.points[2]));
    let q = tr.sample(0.05).unwrap();
    assert!((q.t - 0.05).abs() < EPS);
    assert!((q.s - 0.5).abs() < EPS && (q.l - 0.05).abs() < EPS);
    assert!((q.x - 1.0).abs() < EPS && (q.y + 0.5).abs() < EPS);
    assert!((q.heading - 1.5).abs() < EPS && (q.speed - 5.0).abs() < EPS);
    assert!((q.accel + 5.0).abs() < EPS);
    let q = tr.sample(0.175).unwrap();
    assert!(
        (q.s - 2.5).abs() < EPS && (q.speed - 3.0).abs() < EPS,
        "{q:?}"
    );
    let shorter = 3.0 + 0.75 * (2.0 * core::f64::consts::PI - 6.0);
    assert!((q.heading - shorter).abs() < EPS, "{}", q.heading);
}

#[test]
fn a_passage_sets_its_margin_from_when_it_began_to_one_window_past_the_horizon() {
    // A car crossing 20 m ahead of the ego at 10 m/s, in its passage of the conflict zone
    // from 10 m behind it to 200 m ahead, margins 2 s either side: it entered 1 s ago, so the
    // ego must stay out of its own passage from 3 s ago; the sweep for its leaving ends one
    // window (2 s, 21 steps) past the 5 s horizon, at 7.1 s, so the margin lasts until 9.1 s.
    // A car standing at the start of its passage is in it from the start of the sweep.
    let p = Params::default().trajectory;
    let morph = BuiltIn::PaperIntersection.morphology();
    let (at, tangent, _) = morph.lane(paper::CAV_LEFT).pose_at(25.0, 0);
    let across = tangent + core::f64::consts::FRAC_PI_2;
    let crossing = Forecast {
        pet_s: [2.0, 2.0],
        pass_m: [-10.0, 200.0],
        ego_pass_m: [15.0, 25.0],
        ..Forecast::default()
    };
    let standing = Forecast {
        pass_m: [0.0, 3.0],
        ..crossing
    };
    let mut forecasts = [Forecast::default(); MAX_AGENTS];
    forecasts[0] = crossing;
    forecasts[1] = standing;
    let agents = [
        AgentState::moving(1, at, across, 10.0),
        AgentState::moving(2, at, across, 0.0),
    ];
    let (planner, _) = planner_among(5.0, 4.0, &agents, &forecasts, &p);
    let m = planner.margins();
    assert_eq!(m.len(), 2);
    assert!((m[0].s[0] - 20.0).abs() < EPS && (m[0].s[1] - 30.0).abs() < EPS);
    assert!((m[0].t[0] + 3.0).abs() < 1e-6, "{:?}", m[0].t);
    assert!((m[0].t[1] - 9.1).abs() < 1e-6, "{:?}", m[0].t);
    // Standing: in its passage over the whole sweep, from 2.1 s before now.
    assert!((m[1].t[0] + 4.1).abs() < 1e-6, "{:?}", m[1].t);
    assert!((m[1].t[1] - 9.1).abs() < 1e-6, "{:?}", m[1].t);
}

#[test]
fn a_road_user_far_from_every_reachable_point_leaves_no_box() {
    // 300 m ahead on the line of the ego's lane end, or 60 m beside its start: no candidate
    // can reach it within the horizon, so it is not in the occupancy at any step; 10 m ahead,
    // standing in the lane, it is.
    let p = Params::default().trajectory;
    let morph = BuiltIn::PaperIntersection.morphology();
    let lane = morph.lane(paper::CAV_LEFT);
    let (end, tangent, _) = lane.pose_at(lane.length(), 0);
    let far_ahead = end.plus(concord_core::scene::Vec2::from_angle(tangent).scale(300.0));
    let (start, tangent0, _) = lane.pose_at(5.0, 0);
    let beside = start.plus(
        concord_core::scene::Vec2::from_angle(tangent0 + core::f64::consts::FRAC_PI_2).scale(60.0),
    );
    for pos in [far_ahead, beside] {
        let agents = [AgentState::moving(1, pos, tangent, 0.0)];
        let (planner, _) = planner_among(5.0, 4.0, &agents, &[Forecast::default(); MAX_AGENTS], &p);
        let boxes: usize = (0..50).map(|k| planner.occupancy.boxes(k).count()).sum();
        assert_eq!(boxes, 0, "{pos:?}");
    }
    let (near, tangent, _) = lane.pose_at(15.0, 0);
    let agents = [AgentState::moving(1, near, tangent, 0.0)];
    let (planner, _) = planner_among(5.0, 4.0, &agents, &[Forecast::default(); MAX_AGENTS], &p);
    assert!((0..50).all(|k| planner.occupancy.boxes(k).count() == 1));
}

/// A planner on a straight 200 m lane along x, the ego 5 m along it at 4 m/s, with `agent`
/// standing still (predicted straight on) and trajectory parameters `p`.
fn planner_on_a_straight(agent: AgentState, p: &concord_core::params::TrajectoryParams) -> Planner {
    use concord_core::scene::{Lane, Turn, Vec2};
    let straight = Lane::new(
        &[Vec2::new(0.0, 0.0), Vec2::new(200.0, 0.0)],
        1.75,
        50.0,
        Turn::Straight,
    )
    .expect("a lane");
    let morph = Morphology::new(&[straight]).expect("a map");
    let start = FrenetState {
        s: 5.0,
        ds: 4.0,
        ..FrenetState::default()
    };
    let mut planner = Planner::default();
    planner.prepare(
        0,
        start,
        100.0,
        &[agent],
        &[ProcessState::default(); MAX_AGENTS],
        &[Forecast::default(); MAX_AGENTS],
        &morph,
        p,
    );
    planner
}

#[test]
fn a_car_across_a_straight_lane_blocks_exactly_the_minkowski_box_of_the_two_rectangles() {
    // Standing across a straight lane, 10 m ahead of the ego: at step k its rectangle,
    // longer by the growth 0.2 m/s × t, plus the ego's and the 0.5 m clearance, is a box of
    // half extents hl + w/2 + 0.5 along the lane and w/2 + (hl + growth) + 0.5 across it.
    use concord_core::scene::Vec2;
    let p = Params::default().trajectory;
    let across = AgentState::moving(1, Vec2::new(15.0, 0.0), core::f64::consts::FRAC_PI_2, 0.0);
    let planner = planner_on_a_straight(across, &p);
    let (hl, hw, m) = (
        0.5 * p.vehicle_length_m,
        0.5 * p.vehicle_width_m,
        p.safety_margin_m,
    );
    // Beside the lane, 6 m to either side, beyond any offset the ego may take: no box.
    for l in [-6.0, 6.0] {
        let apart = planner_on_a_straight(AgentState::moving(1, Vec2::new(15.0, l), 0.0, 0.0), &p);
        assert_eq!(apart.occupancy.boxes(0).count(), 0, "l {l}");
    }
    for k in [0, 9, 49] {
        let grown = p.margin_growth_mps * (k + 1) as f64 * p.dt_s;
        let b: Vec<_> = planner.occupancy.boxes(k).collect();
        assert_eq!(b.len(), 1, "step {k}");
        let (ext_s, ext_l) = (hl + hw + m, hw + hl + grown + m);
        let want = [15.0 - ext_s, 15.0 + ext_s, -ext_l, ext_l];
        let got = [b[0].0, b[0].1, b[0].2, b[0].3];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "step {k}: {got:?} vs {want:?}");
        }
    }
}

#[test]
fn the_planning_window_keeps_a_car_beside_the_lane_whose_grown_box_the_ego_can_reach() {
    // A car standing across a straight lane, its centre l m beside it: its box reaches
    // across the lane to l − (w/2 + hl + growth × t + clearance), which by the horizon's end
    // is within the ego's 1 m lateral bound. The window that culls road users before their
    // boxes are built keeps it, without growth, and with a fast one and no clearance.
    for (growth, margin, l) in [(0.0, 0.5, 4.8), (1.0, 0.0, 9.3)] {
        let p = concord_core::params::TrajectoryParams {
            margin_growth_mps: growth,
            safety_margin_m: margin,
            ..Params::default().trajectory
        };
        let beside = AgentState::moving(
            1,
            concord_core::scene::Vec2::new(15.0, l),
            core::f64::consts::FRAC_PI_2,
            0.0,
        );
        let planner = planner_on_a_straight(beside, &p);
        let last = 49;
        let grown = growth * (last + 1) as f64 * p.dt_s;
        let reach = 0.5 * p.vehicle_width_m + 0.5 * p.vehicle_length_m + grown + p.safety_margin_m;
        let b: Vec<_> = planner.occupancy.boxes(last).collect();
        assert_eq!(b.len(), 1, "growth {growth}");
        assert!(
            (b[0].2 - (l - reach)).abs() < 1e-6,
            "growth {growth}: {:?}",
            b[0]
        );
    }
}

#[test]
fn every_evaluated_candidate_is_counted_under_one_verdict() {
    // From 5 m/s, reaching 20 m/s within about a second breaks the acceleration limit: every
    // candidate is a limit reject, and the counts add up to the candidates evaluated.
    let p = Params::default().trajectory;
    let (mut planner, _) = planner_on_the_turn(5.0, 5.0, &p);
    let sprint = Profile {
        accel: 15.0,
        target_speed: 20.0,
        duration: 1.0,
        stop_m: f64::INFINITY,
    };
    planner.sample(&sprint, 32, 1, &p);
    let mut stats = PlanStats::default();
    assert!(planner.run(32, &p, &mut stats).is_none());
    assert_eq!(stats.evaluated, 32);
    assert!(stats.limit_rejects > 24, "{stats:?}");
    assert_eq!(
        stats.feasible
            + stats.limit_rejects
            + stats.collision_rejects
            + stats.zone_rejects
            + stats.score_rejects,
        stats.evaluated,
        "{stats:?}"
    );
    assert_eq!(stats.best_score, f64::INFINITY);
}
