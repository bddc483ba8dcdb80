//! `concord learn dataset`: the advisor's fine-tuning and evaluation sets (§5 step 5), as JSONL,
//! one example per line: `{"task", "messages", "answer", "label", ...}`, where `messages` is
//! the prompt exactly as the sidecar renders it and `answer` the JSON the schema asks for.
//!
//! * **Advice** ([`labelled_scenes`]): scenes from the simulator (the left turn, the left turn
//!   with the right of way, the merge and the stream; every driver style; initial speeds
//!   5–11 m/s; starts ±15 m) driven by Concord logit-only and stopped at a random moment before
//!   the conflict resolves. The label is the oracle's: the fastest route-consistent maneuver
//!   that, rolled out for 8 s against copies of the drivers, never brings the cars within 3 m
//!   ([`best_maneuver`]). Labels are balanced by one rule in both sets: none above a third. Scene k
//!   of the training set is drawn from seed k, of the held-out set from seed
//!   [`HELD_OUT_SEED`] + k: the two never share a seed.
//! * **Intents** ([`intent_examples`]): messages composed from phrase files
//!   (`deploy/llm/intents/train.txt`, and `heldout.txt` with different templates and words),
//!   labelled style, action and task, "unknown" for what a message does not say.
//! * **Interaction log** ([`log_examples`]): advice calls from the sidecar's JSONL log, labelled
//!   with the maneuver the core executed after its verdict on them.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use concord_core::{Maneuver, Params};
use concord_ipc::wire::{AdviceRequest, SceneFrame};
use concord_sidecar::config::{PromptFormat, SidecarConfig};
use concord_sidecar::prompt::{self, ChatMessage, Stated};
use concord_sidecar::schema::{advice_answer, ACTION_VALUES, STYLE_VALUES, TASK_VALUES};
use concord_sim::controllers::{best_maneuver, Advisor, ConcordController, Controller};
use concord_sim::driver::{DriverStyle, HumanDriver};
use concord_sim::experiment::stream_followers;
use concord_sim::world::{ScenarioKind, World, DT};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use serde_json::json;

/// First seed of held-out scenes and messages; training draws only seeds below it.
pub const HELD_OUT_SEED: u64 = 500_000;

/// Phrase file of the held-out intent messages.
pub const HELD_OUT_PHRASES: &str = "deploy/llm/intents/heldout.txt";

/// The scenarios advice scenes are drawn from.
pub const SCENARIOS: [ScenarioKind; 4] = [
    ScenarioKind::LeftTurn,
    ScenarioKind::LeftTurnPriority,
    ScenarioKind::Merge,
    ScenarioKind::Stream,
];

/// One labelled advice scene.
pub struct Labelled {
    pub request: AdviceRequest,
    /// The last 0.45 s of scene frames, oldest first (for the Raw rendering).
    pub history: Vec<SceneFrame>,
    pub label: Maneuver,
    pub scenario: ScenarioKind,
    pub seed: u64,
}

/// The scene drawn from `seed`, or `None` when the conflict resolved before the drawn moment.
fn scene(seed: u64, scenarios: &[ScenarioKind]) -> Option<Labelled> {
    let mut rng = SmallRng::seed_from_u64(seed);
    let scenario = scenarios[rng.random_range(0..scenarios.len())];
    let speed = rng.random_range(5.0..11.0);
    let style = DriverStyle::ALL[rng.random_range(0..DriverStyle::ALL.len())];
    let followers = if scenario == ScenarioKind::Stream {
        stream_followers(&mut rng, speed)
    } else {
        Vec::new()
    };
    let headways: Vec<f64> = followers.iter().map(|f| f.headway_s).collect();
    let mut w = World::with_followers(scenario, speed, rng.random_range(-15.0..15.0), &headways);
    let mut drivers: Vec<HumanDriver> = std::iter::once(style)
        .chain(followers.iter().map(|f| f.style))
        .map(|s| HumanDriver::new(s, speed, rng.random()))
        .collect();
    let mut cav = ConcordController::new(Params::default(), &w, Advisor::None);
    let stop_at = rng.random_range(0.5..5.0);
    let mut history: Vec<SceneFrame> = Vec::new();
    let mut accels = vec![0.0; drivers.len()];
    let mut seq = 0;
    while w.t < stop_at {
        let cmd = cav.act(&w, &drivers);
        history.push(SceneFrame::from_scene(
            seq,
            (w.t * 1e9) as u64 + 1,
            &w.scene(),
        ));
        seq += 1;
        for (i, (d, a)) in drivers.iter_mut().zip(accels.iter_mut()).enumerate() {
            *a = d.act(&w, i, cmd.ehmi).accel;
        }
        w.step(cmd.accel, &accels);
    }
    // Still open: some driver has not left its zone, and the CAV has entered none of those.
    let open: Vec<(f64, f64)> = (0..w.hdvs.len())
        .map(|i| (w.to_conflict(i), w.hdvs[i].zone_half_m))
        .filter(|((_, hdv_d), zone)| *hdv_d >= -zone)
        .map(|((ego_d, _), zone)| (ego_d, zone))
        .collect();
    if open.is_empty() || open.iter().any(|(ego_d, zone)| ego_d < zone) {
        return None;
    }
    let decision = cav.last?;
    let request = AdviceRequest::from_core(
        decision.request_id,
        seq,
        0,
        u64::MAX,
        &decision,
        cav.core(),
        w.ego.lane,
    );
    // No message reaches the drivers in the label's rollouts: the prompt has none either.
    let label = best_maneuver(&w, &drivers, false);
    let keep = (0.45 / DT) as usize;
    let history = history.split_off(history.len().saturating_sub(keep));
    Some(Labelled {
        request,
        history,
        label,
        scenario,
        seed,
    })
}

/// `n` labelled scenes from seeds `first_seed`, `first_seed + 1`, …, none of whose labels
/// fills more than `cap`; `progress` names the set on stderr. Fails when the seeds up to
/// `first_seed + 500 n` do not give enough of every label.
pub fn labelled_scenes(
    n: usize,
    cap: usize,
    first_seed: u64,
    scenarios: &[ScenarioKind],
    progress: &str,
) -> Result<Vec<Labelled>, String> {
    let mut counts = [0usize; 5];
    let mut out = Vec::with_capacity(n);
    let last = first_seed + 500 * n as u64;
    let mut seed = first_seed;
    while out.len() < n {
        if seed >= last {
            return Err(format!(
                "{progress}: seeds {first_seed}..{last} gave only {} of {n} scenes with balanced labels",
                out.len()
            ));
        }
        if let Some(s) = scene(seed, scenarios) {
            if counts[s.label as usize] < cap {
                counts[s.label as usize] += 1;
                out.push(s);
                if out.len() % 25 == 0 || out.len() == n {
                    eprint!("\r{progress}: {}/{n} scenes", out.len());
                }
            }
        }
        seed += 1;
    }
    eprintln!(" (seeds {first_seed}..{seed})");
    Ok(out)
}

/// The advice prompt of scene `s`, as the sidecar configured by `cfg` renders it.
pub fn advice_prompt(cfg: &SidecarConfig, s: &Labelled) -> Vec<ChatMessage> {
    prompt::advice_messages(
        PromptFormat::Opm,
        cfg.advice.reasoning_steps,
        cfg.advice.max_objects,
        &s.request,
        &s.history,
        &Stated::default(),
        cfg.intent.weak_below,
        cfg.llm.fine_tuned,
    )
}

/// A message's intent label: style, action and task, each a schema value ("unknown" when the
/// message does not say).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IntentLabel {
    pub style: &'static str,
    pub action: &'static str,
    pub task: &'static str,
}

impl IntentLabel {
    pub fn answer(&self) -> String {
        format!(
            "{{\"style\": \"{}\", \"action\": \"{}\", \"task\": \"{}\"}}",
            self.style, self.action, self.task
        )
    }
}

/// A labelled message.
pub struct IntentExample {
    pub speaker: String,
    pub text: String,
    pub label: IntentLabel,
}

/// Phrases by dimension and value, from a phrase file: `<dimension> <value> | <phrase>` per
/// line (dimension `style`, `action`, `task`, or `none` without a value for phrases that say
/// nothing), `#` comments.
#[derive(Default)]
pub struct Phrases {
    by_value: HashMap<(String, &'static str), Vec<String>>,
    none: Vec<String>,
}

impl Phrases {
    pub fn parse(text: &str, origin: &str) -> Result<Self, String> {
        let mut p = Phrases::default();
        for (no, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let err = |m: &str| format!("{origin}:{}: {m}: {line:?}", no + 1);
            let (head, phrase) = line
                .split_once('|')
                .ok_or_else(|| err("expected '<dimension> <value> | <phrase>'"))?;
            let phrase = phrase.trim().to_string();
            if phrase.is_empty() {
                return Err(err("empty phrase"));
            }
            let mut words = head.split_whitespace();
            match (words.next(), words.next(), words.next()) {
                (Some("none"), None, None) => p.none.push(phrase),
                (Some(dim), Some(value), None) => {
                    let values: &[&'static str] = match dim {
                        "style" => &STYLE_VALUES,
                        "action" => &ACTION_VALUES,
                        "task" => &TASK_VALUES,
                        _ => return Err(err("dimension must be style, action, task or none")),
                    };
                    let v = values
                        .iter()
                        .find(|v| **v == value && **v != "unknown")
                        .ok_or_else(|| err(&format!("{dim} has no value {value:?}")))?;
                    p.by_value
                        .entry((dim.to_string(), v))
                        .or_default()
                        .push(phrase);
                }
                _ => return Err(err("expected '<dimension> <value> | <phrase>'")),
            }
        }
        for (dim, values) in [
            ("action", &ACTION_VALUES[..]),
            ("task", &TASK_VALUES[..]),
            ("style", &STYLE_VALUES[..]),
        ] {
            for v in values.iter().filter(|v| **v != "unknown") {
                if !p.by_value.contains_key(&(dim.to_string(), *v)) {
                    return Err(format!("{origin}: no phrase for {dim} {v}"));
                }
            }
        }
        if p.none.is_empty() {
            return Err(format!("{origin}: no 'none' phrase"));
        }
        Ok(p)
    }

    /// A phrase for `dim`, its value drawn uniformly, then the phrase.
    fn draw(&self, dim: &str, values: &[&'static str], rng: &mut SmallRng) -> (&'static str, &str) {
        let known: Vec<&'static str> = values.iter().copied().filter(|v| *v != "unknown").collect();
        let v = known[rng.random_range(0..known.len())];
        let list = &self.by_value[&(dim.to_string(), v)];
        (v, &list[rng.random_range(0..list.len())])
    }
}

/// `n` messages composed from `phrases`, message k from seed `first_seed + k`: an action with
/// probability 0.7, a task 0.4, a style 0.3, a phrase saying nothing 0.25 (always when none of
/// the others), in random order and punctuation, from the passenger or a road user.
pub fn intent_examples(phrases: &Phrases, n: usize, first_seed: u64) -> Vec<IntentExample> {
    (0..n as u64)
        .map(|k| {
            let mut rng = SmallRng::seed_from_u64(first_seed + k);
            let mut label = IntentLabel {
                style: "unknown",
                action: "unknown",
                task: "unknown",
            };
            let mut parts: Vec<String> = Vec::new();
            if rng.random_bool(0.7) {
                let (v, p) = phrases.draw("action", &ACTION_VALUES, &mut rng);
                label.action = v;
                parts.push(p.to_string());
            }
            if rng.random_bool(0.4) {
                let (v, p) = phrases.draw("task", &TASK_VALUES, &mut rng);
                label.task = v;
                parts.push(p.to_string());
            }
            if rng.random_bool(0.3) {
                let (v, p) = phrases.draw("style", &STYLE_VALUES, &mut rng);
                label.style = v;
                parts.push(p.to_string());
            }
            if parts.is_empty() || rng.random_bool(0.25) {
                let p = &phrases.none[rng.random_range(0..phrases.none.len())];
                parts.insert(rng.random_range(0..=parts.len()), p.clone());
            }
            for i in (1..parts.len()).rev() {
                parts.swap(i, rng.random_range(0..=i));
            }
            let sep = [", ", ". ", " - ", "; ", " "][rng.random_range(0..5)];
            let mut text = parts.join(sep);
            if rng.random_bool(0.5) {
                let mut c = text.chars();
                if let Some(first) = c.next() {
                    text = first.to_uppercase().chain(c).collect();
                }
            }
            text.push_str(["", ".", "!", "!!", "?"][rng.random_range(0..5)]);
            let speaker = if rng.random_bool(0.4) {
                "the passenger".to_string()
            } else {
                format!("road user {}", rng.random_range(1..40))
            };
            IntentExample {
                speaker,
                text,
                label,
            }
        })
        .collect()
}

/// The intent parser's prompt for `e`, as the sidecar configured by `cfg` renders it.
pub fn intent_prompt(cfg: &SidecarConfig, e: &IntentExample) -> Vec<ChatMessage> {
    prompt::intent_messages(
        &e.speaker,
        None,
        &e.text,
        cfg.intent.max_text_chars,
        cfg.llm.fine_tuned,
    )
}

/// Examples from the sidecar's interaction log: every answered advice call whose request the
/// core gave a verdict on, with the prompt as logged and, as the label, the maneuver the core
/// executed (its own choice where it refused the advice). Lines of other kinds are skipped;
/// a line that is not JSON is an error naming it.
pub fn log_examples(text: &str, origin: &str) -> Result<Vec<(serde_json::Value, String)>, String> {
    let mut prompts: HashMap<u64, serde_json::Value> = HashMap::new();
    let mut out = Vec::new();
    for (no, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v: serde_json::Value = serde_json::from_str(line)
            .map_err(|e| format!("{origin}:{}: not a JSON line: {e}", no + 1))?;
        let id = v["request_id"].as_u64();
        match (v["kind"].as_str(), id) {
            (Some("advice"), Some(id)) if v["outcome"] == "answered" => {
                prompts.insert(id, v["messages"].clone());
            }
            (Some("verdict"), Some(id)) => {
                let executed = v["executed"].as_str().unwrap_or("");
                let Some(m) = Maneuver::ALL.into_iter().find(|m| m.name() == executed) else {
                    continue;
                };
                if let Some(messages) = prompts.remove(&id) {
                    out.push((messages, advice_answer(m)));
                }
            }
            _ => {}
        }
    }
    Ok(out)
}

/// Writes the datasets under `out`: `advice_train.jsonl` and `advice_heldout.jsonl`,
/// `intents_train.jsonl` and `intents_heldout.jsonl`, and `log.jsonl` from `logs`.
#[allow(clippy::too_many_arguments)]
pub fn dataset(
    cfg: &SidecarConfig,
    out: &Path,
    advice: (usize, usize),
    intents: (usize, usize),
    phrase_files: (&Path, &Path),
    logs: &[std::path::PathBuf],
) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let write = |name: &str, lines: &[serde_json::Value]| -> Result<(), String> {
        let mut s = String::new();
        for l in lines {
            let _ = writeln!(s, "{l}");
        }
        let path = out.join(name);
        std::fs::write(&path, s).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("wrote {} ({} examples)", path.display(), lines.len());
        Ok(())
    };
    // Both sets by one rule, none of the labels above a third: the shares the advisor learns
    // are the ones it is judged on (equal shares overstated the rarest label, decelerate,
    // five-fold).
    for (name, n, first) in [
        ("advice_train.jsonl", advice.0, 0),
        ("advice_heldout.jsonl", advice.1, HELD_OUT_SEED),
    ] {
        let set = labelled_scenes(n, n.div_ceil(3), first, &SCENARIOS, name)?;
        let lines: Vec<_> = set
            .iter()
            .map(|s| {
                json!({"task": "advice", "scenario": s.scenario.name(), "seed": s.seed,
                       "label": s.label.name(), "messages": advice_prompt(cfg, s),
                       "answer": advice_answer(s.label)})
            })
            .collect();
        write(name, &lines)?;
    }
    for (name, n, first, file) in [
        ("intents_train.jsonl", intents.0, 0, phrase_files.0),
        (
            "intents_heldout.jsonl",
            intents.1,
            HELD_OUT_SEED,
            phrase_files.1,
        ),
    ] {
        let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
        let phrases = Phrases::parse(&text, &file.display().to_string())?;
        let lines: Vec<_> = intent_examples(&phrases, n, first)
            .iter()
            .map(|e| {
                json!({"task": "intent", "text": e.text, "label": e.label,
                       "messages": intent_prompt(cfg, e), "answer": e.label.answer()})
            })
            .collect();
        write(name, &lines)?;
    }
    let mut lines = Vec::new();
    for file in logs {
        let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
        for (messages, answer) in log_examples(&text, &file.display().to_string())? {
            lines.push(
                json!({"task": "advice", "source": "log", "messages": messages,
                              "answer": answer}),
            );
        }
    }
    if !logs.is_empty() {
        write("log.jsonl", &lines)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const PHRASES: &str = "action yield | go ahead\naction proceed | I go first\n\
        action accelerate | faster\naction decelerate | slower\naction turn_left | left\n\
        action turn_right | right\naction stop | stop here\ntask commute | to work\n\
        task emergency | hospital\ntask official | police\ntask leisure | sightseeing\n\
        style aggressive | move it\nstyle balanced | normal pace\nstyle conservative | careful\n\
        none | hello\n";

    #[test]
    fn messages_carry_the_labels_of_their_phrases_and_unknown_for_the_rest() {
        let p = Phrases::parse(PHRASES, "test").unwrap();
        let set = intent_examples(&p, 300, 0);
        let mut unknown_actions = 0;
        for e in &set {
            let lower = e.text.to_lowercase();
            assert_eq!(
                lower.contains("hospital"),
                e.label.task == "emergency",
                "{}",
                e.text
            );
            assert_eq!(lower.contains("careful"), e.label.style == "conservative");
            unknown_actions += usize::from(e.label.action == "unknown");
            assert_eq!(
                e.label.answer(),
                format!(
                    "{{\"style\": \"{}\", \"action\": \"{}\", \"task\": \"{}\"}}",
                    e.label.style, e.label.action, e.label.task
                )
            );
        }
        // About 30 % say no action.
        assert!((60..120).contains(&unknown_actions), "{unknown_actions}");
        // The same seeds give the same messages.
        assert_eq!(intent_examples(&p, 5, 7)[3].text, set[10].text);
    }

    #[test]
    fn a_phrase_file_without_a_value_or_with_a_bad_line_is_an_error() {
        let missing = PHRASES.replace("task leisure | sightseeing\n", "");
        assert!(Phrases::parse(&missing, "f")
            .err()
            .unwrap()
            .contains("task leisure"));
        let bad = format!("{PHRASES}action fly | up\n");
        assert!(Phrases::parse(&bad, "f").err().unwrap().contains("f:16"));
    }

    #[test]
    fn log_lines_are_labelled_with_the_executed_maneuver() {
        let log = r#"{"kind":"advice","request_id":7,"outcome":"answered","messages":[{"role":"user","content":"x"}],"maneuver":"accelerate"}
{"kind":"intent","outcome":"answered"}
{"kind":"advice","request_id":8,"outcome":"failed","messages":[]}
{"kind":"verdict","request_id":7,"verdict":"vetoed","executed":"decelerate"}
{"kind":"verdict","request_id":8,"verdict":"late","executed":"turn_left"}
"#;
        let ex = log_examples(log, "log").unwrap();
        assert_eq!(ex.len(), 1);
        assert_eq!(ex[0].1, advice_answer(Maneuver::Decelerate));
        assert_eq!(ex[0].0[0]["content"], "x");
        assert!(log_examples("{", "log").err().unwrap().contains("log:1"));
    }

    #[test]
    fn advice_scenes_are_balanced_and_training_never_draws_a_held_out_seed() {
        let set = labelled_scenes(9, 3, 0, &SCENARIOS, "test").unwrap();
        let mut counts = [0; 5];
        for s in &set {
            counts[s.label as usize] += 1;
            assert!(s.seed < HELD_OUT_SEED);
            assert!(
                s.label.consistent_with(concord_core::scene::Turn::Left)
                    || s.scenario == ScenarioKind::Merge
            );
        }
        assert!(counts.iter().all(|c| *c <= 3), "{counts:?}");
        // Rendered as the sidecar renders a request: for the fine-tuned model by default, in
        // full for any other.
        let mut cfg = SidecarConfig::default();
        let m = advice_prompt(&cfg, &set[0]);
        assert_eq!(m.len(), 2);
        assert!(m[1].content.starts_with("ego "), "{}", m[1].content);
        assert!(m[1].content.contains("\nP acc "));
        cfg.llm.fine_tuned = false;
        assert!(advice_prompt(&cfg, &set[0])[1].content.contains("P_n:"));
    }
}
