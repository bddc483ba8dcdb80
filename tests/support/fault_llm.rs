//! A loopback stand-in for an OpenAI-compatible server that misbehaves on purpose, for the
//! timeout, garbage and crash tests (the end-to-end test uses the real local server). It
//! listens on 127.0.0.1 on a free port, answers `GET /v1/models`, and answers
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
}

impl FaultLlm {
    pub fn start(mode: Mode) -> FaultLlm {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind 127.0.0.1:0");
        let port = listener.local_addr().unwrap().port();
        listener.set_nonblocking(true).unwrap();
        let mode = Arc::new(Mutex::new(mode));
        let stop = Arc::new(AtomicBool::new(false));
        let requests = Arc::new(AtomicU64::new(0));
        let (m, s, r) = (mode.clone(), stop.clone(), requests.clone());
        std::thread::spawn(move || {
            while !s.load(Ordering::Relaxed) {
                match listener.accept() {
                    Ok((stream, _)) => {
                        let (m, s, r) = (m.clone(), s.clone(), r.clone());
                        std::thread::spawn(move || serve(stream, &m, &s, &r));
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
        }
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

fn serve(stream: TcpStream, mode: &Mutex<Mode>, stop: &AtomicBool, requests: &AtomicU64) {
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
        let phrase = text.contains("\"name\":\"ehmi\"");
        let current = mode.lock().unwrap().clone();
        let answer = |maneuver: &str, p: f64, ehmi: &str, action: &str| {
            if intent {
                completion(&[
                    (r#"{"style":""#, 0.0),
                    ("balanced", 0.95f64.ln()),
                    (r#"","action":""#, 0.0),
                    (action, p.ln()),
                    (r#"","task":""#, 0.0),
                    ("commute", 0.9f64.ln()),
                    (r#"","reply":""#, 0.0),
                    (ehmi, -0.1),
                    ("\"}", 0.0),
                ])
            } else if phrase {
                completion(&[(r#"{"text":""#, 0.0), (ehmi, -0.2), ("\"}", 0.0)])
            } else {
                completion(&[(r#"{"maneuver":""#, 0.0), (maneuver, p.ln()), ("\"}", 0.0)])
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
                &completion(&[(r#"{"maneuver":"fly","ehmi":"Up we go.","style":"x"}"#, 0.0)]),
            ),
            Mode::ServerError => respond(&mut out, 500, r#"{"error":"internal"}"#),
            Mode::Close => {
                let _ = stream.shutdown(Shutdown::Both);
                return;
            }
        }
    }
}

fn completion(tokens: &[(&str, f64)]) -> String {
    let content: String = tokens.iter().map(|(t, _)| *t).collect();
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
