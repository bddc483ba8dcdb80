//! Configuration of `concord sidecar` (`deploy/sidecar.toml`): every key optional, unknown
//! keys rejected.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::ehmi::Language;

/// How the scene is written into the advice prompt (paper §6.1.3).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PromptFormat {
    /// Objects, processes and relations (eq. 6), with saliency.
    #[default]
    Opm,
    /// Unstructured numeric perception output with history.
    Raw,
    /// Flat fields, no object–process–relation structure.
    Simple,
}

impl PromptFormat {
    pub const ALL: [PromptFormat; 3] = [PromptFormat::Opm, PromptFormat::Raw, PromptFormat::Simple];
    pub fn name(self) -> &'static str {
        match self {
            PromptFormat::Opm => "opm",
            PromptFormat::Raw => "raw",
            PromptFormat::Simple => "simple",
        }
    }
}

/// The LLM server.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct LlmConfig {
    /// Base URL of an OpenAI-compatible API (ending in `/v1`).
    pub base_url: String,
    /// Model name sent with each request.
    pub model: String,
    /// Name of the environment variable holding the API key (sent as a bearer token); empty:
    /// no key.
    pub api_key_env: String,
    /// TCP connect timeout, s.
    pub connect_timeout_s: f64,
    /// Longest time one HTTP attempt may take, s (the request's deadline cuts it shorter).
    pub request_timeout_s: f64,
    /// Requests in flight at once, over advice, intents and eHMI phrasing.
    pub max_in_flight: usize,
    /// An attempt is not started with less than this left before the deadline, s.
    pub min_attempt_s: f64,
    /// Pause before a retry, s.
    pub retry_backoff_s: f64,
    /// Ask for token log-probabilities (the confidence source).
    pub logprobs: bool,
    /// Confidence given to an answer when the server sent no log-probabilities; below the
    /// core's 0.7 gate by default, so such advice is never applied.
    pub confidence_without_logprobs: f64,
    /// Sampling temperature.
    pub temperature: f64,
    /// The model was fine-tuned on Concord's prompts (the adapter in `deploy/llm/adapters`):
    /// each prompt's system message then names the task in one line
    /// ([`crate::prompt::TUNED_ADVICE_PREFIX`]) instead of instructing a general model, and the
    /// OPM scene comes in the short form it was trained on: about 150 prompt tokens fewer for the
    /// prefix and half the scene's. On by default, as the local server loads the adapter
    /// (`deploy/llm/llm.sh start`); turn it off for any other model.
    pub fine_tuned: bool,
    /// With `fine_tuned`, eHMI texts and replies are phrased by the base model: their requests
    /// set the server's adapter to scale 0 ([`crate::llm::LlmClient::with_adapter_scale`],
    /// llama.cpp's per-request `lora` field). The adapter was trained on advice and intents
    /// only and answers a maneuver name ("accelerate") when asked to phrase. On by default;
    /// turn it off for a server without that field or with an adapter that also phrases.
    pub phrase_with_base_model: bool,
}

impl Default for LlmConfig {
    fn default() -> Self {
        LlmConfig {
            base_url: "http://127.0.0.1:8181/v1".into(),
            model: "SmolLM2-135M-Instruct.Q8_0".into(),
            api_key_env: String::new(),
            connect_timeout_s: 0.5,
            request_timeout_s: 10.0,
            max_in_flight: 1,
            min_attempt_s: 0.2,
            retry_backoff_s: 0.05,
            logprobs: true,
            confidence_without_logprobs: 0.5,
            temperature: 0.0,
            fine_tuned: true,
            phrase_with_base_model: true,
        }
    }
}

/// Advice requests (eq. 16).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdviceConfig {
    /// Scene rendering in the prompt.
    pub prompt_format: PromptFormat,
    /// Scene history in the Raw rendering, s.
    pub raw_history_s: f64,
    /// Objects described in the OPM rendering, the most salient first (eq. 7).
    pub max_objects: usize,
    /// Reasoning steps asked for (0: none; each costs generation time).
    pub reasoning_steps: usize,
    /// Most tokens generated per answer.
    pub max_tokens: u32,
    /// Ask only when advice can matter: a request is not sent when the corrected P_n's
    /// favourite leads the runner-up by at least this margin *and* the situation (favourite,
    /// risky road users, the passenger's stated intent) is the one last asked about. Above 1:
    /// ask every request.
    pub settled_margin: f64,
    /// A newer request of another situation cancels the call in flight. Worth it only with a
    /// server that stops work on a closed connection: llama.cpp's server finishes the task
    /// anyway (it polls the connection once a second), so the next request starts no sooner
    /// and the cancelled answer is lost. Off: the call in flight is answered and the newest
    /// request waits for it.
    pub cancel_superseded: bool,
    /// The answer is begun for the model (an assistant message `{"maneuver": "`, the start of
    /// the only answer the schema allows without reasoning steps) and the rest is constrained
    /// by a grammar in the request's `grammar` field instead of `response_format`: the model
    /// writes the value and `"}` (4 to 5 tokens instead of 10 to 11), the same text as
    /// before. Needs llama.cpp's server (assistant prefill and GBNF grammars); off for others.
    /// Not used with reasoning steps.
    pub prefill_answer: bool,
}

impl Default for AdviceConfig {
    fn default() -> Self {
        AdviceConfig {
            prompt_format: PromptFormat::Opm,
            raw_history_s: 0.4,
            max_objects: 3,
            reasoning_steps: 0,
            max_tokens: 64,
            settled_margin: 0.6,
            cancel_superseded: false,
            prefill_answer: true,
        }
    }
}

/// Intents from language (eq. 8, §4.3).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct IntentConfig {
    /// Below this confidence an intent is weak: flagged and not used.
    pub weak_below: f64,
    /// Longest message accepted from a road user or the passenger, characters after
    /// normalisation; longer text is cut.
    pub max_text_chars: usize,
    /// Time allowed for parsing one message once the server is free, s.
    pub deadline_s: f64,
    /// Longest wait for a free request slot (advice requests may hold it), s.
    pub queue_s: f64,
    /// Dialogue turns kept per party (the car's texts and what the party's messages meant),
    /// shown in the reply prompt; the eHMI check keeps the words of as many of each party's
    /// newest messages.
    pub dialogue_turns: usize,
    /// Road users remembered at once (the oldest are forgotten).
    pub max_parties: usize,
    /// File of the id and stamp of the last message parsed from each party, so that a restarted
    /// sidecar does not parse the last message again; a relative path is taken from the
    /// directory of `log.path`; empty: kept in memory only.
    pub parsed_file: PathBuf,
}

impl Default for IntentConfig {
    fn default() -> Self {
        IntentConfig {
            weak_below: 0.7,
            max_text_chars: 200,
            deadline_s: 3.0,
            queue_s: 10.0,
            dialogue_turns: 4,
            max_parties: 32,
            parsed_file: PathBuf::from("concord-parsed-texts.json"),
        }
    }
}

/// eHMI messages (§5).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct EhmiConfig {
    /// An unchanged decision is announced again after this long, s.
    pub repeat_s: f64,
    /// A road user of unknown intent is asked again after this long, s.
    pub inquiry_interval_s: f64,
    /// Ask the model to phrase each new decision and each reply (the template is shown until
    /// its text arrives and passes the check, and instead of a text that fails it).
    pub llm_phrasing: bool,
    /// Language of the texts: templates, maneuver vocabulary, and the characters the check
    /// accepts ("en": ASCII letters, digits, space and `. , ; : ! ? ' -`).
    pub language: Language,
}

impl Default for EhmiConfig {
    fn default() -> Self {
        EhmiConfig {
            repeat_s: 2.0,
            inquiry_interval_s: 8.0,
            llm_phrasing: true,
            language: Language::En,
        }
    }
}

/// The interaction log (JSONL, one object per LLM call and per verdict).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    /// File; empty disables the log.
    pub path: PathBuf,
    /// Size at which the file is rotated, bytes.
    pub max_bytes: u64,
    /// Rotated files kept (`.1` newest).
    pub keep: usize,
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            path: PathBuf::from("concord-interactions.jsonl"),
            max_bytes: 64 << 20,
            keep: 4,
        }
    }
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct SidecarConfig {
    /// Prefix of every service name.
    pub prefix: String,
    /// Period of the statistics line on stderr, s (0: only on exit).
    pub print_period_s: f64,
    pub llm: LlmConfig,
    pub advice: AdviceConfig,
    pub intent: IntentConfig,
    pub ehmi: EhmiConfig,
    pub log: LogConfig,
}

impl Default for SidecarConfig {
    fn default() -> Self {
        SidecarConfig {
            prefix: concord_ipc::services::DEFAULT_PREFIX.into(),
            print_period_s: 10.0,
            llm: LlmConfig::default(),
            advice: AdviceConfig::default(),
            intent: IntentConfig::default(),
            ehmi: EhmiConfig::default(),
            log: LogConfig::default(),
        }
    }
}

impl SidecarConfig {
    /// Where the ledger of parsed messages is kept (`intent.parsed_file` resolved against the
    /// directory of `log.path`), or `None` for memory only.
    pub fn parsed_file(&self) -> Option<PathBuf> {
        let f = &self.intent.parsed_file;
        if f.as_os_str().is_empty() {
            return None;
        }
        let dir = self.log.path.parent().unwrap_or(std::path::Path::new(""));
        Some(dir.join(f))
    }

    /// Reads `path` over the defaults.
    pub fn load(path: &std::path::Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("reading {}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Parses TOML (missing keys take their defaults) and validates it.
    pub fn parse(text: &str) -> Result<Self, String> {
        let cfg: SidecarConfig = toml::from_str(text).map_err(|e| e.to_string())?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Checks ranges.
    pub fn validate(&self) -> Result<(), String> {
        let l = &self.llm;
        // Every period becomes a `Duration`: bounded to an hour so none can overflow.
        let positive = |v: f64| v > 0.0 && v <= 3600.0;
        if !l.base_url.starts_with("http://") && !l.base_url.starts_with("https://") {
            return Err(format!(
                "llm.base_url = {:?}: expected http(s)://…",
                l.base_url
            ));
        }
        if !(positive(l.connect_timeout_s) && positive(l.request_timeout_s)) {
            return Err(
                "llm.connect_timeout_s and llm.request_timeout_s must be in (0, 3600]".into(),
            );
        }
        if l.max_in_flight == 0 {
            return Err("llm.max_in_flight must be >= 1".into());
        }
        let non_negative = |v: f64| (0.0..=3600.0).contains(&v);
        if !(non_negative(l.min_attempt_s) && non_negative(l.retry_backoff_s)) {
            return Err("llm.min_attempt_s and llm.retry_backoff_s must be in [0, 3600]".into());
        }
        if !(0.0..=1.0).contains(&l.confidence_without_logprobs) {
            return Err("llm.confidence_without_logprobs must be in [0, 1]".into());
        }
        if !(l.temperature.is_finite() && (0.0..=2.0).contains(&l.temperature)) {
            return Err("llm.temperature must be in [0, 2]".into());
        }
        if !(self.advice.raw_history_s.is_finite()
            && (0.0..=5.0).contains(&self.advice.raw_history_s))
        {
            return Err("advice.raw_history_s must be in [0, 5]".into());
        }
        if self.advice.max_objects == 0 || self.advice.max_objects > concord_ipc::wire::WIRE_OBJECTS
        {
            return Err(format!(
                "advice.max_objects must be in 1..={}",
                concord_ipc::wire::WIRE_OBJECTS
            ));
        }
        if !(self.advice.settled_margin.is_finite() && self.advice.settled_margin >= 0.0) {
            return Err(format!(
                "advice.settled_margin = {}: expected a finite number >= 0",
                self.advice.settled_margin
            ));
        }
        if self.advice.reasoning_steps > 8 || self.advice.max_tokens < 16 {
            return Err("advice.reasoning_steps must be <= 8 and advice.max_tokens >= 16".into());
        }
        let i = &self.intent;
        if !(0.0..=1.0).contains(&i.weak_below)
            || i.max_text_chars == 0
            || !positive(i.deadline_s)
            || !positive(i.queue_s)
        {
            return Err(
                "intent.weak_below in [0, 1], intent.max_text_chars >= 1, intent.deadline_s and queue_s in (0, 3600]"
                    .into(),
            );
        }
        if i.max_parties == 0 {
            return Err("intent.max_parties must be >= 1".into());
        }
        if !(positive(self.ehmi.repeat_s) && positive(self.ehmi.inquiry_interval_s)) {
            return Err("ehmi.repeat_s and ehmi.inquiry_interval_s must be in (0, 3600]".into());
        }
        if self.log.max_bytes < 4096 {
            return Err("log.max_bytes must be >= 4096".into());
        }
        if !non_negative(self.print_period_s) {
            return Err("print_period_s must be in [0, 3600]".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_is_the_defaults() {
        let text = include_str!("../../deploy/sidecar.toml");
        assert_eq!(
            SidecarConfig::parse(text).unwrap(),
            SidecarConfig::default()
        );
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        assert!(SidecarConfig::parse("[llm]\nbase_urll = \"x\"")
            .unwrap_err()
            .contains("base_urll"));
        assert!(SidecarConfig::parse("[llm]\nbase_url = \"ftp://x\"").is_err());
        assert!(SidecarConfig::parse("[advice]\nprompt_format = \"yaml\"").is_err());
        let c = SidecarConfig::parse("[advice]\nprompt_format = \"raw\"").unwrap();
        assert_eq!(c.advice.prompt_format, PromptFormat::Raw);
        assert_eq!(c.llm, LlmConfig::default());
        assert!(SidecarConfig::parse("[ehmi]\nlanguage = \"klingon\"").is_err());
    }

    #[test]
    fn the_parsed_file_sits_next_to_the_log_unless_absolute_or_empty() {
        let mut c = SidecarConfig::default();
        c.log.path = PathBuf::from("/var/log/concord/interactions.jsonl");
        assert_eq!(
            c.parsed_file(),
            Some(PathBuf::from("/var/log/concord/concord-parsed-texts.json"))
        );
        c.intent.parsed_file = PathBuf::from("/run/concord/parsed.json");
        assert_eq!(
            c.parsed_file(),
            Some(PathBuf::from("/run/concord/parsed.json"))
        );
        c.intent.parsed_file = PathBuf::new();
        assert_eq!(c.parsed_file(), None);
        assert_eq!(
            SidecarConfig::default().parsed_file(),
            Some(PathBuf::from("concord-parsed-texts.json"))
        );
    }
}
