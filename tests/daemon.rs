//! The daemon as a user meets it: a process with a unix socket, jobs started and
//! followed through the API, an emulated instrument on a pty, refusals for those who
//! may not ask, and the systemd side (readiness, watchdog, stop).

use std::time::Duration;

use chromacal::daemon::events::Event;
use chromacal::profile::Profile;

mod common;
use common::daemon::{
    events_of_job, events_until, get, post, start_daemon, start_daemon_with, start_job, subscribe,
    wait_idle,
};
use common::{CRT_PRIMARIES, assert_same_model, emulate, in_process_profile};

const FAST: &str = "[daemon]\nsimulated_time_scale = 0.001\n";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_calibration_started_through_the_api_measures_an_emulated_instrument_and_publishes() {
    let dir = tempfile::tempdir().unwrap();
    let reference_config = dir.path().join("reference.toml");
    std::fs::write(&reference_config, CRT_PRIMARIES).unwrap();
    let reference = in_process_profile(&reference_config, &dir.path().join("reference"));

    let emulator = emulate(&["--instrument", "pr670", "--time-scale", "0.002"]);
    let config = format!(
        "{CRT_PRIMARIES}[instrument]\ndriver = \"pr670\"\nport = \"{}\"\n[instrument.options]\ntiming_scale = 0.002\n[display]\nscreen = \"{}\"\n",
        emulator.device, emulator.screen
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    let status = get(&api, "/status").await.json().unwrap();
    assert!(
        status["job"].is_null() && status["current_profile"].is_null(),
        "{status}"
    );
    assert_eq!(get(&api, "/profile").await.status, 404);

    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = start_job(&api, "calibrate").await;
    // A second job while one runs is refused.
    let busy = post(&api, "/jobs", r#"{"kind": "verify"}"#).await;
    assert_eq!(busy.status, 409, "{}", busy.text());
    assert!(busy.error_message().contains(&id), "{}", busy.text());

    let (seen, _) = events_of_job(&mut events, &id, Duration::from_secs(120)).await;
    assert!(
        matches!(&seen[0], Event::JobStarted { job } if job.id == id),
        "{:?}",
        seen[0]
    );
    let progress: Vec<_> = seen
        .iter()
        .filter_map(|e| match e {
            Event::Progress { job } => Some(job.clone()),
            _ => None,
        })
        .collect();
    let total = progress.last().unwrap().total;
    assert_eq!(progress.len(), total, "one progress event per reading");
    assert!(progress.windows(2).all(|w| w[1].done == w[0].done + 1));
    assert!(
        progress
            .iter()
            .all(|p| p.last.is_some_and(|l| l.luminance.is_some()))
    );
    assert!(progress.iter().skip(5).all(|p| p.eta_s.is_some()));
    // The phase says what the job does: measuring while patches are left, fitting
    // once the last is read.
    assert!(progress[..total - 1].iter().all(|p| p.phase == "measuring"));
    assert_eq!(progress.last().unwrap().phase, "fitting");
    let published = seen.iter().find_map(|e| match e {
        Event::Published { profile_id, .. } => Some(profile_id.clone()),
        _ => None,
    });
    let Some(Event::JobFinished { outcome, .. }) = seen.last() else {
        unreachable!()
    };
    assert_eq!(outcome.result, "ok", "{outcome:?}");
    assert!(outcome.published);
    assert_eq!(published, outcome.profile_id);

    // The published profile, fetched in both forms, is the in-process one within noise.
    let toml = get(&api, "/profile").await;
    assert_eq!(toml.status, 200);
    let profile = Profile::from_toml(&toml.text(), "GET /profile").unwrap();
    assert_eq!(Some(profile.id.clone()), published);
    assert!(
        !profile
            .provenance
            .instrument
            .as_ref()
            .unwrap()
            .name
            .contains("simulated")
    );
    assert_same_model("daemon", &profile, &reference);
    let json = get(&api, "/profile?format=json").await.json().unwrap();
    assert_eq!(json["id"], profile.id.as_str());
    let status = get(&api, "/status").await.json().unwrap();
    assert_eq!(status["current_profile"]["id"], profile.id.as_str());
    assert_eq!(status["last_job"]["outcome"]["result"], "ok");
    // The stable path other tools read.
    let current = Profile::read(&daemon.state.join("current.toml")).unwrap();
    assert_eq!(current.id, profile.id);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_rollback_and_a_verification_are_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start_daemon(dir.path(), FAST);
    let api = daemon.endpoint();
    // Nothing to roll back to, nothing to verify yet.
    assert_eq!(post(&api, "/rollback", "").await.status, 409);
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = start_job(&api, "verify").await;
    let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(30)).await;
    assert_eq!(outcome.result, "failed");
    assert!(
        outcome.message.contains("no current profile"),
        "{outcome:?}"
    );

    let mut ids = Vec::new();
    for _ in 0..2 {
        let id = start_job(&api, "calibrate").await;
        let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(60)).await;
        assert!(outcome.published, "{outcome:?}");
        ids.push(outcome.profile_id.clone().unwrap());
    }
    let id = start_job(&api, "verify").await;
    let (seen, _) = events_of_job(&mut events, &id, Duration::from_secs(30)).await;
    let record = seen
        .iter()
        .find_map(|e| match e {
            Event::Verification { record } => Some(record.clone()),
            _ => None,
        })
        .expect("a verification event");
    assert_eq!(record.profile_id, ids[1]);
    assert_eq!(record.delta_e.len(), 8);
    let mean = record.stats.unwrap().mean;
    assert!(mean < 0.5, "a fresh profile verifies well: {mean}");
    let phases: Vec<String> = seen
        .iter()
        .filter_map(|e| match e {
            Event::Progress { job } => Some(job.phase.clone()),
            _ => None,
        })
        .collect();
    assert_eq!(
        phases.last().map(String::as_str),
        Some("comparing with the profile")
    );
    assert!(!record.escalated);

    let history = get(&api, "/history").await.json().unwrap();
    assert_eq!(history["current"], ids[1].as_str());
    let listed: Vec<&str> = history["profiles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["id"].as_str().unwrap())
        .collect();
    assert_eq!(listed, [ids[0].as_str(), ids[1].as_str()]);
    assert_eq!(history["verifications"].as_array().unwrap().len(), 1);

    // Roll back to the first, then forward again by id; unknown ids are refused.
    let reply = post(&api, "/rollback", "{}").await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert_eq!(reply.json().unwrap()["id"], ids[0].as_str());
    let current = Profile::read(&daemon.state.join("current.toml")).unwrap();
    assert_eq!(current.id, ids[0]);
    let rolled = events_until(&mut events, Duration::from_secs(5), |e| {
        matches!(e, Event::RolledBack { .. })
    })
    .await;
    assert!(matches!(rolled.last(), Some(Event::RolledBack { entry }) if entry.id == ids[0]));
    let reply = post(&api, "/rollback", &format!("{{\"to\": \"{}\"}}", ids[1])).await;
    assert_eq!(reply.status, 200);
    let reply = post(&api, "/rollback", r#"{"to": "no-such-profile"}"#).await;
    assert_eq!(reply.status, 409);
    assert!(reply.error_message().contains("no-such-profile"));
    let current = Profile::read(&daemon.state.join("current.toml")).unwrap();
    assert_eq!(current.id, ids[1]);

    // Ids that would leave the store: a readable profile planted outside it, by a
    // relative path and by an absolute one, and the store's own current profile. Each
    // is refused as an id (400), and the current profile stays as it was.
    let outside = dir.path().join("outside");
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::copy(daemon.state.join("current.toml"), outside.join("evil.toml")).unwrap();
    let relative = format!(
        "{}/outside/evil",
        std::iter::repeat_n("..", daemon.state.components().count())
            .collect::<Vec<_>>()
            .join("/")
    );
    let absolute = outside.join("evil").display().to_string();
    for id in [
        relative.as_str(),
        "../../outside/evil",
        absolute.as_str(),
        "../current",
    ] {
        let body = serde_json::json!({ "to": id }).to_string();
        let reply = post(&api, "/rollback", &body).await;
        assert_eq!(reply.status, 400, "{id}: {}", reply.text());
        assert!(reply.error_message().contains("not a profile id"), "{id}");
        let current = Profile::read(&daemon.state.join("current.toml")).unwrap();
        assert_eq!(current.id, ids[1], "after {id}");
    }
    assert_eq!(get(&api, "/status").await.status, 200);
    assert!(outside.join("evil.toml").exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refusals_are_clear_and_name_what_was_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start_daemon(
        dir.path(),
        &format!("{FAST}max_body_bytes = 1024\nmax_event_streams = 1\n"),
    );
    let api = daemon.endpoint();
    let reply = get(&api, "/no/such/thing").await;
    assert_eq!(reply.status, 404);
    assert!(
        reply
            .error_message()
            .contains("no such endpoint: GET /no/such/thing")
    );
    // The 404 lists the endpoints, as the README says, and each one it lists is there
    // (a POST with a body that does not read is refused by the endpoint, not as
    // unknown; the event stream is left out: it would not end).
    let listed = reply.error_message();
    for endpoint in chromacal::daemon::api::DEVICE_ENDPOINTS
        .iter()
        .chain(&chromacal::daemon::api::DAEMON_ENDPOINTS)
    {
        assert!(
            listed.contains(endpoint),
            "the 404 leaves out {endpoint}: {listed}"
        );
        let (method, path) = endpoint.split_once(' ').unwrap();
        if path == "/events" || path == "/reload" {
            continue;
        }
        let reply = match method {
            "GET" => get(&api, path).await,
            _ => post(&api, path, "{").await,
        };
        assert!(
            !reply.error_message().contains("no such endpoint"),
            "{endpoint} is listed but not there: {}",
            reply.error_message()
        );
    }
    let reply = request_raw(&api, "DELETE", "/status").await;
    assert_eq!(reply.status, 405);
    assert!(
        reply
            .error_message()
            .contains("DELETE is not allowed on /status")
    );
    let reply = post(
        &api,
        "/jobs",
        &format!("{{\"kind\": \"{}\"}}", "x".repeat(4000)),
    )
    .await;
    assert_eq!(reply.status, 413);
    assert!(
        reply.error_message().contains("limit is 1024"),
        "{}",
        reply.text()
    );
    let reply = post(&api, "/jobs", r#"{"kind": "dance"}"#).await;
    assert_eq!(reply.status, 400);
    assert!(reply.error_message().contains("unknown job 'dance'"));
    let reply = post(&api, "/jobs", "not json").await;
    assert_eq!(reply.status, 400);
    assert_eq!(post(&api, "/jobs/cancel", "").await.status, 404);
    let reply = get(&api, "/profile?format=xml").await;
    assert_eq!(reply.status, 404, "no profile yet comes first");
    // A query string that does not parse is refused in JSON too.
    let reply = get(&api, "/profile?colour=red").await;
    assert_eq!(reply.status, 400);
    let error = reply
        .json()
        .ok()
        .and_then(|v| v["error"].as_str().map(String::from));
    assert!(
        error.is_some_and(|e| e.contains("query string")),
        "{}",
        reply.text()
    );

    // One event stream at most, as configured; the second is refused, not queued.
    let _first = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(200)).await;
    let second = chromacal::daemon::client::follow_events(&api, |_, _| true)
        .await
        .unwrap()
        .expect("a refusal");
    assert_eq!(second.status, 503);
    assert!(second.error_message().contains("event streams"));

    // The socket is the owner's only: mode 0600, and a peer that gets through anyway
    // (here: the mode opened up) is refused by its uid.
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(&daemon.socket)
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o600);
    let as_nobody = |path: &std::path::Path| {
        use std::os::unix::process::CommandExt;
        std::process::Command::new("curl")
            .args(["-s", "-o", "-", "-w", "\n%{http_code}", "--unix-socket"])
            .arg(path)
            .arg("http://chromacal/status")
            .uid(65534)
            .gid(65534)
            .output()
            .unwrap()
    };
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let out = as_nobody(&daemon.socket);
    assert_eq!(out.status.code(), Some(7), "connect must fail: {out:?}");
    std::fs::set_permissions(&daemon.socket, std::fs::Permissions::from_mode(0o666)).unwrap();
    let out = as_nobody(&daemon.socket);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.ends_with("403"), "{text}");
    assert!(text.contains("uid 65534 may not use this daemon"), "{text}");
}

async fn request_raw(
    api: &chromacal::daemon::client::Endpoint,
    method: &str,
    path: &str,
) -> chromacal::daemon::client::Reply {
    chromacal::daemon::client::request(api, method, path, None)
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_needs_the_token_and_requests_past_the_rate_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let daemon = start_daemon(
        dir.path(),
        &format!("{FAST}tcp = \"127.0.0.1:{port}\"\nrequests_per_s = 2.0\nburst = 5\n"),
    );
    let token_path = daemon.state.join("api.token");
    let token = std::fs::read_to_string(&token_path)
        .unwrap()
        .trim()
        .to_string();
    use std::os::unix::fs::PermissionsExt;
    assert_eq!(
        std::fs::metadata(&token_path).unwrap().permissions().mode() & 0o777,
        0o600
    );
    let address = format!("127.0.0.1:{port}");
    let wrong = chromacal::daemon::client::Endpoint::Tcp {
        address: address.clone(),
        token: "not-the-token".into(),
    };
    let reply = get(&wrong, "/status").await;
    assert_eq!(reply.status, 401);
    assert!(reply.error_message().contains("Bearer"));
    // A flood of scrapes without a token uses up its own bucket, not the token
    // holders' (58 of 60 token requests were refused when they shared one).
    let nobody = chromacal::daemon::client::Endpoint::Tcp {
        address: address.clone(),
        token: String::new(),
    };
    let mut scrapes = Vec::new();
    for _ in 0..20 {
        scrapes.push(get(&nobody, "/metrics").await.status);
    }
    assert_eq!(scrapes[0], 200);
    assert!(scrapes.contains(&429), "{scrapes:?}");
    let right = chromacal::daemon::client::Endpoint::Tcp { address, token };
    let mut statuses = Vec::new();
    for _ in 0..10 {
        statuses.push(get(&right, "/status").await.status);
    }
    assert_eq!(&statuses[..5], &[200; 5], "{statuses:?}");
    assert!(statuses.contains(&429), "{statuses:?}");
    // A token holder who used up the TCP bucket does not starve the owner's socket,
    // which has no bucket at all: forty requests at once, past the burst of 5.
    for _ in 0..40 {
        assert_eq!(
            get(&daemon.endpoint(), "/status").await.status,
            200,
            "the owner's socket is not rate-limited"
        );
    }
    tokio::time::sleep(Duration::from_millis(1200)).await;
    assert_eq!(
        get(&right, "/status").await.status,
        200,
        "the bucket refills"
    );
    // The scheme's name is case-insensitive: `bearer` as well as `Bearer`.
    tokio::time::sleep(Duration::from_millis(600)).await;
    let chromacal::daemon::client::Endpoint::Tcp { address, token } = &right else {
        unreachable!()
    };
    for scheme in ["bearer", "BEARER"] {
        use tokio::io::{AsyncReadExt, AsyncWriteExt};
        let mut stream = tokio::net::TcpStream::connect(address).await.unwrap();
        stream
            .write_all(
                format!(
                    "GET /status HTTP/1.1\r\nHost: {address}\r\nAuthorization: {scheme} {token}\r\nConnection: close\r\n\r\n"
                )
                .as_bytes(),
            )
            .await
            .unwrap();
        let mut reply = String::new();
        stream.read_to_string(&mut reply).await.unwrap();
        assert!(reply.starts_with("HTTP/1.1 200"), "{scheme}: {reply}");
    }

    // An address other machines can reach is refused unless allowed.
    let other = tempfile::tempdir().unwrap();
    std::fs::write(
        other.path().join("c.toml"),
        "[daemon]\ntcp = \"0.0.0.0:0\"\n",
    )
    .unwrap();
    let out = common::chromacal()
        .args(["daemon", "--config"])
        .arg(other.path().join("c.toml"))
        .arg("--state-dir")
        .arg(other.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("allow_remote"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_finishes_the_reading_exits_zero_and_the_run_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let config = "[daemon]\nsimulated_time_scale = 0.004\n";
    let mut daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    start_job(&api, "calibrate").await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let (ok, took) = daemon.terminate();
    assert!(ok, "{}", daemon.log_text());
    assert!(took < Duration::from_secs(5), "{took:?}");
    assert!(
        daemon
            .log_text()
            .contains("resumes when the daemon starts again")
    );
    let runs = common::daemon_runs(&daemon.state);
    let daemon_state = daemon.state.clone();
    assert_eq!(runs.len(), 1);
    let (_, before, recovery) = chromacal::journal::Journal::read(&runs[0]).unwrap();
    assert!(
        recovery.dropped_tail.is_none(),
        "SIGTERM leaves no torn line"
    );
    assert!(!before.is_empty() && before.len() < 96, "{}", before.len());
    drop(daemon);
    // `chromacal runs` says the daemon resumes it, not `calibrate --resume`.
    let listed = common::chromacal()
        .arg("runs")
        .arg("--state-dir")
        .arg(&daemon_state)
        .output()
        .unwrap();
    let listed = String::from_utf8_lossy(&listed.stdout);
    assert!(
        listed.contains("a daemon's: `chromacal daemon`"),
        "{listed}"
    );
    assert!(!listed.contains("calibrate --resume"), "{listed}");

    let daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    tokio::time::sleep(Duration::from_millis(100)).await;
    wait_idle(&api, Duration::from_secs(30)).await;
    let status = get(&api, "/status").await.json().unwrap();
    assert_eq!(status["last_job"]["job"]["origin"], "resume", "{status}");
    assert_eq!(status["last_job"]["outcome"]["result"], "ok", "{status}");
    let (header, after, _) = chromacal::journal::Journal::read(&runs[0]).unwrap();
    assert_eq!(&after[..before.len()], &before[..]);
    common::assert_each_planned_patch_once(&header, &after);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn systemd_hears_ready_watchdog_and_stopping() {
    let dir = tempfile::tempdir().unwrap();
    let notify_path = dir.path().join("notify.sock");
    let listener = std::os::unix::net::UnixDatagram::bind(&notify_path).unwrap();
    listener
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut daemon = start_daemon_with(
        dir.path(),
        FAST,
        &[
            ("NOTIFY_SOCKET", notify_path.to_str().unwrap()),
            ("WATCHDOG_USEC", "200000"),
        ],
    );
    let mut heard = Vec::new();
    let mut buf = [0u8; 512];
    while heard
        .iter()
        .filter(|m: &&String| m.contains("WATCHDOG=1"))
        .count()
        < 3
    {
        let n = listener.recv(&mut buf).unwrap();
        heard.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    assert!(heard.iter().any(|m| m.contains("READY=1")), "{heard:?}");
    let (ok, _) = daemon.terminate();
    assert!(ok);
    loop {
        let n = listener.recv(&mut buf).unwrap();
        if String::from_utf8_lossy(&buf[..n]).contains("STOPPING=1") {
            break;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_on_a_serial_rig_leaves_the_screen_black_and_the_instrument_free() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = emulate(&["--instrument", "pr670", "--time-scale", "0.002"]);
    let config = format!(
        "{CRT_PRIMARIES}[instrument]\ndriver = \"pr670\"\nport = \"{}\"\n[instrument.options]\ntiming_scale = 0.002\n[display]\nscreen = \"{}\"\n",
        emulator.device, emulator.screen
    );
    let mut daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = start_job(&api, "calibrate").await;
    // Stop in the middle of the run, on a bright patch or a dark one.
    events_until(
        &mut events,
        Duration::from_secs(60),
        |e| matches!(e, Event::Progress { job } if job.id == id && job.done >= 20),
    )
    .await;
    let (ok, took) = daemon.terminate();
    assert!(ok, "{}", daemon.log_text());
    assert!(took < Duration::from_secs(5), "{took:?}");

    // The instrument was let go: another program can open it and read the screen,
    // which the daemon left black.
    let out = common::chromacal()
        .args([
            "measure",
            "--instrument",
            &format!("pr670:{}", emulator.device),
            "--timing-scale",
            "0.002",
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
    let y = readings[0]["xyz"][1]
        .as_f64()
        .unwrap_or_else(|| panic!("{readings}"));
    assert!(y < 0.5, "the screen shows {y} cd/m², not black");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_api_serves_every_export_format_of_the_current_profile() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start_daemon(dir.path(), FAST);
    let api = daemon.endpoint();
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = start_job(&api, "calibrate").await;
    let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(60)).await;
    assert!(outcome.published, "{outcome:?}");
    let current = daemon.state.join("current.toml");

    // The API's ICC is the file `chromacal export` writes, byte for byte.
    for format in ["icc4", "icc2", "psychopy"] {
        let reply = get(&api, &format!("/profile?format={format}")).await;
        assert_eq!(reply.status, 200, "{format}: {}", reply.text());
        let file = dir.path().join(format!("export.{format}"));
        let out = common::chromacal()
            .arg("export")
            .arg(&current)
            .args(["--format", format, "-o"])
            .arg(&file)
            .output()
            .unwrap();
        assert!(out.status.success());
        assert_eq!(
            reply.body.as_ref(),
            std::fs::read(&file).unwrap().as_slice(),
            "{format}"
        );
    }
    let icc = get(&api, "/profile?format=icc4").await;
    assert_eq!(&icc.body[36..40], b"acsp");
    // The run's measurements, as ArgyllCMS reads them.
    let ti3 = get(&api, "/profile?format=ti3").await;
    assert!(ti3.text().starts_with("CTI3"), "{}", ti3.text());
    // Calibration curves need a target, and say so.
    let reply = get(&api, "/profile?format=cal").await;
    assert_eq!(reply.status, 422);
    assert!(reply.error_message().contains("target"), "{}", reply.text());
    let reply = get(&api, "/profile?format=cal&white=D65&tone=srgb&luminance=80").await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert!(reply.text().starts_with("CAL"));
    let reply = get(&api, "/profile?format=cal&white=purple").await;
    assert_eq!(reply.status, 400);
    assert!(reply.error_message().contains("purple"), "{}", reply.text());
    let reply = get(&api, "/profile?format=gif").await;
    assert_eq!(reply.status, 400);
    assert!(reply.error_message().contains("icc4"), "{}", reply.text());

    // The client command writes what the API serves.
    let file = dir.path().join("client.icc");
    let out = common::chromacal()
        .args(["profile", "current", "--format", "icc2", "--socket"])
        .arg(&daemon.socket)
        .arg("-o")
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(&std::fs::read(&file).unwrap()[8..10], &[2, 0x40]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_daemon_calibration_with_a_target_publishes_curves_measured_into_place() {
    let dir = tempfile::tempdir().unwrap();
    // A 10-bit path to the panel: at 8 bits one code step at the darkest level
    // measured is several percent of its luminance on this CRT.
    let config = format!(
        "{FAST}[monitor]\npreset = \"crt\"\nbit_depth = 10\n[target]\nwhite = \"D65\"\ntone = \"srgb\"\nluminance = 80.0\nbit_depth = 10\n"
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = start_job(&api, "calibrate").await;
    let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(60)).await;
    assert!(outcome.published, "{outcome:?}");
    let profile = Profile::read(&daemon.state.join("current.toml")).unwrap();
    let stored = profile.calibration.expect("curves in the profile");
    assert!(
        stored.measured_white_de00 < 1.0 && stored.measured_tone_error < 0.02,
        "{stored:?}"
    );
    // With curves in the profile, the .cal needs no target.
    let reply = get(&api, "/profile?format=cal").await;
    assert_eq!(reply.status, 200, "{}", reply.text());
    assert!(
        reply
            .text()
            .contains("TARGET_DESCRIPTION \"white x 0.3127 y 0.3290, sRGB tone")
    );
}

/// Issue 28, item 7: `runs/` is pruned. With `keep_profiles = 2`, after five
/// calibrations the store holds the two profiles and their runs, the newest two runs
/// whose profiles it let go, and nothing older.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn spent_calibration_runs_past_the_newest_few_are_removed() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start_daemon(
        dir.path(),
        "[daemon]\nsimulated_time_scale = 0.002\nsimulated_idle_ages = false\nkeep_profiles = 2\n",
    );
    let api = daemon.endpoint();
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let mut runs = Vec::new();
    for _ in 0..5 {
        let id = start_job(&api, "calibrate").await;
        let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(60)).await;
        assert!(outcome.published, "{outcome:?}");
        runs.push(outcome.profile_id.unwrap());
    }
    let left: Vec<String> = common::daemon_runs(&daemon.state)
        .iter()
        .map(|p| {
            p.parent()
                .unwrap()
                .file_name()
                .unwrap()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let mut expected = runs[1..].to_vec();
    expected.sort();
    let mut left_sorted = left.clone();
    left_sorted.sort();
    assert_eq!(left_sorted, expected, "runs left: {left:?}, made: {runs:?}");
    assert!(daemon.log_text().contains("removed old job folders"));
}
