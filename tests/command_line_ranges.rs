//! Durations, periods and rates on the command line are checked before anything starts: a
//! value out of range is a clear error naming the option (exit code 2), never a panic or a
//! wrapped clock; and every shipped configuration file passes `concord params --check`.

use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const CONCORD: &str = env!("CARGO_BIN_EXE_concord");

/// Runs `concord args`; one still running after 10 s took the value and is killed.
fn refused_within_10_s(args: &[&str]) -> Output {
    let mut child = Command::new(CONCORD)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("concord runs");
    let give_up = Instant::now() + Duration::from_secs(10);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > give_up {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} was taken: concord still ran after 10 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn out_of_range_durations_and_rates_are_refused_by_name() {
    for args in [
        &["run", "--duration", "1e11"][..],
        &["run", "--duration", "NaN"],
        &["run", "--duration=-1"],
        &["run", "--rate", "0"],
        &["run", "--rate", "inf"],
        &["feed", "--rate", "1e9"],
        &["feed", "--duration", "0"],
        &["monitor", "--period", "0"],
        &["monitor", "--duration", "1e300"],
        &["demo", "--duration", "1e11"],
    ] {
        let out = refused_within_10_s(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        let option = args[1].split('=').next().unwrap();
        assert!(err.contains(option), "{args:?} not named: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn every_shipped_configuration_passes_the_check() {
    let deploy = concat!(env!("CARGO_MANIFEST_DIR"), "/deploy");
    for name in ["concord.toml", "highway-env.toml", "highway-env-merge.toml"] {
        let out = Command::new(CONCORD)
            .args(["params", "--check", &format!("{deploy}/{name}")])
            .output()
            .expect("concord runs");
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
