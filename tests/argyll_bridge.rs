//! The ArgyllCMS bridge against chromacal's own emulators: Debian's ArgyllCMS
//! `spotread`, run by chromacal on a pseudo-terminal, talks real serial bytes to an
//! emulated JETI specbos 1211 or Klein K-10A on another pseudo-terminal
//! (tests/common/argyll.rs says how Argyll is made to see it).

use std::io::BufRead;
use std::path::Path;
use std::time::{Duration, Instant};

use chromacal::journal::Journal;
use chromacal::profile::Profile;

mod common;
use common::argyll::SpotreadWrapper;
use common::{chromacal, emulate};

/// Emulators answer twenty times faster than real time (ArgyllCMS's own timeouts are
/// its own: it only sees replies come sooner).
const TIME_SCALE: &str = "0.05";

/// A shorter plan for the runs that are interrupted.
const SHORT_PLAN: &str =
    "[plan]\nstrategy = \"fixed\"\nbudget = 24\nverification = 8\nuniformity_grid = 0\n";

fn specbos() -> common::Emulator {
    // The specbos is set to its factory rate, which ArgyllCMS's driver expects.
    emulate(&[
        "--instrument",
        "specbos1211",
        "--baud",
        "921600",
        "--time-scale",
        TIME_SCALE,
    ])
}

fn journal_of(state: &Path) -> std::path::PathBuf {
    std::fs::read_dir(state.join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
        .join("journal.jsonl")
}

#[test]
fn argyll_identifies_the_emulated_specbos_and_k10a() {
    let dir = tempfile::tempdir().unwrap();
    for (args, identity) in [
        (
            vec!["--instrument", "specbos1211", "--baud", "921600"],
            "JETI specbos",
        ),
        (vec!["--instrument", "k10a"], "Klein K-10"),
    ] {
        let emulator = emulate(&args);
        let wrapper = SpotreadWrapper::new(dir.path(), &emulator.device);
        let out = common::succeed(
            chromacal()
                .args(["instruments", "--json"])
                .env("CHROMACAL_SPOTREAD", &wrapper.path),
        );
        let rows: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let argyll = rows
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["instrument"] == "argyll:1")
            .unwrap_or_else(|| panic!("no argyll:1 in {rows}"));
        assert_eq!(argyll["port"], "/dev/ttyUSB0");
        assert_eq!(argyll["identity"], identity, "{rows}");
    }
}

#[test]
fn a_calibration_through_spotread_equals_the_native_drivers() {
    let dir = tempfile::tempdir().unwrap();
    let calibrate = |instrument: &str, screen: &str, state: &Path, spotread: Option<&Path>| {
        let mut command = chromacal();
        command
            .args(["calibrate", "--instrument", instrument, "--screen", screen])
            .args(["--timing-scale", TIME_SCALE, "--state-dir"])
            .arg(state);
        if let Some(s) = spotread {
            command.env("CHROMACAL_SPOTREAD", s);
        }
        common::succeed(&mut command);
        Profile::read(&state.join("current.toml")).unwrap()
    };
    let native_emulator = specbos();
    let native = calibrate(
        &format!("specbos1211:{}", native_emulator.device),
        &native_emulator.screen,
        &dir.path().join("native"),
        None,
    );
    drop(native_emulator);

    let emulator = specbos();
    let wrapper = SpotreadWrapper::new(dir.path(), &emulator.device);
    let state = dir.path().join("bridge");
    let bridged = calibrate("argyll:1", &emulator.screen, &state, Some(&wrapper.path));

    let instrument = bridged.provenance.instrument.as_ref().unwrap();
    assert!(
        instrument.name.contains("specbos") && instrument.name.contains("ArgyllCMS"),
        "{instrument:?}"
    );
    common::assert_same_model("bridge vs native", &bridged, &native);
    let (b, n) = (
        bridged.report.held_out.unwrap(),
        native.report.held_out.unwrap(),
    );
    eprintln!("held-out ΔE00: bridge {b:?}, native {n:?}");
    assert!(b.mean < 0.3 && n.mean < 0.3, "{b:?} vs {n:?}");
    assert!((b.mean - n.mean).abs() < 0.1, "{b:?} vs {n:?}");
    // Argyll's spectra are kept with the readings.
    let (_, readings, _) = Journal::read(&journal_of(&state)).unwrap();
    let with_spectrum = readings
        .iter()
        .filter(|m| m.reading.spectrum.is_some())
        .count();
    assert_eq!(with_spectrum, readings.len());
}

#[test]
fn pulling_the_instrument_out_mid_run_is_an_instrument_error_and_the_run_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, SHORT_PLAN).unwrap();
    let state = dir.path().join("state");
    let emulator = specbos();
    let wrapper = SpotreadWrapper::new(dir.path(), &emulator.device);
    let run = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .args(["--instrument", "argyll:1", "--screen", &emulator.screen])
        .args(["--timing-scale", TIME_SCALE, "--state-dir"])
        .arg(&state)
        .env("CHROMACAL_SPOTREAD", &wrapper.path)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for eight readings in the journal, then pull the instrument out.
    let deadline = Instant::now() + Duration::from_secs(120);
    let journal = loop {
        assert!(Instant::now() < deadline, "no readings came");
        if let Ok(entries) = std::fs::read_dir(state.join("runs"))
            && let Some(run) = entries.flatten().next()
        {
            let journal = run.path().join("journal.jsonl");
            let lines = std::fs::File::open(&journal)
                .map(|f| std::io::BufReader::new(f).lines().count())
                .unwrap_or(0);
            if lines > 8 {
                break journal;
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    drop(emulator);
    let out = run.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("pulled out: {stderr}");
    assert!(!out.status.success(), "{stderr}");
    // The emulator carries the screen socket too: whichever of the two the run was
    // using when it went is the one named (on a loaded machine, often the screen).
    assert!(
        stderr.contains("instrument") || stderr.contains("the display is gone"),
        "{stderr}"
    );
    assert!(stderr.contains("--resume"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let (_, before, _) = Journal::read(&journal).unwrap();
    assert!(before.len() >= 8, "{}", before.len());
    // No spotread is left behind.
    let left = std::process::Command::new("pgrep")
        .args(["-f", &wrapper.path.display().to_string()])
        .output()
        .unwrap();
    assert!(
        left.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&left.stdout)
    );

    // Plugged in again (a new pseudo-terminal): the run goes on where it stopped.
    let emulator = specbos();
    wrapper.point_at(&emulator.device);
    common::succeed(
        chromacal()
            .args(["calibrate", "--resume", "--screen", &emulator.screen])
            .args(["--instrument", "argyll:1", "--timing-scale", TIME_SCALE])
            .arg("--state-dir")
            .arg(&state)
            .env("CHROMACAL_SPOTREAD", &wrapper.path),
    );
    let (_, after, _) = Journal::read(&journal).unwrap();
    assert_eq!(&after[..before.len()], &before[..]);
    assert!(state.join("current.toml").exists());
}

/// What the stand-in does after its good readings.
#[derive(Clone, Copy, PartialEq)]
enum Then {
    /// Prints nonsense for a result.
    Nonsense,
    /// Asks for a calibration; a key pressed at that prompt is written to
    /// `fake-calibrated` (it would calibrate against the screen).
    Calibration,
}

/// A stand-in for spotread that lists one port, reads `good` readings, then does
/// `then` (its count kept in a file, across restarts).
fn fake_spotread(dir: &Path, good: usize, then: Then) -> std::path::PathBuf {
    let path = dir.join("fake-spotread");
    let count = dir.join("fake-count");
    std::fs::write(&count, "0").unwrap();
    let script = format!(
        r#"#!/bin/sh
if [ "$1" = "-?" ]; then
  echo "usage: spotread [-options] [logfile]"
  echo " -c listno            Set instrument port from the following list (default 1)"
  echo "    1 = '/dev/ttyUSB0 (Fake Meter)'"
  echo " -t                   Use transmission measurement mode"
  exit 1
fi
stty raw -echo
prompt() {{ printf '\nPlace instrument on spot to be measured,\r\nHit ESC or Q to exit, any other key to take a reading: '; }}
# Asks for a calibration; a key at that prompt would calibrate, and is written down.
ask_calibration() {{
  printf '\r\nSpot read needs a calibration before continuing\r\nPlace the instrument on its white tile,\r\n and then hit any key to continue,\r\n or hit Esc or Q to abort: '
  key=$(dd bs=1 count=1 2>/dev/null)
  case "$key" in q|Q|"$(printf '\033')") exit 0;; esac
  echo "$key" >> "{calibrated}"
}}
# Started again once its calibration has run out, it asks at once (as an i1Pro does).
if [ {calibrate} = 1 ] && [ "$(cat "{count}")" -ge {good} ]; then
  ask_calibration
fi
prompt
while true; do
  key=$(dd bs=1 count=1 2>/dev/null)
  case "$key" in q|Q|"$(printf '\033')") exit 0;; esac
  n=$(cat "{count}"); n=$((n + 1)); echo $n > "{count}"
  if [ $n -le {good} ]; then
    printf '\r\n Result is XYZ: 20.%d 21.0 22.0, D50 Lab: 50 1 2\r\n' $n
  elif [ {calibrate} = 1 ]; then
    ask_calibration
  else
    printf '\r\n Result is XYZ: 20.0 twenty-one 22.0, D50 Lab: 50 1 2\r\n'
  fi
  prompt
done
"#,
        count = count.display(),
        calibrate = u8::from(then == Then::Calibration),
        calibrated = dir.join("fake-calibrated").display(),
    );
    std::fs::write(&path, script).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

#[test]
fn a_missing_argyll_and_an_argyll_that_talks_nonsense_are_named() {
    let dir = tempfile::tempdir().unwrap();
    // Missing: the error says what to install.
    let out = chromacal()
        .args(["measure", "--instrument", "argyll"])
        .env("CHROMACAL_SPOTREAD", dir.path().join("no-such-spotread"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("not found") && stderr.contains("install ArgyllCMS"),
        "{stderr}"
    );
    // A port Argyll does not have: the ports it has are named.
    let fake = fake_spotread(dir.path(), 4, Then::Nonsense);
    let out = chromacal()
        .args(["measure", "--instrument", "argyll:3"])
        .env("CHROMACAL_SPOTREAD", &fake)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no instrument 3") && stderr.contains("Fake Meter"),
        "{stderr}"
    );

    // Nonsense after four readings: a calibration stops with the line named, and the
    // four readings are in its journal.
    let (out, state) = calibrate_through(dir.path(), &fake);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("result line makes no sense") && stderr.contains("twenty-one"),
        "{stderr}"
    );
    let (_, readings, _) = Journal::read(&journal_of(&state)).unwrap();
    assert_eq!(readings.len(), 4);
    assert!((readings[3].reading.xyz.unwrap().x - 20.4).abs() < 1e-9);
}

/// A short calibration of an emulated K-10A through `fake` as Argyll's spotread, its
/// state in `dir/state`: what it printed, and that state directory.
fn calibrate_through(dir: &Path, fake: &Path) -> (std::process::Output, std::path::PathBuf) {
    let emulator = emulate(&["--instrument", "k10a", "--time-scale", TIME_SCALE]);
    let config = dir.join("config.toml");
    std::fs::write(&config, SHORT_PLAN).unwrap();
    let state = dir.join("state");
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .args(["--instrument", "argyll", "--screen", &emulator.screen])
        .arg("--state-dir")
        .arg(&state)
        .env("CHROMACAL_SPOTREAD", fake)
        .output()
        .unwrap();
    (out, state)
}

/// An instrument that asks for a calibration mid-run (an i1Pro's expires): the run
/// stops with Argyll's instructions, no key is pressed at that prompt (it would
/// calibrate against the screen), and the readings so far are kept.
#[test]
fn a_calibration_request_stops_the_run_without_answering_it() {
    let dir = tempfile::tempdir().unwrap();
    let fake = fake_spotread(dir.path(), 3, Then::Calibration);
    let (out, state) = calibrate_through(dir.path(), &fake);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("needs a calibration") && stderr.contains("white tile"),
        "{stderr}"
    );
    assert!(
        !dir.path().join("fake-calibrated").exists(),
        "a key was pressed at the calibration prompt"
    );
    let (_, readings, _) = Journal::read(&journal_of(&state)).unwrap();
    assert_eq!(readings.len(), 3);
}
