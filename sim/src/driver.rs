//! The human driver of an HDV: the Intelligent Driver Model (IDM) for speed keeping and
//! following, gap acceptance at the conflict point, a reaction time, acceleration noise, a
//! response to the CAV's eHMI message, and for the hesitant style a wait for a sign.
//!
//! * **IDM** (Treiber, Hennecke, Helbing 2000): `a = a_max [1 − (v/v0)^4 − (s*/gap)^2]`,
//!   `s* = s0 + v T + v Δv / (2 √(a_max b))`. Every constraint (the HDV ahead on the same lane,
//!   the CAV's) gives one such acceleration; the driver applies the smallest.
//! * **Gap acceptance.** From what it perceived [`DriverParams::reaction_s`] ago, the driver
//!   compares the CAV's time to the conflict point `t_c` with its own `t_h`: with the right of
//!   way it goes first when the lag `t_c − t_h ≥ gap_s`; without it (the minor road) only when
//!   `t_c − t_h ≥ gap_s + MINOR_ROAD_EXTRA_S`, i.e. when it clears the zone well before the CAV
//!   arrives. Otherwise it yields (the conflict zone's entry becomes a stopped virtual leader)
//!   until the CAV has left the zone. A decision to go is frozen once the driver could no
//!   longer stop comfortably before the zone; a decision to yield is reconsidered every step
//!   (a CAV that waits, arriving "never", is passed).
//! * **eHMI.** The CAV's message carries a structured intent (it yields, or it goes first).
//!   On each new message the driver complies with probability `compliance`: it goes when told
//!   "please go ahead" (unless the CAV is already about to enter), and yields when told "please
//!   wait" (if it can still stop).
//! * **Hesitant** (the paper's Fig. 6a deadlock). When the situation is unclear, the CAV
//!   approaching its zone and neither party arriving first by the driver's `gap_s`
//!   (`|t_c − t_h| < gap_s`), and the driver can still stop comfortably, it slows, stops before
//!   the zone and waits for a sign; from then on it no longer reads the CAV's arrival time (a
//!   CAV slowing down is no sign). Told "please go ahead" (and complying), it goes; told "I am
//!   going first", or seeing the CAV move into the zone, it waits until the CAV has cleared it;
//!   while both stand (below [`STAND_MPS`]) without a sign it counts, and after its patience it
//!   goes. A CAV that enters the zone stops it again whenever it can still stop.
//! * **Noise.** Gaussian acceleration noise, standard deviation `noise_mps2`.
//! * **Imposed braking.** Each step the driver also computes its acceleration without the CAV's
//!   constraint (the virtual stop line while it yields, or the CAV as leader in the merge),
//!   noise left out. The braking the CAV imposes is `−a` when the acceleration `a` with the
//!   constraint is negative and below the one without (the CAV's constraint binds), else 0,
//!   m/s². Braking for an HDV ahead that itself yields is counted on that HDV only.
//!
//! Parameters per style ([`DriverParams::of`]), from the literature's ranges:
//!
//! | | aggressive | balanced | conservative | hesitant | source |
//! |---|---|---|---|---|---|
//! | desired speed, × initial | 1.15 | 1.0 | 0.9 | 0.9 | |
//! | time headway T, s | 1.0 | 1.5 | 2.0 | 2.0 | IDM calibrations span 1.0–2.0 s (Kesting & Treiber 2008; Treiber & Kesting, *Traffic Flow Dynamics*, 2013, tab. 11.2) |
//! | max acceleration a_max, m/s² | 2.0 | 1.5 | 1.0 | 1.0 | same, 0.7–2.0 |
//! | comfortable braking b, m/s² | 3.0 | 2.0 | 1.5 | 2.0 | same, 1.5–3.0; hesitant: so it can still stop before the zone from 10 m/s at the paper's start |
//! | minimum gap s0, m | 1.5 | 2.0 | 3.0 | 1.5 | same, 1–3 m; hesitant: pulls up to the line to wait |
//! | reaction time, s | 0.6 | 1.0 | 1.4 | 1.4 | brake reaction 0.7–1.5 s (Green 2000) |
//! | accepted lag gap_s, s | −0.5 | 1.0 | 2.5 | 4.0 | critical gaps 2–5 s around the HCM's 4.1 s for a left turn from the major road (HCM 2010, ch. 19); a negative lag: goes even slightly behind the CAV; hesitant: wants about the HCM's full critical gap, so the paper's start (the HDV 1.6–2.6 s ahead, ±0.8 s) is unclear to it at every speed |
//! | eHMI compliance | 0.5 | 0.8 | 0.95 | 0.95 | eHMI studies report most pedestrians and drivers follow explicit messages (Faas & Baumann 2019; Dey et al. 2020) |
//! | noise, m/s² | 0.3 | 0.2 | 0.1 | 0.1 | |
//! | patience, s | | | | U(6, 10) | the willingness to force one's way grows with the time waited (Mahmassani & Sheffi 1981; Kaysi & Abbany 2007); several times the 0–2 s lags of the paper's start, so a deadlock is plain |
//!
//! [`MINOR_ROAD_EXTRA_S`] (2.4 s) is the difference between the HCM's base critical headways
//! for crossing from the minor road (6.5 s) and for a left turn from the major road (4.1 s)
//! at a two-lane major street (HCM 2010, exhibit 19-10).

use std::collections::VecDeque;

use concord_core::choice::Idm;
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

/// A human driver's style (see the module table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DriverStyle {
    Aggressive,
    Balanced,
    Conservative,
    /// Stops and waits for a sign when the situation is unclear.
    Hesitant,
}

impl DriverStyle {
    /// Every style.
    pub const ALL: [DriverStyle; 4] = [
        DriverStyle::Aggressive,
        DriverStyle::Balanced,
        DriverStyle::Conservative,
        DriverStyle::Hesitant,
    ];
    /// The three styles that read arrival times only (the stream's).
    pub const DECISIVE: [DriverStyle; 3] = [
        DriverStyle::Aggressive,
        DriverStyle::Balanced,
        DriverStyle::Conservative,
    ];
    pub fn name(self) -> &'static str {
        match self {
            DriverStyle::Aggressive => "aggressive",
            DriverStyle::Balanced => "balanced",
            DriverStyle::Conservative => "conservative",
            DriverStyle::Hesitant => "hesitant",
        }
    }
}

/// Extra lag a driver without the right of way needs to go first, s (see the module docs).
pub const MINOR_ROAD_EXTRA_S: f64 = 2.4;
/// Below this speed a vehicle counts as standing for a hesitant driver's patience, m/s.
pub const STAND_MPS: f64 = 0.5;

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
    /// Range of the patience of a driver who waits for a sign, s; `None`: it never waits
    /// for one.
    pub patience_s: Option<(f64, f64)>,
}

impl DriverParams {
    pub fn of(style: DriverStyle) -> DriverParams {
        match style {
            DriverStyle::Aggressive => DriverParams {
                desired_factor: 1.15,
                headway_s: 1.0,
                a_max: 2.0,
                b_comf: 3.0,
                s0_m: 1.5,
                reaction_s: 0.6,
                gap_s: -0.5,
                compliance: 0.5,
                noise_mps2: 0.3,
                patience_s: None,
            },
            DriverStyle::Balanced => DriverParams {
                desired_factor: 1.0,
                headway_s: 1.5,
                a_max: 1.5,
                b_comf: 2.0,
                s0_m: 2.0,
                reaction_s: 1.0,
                gap_s: 1.0,
                compliance: 0.8,
                noise_mps2: 0.2,
                patience_s: None,
            },
            DriverStyle::Conservative => DriverParams {
                desired_factor: 0.9,
                headway_s: 2.0,
                a_max: 1.0,
                b_comf: 1.5,
                s0_m: 3.0,
                reaction_s: 1.4,
                gap_s: 2.5,
                compliance: 0.95,
                noise_mps2: 0.1,
                patience_s: None,
            },
            DriverStyle::Hesitant => DriverParams {
                desired_factor: 0.9,
                headway_s: 2.0,
                a_max: 1.0,
                b_comf: 2.0,
                s0_m: 1.5,
                reaction_s: 1.4,
                gap_s: 4.0,
                compliance: 0.95,
                noise_mps2: 0.1,
                patience_s: Some((6.0, 10.0)),
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

/// What the driver does in the next step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reaction {
    /// Acceleration, m/s².
    pub accel: f64,
    /// Braking the CAV imposes on it (see the module docs), m/s², ≥ 0.
    pub imposed_mps2: f64,
}

/// A hesitant driver's wait before the conflict zone.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Hesitation {
    /// The CAV moved into the conflict zone: wait until it has cleared it.
    cav_entered: bool,
    /// Time both stood without a sign, s.
    stood_s: f64,
}

/// One HDV's driver.
#[derive(Clone, Debug)]
pub struct HumanDriver {
    pub style: DriverStyle,
    pub p: DriverParams,
    desired_mps: f64,
    rng: SmallRng,
    noise: Normal<f64>,
    /// Drawn from [`DriverParams::patience_s`], s.
    patience_s: Option<f64>,
    /// The CAV's (distance to the conflict, speed) as perceived, oldest first.
    perceived: VecDeque<(f64, f64)>,
    /// Goes first (`true`) or yields; frozen once committed.
    goes_first: Option<bool>,
    committed: bool,
    /// The last eHMI message and whether the driver complies with it.
    heard: Option<(Signal, bool)>,
    /// Set once a hesitant driver waits for a sign.
    hesitation: Option<Hesitation>,
}

impl HumanDriver {
    pub fn new(style: DriverStyle, initial_speed: f64, seed: u64) -> Self {
        let p = DriverParams::of(style);
        let mut rng = SmallRng::seed_from_u64(seed);
        let patience_s = p.patience_s.map(|(lo, hi)| rng.random_range(lo..hi));
        HumanDriver {
            style,
            p,
            desired_mps: (initial_speed * p.desired_factor).max(3.0),
            rng,
            noise: Normal::new(0.0, p.noise_mps2).expect("a finite deviation"),
            patience_s,
            perceived: VecDeque::new(),
            goes_first: None,
            committed: false,
            heard: None,
            hesitation: None,
        }
    }

    /// Whether the driver has decided to go first (`None`: not yet).
    pub fn goes_first(&self) -> Option<bool> {
        self.goes_first
    }

    /// The patience of a driver who waits for a sign, s.
    pub fn patience_s(&self) -> Option<f64> {
        self.patience_s
    }

    /// Whether the driver waits for a sign (or has waited for one).
    pub fn hesitating(&self) -> bool {
        self.hesitation.is_some()
    }

    /// What the driver of HDV `i` does next, given the world and the CAV's eHMI message.
    pub fn act(&mut self, w: &World, i: usize, ehmi: Option<Signal>) -> Reaction {
        let me = &w.hdvs[i];
        let zone = me.zone_half_m;
        let (ego_d, hdv_d) = w.to_conflict(i);
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
        let v = me.car.v;
        let stop_dist = v * v / (2.0 * self.p.b_comf) + self.p.s0_m;
        let zone_entry = hdv_d - zone;
        let ego_clear = seen_d < -zone;
        let past = hdv_d < -zone;
        // A decision to go is frozen once the driver could no longer stop; a decision to yield
        // is looked at again every step (a waiting CAV is let through no longer than needed).
        if !self.committed && !past {
            let lag = time_to(seen_d, seen_v) - time_to(hdv_d, v);
            let unclear = seen_d > zone && lag.abs() < self.p.gap_s;
            let go = match self.patience_s {
                Some(patience)
                    if self.hesitation.is_some() || (unclear && zone_entry > stop_dist) =>
                {
                    let h = self.hesitation.get_or_insert_default();
                    h.cav_entered |= seen_d <= zone && !ego_clear;
                    let sign = self.heard.filter(|&(_, complies)| complies).map(|(s, _)| s);
                    if sign.is_none() && !h.cav_entered && v < STAND_MPS && seen_v < STAND_MPS {
                        h.stood_s += DT;
                    }
                    let released =
                        !h.cav_entered && (sign == Some(Signal::Yield) || h.stood_s >= patience);
                    ego_clear || released
                }
                _ => {
                    let needed = if me.has_priority {
                        self.p.gap_s
                    } else {
                        self.p.gap_s + MINOR_ROAD_EXTRA_S
                    };
                    let cav_waits = seen_v < 0.3 && seen_d > zone;
                    let mut go = lag >= needed || ego_clear || cav_waits;
                    match self.heard {
                        Some((Signal::Yield, true)) if seen_d > zone => go = true,
                        Some((Signal::Proceed, true)) if zone_entry > stop_dist * 0.5 => go = false,
                        _ => {}
                    }
                    go
                }
            };
            self.goes_first = Some(go);
            self.committed = go && zone_entry < stop_dist;
        }
        // The HDV ahead on the lane, and the CAV's constraint: in the merge, a CAV past the
        // merge point and ahead is a leader on the same path; else the stop line while yielding.
        let (gap, v_lead) = w.leader_of(i);
        let free = idm(v, self.desired_mps, gap, v_lead, &self.p);
        let merged_ahead = w.kind == ScenarioKind::Merge && ego_d < 0.0 && ego_d < hdv_d;
        let cav = if merged_ahead {
            Some(((hdv_d - ego_d - CAR_LENGTH_M).max(0.1), w.ego.v))
        } else if self.goes_first == Some(false) && !ego_clear && !past {
            Some((zone_entry.max(0.1), 0.0))
        } else {
            None
        };
        let floor = -2.0 * self.p.b_comf.max(3.0);
        let constrained = cav.map(|(gap, v_lead)| idm(v, self.desired_mps, gap, v_lead, &self.p));
        let imposed_mps2 = match constrained {
            Some(a) if a < free => (-a.max(floor)).max(0.0),
            _ => 0.0,
        };
        let a = constrained.map_or(free, |a| a.min(free)) + self.noise.sample(&mut self.rng);
        Reaction {
            accel: a.max(floor),
            imposed_mps2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A driver without acceleration noise.
    fn quiet(style: DriverStyle, seed: u64) -> HumanDriver {
        let mut d = HumanDriver::new(style, 8.0, seed);
        d.p.noise_mps2 = 0.0;
        d.noise = Normal::new(0.0, 0.0).unwrap();
        d
    }

    #[test]
    fn idm_free_road_and_standstill_behind_a_stopped_leader() {
        let p = DriverParams::of(DriverStyle::Balanced);
        assert!((idm(0.0, 10.0, f64::INFINITY, 0.0, &p) - p.a_max).abs() < 1e-12);
        assert!(idm(10.0, 10.0, f64::INFINITY, 0.0, &p).abs() < 1e-12);
        // At standstill the minimum gap is the equilibrium; at half of it, a_max·(1 − 4).
        assert!(idm(0.0, 10.0, p.s0_m, 0.0, &p).abs() < 1e-12);
        assert!((idm(0.0, 10.0, p.s0_m / 2.0, 0.0, &p) + 3.0 * p.a_max).abs() < 1e-12);
    }

    #[test]
    fn a_conservative_driver_yields_to_a_cav_that_arrives_first_and_an_aggressive_one_goes() {
        for (style, expect_go) in [
            (DriverStyle::Conservative, false),
            (DriverStyle::Aggressive, true),
        ] {
            let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
            // The CAV 0.25 s ahead at the conflict point.
            w.ego.s = w.hdvs[0].ego_conflict_s - 20.0;
            w.hdvs[0].car.s = w.hdvs[0].conflict_s - 22.0;
            let mut d = HumanDriver::new(style, 8.0, 1);
            for _ in 0..3 {
                d.act(&w, 0, None);
            }
            assert_eq!(d.goes_first(), Some(expect_go), "{style:?}");
        }
    }

    #[test]
    fn a_compliant_driver_goes_when_told_to_go_ahead() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        w.ego.s = w.hdvs[0].ego_conflict_s - 20.0;
        w.hdvs[0].car.s = w.hdvs[0].conflict_s - 40.0;
        let mut p = HumanDriver::new(DriverStyle::Conservative, 8.0, 3);
        p.p.compliance = 1.0;
        p.act(&w, 0, None);
        assert_eq!(p.goes_first(), Some(false));
        p.act(&w, 0, Some(Signal::Yield));
        assert_eq!(p.goes_first(), Some(true));
    }

    #[test]
    fn a_yielding_driver_stops_before_the_zone() {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let zone = w.hdvs[0].zone_half_m;
        w.ego.v = 0.0;
        w.ego.s = w.hdvs[0].ego_conflict_s - zone - 1.0;
        let mut d = quiet(DriverStyle::Conservative, 2);
        // The CAV waits just before the zone (a long lag: the driver would go) but says it
        // goes first, to a driver who always complies.
        d.p.compliance = 1.0;
        for _ in 0..600 {
            let r = d.act(&w, 0, Some(Signal::Proceed));
            w.step(0.0, &[r.accel]);
        }
        let (_, hdv_d) = w.to_conflict(0);
        assert!(
            hdv_d > zone - 0.5,
            "stopped {hdv_d} m before the conflict point"
        );
        assert!(w.hdvs[0].car.v < 0.1);
    }

    /// What the CAV of [`hesitant_run`] does once it stands before the zone.
    #[derive(Clone, Copy)]
    enum Then {
        Stays,
        /// Moves off at 1.5 m/s² at this time, s.
        GoesAt(f64),
        /// Moves off at this time, s, and stops again 2 m into the zone.
        StallsInZoneAt(f64),
    }

    /// The paper's start at 8 m/s with a hesitant driver; the CAV keeps 8 m/s, brakes at
    /// 2 m/s² to a stop 2 m before the zone (at 7.4 s), shows `sign` from `sign_at_s` (or
    /// nothing), and `then` does what it says. Returns the world and the driver after 40 s,
    /// and when the HDV first entered its zone.
    fn hesitant_run(
        sign: Option<Signal>,
        sign_at_s: f64,
        then: Then,
    ) -> (World, HumanDriver, Option<f64>) {
        let mut w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let mut d = quiet(DriverStyle::Hesitant, 11);
        d.p.compliance = 1.0;
        let zone = w.hdvs[0].zone_half_m;
        let mut entered = None;
        while w.t < 40.0 {
            let (ego_d, hdv_d) = w.to_conflict(0);
            if entered.is_none() && hdv_d <= zone {
                entered = Some(w.t);
            }
            let ego_a = match then {
                Then::StallsInZoneAt(t) if w.t >= t && ego_d <= zone - 2.0 => -3.0,
                Then::GoesAt(t) | Then::StallsInZoneAt(t) if w.t >= t => 1.5,
                _ => {
                    let to_stop = (ego_d - zone - 2.0).max(0.01);
                    let braking = w.ego.v * w.ego.v / (2.0 * to_stop);
                    if braking < 2.0 {
                        0.0
                    } else {
                        -braking
                    }
                }
            };
            let shown = (w.t >= sign_at_s).then_some(sign).flatten();
            let r = d.act(&w, 0, shown);
            w.step(ego_a, &[r.accel]);
        }
        (w, d, entered)
    }

    #[test]
    fn a_hesitant_driver_stops_before_the_zone_and_goes_when_told_to() {
        let (_, d, entered) = hesitant_run(None, 0.0, Then::Stays);
        let patience = d.patience_s().expect("a hesitant driver has patience");
        assert!((6.0..10.0).contains(&patience));
        assert!(d.hesitating());
        // Both stop; after its patience the driver goes.
        let entered = entered.expect("goes in the end");
        assert!(entered > patience + 5.0, "entered at {entered} s");
        // Told to go ahead once both stand (10 s), it goes at once.
        let (_, _, told) = hesitant_run(Some(Signal::Yield), 10.0, Then::Stays);
        let told = told.expect("goes when told");
        assert!(told > 10.0 && told < 14.0, "entered at {told} s");
        assert!(told < entered);
    }

    #[test]
    fn a_hesitant_driver_told_the_cav_goes_first_waits_until_it_has_cleared() {
        // "I am going first" from 10 s, and the CAV stays: the driver waits out 40 s.
        let (w, _, entered) = hesitant_run(Some(Signal::Proceed), 10.0, Then::Stays);
        assert_eq!(entered, None, "waited");
        assert!(w.hdvs[0].car.v < 0.1);
        // The CAV moves off at 12 s: the driver enters only once it has cleared the zone.
        let (w, _, entered) = hesitant_run(Some(Signal::Proceed), 10.0, Then::GoesAt(12.0));
        let entered = entered.expect("goes once the CAV has cleared");
        let ego_cleared_s = 12.0 + (2.0 * (2.0 + 2.0 * w.hdvs[0].zone_half_m) / 1.5).sqrt();
        assert!(
            entered > ego_cleared_s,
            "{entered} s, CAV clear at {ego_cleared_s} s"
        );
        // Without a word, a CAV that moves into the zone is waited for too ...
        let (_, _, entered) = hesitant_run(None, 0.0, Then::GoesAt(12.0));
        assert!(entered.expect("goes after the CAV") > ego_cleared_s);
        // ... also when it stops there: patience no longer counts.
        let (w, _, entered) = hesitant_run(None, 0.0, Then::StallsInZoneAt(12.0));
        assert_eq!(entered, None, "waited");
        let (ego_d, _) = w.to_conflict(0);
        assert!(ego_d.abs() < w.hdvs[0].zone_half_m && w.ego.v == 0.0);
    }

    #[test]
    fn a_minor_road_driver_yields_unless_it_clears_the_zone_well_before_the_cav() {
        // The CAV 1.5 s behind at the conflict point: enough for a balanced driver with the
        // right of way (lag 1 s), not for one on the minor road (1 + 2.4 s).
        let lagged = |kind| {
            let mut w = World::new(kind, 8.0, 0.0);
            w.ego.s = w.hdvs[0].ego_conflict_s - 32.0;
            w.hdvs[0].car.s = w.hdvs[0].conflict_s - 20.0;
            w
        };
        let mut major = HumanDriver::new(DriverStyle::Balanced, 8.0, 1);
        major.act(&lagged(ScenarioKind::LeftTurn), 0, None);
        assert_eq!(major.goes_first(), Some(true));
        let mut minor = quiet(DriverStyle::Balanced, 1);
        let mut w = lagged(ScenarioKind::LeftTurnPriority);
        let r = minor.act(&w, 0, None);
        assert_eq!(minor.goes_first(), Some(false));
        assert!(r.accel < 0.0 && r.imposed_mps2 == -r.accel, "{r:?}");
        // 6.5 s from the conflict point (lag 4 s ≥ 3.4 s): it goes.
        w.ego.s = w.hdvs[0].ego_conflict_s - 52.0;
        let mut minor = quiet(DriverStyle::Balanced, 1);
        let r = minor.act(&w, 0, None);
        assert_eq!(minor.goes_first(), Some(true));
        assert_eq!(r.imposed_mps2, 0.0);
    }

    #[test]
    fn imposed_braking_counts_the_cavs_constraint_only_when_it_binds() {
        let mut w = World::with_followers(ScenarioKind::Stream, 8.0, 0.0, &[2.0]);
        // The CAV 1 s ahead of the first HDV at the conflict point: a conservative driver yields.
        w.ego.s = w.hdvs[0].ego_conflict_s - 24.0;
        w.hdvs[0].car.s = w.hdvs[0].conflict_s - 32.0;
        w.hdvs[1].car.s = w.hdvs[0].car.s - 8.0;
        let (mut first, mut second) = (
            quiet(DriverStyle::Conservative, 1),
            quiet(DriverStyle::Conservative, 2),
        );
        let r1 = first.act(&w, 0, None);
        let r2 = second.act(&w, 1, None);
        assert_eq!(
            (first.goes_first(), second.goes_first()),
            (Some(false), Some(false))
        );
        assert!(
            r1.imposed_mps2 > 0.5 && r1.imposed_mps2 == -r1.accel,
            "{r1:?}"
        );
        // The follower brakes harder, for its leader 3.5 m ahead: not the CAV's doing.
        assert!(r2.accel < r1.accel && r2.imposed_mps2 == 0.0, "{r2:?}");
        // No constraint, no imposed braking, even when braking for the leader.
        w.ego.s = 0.0;
        w.ego.v = 0.0;
        let r2 = quiet(DriverStyle::Aggressive, 2).act(&w, 1, None);
        assert!(r2.accel < 0.0 && r2.imposed_mps2 == 0.0, "{r2:?}");
    }
}
