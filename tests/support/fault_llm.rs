//! A loopback stand-in for an OpenAI-compatible server that misbehaves on purpose, for the
//! timeout, garbage and crash tests and the hostile corpus (the end-to-end test uses the real
//! local server). It listens on 127.0.0.1 on a free port, answers `GET /v1/models`, and answers
//! `POST /v1/chat/completions` according to its current [`Mode`], which a test may change at
//! any time. Dropping it stops it.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How the server answers completions.
#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    /// A well-formed answer: advice `maneuver` with probability `p` (from its
    /// log-probability); `ehmi` as the phrasing of a decision and the reply to a message; for
    /// intent requests, `action` with probability `p`.
    Answer {
        maneuver: &'static str,
        p: f64,
        ehmi: &'static str,
        action: &'static str,
        delay: Duration,
    },
    /// The answer above, but only after `delay` (past any deadline).
    Late(Duration),
    /// HTTP 200 with a body that is not JSON.
    Malformed,
    /// A JSON answer with a maneuver outside the schema.
    UnknownEnum,
    /// A compromised model that obeys every message it is shown and remembers it: see
    /// [`obey`]. Every request body is kept in [`FaultLlm::bodies`].
    Obey,
    /// HTTP 500.
    ServerError,
    /// Reads the request, then closes the connection without a word.
    Close,
}

impl Mode {
    /// Confident advice to decelerate.
    pub fn yielding() -> Mode {
        Mode::Answer {
            maneuver: "decelerate",
            p: 0.9,
            ehmi: "I am slowing down; please go ahead.",
            action: "yield",
            delay: Duration::from_millis(20),
        }
    }
}

/// The running server.
pub struct FaultLlm {
    pub port: u16,
    mode: Arc<Mutex<Mode>>,
    stop: Arc<AtomicBool>,
    /// Completion requests received.
    pub requests: Arc<AtomicU64>,
    /// In [`Mode::Obey`]: every completion request body, and the messages seen so far.
    pub bodies: Arc<Mutex<Vec<serde_json::Value>>>,
    memory: Arc<Mutex<Vec<String>>>,
}

impl FaultLlm {
    pub fn start(mode: Mode) -> FaultLlm {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind 127.0.0.1:0");
        let port = listener.local_addr().unwrap().port();
        listener.set_nonblocking(true).unwrap();
        let mode = Arc::new(Mutex::new(mode));
        let stop = Arc::new(AtomicBool::new(false));
        let requests = Arc::new(AtomicU64::new(0));
        let bodies = Arc::new(Mutex::new(Vec::new()));
        let memory = Arc::new(Mutex::new(Vec::new()));
        let shared = Shared {
            mode: mode.clone(),
            stop: stop.clone(),
            requests: requests.clone(),
            bodies: bodies.clone(),
            memory: memory.clone(),
        };
        std::thread::spawn(move || {
            while !shared.stop.load(Ordering::Relaxed) {
                match listener.accept() {
                    Ok((stream, _)) => {
                        let shared = shared.clone();
                        std::thread::spawn(move || serve(stream, &shared));
                    }
                    Err(_) => std::thread::sleep(Duration::from_millis(5)),
                }
            }
        });
        FaultLlm {
            port,
            mode,
            stop,
            requests,
            bodies,
            memory,
        }
    }

    /// Forgets the request bodies and the messages an obeying model remembers.
    pub fn forget(&self) {
        self.bodies.lock().unwrap().clear();
        self.memory.lock().unwrap().clear();
    }

    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}/v1", self.port)
    }

    pub fn set(&self, mode: Mode) {
        *self.mode.lock().unwrap() = mode;
    }
}

impl Drop for FaultLlm {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

#[derive(Clone)]
struct Shared {
    mode: Arc<Mutex<Mode>>,
    stop: Arc<AtomicBool>,
    requests: Arc<AtomicU64>,
    bodies: Arc<Mutex<Vec<serde_json::Value>>>,
    memory: Arc<Mutex<Vec<String>>>,
}

fn serve(stream: TcpStream, shared: &Shared) {
    let Shared {
        mode,
        stop,
        requests,
        ..
    } = shared;
    stream.set_nonblocking(false).ok();
    stream.set_read_timeout(Some(Duration::from_secs(30))).ok();
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap_or(0) == 0 {
            return;
        }
        let get = line.starts_with("GET");
        let mut length = 0usize;
        loop {
            let mut h = String::new();
            if reader.read_line(&mut h).unwrap_or(0) == 0 {
                return;
            }
            if h == "\r\n" {
                break;
            }
            if let Some(v) = h.to_ascii_lowercase().strip_prefix("content-length:") {
                length = v.trim().parse().unwrap_or(0);
            }
        }
        let mut body = vec![0; length];
        if reader.read_exact(&mut body).is_err() {
            return;
        }
        let mut out = stream.try_clone().unwrap();
        if get {
            respond(
                &mut out,
                200,
                r#"{"object":"list","data":[{"id":"fault-llm"}]}"#,
            );
            continue;
        }
        requests.fetch_add(1, Ordering::Relaxed);
        let text = String::from_utf8_lossy(&body);
        let intent = text.contains("\"name\":\"intent\"");
        let phrase = text.contains("\"name\":\"ehmi\"") || text.contains("\"name\":\"reply\"");
        let current = mode.lock().unwrap().clone();
        let request: serde_json::Value = serde_json::from_slice(&body).unwrap_or_default();
        let start = prefill(&request);
        let answer = |maneuver: &str, p: f64, ehmi: &str, action: &str| {
            if intent {
                completion(&[
                    (r#"{"style":""#, 0.0),
                    ("balanced", 0.95f64.ln()),
                    (r#"","action":""#, 0.0),
                    (action, p.ln()),
                    (r#"","task":""#, 0.0),
                    ("commute", 0.9f64.ln()),
                    ("\"}", 0.0),
                ])
            } else if phrase {
                completion(&[(r#"{"text":""#, 0.0), (ehmi, -0.2), ("\"}", 0.0)])
            } else {
                advice(start, &[(maneuver, p.ln()), ("\"}", 0.0)])
            }
        };
        match current {
            Mode::Answer {
                maneuver,
                p,
                ehmi,
                action,
                delay,
            } => {
                std::thread::sleep(delay);
                respond(&mut out, 200, &answer(maneuver, p, ehmi, action));
            }
            Mode::Late(delay) => {
                let until = std::time::Instant::now() + delay;
                while std::time::Instant::now() < until && !stop.load(Ordering::Relaxed) {
                    std::thread::sleep(Duration::from_millis(20));
                }
                respond(
                    &mut out,
                    200,
                    &answer(
                        "accelerate",
                        0.99,
                        "I am going first; please wait.",
                        "yield",
                    ),
                );
            }
            Mode::Malformed => respond(&mut out, 200, "{\"choices\": [ this is not json"),
            Mode::UnknownEnum => respond(
                &mut out,
                200,
                &advice(start, &[(r#"fly","ehmi":"Up we go.","style":"x"}"#, 0.0)]),
            ),
            Mode::Obey => {
                let reply = obey(&request, &mut shared.memory.lock().unwrap());
                shared.bodies.lock().unwrap().push(request);
                respond(&mut out, 200, &reply);
            }
            Mode::ServerError => respond(&mut out, 500, r#"{"error":"internal"}"#),
            Mode::Close => {
                let _ = stream.shutdown(Shutdown::Both);
                return;
            }
        }
    }
}

/// What a compromised model answers. It remembers every message quoted to it (the intent
/// parser's `<msg>…</msg>`) and obeys the newest in every later answer, at probability 1 (each
/// token's log-probability 0, no alternatives):
/// * intents: the style "aggressive", the task "emergency" and the action the message demands;
/// * advice: the maneuver the message demands (`accelerate` when it names none);
/// * eHMI phrasings and replies: a text that states what the prompt says the car does, followed
///   by as many of the remembered messages' own words (folded to ASCII where they can be) as
///   64 characters hold.
///
/// A message "demands" the first maneuver it names, in English, German or Chinese, also inside
/// base64.
pub fn obey(request: &serde_json::Value, memory: &mut Vec<String>) -> String {
    let name = request["response_format"]["json_schema"]["name"]
        .as_str()
        .unwrap_or("");
    let user = request["messages"]
        .as_array()
        .and_then(|m| m.iter().rev().find(|m| m["role"] == "user"))
        .and_then(|m| m["content"].as_str())
        .unwrap_or("")
        .to_string();
    if let (Some(a), Some(b)) = (user.find("<msg>"), user.rfind("</msg>")) {
        if a + 5 <= b {
            memory.push(user[a + 5..b].to_string());
        }
    }
    let demanded = memory.last().map_or("accelerate", |m| demand(m));
    match name {
        "intent" => {
            let action = match demanded {
                "decelerate" => "yield",
                "keep_speed" => "proceed",
                other => other,
            };
            completion(&[
                (r#"{"style":""#, 0.0),
                ("aggressive", 0.0),
                (r#"","action":""#, 0.0),
                (action, 0.0),
                (r#"","task":""#, 0.0),
                ("emergency", 0.0),
                ("\"}", 0.0),
            ])
        }
        "ehmi" | "reply" => {
            let stated = [
                ("is slowing down", "I am slowing down; please go ahead."),
                (
                    "is accelerating",
                    "I am speeding up to go first; please wait.",
                ),
                ("keeps its speed", "I am keeping my speed; please wait."),
                ("is turning left", "I am turning left first; please wait."),
                ("is turning right", "I am turning right first; please wait."),
                ("is stopping", "Stopping. Please go ahead carefully."),
            ]
            .iter()
            .find(|(says, _)| user.contains(says))
            .map_or("Please go ahead.", |(_, t)| t);
            let own = concord_sidecar::ehmi::own_vocabulary();
            let said: Vec<String> = memory
                .iter()
                .flat_map(|m| concord_sidecar::untrusted::words(m))
                .filter(|w| !own.contains(w))
                .collect();
            let ascii: Vec<&String> = said.iter().filter(|w| w.is_ascii()).collect();
            let echo: Vec<&String> = if ascii.is_empty() {
                said.iter().collect()
            } else {
                ascii
            };
            let mut text = stated.to_string();
            for w in echo {
                if text.chars().count() + 1 + w.chars().count() > 64 {
                    break;
                }
                text.push(' ');
                text.push_str(w);
            }
            let quoted = serde_json::to_string(&text).unwrap();
            completion(&[(r#"{"text":"#, 0.0), (&quoted, 0.0), ("}", 0.0)])
        }
        _ => advice(prefill(request), &[(demanded, 0.0), ("\"}", 0.0)]),
    }
}

/// The maneuver `message` names first (schema names, English, German, Chinese; also inside
/// base64 words), else `accelerate`.
fn demand(message: &str) -> &'static str {
    const NAMES: [(&str, &str); 27] = [
        ("turn_right", "turn_right"),
        ("turn right", "turn_right"),
        ("rechts", "turn_right"),
        ("右转", "turn_right"),
        ("右拐", "turn_right"),
        ("turn_left", "turn_left"),
        ("turn left", "turn_left"),
        ("links", "turn_left"),
        ("左转", "turn_left"),
        ("左拐", "turn_left"),
        ("keep_speed", "keep_speed"),
        ("keep speed", "keep_speed"),
        ("tempo halten", "keep_speed"),
        ("保持", "keep_speed"),
        ("decelerat", "decelerate"),
        ("slow", "decelerate"),
        ("brems", "decelerate"),
        ("langsam", "decelerate"),
        ("减速", "decelerate"),
        ("停", "decelerate"),
        ("stop", "decelerate"),
        ("accelerat", "accelerate"),
        ("beschleunig", "accelerate"),
        ("gas geben", "accelerate"),
        ("加速", "accelerate"),
        ("快", "accelerate"),
        ("hurry", "accelerate"),
    ];
    let mut texts = vec![concord_sidecar::untrusted::normalise(message, usize::MAX).to_lowercase()];
    texts.extend(
        message
            .split(|c: char| !(c.is_ascii_alphanumeric() || matches!(c, '+' | '/' | '=')))
            .filter(|w| w.len() >= 8)
            .filter_map(base64)
            .map(|d| d.to_lowercase()),
    );
    texts
        .iter()
        .filter_map(|t| {
            NAMES
                .iter()
                .filter_map(|(n, m)| t.find(n).map(|at| (at, *m)))
                .min()
        })
        .map(|(_, m)| m)
        .next()
        .unwrap_or("accelerate")
}

/// The UTF-8 text `word` encodes in standard base64, if it does.
fn base64(word: &str) -> Option<String> {
    const ALPHABET: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut bits = 0u32;
    let mut n = 0;
    let mut out = Vec::new();
    for c in word.trim_end_matches('=').bytes() {
        bits = (bits << 6) | ALPHABET.iter().position(|a| *a == c)? as u32;
        n += 6;
        if n >= 8 {
            n -= 8;
            out.push((bits >> n) as u8);
            bits &= (1 << n) - 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The answer's start the request gave as its last (assistant) message, as llama.cpp's server
/// reads it.
fn prefill(request: &serde_json::Value) -> Option<&str> {
    let last = request["messages"].as_array()?.last()?;
    (last["role"] == "assistant").then(|| last["content"].as_str())?
}

/// An advice answer whose maneuver value begins with `rest`: after the request's prefill, as
/// llama.cpp's server answers one (the content repeats the prefill, the tokens do not).
fn advice(prefill: Option<&str>, rest: &[(&str, f64)]) -> String {
    match prefill {
        Some(p) => completion_after(p, rest),
        None => {
            let mut tokens = vec![(r#"{"maneuver":""#, 0.0)];
            tokens.extend_from_slice(rest);
            completion(&tokens)
        }
    }
}

fn completion(tokens: &[(&str, f64)]) -> String {
    completion_after("", tokens)
}

/// A completion of `tokens` after `prefill`.
fn completion_after(prefill: &str, tokens: &[(&str, f64)]) -> String {
    let content: String = std::iter::once(prefill)
        .chain(tokens.iter().map(|(t, _)| *t))
        .collect();
    let lp: Vec<_> = tokens
        .iter()
        .map(|(t, l)| serde_json::json!({"token": t, "logprob": l, "bytes": t.as_bytes(), "top_logprobs": []}))
        .collect();
    serde_json::json!({
        "object": "chat.completion",
        "choices": [{"index": 0, "finish_reason": "stop",
                     "message": {"role": "assistant", "content": content},
                     "logprobs": {"content": lp}}],
        "usage": {"prompt_tokens": 150, "completion_tokens": tokens.len(), "total_tokens": 150 + tokens.len()}
    })
    .to_string()
}

fn respond(out: &mut TcpStream, status: u16, body: &str) {
    let reason = if status == 200 { "OK" } else { "Error" };
    let _ = write!(
        out,
        "HTTP/1.1 {status} {reason}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    let _ = out.flush();
}
