//! What a store keeps of finished jobs, so that a daemon left running for years does
//! not fill its disk: `runs/` (calibration journals), `verifications/` and
//! `uniformity/` (the journals of those jobs) would otherwise grow by one folder a job.
//!
//! The rule, applied after each daemon job:
//! * a calibration run that is not finished (no `profile` marker) is never touched:
//!   it may still be resumed;
//! * a finished run whose profile is still in the store is kept: the report reads
//!   its readings;
//! * a finished run whose profile the store has let go (past `daemon.keep_profiles`),
//!   or that was discarded, is *spent*: as many of those as the store keeps profiles
//!   (the newest) stay, for a look back, the older ones are removed;
//! * a profile kept but never published (a calibration the daemon would not make
//!   current: worse than the one it had, or failing its threshold) is kept among the
//!   newest of its like, as many as the store keeps profiles; older ones go (a
//!   published profile is the history's to let go). The run that made it is then
//!   spent, and goes by the rule above;
//! * of the verification and uniformity journals, the newest [`JOB_JOURNALS_KEPT`] of
//!   each kind are kept (each verification's numbers stay in `verifications.jsonl`).

use std::path::{Path, PathBuf};

use super::session::DONE_MARKER;
use crate::profile::store::ProfileStore;

/// Verification and uniformity journals kept, of each kind.
pub const JOB_JOURNALS_KEPT: usize = 50;

/// Folders removed, by kind.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Pruned {
    pub profiles: usize,
    pub runs: usize,
    pub job_journals: usize,
}

/// The entries under `dir` that `wanted` takes, oldest first: by when they last
/// changed (a run's marker is its last write), then by name. (Ids begin with their
/// second, but two started in one second sort by their random part.)
fn oldest_first(dir: &Path, wanted: impl Fn(&std::fs::DirEntry) -> bool) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut found: Vec<(Option<std::time::SystemTime>, PathBuf)> = entries
        .filter_map(|e| e.ok())
        .filter(|e| wanted(e))
        .map(|e| (e.metadata().and_then(|m| m.modified()).ok(), e.path()))
        .collect();
    found.sort();
    found.into_iter().map(|(_, path)| path).collect()
}

/// The folders under `dir`, oldest first.
fn folders(dir: &Path) -> Vec<PathBuf> {
    oldest_first(dir, |e| e.file_type().is_ok_and(|t| t.is_dir()))
}

/// A finished run whose profile is gone from the store's `profiles/`, or that was
/// discarded. (The marker names the profile's path as it was written, perhaps
/// relative to another directory: its file name is looked for in the store.)
fn spent(store: &ProfileStore, run: &Path) -> bool {
    match std::fs::read_to_string(run.join(DONE_MARKER)) {
        Ok(marker) => {
            let marker = marker.trim();
            marker == "discarded"
                || Path::new(marker)
                    .file_name()
                    .is_some_and(|name| !store.root().join("profiles").join(name).exists())
        }
        // Unfinished (or unreadable): kept.
        Err(_) => false,
    }
}

/// Remove all but the newest `keep` of `found` (oldest first) with `remove`; how many
/// went. One that cannot be removed is logged and left.
fn remove_oldest(
    found: &[PathBuf],
    keep: usize,
    remove: fn(&Path) -> std::io::Result<()>,
) -> usize {
    let excess = found.len().saturating_sub(keep);
    found[..excess]
        .iter()
        .filter(|path| match remove(path) {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(path = %path.display(), error = %e, "cannot remove an old job folder or profile");
                false
            }
        })
        .count()
}

/// The profile files in `store` that its history does not name, oldest first. A
/// history that cannot be read names nothing for certain: then none are listed.
fn unpublished_profiles(store: &ProfileStore) -> Vec<PathBuf> {
    let Ok(history) = store.history() else {
        return Vec::new();
    };
    let published = |id: &str| {
        history.current.as_deref() == Some(id) || history.entries.iter().any(|e| e.id == id)
    };
    oldest_first(&store.root().join("profiles"), |e| {
        let path = e.path();
        let id = path.file_stem().map(|s| s.to_string_lossy().into_owned());
        e.file_type().is_ok_and(|t| t.is_file())
            && path.extension().is_some_and(|x| x == "toml")
            && id.is_some_and(|id| crate::profile::store::is_valid_id(&id) && !published(&id))
    })
}

/// Apply the rule to `store`, keeping as many spent runs, and as many unpublished
/// profiles, as it keeps profiles.
pub fn prune_finished(store: &ProfileStore) -> Pruned {
    let profiles = remove_oldest(&unpublished_profiles(store), store.kept(), |p| {
        std::fs::remove_file(p)
    });
    let spent_runs: Vec<PathBuf> = folders(&store.runs_dir())
        .into_iter()
        .filter(|run| spent(store, run))
        .collect();
    let runs = remove_oldest(&spent_runs, store.kept(), |p| std::fs::remove_dir_all(p));
    let job_journals = ["verifications", "uniformity"]
        .iter()
        .map(|kind| {
            remove_oldest(&folders(&store.root().join(kind)), JOB_JOURNALS_KEPT, |p| {
                std::fs::remove_dir_all(p)
            })
        })
        .sum();
    let pruned = Pruned {
        profiles,
        runs,
        job_journals,
    };
    if pruned != Pruned::default() {
        tracing::info!(
            store = %store.root().display(),
            profiles,
            runs,
            job_journals,
            "removed old job folders and profiles (unpublished profiles, spent calibration runs, old verification and uniformity journals)"
        );
    }
    pruned
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(store: &ProfileStore, id: &str, marker: Option<&str>) -> PathBuf {
        let dir = store.runs_dir().join(id);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("journal.jsonl"), "{}\n").unwrap();
        if let Some(marker) = marker {
            std::fs::write(dir.join(DONE_MARKER), marker).unwrap();
        }
        dir
    }

    #[test]
    fn spent_runs_beyond_the_newest_few_go_and_nothing_that_may_be_read_or_resumed_does() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path()).keeping(2);
        let profiles = dir.path().join("profiles");
        std::fs::create_dir_all(&profiles).unwrap();
        let kept_profile = profiles.join("20260102T000000-aaaa.toml");
        std::fs::write(&kept_profile, "").unwrap();
        // Oldest first: a discarded run, a run whose profile was let go, a run whose
        // profile is kept, an unfinished one, then three more discarded.
        let discarded_old = run(&store, "20260101T000000-0001", Some("discarded\n"));
        let gone = run(
            &store,
            "20260101T000000-0002",
            Some(
                &profiles
                    .join("20260101T000000-gone.toml")
                    .display()
                    .to_string(),
            ),
        );
        let referenced = run(
            &store,
            "20260101T000000-0003",
            Some(&kept_profile.display().to_string()),
        );
        let unfinished = run(&store, "20260101T000000-0004", None);
        let newer: Vec<PathBuf> = (5..8)
            .map(|k| {
                run(
                    &store,
                    &format!("20260101T000000-000{k}"),
                    Some("discarded"),
                )
            })
            .collect();
        for k in 0..(JOB_JOURNALS_KEPT + 3) {
            std::fs::create_dir_all(dir.path().join(format!("verifications/verify-{k:04}")))
                .unwrap();
        }
        let pruned = prune_finished(&store);
        assert_eq!(
            pruned,
            Pruned {
                profiles: 0,
                runs: 3,
                job_journals: 3
            }
        );
        assert!(!discarded_old.exists() && !gone.exists() && !newer[0].exists());
        assert!(referenced.exists() && unfinished.exists());
        assert!(newer[1].exists() && newer[2].exists());
        let left = folders(&dir.path().join("verifications"));
        assert_eq!(left.len(), JOB_JOURNALS_KEPT);
        assert!(left[0].ends_with("verify-0003"));
        // Applied again, nothing more goes.
        assert_eq!(prune_finished(&store), Pruned::default());
    }

    #[test]
    fn unpublished_profiles_beyond_the_newest_few_go_with_their_runs_and_published_ones_stay() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path()).keeping(2);
        // Two published, then four kept but not published, a run for each.
        let ids: Vec<String> = (0..6).map(|k| format!("20260101T00000{k}-abcd")).collect();
        let mut runs = Vec::new();
        for (k, id) in ids.iter().enumerate() {
            let path = if k < 2 {
                store.publish(id, "published", None, "test").unwrap()
            } else {
                store.keep(id, "not published").unwrap()
            };
            runs.push(run(&store, id, Some(&path.display().to_string())));
            // Distinct modification times, oldest first.
            let at = std::time::SystemTime::UNIX_EPOCH
                + std::time::Duration::from_secs(1_000 + k as u64);
            std::fs::File::options()
                .write(true)
                .open(&path)
                .unwrap()
                .set_modified(at)
                .unwrap();
        }
        let pruned = prune_finished(&store);
        assert_eq!(pruned.profiles, 2, "{pruned:?}");
        let profile = |id: &str| store.profile_path(id).unwrap();
        assert!(
            profile(&ids[0]).exists() && profile(&ids[1]).exists(),
            "published stay"
        );
        assert!(!profile(&ids[2]).exists() && !profile(&ids[3]).exists());
        assert!(profile(&ids[4]).exists() && profile(&ids[5]).exists());
        // The runs of the removed profiles are now spent: within the number kept.
        assert!(runs[4].exists() && runs[5].exists() && runs[0].exists() && runs[1].exists());
        assert_eq!(prune_finished(&store).profiles, 0);
    }
}
