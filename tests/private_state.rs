//! The state tree is the user's alone whatever the umask: another local user who
//! could write `current.toml` would have the daemon serve it, load it into the video
//! LUT and publish it. Under `umask 000` a calibration leaves directories 0700 and
//! files 0600; a state directory others may write is refused with the `chmod` to run.

use std::os::unix::fs::PermissionsExt;
use std::path::Path;

mod common;

fn chromacal_under_umask_000(args: &str) -> std::process::Output {
    std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "umask 000 && exec \"{}\" {args}",
            env!("CARGO_BIN_EXE_chromacal")
        ))
        .env("XDG_CONFIG_HOME", "/nonexistent/chromacal-tests-config")
        .output()
        .unwrap()
}

/// Every entry under `dir` with its mode.
fn modes(dir: &Path, out: &mut Vec<(std::path::PathBuf, u32, bool)>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let meta = entry.metadata().unwrap();
        out.push((
            entry.path(),
            meta.permissions().mode() & 0o777,
            meta.is_dir(),
        ));
        if meta.is_dir() {
            modes(&entry.path(), out);
        }
    }
}

#[test]
fn under_umask_000_the_state_tree_is_private_and_a_writable_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let config = dir.path().join("config.toml");
    std::fs::write(&config, "[target]\nwhite = \"D65\"\ntone = \"gamma:2.2\"\n").unwrap();
    let out = chromacal_under_umask_000(&format!(
        "calibrate --config {} --state-dir {}",
        config.display(),
        state.display()
    ));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let root = std::fs::metadata(&state).unwrap().permissions().mode() & 0o777;
    assert_eq!(root, 0o700);
    let mut entries = Vec::new();
    modes(&state, &mut entries);
    assert!(entries.len() >= 6, "{entries:?}");
    assert!(entries.iter().any(|(p, _, _)| p.ends_with("current.toml")));
    for (path, mode, is_dir) in &entries {
        let expected = if *is_dir { 0o700 } else { 0o600 };
        assert_eq!(*mode, expected, "{} is {mode:o}", path.display());
    }

    // A state directory others may write: refused, with the chmod to run, and nothing
    // measured in it.
    let open = dir.path().join("open");
    std::fs::create_dir(&open).unwrap();
    std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o777)).unwrap();
    let out = chromacal_under_umask_000(&format!(
        "calibrate --config {} --state-dir {}",
        config.display(),
        open.display()
    ));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("chmod -R go-w {}", open.display())),
        "{stderr}"
    );
    assert_eq!(std::fs::read_dir(&open).unwrap().count(), 0);
}

/// The current profile's id names files in the store: one written by another hand
/// with `../` in it is refused, and nothing is written outside the store.
#[test]
fn a_current_profile_whose_id_leaves_the_store_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let config = dir.path().join("config.toml");
    std::fs::write(&config, "[target]\nwhite = \"D65\"\ntone = \"gamma:2.2\"\n").unwrap();
    let out = common::succeed(
        common::chromacal()
            .args(["calibrate", "--config"])
            .arg(&config)
            .arg("--state-dir")
            .arg(&state),
    );
    assert!(out.status.success());
    let current = state.join("current.toml");
    let text = std::fs::read_to_string(&current).unwrap();
    let id_line = text.lines().find(|l| l.starts_with("id = ")).unwrap();
    std::fs::write(&current, text.replace(id_line, "id = \"../../escaped\"")).unwrap();
    let out = common::chromacal()
        .args(["verify", "--config"])
        .arg(&config)
        .arg("--state-dir")
        .arg(&state)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("'../../escaped' is not a profile id"),
        "{stderr}"
    );
    assert!(!dir.path().join("escaped.json").exists());
}
