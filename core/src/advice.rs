//! The gate on the LLM's recommendation A_final (eq. 16). Advice replaces the logit choice only
//! when it answers a request still in the request log, its confidence is ≥ 0.7, it was
//! published before that request's deadline, the corrected logit keeps the maneuver plausible
//! (P_n ≥ `prune_below`: the advice refines the choice, it does not override it), and the
//! maneuver passes the core's own navigation and safety checks. Otherwise the logit choice
//! stands and the reason is recorded. The deadline is judged by the advice's publish stamp, so
//! an answer published in time counts even when the core reads it at a later tick. Accepted
//! advice applies until its request's deadline: after it, the same advice is refused as
//! expired (it is still judged once when the first cycle to see it comes after the deadline).

use crate::choice::{Maneuver, MANEUVERS};
use crate::params::AdviceParams;
use crate::scene::Turn;

/// Capacity of the request log. The core issues a request at most every
/// `0.5 × advice.request_period_s`, so the log spans at least that times `MAX_PENDING − 1` in
/// time, whatever the loop rate; `Params::validate` holds `advice.deadline_s` within it.
pub const MAX_PENDING: usize = 256;

/// Share of `advice.request_period_s` after which the next request is due: with scenes at
/// that period, a frame that arrives early (jitter, the loop's tick) still issues one.
pub const REQUEST_DUE_SHARE: f64 = 0.5;

/// Advice as received from the sidecar, with the sidecar's publish stamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Advice {
    /// The request it answers (the cycle number that issued it).
    pub request_id: u64,
    /// A_final.
    pub maneuver: Maneuver,
    /// Confidence in [0, 1].
    pub confidence: f64,
    /// When the sidecar published it, on the core's clock (`CLOCK_MONOTONIC`), s.
    pub published_at_s: f64,
}

coded_enum! {
/// What the gate made of the advice this cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AdviceVerdict {
    /// No advice was offered.
    #[default]
    NoAdvice = 0,
    /// Applied: the decision follows A_final.
    Accepted = 1,
    /// Confidence outside [0, 1], an unknown maneuver or intent code, an intent confidence
    /// outside [0, 1], or a publish stamp that is not finite, lies in the future, or precedes
    /// its request.
    Malformed = 2,
    /// Answers no request in the log (one of the last 256, or never issued).
    UnknownRequest = 3,
    /// Confidence below the threshold.
    LowConfidence = 4,
    /// Published after the request's deadline.
    Late = 5,
    /// A turn against the navigation instruction.
    NavigationInconsistent = 6,
    /// No feasible collision-free trajectory realises it.
    Unsafe = 7,
    /// Judged before, and its request's deadline has passed.
    Expired = 8,
    /// The corrected logit gives the maneuver P_n below `prune_below`.
    Implausible = 9,
}
}

impl AdviceVerdict {
    /// Every verdict, by wire code.
    pub const ALL: [AdviceVerdict; 10] = [
        AdviceVerdict::NoAdvice,
        AdviceVerdict::Accepted,
        AdviceVerdict::Malformed,
        AdviceVerdict::UnknownRequest,
        AdviceVerdict::LowConfidence,
        AdviceVerdict::Late,
        AdviceVerdict::NavigationInconsistent,
        AdviceVerdict::Unsafe,
        AdviceVerdict::Expired,
        AdviceVerdict::Implausible,
    ];
    /// snake_case name.
    pub fn name(self) -> &'static str {
        match self {
            AdviceVerdict::NoAdvice => "no_advice",
            AdviceVerdict::Accepted => "accepted",
            AdviceVerdict::Malformed => "malformed",
            AdviceVerdict::UnknownRequest => "unknown_request",
            AdviceVerdict::LowConfidence => "low_confidence",
            AdviceVerdict::Late => "late",
            AdviceVerdict::NavigationInconsistent => "navigation_inconsistent",
            AdviceVerdict::Unsafe => "unsafe",
            AdviceVerdict::Expired => "expired",
            AdviceVerdict::Implausible => "implausible",
        }
    }
}

/// The last [`MAX_PENDING`] advice requests: id (the cycle that issued it) and issue time.
#[derive(Clone, Copy, Debug)]
pub struct RequestLog {
    ids: [u64; MAX_PENDING],
    issued_at_s: [f64; MAX_PENDING],
    /// Slot the next request goes to.
    next: usize,
}

impl Default for RequestLog {
    fn default() -> Self {
        RequestLog {
            ids: [0; MAX_PENDING],
            issued_at_s: [f64::NAN; MAX_PENDING],
            next: 0,
        }
    }
}

impl RequestLog {
    fn newest(&self) -> usize {
        (self.next + MAX_PENDING - 1) % MAX_PENDING
    }
    /// Id of the newest request, 0 before the first.
    pub fn latest(&self) -> u64 {
        self.ids[self.newest()]
    }
    /// Whether a request is due at `now`: none yet (its time is NaN), or
    /// `REQUEST_DUE_SHARE × period_s` since the newest (or the clock went back), s.
    pub fn due(&self, now: f64, period_s: f64) -> bool {
        let last = self.issued_at_s[self.newest()];
        !(now - last < REQUEST_DUE_SHARE * period_s && now >= last)
    }
    /// Logs request `id` (greater than every id logged before) issued at `now`.
    pub fn issue(&mut self, id: u64, now: f64) {
        self.ids[self.next] = id;
        self.issued_at_s[self.next] = now;
        self.next = (self.next + 1) % MAX_PENDING;
    }
    /// Issue time of request `id` while it is among the last [`MAX_PENDING`] requests.
    pub fn issued_at(&self, id: u64) -> Option<f64> {
        if id == 0 || id > self.latest() {
            return None;
        }
        // Newest first; ids only grow, so the search ends at the first smaller one.
        (1..=MAX_PENDING)
            .map(|back| (self.next + MAX_PENDING - back) % MAX_PENDING)
            .map(|slot| (self.ids[slot], self.issued_at_s[slot]))
            .take_while(|&(logged, _)| logged >= id)
            .find(|&(logged, _)| logged == id)
            .map(|(_, at)| at)
    }
}

/// What the gate weighs the advice against this cycle.
#[derive(Clone, Copy, Debug)]
pub struct GateContext<'a> {
    pub log: &'a RequestLog,
    /// The navigation instruction.
    pub route: Turn,
    /// The core's clock, s.
    pub now: f64,
    /// True when no earlier cycle judged this advice.
    pub first_look: bool,
    /// The corrected logit's P_n (eq. 15), in `Maneuver` order.
    pub p_corrected: &'a [f64; MANEUVERS],
}

/// Checks of eq. 16 that need no trajectory, in order; `Ok` means only the safety check remains.
pub fn pre_check(
    advice: &Advice,
    g: &GateContext,
    p: &AdviceParams,
) -> Result<Maneuver, AdviceVerdict> {
    let published = advice.published_at_s;
    if !(0.0..=1.0).contains(&advice.confidence) || !published.is_finite() || published > g.now {
        return Err(AdviceVerdict::Malformed);
    }
    let issued = g
        .log
        .issued_at(advice.request_id)
        .ok_or(AdviceVerdict::UnknownRequest)?;
    if published < issued {
        return Err(AdviceVerdict::Malformed);
    }
    let deadline = issued + p.deadline_s;
    if g.now > deadline && !g.first_look {
        return Err(AdviceVerdict::Expired);
    }
    if advice.confidence < p.confidence_min {
        return Err(AdviceVerdict::LowConfidence);
    }
    if published > deadline {
        return Err(AdviceVerdict::Late);
    }
    if !advice.maneuver.consistent_with(g.route) {
        return Err(AdviceVerdict::NavigationInconsistent);
    }
    let pn = g.p_corrected[advice.maneuver.index()];
    if pn.is_nan() || pn < p.prune_below {
        return Err(AdviceVerdict::Implausible);
    }
    Ok(advice.maneuver)
}

/// The whole gate: [`pre_check`], then `is_safe` (the core's feasibility and collision check).
pub fn gate(
    advice: Option<&Advice>,
    g: &GateContext,
    p: &AdviceParams,
    is_safe: impl FnOnce(Maneuver) -> bool,
) -> (Option<Maneuver>, AdviceVerdict) {
    let Some(advice) = advice else {
        return (None, AdviceVerdict::NoAdvice);
    };
    match pre_check(advice, g, p) {
        Err(v) => (None, v),
        Ok(m) if is_safe(m) => (Some(m), AdviceVerdict::Accepted),
        Ok(_) => (None, AdviceVerdict::Unsafe),
    }
}
