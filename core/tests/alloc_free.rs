//! The step never allocates: 10 000 steps with 32 agents and 1024 samples, counted by a
//! global allocator that tallies allocations per thread.
mod common;

use common::*;
use concord_core::scene::{Vec2, MAX_AGENTS};
use concord_core::{Advice, AgentState, Maneuver, Params};

mod counting_allocator;

use counting_allocator::{allocations, Counting};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn ten_thousand_steps_with_32_agents_and_1024_samples_allocate_nothing() {
    let mut params = Params::default();
    params.trajectory.samples = 1024;
    let mut core = Box::new(paper_core(params));
    let mut scene = Box::new(paper_scene(0.0, 8.0, 8.0));
    // 31 more agents on every lane, spread along them.
    for i in 1..MAX_AGENTS {
        let lane = core.morphology().lane((i % 8) as u8);
        let (pos, tangent, _) = lane.to_cartesian(5.0 + 2.5 * i as f64, 0.0, 0);
        scene.push(AgentState::moving(
            i as u32 + 1,
            pos,
            tangent,
            3.0 + (i % 5) as f64,
        ));
    }
    assert_eq!(scene.n_agents, MAX_AGENTS);
    let dt = 0.05;
    let before = allocations();
    let mut decisions = 0u64;
    for k in 0..10_000u64 {
        let t = k as f64 * dt;
        scene.time_s = t;
        for a in scene.agents.iter_mut() {
            a.pos = a.pos.plus(a.vel.scale(dt));
            // Wrap agents back so the scene stays dense.
            if a.pos.norm() > 60.0 {
                a.pos = a.pos.scale(-0.6);
            }
        }
        scene.ego.pos = Vec2::new(40.0 - (k % 200) as f64 * 0.2, 5.0);
        let advice = Advice {
            request_id: k.max(1),
            maneuver: Maneuver::Decelerate,
            confidence: 0.9,
            published_at_s: t,
        };
        let d = core
            .step(&scene, t, (k % 3 == 0).then_some(&advice))
            .expect("valid scene");
        decisions += u64::from(d.trajectory.n > 0);
        if k % 100 == 0 {
            // The stale-scene fallback between frames.
            assert!(core.stale_fallback(t + 0.5).is_some());
        }
    }
    let after = allocations();
    assert_eq!(decisions, 10_000);
    assert_eq!(
        after - before,
        0,
        "the step allocated {} times",
        after - before
    );
}

#[test]
fn the_counter_sees_allocations() {
    let before = allocations();
    let v: Vec<u8> = Vec::with_capacity(16);
    assert!(allocations() > before);
    drop(v);
}
