//! Criterion benches of the decision core: the full step over agents × samples, and the
//! trajectory stage alone (per candidate).

use concord_bench::{core, Traffic};
use concord_core::scene::{AgentState, Scene, Vec2};
use concord_core::{DecisionCore, Maneuver, Params};
use concord_map::{paper, BuiltIn};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::hint::black_box;

fn full_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("step");
    for samples in [256, 1024] {
        for agents in [8, 16, 32] {
            let mut core = Box::new(core(samples));
            let mut traffic = Traffic::new(&core, agents);
            let id = BenchmarkId::new(format!("{samples}_samples"), format!("{agents}_agents"));
            group.bench_function(id, |b| {
                b.iter(|| {
                    let d = core
                        .step(black_box(&traffic.scene), traffic.scene.time_s, None)
                        .expect("valid scene");
                    traffic.advance(&core, &d, 0.05);
                    black_box(d)
                })
            });
        }
    }
    group.finish();
}

/// The trajectory stage alone: 1024 candidates against 10 moving obstacles, 5 s at 0.1 s.
fn trajectory_stage(c: &mut Criterion) {
    let samples = 1024;
    let mut core = Box::new(core(samples));
    let ego = AgentState::moving(0, Vec2::new(30.0, 5.0), core::f64::consts::PI, 8.0);
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    // Ten obstacles: crossing, oncoming and turning traffic that the horizon reaches.
    let lanes = [1u8, 1, 1, 3, 3, 4, 4, 5, 5, 7];
    for (i, lane) in lanes.iter().enumerate() {
        let l = core.morphology().lane(*lane);
        let (pos, tangent, _) = l.to_cartesian(8.0 + 6.0 * i as f64, 0.0, 0);
        scene.push(AgentState::moving(
            i as u32 + 1,
            pos,
            tangent,
            4.0 + (i % 4) as f64,
        ));
    }
    core.step(&scene, 0.0, None).expect("valid scene");
    let profile = core.choice().profiles[core.last_decision().maneuver.index()];
    let params = *core.params();
    let mut planner = Box::new(*core.planner());
    let mut stats = Default::default();
    planner.sample(&profile, samples, 1, &params.trajectory);
    planner.run(samples, &params.trajectory, &mut stats);
    eprintln!("trajectory-stage workload: {stats:?}");
    let mut group = c.benchmark_group("trajectory");
    group.throughput(Throughput::Elements(samples as u64));
    group.bench_function("per_candidate_10_obstacles_5s_dt0.1", |b| {
        let mut cycle = 0;
        b.iter(|| {
            cycle += 1;
            planner.sample(&profile, samples, cycle, &params.trajectory);
            let mut stats = Default::default();
            black_box(planner.run(samples, &params.trajectory, &mut stats));
            black_box(stats)
        })
    });
    group.finish();
}

/// Like-for-like with the C++ Frenet planner of the performance notes: 1575 candidates, dt
/// 0.2 s, durations 2.0–4.8 s, ten stationary rectangular obstacles along a curved reference
/// path (the left-turn arc), alternating on both sides of the lane so that they clip the
/// candidates that swing wide; about a quarter of the candidates pass, as there. The 1575
/// candidates run as one batch of 1024 and one of 551.
fn like_for_like(c: &mut Criterion) {
    let mut params = Params::default();
    params.trajectory.samples = 1024;
    params.trajectory.dt_s = 0.2;
    params.trajectory.horizon_s = 4.8;
    params.trajectory.min_duration_s = 2.0;
    params.trajectory.max_duration_s = 4.8;
    params.trajectory.sigma_rel = 0.3;
    params.trajectory.sigma_lateral_m = 0.4;
    let morph = BuiltIn::PaperIntersection.morphology();
    let mut core = Box::new(DecisionCore::new(params, morph).expect("valid parameters"));
    let ego = AgentState::moving(0, Vec2::new(25.0, 5.0), core::f64::consts::PI, 5.0);
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    let lane = morph.lane(paper::CAV_LEFT);
    for i in 0..10 {
        let s = 30.0 + 4.0 * i as f64;
        let l = if i % 2 == 0 { 4.0 } else { -4.0 };
        let (pos, tangent, _) = lane.to_cartesian(s, l, 0);
        scene.push(AgentState::moving(i as u32 + 1, pos, tangent, 0.0));
    }
    core.step(&scene, 0.0, None).expect("valid scene");
    let profile = core.choice().profiles[Maneuver::KeepSpeed.index()];
    let mut planner = Box::new(*core.planner());
    let mut stats = Default::default();
    planner.sample(&profile, 1024, 1, &params.trajectory);
    planner.run(1024, &params.trajectory, &mut stats);
    eprintln!("like-for-like workload: {stats:?}");
    let mut group = c.benchmark_group("trajectory");
    group.throughput(Throughput::Elements(1575));
    group.bench_function("like_for_like_1575_candidates_10_boxes_curved_dt0.2", |b| {
        let mut cycle = 0;
        b.iter(|| {
            let mut stats = Default::default();
            for batch in [1024, 551] {
                cycle += 1;
                planner.sample(&profile, batch, cycle, &params.trajectory);
                black_box(planner.run(batch, &params.trajectory, &mut stats));
            }
            black_box(stats)
        })
    });
    group.finish();
}

criterion_group!(benches, full_step, trajectory_stage, like_for_like);
criterion_main!(benches);
