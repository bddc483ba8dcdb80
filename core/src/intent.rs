//! Implicit intents (§4.1: inferred "by integrating historical behavioral trajectories,
//! acceleration changes"): whether a road user in conflict with the ego is yielding,
//! proceeding or undecided, from its motion, fused with its explicit intent (eq. 8) only where
//! the two agree.
//!
//! Evidence, for a road user at speed v with `d` m to its conflict zone (where its footprint
//! would enter the ego's lane):
//! * inside its zone and moving: proceeding, committed;
//! * standing still before the zone: yielding with probability `standing_yield`, unless it
//!   is moving off (accelerating);
//! * moving: the deceleration it needs to stop before the zone, a_req = v² / 2d, against the
//!   deceleration it shows. It is *committed* when a_req exceeds the comfortable deceleration
//!   and it brakes less than a_req: it can no longer stop comfortably (its point of no return
//!   is behind it). Otherwise the share q = decel / a_req of the needed braking it applies
//!   makes it yielding (smoothly from q = 0.5 to 1), and acceleration makes it proceeding.
//!
//! The deceleration shown for yielding is the *lesser* of the reported acceleration's and the
//! 1 s speed trend's (a braking that both confirm), the acceleration shown for proceeding the
//! greater (noticed at once); a source that reports no acceleration (exactly 0) is read from
//! its speed trend alone.
//!
//! A stated "yield", "stop" or "decelerate" of sufficient confidence c moves c of the
//! undecided share to yielding, but only while the motion does not say proceeding (P < 0.5,
//! not committed); a stated "proceed" or "accelerate" moves c of it to proceeding (the
//! cautious reading, always allowed). No message can make the core believe the opposite of
//! what the road user does.

use crate::params::InteractionParams;
use crate::scene::{AgentState, ExplicitIntent, IntentAction, Track};

coded_enum! {
/// What became of a road user's stated action.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Stated {
    /// Nothing stated (or too weak to count).
    #[default]
    Nothing = 0,
    /// A stated yield, counted.
    Yield = 1,
    /// A stated proceed, counted.
    Proceed = 2,
    /// A stated yield its motion contradicts, ignored.
    Contradicted = 3,
}
}

/// The implicit intent of one road user towards the ego's path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImplicitIntent {
    /// Probability that it lets the ego go first (stops before its zone or keeps standing).
    pub yielding: f64,
    /// Probability that it goes through its zone first.
    pub proceeding: f64,
    /// The rest: it may still do either.
    pub undecided: f64,
    /// It can no longer stop comfortably before its zone, or is in it.
    pub committed: bool,
    /// Deceleration it needs to stop before its zone, m/s² (0 standing, ∞ inside).
    pub required_decel_mps2: f64,
    /// How long it has stood still, s (0 when moving).
    pub standing_s: f64,
    pub stated: Stated,
}

impl Default for ImplicitIntent {
    fn default() -> Self {
        ImplicitIntent {
            yielding: 0.0,
            proceeding: 0.0,
            undecided: 1.0,
            committed: false,
            required_decel_mps2: 0.0,
            standing_s: 0.0,
            stated: Stated::Nothing,
        }
    }
}

/// Kinematics read from a road user's state and history.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    /// Speed, m/s.
    pub speed: f64,
    /// Deceleration both the report and the trend confirm, m/s² (≥ 0).
    pub decel: f64,
    /// Acceleration shown by either, m/s².
    pub accel: f64,
    /// Time stood still, s.
    pub standing_s: f64,
}

/// Smallest span of history for a speed trend, s.
const TREND_MIN_SPAN_S: f64 = 0.3;
/// Span of the speed trend, s.
const TREND_SPAN_S: f64 = 1.0;
/// Acceleration from which a standing road user is moving off, m/s².
const MOVING_OFF_MPS2: f64 = 0.5;

impl Motion {
    /// The motion of `agent` at time `now`, s, with its history `track`.
    pub fn of(agent: &AgentState, track: Option<&Track>, now: f64, p: &InteractionParams) -> Self {
        let speed = agent.speed();
        let reported = agent.longitudinal_accel();
        let (decel, accel) = match (speed_trend(agent, track, now), reported == 0.0) {
            (Some(t), true) => ((-t).max(0.0), t),
            (Some(t), false) => ((-t).min(-reported).max(0.0), t.max(reported)),
            (None, _) => ((-reported).max(0.0), reported),
        };
        let mut standing_since = None;
        if let Some(t) = track {
            for h in t.iter() {
                if h.vel.norm() < p.standing_speed_mps {
                    standing_since.get_or_insert(h.time_s);
                } else {
                    standing_since = None;
                }
            }
        }
        let standing_s = if speed < p.standing_speed_mps {
            standing_since.map_or(0.0, |t0| (now - t0).max(0.0))
        } else {
            0.0
        };
        Motion {
            speed,
            decel,
            accel,
            standing_s,
        }
    }
}

/// Speed trend of `agent` over the last [`TREND_SPAN_S`] of its history, m/s² (`None` with
/// less than [`TREND_MIN_SPAN_S`] of it).
fn speed_trend(agent: &AgentState, track: Option<&Track>, now: f64) -> Option<f64> {
    let old = track?.sample_ago(now, TREND_SPAN_S)?;
    let span = now - old.time_s;
    (span >= TREND_MIN_SPAN_S).then(|| (agent.speed() - old.vel.norm()) / span)
}

/// Acceleration of `agent` along its travel now, m/s², for its forecast: the reported one, or
/// the braking its speed trend shows when the source reports none (exactly 0; 0 without a
/// trend). A trend's speeding up is not extrapolated: read from a car behind the ego, it
/// would drive that car into every plan.
pub fn current_accel(agent: &AgentState, track: Option<&Track>, now: f64) -> f64 {
    match agent.longitudinal_accel() {
        0.0 => speed_trend(agent, track, now).map_or(0.0, |t| t.min(0.0)),
        reported => reported,
    }
}

/// Hermite smoothstep of `x` from 0 at `lo` to 1 at `hi`.
fn smoothstep(x: f64, lo: f64, hi: f64) -> f64 {
    let u = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    u * u * (3.0 - 2.0 * u)
}

/// Infers the implicit intent of a road user with `motion`, `to_zone_m` m from its centre to
/// where it enters its conflict zone, and its explicit `stated` intent (counted when at least
/// `confidence_min`).
pub fn infer(
    motion: &Motion,
    to_zone_m: f64,
    stated: &ExplicitIntent,
    confidence_min: f64,
    p: &InteractionParams,
) -> ImplicitIntent {
    let v = motion.speed;
    let d = to_zone_m;
    let mut out = ImplicitIntent {
        standing_s: motion.standing_s,
        ..ImplicitIntent::default()
    };
    let (y, pr) = if d <= 0.0 {
        // In the zone: it is in the ego's path whatever it intends.
        out.committed = true;
        out.required_decel_mps2 = f64::INFINITY;
        (0.0, 1.0)
    } else if v < p.standing_speed_mps {
        if motion.accel > MOVING_OFF_MPS2 {
            (0.1, 0.6)
        } else {
            (p.standing_yield, 0.0)
        }
    } else {
        let a_req = v * v / (2.0 * d);
        out.required_decel_mps2 = a_req;
        if a_req > p.comfort_decel_mps2 && motion.decel < 0.9 * a_req {
            out.committed = true;
            (0.0, 0.95)
        } else {
            let q = motion.decel / a_req.max(0.3);
            let y = smoothstep(q, 0.5, 1.0);
            let accelerating = smoothstep(motion.accel, 0.2, 1.0);
            (0.9 * y, (1.0 - y) * (0.3 + 0.6 * accelerating))
        }
    };
    out.yielding = y;
    out.proceeding = pr;
    out.undecided = (1.0 - y - pr).max(0.0);
    if let Some(action) = stated.action.filter(|a| a.confidence >= confidence_min) {
        let c = action.confidence.clamp(0.0, 1.0);
        match action.value {
            IntentAction::Yield | IntentAction::Stop | IntentAction::Decelerate => {
                if out.committed || out.proceeding >= 0.5 {
                    out.stated = Stated::Contradicted;
                } else {
                    out.yielding += c * out.undecided;
                    out.undecided *= 1.0 - c;
                    out.stated = Stated::Yield;
                }
            }
            IntentAction::Proceed | IntentAction::Accelerate => {
                out.proceeding += c * out.undecided;
                out.undecided *= 1.0 - c;
                out.stated = Stated::Proceed;
            }
            IntentAction::TurnLeft | IntentAction::TurnRight => {}
        }
    }
    out
}
