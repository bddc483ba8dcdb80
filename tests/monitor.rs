//! `concord monitor` shows a running core's counters, last decision and eHMI line from another
//! process.

use std::process::{Command, Stdio};

const CONCORD: &str = env!("CARGO_BIN_EXE_concord");

#[test]
fn monitor_reads_counters_and_the_last_decision_of_a_running_core() {
    let prefix = format!("monitor-{}/", std::process::id());
    let mut core = Command::new(CONCORD)
        .args([
            "run",
            "--prefix",
            &prefix,
            "--rate",
            "50",
            "--duration",
            "8",
        ])
        .stderr(Stdio::null())
        .spawn()
        .expect("concord run starts");
    let mut feed = Command::new(CONCORD)
        .args([
            "feed",
            "--prefix",
            &prefix,
            "--scenario",
            "paper",
            "--duration",
            "6",
        ])
        .stdout(Stdio::null())
        .spawn()
        .expect("concord feed starts");
    let out = Command::new(CONCORD)
        .args([
            "monitor",
            "--prefix",
            &prefix,
            "--period",
            "0.5",
            "--duration",
            "4",
        ])
        .output()
        .expect("concord monitor runs");
    let _ = feed.wait();
    let core_status = core.wait().expect("core exits");
    assert!(
        out.status.success(),
        "monitor failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(core_status.success(), "the core did not exit cleanly");
    let text = String::from_utf8(out.stdout).expect("UTF-8 output");
    let last = text
        .lines()
        .rfind(|l| l.starts_with("core: "))
        .expect("a core line");
    assert!(
        last.contains(" decided,") && last.contains("cycle µs p50"),
        "no counters in {last:?}"
    );
    let decided: u64 = last
        .split(" decided,")
        .next()
        .and_then(|head| head.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("a decided count");
    assert!(
        decided > 10,
        "the core decided only {decided} frames in 3 s: {last}"
    );
    assert!(
        text.contains("last decision: scene"),
        "no decision line in:\n{text}"
    );
    assert!(
        text.contains("eHMI: (none yet)"),
        "no eHMI line in:\n{text}"
    );
}
