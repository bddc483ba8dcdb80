//! End to end with the real local LLM server (deploy/llm): feed, core and sidecar as processes
//! over iceoryx2; this process speaks as a road user and as the passenger. Scenes go in;
//! advice with request ids and confidences, parsed intents and eHMI text come out.

#[path = "support/local_llm.rs"]
mod local_llm;
#[path = "support/proc.rs"]
mod proc;

use std::process::Stdio;
use std::time::{Duration, Instant};

use concord_core::Maneuver;
use concord_ipc::clock::now_ns;
use concord_ipc::wire::{
    Audience, CoreStats, EhmiKind, EhmiMessage, IntentText, TextSource, WireAdvice, EHMI_MAX_CHARS,
};
use concord_ipc::{iox, services};
use proc::Proc;

#[test]
fn scenes_in_advice_intents_and_ehmi_text_out() {
    let llm = local_llm::LocalLlm::start("e2e");
    let prefix = format!("e2e-{}/", std::process::id());
    let log = std::env::temp_dir().join(format!("concord-e2e-{}.jsonl", std::process::id()));
    let _ = std::fs::remove_file(&log);
    let iox_cfg = iox::init(None).expect("iceoryx2 config");
    let node = iox::node("concord-e2e-observer", &iox_cfg).expect("node");
    let name = |s| services::name(&prefix, s);
    let advice = iox::subscriber::<WireAdvice>(&node, &name(services::ADVICE), 64).expect("advice");
    let ehmi = iox::subscriber::<EhmiMessage>(&node, &name(services::EHMI), 64).expect("ehmi");
    let stats = iox::subscriber::<CoreStats>(&node, &name(services::STATS), 1).expect("stats");
    let texts = iox::publisher::<IntentText>(&node, &name(services::INTENT_TEXT)).expect("texts");

    // This test checks the plumbing, not the model's speed: a 10 s advice deadline keeps it
    // meaningful on a loaded machine (the latency is measured by `advice_report`); requests
    // every 0.1 s, so that the core's log of 256 requests spans it.
    let config = std::env::temp_dir().join(format!("concord-e2e-{}.toml", std::process::id()));
    std::fs::write(
        &config,
        "[core.advice]\ndeadline_s = 10.0\nrequest_period_s = 0.1\n",
    )
    .unwrap();
    // The sidecar as deployed (the local server carries the shipped adapter, which the default
    // configuration asks with the prompts it was trained on), but asking every request.
    let sidecar_config =
        std::env::temp_dir().join(format!("concord-e2e-sidecar-{}.toml", std::process::id()));
    std::fs::write(&sidecar_config, "[advice]\nsettled_margin = 2.0\n").unwrap();
    let args = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let mut core = Proc::start(
        &args(&[
            "run",
            "--prefix",
            &prefix,
            "--rate",
            "20",
            "--duration",
            "90",
            "--config",
            &config.display().to_string(),
        ]),
        Stdio::null(),
    );
    let mut sidecar = Proc::start(
        &args(&[
            "sidecar",
            "--config",
            &sidecar_config.display().to_string(),
            "--prefix",
            &prefix,
            "--llm-url",
            &llm.url,
            "--log",
            &log.display().to_string(),
        ]),
        Stdio::null(),
    );
    let _feed = Proc::start(
        &args(&[
            "feed",
            "--scenario",
            "paper",
            "--speed",
            "6",
            "--repeat",
            "--duration",
            "80",
            "--prefix",
            &prefix,
        ]),
        Stdio::null(),
    );

    let started = Instant::now();
    let mut said = false;
    let mut valid = Vec::new();
    let mut with_road_user_intent = 0;
    let mut announcements = Vec::new();
    let mut replies = Vec::new();
    let mut to_passenger = Vec::new();
    let mut last_stats = None;
    while started.elapsed() < Duration::from_secs(75) {
        std::thread::sleep(Duration::from_millis(20));
        assert!(core.alive(), "the core died");
        assert!(sidecar.alive(), "the sidecar died");
        if !said && started.elapsed() > Duration::from_secs(3) {
            said = true;
            let road_user = IntentText::new(
                now_ns(),
                1,
                TextSource::RoadUser,
                1,
                "Go ahead, I will wait for you.",
            );
            iox::send(&texts, &road_user).unwrap();
            let passenger = IntentText::new(
                now_ns(),
                1,
                TextSource::Passenger,
                0,
                "I am in a hurry, please hurry up.",
            );
            iox::send(&texts, &passenger).unwrap();
        }
        while let Some(a) = advice.receive().unwrap() {
            if a.valid == 1 {
                valid.push(*a);
            }
            let n = a.n_agent_intents as usize;
            if a.agent_intents[..n].iter().any(|i| i.agent_id == 1) {
                with_road_user_intent += 1;
            }
        }
        while let Some(m) = ehmi.receive().unwrap() {
            let text = m.text().expect("UTF-8").to_string();
            assert!(
                !text.is_empty() && text.chars().count() <= EHMI_MAX_CHARS,
                "{text:?}"
            );
            match (m.kind, m.audience) {
                (k, _) if k == EhmiKind::Decision as u8 => announcements.push(text),
                (k, a) if k == EhmiKind::Reply as u8 => {
                    assert_eq!(a, Audience::RoadUser as u8);
                    replies.push((m.addressee, text));
                }
                (_, a) if a == Audience::Passenger as u8 => to_passenger.push(text),
                _ => {}
            }
        }
        if let Some(s) = iox::newest(&stats).unwrap().0 {
            last_stats = Some(s);
        }
        if valid.len() >= 5
            && with_road_user_intent > 0
            && !replies.is_empty()
            && !announcements.is_empty()
        {
            break;
        }
    }
    sidecar.signal(libc::SIGTERM);
    let (sidecar_ok, _) = sidecar.finish(Duration::from_secs(10));
    core.signal(libc::SIGTERM);
    let _ = core.finish(Duration::from_secs(10));
    eprintln!(
        "{} valid advice, {with_road_user_intent} with the road user's intent; announcements {announcements:?}; replies {replies:?}; to the passenger {to_passenger:?}",
        valid.len()
    );

    assert!(sidecar_ok, "the sidecar did not exit cleanly on SIGTERM");
    assert!(
        valid.len() >= 5,
        "only {} answers from the local model",
        valid.len()
    );
    for a in &valid {
        assert!(a.request_id > 0 && a.maneuver < 5, "{a:?}");
        assert!((0.0..=1.0).contains(&a.confidence), "{a:?}");
    }
    assert!(
        with_road_user_intent > 0,
        "the road user's words never reached the core"
    );
    assert!(!announcements.is_empty(), "no decision was announced");
    assert!(
        replies.iter().any(|(to, _)| *to == 1),
        "no reply to road user 1"
    );
    let s = last_stats.expect("core statistics");
    let weighed: u64 = s.advice_verdicts.iter().skip(1).sum();
    assert!(weighed > 0, "the core weighed no advice: {s:?}");

    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&log)
        .expect("interaction log")
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    let answered = lines
        .iter()
        .filter(|l| l["kind"] == "advice" && l["outcome"] == "answered")
        .count();
    assert!(answered >= 5, "{answered} answered advice calls logged");
    assert!(lines
        .iter()
        .any(|l| l["kind"] == "intent" && l["messages"].is_array()));
    assert!(lines.iter().any(|l| l["kind"] == "verdict"));
    // eHMI texts and replies are phrased by the base model: the advisor's adapter, asked to
    // phrase, answers a maneuver or action name ("accelerate", "yield").
    let phrased: Vec<String> = lines
        .iter()
        .filter(|l| (l["kind"] == "ehmi" || l["kind"] == "reply") && l["outcome"] == "answered")
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l["response"].as_str()?).ok())
        .filter_map(|v| v["text"].as_str().map(str::to_string))
        .collect();
    assert!(!phrased.is_empty(), "the model phrased no eHMI text");
    let names: Vec<&str> = Maneuver::ALL
        .iter()
        .map(|m| m.name())
        .chain(["yield", "proceed", "turn_right", "stop", "unknown"])
        .collect();
    assert!(
        phrased
            .iter()
            .all(|t| !names.contains(&t.trim().to_lowercase().as_str())),
        "phrased as a bare name: {phrased:?}"
    );
    let _ = std::fs::remove_file(&log);
    let _ = std::fs::remove_file(&config);
    let _ = std::fs::remove_file(&sidecar_config);
}
