//! `concord monitor`: the core's counters and latency percentiles, the latest decision and the
//! latest eHMI text, read from another process.

use std::time::Duration;

use concord_core::{AdviceVerdict, DecisionSource, Maneuver};
use iceoryx2::config::Config;

use crate::clock::now_ns;
use crate::core_service::render_stats;
use crate::iox::{self, IpcError};
use crate::services;
use crate::wire::{CoreStats, EhmiMessage, WireDecision};

/// What the monitor saw last.
#[derive(Debug, Clone, Default)]
pub struct Snapshot {
    pub stats: Option<CoreStats>,
    pub decision: Option<WireDecision>,
    pub ehmi: Option<String>,
}

/// One line describing a decision: maneuver, source, advice verdict and corrected P_n.
pub fn describe(d: &WireDecision) -> String {
    let name = |m: u8| Maneuver::try_from(m).map(|m| m.name()).unwrap_or("?");
    let source = match DecisionSource::try_from(d.source) {
        Ok(DecisionSource::Logit) => "logit",
        Ok(DecisionSource::Advice) => "advice",
        Ok(DecisionSource::MinimumRisk) => "minimum_risk",
        Err(_) => "?",
    };
    let verdict = AdviceVerdict::try_from(d.advice)
        .map(|v| v.name())
        .unwrap_or("?");
    let p: Vec<String> = d.p_corrected.iter().map(|v| format!("{v:.2}")).collect();
    format!(
        "scene {} cycle {}: {} via {} (advice: {verdict}), P_n [{}], step {} µs",
        d.scene_sequence,
        d.cycle,
        name(d.maneuver),
        source,
        p.join(" "),
        d.compute_ns / 1000
    )
}

/// Prints a snapshot every `period` until SIGINT/SIGTERM or `duration_s`.
pub fn run(
    prefix: &str,
    period: Duration,
    duration_s: Option<f64>,
    iox_config: &Config,
) -> Result<Snapshot, IpcError> {
    let node = iox::node("concord-monitor", iox_config)?;
    let stats = iox::subscriber::<CoreStats>(&node, &services::name(prefix, services::STATS), 1)?;
    let decisions =
        iox::subscriber::<WireDecision>(&node, &services::name(prefix, services::DECISION), 1)?;
    let ehmi = iox::subscriber::<EhmiMessage>(&node, &services::name(prefix, services::EHMI), 1)?;
    let started = now_ns();
    let mut snap = Snapshot::default();
    while node.wait(period).is_ok() {
        if let (Some(s), _) = iox::newest(&stats)? {
            snap.stats = Some(s);
        }
        if let (Some(d), _) = iox::newest(&decisions)? {
            snap.decision = Some(d);
        }
        if let (Some(m), _) = iox::newest(&ehmi)? {
            snap.ehmi = m.text().map(str::to_owned);
        }
        match &snap.stats {
            Some(s) => {
                let mut line = String::new();
                render_stats(s, &mut line);
                println!("core: {line}");
            }
            None => println!(
                "core: no statistics yet on {}",
                services::name(prefix, services::STATS)
            ),
        }
        if let Some(d) = &snap.decision {
            println!("  last decision: {}", describe(d));
        }
        println!("  eHMI: {}", snap.ehmi.as_deref().unwrap_or("(none yet)"));
        if duration_s.is_some_and(|d| (now_ns() - started) as f64 * 1e-9 >= d) {
            break;
        }
    }
    Ok(snap)
}
