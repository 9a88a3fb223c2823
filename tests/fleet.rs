//! One daemon, several devices (`[[device]]`): jobs on different devices run at once,
//! each device keeps its own store, schedule and history, a shared instrument takes
//! one job at a time, and a kill -9 during jobs on two devices resumes both.

mod common;

use std::time::Duration;

use common::daemon::{finished_on, get, json_events_until, post, start_daemon, subscribe_json};
use common::emulate;

/// Start a job on a device; its id.
async fn start_on(api: &chromacal::daemon::client::Endpoint, device: &str, kind: &str) -> String {
    let reply = post(
        api,
        &format!("/devices/{device}/jobs"),
        &format!("{{\"kind\": \"{kind}\"}}"),
    )
    .await;
    assert_eq!(reply.status, 202, "{device}: {}", reply.text());
    reply.json().unwrap()["id"].as_str().unwrap().to_string()
}

/// Where in `seen` the event `name` of `device` first is.
fn first(seen: &[serde_json::Value], device: &str, name: &str) -> usize {
    seen.iter()
        .position(|e| e["event"] == name && e["device"] == device)
        .unwrap_or_else(|| panic!("no {name} of {device} in {seen:#?}"))
}

/// Where in `seen` the first reading of `device` is (a progress event with a reading;
/// a job waiting for a shared instrument also sends one, without).
fn first_reading(seen: &[serde_json::Value], device: &str) -> usize {
    seen.iter()
        .position(|e| {
            e["event"] == "progress" && e["device"] == device && !e["job"]["last"].is_null()
        })
        .unwrap_or_else(|| panic!("no reading of {device} in {seen:#?}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_daemon_runs_two_simulated_devices_and_an_emulated_serial_one_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = emulate(&["--instrument", "pr670", "--time-scale", "0.002"]);
    let config = format!(
        r#"[daemon]
simulated_time_scale = 0.002
simulated_idle_ages = false
[schedule]
verify_every_s = 3600.0
[[device]]
name = "crt"
[[device]]
name = "lcd"
[device.monitor]
preset = "lcd"
[device.schedule]
verify_every_s = 7200.0
threshold_de00 = 2.5
[[device]]
name = "bench"
[device.instrument]
driver = "pr670"
port = "{}"
[device.instrument.options]
timing_scale = 0.002
[device.display]
screen = "{}"
[device.schedule]
"#,
        emulator.device, emulator.screen
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();

    // Without a device named, a device's route is refused with the names; an unknown
    // name is a 404.
    let ambiguous = get(&api, "/status").await;
    assert_eq!(ambiguous.status, 400, "{}", ambiguous.text());
    assert!(
        ambiguous.error_message().contains("crt, lcd, bench"),
        "{}",
        ambiguous.text()
    );
    let unknown = get(&api, "/devices/oled/status").await;
    assert_eq!(unknown.status, 404, "{}", unknown.text());
    assert!(unknown.error_message().contains("\"oled\""));

    let mut events = subscribe_json(&api, "/events");
    let mut lcd_only = subscribe_json(&api, "/devices/lcd/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    let ids: Vec<String> = {
        let mut ids = Vec::new();
        for device in ["crt", "lcd", "bench"] {
            ids.push(start_on(&api, device, "calibrate").await);
        }
        ids
    };
    // One job at a time on a device, but the others are free.
    let busy = post(&api, "/devices/crt/jobs", r#"{"kind": "verify"}"#).await;
    assert_eq!(busy.status, 409, "{}", busy.text());
    assert!(busy.error_message().contains("on crt"), "{}", busy.text());

    let seen = json_events_until(&mut events, Duration::from_secs(240), |seen| {
        ["crt", "lcd", "bench"]
            .iter()
            .all(|d| finished_on(seen, d) == 1)
    })
    .await;
    // All three ran at once: each started, and read, before any of them ended.
    let first_end = ["crt", "lcd", "bench"]
        .map(|d| first(&seen, d, "job_finished"))
        .into_iter()
        .min()
        .unwrap();
    for device in ["crt", "lcd", "bench"] {
        assert!(first_reading(&seen, device) < first_end, "{device}");
    }
    for (device, id) in ["crt", "lcd", "bench"].iter().zip(&ids) {
        let end = &seen[first(&seen, device, "job_finished")];
        assert_eq!(end["job"]["id"], id.as_str());
        assert_eq!(end["outcome"]["result"], "ok", "{device}: {end}");
        assert_eq!(end["outcome"]["published"], true, "{device}: {end}");
    }
    // The device's own stream carries its events only.
    let lcd_seen = json_events_until(&mut lcd_only, Duration::from_secs(10), |seen| {
        finished_on(seen, "lcd") == 1
    })
    .await;
    assert!(lcd_seen.iter().all(|e| e["device"] == "lcd"));
    assert_eq!(
        lcd_seen.len(),
        seen.iter().filter(|e| e["device"] == "lcd").count()
    );

    // Each device has its own store, profile and history, and its own schedule.
    let mut profiles = Vec::new();
    for device in ["crt", "lcd", "bench"] {
        let status = get(&api, &format!("/devices/{device}/status"))
            .await
            .json()
            .unwrap();
        assert_eq!(status["device"], device);
        let state = dir.path().join("state").join(device);
        assert_eq!(status["state_dir"], state.display().to_string());
        assert!(state.join("current.toml").is_file(), "{device}");
        let history = get(&api, &format!("/devices/{device}/history"))
            .await
            .json()
            .unwrap();
        assert_eq!(history["profiles"].as_array().unwrap().len(), 1, "{device}");
        profiles.push(
            status["current_profile"]["id"]
                .as_str()
                .unwrap()
                .to_string(),
        );
        let next = status["next_verification"].as_str().unwrap();
        let next = chromacal_formats::time::parse_rfc3339(next).unwrap();
        let ahead = next
            .duration_since(std::time::SystemTime::now())
            .unwrap()
            .as_secs_f64();
        let every = if device == "lcd" { 7200.0 } else { 3600.0 };
        assert!(
            ahead > every - 600.0 && ahead <= every + 1.0,
            "{device}: {ahead}"
        );
    }
    profiles.sort();
    profiles.dedup();
    assert_eq!(profiles.len(), 3, "three profiles of three monitors");
    // The state directory itself holds no store: only the devices' folders.
    assert!(!dir.path().join("state").join("current.toml").exists());
    // The LCD's threshold is its own, and so is its monitor.
    let metrics = get(&api, "/metrics").await.text();
    for (device, threshold) in [("crt", 1.0), ("lcd", 2.5), ("bench", 1.0)] {
        let line = format!(
            "chromacal_verification_threshold_delta_e00{{device=\"{device}\"}} {threshold:?}"
        );
        assert!(
            metrics.lines().any(|l| l == line),
            "{line} not in\n{metrics}"
        );
    }
    let lcd =
        chromacal::profile::Profile::read(&dir.path().join("state/lcd/current.toml")).unwrap();
    let crt =
        chromacal::profile::Profile::read(&dir.path().join("state/crt/current.toml")).unwrap();
    assert_ne!(lcd.model.white(), crt.model.white());

    // The command line: every device's status, and one device's history by name.
    let socket = daemon.socket.display().to_string();
    let out = common::succeed(common::chromacal().args(["status", "--socket", &socket]));
    let text = String::from_utf8_lossy(&out.stdout);
    for device in ["crt", "lcd", "bench"] {
        assert!(text.contains(&format!("device {device}: state")), "{text}");
    }
    let out = common::succeed(common::chromacal().args([
        "history", "--socket", &socket, "--device", "bench", "--json",
    ]));
    let history: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(history["current"], profiles_of(&dir, "bench"));
    let refused = common::chromacal()
        .args(["job", "start", "verify", "--socket", &socket])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("--device NAME"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
}

/// The current profile's id of `device`, from its store.
fn profiles_of(dir: &tempfile::TempDir, device: &str) -> String {
    chromacal::profile::Profile::read(&dir.path().join("state").join(device).join("current.toml"))
        .unwrap()
        .id
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn devices_sharing_an_instrument_take_turns() {
    let dir = tempfile::tempdir().unwrap();
    let config = r#"[daemon]
simulated_time_scale = 0.002
simulated_idle_ages = false
[instruments.meter.simulated]
seed = 11
[[device]]
name = "left"
instrument = "meter"
[[device]]
name = "right"
instrument = "meter"
[device.monitor]
preset = "lcd"
"#;
    let daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    let devices = get(&api, "/devices").await.json().unwrap();
    let shared: Vec<_> = devices["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["shared_instrument"].clone())
        .collect();
    assert_eq!(shared, vec!["meter", "meter"]);

    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    start_on(&api, "left", "calibrate").await;
    start_on(&api, "right", "calibrate").await;
    // While one measures, the other waits for the meter. Which takes it first is
    // up to the scheduler (under load the second job may get there first).
    let read = |e: &serde_json::Value| e["event"] == "progress" && !e["job"]["last"].is_null();
    let waiting = json_events_until(&mut events, Duration::from_secs(60), |seen| {
        seen.iter().any(read)
    })
    .await;
    let (measuring, waiter) = match waiting.iter().find(|e| read(e)) {
        Some(e) if e["device"] == "right" => ("right", "left"),
        _ => ("left", "right"),
    };
    let status = get(&api, &format!("/devices/{waiter}/status"))
        .await
        .json()
        .unwrap();
    assert_eq!(
        status["job"]["phase"], "waiting for the instrument meter",
        "{status}"
    );
    let mut seen = waiting;
    seen.extend(
        json_events_until(&mut events, Duration::from_secs(240), |seen| {
            finished_on(seen, "left") == 1 && finished_on(seen, "right") == 1
        })
        .await,
    );
    // The waiting one read nothing until the measuring one had ended.
    let measuring_end = first(&seen, measuring, "job_finished");
    assert!(first_reading(&seen, waiter) > measuring_end);
    for device in ["left", "right"] {
        let end = &seen[first(&seen, device, "job_finished")];
        assert_eq!(end["outcome"]["published"], true, "{end}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_kill_during_jobs_on_two_devices_resumes_both() {
    let dir = tempfile::tempdir().unwrap();
    let config = r#"[daemon]
simulated_time_scale = 0.004
simulated_idle_ages = false
[[device]]
name = "one"
[[device]]
name = "two"
[device.monitor]
preset = "lcd"
"#;
    let mut daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    start_on(&api, "one", "calibrate").await;
    start_on(&api, "two", "calibrate").await;
    let progress = |seen: &[serde_json::Value], device: &str| {
        seen.iter()
            .filter(|e| e["event"] == "progress" && e["device"] == device)
            .count()
    };
    json_events_until(&mut events, Duration::from_secs(60), |seen| {
        progress(seen, "one") >= 6 && progress(seen, "two") >= 6
    })
    .await;
    daemon.kill();

    // Each device's journal has what was read before the kill; the daemon started
    // again resumes both calibrations, and measures no patch twice.
    let journal_lines = |device: &str| -> usize {
        let runs = dir.path().join("state").join(device).join("runs");
        let run = std::fs::read_dir(&runs)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        std::fs::read_to_string(run.join("journal.jsonl"))
            .unwrap()
            .lines()
            .count()
    };
    let before = [journal_lines("one"), journal_lines("two")];
    assert!(before.iter().all(|n| *n >= 6), "{before:?}");
    drop(daemon);
    let daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    // The resumed jobs start with the daemon: follow their status.
    let deadline = std::time::Instant::now() + Duration::from_secs(240);
    loop {
        let devices = get(&api, "/devices").await.json().unwrap();
        let done = devices["devices"]
            .as_array()
            .unwrap()
            .iter()
            .all(|d| d["status"]["job"].is_null() && d["status"]["last_job"].is_object());
        if done {
            for d in devices["devices"].as_array().unwrap() {
                let (job, outcome) = (
                    &d["status"]["last_job"]["job"],
                    &d["status"]["last_job"]["outcome"],
                );
                assert_eq!(job["origin"], "resume", "{d}");
                assert_eq!(outcome["result"], "ok", "{d}");
                assert_eq!(outcome["published"], true, "{d}");
            }
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "not resumed: {devices}\n{}",
            daemon.log_text()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // Every patch once: the journal's readings are the plan's patches (plus its header).
    for device in ["one", "two"] {
        let runs = dir.path().join("state").join(device).join("runs");
        let run = std::fs::read_dir(&runs)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let text = std::fs::read_to_string(run.join("journal.jsonl")).unwrap();
        let header: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
        let planned = header["plan"]["patches"].as_array().unwrap().len();
        let mut indices: Vec<u64> = text
            .lines()
            .skip(1)
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .filter_map(|m| m["index"].as_u64())
            .collect();
        let read = indices.len();
        indices.sort_unstable();
        indices.dedup();
        assert_eq!(indices.len(), read, "{device}: a patch measured twice");
        assert_eq!(read, planned, "{device}");
    }
    let log = daemon.log_text();
    assert_eq!(
        log.matches("resuming the calibration a stop cut short")
            .count(),
        2,
        "{log}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_device_that_cannot_be_opened_is_told_and_counted_while_the_others_work() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-tty");
    let config = format!(
        r#"[daemon]
simulated_time_scale = 0.002
simulated_idle_ages = false
[[device]]
name = "good"
[[device]]
name = "unplugged"
[device.instrument]
driver = "pr670"
port = "{}"
[device.display]
screen = "{}"
"#,
        missing.display(),
        dir.path().join("no-such-screen").display()
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    start_on(&api, "unplugged", "calibrate").await;
    start_on(&api, "good", "calibrate").await;
    let seen = json_events_until(&mut events, Duration::from_secs(120), |seen| {
        finished_on(seen, "good") == 1 && finished_on(seen, "unplugged") == 1
    })
    .await;
    let lost = &seen[first(&seen, "unplugged", "device_lost")];
    assert_eq!(lost["fault"], "open", "{lost}");
    assert!(
        lost["message"].as_str().unwrap().contains("no-such"),
        "{lost}"
    );
    let end = &seen[first(&seen, "unplugged", "job_finished")];
    assert_eq!(end["outcome"]["result"], "failed", "{end}");
    let good = &seen[first(&seen, "good", "job_finished")];
    assert_eq!(good["outcome"]["published"], true, "{good}");
    assert!(
        !seen
            .iter()
            .any(|e| e["event"] == "device_lost" && e["device"] == "good")
    );
    // The metrics count the fault on its device, and each job's outcome.
    let metrics = get(&api, "/metrics").await.text();
    for line in [
        "chromacal_device_faults_total{device=\"unplugged\",fault=\"open\"} 1",
        "chromacal_jobs_total{device=\"unplugged\",kind=\"calibrate\",outcome=\"failed\"} 1",
        "chromacal_jobs_total{device=\"good\",kind=\"calibrate\",outcome=\"ok\"} 1",
    ] {
        assert!(
            metrics.lines().any(|l| l == line),
            "{line} not in\n{metrics}"
        );
    }
    // The device that could not be opened is down, the other up.
    for line in [
        "chromacal_device_up{device=\"unplugged\"} 0",
        "chromacal_device_up{device=\"good\"} 1",
    ] {
        assert!(
            metrics.lines().any(|l| l == line),
            "{line} not in\n{metrics}"
        );
    }
    // The device that worked has its fault series, at 0.
    for kind in ["open", "warmup", "instrument", "display"] {
        let line = format!("chromacal_device_faults_total{{device=\"good\",fault=\"{kind}\"}} 0");
        assert!(
            metrics.lines().any(|l| l == line),
            "{line} not in\n{metrics}"
        );
    }
}

#[test]
fn calibrate_takes_a_device_of_a_fleet_config_into_its_folder() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("fleet.toml");
    std::fs::write(
        &config,
        "[[device]]\nname = \"crt\"\n[[device]]\nname = \"lcd\"\n[device.monitor]\npreset = \"lcd\"\n",
    )
    .unwrap();
    let state = dir.path().join("state");
    let run = |device: Option<&str>| {
        let mut command = common::chromacal();
        command
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(&state)
            .arg("--json");
        if let Some(device) = device {
            command.args(["--device", device]);
        }
        command.output().unwrap()
    };
    let refused = run(None);
    assert!(!refused.status.success());
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(
        said.contains("crt, lcd") && said.contains("--device NAME"),
        "{said}"
    );
    let unknown = run(Some("oled"));
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("\"oled\""));
    let out = run(Some("lcd"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reply: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let path = std::path::PathBuf::from(reply["profile_path"].as_str().unwrap());
    assert!(path.starts_with(state.join("lcd")), "{}", path.display());
    assert_eq!(reply["published"], true, "{reply}");
    let profile = chromacal::profile::Profile::read(&state.join("lcd/current.toml")).unwrap();
    // The LCD preset's monitor, not the top level's CRT.
    let display = profile.provenance.display.unwrap_or_default();
    assert!(display.contains("lcd"), "{display}");
    assert!(!state.join("current.toml").exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_serial_instrument_shared_by_two_displays_is_let_go_and_opened_again() {
    let dir = tempfile::tempdir().unwrap();
    // One emulated PR-670 on a real pty, shared by two devices (both showing on the
    // emulator's screen, as a meter carried from one display to the next).
    let emulator = emulate(&["--instrument", "pr670", "--time-scale", "0.002"]);
    let config = format!(
        r#"[daemon]
simulated_idle_ages = false
[instruments.meter]
driver = "pr670"
port = "{}"
[instruments.meter.options]
timing_scale = 0.002
[display]
screen = "{}"
[[device]]
name = "first"
instrument = "meter"
[[device]]
name = "second"
instrument = "meter"
"#,
        emulator.device, emulator.screen
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    // Twice each, in turns: every job after the first opens the port afresh, which the
    // pty refuses while another holds it.
    for round in 1..=2 {
        start_on(&api, "first", "calibrate").await;
        start_on(&api, "second", "calibrate").await;
        let seen = json_events_until(&mut events, Duration::from_secs(240), |seen| {
            finished_on(seen, "first") == 1 && finished_on(seen, "second") == 1
        })
        .await;
        for device in ["first", "second"] {
            let end = &seen[first(&seen, device, "job_finished")];
            assert_eq!(end["outcome"]["published"], true, "round {round}: {end}");
        }
        assert!(
            !seen.iter().any(|e| e["event"] == "device_lost"),
            "{seen:#?}"
        );
        let (a, b) = (
            first(&seen, "first", "job_finished"),
            first(&seen, "second", "job_finished"),
        );
        let later = if a < b { "second" } else { "first" };
        assert!(first_reading(&seen, later) > a.min(b), "round {round}");
    }
    let history = get(&api, "/devices/second/history").await.json().unwrap();
    assert_eq!(history["profiles"].as_array().unwrap().len(), 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_job_waiting_for_a_shared_instrument_can_be_cancelled() {
    let dir = tempfile::tempdir().unwrap();
    let config = r#"[daemon]
simulated_time_scale = 0.01
simulated_idle_ages = false
[instruments.meter.simulated]
[[device]]
name = "busy"
instrument = "meter"
[[device]]
name = "queued"
instrument = "meter"
"#;
    let daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    start_on(&api, "busy", "calibrate").await;
    json_events_until(&mut events, Duration::from_secs(60), |seen| {
        seen.iter()
            .any(|e| e["event"] == "progress" && e["device"] == "busy")
    })
    .await;
    start_on(&api, "queued", "calibrate").await;
    // It says it waits, on the event stream as in its status.
    json_events_until(&mut events, Duration::from_secs(10), |seen| {
        seen.iter().any(|e| {
            e["device"] == "queued" && e["job"]["phase"] == "waiting for the instrument meter"
        })
    })
    .await;
    let cancelled = post(&api, "/devices/queued/jobs/cancel", "").await;
    assert_eq!(cancelled.status, 202, "{}", cancelled.text());
    let seen = json_events_until(&mut events, Duration::from_secs(10), |seen| {
        finished_on(seen, "queued") == 1
    })
    .await;
    let end = &seen[first(&seen, "queued", "job_finished")];
    assert_eq!(end["outcome"]["result"], "cancelled", "{end}");
    // Ended while the other still measures, and without reading anything.
    assert_eq!(finished_on(&seen, "busy"), 0);
    assert!(
        !seen
            .iter()
            .any(|e| e["device"] == "queued" && !e["job"]["last"].is_null())
    );
    let status = get(&api, "/devices/busy/status").await.json().unwrap();
    assert!(status["job"].is_object(), "{status}");
    assert!(
        !dir.path().join("state/queued/runs").exists()
            || std::fs::read_dir(dir.path().join("state/queued/runs"))
                .unwrap()
                .next()
                .is_none(),
        "a cancelled job that never had the instrument started no run"
    );
    // The device takes its next job at once.
    let again = post(&api, "/devices/queued/jobs", r#"{"kind": "verify"}"#).await;
    assert_eq!(again.status, 202, "{}", again.text());
}
