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
pub mod intent;
pub mod negotiation;
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
use negotiation::{EhmiDisplay, Negotiation, Phase};
use opm::{ConflictPair, ConflictSet, OpmTriplet};
use saliency::Saliency;
use scene::{
    History, Lane, ProcessState, RightOfWay, SceneErrorKind, SceneField, Vec2, MAX_AGENTS,
};
use trajectory::{Candidate, Forecast, FrenetState, PlanStats, Planner};

/// Conflict points closer than this are one point for queueing, m.
const QUEUE_POINT_M: f64 = 0.5;
/// A road user more than this further from a shared conflict point than another is queued
/// behind it, m (less than a car length: they cannot be side by side in one lane).
const QUEUE_GAP_M: f64 = 4.0;

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
    /// A choice probability or a trajectory score was not a finite number: never read as a
    /// preference for the first maneuver.
    NotFinite = 3,
}
}

coded_enum! {
/// What the decision tells the other road users on the eHMI.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Announcement {
    /// "I am slowing down; please go ahead."
    #[default]
    GivingWay = 0,
    /// "I am going first; please wait."
    GoingFirst = 1,
}
}

/// One decision of the core.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Decision {
    /// Cycle number; it is also the id of the advice request a cycle issues.
    pub cycle: u64,
    /// Id of the newest advice request: `cycle` when this cycle issued one (at most every
    /// `advice.request_period_s`), else an earlier cycle's; 0 before the first.
    pub request_id: u64,
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
    /// What the eHMI announces: going first while a deadlock negotiation has announced it, or
    /// when the executed trajectory enters a conflicting road user's passage before that road
    /// user has left it; giving way when it passes behind every one or stays out; without a
    /// conflict ahead, giving way when the executed maneuver gives way, else going first. A
    /// change other than the negotiation's shows once it has held `announce_settle_s`.
    pub announce: Announcement,
    /// Phase of the deadlock negotiation.
    pub negotiation: Phase,
    /// Maneuvers refused this cycle because they would make another road user brake harder
    /// than `max_imposed_decel_mps2`.
    pub courtesy_rejects: u8,
    /// Lane the ego drove on: the scene's `ego_lane` (with a route across several junctions,
    /// the leg it was on).
    pub ego_lane: u8,
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
    negotiation: Negotiation,
    /// What the eHMI shows.
    display: EhmiDisplay,
    /// Probability that the other of each conflict pair lets the ego go first.
    yields: [f64; MAX_AGENTS],
    forecasts: [Forecast; MAX_AGENTS],
    /// Request id of the last advice the gate judged (0: none).
    last_advice_id: u64,
}

impl DecisionCore {
    /// A core for `morph` with validated `params`; the conflict zones are derived for the
    /// core's footprint.
    pub fn new(params: Params, mut morph: Morphology) -> Result<Self, ParamError> {
        params.validate()?;
        morph.fit_footprint(
            params.trajectory.vehicle_length_m,
            params.trajectory.vehicle_width_m,
        );
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
            negotiation: Negotiation::default(),
            display: EhmiDisplay::default(),
            yields: [0.0; MAX_AGENTS],
            forecasts: [Forecast::default(); MAX_AGENTS],
            last_advice_id: 0,
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
    /// The planner's forecast of every agent's motion in the last step, in scene order.
    pub fn forecasts(&self) -> &[Forecast; MAX_AGENTS] {
        &self.forecasts
    }
    /// The deadlock negotiation after the last step.
    pub fn negotiation(&self) -> &Negotiation {
        &self.negotiation
    }
    /// Probability that the other of each of [`DecisionCore::conflicts`] lets the ego go first,
    /// in the same order.
    pub fn yields(&self) -> &[f64] {
        &self.yields[..self.conflicts.pairs().len()]
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
            self.negotiation = Negotiation::default();
            self.display = EhmiDisplay::default();
        }
        self.last_scene_time_s = scene.time_s;
        self.cycle += 1;
        self.ego_lane = scene.ego_lane;
        let p = self.params;
        if self.requests.due(now, p.advice.request_period_s) {
            self.requests.issue(self.cycle, now);
        }

        self.history.record(scene.time_s, scene.agents());
        for (i, a) in scene.agents().iter().enumerate() {
            self.processes[i] = ProcessState::of(a, &self.morph, p.opm.lane_match_heading_rad);
        }
        let lane = *self.morph.lane(scene.ego_lane);
        let start = frenet_start(&scene.ego, &lane, &p);
        opm::build(
            scene,
            &self.morph,
            &p.opm,
            &p.interaction,
            p.ego_comfort_stop_m(start.ds, start.dds),
            &self.processes,
            &self.history,
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

        let agents = scene.agents();
        self.negotiation.update(
            self.conflicts.pairs(),
            |k| agents[k as usize].id,
            &negotiation::EgoState {
                speed_mps: start.ds.max(0.0),
                accel_mps2: p.choice.accelerate_mps2,
                gives_way: self.last.maneuver.gives_way(),
            },
            scene.time_s,
            &p.interaction,
        );
        self.expect(agents, scene.time_s);
        let (yield_distance, clear_distance, every_lane) =
            self.yield_point(start.s, start.ds.max(0.0), start.dds);
        let ctx = self.ego_context(&lane, &start, yield_distance);
        choice::choose(
            &self.triplet,
            &self.conflicts,
            &self.yields[..self.conflicts.pairs().len()],
            &ctx,
            &self.choices,
            &p.opm,
            &p.interaction,
            &p.choice,
            &mut self.choice,
        );

        self.planner.prepare(
            scene.ego_lane,
            start,
            ctx.goal_distance,
            agents,
            &self.processes,
            &self.forecasts,
            &self.morph,
            &p.trajectory,
        );
        self.planner.yield_distance = yield_distance;
        self.planner.clear_distance = clear_distance;
        if !every_lane {
            // No waiting point outside every zone is left: the planner may stand where the
            // yield point does, in zones of lanes without traffic.
            self.planner.keep_zones(
                self.conflicts
                    .pairs()
                    .iter()
                    .map(|c| [start.s + c.ego_zone_m[0], start.s + c.ego_zone_m[1]]),
            );
        }

        let mut decision = Decision {
            cycle: self.cycle,
            request_id: self.requests.latest(),
            scene_time_s: scene.time_s,
            logit_maneuver: self.choice.choice,
            p_logit: self.choice.p_logit,
            p_corrected: self.choice.p_corrected,
            negotiation: self.negotiation.phase,
            courtesy_rejects: self.choice.courtesy_rejected.iter().filter(|r| **r).count() as u8,
            ego_lane: scene.ego_lane,
            ..Decision::default()
        };
        // Eq. 16: the advice is tried first; its safety check is a full planning run. An
        // advice applies until its request's deadline, and at least at the first cycle that
        // judges it.
        let first_look = advice.is_some_and(|a| a.request_id != self.last_advice_id);
        if let Some(a) = advice {
            self.last_advice_id = a.request_id;
        }
        let mut planned: Option<(Maneuver, Option<Candidate>, PlanStats)> = None;
        let (advised, verdict) = {
            let planner = &mut self.planner;
            let profiles = &self.choice.profiles;
            let cycle = self.cycle;
            advice::gate(
                advice,
                &advice::GateContext {
                    log: &self.requests,
                    route: lane.turn,
                    now,
                    first_look,
                    p_corrected: &self.choice.p_corrected,
                },
                &p.advice,
                |m| {
                    let (best, stats) = plan(
                        planner,
                        &profiles[m.index()],
                        cycle,
                        p.trajectory.samples,
                        &p,
                    );
                    planned = Some((m, best, stats));
                    best.is_some()
                },
            )
        };
        decision.advice = verdict;
        let mut executed: Option<(Maneuver, Candidate, PlanStats)> = None;
        if let (Some(m), Some((_, Some(best), stats))) = (advised, planned) {
            decision.source = DecisionSource::Advice;
            executed = Some((m, best, stats));
        }
        // The softmax maps NaN utilities to uniform probabilities: check the utilities.
        let c = &self.choice;
        let mut finite = [c.utility, c.utility_corrected, c.p_logit, c.p_corrected]
            .iter()
            .flatten()
            .all(|v| v.is_finite());
        if executed.is_none() && finite {
            // The logit choice, then "decelerate", then the others by corrected probability
            // with `fallback_samples`: every executed plan passed the same limit, collision
            // and margin checks.
            let pc = self.choice.p_corrected;
            let mut by_probability = Maneuver::ALL;
            by_probability.sort_unstable_by(|a, b| {
                pc[b.index()]
                    .total_cmp(&pc[a.index()])
                    .then(a.index().cmp(&b.index()))
            });
            // A maneuver whose profile equals one already tried draws the same samples and
            // fails the same way: it is skipped.
            let mut tried = [false; choice::MANEUVERS];
            let order = [self.choice.choice, Maneuver::Decelerate]
                .into_iter()
                .chain(by_probability);
            for (k, m) in order.enumerate() {
                let profile = self.choice.profiles[m.index()];
                if Maneuver::ALL
                    .iter()
                    .any(|o| tried[o.index()] && self.choice.profiles[o.index()] == profile)
                {
                    continue;
                }
                tried[m.index()] = true;
                // Reuse the advice's safety check when it planned this maneuver already.
                let (best, stats) = match planned {
                    Some((pm, best, stats)) if pm == m => (best, stats),
                    _ => plan(
                        &mut self.planner,
                        &profile,
                        self.cycle,
                        if k < 2 {
                            p.trajectory.samples
                        } else {
                            p.trajectory.later_samples()
                        },
                        &p,
                    ),
                };
                decision.plan = stats;
                finite &= stats.score_rejects == 0;
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
                let stop = ctx.yield_distance.min(self.leader_stop_distance());
                decision.fallback = if finite {
                    FallbackReason::NoFeasibleTrajectory
                } else {
                    FallbackReason::NotFinite
                };
                self.minimum_risk(stop, &lane, &mut decision)
            }
        }
        let negotiated = self.negotiation.announces();
        let meant = if negotiated {
            Announcement::GoingFirst
        } else {
            self.order(&decision.trajectory)
                .unwrap_or(if decision.maneuver.gives_way() {
                    Announcement::GivingWay
                } else {
                    Announcement::GoingFirst
                })
        };
        decision.announce =
            self.display
                .show(meant, scene.time_s, negotiated, &self.params.interaction);
        self.choices
            .record(scene.time_s, self.choice.state, decision.maneuver);
        self.last = decision;
        Ok(decision)
    }

    /// What `trajectory` means for the road users in conflict with the ego: it goes first when
    /// it enters some one's passage of the conflict zone before that road user, proceeding, has
    /// left it (at its latest, [`choice::proceeding_interval`]); it gives way when it passes
    /// behind every one of them or stays out of their passages within the horizon. The eHMI
    /// speaks to everyone: while the plan passes behind a road user that could stop only
    /// braking harder than `request_decel_mps2` ([`negotiation::asked_hard`]), "going first"
    /// meant for another would ask that one to brake hard, so the plan gives way. `None`
    /// without a conflict still ahead of both.
    fn order(&self, trajectory: &trajectory::Trajectory) -> Option<Announcement> {
        let points = trajectory.points();
        let s0 = points.first()?.s;
        let ip = &self.params.interaction;
        let (mut ahead, mut first, mut misread) = (false, false, false);
        for c in self.conflicts.pairs() {
            if c.ego_pass_m[1] <= 0.0 || c.agent_pass_m[1] <= 0.0 {
                continue;
            }
            ahead = true;
            let enters = points
                .iter()
                .find(|q| q.s - s0 >= c.ego_pass_m[0])
                .map(|q| q.t);
            let (_, other_leaves) = choice::proceeding_interval(c, ip);
            if enters.is_some_and(|t| t < other_leaves) {
                first = true;
            } else {
                misread |= negotiation::asked_hard(c, ip);
            }
        }
        if first && !misread {
            Some(Announcement::GoingFirst)
        } else {
            ahead.then_some(Announcement::GivingWay)
        }
    }

    /// Distance, m, to where an ego at `v0` m/s stops behind its car-following leader should
    /// the leader stop as forecast ([`Forecast::stop_distance`]): the centre gap less a car
    /// length and `stop_margin_m`, plus the leader's stopping distance. ∞ without a leader or
    /// when that point is beyond one stopping polynomial (half of `v0 · max_duration_s`):
    /// "decelerate" stops there ([`choice::profile`]).
    fn leader_stop(&self, v0: f64) -> f64 {
        let t = &self.params.trajectory;
        self.triplet.leader.map_or(f64::INFINITY, |l| {
            let d = l.gap_m - t.vehicle_length_m - t.stop_margin_m
                + self.forecasts[l.agent as usize].stop_distance(l.speed_mps);
            if 2.0 * d <= v0 * t.max_duration_s {
                d.max(0.0)
            } else {
                f64::INFINITY
            }
        })
    }

    /// Distance, m, within which the ego must stop behind its car-following leader should the
    /// leader brake at `emergency_brake_mps2` from now: the centre gap less a car length and
    /// `stop_margin_m`, plus the leader's own stopping distance (∞ without a leader): where the
    /// minimum-risk fallback stops at the latest, with the yield point.
    pub fn leader_stop_distance(&self) -> f64 {
        let t = &self.params.trajectory;
        self.triplet.leader.map_or(f64::INFINITY, |l| {
            l.gap_m - t.vehicle_length_m - t.stop_margin_m
                + l.speed_mps * l.speed_mps / (2.0 * t.emergency_brake_mps2)
        })
    }

    /// The minimum-risk fallback into `decision` ([`Planner::fallback`]), driving on, if at
    /// all, as "keep speed" or "accelerate" would.
    fn minimum_risk(&mut self, stop_distance: f64, lane: &Lane, decision: &mut Decision) {
        decision.source = DecisionSource::MinimumRisk;
        let drive_on = [Maneuver::KeepSpeed, Maneuver::Accelerate];
        let profiles = drive_on.map(|m| self.choice.profiles[m.index()]);
        decision.maneuver = self
            .planner
            .fallback(
                stop_distance,
                lane,
                &profiles,
                self.cycle,
                &self.params.trajectory,
                &mut decision.trajectory,
            )
            .map_or(Maneuver::Decelerate, |k| drive_on[k]);
    }

    /// Expectations about every conflicting road user: the probability that it lets the ego
    /// go first, and the planner's forecast of its motion. It counts as yielding for sure
    /// when it kept waiting after the ego announced it goes first, or when the ego has the
    /// right of way and it can still stop comfortably; otherwise its implicit intent says,
    /// weighted by `priority_yield_weight` when it has the right of way over the ego. One
    /// queued behind another at the same conflict point yields at least as surely as that one.
    /// The planner forecasts a stop before its zone when it yields with at least
    /// `trust_yield` and needs no more than `max_imposed_decel_mps2` for it (courtesy: the
    /// ego does not count on harder braking); otherwise it drives on at the acceleration its
    /// motion shows: a conflicting road user's as its implicit intent reads it, any other's
    /// (a leader's) as [`intent::current_accel`] gives it, its speed trend when the source
    /// reports no acceleration.
    fn expect(&mut self, agents: &[scene::AgentState], now: f64) {
        let ip = &self.params.interaction;
        for (j, a) in agents.iter().enumerate() {
            self.forecasts[j] = Forecast {
                accel: intent::current_accel(a, self.history.track(a.id), now),
                ..Forecast::default()
            };
        }
        let pairs = self.conflicts.pairs();
        for (k, c) in pairs.iter().enumerate() {
            let id = agents[c.agent as usize].id;
            self.yields[k] = if self.negotiation.yielded(id)
                || (c.right_of_way == RightOfWay::A && !c.intent.committed)
            {
                1.0
            } else if c.right_of_way == RightOfWay::B {
                c.intent.yielding * ip.priority_yield_weight
            } else {
                c.intent.yielding
            };
        }
        // A road user queued behind another at the same conflict point, both before the zone,
        // cannot enter before the one ahead: it yields at least as surely.
        for (k, c) in pairs.iter().enumerate() {
            if c.agent_zone_m[0] <= 0.0 {
                continue;
            }
            let ahead = pairs
                .iter()
                .enumerate()
                .filter(|(_, m)| {
                    m.agent != c.agent
                        && m.point.minus(c.point).norm() < QUEUE_POINT_M
                        && m.agent_zone_m[0] > 0.0
                        && c.agent_dist_m - m.agent_dist_m > QUEUE_GAP_M
                })
                .map(|(j, _)| self.yields[j])
                .fold(0.0, f64::max);
            self.yields[k] = self.yields[k].max(ahead);
        }
        for (k, c) in pairs.iter().enumerate() {
            let y = self.yields[k];
            let f = &mut self.forecasts[c.agent as usize];
            f.accel = c.agent_accel_mps2;
            f.pet_s = [ip.pet_behind_s, ip.pet_go_s];
            f.pass_m = c.agent_pass_m;
            f.ego_pass_m = c.ego_pass_m;
            if y >= ip.trust_yield
                && !c.intent.committed
                && c.intent.required_decel_mps2 <= ip.max_imposed_decel_mps2
            {
                f.stop_in_m = (c.agent_zone_m[0] - self.params.trajectory.stop_margin_m).max(0.0);
            }
        }
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
        let stop = self.yield_point(q.s, q.speed.max(0.0), q.accel).0;
        let mut d = Decision {
            cycle: self.last.cycle,
            request_id: self.last.request_id,
            ego_lane: self.ego_lane,
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

    fn ego_context(&self, lane: &Lane, start: &FrenetState, yield_distance: f64) -> EgoContext {
        let p = &self.params;
        let v0 = start.ds.max(0.0);
        let look =
            v0 * p.choice.maneuver_horizon_s + v0 * v0 / (2.0 * p.choice.decelerate_mps2) + 10.0;
        EgoContext {
            speed: v0,
            accel: start.dds,
            speed_cap: curve_speed_cap(lane, start.s, look, &p.trajectory)
                .min(p.choice.desired_speed_mps),
            yield_distance,
            leader_stop_m: self.leader_stop(v0),
            goal_distance: self.goal_distance(),
            route: lane.turn,
            max_brake: p.trajectory.max_brake_mps2,
            min_duration: p.trajectory.min_duration_s,
            max_duration: p.trajectory.max_duration_s,
            yield_check_s: p.trajectory.yield_check_s,
        }
    }

    /// Where a yielding ego at arc length `s`, speed `v` and acceleration `a` stops, and past
    /// where it has cleared what it yields to, as distances from `s` (both ∞ when there is
    /// nothing to yield at), and whether the stop point is outside every zone of its lane
    /// (else only outside those of lanes with traffic). It stops the stop margin before the
    /// nearest conflict zone ahead whose road user is arriving (TTC below the cap) and that it
    /// can still stop before comfortably ([`Params::ego_comfort_stop_m`]); a zone it can no
    /// longer stop before is one it clears. A stop
    /// point that would leave the footprint inside, or within the margin of, another conflict
    /// zone of its lane moves back before that zone ("don't block the box"). When the ego is
    /// already past every such point, only the zones of lanes with traffic count (it stops
    /// where it blocks nobody now); when that is past stopping too, there is no point to yield
    /// at. It has cleared once past that conflict zone and every zone of its lane that begins
    /// before that zone ends. An ego within the margin past a stop point stops where it is.
    fn yield_point(&self, s: f64, v: f64, a: f64) -> (f64, f64, bool) {
        let p = &self.params;
        let margin = p.trajectory.stop_margin_m;
        let reach = p.ego_comfort_stop_m(v, a);
        // A stop point up to the margin behind the ego still keeps it out of the zone: it stops
        // where it is (a creep that overshot a point by a centimetre must not turn into
        // clearing the junction).
        let stoppable = |stop: f64| stop + margin - s >= reach && stop + margin > s;
        let (mut stop, mut clear) = self
            .conflicts
            .pairs()
            .iter()
            .filter(|c| c.agent_ttc_s < p.opm.ttc_max_s)
            .map(|c| (s + c.ego_zone_m[0] - margin, s + c.ego_zone_m[1]))
            .filter(|&(stop, _)| stoppable(stop))
            .fold((f64::INFINITY, f64::INFINITY), |a, b| {
                if b.0 < a.0 {
                    b
                } else {
                    a
                }
            });
        // Zones are few, so a fixed number of passes settles the stop point: first against
        // every zone of the lane; when the ego is already too far into the junction for that,
        // against the zones of the lanes that have traffic now.
        let settle = |mut stop: f64, every_lane: bool| {
            for _ in 0..scene::MAX_CONFLICTS {
                let blocks = |z: &[f64; 2]| stop > z[0] - margin && stop < z[1];
                let inside = if every_lane {
                    self.morph.zones_on(self.ego_lane).find(blocks)
                } else {
                    self.conflicts
                        .pairs()
                        .iter()
                        .map(|c| [s + c.ego_zone_m[0], s + c.ego_zone_m[1]])
                        .find(blocks)
                };
                let Some(z) = inside else {
                    break;
                };
                stop = if stoppable(z[0] - margin) {
                    z[0] - margin
                } else {
                    f64::INFINITY
                };
            }
            stop
        };
        let first = settle(stop, true);
        let every_lane = first.is_finite() || !stop.is_finite();
        stop = if every_lane {
            first
        } else {
            settle(stop, false)
        };
        if !stop.is_finite() {
            return (f64::INFINITY, f64::INFINITY, true);
        }
        // Zones beginning before it has cleared extend what it must clear.
        loop {
            let further = self
                .morph
                .zones_on(self.ego_lane)
                .filter(|z| z[0] >= stop && z[0] < clear)
                .fold(clear, |c, z| c.max(z[1]));
            if further <= clear {
                break;
            }
            clear = further;
        }
        ((stop - s).max(0.0), clear - s, every_lane)
    }

    /// Distance through the nearest conflict zone ahead that a road user is in conflict
    /// with, else the reference distance.
    fn goal_distance(&self) -> f64 {
        let p = &self.params;
        let exit = self
            .conflicts
            .pairs()
            .iter()
            .map(|c: &ConflictPair| c.ego_zone_m[1])
            .filter(|d| *d > 1.0)
            .fold(f64::INFINITY, f64::min);
        if exit.is_finite() {
            exit
        } else {
            p.choice.reference_speed_mps * p.trajectory.t_ref_s
        }
    }
}

/// Samples `n` candidates around `profile` and runs the Monte Carlo search.
fn plan(
    planner: &mut Planner,
    profile: &Profile,
    cycle: u64,
    n: usize,
    p: &Params,
) -> (Option<Candidate>, PlanStats) {
    planner.sample(profile, n, cycle, &p.trajectory);
    let mut stats = PlanStats::default();
    let best = planner.run(n, &p.trajectory, &mut stats);
    (best, stats)
}

/// The ego's Frenet state on its lane; acceleration is clamped to the planning limits so that
/// every plan starts from a feasible state: braking is at most what the jerk limit can release
/// before the speed reaches zero, √(2·j_max·v) (a standing car does not decelerate).
fn frenet_start(ego: &AgentState, lane: &Lane, p: &Params) -> FrenetState {
    let f = lane.project(ego.pos);
    let t = Vec2::from_angle(f.tangent);
    let n = Vec2::new(-t.y, t.x);
    let dir = ego.direction();
    let speed = ego.speed();
    let ds = flush(speed * dir.dot(t));
    // A braking ego near a stop is planned from a deceleration it can release in time: within
    // the jerk limit, and such that a quartic stop of the shortest duration still ends at a
    // standstill without reversing (it decelerates monotonically only for T ≤ 3 v / |a|).
    let releasable = libm::sqrt(2.0 * p.trajectory.max_jerk_mps3 * ds.max(0.0))
        .min(3.0 * ds.max(0.0) / p.trajectory.min_duration_s);
    let a_lon = (ego.longitudinal_accel() * dir.dot(t)).clamp(
        -p.trajectory.max_brake_mps2.min(releasable),
        p.trajectory.max_accel_mps2,
    );
    FrenetState {
        s: f.s,
        ds,
        dds: flush(a_lon),
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

#[cfg(test)]
mod tests {
    use super::*;
    use scene::{AgentState, Lane, Turn, Vec2};

    /// The paper's left turn from (40, 5) and the straight lane it crosses (the map
    /// `deploy/maps/paper.toml` has them as lanes 0 and 1).
    fn left_turn_across_a_lane() -> Morphology {
        let left = Lane::builder(Vec2::new(40.0, 5.0))
            .line_to(Vec2::new(5.0, 5.0))
            .arc(Vec2::new(5.0, -5.0), core::f64::consts::FRAC_PI_2, 1.0)
            .line_to(Vec2::new(-5.0, -40.0))
            .build(2.5, 30.0, Turn::Left)
            .unwrap();
        let straight = Lane::new(
            &[Vec2::new(-40.0, -5.0), Vec2::new(40.0, -5.0)],
            2.5,
            30.0,
            Turn::Straight,
        )
        .unwrap()
        .with_priority(3);
        Morphology::new(&[left, straight]).unwrap()
    }

    /// A NaN that gets past validation (here: parameters set behind `validate`'s back) ends in
    /// the minimum-risk fallback with its own reason, never in the first maneuver.
    #[test]
    fn a_non_finite_choice_or_score_ends_in_the_minimum_risk_fallback() {
        let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), core::f64::consts::PI, 8.0);
        let mut scene = Scene::new(0.0, ego, 0);
        scene.push(AgentState::moving(1, Vec2::new(-40.0, -5.0), 0.0, 8.0));
        let fresh = || DecisionCore::new(Params::default(), left_turn_across_a_lane()).unwrap();
        let good = fresh().step(&scene, 0.0, None).unwrap();
        assert_eq!(good.fallback, FallbackReason::None);
        let breaks: [fn(&mut Params); 2] = [
            |p| p.choice.beta[2] = f64::NAN,
            |p| p.trajectory.j_max_norm = 0.0,
        ];
        for (k, set) in breaks.iter().enumerate() {
            let mut core = fresh();
            set(&mut core.params);
            let d = core.step(&scene, 0.0, None).unwrap();
            assert_eq!(d.fallback, FallbackReason::NotFinite, "break {k}");
            assert_eq!(d.source, DecisionSource::MinimumRisk, "break {k}");
            assert_ne!(d.maneuver, Maneuver::Accelerate, "break {k}");
        }
    }
}
