//! Negotiation through the eHMI (§5: the eHMI closes the loop "from language to behavior";
//! Fig. 6a shows the deadlock it breaks). Two ways in, one way on:
//!
//! * **Deadlock.** When the ego and a conflicting road user both wait before their conflict
//!   zones (speeds below `creep_speed_mps`, each within [`NEAR_ZONE_M`] before its zone, the
//!   other neither committed nor moving off) for `deadlock_after_s`: `Idle` → `Waiting` →
//!   `Announced`.
//! * **Request.** When the ego, waiting or slowing down to give way within [`NEAR_ZONE_M`] of
//!   its zone, is held up by an approaching road user that could stop gently (at
//!   `request_decel_mps2` or less after `reaction_s`), and every other one still approaching
//!   could stop as gently or is committed (nobody is asked to brake hard): `Idle` →
//!   `Announced`. The one asked is the first to arrive (its earliest proceeding entry) of
//!   those that would enter before the ego, starting at its nominal acceleration, could have
//!   left its passage with `pet_go_s` to spare (nobody is asked without need).
//!
//! `Announced`: the decision announces "going first" and the ego watches the other. After
//! `watch_s` (a reaction time), one that gives way (standing or creeping, or braking as one
//! that yields: its implicit intent at least `trust_yield`) → `Going`: it counts as yielding,
//! and the plan may go first. One that speeds up or passes its point of no return, or that
//! after `watch_s` still comes on too fast to stop gently without having slowed by
//! [`COMPLYING_MPS2`] on average since the announcement, has refused: → `Idle`, the ego gives
//! way again and does not ask it again ([`REFUSALS`] remembered). `Going` → `Idle` once the
//! ego has left that conflict zone; the other speeding up by [`SPEEDING_UP_MPS`] or passing its
//! point of no return while the ego has not entered its zone, or the ego still standing
//! `deadlock_wait_s` after its turn came, ends it as a refusal.

use crate::choice::proceeding_interval;
use crate::opm::ConflictPair;
use crate::params::InteractionParams;
use crate::Announcement;
use libm::sqrt;

/// Both parties count as waiting for each other only this close to their zones, m.
pub const NEAR_ZONE_M: f64 = 25.0;
/// Acceleration from which a waiting road user is moving off, m/s².
const MOVING_OFF_MPS2: f64 = 0.5;
/// Speed gain since the ego announced from which the other is taking the way, m/s.
const SPEEDING_UP_MPS: f64 = 0.5;
/// Mean deceleration since the ego announced from which the other complies, m/s².
const COMPLYING_MPS2: f64 = 0.3;
/// How many refusals the negotiation remembers.
pub const REFUSALS: usize = 4;

coded_enum! {
/// Phase of a negotiation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Phase {
    #[default]
    Idle = 0,
    /// Both wait; not yet for `deadlock_after_s`.
    Waiting = 1,
    /// The ego announced that it goes first and watches the other.
    Announced = 2,
    /// The other gives way: the ego goes.
    Going = 3,
}
}

/// The negotiation with one road user at a time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Negotiation {
    pub phase: Phase,
    /// Track id of the road user negotiated with.
    pub agent_id: u32,
    /// When the current phase began, s.
    since_s: f64,
    /// The last [`REFUSALS`] road users that refused, or broke off, a negotiation: not asked
    /// again.
    refused: [Option<u32>; REFUSALS],
    /// The other's lowest speed since the ego announced, m/s.
    lowest_mps: f64,
    /// The other's speed when the ego announced, m/s.
    announced_mps: f64,
}

fn moving_off(c: &ConflictPair, ip: &InteractionParams) -> bool {
    c.agent_speed_mps >= ip.creep_speed_mps || c.agent_accel_mps2 > MOVING_OFF_MPS2
}

/// True when a zone `d` m ahead is within [`NEAR_ZONE_M`].
fn near(d: f64) -> bool {
    d > 0.0 && d < NEAR_ZONE_M
}

fn waits(c: &ConflictPair, ip: &InteractionParams) -> bool {
    near(c.agent_zone_m[0]) && !c.intent.committed && !moving_off(c, ip)
}

/// True when road user `c` approaches its zone, neither standing nor committed.
fn approaches(c: &ConflictPair, ip: &InteractionParams) -> bool {
    c.agent_zone_m[0] > 0.0 && c.agent_speed_mps >= ip.creep_speed_mps && !c.intent.committed
}

/// Deceleration road user `c` needs to stop before its zone after reacting for `reaction_s`,
/// m/s² (∞ when it cannot).
fn stop_decel(c: &ConflictPair, ip: &InteractionParams) -> f64 {
    let v = c.agent_speed_mps;
    let d = c.agent_zone_m[0] - v * ip.reaction_s;
    if d > 0.0 {
        v * v / (2.0 * d)
    } else {
        f64::INFINITY
    }
}

/// True when road user `c` approaches its zone and could still stop before it, but only
/// braking harder than `request_decel_mps2`: a message asking it to wait would ask it to brake
/// hard.
pub fn asked_hard(c: &ConflictPair, ip: &InteractionParams) -> bool {
    approaches(c, ip) && stop_decel(c, ip) > ip.request_decel_mps2
}

/// True when road user `c` gives way to the ego: standing or creeping, or braking as one that
/// yields (at least `trust_yield`).
fn gives_way(c: &ConflictPair, ip: &InteractionParams) -> bool {
    c.agent_speed_mps < ip.creep_speed_mps
        || (!c.intent.committed && c.intent.yielding >= ip.trust_yield)
}

/// True when road user `c`, whose speed was down to `lowest_mps` since the ego announced, takes
/// the way after all: past its point of no return, or [`SPEEDING_UP_MPS`] faster again (its
/// speed, not a noisy acceleration, says it).
fn takes_way(c: &ConflictPair, lowest_mps: f64) -> bool {
    c.intent.committed || c.agent_speed_mps > lowest_mps + SPEEDING_UP_MPS
}

/// What the negotiation needs of the ego.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EgoState {
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Acceleration it starts with, m/s² (the nominal one: `choice.accelerate_mps2`).
    pub accel_mps2: f64,
    /// Its last decision gave way.
    pub gives_way: bool,
}

impl Negotiation {
    /// Advances the negotiation at time `now`, s, with the ego at `ego.speed_mps`; `conflicts`
    /// are the ego's conflicts (with each agent's track id from `id_of`).
    pub fn update(
        &mut self,
        conflicts: &[ConflictPair],
        id_of: impl Fn(u8) -> u32,
        ego: &EgoState,
        now: f64,
        ip: &InteractionParams,
    ) {
        let ego_stands = ego.speed_mps < ip.creep_speed_mps;
        let ego_waits = |c: &ConflictPair| ego_stands && near(c.ego_zone_m[0]);
        let partner = conflicts
            .iter()
            .filter(|c| ego_waits(c) && waits(c, ip))
            .min_by(|a, b| a.ego_zone_m[0].total_cmp(&b.ego_zone_m[0]))
            .map(|c| id_of(c.agent));
        let current = conflicts.iter().find(|c| id_of(c.agent) == self.agent_id);
        if let Some(c) = current {
            self.lowest_mps = self.lowest_mps.min(c.agent_speed_mps);
        }
        let elapsed = now - self.since_s;
        let next = match self.phase {
            Phase::Idle => partner
                .map(|id| (Phase::Waiting, id))
                .or_else(|| self.request(conflicts, &id_of, ego, ip)),
            Phase::Waiting => match partner {
                Some(id) if id == self.agent_id && elapsed >= ip.deadlock_after_s => {
                    Some((Phase::Announced, id))
                }
                Some(id) if id == self.agent_id => return,
                Some(id) => Some((Phase::Waiting, id)),
                None => None,
            },
            Phase::Announced => match current {
                None => None,
                Some(c) if c.ego_zone_m[1] < 0.0 => None,
                Some(c) if elapsed >= ip.watch_s && gives_way(c, ip) => {
                    Some((Phase::Going, self.agent_id))
                }
                // One speeding up or past its point of no return has answered; so has one
                // that, watched, kept coming until it could no longer stop gently. One that has
                // slowed since the announcement by [`COMPLYING_MPS2`] on average complies, if
                // later or more gently than asked (a driver's IDM brakes harder near its line).
                Some(c)
                    if c.ego_zone_m[0] > 0.0
                        && (takes_way(c, self.lowest_mps)
                            || (elapsed >= ip.watch_s
                                && stop_decel(c, ip) > ip.request_decel_mps2
                                && self.announced_mps - c.agent_speed_mps
                                    < COMPLYING_MPS2 * elapsed)) =>
                {
                    self.refuse();
                    None
                }
                Some(_) => return,
            },
            Phase::Going => match current {
                None => None,
                Some(c) if c.ego_zone_m[1] < 0.0 => None,
                Some(c)
                    if c.ego_zone_m[0] > 0.0
                        && (takes_way(c, self.lowest_mps)
                            || (ego_stands && elapsed >= ip.deadlock_wait_s)) =>
                {
                    self.refuse();
                    None
                }
                Some(_) => return,
            },
        };
        match next {
            Some((phase, id)) => {
                // Going keeps the lowest speed watched since the announcement.
                if phase != Phase::Going {
                    self.lowest_mps = conflicts
                        .iter()
                        .find(|c| id_of(c.agent) == id)
                        .map_or(0.0, |c| c.agent_speed_mps);
                    self.announced_mps = self.lowest_mps;
                }
                self.phase = phase;
                self.agent_id = id;
                self.since_s = now;
            }
            None => {
                *self = Negotiation {
                    refused: self.refused,
                    ..Negotiation::default()
                }
            }
        }
    }

    /// Remembers that the road user negotiated with refused.
    fn refuse(&mut self) {
        self.refused.rotate_right(1);
        self.refused[0] = Some(self.agent_id);
    }

    /// The road user to ask to let the ego go first, if any (see the module's "Request").
    fn request(
        &self,
        conflicts: &[ConflictPair],
        id_of: &impl Fn(u8) -> u32,
        ego: &EgoState,
        ip: &InteractionParams,
    ) -> Option<(Phase, u32)> {
        let ego_asks = ego.speed_mps < ip.creep_speed_mps || ego.gives_way;
        let gentle = |c: &ConflictPair| stop_decel(c, ip) <= ip.request_decel_mps2;
        if conflicts
            .iter()
            .any(|c| c.ego_zone_m[0] > 0.0 && asked_hard(c, ip))
        {
            return None;
        }
        // The ego, starting now, leaves its passage no earlier than this.
        let ego_exit = |c: &ConflictPair| sqrt(2.0 * c.ego_pass_m[1].max(0.0) / ego.accel_mps2);
        conflicts
            .iter()
            .filter(|c| {
                ego_asks
                    && near(c.ego_zone_m[0])
                    && approaches(c, ip)
                    && gentle(c)
                    && !self.refused.contains(&Some(id_of(c.agent)))
            })
            .map(|c| (proceeding_interval(c, ip).0, c))
            .filter(|&(enters, c)| enters < ego_exit(c) + ip.pet_go_s)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, c)| (Phase::Announced, id_of(c.agent)))
    }

    /// True when the ego announces that it goes first.
    pub fn announces(&self) -> bool {
        matches!(self.phase, Phase::Announced | Phase::Going)
    }

    /// True when road user `id` has let the ego go first after its announcement.
    pub fn yielded(&self, id: u32) -> bool {
        self.phase == Phase::Going && self.agent_id == id
    }
}

/// What the eHMI shows ([`crate::Decision::announce`]). A change in what the executed plan
/// means is shown once it has held for `announce_settle_s`; the negotiation's own
/// announcement, a deliberate request, is shown at once. The plan is sampled anew every
/// cycle, and where its best sample passes just before or just behind a road user, what it
/// means can change from one cycle to the next: a display that followed it would flash
/// "going first" for 50 ms, and a driver who complied would brake for nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EhmiDisplay {
    shown: Option<Announcement>,
    meant: Announcement,
    /// When the plan began to mean `meant`, s.
    meant_since_s: f64,
}

impl EhmiDisplay {
    /// The announcement to show at `now`, s, when the plan means `meant` (`at_once` for the
    /// negotiation's announcement); the first one is shown at once.
    pub fn show(
        &mut self,
        meant: Announcement,
        now: f64,
        at_once: bool,
        ip: &InteractionParams,
    ) -> Announcement {
        if meant != self.meant {
            self.meant = meant;
            self.meant_since_s = now;
        }
        let settled = now - self.meant_since_s >= ip.announce_settle_s;
        let shown = match self.shown {
            Some(shown) if shown != meant && !at_once && !settled => shown,
            _ => meant,
        };
        self.shown = Some(shown);
        shown
    }
}
