//! The human driver of the HDV: the Intelligent Driver Model (IDM) for speed keeping and
//! following, gap acceptance at the conflict point, a reaction time, acceleration noise, and a
//! response to the CAV's eHMI message.
//!
//! * **IDM** (Treiber, Hennecke, Helbing 2000): `a = a_max [1 − (v/v0)^4 − (s*/gap)^2]`,
//!   `s* = s0 + v T + v Δv / (2 √(a_max b))`.
//! * **Gap acceptance.** From what it perceived [`DriverParams::reaction_s`] ago, the driver
//!   compares the CAV's time to the conflict point `t_c` with its own `t_h`: it goes first when
//!   `t_c − t_h ≥ gap_s`, else it yields (the conflict zone's entry becomes a stopped virtual
//!   leader) until the CAV has left the zone. A decision to go is frozen once the driver could
//!   no longer stop comfortably before the zone; a decision to yield is reconsidered every step
//!   (a CAV that waits, arriving "never", is passed).
//! * **eHMI.** The CAV's message carries a structured intent (it yields, or it goes first).
//!   On each new message the driver complies with probability `compliance`: it goes when told
//!   "please go ahead" (unless the CAV is already about to enter), and yields when told "please
//!   wait" (if it can still stop).
//! * **Noise.** Gaussian acceleration noise, standard deviation `noise_mps2`.
//!
//! Parameters per style ([`DriverParams::of`]), from the literature's ranges:
//!
//! | | aggressive | balanced | conservative | source |
//! |---|---|---|---|---|
//! | desired speed, × initial | 1.15 | 1.0 | 0.9 | |
//! | time headway T, s | 1.0 | 1.5 | 2.0 | IDM calibrations span 1.0–2.0 s (Kesting & Treiber 2008; Treiber & Kesting, *Traffic Flow Dynamics*, 2013, tab. 11.2) |
//! | max acceleration a_max, m/s² | 2.0 | 1.5 | 1.0 | same, 0.7–2.0 |
//! | comfortable braking b, m/s² | 3.0 | 2.0 | 1.5 | same, 1.5–3.0 |
//! | minimum gap s0, m | 1.5 | 2.0 | 3.0 | same, 1–3 m |
//! | reaction time, s | 0.6 | 1.0 | 1.4 | brake reaction 0.7–1.5 s (Green 2000) |
//! | accepted lag gap_s, s | −0.5 | 1.0 | 2.5 | critical gaps 2–5 s around the HCM's 4.1 s for a left turn from the major road (HCM 2010, ch. 19); a negative lag: goes even slightly behind the CAV |
//! | eHMI compliance | 0.5 | 0.8 | 0.95 | eHMI studies report most pedestrians and drivers follow explicit messages (Faas & Baumann 2019; Dey et al. 2020) |
//! | noise, m/s² | 0.3 | 0.2 | 0.1 | |

use std::collections::VecDeque;

use concord_core::choice::Idm;
use concord_core::scene::Style;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use crate::world::{ScenarioKind, World, CAR_LENGTH_M, DT};

/// What the CAV's eHMI says it does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Signal {
    /// "I am slowing down; please go ahead."
    Yield,
    /// "I am going first; please wait."
    Proceed,
}

impl Signal {
    /// The message of a CAV that gives way, or else goes first.
    pub fn announcing(gives_way: bool) -> Signal {
        if gives_way {
            Signal::Yield
        } else {
            Signal::Proceed
        }
    }
}

/// One style's parameters (see the module table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriverParams {
    pub desired_factor: f64,
    pub headway_s: f64,
    pub a_max: f64,
    pub b_comf: f64,
    pub s0_m: f64,
    pub reaction_s: f64,
    pub gap_s: f64,
    pub compliance: f64,
    pub noise_mps2: f64,
}

impl DriverParams {
    pub fn of(style: Style) -> DriverParams {
        match style {
            Style::Aggressive => DriverParams {
                desired_factor: 1.15,
                headway_s: 1.0,
                a_max: 2.0,
                b_comf: 3.0,
                s0_m: 1.5,
                reaction_s: 0.6,
                gap_s: -0.5,
                compliance: 0.5,
                noise_mps2: 0.3,
            },
            Style::Balanced => DriverParams {
                desired_factor: 1.0,
                headway_s: 1.5,
                a_max: 1.5,
                b_comf: 2.0,
                s0_m: 2.0,
                reaction_s: 1.0,
                gap_s: 1.0,
                compliance: 0.8,
                noise_mps2: 0.2,
            },
            Style::Conservative => DriverParams {
                desired_factor: 0.9,
                headway_s: 2.0,
                a_max: 1.0,
                b_comf: 1.5,
                s0_m: 3.0,
                reaction_s: 1.4,
                gap_s: 2.5,
                compliance: 0.95,
                noise_mps2: 0.1,
            },
        }
    }
}

/// IDM acceleration at speed `v` towards `v0`, with a leader `gap` m ahead at speed `v_lead`
/// (no leader: `gap` infinite), m/s²: the core's IDM with the driver's parameters.
pub fn idm(v: f64, v0: f64, gap: f64, v_lead: f64, p: &DriverParams) -> f64 {
    Idm {
        max_accel_mps2: p.a_max,
        comfort_decel_mps2: p.b_comf,
        min_gap_m: p.s0_m,
        headway_s: p.headway_s,
        desired_speed_mps: v0,
    }
    .accel(v, gap, v - v_lead)
}

/// Time to cover `d` m at speed `v` (guarded near standstill), s.
fn time_to(d: f64, v: f64) -> f64 {
    d.max(0.0) / v.max(0.5)
}

/// The HDV's driver.
#[derive(Clone, Debug)]
pub struct HumanDriver {
    pub style: Style,
    pub p: DriverParams,
    desired_mps: f64,
    rng: SmallRng,
    noise: Normal<f64>,
    /// The CAV's (distance to the conflict, speed) as perceived, oldest first.
    perceived: VecDeque<(f64, f64)>,
    /// Goes first (`true`) or yields; frozen once committed.
    goes_first: Option<bool>,
    committed: bool,
    /// The last eHMI message and whether the driver complies with it.
    heard: Option<(Signal, bool)>,
}

impl HumanDriver {
    pub fn new(style: Style, initial_speed: f64, seed: u64) -> Self {
        let p = DriverParams::of(style);
        HumanDriver {
            style,
            p,
            desired_mps: (initial_speed * p.desired_factor).max(3.0),
            rng: SmallRng::seed_from_u64(seed),
            noise: Normal::new(0.0, p.noise_mps2).expect("a finite deviation"),
            perceived: VecDeque::new(),
            goes_first: None,
            committed: false,
            heard: None,
        }
    }

    /// Whether the driver has decided to go first (`None`: not yet).
    pub fn goes_first(&self) -> Option<bool> {
        self.goes_first
    }

    /// The HDV's acceleration for the next step, given the world and the CAV's eHMI message.
    pub fn act(&mut self, w: &World, ehmi: Option<Signal>) -> f64 {
        let (ego_d, hdv_d) = w.to_conflict();
        self.perceived.push_back((ego_d, w.ego.v));
        let delay = (self.p.reaction_s / DT).round() as usize;
        while self.perceived.len() > delay + 1 {
            self.perceived.pop_front();
        }
        let (seen_d, seen_v) = *self.perceived.front().expect("just pushed");
        if let Some(signal) = ehmi {
            if self.heard.map(|(s, _)| s) != Some(signal) {
                let complies = self.rng.random::<f64>() < self.p.compliance;
                self.heard = Some((signal, complies));
            }
        }
        let v = w.hdv.v;
        let stop_dist = v * v / (2.0 * self.p.b_comf) + self.p.s0_m;
        let zone_entry = hdv_d - w.zone_half_m;
        let ego_clear = seen_d < -w.zone_half_m;
        let past = hdv_d < -w.zone_half_m;
        // A decision to go is frozen once the driver could no longer stop; a decision to yield
        // is looked at again every step (a waiting CAV is let through no longer than needed).
        if !self.committed && !past {
            let lag = time_to(seen_d, seen_v) - time_to(hdv_d, v);
            let cav_waits = seen_v < 0.3 && seen_d > w.zone_half_m;
            let mut go = lag >= self.p.gap_s || ego_clear || cav_waits;
            match self.heard {
                Some((Signal::Yield, true)) if seen_d > w.zone_half_m => go = true,
                Some((Signal::Proceed, true)) if zone_entry > stop_dist * 0.5 => go = false,
                _ => {}
            }
            self.goes_first = Some(go);
            self.committed = go && zone_entry < stop_dist;
        }
        // Merge: a CAV past the merge point and ahead is a leader on the same path.
        let merged_ahead = w.kind == ScenarioKind::Merge && ego_d < 0.0 && ego_d < hdv_d;
        let (gap, v_lead) = if merged_ahead {
            ((hdv_d - ego_d - CAR_LENGTH_M).max(0.1), w.ego.v)
        } else if self.goes_first == Some(false) && !ego_clear && !past {
            (zone_entry.max(0.1), 0.0)
        } else {
            (f64::INFINITY, 0.0)
        };
        let a = idm(v, self.desired_mps, gap, v_lead, &self.p) + self.noise.sample(&mut self.rng);
        a.max(-2.0 * self.p.b_comf.max(3.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idm_free_road_and_standstill_behind_a_stopped_leader() {
        let p = DriverParams::of(Style::Balanced);
        assert!((idm(0.0, 10.0, f64::INFINITY, 0.0, &p) - p.a_max).abs() < 1e-12);
        assert!(idm(10.0, 10.0, f64::INFINITY, 0.0, &p).abs() < 1e-12);
        // At standstill the minimum gap is the equilibrium; at half of it, a_max·(1 − 4).
        assert!(idm(0.0, 10.0, p.s0_m, 0.0, &p).abs() < 1e-12);
        assert!((idm(0.0, 10.0, p.s0_m / 2.0, 0.0, &p) + 3.0 * p.a_max).abs() < 1e-12);
    }

    #[test]
    fn a_conservative_driver_yields_to_a_cav_that_arrives_first_and_an_aggressive_one_goes() {
        for (style, expect_go) in [(Style::Conservative, false), (Style::Aggressive, true)] {
            let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
            // The CAV 0.25 s ahead at the conflict point.
            w.ego.s = w.ego_conflict_s - 20.0;
            w.hdv.s = w.hdv_conflict_s - 22.0;
            let mut d = HumanDriver::new(style, 8.0, 1);
            for _ in 0..3 {
                d.act(&w, None);
            }
            assert_eq!(d.goes_first(), Some(expect_go), "{style:?}");
        }
    }

    #[test]
    fn a_compliant_driver_goes_when_told_to_go_ahead() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.ego_conflict_s - 20.0;
        w.hdv.s = w.hdv_conflict_s - 40.0;
        let mut p = HumanDriver::new(Style::Conservative, 8.0, 3);
        p.p.compliance = 1.0;
        p.act(&w, None);
        assert_eq!(p.goes_first(), Some(false));
        p.act(&w, Some(Signal::Yield));
        assert_eq!(p.goes_first(), Some(true));
    }

    #[test]
    fn a_yielding_driver_stops_before_the_zone() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.v = 0.0;
        w.ego.s = w.ego_conflict_s - w.zone_half_m - 1.0;
        let mut d = HumanDriver::new(Style::Conservative, 8.0, 2);
        d.p.noise_mps2 = 0.0;
        d.noise = Normal::new(0.0, 0.0).unwrap();
        // The CAV waits just before the zone (a long lag: the driver would go) but says it
        // goes first, to a driver who always complies.
        d.p.compliance = 1.0;
        for _ in 0..600 {
            let a = d.act(&w, Some(Signal::Proceed));
            w.step(0.0, a);
        }
        let (_, hdv_d) = w.to_conflict();
        assert!(
            hdv_d > w.zone_half_m - 0.5,
            "stopped {hdv_d} m before the conflict point"
        );
        assert!(w.hdv.v < 0.1);
    }
}
