//! Replies of an OpenAI-compatible `/v1/chat/completions` server: the JSON answer that the
//! request's schema constrains, and the confidence of each enumerated field, read from the
//! token log-probabilities.
//!
//! **Confidence rule.** The confidence of an enumerated field (the maneuver A_final, an intent
//! dimension) is the probability the model gives to its value *among the values the schema
//! allows*. Servers report log-probabilities before the schema's grammar is applied (llama.cpp
//! does), so at each token that spells the value the chosen token's probability is divided by
//! the total probability of the alternatives in `top_logprobs` that would still spell an
//! allowed value; allowed values with no such alternative in the list are each counted at the
//! list's smallest probability (an upper bound of what the list left out), which keeps the rule
//! on the conservative side. The product over the value's tokens is the confidence. Without
//! `top_logprobs` it is the unnormalised `exp(Σ logprob)`, lower still. A self-reported number
//! is never asked for or trusted. When the server returns no log-probabilities, or they do not
//! spell the answer, the caller's documented default applies (`confidence_without_logprobs`,
//! below the 0.7 gate by default).
//!
//! The tokens may spell more than the content (llama.cpp drops a Markdown fence around the
//! JSON from the content but not from the tokens): the content is located inside them.

use std::ops::Range;

use serde::Deserialize;

/// Why a reply could not be used.
#[derive(Debug, Clone, PartialEq)]
pub enum ReplyError {
    /// Not the JSON of a chat completion, no content, or an answer that is not JSON.
    Malformed(String),
    /// JSON, but it breaks the schema: an unknown enum value, a missing or extra field.
    SchemaViolation(String),
}

impl std::fmt::Display for ReplyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReplyError::Malformed(m) => write!(f, "malformed reply: {m}"),
            ReplyError::SchemaViolation(m) => write!(f, "answer breaks the schema: {m}"),
        }
    }
}

#[derive(Deserialize)]
struct Completion {
    choices: Vec<Choice>,
    #[serde(default)]
    usage: Option<Usage>,
}

#[derive(Deserialize)]
struct Choice {
    message: Message,
    #[serde(default)]
    logprobs: Option<Logprobs>,
    #[serde(default)]
    finish_reason: Option<String>,
}

#[derive(Deserialize)]
struct Message {
    #[serde(default)]
    content: Option<String>,
}

#[derive(Deserialize)]
struct Logprobs {
    #[serde(default)]
    content: Option<Vec<TokenLogprob>>,
}

#[derive(Deserialize)]
struct TokenLogprob {
    token: String,
    logprob: f64,
    #[serde(default)]
    bytes: Option<Vec<u8>>,
    #[serde(default)]
    top_logprobs: Vec<TopLogprob>,
}

#[derive(Deserialize)]
struct TopLogprob {
    token: String,
    logprob: f64,
    #[serde(default)]
    bytes: Option<Vec<u8>>,
}

/// One generated token placed on the content, with the alternatives the server listed.
#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    /// Offset of its first byte in the content; negative, or past the end, for bytes the
    /// content dropped (a fence).
    pub start: isize,
    pub bytes: Vec<u8>,
    pub logprob: f64,
    pub alternatives: Vec<(Vec<u8>, f64)>,
}

/// Token counts the server reported.
#[derive(Debug, Deserialize, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Usage {
    #[serde(default)]
    pub prompt_tokens: u32,
    #[serde(default)]
    pub completion_tokens: u32,
    /// Prompt tokens the server took from its cache, where it says.
    #[serde(default)]
    pub prompt_tokens_details: Option<PromptTokensDetails>,
}

/// Cache use of the prompt, where the server reports it.
#[derive(Debug, Deserialize, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct PromptTokensDetails {
    #[serde(default)]
    pub cached_tokens: u32,
}

/// The answer text of a completion with the byte span and log-probability of each token.
#[derive(Debug, Clone, PartialEq)]
pub struct Answer {
    /// The JSON text the model produced.
    pub content: String,
    /// The generated tokens placed on `content`; empty when the server sent none or they do not
    /// contain `content`.
    pub tokens: Vec<Token>,
    pub usage: Usage,
}

impl Answer {
    /// Parses a completion body. The answer must be a JSON object.
    pub fn parse(body: &[u8]) -> Result<Answer, ReplyError> {
        Self::parse_prefilled(body, "")
    }

    /// Parses a completion body of a request that began the answer with `prefill` (an
    /// assistant message): the answer is `prefill` and the continuation, whether the server's
    /// content repeats `prefill` (llama.cpp's does) or not; the tokens spell the continuation.
    pub fn parse_prefilled(body: &[u8], prefill: &str) -> Result<Answer, ReplyError> {
        let c: Completion = serde_json::from_slice(body)
            .map_err(|e| ReplyError::Malformed(format!("not a chat completion: {e}")))?;
        let choice = c
            .choices
            .into_iter()
            .next()
            .ok_or_else(|| ReplyError::Malformed("no choices".into()))?;
        let mut content = choice
            .message
            .content
            .ok_or_else(|| ReplyError::Malformed("no message content".into()))?;
        if !content.starts_with(prefill) {
            content.insert_str(0, prefill);
        }
        match choice.finish_reason.as_deref() {
            None | Some("stop") => {}
            Some(other) => {
                return Err(ReplyError::Malformed(format!(
                    "the answer ended by {other:?}, not \"stop\""
                )))
            }
        }
        let value: serde_json::Value = serde_json::from_str(&content)
            .map_err(|e| ReplyError::Malformed(format!("answer is not JSON: {e}")))?;
        if !value.is_object() {
            return Err(ReplyError::SchemaViolation(
                "answer is not a JSON object".into(),
            ));
        }
        let tokens = choice
            .logprobs
            .and_then(|l| l.content)
            .map(|t| spans(&t, &content, prefill.as_bytes()))
            .unwrap_or_default();
        Ok(Answer {
            content,
            tokens,
            usage: c.usage.unwrap_or_default(),
        })
    }

    /// The answer as `T`; a shape `T` rejects is a schema violation.
    pub fn decode<T: serde::de::DeserializeOwned>(&self) -> Result<T, ReplyError> {
        serde_json::from_str(&self.content).map_err(|e| ReplyError::SchemaViolation(e.to_string()))
    }

    /// Confidence of the string value of top-level `key`, one of `allowed`, by the rule of this
    /// module; `None` without usable log-probabilities.
    pub fn confidence(&self, key: &str, allowed: &[&str]) -> Option<f64> {
        if self.tokens.is_empty() {
            return None;
        }
        let span = string_value_span(&self.content, key)?;
        let value = &self.content.as_bytes()[span.clone()];
        let (s, e) = (span.start as isize, span.end as isize);
        let mut log_p = 0.0;
        let mut any = false;
        for t in &self.tokens {
            let (t0, t1) = (t.start, t.start + t.bytes.len() as isize);
            if t1 <= s || t0 >= e.max(s + 1) {
                continue;
            }
            any = true;
            // Bytes of the token before the value, and of the value before the token.
            let lead = (s - t0).max(0) as usize;
            let done = &value[..(t0 - s).max(0) as usize];
            log_p += t.logprob - log_allowed_mass(t, lead, done, allowed);
        }
        let p = log_p.exp();
        (any && p.is_finite()).then_some(p.clamp(0.0, 1.0))
    }
}

/// Log of the probability, at token `t`, of the tokens that keep the value an allowed one (the
/// chosen one included), plus the conservative bound for allowed values the list misses; 0 when
/// the server listed no alternatives.
fn log_allowed_mass(t: &Token, lead: usize, done: &[u8], allowed: &[&str]) -> f64 {
    if t.alternatives.is_empty() {
        return 0.0;
    }
    // The allowed values a token would still spell, given the same bytes before the value.
    let spelled = |bytes: &[u8]| -> Vec<usize> {
        if bytes.len() <= lead || bytes[..lead] != t.bytes[..lead] {
            return Vec::new();
        }
        let mut text = done.to_vec();
        text.extend_from_slice(&bytes[lead..]);
        allowed
            .iter()
            .enumerate()
            .filter(|(_, v)| {
                let mut full = v.as_bytes().to_vec();
                full.push(b'"');
                full.starts_with(&text) || text.starts_with(&full)
            })
            .map(|(i, _)| i)
            .collect()
    };
    let mut mass = t.logprob.exp();
    let mut covered = vec![false; allowed.len()];
    for i in spelled(&t.bytes) {
        covered[i] = true;
    }
    for (b, lp) in &t.alternatives {
        let values = if *b == t.bytes {
            Vec::new()
        } else {
            spelled(b)
        };
        if !values.is_empty() {
            mass += lp.exp();
            for i in values {
                covered[i] = true;
            }
        }
    }
    let open = allowed
        .iter()
        .enumerate()
        .filter(|(i, v)| !covered[*i] && v.as_bytes().starts_with(done))
        .count();
    let floor = t
        .alternatives
        .iter()
        .map(|(_, lp)| lp.exp())
        .fold(f64::INFINITY, f64::min);
    if floor.is_finite() {
        mass += open as f64 * floor;
    }
    mass.ln()
}

/// The tokens placed on `content`, which must occur in `prefill` followed by their
/// concatenation; empty otherwise.
fn spans(tokens: &[TokenLogprob], content: &str, prefill: &[u8]) -> Vec<Token> {
    if tokens.iter().any(|t| t.logprob.is_nan() || t.logprob > 0.0) {
        return Vec::new();
    }
    let bytes_of = |t: &TokenLogprob| {
        t.bytes
            .clone()
            .unwrap_or_else(|| t.token.as_bytes().to_vec())
    };
    let text: Vec<u8> = prefill
        .iter()
        .copied()
        .chain(tokens.iter().flat_map(bytes_of))
        .collect();
    let c = content.as_bytes();
    if c.is_empty() || text.len() < c.len() {
        return Vec::new();
    }
    let Some(offset) = text.windows(c.len()).position(|w| w == c) else {
        return Vec::new();
    };
    let mut at = prefill.len() as isize - offset as isize;
    tokens
        .iter()
        .map(|t| {
            let token = Token {
                start: at,
                bytes: bytes_of(t),
                logprob: t.logprob,
                alternatives: t
                    .top_logprobs
                    .iter()
                    .filter(|a| a.logprob.is_finite())
                    .map(|a| {
                        let b = a
                            .bytes
                            .clone()
                            .unwrap_or_else(|| a.token.as_bytes().to_vec());
                        (b, a.logprob)
                    })
                    .collect(),
            };
            at += token.bytes.len() as isize;
            token
        })
        .collect()
}

/// Byte range of the characters of the string value of `key` in the top-level object of
/// `json` (without the quotes). `json` must already be valid JSON.
pub fn string_value_span(json: &str, key: &str) -> Option<Range<usize>> {
    let b = json.as_bytes();
    let mut depth = 0usize;
    let mut i = 0;
    let mut expect_key = false;
    while i < b.len() {
        match b[i] {
            b'{' => {
                depth += 1;
                expect_key = depth == 1;
                i += 1;
            }
            b'[' => {
                depth += 1;
                i += 1;
            }
            b'}' | b']' => {
                depth = depth.checked_sub(1)?;
                i += 1;
            }
            b',' => {
                expect_key = depth == 1;
                i += 1;
            }
            b'"' => {
                let r = string_at(b, i)?;
                i = r.end + 1;
                if depth == 1 && expect_key {
                    expect_key = false;
                    let name: String = serde_json::from_str(&json[r.start - 1..r.end + 1]).ok()?;
                    if name == key {
                        while i < b.len() && (b[i].is_ascii_whitespace() || b[i] == b':') {
                            i += 1;
                        }
                        return (b.get(i) == Some(&b'"')).then(|| string_at(b, i)).flatten();
                    }
                }
            }
            _ => i += 1,
        }
    }
    None
}

/// Range of the characters of the string whose opening quote is at `open`.
fn string_at(b: &[u8], open: usize) -> Option<Range<usize>> {
    let mut i = open + 1;
    while i < b.len() {
        match b[i] {
            b'\\' => i += 2,
            b'"' => return Some(open + 1..i),
            _ => i += 1,
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAMES: [&str; 5] = [
        "accelerate",
        "decelerate",
        "keep_speed",
        "turn_left",
        "turn_right",
    ];

    /// A generated token: (token, logprob, [(alternative, logprob)]).
    type Generated<'a> = (&'a str, f64, &'a [(&'a str, f64)]);

    fn body_with_alternatives(content: &str, tokens: &[Generated]) -> Vec<u8> {
        let lp: Vec<_> = tokens
            .iter()
            .map(|(t, l, alts)| {
                let top: Vec<_> = alts
                    .iter()
                    .map(|(a, l)| serde_json::json!({"token": a, "logprob": l}))
                    .collect();
                serde_json::json!({"token": t, "logprob": l, "top_logprobs": top})
            })
            .collect();
        serde_json::to_vec(&serde_json::json!({
            "choices": [{"message": {"content": content}, "finish_reason": "stop",
                         "logprobs": {"content": lp}}]
        }))
        .unwrap()
    }

    #[test]
    fn probabilities_are_renormalised_over_the_allowed_values() {
        // A fence the content dropped, raw probabilities with forbidden alternatives ("The",
        // "1"), and the left/right choice made at the second token of the value.
        let (l1, l2) = (0.3f64.ln(), 0.6f64.ln());
        let tokens: [Generated; 7] = [
            ("```json\n", -8.0, &[]),
            ("{\"maneuver\": \"", -6.0, &[]),
            (
                "turn",
                l1,
                &[
                    ("The", 0.4f64.ln()),
                    ("turn", l1),
                    ("accel", 0.1f64.ln()),
                    ("1", 0.1f64.ln()),
                ],
            ),
            ("_", -0.01, &[("_", -0.01)]),
            (
                "left",
                l2,
                &[("left", l2), ("right", 0.2f64.ln()), ("up", 0.15f64.ln())],
            ),
            ("\"}", -0.5, &[]),
            ("\n```", -0.1, &[]),
        ];
        let a = Answer::parse(&body_with_alternatives(
            r#"{"maneuver": "turn_left"}"#,
            &tokens,
        ))
        .unwrap();
        // Step 1: turn 0.3 against turn + accel (0.4) plus the bound for decelerate and
        // keep_speed (2 × 0.1, the list's smallest); step 2: "_" alone (only "_" continues
        // "turn"); step 3: left 0.6 against left + right (0.8).
        let expected = 0.3 / (0.4 + 0.2) * 1.0 * (0.6 / 0.8);
        let c = a.confidence("maneuver", &NAMES).unwrap();
        assert!((c - expected).abs() < 1e-9, "{c} vs {expected}");
        assert!(c > 0.3 * 0.6, "renormalising raises the raw product");
    }

    fn body(content: &str, tokens: &[(&str, f64)]) -> Vec<u8> {
        let lp: Vec<_> = tokens
            .iter()
            .map(|(t, l)| serde_json::json!({"token": t, "logprob": l, "top_logprobs": []}))
            .collect();
        serde_json::to_vec(&serde_json::json!({
            "choices": [{"message": {"role": "assistant", "content": content},
                         "finish_reason": "stop", "logprobs": {"content": lp}}],
            "usage": {"prompt_tokens": 120, "completion_tokens": tokens.len()}
        }))
        .unwrap()
    }

    #[test]
    fn confidence_is_the_probability_of_the_value_tokens() {
        let tokens = [
            ("{\"", 0.0),
            ("maneuver", 0.0),
            ("\":\"", 0.0),
            ("turn", -0.2),
            ("_left", -0.1),
            ("\"}", 0.0),
        ];
        let a = Answer::parse(&body(r#"{"maneuver":"turn_left"}"#, &tokens)).unwrap();
        let c = a.confidence("maneuver", &NAMES).unwrap();
        assert!((c - (-0.3f64).exp()).abs() < 1e-12, "{c}");
        assert_eq!(a.usage.prompt_tokens, 120);
        assert_eq!(a.confidence("reason", &NAMES), None);
    }

    #[test]
    fn a_token_that_opens_the_value_counts() {
        let tokens = [
            ("{\"maneuver\": \"", -0.0),
            ("dec", -0.5),
            ("elerate\"}", -0.01),
        ];
        let a = Answer::parse(&body(r#"{"maneuver": "decelerate"}"#, &tokens)).unwrap();
        let c = a.confidence("maneuver", &NAMES).unwrap();
        assert!((c - (-0.51f64).exp()).abs() < 1e-12);
    }

    #[test]
    fn a_prefilled_answer_is_read_whether_or_not_the_content_repeats_the_start() {
        let start = "{\"maneuver\": \"";
        let tokens = [("turn", -0.2), ("_", 0.0), ("left", -0.1), ("\"}", 0.0)];
        // llama.cpp's content repeats the prefill; another server's may be the rest only.
        for content in [r#"{"maneuver": "turn_left"}"#, r#"turn_left"}"#] {
            let a = Answer::parse_prefilled(&body(content, &tokens), start).unwrap();
            assert_eq!(a.content, r#"{"maneuver": "turn_left"}"#);
            let c = a.confidence("maneuver", &NAMES).unwrap();
            assert!((c - (-0.3f64).exp()).abs() < 1e-12, "{content}: {c}");
        }
    }

    #[test]
    fn tokens_that_do_not_spell_the_answer_give_no_confidence() {
        let a = Answer::parse(&body(r#"{"maneuver":"accelerate"}"#, &[("x", -0.1)])).unwrap();
        assert_eq!(a.confidence("maneuver", &NAMES), None);
    }

    #[test]
    fn nested_keys_and_escapes_do_not_confuse_the_locator() {
        let j = r#"{"note": {"maneuver": "x"}, "q": "a\"maneuver\"", "maneuver" : "keep_speed"}"#;
        let r = string_value_span(j, "maneuver").unwrap();
        assert_eq!(&j[r], "keep_speed");
    }

    #[test]
    fn truncated_and_non_json_answers_are_malformed() {
        let mut cut: serde_json::Value =
            serde_json::from_slice(&body(r#"{"maneuver":"acc"#, &[])).unwrap();
        assert!(matches!(
            Answer::parse(&serde_json::to_vec(&cut).unwrap()),
            Err(ReplyError::Malformed(_))
        ));
        cut["choices"][0]["finish_reason"] = "length".into();
        cut["choices"][0]["message"]["content"] = r#"{"maneuver":"accelerate"}"#.into();
        assert!(matches!(
            Answer::parse(&serde_json::to_vec(&cut).unwrap()),
            Err(ReplyError::Malformed(_))
        ));
        assert!(matches!(
            Answer::parse(b"<html>502</html>"),
            Err(ReplyError::Malformed(_))
        ));
        assert!(matches!(
            Answer::parse(&body("[1]", &[])),
            Err(ReplyError::SchemaViolation(_))
        ));
    }
}
