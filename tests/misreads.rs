//! Readings no display can give (a unit lost, a correction that turned light inside
//! out, a program printing nonsense) are misreads: read again, counted, and after the
//! attempts the run stops naming the reading, its journal kept. Through real serial
//! bytes (an emulated K-10A that now and then answers 10⁹ times the light; the
//! spectroradiometers' drivers already refuse an XYZ their spectrum does not give) and
//! through the ArgyllCMS bridge (a stand-in spotread that answers negative light); and
//! a stand-in spotread whose usage text never ends is read within a bound, and one
//! whose scan hangs names the port and ArgyllCMS's way to leave it out.

use std::path::Path;

use chromacal::journal::Journal;

mod common;
use common::{CRT_PRIMARIES, chromacal, emulate};

const TIME_SCALE: &str = "0.002";

/// The journal of the one run in `state`.
fn journal_of(state: &Path) -> std::path::PathBuf {
    common::daemon_runs(state).remove(0)
}

#[test]
fn an_instrument_that_now_and_then_misreads_is_read_again_and_the_run_publishes() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, CRT_PRIMARIES).unwrap();
    let emulator = emulate(&[
        "--instrument",
        "k10a",
        "--ideal-filters",
        "--time-scale",
        TIME_SCALE,
        "--faults",
        "misread=0.08,seed=11",
    ]);
    let state = dir.path().join("state");
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--instrument")
        .arg(format!("k10a:{}", emulator.device))
        .args(["--screen", &emulator.screen, "--timing-scale", TIME_SCALE])
        .arg("--state-dir")
        .arg(&state)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Counted in the summary, and none of them in the journal.
    let misreads: usize = stdout
        .lines()
        .find_map(|l| l.trim().strip_prefix("misreads: "))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no misreads line in\n{stdout}"));
    assert!(misreads >= 1, "{stdout}");
    let (_, readings, _) = Journal::read(&journal_of(&state)).unwrap();
    assert!(readings.len() >= 30, "{} readings", readings.len());
    for m in &readings {
        let xyz = m.reading.xyz.unwrap();
        assert!(xyz.y < 1000.0, "a misread journalled: {m:?}");
    }
    assert!(state.join("current.toml").exists());
}

/// A stand-in spotread that lists one port and answers `result` to every key.
fn stand_in(dir: &Path, usage: &str, result: &str) -> std::path::PathBuf {
    let path = dir.join("fake-spotread");
    let script = format!(
        r#"#!/bin/sh
if [ "$1" = "-?" ]; then
{usage}
  exit 1
fi
stty raw -echo
n=0
while true; do
  printf '\nPlace instrument on spot to be measured,\r\nHit ESC or Q to exit, any other key to take a reading: '
  key=$(dd bs=1 count=1 2>/dev/null)
  case "$key" in q|Q|"$(printf '\033')") exit 0;; esac
  n=$((n + 1))
  if [ $n -le 3 ]; then
    printf '\r\n Result is XYZ: 20.%d 21.0 22.0, D50 Lab: 50 1 2\r\n' $n
  else
    printf '\r\n Result is XYZ: {result}, D50 Lab: 50 1 2\r\n'
  fi
done
"#
    );
    std::fs::write(&path, script).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

const ONE_PORT: &str = r#"  echo "usage: spotread [-options] [logfile]"
  echo " -c listno            Set instrument port from the following list (default 1)"
  echo "    1 = '/dev/ttyUSB0 (Fake Meter)'""#;

#[test]
fn negative_light_through_argyll_stops_the_run_naming_the_reading_and_keeps_the_journal() {
    let dir = tempfile::tempdir().unwrap();
    let fake = stand_in(dir.path(), ONE_PORT, "-20.0 -21.0 -22.0");
    let emulator = emulate(&["--instrument", "k10a", "--time-scale", "0.05"]);
    let config = dir.path().join("config.toml");
    std::fs::write(
        &config,
        "[plan]\nstrategy = \"fixed\"\nbudget = 24\nverification = 8\nuniformity_grid = 0\n",
    )
    .unwrap();
    let state = dir.path().join("state");
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .args(["--instrument", "argyll", "--screen", &emulator.screen])
        .arg("--state-dir")
        .arg(&state)
        .env("CHROMACAL_SPOTREAD", &fake)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("misread") && stderr.contains("X = -20 cd/m²"),
        "{stderr}"
    );
    assert!(stderr.contains("patch 3"), "{stderr}");
    // The three good readings are kept, and --resume is offered.
    let (_, readings, _) = Journal::read(&journal_of(&state)).unwrap();
    assert_eq!(readings.len(), 3);
    assert!(stderr.contains("--resume"), "{stderr}");
}

#[test]
fn a_spotread_whose_usage_never_ends_is_read_within_a_bound() {
    let dir = tempfile::tempdir().unwrap();
    let fake = stand_in(
        dir.path(),
        "  while true; do echo \" -c listno            Set instrument port from the following list\"; done",
        "1 1 1",
    );
    // Peak memory from GNU time (kilobytes).
    let out = std::process::Command::new("/usr/bin/time")
        .args(["-f", "peak-kb %M"])
        .arg(env!("CARGO_BIN_EXE_chromacal"))
        .args(["instruments", "--json"])
        .env("CHROMACAL_SPOTREAD", &fake)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    // The listing goes on without Argyll's ports, saying why.
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains("-? printed more than 1048576 bytes on its output"),
        "{stdout}"
    );
    let peak_kb: u64 = stderr
        .lines()
        .find_map(|l| l.strip_prefix("peak-kb "))
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no peak in {stderr}"));
    assert!(peak_kb < 100_000, "{peak_kb} kB");
    // Measuring through it stops with the same words.
    let out = chromacal()
        .args(["measure", "--instrument", "argyll:1"])
        .env("CHROMACAL_SPOTREAD", &fake)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("printed more than 1048576 bytes"),
        "{stderr}"
    );
}

/// A port that hangs Argyll's scan (here a FIFO, whose open waits for a writer as a
/// tty waiting for its carrier does): after the bound, the port is named with
/// ArgyllCMS's own way to leave it out of the scan.
#[test]
fn a_port_that_hangs_argylls_scan_is_named_with_the_exclusion_to_set() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("hanging-port");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let fake = stand_in(dir.path(), "  sleep 100", "1 1 1");
    let out = chromacal()
        .args(["instruments", "--json", "--port"])
        .arg(&fifo)
        .env("CHROMACAL_SPOTREAD", &fake)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let rows: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let argyll = rows
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["instrument"] == "argyll")
        .unwrap_or_else(|| panic!("{rows}"));
    let error = argyll["error"].as_str().unwrap();
    let path = fifo.display().to_string();
    assert!(
        error.contains(&format!("it hangs on opening {path}"))
            && error.contains(&format!("ARGYLL_EXCLUDE_SERIAL_SCAN={path}")),
        "{error}"
    );
}
