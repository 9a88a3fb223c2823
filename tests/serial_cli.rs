//! The instrument commands as a user runs them: `emulate` (with faults and a
//! recording), `instruments` (scanning ports with a bound), a run that loses its
//! instrument keeping its journal and resuming, the correction matrix, and the light
//! meter's need for chromaticities.

use std::time::Instant;

use chromacal::calibrate::devices::open_devices;
use chromacal::config::parse_config;
use chromacal::journal::Journal;
use chromacal::profile::Profile;
use chromacal_instruments::Instrument;
use chromacal_instruments::transcript::{Direction, read_transcript};
use chromacal_model::fit::{FitError, FitOptions, fit_monitor};

mod common;
use common::{Emulator, chromacal, emulate};

#[test]
fn emulate_records_a_byte_exact_transcript_and_measure_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let record = dir.path().join("k10.jsonl");
    let emulator = emulate(&[
        "--instrument",
        "k10a",
        "--time-scale",
        "0.01",
        "--record",
        record.to_str().unwrap(),
    ]);
    let out = chromacal()
        .args([
            "measure",
            "--instrument",
            &format!("k10a:{}", emulator.device),
            "--timing-scale",
            "0.01",
            "--count",
            "2",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let readings: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(readings.as_array().unwrap().len(), 2);
    assert_eq!(readings[0]["device_code"], "0");
    drop(emulator);
    let (header, events) = read_transcript(&record).unwrap();
    assert_eq!(header.instrument, "K-10A");
    let host: Vec<u8> = events
        .iter()
        .filter(|e| e.dir == Direction::Host)
        .flat_map(|e| e.bytes().unwrap())
        .collect();
    assert!(
        host.starts_with(b"P0\r"),
        "{}",
        String::from_utf8_lossy(&host)
    );
    // The emulator's screen is black: at that light the driver averages 20 readings
    // for each measurement, as Argyll does.
    let per_measurement = chromacal_instruments::klein::driver::readings_to_average(0.1);
    assert_eq!(
        host.windows(3).filter(|w| w == b"N5\r").count(),
        2 * per_measurement
    );
    assert!(
        events
            .iter()
            .filter(|e| e.dir == Direction::Device)
            .all(|e| e.text.ends_with("<0>"))
    );

    let bad = chromacal()
        .args(["emulate", "--instrument", "k10a", "--faults", "nonsense=1"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown fault"));
    let bad = chromacal()
        .args(["emulate", "--instrument", "pr999"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown instrument"));
    // A port that does not exist never had an instrument: said so, with where to look.
    let missing = chromacal()
        .args([
            "measure",
            "--instrument",
            "pr670:/dev/ttyUSB-chromacal-none",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(!missing.status.success());
    assert!(
        stderr.contains("cannot open the pr670's port /dev/ttyUSB-chromacal-none")
            && stderr.contains("chromacal instruments")
            && !stderr.contains("gone"),
        "{stderr}"
    );
    // The wrong kind on a port (a K-10A asked of a PR-670): named, port and all.
    let pr670 = common::emulate(&["--instrument", "pr670", "--time-scale", "0.01"]);
    let wrong = chromacal()
        .args(["measure", "--timing-scale", "0.01", "--instrument"])
        .arg(format!("k10a:{}", pr670.device))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&wrong.stderr);
    assert!(!wrong.status.success());
    assert!(
        stderr.contains(&format!("no k10a answered on {}", pr670.device))
            && stderr.contains("chromacal instruments"),
        "{stderr}"
    );
}

#[test]
fn instruments_identifies_each_emulator_and_bounds_a_silent_port() {
    let kinds = [
        "pr650",
        "pr670",
        "k10a",
        "specbos1211",
        "ls100",
        "colorcal2",
    ];
    let emulators: Vec<Emulator> = kinds
        .iter()
        .map(|k| emulate(&["--instrument", k, "--time-scale", "0.05"]))
        .collect();
    let silent = emulate(&["--instrument", "ls100", "--not-remote"]);
    let mut command = chromacal();
    // chromacal's own scan is timed here; ArgyllCMS's listing, which follows it, is
    // tests/argyll_bridge.rs's.
    command.args(["instruments", "--json", "--no-argyll"]);
    for e in emulators.iter().chain(std::iter::once(&silent)) {
        command.args(["--port", &e.device]);
    }
    let started = Instant::now();
    let out = command.output().unwrap();
    let took = started.elapsed().as_secs_f64();
    assert!(out.status.success());
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    let found = |port: &str| rows.iter().find(|r| r["port"] == port).cloned().unwrap();
    for (kind, e) in kinds.iter().zip(&emulators) {
        assert_eq!(
            found(&e.device)["instrument"],
            *kind,
            "{kind}: {:?}",
            found(&e.device)
        );
    }
    assert!(found(&silent.device)["instrument"].is_null());
    // Ports are probed in parallel, each within its budget.
    assert!(
        took < chromacal_instruments::scan::PORT_BUDGET_S + 4.0,
        "the scan took {took:.1} s"
    );
}

#[test]
fn a_run_that_loses_its_instrument_keeps_its_journal_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    // The emulated PR-670 vanishes after 80 replies, in the middle of the run.
    let dying = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--faults",
        "vanish=1,start_after=80",
    ]);
    let out = chromacal()
        .args([
            "calibrate",
            "--instrument",
            &format!("pr670:{}", dying.device),
            "--screen",
            &dying.screen,
        ])
        .args([
            "--timing-scale",
            "0.002",
            "--state-dir",
            dir.path().to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("reconnection attempts failed") && stderr.contains("--resume"),
        "{stderr}"
    );
    let journal_path = std::fs::read_dir(dir.path().join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
        .join("journal.jsonl");
    let (header, before, _) = Journal::read(&journal_path).unwrap();
    let before = before.len();
    let planned = header.plan.patches.len();
    assert!(
        before > 10 && before < planned,
        "{before} readings of {planned} before the loss"
    );

    // The instrument comes back (on a new port): the run goes on where it stopped.
    let back = emulate(&["--instrument", "pr670", "--time-scale", "0.002"]);
    let out = chromacal()
        .args([
            "calibrate",
            "--resume",
            "--instrument",
            &format!("pr670:{}", back.device),
            "--screen",
            &back.screen,
        ])
        .args([
            "--timing-scale",
            "0.002",
            "--state-dir",
            dir.path().to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The instrument's own time, not a simulation's, is what was spent.
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("  instrument time") && !said.contains("simulated"),
        "{said}"
    );
    let (header, entries, _) = Journal::read(&journal_path).unwrap();
    common::assert_each_planned_patch_once(&header, &entries);
    assert!(entries.len() >= planned, "{} of {planned}", entries.len());
    let profile = Profile::read(&dir.path().join("current.toml")).unwrap();
    assert!(profile.report.held_out.unwrap().mean < 0.5);
}

#[tokio::test]
async fn a_correction_matrix_applies_to_colorimeters_only() {
    let k10 = emulate(&["--instrument", "k10a", "--time-scale", "0.01"]);
    let config_for = |driver: &str, device: &str, screen: &str| {
        parse_config(
            &format!(
                "[instrument]\ndriver = \"{driver}\"\nport = \"{device}\"\ncorrection = [[1.1, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.9]]\n[instrument.options]\ntiming_scale = 0.01\n[display]\nscreen = \"{screen}\"\n"
            ),
            "test",
        )
        .unwrap()
    };
    let config = config_for("k10a", &k10.device, &k10.screen);
    let mut corrected = open_devices(&config, std::path::Path::new("."), None)
        .await
        .unwrap();
    let a = corrected.instrument.measure().await.unwrap().xyz.unwrap();
    corrected.instrument.close();
    drop(corrected);
    let mut plain_config = config.clone();
    plain_config.instrument.correction = None;
    let mut plain = open_devices(&plain_config, std::path::Path::new("."), None)
        .await
        .unwrap();
    let b = plain.instrument.measure().await.unwrap().xyz.unwrap();
    assert!(
        (a.x / b.x - 1.1).abs() < 0.01
            && (a.y / b.y - 1.0).abs() < 0.01
            && (a.z / b.z - 0.9).abs() < 0.01,
        "{a:?} vs {b:?}"
    );

    let pr = emulate(&["--instrument", "pr670", "--time-scale", "0.01"]);
    let spectral = config_for("pr670", &pr.device, &pr.screen);
    let err = open_devices(&spectral, std::path::Path::new("."), None)
        .await
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("for colorimeters"), "{err}");
}

#[test]
fn a_light_meter_run_needs_the_primaries_chromaticities() {
    let dir = tempfile::tempdir().unwrap();
    let ls = emulate(&["--instrument", "ls100", "--time-scale", "0.002"]);
    let run = |config: Option<&std::path::Path>| {
        let mut command = chromacal();
        command.arg("calibrate");
        if let Some(config) = config {
            command.arg("--config").arg(config);
        }
        command
            .args([
                "--instrument",
                &format!("ls100:{}", ls.device),
                "--screen",
                &ls.screen,
            ])
            .args([
                "--timing-scale",
                "0.002",
                "--state-dir",
                dir.path().to_str().unwrap(),
            ])
            .output()
            .unwrap()
    };
    // Refused before the first patch: nothing measured to lose, no run started.
    let out = run(None);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("primaries_xy"));
    assert!(!dir.path().join("runs").exists());
    // With the manufacturer's chromaticities the run measures and fits luminance only.
    let config = dir.path().join("ls100.toml");
    std::fs::write(
        &config,
        "[fit]\nprimaries_xy = [[0.619, 0.344], [0.2765, 0.605], [0.1513, 0.0611]]\n",
    )
    .unwrap();
    let out = run(Some(&config));
    assert!(
        matches!(out.status.code(), Some(0) | Some(3)),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let journal = std::fs::read_dir(dir.path().join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
        .join("journal.jsonl");
    let set = chromacal::measurement_file::read_measurements(&journal).unwrap();
    assert!(matches!(
        fit_monitor(&set, &FitOptions::default()),
        Err(FitError::NeedChromaticities)
    ));
    let options = FitOptions {
        primaries_xy: Some([[0.619, 0.344], [0.2765, 0.605], [0.1513, 0.0611]]),
        ..FitOptions::default()
    };
    let fit = fit_monitor(&set, &options).unwrap();
    assert!(
        fit.report
            .luminance_only
            .as_deref()
            .unwrap()
            .contains("luminance only")
    );
    let red = fit.report.primaries[0].chromaticity;
    assert!(
        (red[0] - 0.619).abs() < 1e-3 && (red[1] - 0.344).abs() < 1e-3,
        "{red:?}"
    );
}
