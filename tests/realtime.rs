//! A refused real-time request is reported loudly and the loop runs on without it.

use std::process::Command;

const CONCORD: &str = env!("CARGO_BIN_EXE_concord");

#[test]
fn a_refused_cpu_pin_is_a_loud_warning_not_a_failure() {
    let dir = std::env::temp_dir().join(format!("concord-rt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let config = dir.join("concord.toml");
    // No machine here has CPU 1000.
    std::fs::write(
        &config,
        "[service]\nrate_hz = 50.0\n\n[realtime]\ncpu = 1000\n",
    )
    .expect("config");
    let prefix = format!("rt-{}/", std::process::id());
    let out = Command::new(CONCORD)
        .args(["run", "--config"])
        .arg(&config)
        .args(["--prefix", &prefix, "--duration", "1"])
        .output()
        .expect("concord run");
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "concord run failed: {stderr}");
    assert!(
        stderr.contains("WARNING: pinning to CPU 1000 refused"),
        "no warning in: {stderr}"
    );
    let ticks = stderr
        .lines()
        .find(|l| l.contains("final:"))
        .and_then(|l| l.split(" ticks").next())
        .and_then(|head| head.rsplit(' ').next())
        .and_then(|n| n.parse::<u64>().ok())
        .expect("a final statistics line");
    assert!(
        ticks >= 40,
        "the loop ran only {ticks} ticks in 1 s at 50 Hz: {stderr}"
    );
}

#[test]
fn an_unknown_configuration_key_is_an_error() {
    let dir = std::env::temp_dir().join(format!("concord-cfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let config = dir.join("concord.toml");
    std::fs::write(&config, "[service]\nrate_hz = 50.0\nrate_hertz = 20.0\n").expect("config");
    let out = Command::new(CONCORD)
        .args(["params", "--check"])
        .arg(&config)
        .output()
        .expect("concord params");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(!out.status.success(), "an unknown key was accepted");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("rate_hertz"),
        "the error does not name the key"
    );
}
