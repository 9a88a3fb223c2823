//! Files that survive a crash or a power cut: a directory entry made durable, and a
//! file replaced whole or not at all. The journal, the profile store and the daemon's
//! history are written through these. And reads with a size limit, so that a path
//! to `/dev/zero` or a runaway file is refused instead of filling the memory.

use std::fs::{self, File};
use std::io::{Read, Write};
use std::path::Path;

/// Largest file of each kind chromacal reads, bytes.
pub mod limits {
    /// A config file.
    pub const CONFIG: u64 = 1 << 20;
    /// A profile, `history.json`, a token file.
    pub const PROFILE: u64 = 16 << 20;
    /// A run's journal (a 1,400-patch run with spectra is about 15 MB).
    pub const JOURNAL: u64 = 1 << 30;
    /// A measurement file (CGATS, `.ti3`, CSV) or a numeric table.
    pub const TABLE: u64 = 256 << 20;
}

/// Read at most `limit` bytes from `reader`; more is an error that names the limit.
pub fn read_limited_from(reader: impl Read, limit: u64) -> std::io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    reader.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("larger than {limit} bytes: not a file of this kind"),
        ));
    }
    Ok(bytes)
}

/// `path` opened for reading if it is a regular file (or a link to one). Opening a
/// FIFO blocks until something writes to it, and reading a device may never end: an
/// input named by a user must be a file, and saying so beats hanging.
pub fn open_regular(path: &Path) -> std::io::Result<File> {
    let kind = fs::metadata(path)?.file_type();
    if !kind.is_file() {
        use std::os::unix::fs::FileTypeExt;
        let what = if kind.is_dir() {
            "a directory"
        } else if kind.is_fifo() {
            "a FIFO (named pipe)"
        } else if kind.is_socket() {
            "a socket"
        } else {
            "a device"
        };
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("is {what}, not a regular file"),
        ));
    }
    File::open(path)
}

/// The whole of `path`, if it is a regular file of at most `limit` bytes.
pub fn read_limited(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    read_limited_from(open_regular(path)?, limit)
}

/// The whole of `path` as UTF-8 text, if it is a regular file of at most `limit` bytes.
pub fn read_text_limited(path: &Path, limit: u64) -> std::io::Result<String> {
    read_text_limited_from(open_regular(path)?, limit)
}

/// All of `reader` as UTF-8 text, if it is at most `limit` bytes.
pub fn read_text_limited_from(reader: impl Read, limit: u64) -> std::io::Result<String> {
    String::from_utf8(read_limited_from(reader, limit)?).map_err(|_| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "stream did not contain valid UTF-8",
        )
    })
}

/// fsync a directory so a new or renamed entry in it survives a power cut. Best
/// effort: not every file system lets a directory be opened for this.
pub fn sync_directory(dir: &Path) {
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

/// State directories: what chromacal keeps there (profiles it loads into the video
/// LUT and serves, journals, tokens) is the user's alone, whatever the umask.
static PRIVATE_ROOTS: std::sync::Mutex<Vec<std::path::PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Keep `root` private: created (with any missing parent) 0700, everything written
/// under it by [`write_atomic`], [`create_dir`] and [`open_options`] 0700 and 0600,
/// whatever the process's umask. A `root` that exists and that others may write is
/// refused, with the `chmod` that fixes it: another user could replace the current
/// profile in it.
pub fn keep_private(root: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
    mark_private(root);
    fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(root)?;
    let mode = fs::metadata(root)?.permissions().mode();
    if mode & 0o022 != 0 {
        return Err(std::io::Error::new(
            std::io::ErrorKind::PermissionDenied,
            format!(
                "{} may be written by other users (mode {:o}), who could replace the profiles chromacal loads and serves: run `chmod -R go-w {}` (or give another --state-dir)",
                root.display(),
                mode & 0o777,
                root.display()
            ),
        ));
    }
    Ok(())
}

/// What is written under `root` from now on is private, as with [`keep_private`],
/// which also creates and checks it.
pub fn mark_private(root: &Path) {
    if let Ok(mut roots) = PRIVATE_ROOTS.lock()
        && !roots.iter().any(|r| r == root)
    {
        roots.push(root.to_path_buf());
    }
}

/// Whether `path` lies in a directory given to [`keep_private`].
pub fn is_private(path: &Path) -> bool {
    PRIVATE_ROOTS
        .lock()
        .map(|roots| roots.iter().any(|r| path.starts_with(r)))
        .unwrap_or(false)
}

/// `fs::create_dir_all`, 0700 in a private directory.
pub fn create_dir(dir: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::DirBuilderExt;
    let mut builder = fs::DirBuilder::new();
    builder.recursive(true);
    if is_private(dir) {
        builder.mode(0o700);
    }
    builder.create(dir)
}

/// `OpenOptions` for a file at `path`: created 0600 in a private directory.
pub fn open_options(path: &Path) -> fs::OpenOptions {
    use std::os::unix::fs::OpenOptionsExt;
    let mut options = fs::OpenOptions::new();
    if is_private(path) {
        options.mode(0o600);
    }
    options
}

/// A lock file taken, or the words of who holds it.
#[derive(Debug)]
pub enum Lock {
    Taken(File),
    /// Another process holds it; what it wrote there (trimmed, maybe empty).
    HeldBy(String),
}

/// Take the advisory lock (`flock`) on `path`, created as [`open_options`] creates
/// files, and write `holder (pid N)` into it for the next comer; the lock goes with
/// the returned file (and with the process: a kill -9 releases it).
pub fn lock_file(path: &Path, holder: &str) -> std::io::Result<Lock> {
    let mut file = open_options(path)
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(fs::TryLockError::WouldBlock) => {
            let words = fs::read_to_string(path).unwrap_or_default();
            return Ok(Lock::HeldBy(words.trim().to_string()));
        }
        Err(fs::TryLockError::Error(e)) => return Err(e),
    }
    // The line in one write: `writeln!` on a file writes each piece apart, and a
    // process refused in between read "chromacal calibrate (pid" without the pid.
    let line = format!("{holder} (pid {})\n", std::process::id());
    file.set_len(0)?;
    file.write_all(line.as_bytes())?;
    file.sync_all()?;
    Ok(Lock::Taken(file))
}

/// [`write_atomic`] to a path a user named (`-o`): its directory must exist already.
/// A mistyped directory is an error that names it, as any other program's would be,
/// not a tree of new directories (`report -o /nonexistent/r.html` made `/nonexistent`).
pub fn write_atomic_named(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    require_parent_dir(path)?;
    write_atomic(path, bytes)
}

/// That the directory `path` would be written in exists (the current one for a bare
/// file name): checked by [`write_atomic_named`], and before a run whose output is
/// written at its end.
pub fn require_parent_dir(path: &Path) -> std::io::Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if dir.is_dir() {
        return Ok(());
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::NotFound,
        format!("no such directory: {}", dir.display()),
    ))
}

/// Write `bytes` to `path` so that a crash leaves either the old file or the new one,
/// never a mix: write a temporary file in the same directory, fsync it, rename it over
/// `path`, fsync the directory.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    create_dir(dir)?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "file".into());
    // Unique per call, so two threads replacing one file never share a temporary.
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let temporary = dir.join(format!(".{name}.tmp-{}-{n}", std::process::id()));
    // Whatever fails (a full disk while writing, the rename), no temporary is left.
    let written = open_options(path)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&temporary)
        .and_then(|mut f| {
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
