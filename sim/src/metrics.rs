//! Per-episode metrics from the recorded states.
//!
//! * **Average speed** of the CAV over the episode, m/s; **average |jerk|**, the mean of
//!   |Δa/Δt| of its acceleration, m/s³.
//! * **Conflict duration**, s: from the first step at which both vehicles are still before the
//!   end of the conflict zone and their |ΔTTC| to the conflict point (guarded TTC = distance /
//!   max(v, 0.5 m/s)) is below the threshold ΔT_th (the core's, 4 s), until the first step at
//!   which one of them has left the conflict zone. 0 when |ΔTTC| never falls below it.
//! * **Minimum TTC**, s: at each step, with both speeds held, the time until both would be in
//!   the conflict zone at once (when their occupancy intervals overlap); the minimum over the
//!   episode (∞ when they never would).
//! * **PET** (post-encroachment time), s: from the first vehicle leaving the conflict zone to
//!   the second entering it (∞ when the second never enters).
//! * **Collision** (footprints overlapped), **success** (the CAV left the conflict zone and
//!   drove 15 m on without collision within the time limit), **time to clear** (when the CAV
//!   left the conflict zone), s.

/// One recorded step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub t: f64,
    /// Distances of the CAV and the HDV to the conflict point along their lanes, m.
    pub ego_d: f64,
    pub hdv_d: f64,
    pub ego_v: f64,
    pub hdv_v: f64,
    pub ego_a: f64,
    pub collided: bool,
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

/// Computes the metrics of `samples` (at a fixed step) with threshold `delta_ttc_s` and a
/// conflict zone of half-length `zone` m along each lane.
pub fn compute(samples: &[Sample], delta_ttc_s: f64, zone: f64) -> Metrics {
    // Speed and jerk count until the CAV is through (15 m past the zone).
    let through = |s: &Sample| s.ego_d < -(zone + 15.0);
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
    let left = |d: f64| d < -zone;
    let inside = |d: f64| d.abs() <= zone;
    let start = samples.iter().find(|s| {
        !left(s.ego_d)
            && !left(s.hdv_d)
            && (ttc(s.ego_d, s.ego_v) - ttc(s.hdv_d, s.hdv_v)).abs() < delta_ttc_s
    });
    let first_exit = samples.iter().find(|s| left(s.ego_d) || left(s.hdv_d));
    let conflict = match (start, first_exit) {
        (Some(a), Some(b)) if b.t >= a.t => b.t - a.t,
        (Some(a), None) => samples.last().map_or(0.0, |l| l.t - a.t),
        _ => 0.0,
    };
    let min_ttc = samples
        .iter()
        .filter(|s| !left(s.ego_d) && !left(s.hdv_d))
        .filter_map(|s| {
            let (e0, e1) = occupancy(s.ego_d, s.ego_v, zone);
            let (h0, h1) = occupancy(s.hdv_d, s.hdv_v, zone);
            (e0 <= h1 && h0 <= e1).then(|| e0.max(h0))
        })
        .fold(f64::INFINITY, f64::min);
    let leave = |f: fn(&Sample) -> f64| samples.iter().find(|s| left(f(s))).map(|s| s.t);
    let enter = |f: fn(&Sample) -> f64| samples.iter().find(|s| inside(f(s))).map(|s| s.t);
    let (ego_in, ego_out) = (enter(|s| s.ego_d), leave(|s| s.ego_d));
    let (hdv_in, hdv_out) = (enter(|s| s.hdv_d), leave(|s| s.hdv_d));
    // Whoever left first, and when the other entered.
    let pet = match (ego_out, hdv_out) {
        (Some(e), h) if h.is_none_or(|h| e <= h) => {
            hdv_in.map_or(f64::INFINITY, |i| (i - e).max(0.0))
        }
        (_, Some(h)) => ego_in.map_or(f64::INFINITY, |i| (i - h).max(0.0)),
        _ => f64::INFINITY,
    };
    let collision = samples.iter().any(|s| s.collided);
    let on = samples.iter().any(through);
    Metrics {
        avg_speed_mps: avg_speed,
        avg_abs_jerk_mps3: avg_jerk,
        conflict_duration_s: conflict,
        min_ttc_s: min_ttc,
        pet_s: pet,
        collision,
        success: on && !collision,
        time_to_clear_s: ego_out.unwrap_or(f64::INFINITY),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both vehicles at constant speeds from given distances, 0.1 s steps for `secs`.
    fn straight(ego: (f64, f64), hdv: (f64, f64), secs: f64) -> Vec<Sample> {
        (0..=(secs / 0.1).round() as usize)
            .map(|i| {
                let t = i as f64 * 0.1;
                Sample {
                    t,
                    ego_d: ego.0 - ego.1 * t,
                    hdv_d: hdv.0 - hdv.1 * t,
                    ego_v: ego.1,
                    hdv_v: hdv.1,
                    ego_a: 0.0,
                    collided: false,
                }
            })
            .collect()
    }

    #[test]
    fn constant_speeds_give_the_textbook_values() {
        // CAV 30 m away at 10 m/s: in the zone 2.5–3.5 s. HDV 60 m away at 10 m/s: 5.5–6.5 s.
        let m = compute(&straight((30.0, 10.0), (60.0, 10.0), 10.0), 4.0, 5.0);
        assert!((m.avg_speed_mps - 10.0).abs() < 1e-9);
        assert_eq!(m.avg_abs_jerk_mps3, 0.0);
        // |ΔTTC| = 3 s < 4 s from the start; the CAV leaves the zone at 3.5 s (the first
        // sample after: 3.6 s).
        let step = 0.1 + 1e-9;
        assert!(
            (m.conflict_duration_s - 3.5).abs() <= step,
            "{}",
            m.conflict_duration_s
        );
        // The second enters at 5.5 s, 2 s after the first left.
        assert!((m.pet_s - 2.0).abs() <= step, "{}", m.pet_s);
        assert_eq!(
            m.min_ttc_s,
            f64::INFINITY,
            "their occupancies never overlap"
        );
        assert!((m.time_to_clear_s - 3.5).abs() <= step);
        assert!(m.success && !m.collision);
    }

    #[test]
    fn overlapping_occupancy_gives_a_finite_ttc_and_far_apart_no_conflict() {
        // Both 30 m away at 10 m/s: they would meet in the zone 2.5 s from the start.
        let m = compute(&straight((30.0, 10.0), (30.0, 10.0), 3.0), 4.0, 5.0);
        assert!(m.min_ttc_s < 0.11, "{}", m.min_ttc_s);
        let first = compute(&straight((30.0, 10.0), (30.0, 10.0), 0.0), 4.0, 5.0);
        assert!((first.min_ttc_s - 2.5).abs() < 1e-9);
        // ΔTTC 10 s: never a conflict.
        let far = compute(&straight((30.0, 10.0), (130.0, 10.0), 8.0), 4.0, 5.0);
        assert_eq!(far.conflict_duration_s, 0.0);
    }

    #[test]
    fn jerk_collision_and_failure() {
        let mut s = straight((30.0, 5.0), (200.0, 5.0), 1.0);
        for (i, x) in s.iter_mut().enumerate() {
            x.ego_a = if i % 2 == 0 { 1.0 } else { -1.0 };
        }
        s[5].collided = true;
        let m = compute(&s, 4.0, 5.0);
        assert!((m.avg_abs_jerk_mps3 - 20.0).abs() < 1e-9);
        assert!(m.collision && !m.success);
        assert_eq!(m.time_to_clear_s, f64::INFINITY);
    }
}
