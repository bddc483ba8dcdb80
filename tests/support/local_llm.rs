//! The real local LLM server (deploy/llm/llm.sh) for tests: started on a free loopback port
//! with a private run directory, stopped when dropped. It needs `deploy/llm/llm.sh setup`
//! (the test command runs it first); without it the test fails and says so.

use std::path::PathBuf;
use std::process::Command;

pub struct LocalLlm {
    pub url: String,
    script: PathBuf,
    run_dir: PathBuf,
}

impl LocalLlm {
    pub fn start(tag: &str) -> LocalLlm {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        let root = if root.join("deploy/llm/llm.sh").exists() {
            root
        } else {
            root.parent().expect("workspace root").to_path_buf()
        };
        let script = root.join("deploy/llm/llm.sh");
        let run_dir =
            std::env::temp_dir().join(format!("concord-llm-{tag}-{}", std::process::id()));
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let out = Command::new(&script)
            .args(["start", "--port", &port.to_string()])
            .env("CONCORD_LLM_RUN_DIR", &run_dir)
            .output()
            .expect("deploy/llm/llm.sh runs");
        assert!(
            out.status.success(),
            "the local LLM did not start (run `deploy/llm/llm.sh setup` first): {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let url = String::from_utf8_lossy(&out.stdout)
            .lines()
            .last()
            .expect("llm.sh prints the URL")
            .trim()
            .to_string();
        LocalLlm {
            url,
            script,
            run_dir,
        }
    }
}

impl Drop for LocalLlm {
    fn drop(&mut self) {
        let _ = Command::new(&self.script)
            .arg("stop")
            .env("CONCORD_LLM_RUN_DIR", &self.run_dir)
            .output();
        let _ = std::fs::remove_dir_all(&self.run_dir);
    }
}
