//! The commands that talk to a running daemon, as a user types them.

use std::process::Output;
use std::time::Duration;

mod common;
use common::chromacal;
use common::daemon::{start_daemon, wait_idle};

fn run(socket: &std::path::Path, args: &[&str]) -> Output {
    chromacal()
        .args(args)
        .arg("--socket")
        .arg(socket)
        .output()
        .unwrap()
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn start_watch_status_history_rollback_and_cancel_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    // Slow enough that a calibration (two minutes simulated) is still running when
    // it is cancelled 300 ms in.
    let daemon = start_daemon(dir.path(), "[daemon]\nsimulated_time_scale = 0.01\n");
    let socket = daemon.socket.clone();

    let out = run(&socket, &["status"]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("job: none running")
            && text(&out).contains("current profile: none yet")
    );

    for _ in 0..2 {
        let out = run(&socket, &["job", "start", "calibrate", "--watch"]);
        assert!(out.status.success(), "{}", text(&out));
        assert!(text(&out).contains("ok: published"), "{}", text(&out));
    }
    let out = run(&socket, &["status"]);
    assert!(text(&out).contains("held-out mean ΔE00"), "{}", text(&out));
    let out = run(&socket, &["profile", "current"]);
    assert!(out.status.success());
    let profile =
        chromacal::profile::Profile::from_toml(&String::from_utf8_lossy(&out.stdout), "stdout")
            .unwrap();
    let out = run(&socket, &["history"]);
    assert_eq!(
        text(&out).matches("calibration").count(),
        2,
        "{}",
        text(&out)
    );
    assert!(text(&out).contains(&format!("{}  held-out", profile.id)));
    let out = run(&socket, &["rollback"]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(!text(&out).contains(&profile.id));
    let out = run(&socket, &["rollback", "no-such-id"]);
    assert!(!out.status.success());
    assert!(
        text(&out).contains("409") && text(&out).contains("no-such-id"),
        "{}",
        text(&out)
    );

    // A cancelled calibration stops after its reading and is not resumed.
    let out = run(&socket, &["job", "start", "calibrate"]);
    assert!(text(&out).contains("started calibrate-"));
    tokio::time::sleep(Duration::from_millis(300)).await;
    let busy = run(&socket, &["job", "start", "verify"]);
    assert!(!busy.status.success());
    assert!(text(&busy).contains("409"), "{}", text(&busy));
    let out = run(&socket, &["job", "cancel"]);
    assert!(out.status.success(), "{}", text(&out));
    wait_idle(&daemon.endpoint(), Duration::from_secs(30)).await;
    let out = run(&socket, &["job", "watch"]);
    assert!(text(&out).contains("cancelled"), "{}", text(&out));
    let cancelled = common::newest_run(&daemon.state);
    assert_eq!(
        std::fs::read_to_string(cancelled.with_file_name("profile"))
            .unwrap()
            .trim(),
        "discarded"
    );
    drop(daemon);
    // Slow enough that a calibration (two minutes simulated) is still running when
    // it is cancelled 300 ms in.
    let daemon = start_daemon(dir.path(), "[daemon]\nsimulated_time_scale = 0.01\n");
    tokio::time::sleep(Duration::from_millis(200)).await;
    let status = run(&daemon.socket, &["status", "--json"]);
    let status: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    assert!(
        status["job"].is_null(),
        "a cancelled run must not resume: {status}"
    );

    // No daemon: a clear error, not a hang.
    drop(daemon);
    let out = run(&dir.path().join("nothing.sock"), &["status"]);
    assert!(!out.status.success());
    assert!(
        text(&out).contains("is `chromacal daemon` running?"),
        "{}",
        text(&out)
    );
}

/// Off a terminal (a pipe, a log), `job watch` writes a line a step as the job goes,
/// not only its outcome at the end: the first progress line is read while the job is
/// still running.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn job_watch_off_a_terminal_streams_a_line_a_step() {
    use std::io::BufRead as _;
    let dir = tempfile::tempdir().unwrap();
    // A calibration of about two simulated minutes takes some 2.4 s here.
    let daemon = start_daemon(dir.path(), "[daemon]\nsimulated_time_scale = 0.02\n");
    let mut watcher = chromacal()
        .args(["job", "start", "calibrate", "--watch", "--socket"])
        .arg(&daemon.socket)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(watcher.stdout.take().unwrap()).lines();
    let first_step = loop {
        let line = lines
            .next()
            .expect("job watch ended before any step")
            .unwrap();
        if line.starts_with("calibrate ") && line.contains('/') {
            break line;
        }
    };
    let status = run(&daemon.socket, &["status", "--json"]);
    let status: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    assert!(
        !status["job"].is_null(),
        "the first step ({first_step}) came only after the job ended: {status}"
    );
    let rest: Vec<String> = lines.map(|l| l.unwrap()).collect();
    let steps = rest.iter().filter(|l| l.starts_with("calibrate ")).count();
    assert!(steps >= 10, "{steps} step lines: {rest:?}");
    assert!(
        rest.last().is_some_and(|l| l.contains("ok: published")),
        "{rest:?}"
    );
    assert!(watcher.wait().unwrap().success());
    // The last job is an object that names its parts.
    let status = run(&daemon.socket, &["status", "--json"]);
    let status: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    assert_eq!(status["last_job"]["outcome"]["result"], "ok", "{status}");
    assert_eq!(status["last_job"]["job"]["kind"], "calibrate", "{status}");
}

/// `calibrate --display window --instrument …` then `daemon` with a config that says
/// neither: the daemon would verify the in-process simulation against the screen's
/// profile (and call it good). It refuses to start, naming both and the remedy.
#[test]
fn a_daemon_configured_for_the_simulation_refuses_a_store_measured_on_a_screen() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let config = dir.path().join("my.toml");
    std::fs::write(&config, "[plan]\nuniformity_grid = 0\n").unwrap();
    let out = chromacal()
        .args(["calibrate", "--config"])
        .arg(&config)
        .arg("--state-dir")
        .arg(&state)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let daemon = |socket: &str| {
        let mut child = chromacal()
            .args(["daemon", "--config"])
            .arg(&config)
            .arg("--state-dir")
            .arg(&state)
            .arg("--socket")
            .arg(dir.path().join(socket))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // A daemon that starts serves until stopped: give it two seconds.
        let deadline = std::time::Instant::now() + Duration::from_secs(2);
        while std::time::Instant::now() < deadline {
            if let Ok(Some(_)) = child.try_wait() {
                return Some(child.wait_with_output().unwrap());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        common::terminate(&mut child, Duration::from_secs(5));
        None
    };
    // A simulated profile: the simulated daemon starts.
    assert!(
        daemon("a.sock").is_none(),
        "the daemon stopped on its own store"
    );
    // The same profile as if measured on a window with a PR-670.
    let current = state.join("current.toml");
    let profile = std::fs::read_to_string(&current).unwrap();
    let measured = profile.replace(
        "display = \"virtual monitor 'crt'\"",
        "display = \"window on DUMMY0 of X display :0 (8 bits)\"",
    );
    assert_ne!(measured, profile, "{profile}");
    std::fs::write(&current, measured).unwrap();
    let out = daemon("b.sock").expect("the daemon started");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("was measured on window on DUMMY0")
            && stderr.contains("simulated monitor")
            && stderr.contains("[display] sink"),
        "{stderr}"
    );
}

/// Without a running daemon, `history` and `profile current` read the state
/// directory on disk (saying so), and name the export for binary formats.
#[test]
fn history_and_the_current_profile_read_the_store_when_no_daemon_runs() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    common::calibrate_default(&state);
    let current = chromacal::profile::Profile::read(&state.join("current.toml")).unwrap();
    let out = common::succeed(
        common::chromacal()
            .args(["history", "--json", "--state-dir"])
            .arg(&state),
    );
    let history: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(history["current"], current.id.as_str());
    assert_eq!(history["profiles"][0]["id"], current.id.as_str());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no daemon answers"));
    let out = common::succeed(
        common::chromacal()
            .args(["profile", "current", "--json", "--state-dir"])
            .arg(&state),
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["id"], current.id.as_str());
    let out = common::chromacal()
        .args(["profile", "current", "--format", "icc4", "-o"])
        .arg(dir.path().join("x.icc"))
        .arg("--state-dir")
        .arg(&state)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("chromacal export"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
