//! Concord's decision core: the whole method of the paper as one allocation-free,
//! bounded-time step.
//!
//! [`DecisionCore::step`] runs, in order: scene validation and history ([`scene`], eq. 1–3),
//! OPM object selection and conflict assessment ([`opm`], eq. 4–6), saliency ([`saliency`],
//! eq. 7), the corrected logit choice ([`choice`], eq. 9–15), the gate on LLM advice
//! ([`advice`], eq. 16) and Monte Carlo trajectory sampling ([`trajectory`], eq. 17–24).
//!
//! The crate is `no_std` without `alloc`: every buffer has a fixed capacity, and nothing
//! blocks, allocates or does I/O. Bad numbers are rejected with a reason, never a panic.

#![no_std]

/// Declares a `#[repr(u8)]` enum whose discriminants are its wire codes, with
/// `TryFrom<u8>` (the error is the unknown code).
macro_rules! coded_enum {
    ($(#[$meta:meta])* $vis:vis enum $name:ident { $($(#[$vmeta:meta])* $variant:ident = $code:literal),+ $(,)? }) => {
        $(#[$meta])*
        #[repr(u8)]
        $vis enum $name { $($(#[$vmeta])* $variant = $code),+ }

        impl TryFrom<u8> for $name {
            type Error = u8;
            fn try_from(code: u8) -> Result<Self, u8> {
                match code {
                    $($code => Ok($name::$variant),)+
                    other => Err(other),
                }
            }
        }
    };
}

pub mod advice;
pub mod choice;
pub mod opm;
pub mod params;
pub mod saliency;
mod saliency_key;
pub mod scene;
pub mod trajectory;

pub use advice::{Advice, AdviceVerdict};
pub use choice::Maneuver;
pub use params::{ParamError, Params};
pub use scene::{AgentState, Morphology, Scene, SceneError};
pub use trajectory::{Trajectory, TrajectoryPoint};

use advice::RequestLog;
use choice::{ChoiceHistory, ChoiceOutcome, EgoContext, Profile};
use opm::{ConflictSet, OpmTriplet};
use saliency::Saliency;
use scene::{History, Lane, ProcessState, SceneErrorKind, SceneField, Vec2, MAX_AGENTS};
use trajectory::{Candidate, FrenetState, PlanStats, Planner};

coded_enum! {
/// Which path produced a decision.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DecisionSource {
    /// The corrected logit choice (eq. 15).
    #[default]
    Logit = 0,
    /// The LLM's A_final, accepted by the gate (eq. 16).
    Advice = 1,
    /// The minimum-risk fallback.
    MinimumRisk = 2,
}
}

coded_enum! {
/// Why the minimum-risk fallback ran.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FallbackReason {
    #[default]
    None = 0,
    /// No sampled candidate of the chosen maneuver, nor of "decelerate", was feasible.
    NoFeasibleTrajectory = 1,
    /// The scene is older than the staleness limit (decided by the host).
    StaleScene = 2,
}
}

/// One decision of the core.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Decision {
    /// Cycle number; it is also the id of the advice request this cycle issues.
    pub cycle: u64,
    /// Timestamp of the scene it answers, s.
    pub scene_time_s: f64,
    /// The executed maneuver.
    pub maneuver: Maneuver,
    /// The corrected logit's choice, whatever was executed.
    pub logit_maneuver: Maneuver,
    /// P_n before correction (eq. 11) and after (eq. 15), in `Maneuver` order.
    pub p_logit: [f64; choice::MANEUVERS],
    pub p_corrected: [f64; choice::MANEUVERS],
    pub source: DecisionSource,
    /// What the gate made of the advice offered this cycle.
    pub advice: AdviceVerdict,
    pub fallback: FallbackReason,
    pub trajectory: Trajectory,
    /// Monte Carlo statistics of the executed plan.
    pub plan: PlanStats,
}

/// The decision core: parameters, geometry and every piece of state the method keeps.
#[derive(Clone, Copy, Debug)]
pub struct DecisionCore {
    params: Params,
    morph: Morphology,
    cycle: u64,
    last_scene_time_s: f64,
    history: History,
    choices: ChoiceHistory,
    requests: RequestLog,
    triplet: OpmTriplet,
    conflicts: ConflictSet,
    saliency: Saliency,
    processes: [ProcessState; MAX_AGENTS],
    choice: ChoiceOutcome,
    planner: Planner,
    last: Decision,
    ego_lane: u8,
}

impl DecisionCore {
    /// A core for `morph` with validated `params`.
    pub fn new(params: Params, morph: Morphology) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(DecisionCore {
            params,
            morph,
            cycle: 0,
            last_scene_time_s: f64::NEG_INFINITY,
            history: History::default(),
            choices: ChoiceHistory::default(),
            requests: RequestLog::default(),
            triplet: OpmTriplet::default(),
            conflicts: ConflictSet::default(),
            saliency: Saliency::default(),
            processes: [ProcessState::default(); MAX_AGENTS],
            choice: ChoiceOutcome::default(),
            planner: Planner::default(),
            last: Decision::default(),
            ego_lane: 0,
        })
    }

    pub fn params(&self) -> &Params {
        &self.params
    }
    pub fn morphology(&self) -> &Morphology {
        &self.morph
    }
    /// The ego's conflicts with every agent in the last step.
    pub fn conflicts(&self) -> &ConflictSet {
        &self.conflicts
    }
    /// The OPM triplet of the last step, with saliency filled in.
    pub fn triplet(&self) -> &OpmTriplet {
        &self.triplet
    }
    /// The attention output of the last step.
    pub fn saliency(&self) -> &Saliency {
        &self.saliency
    }
    /// Everything the choice stage computed in the last step.
    pub fn choice(&self) -> &ChoiceOutcome {
        &self.choice
    }
    /// The planner of the last step: start state, occupancy, samples.
    pub fn planner(&self) -> &Planner {
        &self.planner
    }
    /// Process states of all agents of the last step, in scene order.
    pub fn processes(&self) -> &[ProcessState; MAX_AGENTS] {
        &self.processes
    }
    /// The last decision.
    pub fn last_decision(&self) -> &Decision {
        &self.last
    }

    /// Runs the whole method on one scene. `now` is the host's monotonic clock, s, against
    /// which advice deadlines are kept; `advice` is the newest advice received, if any.
    pub fn step(
        &mut self,
        scene: &Scene,
        now: f64,
        advice: Option<&Advice>,
    ) -> Result<Decision, SceneError> {
        scene.validate(&self.params.limits, self.morph.lanes().len())?;
        if !now.is_finite() {
            return Err(SceneError {
                agent: None,
                field: SceneField::Time,
                kind: SceneErrorKind::NotFinite,
            });
        }
        if scene.time_s < self.last_scene_time_s {
            // A restarted source: the histories belong to another timeline.
            self.history = History::default();
            self.choices = ChoiceHistory::default();
        }
        self.last_scene_time_s = scene.time_s;
        self.cycle += 1;
        self.ego_lane = scene.ego_lane;
        self.requests.issue(self.cycle, now);
        let p = self.params;

        self.history.record(scene.time_s, scene.agents());
        for (i, a) in scene.agents().iter().enumerate() {
            self.processes[i] = ProcessState::of(a, &self.morph, p.opm.lane_match_heading_rad);
        }
        opm::build(
            scene,
            &self.morph,
            &p.opm,
            &self.processes,
            &mut self.triplet,
            &mut self.conflicts,
        );
        saliency::apply(
            scene,
            &mut self.triplet,
            &self.history,
            &p.opm,
            &p.saliency,
            &mut self.saliency,
        );

        let lane = *self.morph.lane(scene.ego_lane);
        let start = frenet_start(&scene.ego, &lane, &p);
        let ctx = self.ego_context(&lane, &start);
        choice::choose(
            &self.triplet,
            &self.conflicts,
            &ctx,
            &self.choices,
            &p.opm,
            &p.choice,
            &mut self.choice,
        );

        self.planner.prepare(
            &lane,
            start,
            self.goal_distance(),
            scene.agents(),
            &self.processes,
            &self.morph,
            &p.trajectory,
        );
        self.planner.yield_distance = ctx.yield_distance;
        self.planner.clear_distance = ctx.yield_distance + stop_before_m(&p) + clear_past_m(&p);

        let mut decision = Decision {
            cycle: self.cycle,
            scene_time_s: scene.time_s,
            logit_maneuver: self.choice.choice,
            p_logit: self.choice.p_logit,
            p_corrected: self.choice.p_corrected,
            ..Decision::default()
        };
        // Eq. 16: the advice is tried first; its safety check is a full planning run.
        let mut planned: Option<(Maneuver, Option<Candidate>, PlanStats)> = None;
        let (advised, verdict) = {
            let planner = &mut self.planner;
            let profiles = &self.choice.profiles;
            let cycle = self.cycle;
            advice::gate(advice, &self.requests, lane.turn, &p.advice, |m| {
                let (best, stats) = plan(planner, &profiles[m.index()], cycle, &p);
                planned = Some((m, best, stats));
                best.is_some()
            })
        };
        decision.advice = verdict;
        let mut executed: Option<(Maneuver, Candidate, PlanStats)> = None;
        if let (Some(m), Some((_, Some(best), stats))) = (advised, planned) {
            decision.source = DecisionSource::Advice;
            executed = Some((m, best, stats));
        }
        if executed.is_none() {
            // The logit choice, then "decelerate" unless that was the choice.
            let order = [self.choice.choice, Maneuver::Decelerate];
            let tries = if order[0] == order[1] { 1 } else { 2 };
            for m in order.into_iter().take(tries) {
                // Reuse the advice's safety check when it planned this maneuver already.
                let (best, stats) = match planned {
                    Some((pm, best, stats)) if pm == m => (best, stats),
                    _ => plan(
                        &mut self.planner,
                        &self.choice.profiles[m.index()],
                        self.cycle,
                        &p,
                    ),
                };
                decision.plan = stats;
                if let Some(best) = best {
                    executed = Some((m, best, stats));
                    break;
                }
            }
        }
        match executed {
            Some((m, best, stats)) => {
                decision.maneuver = m;
                decision.plan = stats;
                self.planner.render(&best, &lane, &mut decision.trajectory);
            }
            None => {
                decision.maneuver = Maneuver::Decelerate;
                decision.source = DecisionSource::MinimumRisk;
                decision.fallback = FallbackReason::NoFeasibleTrajectory;
                self.planner.minimum_risk(
                    ctx.yield_distance,
                    &lane,
                    &p.trajectory,
                    &mut decision.trajectory,
                );
                // Braking where the ego stands can be the worst choice inside a junction, in
                // the path of crossing traffic. When braking is predicted to be hit too, the
                // dynamically feasible plan holding or gaining speed that postpones the first
                // predicted contact longest is taken instead, if it does: it leaves the
                // others the most time to react.
                if let Some(mut latest) = self.planner.first_contact(&decision.trajectory) {
                    let n = p.trajectory.samples;
                    for m in [Maneuver::KeepSpeed, Maneuver::Accelerate] {
                        let profile = &self.choice.profiles[m.index()];
                        self.planner.sample(profile, n, self.cycle, &p.trajectory);
                        if let Some((c, t)) = self.planner.latest_contact(n, &p.trajectory) {
                            if t > latest {
                                latest = t;
                                decision.maneuver = m;
                                self.planner.render(&c, &lane, &mut decision.trajectory);
                            }
                        }
                    }
                }
            }
        }
        self.choices
            .record(scene.time_s, self.choice.state, decision.maneuver);
        self.last = decision;
        Ok(decision)
    }

    /// Minimum-risk decision for a stale scene: continue from where the last trajectory puts
    /// the ego `now − scene time` later, and brake. `None` before the first decision.
    pub fn stale_fallback(&mut self, now: f64) -> Option<Decision> {
        if !now.is_finite() {
            return None;
        }
        let q = self
            .last
            .trajectory
            .sample((now - self.last.scene_time_s).max(0.0))?;
        self.planner.start = FrenetState {
            s: q.s,
            ds: q.speed.max(0.0),
            dds: 0.0,
            l: q.l,
            dl: 0.0,
            ddl: 0.0,
        };
        let lane = *self.morph.lane(self.ego_lane);
        let stop = self.yield_distance_from(q.s);
        let mut d = Decision {
            cycle: self.last.cycle,
            scene_time_s: self.last.scene_time_s,
            maneuver: Maneuver::Decelerate,
            logit_maneuver: self.last.logit_maneuver,
            p_logit: self.last.p_logit,
            p_corrected: self.last.p_corrected,
            source: DecisionSource::MinimumRisk,
            advice: AdviceVerdict::NoAdvice,
            fallback: FallbackReason::StaleScene,
            ..Decision::default()
        };
        self.planner
            .minimum_risk(stop, &lane, &self.params.trajectory, &mut d.trajectory);
        Some(d)
    }

    fn ego_context(&self, lane: &Lane, start: &FrenetState) -> EgoContext {
        let p = &self.params;
        let v0 = start.ds.max(0.0);
        let look =
            v0 * p.choice.maneuver_horizon_s + v0 * v0 / (2.0 * p.choice.decelerate_mps2) + 10.0;
        EgoContext {
            speed: v0,
            accel: start.dds,
            speed_cap: curve_speed_cap(lane, start.s, look, &p.trajectory)
                .min(p.choice.desired_speed_mps),
            yield_distance: self.yield_distance_from(start.s),
            route: lane.turn,
            max_brake: p.trajectory.max_brake_mps2,
            min_duration: p.trajectory.min_duration_s,
            max_duration: p.trajectory.max_duration_s,
        }
    }

    /// Distance from arc length `s` to where a yielding ego stops: before the nearest conflict
    /// zone, not yet reached, that an agent is approaching, by the stop margin plus half a
    /// vehicle length. A stop point that would leave the car inside another crossing of its
    /// lane moves back before that crossing ("don't block the box"); when no such point is
    /// ahead, there is nothing to yield at (∞).
    fn yield_distance_from(&self, s: f64) -> f64 {
        let p = &self.params;
        let before = stop_before_m(p);
        let mut stop = self
            .conflicts
            .pairs()
            .iter()
            .filter(|c| c.agent_ttc_s < p.opm.ttc_max_s)
            .map(|c| c.ego_point_s - before)
            .filter(|stop| *stop > s)
            .fold(f64::INFINITY, f64::min);
        // Each crossing of the ego's lane occupies [point − before, point + before]; crossings
        // are few, so a fixed number of passes settles the stop point.
        for _ in 0..scene::MAX_CONFLICTS {
            let inside = self
                .morph
                .conflicts()
                .iter()
                .filter_map(
                    |c| match (c.lane_a == self.ego_lane, c.lane_b == self.ego_lane) {
                        (true, _) => Some(c.s_a),
                        (_, true) => Some(c.s_b),
                        _ => None,
                    },
                )
                .find(|point| (stop - point).abs() < before);
            match inside {
                Some(point) => stop = point - before,
                None => break,
            }
        }
        if stop > s {
            stop - s
        } else {
            f64::INFINITY
        }
    }

    /// Distance to clear the nearest conflict zone ahead, else the reference distance.
    fn goal_distance(&self) -> f64 {
        let p = &self.params;
        let exit = self
            .conflicts
            .pairs()
            .iter()
            .map(|c| c.ego_dist_m + clear_past_m(p))
            .filter(|d| *d > 1.0)
            .fold(f64::INFINITY, f64::min);
        if exit.is_finite() {
            exit
        } else {
            p.choice.reference_speed_mps * p.trajectory.t_ref_s
        }
    }
}

/// How far before a conflict point a yielding ego stops, m: half the conflict zone, the stop
/// margin and half the car.
fn stop_before_m(p: &Params) -> f64 {
    p.opm.conflict_zone_half_m + p.trajectory.stop_margin_m + 0.5 * p.trajectory.vehicle_length_m
}

/// How far past a conflict point the ego has cleared its zone, m: half the zone and the car.
fn clear_past_m(p: &Params) -> f64 {
    p.opm.conflict_zone_half_m + p.trajectory.vehicle_length_m
}

/// Samples around `profile` and runs the Monte Carlo search.
fn plan(
    planner: &mut Planner,
    profile: &Profile,
    cycle: u64,
    p: &Params,
) -> (Option<Candidate>, PlanStats) {
    let n = p.trajectory.samples;
    planner.sample(profile, n, cycle, &p.trajectory);
    let mut stats = PlanStats::default();
    let best = planner.run(n, &p.trajectory, &mut stats);
    (best, stats)
}

/// The ego's Frenet state on its lane; acceleration is clamped to the planning limits so that
/// every plan starts from a feasible state.
fn frenet_start(ego: &AgentState, lane: &Lane, p: &Params) -> FrenetState {
    let f = lane.project(ego.pos);
    let t = Vec2::from_angle(f.tangent);
    let n = Vec2::new(-t.y, t.x);
    let dir = ego.direction();
    let speed = ego.speed();
    let a_lon = ego
        .longitudinal_accel()
        .clamp(-p.trajectory.max_brake_mps2, p.trajectory.max_accel_mps2);
    FrenetState {
        s: f.s,
        ds: flush(speed * dir.dot(t)),
        dds: flush(a_lon * dir.dot(t)),
        l: flush(f.l),
        dl: flush(speed * dir.dot(n)),
        ddl: 0.0,
    }
}

/// Zero for |x| < 1e-9: a speed decaying towards a stop in closed loop would otherwise reach
/// subnormal numbers, which multiply the cost of every polynomial evaluation tenfold.
fn flush(x: f64) -> f64 {
    if x.abs() < 1e-9 {
        0.0
    } else {
        x
    }
}

/// Comfortable speed through the sharpest curve within `distance` m ahead of `s`:
/// √(a_lat,max / κ), at most the speed limit.
pub fn curve_speed_cap(lane: &Lane, s: f64, distance: f64, p: &params::TrajectoryParams) -> f64 {
    let mut k = lane.segment_at(s, 0);
    let mut kappa: f64 = lane.curvature_at(s, k);
    while k + 1 < lane.segments() && lane.s_at_vertex(k + 1) < s + distance {
        k += 1;
        kappa = kappa.max(lane.curvature_at(lane.s_at_vertex(k), k));
    }
    if kappa > 1e-9 {
        libm::sqrt(p.max_lateral_accel_mps2 / kappa).min(p.max_speed_mps)
    } else {
        p.max_speed_mps
    }
}
