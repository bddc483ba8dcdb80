//! The experiments that need an LLM server (any OpenAI-compatible one):
//!
//! * [`LlmAdvisor`], Concord's advisor in closed loop (`concord experiment paper --llm URL`):
//!   every request is the one `concord run` would issue, rendered and sent as the sidecar does
//!   (OPM prompt, schema, confidence from log-probabilities); its answer becomes the advice
//!   the core weighs, now (simulated time waits) or after the call's measured latency.
//! * `concord experiment prompts`: OPM vs Raw vs Simple (paper §6.1.3, Fig. 5).
//!
//! Labelled scenes are [`crate::learn::labelled_scenes`]' left turns (the oracle's label). Each
//! scene becomes the advice request the core would issue, rendered in the three formats with
//! the sidecar's own prompts (asking for up to 3 reasoning steps) and sent once per format;
//! accuracy is the share of answers equal to the label, latency is the whole call, reasoning
//! steps are the answer's `steps` count.

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use concord_ipc::wire::{AdviceRequest, SceneFrame};
use concord_sidecar::config::{AdviceConfig, LlmConfig, PromptFormat, SidecarConfig};
use concord_sidecar::llm::LlmClient;
use concord_sidecar::schema::AdviceAnswer;
use concord_sim::controllers::AdviceSource;
use concord_sim::world::World;

/// Concord's LLM advisor in the simulation; also the client of the prompt comparison.
pub struct LlmAdvisor {
    pub client: LlmClient,
    pub rt: tokio::runtime::Runtime,
    /// The sidecar's defaults, `llm.fine_tuned` set when the server has an adapter loaded.
    pub cfg: SidecarConfig,
    /// The model the server reports.
    pub model: String,
}

/// Whether the llama.cpp server at `url` (ending in `/v1`) has a LoRA adapter loaded.
async fn has_adapter(url: &str) -> bool {
    let root = url.trim_end_matches('/').trim_end_matches("/v1");
    let Ok(r) = reqwest::get(format!("{root}/lora-adapters")).await else {
        return false;
    };
    let v: serde_json::Value = r.json().await.unwrap_or_default();
    v.as_array().is_some_and(|a| !a.is_empty())
}

impl LlmAdvisor {
    /// An advisor on the server at `url`; fails when it does not answer. A server with a LoRA
    /// adapter loaded (the shipped advisor) is asked with the prompts it was trained on.
    pub fn new(url: &str) -> Result<Self, String> {
        let mut cfg = SidecarConfig::default();
        let llm = LlmConfig {
            base_url: url.to_string(),
            request_timeout_s: 60.0,
            ..cfg.llm.clone()
        };
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| e.to_string())?;
        let model = rt.block_on(concord_sidecar::probe(&llm)).map_err(|e| {
            format!(
                "no LLM server answers at {url} ({e}); start one with `deploy/llm/llm.sh start`"
            )
        })?;
        cfg.llm.fine_tuned = rt.block_on(has_adapter(url));
        // The shipped advisor is asked in its deployed form, the answer begun for it; any
        // other server answers under the schema alone.
        cfg.advice.prefill_answer = cfg.llm.fine_tuned;
        Ok(LlmAdvisor {
            client: LlmClient::new(&llm)?,
            rt,
            cfg,
            model,
        })
    }
}

impl LlmAdvisor {
    /// Asks for advice on `request` (with `history` for the Raw format) as the sidecar does:
    /// the answer with its prompt tokens, and the call's latency, s (also when it failed).
    fn ask(
        &self,
        format: PromptFormat,
        steps: usize,
        max_tokens: u32,
        request: &AdviceRequest,
        history: &[SceneFrame],
    ) -> (Result<(AdviceAnswer, u32), String>, f64) {
        let messages = concord_sidecar::prompt::advice_messages(
            format,
            steps,
            self.cfg.advice.max_objects,
            request,
            history,
            &concord_sidecar::prompt::Stated::default(),
            self.cfg.intent.weak_below,
            self.cfg.llm.fine_tuned,
        );
        let advice = AdviceConfig {
            reasoning_steps: steps,
            max_tokens,
            ..self.cfg.advice.clone()
        };
        let body = self.client.advice_body(&messages, &advice);
        let started = Instant::now();
        let reply = self
            .rt
            .block_on(self.client.call(&body, started + Duration::from_secs(60)));
        let latency = started.elapsed().as_secs_f64();
        let answer = reply.map_err(|e| e.to_string()).and_then(|r| {
            AdviceAnswer::decode(&r.answer)
                .map(|a| (a, r.answer.usage.prompt_tokens))
                .map_err(|e| e.to_string())
        });
        (answer, latency)
    }
}

impl AdviceSource for LlmAdvisor {
    fn advise(
        &mut self,
        core: &concord_core::DecisionCore,
        decision: &concord_core::Decision,
        w: &World,
    ) -> Option<(concord_core::Maneuver, f64, f64)> {
        let request = AdviceRequest::from_core(
            decision.request_id,
            decision.cycle,
            0,
            u64::MAX,
            decision,
            core,
            w.ego.lane,
        );
        let advice = &self.cfg.advice;
        let (answer, latency) = self.ask(
            PromptFormat::Opm,
            advice.reasoning_steps,
            advice.max_tokens,
            &request,
            &[],
        );
        let (answer, _) = answer.ok()?;
        let confidence = answer
            .confidence
            .unwrap_or(self.cfg.llm.confidence_without_logprobs);
        Some((answer.maneuver, confidence, latency))
    }
}

/// Reasoning steps asked for.
const STEPS: usize = 3;

/// Runs the comparison against `url` and writes `prompts.csv` under `out`.
pub fn run(url: &str, n: usize, seed: u64, out: &Path) -> Result<(), String> {
    let advisor = LlmAdvisor::new(url)?;
    let model = &advisor.model;
    let set = crate::learn::labelled_scenes(
        n,
        n.div_ceil(2),
        seed,
        &[concord_sim::world::ScenarioKind::LeftTurn],
        "labelled scenes",
    )?;
    let mut labels = [0usize; 5];
    for s in &set {
        labels[s.label as usize] += 1;
    }
    eprintln!(
        "concord experiment prompts: {n} labelled scenes (labels: {}), model {model:?} at {url}",
        concord_core::Maneuver::ALL
            .iter()
            .map(|m| format!("{} {}", m.name(), labels[*m as usize]))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut csv = String::from(
        "scene,format,label,answer,correct,confidence,latency_ms,prompt_tokens,steps,error\n",
    );
    let mut table = Vec::new();
    for format in PromptFormat::ALL {
        let (mut correct, mut answered, mut steps, mut tokens) = (0, 0, 0, 0u64);
        let mut latencies = Vec::new();
        for (i, s) in set.iter().enumerate() {
            eprint!("\r{} {}/{}   ", format.name(), i + 1, set.len());
            let (result, latency) = advisor.ask(format, STEPS, 160, &s.request, &s.history);
            let ms = latency * 1e3;
            match result {
                Ok((a, t)) => {
                    answered += 1;
                    latencies.push(ms);
                    steps += a.steps.len();
                    tokens += u64::from(t);
                    let ok = a.maneuver == s.label;
                    correct += usize::from(ok);
                    let _ = writeln!(
                        csv,
                        "{i},{},{},{},{},{:.3},{ms:.0},{t},{},",
                        format.name(),
                        s.label.name(),
                        a.maneuver.name(),
                        ok as u8,
                        a.confidence.unwrap_or(f64::NAN),
                        a.steps.len()
                    );
                }
                Err(e) => {
                    let _ = writeln!(
                        csv,
                        "{i},{},{},,0,,{ms:.0},,,{}",
                        format.name(),
                        s.label.name(),
                        e.replace([',', '\n'], " ")
                    );
                }
            }
        }
        latencies.sort_by(f64::total_cmp);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        table.push((
            format,
            correct,
            answered,
            mean(&latencies),
            latencies
                .get(latencies.len() / 2)
                .copied()
                .unwrap_or(f64::NAN),
            steps as f64 / answered.max(1) as f64,
            tokens as f64 / answered.max(1) as f64,
        ));
    }
    eprintln!();
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    std::fs::write(out.join("prompts.csv"), csv).map_err(|e| e.to_string())?;
    println!("| format | accuracy | answered | mean latency | p50 latency | reasoning steps | prompt tokens |");
    println!("|---|---|---|---|---|---|---|");
    for (f, correct, answered, mean, p50, steps, tokens) in table {
        println!(
            "| {} | {:.0} % ({correct}/{n}) | {answered}/{n} | {:.2} s | {:.2} s | {steps:.1} | {tokens:.0} |",
            f.name(),
            100.0 * correct as f64 / n.max(1) as f64,
            mean / 1e3,
            p50 / 1e3
        );
    }
    println!("wrote {}", out.join("prompts.csv").display());
    Ok(())
}
