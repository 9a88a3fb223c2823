//! The profile store: a state directory with the published profiles and a stable
//! path to the current one.
//!
//! ```text
//! <state>/current.toml          the current profile (replaced atomically)
//! <state>/profiles/<id>.toml    every profile made, published or not
//! <state>/runs/<run-id>/        each calibration run: journal.jsonl, ...
//! ```

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::calibrate::journal::sync_directory;

/// Write `bytes` to `path` so that a crash leaves either the old file or the new one,
/// never a mix: write a temporary file in the same directory, fsync it, rename it over
/// `path`, fsync the directory.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    fs::create_dir_all(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "file".into());
    let temporary = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    {
        let mut f = File::create(&temporary)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    if let Err(e) = fs::rename(&temporary, path) {
        let _ = fs::remove_file(&temporary);
        return Err(e);
    }
    sync_directory(dir);
    Ok(())
}

/// A state directory.
#[derive(Debug, Clone)]
pub struct ProfileStore {
    root: PathBuf,
}

impl ProfileStore {
    pub fn new(root: &Path) -> Self {
        ProfileStore {
            root: root.to_path_buf(),
        }
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

    /// Keep a profile and make it the current one.
    pub fn publish(&self, id: &str, toml: &str) -> std::io::Result<PathBuf> {
        let path = self.keep(id, toml)?;
        write_atomic(&self.current_path(), toml.as_bytes())?;
        Ok(path)
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
        store.publish("a", "first").unwrap();
        store.publish("b", "second").unwrap();
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
    }
}
