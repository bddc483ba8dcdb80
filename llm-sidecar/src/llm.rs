//! Client of an OpenAI-compatible `/v1/chat/completions` server (llama.cpp's server, Ollama,
//! vLLM): JSON-schema-constrained answers with token log-probabilities, connect and request
//! timeouts, and retries only while the caller's deadline leaves room for another attempt.

use std::time::{Duration, Instant};

use concord_ipc::wire::AdviceFailure;
use serde_json::{json, Value};

use crate::config::{AdviceConfig, LlmConfig};
use crate::prompt::ChatMessage;
use crate::reply::{Answer, ReplyError};
use crate::schema;

/// Why a call gave no answer.
#[derive(Debug, Clone, PartialEq)]
pub enum LlmError {
    /// The deadline passed (or left no room for an attempt).
    Timeout,
    /// Connecting failed, or the connection closed before a whole reply.
    Connection(String),
    /// An HTTP error status, with the start of its body.
    HttpStatus(u16, String),
    Reply(ReplyError),
}

impl LlmError {
    /// The wire code reported to the core.
    pub fn failure(&self) -> AdviceFailure {
        match self {
            LlmError::Timeout => AdviceFailure::Timeout,
            LlmError::Connection(_) => AdviceFailure::Connection,
            LlmError::HttpStatus(..) => AdviceFailure::HttpStatus,
            LlmError::Reply(ReplyError::Malformed(_)) => AdviceFailure::Malformed,
            LlmError::Reply(ReplyError::SchemaViolation(_)) => AdviceFailure::SchemaViolation,
        }
    }
    /// Worth another attempt: the server may answer next time.
    fn retryable(&self) -> bool {
        match self {
            LlmError::Connection(_) => true,
            LlmError::HttpStatus(s, _) => *s == 429 || *s >= 500,
            _ => false,
        }
    }
}

impl std::fmt::Display for LlmError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LlmError::Timeout => f.write_str("no answer before the deadline"),
            LlmError::Connection(e) => write!(f, "connection: {e}"),
            LlmError::HttpStatus(s, body) => write!(f, "HTTP {s}: {body}"),
            LlmError::Reply(e) => write!(f, "{e}"),
        }
    }
}

/// One answered call.
#[derive(Debug, Clone)]
pub struct Reply {
    pub answer: Answer,
    /// From sending the first attempt to the whole reply.
    pub latency: Duration,
    pub attempts: u32,
}

/// The client. Cheap to clone (the connection pool is shared).
#[derive(Clone)]
pub struct LlmClient {
    http: reqwest::Client,
    url: String,
    cfg: LlmConfig,
    api_key: Option<String>,
}

impl LlmClient {
    /// A client for `cfg`; the API key is read once from `cfg.api_key_env`.
    pub fn new(cfg: &LlmConfig) -> Result<Self, String> {
        let http = reqwest::Client::builder()
            .connect_timeout(Duration::from_secs_f64(cfg.connect_timeout_s))
            .timeout(Duration::from_secs_f64(cfg.request_timeout_s))
            .pool_max_idle_per_host(cfg.max_in_flight)
            .build()
            .map_err(|e| format!("HTTP client: {e}"))?;
        let api_key = if cfg.api_key_env.is_empty() {
            None
        } else {
            Some(std::env::var(&cfg.api_key_env).map_err(|_| {
                format!(
                    "llm.api_key_env names {:?}, which is not set",
                    cfg.api_key_env
                )
            })?)
        };
        Ok(LlmClient {
            http,
            url: format!("{}/chat/completions", cfg.base_url.trim_end_matches('/')),
            cfg: cfg.clone(),
            api_key,
        })
    }

    pub fn config(&self) -> &LlmConfig {
        &self.cfg
    }

    /// The request body for `messages` with the answer constrained by `schema`.
    pub fn body(
        &self,
        messages: &[ChatMessage],
        name: &str,
        schema: &Value,
        max_tokens: u32,
    ) -> Value {
        let mut b = json!({
            "model": self.cfg.model,
            "messages": messages,
            "temperature": self.cfg.temperature,
            "max_tokens": max_tokens,
            "stream": false,
            "response_format": {"type": "json_schema",
                                "json_schema": {"name": name, "strict": true, "schema": schema}},
        });
        if self.cfg.logprobs {
            b["logprobs"] = true.into();
            b["top_logprobs"] = 20.into();
        }
        b
    }

    /// The request body of an advice call (eq. 16) for `messages`: the answer constrained by
    /// the advice schema, or with `advice.prefill_answer` (and no reasoning steps) begun as
    /// [`schema::ADVICE_ANSWER_START`] and finished under [`schema::advice_rest_grammar`].
    pub fn advice_body(&self, messages: &[ChatMessage], advice: &AdviceConfig) -> Value {
        let steps = advice.reasoning_steps;
        if !advice.prefill_answer || steps > 0 {
            let schema = schema::advice_schema(steps);
            return self.body(messages, "advice", &schema, advice.max_tokens);
        }
        let mut b = self.body(messages, "advice", &Value::Null, advice.max_tokens);
        let o = b.as_object_mut().expect("a body is an object");
        o.remove("response_format");
        o.insert("grammar".into(), schema::advice_rest_grammar().into());
        o["messages"]
            .as_array_mut()
            .expect("messages are an array")
            .push(json!({"role": "assistant", "content": schema::ADVICE_ANSWER_START}));
        b
    }

    /// `body` asking llama.cpp's server to run its first LoRA adapter at `scale` (its per-request
    /// `lora` field): 0 is the base model, 1 the adapter as loaded. Other servers reject or
    /// ignore the field.
    pub fn with_adapter_scale(mut body: Value, scale: f64) -> Value {
        body["lora"] = json!([{"id": 0, "scale": scale}]);
        body
    }

    /// Sends `body`, retrying connection failures and 429/5xx while `deadline` leaves at least
    /// `min_attempt_s` for another attempt; each attempt is cut at the deadline.
    pub async fn call(&self, body: &Value, deadline: Instant) -> Result<Reply, LlmError> {
        let started = Instant::now();
        let min_attempt = Duration::from_secs_f64(self.cfg.min_attempt_s);
        let mut attempts = 0;
        let mut last = LlmError::Timeout;
        loop {
            let now = Instant::now();
            let left = deadline.saturating_duration_since(now);
            if left < min_attempt.max(Duration::from_millis(1)) {
                return Err(last);
            }
            attempts += 1;
            match tokio::time::timeout(left, self.attempt(body)).await {
                Err(_) => return Err(LlmError::Timeout),
                Ok(Ok(answer)) => {
                    return Ok(Reply {
                        answer,
                        latency: started.elapsed(),
                        attempts,
                    })
                }
                Ok(Err(e)) if e.retryable() => last = e,
                Ok(Err(e)) => return Err(e),
            }
            let pause = Duration::from_secs_f64(self.cfg.retry_backoff_s);
            if deadline.saturating_duration_since(Instant::now()) < pause + min_attempt {
                return Err(last);
            }
            tokio::time::sleep(pause).await;
        }
    }

    /// One attempt. A body whose last message is the assistant's holds the answer's start
    /// (prefill): the answer is read as that start and the continuation.
    async fn attempt(&self, body: &Value) -> Result<Answer, LlmError> {
        let mut req = self.http.post(&self.url).json(body);
        if let Some(key) = &self.api_key {
            req = req.bearer_auth(key);
        }
        let resp = req.send().await.map_err(classify)?;
        let status = resp.status();
        let bytes = resp.bytes().await.map_err(classify)?;
        if !status.is_success() {
            let text = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).into_owned();
            return Err(LlmError::HttpStatus(status.as_u16(), text));
        }
        let messages = body["messages"].as_array();
        let prefill = match messages.and_then(|m| m.last()) {
            Some(m) if m["role"] == "assistant" => m["content"].as_str().unwrap_or(""),
            _ => "",
        };
        Answer::parse_prefilled(&bytes, prefill).map_err(LlmError::Reply)
    }
}

fn classify(e: reqwest::Error) -> LlmError {
    if e.is_timeout() {
        LlmError::Timeout
    } else {
        LlmError::Connection(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use concord_core::Maneuver;

    #[test]
    fn a_prefilled_advice_body_begins_the_answer_and_the_grammar_finishes_it() {
        let client = LlmClient::new(&LlmConfig::default()).unwrap();
        let messages = [ChatMessage::system("Concord advice.")];
        let mut advice = AdviceConfig::default();
        let b = client.advice_body(&messages, &advice);
        let last = b["messages"].as_array().unwrap().last().unwrap();
        assert_eq!(last["role"], "assistant");
        assert_eq!(last["content"], schema::ADVICE_ANSWER_START);
        assert!(b.get("response_format").is_none());
        let grammar = b["grammar"].as_str().unwrap();
        for m in Maneuver::ALL {
            assert!(grammar.contains(&format!("\"{}\"", m.name())), "{grammar}");
            assert!(schema::advice_answer(m).starts_with(schema::ADVICE_ANSWER_START));
        }
        // Reasoning steps, or the option off: the schema alone.
        advice.reasoning_steps = 2;
        let with_steps = client.advice_body(&messages, &advice);
        advice.reasoning_steps = 0;
        advice.prefill_answer = false;
        for b in [with_steps, client.advice_body(&messages, &advice)] {
            assert!(b.get("grammar").is_none());
            assert_eq!(b["response_format"]["json_schema"]["name"], "advice");
            assert_eq!(b["messages"].as_array().unwrap().len(), 1);
        }
    }
}
