//! `GET /metrics` read by a real Prometheus scraping two daemons with three devices
//! between them, and the shipped scrape config and alert rules checked by promtool.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::daemon::{
    Server, finished_on, free_port, get, installed, json_events_until, post, start_daemon,
    subscribe_json, wait_for_port,
};

fn promtool(args: &[&str], dir: &Path) -> std::process::Output {
    let out = Command::new(installed("promtool"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "promtool {args:?}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn the_shipped_scrape_config_and_alert_rules_pass_promtool() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/prometheus");
    let out = promtool(&["check", "config", "prometheus.yml"], &dir);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("9 rules found"), "{text}");
    // The rule tests: the drift alert fires on a drifting device only after 30
    // minutes, and not on its steady neighbour; the others likewise.
    let out = promtool(&["test", "rules", "alerts_test.yml"], &dir);
    assert!(String::from_utf8_lossy(&out.stdout).contains("SUCCESS"));
    // A rule test that cannot fail proves nothing: with the drift threshold of the
    // rules raised past the test's drift, the same test fails.
    let scratch = tempfile::tempdir().unwrap();
    let rules = std::fs::read_to_string(dir.join("alerts.yml")).unwrap();
    assert!(rules.contains("> 0.01"));
    std::fs::write(
        scratch.path().join("alerts.yml"),
        rules.replace("> 0.01", "> 0.05"),
    )
    .unwrap();
    std::fs::copy(
        dir.join("alerts_test.yml"),
        scratch.path().join("alerts_test.yml"),
    )
    .unwrap();
    let failed = Command::new(installed("promtool"))
        .args(["test", "rules", "alerts_test.yml"])
        .current_dir(scratch.path())
        .output()
        .unwrap();
    assert!(!failed.status.success());
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&failed.stdout),
        String::from_utf8_lossy(&failed.stderr)
    );
    assert!(said.contains("ChromacalWhiteLuminanceDrifting"), "{said}");
}

/// A real Prometheus (its config, storage and log in `dir`) scraping the daemons on
/// loopback `ports` every second and evaluating `rules` as often; it and its port.
fn prometheus(dir: &Path, ports: &[u16], rules: Option<&Path>) -> (Server, u16) {
    let port = free_port();
    let config = dir.join("prometheus.yml");
    let targets: Vec<String> = ports.iter().map(|p| format!("'127.0.0.1:{p}'")).collect();
    let rule_files = rules.map_or(String::new(), |r| {
        format!("rule_files: ['{}']\n", r.display())
    });
    std::fs::write(
        &config,
        format!(
            "global:\n  scrape_interval: 1s\n  evaluation_interval: 1s\n{rule_files}scrape_configs:\n  - job_name: chromacal\n    static_configs:\n      - targets: [{}]\n",
            targets.join(", ")
        ),
    )
    .unwrap();
    let log = std::fs::File::create(dir.join("prometheus.log")).unwrap();
    let server = Server(
        Command::new(installed("prometheus"))
            .arg(format!("--config.file={}", config.display()))
            .arg(format!(
                "--storage.tsdb.path={}",
                dir.join("tsdb").display()
            ))
            .arg(format!("--web.listen-address=127.0.0.1:{port}"))
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap(),
    );
    wait_for_port(port, "prometheus");
    (server, port)
}

/// Prometheus's answer to `query` (the `data.result` array).
fn query(port: u16, query: &str) -> Vec<serde_json::Value> {
    let url = format!("http://127.0.0.1:{port}/api/v1/query");
    let reply: serde_json::Value = ureq::get(&url)
        .query("query", query)
        .call()
        .unwrap()
        .body_mut()
        .read_json()
        .unwrap();
    assert_eq!(reply["status"], "success", "{reply}");
    reply["data"]["result"].as_array().unwrap().clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn prometheus_scrapes_two_daemons_with_three_devices() {
    let dir = tempfile::tempdir().unwrap();
    let fast = "[daemon]\nsimulated_time_scale = 0.002\nsimulated_idle_ages = false\n";
    // Daemon A: two devices; daemon B: one (no [[device]]).
    let (port_a, port_b) = (free_port(), free_port());
    let a_dir = dir.path().join("a");
    let b_dir = dir.path().join("b");
    std::fs::create_dir_all(&a_dir).unwrap();
    std::fs::create_dir_all(&b_dir).unwrap();
    let a = start_daemon(
        &a_dir,
        &format!(
            "{fast}tcp = \"127.0.0.1:{port_a}\"\n[[device]]\nname = \"left\"\n[[device]]\nname = \"right\"\n[device.monitor]\npreset = \"lcd\"\n"
        ),
    );
    let b = start_daemon(&b_dir, &format!("{fast}tcp = \"127.0.0.1:{port_b}\"\n"));

    // Prometheus, scraping both every second.
    let (_prometheus, prometheus_port) = prometheus(dir.path(), &[port_a, port_b], None);

    // A calibration on each of the three devices.
    let (api_a, api_b) = (a.endpoint(), b.endpoint());
    let mut events_a = subscribe_json(&api_a, "/events");
    let mut events_b = subscribe_json(&api_b, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    for (api, path) in [
        (&api_a, "/devices/left/jobs"),
        (&api_a, "/devices/right/jobs"),
        (&api_b, "/jobs"),
    ] {
        let reply = post(api, path, r#"{"kind": "calibrate"}"#).await;
        assert_eq!(reply.status, 202, "{}", reply.text());
    }
    json_events_until(&mut events_a, Duration::from_secs(240), |seen| {
        finished_on(seen, "left") == 1 && finished_on(seen, "right") == 1
    })
    .await;
    json_events_until(&mut events_b, Duration::from_secs(240), |seen| {
        finished_on(seen, "default") == 1
    })
    .await;

    // What each daemon says of its profiles.
    let mut expected = Vec::new();
    for (api, port, path, device) in [
        (&api_a, port_a, "/devices/left/status", "left"),
        (&api_a, port_a, "/devices/right/status", "right"),
        (&api_b, port_b, "/status", "default"),
    ] {
        let status = get(api, path).await.json().unwrap();
        let mean = status["current_profile"]["held_out"]["mean"]
            .as_f64()
            .unwrap();
        expected.push((format!("127.0.0.1:{port}"), device.to_string(), mean));
    }

    // Prometheus has scraped them all: the held-out error of each device's profile,
    // its calibration counted, its readings and white luminance.
    let deadline = Instant::now() + Duration::from_secs(60);
    let held_out = loop {
        let result = query(
            prometheus_port,
            r#"chromacal_held_out_delta_e00{stat="mean"}"#,
        );
        let jobs = query(
            prometheus_port,
            r#"chromacal_jobs_total{kind="calibrate",outcome="ok"}"#,
        );
        if result.len() == 3 && jobs.len() == 3 {
            break result;
        }
        assert!(
            Instant::now() < deadline,
            "prometheus has {} series: {result:?}\n{}",
            result.len(),
            std::fs::read_to_string(dir.path().join("prometheus.log")).unwrap_or_default()
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    };
    for (instance, device, mean) in &expected {
        let series = held_out
            .iter()
            .find(|s| {
                s["metric"]["instance"] == instance.as_str()
                    && s["metric"]["device"] == device.as_str()
            })
            .unwrap_or_else(|| panic!("no series of {device} at {instance}: {held_out:?}"));
        let value: f64 = series["value"][1].as_str().unwrap().parse().unwrap();
        assert!(
            (value - mean).abs() <= 1e-9 * mean.abs().max(1.0),
            "{device}: {value} against {mean}"
        );
    }
    let up = query(prometheus_port, "sum(chromacal_device_up)");
    assert_eq!(up[0]["value"][1], "3");
    let whites = query(prometheus_port, "chromacal_white_luminance_cd_m2 > 10");
    assert_eq!(whites.len(), 3, "{whites:?}");
    let readings = query(
        prometheus_port,
        r#"sum by (instance) (chromacal_readings_total{status="ok"})"#,
    );
    assert_eq!(readings.len(), 2, "{readings:?}");
    let since = query(
        prometheus_port,
        "time() - chromacal_last_calibration_timestamp_seconds < 600",
    );
    assert_eq!(since.len(), 3, "{since:?}");
    // Nothing was verified yet, so nothing is said of it.
    assert!(query(prometheus_port, "chromacal_verification_delta_e00").is_empty());

    // /metrics needs no token on TCP, but the rest of the API does.
    let metrics = ureq::get(&format!("http://127.0.0.1:{port_a}/metrics"))
        .call()
        .unwrap()
        .body_mut()
        .read_to_string()
        .unwrap();
    assert!(
        metrics
            .contains("chromacal_jobs_total{device=\"left\",kind=\"calibrate\",outcome=\"ok\"} 1"),
        "{metrics}"
    );
    // Asked without OpenMetrics, the classic format, which promtool lints: clean
    // (units and `_total` in the names, an `_info` for the build).
    assert!(
        metrics.contains("chromacal_build_info{version="),
        "{metrics}"
    );
    let mut lint = Command::new(installed("promtool"))
        .args(["check", "metrics"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        lint.stdin
            .take()
            .unwrap()
            .write_all(metrics.as_bytes())
            .unwrap();
    }
    let lint = lint.wait_with_output().unwrap();
    assert!(
        lint.status.success() && lint.stdout.is_empty() && lint.stderr.is_empty(),
        "promtool check metrics: {}{}",
        String::from_utf8_lossy(&lint.stdout),
        String::from_utf8_lossy(&lint.stderr)
    );
    let refused = ureq::get(&format!("http://127.0.0.1:{port_a}/devices"))
        .config()
        .http_status_as_error(false)
        .build()
        .call()
        .unwrap();
    assert_eq!(refused.status(), 401);
}

/// The shipped rules, their `for:` scaled to the test: the devices' clocks run 500 ×
/// fast, so the drift alert's 30 minutes is 4 s here; the others fire at once.
fn rules_for_the_test(time_scale: f64) -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/prometheus");
    let rules = std::fs::read_to_string(dir.join("alerts.yml")).unwrap();
    let drift_for = format!("for: {}s", (1800.0 * time_scale).ceil());
    assert!(rules.contains("        for: 30m"));
    rules
        .lines()
        .map(|line| match line.trim_start().strip_prefix("for: ") {
            Some("30m") => format!("        {drift_for}"),
            Some(_) => "        for: 0s".to_string(),
            None => line.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn in_a_real_prometheus_the_drift_alert_fires_on_drift_only_and_five_faults_read_five() {
    let dir = tempfile::tempdir().unwrap();
    let scale = 0.002;
    let port = free_port();
    let missing = dir.path().join("no-such-tty");
    let daemon = start_daemon(
        dir.path(),
        &format!(
            r#"[daemon]
simulated_time_scale = {scale}
simulated_idle_ages = false
tcp = "127.0.0.1:{port}"
[[device]]
name = "steady"
[[device]]
name = "drifting"
[device.monitor.failures]
drift_per_hour = 0.03
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
        ),
    );
    let rules = dir.path().join("alerts.yml");
    std::fs::write(&rules, rules_for_the_test(scale)).unwrap();
    let (_prometheus, prometheus_port) = prometheus(dir.path(), &[port], Some(&rules));
    // The counters' zeros scraped before anything happens, as in a lab.
    let deadline = Instant::now() + Duration::from_secs(60);
    let scraped = || -> Option<()> {
        let reply: serde_json::Value =
            ureq::get(format!("http://127.0.0.1:{prometheus_port}/api/v1/query"))
                .query(
                    "query",
                    r#"chromacal_device_faults_total{device="unplugged", fault="open"} == 0"#,
                )
                .call()
                .ok()?
                .body_mut()
                .read_json()
                .ok()?;
        (!reply["data"]["result"].as_array()?.is_empty()).then_some(())
    };
    // (Prometheus answers 503 until its storage is ready.)
    while scraped().is_none() {
        assert!(
            Instant::now() < deadline,
            "prometheus never scraped the daemon"
        );
        tokio::time::sleep(Duration::from_millis(250)).await;
    }

    // 20 calibrations on the steady and the drifting monitor side by side; five jobs
    // on the unplugged one, each failing at the open.
    let api = daemon.endpoint();
    let mut events = subscribe_json(&api, "/events");
    tokio::time::sleep(Duration::from_millis(100)).await;
    for round in 1..=20 {
        let mut devices = vec!["steady", "drifting"];
        if round <= 5 {
            devices.push("unplugged");
        }
        for device in &devices {
            let reply = post(
                &api,
                &format!("/devices/{device}/jobs"),
                r#"{"kind": "calibrate"}"#,
            )
            .await;
            assert_eq!(reply.status, 202, "{}", reply.text());
        }
        json_events_until(&mut events, Duration::from_secs(120), |seen| {
            devices.iter().all(|d| finished_on(seen, d) == 1)
        })
        .await;
    }
    // A few scrapes and evaluations past the last reading.
    tokio::time::sleep(Duration::from_secs(8)).await;

    let fired = |alert: &str| -> Vec<String> {
        let mut devices: Vec<String> = query(
            prometheus_port,
            &format!(r#"max_over_time(ALERTS{{alertname="{alert}", alertstate="firing"}}[30m])"#),
        )
        .iter()
        .map(|s| s["metric"]["device"].as_str().unwrap_or("").to_string())
        .collect();
        devices.sort();
        devices
    };
    let drift = query(
        prometheus_port,
        "3600 * chromacal_white_luminance_drift_cd_m2_per_second / chromacal_white_luminance_cd_m2",
    );
    assert_eq!(
        fired("ChromacalWhiteLuminanceDrifting"),
        ["drifting"],
        "drift now, per hour: {drift:?}\n{}",
        std::fs::read_to_string(dir.path().join("prometheus.log")).unwrap_or_default()
    );
    // The drifting monitor's estimate is near its 3 %/h.
    let rate = drift
        .iter()
        .find(|s| s["metric"]["device"] == "drifting")
        .and_then(|s| s["value"][1].as_str()?.parse::<f64>().ok())
        .unwrap();
    assert!((0.02..0.04).contains(&rate), "{rate}");

    // Five faults read five: the counters were at 0 before the first one.
    let faults = query(
        prometheus_port,
        r#"sum without (fault) (increase(chromacal_device_faults_total{device="unplugged"}[30m]))"#,
    );
    let value: f64 = faults[0]["value"][1].as_str().unwrap().parse().unwrap();
    assert!(
        (value - 5.0).abs() < 0.5,
        "{value}: {:?}",
        query(
            prometheus_port,
            r#"chromacal_device_faults_total{device="unplugged"}[30m]"#
        )
    );
    assert_eq!(fired("ChromacalDeviceFaultsClimbing"), ["unplugged"]);
    let alerts: serde_json::Value =
        ureq::get(&format!("http://127.0.0.1:{prometheus_port}/api/v1/alerts"))
            .call()
            .unwrap()
            .body_mut()
            .read_json()
            .unwrap();
    let climbing = alerts["data"]["alerts"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["labels"]["alertname"] == "ChromacalDeviceFaultsClimbing")
        .unwrap_or_else(|| panic!("{alerts}"));
    assert!(
        climbing["annotations"]["summary"]
            .as_str()
            .unwrap()
            .contains(": 5 device faults in the last hour"),
        "{climbing}"
    );
}
