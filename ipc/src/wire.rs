//! The wire contract: every payload that crosses a process boundary.
//!
//! All types are `#[repr(C)]`, plain old data of fixed size, and `ZeroCopySend` with a stable
//! `type_name`, so Rust, Python (`bridges/python/concord_wire.py`) and any C-ABI language read
//! them in place. Fields are ordered by alignment and padded explicitly, so no layout depends
//! on a compiler's padding. Floats are IEEE-754, integers little-endian as on the host.
//! Timestamps are `CLOCK_MONOTONIC` nanoseconds, shared by all processes of one machine.
//! Enumerations travel as `u8` codes (the core's enum discriminants); [`UNKNOWN`] marks "not
//! given".

use concord_core::scene::{
    AgentKind, AgentState, ExplicitIntent, ProcessState, Rated, Scene, TurnSignal, Vec2, MAX_AGENTS,
};
use concord_core::trajectory::MAX_POINTS;
use concord_core::{
    opm, Advice, AdviceVerdict, Decision, DecisionCore, DecisionSource, FallbackReason, Maneuver,
};

use crate::clock::secs;
use iceoryx2::prelude::ZeroCopySend;

/// Code for an absent optional value (unknown intent dimension, no lane, no conflict).
pub const UNKNOWN: u8 = 255;
/// Capacity of text buffers, bytes of UTF-8.
pub const TEXT_BYTES: usize = 256;
/// Most characters of an eHMI message.
pub const EHMI_MAX_CHARS: usize = 64;
/// Objects carried by an advice request (the OPM selection).
pub const WIRE_OBJECTS: usize = opm::MAX_SELECTED;
/// Number of `AdviceVerdict` codes.
pub const VERDICTS: usize = AdviceVerdict::ALL.len();
/// Number of `FallbackReason` codes.
pub const FALLBACKS: usize = 4;

/// An explicit intent [style, action, task] (eq. 8), each code with its confidence in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordIntent")]
#[repr(C)]
pub struct WireIntent {
    pub style_confidence: f32,
    pub action_confidence: f32,
    pub task_confidence: f32,
    /// `Style` code or [`UNKNOWN`].
    pub style: u8,
    /// `IntentAction` code or [`UNKNOWN`].
    pub action: u8,
    /// `Task` code or [`UNKNOWN`].
    pub task: u8,
    pub reserved: u8,
}

impl Default for WireIntent {
    fn default() -> Self {
        WireIntent {
            style_confidence: 0.0,
            action_confidence: 0.0,
            task_confidence: 0.0,
            style: UNKNOWN,
            action: UNKNOWN,
            task: UNKNOWN,
            reserved: 0,
        }
    }
}

/// One road user, 𝓕ᵢ (eq. 1) plus identity and explicit cues.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordAgent")]
#[repr(C)]
pub struct WireAgent {
    /// Position, m.
    pub x: f64,
    pub y: f64,
    /// Velocity, m/s.
    pub vx: f64,
    pub vy: f64,
    /// Acceleration, m/s².
    pub ax: f64,
    pub ay: f64,
    /// Heading, rad, counter-clockwise from +x.
    pub heading: f64,
    pub intent: WireIntent,
    /// Track id, stable across frames.
    pub id: u32,
    /// `AgentKind` code.
    pub kind: u8,
    /// `TurnSignal` code.
    pub turn_signal: u8,
    /// 1 when the entry holds a road user; entries with 0 are ignored.
    pub valid: u8,
    pub reserved: u8,
}

/// One perception frame, on `concord/scene`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordSceneFrame")]
#[repr(C)]
pub struct SceneFrame {
    /// Publisher's sequence number, increasing by one per frame.
    pub sequence: u64,
    /// Time of the perception, ns (CLOCK_MONOTONIC).
    pub stamp_ns: u64,
    /// The ego; its intent is the passenger's.
    pub ego: WireAgent,
    pub agents: [WireAgent; MAX_AGENTS],
    /// Navigation intent: index of the ego's route lane; the lane's turn is the instruction.
    pub ego_route_lane: u8,
    pub reserved: [u8; 7],
}

impl Default for SceneFrame {
    fn default() -> Self {
        SceneFrame {
            sequence: 0,
            stamp_ns: 0,
            ego: WireAgent::default(),
            agents: [WireAgent::default(); MAX_AGENTS],
            ego_route_lane: 0,
            reserved: [0; 7],
        }
    }
}

/// A field of a frame that holds no valid code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CodeError {
    /// Agent index, `None` for the ego.
    pub agent: Option<u8>,
    pub field: &'static str,
    pub code: u8,
}

impl core::fmt::Display for CodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.agent {
            Some(i) => write!(f, "agent {i}: {} has no code {}", self.field, self.code),
            None => write!(f, "ego: {} has no code {}", self.field, self.code),
        }
    }
}

fn rated<T: TryFrom<u8, Error = u8>>(
    code: u8,
    confidence: f32,
    field: &'static str,
) -> Result<Option<Rated<T>>, &'static str> {
    if code == UNKNOWN {
        return Ok(None);
    }
    T::try_from(code)
        .map(|value| {
            Some(Rated {
                value,
                confidence: f64::from(confidence),
            })
        })
        .map_err(|_| field)
}

impl WireIntent {
    /// The core's intent; unknown codes are errors (named by field).
    pub fn to_intent(&self) -> Result<ExplicitIntent, &'static str> {
        Ok(ExplicitIntent {
            style: rated(self.style, self.style_confidence, "intent.style")?,
            action: rated(self.action, self.action_confidence, "intent.action")?,
            task: rated(self.task, self.task_confidence, "intent.task")?,
        })
    }

    pub fn from_intent(i: &ExplicitIntent) -> Self {
        let code = |c: Option<(u8, f64)>| {
            c.map(|(v, conf)| (v, conf as f32))
                .unwrap_or((UNKNOWN, 0.0))
        };
        let (style, style_confidence) = code(i.style.map(|r| (r.value as u8, r.confidence)));
        let (action, action_confidence) = code(i.action.map(|r| (r.value as u8, r.confidence)));
        let (task, task_confidence) = code(i.task.map(|r| (r.value as u8, r.confidence)));
        WireIntent {
            style_confidence,
            action_confidence,
            task_confidence,
            style,
            action,
            task,
            reserved: 0,
        }
    }
}

impl WireAgent {
    /// The core's agent state; numbers are checked by the core, codes here.
    pub fn to_agent(&self) -> Result<AgentState, &'static str> {
        Ok(AgentState {
            id: self.id,
            kind: AgentKind::try_from(self.kind).map_err(|_| "kind")?,
            pos: Vec2::new(self.x, self.y),
            vel: Vec2::new(self.vx, self.vy),
            acc: Vec2::new(self.ax, self.ay),
            heading: self.heading,
            turn_signal: TurnSignal::try_from(self.turn_signal).map_err(|_| "turn_signal")?,
            intent: self.intent.to_intent()?,
        })
    }

    pub fn from_agent(a: &AgentState) -> Self {
        WireAgent {
            x: a.pos.x,
            y: a.pos.y,
            vx: a.vel.x,
            vy: a.vel.y,
            ax: a.acc.x,
            ay: a.acc.y,
            heading: a.heading,
            intent: WireIntent::from_intent(&a.intent),
            id: a.id,
            kind: a.kind as u8,
            turn_signal: a.turn_signal as u8,
            valid: 1,
            reserved: 0,
        }
    }
}

impl SceneFrame {
    /// The core's scene, with `time_s` from the frame's stamp. Invalid entries are skipped;
    /// a valid entry with an unknown code is an error.
    pub fn to_scene(&self) -> Result<Scene, CodeError> {
        let ego = self.ego.to_agent().map_err(|field| CodeError {
            agent: None,
            field,
            code: 0,
        })?;
        let mut scene = Scene::new(self.stamp_ns as f64 * 1e-9, ego, self.ego_route_lane);
        for (i, a) in self.agents.iter().enumerate().filter(|(_, a)| a.valid != 0) {
            let agent = a.to_agent().map_err(|field| CodeError {
                agent: Some(i as u8),
                field,
                code: field_code(a, field),
            })?;
            scene.push(agent);
        }
        Ok(scene)
    }

    /// A frame holding `scene`.
    pub fn from_scene(sequence: u64, stamp_ns: u64, scene: &Scene) -> Self {
        let mut f = SceneFrame {
            sequence,
            stamp_ns,
            ego: WireAgent::from_agent(&scene.ego),
            ego_route_lane: scene.ego_lane,
            ..SceneFrame::default()
        };
        for (w, a) in f.agents.iter_mut().zip(scene.agents()) {
            *w = WireAgent::from_agent(a);
        }
        f
    }
}

fn field_code(a: &WireAgent, field: &str) -> u8 {
    match field {
        "kind" => a.kind,
        "turn_signal" => a.turn_signal,
        "intent.style" => a.intent.style,
        "intent.action" => a.intent.action,
        _ => a.intent.task,
    }
}

/// One trajectory point.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordTrajectoryPoint")]
#[repr(C)]
pub struct WirePoint {
    /// Time from the decision, s.
    pub t: f64,
    /// Position, m.
    pub x: f64,
    pub y: f64,
    /// Heading, rad.
    pub heading: f64,
    /// Speed, m/s.
    pub speed: f64,
    /// Longitudinal acceleration, m/s².
    pub accel: f64,
}

/// A decision, on `concord/decision`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordDecision")]
#[repr(C)]
pub struct WireDecision {
    /// Sequence number of the scene it answers. A stale-scene fallback (`fallback =
    /// stale_scene`) answers no new scene and carries the last valid one's: a client matching
    /// decisions to its frames skips it by that code.
    pub scene_sequence: u64,
    /// Core cycle; also the id of the advice request issued with it.
    pub cycle: u64,
    /// Stamp of the scene it answers, ns.
    pub scene_stamp_ns: u64,
    /// When the decision was published, ns.
    pub decided_ns: u64,
    /// Time the core step took, ns.
    pub compute_ns: u64,
    /// Request id of the advice the gate weighed (0 when none): `advice` is its verdict.
    pub advice_request_id: u64,
    /// P_n before (eq. 11) and after (eq. 15) correction, in `Maneuver` order.
    pub p_logit: [f64; 5],
    pub p_corrected: [f64; 5],
    pub trajectory: [WirePoint; MAX_POINTS],
    pub n_points: u32,
    /// `Maneuver` code executed.
    pub maneuver: u8,
    /// `Maneuver` code of the corrected logit.
    pub logit_maneuver: u8,
    /// `DecisionSource` code.
    pub source: u8,
    /// `AdviceVerdict` code.
    pub advice: u8,
    /// `FallbackReason` code.
    pub fallback: u8,
    /// `Announcement` code: what the eHMI tells the other road users.
    pub announce: u8,
    /// Deadlock negotiation `Phase` code.
    pub negotiation: u8,
    /// Maneuvers refused for courtesy in this decision.
    pub courtesy_rejects: u8,
    /// Index of the lane the ego drove on (with a route across several junctions, the leg it
    /// was on; `concord map --route` lists them).
    pub ego_lane: u8,
}

impl WireDecision {
    pub fn from_decision(
        d: &Decision,
        scene_sequence: u64,
        scene_stamp_ns: u64,
        decided_ns: u64,
        compute_ns: u64,
    ) -> Self {
        let mut trajectory = [WirePoint::default(); MAX_POINTS];
        for (w, p) in trajectory.iter_mut().zip(d.trajectory.points()) {
            *w = WirePoint {
                t: p.t,
                x: p.x,
                y: p.y,
                heading: p.heading,
                speed: p.speed,
                accel: p.accel,
            };
        }
        WireDecision {
            scene_sequence,
            cycle: d.cycle,
            scene_stamp_ns,
            decided_ns,
            compute_ns,
            advice_request_id: 0,
            p_logit: d.p_logit,
            p_corrected: d.p_corrected,
            trajectory,
            n_points: d.trajectory.n as u32,
            maneuver: d.maneuver as u8,
            logit_maneuver: d.logit_maneuver as u8,
            source: d.source as u8,
            advice: d.advice as u8,
            fallback: d.fallback as u8,
            announce: d.announce as u8,
            negotiation: d.negotiation as u8,
            courtesy_rejects: d.courtesy_rejects,
            ego_lane: d.ego_lane,
        }
    }

    /// The executed maneuver, source, verdict and fallback, decoded.
    pub fn decode(&self) -> Option<(Maneuver, DecisionSource, AdviceVerdict, FallbackReason)> {
        Some((
            Maneuver::try_from(self.maneuver).ok()?,
            DecisionSource::try_from(self.source).ok()?,
            AdviceVerdict::try_from(self.advice).ok()?,
            FallbackReason::try_from(self.fallback).ok()?,
        ))
    }
}

/// Process state P_ti (eq. 3).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordProcess")]
#[repr(C)]
pub struct WireProcess {
    /// Distance to the stop line, m (positive before it).
    pub dist_to_stop_m: f64,
    pub speed_mps: f64,
    pub accel_mps2: f64,
    /// Angles of velocity and acceleration to the lane, rad.
    pub theta_v: f64,
    pub theta_a: f64,
    /// Frenet position on the matched lane, m.
    pub s_m: f64,
    pub l_m: f64,
    /// Matched lane or [`UNKNOWN`].
    pub lane: u8,
    pub reserved: [u8; 7],
}

impl WireProcess {
    pub fn from_process(p: &ProcessState) -> Self {
        WireProcess {
            dist_to_stop_m: if p.dist_to_stop_m.is_finite() {
                p.dist_to_stop_m
            } else {
                f64::MAX
            },
            speed_mps: p.speed_mps,
            accel_mps2: p.accel_mps2,
            theta_v: p.theta_v,
            theta_a: p.theta_a,
            s_m: p.s_m,
            l_m: p.l_m,
            lane: p.lane.unwrap_or(UNKNOWN),
            reserved: [0; 7],
        }
    }
}

/// Conflict pair C(ego, vⱼ, ΔTTC) (eq. 4).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordConflict")]
#[repr(C)]
pub struct WireConflict {
    /// Conflict point, m.
    pub x: f64,
    pub y: f64,
    /// Distances to the point, m, and guarded TTCs, s.
    pub ego_dist_m: f64,
    pub agent_dist_m: f64,
    pub ego_ttc_s: f64,
    pub agent_ttc_s: f64,
    /// |ΔTTC|, s.
    pub delta_ttc_s: f64,
    /// The other's implicit intent (§4.1): probabilities that it yields, proceeds or is
    /// undecided, and the deceleration it needs to stop before its zone, m/s².
    pub yielding: f32,
    pub proceeding: f32,
    pub undecided: f32,
    pub required_decel_mps2: f32,
    /// Track id of the other party.
    pub agent_id: u32,
    /// 1 when |ΔTTC| is below the threshold.
    pub risky: u8,
    /// 1 when the other can no longer stop comfortably before its zone.
    pub committed: u8,
    /// `RightOfWay` code: 1 the ego, 2 the other, 0 neither.
    pub right_of_way: u8,
    /// `Stated` code: what became of the other's stated action.
    pub stated: u8,
}

/// A selected object of 𝓞 with its process, saliency and relation.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordObject")]
#[repr(C)]
pub struct WireObject {
    pub state: WireAgent,
    pub process: WireProcess,
    /// Longitudinal distance to the ego along lane centre lines, m (`f64::MAX` when none).
    pub longitudinal_m: f64,
    /// Saliency from eq. 7.
    pub saliency: f64,
    /// Index into the request's conflicts, or [`UNKNOWN`].
    pub conflict: u8,
    pub reserved: [u8; 7],
}

/// A request for advice (eq. 16), on `concord/advice_request`: the OPM triplet (eq. 6) and P_n.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordAdviceRequest")]
#[repr(C)]
pub struct AdviceRequest {
    /// Id the advice must quote (the core cycle that issued it).
    pub request_id: u64,
    pub scene_sequence: u64,
    /// When it was issued, and by when the answer must arrive, ns.
    pub issued_ns: u64,
    pub deadline_ns: u64,
    pub p_logit: [f64; 5],
    pub p_corrected: [f64; 5],
    /// The ego's process state and the passenger's intent.
    pub ego: WireProcess,
    pub ego_intent: WireIntent,
    pub objects: [WireObject; WIRE_OBJECTS],
    pub conflicts: [WireConflict; WIRE_OBJECTS],
    /// The car-following leader's gap, m, and speed, m/s (gap `f64::MAX` when none).
    pub leader_gap_m: f64,
    pub leader_speed_mps: f64,
    /// Route turn of the ego (`Turn` code): the navigation instruction.
    pub route_turn: u8,
    pub n_objects: u8,
    pub n_conflicts: u8,
    pub reserved: [u8; 5],
}

impl AdviceRequest {
    /// Builds the request for `decision`, the newest step of `core` (its OPM triplet), whose
    /// ego follows lane `ego_lane` (its turn is the navigation instruction).
    pub fn from_core(
        request_id: u64,
        scene_sequence: u64,
        issued_ns: u64,
        deadline_ns: u64,
        decision: &Decision,
        core: &DecisionCore,
        ego_lane: u8,
    ) -> Self {
        let triplet = core.triplet();
        let opm = core.params().opm;
        let route_turn = core.morphology().lane(ego_lane).turn as u8;
        let mut conflicts = [WireConflict::default(); WIRE_OBJECTS];
        for (w, c) in conflicts.iter_mut().zip(triplet.conflicts()) {
            *w = WireConflict {
                x: c.point.x,
                y: c.point.y,
                ego_dist_m: c.ego_dist_m,
                agent_dist_m: c.agent_dist_m,
                ego_ttc_s: c.ego_ttc_s,
                agent_ttc_s: c.agent_ttc_s,
                delta_ttc_s: c.delta_ttc_s,
                agent_id: triplet
                    .objects()
                    .iter()
                    .find(|o| o.agent == c.agent)
                    .map(|o| o.id)
                    .unwrap_or(u32::MAX),
                yielding: c.intent.yielding as f32,
                proceeding: c.intent.proceeding as f32,
                undecided: c.intent.undecided as f32,
                required_decel_mps2: c.intent.required_decel_mps2 as f32,
                risky: u8::from(c.is_risky(&opm)),
                committed: u8::from(c.intent.committed),
                right_of_way: c.right_of_way as u8,
                stated: c.intent.stated as u8,
            };
        }
        let mut objects = [WireObject::default(); WIRE_OBJECTS];
        for (w, o) in objects.iter_mut().zip(triplet.objects()) {
            *w = WireObject {
                state: WireAgent::from_agent(&o.state),
                process: WireProcess::from_process(&o.process),
                longitudinal_m: if o.longitudinal_m.is_finite() {
                    o.longitudinal_m
                } else {
                    f64::MAX
                },
                saliency: o.saliency,
                conflict: o.conflict.unwrap_or(UNKNOWN),
                reserved: [0; 7],
            };
        }
        AdviceRequest {
            request_id,
            scene_sequence,
            issued_ns,
            deadline_ns,
            p_logit: decision.p_logit,
            p_corrected: decision.p_corrected,
            ego: WireProcess::from_process(&triplet.ego),
            ego_intent: WireIntent::from_intent(&triplet.ego_intent),
            objects,
            conflicts,
            leader_gap_m: triplet.leader.map(|l| l.gap_m).unwrap_or(f64::MAX),
            leader_speed_mps: triplet.leader.map(|l| l.speed_mps).unwrap_or(0.0),
            route_turn,
            n_objects: triplet.n_objects as u8,
            n_conflicts: triplet.n_conflicts as u8,
            reserved: [0; 5],
        }
    }
}

/// An intent parsed for one road user, by track id.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordAgentIntent")]
#[repr(C)]
pub struct WireAgentIntent {
    pub intent: WireIntent,
    pub agent_id: u32,
    pub reserved: [u8; 4],
}

/// The sidecar's advice A_final, on `concord/advice`.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordAdvice")]
#[repr(C)]
pub struct WireAdvice {
    /// The request it answers.
    pub request_id: u64,
    /// When the sidecar published it (`CLOCK_MONOTONIC`, ns): the core judges the deadline by
    /// it, and refuses a stamp later than its own receipt or earlier than the request.
    pub published_ns: u64,
    /// Confidence in [0, 1].
    pub confidence: f64,
    /// The passenger's parsed intent, and other road users' (up to eight).
    pub ego_intent: WireIntent,
    pub agent_intents: [WireAgentIntent; WIRE_OBJECTS],
    /// `Maneuver` code.
    pub maneuver: u8,
    /// 1 when the sidecar produced a usable answer; 0 marks a failed request.
    pub valid: u8,
    pub n_agent_intents: u8,
    /// [`AdviceFailure`] code when `valid` is 0.
    pub failure: u8,
    pub reserved: [u8; 4],
}

/// A valid advice as the core takes it: A_final and the intents parsed from language that it
/// carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CheckedAdvice {
    pub advice: Advice,
    /// The passenger's intent.
    pub ego: ExplicitIntent,
    /// Other road users' intents by agent id; the first `n_agents` are set.
    pub agents: [(u32, ExplicitIntent); WIRE_OBJECTS],
    pub n_agents: usize,
}

impl CheckedAdvice {
    /// Merges the intents into `scene`, each dimension keeping the more confident parse; weak
    /// ones are ignored later by the core's threshold.
    pub fn merge_intents_into(&self, scene: &mut Scene) {
        scene.ego.intent = scene.ego.intent.merged_with(&self.ego);
        let n = scene.n_agents;
        for agent in scene.agents[..n].iter_mut() {
            if let Some((_, i)) = self.agents[..self.n_agents]
                .iter()
                .find(|(id, _)| *id == agent.id)
            {
                agent.intent = agent.intent.merged_with(i);
            }
        }
    }
}

impl WireAdvice {
    /// The advice, checked as a scene frame is: every code known, every confidence finite and
    /// in [0, 1], at most [`WIRE_OBJECTS`] intents, and a publish stamp no later than its
    /// receipt at `received_ns`. `Ok(None)` for a failure report (`valid = 0`), which carries
    /// nothing to install; `Err` names the first field at fault.
    pub fn check(&self, received_ns: u64) -> Result<Option<CheckedAdvice>, &'static str> {
        if self.valid == 0 {
            return Ok(None);
        }
        if self.valid != 1 {
            return Err("valid");
        }
        let maneuver = Maneuver::try_from(self.maneuver).map_err(|_| "maneuver")?;
        if !(0.0..=1.0).contains(&self.confidence) {
            return Err("confidence");
        }
        if self.published_ns > received_ns {
            return Err("published_ns");
        }
        let n = self.n_agent_intents as usize;
        if n > WIRE_OBJECTS {
            return Err("n_agent_intents");
        }
        let intent = |w: &WireIntent| {
            let i = w.to_intent()?;
            i.check().map_err(|_| "intent confidence")?;
            Ok(i)
        };
        let mut out = CheckedAdvice {
            advice: Advice {
                request_id: self.request_id,
                maneuver,
                confidence: self.confidence,
                published_at_s: secs(self.published_ns),
            },
            ego: intent(&self.ego_intent)?,
            agents: [(0, ExplicitIntent::UNKNOWN); WIRE_OBJECTS],
            n_agents: n,
        };
        for (o, w) in out.agents.iter_mut().zip(&self.agent_intents[..n]) {
            *o = (w.agent_id, intent(&w.intent)?);
        }
        Ok(Some(out))
    }
}

/// Why the sidecar could not answer a request; the index into [`CoreStats::advice_failures`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum AdviceFailure {
    /// No reply before the deadline.
    Timeout = 0,
    /// The server refused or dropped the connection.
    Connection = 1,
    /// The server answered with an HTTP error status.
    HttpStatus = 2,
    /// The reply is not the JSON of a chat completion.
    Malformed = 3,
    /// The answer is JSON but breaks the schema (unknown enum value, missing field).
    SchemaViolation = 4,
}

impl AdviceFailure {
    pub const ALL: [AdviceFailure; 5] = [
        AdviceFailure::Timeout,
        AdviceFailure::Connection,
        AdviceFailure::HttpStatus,
        AdviceFailure::Malformed,
        AdviceFailure::SchemaViolation,
    ];
    pub fn name(self) -> &'static str {
        match self {
            AdviceFailure::Timeout => "timeout",
            AdviceFailure::Connection => "connection",
            AdviceFailure::HttpStatus => "http_status",
            AdviceFailure::Malformed => "malformed",
            AdviceFailure::SchemaViolation => "schema_violation",
        }
    }
    pub fn from_code(code: u8) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }
}

/// Who wrote a text.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum TextSource {
    Passenger = 0,
    RoadUser = 1,
}

/// Text from the passenger or another road user, on `concord/intent_text`. Untrusted.
///
/// `(source, source_id)` names the party: the sidecar sets only that party's intent from the
/// text, whatever the text says. `id` numbers the messages of one party; with `stamp_ns` it lets
/// the sidecar parse each message once, also when iceoryx2 hands a restarted sidecar the last
/// sample again (a message is a repeat when neither its id nor its stamp is newer than those of
/// the party's last parsed message, so a restarted publisher whose ids begin again is heard).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordIntentText")]
#[repr(C)]
pub struct IntentText {
    /// When the message was sent, `CLOCK_MONOTONIC` ns.
    pub stamp_ns: u64,
    /// Number of the message from its source, increasing by 1 per message (from 1).
    pub id: u64,
    /// Track id of the road user (0 for the passenger).
    pub source_id: u32,
    /// Bytes used in `text`.
    pub len: u16,
    /// `TextSource` code.
    pub source: u8,
    pub reserved: u8,
    /// UTF-8, not NUL-terminated.
    pub text: [u8; TEXT_BYTES],
}

/// Who an eHMI message is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Audience {
    /// Everyone around the car (the external display).
    Broadcast = 0,
    /// One road user, by track id (`addressee`).
    RoadUser = 1,
    /// The passenger (the in-vehicle HMI).
    Passenger = 2,
}

/// What an eHMI message does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum EhmiKind {
    /// Announces the executed decision.
    Decision = 0,
    /// Asks a road user whose intent is unknown ("Do you intend to pass first?").
    Inquiry = 1,
    /// Answers a road user's message.
    Reply = 2,
    /// Asks the passenger to confirm a weak intent.
    Confirmation = 3,
}

/// An eHMI message, on `concord/ehmi`: a decision announced, a question or a reply.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("ConcordEhmiMessage")]
#[repr(C)]
pub struct EhmiMessage {
    /// The core cycle of the decision it describes (the newest one for questions and replies).
    pub decision_cycle: u64,
    pub stamp_ns: u64,
    /// Bytes used in `text` (at most [`EHMI_MAX_CHARS`] characters).
    pub len: u16,
    /// `Maneuver` code of that decision.
    pub maneuver: u8,
    /// [`Audience`] code.
    pub audience: u8,
    /// Track id of the road user addressed (audience `RoadUser`), else 0.
    pub addressee: u32,
    /// [`EhmiKind`] code.
    pub kind: u8,
    pub reserved: [u8; 7],
    pub text: [u8; TEXT_BYTES],
}

/// Copies `s` into a fixed buffer, cut at a character boundary; returns the bytes used.
pub fn write_text(buf: &mut [u8; TEXT_BYTES], s: &str) -> u16 {
    let mut end = s.len().min(TEXT_BYTES);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    buf[..end].copy_from_slice(&s.as_bytes()[..end]);
    buf[end..].fill(0);
    end as u16
}

/// The text of a fixed buffer, or `None` when it is not UTF-8 or `len` is out of range.
pub fn read_text(buf: &[u8; TEXT_BYTES], len: u16) -> Option<&str> {
    core::str::from_utf8(buf.get(..len as usize)?).ok()
}

impl IntentText {
    /// Message `id` of party (`source`, `source_id`), sent at `stamp_ns`; `text` is cut at a
    /// character boundary to [`TEXT_BYTES`].
    pub fn new(stamp_ns: u64, id: u64, source: TextSource, source_id: u32, text: &str) -> Self {
        let mut t = IntentText {
            stamp_ns,
            id,
            source_id,
            len: 0,
            source: source as u8,
            reserved: 0,
            text: [0; TEXT_BYTES],
        };
        t.len = write_text(&mut t.text, text);
        t
    }
    pub fn text(&self) -> Option<&str> {
        read_text(&self.text, self.len)
    }
}

impl EhmiMessage {
    /// A message of `kind` for `audience`; `text` is cut to [`EHMI_MAX_CHARS`] characters.
    pub fn new(
        decision_cycle: u64,
        stamp_ns: u64,
        maneuver: Maneuver,
        kind: EhmiKind,
        audience: Audience,
        addressee: u32,
        text: &str,
    ) -> Self {
        let cut: usize = text
            .char_indices()
            .nth(EHMI_MAX_CHARS)
            .map(|(i, _)| i)
            .unwrap_or(text.len());
        let mut m = EhmiMessage {
            decision_cycle,
            stamp_ns,
            len: 0,
            maneuver: maneuver as u8,
            audience: audience as u8,
            addressee,
            kind: kind as u8,
            reserved: [0; 7],
            text: [0; TEXT_BYTES],
        };
        m.len = write_text(&mut m.text, &text[..cut]);
        m
    }
    pub fn text(&self) -> Option<&str> {
        read_text(&self.text, self.len)
    }
}

/// Why the core rejected a frame; the index into [`CoreStats::frames_rejected`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum FrameReject {
    /// An enumeration field holds an unknown code.
    BadCode = 0,
    /// NaN or ±∞.
    NotFinite = 1,
    /// A value outside its plausible range.
    OutOfRange = 2,
    /// The same sequence number again.
    Duplicate = 3,
    /// An older sequence number with an older stamp.
    OutOfOrder = 4,
}

impl FrameReject {
    pub const ALL: [FrameReject; 5] = [
        FrameReject::BadCode,
        FrameReject::NotFinite,
        FrameReject::OutOfRange,
        FrameReject::Duplicate,
        FrameReject::OutOfOrder,
    ];
    pub fn name(self) -> &'static str {
        match self {
            FrameReject::BadCode => "bad_code",
            FrameReject::NotFinite => "not_finite",
            FrameReject::OutOfRange => "out_of_range",
            FrameReject::Duplicate => "duplicate",
            FrameReject::OutOfOrder => "out_of_order",
        }
    }
}

/// Latency percentiles, ns: p50, p90, p99, p99.9, max.
pub type Percentiles = [u64; 5];

/// The core's counters and latencies, on `stats`, published once a second.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("ConcordCoreStats")]
#[repr(C)]
pub struct CoreStats {
    pub stamp_ns: u64,
    /// Since the loop started, ns.
    pub uptime_ns: u64,
    /// Loop period, ns.
    pub period_ns: u64,
    pub ticks: u64,
    /// Ticks whose work ended after the next tick was due, or that started a period late.
    pub missed_deadlines: u64,
    /// Samples taken from `scene` (including those superseded within a tick).
    pub frames_received: u64,
    /// Frames replaced by a newer one before the core looked at them (newest wins).
    pub frames_superseded: u64,
    /// Frames the core decided on.
    pub frames_accepted: u64,
    /// Frames rejected, by [`FrameReject`] code.
    pub frames_rejected: [u64; 5],
    /// Restarts of the scene publisher (sequence went back while time went on).
    pub publisher_restarts: u64,
    /// Decisions published, by `DecisionSource` code.
    pub decisions: [u64; 3],
    /// Decisions by `FallbackReason` code.
    pub fallbacks: [u64; FALLBACKS],
    pub advice_requests: u64,
    /// Samples taken from `advice`. Each is counted once more: under a verdict, as superseded,
    /// or as pending: `advice_received = Σ advice_verdicts + advice_superseded + advice_pending`.
    pub advice_received: u64,
    /// Each received advice by the verdict of the first decision that weighed it
    /// (`AdviceVerdict` code); malformed advice and failure reports when taken.
    pub advice_verdicts: [u64; VERDICTS],
    /// Advice replaced by a newer one before any decision weighed it (newest wins).
    pub advice_superseded: u64,
    /// 1 while a valid advice waits for its first decision, else 0.
    pub advice_pending: u64,
    /// Requests the sidecar reported it could not answer, by [`AdviceFailure`] code.
    pub advice_failures: [u64; 5],
    /// Maneuvers refused for courtesy (they would make another road user brake harder than
    /// `max_imposed_decel_mps2`), over all decisions.
    pub courtesy_rejects: u64,
    /// Deadlock negotiations in which the ego announced that it goes first.
    pub deadlock_announcements: u64,
    /// Whole-tick work time.
    pub cycle_ns: Percentiles,
    /// Scene stamp to the core's receipt.
    pub scene_age_ns: Percentiles,
    /// Scene receipt to decision published.
    pub decide_ns: Percentiles,
}
