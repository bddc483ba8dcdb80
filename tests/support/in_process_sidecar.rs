//! A sidecar in the test's own process, for the loopback tests: built from `cfg` with its
//! interaction log opened, and the receiver of everything it publishes.

use std::sync::atomic::AtomicU64;
use std::sync::{mpsc, Arc, Mutex};

use concord_sidecar::bus::Outbound;
use concord_sidecar::config::SidecarConfig;
use concord_sidecar::interaction_log::InteractionLog;
use concord_sidecar::ledger::Ledger;
use concord_sidecar::llm::LlmClient;
use concord_sidecar::service::Sidecar;

pub fn start(cfg: SidecarConfig) -> (Sidecar, mpsc::Receiver<Outbound>) {
    let client = LlmClient::new(&cfg.llm).unwrap();
    let log = InteractionLog::open(&cfg.log.path, cfg.log.max_bytes, cfg.log.keep).unwrap();
    let (out_tx, out_rx) = mpsc::channel();
    let sidecar = Sidecar::new(
        cfg,
        client,
        log,
        Ledger::in_memory(8),
        out_tx,
        Arc::new(Mutex::new(Default::default())),
        Arc::new(AtomicU64::new(0)),
    );
    (sidecar, out_rx)
}
