//! A child `concord` process for the multi-process tests, killed when dropped.
#![allow(dead_code)]

use std::io::Read;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CONCORD: &str = env!("CARGO_BIN_EXE_concord");

pub struct Proc(pub Child);

impl Proc {
    pub fn start(args: &[String], stdout: Stdio) -> Proc {
        Proc(
            Command::new(CONCORD)
                .args(args)
                .stdout(stdout)
                .spawn()
                .expect("concord starts"),
        )
    }
    pub fn signal(&self, sig: i32) {
        // SAFETY: kill with the child's pid.
        unsafe { libc::kill(self.0.id() as i32, sig) };
    }
    pub fn alive(&mut self) -> bool {
        matches!(self.0.try_wait(), Ok(None))
    }
    /// Waits for the exit; returns success and the captured stdout.
    pub fn finish(mut self, within: Duration) -> (bool, String) {
        let deadline = Instant::now() + within;
        while self.alive() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        if self.alive() {
            let _ = self.0.kill();
        }
        let status = self.0.wait().expect("child status");
        let mut out = String::new();
        if let Some(mut s) = self.0.stdout.take() {
            let _ = s.read_to_string(&mut out);
        }
        (status.success(), out)
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if self.alive() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}
