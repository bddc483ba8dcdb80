//! IPC overhead from scene to decision, without the core step and without waiting for the
//! loop's tick: publish a `SceneFrame`, receive it, decode it into the core's scene, encode a
//! decision into a `WireDecision`, publish it, and receive it — two iceoryx2 hops in one
//! process with the core process's conversions.

use concord_bench::{core, Traffic};
use concord_ipc::wire::{SceneFrame, WireDecision};
use concord_ipc::{clock, iox};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

fn scene_to_decision(c: &mut Criterion) {
    let config = iox::init(None).expect("iceoryx2 config");
    let node = iox::node("concord-bench-ipc", &config).expect("node");
    let prefix = format!("bench-{}/", std::process::id());
    let scene_pub =
        iox::publisher::<SceneFrame>(&node, &format!("{prefix}scene")).expect("publisher");
    let scene_sub =
        iox::subscriber::<SceneFrame>(&node, &format!("{prefix}scene"), 1).expect("subscriber");
    let decision_pub =
        iox::publisher::<WireDecision>(&node, &format!("{prefix}decision")).expect("publisher");
    let decision_sub = iox::subscriber::<WireDecision>(&node, &format!("{prefix}decision"), 1)
        .expect("subscriber");
    let mut core = Box::new(core(256));
    let traffic = Traffic::new(&core, 16);
    let decision = core.step(&traffic.scene, 0.0, None).expect("valid scene");
    let frame = SceneFrame::from_scene(1, clock::now_ns(), &traffic.scene);
    let mut sequence = 0;
    c.bench_function("ipc/scene_to_decision_two_hops_16_agents", |b| {
        b.iter(|| {
            sequence += 1;
            let mut next = frame;
            next.sequence = sequence;
            iox::send(&scene_pub, &next).expect("send");
            let (received, _) = iox::newest(&scene_sub).expect("receive");
            let scene = received.expect("a frame").to_scene().expect("valid codes");
            let wire = WireDecision::from_decision(
                &decision,
                sequence,
                scene.time_s as u64,
                clock::now_ns(),
                0,
            );
            iox::send(&decision_pub, &wire).expect("send");
            black_box(
                iox::newest(&decision_sub)
                    .expect("receive")
                    .0
                    .expect("a decision"),
            )
        })
    });
}

criterion_group!(benches, scene_to_decision);
criterion_main!(benches);
