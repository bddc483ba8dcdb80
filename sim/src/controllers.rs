//! Controllers of the CAV, behind one interface ([`Controller`]): each step it sees the world
//! (and, for the oracle only, the human driver's mind) and returns the CAV's acceleration
//! along its route and the eHMI message it shows, if any.
//!
//! * [`IdmYield`], the paper's conservative baseline: IDM car-following, treating the conflict
//!   zone as a stop line until the HDV has passed it or is at least `clear_gap_s` (6 s) away.
//! * [`Stackelberg`], game-theoretic: the CAV leads, the HDV follows. Every 0.5 s the CAV
//!   picks an acceleration from {−3, −1.5, 0, 1, 2} m/s², predicting for each the HDV's best
//!   response from the same set, both held for a 4 s horizon; each side's payoff is
//!   `progress / horizon − 0.05 a² − 100 · overlap − 10 · close`, where `overlap` is 1 when both
//!   would be in the conflict zone at once and `close` is 1 when one would enter less than
//!   1.5 s after the other left. The leader counts an overlap or a close call also when the
//!   HDV would simply hold its current acceleration (a human need not play the best
//!   response), and pays `0.05 Δa²` for changing its acceleration. Ties go to the gentler
//!   acceleration. Deterministic.
//! * [`ConcordController`], the decision core's step (the same as `concord run`): logit-only,
//!   or with an [`Advisor`]: the oracle, which rolls every route-consistent maneuver out for
//!   8 s under a copy of the human driver (who hears the matching eHMI message) and advises the
//!   fastest one without conflict, with confidence 1; the core's gate and safety veto still
//!   apply. Both show the eHMI message of each decision (`ehmi_of`), as the onboard sidecar
//!   announces every decision.
//! * [`ExternalAdvice`]: Concord advised from outside the simulation (an LLM through the
//!   sidecar's prompts, see `concord experiment paper --llm`), with simulated time either
//!   waiting for each answer or letting it land after its measured latency.

use concord_core::advice::Advice;
use concord_core::scene::Turn;
use concord_core::{Decision, DecisionCore, DecisionSource, Maneuver, Params};

use crate::driver::{idm, DriverParams, HumanDriver, Signal};
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
    /// The command for the next step. `hdv` is the human driver; only the oracle looks at it.
    fn act(&mut self, w: &World, hdv: &HumanDriver) -> Command;
}

/// The CAV's own IDM parameters (a balanced driver's).
fn cav_params() -> DriverParams {
    DriverParams::of(concord_core::scene::Style::Balanced)
}

/// Conservative IDM with yielding at the conflict zone.
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
    fn act(&mut self, w: &World, _: &HumanDriver) -> Command {
        let p = cav_params();
        let (ego_d, hdv_d) = w.to_conflict();
        let entry = ego_d - w.zone_half_m;
        let hdv_clear = hdv_d < -w.zone_half_m;
        let hdv_far = hdv_d - w.zone_half_m > self.clear_gap_s * w.hdv.v.max(0.5);
        if entry < w.ego.v * w.ego.v / (2.0 * p.b_comf) && (hdv_clear || hdv_far) {
            self.committed = true;
        }
        let yield_now = !self.committed && !hdv_clear && !hdv_far && entry > -w.zone_half_m;
        let (gap, v_lead) = w.ego_leader();
        let accel = if yield_now {
            idm(w.ego.v, self.desired_mps, entry.max(0.1), 0.0, &p)
        } else {
            idm(w.ego.v, self.desired_mps, gap, v_lead, &p)
        };
        Command { accel, ehmi: None }
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

/// (progress of the ego, of the HDV, both in the zone at once, too close in time) for constant
/// accelerations over the horizon.
fn predict(w: &World, a_c: f64, a_h: f64) -> (f64, f64, bool, bool) {
    let dt = 0.25;
    let (mut ec, mut hc) = w.to_conflict();
    let (mut vc, mut vh) = (w.ego.v, w.hdv.v);
    let (mut pc, mut ph) = (0.0, 0.0);
    let mut overlap = false;
    let (mut c_left, mut h_left, mut c_in, mut h_in) = (None, None, None, None);
    let mut t = 0.0;
    while t < HORIZON_S {
        let (nc, nh) = (
            (vc + a_c * dt).clamp(0.0, 14.0),
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
        let ci = ec.abs() < w.zone_half_m;
        let hi = hc.abs() < w.zone_half_m;
        overlap |= ci && hi;
        if ci && c_in.is_none() {
            c_in = Some(t);
        }
        if hi && h_in.is_none() {
            h_in = Some(t);
        }
        if ec < -w.zone_half_m && c_left.is_none() {
            c_left = Some(t);
        }
        if hc < -w.zone_half_m && h_left.is_none() {
            h_left = Some(t);
        }
    }
    let close = matches!((c_left, h_in), (Some(l), Some(i)) if i > l && i - l < 1.5)
        || matches!((h_left, c_in), (Some(l), Some(i)) if i > l && i - l < 1.5);
    (pc, ph, overlap, close)
}

fn payoff(progress: f64, a: f64, overlap: bool, close: bool) -> f64 {
    progress / HORIZON_S
        - 0.05 * a * a
        - 100.0 * f64::from(overlap as u8)
        - 10.0 * f64::from(close as u8)
}

impl Controller for Stackelberg {
    fn act(&mut self, w: &World, _: &HumanDriver) -> Command {
        let (ego_d, hdv_d) = w.to_conflict();
        if ego_d < -w.zone_half_m || hdv_d < -w.zone_half_m {
            // The conflict is resolved: drive on (behind the HDV in the merge) up to the
            // game's top speed.
            let (gap, v_lead) = w.ego_leader();
            return Command {
                accel: idm(w.ego.v, 14.0, gap, v_lead, &cav_params()),
                ehmi: None,
            };
        }
        if w.t + 1e-9 < self.next_decision_s {
            return Command {
                accel: self.held,
                ehmi: None,
            };
        }
        self.next_decision_s = w.t + GAME_PERIOD_S;
        let mut best = (f64::NEG_INFINITY, 0.0_f64);
        let holding = w.hdv.a;
        for a_c in ACCELS {
            let response = ACCELS
                .iter()
                .map(|&a_h| {
                    let (_, ph, o, c) = predict(w, a_c, a_h);
                    (payoff(ph, a_h, o, c), -a_h.abs(), a_h)
                })
                .max_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)))
                .map(|r| r.2)
                .unwrap_or(0.0);
            let (pc, _, o, c) = predict(w, a_c, response);
            // A human may not play the best response: the leader also guards against the HDV
            // simply holding its current acceleration.
            let (_, _, o_hold, c_hold) = predict(w, a_c, holding);
            // Comfort: a change of acceleration costs as the acceleration does (no chattering).
            let change = a_c - w.ego.a;
            let u = payoff(pc, a_c, o || o_hold, c || c_hold) - 0.05 * change * change;
            if u > best.0 + 1e-9 || (u > best.0 - 1e-9 && a_c.abs() < best.1.abs()) {
                best = (u, a_c);
            }
        }
        self.held = best.1;
        Command {
            accel: best.1,
            ehmi: None,
        }
    }
}

/// Who advises the core.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Advisor {
    /// Nobody: logit-only.
    None,
    /// Rollouts under the true driver model; upper bound.
    Oracle,
}

/// The decision core as a controller.
#[derive(Clone, Debug)]
pub struct ConcordController {
    core: Box<DecisionCore>,
    advisor: Advisor,
    last_cycle: Option<u64>,
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
            last_cycle: None,
            last: None,
            sources: [0; 3],
        }
    }

    /// The decision core (its OPM triplet describes the newest decision's scene).
    pub fn core(&self) -> &DecisionCore {
        &self.core
    }
}

/// The eHMI message that shows decision `d`: "please go ahead" when it gives way (or brakes
/// as the minimum-risk fallback), else "I am going first". Every Concord controller speaks
/// through this one function.
fn ehmi_of(d: &Decision) -> Option<Signal> {
    Some(Signal::announcing(
        d.maneuver.gives_way() || d.source == DecisionSource::MinimumRisk,
    ))
}

impl ConcordController {
    /// One core step with `advice`; the eHMI shows the decision.
    fn step_with(&mut self, w: &World, advice: Option<&Advice>) -> Command {
        let Ok(d) = self.core.step(&w.scene(), w.t, advice) else {
            return Command {
                accel: -crate::world::MAX_BRAKE_MPS2,
                ehmi: None,
            };
        };
        self.last_cycle = Some(d.cycle);
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
    fn act(&mut self, w: &World, hdv: &HumanDriver) -> Command {
        let advice = match (self.advisor, self.last_cycle) {
            (Advisor::Oracle, Some(id)) => Some(Advice {
                request_id: id,
                maneuver: oracle(w, hdv),
                confidence: 1.0,
                received_at_s: w.t,
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
    fn act(&mut self, w: &World, _: &HumanDriver) -> Command {
        if let Some(a) = self.pending.filter(|a| w.t + 1e-9 >= a.received_at_s) {
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
                        request_id: d.cycle,
                        maneuver,
                        confidence,
                        received_at_s: match self.timing {
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

/// The CAV's acceleration when it simply executes `m` (the oracle's rollout model).
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
            let (ego_d, hdv_d) = w.to_conflict();
            if hdv_d < -w.zone_half_m || ego_d < -w.zone_half_m {
                let (gap, v_lead) = w.ego_leader();
                idm(w.ego.v, 10.0, gap, v_lead, &p)
            } else {
                idm(w.ego.v, 10.0, (ego_d - w.zone_half_m).max(0.1), 0.0, &p)
            }
        }
    }
}

/// The fastest route-consistent maneuver that, executed for 8 s against a copy of the human
/// driver (who hears the matching eHMI message), never brings the two cars within 3 m.
pub fn oracle(w: &World, hdv: &HumanDriver) -> Maneuver {
    best_maneuver(w, hdv, true)
}

/// [`oracle`], with or without the eHMI message reaching the driver in the rollouts.
pub fn best_maneuver(w: &World, hdv: &HumanDriver, ehmi: bool) -> Maneuver {
    let route = w.morph.lane(w.ego.lane).turn;
    let mut best = (f64::NEG_INFINITY, Maneuver::Decelerate);
    for m in Maneuver::ALL {
        if !m.consistent_with(route) || (route != Turn::Straight && m == Maneuver::KeepSpeed) {
            continue;
        }
        let (mut world, mut driver) = (w.clone(), hdv.clone());
        let signal = Signal::announcing(m.gives_way());
        let mut closest = f64::INFINITY;
        for _ in 0..(8.0 / DT) as usize {
            let a_h = driver.act(&world, ehmi.then_some(signal));
            world.step(rollout_accel(m, &world), a_h);
            let (e, _) = world.pose(&world.ego);
            let (h, _) = world.pose(&world.hdv);
            closest = closest.min(e.minus(h).norm());
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
    use concord_core::scene::Style;

    fn driver() -> HumanDriver {
        HumanDriver::new(Style::Balanced, 8.0, 1)
    }

    #[test]
    fn idm_yields_to_a_close_hdv_and_goes_when_it_has_passed() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.ego_conflict_s - 25.0;
        w.hdv.s = w.hdv_conflict_s - 20.0;
        let mut c = IdmYield::new(8.0);
        assert!(
            c.act(&w, &driver()).accel < -1.0,
            "brakes for the stop line"
        );
        w.hdv.s = w.hdv_conflict_s + w.zone_half_m + 1.0;
        let mut c = IdmYield::new(8.0);
        assert!(c.act(&w, &driver()).accel >= 0.0);
    }

    #[test]
    fn the_leader_avoids_a_predicted_overlap() {
        // Both would reach the conflict point together at constant speed.
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.ego_conflict_s - 16.0;
        w.hdv.s = w.hdv_conflict_s - 16.0;
        let a = Stackelberg::default().act(&w, &driver()).accel;
        assert!(a != 0.0, "keeping speed means an overlap");
        let (_, _, overlap, _) = predict(&w, 0.0, 0.0);
        assert!(overlap);
    }

    /// Always advises decelerating, confidently, after `latency` s.
    struct Constant(f64);

    impl AdviceSource for Constant {
        fn advise(
            &mut self,
            _: &DecisionCore,
            _: &Decision,
            _: &World,
        ) -> Option<(Maneuver, f64, f64)> {
            Some((Maneuver::Decelerate, 0.9, self.0))
        }
    }

    fn advice_decisions(timing: Timing, latency: f64) -> u64 {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let mut source = Constant(latency);
        let mut x = ExternalAdvice::new(Params::default(), &w, &mut source, timing, 1.0);
        let d = driver();
        for _ in 0..60 {
            let c = x.act(&w, &d);
            w.step(c.accel, 0.0);
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
            let cmd = c.act(&w, &driver());
            let d = c.last.expect("decided");
            assert_eq!(cmd.ehmi, ehmi_of(&d), "{advisor:?}");
            assert!(cmd.ehmi.is_some());
        }
    }

    #[test]
    fn the_oracle_never_advises_a_maneuver_that_meets_the_hdv() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.ego_conflict_s - 18.0;
        w.hdv.s = w.hdv_conflict_s - 18.0;
        let m = oracle(&w, &driver());
        let (mut world, mut d) = (w.clone(), driver());
        let signal = Signal::announcing(m.gives_way());
        for _ in 0..160 {
            let a = d.act(&world, Some(signal));
            world.step(rollout_accel(m, &world), a);
            assert!(!world.collided(), "{m:?}");
        }
    }
}
