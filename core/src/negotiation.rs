//! Deadlock resolution through the eHMI (§5: the eHMI closes the loop "from language to
//! behavior"; Fig. 6a shows the deadlock it breaks). When the ego and a conflicting road user
//! both wait before their conflict zones, the ego announces that it goes first, watches the
//! other for a reaction time, and goes if the other keeps waiting.
//!
//! Phases: `Idle` → (both waiting or creeping: speeds below `creep_speed_mps`, each within
//! [`NEAR_ZONE_M`] before its zone, the other neither committed nor moving off) `Waiting` →
//! (for `deadlock_after_s`) `Announced` (the decision announces "going first") → (the other
//! still waits after `watch_s`) `Going` (the other counts as yielding) → `Idle` once the ego
//! has left that conflict zone. The other moving off while the ego has not entered its zone
//! ends the negotiation at any phase: it took the way, and the ego gives way again.

use crate::opm::ConflictPair;
use crate::params::InteractionParams;

/// Both parties count as waiting for each other only this close to their zones, m.
pub const NEAR_ZONE_M: f64 = 25.0;
/// Acceleration from which a waiting road user is moving off, m/s².
const MOVING_OFF_MPS2: f64 = 0.5;

coded_enum! {
/// Phase of a deadlock negotiation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Phase {
    #[default]
    Idle = 0,
    /// Both wait; not yet for `deadlock_after_s`.
    Waiting = 1,
    /// The ego announced that it goes first and watches the other.
    Announced = 2,
    /// The other kept waiting: the ego goes.
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
}

fn moving_off(c: &ConflictPair, ip: &InteractionParams) -> bool {
    c.agent_speed_mps >= ip.creep_speed_mps || c.agent_accel_mps2 > MOVING_OFF_MPS2
}

fn waits(c: &ConflictPair, ip: &InteractionParams) -> bool {
    let d = c.agent_zone_m[0];
    d > 0.0 && d < NEAR_ZONE_M && !c.intent.committed && !moving_off(c, ip)
}

impl Negotiation {
    /// Advances the negotiation at time `now`, s, with the ego at `ego_speed` m/s; `conflicts`
    /// are the ego's conflicts (with each agent's track id from `id_of`).
    pub fn update(
        &mut self,
        conflicts: &[ConflictPair],
        id_of: impl Fn(u8) -> u32,
        ego_speed: f64,
        now: f64,
        ip: &InteractionParams,
    ) {
        let ego_waits = |c: &ConflictPair| {
            let d = c.ego_zone_m[0];
            ego_speed < ip.creep_speed_mps && d > 0.0 && d < NEAR_ZONE_M
        };
        let partner = conflicts
            .iter()
            .filter(|c| ego_waits(c) && waits(c, ip))
            .min_by(|a, b| a.ego_zone_m[0].total_cmp(&b.ego_zone_m[0]))
            .map(|c| id_of(c.agent));
        let current = conflicts.iter().find(|c| id_of(c.agent) == self.agent_id);
        let elapsed = now - self.since_s;
        let next = match self.phase {
            Phase::Idle => partner.map(|id| (Phase::Waiting, id)),
            Phase::Waiting => match partner {
                Some(id) if id == self.agent_id && elapsed >= ip.deadlock_after_s => {
                    Some((Phase::Announced, id))
                }
                Some(id) if id == self.agent_id => return,
                Some(id) => Some((Phase::Waiting, id)),
                None => None,
            },
            Phase::Announced | Phase::Going => match current {
                None => None,
                Some(c) if c.ego_zone_m[1] < 0.0 => None,
                Some(c) if moving_off(c, ip) && c.ego_zone_m[0] > 0.0 => None,
                Some(_) if self.phase == Phase::Announced && elapsed >= ip.watch_s => {
                    Some((Phase::Going, self.agent_id))
                }
                Some(_) => return,
            },
        };
        match next {
            Some((phase, id)) => {
                self.phase = phase;
                self.agent_id = id;
                self.since_s = now;
            }
            None => *self = Negotiation::default(),
        }
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
