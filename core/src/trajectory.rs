//! Trajectory generation: quartic s(t) (eq. 17, 19–20) and quintic l(t) (eq. 18, 21–22) in the
//! Frenet frame of the ego's lane, Monte Carlo terminal states s_end = f_a(s_start) ⊙ (1 + σ𝒩)
//! (eq. 23), candidates τ_k (eq. 24) scored by S_k = c_e·T_n/T_ref + c_s·∫|jerk|/J_max
//! (Table 2) plus a lane-centring term c_l·|l_T|/l_max, hard limits and collision checks, and
//! the minimum-risk fallback.
//!
//! Speed comes from analytic limit checks: s̈ is quadratic and l̈ cubic, so every extremum of
//! speed, acceleration and jerk is found from polynomial roots in O(1), and the jerk integrals
//! are total variations of the accelerations. Only position needs the time grid: each point is
//! tested against a per-step occupancy of the ego's lane (boxes in (s, l)) built once per cycle
//! from the predicted paths of the other road users, with a whole-step rejection interval first.

use libm::{cos, fabs, sin, sqrt};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

use crate::choice::Profile;
use crate::params::TrajectoryParams;
use crate::scene::{AgentState, Lane, Morphology, ProcessState, Vec2, MAX_AGENTS, MAX_CONFLICTS};

/// Most Monte Carlo samples per cycle.
pub const MAX_SAMPLES: usize = 1024;
/// Most time steps of the horizon.
pub const MAX_STEPS: usize = 64;
/// Trajectory points: t = 0 and every step.
pub const MAX_POINTS: usize = MAX_STEPS + 1;
/// Occupancy boxes per time step; on overflow boxes are merged conservatively.
pub const MAX_BOXES: usize = 32;
/// Bins of the curvature speed-cap table.
pub const VCAP_BINS: usize = 256;
/// Largest overshoot of a quintic that brings a lateral speed u to rest over T with no change
/// of offset (l̈ = 0 at both ends), per u·T: 16/81, at T/3.
const OVERSHOOT_PER_UT: f64 = 16.0 / 81.0;
/// Relative error below which a footprint box counts as exact: the lane's curvature times the
/// box's lateral reach, and |cos·sin| of the relative heading.
const FRAME_EXACT_TOLERANCE: f64 = 0.02;
/// Inside the junction, a drive-on candidate of the minimum-risk fallback is refused when it is
/// predicted to collide more than this many planning steps before braking is: closer than
/// that, the two predictions meet the same crossing car within the forecasts' resolution,
/// and standing in its path is the worse of the two.
const DRIVE_ON_STEPS: f64 = 3.0;
/// Bins of the ego lane's pose table over the planning window.
const FRAME_BINS: usize = 256;
/// Below this speed at the end of the horizon a candidate stands, m/s.
const STANDING_MPS: f64 = 0.3;
/// Most time steps before now and past the horizon searched for another road user's passage
/// (its post-encroachment margins reach that far).
pub const MAX_SWEEP_STEPS: usize = 48;

/// s(t) = a₀ + a₁t + a₂t² + a₃t³ + a₄t⁴ (eq. 17).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Quartic {
    pub c: [f64; 5],
}

impl Quartic {
    /// Fits s(0) = s₀, ṡ(0) = v₀, s̈(0) = a₀ (eq. 19) and ṡ(T) = v_T, s̈(T) = a_T (eq. 20).
    pub fn fit(s0: f64, v0: f64, a0: f64, vt: f64, at: f64, t: f64) -> Self {
        let a = vt - v0 - a0 * t;
        let b = at - a0;
        let t2 = t * t;
        let c4 = (b * t - 2.0 * a) / (4.0 * t2 * t);
        let c3 = (a - 4.0 * c4 * t2 * t) / (3.0 * t2);
        Quartic {
            c: [s0, v0, 0.5 * a0, c3, c4],
        }
    }
    pub fn pos(&self, t: f64) -> f64 {
        let c = &self.c;
        c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * c[4])))
    }
    pub fn vel(&self, t: f64) -> f64 {
        let c = &self.c;
        c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * 4.0 * c[4]))
    }
    pub fn acc(&self, t: f64) -> f64 {
        let c = &self.c;
        2.0 * c[2] + t * (6.0 * c[3] + t * 12.0 * c[4])
    }
    pub fn jerk(&self, t: f64) -> f64 {
        6.0 * self.c[3] + 24.0 * self.c[4] * t
    }
}

/// l(t) = b₀ + b₁t + … + b₅t⁵ (eq. 18).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Quintic {
    pub c: [f64; 6],
}

impl Quintic {
    /// Fits l, l̇, l̈ at 0 (eq. 21) and at T (eq. 22).
    pub fn fit(l0: f64, v0: f64, a0: f64, lt: f64, vt: f64, at: f64, t: f64) -> Self {
        let d0 = lt - (l0 + v0 * t + 0.5 * a0 * t * t);
        let d1 = vt - (v0 + a0 * t);
        let d2 = at - a0;
        let t2 = t * t;
        let t3 = t2 * t;
        Quintic {
            c: [
                l0,
                v0,
                0.5 * a0,
                (10.0 * d0 - 4.0 * d1 * t + 0.5 * d2 * t2) / t3,
                (-15.0 * d0 + 7.0 * d1 * t - d2 * t2) / (t3 * t),
                (6.0 * d0 - 3.0 * d1 * t + 0.5 * d2 * t2) / (t3 * t2),
            ],
        }
    }
    pub fn pos(&self, t: f64) -> f64 {
        let c = &self.c;
        c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
    }
    pub fn vel(&self, t: f64) -> f64 {
        let c = &self.c;
        c[1] + t * (2.0 * c[2] + t * (3.0 * c[3] + t * (4.0 * c[4] + t * 5.0 * c[5])))
    }
    pub fn acc(&self, t: f64) -> f64 {
        let c = &self.c;
        2.0 * c[2] + t * (6.0 * c[3] + t * (12.0 * c[4] + t * 20.0 * c[5]))
    }
    pub fn jerk(&self, t: f64) -> f64 {
        let c = &self.c;
        6.0 * c[3] + t * (24.0 * c[4] + t * 60.0 * c[5])
    }
}

/// Roots of a·t² + b·t + c = 0 strictly inside (0, T), ascending.
fn roots_in(a: f64, b: f64, c: f64, t_end: f64) -> ([f64; 2], usize) {
    let mut out = [0.0; 2];
    let mut n = 0;
    let mut push = |r: f64| {
        if r > 0.0 && r < t_end {
            out[n] = r;
            n += 1;
        }
    };
    if fabs(a) < 1e-12 {
        if fabs(b) > 1e-12 {
            push(-c / b);
        }
    } else {
        let disc = b * b - 4.0 * a * c;
        if disc >= 0.0 {
            let sq = sqrt(disc);
            let (r1, r2) = ((-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a));
            let (lo, hi) = if r1 <= r2 { (r1, r2) } else { (r2, r1) };
            push(lo);
            push(hi);
        }
    }
    (out, n)
}

/// The ego's Frenet state at t = 0.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrenetState {
    pub s: f64,
    pub ds: f64,
    pub dds: f64,
    pub l: f64,
    pub dl: f64,
    pub ddl: f64,
}

/// What a point of a candidate meets in the occupancy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hit {
    Free,
    /// Another road user's footprint (with its clearance).
    Contact,
}

/// A post-encroachment margin: while another road user is, was or will be in its passage of
/// a conflict zone, the ego keeps its centre out of its own passage of that zone, at any
/// lateral offset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PassageMargin {
    /// The ego's passage, arc length along its lane, m.
    pub s: [f64; 2],
    /// When the ego may not be in it, s from now: from `pet_s[1]` before the other enters its
    /// passage until `pet_s[0]` after it has left it ([`Forecast::pet_s`]).
    pub t: [f64; 2],
}

/// The other road user's predicted footprint behind an occupancy box: centre, heading
/// (cos, sin) and the growth of its length with the prediction time, m; `exact` when the box
/// is the Minkowski sum of the two rectangles with the clearance (no narrow phase needed).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Footprint {
    pub centre: Vec2,
    pub cos: f64,
    pub sin: f64,
    pub grown: f64,
    pub exact: bool,
}

/// Where the lane bends, the part of the ego lane's frame, [s_lo, s_hi, l_lo, l_hi] (m, about
/// the other road user's foot point (`s`, `l`)), of the ego centres whose rectangle (half
/// extents `ego`, along and across its lane) can meet another road user's (half extents
/// `tangential` and `radial` to the lane at its foot point, clearance included), for egos at
/// most `l_ego` m off the lane; `None` where none can. The lane bends at up to `kappa` 1/m
/// towards `side` (+1 left, −1 right, 0 both ways). On an arc of radius ρ = 1/κ about O, a
/// rectangle centred at radius r lies within its radial half extent of r inwards, within
/// √((r + radial)² + tangential²) outwards and within atan(tangential / (r − radial)) of its
/// own angle about O; two can meet only where those rings and sectors overlap, which bounds
/// the ego's l (by its radius) and its s (ρ times the angle). 0.25 m more for the polyline
/// and the tabulated frame.
#[allow(clippy::too_many_arguments)]
fn curved_reach(
    (s, l): (f64, f64),
    ego: (f64, f64),
    tangential: f64,
    radial: f64,
    kappa: f64,
    side: f64,
    l_ego: f64,
) -> Option<[f64; 4]> {
    const SLACK_M: f64 = 0.25;
    let (hl, hw) = ego;
    let straight = [
        s - hl - tangential - SLACK_M,
        s + hl + tangential + SLACK_M,
        l - hw - radial - SLACK_M,
        l + hw + radial + SLACK_M,
    ];
    if kappa < 1e-9 {
        return Some(straight);
    }
    let rho = 1.0 / kappa;
    let half_circle = core::f64::consts::PI * rho;
    let diagonal = sqrt(tangential * tangential + radial * radial);
    // The nearest the ego's rectangle comes to O.
    let ego_in = rho - l_ego - hw;
    if side == 0.0 || ego_in < 0.5 {
        // Bends both ways, or so sharply that the ego can reach the centre: half the circle
        // along, and across both rectangles' diagonals.
        let d = sqrt(hl * hl + hw * hw) + diagonal;
        return Some([
            s - half_circle,
            s + half_circle,
            l - d - SLACK_M,
            l + d + SLACK_M,
        ]);
    }
    // Radii about O of the other's centre and of its nearest and furthest points.
    let r = rho - side * l;
    let (near, far) = (
        (r - radial).max(0.0),
        sqrt((r + radial) * (r + radial) + tangential * tangential),
    );
    // The ego's centre radii whose rectangle spans part of [near, far]: its inner edge is at
    // most `far`, its outer corners at least `near`.
    let r_hi = far + hw;
    let r_lo = if near > hl {
        sqrt(near * near - hl * hl) - hw
    } else {
        0.0
    };
    let (r_lo, r_hi) = (r_lo.max(rho - l_ego), r_hi.min(rho + l_ego));
    if r_lo > r_hi {
        return None;
    }
    // The other's points the ego can touch are at least `touch` from O: within
    // asin(diagonal / touch) of the other's own angle, as well as within its own sector.
    let touch = (r_lo - hw).max(1e-3);
    let sector = if near > 0.3 {
        libm::atan(tangential / near)
    } else {
        core::f64::consts::PI
    };
    let reachable = if diagonal < touch {
        libm::asin(diagonal / touch)
    } else {
        core::f64::consts::PI
    };
    let angle = libm::atan(hl / touch) + sector.min(reachable);
    let along = (rho * angle).min(half_circle) + SLACK_M;
    // l = side × (ρ − radius).
    let (l_a, l_b) = (side * (rho - r_hi), side * (rho - r_lo));
    Some([
        (s - along).min(straight[0]),
        (s + along).max(straight[1]),
        (l_a.min(l_b) - SLACK_M).min(straight[2]),
        (l_a.max(l_b) + SLACK_M).max(straight[3]),
    ])
}

/// Poses of the ego lane's reference line over the planning window, tabulated so that the
/// ego's footprint can be placed at any (s, l) without searching the polyline.
#[derive(Clone, Copy, Debug)]
struct LaneFrame {
    s_lo: f64,
    inv_bin: f64,
    x: [f64; FRAME_BINS + 1],
    y: [f64; FRAME_BINS + 1],
    cos: [f64; FRAME_BINS + 1],
    sin: [f64; FRAME_BINS + 1],
}

impl Default for LaneFrame {
    fn default() -> Self {
        LaneFrame {
            s_lo: 0.0,
            inv_bin: 1.0,
            x: [0.0; FRAME_BINS + 1],
            y: [0.0; FRAME_BINS + 1],
            cos: [1.0; FRAME_BINS + 1],
            sin: [0.0; FRAME_BINS + 1],
        }
    }
}

impl LaneFrame {
    fn fill(&mut self, lane: &Lane, s_lo: f64, s_hi: f64) {
        let bin = ((s_hi - s_lo) / FRAME_BINS as f64).max(1e-3);
        self.s_lo = s_lo;
        self.inv_bin = 1.0 / bin;
        let mut hint = lane.segment_at(s_lo, 0);
        for k in 0..=FRAME_BINS {
            let (q, tangent, seg) = lane.pose_at(s_lo + k as f64 * bin, hint);
            hint = seg;
            self.x[k] = q.x;
            self.y[k] = q.y;
            self.cos[k] = cos(tangent);
            self.sin[k] = sin(tangent);
        }
    }

    /// The ego's centre and heading (cos, sin) at Frenet (s, l), interpolated between bins
    /// (extrapolated along the end bins outside the window).
    fn pose(&self, s: f64, l: f64) -> (Vec2, f64, f64) {
        let u = (s - self.s_lo) * self.inv_bin;
        let k = (u.max(0.0) as usize).min(FRAME_BINS - 1);
        let f = u - k as f64;
        let lerp = |a: &[f64; FRAME_BINS + 1]| a[k] + (a[k + 1] - a[k]) * f;
        let (c, s_) = (lerp(&self.cos), lerp(&self.sin));
        let norm = sqrt(c * c + s_ * s_).max(1e-9);
        let (c, s_) = (c / norm, s_ / norm);
        (
            Vec2::new(lerp(&self.x) - s_ * l, lerp(&self.y) + c * l),
            c,
            s_,
        )
    }
}

/// True when rectangles with centres `a`, `b`, headings (cos, sin) and half extents
/// (length, width) overlap (separating-axis test on their four edge normals).
fn rectangles_overlap(
    a: Vec2,
    (ac, as_): (f64, f64),
    (al, aw): (f64, f64),
    b: Vec2,
    (bc, bs): (f64, f64),
    (bl, bw): (f64, f64),
) -> bool {
    let d = b.minus(a);
    let axes = [(ac, as_), (-as_, ac), (bc, bs), (-bs, bc)];
    axes.iter().all(|&(x, y)| {
        let radius_a = al * fabs(ac * x + as_ * y) + aw * fabs(-as_ * x + ac * y);
        let radius_b = bl * fabs(bc * x + bs * y) + bw * fabs(-bs * x + bc * y);
        fabs(d.x * x + d.y * y) <= radius_a + radius_b
    })
}

/// Boxes in (s, l) that the ego's reference point may not enter, per time step: the others'
/// footprints. A footprint box is the broad phase: a point inside
/// one is a contact only when the ego's rectangle placed there overlaps the other's predicted
/// rectangle with its clearance (boxes in a curved lane's frame are larger than the cars, and
/// a car in the opposite lane beside the start of a turn would otherwise touch a car standing
/// at the stop line). Merged boxes are contacts without that test.
#[derive(Clone, Copy, Debug)]
pub struct Occupancy {
    s_lo: [[f64; MAX_BOXES]; MAX_STEPS],
    s_hi: [[f64; MAX_BOXES]; MAX_STEPS],
    l_lo: [[f64; MAX_BOXES]; MAX_STEPS],
    l_hi: [[f64; MAX_BOXES]; MAX_STEPS],
    /// The footprint of a box that holds one road user's, for the exact test.
    footprint: [[Option<Footprint>; MAX_BOXES]; MAX_STEPS],
    n: [u8; MAX_STEPS],
    /// Union s-interval of the step's boxes, for whole-step rejection.
    step_lo: [f64; MAX_STEPS],
    step_hi: [f64; MAX_STEPS],
    steps: usize,
    frame: LaneFrame,
    /// Half length and half width of the ego and of the others' rectangles, m.
    half: (f64, f64),
    /// The clearance added around the others' rectangles, m.
    clearance: f64,
}

impl Default for Occupancy {
    fn default() -> Self {
        Occupancy {
            s_lo: [[0.0; MAX_BOXES]; MAX_STEPS],
            s_hi: [[0.0; MAX_BOXES]; MAX_STEPS],
            l_lo: [[0.0; MAX_BOXES]; MAX_STEPS],
            l_hi: [[0.0; MAX_BOXES]; MAX_STEPS],
            footprint: [[None; MAX_BOXES]; MAX_STEPS],
            n: [0; MAX_STEPS],
            step_lo: [f64::INFINITY; MAX_STEPS],
            step_hi: [f64::NEG_INFINITY; MAX_STEPS],
            steps: 0,
            frame: LaneFrame::default(),
            half: (2.4, 1.0),
            clearance: 0.0,
        }
    }
}

impl Occupancy {
    fn clear(&mut self, steps: usize) {
        self.steps = steps;
        self.n[..steps].fill(0);
        self.step_lo[..steps].fill(f64::INFINITY);
        self.step_hi[..steps].fill(f64::NEG_INFINITY);
    }

    /// Adds a box at `step` (`footprint`: the one road user's rectangle behind it; where it is
    /// not exact, the box is where the rectangles are tested; `None`: all of the box blocks). A
    /// box inside another that blocks at least as much is dropped (a box that covers another
    /// footprint's loses its rectangle and blocks all of itself; one whose rectangle decides
    /// covers nothing); when the step is full, it is merged into the box whose area grows
    /// least (a merged box loses its rectangle).
    fn add(
        &mut self,
        step: usize,
        s_lo: f64,
        s_hi: f64,
        l_lo: f64,
        l_hi: f64,
        footprint: Option<Footprint>,
    ) {
        let k = self.n[step] as usize;
        // A box whose rectangles decide does not block all of itself: it covers only its own
        // footprint again.
        let covering = (0..k).find(|&b| {
            (self.footprint[step][b].is_none_or(|f| f.exact)
                || self.footprint[step][b] == footprint)
                && self.s_lo[step][b] <= s_lo
                && self.s_hi[step][b] >= s_hi
                && self.l_lo[step][b] <= l_lo
                && self.l_hi[step][b] >= l_hi
        });
        if let Some(b) = covering {
            // A footprint inside another footprint's box: the covering box keeps both by
            // blocking all of itself.
            if self.footprint[step][b] != footprint {
                self.footprint[step][b] = None;
            }
            return;
        }
        if k < MAX_BOXES {
            self.s_lo[step][k] = s_lo;
            self.s_hi[step][k] = s_hi;
            self.l_lo[step][k] = l_lo;
            self.l_hi[step][k] = l_hi;
            self.footprint[step][k] = footprint;
            self.n[step] += 1;
        } else {
            let mut best = 0;
            let mut best_cost = f64::INFINITY;
            for b in 0..MAX_BOXES {
                let (b_s_lo, b_s_hi) = (self.s_lo[step][b], self.s_hi[step][b]);
                let (b_l_lo, b_l_hi) = (self.l_lo[step][b], self.l_hi[step][b]);
                let merged =
                    (b_s_hi.max(s_hi) - b_s_lo.min(s_lo)) * (b_l_hi.max(l_hi) - b_l_lo.min(l_lo));
                let growth = merged - (b_s_hi - b_s_lo) * (b_l_hi - b_l_lo);
                if growth < best_cost {
                    best_cost = growth;
                    best = b;
                }
            }
            self.s_lo[step][best] = self.s_lo[step][best].min(s_lo);
            self.s_hi[step][best] = self.s_hi[step][best].max(s_hi);
            self.l_lo[step][best] = self.l_lo[step][best].min(l_lo);
            self.l_hi[step][best] = self.l_hi[step][best].max(l_hi);
            self.footprint[step][best] = None;
        }
        self.step_lo[step] = self.step_lo[step].min(s_lo);
        self.step_hi[step] = self.step_hi[step].max(s_hi);
    }

    /// True when `s` lies in the union s-interval of the boxes of `step`.
    #[inline(always)]
    pub fn may_hit(&self, step: usize, s: f64) -> bool {
        s >= self.step_lo[step] && s <= self.step_hi[step]
    }

    /// What the ego centred at (s, l) meets at `step`.
    #[inline(always)]
    pub fn hit(&self, step: usize, s: f64, l: f64) -> Hit {
        if !self.may_hit(step, s) {
            return Hit::Free;
        }
        let mut ego = None;
        for b in self.containing(step, s, l) {
            let f = match self.footprint[step][b] {
                Some(f) if !f.exact => f,
                _ => return Hit::Contact,
            };
            let (centre, c, s_) = *ego.get_or_insert_with(|| self.frame.pose(s, l));
            let (hl, hw) = self.half;
            let other = (hl + f.grown + self.clearance, hw + self.clearance);
            if rectangles_overlap(centre, (c, s_), (hl, hw), f.centre, (f.cos, f.sin), other) {
                return Hit::Contact;
            }
        }
        Hit::Free
    }

    /// True when the ego centred at (s, l) at `step` overlaps another road user's predicted
    /// rectangle itself, without clearance or growth (a merged box counts as overlapping).
    pub fn collides(&self, step: usize, s: f64, l: f64) -> bool {
        if !self.may_hit(step, s) {
            return false;
        }
        let (hl, hw) = self.half;
        let mut ego = None;
        self.containing(step, s, l).any(|b| {
            self.footprint[step][b].is_none_or(|f| {
                let (centre, c, s_) = *ego.get_or_insert_with(|| self.frame.pose(s, l));
                rectangles_overlap(
                    centre,
                    (c, s_),
                    (hl, hw),
                    f.centre,
                    (f.cos, f.sin),
                    (hl, hw),
                )
            })
        })
    }

    /// Indices of the boxes of `step` that contain (s, l).
    #[inline(always)]
    fn containing(&self, step: usize, s: f64, l: f64) -> impl Iterator<Item = usize> + '_ {
        (0..self.n[step] as usize).filter(move |&b| {
            s >= self.s_lo[step][b]
                && s <= self.s_hi[step][b]
                && l >= self.l_lo[step][b]
                && l <= self.l_hi[step][b]
        })
    }

    /// Boxes at `step`, as (s_lo, s_hi, l_lo, l_hi).
    pub fn boxes(&self, step: usize) -> impl Iterator<Item = (f64, f64, f64, f64)> + '_ {
        (0..self.n[step] as usize).map(move |b| {
            (
                self.s_lo[step][b],
                self.s_hi[step][b],
                self.l_lo[step][b],
                self.l_hi[step][b],
            )
        })
    }
}

/// How the planner expects another road user to move.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Forecast {
    /// Acceleration along its lane, m/s² (what its motion shows).
    pub accel: f64,
    /// It stops this far ahead along its lane, m, braking evenly (∞: it drives on at `accel`).
    pub stop_in_m: f64,
    /// Post-encroachment margins kept to it, s: [behind, ahead]. The ego stays out of its own
    /// passage from `ahead` s before this road user enters its passage until `behind` s after
    /// it has left it ([`PassageMargin`]; 0 for road users the ego has no conflict with).
    pub pet_s: [f64; 2],
    /// Its passage of the conflict zone, distances [enter, exit] along its lane from where it
    /// is, m.
    pub pass_m: [f64; 2],
    /// The ego's passage of the same zone, distances [enter, exit] of its centre along its lane
    /// from where it is, m: the margins apply there (a post-encroachment time is measured in
    /// the conflict zone, not beside it).
    pub ego_pass_m: [f64; 2],
}

impl Default for Forecast {
    fn default() -> Self {
        Forecast {
            accel: 0.0,
            stop_in_m: f64::INFINITY,
            pet_s: [0.0; 2],
            pass_m: [f64::INFINITY; 2],
            ego_pass_m: [f64::NEG_INFINITY, f64::INFINITY],
        }
    }
}

impl Forecast {
    /// Distance it covers from speed `v` to a standstill, m (∞ when it does not brake).
    pub fn stop_distance(&self, v: f64) -> f64 {
        if self.stop_in_m.is_finite() {
            self.stop_in_m.max(0.0)
        } else if v < 1e-6 {
            0.0
        } else if self.accel < 0.0 {
            v * v / (-2.0 * self.accel)
        } else {
            f64::INFINITY
        }
    }

    /// Distance covered in `t` s from speed `v`, m, at most `v_top` m/s.
    pub fn travel(&self, v: f64, t: f64, v_top: f64) -> f64 {
        if self.stop_in_m.is_finite() {
            if self.stop_in_m <= 0.0 || v < 1e-6 {
                return 0.0;
            }
            travel(v, -v * v / (2.0 * self.stop_in_m), t, v_top)
        } else {
            travel(v, self.accel, t, v_top)
        }
    }
}

/// Predicted pose of an agent `t` s ahead: along its matched lane when it has one, otherwise
/// straight along its direction of travel; per its `forecast` (never reversing, speed at most
/// `v_max`). Returns (position, heading) and updates the lane-segment `hint`.
pub fn predict(
    agent: &AgentState,
    process: &ProcessState,
    forecast: &Forecast,
    morph: &Morphology,
    t: f64,
    v_max: f64,
    hint: &mut usize,
) -> (Vec2, f64) {
    let v = agent.speed();
    let dist = forecast.travel(v, t, v_max.max(v));
    match process.lane {
        Some(lane_id) => {
            let lane = morph.lane(lane_id);
            let (p, tangent, seg) = lane.to_cartesian(process.s_m + dist, process.l_m, *hint);
            *hint = seg;
            (p, tangent)
        }
        None => {
            let dir = agent.direction();
            (agent.pos.plus(dir.scale(dist)), libm::atan2(dir.y, dir.x))
        }
    }
}

/// Distance covered in `t` s from speed `v` at constant acceleration `a`, stopping at 0 and
/// saturating at `v_top`.
pub fn travel(v: f64, a: f64, t: f64, v_top: f64) -> f64 {
    if a < 0.0 {
        let t_stop = v / -a;
        let tt = t.min(t_stop);
        v * tt + 0.5 * a * tt * tt
    } else if a > 0.0 {
        let t_top = ((v_top - v) / a).max(0.0);
        let tt = t.min(t_top);
        v * tt + 0.5 * a * tt * tt + (t - tt) * (v + a * tt)
    } else {
        v * t
    }
}

/// One point of the output trajectory.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrajectoryPoint {
    /// Time from the cycle start, s.
    pub t: f64,
    /// Frenet s, l on the ego's lane, m.
    pub s: f64,
    pub l: f64,
    /// Cartesian position, m.
    pub x: f64,
    pub y: f64,
    /// Heading, rad.
    pub heading: f64,
    /// Speed along the lane, m/s.
    pub speed: f64,
    /// Longitudinal acceleration, m/s².
    pub accel: f64,
}

/// A planned trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trajectory {
    pub points: [TrajectoryPoint; MAX_POINTS],
    pub n: usize,
}

impl Default for Trajectory {
    fn default() -> Self {
        Trajectory {
            points: [TrajectoryPoint::default(); MAX_POINTS],
            n: 0,
        }
    }
}

impl Trajectory {
    pub fn points(&self) -> &[TrajectoryPoint] {
        &self.points[..self.n]
    }

    /// The state `t` s after the start, interpolated linearly between points (heading along
    /// the shorter arc); held at the last point beyond the end. `None` when empty.
    pub fn sample(&self, t: f64) -> Option<TrajectoryPoint> {
        let pts = self.points();
        let first = *pts.first()?;
        if t <= first.t || t.is_nan() {
            return Some(first);
        }
        let Some(k) = pts.iter().position(|q| q.t >= t) else {
            return pts.last().copied();
        };
        let (a, b) = (pts[k - 1], pts[k]);
        let u = (t - a.t) / (b.t - a.t);
        let lerp = |x: f64, y: f64| x + (y - x) * u;
        let turn = libm::remainder(b.heading - a.heading, core::f64::consts::TAU);
        Some(TrajectoryPoint {
            t,
            s: lerp(a.s, b.s),
            l: lerp(a.l, b.l),
            x: lerp(a.x, b.x),
            y: lerp(a.y, b.y),
            heading: a.heading + turn * u,
            speed: lerp(a.speed, b.speed),
            accel: lerp(a.accel, b.accel),
        })
    }
}

/// Result of one planning run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanStats {
    /// Candidates evaluated.
    pub evaluated: u16,
    /// Candidates that passed limits and collision checks.
    pub feasible: u16,
    /// Rejected by speed, acceleration, jerk or curvature limits.
    pub limit_rejects: u16,
    /// Rejected by collision.
    pub collision_rejects: u16,
    /// Rejected for ending the horizon standing inside a conflict zone.
    pub zone_rejects: u16,
    /// Feasible but scored by a number that is not finite: a defect upstream, never a plan.
    pub score_rejects: u16,
    /// S_k of the best candidate (∞ when none).
    pub best_score: f64,
}

/// The best candidate of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Candidate {
    pub s: Quartic,
    pub l: Quintic,
    /// Polynomial duration T, s.
    pub duration: f64,
    pub score: f64,
}

/// Per-cycle planning context plus the scratch of the Monte Carlo run.
#[derive(Clone, Copy, Debug)]
pub struct Planner {
    /// The ego's start state.
    pub start: FrenetState,
    /// Occupancy from predicted agents.
    pub occupancy: Occupancy,
    /// Curvature speed caps over [s₀, s₀ + reach], m/s.
    vcap: [f64; VCAP_BINS],
    vcap_inv_bin: f64,
    /// Largest reference curvature over the reach, 1/m.
    kappa_max_ahead: f64,
    /// Lowest curvature speed cap over the reach, m/s.
    vcap_min: f64,
    /// Where the first cap below the speed limit begins, m (∞ when none).
    vcap_from_s: f64,
    /// Distance whose traversal time is T_n of S_k, m.
    pub goal_distance: f64,
    /// Distance to the yield point, m, and past which the ego has cleared the conflict zone
    /// it yields at, m (both ∞ when it yields at none).
    pub yield_distance: f64,
    pub clear_distance: f64,
    /// The sampled profile yields: candidates that do not stop must end the horizon past
    /// `clear_distance` or able to stop before `yield_distance`.
    yielding: bool,
    /// Conflict zones on the ego's lane, centre arc lengths [enter, exit], m: no candidate may
    /// end the horizon standing in one.
    zones: [[f64; 2]; MAX_CONFLICTS],
    n_zones: usize,
    /// Post-encroachment margins, one per road user in conflict at most.
    margins: [PassageMargin; MAX_AGENTS],
    n_margins: usize,
    steps: usize,
    dt: f64,
    // Monte Carlo terminal states, structure of arrays.
    end_t: [f64; MAX_SAMPLES],
    end_v: [f64; MAX_SAMPLES],
    end_l: [f64; MAX_SAMPLES],
}

impl Default for Planner {
    fn default() -> Self {
        Planner {
            start: FrenetState::default(),
            occupancy: Occupancy::default(),
            vcap: [0.0; VCAP_BINS],
            vcap_inv_bin: 1.0,
            kappa_max_ahead: 0.0,
            vcap_min: 0.0,
            vcap_from_s: f64::INFINITY,
            goal_distance: 50.0,
            yield_distance: f64::INFINITY,
            clear_distance: f64::INFINITY,
            yielding: false,
            zones: [[0.0; 2]; MAX_CONFLICTS],
            n_zones: 0,
            margins: [PassageMargin::default(); MAX_AGENTS],
            n_margins: 0,
            steps: 0,
            dt: 0.1,
            end_t: [0.0; MAX_SAMPLES],
            end_v: [0.0; MAX_SAMPLES],
            end_l: [0.0; MAX_SAMPLES],
        }
    }
}

impl Planner {
    /// This cycle's post-encroachment margins.
    pub fn margins(&self) -> &[PassageMargin] {
        &self.margins[..self.n_margins]
    }

    /// Prepares a cycle: start state, curvature caps, the conflict zones of the ego's lane
    /// `lane_id` and the occupancy of `agents` (all valid agents, with their process states and
    /// forecasts). Agents following the ego in its lane are left to keep their own distance.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        &mut self,
        lane_id: u8,
        start: FrenetState,
        goal_distance: f64,
        agents: &[AgentState],
        processes: &[ProcessState; MAX_AGENTS],
        forecasts: &[Forecast; MAX_AGENTS],
        morph: &Morphology,
        p: &TrajectoryParams,
    ) {
        let lane = morph.lane(lane_id);
        self.keep_zones(morph.zones_on(lane_id));
        self.start = start;
        self.dt = p.dt_s;
        self.steps = ((p.horizon_s / p.dt_s + 1e-9) as usize).clamp(1, MAX_STEPS);
        self.goal_distance = goal_distance.max(1.0);
        let reach = p.max_speed_mps.max(start.ds) * self.steps as f64 * p.dt_s + 1.0;
        self.fill_vcap(lane, start.s, reach, p);
        self.fill_occupancy(lane, agents, processes, forecasts, morph, reach, p);
    }

    /// Keeps only the conflict zones `zones` (centre arc lengths [enter, exit]) as places the
    /// ego may not stand in.
    pub fn keep_zones(&mut self, zones: impl Iterator<Item = [f64; 2]>) {
        self.n_zones = 0;
        for z in zones.take(MAX_CONFLICTS) {
            self.zones[self.n_zones] = z;
            self.n_zones += 1;
        }
    }

    /// True when the ego's centre at arc length `s` puts its footprint inside a conflict zone
    /// of its lane.
    pub fn in_zone(&self, s: f64) -> bool {
        self.zones[..self.n_zones]
            .iter()
            .any(|z| s > z[0] && s < z[1])
    }

    fn fill_vcap(&mut self, lane: &Lane, s0: f64, reach: f64, p: &TrajectoryParams) {
        let bin = reach / VCAP_BINS as f64;
        self.vcap_inv_bin = 1.0 / bin;
        self.kappa_max_ahead = 0.0;
        self.vcap_min = f64::INFINITY;
        self.vcap_from_s = f64::INFINITY;
        let mut seg = lane.segment_at(s0, 0);
        for b in 0..VCAP_BINS {
            let (lo, hi) = (s0 + b as f64 * bin, s0 + (b + 1) as f64 * bin);
            seg = lane.segment_at(lo, seg);
            let mut kappa = lane.curvature_at(lo, seg);
            let mut k = seg;
            while k + 1 < lane.segments() && lane.s_at_vertex(k + 1) < hi {
                k += 1;
                kappa = kappa.max(lane.curvature_at(lane.s_at_vertex(k), k));
            }
            self.kappa_max_ahead = self.kappa_max_ahead.max(kappa);
            self.vcap[b] = if kappa > p.max_curvature {
                0.0
            } else if kappa > 1e-9 {
                sqrt(p.max_lateral_accel_mps2 / kappa).min(p.max_speed_mps)
            } else {
                p.max_speed_mps
            };
            self.vcap_min = self.vcap_min.min(self.vcap[b]);
            if self.vcap[b] < p.max_speed_mps && self.vcap_from_s.is_infinite() {
                self.vcap_from_s = lo;
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn fill_occupancy(
        &mut self,
        lane: &Lane,
        agents: &[AgentState],
        processes: &[ProcessState; MAX_AGENTS],
        forecasts: &[Forecast; MAX_AGENTS],
        morph: &Morphology,
        reach: f64,
        p: &TrajectoryParams,
    ) {
        let s0 = self.start.s;
        self.occupancy.clear(self.steps);
        self.n_margins = 0;
        let half_l = 0.5 * p.vehicle_length_m;
        let half_w = 0.5 * p.vehicle_width_m;
        // Window of the ego's lane that any candidate can reach, and its bounding box.
        let first = lane.segment_at(s0 - p.vehicle_length_m, 0);
        let last = lane.segment_at(s0 + reach + p.vehicle_length_m, first) + 1;
        let inflate = lane.half_width
            + p.max_lateral_offset_m
            + p.vehicle_length_m
            + p.safety_margin_m
            + p.margin_growth_mps * self.steps as f64 * self.dt;
        let (mut min, mut max) = (
            Vec2::new(f64::INFINITY, f64::INFINITY),
            Vec2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        // Vertices of the window, plus its ends, which may be extrapolated past the lane's.
        let ends = [
            lane.pose_at(s0 - p.vehicle_length_m, first).0,
            lane.pose_at(s0 + reach + p.vehicle_length_m, first).0,
        ];
        for q in lane.points()[first..=last.min(lane.segments())]
            .iter()
            .chain(&ends)
        {
            min = Vec2::new(min.x.min(q.x), min.y.min(q.y));
            max = Vec2::new(max.x.max(q.x), max.y.max(q.y));
        }
        let (min, max) = (
            Vec2::new(min.x - inflate, min.y - inflate),
            Vec2::new(max.x + inflate, max.y + inflate),
        );
        // How far off the lane the ego's centre can be.
        let ego_reach = self.lateral_bound(p);
        self.occupancy.half = (half_l, half_w);
        self.occupancy.clearance = p.safety_margin_m;
        self.occupancy.frame.fill(
            lane,
            s0 - p.vehicle_length_m,
            s0 + reach + p.vehicle_length_m,
        );

        for (j, agent) in agents.iter().enumerate() {
            let here = lane.project_range(agent.pos, first, last);
            let heading_along = Vec2::from_angle(here.tangent).dot(agent.direction()) > 0.5;
            if here.s < s0 && fabs(here.l) < lane.half_width && heading_along {
                continue; // a follower in the ego's lane
            }
            let mut hint = processes[j]
                .lane
                .map(|l| morph.lane(l).segment_at(processes[j].s_m, 0))
                .unwrap_or(0);
            // The agent's box at every step, and for the post-encroachment margins when it is
            // in its passage of the conflict zone (before now: at its current speed).
            let f = &forecasts[j];
            // How far before now and past the horizon its passage can still set a margin
            // within the horizon (a step more: the passage is found step by step).
            let window = |secs: f64| (libm::ceil(secs / self.dt) as usize + 1).min(MAX_SWEEP_STEPS);
            let (behind, ahead) = (window(f.pet_s[0]), window(f.pet_s[1]));
            let total = behind + self.steps + ahead;
            let v = agent.speed();
            let v_top = p.max_speed_mps.max(v);
            // When it enters and leaves its passage, s from now.
            let mut passage: Option<(f64, f64)> = None;
            // Predictions move at most a few segments per step: after the first global
            // projection, search only segments near the previous foot point.
            let mut near: Option<usize> = None;
            // Its forecast at time t, s (before now: at its current speed), and the distance
            // it has covered by then, m.
            let forecast_at = |t: f64| if t > 0.0 { *f } else { Forecast::default() };
            let along = |t: f64| forecast_at(t).travel(v, t, v_top);
            for i in 0..total {
                let t = (i as f64 - behind as f64 + 1.0) * self.dt;
                // In its passage at any moment of the step; the moments it enters and leaves
                // are interpolated within the step (at the step's ends alone, the margins
                // would depend on where the steps fall, and the plan would flip between
                // cycles half a step apart).
                let (a0, a1) = (along(t - self.dt), along(t));
                if a1 >= f.pass_m[0] && a0 <= f.pass_m[1] {
                    let at = |x: f64| {
                        let u = if a1 > a0 { (x - a0) / (a1 - a0) } else { 0.0 };
                        t - self.dt + self.dt * u.clamp(0.0, 1.0)
                    };
                    let leaves = if a1 > f.pass_m[1] { at(f.pass_m[1]) } else { t };
                    passage = Some((passage.map_or(at(f.pass_m[0]), |(e, _)| e), leaves));
                }
                let step = i.wrapping_sub(behind);
                if step >= self.steps {
                    continue;
                }
                let (pos, heading) = predict(
                    agent,
                    &processes[j],
                    &forecast_at(t),
                    morph,
                    t,
                    p.max_speed_mps,
                    &mut hint,
                );
                if pos.x < min.x || pos.x > max.x || pos.y < min.y || pos.y > max.y {
                    near = None;
                    continue;
                }
                let fr = match near {
                    Some(k) => {
                        lane.project_range(pos, k.saturating_sub(4).max(first), (k + 6).min(last))
                    }
                    None => lane.project_range(pos, first, last),
                };
                near = Some(fr.segment);
                let rel = heading - fr.tangent;
                let (c, s) = (fabs(cos(rel)), fabs(sin(rel)));
                // The other's rectangle with the clearance, longer by the growth: what grows
                // uncertain with time is where it is along its path, not across it (a car
                // waiting beside a crossing lane is not in the way of its traffic later on).
                let grown = p.margin_growth_mps * t.max(0.0);
                let (other_l, other_w) = (half_l + grown, half_w);
                let margin = p.safety_margin_m;
                let ext_s = half_l + c * other_l + s * other_w + margin;
                let ext_l = half_w + s * other_l + c * other_w + margin;
                let b = [fr.s - ext_s, fr.s + ext_s, fr.l - ext_l, fr.l + ext_l];
                // The box is the exact Minkowski sum of the two rectangles where the lane is
                // straight across it and the headings are parallel or perpendicular;
                // elsewhere it is larger, and the rectangles decide.
                let bent = fabs(fr.l) + ext_l;
                let curved = [b[0], fr.s, b[1]]
                    .iter()
                    .any(|&q| lane.curvature_at(q, fr.segment) * bent > FRAME_EXACT_TOLERANCE);
                let exact = !curved && c * s <= FRAME_EXACT_TOLERANCE;
                let b = if exact {
                    b
                } else {
                    // The other's extents along and across the lane, with the clearance.
                    let (ol, ow) = (other_l + margin, other_w + margin);
                    let (tangential, radial) = (c * ol + s * ow, s * ol + c * ow);
                    // How the lane bends about the foot point: over both half lengths and 2 m
                    // more on either side.
                    let bend_m = tangential + half_l + 2.0;
                    let (kappa, side) =
                        lane.curvature_within(fr.s - bend_m, fr.s + bend_m, fr.segment);
                    let reach = curved_reach(
                        (fr.s, fr.l),
                        (half_l, half_w),
                        tangential,
                        radial,
                        kappa,
                        side,
                        ego_reach,
                    );
                    match reach {
                        Some(r) => r,
                        None => continue,
                    }
                };
                if b[2] > ego_reach || b[3] < -ego_reach {
                    continue;
                }
                let footprint = Footprint {
                    centre: pos,
                    cos: cos(heading),
                    sin: sin(heading),
                    grown,
                    exact,
                };
                self.occupancy
                    .add(step, b[0], b[1], b[2], b[3], Some(footprint));
            }
            // Margins: the PET is measured on the passages.
            if let Some((enters, leaves)) = passage.filter(|_| f.pet_s != [0.0; 2]) {
                self.margins[self.n_margins] = PassageMargin {
                    s: [s0 + f.ego_pass_m[0], s0 + f.ego_pass_m[1]],
                    t: [enters - f.pet_s[1], leaves + f.pet_s[0]],
                };
                self.n_margins += 1;
            }
        }
    }

    /// Draws `n` terminal states around `nominal` (eq. 23): T and v_T are scaled by
    /// (1 + σ·z), l_T = σ_l·z (its nominal is 0), z ~ 𝒩(0, 1) clipped to ±`sigma_clip`.
    /// Sample 0 is the nominal itself.
    ///
    /// A yielding profile stops at the yield point, and a zero v_T cannot be perturbed by
    /// scaling. Its odd samples instead reach the yield point at v_T ~ U(0, v₀) and roll on
    /// (T = 2d / (v₀ + v_T), perturbed the same way): they pass behind a crossing car without
    /// stopping, and `evaluate` keeps them only when they also clear the conflict zone within
    /// the checked horizon or can still stop before it at its end. Below `low_speed_mps`,
    /// sample 1 stops at the yield point instead (v_T = 0, T = 2d / v₀).
    pub fn sample(&mut self, nominal: &Profile, n: usize, cycle: u64, p: &TrajectoryParams) {
        let n = n.clamp(1, MAX_SAMPLES);
        let mut rng = SmallRng::seed_from_u64(p.seed ^ cycle.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let clip = p.sigma_clip;
        let z = |rng: &mut SmallRng| -> f64 {
            let v: f64 = rng.sample(StandardNormal);
            v.clamp(-clip, clip)
        };
        let v0 = self.start.ds.max(0.0);
        let v_top = p.max_speed_mps.max(v0);
        let low_speed = self.start.ds < p.low_speed_mps;
        self.yielding = nominal.yields();
        for k in 0..n {
            let (zt, zv, zl) = if k == 0 {
                (0.0, 0.0, 0.0)
            } else {
                (z(&mut rng), z(&mut rng), z(&mut rng))
            };
            // Below the low-speed threshold the nominal may be a creep towards the yield point:
            // sample 1 stops there instead (a quartic to rest from rest acceleration covers
            // v₀·T/2; perturbed only to stop sooner), for when the traffic leaves no time to
            // creep on. One is enough: near standstill such stops are all alike, and each
            // feasible one costs a whole horizon's check.
            let stops = self.yielding && low_speed && k == 1;
            let zt = if stops { -fabs(zt) } else { zt };
            let (duration, target) = if stops {
                (2.0 * nominal.stop_m / v0.max(STANDING_MPS), 0.0)
            } else if self.yielding && !low_speed && k % 2 == 1 {
                let v_end = v0 * rng.random::<f64>();
                (nominal.duration * v0 / (v0 + v_end), v_end)
            } else {
                (
                    nominal.duration,
                    nominal.target_speed * (1.0 + p.sigma_rel * zv),
                )
            };
            self.end_v[k] = target.clamp(0.0, v_top);
            // Slowing from a braking start, the quartic's speed stays between its ends only for
            // T ≤ 3 (v₀ − v_T) / |a₀|; longer ones undershoot, below zero near a stop.
            let monotone = if self.start.dds < 0.0 && self.end_v[k] < v0 {
                (3.0 * (v0 - self.end_v[k]) / -self.start.dds).max(p.min_duration_s)
            } else {
                p.max_duration_s
            };
            self.end_t[k] = (duration * (1.0 + p.sigma_rel * zt))
                .clamp(p.min_duration_s, p.max_duration_s)
                .min(monotone);
            // Below the low-speed threshold, at either end, the offset is held: a time-based
            // lateral polynomial would need unbounded path curvature near standstill.
            self.end_l[k] = if low_speed || self.end_v[k] < p.low_speed_mps {
                self.start.l
            } else {
                (p.sigma_lateral_m * zl).clamp(-p.max_lateral_offset_m, p.max_lateral_offset_m)
            };
        }
    }

    /// Evaluates the first `n` sampled candidates (Table 2) and returns the best feasible one.
    pub fn run(&self, n: usize, p: &TrajectoryParams, stats: &mut PlanStats) -> Option<Candidate> {
        let n = n.clamp(1, MAX_SAMPLES);
        *stats = PlanStats {
            best_score: f64::INFINITY,
            ..PlanStats::default()
        };
        let mut best: Option<Candidate> = None;
        for k in 0..n {
            stats.evaluated += 1;
            match self.evaluate(self.end_t[k], self.end_v[k], self.end_l[k], p) {
                Ok(c) if !c.score.is_finite() => stats.score_rejects += 1,
                Ok(c) => {
                    stats.feasible += 1;
                    if c.score < stats.best_score {
                        stats.best_score = c.score;
                        best = Some(c);
                    }
                }
                Err(Reject::Limits) => stats.limit_rejects += 1,
                Err(Reject::Collision(_) | Reject::Commits) => stats.collision_rejects += 1,
                Err(Reject::StandsInZone) => stats.zone_rejects += 1,
            }
        }
        best
    }

    /// The longitudinal quartic and lateral quintic from the start state to terminal time
    /// `t_end`, speed `v_end` and offset `l_end` (eq. 19–22; the offset is held below the
    /// low-speed threshold).
    fn polynomials(
        &self,
        t_end: f64,
        v_end: f64,
        l_end: f64,
        p: &TrajectoryParams,
    ) -> (Quartic, Quintic) {
        let st = &self.start;
        let q = Quartic::fit(st.s, st.ds, st.dds, v_end, 0.0, t_end);
        let l = if l_end == st.l && (st.ds < p.low_speed_mps || v_end < p.low_speed_mps) {
            Quintic {
                c: [st.l, 0.0, 0.0, 0.0, 0.0, 0.0],
            }
        } else {
            Quintic::fit(st.l, st.dl, st.ddl, l_end, 0.0, 0.0, t_end)
        };
        (q, l)
    }

    /// Among the first `n` sampled candidates that respect every limit, the one whose first
    /// predicted contact with a footprint is latest, with that time (s; ∞ for one without;
    /// `None` when every candidate breaks a limit). Post-encroachment margins do not count
    /// here: for when no candidate is free of contact, see [`Planner::first_contact`].
    pub fn latest_contact(&self, n: usize, p: &TrajectoryParams) -> Option<(Candidate, f64)> {
        let mut latest: Option<(Candidate, f64)> = None;
        for k in 0..n.clamp(1, MAX_SAMPLES) {
            let (t_end, v_end, l_end) = (self.end_t[k], self.end_v[k], self.end_l[k]);
            let contact = match self.evaluate_with(t_end, v_end, l_end, false, p) {
                Ok(c) => return Some((c, f64::INFINITY)),
                Err(Reject::Collision(t)) => t,
                Err(Reject::Limits | Reject::Commits | Reject::StandsInZone) => continue,
            };
            if latest.is_none_or(|(_, t)| contact > t) {
                let (s, l) = self.polynomials(t_end, v_end, l_end, p);
                let c = Candidate {
                    s,
                    l,
                    duration: t_end,
                    score: f64::INFINITY,
                };
                latest = Some((c, contact));
            }
        }
        latest
    }

    /// Time of the first predicted contact with a footprint along a rendered trajectory, s
    /// (`None`: none within the horizon).
    pub fn first_contact(&self, trajectory: &Trajectory) -> Option<f64> {
        self.first(trajectory, |step, q| {
            self.occupancy.hit(step, q.s, q.l) == Hit::Contact
        })
    }

    /// Time of the first predicted collision along a rendered trajectory, the rectangles
    /// themselves overlapping ([`Occupancy::collides`]), s (`None`: none within the horizon).
    pub fn first_collision(&self, trajectory: &Trajectory) -> Option<f64> {
        self.first(trajectory, |step, q| {
            self.occupancy.collides(step, q.s, q.l)
        })
    }

    fn first(
        &self,
        trajectory: &Trajectory,
        meets: impl Fn(usize, &TrajectoryPoint) -> bool,
    ) -> Option<f64> {
        trajectory
            .points()
            .iter()
            .skip(1)
            .take(self.steps)
            .enumerate()
            .find(|(step, q)| meets(*step, q))
            .map(|(_, q)| q.t)
    }

    /// Evaluates one candidate with terminal time `t_end`, speed `v_end` and offset `l_end`.
    pub fn evaluate(
        &self,
        t_end: f64,
        v_end: f64,
        l_end: f64,
        p: &TrajectoryParams,
    ) -> Result<Candidate, Reject> {
        self.evaluate_with(t_end, v_end, l_end, true, p)
    }

    /// [`Planner::evaluate`]; post-encroachment margins reject only when `margins`.
    fn evaluate_with(
        &self,
        t_end: f64,
        v_end: f64,
        l_end: f64,
        margins: bool,
        p: &TrajectoryParams,
    ) -> Result<Candidate, Reject> {
        let st = &self.start;
        let (q, l) = self.polynomials(t_end, v_end, l_end, p);
        let (jerk_s, jerk_l, v_peak) = self.check_limits(&q, &l, t_end, p)?;

        // Time grid: collisions, curvature speed caps (only when the candidate's peak speed
        // exceeds the lowest cap ahead), the lateral bound and the time to the goal distance.
        // A held lateral offset is evaluated only where a box could be hit.
        let check_caps = v_peak > self.vcap_min + 1e-6;
        // The lateral path must stay within the offset allowed for terminal states (or within
        // the start's offset when the ego is already further out): a quintic that starts
        // with lateral velocity can overshoot both ends, and replanning from the overshoot
        // would let the ego drift out of its lane in a turn. An ego already drifting outwards
        // at u m/s cannot stop at once: a quintic that brings u to rest over T while holding
        // its offset overshoots it by 16/81·u·T, and its initial jerk 36u/T² keeps within the
        // jerk limit J only for T ≥ 6√(u/J). The bound allows the overshoot of the quickest
        // such correction (T also at least the shortest duration) beyond the start's offset;
        // without it, near the bound, every candidate fails and the ego brakes hard where
        // nothing is in its way.
        let lateral_moves = l.c[1..].iter().any(|c| *c != 0.0);
        let l_bound = self.lateral_bound(p);
        let goal = st.s + self.goal_distance;
        let mut t_goal = f64::NAN;
        let (mut prev_t, mut prev_s) = (0.0, st.s);
        let s_end = q.pos(t_end);
        // When the candidate enters and leaves each margin's passage, s (∞: not within the
        // horizon; one already past the passage never enters it).
        let margins = if margins {
            &self.margins[..self.n_margins]
        } else {
            &[]
        };
        let mut passage = [(f64::INFINITY, f64::INFINITY); MAX_AGENTS];
        for (m, (enters, _)) in margins.iter().zip(passage.iter_mut()) {
            if st.s >= m.s[0] && st.s <= m.s[1] {
                *enters = 0.0;
            }
        }
        // Short of every passage, no margin needs a look.
        let margins_from = margins.iter().fold(f64::INFINITY, |a, m| a.min(m.s[0]));
        for step in 0..self.steps {
            let t = (step + 1) as f64 * self.dt;
            let on_poly = t <= t_end;
            let s = if on_poly {
                q.pos(t)
            } else {
                s_end + v_end * (t - t_end)
            };
            if check_caps && s >= self.vcap_from_s {
                let ds = if on_poly { q.vel(t) } else { v_end };
                let bin = ((s - st.s) * self.vcap_inv_bin) as usize;
                // A cap the ego cannot meet even braking at the limit is relaxed to that
                // braking curve, so an ego that is too fast for a curve brakes instead of
                // having no plan.
                if ds > self.vcap[bin.min(VCAP_BINS - 1)] + 1e-6
                    && ds * ds > st.ds * st.ds - 2.0 * p.max_brake_mps2 * (s - st.s) + 1e-6
                {
                    return Err(Reject::Limits);
                }
            }
            let lat = if on_poly && lateral_moves {
                let lat = l.pos(t);
                if fabs(lat) > l_bound {
                    return Err(Reject::Limits);
                }
                Some(lat)
            } else {
                None
            };
            if self.occupancy.may_hit(step, s) {
                let lat = lat.unwrap_or_else(|| if on_poly { l.pos(t) } else { l_end });
                if self.occupancy.hit(step, s, lat) == Hit::Contact {
                    return Err(Reject::Collision(t));
                }
            }
            // The moments between steps, interpolated: where the steps fall must not decide
            // whether a candidate keeps a margin (they move by half a step each 50 ms cycle).
            let at = |x: f64| prev_t + (x - prev_s) / (s - prev_s) * (t - prev_t);
            if s >= margins_from {
                for (m, (enters, leaves)) in margins.iter().zip(passage.iter_mut()) {
                    if prev_s < m.s[0] && s >= m.s[0] {
                        *enters = at(m.s[0]);
                    }
                    if prev_s < m.s[1] && s >= m.s[1] && enters.is_finite() {
                        *leaves = at(m.s[1]);
                    }
                    // In the passage at some moment of (max(enters, t₀), min(leaves, t, t₁)).
                    if *enters < m.t[1] && leaves.min(t) > m.t[0] {
                        return Err(Reject::Collision(enters.max(m.t[0])));
                    }
                }
            }
            if t_goal.is_nan() && s >= goal {
                t_goal = prev_t + (goal - prev_s) / (s - prev_s).max(1e-9) * (t - prev_t);
            }
            prev_t = t;
            prev_s = s;
        }
        let horizon = self.steps as f64 * self.dt;
        let v_last = if horizon <= t_end {
            q.vel(horizon)
        } else {
            v_end
        };
        // A yielding candidate must stop at or before the yield point, or end the horizon
        // through what it yields to, or still be able to stop before the yield point at the
        // yield check time (a quartic stop peaks at 1.5 × its mean deceleration); otherwise
        // the next car could find it inside.
        if self.yielding && prev_s < st.s + self.clear_distance {
            let t_check = p.yield_check_s.min(horizon);
            let (s_check, v_check) = if t_check <= t_end {
                (q.pos(t_check), q.vel(t_check))
            } else {
                (s_end + v_end * (t_check - t_end), v_end)
            };
            let stops_at = if v_end > 0.0 {
                s_check + v_check * v_check / (2.0 * p.max_brake_mps2 / 1.5)
            } else {
                s_end
            };
            if stops_at > st.s + self.yield_distance + 1e-6 {
                return Err(Reject::Commits);
            }
        }
        // Never plan to stand inside a conflict zone: a car waiting there blocks the crossing
        // lane (and is hit if that lane's traffic has the right of way).
        let stands_at = if v_end < STANDING_MPS {
            Some(s_end)
        } else {
            (v_last < STANDING_MPS).then_some(prev_s)
        };
        if stands_at.is_some_and(|s| self.in_zone(s)) {
            return Err(Reject::StandsInZone);
        }
        let t_n = if t_goal.is_nan() {
            (horizon + (goal - prev_s) / v_last.max(0.5)).min(10.0 * p.t_ref_s)
        } else {
            t_goal
        };
        let score = p.c_efficiency * t_n / p.t_ref_s
            + p.c_smoothness * (jerk_s + jerk_l) / p.j_max_norm
            + p.c_lateral * fabs(l_end) / p.max_lateral_offset_m;
        Ok(Candidate {
            s: q,
            l,
            duration: t_end,
            score,
        })
    }

    /// The largest offset from the lane, m, that a candidate's lateral path may reach (see
    /// `evaluate_with`).
    fn lateral_bound(&self, p: &TrajectoryParams) -> f64 {
        let st = &self.start;
        let outward = if st.l * st.dl >= 0.0 {
            fabs(st.dl)
        } else {
            0.0
        };
        let quickest = p.min_duration_s.max(6.0 * sqrt(outward / p.max_jerk_mps3));
        p.max_lateral_offset_m
            .max(fabs(st.l) + OVERSHOOT_PER_UT * outward * quickest)
            + 1e-6
    }

    /// Analytic limit checks over [0, T]; returns ∫|s⃛| dt, ∫|l⃛| dt and the peak speed.
    fn check_limits(
        &self,
        q: &Quartic,
        l: &Quintic,
        t_end: f64,
        p: &TrajectoryParams,
    ) -> Result<(f64, f64, f64), Reject> {
        let v_top = p.max_speed_mps.max(self.start.ds) + 1e-6;
        let a_top = p.max_accel_mps2.max(self.start.dds) + 1e-6;
        let b_top = p.max_brake_mps2.max(-self.start.dds) + 1e-6;
        let j_top = p.max_jerk_mps3 + 1e-6;
        // Longitudinal jerk is linear: extremes at the ends.
        if fabs(q.jerk(0.0)).max(fabs(q.jerk(t_end))) > j_top {
            return Err(Reject::Limits);
        }
        // Acceleration is quadratic: ends and vertex (where the jerk vanishes).
        let (a0, a_t) = (q.acc(0.0), q.acc(t_end));
        let (mut a_min, mut a_max) = (a0.min(a_t), a0.max(a_t));
        let mut jerk_s = fabs(a_t - a0);
        let (jr, jn) = roots_in(0.0, 24.0 * q.c[4], 6.0 * q.c[3], t_end);
        if jn == 1 {
            let a_v = q.acc(jr[0]);
            a_min = a_min.min(a_v);
            a_max = a_max.max(a_v);
            jerk_s = fabs(a_v - a0) + fabs(a_t - a_v);
        }
        if a_max > a_top || -a_min > b_top {
            return Err(Reject::Limits);
        }
        // Speed is cubic: ends and the roots of the acceleration.
        let (mut v_min, mut v_max) = (q.vel(0.0).min(q.vel(t_end)), q.vel(0.0).max(q.vel(t_end)));
        let (vr, vn) = roots_in(12.0 * q.c[4], 6.0 * q.c[3], 2.0 * q.c[2], t_end);
        for &r in &vr[..vn] {
            let v = q.vel(r);
            v_min = v_min.min(v);
            v_max = v_max.max(v);
        }
        // Planned speeds never go negative (a stop that undershoots would plan reversing).
        if v_max > v_top || v_min < -1e-6 {
            return Err(Reject::Limits);
        }
        // Lateral jerk is quadratic: ends and vertex; lateral acceleration is cubic: ends and
        // the roots of the jerk. ∫|l⃛| is the total variation of l̈ between those roots.
        let (c3, c4, c5) = (l.c[3], l.c[4], l.c[5]);
        let mut lj_max = fabs(l.jerk(0.0)).max(fabs(l.jerk(t_end)));
        if fabs(c5) > 1e-12 {
            let tv = -24.0 * c4 / (120.0 * c5);
            if tv > 0.0 && tv < t_end {
                lj_max = lj_max.max(fabs(l.jerk(tv)));
            }
        }
        if lj_max > j_top {
            return Err(Reject::Limits);
        }
        let (lr, ln) = roots_in(60.0 * c5, 24.0 * c4, 6.0 * c3, t_end);
        let mut prev = l.acc(0.0);
        let mut la_max = fabs(prev);
        let mut jerk_l = 0.0;
        for &r in lr[..ln].iter().chain(core::iter::once(&t_end)) {
            let a = l.acc(r);
            la_max = la_max.max(fabs(a));
            jerk_l += fabs(a - prev);
            prev = a;
        }
        if la_max > p.max_lateral_accel_mps2 + 1e-6 {
            return Err(Reject::Limits);
        }
        // Curvature bound: reference curvature plus the curvature of the lateral motion,
        // |l̈| / ṡ², with ṡ floored at 1 m/s.
        if la_max > 1e-3
            && self.kappa_max_ahead + la_max / (v_min.max(1.0) * v_min.max(1.0)) > p.max_curvature
        {
            return Err(Reject::Limits);
        }
        Ok((jerk_s, jerk_l, v_max))
    }

    /// Samples the chosen candidate into Cartesian points on `lane`.
    pub fn render(&self, c: &Candidate, lane: &Lane, out: &mut Trajectory) {
        let mut hint = lane.segment_at(self.start.s, 0);
        out.n = self.steps + 1;
        let (s_end, l_end) = (c.s.pos(c.duration), c.l.pos(c.duration));
        let v_end = c.s.vel(c.duration);
        for i in 0..out.n {
            let t = i as f64 * self.dt;
            let (s, ds, dds, lat, dl) = if t <= c.duration {
                (c.s.pos(t), c.s.vel(t), c.s.acc(t), c.l.pos(t), c.l.vel(t))
            } else {
                (s_end + v_end * (t - c.duration), v_end, 0.0, l_end, 0.0)
            };
            let (pos, tangent, seg) = lane.to_cartesian(s, lat, hint);
            hint = seg;
            out.points[i] = TrajectoryPoint {
                t,
                s,
                l: lat,
                x: pos.x,
                y: pos.y,
                heading: tangent + libm::atan2(dl, ds.max(0.1)),
                // The limit check refuses any candidate below −1e-6 m/s; this drops the
                // rounding left where a stop polynomial reaches zero.
                speed: ds.max(0.0),
                accel: dds,
            };
        }
    }

    /// The minimum-risk fallback into `out`: brake ([`Planner::minimum_risk`]), enough to stop
    /// before the yield point `stop_distance` m ahead if possible. Braking where the ego
    /// stands can be the worst choice inside a junction, in the path of crossing traffic: when
    /// braking is predicted to be hit (the footprints themselves overlapping, not just the
    /// clearance around them: a car waiting beside a crossing lane is not in its traffic's
    /// way, and driving on from there would squeeze in behind a passing car), the
    /// dynamically feasible candidate around one of
    /// `drive_on` (profiles that hold or gain speed) that postpones the first predicted
    /// contact longest is taken instead, if it does (it leaves the others the most time to
    /// react); when braking would end standing inside a conflict zone, one free of predicted
    /// contact is taken: the ego clears the zone. Past its stop line and before the end of the
    /// last conflict zone, inside the junction, a braking that is predicted to be hit leaves
    /// the ego standing in the other's path: a feasible drive-on candidate is taken instead,
    /// the one with the latest contact, unless that candidate's own footprint is predicted to
    /// collide more than [`DRIVE_ON_STEPS`] steps before the braking's (it would run into a
    /// car ahead, a leader standing in the exit, say, which braking avoids). Drive-on
    /// candidates are searched with `fallback_samples`. Returns the index of the profile
    /// taken (`None`: braking).
    pub fn fallback(
        &mut self,
        stop_distance: f64,
        lane: &Lane,
        drive_on: &[Profile],
        cycle: u64,
        p: &TrajectoryParams,
        out: &mut Trajectory,
    ) -> Option<usize> {
        self.minimum_risk(stop_distance, lane, p, out);
        let contact = self.first_collision(out);
        let stands_in_zone = out.points().last().is_some_and(|q| self.in_zone(q.s));
        if contact.is_none() && !stands_in_zone {
            return None;
        }
        let in_junction = self.start.s > lane.stop_s
            && self.zones[..self.n_zones]
                .iter()
                .any(|z| self.start.s < z[1]);
        let clear_out = contact.is_some() && in_junction;
        let braking_hit = contact.unwrap_or(f64::INFINITY);
        let mut latest = braking_hit;
        let mut taken = None;
        let mut candidate = Trajectory::default();
        for (k, profile) in drive_on.iter().enumerate() {
            self.sample(profile, p.later_samples(), cycle, p);
            if let Some((c, t)) = self.latest_contact(p.later_samples(), p) {
                // Inside the junction the candidate is rendered to check its own collision.
                let clears = if clear_out {
                    self.render(&c, lane, &mut candidate);
                    self.first_collision(&candidate)
                        .is_none_or(|hit| hit + DRIVE_ON_STEPS * self.dt >= braking_hit)
                } else {
                    stands_in_zone && t.is_infinite()
                };
                if t > latest || (clears && taken.is_none()) {
                    latest = t;
                    taken = Some(k);
                    if clear_out {
                        *out = candidate;
                    } else {
                        self.render(&c, lane, out);
                    }
                }
            }
        }
        taken
    }

    /// Minimum-risk fallback: brake along the lane at constant deceleration, enough to stop
    /// `stop_distance` m ahead (before the conflict zone, behind the leader) but at least
    /// `max_brake` and at most `emergency_brake`; with nothing to stop for (∞), or already
    /// past it, brake at `emergency_brake`.
    pub fn minimum_risk(
        &self,
        stop_distance: f64,
        lane: &Lane,
        p: &TrajectoryParams,
        out: &mut Trajectory,
    ) {
        let v0 = self.start.ds.max(0.0);
        let need = if stop_distance.is_finite() && stop_distance > 0.0 {
            v0 * v0 / (2.0 * stop_distance)
        } else {
            f64::INFINITY
        };
        let decel = need.clamp(p.max_brake_mps2, p.emergency_brake_mps2);
        let t_stop = v0 / decel;
        let mut hint = lane.segment_at(self.start.s, 0);
        out.n = self.steps + 1;
        for i in 0..out.n {
            let t = i as f64 * self.dt;
            let tt = t.min(t_stop);
            let s = self.start.s + v0 * tt - 0.5 * decel * tt * tt;
            let (pos, tangent, seg) = lane.to_cartesian(s, self.start.l, hint);
            hint = seg;
            out.points[i] = TrajectoryPoint {
                t,
                s,
                l: self.start.l,
                x: pos.x,
                y: pos.y,
                heading: tangent,
                speed: (v0 - decel * tt).max(0.0),
                accel: if t < t_stop { -decel } else { 0.0 },
            };
        }
    }
}

/// Why a candidate failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reject {
    /// Speed, acceleration, jerk, curvature or lateral limits.
    Limits,
    /// A predicted contact this many seconds ahead.
    Collision(f64),
    /// A yielding candidate that neither clears the conflict zone within the horizon nor can
    /// still stop before it (counted with collisions).
    Commits,
    /// Ends the horizon standing inside a conflict zone.
    StandsInZone,
}

#[cfg(test)]
mod tests;
