//! Which unfinished run is resumed, and with which settings (issue 12, items 4, 8 and
//! 10): a run whose fit failed twice is no longer resumed unless named, older runs are
//! listed and can be named, and `--resume --config` may change the fit settings but not
//! what was measured.

use std::path::Path;
use std::time::Duration;

use chromacal::calibrate::session::measure_simulated;
use chromacal::config::parse_config;
use chromacal::journal::Journal;
use chromacal::profile::Profile;

mod common;
use common::daemon::{get, start_daemon, wait_idle};
use common::{LCD_CONFIG, chromacal, fixture};

const GOOD: &str = "20260101T000000-aaaa";
const BROKEN: &str = "20260102T000000-bbbb";

/// A complete journal of the LCD whose every reading is the same grey light: every
/// patch is measured, so a resume only fits, and the fit has nothing to fit.
async fn broken_run(state: &Path) {
    let dir = state.join("runs").join(BROKEN);
    std::fs::create_dir_all(&dir).unwrap();
    let config = parse_config(LCD_CONFIG, "test").unwrap();
    let whole = dir.join("whole.jsonl");
    measure_simulated(&config, LCD_CONFIG, Path::new("."), &whole)
        .await
        .unwrap();
    let text = std::fs::read_to_string(&whole).unwrap();
    let mut lines = text.lines();
    let mut out = vec![lines.next().unwrap().to_string()];
    for line in lines {
        let mut entry: serde_json::Value = serde_json::from_str(line).unwrap();
        entry["reading"]["xyz"] = serde_json::json!([5.0, 5.0, 5.0]);
        entry["reading"]["spectrum"] = serde_json::Value::Null;
        out.push(entry.to_string());
    }
    std::fs::remove_file(&whole).unwrap();
    std::fs::write(dir.join("journal.jsonl"), out.join("\n") + "\n").unwrap();
}

fn good_run(state: &Path) -> std::path::PathBuf {
    let dir = state.join("runs").join(GOOD);
    std::fs::create_dir_all(&dir).unwrap();
    let journal = dir.join("journal.jsonl");
    std::fs::copy(fixture("journals/lcd-interrupted.jsonl"), &journal).unwrap();
    journal
}

fn runs_json(state: &Path) -> Vec<serde_json::Value> {
    let out = chromacal()
        .args(["runs", "--json", "--state-dir"])
        .arg(state)
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    serde_json::from_slice::<Vec<serde_json::Value>>(&out.stdout).unwrap()
}

fn failures_of(state: &Path, id: &str) -> u64 {
    runs_json(state)
        .iter()
        .find(|r| r["id"] == id)
        .unwrap_or_else(|| panic!("{id} is not listed"))["fit_failures"]
        .as_u64()
        .unwrap()
}

fn resume(state: &Path, extra: &[&str]) -> std::process::Output {
    chromacal()
        .args(["calibrate", "--state-dir"])
        .arg(state)
        .args(extra)
        .output()
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_run_whose_fit_failed_twice_is_kept_but_not_resumed_unless_named() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    good_run(&state);
    broken_run(&state).await;
    assert_eq!(runs_json(&state).len(), 2);

    // The newest run is resumed and its fit fails, twice.
    for attempt in 1..=2 {
        let out = resume(&state, &["--resume"]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "attempt {attempt}: {stderr}");
        assert!(stderr.contains("fit"), "attempt {attempt}: {stderr}");
        assert_eq!(failures_of(&state, BROKEN), attempt);
    }
    let listing = chromacal()
        .args(["runs", "--state-dir"])
        .arg(&state)
        .output()
        .unwrap();
    let listing = String::from_utf8_lossy(&listing.stdout);
    assert!(
        listing.contains("failed 2 times: resumed only by name"),
        "{listing}"
    );
    assert!(listing.contains(GOOD), "{listing}");

    // A name that is no run is refused, listing the real ones.
    let out = resume(&state, &["--resume", "no-such-run"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("no unfinished run is named no-such-run") && stderr.contains(BROKEN),
        "{stderr}"
    );
    // Named, the broken run is tried again (and fails again).
    let out = resume(&state, &["--resume", BROKEN]);
    assert!(!out.status.success());
    assert_eq!(failures_of(&state, BROKEN), 3);

    // The daemon resumes the older, good run, not the broken one, and says why.
    let daemon = start_daemon(
        dir.path(),
        &format!("{LCD_CONFIG}[daemon]\nsimulated_time_scale = 0.001\n"),
    );
    let api = daemon.endpoint();
    tokio::time::sleep(Duration::from_millis(300)).await;
    wait_idle(&api, Duration::from_secs(120)).await;
    let status = get(&api, "/status").await.json().unwrap();
    assert_eq!(status["last_job"]["outcome"]["result"], "ok", "{status}");
    let good_id = Journal::read(&state.join("runs").join(GOOD).join("journal.jsonl"))
        .unwrap()
        .0
        .run_id;
    assert_eq!(
        status["current_profile"]["id"], good_id,
        "the good run was resumed and published: {status}"
    );
    let unfinished = status["unfinished_runs"].as_array().unwrap();
    assert_eq!(unfinished.len(), 1, "{status}");
    assert_eq!(unfinished[0]["id"], BROKEN);
    assert_eq!(unfinished[0]["fit_failures"], 3);
    assert!(
        daemon.log_text().contains("fit failed twice"),
        "{}",
        daemon.log_text()
    );
}

#[test]
fn resume_takes_new_fit_settings_but_refuses_a_changed_plan() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let journal = good_run(&state);
    let (header, before, _) = Journal::read(&journal).unwrap();

    // A config that measures differently is refused, naming the section, and the
    // journal is untouched.
    let mut changed: toml::Table = toml::from_str(&header.config).unwrap();
    changed
        .entry("plan")
        .or_insert(toml::Value::Table(Default::default()))
        .as_table_mut()
        .unwrap()
        .insert("seed".into(), toml::Value::Integer(99));
    let changed_path = dir.path().join("changed-plan.toml");
    std::fs::write(&changed_path, toml::to_string(&changed).unwrap()).unwrap();
    let out = resume(
        &state,
        &["--resume", "--config", changed_path.to_str().unwrap()],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("[plan]"), "{stderr}");
    assert_eq!(Journal::read(&journal).unwrap().1.len(), before.len());

    // A config that changes only [fit] is taken, and the profile says so.
    let mut fit_only: toml::Table = toml::from_str(&header.config).unwrap();
    fit_only
        .entry("fit")
        .or_insert(toml::Value::Table(Default::default()))
        .as_table_mut()
        .unwrap()
        .insert("additivity_terms".into(), toml::Value::Boolean(false));
    let fit_path = dir.path().join("fit-only.toml");
    std::fs::write(&fit_path, toml::to_string(&fit_only).unwrap()).unwrap();
    let out = resume(
        &state,
        &["--resume", "--config", fit_path.to_str().unwrap()],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_published_with_fit_only_settings(&state);
}

/// On a serial rig the run's config holds the command line's instrument and screen:
/// `--resume --config F` with the same command line compares like with like, and the
/// settings it gives outlive a second interruption.
#[test]
fn resume_with_new_fit_settings_on_a_serial_rig_survives_a_second_interruption() {
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let emulator = common::emulate(&["--instrument", "k10a", "--time-scale", "0.002"]);
    let base = "[fit]\nprimaries_xy = [[0.6190, 0.3440], [0.2765, 0.6050], [0.1513, 0.0611]]\n";
    let config = dir.path().join("c.toml");
    std::fs::write(&config, base).unwrap();
    let fit_only = dir.path().join("fit-only.toml");
    std::fs::write(&fit_only, format!("{base}additivity_terms = false\n")).unwrap();
    let rig = [
        "--instrument".to_string(),
        format!("k10a:{}", emulator.device),
        "--screen".into(),
        emulator.screen.clone(),
        "--timing-scale".into(),
        "0.002".into(),
        "--state-dir".into(),
        state.display().to_string(),
    ];
    // Start (or resume) a calibration and kill it once its journal has `readings`.
    let run_until_killed = |extra: &[&str], readings: usize| {
        let mut child = chromacal()
            .arg("calibrate")
            .args(extra)
            .args(&rig)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let now = common::daemon_runs(&state)
                .first()
                .and_then(|journal| std::fs::read_to_string(journal).ok())
                .map_or(0, |t| t.lines().count().saturating_sub(1));
            if now >= readings {
                break;
            }
            assert!(Instant::now() < deadline, "the run measured {now} readings");
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
    };
    run_until_killed(&["--config", config.to_str().unwrap()], 10);
    // Resumed with new fit settings, and interrupted again.
    run_until_killed(&["--resume", "--config", fit_only.to_str().unwrap()], 30);
    // A plain resume keeps the settings given before.
    let out = chromacal()
        .args(["calibrate", "--resume"])
        .args(&rig)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_published_with_fit_only_settings(&state);
}

/// The current profile in `state` names `fit-only.toml` as the settings given at
/// resume, and was fitted with them (the additivity terms switched off).
fn assert_published_with_fit_only_settings(state: &std::path::Path) {
    let profile = Profile::read(&state.join("current.toml")).unwrap();
    let note = profile
        .provenance
        .settings_at_resume
        .expect("the provenance names the settings given at resume");
    assert!(note.contains("fit-only.toml"), "{note}");
    assert!(
        profile
            .report
            .terms_rule
            .contains("fit.additivity_terms = false"),
        "{}",
        profile.report.terms_rule
    );
}
