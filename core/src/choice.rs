//! Maneuver choice: attributes x_i (matching, safety, efficiency), utility V_i = βᵀx_i (eq. 9),
//! multinomial logit P_ni (eq. 11), history consistency γ·D_prev (eq. 12–13), switch penalty λ
//! (eq. 14) and the corrected logit (eq. 15).

use libm::{exp, sqrt};

use crate::opm::{ConflictPair, ConflictSet, OpmTriplet};
use crate::params::{ChoiceParams, OpmParams};
use crate::saliency::softmax;
use crate::scene::{IntentAction, Style, Turn};

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
/// then hold it. Also the nominal terminal state f_a(s_start) of eq. 23.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Profile {
    /// m/s², signed.
    pub accel: f64,
    /// Terminal speed v_T, m/s.
    pub target_speed: f64,
    /// Duration T of the polynomial, s.
    pub duration: f64,
    /// True when the profile stops before a conflict zone.
    pub yields: bool,
}

impl Profile {
    /// Time to travel `d` m from speed `v0` under this profile; ∞ if it stops first.
    pub fn arrival_time(&self, v0: f64, d: f64) -> f64 {
        if d <= 0.0 {
            return 0.0;
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
}

/// What the choice stage needs to know about the ego's situation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EgoContext {
    /// Speed, m/s.
    pub speed: f64,
    /// Longitudinal acceleration, m/s².
    pub accel: f64,
    /// Speed cap from the road and the curvature ahead, m/s.
    pub speed_cap: f64,
    /// Distance to the point where a yielding ego must stop, m (∞ when nothing to yield to).
    pub yield_distance: f64,
    /// Navigation instruction: the turn of the route lane.
    pub route: Turn,
    /// Largest braking of planned trajectories, m/s².
    pub max_brake: f64,
    pub min_duration: f64,
    pub max_duration: f64,
}

/// Below this speed the ego counts as stopped for the idle penalty, m/s.
const IDLE_SPEED_MPS: f64 = 0.1;

/// Nominal profile of maneuver `m`.
pub fn profile(m: Maneuver, ctx: &EgoContext, p: &ChoiceParams) -> Profile {
    let v0 = ctx.speed;
    let h = p.maneuver_horizon_s;
    let cap = ctx.speed_cap.max(0.0);
    let toward = |target: f64| {
        let target = target.clamp(0.0, cap);
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
            duration: ramp.max(h).clamp(ctx.min_duration, ctx.max_duration),
            yields: false,
        }
    };
    match m {
        Maneuver::Accelerate => toward(v0 + p.accelerate_mps2 * h),
        Maneuver::KeepSpeed => toward(v0),
        Maneuver::TurnLeft | Maneuver::TurnRight => toward(cap),
        Maneuver::Decelerate => {
            let d = ctx.yield_distance;
            if d.is_finite() && d > 0.0 {
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
                    yields: true,
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
/// intensity. Priority task > action > style is carried by the gains' magnitudes.
pub fn preferences(triplet: &OpmTriplet, opm: &OpmParams, p: &ChoiceParams) -> (f64, f64) {
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
        match other.strong_action(th) {
            Some(IntentAction::Proceed | IntentAction::Accelerate) => ws += p.other_proceeds_safety,
            Some(IntentAction::Yield | IntentAction::Stop | IntentAction::Decelerate) => {
                we += p.other_yields_efficiency
            }
            _ => {}
        }
    }
    ws += p.conflict_intensity_safety * triplet.risky_conflicts(opm).count() as f64;
    (ws.max(0.1), we.max(0.1))
}

/// Safety degree of a profile in [0, 1]: 1 − max over conflicts of
/// exp(−Δt² / (2σ²)), Δt = |t_ego(profile) − TTC_agent|, σ = ΔT_th / 2.
pub fn safety_degree(
    profile: &Profile,
    ego_speed: f64,
    conflicts: &[ConflictPair],
    opm: &OpmParams,
) -> f64 {
    let sigma = opm.delta_ttc_threshold_s / 2.0;
    let mut risk: f64 = 0.0;
    for c in conflicts {
        if c.agent_ttc_s >= opm.ttc_max_s {
            continue;
        }
        let t_ego = profile.arrival_time(ego_speed, c.ego_dist_m);
        if !t_ego.is_finite() {
            continue;
        }
        let dt = t_ego - c.agent_ttc_s;
        risk = risk.max(exp(-dt * dt / (2.0 * sigma * sigma)));
    }
    1.0 - risk
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

/// Index of the largest value; ties go to the lowest index.
pub fn argmax(p: &[f64; MANEUVERS]) -> Maneuver {
    let mut best = 0;
    for i in 1..MANEUVERS {
        if p[i] > p[best] {
            best = i;
        }
    }
    Maneuver::ALL[best]
}

/// Runs eq. 9–15 for one scene; `conflicts` holds the ego's conflicts with every agent.
pub fn choose(
    triplet: &OpmTriplet,
    conflicts: &ConflictSet,
    ctx: &EgoContext,
    history: &ChoiceHistory,
    opm: &OpmParams,
    p: &ChoiceParams,
    out: &mut ChoiceOutcome,
) {
    let (ws, we) = preferences(triplet, opm, p);
    out.safety_preference = ws;
    out.efficiency_preference = we;
    let a_idm = triplet
        .leader
        .map(|l| idm_accel(ctx.speed, l.gap_m, ctx.speed - l.speed_mps, p));
    // Stopped, yielding to nothing, and free to move off (no leader, or one IDM would follow).
    let idle = ctx.speed < IDLE_SPEED_MPS
        && ctx.yield_distance.is_infinite()
        && a_idm.is_none_or(|a| a > 0.0);
    for m in Maneuver::ALL {
        let i = m.index();
        let prof = profile(m, ctx, p);
        out.profiles[i] = prof;
        let mut matching = 1.0;
        if let Some(a_idm) = a_idm {
            matching -=
                p.idm_penalty_gain * (prof.accel - a_idm).max(0.0) / p.idm_comfort_decel_mps2;
        }
        if !m.consistent_with(ctx.route) {
            matching -= p.navigation_penalty;
        }
        if idle && prof.target_speed < IDLE_SPEED_MPS {
            matching -= p.idle_penalty;
        }
        let safety = safety_degree(&prof, ctx.speed, conflicts.pairs(), opm);
        out.safety[i] = safety;
        let efficiency = (prof.target_speed / p.reference_speed_mps).clamp(0.0, 1.5);
        out.attributes[i] = [matching, ws * safety, we * efficiency];
        out.utility[i] = p
            .beta
            .iter()
            .zip(&out.attributes[i])
            .map(|(b, x)| b * x)
            .sum();
    }
    softmax(&out.utility, &mut out.p_logit);
    out.state = state_features(triplet, ctx, opm, p);
    out.d_prev = history.d_prev(&out.state);
    out.utility_corrected = correct(&out.utility, &out.d_prev, history.previous, p);
    softmax(&out.utility_corrected, &mut out.p_corrected);
    out.choice = argmax(&out.p_corrected);
}
