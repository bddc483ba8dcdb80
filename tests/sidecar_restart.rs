//! Each message on `intent_text` is parsed once, also across a restart of the sidecar: iceoryx2
//! hands every new subscriber the service's last sample again (history 1), and the sidecar's
//! ledger of parsed messages (`intent.parsed_file`, next to its log) keeps it from parsing that
//! sample twice. A message sent while no sidecar runs is parsed when one starts.

#[path = "support/fault_llm.rs"]
mod fault_llm;
#[path = "support/proc.rs"]
mod proc;

use std::process::Stdio;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use concord_ipc::clock::now_ns;
use concord_ipc::wire::{IntentText, TextSource};
use concord_ipc::{iox, services};
use fault_llm::{FaultLlm, Mode};
use iceoryx2::port::update_connections::UpdateConnections;
use proc::Proc;

#[test]
fn a_restarted_sidecar_does_not_parse_the_last_message_again() {
    let llm = FaultLlm::start(Mode::yielding());
    let prefix = format!("restart-{}/", std::process::id());
    let dir = std::env::temp_dir().join(format!("concord-restart-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("interactions.jsonl");
    let iox_cfg = iox::init(None).expect("iceoryx2 config");
    let node = iox::node("concord-restart-hmi", &iox_cfg).expect("node");
    let texts =
        iox::publisher::<IntentText>(&node, &services::name(&prefix, services::INTENT_TEXT))
            .expect("texts");
    let sidecar = || {
        Proc::start(
            &[
                "sidecar",
                "--prefix",
                &prefix,
                "--llm-url",
                &llm.url(),
                "--log",
                &log.display().to_string(),
            ]
            .map(String::from),
            Stdio::null(),
        )
    };
    // Parses seen by the server after `settle`, while this publisher keeps its connections
    // up to date (which is when iceoryx2 delivers its history to a new subscriber).
    let parses_after = |settle: Duration, at_least: u64| {
        let end = Instant::now() + settle;
        while Instant::now() < end
            || llm.requests.load(Ordering::Relaxed) < at_least
                && Instant::now() < end + Duration::from_secs(20)
        {
            texts.update_connections().expect("connections");
            std::thread::sleep(Duration::from_millis(20));
        }
        llm.requests.load(Ordering::Relaxed)
    };
    let say = |id: u64, text: &str| {
        iox::send(
            &texts,
            &IntentText::new(now_ns(), id, TextSource::RoadUser, 1, text),
        )
        .expect("send");
    };

    // Sent while no sidecar runs: parsed when the first one starts.
    say(1, "Go ahead, I will wait for you.");
    let first = sidecar();
    assert_eq!(parses_after(Duration::from_secs(2), 1), 1);
    assert!(
        dir.join("concord-parsed-texts.json").exists(),
        "the ledger is written"
    );

    // Killed and started again: iceoryx2 replays message 1, which is not parsed again.
    first.signal(libc::SIGKILL);
    let _ = first.finish(Duration::from_secs(5));
    let mut second = sidecar();
    assert_eq!(
        parses_after(Duration::from_secs(4), 1),
        1,
        "the restarted sidecar parsed the replayed message again"
    );
    assert!(second.alive(), "the restarted sidecar died");

    // A new message is parsed.
    say(2, "Thanks, I am turning now.");
    assert_eq!(parses_after(Duration::from_millis(500), 2), 2);
    second.signal(libc::SIGTERM);
    let (clean, _) = second.finish(Duration::from_secs(10));
    assert!(clean, "the sidecar did not exit cleanly on SIGTERM");
    let _ = std::fs::remove_dir_all(&dir);
}
