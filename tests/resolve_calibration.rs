//! A whole calibration across a real TCP socket and a real tty: run loop → Resolve
//! server → `chromacal emulate --resolve` (the virtual monitor as pattern generator) →
//! emulated PR-670 → pty → driver. The profile must be the in-process run's, within
//! noise, also when the generator drops its connection in the middle of the run.

use chromacal::journal::Journal;
use chromacal::profile::Profile;

mod common;
use common::{CRT_PRIMARIES, assert_same_model, chromacal, emulate, in_process_profile};

const TIME_SCALE: &str = "0.002";

/// A loopback address with a port free now.
fn free_address() -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.local_addr().unwrap().to_string()
}

/// Calibrate in-process (the reference), then over Resolve with `emulate_args` extra.
fn calibrate_over_resolve(
    emulate_args: &[&str],
) -> (
    Profile,
    Profile,
    std::path::PathBuf,
    String,
    tempfile::TempDir,
) {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    // A generator that never comes is an error here, not a hang.
    std::fs::write(
        &config,
        format!("{CRT_PRIMARIES}[display.resolve]\nconnect_timeout_s = 60.0\n"),
    )
    .unwrap();
    let reference = in_process_profile(&config, &dir.path().join("reference"));

    let address = free_address();
    let mut args = vec![
        "--instrument",
        "pr670",
        "--time-scale",
        TIME_SCALE,
        "--resolve",
        &address,
    ];
    args.extend_from_slice(emulate_args);
    let emulator = emulate(&args);
    let state = dir.path().join("resolve");
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--instrument")
        .arg(format!("pr670:{}", emulator.device))
        .args([
            "--display",
            "resolve",
            "--listen",
            &address,
            "--timing-scale",
            TIME_SCALE,
            "--state-dir",
        ])
        .arg(&state)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    let profile = Profile::read(&state.join("current.toml")).unwrap();
    eprintln!(
        "over Resolve: held-out mean ΔE00 {:.3} (in-process {:.3}), white Y {:.3} vs {:.3} cd/m²",
        profile
            .report
            .held_out
            .as_ref()
            .map_or(f64::NAN, |h| h.mean),
        reference
            .report
            .held_out
            .as_ref()
            .map_or(f64::NAN, |h| h.mean),
        profile.model.white().y,
        reference.model.white().y
    );
    (profile, reference, state, stderr, dir)
}

/// The journal has every planned patch exactly once.
fn assert_complete_journal(state: &std::path::Path) {
    let runs: Vec<_> = std::fs::read_dir(state.join("runs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(runs.len(), 1);
    let (header, entries, recovery) = Journal::read(&runs[0].join("journal.jsonl")).unwrap();
    assert!(recovery.dropped_tail.is_none());
    let mut indices: Vec<usize> = entries.iter().map(|m| m.index).collect();
    indices.sort();
    let planned: Vec<usize> = header.plan.patches.iter().map(|p| p.index).collect();
    assert_eq!(indices, planned, "a patch was lost or measured twice");
}

#[test]
fn a_calibration_over_resolve_and_a_pty_matches_the_in_process_one() {
    let (profile, reference, state, stderr, _dir) = calibrate_over_resolve(&[]);
    assert!(
        profile
            .provenance
            .display
            .as_deref()
            .unwrap_or("")
            .contains("Resolve")
    );
    assert!(
        stderr.contains("waiting for a Resolve pattern generator"),
        "{stderr}"
    );
    assert!(!stderr.contains("went away"), "{stderr}");
    assert_same_model("resolve", &profile, &reference);
    assert!(profile.report.held_out.as_ref().unwrap().mean < 0.5);
    assert_complete_journal(&state);
}

#[test]
fn a_generator_that_drops_mid_run_pauses_it_and_nothing_is_lost() {
    let (profile, reference, state, stderr, _dir) =
        calibrate_over_resolve(&["--resolve-drop-after", "30"]);
    assert_eq!(stderr.matches("went away").count(), 1, "{stderr}");
    assert_same_model("resolve with a drop", &profile, &reference);
    assert_complete_journal(&state);
}
