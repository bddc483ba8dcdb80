//! The interaction log: one JSON object per line for every LLM call (prompt messages, answer,
//! latency, tokens, outcome) and for every verdict the core gave, ready to be turned into a
//! fine-tuning set (§5 step 5). The file is rotated at a size cap: `name` → `name.1` → … →
//! `name.<keep>`, the oldest dropped. A write failure is counted, never fatal.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

/// A size-capped, rotating JSONL file.
pub struct InteractionLog {
    path: PathBuf,
    max_bytes: u64,
    keep: usize,
    file: Option<File>,
    size: u64,
    /// Lines that could not be written.
    pub failures: u64,
}

impl InteractionLog {
    /// Opens (appending) `path`; an empty path gives a log that writes nothing.
    pub fn open(path: &Path, max_bytes: u64, keep: usize) -> std::io::Result<Self> {
        let mut log = InteractionLog {
            path: path.to_path_buf(),
            max_bytes,
            keep,
            file: None,
            size: 0,
            failures: 0,
        };
        if !path.as_os_str().is_empty() {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)?;
            }
            let f = OpenOptions::new().create(true).append(true).open(path)?;
            log.size = f.metadata()?.len();
            log.file = Some(f);
        }
        Ok(log)
    }

    /// Appends `record` as one line.
    pub fn write<T: Serialize>(&mut self, record: &T) {
        if self.file.is_none() {
            return;
        }
        let mut line = match serde_json::to_vec(record) {
            Ok(l) => l,
            Err(_) => {
                self.failures += 1;
                return;
            }
        };
        line.push(b'\n');
        if self.size > 0 && self.size + line.len() as u64 > self.max_bytes && self.rotate().is_err()
        {
            self.failures += 1;
        }
        match self.file.as_mut().map(|f| f.write_all(&line)) {
            Some(Ok(())) => self.size += line.len() as u64,
            _ => self.failures += 1,
        }
    }

    fn rotated(&self, k: usize) -> PathBuf {
        let mut p = self.path.clone().into_os_string();
        p.push(format!(".{k}"));
        p.into()
    }

    fn rotate(&mut self) -> std::io::Result<()> {
        self.file = None;
        if self.keep == 0 {
            std::fs::remove_file(&self.path)?;
        } else {
            let _ = std::fs::remove_file(self.rotated(self.keep));
            for k in (1..self.keep).rev() {
                let from = self.rotated(k);
                if from.exists() {
                    std::fs::rename(&from, self.rotated(k + 1))?;
                }
            }
            std::fs::rename(&self.path, self.rotated(1))?;
        }
        self.file = Some(
            OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)?,
        );
        self.size = 0;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotates_at_the_cap_and_keeps_every_line_until_dropped() {
        let dir = std::env::temp_dir().join(format!("concord-log-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("interactions.jsonl");
        let mut log = InteractionLog::open(&path, 4096, 2).unwrap();
        let record = serde_json::json!({"kind": "advice", "pad": "x".repeat(900)});
        for _ in 0..12 {
            log.write(&record);
        }
        assert_eq!(log.failures, 0);
        let lines = |p: &Path| {
            std::fs::read_to_string(p)
                .map(|s| s.lines().count())
                .unwrap_or(0)
        };
        let sizes: Vec<u64> = [path.clone(), log.rotated(1), log.rotated(2)]
            .iter()
            .map(|p| std::fs::metadata(p).unwrap().len())
            .collect();
        assert!(sizes.iter().all(|&s| s <= 4096), "{sizes:?}");
        // 4 lines of ~920 bytes fit under 4096: 12 lines fill exactly three files.
        assert_eq!(
            lines(&path) + lines(&log.rotated(1)) + lines(&log.rotated(2)),
            12
        );
        assert!(!log.rotated(3).exists());
        for l in std::fs::read_to_string(&path).unwrap().lines() {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            assert_eq!(v["kind"], "advice");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
