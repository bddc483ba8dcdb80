//! The kinematic world of one episode: the CAV (ego) and one human-driven vehicle (HDV), each
//! bound to a lane of the core's morphology, integrated at [`DT`] (20 Hz). Geometry and the
//! conflict zone come from [`Morphology`]: the conflict point of the two lanes, and a zone of
//! ±[`ZONE_HALF_M`] along each lane around it.

use concord_core::scene::{merge, paper, AgentState, BuiltIn, Morphology, Scene, Vec2};

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

/// Which scenario.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ScenarioKind {
    /// The paper's unprotected left turn: CAV from (40, 5) turning left, HDV from (−40, −5)
    /// straight on.
    LeftTurn,
    /// The on-ramp merge: CAV on the ramp, HDV on the main lane.
    Merge,
}

impl ScenarioKind {
    pub fn name(self) -> &'static str {
        match self {
            ScenarioKind::LeftTurn => "left_turn",
            ScenarioKind::Merge => "merge",
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

/// The world of one episode.
#[derive(Clone, Debug)]
pub struct World {
    pub kind: ScenarioKind,
    pub morph: Morphology,
    /// Simulated time, s.
    pub t: f64,
    pub ego: Vehicle,
    pub hdv: Vehicle,
    /// Arc lengths of the conflict point on the ego's and the HDV's lane, m.
    pub ego_conflict_s: f64,
    pub hdv_conflict_s: f64,
    /// Half-length of the conflict zone along each lane, m: at least [`ZONE_HALF_M`], and
    /// before a merge as far back as the two lanes are closer than a car width and a margin.
    pub zone_half_m: f64,
}

impl World {
    /// The scenario with both vehicles at `speed`, the HDV shifted `hdv_offset_m` along its lane
    /// from the nominal start (positive: closer to the conflict).
    pub fn new(kind: ScenarioKind, speed: f64, hdv_offset_m: f64) -> World {
        let (built_in, ego_lane, hdv_lane) = match kind {
            ScenarioKind::LeftTurn => (
                BuiltIn::PaperIntersection,
                paper::CAV_LEFT,
                paper::HDV_STRAIGHT,
            ),
            ScenarioKind::Merge => (BuiltIn::Merge, merge::RAMP, merge::MAIN),
        };
        let morph = Morphology::built_in(built_in);
        let (ego_conflict_s, hdv_conflict_s) = morph
            .conflict_between(ego_lane, hdv_lane)
            .expect("the scenario's lanes conflict");
        // Left turn: the paper's starts. Merge: both 60 m before the merge point.
        let (ego_s, hdv_s) = match kind {
            ScenarioKind::LeftTurn => (0.0, 0.0),
            ScenarioKind::Merge => (ego_conflict_s - 60.0, hdv_conflict_s - 60.0),
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
        let zone_half_m = (reach(ego_lane, hdv_lane, ego_conflict_s).max(reach(
            hdv_lane,
            ego_lane,
            hdv_conflict_s,
        )) + CAR_LENGTH_M / 2.0)
            .max(ZONE_HALF_M);
        let vehicle = |id, lane, s| Vehicle {
            id,
            lane,
            s,
            v: speed,
            a: 0.0,
        };
        World {
            kind,
            morph,
            t: 0.0,
            ego: vehicle(0, ego_lane, ego_s),
            hdv: vehicle(1, hdv_lane, (hdv_s + hdv_offset_m).max(0.0)),
            ego_conflict_s,
            hdv_conflict_s,
            zone_half_m,
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

    /// The scene the core decides on.
    pub fn scene(&self) -> Scene {
        let mut scene = Scene::new(self.t, self.agent(&self.ego), self.ego.lane);
        scene.push(self.agent(&self.hdv));
        scene
    }

    /// Distances of the ego's and the HDV's centres to the conflict point along their lanes, m
    /// (negative once past it).
    pub fn to_conflict(&self) -> (f64, f64) {
        (
            self.ego_conflict_s - self.ego.s,
            self.hdv_conflict_s - self.hdv.s,
        )
    }

    /// In the merge, the HDV as the CAV's leader once it is past the merge point and ahead:
    /// (bumper gap, m; its speed, m/s). Infinite gap otherwise.
    pub fn ego_leader(&self) -> (f64, f64) {
        let (ego_d, hdv_d) = self.to_conflict();
        if self.kind == ScenarioKind::Merge && hdv_d < 0.0 && hdv_d < ego_d {
            ((ego_d - hdv_d - CAR_LENGTH_M).max(0.1), self.hdv.v)
        } else {
            (f64::INFINITY, 0.0)
        }
    }

    /// Advances both vehicles by [`DT`] with the given accelerations (clamped to what a car can
    /// do; speeds never go negative).
    pub fn step(&mut self, ego_accel: f64, hdv_accel: f64) {
        for (v, a) in [(&mut self.ego, ego_accel), (&mut self.hdv, hdv_accel)] {
            let a = if a.is_finite() { a } else { -MAX_BRAKE_MPS2 };
            let a = a.clamp(-MAX_BRAKE_MPS2, MAX_ACCEL_MPS2);
            let v1 = (v.v + a * DT).max(0.0);
            v.a = (v1 - v.v) / DT;
            v.s += 0.5 * (v.v + v1) * DT;
            v.v = v1;
        }
        self.t += DT;
    }

    /// True when the two footprints overlap (separating-axis test on oriented rectangles).
    pub fn collided(&self) -> bool {
        let corners = |v: &Vehicle| {
            let (p, h) = self.pose(v);
            let f = Vec2::from_angle(h);
            let l = Vec2::new(-f.y, f.x);
            let (hl, hw) = (CAR_LENGTH_M / 2.0, CAR_WIDTH_M / 2.0);
            [
                p.plus(f.scale(hl)).plus(l.scale(hw)),
                p.plus(f.scale(hl)).minus(l.scale(hw)),
                p.minus(f.scale(hl)).plus(l.scale(hw)),
                p.minus(f.scale(hl)).minus(l.scale(hw)),
            ]
        };
        let (a, b) = (corners(&self.ego), corners(&self.hdv));
        let axes = |c: &[Vec2; 4]| {
            let e1 = c[0].minus(c[2]);
            let e2 = c[0].minus(c[1]);
            [e1, e2]
        };
        for axis in axes(&a).into_iter().chain(axes(&b)) {
            let project = |c: &[Vec2; 4]| {
                c.iter()
                    .map(|p| p.dot(axis))
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                        (lo.min(x), hi.max(x))
                    })
            };
            let (a0, a1) = project(&a);
            let (b0, b1) = project(&b);
            if a1 < b0 || b1 < a0 {
                return false;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_scenario_starts_where_the_paper_says() {
        let w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let (e, _) = w.pose(&w.ego);
        let (h, _) = w.pose(&w.hdv);
        assert!((e.x - 40.0).abs() < 1e-6 && (e.y - 5.0).abs() < 1e-6);
        assert!((h.x + 40.0).abs() < 1e-6 && (h.y + 5.0).abs() < 1e-6);
        assert!(w.ego_conflict_s > 30.0 && w.hdv_conflict_s > 30.0);
        assert!(!w.collided());
    }

    #[test]
    fn vehicles_at_the_conflict_point_collide() {
        let mut w = World::new(ScenarioKind::LeftTurn, 0.0, 0.0);
        w.ego.s = w.ego_conflict_s;
        w.hdv.s = w.hdv_conflict_s;
        assert!(w.collided());
        w.hdv.s = w.hdv_conflict_s - ZONE_HALF_M;
        assert!(!w.collided());
        assert!(
            w.zone_half_m < 6.0,
            "a right-angle crossing: {}",
            w.zone_half_m
        );
        let m = World::new(ScenarioKind::Merge, 0.0, 0.0);
        assert!(m.zone_half_m > 10.0, "a shallow merge: {}", m.zone_half_m);
    }

    #[test]
    fn integration_keeps_speed_non_negative_and_records_the_applied_acceleration() {
        let mut w = World::new(ScenarioKind::Merge, 1.0, 0.0);
        w.step(-8.0, 2.0);
        assert_eq!(w.ego.v, 0.6);
        assert!((w.ego.a + 8.0).abs() < 1e-9);
        for _ in 0..10 {
            w.step(-8.0, 0.0);
        }
        assert_eq!(w.ego.v, 0.0);
        assert_eq!(w.ego.a, 0.0);
        assert!((w.hdv.v - 1.1).abs() < 1e-9);
    }
}
