//! Latency report of the full core step: percentiles and maximum over many closed-loop steps
//! of dense traffic.
//!
//! `cargo run --release -p concord-bench --bin step_report -- [steps] [agents] [samples]
//! [MAP ROUTE]` (defaults 10 000, 16, 1024, the paper's intersection). With a map file and
//! the ego's route on it, it also reports how long loading the map took. Pin it to one core
//! with `taskset -c 1` for stable figures.

use std::path::Path;
use std::time::Instant;

use concord_bench::{core, core_on, Traffic};
use concord_core::DecisionSource;
use concord_map::Map;

fn main() {
    let all: Vec<String> = std::env::args().skip(1).collect();
    let count = |i: usize, default: usize| {
        all.get(i).map_or(default, |a| {
            a.parse().unwrap_or_else(|_| {
                panic!("arguments: steps agents samples [MAP ROUTE]; got {a:?}")
            })
        })
    };
    let steps = count(0, 10_000);
    let agents = count(1, 16);
    let samples = count(2, 1024);
    let (mut core, mut traffic) = match (all.get(3), all.get(4)) {
        (Some(path), Some(route)) => {
            let started = Instant::now();
            let (map, lane) =
                Map::load_route(Path::new(path), Some(route)).unwrap_or_else(|e| panic!("{e}"));
            let core = Box::new(core_on(map.morphology(), samples));
            println!(
                "map {path}: {} lanes, {} conflict points, loaded in {:.2} ms",
                map.ids().len(),
                core.morphology().conflicts().len(),
                started.elapsed().as_secs_f64() * 1e3
            );
            let lane = lane.expect("a route").first();
            let traffic = Traffic::on_map(&core, lane, agents);
            (core, traffic)
        }
        (None, None) => {
            let core = Box::new(core(samples));
            let traffic = Traffic::new(&core, agents);
            (core, traffic)
        }
        _ => panic!("a map needs the ego's route: MAP ROUTE"),
    };
    let mut micros = Vec::with_capacity(steps);
    let (mut replanned, mut minimum_risk) = (0, 0);
    for _ in 0..steps {
        let started = Instant::now();
        let decision = core
            .step(&traffic.scene, traffic.scene.time_s, None)
            .expect("valid scene");
        micros.push(started.elapsed().as_secs_f64() * 1e6);
        // A second planning run happens when the logit choice had no feasible candidate.
        replanned += usize::from(
            decision.source == DecisionSource::Logit
                && decision.maneuver != decision.logit_maneuver,
        );
        minimum_risk += usize::from(decision.source == DecisionSource::MinimumRisk);
        traffic.advance(&core, &decision, 0.05);
    }
    micros.sort_by(f64::total_cmp);
    let pct = |q: f64| micros[((micros.len() - 1) as f64 * q).round() as usize];
    println!(
        "{steps} steps, {agents} agents, {samples} samples: p50 {:.0} µs, p90 {:.0} µs, p99 {:.0} µs, p99.9 {:.0} µs, max {:.0} µs",
        pct(0.5),
        pct(0.9),
        pct(0.99),
        pct(0.999),
        micros[micros.len() - 1]
    );
    println!(
        "planned twice: {replanned} steps fell back to decelerate, {minimum_risk} to minimum risk"
    );
}
