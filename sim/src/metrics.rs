//! Per-episode metrics from the recorded states. Every HDV has its own conflict zone (of
//! half-length `zone_half_m` along both lanes around its conflict point with the CAV); "the
//! conflict zone" of the CAV is all of them: it has cleared it once it has left every one.
//!
//! * **Average speed** of the CAV, m/s, and **average |jerk|**, the mean of |Δa/Δt| of its
//!   acceleration, m/s³, until it is through (15 m past the conflict zone).
//! * **Conflict duration**, s: from the first step at which some HDV and the CAV are both still
//!   before the end of that HDV's zone and their |ΔTTC| to its conflict point (guarded TTC =
//!   distance / max(v, 0.5 m/s)) is below the threshold ΔT_th (the core's, 4 s), until the CAV
//!   has cleared the conflict zone or every HDV that conflicted so before then has left its
//!   zone, whichever is first. 0 when |ΔTTC| never falls below it. With one HDV: until the
//!   first of the two leaves the zone.
//! * **Minimum TTC**, s: at each step and for each HDV, with both speeds held, the time until
//!   both would be in its zone at once (when their occupancy intervals overlap); the minimum
//!   over the episode and the HDVs (∞ when they never would).
//! * **PET** (post-encroachment time), s: per HDV, from the first of it and the CAV leaving its
//!   passage (the zone at a crossing; at a merge, half a car length around the merge point, so
//!   the PET is the time gap there) to the other entering it (∞ when the other never enters);
//!   the smallest over the HDVs.
//! * **Collision** (footprints overlapped), **success** (the CAV drove 15 m past the conflict
//!   zone without collision within the time limit), **time to clear** (when the CAV cleared the
//!   conflict zone; the stream's measure of delay), s.
//! * **Imposed deceleration**, m/s²: the largest braking the CAV imposed on any HDV (its
//!   driver's acceleration with the CAV's constraint when that is negative and below the one
//!   without, noise left out; see `driver`), and the part of it at the first step
//!   (**imposed at the start**: the scene as drawn, before any decision of the CAV has moved
//!   it, which every controller imposes alike).
//! * **Standing**, s: the time the CAV stood (speed < [`STOOD_MPS`]) before it cleared the
//!   conflict zone.
//! * **Stood in a crossing**: whether the CAV ever stood (speed < [`STOOD_MPS`]) with a corner
//!   of its footprint inside the band of an HDV's lane (centre line ± half its width) within
//!   the junction (the bounding box of the lanes' stop lines).
//! * **Wait while the other stands**, s: the longest stretch, and the total, of steps at which
//!   the CAV stood before the zone of the HDV it waits for (the HDV nearest its zone entry
//!   among those not yet in or past their zone) while that HDV also stood before it, both
//!   below [`WAIT_STAND_MPS`], with no HDV inside a zone: the deadlock time.
//!
//! * **eHMI changes**: how often the CAV's eHMI message changed before it cleared the conflict
//!   zone (a message that flickers makes a driver who complies brake for nothing).
//!
//! Durations sum the sample intervals that start at a step with the property.

use concord_core::scene::{Lane, Vec2};

use crate::driver::Signal;
use crate::world::footprint;

/// Below this speed the CAV stands, for standing time and standing in a crossing, m/s.
pub const STOOD_MPS: f64 = 0.1;
/// Below this speed both stand, for the deadlock time, m/s.
pub const WAIT_STAND_MPS: f64 = 0.5;

/// One HDV at one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HdvSample {
    /// Distances of the CAV and the HDV to their conflict point along their lanes, m.
    pub ego_d: f64,
    pub d: f64,
    /// Speed, m/s.
    pub v: f64,
    /// Braking the CAV imposed on it this step, m/s².
    pub imposed_mps2: f64,
}

/// One recorded step.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub t: f64,
    /// The CAV's speed, m/s, acceleration, m/s², position, m, and heading, rad.
    pub ego_v: f64,
    pub ego_a: f64,
    pub ego_pos: Vec2,
    pub ego_heading: f64,
    pub collided: bool,
    /// The CAV's eHMI message this step (`None`: none shown).
    pub ehmi: Option<Signal>,
    /// Every HDV, in the world's order.
    pub hdvs: Vec<HdvSample>,
}

/// What the metrics need besides the samples.
#[derive(Clone, Debug)]
pub struct Layout {
    /// ΔT_th, s.
    pub delta_ttc_s: f64,
    /// Each HDV's conflict-zone half-length, m, in the world's order.
    pub zone_half_m: Vec<f64>,
    /// Half-length of the stretch around each HDV's conflict point whose occupancy gives the
    /// PET, m: the zone at a crossing; at a merge, half a car length (the PET is then the time
    /// gap at the merge point: after it the two cars follow each other inside the zone).
    pub pass_half_m: Vec<f64>,
    /// The HDVs' lanes, each once.
    pub crossing_lanes: Vec<Lane>,
    /// The junction's bounding box (lower-left, upper-right corner), m.
    pub junction: (Vec2, Vec2),
}

/// The metrics of one episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    pub avg_speed_mps: f64,
    pub avg_abs_jerk_mps3: f64,
    pub conflict_duration_s: f64,
    pub min_ttc_s: f64,
    pub pet_s: f64,
    pub collision: bool,
    pub success: bool,
    pub time_to_clear_s: f64,
    pub imposed_decel_mps2: f64,
    pub imposed_at_start_mps2: f64,
    pub standing_s: f64,
    pub stood_in_crossing: bool,
    /// The longest and the total deadlock time, s.
    pub wait_while_other_stands_s: f64,
    pub wait_while_other_stands_total_s: f64,
    pub ehmi_changes: u32,
}

/// Guarded time to cover `d` m at `v` m/s.
fn ttc(d: f64, v: f64) -> f64 {
    d.max(0.0) / v.max(0.5)
}

/// Occupancy interval [enter, leave] of a zone of half-length `zone` from now at constant
/// speed, s.
fn occupancy(d: f64, v: f64, zone: f64) -> (f64, f64) {
    let v = v.max(1e-6);
    (((d - zone) / v).max(0.0), ((d + zone) / v).max(0.0))
}

/// Whether a footprint corner at `p` lies in a crossing lane's band within the junction.
fn in_crossing(p: Vec2, layout: &Layout) -> bool {
    let (lo, hi) = layout.junction;
    (lo.x..=hi.x).contains(&p.x)
        && (lo.y..=hi.y).contains(&p.y)
        && layout.crossing_lanes.iter().any(|lane| {
            let f = lane.project(p);
            f.l.abs() <= lane.half_width && (0.0..=lane.length()).contains(&f.s)
        })
}

/// Computes the metrics of `samples` (at a fixed step, at least one HDV) in `layout`.
pub fn compute(samples: &[Sample], layout: &Layout) -> Metrics {
    let zone = |i: usize| layout.zone_half_m[i];
    let left = |d: f64, i: usize| d < -zone(i);
    let inside = |d: f64, i: usize| d.abs() <= zone(i);
    let n_hdvs = layout.zone_half_m.len();
    // Speed and jerk count until the CAV is through (15 m past the zone).
    let through = |s: &Sample| {
        s.hdvs
            .iter()
            .enumerate()
            .all(|(i, h)| h.ego_d < -(zone(i) + 15.0))
    };
    let cleared = |s: &Sample| s.hdvs.iter().enumerate().all(|(i, h)| left(h.ego_d, i));
    let until = samples
        .iter()
        .position(through)
        .map_or(samples.len(), |i| i + 1);
    let driven = &samples[..until];
    let n = driven.len().max(1) as f64;
    let avg_speed = driven.iter().map(|s| s.ego_v).sum::<f64>() / n;
    let jerk: Vec<f64> = driven
        .windows(2)
        .map(|w| ((w[1].ego_a - w[0].ego_a) / (w[1].t - w[0].t)).abs())
        .collect();
    let avg_jerk = if jerk.is_empty() {
        0.0
    } else {
        jerk.iter().sum::<f64>() / jerk.len() as f64
    };
    let conflicts = |s: &Sample, i: usize| {
        let h = &s.hdvs[i];
        !left(h.ego_d, i)
            && !left(h.d, i)
            && (ttc(h.ego_d, s.ego_v) - ttc(h.d, h.v)).abs() < layout.delta_ttc_s
    };
    let clear_at = samples.iter().position(cleared);
    let start = samples
        .iter()
        .position(|s| (0..n_hdvs).any(|i| conflicts(s, i)));
    let last_t = samples.last().map_or(0.0, |l| l.t);
    let conflict = match start {
        None => 0.0,
        Some(a) => {
            let before = &samples[..clear_at.map_or(samples.len(), |c| c + 1)];
            // When the last HDV that conflicted before the CAV cleared has left its zone.
            let hdvs_gone = (0..n_hdvs)
                .filter(|&i| before.iter().any(|s| conflicts(s, i)))
                .map(|i| {
                    samples
                        .iter()
                        .find(|s| left(s.hdvs[i].d, i))
                        .map_or(last_t, |s| s.t)
                })
                .fold(f64::NEG_INFINITY, f64::max);
            let end = clear_at.map_or(last_t, |c| samples[c].t).min(hdvs_gone);
            end - samples[a].t
        }
    };
    let min_ttc = (0..n_hdvs)
        .flat_map(|i| {
            samples
                .iter()
                .filter(move |s| !left(s.hdvs[i].ego_d, i) && !left(s.hdvs[i].d, i))
                .filter_map(move |s| {
                    let h = &s.hdvs[i];
                    let (e0, e1) = occupancy(h.ego_d, s.ego_v, zone(i));
                    let (h0, h1) = occupancy(h.d, h.v, zone(i));
                    (e0 <= h1 && h0 <= e1).then(|| e0.max(h0))
                })
        })
        .fold(f64::INFINITY, f64::min);
    let pet = (0..n_hdvs)
        .map(|i| {
            let first = |f: &dyn Fn(&HdvSample) -> bool| {
                samples.iter().find(|s| f(&s.hdvs[i])).map(|s| s.t)
            };
            let pass = layout.pass_half_m[i];
            let ego_in = first(&|h| h.ego_d.abs() <= pass);
            let ego_out = first(&|h| h.ego_d < -pass);
            let hdv_in = first(&|h| h.d.abs() <= pass);
            let hdv_out = first(&|h| h.d < -pass);
            // Whoever left first, and when the other entered.
            match (ego_out, hdv_out) {
                (Some(e), h) if h.is_none_or(|h| e <= h) => {
                    hdv_in.map_or(f64::INFINITY, |i| (i - e).max(0.0))
                }
                (_, Some(h)) => ego_in.map_or(f64::INFINITY, |i| (i - h).max(0.0)),
                _ => f64::INFINITY,
            }
        })
        .fold(f64::INFINITY, f64::min);
    let collision = samples.iter().any(|s| s.collided);
    let on = samples.iter().any(through);
    let imposed = samples
        .iter()
        .flat_map(|s| s.hdvs.iter().map(|h| h.imposed_mps2))
        .fold(0.0, f64::max);
    // Each sample's interval to the next.
    let dt = |k: usize| samples.get(k + 1).map_or(0.0, |n| n.t - samples[k].t);
    let standing = (0..clear_at.unwrap_or(samples.len()))
        .filter(|&k| samples[k].ego_v < STOOD_MPS)
        .map(dt)
        .fold(0.0, |a, b| a + b);
    let stood_in_crossing = samples.iter().any(|s| {
        s.ego_v < STOOD_MPS
            && footprint(s.ego_pos, s.ego_heading)
                .iter()
                .any(|&c| in_crossing(c, layout))
    });
    let deadlocked = |s: &Sample| {
        let none_inside = s.hdvs.iter().enumerate().all(|(i, h)| !inside(h.d, i));
        let waited_for = s
            .hdvs
            .iter()
            .enumerate()
            .filter(|&(i, h)| h.d > zone(i))
            .min_by(|(i, a), (j, b)| (a.d - zone(*i)).total_cmp(&(b.d - zone(*j))));
        none_inside
            && s.ego_v < WAIT_STAND_MPS
            && waited_for.is_some_and(|(i, h)| h.v < WAIT_STAND_MPS && h.ego_d > zone(i))
    };
    let (mut longest, mut total, mut run) = (0.0_f64, 0.0, 0.0);
    for (k, s) in samples.iter().enumerate() {
        if deadlocked(s) {
            run += dt(k);
            total += dt(k);
            longest = longest.max(run);
        } else {
            run = 0.0;
        }
    }
    let shown: Vec<Signal> = samples[..clear_at.unwrap_or(samples.len())]
        .iter()
        .filter_map(|s| s.ehmi)
        .collect();
    let ehmi_changes = shown.windows(2).filter(|w| w[0] != w[1]).count() as u32;
    Metrics {
        avg_speed_mps: avg_speed,
        avg_abs_jerk_mps3: avg_jerk,
        conflict_duration_s: conflict,
        min_ttc_s: min_ttc,
        pet_s: pet,
        collision,
        success: on && !collision,
        time_to_clear_s: clear_at.map_or(f64::INFINITY, |c| samples[c].t),
        imposed_decel_mps2: imposed,
        imposed_at_start_mps2: samples.first().map_or(0.0, |s| {
            s.hdvs.iter().map(|h| h.imposed_mps2).fold(0.0, f64::max)
        }),
        standing_s: standing,
        stood_in_crossing,
        wait_while_other_stands_s: longest,
        wait_while_other_stands_total_s: total,
        ehmi_changes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{ScenarioKind, World};
    use concord_map::paper;

    /// A layout of `n` HDVs with zones of 5 m, no crossing lanes.
    fn zones(n: usize) -> Layout {
        Layout {
            delta_ttc_s: 4.0,
            zone_half_m: vec![5.0; n],
            pass_half_m: vec![5.0; n],
            crossing_lanes: Vec::new(),
            junction: (Vec2::ZERO, Vec2::ZERO),
        }
    }

    /// The CAV and HDVs at constant speeds from given (distance, speed), 0.1 s steps for
    /// `secs`; the CAV's distance is the same to every conflict point.
    fn straight(ego: (f64, f64), hdvs: &[(f64, f64)], secs: f64) -> Vec<Sample> {
        (0..=(secs / 0.1).round() as usize)
            .map(|i| {
                let t = i as f64 * 0.1;
                Sample {
                    t,
                    ego_v: ego.1,
                    ego_a: 0.0,
                    ego_pos: Vec2::new(100.0, 100.0),
                    ego_heading: 0.0,
                    collided: false,
                    ehmi: None,
                    hdvs: hdvs
                        .iter()
                        .map(|h| HdvSample {
                            ego_d: ego.0 - ego.1 * t,
                            d: h.0 - h.1 * t,
                            v: h.1,
                            imposed_mps2: 0.0,
                        })
                        .collect(),
                }
            })
            .collect()
    }

    const STEP: f64 = 0.1 + 1e-9;

    #[test]
    fn constant_speeds_give_the_textbook_values() {
        // CAV 30 m away at 10 m/s: in the zone 2.5–3.5 s. HDV 60 m away at 10 m/s: 5.5–6.5 s.
        let m = compute(&straight((30.0, 10.0), &[(60.0, 10.0)], 10.0), &zones(1));
        assert!((m.avg_speed_mps - 10.0).abs() < 1e-9);
        assert_eq!(m.avg_abs_jerk_mps3, 0.0);
        // |ΔTTC| = 3 s < 4 s from the start; the CAV leaves the zone at 3.5 s (the first
        // sample after: 3.6 s).
        assert!(
            (m.conflict_duration_s - 3.5).abs() <= STEP,
            "{}",
            m.conflict_duration_s
        );
        // The second enters at 5.5 s, 2 s after the first left.
        assert!((m.pet_s - 2.0).abs() <= STEP, "{}", m.pet_s);
        assert_eq!(
            m.min_ttc_s,
            f64::INFINITY,
            "their occupancies never overlap"
        );
        assert!((m.time_to_clear_s - 3.5).abs() <= STEP);
        assert!(m.success && !m.collision);
        assert_eq!((m.standing_s, m.imposed_decel_mps2), (0.0, 0.0));
        assert!(!m.stood_in_crossing);
        assert_eq!(m.wait_while_other_stands_s, 0.0);
    }

    #[test]
    fn overlapping_occupancy_gives_a_finite_ttc_and_far_apart_no_conflict() {
        // Both 30 m away at 10 m/s: they would meet in the zone 2.5 s from the start.
        let m = compute(&straight((30.0, 10.0), &[(30.0, 10.0)], 3.0), &zones(1));
        assert!(m.min_ttc_s < 0.11, "{}", m.min_ttc_s);
        let first = compute(&straight((30.0, 10.0), &[(30.0, 10.0)], 0.0), &zones(1));
        assert!((first.min_ttc_s - 2.5).abs() < 1e-9);
        // ΔTTC 10 s: never a conflict.
        let far = compute(&straight((30.0, 10.0), &[(130.0, 10.0)], 8.0), &zones(1));
        assert_eq!(far.conflict_duration_s, 0.0);
    }

    #[test]
    fn jerk_collision_and_failure() {
        let mut s = straight((30.0, 5.0), &[(200.0, 5.0)], 1.0);
        for (i, x) in s.iter_mut().enumerate() {
            x.ego_a = if i % 2 == 0 { 1.0 } else { -1.0 };
        }
        s[5].collided = true;
        let m = compute(&s, &zones(1));
        assert!((m.avg_abs_jerk_mps3 - 20.0).abs() < 1e-9);
        assert!(m.collision && !m.success);
        assert_eq!(m.time_to_clear_s, f64::INFINITY);
    }

    #[test]
    fn several_hdvs_smallest_pet_and_ttc_and_conflict_until_the_last_conflicting_one_left() {
        // Two HDVs at 10 m/s, 20 and 50 m away: in the zone 1.5–2.5 s and 4.5–5.5 s. The CAV
        // 80 m away at 10 m/s: 7.5–8.5 s.
        let m = compute(
            &straight((80.0, 10.0), &[(20.0, 10.0), (50.0, 10.0)], 10.0),
            &zones(2),
        );
        // The second (ΔTTC 3 s) conflicts from the start and leaves at 5.5 s, before the CAV
        // enters; the first never conflicts (ΔTTC 6 s).
        assert!(
            (m.conflict_duration_s - 5.5).abs() <= STEP,
            "{}",
            m.conflict_duration_s
        );
        // PETs 5 s and 2 s: the smallest.
        assert!((m.pet_s - 2.0).abs() <= STEP, "{}", m.pet_s);
        // At one instant: the CAV in the zone 2.5–3.5 s from now, the first HDV 5.5–6.5 s (no
        // overlap), the second 2.7–3.7 s (TTC 2.7 s).
        let m = compute(
            &straight((30.0, 10.0), &[(60.0, 10.0), (32.0, 10.0)], 0.0),
            &zones(2),
        );
        assert!((m.min_ttc_s - 2.7).abs() < 1e-9, "{}", m.min_ttc_s);
        // The CAV goes between the two: the conflict ends when it has cleared (3.5 s) although
        // the second, conflicting from the start, leaves later (6.5 s).
        let m = compute(
            &straight((30.0, 10.0), &[(10.0, 10.0), (60.0, 10.0)], 10.0),
            &zones(2),
        );
        assert!(
            (m.conflict_duration_s - 3.5).abs() <= STEP,
            "{}",
            m.conflict_duration_s
        );
    }

    #[test]
    fn ehmi_changes_count_each_new_message_until_the_cav_has_cleared() {
        // The CAV clears its zone (5 m past the point) at 2.0 s, from 15 m at 10 m/s.
        let mut s = straight((15.0, 10.0), &[(40.0, 5.0)], 3.0);
        let shows = |s: &mut [Sample], from: usize, to: usize, signal| {
            s[from..to].iter_mut().for_each(|x| x.ehmi = Some(signal));
        };
        shows(&mut s, 0, 5, Signal::Yield);
        shows(&mut s, 5, 6, Signal::Proceed);
        shows(&mut s, 6, 10, Signal::Yield);
        // Steps without a message do not split one; after clearing, changes do not count.
        s[7].ehmi = None;
        shows(&mut s, 25, 31, Signal::Proceed);
        assert_eq!(compute(&s, &zones(1)).ehmi_changes, 2);
        shows(&mut s, 12, 14, Signal::Proceed);
        assert_eq!(compute(&s, &zones(1)).ehmi_changes, 3);
    }

    #[test]
    fn imposed_deceleration_is_the_largest_over_hdvs_and_steps() {
        let mut s = straight((30.0, 10.0), &[(60.0, 10.0), (90.0, 10.0)], 5.0);
        s[3].hdvs[0].imposed_mps2 = 1.5;
        s[7].hdvs[1].imposed_mps2 = 2.5;
        s[8].hdvs[0].imposed_mps2 = 0.5;
        assert_eq!(compute(&s, &zones(2)).imposed_decel_mps2, 2.5);
        assert_eq!(compute(&s, &zones(2)).imposed_at_start_mps2, 0.0);
        s[0].hdvs[1].imposed_mps2 = 3.5;
        s[0].hdvs[0].imposed_mps2 = 1.0;
        let m = compute(&s, &zones(2));
        assert_eq!((m.imposed_decel_mps2, m.imposed_at_start_mps2), (3.5, 3.5));
    }

    /// The CAV drives 10 m/s for 2 s, stands 3 s 10 m before the zone, and drives on at 10
    /// m/s; the HDV stands 8 m from its conflict point (3 m before its zone) from 1 s to
    /// `hdv_stands_until` s, then passes at 10 m/s.
    fn stop_and_go(hdv_stands_until: f64) -> Vec<Sample> {
        (0..=150)
            .map(|k| {
                let t = k as f64 * 0.1;
                let (ego_d, ego_v) = if t < 2.0 {
                    (35.0 - 10.0 * t, 10.0)
                } else if t < 5.0 {
                    (15.0, 0.0)
                } else {
                    (15.0 - 10.0 * (t - 5.0), 10.0)
                };
                let (d, v) = if t < 1.0 {
                    (18.0 - 10.0 * t, 10.0)
                } else if t < hdv_stands_until {
                    (8.0, 0.0)
                } else {
                    (8.0 - 10.0 * (t - hdv_stands_until), 10.0)
                };
                Sample {
                    t,
                    ego_v,
                    ego_a: 0.0,
                    ego_pos: Vec2::new(100.0, 100.0),
                    ego_heading: 0.0,
                    collided: false,
                    ehmi: None,
                    hdvs: vec![HdvSample {
                        ego_d,
                        d,
                        v,
                        imposed_mps2: 0.0,
                    }],
                }
            })
            .collect()
    }

    #[test]
    fn standing_and_the_deadlock_time() {
        // The HDV stands until 4 s: both stand 2–4 s, then the CAV waits 1 s more alone.
        let m = compute(&stop_and_go(4.0), &zones(1));
        assert!((m.standing_s - 3.0).abs() <= STEP, "{}", m.standing_s);
        // Standing after it has cleared the zone (at 7 s) does not count.
        let mut s = stop_and_go(4.0);
        for x in s.iter_mut().filter(|x| x.t >= 12.0) {
            x.ego_v = 0.0;
        }
        assert_eq!(compute(&s, &zones(1)).standing_s, m.standing_s);
        assert!(
            (m.wait_while_other_stands_s - 2.0).abs() <= STEP,
            "{}",
            m.wait_while_other_stands_s
        );
        assert_eq!(
            m.wait_while_other_stands_total_s,
            m.wait_while_other_stands_s
        );
        // The HDV stands until 12 s: both stand 2–5 s; the CAV goes on and stood 3 s in all.
        let m = compute(&stop_and_go(12.0), &zones(1));
        assert!((m.wait_while_other_stands_s - 3.0).abs() <= STEP);
        assert!((m.standing_s - 3.0).abs() <= STEP);
        // Two stretches of 1 s: longest 1 s, total 2 s.
        let mut s = stop_and_go(12.0);
        for x in s.iter_mut().filter(|x| (3.0..4.0).contains(&x.t)) {
            x.ego_v = 1.0;
        }
        let m = compute(&s, &zones(1));
        assert!((m.wait_while_other_stands_s - 1.0).abs() <= STEP);
        assert!((m.wait_while_other_stands_total_s - 2.0).abs() <= STEP);
        // An HDV standing inside the zone is not waited for; and while one is in a zone, another
        // standing before it is no deadlock either.
        let mut s = stop_and_go(12.0);
        for x in &mut s {
            x.hdvs[0].d = 3.0;
        }
        assert_eq!(compute(&s, &zones(1)).wait_while_other_stands_s, 0.0);
        let mut s = stop_and_go(12.0);
        for x in &mut s {
            let waiting = x.hdvs[0];
            x.hdvs.insert(
                0,
                HdvSample {
                    d: 3.0,
                    v: 0.0,
                    ..waiting
                },
            );
        }
        assert_eq!(compute(&s, &zones(2)).wait_while_other_stands_s, 0.0);
    }

    #[test]
    fn standing_in_a_crossing_lane_is_found_from_the_lanes() {
        let w = World::new(ScenarioKind::LeftTurn, 8.0, 0.0);
        let layout = Layout {
            crossing_lanes: vec![*w.morph.lane(paper::HDV_STRAIGHT)],
            junction: w.junction(),
            ..zones(1)
        };
        let standing_at = |pos: Vec2, heading: f64, v: f64| {
            let mut s = straight((30.0, v), &[(60.0, 10.0)], 1.0);
            for x in &mut s {
                (x.ego_pos, x.ego_heading) = (pos, heading);
            }
            compute(&s, &layout).stood_in_crossing
        };
        let south = -std::f64::consts::FRAC_PI_2;
        // Heading south at x = −5, centred at y = −0.1: the front corners at y = −2.35, outside
        // the HDV's band y ∈ [−7.5, −2.5]; centred at y = −0.3, at y = −2.55: inside.
        assert!(!standing_at(Vec2::new(-5.0, -0.1), south, 0.0));
        assert!(standing_at(Vec2::new(-5.0, -0.3), south, 0.0));
        // Moving there is not standing.
        assert!(!standing_at(Vec2::new(-5.0, -0.3), south, 1.0));
        // In the band but outside the junction (x < −10): not a crossing.
        assert!(!standing_at(Vec2::new(-14.0, -5.0), 0.0, 0.0));
        assert!(standing_at(Vec2::new(-11.0, -5.0), 0.0, 0.0));
        // The CAV's own approach, clear of the HDV's lane.
        assert!(!standing_at(
            Vec2::new(12.0, 5.0),
            std::f64::consts::PI,
            0.0
        ));
    }
}
