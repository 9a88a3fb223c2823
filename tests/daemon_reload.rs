//! Rereading the config in a running daemon (SIGHUP, `chromacal daemon reload`):
//! devices added start, removed and changed ones leave after their running job, the
//! others' jobs go on undisturbed, and a broken config is refused while the daemon
//! runs on with the one it had.

mod common;

use std::time::Duration;

use common::daemon::{get, json_events_until, post, start_daemon, subscribe_json};

const TOP: &str = r#"[daemon]
simulated_time_scale = 0.03
simulated_idle_ages = false
"#;

/// The config with these `[[device]]` sections.
fn config(devices: &str) -> String {
    format!("{TOP}{devices}")
}

async fn device_names(api: &chromacal::daemon::client::Endpoint) -> Vec<String> {
    let reply = get(api, "/devices").await.json().unwrap();
    reply["devices"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["name"].as_str().unwrap().to_string())
        .collect()
}

fn sighup(daemon: &common::daemon::TestDaemon) {
    let status = std::process::Command::new("kill")
        .args(["-HUP", &daemon.child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

fn metric_line(metrics: &str, prefix: &str) -> Option<String> {
    metrics
        .lines()
        .find(|l| l.starts_with(prefix))
        .map(String::from)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sighup_adds_removes_and_changes_devices_without_disturbing_a_running_job() {
    let dir = tempfile::tempdir().unwrap();
    let v1 = config(
        r#"[[device]]
name = "a"
[[device]]
name = "b"
[[device]]
name = "d"
[device.monitor]
preset = "lcd"
[device.schedule]
verify_every_s = 0.2
"#,
    );
    let mut daemon = start_daemon(dir.path(), &v1);
    let api = daemon.endpoint();
    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    let start = |device: &'static str| {
        let api = api.clone();
        async move {
            let reply = post(
                &api,
                &format!("/devices/{device}/jobs"),
                r#"{"kind": "calibrate"}"#,
            )
            .await;
            assert_eq!(reply.status, 202, "{device}: {}", reply.text());
            reply.json().unwrap()["id"].as_str().unwrap().to_string()
        }
    };
    let job_a = start("a").await;
    let job_d = start("d").await;
    // Both measuring.
    json_events_until(&mut events, Duration::from_secs(60), |seen| {
        ["a", "d"].iter().all(|d| {
            seen.iter().any(|e| {
                e["event"] == "progress" && e["device"] == *d && !e["job"]["last"].is_null()
            })
        })
    })
    .await;

    // v2: a as it was, b with its own threshold, d gone, c new.
    let v2 = config(
        r#"[[device]]
name = "a"
[[device]]
name = "b"
[device.schedule]
threshold_de00 = 2.5
[[device]]
name = "c"
[device.monitor]
preset = "lcd"
"#,
    );
    std::fs::write(dir.path().join("config.toml"), &v2).unwrap();
    sighup(&daemon);
    let seen = json_events_until(&mut events, Duration::from_secs(30), |seen| {
        seen.iter().any(|e| e["event"] == "config_reloaded")
    })
    .await;
    let reloaded = seen.last().unwrap();
    assert_eq!(reloaded["origin"], "SIGHUP");
    assert_eq!(reloaded["added"], serde_json::json!(["c"]), "{reloaded}");
    assert_eq!(reloaded["removed"], serde_json::json!(["d"]), "{reloaded}");
    assert_eq!(reloaded["changed"], serde_json::json!(["b"]), "{reloaded}");
    assert_eq!(reloaded["restart_needed"], serde_json::json!([]));
    assert!(
        daemon.child.try_wait().unwrap().is_none(),
        "SIGHUP ended the daemon"
    );

    // d finishes its job but takes no new one; c takes jobs at once.
    let d = get(&api, "/devices/d/status").await.json().unwrap();
    assert_eq!(d["retiring"], true, "{d}");
    assert_eq!(d["job"]["id"], job_d.as_str(), "{d}");
    let refused = post(&api, "/devices/d/jobs", r#"{"kind": "verify"}"#).await;
    assert_eq!(refused.status, 503, "{}", refused.text());
    assert!(
        refused.error_message().contains("leaving"),
        "{}",
        refused.text()
    );
    let job_c = start("c").await;

    // a and d end as they would have: their whole calibration, published.
    let seen = json_events_until(&mut events, Duration::from_secs(240), |seen| {
        [&job_a, &job_d, &job_c].iter().all(|id| {
            seen.iter()
                .any(|e| e["event"] == "job_finished" && e["job"]["id"] == id.as_str())
        })
    })
    .await;
    for id in [&job_a, &job_d, &job_c] {
        let end = seen
            .iter()
            .find(|e| e["event"] == "job_finished" && e["job"]["id"] == id.as_str())
            .unwrap();
        assert_eq!(end["outcome"]["result"], "ok", "{end}");
        assert_eq!(end["outcome"]["published"], true, "{end}");
    }
    let state = dir.path().join("state");
    let journal = common::newest_run(&state.join("a"));
    let (header, entries, _) = chromacal::journal::Journal::read(&journal).unwrap();
    common::assert_each_planned_patch_once(&header, &entries);

    // Once its job ended, d left: its store is free, its series gone; c's are there
    // from 0, and b runs with its new threshold.
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while device_names(&api).await.contains(&"d".to_string()) {
        assert!(std::time::Instant::now() < deadline, "d never left");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(device_names(&api).await, ["a", "b", "c"]);
    // Its schedule ended with it: no verification was tried on it once retired.
    let log = daemon.log_text();
    assert!(
        !log.contains("d is leaving the daemon"),
        "the retired device's schedule went on: {log}"
    );
    let store = chromacal::profile::store::ProfileStore::new(&state.join("d"));
    let lock = store.lock("the test");
    assert!(lock.is_ok(), "d's store is still held: {lock:?}");
    drop(lock);
    assert!(state.join("d/current.toml").is_file());
    let metrics = get(&api, "/metrics").await.text();
    assert!(!metrics.contains("device=\"d\""), "{metrics}");
    assert!(
        metrics.contains("chromacal_device_faults_total{device=\"c\",fault=\"open\"} 0"),
        "{metrics}"
    );
    assert_eq!(
        metric_line(
            &metrics,
            "chromacal_verification_threshold_delta_e00{device=\"b\"}"
        )
        .as_deref(),
        Some("chromacal_verification_threshold_delta_e00{device=\"b\"} 2.5"),
    );
    assert_eq!(
        metric_line(
            &metrics,
            "chromacal_verification_threshold_delta_e00{device=\"a\"}"
        )
        .as_deref(),
        Some("chromacal_verification_threshold_delta_e00{device=\"a\"} 1.0"),
    );

    // A broken config is refused, said on the command line with where it breaks,
    // logged and told; the daemon runs on with the devices it had.
    std::fs::write(
        dir.path().join("config.toml"),
        format!("{v2}[[device]]\nname = \"e\"\n[device.monitor]\npreset = \"plasma\"\n"),
    )
    .unwrap();
    let socket = daemon.socket.display().to_string();
    let out = common::chromacal()
        .args(["daemon", "reload", "--socket", &socket])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("422") && stderr.contains("plasma") && stderr.contains("config.toml"),
        "{stderr}"
    );
    let seen = json_events_until(&mut events, Duration::from_secs(10), |seen| {
        seen.iter().any(|e| e["event"] == "config_refused")
    })
    .await;
    assert_eq!(seen.last().unwrap()["origin"], "api");
    assert_eq!(device_names(&api).await, ["a", "b", "c"]);
    let metrics = get(&api, "/metrics").await.text();
    assert!(
        metrics
            .lines()
            .any(|l| l == "chromacal_config_last_reload_successful 0"),
        "{metrics}"
    );
    assert!(daemon.log_text().contains("config reload refused"));

    // Put right, it is taken: a [daemon] change is said to wait for a restart.
    std::fs::write(
        dir.path().join("config.toml"),
        v2.replace(
            "simulated_idle_ages = false",
            "simulated_idle_ages = false\nburst = 50",
        ),
    )
    .unwrap();
    let out = common::succeed(common::chromacal().args(["daemon", "reload", "--socket", &socket]));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("added none; removed none; changed none")
            && stdout.contains("[daemon] take effect at the next restart"),
        "{stdout}"
    );
    let metrics = get(&api, "/metrics").await.text();
    assert!(
        metrics
            .lines()
            .any(|l| l == "chromacal_config_last_reload_successful 1"),
        "{metrics}"
    );

    // A stop is still clean.
    let (clean, _) = daemon.terminate();
    assert!(clean, "{}", daemon.log_text());
}
