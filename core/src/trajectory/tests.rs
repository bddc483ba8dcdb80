//! Unit tests of the planner's private parts: boxes, frames, caps and sampling.

use super::{
    curved_reach, rectangles_overlap, roots_in, Footprint, FrenetState, Hit, LaneFrame, Occupancy,
    PassageMargin, Planner, Reject, MAX_BOXES, VCAP_BINS,
};
use crate::choice::Profile;
use crate::params::Params;
use crate::scene::{Lane, Turn, Vec2};

#[test]
fn sample_zero_is_the_nominal_itself_and_its_offset_is_held_only_below_the_threshold() {
    // eq. 23: sample 0 carries no noise, also for a yielding profile (whose odd samples
    // roll on at a random speed). Its offset is held at the start's only when an end is
    // below the low-speed threshold, not at it.
    let p = Params::default().trajectory;
    let mut planner = Planner {
        start: FrenetState {
            ds: 8.0,
            l: 0.3,
            ..FrenetState::default()
        },
        ..Planner::default()
    };
    let stop = Profile {
        accel: -2.0,
        target_speed: 0.0,
        duration: 4.0,
        stop_m: 16.0,
    };
    planner.sample(&stop, 8, 7, &p);
    assert_eq!((planner.end_t[0], planner.end_v[0]), (4.0, 0.0));
    assert_eq!(planner.end_l[0], 0.3, "stopping: the offset is held");
    assert!(planner.end_v[1] > 0.0, "an odd sample of a stop rolls on");
    // Rolling on at v_T, an odd sample covers the stop's distance d = v₀T/2 in
    // T' = 2d / (v₀ + v_T): between T/2 and T before its own perturbation.
    let short = Profile {
        duration: 3.0,
        ..stop
    };
    planner.sample(&short, 64, 7, &p);
    let spread = p.sigma_rel * p.sigma_clip;
    for k in (1..64).step_by(2) {
        let t = planner.end_t[k];
        assert!(
            t <= 3.0 * (1.0 + spread) + 1e-9 && t >= (1.5 * (1.0 - spread)).max(p.min_duration_s),
            "sample {k}: T {t}"
        );
    }
    let slow = Profile {
        accel: -1.0,
        target_speed: p.low_speed_mps,
        duration: 3.0,
        stop_m: f64::INFINITY,
    };
    planner.sample(&slow, 8, 7, &p);
    assert_eq!((planner.end_t[0], planner.end_v[0]), (3.0, p.low_speed_mps));
    assert_eq!(
        planner.end_l[0], 0.0,
        "at the threshold the offset is sampled (z = 0)"
    );
}

#[test]
fn a_box_beyond_the_last_slot_merges_into_the_one_it_grows_least() {
    // Every slot of a step filled with 2 × 2 m boxes 10 m apart along the lane; one more,
    // just past box 5's end, goes into box 5 (growth 1 m × 2 m), and every other box is
    // left as it was.
    let mut occ = Occupancy::default();
    for k in 0..MAX_BOXES {
        let s = 10.0 * k as f64;
        occ.add(0, s, s + 2.0, -1.0, 1.0, None);
    }
    occ.add(0, 52.5, 53.0, -1.0, 1.0, None);
    for (k, b) in occ.boxes(0).enumerate() {
        let s = 10.0 * k as f64;
        let end = if k == 5 { 53.0 } else { s + 2.0 };
        assert_eq!(b, (s, end, -1.0, 1.0), "box {k}");
    }
}

#[test]
fn a_curve_box_stays_within_the_egos_lateral_bound_where_it_cannot_reach_the_centre() {
    // The ego's centre stays within ±l_ego of its lane, so on a turn whose centre it
    // cannot reach no box needs to reach further out than that (or than the straight box
    // around the other car): radii 5–40 m, either side, cars across the lane.
    let (hl, hw, l_ego) = (2.4, 0.9, 3.0);
    for rho in [5.0, 10.0, 20.0, 40.0] {
        for side in [-1.0, 1.0] {
            for l in [-2.5, -1.0, 0.0, 1.0, 2.5] {
                let (tangential, radial) = (2.4, 0.9);
                let b = curved_reach(
                    (30.0, l),
                    (hl, hw),
                    tangential,
                    radial,
                    1.0 / rho,
                    side,
                    l_ego,
                );
                let Some([_, _, l_lo, l_hi]) = b else {
                    continue;
                };
                let straight = (l - hw - radial - 0.25, l + hw + radial + 0.25);
                let (lo, hi) = (straight.0.min(-l_ego - 0.25), straight.1.max(l_ego + 0.25));
                assert!(
                    l_lo >= lo - 1e-9 && l_hi <= hi + 1e-9,
                    "ρ {rho}, side {side}, l {l}: [{l_lo}, {l_hi}] beyond [{lo}, {hi}]"
                );
            }
        }
    }
}

#[test]
fn on_a_bend_the_ego_can_reach_the_centre_of_the_box_spans_both_diagonals() {
    // A 3 m radius turn, the ego allowed 3 m off its lane: it can reach the centre, so the
    // box is half the circle along and, across, at least the two rectangles'
    // half-diagonals on either side (the centre distance at which they can still touch).
    let (hl, hw, tangential, radial) = (2.4, 0.9, 2.5, 1.0);
    let [s_lo, s_hi, l_lo, l_hi] = curved_reach(
        (30.0, 0.5),
        (hl, hw),
        tangential,
        radial,
        1.0 / 3.0,
        1.0,
        3.0,
    )
    .expect("reachable");
    let touch = (hl * hl + hw * hw).sqrt() + (tangential * tangential + radial * radial).sqrt();
    assert!(
        l_lo <= 0.5 - touch && l_hi >= 0.5 + touch,
        "[{l_lo}, {l_hi}]"
    );
    let half_circle = core::f64::consts::PI * 3.0;
    assert!(s_lo <= 30.0 - half_circle && s_hi >= 30.0 + half_circle);
}

#[test]
fn the_same_footprint_added_again_leaves_its_box_exact() {
    // A car's 10 × 8 m box with its 4.8 × 2 m rectangle at (5, 0), then the same footprint
    // again: the ego 3.5 m to the side of the car is inside the box but clear of the
    // rectangle, so it still meets nothing (had the addition stripped the box of its
    // rectangle, all of the box would block), and the footprint is not stored twice.
    let mut occ = Occupancy::default();
    for (k, x) in occ.frame.x.iter_mut().enumerate() {
        *x = k as f64;
    }
    let car = Footprint {
        centre: Vec2::new(5.0, 0.0),
        cos: 1.0,
        sin: 0.0,
        grown: 0.0,
        exact: false,
    };
    occ.add(0, 0.0, 10.0, -4.0, 4.0, Some(car));
    assert_eq!(occ.hit(0, 5.0, 3.5), Hit::Free);
    assert_eq!(occ.hit(0, 5.0, 1.5), Hit::Contact);
    occ.add(0, 0.0, 10.0, -4.0, 4.0, Some(car));
    assert_eq!(occ.boxes(0).count(), 1);
    assert_eq!(occ.hit(0, 5.0, 0.5), Hit::Contact);
    assert_eq!(occ.hit(0, 5.0, 3.5), Hit::Free);
}

#[test]
fn each_curve_cap_holds_for_the_sharpest_vertex_of_its_bin() {
    // A straight run into a 5 m radius arc sampled every 0.1 m, finer than the caps'
    // 0.3 m bins: the bin where the arc begins is capped by the arc's first vertices, not
    // by the straight segment its start lies on.
    let p = Params::default().trajectory;
    let lane = Lane::builder(Vec2::new(-30.0, 0.0))
        .line_to(Vec2::new(0.0, 0.0))
        .arc(Vec2::new(0.0, 5.0), 1.0, 0.1)
        .line_to(Vec2::new(20.0, 30.0))
        .build(1.75, 0.0, Turn::Left)
        .expect("a lane");
    let mut planner = Planner::default();
    let (s0, reach) = (20.0, 81.0);
    planner.fill_vcap(&lane, s0, reach, &p);
    let bin = reach / VCAP_BINS as f64;
    let cap = |kappa: f64| {
        if kappa > p.max_curvature {
            0.0
        } else {
            libm::sqrt(p.max_lateral_accel_mps2 / kappa.max(1e-12)).min(p.max_speed_mps)
        }
    };
    let mut checked = 0;
    for k in 0..lane.segments() {
        let s = lane.s_at_vertex(k);
        if s <= s0 || s >= s0 + reach {
            continue;
        }
        let b = ((s - s0) / bin) as usize;
        assert!(
            planner.vcap[b] <= cap(lane.curvature_at(s, k)) + 1e-9,
            "vertex {k} at {s:.2} m: bin {b} capped at {}",
            planner.vcap[b]
        );
        checked += 1;
    }
    assert!(checked > 40, "{checked} vertices");
}

#[test]
fn each_curve_cap_is_that_of_the_segments_its_bin_touches_and_no_other() {
    // Integer-length segments (10 m straights, 3-4-5 diagonals) and 0.25 m bins: vertices
    // fall exactly on bin edges. A bin [lo, hi) is capped by every segment that reaches
    // into it (also one ending at lo), and not by the one starting at hi.
    let p = Params::default().trajectory;
    let mut b = Lane::builder(Vec2::new(0.0, 0.0));
    let mut at = Vec2::new(0.0, 0.0);
    for _ in 0..3 {
        for d in [(10.0, 0.0), (3.0, 4.0), (0.0, 5.0), (3.0, 4.0)] {
            at = Vec2::new(at.x + d.0, at.y + d.1);
            b = b.line_to(at);
        }
    }
    let lane = b.build(1.75, 0.0, Turn::Left).expect("a lane");
    let reach = 0.25 * VCAP_BINS as f64;
    assert!(lane.length() > reach + 1.0);
    let cap = |kappa: f64| {
        if kappa > p.max_curvature {
            0.0
        } else if kappa > 1e-9 {
            libm::sqrt(p.max_lateral_accel_mps2 / kappa).min(p.max_speed_mps)
        } else {
            p.max_speed_mps
        }
    };
    let mut planner = Planner::default();
    planner.fill_vcap(&lane, 0.0, reach, &p);
    let mut differ = 0;
    for bin in 0..VCAP_BINS {
        let (lo, hi) = (0.25 * bin as f64, 0.25 * (bin + 1) as f64);
        let kappa = (0..lane.segments())
            .filter(|&i| lane.s_at_vertex(i) < hi && lane.s_at_vertex(i + 1) >= lo)
            .map(|i| lane.curvature_at(lane.s_at_vertex(i), i))
            .fold(0.0, f64::max);
        assert_eq!(planner.vcap[bin], cap(kappa), "bin {bin}: [{lo}, {hi})");
        let next = (0..lane.segments()).find(|&i| lane.s_at_vertex(i) == hi);
        differ += usize::from(next.is_some_and(|i| lane.curvature_at(hi, i + 1) > kappa + 1e-9));
    }
    assert!(
        differ >= 3,
        "{differ} bins end where a sharper segment starts"
    );
}

#[test]
fn an_ego_above_the_top_speed_may_slow_gently_before_the_curve_caps_it() {
    // 22 m/s on a straight 120 m before a 10 m turn (capped at √(4 / 0.1) = 6.3 m/s),
    // above the top speed of 20 m/s: easing to 20 m/s over 4 s stays short of the turn
    // within the 5 s horizon, so no curve cap applies and the plan stands (the straight's
    // caps are the top speed, which the start may exceed).
    let p = Params::default().trajectory;
    let lane = Lane::builder(Vec2::new(0.0, 0.0))
        .line_to(Vec2::new(120.0, 0.0))
        .arc(Vec2::new(120.0, 10.0), core::f64::consts::FRAC_PI_2, 1.0)
        .line_to(Vec2::new(130.0, 40.0))
        .build(1.75, 0.0, Turn::Left)
        .expect("a lane");
    let mut planner = Planner {
        start: FrenetState {
            ds: 22.0,
            ..FrenetState::default()
        },
        steps: 50,
        dt: 0.1,
        ..Planner::default()
    };
    planner.fill_vcap(&lane, 0.0, 150.0, &p);
    assert!(planner.vcap_min < 7.0 && planner.vcap_from_s > 110.0);
    let eased = planner.evaluate(4.0, 20.0, 0.0, &p);
    assert!(eased.is_ok(), "{eased:?}");
}

#[test]
fn the_lane_frame_gives_the_lanes_own_pose_with_a_unit_heading() {
    // A 20 m radius quarter turn: the interpolated frame matches the lane's own Frenet
    // conversion within a bin's chord error, and its heading is a unit vector.
    let lane = Lane::builder(Vec2::new(-10.0, 0.0))
        .line_to(Vec2::new(0.0, 0.0))
        .arc(Vec2::new(0.0, 20.0), core::f64::consts::FRAC_PI_2, 1.0)
        .line_to(Vec2::new(20.0, 40.0))
        .build(1.75, 0.0, Turn::Left)
        .expect("a lane");
    let mut frame = LaneFrame::default();
    frame.fill(&lane, 5.0, 45.0);
    for i in 0..=80 {
        let s = 5.0 + 0.5 * i as f64;
        for l in [-2.0, 0.0, 1.5] {
            let (q, c, sn) = frame.pose(s, l);
            let (want, tangent, _) = lane.to_cartesian(s, l, 0);
            assert!((c * c + sn * sn - 1.0).abs() < 1e-9, "({s}, {l}): |h| ≠ 1");
            assert!(q.minus(want).norm() < 0.02, "({s}, {l}): {q:?} vs {want:?}");
            let turn = libm::atan2(sn, c) - tangent;
            assert!(
                libm::sin(turn).abs() < 0.01,
                "({s}, {l}): heading off by {turn}"
            );
        }
    }
}

#[test]
fn a_box_inside_another_is_absorbed_and_one_sticking_out_is_kept() {
    // A 10 × 4 m footprint box, then one with the same extent along the lane and 1 m
    // further to either side: not inside it, so it is kept and its own part is a contact;
    // one within it on every side is absorbed.
    for (l_lo, l_hi) in [(-1.0, 3.0), (-3.0, 1.0)] {
        let mut occ = Occupancy::default();
        occ.add(0, 0.0, 10.0, -2.0, 2.0, None);
        occ.add(0, 0.0, 10.0, l_lo, l_hi, None);
        assert_eq!(occ.boxes(0).count(), 2, "{l_lo}..{l_hi}");
        let outside_the_first = if l_hi > 2.0 { 2.5 } else { -2.5 };
        assert_eq!(occ.hit(0, 5.0, outside_the_first), Hit::Contact);
        occ.add(0, 1.0, 9.0, -1.0, 1.0, None);
        assert_eq!(occ.boxes(0).count(), 2, "{l_lo}..{l_hi}");
    }
}

#[test]
fn a_curve_box_holds_every_ego_centre_that_touches_the_other_and_little_more() {
    // A lane that is a circle of radius ρ about O, bending to `side`; the other's
    // rectangle (half extents `tangential`, `radial`) aligned with the lane at its foot
    // point (s, l), the ego at most half the circle away. Every ego centre within ±l_ego of the lane whose rectangle, aligned
    // with the lane, meets the other's lies in the box (sound), and the box reaches no
    // more than 2 m beyond the furthest of them on any side for radii of 10 m or more,
    // 12 m on sharper bends (tight: a looser box costs only narrow-phase tests, but it is
    // the broad phase of every step).
    let (hl, hw, l_ego) = (2.4, 0.9, 3.0);
    let pose = |rho: f64, side: f64, s: f64, l: f64| {
        let phi = side * s / rho;
        let r = rho - side * l;
        let heading = phi + side * core::f64::consts::FRAC_PI_2;
        (
            Vec2::new(r * phi.cos(), r * phi.sin()),
            (heading.cos(), heading.sin()),
        )
    };
    let mut worst: f64 = 0.0;
    for rho in [4.5, 6.0, 10.0, 20.0, 40.0] {
        for side in [-1.0, 1.0] {
            for l in [-2.5, -1.0, 0.0, 1.5, 3.0] {
                for (tangential, radial) in [(2.9, 1.4), (1.4, 2.9), (4.0, 3.0)] {
                    let s = 30.0;
                    let reach =
                        curved_reach((s, l), (hl, hw), tangential, radial, 1.0 / rho, side, l_ego);
                    let (oc, oh) = pose(rho, side, s, l);
                    let mut seen = [f64::INFINITY, -f64::INFINITY, f64::INFINITY, -f64::INFINITY];
                    for i in -400..=400 {
                        let se = s + 0.05 * i as f64;
                        // A turn is less than half a circle: no wrapping round.
                        if (se - s).abs() >= core::f64::consts::PI * rho {
                            continue;
                        }
                        for j in -30..=30 {
                            let le = 0.1 * j as f64;
                            let (ec, eh) = pose(rho, side, se, le);
                            if !rectangles_overlap(ec, eh, (hl, hw), oc, oh, (tangential, radial)) {
                                continue;
                            }

                            let [s_lo, s_hi, l_lo, l_hi] = reach.unwrap_or_else(|| {
                                panic!("ρ {rho}, side {side}, l {l}: ({se}, {le}) touches")
                            });
                            assert!(
                                se >= s_lo && se <= s_hi && le >= l_lo && le <= l_hi,
                                "ρ {rho}, side {side}, l {l}, {tangential}×{radial}: ({se}, {le}) touches, outside {reach:?}"
                            );
                            seen = [
                                seen[0].min(se),
                                seen[1].max(se),
                                seen[2].min(le),
                                seen[3].max(le),
                            ];
                        }
                    }
                    if let (Some(b), true) = (reach, seen[0].is_finite()) {
                        // Across, what lies beyond ±l_ego is not the ego's (the planner drops it).
                        let excess = [
                            seen[0] - b[0],
                            b[1] - seen[1],
                            seen[2] - b[2].max(-l_ego),
                            b[3].min(l_ego) - seen[3],
                        ];
                        for e in excess {
                            worst = worst.max(e);
                        }
                        assert!(
                            excess.iter().all(|&e| e <= if rho < 10.0 { 12.0 } else { 2.0 }),
                            "ρ {rho}, side {side}, l {l}, {tangential}×{radial}: box {b:?} against touching {seen:?}: {excess:?}"
                        );
                    }
                }
            }
        }
    }
    assert!(
        worst > 0.25 && worst < 12.0,
        "the box keeps its slack ({worst})"
    );
}

#[test]
fn roots_are_those_strictly_inside_the_interval_in_ascending_order() {
    // Linear (a = 0): t = −c/b, none when b = 0 or when the root is at an end; quadratic:
    // both roots ascending whatever the sign of a, a double root twice, none for a negative
    // discriminant; a coefficient below 1e-12 counts as zero.
    assert_eq!(roots_in(0.0, 2.0, -1.0, 1.0), ([0.5, 0.0], 1));
    assert_eq!(roots_in(0.0, 0.0, 5.0, 1.0).1, 0);
    assert_eq!(roots_in(0.0, 1e-13, -1e-13, 10.0).1, 0);
    assert_eq!(roots_in(0.0, 2.0, -1.0, 0.5).1, 0, "a root at T is outside");
    assert_eq!(roots_in(0.0, 2.0, 0.0, 1.0).1, 0, "a root at 0 is outside");
    assert_eq!(
        roots_in(0.0, 2.0, 1.0, 1.0).1,
        0,
        "a negative root is outside"
    );
    assert_eq!(roots_in(1.0, -3.0, 2.0, 3.0), ([1.0, 2.0], 2));
    assert_eq!(roots_in(-1.0, 3.0, -2.0, 3.0), ([1.0, 2.0], 2));
    assert_eq!(roots_in(1.0, -3.0, 2.0, 1.5), ([1.0, 0.0], 1));
    assert_eq!(roots_in(1.0, -3.0, 2.0, 2.0), ([1.0, 0.0], 1));
    assert_eq!(roots_in(2.0, -5.0, 2.0, 3.0), ([0.5, 2.0], 2));
    assert_eq!(roots_in(1.0, -2.0, 1.0, 3.0), ([1.0, 1.0], 2));
    assert_eq!(roots_in(1.0, 0.0, 1.0, 3.0).1, 0);
    assert_eq!(
        roots_in(1.0, 1.0, -2.0, 3.0),
        ([1.0, 0.0], 1),
        "−2 is outside"
    );
}

#[test]
fn a_curve_box_on_a_straight_a_double_bend_or_a_sharp_turn_is_its_documented_box() {
    // Straight (κ = 0): the Minkowski box of the two rectangles, 0.25 m slack. Bending both
    // ways (side 0), or so sharply that the ego's rectangle reaches within 0.5 m of the
    // turn's centre: half the circle along, both diagonals across. At exactly 0.5 m the turn
    // is not sharp. An other beyond the ego's lateral reach on the inside of a bend: no box.
    let (hl, hw, tangential, radial) = (2.4, 1.0, 2.9, 1.4);
    let (s, l) = (30.0, 0.5);
    assert_eq!(
        curved_reach((s, l), (hl, hw), tangential, radial, 0.0, 1.0, 2.5),
        Some([
            s - hl - tangential - 0.25,
            s + hl + tangential + 0.25,
            l - hw - radial - 0.25,
            l + hw + radial + 0.25,
        ])
    );
    let d = libm::sqrt(hl * hl + hw * hw) + libm::sqrt(tangential * tangential + radial * radial);
    let wide = |rho: f64| {
        Some([
            s - core::f64::consts::PI * rho,
            s + core::f64::consts::PI * rho,
            l - d - 0.25,
            l + d + 0.25,
        ])
    };
    assert_eq!(
        curved_reach((s, l), (hl, hw), tangential, radial, 0.05, 0.0, 2.5),
        wide(20.0)
    );
    assert_eq!(
        curved_reach((s, l), (hl, hw), tangential, radial, 0.25, 1.0, 2.6),
        wide(4.0)
    );
    assert_ne!(
        curved_reach((s, l), (hl, hw), tangential, radial, 0.25, 1.0, 2.5),
        wide(4.0)
    );
    for side in [-1.0, 1.0] {
        assert_eq!(
            curved_reach((s, 9.0 * side), (hl, hw), 1.4, 1.4, 0.05, side, 2.5),
            None,
            "side {side}"
        );
        assert!(curved_reach((s, 4.0 * side), (hl, hw), 1.4, 1.4, 0.05, side, 2.5).is_some());
    }
}

/// A box as (s_lo, s_hi, l_lo, l_hi), m.
type Box4 = (f64, f64, f64, f64);

#[test]
fn a_box_beyond_the_last_slot_merges_where_the_area_grows_least() {
    // Random boxes in every slot and one more: exactly one box changes, it becomes the union
    // of itself and the new box, and no other box's union would have grown less.
    let mut rng = <rand::rngs::SmallRng as rand::SeedableRng>::seed_from_u64(11);
    use rand::Rng;
    for _ in 0..200 {
        let mut occ = Occupancy::default();
        let draw = |rng: &mut rand::rngs::SmallRng| {
            let (s, l): (f64, f64) = (rng.random_range(0.0..100.0), rng.random_range(-5.0..5.0));
            let (ds, dl): (f64, f64) = (rng.random_range(0.5..8.0), rng.random_range(0.5..4.0));
            (s, s + ds, l, l + dl)
        };
        let mut before = [(0.0, 0.0, 0.0, 0.0); MAX_BOXES];
        for slot in before.iter_mut() {
            let b = draw(&mut rng);
            occ.add(0, b.0, b.1, b.2, b.3, None);
            *slot = b;
        }
        if occ.boxes(0).count() < MAX_BOXES {
            continue; // one fell inside another
        }
        let new = draw(&mut rng);
        occ.add(0, new.0, new.1, new.2, new.3, None);
        let union = |b: (f64, f64, f64, f64)| {
            (
                b.0.min(new.0),
                b.1.max(new.1),
                b.2.min(new.2),
                b.3.max(new.3),
            )
        };
        let area = |b: (f64, f64, f64, f64)| (b.1 - b.0) * (b.3 - b.2);
        let growth = |b| area(union(b)) - area(b);
        let least = before
            .iter()
            .map(|&b| growth(b))
            .fold(f64::INFINITY, f64::min);
        let differs = |(now, was): (&Box4, &Box4)| now != was;
        let now: [(f64, f64, f64, f64); MAX_BOXES] =
            core::array::from_fn(|k| occ.boxes(0).nth(k).expect("every slot"));
        if least == 0.0 {
            continue; // the new box lies inside one: dropped, nothing changes
        }
        assert_eq!(
            now.iter()
                .zip(before.iter())
                .filter(|&x| differs(x))
                .count(),
            1
        );
        let k = now
            .iter()
            .zip(before.iter())
            .position(differs)
            .expect("one changed");
        assert_eq!(occ.boxes(0).nth(k), Some(union(before[k])));
        assert!(
            growth(before[k]) <= least + 1e-9,
            "box {k} grew {}",
            growth(before[k])
        );
    }
}

#[test]
fn below_the_low_speed_only_sample_one_of_a_creep_stops_at_the_yield_point() {
    // At 1 m/s, under the 2 m/s threshold, a yielding creep towards a yield point 4 m ahead:
    // sample 1 stops there (v_T = 0, T = 2d / v₀ = 8 s, perturbed only shorter, clipped to
    // the longest duration); every other sample creeps on at its perturbed target speed.
    let p = Params::default().trajectory;
    let mut planner = Planner {
        start: FrenetState {
            ds: 1.0,
            ..FrenetState::default()
        },
        ..Planner::default()
    };
    let creep = Profile {
        accel: 0.5,
        target_speed: 1.5,
        duration: 3.0,
        stop_m: 4.0,
    };
    planner.sample(&creep, 16, 3, &p);
    assert_eq!(planner.end_v[1], 0.0);
    assert!(planner.end_t[1] <= p.max_duration_s);
    for k in (0..16).filter(|&k| k != 1) {
        assert!(planner.end_v[k] > 0.5, "sample {k}: {}", planner.end_v[k]);
    }
}

#[test]
fn rolling_samples_end_below_the_start_speed_and_take_the_time_their_mean_speed_needs() {
    // A yielding stop from 8 m/s over 6 s: odd samples reach the yield point at
    // v_T ∈ [0, v₀] and take T' = T·v₀ / (v₀ + v_T) before their ±45 % perturbation.
    let p = Params::default().trajectory;
    let mut planner = Planner {
        start: FrenetState {
            ds: 8.0,
            ..FrenetState::default()
        },
        ..Planner::default()
    };
    let stop = Profile {
        accel: -1.33,
        target_speed: 0.0,
        duration: 6.0,
        stop_m: 24.0,
    };
    planner.sample(&stop, 64, 5, &p);
    let spread = p.sigma_rel * p.sigma_clip;
    for k in (1..64).step_by(2) {
        let (t, v) = (planner.end_t[k], planner.end_v[k]);
        assert!((0.0..=8.0).contains(&v), "sample {k}: v_T {v}");
        let ratio = t / (6.0 * 8.0 / (8.0 + v));
        assert!(ratio >= 1.0 - spread - 1e-9, "sample {k}: T {t}, v_T {v}");
        assert!(
            t == p.max_duration_s || ratio <= 1.0 + spread + 1e-9,
            "sample {k}: T {t}, v_T {v}"
        );
    }
}

#[test]
fn slowing_from_a_braking_start_is_no_longer_than_its_speed_stays_monotone() {
    // Braking at 2 m/s² from 8 m/s towards 6 m/s over 5 s: a quartic's speed stays between
    // its ends only for T ≤ 3 (v₀ − v_T) / |a₀| (≈ 3 s here), so each sample slowing down is cut
    // there (but not below the shortest duration), and otherwise keeps its perturbed duration.
    let p = Params::default().trajectory;
    let mut planner = Planner {
        start: FrenetState {
            ds: 8.0,
            dds: -2.0,
            ..FrenetState::default()
        },
        ..Planner::default()
    };
    let slow = Profile {
        accel: -0.4,
        target_speed: 6.0,
        duration: 5.0,
        stop_m: f64::INFINITY,
    };
    planner.sample(&slow, 64, 9, &p);
    let spread = p.sigma_rel * p.sigma_clip;
    let mut cut = 0;
    for k in 0..64 {
        let (t, v) = (planner.end_t[k], planner.end_v[k]);
        if v >= 8.0 {
            continue;
        }
        let monotone = (3.0 * (8.0 - v) / 2.0).max(p.min_duration_s);
        assert!(t <= monotone + 1e-9, "sample {k}: T {t}, v_T {v}");
        assert!(
            t >= monotone.min(5.0 * (1.0 - spread)) - 1e-9,
            "sample {k}: T {t}, v_T {v}"
        );
        cut += usize::from(t == monotone);
    }
    assert!(cut > 10, "{cut} samples cut");
}

/// A planner on an empty road (no occupancy, no curve caps) from `start`, 50 steps of 0.1 s,
/// keeping one post-encroachment margin: out of [s₀, s₁] m during [t₀, t₁] s.
fn keeping(start: FrenetState, s: [f64; 2], t: [f64; 2]) -> Planner {
    let mut planner = Planner {
        start,
        steps: 50,
        dt: 0.1,
        vcap_min: f64::INFINITY,
        ..Planner::default()
    };
    planner.margins[0] = PassageMargin { s, t };
    planner.n_margins = 1;
    planner
}

/// When the candidate of `planner` to (`t_end`, `v_end`) first reaches `x` m, interpolated
/// linearly between the 0.1 s steps (past `t_end` at `v_end`), s.
fn reaches(planner: &Planner, t_end: f64, v_end: f64, x: f64) -> f64 {
    let p = Params::default().trajectory;
    let (q, _) = planner.polynomials(t_end, v_end, 0.0, &p);
    let (mut t0, mut s0) = (0.0, planner.start.s);
    for k in 1..=50 {
        let t = 0.1 * k as f64;
        let s = if t <= t_end {
            q.pos(t)
        } else {
            q.pos(t_end) + v_end * (t - t_end)
        };
        if s >= x {
            return t0 + (x - s0) / (s - s0) * (t - t0);
        }
        (t0, s0) = (t, s);
    }
    f64::INFINITY
}

#[test]
fn a_margin_refuses_exactly_the_candidates_in_the_passage_while_it_holds() {
    // Cruising at 8 m/s from s = 0, the ego is in the passage [20.4, 30.4] m from 2.55 s to
    // 3.8 s (between steps: interpolated). A margin holding until just before it enters, or
    // from just after it has left, lets it pass; one overlapping its stay by 0.01 s refuses
    // it, at the moment the two overlap first. Slowing from 10 to 4 m/s, the same holds at
    // the moments its own polynomial reaches the passage's ends.
    let p = Params::default().trajectory;
    let cruise = FrenetState {
        ds: 8.0,
        ..FrenetState::default()
    };
    let s = [20.4, 30.4];
    let verdict = |start: FrenetState, t: [f64; 2], t_end: f64, v_end: f64| {
        keeping(start, s, t).evaluate(t_end, v_end, 0.0, &p).err()
    };
    assert_eq!(verdict(cruise, [0.0, 2.54], 3.0, 8.0), None);
    assert_eq!(verdict(cruise, [3.81, 9.0], 3.0, 8.0), None);
    let Some(Reject::Collision(t)) = verdict(cruise, [0.0, 2.56], 3.0, 8.0) else {
        panic!("entering inside the margin");
    };
    assert!((t - 2.55).abs() < 1e-9, "{t}");
    let Some(Reject::Collision(t)) = verdict(cruise, [3.79, 9.0], 3.0, 8.0) else {
        panic!("leaving inside the margin");
    };
    assert!((t - 3.79).abs() < 1e-9, "{t}");
    let slowing = FrenetState {
        ds: 10.0,
        dds: -1.0,
        ..FrenetState::default()
    };
    let probe = keeping(slowing, s, [0.0, 0.0]);
    let (enter, leave) = (
        reaches(&probe, 4.0, 4.0, s[0]),
        reaches(&probe, 4.0, 4.0, s[1]),
    );
    assert!(
        enter > 1.0 && leave < 5.0 && enter < leave,
        "{enter}, {leave}"
    );
    assert_eq!(verdict(slowing, [0.0, enter - 0.01], 4.0, 4.0), None);
    assert_eq!(verdict(slowing, [leave + 0.01, 9.0], 4.0, 4.0), None);
    let Some(Reject::Collision(t)) = verdict(slowing, [0.0, enter + 0.01], 4.0, 4.0) else {
        panic!("slowing, entering inside the margin");
    };
    assert!((t - enter).abs() < 1e-9, "{t} vs {enter}");
    assert!(matches!(
        verdict(slowing, [leave - 0.01, 9.0], 4.0, 4.0),
        Some(Reject::Collision(_))
    ));
    // Speeding up from 4 to 12 m/s: the moment it leaves stays the one interpolated on the
    // step it crosses the passage's end.
    let speeding = FrenetState {
        ds: 4.0,
        ..FrenetState::default()
    };
    let probe = keeping(speeding, s, [0.0, 0.0]);
    let leave = reaches(&probe, 4.0, 12.0, s[1]);
    assert!(leave < 4.5, "{leave}");
    assert_eq!(verdict(speeding, [leave + 0.01, 9.0], 4.0, 12.0), None);
    // Starting inside the passage, the ego is in it from now; past it, or stopping short of
    // it, it keeps any margin.
    let past = FrenetState { s: 35.0, ..cruise };
    assert_eq!(
        verdict(past, [0.0, 9.0], 3.0, 8.0),
        None,
        "past the passage"
    );
    let inside = FrenetState { s: 25.0, ..cruise };
    let Some(Reject::Collision(t)) = verdict(inside, [0.2, 9.0], 3.0, 8.0) else {
        panic!("inside the passage from the start");
    };
    assert!((t - 0.2).abs() < 1e-9, "{t}");
    let short = FrenetState {
        s: 5.0,
        ds: 4.0,
        ..FrenetState::default()
    };
    assert_eq!(verdict(short, [0.0, 9.0], 3.0, 0.0), None, "stops short");
}

#[test]
fn a_held_offset_ignores_the_lateral_start_motion_only_at_low_speed_with_no_offset_change() {
    // At 1 m/s (under 2 m/s), holding the start's 0.3 m offset: the lateral polynomial is
    // the constant 0.3 (a time-based lateral motion would need unbounded curvature), also
    // with a lateral speed and acceleration at the start; so it is when only the end is
    // slow. Both fast, or a new offset: the quintic of eq. 21–22 from the start's state.
    let p = Params::default().trajectory;
    let planner = |ds: f64| Planner {
        start: FrenetState {
            ds,
            l: 0.3,
            dl: 0.2,
            ddl: 0.1,
            ..FrenetState::default()
        },
        ..Planner::default()
    };
    let held = [0.3, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(planner(1.0).polynomials(3.0, 3.0, 0.3, &p).1.c, held);
    assert_eq!(planner(3.0).polynomials(3.0, 1.0, 0.3, &p).1.c, held);
    for (ds, v_end, l_end) in [(3.0, 3.0, 0.3), (1.0, 1.0, 0.5)] {
        let l = planner(ds).polynomials(3.0, v_end, l_end, &p).1;
        assert_eq!(
            (l.c[0], l.c[1], l.c[2]),
            (0.3, 0.2, 0.05),
            "{ds}, {v_end}, {l_end}"
        );
        assert!((l.pos(3.0) - l_end).abs() < 1e-9);
    }
}

#[test]
fn a_lateral_path_beyond_its_bound_is_refused_between_the_ends() {
    // Drifting out at 1 m/s from 0.9 m, with lateral acceleration, towards the 1 m offset
    // over 6 s: the quintic overshoots to about 2 m mid-way, beyond the bound (the largest
    // offset plus the overshoot of the quickest correction), though both ends are within it.
    let p = Params::default().trajectory;
    let planner = Planner {
        start: FrenetState {
            ds: 5.0,
            l: 0.9,
            dl: 1.0,
            ddl: 0.1,
            ..FrenetState::default()
        },
        steps: 50,
        dt: 0.1,
        vcap_min: f64::INFINITY,
        ..Planner::default()
    };
    let (_, l) = planner.polynomials(6.0, 5.0, 1.0, &p);
    let bound = planner.lateral_bound(&p);
    // 0.9 m plus 16/81 · u · T for u = 1 m/s and the quickest correction T = 6√(u/J), 1e-6 m
    // tolerance.
    let quickest = 6.0 * libm::sqrt(1.0 / p.max_jerk_mps3);
    assert!(quickest > p.min_duration_s);
    let want = (0.9 + 16.0 / 81.0 * quickest).max(p.max_lateral_offset_m) + 1e-6;
    assert!((bound - want).abs() < 1e-12, "{bound} vs {want}");
    assert!(l.c.iter().all(|c| *c != 0.0), "{:?}", l.c);
    assert!((0..=50).any(|k| l.pos(0.1 * k as f64) > bound), "{bound}");
    assert_eq!(
        planner.evaluate(6.0, 5.0, 1.0, &p).err(),
        Some(Reject::Limits)
    );
}

#[test]
fn a_yielding_candidate_short_of_the_check_time_is_judged_at_its_end_speed() {
    // Easing from 8 to 7 m/s over 1 s, then rolling on at 7 m/s: at the yield check time it
    // is at s(1) + 7 (t_check − 1) m and stops within 7² / (2 · b / 1.5) m more. It commits
    // when that is past the yield point, however little (1e-6 m tolerance), and not when it
    // is short of it. (Checked at 2 s here.)
    let mut p = Params::default().trajectory;
    p.yield_check_s = 2.0;
    let start = FrenetState {
        ds: 8.0,
        ..FrenetState::default()
    };
    let q = super::Quartic::fit(0.0, 8.0, 0.0, 7.0, 0.0, 1.0);
    let t_check = p.yield_check_s.min(5.0);
    assert!(t_check > 1.0);
    let stops_at = q.pos(1.0) + 7.0 * (t_check - 1.0) + 49.0 / (2.0 * p.max_brake_mps2 / 1.5);
    let planner = |yield_distance: f64| Planner {
        start,
        steps: 50,
        dt: 0.1,
        vcap_min: f64::INFINITY,
        yielding: true,
        yield_distance,
        clear_distance: 100.0,
        ..Planner::default()
    };
    assert!(planner(stops_at + 0.01).evaluate(1.0, 7.0, 0.0, &p).is_ok());
    assert_eq!(
        planner(stops_at - 0.01).evaluate(1.0, 7.0, 0.0, &p).err(),
        Some(Reject::Commits)
    );
}

#[test]
fn a_stop_longer_than_the_horizon_still_counts_as_standing_where_it_ends() {
    // A 6 s stop from 6 m/s, longer than the 5 s horizon, still rolls at its end; it ends
    // standing about 18 m on, inside the zone [10, 25] m: refused. Ending short of the zone,
    // it is not.
    let p = Params::default().trajectory;
    let mut planner = Planner {
        start: FrenetState {
            ds: 6.0,
            ..FrenetState::default()
        },
        steps: 50,
        dt: 0.1,
        vcap_min: f64::INFINITY,
        ..Planner::default()
    };
    let (q, _) = planner.polynomials(6.0, 0.0, 0.0, &p);
    assert!(q.vel(5.0) > 0.3 && (10.0..25.0).contains(&q.pos(6.0)));
    planner.keep_zones([[10.0, 25.0]].into_iter());
    assert_eq!(
        planner.evaluate(6.0, 0.0, 0.0, &p).err(),
        Some(Reject::StandsInZone)
    );
    planner.keep_zones([[20.0, 25.0]].into_iter());
    assert!(planner.evaluate(6.0, 0.0, 0.0, &p).is_ok());
}

#[test]
fn a_candidates_score_is_table_2s_sum_with_the_lateral_term_and_a_capped_time_to_goal() {
    // S_k = c_e·T_n/T_ref + c_s·(∫|s⃛| + ∫|l⃛|)/J_max + c_l·|l_T|/l_max, the jerk integrals
    // being the total variations of the accelerations (summed here over a fine grid), T_n
    // the interpolated time to the goal, and, for a goal beyond the horizon, the horizon
    // plus the rest at the final speed (at least 0.5 m/s), at most 10·T_ref.
    let mut p = Params::default().trajectory;
    p.max_lateral_offset_m = 2.0;
    let variation = |f: &dyn Fn(f64) -> f64, t_end: f64| {
        (0..10_000)
            .map(|i| {
                let (a, b) = (t_end * i as f64 / 1e4, t_end * (i + 1) as f64 / 1e4);
                (f(b) - f(a)).abs()
            })
            .sum::<f64>()
    };
    let planner = |ds: f64, goal_distance: f64| Planner {
        start: FrenetState {
            ds,
            ..FrenetState::default()
        },
        steps: 50,
        dt: 0.1,
        vcap_min: f64::INFINITY,
        goal_distance,
        ..Planner::default()
    };
    // Cruising at 8 m/s to 0.5 m off the lane over 3 s: the goal 20 m ahead at 2.5 s.
    let cruise = planner(8.0, 20.0);
    let c = cruise.evaluate(3.0, 8.0, 0.5, &p).expect("feasible");
    let jerk = variation(&|t| c.l.acc(t), 3.0);
    let want = p.c_efficiency * 2.5 / p.t_ref_s
        + p.c_smoothness * jerk / p.j_max_norm
        + p.c_lateral * 0.5 / p.max_lateral_offset_m;
    assert!((c.score - want).abs() < 1e-6, "{} vs {want}", c.score);
    // Stopping from 4 m/s over 3 s with the goal 1000 m away: T_n is capped.
    let stop = planner(4.0, 1000.0);
    let c = stop.evaluate(3.0, 0.0, 0.0, &p).expect("feasible");
    let jerk = variation(&|t| c.s.acc(t), 3.0);
    let want = p.c_efficiency * 10.0 + p.c_smoothness * jerk / p.j_max_norm;
    assert!((c.score - want).abs() < 1e-6, "{} vs {want}", c.score);
}

#[test]
fn each_longitudinal_limit_holds_at_its_value_and_refuses_past_it_at_the_extremum() {
    // Table 2's limits on the quartic (eq. 17): extremes of jerk at the ends, of acceleration
    // at the ends and the vertex, of speed at the ends and the roots of the acceleration;
    // a start already beyond the braking limit may keep braking as hard; each limit has a
    // 1e-6 tolerance. The jerk integral is the total variation of the acceleration.
    let p = Params::default().trajectory;
    let limits = |ds: f64, dds: f64, t_end: f64, v_end: f64| {
        let planner = Planner {
            start: FrenetState {
                ds,
                dds,
                ..FrenetState::default()
            },
            ..Planner::default()
        };
        let (q, l) = planner.polynomials(t_end, v_end, 0.0, &p);
        (planner.check_limits(&q, &l, t_end, &p), q)
    };
    // Braking at 10 m/s² (beyond the 5 m/s² limit) eased to 0 over 1 s: jerk exactly 10.
    assert!(limits(10.0, -10.0, 1.0, 5.0).0.is_ok());
    // A 6 m/s² braking start eased out linearly (6 m/s³) is within its own braking.
    assert!(limits(10.0, -6.0, 1.0, 7.0).0.is_ok());
    // Stopping from 10 m/s over 2.5 s peaks at 1.5 · 4 = 6 m/s² (jerk 9.6): too hard.
    assert_eq!(limits(10.0, 0.0, 2.5, 0.0).0.err(), Some(Reject::Limits));
    assert!(limits(10.0, 0.0, 3.5, 0.0).0.is_ok());
    // Speeding up by 10 m/s over 2.5 s peaks at 6 m/s² too.
    assert!(p.max_accel_mps2 < 6.0);
    assert_eq!(limits(5.0, 0.0, 2.5, 15.0).0.err(), Some(Reject::Limits));
    // From a 4 m/s² braking start at 2 m/s, a 3 s stop undershoots below zero mid-way;
    // from 2 m/s² at 19.5 m/s, holding 19.5 over 4 s overshoots the 20 m/s top speed.
    let (verdict, q) = limits(2.0, -4.0, 3.0, 0.0);
    assert!((0..30).any(|k| q.vel(0.1 * k as f64) < -1e-3));
    assert_eq!(verdict.err(), Some(Reject::Limits));
    let (verdict, q) = limits(19.5, 2.0, 4.0, 19.5);
    assert!((0..40).any(|k| q.vel(0.1 * k as f64) > 20.0 + 1e-3));
    assert_eq!(verdict.err(), Some(Reject::Limits));
    // The jerk integral and the peak speed of a gentle speed-up from an accelerating start,
    // whose acceleration peaks inside: against a fine grid.
    let (verdict, q) = limits(8.0, 1.0, 4.0, 12.0);
    let (jerk_s, jerk_l, v_peak) = verdict.expect("within the limits");
    let tv: f64 = (0..10_000)
        .map(|i| (q.acc(4.0 * (i + 1) as f64 / 1e4) - q.acc(4.0 * i as f64 / 1e4)).abs())
        .sum();
    let peak = (0..=10_000)
        .map(|i| q.vel(4.0 * i as f64 / 1e4))
        .fold(0.0, f64::max);
    let a_peak = (0..=10_000)
        .map(|i| q.acc(4.0 * i as f64 / 1e4))
        .fold(0.0, f64::max);
    assert!(
        a_peak > 1.0 + 1e-3,
        "the acceleration peaks inside: {a_peak}"
    );
    assert!((jerk_s - tv).abs() < 1e-6, "{jerk_s} vs {tv}");
    assert!(
        (v_peak - peak).abs() < 1e-6 && jerk_l == 0.0,
        "{v_peak} vs {peak}"
    );
}
