//! Every threshold and weight of the core, with units and defaults. Callers load it from TOML
//! (`#[serde(default, deny_unknown_fields)]`: a missing key takes its default, an unknown key is
//! an error); the core itself does no I/O.

use crate::saliency::{FEATURES, FITTED_KEY};
use crate::scene::InputLimits;
use crate::trajectory::{MAX_SAMPLES, MAX_STEPS, MAX_SWEEP_STEPS};

/// All parameters of the decision core.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub limits: InputLimits,
    pub opm: OpmParams,
    pub saliency: SaliencyParams,
    pub choice: ChoiceParams,
    pub interaction: InteractionParams,
    pub advice: AdviceParams,
    pub trajectory: TrajectoryParams,
}

/// Object selection and conflict assessment (eq. 4–6).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct OpmParams {
    /// ΔT_th: a conflict with |ΔTTC| below this is risky and selects the agent, s.
    pub delta_ttc_threshold_s: f64,
    /// d_th: agents closer than this along the ego's lane centre line are selected, m.
    pub proximity_threshold_m: f64,
    /// Speed floor in TTC = d / max(v, floor) (guard of eq. 4 near standstill), m/s.
    pub ttc_speed_floor_mps: f64,
    /// TTC cap; a TTC at the cap means "not arriving", s.
    pub ttc_max_s: f64,
    /// Half-length of the conflict zone around a conflict point, m.
    pub conflict_zone_half_m: f64,
    /// Largest heading error for matching an agent to a lane, rad.
    pub lane_match_heading_rad: f64,
    /// An intent counts only at or above this confidence (weak intents are ignored, §4.3).
    pub intent_confidence_min: f64,
}

impl Default for OpmParams {
    fn default() -> Self {
        Self {
            delta_ttc_threshold_s: 4.0,
            proximity_threshold_m: 30.0,
            ttc_speed_floor_mps: 0.5,
            ttc_max_s: 30.0,
            conflict_zone_half_m: 4.0,
            lane_match_heading_rad: 1.0,
            intent_confidence_min: 0.7,
        }
    }
}

/// Saliency attention (eq. 7).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct SaliencyParams {
    /// Key vector K, one weight per query feature (see `saliency::FEATURE_NAMES`).
    pub key: [f64; FEATURES],
}

impl Default for SaliencyParams {
    fn default() -> Self {
        Self { key: FITTED_KEY }
    }
}

/// Maneuver utility, logit and its correction (eq. 9–15).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChoiceParams {
    /// β for x = [matching, safety, efficiency] (eq. 9).
    pub beta: [f64; 3],
    /// γ, weight of history consistency D_prev (eq. 12).
    pub gamma: f64,
    /// λ, switch penalty (eq. 14).
    pub lambda: f64,
    /// Penalty on a turn against the navigation instruction (matching degree).
    pub navigation_penalty: f64,
    /// Penalty on waiting or slowing without a reason (matching degree): a maneuver that stops
    /// the ego, keeps it standing or creeping (below `interaction.creep_speed_mps`), yields,
    /// or slows it more than 0.5 m/s below the lowest of its speed, the desired speed and the
    /// speed cap, when no leader holds it back and nothing requires it: no conflict to yield
    /// to, or every conflicting road user lets it go (speeding up or taking the route's turn
    /// is free of risk and imposes nothing). Without it the history terms of eq. 12–14 (γ + λ)
    /// keep the ego in "decelerate", or in "keep speed" at a crawl, once the reason to wait is
    /// gone.
    pub idle_penalty: f64,
    /// Gain of the IDM car-following penalty, per m/s² of excess acceleration.
    pub idm_penalty_gain: f64,
    /// Nominal acceleration of "accelerate", m/s².
    pub accelerate_mps2: f64,
    /// Nominal deceleration of "decelerate", m/s² (positive).
    pub decelerate_mps2: f64,
    /// Horizon over which a maneuver reaches its target speed, s.
    pub maneuver_horizon_s: f64,
    /// Reference speed for the efficiency degree, m/s.
    pub reference_speed_mps: f64,
    /// Desired (free-road) speed, m/s; the speed cap of every maneuver.
    pub desired_speed_mps: f64,
    /// IDM: time headway T, s.
    pub idm_headway_s: f64,
    /// IDM: standstill gap s0, m.
    pub idm_min_gap_m: f64,
    /// IDM: comfortable deceleration b, m/s².
    pub idm_comfort_decel_mps2: f64,
    /// IDM: maximum acceleration a, m/s².
    pub idm_max_accel_mps2: f64,
    /// Safety preference gains [aggressive, balanced, conservative] of the ego's style.
    pub ego_style_safety: [f64; 3],
    /// Efficiency preference gains [aggressive, balanced, conservative] of the ego's style.
    pub ego_style_efficiency: [f64; 3],
    /// Efficiency gains [commute, emergency, official, leisure] of the ego's task.
    pub ego_task_efficiency: [f64; 4],
    /// Efficiency gain when the passenger asks to accelerate or proceed.
    pub ego_hurry_efficiency: f64,
    /// Safety gains [commute, emergency, official, leisure] of an interacting agent's task.
    pub other_task_safety: [f64; 4],
    /// Safety gain when an interacting agent is aggressive.
    pub other_aggressive_safety: f64,
    /// Safety gain when an interacting agent announces it proceeds or accelerates.
    pub other_proceeds_safety: f64,
    /// Efficiency gain when an interacting agent announces it yields or stops.
    pub other_yields_efficiency: f64,
    /// Safety gain per risky conflict (scene conflict intensity).
    pub conflict_intensity_safety: f64,
}

impl Default for ChoiceParams {
    fn default() -> Self {
        Self {
            beta: [1.0, 4.0, 2.0],
            gamma: 0.5,
            lambda: 0.5,
            navigation_penalty: 5.0,
            idle_penalty: 1.0,
            idm_penalty_gain: 1.0,
            accelerate_mps2: 1.5,
            decelerate_mps2: 2.0,
            maneuver_horizon_s: 3.0,
            reference_speed_mps: 10.0,
            desired_speed_mps: 13.9,
            idm_headway_s: 1.5,
            idm_min_gap_m: 2.0,
            idm_comfort_decel_mps2: 2.0,
            idm_max_accel_mps2: 1.5,
            // Priority task > action > style (§4.1): task gains are the largest.
            ego_style_safety: [-0.2, 0.0, 0.2],
            ego_style_efficiency: [0.2, 0.0, -0.2],
            ego_task_efficiency: [0.0, 0.8, 0.5, -0.2],
            ego_hurry_efficiency: 0.4,
            other_task_safety: [0.0, 1.0, 0.6, 0.0],
            other_aggressive_safety: 0.2,
            other_proceeds_safety: 0.4,
            other_yields_efficiency: 0.4,
            conflict_intensity_safety: 0.1,
        }
    }
}

/// Interaction with the road users the ego conflicts with: implicit intents, post-encroachment
/// margins, right of way, courtesy and deadlock negotiation (`intent`, `choice`, the core's
/// negotiation).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct InteractionParams {
    /// Below this speed a road user stands still, m/s.
    pub standing_speed_mps: f64,
    /// Deceleration a road user (and the ego) can brake comfortably at, m/s²: one that would
    /// need more to stop before its conflict zone is committed.
    pub comfort_decel_mps2: f64,
    /// Yield probability of a road user standing still before its conflict zone.
    pub standing_yield: f64,
    /// Acceleration of a road user that proceeds from its current state, m/s² (the earliest
    /// it may arrive: its current acceleration if higher).
    pub proceed_accel_mps2: f64,
    /// Slowest speed at which a proceeding road user crosses, m/s (its latest exit).
    pub proceed_min_speed_mps: f64,
    /// Fastest a proceeding road user accelerates to, m/s (its earliest entry; its current
    /// speed if higher): the road's speed limit.
    pub proceed_top_speed_mps: f64,
    /// Post-encroachment margin the ego needs to go first, before another road user's
    /// proceeding occupancy of the conflict zone, s.
    pub pet_go_s: f64,
    /// Margin the ego needs to pass behind another road user that will have left, s.
    pub pet_behind_s: f64,
    /// A plan that would make another road user brake harder than this to keep `pet_behind_s`
    /// behind the ego is not taken, m/s².
    pub max_imposed_decel_mps2: f64,
    /// Time another road user takes to react to the ego before braking, s.
    pub reaction_s: f64,
    /// Yield probability from which the planner predicts a road user stopping before its zone
    /// instead of driving on.
    pub trust_yield: f64,
    /// Weight in [0, 1] of the implicit yield evidence of a road user with the right of way
    /// over the ego: its yield probability from motion and words is scaled by it. 1 reads its
    /// motion as anyone's; 0 never expects it to give up its right of way unless it kept
    /// waiting after the ego announced it goes first (traffic that never yields to a car
    /// without priority, and brakes only for others).
    pub priority_yield_weight: f64,
    /// Waiting for a road user that itself waits is expected to last this long, s (the cost
    /// of a deadlock in the efficiency degree).
    pub deadlock_wait_s: f64,
    /// Both the ego and another road user below this speed before their zones: waiting or
    /// creeping, m/s.
    pub creep_speed_mps: f64,
    /// Both waiting this long: the ego announces on the eHMI that it goes first, s.
    pub deadlock_after_s: f64,
    /// After announcing, the ego watches the other for this long (a reaction time) and goes if
    /// it keeps waiting, s.
    pub watch_s: f64,
    /// A waiting ego asks an approaching road user to let it go first (announces on the eHMI
    /// that it goes first) only when that road user could stop before its zone at this
    /// deceleration or less after `reaction_s`, and no other still could stop but only
    /// harder, m/s². Well below `max_imposed_decel_mps2`, since drivers brake earlier and
    /// harder than the kinematic minimum. 0 never asks (traffic that does not read the eHMI).
    pub request_decel_mps2: f64,
    /// A change in what the plan means for the others ("going first", "please go ahead") is
    /// shown on the eHMI once it has held this long, s; the negotiation's announcement is
    /// shown at once ([`crate::negotiation::EhmiDisplay`]). About a glance: long enough that one
    /// cycle's sample does not flash a message, short against a driver's reaction time.
    pub announce_settle_s: f64,
    /// Utility penalty of a maneuver rejected for courtesy (kept finite so the logit stays
    /// defined; large enough that it is never chosen over one that is not rejected).
    pub courtesy_penalty: f64,
    /// How the courtesy rule expects another road user to brake for an ego that goes first.
    pub follower: Follower,
    /// The IDM of [`Follower::Idm`] (its desired speed is `proceed_top_speed_mps`): minimum
    /// gap s₀ from its front to the ego's passage, m; time headway T, s; maximum
    /// acceleration a and comfortable deceleration b, m/s².
    pub follower_min_gap_m: f64,
    pub follower_headway_s: f64,
    pub follower_max_accel_mps2: f64,
    pub follower_comfort_decel_mps2: f64,
}

/// The courtesy rule's model of the braking of a road user the ego goes first in front of
/// ([`crate::choice::imposed_decel`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Follower {
    /// It reads the ego's intent early: after `reaction_s` it brakes at the least constant
    /// deceleration that keeps `pet_behind_s` behind the ego's passage.
    #[default]
    Kinematic,
    /// It brakes only for a car on its path, as for its IDM leader (`follower_*`): from the
    /// moment the ego enters its passage until it leaves it (traffic such as highway-env's).
    Idm,
}

impl InteractionParams {
    /// Distance to stop from `v` m/s braking at `comfort_decel_mps2`, m: nearer than that, a
    /// road user can no longer stop comfortably (it is committed).
    pub fn comfort_stop_m(&self, v: f64) -> f64 {
        v * v / (2.0 * self.comfort_decel_mps2)
    }
}

impl Default for InteractionParams {
    fn default() -> Self {
        Self {
            standing_speed_mps: 0.5,
            comfort_decel_mps2: 3.0,
            standing_yield: 0.7,
            proceed_accel_mps2: 1.5,
            proceed_min_speed_mps: 2.0,
            proceed_top_speed_mps: 14.0,
            pet_go_s: 2.0,
            pet_behind_s: 1.8,
            max_imposed_decel_mps2: 3.0,
            reaction_s: 0.5,
            trust_yield: 0.8,
            priority_yield_weight: 1.0,
            deadlock_wait_s: 5.0,
            creep_speed_mps: 1.0,
            deadlock_after_s: 0.5,
            watch_s: 1.0,
            request_decel_mps2: 1.5,
            announce_settle_s: 0.3,
            courtesy_penalty: 10.0,
            follower: Follower::Kinematic,
            // Treiber & Kesting's IDM calibrations, as the simulator's balanced driver.
            follower_min_gap_m: 2.0,
            follower_headway_s: 1.5,
            follower_max_accel_mps2: 1.5,
            follower_comfort_decel_mps2: 2.0,
        }
    }
}

/// The gate on the LLM's A_final (eq. 16).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdviceParams {
    /// Period of advice requests, s: a decision issues one when at least half of it has
    /// passed since the last (at this period, every decision, even an early one). The request
    /// log then spans `deadline_s` at any loop rate (`advice::MAX_PENDING`).
    pub request_period_s: f64,
    /// Smallest confidence accepted (0.7, §4.3).
    pub confidence_min: f64,
    /// Time after a request's issue by which its answer must be published, s.
    pub deadline_s: f64,
    /// A_final must be a maneuver the corrected logit keeps plausible: P_n (eq. 15) at least
    /// this. The advice refines the choice (eq. 16), it does not override it.
    pub prune_below: f64,
}

impl Default for AdviceParams {
    fn default() -> Self {
        Self {
            request_period_s: 0.05,
            confidence_min: 0.7,
            deadline_s: 1.5,
            prune_below: 0.1,
        }
    }
}

/// Monte Carlo trajectory sampling and scoring (eq. 17–24, Table 2).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrajectoryParams {
    /// N_samples, at most `MAX_SAMPLES`.
    pub samples: usize,
    /// Samples of the later plans of a cycle, at least 1 (at most `samples` are used): the
    /// maneuvers tried after the logit choice and "decelerate" have failed, and the
    /// minimum-risk fallback's search for a drive-on candidate. Bounds a cycle that ends in
    /// the fallback to about two full plans and five small ones.
    pub fallback_samples: usize,
    /// RNG seed; each cycle uses seed ⊕ cycle, so runs replay exactly.
    pub seed: u64,
    /// Planning and collision-check horizon, s.
    pub horizon_s: f64,
    /// Time step of trajectory points and checks, s.
    pub dt_s: f64,
    /// Relative standard deviation of the terminal speed and duration (eq. 23).
    pub sigma_rel: f64,
    /// Standard deviation of the terminal lateral offset, m (additive, the nominal is 0).
    pub sigma_lateral_m: f64,
    /// Standard-normal draws are clipped to ±this, so perturbations stay bounded.
    pub sigma_clip: f64,
    /// Shortest and longest polynomial duration T, s.
    pub min_duration_s: f64,
    pub max_duration_s: f64,
    /// c_e, efficiency weight of S_k.
    pub c_efficiency: f64,
    /// c_s, smoothness weight of S_k.
    pub c_smoothness: f64,
    /// c_l, lane-centring weight on |l_T| / max_lateral_offset_m (an addition to Table 2's
    /// score: without it the terminal offset random-walks between cycles).
    pub c_lateral: f64,
    /// T_ref, reference time of S_k, s.
    pub t_ref_s: f64,
    /// J_max, jerk-integral normaliser of S_k, m/s².
    pub j_max_norm: f64,
    /// Speed limit, m/s.
    pub max_speed_mps: f64,
    /// Acceleration limit, m/s².
    pub max_accel_mps2: f64,
    /// Braking limit for planned trajectories, m/s² (positive).
    pub max_brake_mps2: f64,
    /// Emergency braking of the minimum-risk fallback, m/s² (positive).
    pub emergency_brake_mps2: f64,
    /// Longitudinal and lateral jerk limit, m/s³.
    pub max_jerk_mps3: f64,
    /// Lateral acceleration limit, on curves and from lateral motion, m/s².
    pub max_lateral_accel_mps2: f64,
    /// Curvature limit of the followed path, 1/m.
    pub max_curvature: f64,
    /// Below this speed (at the start or the end of a candidate) the lateral offset is held, m/s.
    pub low_speed_mps: f64,
    /// Largest |l| of a terminal state, m.
    pub max_lateral_offset_m: f64,
    /// Footprint length of the ego and of other vehicles, m.
    pub vehicle_length_m: f64,
    /// Footprint width of the ego and of other vehicles, m.
    pub vehicle_width_m: f64,
    /// Clearance added around every footprint, m.
    pub safety_margin_m: f64,
    /// Growth of the other vehicles' footprint length with prediction time, m/s: where a
    /// vehicle is along its path grows uncertain with time, where it is across its lane does
    /// not.
    pub margin_growth_mps: f64,
    /// Stopping margin before a conflict zone, m.
    pub stop_margin_m: f64,
    /// A yielding candidate must still be able to stop before its yield point at this time
    /// into the plan (or at the horizon, if shorter), s. Replanning every cycle keeps that
    /// promise for later times, so the ego can approach briskly instead of planning a stop
    /// at the horizon's end.
    pub yield_check_s: f64,
}

impl TrajectoryParams {
    /// Samples of a cycle's later plans: `fallback_samples`, at most `samples`.
    pub fn later_samples(&self) -> usize {
        self.fallback_samples.min(self.samples)
    }
}

impl Default for TrajectoryParams {
    fn default() -> Self {
        Self {
            samples: 1024,
            fallback_samples: 256,
            seed: 0x5EED_C0C0,
            horizon_s: 5.0,
            dt_s: 0.1,
            sigma_rel: 0.15,
            sigma_lateral_m: 0.3,
            sigma_clip: 3.0,
            min_duration_s: 1.0,
            max_duration_s: 6.0,
            c_efficiency: 1.0,
            c_smoothness: 0.5,
            c_lateral: 0.3,
            t_ref_s: 5.0,
            j_max_norm: 10.0,
            max_speed_mps: 20.0,
            max_accel_mps2: 3.0,
            max_brake_mps2: 5.0,
            emergency_brake_mps2: 8.0,
            max_jerk_mps3: 10.0,
            max_lateral_accel_mps2: 4.0,
            max_curvature: 0.25,
            low_speed_mps: 2.0,
            max_lateral_offset_m: 1.0,
            vehicle_length_m: 4.8,
            vehicle_width_m: 2.0,
            safety_margin_m: 0.5,
            margin_growth_mps: 0.2,
            stop_margin_m: 1.0,
            yield_check_s: 1.0,
        }
    }
}

/// A parameter outside its allowed range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamError {
    /// Dotted TOML path of the offending key.
    pub key: &'static str,
    pub problem: ParamProblem,
}

/// What is wrong with a parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamProblem {
    /// Not finite, or outside [min, max].
    Range { value: f64, min: f64, max: f64 },
    /// Breaks a rule that relates it to other parameters.
    Rule(&'static str),
}

impl core::fmt::Display for ParamError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.problem {
            ParamProblem::Range { value, min, max } => write!(
                f,
                "parameter `{}` = {value}: must be a number in [{min}, {max}]",
                self.key
            ),
            ParamProblem::Rule(rule) => write!(f, "parameter `{}`: {rule}", self.key),
        }
    }
}

/// Smallest value of a parameter that divides or normalises: positive, and far enough from 0
/// that a quotient stays finite.
const TINY: f64 = 1e-3;
/// Largest magnitude of a weight, gain or penalty.
const WEIGHT: f64 = 1e3;

impl Params {
    /// Distance the ego needs to stop comfortably from `v` m/s at acceleration `a` m/s², m:
    /// its braking ramps from `a` to `comfort_decel_mps2` at the jerk limit `max_jerk_mps3`,
    /// as a planned stop must, then holds. Nearer than that to its passage, the ego is
    /// committed (at 1.9 m/s from a = 0, 0.88 m where v²/2b gives 0.60 m).
    pub fn ego_comfort_stop_m(&self, v: f64, a: f64) -> f64 {
        let (b, j) = (
            self.interaction.comfort_decel_mps2,
            self.trajectory.max_jerk_mps3,
        );
        let (v, a) = (v.max(0.0), a.max(-b));
        let ramp = (a + b) / j;
        let speed_at = |t: f64| v + a * t - 0.5 * j * t * t;
        let covered = |t: f64| v * t + 0.5 * a * t * t - j * t * t * t / 6.0;
        if speed_at(ramp) > 0.0 {
            covered(ramp) + speed_at(ramp) * speed_at(ramp) / (2.0 * b)
        } else {
            // At rest within the ramp.
            covered((a + libm::sqrt(a * a + 2.0 * j * v)) / j)
        }
    }

    /// Every number of the core with its allowed closed range [min, max]: positive where a
    /// division or a normaliser needs it, bounded where a conversion to cycles or nanoseconds
    /// or the fixed buffers need it. Array parameters appear once per element.
    pub fn ranges(&self) -> impl Iterator<Item = (&'static str, f64, f64, f64)> + '_ {
        let (l, o, c, i, a, t) = (
            &self.limits,
            &self.opm,
            &self.choice,
            &self.interaction,
            &self.advice,
            &self.trajectory,
        );
        let scalars = [
            ("limits.max_abs_time_s", l.max_abs_time_s, 1.0, 1e15),
            ("limits.max_abs_position_m", l.max_abs_position_m, 1.0, 1e7),
            ("limits.max_speed_mps", l.max_speed_mps, 1.0, 200.0),
            ("limits.max_accel_mps2", l.max_accel_mps2, 1.0, 200.0),
            (
                "opm.delta_ttc_threshold_s",
                o.delta_ttc_threshold_s,
                TINY,
                60.0,
            ),
            (
                "opm.proximity_threshold_m",
                o.proximity_threshold_m,
                0.0,
                1000.0,
            ),
            ("opm.ttc_speed_floor_mps", o.ttc_speed_floor_mps, TINY, 10.0),
            ("opm.ttc_max_s", o.ttc_max_s, TINY, 1000.0),
            (
                "opm.conflict_zone_half_m",
                o.conflict_zone_half_m,
                TINY,
                50.0,
            ),
            (
                "opm.lane_match_heading_rad",
                o.lane_match_heading_rad,
                TINY,
                core::f64::consts::PI,
            ),
            (
                "opm.intent_confidence_min",
                o.intent_confidence_min,
                0.0,
                1.0,
            ),
            ("choice.gamma", c.gamma, 0.0, WEIGHT),
            ("choice.lambda", c.lambda, 0.0, WEIGHT),
            (
                "choice.navigation_penalty",
                c.navigation_penalty,
                0.0,
                WEIGHT,
            ),
            ("choice.idle_penalty", c.idle_penalty, 0.0, WEIGHT),
            ("choice.idm_penalty_gain", c.idm_penalty_gain, 0.0, WEIGHT),
            ("choice.accelerate_mps2", c.accelerate_mps2, TINY, 20.0),
            ("choice.decelerate_mps2", c.decelerate_mps2, TINY, 20.0),
            (
                "choice.maneuver_horizon_s",
                c.maneuver_horizon_s,
                TINY,
                60.0,
            ),
            (
                "choice.reference_speed_mps",
                c.reference_speed_mps,
                TINY,
                100.0,
            ),
            ("choice.desired_speed_mps", c.desired_speed_mps, TINY, 100.0),
            ("choice.idm_headway_s", c.idm_headway_s, 0.0, 10.0),
            ("choice.idm_min_gap_m", c.idm_min_gap_m, 0.0, 50.0),
            (
                "choice.idm_comfort_decel_mps2",
                c.idm_comfort_decel_mps2,
                TINY,
                20.0,
            ),
            (
                "choice.idm_max_accel_mps2",
                c.idm_max_accel_mps2,
                TINY,
                20.0,
            ),
            (
                "choice.ego_hurry_efficiency",
                c.ego_hurry_efficiency,
                -5.0,
                5.0,
            ),
            (
                "choice.other_aggressive_safety",
                c.other_aggressive_safety,
                -5.0,
                5.0,
            ),
            (
                "choice.other_proceeds_safety",
                c.other_proceeds_safety,
                -5.0,
                5.0,
            ),
            (
                "choice.other_yields_efficiency",
                c.other_yields_efficiency,
                -5.0,
                5.0,
            ),
            (
                "choice.conflict_intensity_safety",
                c.conflict_intensity_safety,
                -5.0,
                5.0,
            ),
            (
                "interaction.standing_speed_mps",
                i.standing_speed_mps,
                0.0,
                10.0,
            ),
            (
                "interaction.comfort_decel_mps2",
                i.comfort_decel_mps2,
                TINY,
                20.0,
            ),
            ("interaction.standing_yield", i.standing_yield, 0.0, 1.0),
            (
                "interaction.proceed_accel_mps2",
                i.proceed_accel_mps2,
                0.0,
                20.0,
            ),
            (
                "interaction.proceed_min_speed_mps",
                i.proceed_min_speed_mps,
                TINY,
                100.0,
            ),
            (
                "interaction.proceed_top_speed_mps",
                i.proceed_top_speed_mps,
                TINY,
                100.0,
            ),
            ("interaction.pet_go_s", i.pet_go_s, 0.0, 30.0),
            ("interaction.pet_behind_s", i.pet_behind_s, 0.0, 30.0),
            (
                "interaction.max_imposed_decel_mps2",
                i.max_imposed_decel_mps2,
                TINY,
                20.0,
            ),
            ("interaction.reaction_s", i.reaction_s, 0.0, 10.0),
            ("interaction.trust_yield", i.trust_yield, 0.0, 1.0),
            (
                "interaction.priority_yield_weight",
                i.priority_yield_weight,
                0.0,
                1.0,
            ),
            ("interaction.deadlock_wait_s", i.deadlock_wait_s, 0.0, 600.0),
            ("interaction.creep_speed_mps", i.creep_speed_mps, 0.0, 10.0),
            (
                "interaction.deadlock_after_s",
                i.deadlock_after_s,
                0.0,
                600.0,
            ),
            ("interaction.watch_s", i.watch_s, 0.0, 600.0),
            (
                "interaction.follower_min_gap_m",
                i.follower_min_gap_m,
                0.0,
                100.0,
            ),
            (
                "interaction.follower_headway_s",
                i.follower_headway_s,
                0.0,
                10.0,
            ),
            (
                "interaction.follower_max_accel_mps2",
                i.follower_max_accel_mps2,
                TINY,
                20.0,
            ),
            (
                "interaction.follower_comfort_decel_mps2",
                i.follower_comfort_decel_mps2,
                TINY,
                20.0,
            ),
            (
                "interaction.request_decel_mps2",
                i.request_decel_mps2,
                0.0,
                20.0,
            ),
            (
                "interaction.announce_settle_s",
                i.announce_settle_s,
                0.0,
                10.0,
            ),
            (
                "interaction.courtesy_penalty",
                i.courtesy_penalty,
                0.0,
                WEIGHT,
            ),
            ("advice.confidence_min", a.confidence_min, 0.0, 1.0),
            ("advice.deadline_s", a.deadline_s, TINY, 60.0),
            ("advice.request_period_s", a.request_period_s, TINY, 60.0),
            ("advice.prune_below", a.prune_below, 0.0, 1.0),
            ("trajectory.horizon_s", t.horizon_s, TINY, 60.0),
            ("trajectory.dt_s", t.dt_s, TINY, 1.0),
            ("trajectory.sigma_rel", t.sigma_rel, 0.0, 1.0),
            ("trajectory.sigma_lateral_m", t.sigma_lateral_m, 0.0, 5.0),
            ("trajectory.sigma_clip", t.sigma_clip, TINY, 5.0),
            ("trajectory.min_duration_s", t.min_duration_s, TINY, 60.0),
            ("trajectory.max_duration_s", t.max_duration_s, TINY, 60.0),
            ("trajectory.c_efficiency", t.c_efficiency, 0.0, WEIGHT),
            ("trajectory.c_smoothness", t.c_smoothness, 0.0, WEIGHT),
            ("trajectory.c_lateral", t.c_lateral, 0.0, WEIGHT),
            ("trajectory.t_ref_s", t.t_ref_s, TINY, 60.0),
            ("trajectory.j_max_norm", t.j_max_norm, TINY, 1e4),
            ("trajectory.max_speed_mps", t.max_speed_mps, TINY, 100.0),
            ("trajectory.max_accel_mps2", t.max_accel_mps2, TINY, 20.0),
            ("trajectory.max_brake_mps2", t.max_brake_mps2, TINY, 20.0),
            (
                "trajectory.emergency_brake_mps2",
                t.emergency_brake_mps2,
                TINY,
                20.0,
            ),
            ("trajectory.max_jerk_mps3", t.max_jerk_mps3, TINY, 100.0),
            (
                "trajectory.max_lateral_accel_mps2",
                t.max_lateral_accel_mps2,
                TINY,
                20.0,
            ),
            ("trajectory.max_curvature", t.max_curvature, TINY, 2.0),
            ("trajectory.low_speed_mps", t.low_speed_mps, 0.0, 20.0),
            (
                "trajectory.max_lateral_offset_m",
                t.max_lateral_offset_m,
                TINY,
                5.0,
            ),
            (
                "trajectory.vehicle_length_m",
                t.vehicle_length_m,
                TINY,
                30.0,
            ),
            ("trajectory.vehicle_width_m", t.vehicle_width_m, TINY, 5.0),
            ("trajectory.safety_margin_m", t.safety_margin_m, 0.0, 5.0),
            (
                "trajectory.margin_growth_mps",
                t.margin_growth_mps,
                0.0,
                5.0,
            ),
            ("trajectory.stop_margin_m", t.stop_margin_m, 0.0, 20.0),
            ("trajectory.yield_check_s", t.yield_check_s, TINY, 60.0),
        ];
        let arrays = [
            ("saliency.key", &self.saliency.key[..], -WEIGHT, WEIGHT),
            ("choice.beta", &c.beta[..], -WEIGHT, WEIGHT),
            (
                "choice.ego_style_safety",
                &c.ego_style_safety[..],
                -5.0,
                5.0,
            ),
            (
                "choice.ego_style_efficiency",
                &c.ego_style_efficiency[..],
                -5.0,
                5.0,
            ),
            (
                "choice.ego_task_efficiency",
                &c.ego_task_efficiency[..],
                -5.0,
                5.0,
            ),
            (
                "choice.other_task_safety",
                &c.other_task_safety[..],
                -5.0,
                5.0,
            ),
        ];
        scalars.into_iter().chain(
            arrays.into_iter().flat_map(|(key, values, min, max)| {
                values.iter().map(move |&v| (key, v, min, max))
            }),
        )
    }

    /// Checks every number against [`Params::ranges`], the counts against the fixed buffers,
    /// and the rules that relate parameters.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (key, value, min, max) in self.ranges() {
            // Not `value < min || value > max`: NaN fails this test.
            if !(min..=max).contains(&value) {
                return Err(ParamError {
                    key,
                    problem: ParamProblem::Range { value, min, max },
                });
            }
        }
        let t = &self.trajectory;
        let bad = |key, rule| {
            Err(ParamError {
                key,
                problem: ParamProblem::Rule(rule),
            })
        };
        if t.samples == 0 || t.samples > MAX_SAMPLES {
            return bad("trajectory.samples", "must be in 1..=1024");
        }
        if t.fallback_samples == 0 || t.fallback_samples > MAX_SAMPLES {
            return bad("trajectory.fallback_samples", "must be in 1..=1024");
        }
        if t.horizon_s / t.dt_s > MAX_STEPS as f64 + 1e-6 {
            return bad("trajectory.horizon_s", "horizon_s / dt_s must be in 1..=64");
        }
        if t.yield_check_s > t.horizon_s {
            return bad(
                "trajectory.yield_check_s",
                "need yield_check_s <= horizon_s",
            );
        }
        if t.min_duration_s > t.max_duration_s {
            return bad(
                "trajectory.min_duration_s",
                "need min_duration_s <= max_duration_s",
            );
        }
        if self.interaction.proceed_min_speed_mps > self.interaction.proceed_top_speed_mps {
            return bad(
                "interaction.proceed_min_speed_mps",
                "need proceed_min_speed_mps <= proceed_top_speed_mps",
            );
        }
        let a = &self.advice;
        let log_span_s = crate::advice::REQUEST_DUE_SHARE
            * a.request_period_s
            * (crate::advice::MAX_PENDING - 1) as f64;
        if a.deadline_s > log_span_s {
            return bad(
                "advice.request_period_s",
                "the request log (256 requests at 0.5 request_period_s apart) must span \
                 advice.deadline_s: need request_period_s >= deadline_s / 127.5",
            );
        }
        // The planner searches another road user's passage this many steps before now and
        // past its horizon; a longer margin would be cut short there.
        let sweep_s = (MAX_SWEEP_STEPS - 1) as f64 * t.dt_s;
        for (key, margin) in [
            ("interaction.pet_go_s", self.interaction.pet_go_s),
            ("interaction.pet_behind_s", self.interaction.pet_behind_s),
        ] {
            if margin > sweep_s + 1e-9 {
                return bad(
                    key,
                    "the planner searches passages 47 steps back and ahead: need \
                     pet_go_s and pet_behind_s <= 47 trajectory.dt_s",
                );
            }
        }
        if t.emergency_brake_mps2 < t.max_brake_mps2 {
            return bad(
                "trajectory.emergency_brake_mps2",
                "need max_brake_mps2 <= emergency_brake_mps2",
            );
        }
        Ok(())
    }
}
