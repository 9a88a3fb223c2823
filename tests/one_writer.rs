//! One writer per state directory and per journal (issue 12, item 1), with real
//! processes racing on one store: a second `calibrate` (fresh or `--resume`) or a
//! second daemon is refused with the holder's pid, and the run that holds the store
//! ends with every reading kept exactly once and one history entry.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use chromacal::journal::{Journal, JournalError};
use chromacal::profile::store::ProfileStore;

mod common;
use common::chromacal;
use common::daemon::start_daemon;

/// Wait until `state`'s lock file names a holder, and return what it says.
fn wait_for_holder(state: &Path) -> String {
    let started = Instant::now();
    loop {
        if let Ok(text) = std::fs::read_to_string(state.join("lock"))
            && text.contains("pid")
        {
            return text.trim().to_string();
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no process took the store's lock"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn stderr_of(args: &[&str], state: &Path) -> (bool, String) {
    let out = chromacal()
        .args(args)
        .arg("--state-dir")
        .arg(state)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_second_calibrate_on_one_store_is_refused_and_the_first_keeps_everything_once() {
    let state = tempfile::tempdir().unwrap();
    // About 3 s of real time: long enough to race.
    let mut first = chromacal()
        .args([
            "calibrate",
            "--realtime",
            "--time-scale",
            "0.01",
            "--state-dir",
        ])
        .arg(state.path())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let holder = wait_for_holder(state.path());
    assert_eq!(
        holder,
        format!("chromacal calibrate (pid {})", first.id()),
        "the lock file names its holder"
    );
    for args in [&["calibrate"][..], &["calibrate", "--resume"][..]] {
        let (ok, stderr) = stderr_of(args, state.path());
        assert!(!ok, "{args:?} ran beside the first run");
        assert!(
            stderr.contains("is in use by") && stderr.contains(&format!("pid {}", first.id())),
            "{args:?}: {stderr}"
        );
    }
    assert!(first.wait().unwrap().success());
    // One run, one profile, every planned reading once.
    let store = ProfileStore::new(state.path());
    assert_eq!(store.history().unwrap().entries.len(), 1);
    let runs: Vec<_> = std::fs::read_dir(store.runs_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    let (header, entries, recovery) = Journal::read(&runs[0].join("journal.jsonl")).unwrap();
    assert!(recovery.dropped_tail.is_none());
    let unique: BTreeSet<usize> = entries.iter().map(|m| m.index).collect();
    assert_eq!(unique.len(), entries.len(), "a reading was kept twice");
    assert!(entries.len() >= header.plan.patches.len());
    // With the first run gone the store is free again.
    let (ok, stderr) = stderr_of(&["calibrate"], state.path());
    assert!(ok, "{stderr}");
    assert_eq!(store.history().unwrap().entries.len(), 2);
}

#[test]
fn a_daemon_holds_its_store_against_calibrate_and_a_second_daemon() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start_daemon(dir.path(), "");
    let holder = wait_for_holder(&daemon.state);
    assert!(holder.starts_with("chromacal daemon (pid "), "{holder}");
    let (ok, stderr) = stderr_of(&["calibrate"], &daemon.state);
    assert!(!ok);
    assert!(stderr.contains(&holder), "{stderr}");
    // A second daemon on the same state directory, on another socket.
    let out = chromacal()
        .arg("daemon")
        .arg("--config")
        .arg(dir.path().join("config.toml"))
        .arg("--state-dir")
        .arg(&daemon.state)
        .arg("--socket")
        .arg(dir.path().join("other.sock"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(&holder), "{stderr}");
    assert!(!dir.path().join("other.sock").exists());
}

#[test]
fn a_journal_has_one_writer() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    // A journal made by a real run, then opened for writing twice.
    let (ok, stderr) = stderr_of(&["calibrate"], &state);
    assert!(ok, "{stderr}");
    let run = std::fs::read_dir(state.join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let path = run.join("journal.jsonl");
    let (first, _) = Journal::open(&path).unwrap();
    match Journal::open(&path) {
        Err(JournalError::Busy { path: busy }) => assert_eq!(busy, path),
        other => panic!("a second writer was let in: {:?}", other.map(|_| ())),
    }
    drop(first);
    // Released with the writer. A child another test thread forks in that instant
    // holds a copy of the descriptor, and with it the lock, until it execs (the
    // descriptor is close-on-exec): so a refusal may last that long, not longer.
    let mut last = Journal::open(&path).map(|_| ());
    for _ in 0..100 {
        if !matches!(last, Err(JournalError::Busy { .. })) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
        last = Journal::open(&path).map(|_| ());
    }
    if let Err(e) = last {
        panic!("the journal stayed locked after its writer was dropped: {e}");
    }
}
