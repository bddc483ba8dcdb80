//! The kinematic world of one episode: the CAV (ego) and a list of human-driven vehicles
//! (HDVs), each bound to a lane of the core's morphology, integrated at [`DT`] (20 Hz).
//! Geometry and the conflict zones come from [`Morphology`]: each HDV has the conflict point
//! of its lane with the ego's (`Morphology::conflict_between`) and a zone of ±`zone_half_m`
//! (at least [`ZONE_HALF_M`]) along both lanes around it. HDVs on one lane follow each other
//! (the one ahead is the leader).

use concord_core::scene::{AgentState, Morphology, Scene, Vec2};
use concord_map::{merge, paper, BuiltIn};

/// Lateral acceleration every CAV controller keeps to in curves, m/s² (the core's default
/// `max_lateral_accel_mps2`), and how far ahead it looks for them, m.
pub const CURVE_LATERAL_MPS2: f64 = 4.0;
pub const CURVE_LOOKAHEAD_M: f64 = 60.0;

/// Simulation step, s (20 Hz).
pub const DT: f64 = 0.05;
/// Vehicle footprint, m.
pub const CAR_LENGTH_M: f64 = 4.5;
pub const CAR_WIDTH_M: f64 = 1.8;
/// Smallest half-length of the conflict zone along each lane around the conflict point, m
/// (half a car length plus half a lane width plus a margin); a shallow merge needs more.
pub const ZONE_HALF_M: f64 = 5.0;
/// Lateral distance between the lanes' centre lines beyond which two cars side by side cannot
/// touch, m (a car width and a margin).
const CLEAR_LATERAL_M: f64 = CAR_WIDTH_M + 1.0;
/// Hardest braking and strongest acceleration any vehicle can apply, m/s².
pub const MAX_BRAKE_MPS2: f64 = 8.0;
pub const MAX_ACCEL_MPS2: f64 = 4.0;

/// Which scenario. The discriminants seed the experiment grids: keep them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ScenarioKind {
    /// The paper's unprotected left turn: CAV from (40, 5) turning left, HDV from (−40, −5)
    /// straight on, on the priority road (the CAV turning across oncoming traffic gives way).
    LeftTurn = 0,
    /// The on-ramp merge: CAV on the ramp, HDV on the main lane (which has the right of way).
    Merge = 1,
    /// The same left turn with the right of way: the HDV comes from the minor road
    /// (`paper::NORTH_STRAIGHT`, northbound at x = 5), as far from the conflict point as the
    /// CAV, so both would reach it together at equal speeds.
    LeftTurnPriority = 2,
    /// The left turn across a stream of cars on `paper::HDV_STRAIGHT`, the first placed like
    /// the paper's HDV, the others behind it (see [`World::with_followers`]).
    Stream = 3,
}

impl ScenarioKind {
    pub fn name(self) -> &'static str {
        match self {
            ScenarioKind::LeftTurn => "left_turn",
            ScenarioKind::Merge => "merge",
            ScenarioKind::LeftTurnPriority => "left_turn_priority",
            ScenarioKind::Stream => "stream",
        }
    }
}

/// A vehicle on a lane: arc length, speed and the acceleration of the last step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vehicle {
    pub id: u32,
    pub lane: u8,
    /// Arc length along the lane, m.
    pub s: f64,
    /// Speed, m/s.
    pub v: f64,
    /// Acceleration applied over the last step, m/s².
    pub a: f64,
}

/// One HDV and its conflict with the ego.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hdv {
    pub car: Vehicle,
    /// Arc lengths of the conflict point on the ego's lane and on the HDV's, m.
    pub ego_conflict_s: f64,
    pub conflict_s: f64,
    /// Half-length of the conflict zone along each lane, m: at least [`ZONE_HALF_M`], and
    /// before a merge as far back as the two lanes are closer than a car width and a margin.
    pub zone_half_m: f64,
    /// Whether it has the right of way over the CAV.
    pub has_priority: bool,
}

/// The world of one episode.
#[derive(Clone, Debug)]
pub struct World {
    pub kind: ScenarioKind,
    pub morph: Morphology,
    /// Simulated time, s.
    pub t: f64,
    pub ego: Vehicle,
    /// The HDVs, the scenario's first one first.
    pub hdvs: Vec<Hdv>,
}

/// Corners of a car's footprint centred at `p` with heading `h` rad.
pub fn footprint(p: Vec2, h: f64) -> [Vec2; 4] {
    let f = Vec2::from_angle(h);
    let l = Vec2::new(-f.y, f.x);
    let (hl, hw) = (CAR_LENGTH_M / 2.0, CAR_WIDTH_M / 2.0);
    [
        p.plus(f.scale(hl)).plus(l.scale(hw)),
        p.plus(f.scale(hl)).minus(l.scale(hw)),
        p.minus(f.scale(hl)).plus(l.scale(hw)),
        p.minus(f.scale(hl)).minus(l.scale(hw)),
    ]
}

/// True when two footprints overlap (separating-axis test on oriented rectangles).
fn overlap(a: &[Vec2; 4], b: &[Vec2; 4]) -> bool {
    let axes = |c: &[Vec2; 4]| [c[0].minus(c[2]), c[0].minus(c[1])];
    for axis in axes(a).into_iter().chain(axes(b)) {
        let project = |c: &[Vec2; 4]| {
            c.iter()
                .map(|p| p.dot(axis))
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                })
        };
        let (a0, a1) = project(a);
        let (b0, b1) = project(b);
        if a1 < b0 || b1 < a0 {
            return false;
        }
    }
    true
}

impl World {
    /// The scenario with every vehicle at `speed` and one HDV, shifted `hdv_offset_m` along
    /// its lane from the nominal start (positive: closer to the conflict).
    pub fn new(kind: ScenarioKind, speed: f64, hdv_offset_m: f64) -> World {
        World::with_followers(kind, speed, hdv_offset_m, &[])
    }

    /// [`World::new`] with one more HDV on the first one's lane per entry of `headways_s`,
    /// each that many seconds (front to front, at `speed`) behind the one before; followers
    /// may start before the lane's first vertex (the lane is extended straight back).
    pub fn with_followers(
        kind: ScenarioKind,
        speed: f64,
        hdv_offset_m: f64,
        headways_s: &[f64],
    ) -> World {
        let (built_in, ego_lane, hdv_lane, has_priority) = match kind {
            ScenarioKind::LeftTurn | ScenarioKind::Stream => (
                BuiltIn::PaperIntersection,
                paper::CAV_LEFT,
                paper::HDV_STRAIGHT,
                true,
            ),
            ScenarioKind::LeftTurnPriority => (
                BuiltIn::PaperIntersection,
                paper::CAV_LEFT,
                paper::NORTH_STRAIGHT,
                false,
            ),
            ScenarioKind::Merge => (BuiltIn::Merge, merge::RAMP, merge::MAIN, true),
        };
        let morph = built_in.morphology();
        let (ego_conflict_s, conflict_s) = morph
            .conflict_between(ego_lane, hdv_lane)
            .expect("the scenario's lanes conflict");
        // Left turns: the paper's starts (the minor-road HDV as far from the conflict point
        // as the CAV). Merge: both 60 m before the merge point.
        let (ego_s, hdv_s) = match kind {
            ScenarioKind::LeftTurn | ScenarioKind::Stream => (0.0, 0.0),
            ScenarioKind::LeftTurnPriority => (0.0, conflict_s - ego_conflict_s),
            ScenarioKind::Merge => (ego_conflict_s - 60.0, conflict_s - 60.0),
        };
        // Walk back from the conflict point along each lane while the other lane is too close.
        let reach = |lane: u8, other: u8, s_c: f64| {
            let mut back = 0.0;
            while back < s_c {
                let (p, _, _) = morph.lane(lane).to_cartesian(s_c - back, 0.0, 0);
                if morph.lane(other).project(p).l.abs() > CLEAR_LATERAL_M {
                    break;
                }
                back += 0.5;
            }
            back
        };
        let zone_half_m = (reach(ego_lane, hdv_lane, ego_conflict_s)
            .max(reach(hdv_lane, ego_lane, conflict_s))
            + CAR_LENGTH_M / 2.0)
            .max(ZONE_HALF_M);
        let vehicle = |id, lane, s| Vehicle {
            id,
            lane,
            s,
            v: speed,
            a: 0.0,
        };
        let mut s = (hdv_s + hdv_offset_m).max(0.0);
        let mut hdvs = Vec::with_capacity(1 + headways_s.len());
        for (i, h) in std::iter::once(0.0)
            .chain(headways_s.iter().copied())
            .enumerate()
        {
            s -= h * speed;
            hdvs.push(Hdv {
                car: vehicle(i as u32 + 1, hdv_lane, s),
                ego_conflict_s,
                conflict_s,
                zone_half_m,
                has_priority,
            });
        }
        World {
            kind,
            morph,
            t: 0.0,
            ego: vehicle(0, ego_lane, ego_s),
            hdvs,
        }
    }

    /// Position and heading of `v`.
    pub fn pose(&self, v: &Vehicle) -> (Vec2, f64) {
        let (p, h, _) = self.morph.lane(v.lane).to_cartesian(v.s, 0.0, 0);
        (p, h)
    }

    /// `v` as the core sees it.
    pub fn agent(&self, v: &Vehicle) -> AgentState {
        let (p, h) = self.pose(v);
        let mut a = AgentState::moving(v.id, p, h, v.v);
        a.acc = Vec2::from_angle(h).scale(v.a);
        a
    }

    /// The scene the core decides on: the ego and every HDV.
    pub fn scene(&self) -> Scene {
        let mut scene = Scene::new(self.t, self.agent(&self.ego), self.ego.lane);
        for h in &self.hdvs {
            scene.push(self.agent(&h.car));
        }
        scene
    }

    /// Distances of the ego's and HDV `i`'s centres to their conflict point along their lanes,
    /// m (negative once past it).
    pub fn to_conflict(&self, i: usize) -> (f64, f64) {
        let h = &self.hdvs[i];
        (h.ego_conflict_s - self.ego.s, h.conflict_s - h.car.s)
    }

    /// HDV `i`'s leader on its lane, the nearest HDV ahead: (bumper gap, m; its speed, m/s).
    /// Infinite gap when none.
    pub fn leader_of(&self, i: usize) -> (f64, f64) {
        let me = &self.hdvs[i].car;
        self.hdvs
            .iter()
            .map(|h| &h.car)
            .filter(|o| o.id != me.id && o.lane == me.lane && o.s > me.s)
            .map(|o| ((o.s - me.s - CAR_LENGTH_M).max(0.1), o.v))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap_or((f64::INFINITY, 0.0))
    }

    /// Fastest the CAV may drive now to take every curve within [`CURVE_LOOKAHEAD_M`] at no
    /// more than [`CURVE_LATERAL_MPS2`] of lateral acceleration, braking at `brake_mps2` before
    /// it: min over the vertices ahead of √(v_k² + 2·b·d_k), v_k = √(a_lat / κ_k), m/s.
    pub fn ego_speed_limit(&self, brake_mps2: f64) -> f64 {
        self.ego_speed_limit_at(self.ego.s, brake_mps2)
    }

    /// [`World::ego_speed_limit`] with the CAV at arc length `s` of its lane, m/s.
    pub fn ego_speed_limit_at(&self, s: f64, brake_mps2: f64) -> f64 {
        let lane = self.morph.lane(self.ego.lane);
        (0..=lane.segments())
            .map(|k| (k, lane.s_at_vertex(k)))
            .filter(|&(_, sk)| sk >= s - 1.0 && sk <= s + CURVE_LOOKAHEAD_M)
            .map(|(k, sk)| {
                let kappa = lane.curvature_at(sk, k.saturating_sub(1));
                if kappa < 1e-9 {
                    return f64::INFINITY;
                }
                let v = (CURVE_LATERAL_MPS2 / kappa).sqrt();
                (v * v + 2.0 * brake_mps2 * (sk - s).max(0.0)).sqrt()
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// In the merge, the nearest HDV past the merge point and ahead of the CAV as its leader:
    /// (bumper gap, m; its speed, m/s). Infinite gap otherwise.
    pub fn ego_leader(&self) -> (f64, f64) {
        if self.kind != ScenarioKind::Merge {
            return (f64::INFINITY, 0.0);
        }
        (0..self.hdvs.len())
            .filter_map(|i| {
                let (ego_d, hdv_d) = self.to_conflict(i);
                (hdv_d < 0.0 && hdv_d < ego_d)
                    .then(|| ((ego_d - hdv_d - CAR_LENGTH_M).max(0.1), self.hdvs[i].car.v))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap_or((f64::INFINITY, 0.0))
    }

    /// True once the ego's centre is `beyond_m` past every HDV's conflict zone.
    pub fn ego_past_zones(&self, beyond_m: f64) -> bool {
        (0..self.hdvs.len()).all(|i| self.to_conflict(i).0 < -(self.hdvs[i].zone_half_m + beyond_m))
    }

    /// The junction: the bounding box (lower-left, upper-right corner) of every lane's stop
    /// line, m. At the paper's intersection the box |x|, |y| ≤ 10; at the merge, the taper.
    pub fn junction(&self) -> (Vec2, Vec2) {
        self.morph.lanes().iter().fold(
            (
                Vec2::new(f64::INFINITY, f64::INFINITY),
                Vec2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
            ),
            |(lo, hi), lane| {
                let (p, _, _) = lane.to_cartesian(lane.stop_s, 0.0, 0);
                (
                    Vec2::new(lo.x.min(p.x), lo.y.min(p.y)),
                    Vec2::new(hi.x.max(p.x), hi.y.max(p.y)),
                )
            },
        )
    }

    /// Advances every vehicle by [`DT`] with the given accelerations (the HDVs' in their
    /// order; clamped to what a car can do; speeds never go negative).
    pub fn step(&mut self, ego_accel: f64, hdv_accels: &[f64]) {
        let cars = std::iter::once(&mut self.ego).chain(self.hdvs.iter_mut().map(|h| &mut h.car));
        for (v, &a) in cars.zip(std::iter::once(&ego_accel).chain(hdv_accels)) {
            let a = if a.is_finite() { a } else { -MAX_BRAKE_MPS2 };
            let a = a.clamp(-MAX_BRAKE_MPS2, MAX_ACCEL_MPS2);
            let v1 = (v.v + a * DT).max(0.0);
            v.a = (v1 - v.v) / DT;
            v.s += 0.5 * (v.v + v1) * DT;
            v.v = v1;
        }
        self.t += DT;
    }

    /// True when the ego's footprint overlaps any HDV's.
    pub fn collided(&self) -> bool {
        let (p, h) = self.pose(&self.ego);
        let ego = footprint(p, h);
        self.hdvs.iter().any(|o| {
            let (p, h) = self.pose(&o.car);
            overlap(&ego, &footprint(p, h))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_scenario_starts_where_the_paper_says() {
        let w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let (e, _) = w.pose(&w.ego);
        let (h, _) = w.pose(&w.hdvs[0].car);
        assert!((e.x - 40.0).abs() < 1e-6 && (e.y - 5.0).abs() < 1e-6);
        assert!((h.x + 40.0).abs() < 1e-6 && (h.y + 5.0).abs() < 1e-6);
        assert!(w.hdvs[0].ego_conflict_s > 30.0 && w.hdvs[0].conflict_s > 30.0);
        assert!(w.hdvs[0].has_priority);
        assert!(!w.collided());
    }

    #[test]
    fn vehicles_at_the_conflict_point_collide() {
        let mut w = World::new(ScenarioKind::LeftTurn, 0.0, 0.0);
        let h = w.hdvs[0];
        w.ego.s = h.ego_conflict_s;
        w.hdvs[0].car.s = h.conflict_s;
        assert!(w.collided());
        w.hdvs[0].car.s = h.conflict_s - ZONE_HALF_M;
        assert!(!w.collided());
        assert!(
            h.zone_half_m < 6.0,
            "a right-angle crossing: {}",
            h.zone_half_m
        );
        let m = World::new(ScenarioKind::Merge, 0.0, 0.0);
        assert!(
            m.hdvs[0].zone_half_m > 10.0,
            "a shallow merge: {}",
            m.hdvs[0].zone_half_m
        );
    }

    #[test]
    fn integration_keeps_speed_non_negative_and_records_the_applied_acceleration() {
        let mut w = World::new(ScenarioKind::Merge, 1.0, 0.0);
        w.step(-8.0, &[2.0]);
        assert_eq!(w.ego.v, 0.6);
        assert!((w.ego.a + 8.0).abs() < 1e-9);
        for _ in 0..10 {
            w.step(-8.0, &[0.0]);
        }
        assert_eq!(w.ego.v, 0.0);
        assert_eq!(w.ego.a, 0.0);
        assert!((w.hdvs[0].car.v - 1.1).abs() < 1e-9);
    }

    #[test]
    fn the_minor_road_hdv_starts_as_far_from_the_conflict_as_the_cav() {
        let w = World::new(ScenarioKind::LeftTurnPriority, 8.0, 0.0);
        let (ego_d, hdv_d) = w.to_conflict(0);
        assert!((ego_d - hdv_d).abs() < 1e-9, "{ego_d} {hdv_d}");
        let (p, h) = w.pose(&w.hdvs[0].car);
        assert!((p.x - 5.0).abs() < 1e-6 && p.y < -10.0, "{p:?}");
        assert!((h - std::f64::consts::FRAC_PI_2).abs() < 1e-6, "northbound");
        assert!(!w.hdvs[0].has_priority);
        // The CAV crosses the northbound lane where its turn begins, (5, 5).
        let (c, _, _) = w
            .morph
            .lane(w.ego.lane)
            .to_cartesian(w.hdvs[0].ego_conflict_s, 0.0, 0);
        assert!(c.minus(Vec2::new(5.0, 5.0)).norm() < 1e-6, "{c:?}");
    }

    #[test]
    fn followers_queue_behind_the_first_hdv_and_follow_their_leader() {
        let w = World::with_followers(ScenarioKind::Stream, 8.0, 0.0, &[2.0, 3.0]);
        assert_eq!(w.hdvs.len(), 3);
        let s: Vec<f64> = w.hdvs.iter().map(|h| h.car.s).collect();
        assert_eq!(s, vec![0.0, -16.0, -40.0]);
        assert!(w.hdvs.iter().all(|h| h.car.lane == paper::HDV_STRAIGHT));
        assert_eq!(w.leader_of(0).0, f64::INFINITY);
        assert_eq!(w.leader_of(1), (16.0 - CAR_LENGTH_M, 8.0));
        assert_eq!(w.leader_of(2), (24.0 - CAR_LENGTH_M, 8.0));
        assert_eq!(w.scene().n_agents, 3);
        let (lo, hi) = w.junction();
        assert_eq!((lo.x, lo.y, hi.x, hi.y), (-10.0, -10.0, 10.0, 10.0));
    }
}
