//! Files that survive a crash or a power cut: a directory entry made durable, and a
//! file replaced whole or not at all. The journal, the profile store and the daemon's
//! history are written through these.

use std::fs::{self, File};
use std::io::Write;
use std::path::Path;

/// fsync a directory so a new or renamed entry in it survives a power cut. Best
/// effort: not every file system lets a directory be opened for this.
pub fn sync_directory(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

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
    // Unique per call, so two threads replacing one file never share a temporary.
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let temporary = dir.join(format!(".{name}.tmp-{}-{n}", std::process::id()));
    // Whatever fails (a full disk while writing, the rename), no temporary is left.
    let written = File::create(&temporary).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    if let Err(e) = written.and_then(|()| fs::rename(&temporary, path)) {
        let _ = fs::remove_file(&temporary);
        return Err(e);
    }
    sync_directory(dir);
    Ok(())
}
