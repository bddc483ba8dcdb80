//! The map files of highway-env's intersection-v0 (`deploy/maps/highway-env-intersection.toml`)
//! and merge-v0 (`deploy/maps/highway-env-merge.toml`, in `mod merge`) against highway-env's
//! own dimensions (1.12.1, `_make_road`): lanes, conflict points against hand-computed ones,
//! and lane matching of poses as highway-env reports them.

use concord_core::scene::{
    AgentState, Morphology, Turn, TurnSignal, Vec2, MAX_LANES, MAX_LANE_POINTS,
};
use concord_core::{DecisionCore, Params};
use concord_map::BuiltIn;
use highway_env_intersection::*;
use std::f64::consts::{FRAC_PI_2, PI};

/// highway-env's intersection-v0 road, and the lane index of each movement in the map file
/// (checked by `the_lane_indices_are_the_files`).
mod highway_env_intersection {
    /// Lane width, m (`AbstractLane.DEFAULT_WIDTH`).
    pub const LANE_WIDTH_M: f64 = 4.0;
    /// Length of each approach lane, m.
    pub const APPROACH_M: f64 = 100.0;
    /// Distance from the centre to where approaches end and exits begin, m.
    pub const OUTER_M: f64 = 11.0;
    /// Radius of right turns, m.
    pub const RIGHT_TURN_RADIUS_M: f64 = 9.0;
    /// Radius of left turns, m.
    pub const LEFT_TURN_RADIUS_M: f64 = 13.0;
    /// Lateral offset of each lane centre from the road's axis, m.
    pub const HALF_LANE_M: f64 = 2.0;

    /// From the south (x = 2, towards −y), turning left to the west exit: the ego's route.
    pub const EGO_LEFT: u8 = 0;
    /// From the north (x = −2, towards +y), straight on: oncoming traffic; crosses the turn.
    pub const NORTH_STRAIGHT: u8 = 1;
    /// From the north, turning right into the west exit: joins the ego's exit lane.
    pub const NORTH_RIGHT: u8 = 2;
    /// From the north, turning left to the east exit: passes the ego's turn without crossing.
    pub const NORTH_LEFT: u8 = 3;
    /// From the west (y = 2, towards +x), straight on: priority road; crosses the turn.
    pub const WEST_STRAIGHT: u8 = 4;
    /// From the west, turning left to the north exit: crosses the turn.
    pub const WEST_LEFT: u8 = 5;
    /// From the east (y = −2, towards −x), straight on: priority road; joins the ego's exit.
    pub const EAST_STRAIGHT: u8 = 6;
    /// From the east, turning left to the south exit: crosses the turn.
    pub const EAST_LEFT: u8 = 7;
    /// From the west, turning right to the south exit: shares the west approach, then turns
    /// away from the ego's route (concentric with its turn, 4 m inside it).
    pub const WEST_RIGHT: u8 = 8;
    /// From the east, turning right to the north exit: shares the east approach, then turns
    /// away from the ego's route.
    pub const EAST_RIGHT: u8 = 9;
    /// Number of lanes.
    pub const LANES: usize = 10;
}

/// Chords of 1 m on a 13 m arc sag by 1 cm; crossings of two chorded arcs move by a few.
const TOL: f64 = 0.05;

fn morph() -> Morphology {
    BuiltIn::HighwayEnvIntersection.morphology()
}

fn conflict_point(m: &Morphology, a: u8, b: u8) -> Option<(f64, f64, Vec2)> {
    m.conflicts().iter().find_map(|c| {
        if c.lane_a == a && c.lane_b == b {
            Some((c.s_a, c.s_b, c.pos))
        } else if c.lane_a == b && c.lane_b == a {
            Some((c.s_b, c.s_a, c.pos))
        } else {
            None
        }
    })
}

fn near(p: Vec2, x: f64, y: f64) -> bool {
    (p.x - x).abs() < TOL && (p.y - y).abs() < TOL
}

#[test]
fn lanes_fit_the_core_and_reproduce_highway_env_lengths() {
    let m = morph();
    assert_eq!(m.lanes().len(), LANES);
    const { assert!(LANES <= MAX_LANES) };
    let quarter = |r: f64| r * FRAC_PI_2;
    for (i, lane) in m.lanes().iter().enumerate() {
        assert!(lane.points().len() <= MAX_LANE_POINTS, "lane {i}");
        assert_eq!(lane.half_width, HALF_LANE_M, "lane {i}");
        assert_eq!(lane.half_width, 0.5 * LANE_WIDTH_M, "lane {i}");
        assert_eq!(lane.stop_s, APPROACH_M, "lane {i}");
        // Approach, junction, exit: 100 m + (22 m straight | a quarter circle) + 100 m.
        let junction = match lane.turn {
            Turn::Straight => 2.0 * OUTER_M,
            Turn::Left => quarter(LEFT_TURN_RADIUS_M),
            Turn::Right => quarter(RIGHT_TURN_RADIUS_M),
        };
        let expected = 2.0 * APPROACH_M + junction;
        assert!(
            (lane.length() - expected).abs() < 0.02,
            "lane {i}: length {} != {expected}",
            lane.length()
        );
    }
    let ego = m.lane(EGO_LEFT);
    assert_eq!(ego.turn, Turn::Left);
    // highway-env: o0 starts at (2, 111); il1 → o1 ends at (−111, −2).
    let (first, last) = (ego.points()[0], *ego.points().last().unwrap());
    assert!(near(first, 2.0, 111.0) && near(last, -111.0, -2.0));
    // The turn ends where the west exit begins, (−11, −2), heading −x (π).
    let (p, tangent, _) = ego.pose_at(APPROACH_M + quarter(LEFT_TURN_RADIUS_M) + 1.0, 0);
    assert!(near(p, -12.0, -2.0), "{p:?}");
    assert!((tangent.abs() - PI).abs() < 1e-3, "{tangent}");
}

#[test]
fn the_left_turn_conflicts_with_every_crossing_and_joining_lane() {
    let m = morph();
    // Ego arc: centre (−11, 11), radius 13. Crossings with x = −2 and y = 2 are 11 − √88 from
    // the centre lines; with the radius-13 arcs centred at (−11, −11) and (11, 11) they are on
    // the bisector, √(13² − 11²) = √48 from it.
    let r88 = 11.0 - 88f64.sqrt();
    let r48 = 48f64.sqrt();
    let expect = [
        (NORTH_STRAIGHT, -2.0, r88),
        (WEST_STRAIGHT, -r88, 2.0),
        (WEST_LEFT, -11.0 + r48, 0.0),
        (EAST_LEFT, 0.0, 11.0 - r48),
        // Joining: the exit lane il1 → o1 begins at (−11, −2).
        (NORTH_RIGHT, -11.0, -2.0),
        (EAST_STRAIGHT, -11.0, -2.0),
    ];
    for (lane, x, y) in expect {
        let (s_ego, s_other, p) = conflict_point(&m, EGO_LEFT, lane)
            .unwrap_or_else(|| panic!("no conflict between the turn and lane {lane}"));
        assert!(
            near(p, x, y),
            "lane {lane}: conflict at {p:?}, expected ({x}, {y})"
        );
        // Arc lengths locate the same point on both lanes.
        let on_ego = m.lane(EGO_LEFT).pose_at(s_ego, 0).0;
        let on_other = m.lane(lane).pose_at(s_other, 0).0;
        assert!(near(on_ego, x, y) && near(on_other, x, y), "lane {lane}");
        // Every conflict lies in the junction, after the stop line of both lanes.
        assert!(
            s_ego > APPROACH_M && s_other > APPROACH_M - TOL,
            "lane {lane}"
        );
    }
    // Crossings order along the turn: east-left, west-straight, north-straight, west-left,
    // then the joins at the end of the arc.
    let s = |lane| conflict_point(&m, EGO_LEFT, lane).unwrap().0;
    assert!(s(EAST_LEFT) < s(WEST_STRAIGHT));
    assert!(s(WEST_STRAIGHT) < s(NORTH_STRAIGHT));
    assert!(s(NORTH_STRAIGHT) < s(WEST_LEFT));
    assert!(s(WEST_LEFT) < s(NORTH_RIGHT));
    assert!((s(NORTH_RIGHT) - s(EAST_STRAIGHT)).abs() < TOL);
    // The oncoming left turn passes without crossing (the circles are 31 m apart, radii 13),
    // and the right turns from the west and east turn away from it.
    for lane in [NORTH_LEFT, WEST_RIGHT, EAST_RIGHT] {
        assert!(conflict_point(&m, EGO_LEFT, lane).is_none(), "lane {lane}");
    }
}

#[test]
fn highway_env_poses_match_their_lanes() {
    let m = morph();
    let signalling = |x: f64, y: f64, heading: f64, signal: TurnSignal| {
        let a = AgentState::moving(1, Vec2::new(x, y), heading, 8.0);
        m.match_lane(a.pos, a.direction(), 1.0, signal)
            .map(|(lane, _)| lane)
    };
    let at = |x: f64, y: f64, heading: f64| signalling(x, y, heading, TurnSignal::Off);
    // intersection-v0's ego spawn: (2, ~39), heading −π/2 (towards −y).
    assert_eq!(at(2.0, 39.3, -FRAC_PI_2), Some(EGO_LEFT));
    // Priority road from the west (heading 0) and from the east (heading π).
    assert_eq!(at(-42.0, 2.0, 0.0), Some(WEST_STRAIGHT));
    assert_eq!(at(45.9, -2.0, PI), Some(EAST_STRAIGHT));
    // Oncoming from the north, heading +π/2; half-way through its left turn it is on its arc.
    assert_eq!(at(-2.0, -47.9, FRAC_PI_2), Some(NORTH_STRAIGHT));
    let phase = PI - FRAC_PI_2 / 2.0;
    let (x, y) = (11.0 + 13.0 * phase.cos(), -11.0 + 13.0 * phase.sin());
    assert_eq!(at(x, y, FRAC_PI_2 / 2.0), Some(NORTH_LEFT));
    // On a shared approach the turn signal picks the movement; hazard lights do not.
    let west = |signal| signalling(-42.0, 2.0, 0.0, signal);
    assert_eq!(west(TurnSignal::Left), Some(WEST_LEFT));
    assert_eq!(west(TurnSignal::Right), Some(WEST_RIGHT));
    assert_eq!(west(TurnSignal::Hazard), Some(WEST_STRAIGHT));
    assert_eq!(
        signalling(45.9, -2.0, PI, TurnSignal::Right),
        Some(EAST_RIGHT)
    );
    assert_eq!(
        signalling(-2.0, -47.9, FRAC_PI_2, TurnSignal::Right),
        Some(NORTH_RIGHT)
    );
    // Once the lanes have diverged, position outweighs a contradicting signal: 6 m into the
    // junction the west left turn is 1.5 m off a car still on the straight line.
    assert_eq!(
        signalling(-5.0, 2.0, 0.0, TurnSignal::Left),
        Some(WEST_STRAIGHT)
    );
}

#[test]
fn a_core_on_the_geometry_sees_the_oncoming_car_as_a_risky_conflict() {
    let mut core =
        DecisionCore::new(Params::default(), morph()).expect("default parameters are valid");
    // Ego 20 m before the junction at 8 m/s; oncoming car 20 m before it at 8 m/s.
    let ego = AgentState::moving(0, Vec2::new(2.0, 31.0), -FRAC_PI_2, 8.0);
    let mut scene = concord_core::Scene::new(0.0, ego, EGO_LEFT);
    scene.push(AgentState::moving(
        1,
        Vec2::new(-2.0, -31.0),
        FRAC_PI_2,
        8.0,
    ));
    core.step(&scene, 0.0, None).expect("a valid scene");
    let t = core.triplet();
    assert_eq!(t.n_conflicts, 1);
    let c = t.conflicts[0];
    assert!(c.is_risky(&Params::default().opm), "{c:?}");
    assert!(near(c.point, -2.0, 11.0 - 88f64.sqrt()));
}

#[test]
fn the_lane_indices_are_the_files() {
    let map = BuiltIn::HighwayEnvIntersection.map();
    for (id, index) in [
        ("ego_left", EGO_LEFT),
        ("north_straight", NORTH_STRAIGHT),
        ("north_right", NORTH_RIGHT),
        ("north_left", NORTH_LEFT),
        ("west_straight", WEST_STRAIGHT),
        ("west_left", WEST_LEFT),
        ("east_straight", EAST_STRAIGHT),
        ("east_left", EAST_LEFT),
        ("west_right", WEST_RIGHT),
        ("east_right", EAST_RIGHT),
    ] {
        assert_eq!(map.lane_index(id).unwrap(), index, "{id}");
    }
    let merge = BuiltIn::HighwayEnvMerge.map();
    assert_eq!(merge.ids(), ["ego_right", "main_left", "ramp"]);
}

// ---- merge-v0 (`BuiltIn::HighwayEnvMerge`) ----

mod merge {
    use concord_core::scene::{AgentState, Morphology, Turn, Vec2, MAX_LANES, MAX_LANE_POINTS};
    use concord_core::{DecisionCore, Params};
    use concord_map::BuiltIn;
    use highway_env_merge::*;
    use std::f64::consts::PI;

    /// highway-env's merge-v0 road, and the lane index of each lane in the map file.
    mod highway_env_merge {
        /// Lane width, m (`AbstractLane.DEFAULT_WIDTH`).
        pub const LANE_WIDTH_M: f64 = 4.0;
        /// Where the main road ends, m (x of node d).
        pub const ROAD_END_M: f64 = 460.0;
        /// y of the left-hand main lane (highway-env lane index 0).
        pub const LEFT_Y_M: f64 = 0.0;
        /// y of the right-hand main lane (index 1), the ego's.
        pub const RIGHT_Y_M: f64 = 4.0;
        /// y of the ramp's straight approach (j → k).
        pub const RAMP_Y_M: f64 = 14.5;
        /// y of the auxiliary lane (b → c, index 2).
        pub const AUX_Y_M: f64 = 8.0;
        /// x where the ramp's sine section begins (node k).
        pub const SINE_START_M: f64 = 150.0;
        /// x where the sine section ends and the auxiliary lane begins (node b).
        pub const AUX_START_M: f64 = 230.0;
        /// x where the auxiliary lane ends at an obstacle (node c).
        pub const AUX_END_M: f64 = 310.0;
        /// Length along x of the core's taper from the auxiliary lane into the right-hand lane, m.
        pub const TAPER_M: f64 = 20.0;
        /// x where the ramp joins the ego's lane: the conflict point.
        pub const JOIN_M: f64 = AUX_START_M + TAPER_M;
        /// x beyond which highway-env ends the episode (`MergeEnv._is_terminated`).
        pub const TERMINATION_X_M: f64 = 370.0;
        /// Chord length along x of the sampled sine section, m.
        pub const SINE_STEP_M: f64 = 5.0;

        /// Right-hand main lane, y = 4 (highway-env `("a", "b", 1)` onwards): the ego's route.
        pub const EGO_RIGHT: u8 = 0;
        /// Left-hand main lane, y = 0 (`("a", "b", 0)` onwards); parallel, no conflict.
        pub const MAIN_LEFT: u8 = 1;
        /// On-ramp (`j → k → b`), tapering into the ego's lane from the auxiliary lane.
        pub const RAMP: u8 = 2;
        /// Number of lanes.
        pub const LANES: usize = 3;
    }

    fn morph() -> Morphology {
        BuiltIn::HighwayEnvMerge.morphology()
    }

    fn near(p: Vec2, x: f64, y: f64, tol: f64) -> bool {
        (p.x - x).abs() < tol && (p.y - y).abs() < tol
    }

    /// highway-env's `SineLane` k → b of merge-v0, as a function of x.
    fn ramp_sine_y(x: f64) -> f64 {
        11.25 + 3.25 * (PI * (x - SINE_START_M) / (AUX_START_M - SINE_START_M)).cos()
    }

    #[test]
    fn lanes_reproduce_highway_env_merge_road() {
        let m = morph();
        assert_eq!(m.lanes().len(), LANES);
        const { assert!(LANES <= MAX_LANES) };
        for (i, lane) in m.lanes().iter().enumerate() {
            assert!(lane.points().len() <= MAX_LANE_POINTS, "lane {i}");
            assert_eq!(lane.half_width, 0.5 * LANE_WIDTH_M, "lane {i}");
            assert_eq!(lane.turn, Turn::Straight, "lane {i}");
        }
        // Main lanes: 460 m straight at y = 4 (the ego's) and y = 0, with vertices where the
        // auxiliary lane begins and ends; stop line at the join.
        for (lane, y) in [(EGO_RIGHT, RIGHT_Y_M), (MAIN_LEFT, LEFT_Y_M)] {
            let l = m.lane(lane);
            assert!((l.length() - ROAD_END_M).abs() < 1e-9);
            assert!(near(l.points()[0], 0.0, y, 1e-9));
            assert!(near(l.points()[1], AUX_START_M, y, 1e-9));
            assert!(near(l.points()[2], AUX_END_M, y, 1e-9));
            assert!(near(*l.points().last().unwrap(), ROAD_END_M, y, 1e-9));
            assert_eq!(l.stop_s, JOIN_M);
        }
        // Ramp: highway-env's j → k along y = 14.5, then the sine section to (230, 8) in
        // chords of 5 m.
        let ramp = m.lane(RAMP);
        assert!(near(ramp.points()[0], 0.0, RAMP_Y_M, 1e-9));
        assert!(near(ramp.points()[1], SINE_START_M, RAMP_Y_M, 1e-9));
        assert!((ramp.points()[2].x - SINE_START_M - SINE_STEP_M).abs() < 1e-9);
        for x in [150.0, 160.0, 172.5, 190.0, 207.5, 220.0, 230.0] {
            let f = ramp.project(Vec2::new(x, ramp_sine_y(x)));
            assert!(f.l.abs() < 0.02, "x = {x}: {} m off the sine", f.l);
        }
        // The sine's steepest point (x = 190, y = 11.25) slopes at atan(3.25 π / 80).
        let (p, tangent, _) = ramp.pose_at(ramp.project(Vec2::new(190.0, 11.25)).s, 0);
        assert!(near(p, 190.0, 11.25, 0.02), "{p:?}");
        assert!(
            (tangent + (3.25 * PI / 80.0).atan()).abs() < 0.01,
            "{tangent}"
        );
        // Its stop line is where highway-env's auxiliary lane begins.
        let (stop, _, _) = ramp.pose_at(ramp.stop_s, 0);
        assert!(near(stop, AUX_START_M, AUX_Y_M, 1e-6), "{stop:?}");
        // It ends on the ego's lane.
        assert!(near(
            *ramp.points().last().unwrap(),
            ROAD_END_M,
            RIGHT_Y_M,
            1e-9
        ));
    }

    #[test]
    fn the_ramp_joins_the_ego_lane_and_nothing_else_conflicts() {
        let m = morph();
        let (s_ego, s_ramp) = m
            .conflict_between(EGO_RIGHT, RAMP)
            .expect("the ramp joins the ego's lane");
        assert!((s_ego - JOIN_M).abs() < 1e-6, "{s_ego}");
        let on_ramp = m.lane(RAMP).pose_at(s_ramp, 0).0;
        assert!(near(on_ramp, JOIN_M, 4.0, 1e-6), "{on_ramp:?}");
        // The ramp reaches the join after its stop line, and the ego reaches it after its own.
        assert!(s_ramp > m.lane(RAMP).stop_s);
        assert!((m.lane(EGO_RIGHT).stop_s - s_ego).abs() < 1e-9);
        assert!(m.conflict_between(EGO_RIGHT, MAIN_LEFT).is_none());
        assert!(m.conflict_between(MAIN_LEFT, RAMP).is_none());
        assert_eq!(m.conflicts().len(), 1);
        // The join lies before highway-env's end of the episode.
        const { assert!(JOIN_M < TERMINATION_X_M) };
    }

    #[test]
    fn highway_env_poses_match_their_lanes() {
        let m = morph();
        let at = |x: f64, y: f64, heading: f64| {
            let a = AgentState::moving(1, Vec2::new(x, y), heading, 25.0);
            m.match_lane(a.pos, a.direction(), 1.0, a.turn_signal)
                .map(|(lane, _)| lane)
        };
        // merge-v0's ego spawn: ("a", "b", 1) at 30 m, heading 0.
        assert_eq!(at(30.0, 4.0, 0.0), Some(EGO_RIGHT));
        assert_eq!(at(90.0, 0.0, 0.0), Some(MAIN_LEFT));
        // The merging car spawns at 110 m on j → k; on the sine section it heads along it.
        assert_eq!(at(110.0, 14.5, 0.0), Some(RAMP));
        let slope = -(3.25 * PI / 80.0).atan();
        assert_eq!(at(190.0, 11.25, slope), Some(RAMP));
        // Starting its lane change on the auxiliary lane, it is on the taper.
        assert_eq!(at(238.0, 7.5, -0.1), Some(RAMP));
        // Once across, the shared part of the ramp is the ego's lane (the lower index).
        assert_eq!(at(300.0, 4.0, 0.0), Some(EGO_RIGHT));
    }

    #[test]
    fn a_core_on_the_geometry_sees_the_merging_car_as_a_conflict() {
        let mut core =
            DecisionCore::new(Params::default(), morph()).expect("default parameters are valid");
        // Ego 50 m before the join at 20 m/s; the merging car 50 m before it along the ramp.
        let ego = AgentState::moving(0, Vec2::new(JOIN_M - 50.0, 4.0), 0.0, 20.0);
        let mut scene = concord_core::Scene::new(0.0, ego, EGO_RIGHT);
        let slope = -(3.25 * PI / 80.0).atan();
        scene.push(AgentState::moving(
            1,
            Vec2::new(205.0, ramp_sine_y(205.0)),
            slope * 0.8,
            20.0,
        ));
        core.step(&scene, 0.0, None).expect("a valid scene");
        let t = core.triplet();
        assert_eq!(t.n_conflicts, 1);
        let c = t.conflicts[0];
        assert!(near(c.point, JOIN_M, 4.0, 1e-6), "{c:?}");
        assert!(c.is_risky(&Params::default().opm), "{c:?}");
    }
}
