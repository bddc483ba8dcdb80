//! Closed-loop smoke runs of the paper's left turn: the ego follows its own decisions.
mod common;

use common::*;
use concord_core::scene::Vec2;
use concord_core::{DecisionSource, Params};

/// Runs the left turn against a constant-speed HDV; returns (min distance, time the ego
/// reached the exit, count of minimum-risk decisions).
fn run(cav_speed: f64, hdv_speed: f64) -> (f64, Option<f64>, usize) {
    let mut core = paper_core(Params::default());
    let dt = 0.05;
    let mut scene = paper_scene(0.0, cav_speed, hdv_speed);
    let mut min_dist = f64::INFINITY;
    let mut fallbacks = 0;
    for k in 0..400 {
        let t = k as f64 * dt;
        scene.time_s = t;
        let d = core.step(&scene, t, None).expect("valid scene");
        if d.source == DecisionSource::MinimumRisk {
            fallbacks += 1;
        }
        // The ego executes the first `dt` of its trajectory.
        let now = d.trajectory.points[0];
        let next = d.trajectory.sample(dt).expect("a trajectory");
        let dir = Vec2::from_angle(next.heading);
        scene.ego.pos = Vec2::new(next.x, next.y);
        scene.ego.vel = dir.scale(next.speed);
        scene.ego.acc = dir.scale((next.speed - now.speed) / dt);
        scene.ego.heading = next.heading;
        let hdv = &mut scene.agents[0];
        hdv.pos = hdv.pos.plus(hdv.vel.scale(dt));
        min_dist = min_dist.min(scene.ego.pos.minus(scene.agents[0].pos).norm());
        if scene.ego.pos.y < -15.0 {
            return (min_dist, Some(t), fallbacks);
        }
    }
    (min_dist, None, fallbacks)
}

#[test]
fn left_turn_is_collision_free_and_completes_at_each_paper_speed() {
    for v in [6.0, 8.0, 10.0] {
        let (min_dist, done, fallbacks) = run(v, v);
        eprintln!(
            "v={v}: min distance {min_dist:.2} m, cleared at {done:?} s, {fallbacks} fallbacks"
        );
        assert!(
            min_dist > 3.0,
            "speed {v}: vehicles came within {min_dist:.2} m"
        );
        assert!(
            done.is_some(),
            "speed {v}: the ego never completed its turn"
        );
    }
}
