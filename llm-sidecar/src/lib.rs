//! `concord-sidecar`: the slow, fallible LLM side of Concord (paper §4.1, §4.3, §5). It answers
//! the core's advice requests with A_final and a confidence read from token log-probabilities
//! (eq. 16), parses intents from what the passenger and other road users say (eq. 8), and
//! writes the eHMI messages. The core only ever *considers* what it publishes.
//!
//! Threads: one owns the iceoryx2 ports ([`bus`]); a single-threaded tokio runtime runs the
//! three workers of [`service`] and the HTTP client ([`llm`]).

pub mod bus;
pub mod config;
pub mod ehmi;
pub mod interaction_log;
pub mod ledger;
pub mod llm;
pub mod prompt;
pub mod reply;
pub mod schema;
pub mod service;
pub mod slots;
pub mod untrusted;

use std::sync::atomic::AtomicU64;
use std::sync::{mpsc as std_mpsc, Arc, Mutex};
use std::time::Duration;

use iceoryx2::config::Config;
use tokio::sync::{mpsc, watch};

pub use config::SidecarConfig;
use service::Sidecar;

/// Checks that the server answers `GET /models`; the error says what to do.
pub async fn probe(client_cfg: &config::LlmConfig) -> Result<String, String> {
    let url = format!("{}/models", client_cfg.base_url.trim_end_matches('/'));
    let http = reqwest::Client::builder()
        .connect_timeout(Duration::from_secs_f64(client_cfg.connect_timeout_s))
        .timeout(Duration::from_secs(3))
        .build()
        .map_err(|e| e.to_string())?;
    let resp = http.get(&url).send().await.map_err(|e| e.to_string())?;
    let status = resp.status();
    let body: serde_json::Value = resp.json().await.map_err(|e| e.to_string())?;
    if !status.is_success() {
        return Err(format!("HTTP {status}"));
    }
    Ok(body["data"][0]["id"].as_str().unwrap_or("?").to_string())
}

/// Runs the sidecar until SIGINT or SIGTERM; prints its counters every `print_period_s` and on
/// exit.
pub fn run(cfg: SidecarConfig, iox_config: &Config) -> Result<(), String> {
    let client = llm::LlmClient::new(&cfg.llm)?;
    let log = interaction_log::InteractionLog::open(&cfg.log.path, cfg.log.max_bytes, cfg.log.keep)
        .map_err(|e| format!("interaction log {}: {e}", cfg.log.path.display()))?;
    let parties = cfg.intent.max_parties + 1;
    let ledger = match cfg.parsed_file() {
        None => ledger::Ledger::in_memory(parties),
        Some(path) => ledger::Ledger::open(&path, parties, concord_ipc::clock::now_ns())
            .unwrap_or_else(|e| {
                eprintln!(
                    "concord sidecar: WARNING: {e}; starting with an empty ledger of parsed \
                     messages (the last message may be parsed again)"
                );
                ledger::Ledger::empty_at(&path, parties)
            }),
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| format!("tokio runtime: {e}"))?;

    let (requests_tx, requests_rx) = watch::channel(None);
    let (decisions_tx, decisions_rx) = watch::channel(None);
    let (texts_tx, texts_rx) = mpsc::channel(64);
    let (out_tx, out_rx) = std_mpsc::channel();
    let (ready_tx, ready_rx) = std_mpsc::channel();
    let history = Arc::new(Mutex::new(Default::default()));
    let texts_dropped = Arc::new(AtomicU64::new(0));
    let inbound = bus::Inbound {
        requests: requests_tx,
        decisions: decisions_tx,
        texts: texts_tx,
        history: history.clone(),
        texts_dropped: texts_dropped.clone(),
    };
    let (done_tx, done_rx) = tokio::sync::oneshot::channel();
    let bus_config = iox_config.clone();
    let prefix = cfg.prefix.clone();
    let history_s = cfg.advice.raw_history_s;
    let bus = std::thread::Builder::new()
        .name("concord-sidecar-bus".into())
        .spawn(move || {
            let r = bus::run(&bus_config, &prefix, history_s, inbound, out_rx, ready_tx);
            let _ = done_tx.send(());
            r
        })
        .map_err(|e| format!("bus thread: {e}"))?;
    ready_rx
        .recv()
        .map_err(|_| "the bus thread ended before starting".to_string())??;

    let print_period = cfg.print_period_s;
    let sidecar = Sidecar::new(
        cfg.clone(),
        client,
        log,
        ledger,
        out_tx,
        history,
        texts_dropped,
    );
    runtime.block_on(async {
        match probe(&cfg.llm).await {
            Ok(model) => eprintln!(
                "concord sidecar: LLM server {} serves {model:?}; prompts: {}",
                cfg.llm.base_url,
                cfg.advice.prompt_format.name()
            ),
            Err(e) => eprintln!(
                "concord sidecar: WARNING: the LLM server at {} does not answer ({e}); every \
                 request fails and the core keeps its own decision until it does \
                 (start the local one with `deploy/llm/llm.sh start`)",
                cfg.llm.base_url
            ),
        }
        let printer = async {
            if print_period <= 0.0 {
                return std::future::pending().await;
            }
            let mut every = tokio::time::interval(Duration::from_secs_f64(print_period));
            every.tick().await;
            loop {
                every.tick().await;
                eprintln!("concord sidecar: {}", sidecar.render());
            }
        };
        tokio::select! {
            () = sidecar.advice_worker(requests_rx) => {}
            () = sidecar.text_worker(texts_rx) => {}
            () = sidecar.ehmi_worker(decisions_rx) => {}
            () = printer => {}
            _ = done_rx => {}
        }
    });
    eprintln!("concord sidecar: final: {}", sidecar.render());
    drop(sidecar);
    bus.join()
        .map_err(|_| "the bus thread panicked".to_string())?
        .map_err(|e| e.to_string())
}
