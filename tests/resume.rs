//! A run killed part way resumes from its journal: nothing measured twice, nothing
//! lost, and the same profile as a run that was never stopped.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use chromacal::calibrate::session::{CalibrateOptions, calibrate, measure_simulated};
use chromacal::config::{load_config, parse_config};
use chromacal::journal::Journal;
use chromacal::profile::Profile;

mod common;
use common::{LCD_CONFIG, chromacal, fixture};

fn indices(journal: &Path) -> Vec<usize> {
    let (_, entries, _) = Journal::read(journal).unwrap();
    entries.iter().map(|m| m.index).collect()
}

fn assert_complete_and_unique(journal: &Path) {
    let (header, entries, recovery) = Journal::read(journal).unwrap();
    assert!(recovery.dropped_tail.is_none());
    let mut seen: Vec<usize> = entries.iter().map(|m| m.index).collect();
    seen.sort();
    let plan: Vec<usize> = header.plan.patches.iter().map(|p| p.index).collect();
    assert_eq!(seen, plan, "every planned patch exactly once");
}

/// The recorded interrupted LCD run (40 readings, then a torn line) resumes to exactly
/// the readings an uninterrupted run takes: the simulated noise depends only on the
/// virtual time, which the journal restores.
#[tokio::test]
async fn an_interrupted_journal_resumes_to_the_uninterrupted_readings() {
    let state = tempfile::tempdir().unwrap();
    let run_dir = state.path().join("runs/interrupted");
    std::fs::create_dir_all(&run_dir).unwrap();
    let journal = run_dir.join("journal.jsonl");
    std::fs::copy(fixture("journals/lcd-interrupted.jsonl"), &journal).unwrap();
    let before = Journal::read(&journal).unwrap().1;
    assert_eq!(before.len(), 40);

    let loaded = load_config(None).unwrap(); // ignored on resume: the journal's config wins
    let options = CalibrateOptions {
        state_dir: state.path().to_path_buf(),
        resume: Some(chromacal::calibrate::session::Resume::Newest),
        resume_settings: false,
        realtime_scale: None,
        overrides: Default::default(),
        stop: None,
    };
    let outcome = calibrate(&loaded, &options, &mut |_| {}, None)
        .await
        .unwrap();
    assert_eq!(outcome.run.already_measured, 40);
    assert_eq!(outcome.run.measured_now, 96 - 40);
    assert_complete_and_unique(&journal);
    let (_, after, _) = Journal::read(&journal).unwrap();
    assert_eq!(
        &after[..40],
        &before[..],
        "the readings taken before are kept as they were"
    );

    // The same run, never interrupted.
    let whole_dir = tempfile::tempdir().unwrap();
    let config = parse_config(LCD_CONFIG, "lcd").unwrap();
    let whole = measure_simulated(
        &config,
        LCD_CONFIG,
        Path::new("."),
        &whole_dir.path().join("j.jsonl"),
    )
    .await
    .unwrap();
    let mut resumed = after.clone();
    resumed.sort_by_key(|m| m.index);
    let mut uninterrupted = whole.entries().to_vec();
    uninterrupted.sort_by_key(|m| m.index);
    assert_eq!(resumed.len(), uninterrupted.len());
    for (a, b) in resumed.iter().zip(&uninterrupted) {
        assert_eq!(a.index, b.index);
        assert!(
            a == b,
            "patch {}: resumed {:?} at {:?}, uninterrupted {:?} at {:?}",
            a.index,
            a.reading.xyz,
            a.time_s,
            b.reading.xyz,
            b.time_s
        );
    }

    // The profile is published and says it was made from this journal.
    assert!(outcome.rejection.is_none());
    let current = Profile::read(&state.path().join("current.toml")).unwrap();
    assert_eq!(current.provenance.source, journal.display().to_string());
    // Nothing left to resume.
    let again = calibrate(&loaded, &options, &mut |_| {}, None).await;
    assert!(again.is_err());
}

/// A real process killed with SIGKILL in the middle of a real-time run, then resumed
/// with `chromacal calibrate --resume`.
#[test]
fn a_killed_process_resumes_with_nothing_twice_and_nothing_lost() {
    let state = tempfile::tempdir().unwrap();
    // 5 simulated minutes at 0.01 real seconds each: about 3 s of real time.
    let mut child = chromacal()
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
    let runs = state.path().join("runs");
    let started = Instant::now();
    let journal = loop {
        let found = std::fs::read_dir(&runs)
            .ok()
            .and_then(|mut d| d.next())
            .and_then(|e| e.ok())
            .map(|e| e.path().join("journal.jsonl"));
        if let Some(j) = found.filter(|j| j.is_file())
            && std::fs::read_to_string(&j).map_or(0, |t| t.lines().count()) > 31
        {
            break j;
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "the run never got going"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    child.kill().unwrap();
    child.wait().unwrap();
    let measured_before = indices(&journal);
    assert!(
        measured_before.len() >= 30 && measured_before.len() < 96,
        "{}",
        measured_before.len()
    );
    assert!(!state.path().join("current.toml").exists());

    let output = chromacal()
        .args(["calibrate", "--resume", "--state-dir"])
        .arg(state.path())
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("resumed"), "{stdout}");
    assert_complete_and_unique(&journal);
    let after = indices(&journal);
    assert_eq!(&after[..measured_before.len()], &measured_before[..]);

    // Same profile within noise as an uninterrupted run of the same config.
    let resumed = Profile::read(&state.path().join("current.toml")).unwrap();
    let fresh_state = tempfile::tempdir().unwrap();
    let fresh = chromacal()
        .args(["calibrate", "--state-dir"])
        .arg(fresh_state.path())
        .output()
        .unwrap();
    assert!(fresh.status.success());
    let fresh = Profile::read(&fresh_state.path().join("current.toml")).unwrap();
    let (a, b) = (resumed.model.white(), fresh.model.white());
    assert!((a - b).norm() / b.norm() < 0.01, "{a:?} vs {b:?}");
    let held = resumed.report.held_out.unwrap();
    assert!(held.mean < 0.5, "{held:?}");
}
