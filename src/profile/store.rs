//! The profile store: a state directory with the published profiles and a stable
//! path to the current one.
//!
//! ```text
//! <state>/current.toml          the current profile (replaced atomically)
//! <state>/profiles/<id>.toml    every profile made, published or not
//! <state>/history.json          the profiles made current, oldest first
//! <state>/verifications.jsonl   every verification, a line each
//! <state>/runs/<run-id>/        each calibration run: journal.jsonl, ...
//! ```
//!
//! Every file is replaced atomically or appended with fsync, so a power cut leaves
//! the store as it was before or after a change, and `current.toml` is always a whole
//! profile that passed the publishing limits.

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::durable::write_atomic;
use crate::fit::stats::ErrorStats;

/// Why the store could not do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Corrupt { path: PathBuf, message: String },
    #[error("no profile to roll back to: {0}")]
    NoRollback(String),
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A profile that was made current.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    pub id: String,
    /// When it became current (RFC 3339).
    pub at: String,
    /// How: `calibration`, `uniformity` or `rollback`.
    pub how: String,
    /// Its held-out error when it was made.
    pub held_out: Option<ErrorStats>,
}

/// `history.json`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct History {
    pub current: Option<String>,
    /// Oldest first.
    pub entries: Vec<HistoryEntry>,
}

/// One verification of the current profile: a few patches measured and compared with
/// what the profile predicts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VerificationRecord {
    /// When it ended (RFC 3339).
    pub at: String,
    /// The profile verified.
    pub profile_id: String,
    /// ΔE00 over the patches.
    pub stats: Option<ErrorStats>,
    /// Each patch's ΔE00, in the order measured.
    pub delta_e00: Vec<f64>,
    /// The mean ΔE00 past which a recalibration is started.
    pub threshold: f64,
    /// A recalibration was started because of it.
    pub escalated: bool,
}

fn now_rfc3339() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

/// Profiles kept in the history unless configured otherwise.
pub const DEFAULT_KEEP: usize = 10;

/// A state directory.
#[derive(Debug, Clone)]
pub struct ProfileStore {
    root: PathBuf,
    /// Profiles kept in the history; older ones (and their files) are removed.
    keep: usize,
}

impl ProfileStore {
    pub fn new(root: &Path) -> Self {
        ProfileStore {
            root: root.to_path_buf(),
            keep: DEFAULT_KEEP,
        }
    }

    /// Keep the last `n` current profiles (at least 2, so there is one to roll back to).
    pub fn keeping(mut self, n: usize) -> Self {
        self.keep = n.max(2);
        self
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn current_path(&self) -> PathBuf {
        self.root.join("current.toml")
    }

    pub fn profile_path(&self, id: &str) -> PathBuf {
        self.root.join("profiles").join(format!("{id}.toml"))
    }

    pub fn runs_dir(&self) -> PathBuf {
        self.root.join("runs")
    }

    /// Keep a profile in the store without making it current.
    pub fn keep(&self, id: &str, toml: &str) -> std::io::Result<PathBuf> {
        let path = self.profile_path(id);
        write_atomic(&path, toml.as_bytes())?;
        Ok(path)
    }

    /// Keep a profile and make it the current one; `how` and `held_out` go into the
    /// history.
    pub fn publish(
        &self,
        id: &str,
        toml: &str,
        held_out: Option<&ErrorStats>,
        how: &str,
    ) -> std::io::Result<PathBuf> {
        let path = self.keep(id, toml)?;
        write_atomic(&self.current_path(), toml.as_bytes())?;
        self.record_current(id, how, held_out.cloned())
            .map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(path)
    }

    pub fn history_path(&self) -> PathBuf {
        self.root.join("history.json")
    }

    pub fn verifications_path(&self) -> PathBuf {
        self.root.join("verifications.jsonl")
    }

    /// The history (empty when nothing was published yet).
    pub fn history(&self) -> Result<History, StoreError> {
        let path = self.history_path();
        match fs::read_to_string(&path) {
            Ok(text) => serde_json::from_str(&text).map_err(|e| StoreError::Corrupt {
                path: path.clone(),
                message: e.to_string(),
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(History::default()),
            Err(e) => Err(io_error(&path)(e)),
        }
    }

    /// Add `id` as current to the history, and drop the oldest entries (and their
    /// profile files) past the number kept.
    fn record_current(
        &self,
        id: &str,
        how: &str,
        held_out: Option<ErrorStats>,
    ) -> Result<(), StoreError> {
        let mut history = self.history()?;
        history.entries.push(HistoryEntry {
            id: id.to_string(),
            at: now_rfc3339(),
            how: how.to_string(),
            held_out,
        });
        history.current = Some(id.to_string());
        let mut dropped = Vec::new();
        while history.entries.len() > self.keep {
            dropped.push(history.entries.remove(0));
        }
        let path = self.history_path();
        let text = serde_json::to_string_pretty(&history).map_err(|e| StoreError::Corrupt {
            path: path.clone(),
            message: e.to_string(),
        })?;
        write_atomic(&path, text.as_bytes()).map_err(io_error(&path))?;
        for old in dropped {
            if !history.entries.iter().any(|e| e.id == old.id) {
                let _ = fs::remove_file(self.profile_path(&old.id));
            }
        }
        Ok(())
    }

    /// Make an earlier profile current again: `to`, or else the one current before
    /// the current one. Returns the new history entry.
    pub fn rollback(&self, to: Option<&str>) -> Result<HistoryEntry, StoreError> {
        let history = self.history()?;
        let current = history.current.clone();
        let target = match to {
            Some(id) => id.to_string(),
            None => history
                .entries
                .iter()
                .rev()
                .map(|e| &e.id)
                .find(|id| Some(*id) != current.as_ref())
                .cloned()
                .ok_or_else(|| {
                    StoreError::NoRollback("the history has no earlier profile".into())
                })?,
        };
        let path = self.profile_path(&target);
        let text = fs::read_to_string(&path).map_err(|e| {
            StoreError::NoRollback(format!("profile '{target}' is not in the store ({e})"))
        })?;
        write_atomic(&self.current_path(), text.as_bytes())
            .map_err(io_error(&self.current_path()))?;
        let held_out = history
            .entries
            .iter()
            .rev()
            .find(|e| e.id == target)
            .and_then(|e| e.held_out);
        self.record_current(&target, "rollback", held_out)?;
        self.history()?
            .entries
            .pop()
            .ok_or_else(|| StoreError::NoRollback("the history did not keep the rollback".into()))
    }

    /// Append a verification, durably.
    pub fn append_verification(&self, record: &VerificationRecord) -> Result<(), StoreError> {
        let path = self.verifications_path();
        let line = serde_json::to_string(record).map_err(|e| StoreError::Corrupt {
            path: path.clone(),
            message: e.to_string(),
        })?;
        fs::create_dir_all(&self.root).map_err(io_error(&self.root))?;
        let mut file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_error(&path))?;
        file.write_all(format!("{line}\n").as_bytes())
            .and_then(|()| file.sync_all())
            .map_err(io_error(&path))
    }

    /// Every verification, oldest first (a line torn by a crash is skipped).
    pub fn verifications(&self) -> Result<Vec<VerificationRecord>, StoreError> {
        let path = self.verifications_path();
        let text = match fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(io_error(&path)(e)),
        };
        Ok(text
            .lines()
            .filter_map(|l| serde_json::from_str(l).ok())
            .collect())
    }
}

/// The default state directory: `$STATE_DIRECTORY` (set by systemd), else
/// `$XDG_STATE_HOME/chromacal`, else `~/.local/state/chromacal`, else `./chromacal-state`.
pub fn default_state_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("STATE_DIRECTORY").filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    if let Some(d) = std::env::var_os("XDG_STATE_HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(d).join("chromacal");
    }
    if let Some(home) = std::env::var_os("HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(home).join(".local/state/chromacal");
    }
    PathBuf::from("chromacal-state")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn publish_replaces_current_and_keeps_history() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path());
        store.publish("a", "first", None, "calibration").unwrap();
        store.publish("b", "second", None, "calibration").unwrap();
        store.keep("c", "rejected").unwrap();
        assert_eq!(fs::read_to_string(store.current_path()).unwrap(), "second");
        assert_eq!(
            fs::read_to_string(store.profile_path("a")).unwrap(),
            "first"
        );
        assert_eq!(
            fs::read_to_string(store.profile_path("c")).unwrap(),
            "rejected"
        );
        let leftovers: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(leftovers.is_empty());
        let history = store.history().unwrap();
        assert_eq!(history.current.as_deref(), Some("b"));
        assert_eq!(history.entries.len(), 2);
    }

    #[test]
    fn rollback_restores_the_previous_profile_and_history_is_bounded() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path()).keeping(3);
        assert!(matches!(
            store.rollback(None),
            Err(StoreError::NoRollback(_))
        ));
        for id in ["a", "b", "c", "d"] {
            store
                .publish(id, &format!("profile {id}"), None, "calibration")
                .unwrap();
        }
        // Only the last three are kept, with their files.
        let history = store.history().unwrap();
        let ids: Vec<&str> = history.entries.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, ["b", "c", "d"]);
        assert!(!store.profile_path("a").exists());
        let entry = store.rollback(None).unwrap();
        assert_eq!((entry.id.as_str(), entry.how.as_str()), ("c", "rollback"));
        assert_eq!(
            fs::read_to_string(store.current_path()).unwrap(),
            "profile c"
        );
        store.rollback(Some("d")).unwrap();
        assert_eq!(
            fs::read_to_string(store.current_path()).unwrap(),
            "profile d"
        );
        assert!(matches!(
            store.rollback(Some("a")),
            Err(StoreError::NoRollback(_))
        ));
        assert_eq!(
            fs::read_to_string(store.current_path()).unwrap(),
            "profile d"
        );
    }

    #[test]
    fn verifications_append_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path());
        let record = VerificationRecord {
            at: "2026-11-23T12:00:00Z".into(),
            profile_id: "a".into(),
            stats: ErrorStats::of(&[0.5, 1.5]),
            delta_e00: vec![0.5, 1.5],
            threshold: 1.0,
            escalated: true,
        };
        store.append_verification(&record).unwrap();
        // A torn line from a crash is skipped.
        let mut f = OpenOptions::new()
            .append(true)
            .open(store.verifications_path())
            .unwrap();
        f.write_all(b"{\"at\": \"2026").unwrap();
        assert_eq!(store.verifications().unwrap(), vec![record]);
    }
}
