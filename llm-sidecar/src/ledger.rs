//! Which messages the sidecar has parsed, per party, kept in a small file (`intent.parsed_file`,
//! next to the interaction log by default) so that each message on `intent_text` is parsed once,
//! also across a restart: iceoryx2 hands a new subscriber the service's last sample again
//! (history 1), which a restarted sidecar must not parse a second time.
//!
//! For each party (the `TextSource` code and the source id) the ledger keeps the id and stamp of
//! the newest message taken for parsing. A message is a repeat when neither its id nor its stamp
//! is newer than those; so a publisher that restarts and numbers its messages from 1 again is
//! still heard (its stamps are newer). A message is marked when its parse starts: one that
//! crashes the sidecar is not parsed again after the restart (at most once).
//!
//! The file is rewritten (a temporary file renamed over it) at every mark, so it survives the
//! process being killed. `CLOCK_MONOTONIC` starts again at boot: entries stamped later than the
//! clock when the ledger is opened are from before a reboot and are dropped (no iceoryx2 sample
//! survives a reboot either).
//!
//! Why a ledger and not a longer history: with history 1 a sidecar that was down gets the newest
//! message sent meanwhile, and parses it when the ledger does not hold it; the earlier ones are
//! lost. A longer history would replay them, but a message the driver of another car said
//! minutes ago says nothing about what they do now, and every publisher and subscriber of the
//! service (the Python bridge's too) would have to agree on the new history size.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use concord_ipc::wire::IntentText;
use serde::{Deserialize, Serialize};

/// One party's newest parsed message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
struct Entry {
    /// `TextSource` code.
    source: u8,
    source_id: u32,
    id: u64,
    stamp_ns: u64,
}

#[derive(Debug, Default, Deserialize, Serialize)]
struct File {
    parsed: Vec<Entry>,
}

/// The ledger of parsed messages.
#[derive(Debug)]
pub struct Ledger {
    /// `None`: kept in memory only.
    path: Option<PathBuf>,
    /// (source, source id) → (id, stamp, ns).
    parties: BTreeMap<(u8, u32), (u64, u64)>,
    max_parties: usize,
    /// Marks that could not be written to the file.
    pub write_failures: u64,
}

impl Ledger {
    /// A ledger in memory only.
    pub fn in_memory(max_parties: usize) -> Self {
        Ledger {
            path: None,
            parties: BTreeMap::new(),
            max_parties: max_parties.max(1),
            write_failures: 0,
        }
    }

    /// The ledger kept in `path` (created at the first mark), keeping at most `max_parties`
    /// parties (the one heard longest ago is forgotten first); `now_ns` is `CLOCK_MONOTONIC`
    /// now. A file that cannot be read is an error (the caller may start with an empty ledger
    /// at the same path).
    pub fn open(path: &Path, max_parties: usize, now_ns: u64) -> Result<Self, String> {
        let mut ledger = Ledger::in_memory(max_parties);
        ledger.path = Some(path.to_path_buf());
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(ledger),
            Err(e) => return Err(format!("reading {}: {e}", path.display())),
        };
        let file: File = serde_json::from_str(&text)
            .map_err(|e| format!("{}: not a ledger: {e}", path.display()))?;
        for e in file.parsed.into_iter().filter(|e| e.stamp_ns <= now_ns) {
            ledger
                .parties
                .insert((e.source, e.source_id), (e.id, e.stamp_ns));
        }
        Ok(ledger)
    }

    /// An empty ledger that will be written to `path`.
    pub fn empty_at(path: &Path, max_parties: usize) -> Self {
        Ledger {
            path: Some(path.to_path_buf()),
            ..Ledger::in_memory(max_parties)
        }
    }

    /// True when `t` is new: it is marked as parsed (and the file rewritten). False for a
    /// repeat.
    pub fn take(&mut self, t: &IntentText) -> bool {
        let key = (t.source, t.source_id);
        if let Some(&(id, stamp)) = self.parties.get(&key) {
            if t.id <= id && t.stamp_ns <= stamp {
                return false;
            }
        }
        self.parties.insert(key, (t.id, t.stamp_ns));
        while self.parties.len() > self.max_parties {
            let oldest = self
                .parties
                .iter()
                .min_by_key(|(_, (_, stamp))| *stamp)
                .map(|(k, _)| *k);
            if let Some(k) = oldest {
                self.parties.remove(&k);
            }
        }
        if self.write().is_err() {
            self.write_failures += 1;
        }
        true
    }

    fn write(&self) -> std::io::Result<()> {
        let Some(path) = &self.path else {
            return Ok(());
        };
        let file = File {
            parsed: self
                .parties
                .iter()
                .map(|(&(source, source_id), &(id, stamp_ns))| Entry {
                    source,
                    source_id,
                    id,
                    stamp_ns,
                })
                .collect(),
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let mut tmp = path.clone().into_os_string();
        tmp.push(".tmp");
        std::fs::write(&tmp, serde_json::to_vec(&file)?)?;
        std::fs::rename(&tmp, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use concord_ipc::wire::TextSource;

    fn text(stamp_ns: u64, id: u64, source: TextSource, source_id: u32) -> IntentText {
        IntentText::new(stamp_ns, id, source, source_id, "hello")
    }

    #[test]
    fn each_message_is_taken_once_per_party() {
        let mut l = Ledger::in_memory(8);
        let a = text(100, 1, TextSource::RoadUser, 3);
        assert!(l.take(&a));
        assert!(!l.take(&a), "the same message again");
        assert!(l.take(&text(200, 2, TextSource::RoadUser, 3)));
        assert!(
            !l.take(&text(150, 1, TextSource::RoadUser, 3)),
            "an older one"
        );
        // Another party with the same id, and the passenger under source id 3, are others.
        assert!(l.take(&text(120, 1, TextSource::RoadUser, 4)));
        assert!(l.take(&text(130, 1, TextSource::Passenger, 3)));
        // A publisher that restarted numbers from 1 again with newer stamps.
        assert!(l.take(&text(300, 1, TextSource::RoadUser, 3)));
    }

    #[test]
    fn the_file_survives_a_restart_and_a_reboot_clears_it() {
        let dir = std::env::temp_dir().join(format!("concord-ledger-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("parsed.json");
        let mut l = Ledger::open(&path, 8, 1_000).unwrap();
        let last = text(500, 7, TextSource::RoadUser, 1);
        assert!(l.take(&last));
        assert!(l.take(&text(400, 2, TextSource::Passenger, 0)));
        drop(l);
        let mut again = Ledger::open(&path, 8, 1_000).unwrap();
        assert!(
            !again.take(&last),
            "the replayed sample is not parsed again"
        );
        assert!(again.take(&text(600, 8, TextSource::RoadUser, 1)));
        // After a reboot the clock is behind the stamps: the ledger starts empty.
        let mut rebooted = Ledger::open(&path, 8, 450).unwrap();
        assert!(rebooted.take(&text(420, 1, TextSource::RoadUser, 1)));
        std::fs::write(&path, "not json").unwrap();
        assert!(Ledger::open(&path, 8, 1_000).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_ledger_is_bounded() {
        let mut l = Ledger::in_memory(2);
        for id in 1..=3 {
            assert!(l.take(&text(u64::from(id) * 10, 1, TextSource::RoadUser, id)));
        }
        assert_eq!(l.parties.len(), 2);
        assert!(!l.parties.contains_key(&(TextSource::RoadUser as u8, 1)));
    }
}
