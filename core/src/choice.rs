//! Maneuver choice: attributes x_i (matching, safety, efficiency), utility V_i = βᵀx_i (eq. 9),
//! multinomial logit P_ni (eq. 11), history consistency γ·D_prev (eq. 12–13), switch penalty λ
//! (eq. 14) and the corrected logit (eq. 15).
//!
//! The safety degree weighs, per conflict, how the ego's and the other's occupancies of the
//! conflict zone would be separated in time (the post-encroachment margin) under each
//! behaviour the other may still take, and the courtesy check refuses plans that would make
//! another road user brake hard; see [`conflict_risk`], [`imposed_decel`], [`choose`].

use libm::{exp, sqrt};

use crate::intent::Stated;
use crate::opm::{ConflictPair, ConflictSet, OpmTriplet};
use crate::params::{ChoiceParams, Follower, InteractionParams, OpmParams};
use crate::saliency::softmax;
use crate::scene::{ConflictKind, IntentAction, Style, Turn};

/// Number of maneuvers.
pub const MANEUVERS: usize = 5;
/// Attributes per maneuver: [matching, safety, efficiency].
pub const ATTRIBUTES: usize = 3;
/// Features of the scene state x_n used by eq. 13.
pub const STATE_FEATURES: usize = 6;
/// Entries of the choice history 𝓗: 2 s at 10 Hz.
pub const CHOICE_HISTORY: usize = 20;

coded_enum! {
/// The five maneuvers of §4.2, in the paper's order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Maneuver {
    /// Straight-line acceleration along the route.
    Accelerate = 0,
    /// Straight-line deceleration; yields (stops before the conflict zone) when one is ahead.
    Decelerate = 1,
    /// Constant speed along the route.
    #[default]
    KeepSpeed = 2,
    /// Follow a left-turning route at the curve's comfortable speed.
    TurnLeft = 3,
    /// Follow a right-turning route at the curve's comfortable speed.
    TurnRight = 4,
}
}

impl Maneuver {
    pub const ALL: [Maneuver; MANEUVERS] = [
        Maneuver::Accelerate,
        Maneuver::Decelerate,
        Maneuver::KeepSpeed,
        Maneuver::TurnLeft,
        Maneuver::TurnRight,
    ];
    pub fn index(self) -> usize {
        self as usize
    }
    /// snake_case name.
    pub fn name(self) -> &'static str {
        match self {
            Maneuver::Accelerate => "accelerate",
            Maneuver::Decelerate => "decelerate",
            Maneuver::KeepSpeed => "keep_speed",
            Maneuver::TurnLeft => "turn_left",
            Maneuver::TurnRight => "turn_right",
        }
    }
    /// True for the maneuver that gives way to crossing traffic (what an eHMI announces as
    /// "please go ahead"); every other maneuver goes first.
    pub fn gives_way(self) -> bool {
        self == Maneuver::Decelerate
    }
    /// False for a turn against the navigation instruction `route`.
    pub fn consistent_with(self, route: Turn) -> bool {
        match self {
            Maneuver::TurnLeft => route == Turn::Left,
            Maneuver::TurnRight => route == Turn::Right,
            _ => true,
        }
    }
}

/// Nominal longitudinal profile of a maneuver: accelerate at `accel` until `target_speed`,
/// then hold it, and stop `stop_m` ahead when that is finite. Also the nominal terminal state
/// f_a(s_start) of eq. 23.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Profile {
    /// m/s², signed.
    pub accel: f64,
    /// Terminal speed v_T, m/s.
    pub target_speed: f64,
    /// Duration T of the polynomial, s.
    pub duration: f64,
    /// The profile yields: it goes no further than this, m (∞ when it does not yield).
    pub stop_m: f64,
}

impl Default for Profile {
    fn default() -> Self {
        Profile {
            accel: 0.0,
            target_speed: 0.0,
            duration: 0.0,
            stop_m: f64::INFINITY,
        }
    }
}

impl Profile {
    /// True when the profile stops before a conflict zone or behind a stopping leader.
    pub fn yields(&self) -> bool {
        self.stop_m.is_finite()
    }

    /// Time to travel `d` m from speed `v0` under this profile; ∞ if it stops first.
    pub fn arrival_time(&self, v0: f64, d: f64) -> f64 {
        if d <= 0.0 {
            return 0.0;
        }
        if d > self.stop_m {
            return f64::INFINITY;
        }
        let (a, vt) = (self.accel, self.target_speed);
        if a.abs() < 1e-9 {
            return if v0 > 1e-9 { d / v0 } else { f64::INFINITY };
        }
        let t1 = ((vt - v0) / a).max(0.0);
        let d1 = 0.5 * (v0 + vt) * t1;
        if d <= d1 {
            let disc = v0 * v0 + 2.0 * a * d;
            if disc < 0.0 {
                return f64::INFINITY;
            }
            return (-v0 + sqrt(disc)) / a;
        }
        if vt > 1e-9 {
            t1 + (d - d1) / vt
        } else {
            f64::INFINITY
        }
    }

    /// Speed `t` s after starting at `v0`, m/s: the ramp of [`Profile::arrival_time`].
    pub fn speed_at(&self, v0: f64, t: f64) -> f64 {
        let (a, vt) = (self.accel, self.target_speed);
        if a.abs() < 1e-9 {
            v0
        } else if t >= ((vt - v0) / a).max(0.0) {
            vt
        } else {
            v0 + a * t
        }
    }
}

/// What the choice stage needs to know about the ego's situation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EgoContext {
    /// Speed, m/s.
    pub speed: f64,
    /// Longitudinal acceleration, m/s².
    pub accel: f64,
    /// Speed cap from the road and the curvature ahead, m/s.
    pub speed_cap: f64,
    /// Distance to the point where a yielding ego must stop, m (∞ when nothing to yield to).
    pub yield_distance: f64,
    /// Distance to where the ego stops behind its car-following leader should the leader
    /// stop as forecast, m: ∞ without a leader, for one that does not brake, and for one
    /// whose stop is beyond a single stopping polynomial's reach (the ego has time to slow).
    pub leader_stop_m: f64,
    /// Distance whose traversal measures efficiency: through the nearest conflict zone ahead,
    /// or the reference distance when there is none, m.
    pub goal_distance: f64,
    /// Navigation instruction: the turn of the route lane.
    pub route: Turn,
    /// Largest braking of planned trajectories, m/s².
    pub max_brake: f64,
    pub min_duration: f64,
    pub max_duration: f64,
    /// Time into a plan at which a yielding ego must still be able to stop before its yield
    /// point (`trajectory.yield_check_s`), s.
    pub yield_check_s: f64,
}

impl Default for EgoContext {
    /// Standing, nothing ahead to stop behind, everything else 0.
    fn default() -> Self {
        EgoContext {
            speed: 0.0,
            accel: 0.0,
            speed_cap: 0.0,
            yield_distance: 0.0,
            leader_stop_m: f64::INFINITY,
            goal_distance: 0.0,
            route: Turn::default(),
            max_brake: 0.0,
            min_duration: 0.0,
            max_duration: 0.0,
            yield_check_s: 0.0,
        }
    }
}

/// Below this speed the ego counts as stopped for the idle penalty (and below
/// `creep_speed_mps` as creeping), m/s.
const IDLE_SPEED_MPS: f64 = 0.1;
/// A profile whose target speed is this far below the speed the ego may keep slows it, for
/// the idle penalty, m/s.
const SLOWING_MPS: f64 = 0.5;
/// A yielding ego more than this short of its yield point and too far to reach it with one
/// stopping polynomial approaches it (see [`profile`]), m.
const CREEP_FROM_M: f64 = 1.0;

/// Profile that goes from the ego's speed towards `target` (clamped to the speed cap) at the
/// nominal acceleration or deceleration, over at least the maneuver horizon.
pub fn toward(target: f64, ctx: &EgoContext, p: &ChoiceParams) -> Profile {
    let v0 = ctx.speed;
    let target = target.clamp(0.0, ctx.speed_cap.max(0.0));
    let accel = if target > v0 {
        p.accelerate_mps2
    } else if target < v0 {
        -p.decelerate_mps2
    } else {
        0.0
    };
    let ramp = if accel == 0.0 {
        0.0
    } else {
        (target - v0) / accel
    };
    Profile {
        accel,
        target_speed: target,
        duration: ramp
            .max(p.maneuver_horizon_s)
            .clamp(ctx.min_duration, ctx.max_duration),
        stop_m: f64::INFINITY,
    }
}

/// Nominal profile of maneuver `m`.
pub fn profile(m: Maneuver, ctx: &EgoContext, p: &ChoiceParams) -> Profile {
    let v0 = ctx.speed;
    let h = p.maneuver_horizon_s;
    let cap = ctx.speed_cap.max(0.0);
    let toward = |target: f64| toward(target, ctx, p);
    match m {
        Maneuver::Accelerate => toward(v0 + p.accelerate_mps2 * h),
        Maneuver::KeepSpeed => toward(v0),
        Maneuver::TurnLeft | Maneuver::TurnRight => toward(cap),
        Maneuver::Decelerate => {
            let d = ctx.yield_distance.min(ctx.leader_stop_m);
            // The approach speed v_a from which the ego, holding v_a for the yield check time
            // τ and then braking at `decelerate_mps2` (b), stops at the yield point:
            // v_a·τ + v_a²/(2b) = d. Near the point this is a creep.
            let (b, tau) = (p.decelerate_mps2, ctx.yield_check_s);
            let approach = b * (sqrt(tau * tau + 2.0 * d / b) - tau);
            if d.is_finite()
                && d > CREEP_FROM_M
                && (v0 < approach || 2.0 * d > v0 * ctx.max_duration)
            {
                // Slower than v_a, or too far to reach the point with one stopping
                // polynomial: approach it at v_a.
                Profile {
                    stop_m: d,
                    ..toward(approach.min(p.desired_speed_mps))
                }
            } else if d.is_finite() && d > 0.0 {
                // Stop at the yield point: a quartic with v_T = a_T = 0 from rest acceleration
                // covers v0·T/2, so T = 2d/v0.
                let accel = -(v0 * v0 / (2.0 * d)).min(ctx.max_brake);
                let duration = if v0 > 0.1 {
                    (2.0 * d / v0).clamp(ctx.min_duration, ctx.max_duration)
                } else {
                    ctx.min_duration
                };
                Profile {
                    accel,
                    target_speed: 0.0,
                    duration,
                    stop_m: d,
                }
            } else {
                toward(v0 - p.decelerate_mps2 * h)
            }
        }
    }
}

/// Parameters of the Intelligent Driver Model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Idm {
    /// Maximum acceleration a and comfortable deceleration b, m/s².
    pub max_accel_mps2: f64,
    pub comfort_decel_mps2: f64,
    /// Minimum gap s₀, m; time headway T, s; desired speed v₀, m/s.
    pub min_gap_m: f64,
    pub headway_s: f64,
    pub desired_speed_mps: f64,
}

impl Idm {
    /// IDM acceleration (Treiber et al. 2000), m/s², at speed `v` with a leader `gap` m ahead
    /// closing at `dv` m/s (an infinite gap: free road): a[1 − (v/v₀)⁴ − (s*/s)²],
    /// s* = s₀ + vT + vΔv / (2√(ab)).
    pub fn accel(&self, v: f64, gap: f64, dv: f64) -> f64 {
        let (a, b) = (self.max_accel_mps2, self.comfort_decel_mps2);
        let s_star = self.min_gap_m + (v * self.headway_s + v * dv / (2.0 * sqrt(a * b))).max(0.0);
        let free = v / self.desired_speed_mps.max(0.1);
        let interaction = s_star / gap.max(0.1);
        a * (1.0 - free * free * free * free - interaction * interaction)
    }
}

/// The core's IDM (its parameters in [`ChoiceParams`]); see [`Idm::accel`].
pub fn idm_accel(v: f64, gap: f64, dv: f64, p: &ChoiceParams) -> f64 {
    Idm {
        max_accel_mps2: p.idm_max_accel_mps2,
        comfort_decel_mps2: p.idm_comfort_decel_mps2,
        min_gap_m: p.idm_min_gap_m,
        headway_s: p.idm_headway_s,
        desired_speed_mps: p.desired_speed_mps,
    }
    .accel(v, gap, dv)
}

/// Everything the choice stage computed for one scene.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChoiceOutcome {
    /// x_i = [matching, safety, efficiency] per maneuver (eq. 9).
    pub attributes: [[f64; ATTRIBUTES]; MANEUVERS],
    /// Safety degree in [0, 1] before weighting, per maneuver.
    pub safety: [f64; MANEUVERS],
    /// Efficiency degree before weighting, per maneuver.
    pub efficiency: [f64; MANEUVERS],
    /// Largest deceleration the maneuver would impose on another road user, m/s².
    pub imposed_decel: [f64; MANEUVERS],
    /// Refused for courtesy: it would impose more than `max_imposed_decel_mps2`.
    pub courtesy_rejected: [bool; MANEUVERS],
    /// Safety and efficiency preferences from intents and conflict intensity.
    pub safety_preference: f64,
    pub efficiency_preference: f64,
    /// V_i (eq. 9).
    pub utility: [f64; MANEUVERS],
    /// P_ni (eq. 11).
    pub p_logit: [f64; MANEUVERS],
    /// D_prev_i (eq. 13).
    pub d_prev: [f64; MANEUVERS],
    /// Ṽ_i after eq. 12 and 14.
    pub utility_corrected: [f64; MANEUVERS],
    /// Corrected P_ni (eq. 15).
    pub p_corrected: [f64; MANEUVERS],
    /// argmax of the corrected probabilities.
    pub choice: Maneuver,
    /// Nominal profile per maneuver.
    pub profiles: [Profile; MANEUVERS],
    /// Scene state x_n (eq. 13).
    pub state: [f64; STATE_FEATURES],
}

/// Safety and efficiency preferences from explicit intents (strong ones only) and conflict
/// intensity. Priority task > action > style is carried by the gains' magnitudes. A road
/// user's stated yield counts only where its motion agreed (its conflict's implicit intent
/// counted it, see [`crate::intent`]).
pub fn preferences(
    triplet: &OpmTriplet,
    conflicts: &ConflictSet,
    opm: &OpmParams,
    p: &ChoiceParams,
) -> (f64, f64) {
    let th = opm.intent_confidence_min;
    let (mut ws, mut we) = (1.0, 1.0);
    let ego = &triplet.ego_intent;
    if let Some(style) = ego.strong_style(th) {
        ws += p.ego_style_safety[style as usize];
        we += p.ego_style_efficiency[style as usize];
    }
    if let Some(task) = ego.strong_task(th) {
        we += p.ego_task_efficiency[task as usize];
    }
    if matches!(
        ego.strong_action(th),
        Some(IntentAction::Accelerate | IntentAction::Proceed)
    ) {
        we += p.ego_hurry_efficiency;
    }
    for pair in triplet.intents() {
        let other = &pair.intent;
        if let Some(task) = other.strong_task(th) {
            ws += p.other_task_safety[task as usize];
        }
        if other.strong_style(th) == Some(Style::Aggressive) {
            ws += p.other_aggressive_safety;
        }
        let counted = conflicts
            .pairs()
            .iter()
            .find(|c| c.agent == pair.agent)
            .map(|c| c.intent.stated);
        match other.strong_action(th) {
            Some(IntentAction::Proceed | IntentAction::Accelerate) => ws += p.other_proceeds_safety,
            Some(IntentAction::Yield | IntentAction::Stop | IntentAction::Decelerate)
                if counted != Some(Stated::Contradicted) =>
            {
                we += p.other_yields_efficiency
            }
            _ => {}
        }
    }
    ws += p.conflict_intensity_safety * triplet.risky_conflicts(opm).count() as f64;
    (ws.max(0.1), we.max(0.1))
}

/// Time for a road user at speed `v` accelerating at `a` (≥ 0) up to `v_top` to cover `d` m,
/// s.
fn time_to_cover(v: f64, a: f64, v_top: f64, d: f64) -> f64 {
    if d <= 0.0 {
        return 0.0;
    }
    let v_top = v_top.max(v);
    if a > 1e-9 && v_top > v {
        let ramp_t = (v_top - v) / a;
        let ramp_d = 0.5 * (v + v_top) * ramp_t;
        if d <= ramp_d {
            return (-v + sqrt(v * v + 2.0 * a * d)) / a;
        }
        return ramp_t + (d - ramp_d) / v_top;
    }
    if v > 1e-9 {
        d / v
    } else {
        f64::INFINITY
    }
}

/// The other's occupancy of its passage if it proceeds, [enter, exit] in s from now: it
/// enters at the earliest when accelerating at its shown acceleration or
/// `proceed_accel_mps2`, whichever is higher, up to `proceed_top_speed_mps`, and leaves at the
/// latest when holding its speed (at least `proceed_min_speed_mps`). A passage it has already
/// entered or left was entered or left that long ago at that speed: negative times.
pub fn proceeding_interval(c: &ConflictPair, ip: &InteractionParams) -> (f64, f64) {
    let v = c.agent_speed_mps;
    let a = c.agent_accel_mps2.max(ip.proceed_accel_mps2);
    let top = ip.proceed_top_speed_mps;
    let [d_in, d_out] = c.agent_pass_m;
    let held = v.max(ip.proceed_min_speed_mps);
    let at = |d: f64| {
        if d < 0.0 {
            d / held
        } else {
            time_to_cover(v, a, top, d)
        }
    };
    (at(d_in), at(d_out).max(d_out / held))
}

/// The ego's occupancy of its passage under `profile` from speed `v0`, [enter, exit] in s
/// from now (∞ for a part it does not reach: a yielding profile stops before).
pub fn ego_interval(profile: &Profile, v0: f64, c: &ConflictPair) -> (f64, f64) {
    let [d_in, d_out] = c.ego_pass_m;
    (
        profile.arrival_time(v0, d_in.max(0.0)),
        profile.arrival_time(v0, d_out),
    )
}

/// Collision risk of `profile` against conflict `c`, in [0, 1]: with the ego's occupancy
/// [t_in, t_out] and the other's proceeding one [a_in, a_out] ([`proceeding_interval`]), the
/// margin going first is a_in − t_out (it needs `pet_go_s`) and passing behind t_in − a_out
/// (it needs `pet_behind_s`); the shortfall s of the better order gives
/// r = 1 − exp(−s² / 2σ²), σ = pet_go_s / 2, weighted by the probability 1 − `yields` that
/// the other does not let the ego go first. A profile that does not enter has no risk; one
/// that would stand in the passage, r = 1.
pub fn conflict_risk(
    profile: &Profile,
    v0: f64,
    c: &ConflictPair,
    yields: f64,
    ip: &InteractionParams,
) -> f64 {
    let (t_in, t_out) = ego_interval(profile, v0, c);
    if !t_in.is_finite() {
        return 0.0;
    }
    let r = if t_out.is_finite() {
        let (a_in, a_out) = proceeding_interval(c, ip);
        let short = (ip.pet_go_s - (a_in - t_out))
            .min(ip.pet_behind_s - (t_in - a_out))
            .max(0.0);
        let sigma = 0.5 * ip.pet_go_s;
        1.0 - exp(-short * short / (2.0 * sigma * sigma))
    } else {
        1.0
    };
    (1.0 - yields.clamp(0.0, 1.0)) * r
}

/// The deceleration `profile` would impose on the other of conflict `c`, m/s², when the ego
/// goes first, as `follower` models the other:
/// * [`Follower::Kinematic`]: it must not enter the ego's passage before the ego has left it
///   plus `pet_behind_s`; after `reaction_s` at its speed v, with D m left and T s to go, it
///   needs b = 2(vT − D)/T² (or v²/2D when that stops it first);
/// * [`Follower::Idm`]: its hardest braking as the IDM follower of the ego ([`idm_follower_decel`]).
///
/// A road user already yielding (`yields` ≥ `trust_yield`) has its own braking subtracted. 0
/// when the ego passes behind or does not enter, and for the kinematic follower when the
/// other is committed (then [`conflict_risk`] speaks); an IDM follower brakes for a leader
/// whether or not it could stop comfortably.
pub fn imposed_decel(
    profile: &Profile,
    v0: f64,
    c: &ConflictPair,
    yields: f64,
    ip: &InteractionParams,
) -> f64 {
    let (t_in, t_out) = ego_interval(profile, v0, c);
    if !t_in.is_finite() || (c.intent.committed && ip.follower == Follower::Kinematic) {
        return 0.0;
    }
    let (a_in, a_out) = proceeding_interval(c, ip);
    let ego_first = a_in - t_out >= t_in - a_out;
    if !ego_first {
        return 0.0;
    }
    let needed = match ip.follower {
        Follower::Kinematic => {
            let v = c.agent_speed_mps;
            let d = c.agent_pass_m[0] - v * ip.reaction_s;
            let t = t_out + ip.pet_behind_s - ip.reaction_s;
            if v < 1e-6 || v * t <= d {
                0.0
            } else if d <= 0.0 || t <= 0.0 {
                f64::INFINITY
            } else {
                let b = 2.0 * (v * t - d) / (t * t);
                if b * t <= v {
                    b
                } else {
                    v * v / (2.0 * d)
                }
            }
        }
        Follower::Idm => idm_follower_decel(profile, v0, c, (t_in, t_out), ip),
    };
    if yields >= ip.trust_yield {
        (needed - c.intent.required_decel_mps2.min(needed)).max(0.0)
    } else {
        needed
    }
}

/// Step of [`idm_follower_decel`]'s integration, s.
const FOLLOW_DT_S: f64 = 0.1;
/// Longest integration of [`idm_follower_decel`], s.
const FOLLOW_MAX_S: f64 = 10.0;
/// Hardest braking the integrated follower applies, m/s² (a car's emergency braking).
const FOLLOW_MAX_BRAKE_MPS2: f64 = 9.0;

/// Hardest braking of the other of conflict `c` as the IDM follower (`follower_*`) of an ego
/// that goes first under `profile`, m/s². The other keeps its speed until the ego enters its
/// passage at `t_in`; from then until it leaves at `t_out` the ego is its leader,
/// `agent_pass_m[0]` ahead of where it was: standing across its lane in a crossing, driving
/// on at the ego's speed in a merge (the IDM brakes hardest when it first sees a leader, so
/// the rest of a merge adds little). Integrated every `FOLLOW_DT_S`, its braking capped at
/// `FOLLOW_MAX_BRAKE_MPS2` (the IDM's wish is what counts); ∞ if it would reach the ego.
pub fn idm_follower_decel(
    profile: &Profile,
    v0: f64,
    c: &ConflictPair,
    (t_in, t_out): (f64, f64),
    ip: &InteractionParams,
) -> f64 {
    let idm = Idm {
        max_accel_mps2: ip.follower_max_accel_mps2,
        comfort_decel_mps2: ip.follower_comfort_decel_mps2,
        min_gap_m: ip.follower_min_gap_m,
        headway_s: ip.follower_headway_s,
        desired_speed_mps: ip.proceed_top_speed_mps.max(c.agent_speed_mps),
    };
    let merging = c.kind == ConflictKind::Merging;
    let end = t_out.min(FOLLOW_MAX_S);
    let (mut x, mut v, mut lead) = (0.0, c.agent_speed_mps.max(0.0), c.agent_pass_m[0]);
    let (mut t, mut worst) = (0.0, 0.0_f64);
    while t < end {
        let mut a = 0.0;
        if t >= t_in {
            let gap = lead - x;
            if gap <= 0.0 {
                return f64::INFINITY;
            }
            let v_lead = if merging {
                profile.speed_at(v0, t)
            } else {
                0.0
            };
            a = idm.accel(v, gap, v - v_lead);
            worst = worst.max(-a);
            a = a.max(-FOLLOW_MAX_BRAKE_MPS2);
            lead += v_lead * FOLLOW_DT_S;
        }
        let v_next = (v + a * FOLLOW_DT_S).max(0.0);
        x += 0.5 * (v + v_next) * FOLLOW_DT_S;
        v = v_next;
        t += FOLLOW_DT_S;
    }
    worst
}

/// Efficiency degree of `profile`: the time to cover `ctx.goal_distance` at the reference
/// speed over the time it takes, in [0, 1.5]. A yielding profile takes the time to its yield
/// point or `wait_s` (how long the way is expected to stay taken), whichever is longer, then
/// the rest from standstill at the nominal acceleration.
pub fn efficiency(profile: &Profile, ctx: &EgoContext, wait_s: f64, p: &ChoiceParams) -> f64 {
    let d = ctx.goal_distance;
    let free = d / p.reference_speed_mps;
    let taken = if profile.yields() && ctx.yield_distance < d {
        let restart = Profile {
            accel: p.accelerate_mps2,
            target_speed: ctx.speed_cap.max(1.0),
            ..Profile::default()
        };
        profile.duration.max(wait_s) + restart.arrival_time(0.0, d - ctx.yield_distance)
    } else {
        profile.arrival_time(ctx.speed, d)
    };
    if taken.is_finite() && taken > 0.0 {
        (free / taken).clamp(0.0, 1.5)
    } else if taken == 0.0 {
        1.5
    } else {
        0.0
    }
}

/// How long a yielding ego expects to wait for the way to clear, s: for each conflicting road
/// user that is arriving (TTC below the cap) and whose passage the ego has not entered, its
/// proceeding exit if it proceeds, `deadlock_wait_s` if it waits too (probability `yields`);
/// the longest.
pub fn expected_wait(
    conflicts: &[ConflictPair],
    yields: &[f64],
    opm: &OpmParams,
    ip: &InteractionParams,
) -> f64 {
    conflicts
        .iter()
        .zip(yields)
        .filter(|(c, _)| c.agent_ttc_s < opm.ttc_max_s && c.ego_pass_m[0] > 0.0)
        .map(|(c, &y)| {
            let (_, a_out) = proceeding_interval(c, ip);
            (1.0 - y) * a_out + y * ip.deadlock_wait_s
        })
        .fold(0.0, f64::max)
}

/// Scene state x_n for eq. 13, centred so that cosine similarity separates situations.
pub fn state_features(
    triplet: &OpmTriplet,
    ctx: &EgoContext,
    opm: &OpmParams,
    p: &ChoiceParams,
) -> [f64; STATE_FEATURES] {
    let min_dttc = triplet
        .risky_conflicts(opm)
        .map(|c| c.delta_ttc_s)
        .fold(opm.delta_ttc_threshold_s, f64::min);
    let conflict_dist = triplet
        .conflicts()
        .iter()
        .map(|c| c.ego_dist_m)
        .fold(50.0, f64::min)
        .clamp(-10.0, 50.0);
    let gap = triplet.leader.map(|l| l.gap_m).unwrap_or(50.0).min(50.0);
    [
        ctx.speed / p.reference_speed_mps - 1.0,
        ctx.accel / 3.0,
        min_dttc / opm.delta_ttc_threshold_s - 0.5,
        conflict_dist / 25.0 - 1.0,
        gap / 25.0 - 1.0,
        triplet.risky_conflicts(opm).count() as f64 / 2.0 - 0.5,
    ]
}

/// One entry of the choice history 𝓗: the scene state and the maneuver executed in it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ChoiceRecord {
    pub time_s: f64,
    pub state: [f64; STATE_FEATURES],
    pub maneuver: Maneuver,
}

/// Ring of the last [`CHOICE_HISTORY`] executed choices, one per 0.1 s.
#[derive(Clone, Copy, Debug, Default)]
pub struct ChoiceHistory {
    records: [ChoiceRecord; CHOICE_HISTORY],
    head: usize,
    len: usize,
    /// i_prev of eq. 14: the maneuver executed at the previous step.
    pub previous: Option<Maneuver>,
}

impl ChoiceHistory {
    /// Records the executed maneuver; the ring samples at most every 0.1 s.
    pub fn record(&mut self, time_s: f64, state: [f64; STATE_FEATURES], maneuver: Maneuver) {
        self.previous = Some(maneuver);
        if self.len > 0 {
            let newest = &self.records[(self.head + CHOICE_HISTORY - 1) % CHOICE_HISTORY];
            if time_s - newest.time_s < crate::scene::HISTORY_PERIOD_S - 1e-9 {
                return;
            }
        }
        self.records[self.head] = ChoiceRecord {
            time_s,
            state,
            maneuver,
        };
        self.head = (self.head + 1) % CHOICE_HISTORY;
        self.len = (self.len + 1).min(CHOICE_HISTORY);
    }

    /// Held records, in no particular order.
    pub fn records(&self) -> &[ChoiceRecord] {
        &self.records[..self.len]
    }

    /// D_prev_i (eq. 13): max cosine similarity between `state` and past states where
    /// maneuver i was executed; 0 when it never was (or a state is all zeros).
    pub fn d_prev(&self, state: &[f64; STATE_FEATURES]) -> [f64; MANEUVERS] {
        let mut d = [0.0; MANEUVERS];
        let mut seen = [false; MANEUVERS];
        for r in self.records() {
            let i = r.maneuver.index();
            let c = cosine(state, &r.state);
            if !seen[i] || c > d[i] {
                d[i] = c;
                seen[i] = true;
            }
        }
        d
    }
}

/// Cosine similarity; 0 when either vector is zero.
pub fn cosine(a: &[f64; STATE_FEATURES], b: &[f64; STATE_FEATURES]) -> f64 {
    let dot: f64 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na = sqrt(a.iter().map(|x| x * x).sum());
    let nb = sqrt(b.iter().map(|x| x * x).sum());
    if na < 1e-12 || nb < 1e-12 {
        0.0
    } else {
        (dot / (na * nb)).clamp(-1.0, 1.0)
    }
}

/// Corrected utilities Ṽ_i = V_i + γ·D_prev_i − λ·𝟙(i ≠ i_prev) (eq. 12, 14).
pub fn correct(
    utility: &[f64; MANEUVERS],
    d_prev: &[f64; MANEUVERS],
    previous: Option<Maneuver>,
    p: &ChoiceParams,
) -> [f64; MANEUVERS] {
    let mut v = [0.0; MANEUVERS];
    for (i, m) in Maneuver::ALL.iter().enumerate() {
        let switch = previous.is_some_and(|prev| prev != *m);
        v[i] = utility[i] + p.gamma * d_prev[i] - if switch { p.lambda } else { 0.0 };
    }
    v
}

/// Index of the largest value; ties go to the lowest index, and a NaN is never the largest
/// while a number is left (the core's step refuses non-finite probabilities before this).
pub fn argmax(p: &[f64; MANEUVERS]) -> Maneuver {
    let mut best = 0;
    for i in 1..MANEUVERS {
        if p[i] > p[best] || (p[best].is_nan() && !p[i].is_nan()) {
            best = i;
        }
    }
    Maneuver::ALL[best]
}

/// Target-speed factors at which a maneuver that goes is judged (see [`choose`]).
pub const TIMING_FACTORS: [f64; 3] = [1.0, 0.8, 0.6];

/// One maneuver at one timing, as [`choose`] judged it.
#[derive(Clone, Copy)]
struct Judged {
    profile: Profile,
    attributes: [f64; ATTRIBUTES],
    safety: f64,
    efficiency: f64,
    imposed: f64,
    rejected: bool,
}

/// Runs eq. 9–15 for one scene; `conflicts` holds the ego's conflicts with every agent and
/// `yields[k]` the probability that the other of `conflicts.pairs()[k]` lets the ego go first.
#[allow(clippy::too_many_arguments)]
pub fn choose(
    triplet: &OpmTriplet,
    conflicts: &ConflictSet,
    yields: &[f64],
    ctx: &EgoContext,
    history: &ChoiceHistory,
    opm: &OpmParams,
    ip: &InteractionParams,
    p: &ChoiceParams,
    out: &mut ChoiceOutcome,
) {
    let (ws, we) = preferences(triplet, conflicts, opm, p);
    out.safety_preference = ws;
    out.efficiency_preference = we;
    let a_idm = triplet
        .leader
        .map(|l| idm_accel(ctx.speed, l.gap_m, ctx.speed - l.speed_mps, p));
    let pairs = conflicts.pairs();
    // Every conflict free: a maneuver of the route that goes at its nominal timing (speeds up,
    // or takes the turn at the curve's speed) is free of risk and imposes nothing. "Keep speed"
    // does not count: at a crawl it passes behind everyone as surely as yielding does.
    let free_to_go = || {
        [
            Maneuver::Accelerate,
            Maneuver::TurnLeft,
            Maneuver::TurnRight,
        ]
        .into_iter()
        .filter(|m| m.consistent_with(ctx.route))
        .map(|m| profile(m, ctx, p))
        .filter(|prof| prof.target_speed >= 1.0)
        .any(|prof| {
            pairs.iter().zip(yields).all(|(c, &y)| {
                conflict_risk(&prof, ctx.speed, c, y, ip) < 0.01
                    && imposed_decel(&prof, ctx.speed, c, y, ip) <= ip.max_imposed_decel_mps2
            })
        })
    };
    // No reason to wait or slow: no leader that IDM would brake for, and nothing to yield to
    // or every conflict free. Then a profile that stops, creeps (below `creep_speed_mps`),
    // yields, or slows below the speed the ego may keep (its own, the desired speed and the
    // speed cap, whichever is lowest) is penalised, at any speed: the history terms of eq.
    // 12–14 would otherwise hold the ego in "decelerate" down to a standstill, or in "keep
    // speed" at a crawl, once the last conflict is gone.
    let idle = a_idm.is_none_or(|a| a > 0.0) && (ctx.yield_distance.is_infinite() || free_to_go());
    let keep = ctx.speed.min(p.desired_speed_mps).min(ctx.speed_cap);
    let slows = |prof: &Profile| {
        prof.yields()
            || prof.target_speed
                < IDLE_SPEED_MPS
                    .max(ip.creep_speed_mps)
                    .max(keep - SLOWING_MPS)
    };
    let wait = expected_wait(pairs, yields, opm, ip);
    for m in Maneuver::ALL {
        let i = m.index();
        let nominal = profile(m, ctx, p);
        // A maneuver that goes is judged at its best timing: its nominal target speed, or a
        // slower one that lets a crossing road user pass first (the planner samples around it).
        let timings = if m == Maneuver::Decelerate || nominal.target_speed < 1.0 {
            1
        } else {
            TIMING_FACTORS.len()
        };
        let mut best: Option<(f64, Judged)> = None;
        for factor in TIMING_FACTORS.iter().take(timings) {
            let prof = if *factor == 1.0 {
                nominal
            } else {
                toward(nominal.target_speed * factor, ctx, p)
            };
            let mut matching = 1.0;
            if let Some(a_idm) = a_idm {
                matching -=
                    p.idm_penalty_gain * (prof.accel - a_idm).max(0.0) / p.idm_comfort_decel_mps2;
            }
            if !m.consistent_with(ctx.route) {
                matching -= p.navigation_penalty;
            }
            if idle && slows(&prof) {
                matching -= p.idle_penalty;
            }
            let (mut risk, mut imposed) = (0.0_f64, 0.0_f64);
            for (c, &y) in pairs.iter().zip(yields) {
                risk = risk.max(conflict_risk(&prof, ctx.speed, c, y, ip));
                imposed = imposed.max(imposed_decel(&prof, ctx.speed, c, y, ip));
            }
            let rejected = imposed > ip.max_imposed_decel_mps2;
            let eff = efficiency(&prof, ctx, wait, p);
            let attributes = [matching, ws * (1.0 - risk), we * eff];
            let utility = p
                .beta
                .iter()
                .zip(&attributes)
                .map(|(b, x)| b * x)
                .sum::<f64>()
                - if rejected { ip.courtesy_penalty } else { 0.0 };
            if best.is_none_or(|(u, _)| utility > u + 1e-9) {
                best = Some((
                    utility,
                    Judged {
                        profile: prof,
                        attributes,
                        safety: 1.0 - risk,
                        efficiency: eff,
                        imposed,
                        rejected,
                    },
                ));
            }
        }
        let (utility, j) = best.expect("at least one timing");
        out.profiles[i] = j.profile;
        out.attributes[i] = j.attributes;
        out.safety[i] = j.safety;
        out.efficiency[i] = j.efficiency;
        out.imposed_decel[i] = j.imposed;
        out.courtesy_rejected[i] = j.rejected;
        out.utility[i] = utility;
    }
    softmax(&out.utility, &mut out.p_logit);
    out.state = state_features(triplet, ctx, opm, p);
    out.d_prev = history.d_prev(&out.state);
    out.utility_corrected = correct(&out.utility, &out.d_prev, history.previous, p);
    softmax(&out.utility_corrected, &mut out.p_corrected);
    out.choice = argmax(&out.p_corrected);
}
