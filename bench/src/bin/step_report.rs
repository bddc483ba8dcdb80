//! Latency report of the full core step: percentiles and maximum over many closed-loop steps
//! of dense traffic.
//!
//! `cargo run --release -p concord-bench --bin step_report -- [steps] [agents] [samples]`
//! (defaults 10 000, 16, 1024). Pin it to one core with `taskset -c 1` for stable figures.

use std::time::Instant;

use concord_bench::{core, Traffic};
use concord_core::DecisionSource;

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| {
            a.parse()
                .unwrap_or_else(|_| panic!("arguments are counts: steps agents samples; got {a:?}"))
        })
        .collect();
    let steps = args.first().copied().unwrap_or(10_000);
    let agents = args.get(1).copied().unwrap_or(16);
    let samples = args.get(2).copied().unwrap_or(1024);
    let mut core = Box::new(core(samples));
    let mut traffic = Traffic::new(&core, agents);
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
