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

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use chromacal_formats::durable::{Lock, write_atomic};
use chromacal_model::fit::stats::ErrorStats;

use chromacal_color::difference::Metric;

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
    #[error(
        "{path} is in use by {holder}: one process at a time may write a state directory (stop it, or give this one another --state-dir)"
    )]
    Locked { path: PathBuf, holder: String },
    #[error(
        "'{0}' is not a profile id of this store (ids are letters, digits, '-', '_' and '.', at most {MAX_ID_LEN} characters, without '..')"
    )]
    InvalidId(String),
}

/// Longest profile id the store accepts.
pub const MAX_ID_LEN: usize = 128;

/// Is `id` of the form the store gives its profiles (a run id, with its job kind or
/// `-uniformity`, or a run directory's name)? Only such ids are ever joined into a
/// path, so an id can never name a file outside `profiles/` (no separator, no `..`,
/// not absolute).
pub fn is_valid_id(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= MAX_ID_LEN
        && !id.contains("..")
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
}

fn checked_id(id: &str) -> Result<&str, StoreError> {
    if is_valid_id(id) {
        Ok(id)
    } else {
        Err(StoreError::InvalidId(id.to_string()))
    }
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
    /// What `stats`, `delta_e` and `threshold` measure: ΔE00, or ΔE ITP (BT.2124)
    /// for a profile of an HDR signal, whose light is absolute and whose error near
    /// black ΔE00 relative to the white does not see. Records written before HDR
    /// profiles were judged in ΔE ITP read as ΔE00.
    #[serde(default)]
    pub metric: Metric,
    /// The error over the patches, in `metric`.
    pub stats: Option<ErrorStats>,
    /// Each patch's error in `metric`, in the order measured.
    #[serde(alias = "delta_e00")]
    pub delta_e: Vec<f64>,
    /// The mean error (in `metric`) past which a recalibration is started.
    pub threshold: f64,
    /// A recalibration was started because of it.
    pub escalated: bool,
    /// The verification's readings (its run journal), for the report's verification
    /// sections.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub journal: Option<String>,
    /// For a chart measured through the calibration curves (`chromacal verify`, and
    /// the end of a calibration or of the daemon's verify job): the verdict under its
    /// criteria, pass, fail or undecided. None for the profile's own check.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<String>,
}

impl VerificationRecord {
    /// Its mean within its threshold (no patches read, or a mean that is not a
    /// number: not passed), and no failing verdict.
    pub fn passed(&self) -> bool {
        self.stats.is_some_and(|s| s.mean <= self.threshold)
            && self.verdict.as_deref() != Some("fail")
    }
}

fn now_rfc3339() -> String {
    chromacal_formats::time::now_rfc3339()
}

/// Profiles kept in the history unless configured otherwise.
pub const DEFAULT_KEEP: usize = 10;

/// A state directory.
#[derive(Debug, Clone)]
pub struct ProfileStore {
    root: PathBuf,
    /// Profiles kept in the history; older ones (and their files) are removed.
    keep: usize,
    /// Serialises this process's read-modify-writes of `history.json` (a daemon's
    /// rollback and a job's publish may run at once); other processes are kept out by
    /// [`ProfileStore::lock`].
    history_guard: std::sync::Arc<std::sync::Mutex<()>>,
}

/// The advisory lock on a state directory (`<state>/lock`, `flock`), held while the
/// value lives: one writer per store, whether a daemon or a `calibrate`.
#[derive(Debug)]
pub struct StoreLock {
    file: fs::File,
}

impl Drop for StoreLock {
    /// Leave no stale holder behind (best effort: a kill -9 leaves the text, but not
    /// the lock, and the next holder writes its own).
    fn drop(&mut self) {
        let _ = self.file.set_len(0);
    }
}

impl ProfileStore {
    /// The store at `root`; what is written in it is private (see
    /// `durable::keep_private`, which [`ProfileStore::lock`] also checks).
    pub fn new(root: &Path) -> Self {
        chromacal_formats::durable::mark_private(root);
        ProfileStore {
            root: root.to_path_buf(),
            keep: DEFAULT_KEEP,
            history_guard: Default::default(),
        }
    }

    pub fn lock_path(&self) -> PathBuf {
        self.root.join("lock")
    }

    /// Take the store's lock for `what` (e.g. "chromacal daemon"), or say who holds it.
    /// The holder's pid and `what` are written into the lock file for the next comer;
    /// the lock goes with the process (a kill -9 releases it).
    pub fn lock(&self, what: &str) -> Result<StoreLock, StoreError> {
        chromacal_formats::durable::keep_private(&self.root).map_err(io_error(&self.root))?;
        let path = self.lock_path();
        match chromacal_formats::durable::lock_file(&path, what).map_err(io_error(&path))? {
            Lock::Taken(file) => Ok(StoreLock { file }),
            Lock::HeldBy(words) => Err(StoreError::Locked {
                holder: if words.is_empty() {
                    "another process".into()
                } else {
                    words
                },
                path,
            }),
        }
    }

    /// Keep the last `n` current profiles (at least 2, so there is one to roll back to).
    pub fn keeping(mut self, n: usize) -> Self {
        self.keep = n.max(2);
        self
    }

    /// How many current profiles it keeps.
    pub fn kept(&self) -> usize {
        self.keep
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    pub fn current_path(&self) -> PathBuf {
        self.root.join("current.toml")
    }

    /// The file of profile `id`; an id not of the store's form has none.
    pub fn profile_path(&self, id: &str) -> Result<PathBuf, StoreError> {
        Ok(self
            .root
            .join("profiles")
            .join(format!("{}.toml", checked_id(id)?)))
    }

    pub fn runs_dir(&self) -> PathBuf {
        self.root.join("runs")
    }

    /// Keep a profile in the store without making it current.
    pub fn keep(&self, id: &str, toml: &str) -> std::io::Result<PathBuf> {
        let path = self
            .profile_path(id)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
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
        let _guard = self.guard();
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
        match chromacal_formats::durable::read_text_limited(
            &path,
            chromacal_formats::durable::limits::PROFILE,
        ) {
            Ok(text) => serde_json::from_str(&text).map_err(|e| StoreError::Corrupt {
                path: path.clone(),
                message: e.to_string(),
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(History::default()),
            Err(e) => Err(io_error(&path)(e)),
        }
    }

    /// This process's turn at `current.toml` and `history.json`: held across a whole
    /// publish or rollback, so the two always name the same profile. A poisoned guard
    /// only means another thread panicked mid-update; the files are whole (written
    /// atomically), so go on.
    fn guard(&self) -> std::sync::MutexGuard<'_, ()> {
        self.history_guard
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Add `id` as current to the history, and drop the oldest entries (and their
    /// profile files) past the number kept. The caller holds [`Self::guard`].
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
            // An id not of the store's form (a hand-edited history) names no file.
            if let (false, Ok(file)) = (
                history.entries.iter().any(|e| e.id == old.id),
                self.profile_path(&old.id),
            ) {
                let _ = fs::remove_file(file);
            }
        }
        Ok(())
    }

    /// Make an earlier profile current again: `to`, or else the one current before
    /// the current one. `to` must be an id of the store's form that the history holds,
    /// and its file must read as a profile, before anything is replaced. Returns the
    /// new history entry.
    pub fn rollback(&self, to: Option<&str>) -> Result<HistoryEntry, StoreError> {
        let _guard = self.guard();
        let history = self.history()?;
        let current = history.current.clone();
        let target = match to {
            Some(id) => {
                checked_id(id)?;
                if !history.entries.iter().any(|e| e.id == id) {
                    return Err(StoreError::NoRollback(format!(
                        "profile '{id}' is not in the history (chromacal history lists it)"
                    )));
                }
                id.to_string()
            }
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
        let path = self.profile_path(&target)?;
        let text = chromacal_formats::durable::read_text_limited(
            &path,
            chromacal_formats::durable::limits::PROFILE,
        )
        .map_err(|e| {
            StoreError::NoRollback(format!("profile '{target}' is not in the store ({e})"))
        })?;
        let profile =
            super::Profile::from_toml(&text, &path.display().to_string()).map_err(|e| {
                StoreError::NoRollback(format!(
                    "profile '{target}' does not read as a profile: {e}"
                ))
            })?;
        if profile.id != target {
            return Err(StoreError::NoRollback(format!(
                "the file of profile '{target}' holds profile '{}'",
                profile.id
            )));
        }
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
        chromacal_formats::durable::create_dir(&self.root).map_err(io_error(&self.root))?;
        let mut file = chromacal_formats::durable::open_options(&path)
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
        let text = match chromacal_formats::durable::read_text_limited(
            &path,
            chromacal_formats::durable::limits::JOURNAL,
        ) {
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
            fs::read_to_string(store.profile_path("a").unwrap()).unwrap(),
            "first"
        );
        assert_eq!(
            fs::read_to_string(store.profile_path("c").unwrap()).unwrap(),
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

    /// A real profile's TOML with id `id` (rollback reads what it restores), fitted
    /// once to a simulated run.
    fn profile_text(id: &str) -> String {
        static FITTED: std::sync::OnceLock<chromacal_model::fit::FittedModel> =
            std::sync::OnceLock::new();
        let fitted = FITTED.get_or_init(|| {
            let config = crate::config::parse_config("", "test").unwrap();
            let dir = tempfile::tempdir().unwrap();
            let journal =
                crate::calibrate::session::block_on(crate::calibrate::session::measure_simulated(
                    &config,
                    "",
                    Path::new("."),
                    &dir.path().join("journal.jsonl"),
                ))
                .unwrap()
                .unwrap();
            chromacal_model::fit::fit_monitor(&journal.measurement_set(), &Default::default())
                .unwrap()
        });
        super::super::Profile {
            schema_version: super::super::SCHEMA_VERSION,
            id: id.to_string(),
            created: "2026-12-01T00:00:00Z".into(),
            units: chromacal_model::measurement::Units::Absolute,
            model: fitted.model.clone(),
            provenance: super::super::Provenance {
                source: "test".into(),
                display: None,
                instrument: None,
                measured_at: None,
                config_digest: None,
                program: "test".into(),
                settings_at_resume: None,
                edid: None,
                correction: None,
                uncorrected: None,
                signal: None,
            },
            report: fitted.report.clone(),
            calibration: None,
            cost: None,
        }
        .to_toml()
        .unwrap()
    }

    fn current_id(store: &ProfileStore) -> String {
        let text = fs::read_to_string(store.current_path()).unwrap();
        super::super::Profile::from_toml(&text, "current")
            .unwrap()
            .id
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
                .publish(id, &profile_text(id), None, "calibration")
                .unwrap();
        }
        // Only the last three are kept, with their files.
        let history = store.history().unwrap();
        let ids: Vec<&str> = history.entries.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, ["b", "c", "d"]);
        assert!(!store.profile_path("a").unwrap().exists());
        let entry = store.rollback(None).unwrap();
        assert_eq!((entry.id.as_str(), entry.how.as_str()), ("c", "rollback"));
        assert_eq!(current_id(&store), "c");
        store.rollback(Some("d")).unwrap();
        assert_eq!(current_id(&store), "d");
        assert!(matches!(
            store.rollback(Some("a")),
            Err(StoreError::NoRollback(_))
        ));
        assert_eq!(current_id(&store), "d");
    }

    #[test]
    fn ids_that_would_leave_the_store_are_refused_and_nothing_outside_is_touched() {
        let dir = tempfile::tempdir().unwrap();
        let state = dir.path().join("state");
        let store = ProfileStore::new(&state).keeping(2);
        for id in ["a", "b"] {
            store
                .publish(id, &profile_text(id), None, "calibration")
                .unwrap();
        }
        // A readable profile outside the store, as an attacker would plant it.
        let outside = dir.path().join("outside");
        fs::create_dir_all(&outside).unwrap();
        fs::write(outside.join("evil.toml"), profile_text("evil")).unwrap();
        let absolute = outside.join("evil").display().to_string();
        for id in [
            "../../outside/evil",
            absolute.as_str(),
            "../current",
            "a/b",
            "",
        ] {
            assert!(
                matches!(store.rollback(Some(id)), Err(StoreError::InvalidId(_))),
                "{id:?} was not refused as an id"
            );
            assert_eq!(current_id(&store), "b", "after {id:?}");
            assert!(store.current_path().exists(), "after {id:?}");
        }
        // A history edited by hand to hold an outside id: pruning it deletes nothing
        // outside `profiles/`, and rolling back to it is still refused.
        let mut history = store.history().unwrap();
        history.entries.insert(
            0,
            HistoryEntry {
                id: "../../outside/evil".into(),
                at: "2026-12-01T00:00:00Z".into(),
                how: "calibration".into(),
                held_out: None,
            },
        );
        fs::write(
            store.history_path(),
            serde_json::to_string(&history).unwrap(),
        )
        .unwrap();
        assert!(matches!(
            store.rollback(Some("../../outside/evil")),
            Err(StoreError::InvalidId(_))
        ));
        store
            .publish("c", &profile_text("c"), None, "calibration")
            .unwrap();
        let ids: Vec<String> = store
            .history()
            .unwrap()
            .entries
            .into_iter()
            .map(|e| e.id)
            .collect();
        assert_eq!(ids, ["b", "c"]);
        assert!(outside.join("evil.toml").exists());
        // A profile of the store's form whose file is not a profile is not made current.
        fs::write(store.profile_path("b").unwrap(), "not a profile").unwrap();
        assert!(matches!(
            store.rollback(Some("b")),
            Err(StoreError::NoRollback(why)) if why.contains("does not read as a profile")
        ));
        assert_eq!(current_id(&store), "c");
        // Keeping a profile under a bad id is refused too.
        assert!(store.keep("../x", "anything").is_err());
        assert!(!state.join("x.toml").exists());
    }

    #[test]
    fn publishing_and_rolling_back_at_once_leave_current_and_history_agreeing() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path()).keeping(50);
        for id in ["a", "b"] {
            store
                .publish(id, &profile_text(id), None, "calibration")
                .unwrap();
        }
        let texts: Vec<(String, String)> = (0..20)
            .map(|k| (format!("p{k}"), profile_text(&format!("p{k}"))))
            .collect();
        std::thread::scope(|scope| {
            let publisher = store.clone();
            scope.spawn(move || {
                for (id, text) in &texts {
                    publisher.publish(id, text, None, "calibration").unwrap();
                }
            });
            let roller = store.clone();
            scope.spawn(move || {
                for _ in 0..20 {
                    roller.rollback(None).unwrap();
                }
            });
        });
        let history = store.history().unwrap();
        // No update lost: two to start, twenty published, twenty rollbacks.
        assert_eq!(history.entries.len(), 42, "history entries were lost");
        assert_eq!(
            Some(current_id(&store)),
            history.current,
            "current.toml and history.json name different profiles"
        );
        let leftovers = fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .count();
        assert_eq!(leftovers, 0);
    }

    #[test]
    fn the_store_accepts_its_own_ids() {
        for id in [
            "20261201T223403-ab12",
            "calibrate-20261201T223403-ab12",
            "20261201T223403-ab12-uniformity",
            "dell_u2713hm.v2",
            ".tmpGVcBoq",
        ] {
            assert!(is_valid_id(id), "{id}");
        }
        for id in ["a/b", "a\\b", "..", "a..b", "/abs", "a b", "é"] {
            assert!(!is_valid_id(id), "{id}");
        }
        assert!(!is_valid_id(&"x".repeat(MAX_ID_LEN + 1)));
    }

    #[test]
    fn verifications_append_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path());
        let record = VerificationRecord {
            at: "2026-11-23T12:00:00Z".into(),
            profile_id: "a".into(),
            metric: Metric::Itp,
            stats: ErrorStats::of(&[0.5, 1.5]),
            delta_e: vec![0.5, 1.5],
            threshold: 1.0,
            escalated: true,
            journal: None,
            verdict: None,
        };
        store.append_verification(&record).unwrap();
        // A torn line from a crash is skipped.
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(store.verifications_path())
            .unwrap();
        f.write_all(b"{\"at\": \"2026").unwrap();
        assert_eq!(store.verifications().unwrap(), vec![record.clone()]);
        assert!(record.passed(), "a mean of 1.0 is within 1.0");
    }

    #[test]
    fn a_verification_written_before_hdr_reads_as_de00() {
        let line = r#"{"at":"2026-11-23T12:00:00Z","profile_id":"a","stats":null,"delta_e00":[0.5],"threshold":1.0,"escalated":false}"#;
        let record: VerificationRecord = serde_json::from_str(line).unwrap();
        assert_eq!(record.metric, Metric::De00);
        assert_eq!(record.delta_e, vec![0.5]);
        assert!(!record.passed(), "no stats");
    }
}
