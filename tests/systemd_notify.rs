//! Under systemd, `concord run` reports readiness once its loop runs, pings the watchdog while
//! ticks advance, and says it is stopping on SIGTERM (the sd_notify protocol over
//! `$NOTIFY_SOCKET`).

use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const CONCORD: &str = env!("CARGO_BIN_EXE_concord");

#[test]
fn ready_watchdog_and_stopping_are_notified() {
    let dir = std::env::temp_dir().join(format!("concord-notify-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("notify.sock");
    let _ = std::fs::remove_file(&path);
    let socket = UnixDatagram::bind(&path).expect("notify socket");
    socket
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let prefix = format!("notify-{}/", std::process::id());
    let mut core = Command::new(CONCORD)
        .args(["run", "--prefix", &prefix, "--rate", "50"])
        .env("NOTIFY_SOCKET", &path)
        .env("WATCHDOG_USEC", "200000")
        .stderr(Stdio::null())
        .spawn()
        .expect("concord run starts");
    let mut messages = Vec::new();
    let started = Instant::now();
    let mut buf = [0u8; 256];
    while started.elapsed() < Duration::from_secs(3) {
        if let Ok(n) = socket.recv(&mut buf) {
            messages.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    // SAFETY: kill with the child's pid.
    unsafe { libc::kill(core.id() as i32, libc::SIGTERM) };
    let status = core.wait().expect("exit status");
    while let Ok(n) = socket.recv(&mut buf) {
        messages.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(status.success(), "concord run failed on SIGTERM");
    assert_eq!(
        messages.first().map(String::as_str),
        Some("READY=1"),
        "{messages:?}"
    );
    let pings = messages.iter().filter(|m| *m == "WATCHDOG=1").count();
    // 0.1 s ping interval for about 2.5 s of running.
    assert!(pings >= 10, "only {pings} watchdog pings: {messages:?}");
    assert_eq!(
        messages.last().map(String::as_str),
        Some("STOPPING=1"),
        "{messages:?}"
    );
}
