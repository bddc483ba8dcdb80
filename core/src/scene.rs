//! Scene: agent states 𝓕ᵢ (eq. 1), explicit intents (eq. 8), the intersection morphology
//! 𝓘 = {P_stop, R_lane, L_ref} (eq. 2), Frenet projection onto lane reference lines, process
//! states P_ti (eq. 3) and fixed-length history rings H.
//!
//! Units: metres, seconds, radians; headings are counter-clockwise from the +x axis.

use libm::{atan2, cos, hypot, sin, sqrt};

/// Most agents one scene carries (besides the ego).
pub const MAX_AGENTS: usize = 32;
/// Most lane reference lines in one morphology: the 12 movements of a four-way junction
/// with one lane per approach, and room for more.
pub const MAX_LANES: usize = 16;
/// Most vertices of one lane reference polyline.
pub const MAX_LANE_POINTS: usize = 64;
/// Most lane-pair conflict points in one morphology (a four-way junction's 12 movements have
/// about 30).
pub const MAX_CONFLICTS: usize = 64;
/// A lane's reference line extends this far back along its first segment for lane matching,
/// m: queued traffic behind the start of a map's approach still belongs to it.
pub const LANE_EXTENSION_M: f64 = 50.0;
/// Extra lateral distance, m, at which lane matching counts a lane whose turn contradicts the
/// agent's turn signal: where lanes overlap the signal decides, where they are apart the
/// position does.
pub const SIGNAL_MISMATCH_M: f64 = 1.0;
/// A lane whose first vertex lies within this distance of another's reference line starts
/// on it, m.
pub const BRANCH_TOLERANCE_M: f64 = 0.5;
/// A lane that starts on another heads along it when its first segment is within this angle
/// of the other's tangent there, rad (30°).
pub const BRANCH_HEADING_RAD: f64 = core::f64::consts::FRAC_PI_6;
/// Most junctions one route passes ([`Route`]).
pub const MAX_ROUTE_LEGS: usize = 4;
/// Samples kept per agent history ring: 2 s at 10 Hz.
pub const HISTORY_LEN: usize = 20;
/// Spacing of history samples, s (10 Hz).
pub const HISTORY_PERIOD_S: f64 = 0.1;

/// A planar vector, m or m/s or m/s².
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec2 {
    pub x: f64,
    pub y: f64,
}

impl Vec2 {
    pub const ZERO: Vec2 = Vec2 { x: 0.0, y: 0.0 };
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }
    pub fn plus(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
    pub fn minus(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
    pub fn scale(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
    pub fn dot(self, o: Vec2) -> f64 {
        self.x * o.x + self.y * o.y
    }
    pub fn cross(self, o: Vec2) -> f64 {
        self.x * o.y - self.y * o.x
    }
    pub fn norm(self) -> f64 {
        hypot(self.x, self.y)
    }
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
    /// Unit vector at `angle` rad.
    pub fn from_angle(angle: f64) -> Vec2 {
        Vec2::new(cos(angle), sin(angle))
    }
}

coded_enum! {
/// Kind of road user.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AgentKind {
    #[default]
    Car = 0,
    Truck = 1,
    Bus = 2,
    Motorcycle = 3,
    Bicycle = 4,
    Pedestrian = 5,
    Unknown = 6,
}
}

coded_enum! {
/// Turn-signal state, one of the explicit cues of §4.1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TurnSignal {
    #[default]
    Off = 0,
    Left = 1,
    Right = 2,
    Hazard = 3,
}
}

coded_enum! {
/// Driving style I_style (eq. 8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    Aggressive = 0,
    Balanced = 1,
    Conservative = 2,
}
}

coded_enum! {
/// Current action I_action (eq. 8) as announced or parsed from language.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IntentAction {
    /// "Go ahead", "after you".
    Yield = 0,
    /// "I'm going first".
    Proceed = 1,
    Accelerate = 2,
    Decelerate = 3,
    TurnLeft = 4,
    TurnRight = 5,
    Stop = 6,
}
}

coded_enum! {
/// Task I_task (eq. 8); it sets priority.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Task {
    Commute = 0,
    Emergency = 1,
    Official = 2,
    Leisure = 3,
}
}

/// One intent dimension with the confidence of its parse, in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rated<T> {
    pub value: T,
    pub confidence: f64,
}

/// Explicit intent [I_style, I_action, I_task] (eq. 8). `None` means unknown.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExplicitIntent {
    pub style: Option<Rated<Style>>,
    pub action: Option<Rated<IntentAction>>,
    pub task: Option<Rated<Task>>,
}

impl ExplicitIntent {
    /// No intent known.
    pub const UNKNOWN: ExplicitIntent = ExplicitIntent {
        style: None,
        action: None,
        task: None,
    };

    /// Every confidence finite and in [0, 1]: the rule for intents from scene frames and from
    /// the sidecar's parses alike.
    pub fn check(&self) -> Result<(), SceneErrorKind> {
        for c in self.confidences().into_iter().flatten() {
            if !c.is_finite() {
                return Err(SceneErrorKind::NotFinite);
            }
            if !(0.0..=1.0).contains(&c) {
                return Err(SceneErrorKind::OutOfRange);
            }
        }
        Ok(())
    }

    /// The style, if its confidence reaches `threshold` (weak intents are ignored, §4.3).
    pub fn strong_style(&self, threshold: f64) -> Option<Style> {
        strong(self.style, threshold)
    }
    /// The action, if its confidence reaches `threshold`.
    pub fn strong_action(&self, threshold: f64) -> Option<IntentAction> {
        strong(self.action, threshold)
    }
    /// The task, if its confidence reaches `threshold`.
    pub fn strong_task(&self, threshold: f64) -> Option<Task> {
        strong(self.task, threshold)
    }
    /// True when any dimension is strong.
    pub fn any_strong(&self, threshold: f64) -> bool {
        self.strong_style(threshold).is_some()
            || self.strong_action(threshold).is_some()
            || self.strong_task(threshold).is_some()
    }
    /// Each dimension from whichever of `self` and `other` is the more confident parse.
    pub fn merged_with(&self, other: &ExplicitIntent) -> ExplicitIntent {
        fn pick<T: Copy>(a: Option<Rated<T>>, b: Option<Rated<T>>) -> Option<Rated<T>> {
            match (a, b) {
                (Some(x), Some(y)) if y.confidence > x.confidence => Some(y),
                (None, y) => y,
                (x, _) => x,
            }
        }
        ExplicitIntent {
            style: pick(self.style, other.style),
            action: pick(self.action, other.action),
            task: pick(self.task, other.task),
        }
    }
    fn confidences(&self) -> [Option<f64>; 3] {
        [
            self.style.map(|r| r.confidence),
            self.action.map(|r| r.confidence),
            self.task.map(|r| r.confidence),
        ]
    }
}

fn strong<T: Copy>(r: Option<Rated<T>>, threshold: f64) -> Option<T> {
    r.filter(|r| r.confidence >= threshold).map(|r| r.value)
}

/// Agent state 𝓕ᵢ = [x, y, vˣ, vʸ, aˣ, aʸ, φ] (eq. 1) with identity and explicit cues.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AgentState {
    /// Track id, stable across frames.
    pub id: u32,
    pub kind: AgentKind,
    /// Position, m.
    pub pos: Vec2,
    /// Velocity, m/s.
    pub vel: Vec2,
    /// Acceleration, m/s².
    pub acc: Vec2,
    /// Heading φ, rad.
    pub heading: f64,
    pub turn_signal: TurnSignal,
    /// Explicit intent parsed from this road user's language or signals (eq. 8).
    pub intent: ExplicitIntent,
}

impl AgentState {
    /// A car at `pos` moving at `speed` m/s along `heading` rad, unaccelerated, with no intent.
    pub fn moving(id: u32, pos: Vec2, heading: f64, speed: f64) -> Self {
        AgentState {
            id,
            pos,
            vel: Vec2::from_angle(heading).scale(speed),
            heading,
            ..AgentState::default()
        }
    }

    /// Speed |v|, m/s.
    pub fn speed(&self) -> f64 {
        self.vel.norm()
    }
    /// Acceleration along the velocity (or heading when stopped), m/s².
    pub fn longitudinal_accel(&self) -> f64 {
        let dir = self.direction();
        self.acc.dot(dir)
    }
    /// Unit direction of travel: the velocity's, or the heading's when nearly stopped.
    pub fn direction(&self) -> Vec2 {
        let v = self.speed();
        if v > 0.1 {
            self.vel.scale(1.0 / v)
        } else {
            Vec2::from_angle(self.heading)
        }
    }
}

/// One perception frame: the ego and up to [`MAX_AGENTS`] other road users.
#[derive(Clone, Copy, Debug)]
pub struct Scene {
    /// Frame timestamp, s (the caller's monotonic clock).
    pub time_s: f64,
    /// Ego state; its `intent` is the passenger's explicit intent I_explicitEgo.
    pub ego: AgentState,
    /// Index of the ego's route lane in the morphology; the lane's turn is the navigation
    /// instruction.
    pub ego_lane: u8,
    pub agents: [AgentState; MAX_AGENTS],
    /// Valid entries at the front of `agents`.
    pub n_agents: usize,
}

impl Scene {
    /// A scene with the ego only.
    pub fn new(time_s: f64, ego: AgentState, ego_lane: u8) -> Self {
        Scene {
            time_s,
            ego,
            ego_lane,
            agents: [AgentState::default(); MAX_AGENTS],
            n_agents: 0,
        }
    }
    /// Adds an agent; returns false when the scene is full.
    pub fn push(&mut self, agent: AgentState) -> bool {
        if self.n_agents >= MAX_AGENTS {
            return false;
        }
        self.agents[self.n_agents] = agent;
        self.n_agents += 1;
        true
    }
    /// The valid agents.
    pub fn agents(&self) -> &[AgentState] {
        &self.agents[..self.n_agents.min(MAX_AGENTS)]
    }
}

/// Which field of a scene failed validation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneField {
    Time,
    AgentCount,
    EgoLane,
    Position,
    Velocity,
    Acceleration,
    Heading,
    IntentConfidence,
}

/// Why a scene was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneErrorKind {
    /// NaN or ±∞.
    NotFinite,
    /// Finite but outside the plausible range set in `Params::limits`.
    OutOfRange,
}

/// A rejected scene: which agent (`None` = ego or frame), which field, why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneError {
    pub agent: Option<u8>,
    pub field: SceneField,
    pub kind: SceneErrorKind,
}

/// Plausibility bounds for scene validation.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputLimits {
    /// Largest |timestamp| accepted, s.
    pub max_abs_time_s: f64,
    /// Largest |x|, |y| accepted, m.
    pub max_abs_position_m: f64,
    /// Largest speed accepted, m/s.
    pub max_speed_mps: f64,
    /// Largest |acceleration| accepted, m/s².
    pub max_accel_mps2: f64,
}

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            max_abs_time_s: 1e12,
            max_abs_position_m: 10_000.0,
            max_speed_mps: 70.0,
            max_accel_mps2: 30.0,
        }
    }
}

impl Scene {
    /// Checks every number of the frame: finite and within `limits`. Never panics.
    pub fn validate(&self, limits: &InputLimits, n_lanes: usize) -> Result<(), SceneError> {
        let err = |agent, field, kind| Err(SceneError { agent, field, kind });
        if !self.time_s.is_finite() {
            return err(None, SceneField::Time, SceneErrorKind::NotFinite);
        }
        if self.time_s.abs() > limits.max_abs_time_s {
            return err(None, SceneField::Time, SceneErrorKind::OutOfRange);
        }
        if self.n_agents > MAX_AGENTS {
            return err(None, SceneField::AgentCount, SceneErrorKind::OutOfRange);
        }
        if self.ego_lane as usize >= n_lanes {
            return err(None, SceneField::EgoLane, SceneErrorKind::OutOfRange);
        }
        check_agent(&self.ego, limits).map_err(|(field, kind)| SceneError {
            agent: None,
            field,
            kind,
        })?;
        for (i, a) in self.agents().iter().enumerate() {
            check_agent(a, limits).map_err(|(field, kind)| SceneError {
                agent: Some(i as u8),
                field,
                kind,
            })?;
        }
        Ok(())
    }
}

fn check_agent(a: &AgentState, lim: &InputLimits) -> Result<(), (SceneField, SceneErrorKind)> {
    use SceneErrorKind::*;
    let check = |v: Vec2, max: f64, field| {
        if !v.is_finite() {
            Err((field, NotFinite))
        } else if v.x.abs() > max || v.y.abs() > max {
            Err((field, OutOfRange))
        } else {
            Ok(())
        }
    };
    check(a.pos, lim.max_abs_position_m, SceneField::Position)?;
    check(a.vel, lim.max_speed_mps, SceneField::Velocity)?;
    check(a.acc, lim.max_accel_mps2, SceneField::Acceleration)?;
    if !a.heading.is_finite() {
        return Err((SceneField::Heading, NotFinite));
    }
    if a.heading.abs() > 100.0 {
        return Err((SceneField::Heading, OutOfRange));
    }
    a.intent
        .check()
        .map_err(|kind| (SceneField::IntentConfidence, kind))
}

coded_enum! {
/// Turn a lane makes through the junction; for the ego's route lane it is the navigation
/// instruction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Turn {
    #[default]
    Straight = 0,
    Left = 1,
    Right = 2,
}
}

/// A point of a lane reference line in Frenet coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frenet {
    /// Arc length along the reference line, m.
    pub s: f64,
    /// Signed lateral offset, m, positive to the left.
    pub l: f64,
    /// Tangent angle of the reference line at `s`, rad.
    pub tangent: f64,
    /// Segment index, a hint for the next lookup.
    pub segment: usize,
}

/// One lane: its centre reference line L_ref, boundary half-width R_lane and stop line P_stop
/// (eq. 2).
#[derive(Clone, Copy, Debug)]
pub struct Lane {
    points: [Vec2; MAX_LANE_POINTS],
    /// Cumulative arc length at each vertex, m.
    cum_s: [f64; MAX_LANE_POINTS],
    /// Unsigned curvature at each vertex, 1/m (Menger curvature of neighbours).
    kappa: [f64; MAX_LANE_POINTS],
    /// Tangent angle at each vertex, rad: the direction from the previous to the next vertex.
    /// Tangents and normals are interpolated between vertices, so the Frenet frame turns
    /// smoothly instead of jumping at every vertex of the polyline.
    vertex_tangent: [f64; MAX_LANE_POINTS],
    /// Turn of the tangent over each segment, rad, wrapped to (−π, π].
    segment_turn: [f64; MAX_LANE_POINTS],
    n: usize,
    /// Half the lane width, m.
    pub half_width: f64,
    /// Arc length of the stop line P_stop, m.
    pub stop_s: f64,
    /// Turn through the junction.
    pub turn: Turn,
    /// Right-of-way level at the junction: where two lanes cross or merge, the higher level
    /// goes first (equal levels: [`JunctionRule`]).
    pub priority: u8,
}

/// Why a lane or morphology could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeometryError {
    TooFewPoints,
    TooManyPoints,
    TooManyLanes,
    /// More lane pairs cross or merge than [`MAX_CONFLICTS`].
    TooManyConflicts,
    NotFinite,
    DuplicatePoint,
}

impl Lane {
    /// Builds a lane from its reference polyline. Points must be distinct and finite.
    pub fn new(
        points: &[Vec2],
        half_width: f64,
        stop_s: f64,
        turn: Turn,
    ) -> Result<Self, GeometryError> {
        if points.len() < 2 {
            return Err(GeometryError::TooFewPoints);
        }
        if points.len() > MAX_LANE_POINTS {
            return Err(GeometryError::TooManyPoints);
        }
        if points.iter().any(|p| !p.is_finite()) || !half_width.is_finite() || !stop_s.is_finite() {
            return Err(GeometryError::NotFinite);
        }
        let mut lane = Lane {
            points: [Vec2::ZERO; MAX_LANE_POINTS],
            cum_s: [0.0; MAX_LANE_POINTS],
            kappa: [0.0; MAX_LANE_POINTS],
            vertex_tangent: [0.0; MAX_LANE_POINTS],
            segment_turn: [0.0; MAX_LANE_POINTS],
            n: points.len(),
            half_width,
            stop_s,
            turn,
            priority: 0,
        };
        lane.points[..points.len()].copy_from_slice(points);
        for i in 1..points.len() {
            let d = points[i].minus(points[i - 1]).norm();
            if d < 1e-6 {
                return Err(GeometryError::DuplicatePoint);
            }
            lane.cum_s[i] = lane.cum_s[i - 1] + d;
        }
        let last = points.len() - 1;
        for i in 0..=last {
            let d = points[(i + 1).min(last)].minus(points[i.saturating_sub(1)]);
            lane.vertex_tangent[i] = atan2(d.y, d.x);
        }
        for i in 0..last {
            lane.segment_turn[i] = libm::remainder(
                lane.vertex_tangent[i + 1] - lane.vertex_tangent[i],
                core::f64::consts::TAU,
            );
        }
        for i in 1..points.len() - 1 {
            let (a, b, c) = (points[i - 1], points[i], points[i + 1]);
            let area2 = b.minus(a).cross(c.minus(a)).abs();
            let denom = b.minus(a).norm() * c.minus(b).norm() * c.minus(a).norm();
            lane.kappa[i] = 2.0 * area2 / denom;
        }
        Ok(lane)
    }

    /// The lane with right-of-way level `level`.
    pub fn with_priority(mut self, level: u8) -> Self {
        self.priority = level;
        self
    }

    /// Builder for polylines made of straight runs and circular arcs.
    pub fn builder(start: Vec2) -> LaneBuilder {
        LaneBuilder::new(start)
    }

    /// Vertices of the reference line.
    pub fn points(&self) -> &[Vec2] {
        &self.points[..self.n]
    }
    /// Total length, m.
    pub fn length(&self) -> f64 {
        self.cum_s[self.n - 1]
    }
    /// Number of segments.
    pub fn segments(&self) -> usize {
        self.n - 1
    }
    /// Arc length at vertex `i`, m.
    pub fn s_at_vertex(&self, i: usize) -> f64 {
        self.cum_s[i]
    }

    /// Segment holding arc length `s`, searched from `hint` (amortised O(1) for monotone `s`).
    pub fn segment_at(&self, s: f64, hint: usize) -> usize {
        let mut i = hint.min(self.n - 2);
        while i + 1 < self.n - 1 && s > self.cum_s[i + 1] {
            i += 1;
        }
        while i > 0 && s < self.cum_s[i] {
            i -= 1;
        }
        i
    }

    /// Cartesian point and tangent angle at arc length `s` (linear extrapolation past the ends).
    pub fn pose_at(&self, s: f64, hint: usize) -> (Vec2, f64, usize) {
        let i = self.segment_at(s, hint);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let len = self.cum_s[i + 1] - self.cum_s[i];
        let u = (s - self.cum_s[i]) / len;
        (a.plus(b.minus(a).scale(u)), self.tangent_in(i, u), i)
    }

    /// Tangent angle at fraction `u` of segment `i`, interpolated between its vertices.
    fn tangent_in(&self, i: usize, u: f64) -> f64 {
        self.vertex_tangent[i] + self.segment_turn[i] * u.clamp(0.0, 1.0)
    }

    /// Cartesian point at Frenet (s, l).
    pub fn to_cartesian(&self, s: f64, l: f64, hint: usize) -> (Vec2, f64, usize) {
        let (p, tangent, i) = self.pose_at(s, hint);
        let normal = Vec2::new(-sin(tangent), cos(tangent));
        (p.plus(normal.scale(l)), tangent, i)
    }

    /// Reference curvature at arc length `s`, 1/m (largest of the segment's two vertices).
    pub fn curvature_at(&self, s: f64, hint: usize) -> f64 {
        let i = self.segment_at(s, hint);
        self.kappa[i].max(self.kappa[i + 1])
    }

    /// Largest reference curvature over arc lengths [`s_lo`, `s_hi`], 1/m, searched from the
    /// segment `hint`, and the side its centre is on: +1 left (l > 0), −1 right, 0 when the
    /// lane bends both ways there.
    pub fn curvature_within(&self, s_lo: f64, s_hi: f64, hint: usize) -> (f64, f64) {
        let first = self.segment_at(s_lo, hint);
        let last = self.segment_at(s_hi, first);
        let (mut kappa, mut left, mut right) = (0.0f64, false, false);
        for i in first..=last {
            kappa = kappa.max(self.kappa[i].max(self.kappa[i + 1]));
            left |= self.segment_turn[i] > 1e-9;
            right |= self.segment_turn[i] < -1e-9;
        }
        let side = match (left, right) {
            (true, false) => 1.0,
            (false, true) => -1.0,
            _ => 0.0,
        };
        (kappa, side)
    }

    /// Projects `p` onto segments `first..last` (exclusive) of the reference line.
    pub fn project_range(&self, p: Vec2, first: usize, last: usize) -> Frenet {
        let last = last.min(self.n - 1).max(first + 1);
        let mut best = Frenet {
            s: 0.0,
            l: f64::INFINITY,
            tangent: 0.0,
            segment: first,
        };
        let mut best_d2 = f64::INFINITY;
        for i in first..last {
            let (a, b) = (self.points[i], self.points[i + 1]);
            let d = b.minus(a);
            let len = self.cum_s[i + 1] - self.cum_s[i];
            let rel = p.minus(a);
            let mut u = rel.dot(d) / (len * len);
            // Extrapolate beyond the first and last vertex so that s stays meaningful there.
            if i > 0 {
                u = u.max(0.0);
            }
            if i + 2 < self.n {
                u = u.min(1.0);
            }
            let foot = a.plus(d.scale(u));
            let off = p.minus(foot);
            let d2 = off.dot(off);
            if d2 < best_d2 {
                best_d2 = d2;
                let side = d.cross(rel);
                best = Frenet {
                    s: self.cum_s[i] + u * len,
                    l: sqrt(d2).copysign(side),
                    tangent: self.tangent_in(i, u),
                    segment: i,
                };
            }
        }
        best
    }

    /// Projects `p` onto the whole reference line.
    pub fn project(&self, p: Vec2) -> Frenet {
        self.project_range(p, 0, self.n - 1)
    }
}

/// Builds a lane reference polyline from straight runs and circular arcs.
#[derive(Clone, Copy, Debug)]
pub struct LaneBuilder {
    points: [Vec2; MAX_LANE_POINTS],
    n: usize,
    overflow: bool,
}

impl LaneBuilder {
    fn new(start: Vec2) -> Self {
        let mut points = [Vec2::ZERO; MAX_LANE_POINTS];
        points[0] = start;
        LaneBuilder {
            points,
            n: 1,
            overflow: false,
        }
    }
    fn push(mut self, p: Vec2) -> Self {
        if self.n < MAX_LANE_POINTS {
            self.points[self.n] = p;
            self.n += 1;
        } else {
            self.overflow = true;
        }
        self
    }
    /// Straight run to `p`.
    pub fn line_to(self, p: Vec2) -> Self {
        self.push(p)
    }
    /// Circular arc about `centre` from the current point through `sweep` rad
    /// (positive = counter-clockwise), sampled at most `step` m apart.
    pub fn arc(mut self, centre: Vec2, sweep: f64, step: f64) -> Self {
        let start = self.points[self.n - 1];
        let r = start.minus(centre).norm();
        let a0 = atan2(start.y - centre.y, start.x - centre.x);
        let k = libm::ceil((r * sweep.abs()) / step).max(1.0) as usize;
        for j in 1..=k {
            let a = a0 + sweep * j as f64 / k as f64;
            self = self.push(centre.plus(Vec2::from_angle(a).scale(r)));
        }
        self
    }
    /// Vertices so far.
    pub fn points(&self) -> &[Vec2] {
        &self.points[..self.n]
    }
    /// True when more than [`MAX_LANE_POINTS`] vertices were added (the rest were dropped).
    pub fn overflowed(&self) -> bool {
        self.overflow
    }
    /// Finishes the lane.
    pub fn build(self, half_width: f64, stop_s: f64, turn: Turn) -> Result<Lane, GeometryError> {
        if self.overflow {
            return Err(GeometryError::TooManyPoints);
        }
        Lane::new(&self.points[..self.n], half_width, stop_s, turn)
    }
}

coded_enum! {
/// How two lanes meet at a conflict point.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ConflictKind {
    /// The lanes cross: each is in the other's path only around the point.
    #[default]
    Crossing = 0,
    /// The lanes join and go on as one: past the point the two cars follow each other.
    Merging = 1,
}
}

coded_enum! {
/// Which lane of a conflict point has the right of way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RightOfWay {
    /// Neither: equal priority, first come first served.
    #[default]
    Neither = 0,
    A = 1,
    B = 2,
}
}

coded_enum! {
/// How a junction resolves two lanes of equal priority level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JunctionRule {
    /// Levels alone decide; at equal levels neither lane has the right of way.
    #[default]
    Levels = 0,
    /// At equal levels the lane coming from the right goes first (in the counter-clockwise
    /// frame: x east, y north; a mirrored frame such as highway-env's would swap the sides).
    RightBeforeLeft = 1,
}
}

/// Footprint, length × width in m, for which [`Morphology::new`] derives conflict zones; the
/// core refits them to its own (`Morphology::fit_footprint`).
pub const DEFAULT_FOOTPRINT_M: [f64; 2] = [4.8, 2.0];
/// Step of the scan for a conflict zone's ends, m (the ends are then bisected to ~1 mm).
const ZONE_STEP_M: f64 = 1.0;
/// How far from the conflict point the scan for a zone's ends looks, m.
const ZONE_SCAN_M: f64 = 40.0;
/// Lanes whose centre lines are still within each other's band this far past their first
/// contact merge, m.
const MERGE_CHECK_M: f64 = 20.0;

/// Where two lane reference lines cross or merge, with the stretch of each lane where a
/// vehicle is in the other's path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ConflictPoint {
    pub lane_a: u8,
    pub lane_b: u8,
    /// Arc length of the point on lane a, m.
    pub s_a: f64,
    /// Arc length of the point on lane b, m.
    pub s_b: f64,
    pub pos: Vec2,
    pub kind: ConflictKind,
    /// Conflict zone on lane a: the centre arc lengths [enter, exit] between which a footprint
    /// centred on lane a overlaps lane b's band (its centre line ± half-width), m. At a merge,
    /// exit is one footprint length past the point, where the car is wholly on the joint lane.
    pub zone_a: [f64; 2],
    /// The same on lane b against lane a's band, m.
    pub zone_b: [f64; 2],
    /// Passage on lane a, centre arc lengths [enter, exit], m: the stretch whose occupancy
    /// times give the post-encroachment time. At a crossing it is the zone; at a merge the
    /// footprint passing the point, where the two cars' order is settled.
    pub pass_a: [f64; 2],
    /// The same on lane b, m.
    pub pass_b: [f64; 2],
    pub right_of_way: RightOfWay,
}

impl ConflictPoint {
    /// The point seen from `lane`: lane a is `lane` (a and b swapped when needed).
    pub fn seen_from(&self, lane: u8) -> ConflictPoint {
        if self.lane_a == lane {
            return *self;
        }
        ConflictPoint {
            lane_a: self.lane_b,
            lane_b: self.lane_a,
            s_a: self.s_b,
            s_b: self.s_a,
            pos: self.pos,
            kind: self.kind,
            zone_a: self.zone_b,
            zone_b: self.zone_a,
            pass_a: self.pass_b,
            pass_b: self.pass_a,
            right_of_way: match self.right_of_way {
                RightOfWay::A => RightOfWay::B,
                RightOfWay::B => RightOfWay::A,
                RightOfWay::Neither => RightOfWay::Neither,
            },
        }
    }
}

/// True when a `footprint` (length × width, m) centred on `a`'s reference line at arc length
/// `s` overlaps `b`'s band: some point of a 5 × 3 grid over the rectangle (spacing a quarter
/// length by half a width) lies within b's half-width of its centre line and within its
/// extent. A band narrower than the grid spacing (¼ length) could slip between grid points;
/// lanes are wider. `near_s` (b's arc length of the conflict point) bounds the projection.
fn footprint_overlaps(a: &Lane, s: f64, b: &Lane, near_s: f64, footprint: [f64; 2]) -> bool {
    let (p, tangent, _) = a.pose_at(s, 0);
    let f = Vec2::from_angle(tangent);
    let n = Vec2::new(-f.y, f.x);
    let reach = ZONE_SCAN_M + footprint[0];
    let first = b.segment_at(near_s - reach, 0);
    let last = b.segment_at(near_s + reach, first) + 1;
    for i in 0..5 {
        for j in 0..3 {
            let along = footprint[0] * (i as f64 / 4.0 - 0.5);
            let across = footprint[1] * (j as f64 / 2.0 - 0.5);
            let q = p.plus(f.scale(along)).plus(n.scale(across));
            let fr = b.project_range(q, first, last);
            if fr.s >= 0.0 && fr.s <= b.length() && fr.l.abs() <= b.half_width {
                return true;
            }
        }
    }
    false
}

/// Conflict zone on `a` around its point `s_a` (b's arc length `s_b`) for `footprint`, and
/// whether the lanes merge: b's band still holds a's centre [`MERGE_CHECK_M`] past the point
/// (or at a's end). See [`ConflictPoint::zone_a`].
fn zone_on(a: &Lane, s_a: f64, b: &Lane, s_b: f64, footprint: [f64; 2]) -> ([f64; 2], bool) {
    let inside = |s: f64| footprint_overlaps(a, s, b, s_b, footprint);
    let bisect = |mut inn: f64, mut out: f64| {
        for _ in 0..10 {
            let mid = 0.5 * (inn + out);
            if inside(mid) {
                inn = mid;
            } else {
                out = mid;
            }
        }
        inn
    };
    let lowest = (s_a - ZONE_SCAN_M).max(-0.5 * footprint[0]);
    let mut s = s_a;
    while s - ZONE_STEP_M >= lowest && inside(s - ZONE_STEP_M) {
        s -= ZONE_STEP_M;
    }
    let enter = if s - ZONE_STEP_M < lowest {
        lowest
    } else {
        bisect(s, s - ZONE_STEP_M)
    };
    let later = (s_a + MERGE_CHECK_M).min(a.length());
    let f = b.project(a.pose_at(later, 0).0);
    if later > s_a && f.s >= 0.0 && f.s <= b.length() + 1e-6 && f.l.abs() <= b.half_width {
        return ([enter, s_a + footprint[0]], true);
    }
    let mut s = s_a;
    while s + ZONE_STEP_M <= s_a + ZONE_SCAN_M && inside(s + ZONE_STEP_M) {
        s += ZONE_STEP_M;
    }
    ([enter, bisect(s, s + ZONE_STEP_M)], false)
}

/// Right of way between lanes `a` and `b` at their point (arc lengths `s_a`, `s_b`).
fn right_of_way(a: &Lane, s_a: f64, b: &Lane, s_b: f64, rule: JunctionRule) -> RightOfWay {
    match a.priority.cmp(&b.priority) {
        core::cmp::Ordering::Greater => RightOfWay::A,
        core::cmp::Ordering::Less => RightOfWay::B,
        core::cmp::Ordering::Equal => match rule {
            JunctionRule::Levels => RightOfWay::Neither,
            JunctionRule::RightBeforeLeft => {
                // b comes from a's right when it heads to a's left: t_a × t_b > 0.
                let ta = Vec2::from_angle(a.pose_at(s_a, 0).1);
                let tb = Vec2::from_angle(b.pose_at(s_b, 0).1);
                let c = ta.cross(tb);
                if c > 0.1 {
                    RightOfWay::B
                } else if c < -0.1 {
                    RightOfWay::A
                } else {
                    RightOfWay::Neither
                }
            }
        },
    }
}

/// Intersection morphology 𝓘 = {P_stop, R_lane, L_ref} (eq. 2) with its conflict points,
/// their zones and right of way.
#[derive(Clone, Copy, Debug)]
pub struct Morphology {
    lanes: [Lane; MAX_LANES],
    n_lanes: usize,
    conflicts: [ConflictPoint; MAX_CONFLICTS],
    n_conflicts: usize,
    rule: JunctionRule,
    footprint: [f64; 2],
}

impl Morphology {
    /// Builds a morphology and finds every conflict point between lanes where neither
    /// branches off the other (lanes of one approach, or a lane that starts on another and
    /// runs along it, diverge rather than conflict: a road user ahead on the shared stretch is
    /// a leader); equal priority levels are first come first served.
    pub fn new(lanes: &[Lane]) -> Result<Self, GeometryError> {
        Self::with_rule(lanes, JunctionRule::Levels)
    }

    /// [`Morphology::new`] with `rule` for equal priority levels.
    pub fn with_rule(lanes: &[Lane], rule: JunctionRule) -> Result<Self, GeometryError> {
        if lanes.is_empty() {
            return Err(GeometryError::TooFewPoints);
        }
        if lanes.len() > MAX_LANES {
            return Err(GeometryError::TooManyLanes);
        }
        let mut m = Morphology {
            lanes: [lanes[0]; MAX_LANES],
            n_lanes: lanes.len(),
            conflicts: [ConflictPoint::default(); MAX_CONFLICTS],
            n_conflicts: 0,
            rule,
            footprint: DEFAULT_FOOTPRINT_M,
        };
        m.lanes[..lanes.len()].copy_from_slice(lanes);
        for a in 0..lanes.len() {
            for b in a + 1..lanes.len() {
                if branches_off(&lanes[a], &lanes[b]) || branches_off(&lanes[b], &lanes[a]) {
                    continue;
                }
                if let Some((s_a, s_b, pos)) = first_contact(&lanes[a], &lanes[b]) {
                    if m.n_conflicts == MAX_CONFLICTS {
                        return Err(GeometryError::TooManyConflicts);
                    }
                    m.conflicts[m.n_conflicts] = ConflictPoint {
                        lane_a: a as u8,
                        lane_b: b as u8,
                        s_a,
                        s_b,
                        pos,
                        right_of_way: right_of_way(&lanes[a], s_a, &lanes[b], s_b, rule),
                        ..ConflictPoint::default()
                    };
                    m.n_conflicts += 1;
                }
            }
        }
        m.derive_zones();
        Ok(m)
    }

    /// Derives every conflict zone again for a vehicle footprint of `length_m` × `width_m`.
    pub fn fit_footprint(&mut self, length_m: f64, width_m: f64) {
        if self.footprint != [length_m, width_m] {
            self.footprint = [length_m, width_m];
            self.derive_zones();
        }
    }

    fn derive_zones(&mut self) {
        for c in self.conflicts[..self.n_conflicts].iter_mut() {
            let (a, b) = (
                &self.lanes[c.lane_a as usize],
                &self.lanes[c.lane_b as usize],
            );
            let (zone_a, merge_a) = zone_on(a, c.s_a, b, c.s_b, self.footprint);
            let (zone_b, merge_b) = zone_on(b, c.s_b, a, c.s_a, self.footprint);
            c.zone_a = zone_a;
            c.zone_b = zone_b;
            let half = 0.5 * self.footprint[0];
            (c.kind, c.pass_a, c.pass_b) = if merge_a || merge_b {
                (
                    ConflictKind::Merging,
                    [c.s_a - half, c.s_a + half],
                    [c.s_b - half, c.s_b + half],
                )
            } else {
                (ConflictKind::Crossing, zone_a, zone_b)
            };
        }
    }

    /// Sets the right of way at the conflict point of lanes `a` and `b` (`A` is lane `a`), as
    /// a map with pairwise rules (SUMO's junction requests) gives it; false when the lanes
    /// have no conflict point.
    pub fn set_right_of_way(&mut self, a: u8, b: u8, right_of_way: RightOfWay) -> bool {
        match self.conflicts[..self.n_conflicts]
            .iter_mut()
            .find(|c| (c.lane_a, c.lane_b) == (a, b) || (c.lane_a, c.lane_b) == (b, a))
        {
            Some(c) => {
                c.right_of_way = if c.lane_a == a {
                    right_of_way
                } else {
                    match right_of_way {
                        RightOfWay::A => RightOfWay::B,
                        RightOfWay::B => RightOfWay::A,
                        RightOfWay::Neither => RightOfWay::Neither,
                    }
                };
                true
            }
            None => false,
        }
    }

    /// How equal priority levels are resolved.
    pub fn rule(&self) -> JunctionRule {
        self.rule
    }

    /// The footprint the conflict zones are derived for, [length, width] in m.
    pub fn footprint(&self) -> [f64; 2] {
        self.footprint
    }

    pub fn lanes(&self) -> &[Lane] {
        &self.lanes[..self.n_lanes]
    }
    pub fn lane(&self, i: u8) -> &Lane {
        &self.lanes[i as usize]
    }
    pub fn conflicts(&self) -> &[ConflictPoint] {
        &self.conflicts[..self.n_conflicts]
    }

    /// Conflict point between lanes `a` and `b`, as (s on a, s on b).
    pub fn conflict_between(&self, a: u8, b: u8) -> Option<(f64, f64)> {
        self.conflict(a, b).map(|c| (c.s_a, c.s_b))
    }

    /// The conflict point between lanes `a` and `b`, seen from `a`.
    pub fn conflict(&self, a: u8, b: u8) -> Option<ConflictPoint> {
        self.conflicts()
            .iter()
            .find(|c| (c.lane_a, c.lane_b) == (a, b) || (c.lane_a, c.lane_b) == (b, a))
            .map(|c| c.seen_from(a))
    }

    /// Conflict zones on `lane` against every other lane, as centre arc lengths [enter, exit].
    pub fn zones_on(&self, lane: u8) -> impl Iterator<Item = [f64; 2]> + '_ {
        self.conflicts()
            .iter()
            .filter(move |c| c.lane_a == lane || c.lane_b == lane)
            .map(move |c| c.seen_from(lane).zone_a)
    }

    /// Lane that best explains an agent's pose: within the lane boundary (from
    /// [`LANE_EXTENSION_M`] before its first vertex to its end) and heading within
    /// `max_heading_err` rad of the tangent; the smallest |l| (plus, behind the first vertex,
    /// the distance to it) wins, and a lane whose turn
    /// contradicts a left or right `signal` counts as [`SIGNAL_MISMATCH_M`] further away (lanes
    /// of one approach overlap until they diverge, so there the signal decides; without a
    /// signal, or with hazard lights, the lowest index wins ties). Returns (lane, Frenet).
    pub fn match_lane(
        &self,
        pos: Vec2,
        dir: Vec2,
        max_heading_err: f64,
        signal: TurnSignal,
    ) -> Option<(u8, Frenet)> {
        let shown = match signal {
            TurnSignal::Left => Some(Turn::Left),
            TurnSignal::Right => Some(Turn::Right),
            TurnSignal::Off | TurnSignal::Hazard => None,
        };
        let mut best: Option<(u8, Frenet, f64)> = None;
        for (i, lane) in self.lanes().iter().enumerate() {
            let f = lane.project(pos);
            if f.l.abs() > lane.half_width
                || f.s < -LANE_EXTENSION_M
                || f.s > lane.length() + lane.half_width
            {
                continue;
            }
            let t = Vec2::from_angle(f.tangent);
            let err = atan2(t.cross(dir), t.dot(dir)).abs();
            if err > max_heading_err {
                continue;
            }
            let mismatch = shown.is_some_and(|turn| turn != lane.turn);
            // Behind the first vertex, the distance along the extension counts too: a lane
            // the agent is on beats one it would be on only if that lane reached back further.
            let cost = f.l.abs() + (-f.s).max(0.0) + if mismatch { SIGNAL_MISMATCH_M } else { 0.0 };
            if best.is_none_or(|(_, _, b)| cost < b - 1e-9) {
                best = Some((i as u8, f, cost));
            }
        }
        best.map(|(i, f, _)| (i, f))
    }
}

/// The ego's route across one or more junctions, as lanes of a morphology: one *leg* per
/// junction, each leg's lane the rest of the route from that junction's approach on (so the
/// junctions further along are in view from the first), with its stop line and its turn.
/// The ego drives on a leg until it has passed the leg's handover arc length (where it has
/// cleared the leg's junction), then on the next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Route {
    lanes: [u8; MAX_ROUTE_LEGS],
    /// Arc length on each leg's lane past which the next leg takes over, m.
    handover_s: [f64; MAX_ROUTE_LEGS],
    n: usize,
}

impl Route {
    /// A route of one lane.
    pub fn single(lane: u8) -> Route {
        Route {
            lanes: [lane; MAX_ROUTE_LEGS],
            handover_s: [f64::INFINITY; MAX_ROUTE_LEGS],
            n: 1,
        }
    }

    /// A route of `legs`, each (lane, handover arc length on it in m; the last one's is
    /// unused); `None` when there are none or more than [`MAX_ROUTE_LEGS`].
    pub fn new(legs: &[(u8, f64)]) -> Option<Route> {
        if legs.is_empty() || legs.len() > MAX_ROUTE_LEGS {
            return None;
        }
        let mut r = Route::single(legs[0].0);
        for (k, &(lane, handover)) in legs.iter().enumerate() {
            r.lanes[k] = lane;
            r.handover_s[k] = handover;
        }
        r.n = legs.len();
        Some(r)
    }

    /// The legs' lanes, in driving order.
    pub fn lanes(&self) -> &[u8] {
        &self.lanes[..self.n]
    }

    /// The lane of the first leg.
    pub fn first(&self) -> u8 {
        self.lanes[0]
    }

    /// Arc length on leg `k`'s lane past which the next leg takes over, m.
    pub fn handover_s(&self, k: usize) -> f64 {
        self.handover_s[k]
    }

    /// The lane of the leg an ego at `pos` drives on: the first whose handover it has not
    /// passed (the first leg for a position that is not finite, which the step refuses).
    pub fn lane_at(&self, morph: &Morphology, pos: Vec2) -> u8 {
        if !pos.is_finite() {
            return self.lanes[0];
        }
        (0..self.n - 1)
            .find(|&k| morph.lane(self.lanes[k]).project(pos).s <= self.handover_s[k])
            .map_or(self.lanes[self.n - 1], |k| self.lanes[k])
    }
}

/// Whether `b` branches off `a`: its first vertex lies on `a`'s reference line (within
/// [`BRANCH_TOLERANCE_M`], from `a`'s start to its end) heading along it (within
/// [`BRANCH_HEADING_RAD`]). Lanes of one approach, and a route's leg that continues another
/// (the rest of the route from a later junction on), branch off each other.
fn branches_off(a: &Lane, b: &Lane) -> bool {
    let f = a.project(b.points[0]);
    if f.l.abs() > BRANCH_TOLERANCE_M || f.s < -BRANCH_TOLERANCE_M || f.s > a.length() {
        return false;
    }
    let t = Vec2::from_angle(f.tangent);
    let d = b.points[1].minus(b.points[0]);
    atan2(t.cross(d), t.dot(d)).abs() <= BRANCH_HEADING_RAD
}

/// First point along `a` where it touches `b`: (s on a, s on b, point).
fn first_contact(a: &Lane, b: &Lane) -> Option<(f64, f64, Vec2)> {
    const EPS: f64 = 1e-9;
    for i in 0..a.segments() {
        let (p, p2) = (a.points[i], a.points[i + 1]);
        let r = p2.minus(p);
        let mut best: Option<(f64, f64, Vec2)> = None;
        for j in 0..b.segments() {
            let (q, q2) = (b.points[j], b.points[j + 1]);
            let sv = q2.minus(q);
            let denom = r.cross(sv);
            if denom.abs() < EPS {
                continue;
            }
            let qp = q.minus(p);
            let t = qp.cross(sv) / denom;
            let u = qp.cross(r) / denom;
            if (-1e-6..=1.0 + 1e-6).contains(&t) && (-1e-6..=1.0 + 1e-6).contains(&u) {
                let s_a = a.cum_s[i] + t * (a.cum_s[i + 1] - a.cum_s[i]);
                let s_b = b.cum_s[j] + u * (b.cum_s[j + 1] - b.cum_s[j]);
                if best.is_none_or(|(bs, _, _)| s_a < bs) {
                    best = Some((s_a, s_b, p.plus(r.scale(t))));
                }
            }
        }
        if best.is_some() {
            return best;
        }
    }
    None
}

/// Process state P_ti = (p, v, a, θ_v, θ_a, l) of one agent (eq. 3).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProcessState {
    /// Signed distance to the lane's stop line, m (positive before it).
    pub dist_to_stop_m: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Acceleration along the direction of travel, m/s².
    pub accel_mps2: f64,
    /// Angle between velocity and lane direction θ_v, rad.
    pub theta_v: f64,
    /// Angle between acceleration and lane direction θ_a, rad (0 when |a| ≈ 0).
    pub theta_a: f64,
    /// Matched lane l_i, or `None` when the agent is off every lane.
    pub lane: Option<u8>,
    /// Arc length on the matched lane, m.
    pub s_m: f64,
    /// Lateral offset on the matched lane, m.
    pub l_m: f64,
}

impl ProcessState {
    /// Computes P_ti (eq. 3) of an agent in the morphology.
    pub fn of(agent: &AgentState, morph: &Morphology, max_heading_err: f64) -> Self {
        let speed = agent.speed();
        let dir = agent.direction();
        let a_mag = agent.acc.norm();
        match morph.match_lane(agent.pos, dir, max_heading_err, agent.turn_signal) {
            Some((lane_id, f)) => {
                let lane = morph.lane(lane_id);
                let t = Vec2::from_angle(f.tangent);
                let angle_to = |v: Vec2| atan2(t.cross(v), t.dot(v));
                ProcessState {
                    dist_to_stop_m: lane.stop_s - f.s,
                    speed_mps: speed,
                    accel_mps2: agent.longitudinal_accel(),
                    theta_v: if speed > 0.1 {
                        angle_to(agent.vel)
                    } else {
                        angle_to(dir)
                    },
                    theta_a: if a_mag > 0.05 {
                        angle_to(agent.acc)
                    } else {
                        0.0
                    },
                    lane: Some(lane_id),
                    s_m: f.s,
                    l_m: f.l,
                }
            }
            None => ProcessState {
                dist_to_stop_m: f64::INFINITY,
                speed_mps: speed,
                accel_mps2: agent.longitudinal_accel(),
                theta_v: 0.0,
                theta_a: 0.0,
                lane: None,
                s_m: 0.0,
                l_m: 0.0,
            },
        }
    }
}

/// One sample of an agent's history h_i: position and velocity at a time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HistorySample {
    pub time_s: f64,
    pub pos: Vec2,
    pub vel: Vec2,
}

/// History ring of one tracked agent: the last 2 s at 10 Hz.
#[derive(Clone, Copy, Debug, Default)]
pub struct Track {
    pub id: u32,
    samples: [HistorySample; HISTORY_LEN],
    head: usize,
    len: usize,
    last_seen_s: f64,
}

impl Track {
    /// Samples, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &HistorySample> {
        let start = (self.head + HISTORY_LEN - self.len) % HISTORY_LEN;
        (0..self.len).map(move |k| &self.samples[(start + k) % HISTORY_LEN])
    }
    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// The oldest sample no older than `age_s` before `now`, if any.
    pub fn sample_ago(&self, now: f64, age_s: f64) -> Option<&HistorySample> {
        self.iter().find(|h| now - h.time_s <= age_s + 1e-9)
    }
    fn record(&mut self, now: f64, a: &AgentState) {
        self.last_seen_s = now;
        if self.len > 0 {
            let newest = &self.samples[(self.head + HISTORY_LEN - 1) % HISTORY_LEN];
            if now - newest.time_s < HISTORY_PERIOD_S - 1e-9 {
                return;
            }
        }
        self.samples[self.head] = HistorySample {
            time_s: now,
            pos: a.pos,
            vel: a.vel,
        };
        self.head = (self.head + 1) % HISTORY_LEN;
        self.len = (self.len + 1).min(HISTORY_LEN);
    }
}

/// History rings H for every tracked agent, matched by id; the least recently seen slot is
/// reused for a new id.
#[derive(Clone, Copy, Debug)]
pub struct History {
    tracks: [Track; MAX_AGENTS],
    used: [bool; MAX_AGENTS],
}

impl Default for History {
    fn default() -> Self {
        History {
            tracks: [Track::default(); MAX_AGENTS],
            used: [false; MAX_AGENTS],
        }
    }
}

impl History {
    /// Records the scene's agents at time `now`.
    pub fn record(&mut self, now: f64, agents: &[AgentState]) {
        for a in agents {
            let slot = self.slot_for(a.id);
            if !self.used[slot] || self.tracks[slot].id != a.id {
                self.tracks[slot] = Track {
                    id: a.id,
                    ..Track::default()
                };
                self.used[slot] = true;
            }
            self.tracks[slot].record(now, a);
        }
    }

    /// The track of agent `id`.
    pub fn track(&self, id: u32) -> Option<&Track> {
        (0..MAX_AGENTS)
            .find(|&i| self.used[i] && self.tracks[i].id == id)
            .map(|i| &self.tracks[i])
    }

    fn slot_for(&self, id: u32) -> usize {
        if let Some(i) = (0..MAX_AGENTS).find(|&i| self.used[i] && self.tracks[i].id == id) {
            return i;
        }
        if let Some(i) = (0..MAX_AGENTS).find(|&i| !self.used[i]) {
            return i;
        }
        let mut oldest = 0;
        for i in 1..MAX_AGENTS {
            if self.tracks[i].last_seen_s < self.tracks[oldest].last_seen_s {
                oldest = i;
            }
        }
        oldest
    }
}
