//! The HTTP client against a loopback server that answers late, with garbage, with an unknown
//! enum, with HTTP 500, or by closing the connection: every case ends in its own error within
//! the deadline, and a good answer gives the confidence of its log-probabilities.

#[path = "../../tests/support/fault_llm.rs"]
mod fault_llm;

use std::time::{Duration, Instant};

use concord_core::Maneuver;
use concord_ipc::wire::AdviceFailure;
use concord_sidecar::config::LlmConfig;
use concord_sidecar::llm::{LlmClient, LlmError};
use concord_sidecar::prompt::ChatMessage;
use concord_sidecar::reply::ReplyError;
use concord_sidecar::schema::{advice_schema, AdviceAnswer};
use fault_llm::{FaultLlm, Mode};

fn client(url: String) -> LlmClient {
    LlmClient::new(&LlmConfig {
        base_url: url,
        ..LlmConfig::default()
    })
    .unwrap()
}

async fn ask(c: &LlmClient, within: Duration) -> (Result<AdviceAnswer, LlmError>, Duration) {
    let body = c.body(
        &[ChatMessage::user("scene")],
        "advice",
        &advice_schema(0),
        64,
    );
    let t0 = Instant::now();
    let r = c
        .call(&body, t0 + within)
        .await
        .and_then(|r| AdviceAnswer::decode(&r.answer).map_err(LlmError::Reply));
    (r, t0.elapsed())
}

fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

#[test]
fn a_good_answer_carries_the_probability_of_its_maneuver() {
    let server = FaultLlm::start(Mode::yielding());
    let c = client(server.url());
    let (r, _) = rt().block_on(ask(&c, Duration::from_secs(2)));
    let a = r.unwrap();
    assert_eq!(a.maneuver, Maneuver::Decelerate);
    assert!((a.confidence.unwrap() - 0.9).abs() < 1e-9);
}

#[test]
fn each_fault_ends_in_its_own_error_before_the_deadline() {
    let server = FaultLlm::start(Mode::Late(Duration::from_secs(5)));
    let c = client(server.url());
    let rt = rt();
    let cases = [
        (Mode::Late(Duration::from_secs(5)), AdviceFailure::Timeout),
        (Mode::Malformed, AdviceFailure::Malformed),
        (Mode::UnknownEnum, AdviceFailure::SchemaViolation),
        (Mode::ServerError, AdviceFailure::HttpStatus),
        (Mode::Close, AdviceFailure::Connection),
    ];
    for (mode, expected) in cases {
        server.set(mode.clone());
        let (r, took) = rt.block_on(ask(&c, Duration::from_millis(800)));
        let e = r.expect_err("a fault gives an error");
        assert_eq!(e.failure(), expected, "{mode:?}: {e}");
        assert!(
            took < Duration::from_millis(800) + Duration::from_millis(150),
            "{mode:?} took {took:?}"
        );
    }
}

#[test]
fn server_errors_are_retried_while_the_deadline_allows_and_garbage_is_not() {
    let server = FaultLlm::start(Mode::ServerError);
    let c = client(server.url());
    let rt = rt();
    let (r, _) = rt.block_on(ask(&c, Duration::from_millis(600)));
    assert!(matches!(r, Err(LlmError::HttpStatus(500, _))));
    let retried = server.requests.load(std::sync::atomic::Ordering::Relaxed);
    assert!(retried >= 2, "only {retried} attempt(s)");
    server.set(Mode::Malformed);
    let before = server.requests.load(std::sync::atomic::Ordering::Relaxed);
    let (r, _) = rt.block_on(ask(&c, Duration::from_millis(600)));
    assert!(matches!(r, Err(LlmError::Reply(ReplyError::Malformed(_)))));
    assert_eq!(
        server.requests.load(std::sync::atomic::Ordering::Relaxed) - before,
        1,
        "a malformed answer is not retried"
    );
}

#[test]
fn a_dead_server_is_a_connection_failure_at_once() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let c = client(format!("http://127.0.0.1:{port}/v1"));
    let (r, took) = rt().block_on(ask(&c, Duration::from_millis(500)));
    assert_eq!(r.unwrap_err().failure(), AdviceFailure::Connection);
    assert!(took < Duration::from_millis(650), "{took:?}");
}
