//! `concord experiment advisor`: the advisor on held-out scenes and messages, the base model
//! against the fine-tuned one, on one llama.cpp server that carries the adapter (a request sets
//! the adapter's scale with llama.cpp's per-request `lora` field: 0 for the base model).
//!
//! * **Advice:** [`crate::learn::labelled_scenes`] from the held-out seeds, each asked once as the
//!   sidecar asks (the base model with the instructions, the fine-tuned one with its one-line
//!   prefix; schema, confidence from log-probabilities). Accuracy, the confusion matrix, the
//!   expected calibration error over 10 equal confidence bins (ECE = Σ_b n_b/N |acc_b −
//!   conf_b|), the share of correct answers that pass the core's 0.7 gate and the share of all
//!   answers that are wrong and pass it, latency; a reliability diagram per model (SVG).
//! * **Intents:** messages from the held-out phrase file. Per dimension (style, action, task):
//!   among messages that state it, the share parsed right with a confidence at or above the
//!   sidecar's `intent.weak_below` (strong and correct); among all, the share parsed strong and
//!   wrong; among messages that do not state it, the share parsed "unknown".

use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

use crate::learn;
use crate::llm_experiments::LlmAdvisor;
use concord_core::Maneuver;
use concord_sidecar::llm::LlmClient;
use concord_sidecar::schema::{
    action_name, intent_schema, style_name, task_name, AdviceAnswer, IntentAnswer,
    INTENT_MAX_TOKENS,
};

/// The intent dimensions, in the schema's order.
const DIMENSIONS: [&str; 3] = ["style", "action", "task"];

/// One model's answers.
#[derive(Default)]
struct AdviceRun {
    /// (label, answer, confidence) per answered scene.
    answers: Vec<(Maneuver, Maneuver, f64)>,
    failures: usize,
    latencies_ms: Vec<f64>,
}

impl AdviceRun {
    fn accuracy(&self, n: usize) -> f64 {
        self.answers.iter().filter(|(l, a, _)| l == a).count() as f64 / n.max(1) as f64
    }

    /// Expected calibration error over 10 bins, and each bin's (count, mean confidence,
    /// accuracy).
    fn calibration(&self) -> (f64, Vec<(usize, f64, f64)>) {
        let mut bins = vec![(0usize, 0.0, 0.0); 10];
        for (l, a, c) in &self.answers {
            let b = ((c * 10.0) as usize).min(9);
            bins[b].0 += 1;
            bins[b].1 += c;
            bins[b].2 += f64::from(u8::from(l == a));
        }
        let n = self.answers.len().max(1) as f64;
        let mut ece = 0.0;
        for b in &mut bins {
            if b.0 > 0 {
                b.1 /= b.0 as f64;
                b.2 /= b.0 as f64;
                ece += b.0 as f64 / n * (b.2 - b.1).abs();
            }
        }
        (ece, bins)
    }

    /// Correct answers passing a confidence gate at `gate`, over correct answers; wrong ones
    /// passing it, over all.
    fn gate(&self, gate: f64) -> (f64, f64) {
        let correct = self.answers.iter().filter(|(l, a, _)| l == a);
        let n_correct = correct.clone().count();
        let pass = correct.filter(|(_, _, c)| *c >= gate).count();
        let wrong_pass = self
            .answers
            .iter()
            .filter(|(l, a, c)| l != a && *c >= gate)
            .count();
        (
            pass as f64 / n_correct.max(1) as f64,
            wrong_pass as f64 / self.answers.len().max(1) as f64,
        )
    }
}

fn percentile(v: &[f64], p: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(((s.len() as f64 * p) as usize).min(s.len().saturating_sub(1)))
        .copied()
        .unwrap_or(f64::NAN)
}

/// A reliability diagram: per bin, the accuracy (bar) against the diagonal.
fn reliability_svg(title: &str, bins: &[(usize, f64, f64)], ece: f64) -> String {
    let (w, h, m) = (360.0, 360.0, 40.0);
    let x = |v: f64| m + v * (w - 2.0 * m);
    let y = |v: f64| h - m - v * (h - 2.0 * m);
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"11\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{}\" y=\"20\" text-anchor=\"middle\">{title} (ECE {ece:.3})</text>\n",
        w / 2.0
    );
    for (i, (n, _, acc)) in bins.iter().enumerate() {
        if *n == 0 {
            continue;
        }
        let x0 = x(i as f64 / 10.0);
        let _ = writeln!(
            s,
            "<rect x=\"{x0:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#4477aa\" stroke=\"white\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"9\">{n}</text>",
            y(*acc),
            x(0.1) - x(0.0),
            y(0.0) - y(*acc),
            x0 + (x(0.1) - x(0.0)) / 2.0,
            y(*acc) - 3.0
        );
    }
    let _ = writeln!(
        s,
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"#cc3311\" stroke-dasharray=\"4 3\"/>\n\
         <line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>\n\
         <line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>\n\
         <text x=\"{}\" y=\"{}\" text-anchor=\"middle\">confidence</text>\n\
         <text x=\"12\" y=\"{}\" transform=\"rotate(-90 12 {})\" text-anchor=\"middle\">accuracy</text>\n</svg>",
        x(0.0), y(0.0), x(1.0), y(1.0),
        x(0.0), y(0.0), x(1.0), y(0.0),
        x(0.0), y(0.0), x(0.0), y(1.0),
        w / 2.0, h - 10.0, h / 2.0, h / 2.0
    );
    s
}

/// The models compared: name, whether prompts are the fine-tuned ones, adapter scale.
fn models(has_adapter: bool) -> Vec<(&'static str, bool, Option<f64>)> {
    let mut m = vec![("base", false, has_adapter.then_some(0.0))];
    if has_adapter {
        m.push(("fine-tuned", true, Some(1.0)));
    }
    m
}

/// Runs the evaluation against `url`, writes `advisor.csv`, `intents.csv` and the reliability
/// diagrams under `out`, and prints the tables.
pub fn run(url: &str, scenes: usize, messages: usize, out: &Path) -> Result<(), String> {
    let advisor = LlmAdvisor::new(url)?;
    // The core's gate on A_final (eq. 16).
    let gate = concord_core::Params::default().advice.confidence_min;
    let (rt, client, base_cfg) = (&advisor.rt, &advisor.client, &advisor.cfg);
    let adapter = base_cfg.llm.fine_tuned;
    eprintln!(
        "concord experiment advisor: model {:?} at {url}, {}",
        advisor.model,
        if adapter {
            "adapter loaded: base (scale 0) against fine-tuned (scale 1)"
        } else {
            "no adapter loaded: base model only"
        }
    );
    let set = learn::labelled_scenes(
        scenes,
        scenes.div_ceil(3),
        learn::HELD_OUT_SEED,
        &learn::SCENARIOS,
        "held-out scenes",
    )?;
    let phrases_path = Path::new(learn::HELD_OUT_PHRASES);
    let text = std::fs::read_to_string(phrases_path)
        .map_err(|e| format!("{}: {e}", phrases_path.display()))?;
    let phrases = learn::Phrases::parse(&text, &phrases_path.display().to_string())?;
    let heard = learn::intent_examples(&phrases, messages, learn::HELD_OUT_SEED);
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;

    let ask = |body: serde_json::Value, scale: Option<f64>| {
        let body = match scale {
            Some(s) => LlmClient::with_adapter_scale(body, s),
            None => body,
        };
        let started = Instant::now();
        let r = rt.block_on(client.call(&body, started + Duration::from_secs(60)));
        (r, started.elapsed().as_secs_f64() * 1e3)
    };

    let mut csv = String::from("model,scene,scenario,label,answer,confidence,latency_ms,error\n");
    let mut icsv = String::from("model,message,dimension,label,answer,confidence\n");
    let mut advice_rows = Vec::new();
    let mut intent_rows = Vec::new();
    for (name, tuned, scale) in models(adapter) {
        let mut cfg = base_cfg.clone();
        cfg.llm.fine_tuned = tuned;
        let mut run = AdviceRun::default();
        for (i, s) in set.iter().enumerate() {
            eprint!("\r{name}: advice {}/{}   ", i + 1, set.len());
            let messages = learn::advice_prompt(&cfg, s);
            // The fine-tuned adapter is asked in its deployed form, the answer begun for it.
            cfg.advice.prefill_answer = tuned;
            let body = client.advice_body(&messages, &cfg.advice);
            let (reply, ms) = ask(body, scale);
            match reply
                .map_err(|e| e.to_string())
                .and_then(|r| AdviceAnswer::decode(&r.answer).map_err(|e| e.to_string()))
            {
                Ok(a) => {
                    let c = a
                        .confidence
                        .unwrap_or(base_cfg.llm.confidence_without_logprobs);
                    run.answers.push((s.label, a.maneuver, c));
                    run.latencies_ms.push(ms);
                    let _ = writeln!(
                        csv,
                        "{name},{i},{},{},{},{c:.4},{ms:.0},",
                        s.scenario.name(),
                        s.label.name(),
                        a.maneuver.name()
                    );
                }
                Err(e) => {
                    run.failures += 1;
                    let _ = writeln!(
                        csv,
                        "{name},{i},{},{},,,{ms:.0},{}",
                        s.scenario.name(),
                        s.label.name(),
                        e.replace([',', '\n'], " ")
                    );
                }
            }
        }
        let (ece, bins) = run.calibration();
        let svg = out.join(format!("reliability_{}.svg", name.replace('-', "_")));
        std::fs::write(
            &svg,
            reliability_svg(&format!("advice, {name}"), &bins, ece),
        )
        .map_err(|e| format!("{}: {e}", svg.display()))?;
        advice_rows.push((name, run));

        // Intents.
        let weak_below = cfg.intent.weak_below;
        let mut counts = [[0usize; 4]; 3]; // per dimension: stated, strong right, strong wrong, unknown right
        let mut unstated = [0usize; 3];
        for (i, e) in heard.iter().enumerate() {
            eprint!("\r{name}: intents {}/{}   ", i + 1, heard.len());
            let messages = learn::intent_prompt(&cfg, e);
            let body = client.body(&messages, "intent", &intent_schema(), INTENT_MAX_TOKENS);
            let (reply, _) = ask(body, scale);
            let parsed = reply.map_err(|e| e.to_string()).and_then(|r| {
                IntentAnswer::decode(&r.answer, base_cfg.llm.confidence_without_logprobs)
                    .map_err(|e| e.to_string())
            });
            let got: [Option<(&str, f64)>; 3] = match &parsed {
                Ok(a) => [
                    a.style.map(|(v, c)| (style_name(v), c)),
                    a.action.map(|(v, c)| (action_name(v), c)),
                    a.task.map(|(v, c)| (task_name(v), c)),
                ],
                Err(_) => [None; 3],
            };
            let labels = [e.label.style, e.label.action, e.label.task];
            for d in 0..3 {
                let (answer, conf) = got[d].unwrap_or(("unknown", 0.0));
                let strong = conf >= weak_below && answer != "unknown";
                if labels[d] != "unknown" {
                    counts[d][0] += 1;
                    counts[d][1] += usize::from(strong && answer == labels[d]);
                } else {
                    unstated[d] += 1;
                    counts[d][3] += usize::from(answer == "unknown");
                }
                counts[d][2] += usize::from(strong && answer != labels[d]);
                let _ = writeln!(
                    icsv,
                    "{name},{i},{},{},{answer},{conf:.4}",
                    DIMENSIONS[d], labels[d]
                );
            }
        }
        intent_rows.push((name, counts, unstated));
    }
    eprintln!();
    std::fs::write(out.join("advisor.csv"), csv).map_err(|e| e.to_string())?;
    std::fs::write(out.join("intents.csv"), icsv).map_err(|e| e.to_string())?;

    let n = set.len();
    // The numbers `finetune.py promote` compares, per model.
    let mut summary = serde_json::Map::new();
    for ((name, run), (_, counts, unstated)) in advice_rows.iter().zip(&intent_rows) {
        let (ece, _) = run.calibration();
        let (pass, wrong) = run.gate(gate);
        let dims: Vec<_> = (0..3)
            .map(|d| {
                serde_json::json!({
                    "dimension": DIMENSIONS[d],
                    "strong_correct": counts[d][1] as f64 / counts[d][0].max(1) as f64,
                    "strong_wrong": counts[d][2] as f64 / heard.len().max(1) as f64,
                    "unknown_right": counts[d][3] as f64 / unstated[d].max(1) as f64,
                })
            })
            .collect();
        summary.insert(
            name.to_string(),
            serde_json::json!({"scenes": n, "accuracy": run.accuracy(n), "ece": ece,
                               "correct_passing_gate": pass, "wrong_passing_gate": wrong,
                               "latency_p50_ms": percentile(&run.latencies_ms, 0.5),
                               "latency_p95_ms": percentile(&run.latencies_ms, 0.95),
                               "intents": dims}),
        );
    }
    std::fs::write(
        out.join("summary.json"),
        serde_json::to_string_pretty(&summary).map_err(|e| e.to_string())? + "\n",
    )
    .map_err(|e| e.to_string())?;
    println!("Advice on {n} held-out scenes:\n");
    println!("| model | accuracy | answered | ECE | correct passing the gate | wrong passing the gate (of all) | latency p50 / p95 ms |");
    println!("|---|---|---|---|---|---|---|");
    for (name, run) in &advice_rows {
        let (ece, _) = run.calibration();
        let (pass, wrong) = run.gate(gate);
        println!(
            "| {name} | {:.1} % | {}/{n} | {ece:.3} | {:.1} % | {:.1} % | {:.0} / {:.0} |",
            100.0 * run.accuracy(n),
            run.answers.len(),
            100.0 * pass,
            100.0 * wrong,
            percentile(&run.latencies_ms, 0.5),
            percentile(&run.latencies_ms, 0.95)
        );
    }
    for (name, run) in &advice_rows {
        println!("\nConfusion, {name} (rows: label, columns: answer):\n");
        let used: Vec<Maneuver> = Maneuver::ALL
            .into_iter()
            .filter(|m| run.answers.iter().any(|(l, a, _)| l == m || a == m))
            .collect();
        println!(
            "| label | {} |",
            used.iter()
                .map(|m| m.name())
                .collect::<Vec<_>>()
                .join(" | ")
        );
        println!("|---|{}", "---|".repeat(used.len()));
        for l in &used {
            let row: Vec<String> = used
                .iter()
                .map(|a| {
                    run.answers
                        .iter()
                        .filter(|(x, y, _)| x == l && y == a)
                        .count()
                        .to_string()
                })
                .collect();
            println!("| {} | {} |", l.name(), row.join(" | "));
        }
    }
    println!(
        "\nIntents on {} held-out messages (strong: confidence >= {}):\n",
        heard.len(),
        base_cfg.intent.weak_below
    );
    println!("| model | dimension | stated | strong and correct | strong and wrong (of all) | unknown right (of unstated) |");
    println!("|---|---|---|---|---|---|");
    for (name, counts, unstated) in &intent_rows {
        for d in 0..3 {
            let c = counts[d];
            println!(
                "| {name} | {} | {} | {:.1} % | {:.1} % | {:.1} % |",
                DIMENSIONS[d],
                c[0],
                100.0 * c[1] as f64 / c[0].max(1) as f64,
                100.0 * c[2] as f64 / heard.len().max(1) as f64,
                100.0 * c[3] as f64 / unstated[d].max(1) as f64
            );
        }
    }
    println!(
        "\nwrote {}, {} and the reliability diagrams",
        out.join("advisor.csv").display(),
        out.join("intents.csv").display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn calibration_and_gate_shares_follow_their_definitions() {
        use Maneuver::*;
        let run = AdviceRun {
            answers: vec![
                (Accelerate, Accelerate, 0.95),
                (Accelerate, Decelerate, 0.92),
                (TurnLeft, TurnLeft, 0.35),
                (TurnLeft, TurnLeft, 0.31),
            ],
            ..AdviceRun::default()
        };
        let (ece, bins) = run.calibration();
        // Bin 9: conf 0.935, acc 0.5; bin 3: conf 0.33, acc 1.
        assert_eq!(bins[9].0, 2);
        assert!((ece - (0.5 * 0.435 + 0.5 * 0.67)).abs() < 1e-9, "{ece}");
        let (pass, wrong) = run.gate(0.7);
        assert!((pass - 1.0 / 3.0).abs() < 1e-9);
        assert!((wrong - 0.25).abs() < 1e-9);
        assert!((run.accuracy(5) - 0.6).abs() < 1e-9);
        let svg = reliability_svg("t", &bins, ece);
        assert_eq!(svg.matches("<rect").count(), 3);
    }
}
