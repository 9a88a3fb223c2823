//! The daemon's events and state on a real Mosquitto broker, read by Mosquitto's own
//! client: a calibration's events, a failed verification, the retained state a new
//! subscriber gets, the last will after a kill -9 and none after a SIGTERM; and a
//! broker that is down or restarted, which holds no job up and loses no outcome.

mod common;

use std::io::BufRead;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use chromacal::daemon::events::Event;
use common::daemon::{
    Server, free_port, get, installed, post, start_daemon, wait_for_port, wait_idle,
};

/// Mosquitto on loopback `port`, without persistence (its config in `dir`).
fn mosquitto_on(dir: &Path, port: u16) -> Server {
    mosquitto_with(dir, port, false)
}

/// Mosquitto on loopback `port`; with `persistent`, its sessions and queued messages
/// are saved in `dir` when it stops and restored when it starts again, as a broker
/// restarted by its service manager does. (Mosquitto started as root drops to its own
/// user: `dir` must let that user write.)
fn mosquitto_with(dir: &Path, port: u16, persistent: bool) -> Server {
    mosquitto_configured(dir, port, persistent, "allow_anonymous true\n")
}

/// Mosquitto on loopback `port` with `access` (its authentication lines).
fn mosquitto_configured(dir: &Path, port: u16, persistent: bool, access: &str) -> Server {
    let config = dir.join(format!("mosquitto-{port}.conf"));
    let persistence = if persistent {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o777)).unwrap();
        format!(
            "persistence true\npersistence_location {}/\n",
            dir.display()
        )
    } else {
        "persistence false\n".to_string()
    };
    std::fs::write(
        &config,
        format!("listener {port} 127.0.0.1\n{access}{persistence}"),
    )
    .unwrap();
    Server(
        Command::new(installed("mosquitto"))
            .arg("-c")
            .arg(&config)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    )
}

/// A broker on a free loopback port. A port another test's broker took between
/// `free_port` and the bind makes this broker exit: another port is tried, so that
/// no test talks to another's broker.
fn broker(dir: &Path) -> (Server, u16) {
    broker_with(dir, false)
}

/// [`broker`], persistent or not (see [`mosquitto_with`]).
fn broker_with(dir: &Path, persistent: bool) -> (Server, u16) {
    for _ in 0..5 {
        let port = free_port();
        let mut server = mosquitto_with(dir, port, persistent);
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            if let Ok(Some(_)) = server.0.try_wait() {
                break; // it could not bind: another port
            }
            if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
                // Ours, if it still runs once the port answers.
                std::thread::sleep(Duration::from_millis(50));
                if matches!(server.0.try_wait(), Ok(None)) {
                    return (server, port);
                }
                break;
            }
            assert!(
                Instant::now() < deadline,
                "mosquitto did not listen on {port}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    panic!("mosquitto could not bind a free port in 5 tries");
}

/// `mosquitto_sub` on `topic`: (topic, JSON payload) as they arrive.
struct Subscriber {
    _child: Server,
    lines: mpsc::Receiver<(String, serde_json::Value)>,
}

fn subscribe(port: u16, topic: &str) -> Subscriber {
    subscribe_as(port, topic, None)
}

/// [`subscribe`]; with `session`, a persistent session of that client id at QoS 1:
/// the broker keeps what is published while the subscriber is away (and across its
/// own restart, when persistent), and `mosquitto_sub` reconnects by itself.
fn subscribe_as(port: u16, topic: &str, session: Option<&str>) -> Subscriber {
    let port = port.to_string();
    let mut args = vec!["-h", "127.0.0.1", "-p", &port, "-v", "-t", topic];
    if let Some(id) = session {
        args.extend(["-c", "-i", id, "-q", "1"]);
    }
    let mut child = Command::new(installed("mosquitto_sub"))
        .args(&args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            let Some((topic, payload)) = line.split_once(' ') else {
                continue;
            };
            let payload = serde_json::from_str(payload)
                .unwrap_or_else(|e| panic!("not JSON on {topic} ({e}): {payload}"));
            if tx.send((topic.to_string(), payload)).is_err() {
                return;
            }
        }
    });
    Subscriber {
        _child: Server(child),
        lines: rx,
    }
}

impl Subscriber {
    /// Messages until one on `topic` that `accept` takes (returned last).
    fn until(
        &self,
        topic: &str,
        timeout: Duration,
        accept: impl Fn(&serde_json::Value) -> bool,
    ) -> Vec<(String, serde_json::Value)> {
        let deadline = Instant::now() + timeout;
        let mut seen = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let Ok((t, payload)) = self.lines.recv_timeout(left) else {
                panic!("nothing on {topic} within {timeout:?}; seen: {seen:#?}");
            };
            let done = t == topic && accept(&payload);
            seen.push((t, payload));
            if done {
                return seen;
            }
        }
    }
}

const PREFIX: &str = "lab/testhost/default";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibration_and_a_failed_verification_reach_the_broker_with_state_and_last_will() {
    let dir = tempfile::tempdir().unwrap();
    let (_broker, port) = broker(dir.path());
    let live = subscribe(port, "lab/#");
    // A threshold no verification meets: the verification fails, and only says so.
    let config = format!(
        "[daemon]\nsimulated_time_scale = 0.002\nsimulated_idle_ages = false\n[schedule]\nthreshold_de00 = 0.001\nescalate = false\n[mqtt]\nbroker = \"127.0.0.1:{port}\"\nprefix = \"lab\"\nhost = \"testhost\"\n"
    );
    let mut daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    live.until("lab/testhost/status", Duration::from_secs(20), |p| {
        p["online"] == true && p["devices"][0] == "default"
    });

    let reply = post(&api, "/jobs", r#"{"kind": "calibrate"}"#).await;
    assert_eq!(reply.status, 202, "{}", reply.text());
    let id = reply.json().unwrap()["id"].as_str().unwrap().to_string();
    let seen = live.until(
        &format!("{PREFIX}/event/job_finished"),
        Duration::from_secs(240),
        |p| p["job"]["id"] == id.as_str(),
    );
    let topics: Vec<&str> = seen.iter().map(|(t, _)| t.as_str()).collect();
    let at = |topic: &str| {
        topics
            .iter()
            .position(|t| *t == topic)
            .unwrap_or_else(|| panic!("no {topic} in {topics:?}"))
    };
    let started = at(&format!("{PREFIX}/event/job_started"));
    let published = at(&format!("{PREFIX}/event/published"));
    let finished = at(&format!("{PREFIX}/event/job_finished"));
    assert!(started < published && published < finished);
    let progress = topics
        .iter()
        .filter(|t| **t == format!("{PREFIX}/event/progress"))
        .count();
    assert!(progress > 20, "{progress} progress events");
    let (_, profile) = &seen[published];
    assert_eq!(profile["device"], "default");
    assert_eq!(profile["host"], "testhost");
    let profile_id = profile["profile_id"].as_str().unwrap().to_string();
    let held_out = profile["held_out"]["mean"].as_f64().unwrap();
    let status = get(&api, "/status").await.json().unwrap();
    assert_eq!(status["current_profile"]["id"], profile_id.as_str());
    assert_eq!(
        status["current_profile"]["held_out"]["mean"].as_f64(),
        Some(held_out)
    );

    // The verification fails its threshold; the broker hears it, and the state says so.
    wait_idle(&api, Duration::from_secs(10)).await;
    let reply = post(&api, "/jobs", r#"{"kind": "verify"}"#).await;
    assert_eq!(reply.status, 202, "{}", reply.text());
    let seen = live.until(
        &format!("{PREFIX}/event/verification"),
        Duration::from_secs(120),
        |_| true,
    );
    let (_, verification) = seen.last().unwrap();
    let mean = verification["record"]["stats"]["mean"].as_f64().unwrap();
    assert!(mean > 0.001, "{verification}");
    assert_eq!(verification["record"]["profile_id"], profile_id.as_str());
    live.until(&format!("{PREFIX}/state"), Duration::from_secs(30), |p| {
        p["last_verification"]["passed"] == false
    });
    wait_idle(&api, Duration::from_secs(30)).await;

    // A client that connects now gets the retained status and state at once (in
    // whatever order the broker keeps them).
    let late = subscribe(port, "lab/#");
    let mut retained = std::collections::BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while retained.len() < 2 {
        let left = deadline.saturating_duration_since(Instant::now());
        let (topic, payload) = late
            .lines
            .recv_timeout(left)
            .unwrap_or_else(|_| panic!("retained so far: {retained:#?}"));
        retained.insert(topic, payload);
    }
    let state = &retained[&format!("{PREFIX}/state")];
    assert_eq!(
        state["current_profile"]["id"],
        profile_id.as_str(),
        "{state}"
    );
    assert_eq!(state["last_verification"]["passed"], false, "{state}");
    assert_eq!(state["last_job"]["kind"], "verify", "{state}");
    assert!(state["job"].is_null(), "{state}");
    assert_eq!(retained["lab/testhost/status"]["online"], true);

    // Killed without a word: the broker gives out the last will, retained.
    daemon.kill();
    live.until("lab/testhost/status", Duration::from_secs(30), |p| {
        p["online"] == false && p["reason"] == "lost"
    });
    let after = subscribe(port, "lab/testhost/status");
    after.until("lab/testhost/status", Duration::from_secs(10), |p| {
        p["online"] == false
    });
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clean_stop_leaves_the_status_stopped_and_the_broker_gives_no_will() {
    let dir = tempfile::tempdir().unwrap();
    let (_broker, port) = broker(dir.path());
    let live = subscribe(port, "lab/testhost/status");
    let config = format!(
        "[daemon]\nsimulated_time_scale = 0.002\n[mqtt]\nbroker = \"127.0.0.1:{port}\"\nprefix = \"lab\"\nhost = \"testhost\"\n"
    );
    // Three times over: the race this guards against (the socket closed with the
    // broker's acknowledgements unread) lost every SIGTERM of eight.
    for round in 0..3 {
        let state = dir.path().join(format!("run-{round}"));
        std::fs::create_dir_all(&state).unwrap();
        let mut daemon = start_daemon(&state, &config);
        let pid = daemon.child.id();
        live.until("lab/testhost/status", Duration::from_secs(20), |p| {
            p["online"] == true && p["pid"] == pid
        });
        let (clean, took) = daemon.terminate();
        assert!(clean, "round {round}: {}", daemon.log_text());
        assert!(took < Duration::from_secs(10), "round {round}: {took:?}");
        live.until("lab/testhost/status", Duration::from_secs(10), |p| {
            p["online"] == false && p["reason"] == "stopped"
        });
        // No last will after it: a will would come within the broker's own
        // handling of the closed socket, milliseconds.
        if let Ok((topic, payload)) = live.lines.recv_timeout(Duration::from_millis(1500)) {
            panic!("round {round}: after \"stopped\", {topic}: {payload}");
        }
        let fresh = subscribe(port, "lab/testhost/status");
        fresh.until("lab/testhost/status", Duration::from_secs(10), |p| {
            assert_eq!(p["reason"], "stopped", "round {round}: retained {p}");
            true
        });
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broker_restarted_mid_job_loses_no_outcome_and_replays_no_stale_progress() {
    let dir = tempfile::tempdir().unwrap();
    let (broker, port) = broker_with(dir.path(), true);
    let mut broker = Some(broker);
    // A persistent session: the broker keeps what arrives for it across its restart.
    let watcher = subscribe_as(
        port,
        "lab/#",
        Some(&format!("watcher-{}", std::process::id())),
    );
    let config = format!(
        "[daemon]\nsimulated_time_scale = 0.05\nsimulated_idle_ages = false\n[mqtt]\nbroker = \"127.0.0.1:{port}\"\nprefix = \"lab\"\nhost = \"testhost\"\nqueue = 8\n"
    );
    let state = dir.path().join("state");
    std::fs::create_dir_all(&state).unwrap();
    let daemon = start_daemon(&state, &config);
    let api = daemon.endpoint();
    watcher.until("lab/testhost/status", Duration::from_secs(20), |p| {
        p["online"] == true
    });
    let mut events = common::daemon::subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = common::daemon::start_job(&api, "calibrate").await;
    watcher.until(
        &format!("{PREFIX}/event/progress"),
        Duration::from_secs(60),
        |_| true,
    );

    // The broker stops (saving its sessions) while the job measures, and the job ends
    // while it is away.
    if let Some(mut broker) = broker.take() {
        let pid = broker.0.id().to_string();
        assert!(
            Command::new("kill")
                .args(["-TERM", &pid])
                .status()
                .unwrap()
                .success()
        );
        broker.0.wait().unwrap();
    }
    let (seen, outcome) =
        common::daemon::events_of_job(&mut events, &id, Duration::from_secs(240)).await;
    assert_eq!(outcome.result, "ok", "{outcome:?}");
    assert!(outcome.published, "{outcome:?}");
    let outcomes_while_away = seen
        .iter()
        .filter(|e| !matches!(e, Event::Progress { .. } | Event::Warmup { .. }))
        .count();
    assert!(outcomes_while_away >= 3, "{seen:#?}");

    let _back = mosquitto_with(dir.path(), port, true);
    wait_for_port(port, "mosquitto");
    let arrived = watcher.until(
        &format!("{PREFIX}/event/job_finished"),
        Duration::from_secs(60),
        |p| p["job"]["id"] == id.as_str(),
    );
    let names: Vec<&str> = arrived.iter().map(|(t, _)| t.as_str()).collect();
    assert!(
        names.contains(&format!("{PREFIX}/event/published").as_str()),
        "{names:#?}"
    );
    // What the client had in hand when the broker went may come late; the progress
    // of the rest of the job may not. (With the queue of 8 full of progress, the
    // outcomes were dropped before.)
    let stale = names
        .iter()
        .filter(|t| t.ends_with("/event/progress"))
        .count();
    eprintln!(
        "after the restart: {} messages, {stale} of them progress",
        names.len()
    );
    assert!(
        stale <= 4,
        "{stale} stale progress messages replayed: {names:#?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_the_broker_down_a_calibration_completes_and_the_dropped_events_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    // A stopped broker: nothing listens on its port. The port is below the ephemeral
    // range, so no other test's broker (on a port the system handed out) takes it.
    let port = (20_000 + (std::process::id() % 9_000) as u16..30_000)
        .find(|p| std::net::TcpStream::connect(("127.0.0.1", *p)).is_err())
        .unwrap();
    let config = format!(
        "[daemon]\nsimulated_time_scale = 0.002\nsimulated_idle_ages = false\n[mqtt]\nbroker = \"127.0.0.1:{port}\"\nqueue = 8\n"
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    let mut events = common::daemon::subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = common::daemon::start_job(&api, "calibrate").await;
    let (seen, outcome) =
        common::daemon::events_of_job(&mut events, &id, Duration::from_secs(240)).await;
    assert_eq!(outcome.result, "ok", "{outcome:?}");
    assert!(outcome.published, "{outcome:?}");
    let metrics = get(&api, "/metrics").await.text();
    let count = |name: &str| -> f64 {
        metrics
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.rsplit(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no {name} in {metrics}"))
    };
    let dropped = count("chromacal_mqtt_messages_dropped_total");
    let queued = count("chromacal_mqtt_messages_queued_total");
    // Outcome events wait for the broker (up to the queue's 8 in the client, the rest
    // in the backlog); the job's progress was coalesced and, the job over, dropped.
    let progress = seen
        .iter()
        .filter(|e| matches!(e, Event::Progress { .. } | Event::Warmup { .. }))
        .count();
    assert!(progress > 20, "{progress} progress events");
    assert!(queued <= 10.0, "{queued}");
    assert_eq!(dropped, progress as f64, "{metrics}");
    assert!(
        daemon.log_text().contains("progress coalesced"),
        "{}",
        daemon.log_text()
    );

    // The broker comes back on its port: the daemon connects again by itself and
    // publishes its retained status and the device's newest state.
    let _back = mosquitto_on(dir.path(), port);
    wait_for_port(port, "mosquitto");
    let profile = get(&api, "/status").await.json().unwrap()["current_profile"]["id"].clone();
    assert!(profile.is_string());
    let late = subscribe(port, "chromacal/#");
    let topic = |end: &str| format!("chromacal/{}/default/{end}", chromacal::daemon::host_name());
    late.until(&topic("state"), Duration::from_secs(30), |p| {
        p["current_profile"]["id"] == profile && p["last_job"]["result"] == "ok"
    });
}

/// Issue 28, item 7: a broker that refuses the login is named as such ("wrong user
/// name or password", "not authorised"), not as "unreachable"; with the right
/// credentials the daemon connects.
#[test]
fn a_broker_refusing_the_password_is_named_not_called_unreachable() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    // Mosquitto drops to its own user: it must read its password file.
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let passwords = dir.path().join("passwords");
    let made = Command::new("mosquitto_passwd")
        .args(["-b", "-c"])
        .arg(&passwords)
        .args(["lab", "right-password"])
        .output()
        .unwrap();
    assert!(made.status.success(), "{made:?}");
    std::fs::set_permissions(&passwords, std::fs::Permissions::from_mode(0o644)).unwrap();
    let port = free_port();
    let _broker = mosquitto_configured(
        dir.path(),
        port,
        false,
        &format!(
            "allow_anonymous false\npassword_file {}\n",
            passwords.display()
        ),
    );
    wait_for_port(port, "mosquitto");
    for (password, said) in [
        ("wrong-password", "the MQTT broker refused the connection"),
        ("right-password", "MQTT connected"),
    ] {
        let run = tempfile::tempdir().unwrap();
        let credentials = run.path().join("mqtt.credentials");
        std::fs::write(&credentials, format!("lab\n{password}\n")).unwrap();
        std::fs::set_permissions(&credentials, std::fs::Permissions::from_mode(0o600)).unwrap();
        let mut daemon = start_daemon(
            run.path(),
            &format!(
                "[mqtt]\nbroker = \"127.0.0.1:{port}\"\ncredentials_file = \"mqtt.credentials\"\n"
            ),
        );
        let deadline = Instant::now() + Duration::from_secs(20);
        while !daemon.log_text().contains(said) {
            assert!(
                Instant::now() < deadline,
                "{password}: no \"{said}\" in\n{}",
                daemon.log_text()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let log = daemon.log_text();
        assert!(!log.contains("unreachable"), "{log}");
        if password == "wrong-password" {
            assert!(
                log.contains("wrong user name or password") || log.contains("not authorised"),
                "{log}"
            );
        }
        daemon.terminate();
    }
}
