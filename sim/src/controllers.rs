//! Controllers of the CAV, behind one interface ([`Controller`]): each step it sees the world
//! with every HDV (and, for the oracle only, the human drivers' minds) and returns the CAV's
//! acceleration along its route and the eHMI message it shows, if any.
//!
//! * [`IdmYield`], the paper's conservative baseline: IDM car-following, treating the zone of
//!   every HDV that has neither passed it nor is at least `clear_gap_s` (6 s) away as a stop
//!   line (the nearest one binds), until the CAV has passed that HDV's conflict point; once it
//!   can no longer stop comfortably before the nearest zone while every HDV has passed or is
//!   far, it is committed and yields no more.
//! * [`Stackelberg`], game-theoretic: the CAV leads, every HDV follows. Every 0.5 s the CAV
//!   picks an acceleration from {−3, −1.5, 0, 1, 2} m/s², predicting for each every HDV's best
//!   response from the same set (each on its own, against the CAV alone), all held for a 4 s
//!   horizon; each side's payoff is `progress / horizon − 0.05 a² − 100 · overlap − 10 ·
//!   close`, where `overlap` is 1 when the CAV and that HDV would be in its conflict zone at
//!   once and `close` is 1 when one would enter less than 1.5 s after the other left. The
//!   leader pays the penalties of every HDV that has not passed its zone (and whose zone it
//!   has not passed), counts an overlap or a close call also when an HDV would simply hold its
//!   current acceleration (a human need not play the best response), and pays `0.05 Δa²` for
//!   changing its acceleration. Ties go to the gentler acceleration. Deterministic.
//! * [`GapAcceptance`]: stops at the entry of the conflict zone (IDM towards a stopped virtual
//!   leader there) and goes when the gap, the time until the next HDV reaches its zone after
//!   every HDV in a zone has left it (or from now when none is in one), is at least
//!   `min_gap_s` (4 s), entering only once no HDV is in a zone; committed once it has gone and
//!   can no longer stop comfortably before the zone (or is in it). An HDV's arrival is at its current speed, or at its current acceleration while it
//!   speeds up (so one moving off is seen coming); one that stands (below 0.1 m/s) does not
//!   arrive, and a braking one is taken to keep its speed (the acceleration of one braking to a
//!   stop says little of whether it will, and reading it made the decision flicker with the
//!   driver's noise). One in the zone leaves at its current speed (at least 0.5 m/s).
//! * [`ConcordController`], the decision core's step (the same as `concord run`) on a scene with
//!   every HDV: logit-only, or with an [`Advisor`]: the oracle, which rolls every
//!   route-consistent maneuver out for 8 s under a copy of every human driver (who hear the
//!   matching eHMI message) and advises the fastest one without conflict, with confidence 1;
//!   the core's gate and safety veto still apply. Both show the eHMI message of each decision
//!   (`ehmi_of`), as the onboard sidecar announces every decision.
//! * [`ExternalAdvice`]: Concord advised from outside the simulation (an LLM through the
//!   sidecar's prompts, see `concord experiment paper --llm`), with simulated time either
//!   waiting for each answer or letting it land after its measured latency.

use concord_core::advice::Advice;
use concord_core::scene::Turn;
use concord_core::{Announcement, Decision, DecisionCore, Maneuver, Params};

use crate::driver::{idm, DriverParams, DriverStyle, HumanDriver, Signal};
use crate::world::{World, DT};

/// What the CAV does in the next step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Command {
    /// Acceleration along the route, m/s².
    pub accel: f64,
    /// The eHMI message shown, if the controller has one.
    pub ehmi: Option<Signal>,
}

/// A CAV controller.
pub trait Controller {
    /// The command for the next step. `drivers` are the HDVs' drivers, in the world's order;
    /// only the oracle looks at them.
    fn act(&mut self, w: &World, drivers: &[HumanDriver]) -> Command;
}

/// The CAV's own IDM parameters (a balanced driver's).
fn cav_params() -> DriverParams {
    DriverParams::of(DriverStyle::Balanced)
}

/// Time constant with which a baseline closes on the curve speed limit, s.
const CURVE_TAU_S: f64 = 0.5;

/// `accel`, limited so that the CAV takes the curves ahead at no more lateral acceleration
/// than Concord's planner allows ([`World::ego_speed_limit`] at the CAV's comfortable
/// braking): every controller drives the same car.
fn within_curves(w: &World, accel: f64) -> f64 {
    let limit = w.ego_speed_limit(cav_params().b_comf);
    accel.min((limit - w.ego.v) / CURVE_TAU_S)
}

/// Conservative IDM with yielding at the conflict zones.
#[derive(Clone, Debug)]
pub struct IdmYield {
    desired_mps: f64,
    clear_gap_s: f64,
    committed: bool,
}

impl IdmYield {
    pub fn new(initial_speed: f64) -> Self {
        IdmYield {
            desired_mps: initial_speed.max(6.0),
            clear_gap_s: 6.0,
            committed: false,
        }
    }
}

impl Controller for IdmYield {
    fn act(&mut self, w: &World, _: &[HumanDriver]) -> Command {
        let p = cav_params();
        let mut entry = f64::INFINITY;
        let mut all_gone = true;
        let mut stop_line = None::<f64>;
        for (i, h) in w.hdvs.iter().enumerate() {
            let (ego_d, hdv_d) = w.to_conflict(i);
            let hdv_entry = ego_d - h.zone_half_m;
            let hdv_clear = hdv_d < -h.zone_half_m;
            let hdv_far = hdv_d - h.zone_half_m > self.clear_gap_s * h.car.v.max(0.5);
            entry = entry.min(hdv_entry);
            all_gone &= hdv_clear || hdv_far;
            if !hdv_clear && !hdv_far && hdv_entry > -h.zone_half_m {
                stop_line = Some(stop_line.map_or(hdv_entry, |s| s.min(hdv_entry)));
            }
        }
        if entry < w.ego.v * w.ego.v / (2.0 * p.b_comf) && all_gone {
            self.committed = true;
        }
        let (gap, v_lead) = w.ego_leader();
        let follow = idm(w.ego.v, self.desired_mps, gap, v_lead, &p);
        let accel = match stop_line.filter(|_| !self.committed) {
            Some(line) => idm(w.ego.v, self.desired_mps, line.max(0.1), 0.0, &p).min(follow),
            None => follow,
        };
        Command {
            accel: within_curves(w, accel),
            ehmi: None,
        }
    }
}

/// Leader–follower game, decided every [`GAME_PERIOD_S`] and held in between.
#[derive(Clone, Debug, Default)]
pub struct Stackelberg {
    held: f64,
    next_decision_s: f64,
}

/// How often the game is played, s (a receding horizon; drivers do not re-decide at 20 Hz).
pub const GAME_PERIOD_S: f64 = 0.5;

const ACCELS: [f64; 5] = [-3.0, -1.5, 0.0, 1.0, 2.0];
const HORIZON_S: f64 = 4.0;

/// (progress of the ego, of HDV `i`, both in its zone at once, too close in time) for
/// constant accelerations over the horizon.
fn predict(w: &World, i: usize, a_c: f64, a_h: f64) -> (f64, f64, bool, bool) {
    let dt = 0.25;
    let zone = w.hdvs[i].zone_half_m;
    let (mut ec, mut hc) = w.to_conflict(i);
    let (mut vc, mut vh) = (w.ego.v, w.hdvs[i].car.v);
    let (mut pc, mut ph) = (0.0, 0.0);
    let brake = cav_params().b_comf;
    let mut overlap = false;
    let (mut c_left, mut h_left, mut c_in, mut h_in) = (None, None, None, None);
    let mut t = 0.0;
    while t < HORIZON_S {
        // The leader's own speed also keeps to the curves (see `within_curves`).
        let limit = w.ego_speed_limit_at(w.ego.s + pc, brake);
        let (nc, nh) = (
            (vc + a_c * dt)
                .clamp(0.0, 14.0)
                .min(limit.max(vc.min(limit))),
            (vh + a_h * dt).clamp(0.0, 14.0),
        );
        let (dc, dh) = (0.5 * (vc + nc) * dt, 0.5 * (vh + nh) * dt);
        ec -= dc;
        hc -= dh;
        pc += dc;
        ph += dh;
        vc = nc;
        vh = nh;
        t += dt;
        let ci = ec.abs() < zone;
        let hi = hc.abs() < zone;
        overlap |= ci && hi;
        if ci && c_in.is_none() {
            c_in = Some(t);
        }
        if hi && h_in.is_none() {
            h_in = Some(t);
        }
        if ec < -zone && c_left.is_none() {
            c_left = Some(t);
        }
        if hc < -zone && h_left.is_none() {
            h_left = Some(t);
        }
    }
    let close = matches!((c_left, h_in), (Some(l), Some(i)) if i > l && i - l < 1.5)
        || matches!((h_left, c_in), (Some(l), Some(i)) if i > l && i - l < 1.5);
    (pc, ph, overlap, close)
}

/// A side's payoff: its progress rate and comfort, minus the penalties of each (overlap,
/// close call).
fn payoff(progress: f64, a: f64, risks: &[(bool, bool)]) -> f64 {
    risks
        .iter()
        .fold(progress / HORIZON_S - 0.05 * a * a, |u, &(o, c)| {
            u - 100.0 * f64::from(o as u8) - 10.0 * f64::from(c as u8)
        })
}

impl Controller for Stackelberg {
    fn act(&mut self, w: &World, _: &[HumanDriver]) -> Command {
        let open: Vec<usize> = (0..w.hdvs.len())
            .filter(|&i| {
                let (ego_d, hdv_d) = w.to_conflict(i);
                let zone = w.hdvs[i].zone_half_m;
                ego_d >= -zone && hdv_d >= -zone
            })
            .collect();
        if open.is_empty() {
            // Every conflict is resolved: drive on (behind the HDV in the merge) up to the
            // game's top speed.
            let (gap, v_lead) = w.ego_leader();
            return Command {
                accel: within_curves(w, idm(w.ego.v, 14.0, gap, v_lead, &cav_params())),
                ehmi: None,
            };
        }
        if w.t + 1e-9 < self.next_decision_s {
            return Command {
                accel: within_curves(w, self.held),
                ehmi: None,
            };
        }
        self.next_decision_s = w.t + GAME_PERIOD_S;
        let mut best = (f64::NEG_INFINITY, 0.0_f64);
        for a_c in ACCELS {
            let mut progress = 0.0;
            let mut risks = Vec::with_capacity(open.len());
            for &i in &open {
                let response = ACCELS
                    .iter()
                    .map(|&a_h| {
                        let (_, ph, o, c) = predict(w, i, a_c, a_h);
                        (payoff(ph, a_h, &[(o, c)]), -a_h.abs(), a_h)
                    })
                    .max_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)))
                    .map(|r| r.2)
                    .unwrap_or(0.0);
                let (pc, _, o, c) = predict(w, i, a_c, response);
                // A human may not play the best response: the leader also guards against the
                // HDV simply holding its current acceleration.
                let (_, _, o_hold, c_hold) = predict(w, i, a_c, w.hdvs[i].car.a);
                progress = pc;
                risks.push((o || o_hold, c || c_hold));
            }
            // Comfort: a change of acceleration costs as the acceleration does (no chattering).
            let change = a_c - w.ego.a;
            let u = payoff(progress, a_c, &risks) - 0.05 * change * change;
            if u > best.0 + 1e-9 || (u > best.0 - 1e-9 && a_c.abs() < best.1.abs()) {
                best = (u, a_c);
            }
        }
        self.held = best.1;
        Command {
            accel: within_curves(w, best.1),
            ehmi: None,
        }
    }
}

/// Gap acceptance at the entry of the conflict zone.
#[derive(Clone, Debug)]
pub struct GapAcceptance {
    desired_mps: f64,
    /// Smallest gap accepted, s.
    pub min_gap_s: f64,
    /// The last step's decision to go.
    going: bool,
    committed: bool,
}

impl GapAcceptance {
    pub fn new(initial_speed: f64) -> Self {
        GapAcceptance {
            desired_mps: initial_speed.max(6.0),
            min_gap_s: 4.0,
            going: false,
            committed: false,
        }
    }

    /// The gap now (see the module docs), s; infinite when no HDV is left to come.
    pub fn gap_s(w: &World) -> f64 {
        let mut leave: f64 = 0.0;
        let mut arrive = f64::INFINITY;
        for (i, h) in w.hdvs.iter().enumerate() {
            let (_, d) = w.to_conflict(i);
            let (v, a, zone) = (h.car.v, h.car.a, h.zone_half_m);
            if d.abs() <= zone {
                leave = leave.max((d + zone) / v.max(0.5));
            } else if d > zone {
                arrive = arrive.min(arrival_s(d - zone, v, a));
            }
        }
        arrive - leave
    }
}

/// Below this speed an HDV stands and does not arrive, for gap acceptance, m/s.
const GAP_STANDING_MPS: f64 = 0.1;

/// Time for an HDV at speed `v` and acceleration `a` to cover `d` m, s: at constant
/// acceleration while it speeds up, else at constant speed; infinite while it stands.
fn arrival_s(d: f64, v: f64, a: f64) -> f64 {
    if v < GAP_STANDING_MPS {
        f64::INFINITY
    } else if a > 0.0 {
        ((v * v + 2.0 * a * d).sqrt() - v) / a
    } else {
        d / v
    }
}

impl Controller for GapAcceptance {
    fn act(&mut self, w: &World, _: &[HumanDriver]) -> Command {
        let p = cav_params();
        // The nearest zone entry of an HDV that has not passed, before the CAV's centre has
        // passed that HDV's conflict point.
        let entry = (0..w.hdvs.len())
            .filter_map(|i| {
                let (ego_d, hdv_d) = w.to_conflict(i);
                let zone = w.hdvs[i].zone_half_m;
                (ego_d > 0.0 && hdv_d >= -zone).then_some(ego_d - zone)
            })
            .fold(None, |m: Option<f64>, e| Some(m.map_or(e, |m| m.min(e))));
        let occupied = (0..w.hdvs.len()).any(|i| w.to_conflict(i).1.abs() <= w.hdvs[i].zone_half_m);
        let go = !occupied && Self::gap_s(w) >= self.min_gap_s;
        if (go || self.going) && entry.is_some_and(|e| e < w.ego.v * w.ego.v / (2.0 * p.b_comf)) {
            self.committed = true;
        }
        self.going = go;
        let (gap, v_lead) = w.ego_leader();
        let follow = idm(w.ego.v, self.desired_mps, gap, v_lead, &p);
        let accel = match entry.filter(|_| !go && !self.committed) {
            Some(e) => idm(w.ego.v, self.desired_mps, e.max(0.1), 0.0, &p).min(follow),
            None => follow,
        };
        Command {
            accel: within_curves(w, accel),
            ehmi: None,
        }
    }
}

/// Who advises the core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Advisor {
    /// Nobody: logit-only.
    None,
    /// Rollouts under the true driver models; upper bound.
    Oracle,
}

/// The eHMI message of a decision: the core's own announcement (`Decision::announce`: "I am
/// going first" when its plan enters a driver's passage before the driver has left it, or
/// while a deadlock negotiation has announced it; "please go ahead" otherwise). Every Concord
/// controller speaks through this one function.
fn ehmi_of(d: &Decision) -> Option<Signal> {
    Some(Signal::announcing(d.announce == Announcement::GivingWay))
}

/// The decision core as a controller.
#[derive(Clone, Debug)]
pub struct ConcordController {
    core: Box<DecisionCore>,
    advisor: Advisor,
    last_request: Option<u64>,
    /// The newest decision.
    pub last: Option<Decision>,
    /// Decisions taken by source (`DecisionSource` code).
    pub sources: [u64; 3],
}

impl ConcordController {
    pub fn new(params: Params, w: &World, advisor: Advisor) -> Self {
        ConcordController {
            core: Box::new(DecisionCore::new(params, w.morph).expect("valid parameters")),
            advisor,
            last_request: None,
            last: None,
            sources: [0; 3],
        }
    }

    /// The decision core (its OPM triplet describes the newest decision's scene).
    pub fn core(&self) -> &DecisionCore {
        &self.core
    }

    /// One core step with `advice`; the eHMI shows the decision.
    fn step_with(&mut self, w: &World, advice: Option<&Advice>) -> Command {
        let Ok(d) = self.core.step(&w.scene(), w.t, advice) else {
            return Command {
                accel: -crate::world::MAX_BRAKE_MPS2,
                ehmi: None,
            };
        };
        self.last_request = Some(d.request_id);
        self.last = Some(d);
        self.sources[d.source as usize] += 1;
        let accel = d
            .trajectory
            .sample(DT)
            .map_or(-3.0, |p| (p.speed - w.ego.v) / DT);
        Command {
            accel,
            ehmi: ehmi_of(&d),
        }
    }
}

impl Controller for ConcordController {
    fn act(&mut self, w: &World, drivers: &[HumanDriver]) -> Command {
        let advice = match (self.advisor, self.last_request) {
            (Advisor::Oracle, Some(id)) => Some(Advice {
                request_id: id,
                maneuver: oracle(w, drivers),
                confidence: 1.0,
                published_at_s: w.t,
            }),
            _ => None,
        };
        self.step_with(w, advice.as_ref())
    }
}

/// Advice from outside the simulation (the sidecar's prompts and an LLM server).
pub trait AdviceSource {
    /// A_final and its confidence for the request the core issued with `decision` (its OPM
    /// triplet is `core.triplet()`), and how long the answer took, s; `None` when it failed.
    fn advise(
        &mut self,
        core: &DecisionCore,
        decision: &Decision,
        w: &World,
    ) -> Option<(Maneuver, f64, f64)>;
}

/// When external advice reaches the core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Timing {
    /// Simulated time waits for the answer: it lands in the step that asked.
    Wait,
    /// The answer lands after its measured latency in simulated time (and may be late for
    /// the core's deadline, as on the road).
    Latency,
}

/// Concord with an external advisor asked every `period_s` of simulated time; the sidecar's
/// eHMI speaks for the decision.
pub struct ExternalAdvice<'a> {
    inner: ConcordController,
    source: &'a mut dyn AdviceSource,
    timing: Timing,
    period_s: f64,
    next_ask_s: f64,
    pending: Option<Advice>,
    held: Option<Advice>,
}

impl<'a> ExternalAdvice<'a> {
    pub fn new(
        params: Params,
        w: &World,
        source: &'a mut dyn AdviceSource,
        timing: Timing,
        period_s: f64,
    ) -> Self {
        ExternalAdvice {
            inner: ConcordController::new(params, w, Advisor::None),
            source,
            timing,
            period_s,
            next_ask_s: 0.0,
            pending: None,
            held: None,
        }
    }

    /// Decisions by source (logit, advice, minimum risk).
    pub fn sources(&self) -> [u64; 3] {
        self.inner.sources
    }
}

impl Controller for ExternalAdvice<'_> {
    fn act(&mut self, w: &World, _: &[HumanDriver]) -> Command {
        if let Some(a) = self.pending.filter(|a| w.t + 1e-9 >= a.published_at_s) {
            self.held = Some(a);
            self.pending = None;
        }
        if self.pending.is_none() && w.t + 1e-9 >= self.next_ask_s {
            if let Some(d) = self.inner.last {
                self.next_ask_s = w.t + self.period_s;
                if let Some((maneuver, confidence, latency_s)) =
                    self.source.advise(self.inner.core(), &d, w)
                {
                    let advice = Advice {
                        request_id: d.request_id,
                        maneuver,
                        confidence,
                        published_at_s: match self.timing {
                            Timing::Wait => w.t,
                            Timing::Latency => w.t + latency_s,
                        },
                    };
                    match self.timing {
                        Timing::Wait => self.held = Some(advice),
                        Timing::Latency => self.pending = Some(advice),
                    }
                }
            }
        }
        let held = self.held;
        self.inner.step_with(w, held.as_ref())
    }
}

/// The CAV's acceleration when it simply executes `m` (the oracle's rollout model): a
/// yielding "decelerate" stops before the nearest zone of an HDV that has not passed it.
fn rollout_accel(m: Maneuver, w: &World) -> f64 {
    let p = cav_params();
    match m {
        Maneuver::Accelerate => {
            if w.ego.v < 12.0 {
                1.5
            } else {
                0.0
            }
        }
        Maneuver::KeepSpeed => 0.0,
        Maneuver::TurnLeft | Maneuver::TurnRight => (0.8 * (7.0 - w.ego.v)).clamp(-2.0, 1.5),
        Maneuver::Decelerate => {
            let entry = (0..w.hdvs.len())
                .filter_map(|i| {
                    let (ego_d, hdv_d) = w.to_conflict(i);
                    let zone = w.hdvs[i].zone_half_m;
                    (hdv_d >= -zone && ego_d >= -zone).then_some(ego_d - zone)
                })
                .reduce(f64::min);
            match entry {
                None => {
                    let (gap, v_lead) = w.ego_leader();
                    idm(w.ego.v, 10.0, gap, v_lead, &p)
                }
                Some(e) => idm(w.ego.v, 10.0, e.max(0.1), 0.0, &p),
            }
        }
    }
}

/// The fastest route-consistent maneuver that, executed for 8 s against a copy of every human
/// driver (who hear the matching eHMI message), never brings the CAV within 3 m of an HDV.
pub fn oracle(w: &World, drivers: &[HumanDriver]) -> Maneuver {
    best_maneuver(w, drivers, true)
}

/// [`oracle`], with or without the eHMI message reaching the drivers in the rollouts.
pub fn best_maneuver(w: &World, drivers: &[HumanDriver], ehmi: bool) -> Maneuver {
    let route = w.morph.lane(w.ego.lane).turn;
    let mut best = (f64::NEG_INFINITY, Maneuver::Decelerate);
    let mut accels = vec![0.0; drivers.len()];
    for m in Maneuver::ALL {
        if !m.consistent_with(route) || (route != Turn::Straight && m == Maneuver::KeepSpeed) {
            continue;
        }
        let (mut world, mut copies) = (w.clone(), drivers.to_vec());
        let signal = ehmi.then_some(Signal::announcing(m.gives_way()));
        let mut closest = f64::INFINITY;
        for _ in 0..(8.0 / DT) as usize {
            for (i, (d, a)) in copies.iter_mut().zip(accels.iter_mut()).enumerate() {
                *a = d.act(&world, i, signal).accel;
            }
            world.step(rollout_accel(m, &world), &accels);
            let (e, _) = world.pose(&world.ego);
            for h in &world.hdvs {
                let (p, _) = world.pose(&h.car);
                closest = closest.min(e.minus(p).norm());
            }
        }
        let score = world.ego.s - if closest < 3.0 { 1e6 } else { 0.0 };
        if score > best.0 {
            best = (score, m);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::ScenarioKind;
    use concord_core::DecisionSource;

    fn drivers(w: &World) -> Vec<HumanDriver> {
        (0..w.hdvs.len())
            .map(|i| HumanDriver::new(DriverStyle::Balanced, 8.0, i as u64 + 1))
            .collect()
    }

    #[test]
    fn idm_yields_to_a_close_hdv_and_goes_when_it_has_passed() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.hdvs[0].ego_conflict_s - 25.0;
        w.hdvs[0].car.s = w.hdvs[0].conflict_s - 20.0;
        let mut c = IdmYield::new(8.0);
        assert!(
            c.act(&w, &drivers(&w)).accel < -1.0,
            "brakes for the stop line"
        );
        w.hdvs[0].car.s = w.hdvs[0].conflict_s + w.hdvs[0].zone_half_m + 1.0;
        let mut c = IdmYield::new(8.0);
        assert!(c.act(&w, &drivers(&w)).accel >= 0.0);
    }

    #[test]
    fn idm_yields_to_the_next_car_of_a_stream_once_the_first_has_passed() {
        let mut w = World::with_followers(ScenarioKind::Stream, 8.0, 0.0, &[2.5]);
        let h = w.hdvs[0];
        w.ego.s = h.ego_conflict_s - 25.0;
        w.hdvs[0].car.s = h.conflict_s + h.zone_half_m + 1.0;
        w.hdvs[1].car.s = h.conflict_s - 20.0;
        assert!(IdmYield::new(8.0).act(&w, &drivers(&w)).accel < -1.0);
        // The second one far (more than 6 s) away: the CAV goes.
        w.hdvs[1].car.s = h.conflict_s - h.zone_half_m - 60.0;
        assert!(IdmYield::new(8.0).act(&w, &drivers(&w)).accel >= 0.0);
    }

    #[test]
    fn the_leader_avoids_a_predicted_overlap() {
        // Both would reach the conflict point together at constant speed.
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.hdvs[0].ego_conflict_s - 16.0;
        w.hdvs[0].car.s = w.hdvs[0].conflict_s - 16.0;
        let a = Stackelberg::default().act(&w, &drivers(&w)).accel;
        assert!(a != 0.0, "keeping speed means an overlap");
        let (_, _, overlap, _) = predict(&w, 0, 0.0, 0.0);
        assert!(overlap);
    }

    #[test]
    fn the_leader_plays_against_every_car_of_a_stream() {
        // The first car of a stream leaving the zone, the second one meeting the CAV at the
        // conflict point at constant speed: the game decides as against the second alone.
        let mut w = World::with_followers(ScenarioKind::Stream, 8.0, 0.0, &[3.6]);
        let h = w.hdvs[0];
        w.ego.s = h.ego_conflict_s - 24.0;
        w.hdvs[0].car.s = h.conflict_s + 5.0;
        w.hdvs[1].car.s = h.conflict_s - 24.0;
        assert!(predict(&w, 1, 0.0, 0.0).2);
        let both = Stackelberg::default().act(&w, &drivers(&w)).accel;
        let mut second = w.clone();
        second.hdvs[0].car.s = h.conflict_s + 60.0;
        let mut first = w.clone();
        first.hdvs[1].car.s = h.conflict_s + 60.0;
        let second = Stackelberg::default().act(&second, &drivers(&w)).accel;
        let first = Stackelberg::default().act(&first, &drivers(&w)).accel;
        assert_eq!(both, second);
        assert_ne!(
            both, first,
            "the first car alone would not hold the CAV back"
        );
    }

    /// The CAV standing 2 m before the zone; the first car of a stream at the conflict point
    /// (it leaves the zone in `zone / 8` s), the next one `gap_s` s after that from the zone.
    fn at_the_line(gap_s: f64) -> World {
        let mut w = World::with_followers(ScenarioKind::Stream, 8.0, 0.0, &[3.0]);
        let h = w.hdvs[0];
        let zone = h.zone_half_m;
        w.ego.s = h.ego_conflict_s - zone - 2.0;
        w.ego.v = 0.0;
        w.hdvs[0].car.s = h.conflict_s;
        w.hdvs[1].car.s = h.conflict_s - zone - 8.0 * (zone / 8.0 + gap_s);
        w
    }

    #[test]
    fn gap_acceptance_waits_for_a_3_s_gap_and_goes_on_a_5_s_gap() {
        let w = at_the_line(3.0);
        assert!((GapAcceptance::gap_s(&w) - 3.0).abs() < 1e-9);
        let mut c = GapAcceptance::new(8.0);
        assert!(c.act(&w, &drivers(&w)).accel <= 1e-9, "waits");
        let mut w = at_the_line(5.0);
        assert!((GapAcceptance::gap_s(&w) - 5.0).abs() < 1e-9);
        let mut c = GapAcceptance::new(8.0);
        assert!(
            c.act(&w, &drivers(&w)).accel <= 1e-9,
            "enters once the first has left"
        );
        // Once the first has left the zone, the gap counts from now: both cars 0.1 m further.
        let on = w.hdvs[0].zone_half_m + 0.1;
        w.hdvs[0].car.s += on;
        w.hdvs[1].car.s += on;
        assert!((GapAcceptance::gap_s(&w) - (5.0 - 0.1 / 8.0)).abs() < 1e-9);
        assert!(c.act(&w, &drivers(&w)).accel > 1.0, "goes");
        // With nobody in the zone the gap counts from now: the second car 3 s away.
        let mut w = at_the_line(3.0);
        w.hdvs[0].car.s = w.hdvs[0].conflict_s + 20.0;
        let gap = GapAcceptance::gap_s(&w);
        assert!((gap - (3.0 + w.hdvs[0].zone_half_m / 8.0)).abs() < 1e-9);
        assert!(GapAcceptance::new(8.0).act(&w, &drivers(&w)).accel <= 1e-9);
        // A car that stands before the zone does not arrive; one moving off does, soon.
        w.hdvs[1].car.s = w.hdvs[1].conflict_s - w.hdvs[1].zone_half_m - 1.5;
        w.hdvs[1].car.v = 0.0;
        assert_eq!(GapAcceptance::gap_s(&w), f64::INFINITY);
        (w.hdvs[1].car.v, w.hdvs[1].car.a) = (0.2, 1.0);
        // 1.5 m = 0.2 t + t²/2.
        let t = (0.2f64 * 0.2 + 3.0).sqrt() - 0.2;
        assert!((GapAcceptance::gap_s(&w) - t).abs() < 1e-9);
    }

    #[test]
    fn gap_acceptance_is_committed_once_it_cannot_stop() {
        let mut w = at_the_line(5.0);
        w.hdvs[0].car.s += 30.0;
        // Rolling at 6 m/s, 7 m before the zone (comfortable braking needs 9 m).
        w.ego.s -= 5.0;
        w.ego.v = 6.0;
        let mut c = GapAcceptance::new(8.0);
        // It brakes no harder than the turn ahead asks.
        let curve = within_curves(&w, 0.0);
        assert!(curve > -2.0, "the turn alone asks {curve} m/s²");
        assert!(c.act(&w, &drivers(&w)).accel >= curve - 1e-9);
        // The gap closes to under 1 s: it goes on.
        w.hdvs[1].car.s += 40.0;
        assert!(GapAcceptance::gap_s(&w) < 1.0);
        assert!(c.act(&w, &drivers(&w)).accel >= curve - 1e-9);
        assert!(GapAcceptance::new(8.0).act(&w, &drivers(&w)).accel < -2.0);
    }

    /// Always advises the route's left turn, confidently, after `latency` s.
    struct Constant(f64);

    impl AdviceSource for Constant {
        fn advise(
            &mut self,
            _: &DecisionCore,
            _: &Decision,
            _: &World,
        ) -> Option<(Maneuver, f64, f64)> {
            Some((Maneuver::TurnLeft, 0.9, self.0))
        }
    }

    fn advice_decisions(timing: Timing, latency: f64) -> u64 {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let mut source = Constant(latency);
        let mut x = ExternalAdvice::new(Params::default(), &w, &mut source, timing, 1.0);
        let d = drivers(&w);
        for _ in 0..60 {
            let c = x.act(&w, &d);
            w.step(c.accel, &[0.0]);
        }
        x.sources()[DecisionSource::Advice as usize]
    }

    #[test]
    fn external_advice_lands_now_or_after_its_latency_and_late_advice_is_refused() {
        assert!(
            advice_decisions(Timing::Wait, 5.0) > 40,
            "waiting: applied at once"
        );
        let timely = advice_decisions(Timing::Latency, 0.5);
        assert!(timely > 0 && timely < advice_decisions(Timing::Wait, 0.5));
        assert_eq!(
            advice_decisions(Timing::Latency, 2.0),
            0,
            "after the 1.5 s deadline"
        );
    }

    #[test]
    fn every_concord_controller_shows_its_decision_on_the_ehmi() {
        let w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        for advisor in [Advisor::None, Advisor::Oracle] {
            let mut c = ConcordController::new(Params::default(), &w, advisor);
            let cmd = c.act(&w, &drivers(&w));
            let d = c.last.expect("decided");
            assert_eq!(cmd.ehmi, ehmi_of(&d), "{advisor:?}");
            assert!(cmd.ehmi.is_some());
        }
    }

    #[test]
    fn the_oracle_never_advises_a_maneuver_that_meets_an_hdv() {
        let mut w = World::with_followers(ScenarioKind::Stream, 8.0, 0.0, &[2.0]);
        w.ego.s = w.hdvs[0].ego_conflict_s - 18.0;
        w.hdvs[0].car.s = w.hdvs[0].conflict_s - 18.0;
        w.hdvs[1].car.s = w.hdvs[0].car.s - 16.0;
        let m = oracle(&w, &drivers(&w));
        let (mut world, mut ds) = (w.clone(), drivers(&w));
        let signal = Signal::announcing(m.gives_way());
        for _ in 0..160 {
            let a: Vec<f64> = ds
                .iter_mut()
                .enumerate()
                .map(|(i, d)| d.act(&world, i, Some(signal)).accel)
                .collect();
            world.step(rollout_accel(m, &world), &a);
            assert!(!world.collided(), "{m:?}");
        }
    }
}
