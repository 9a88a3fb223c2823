//! A `chromacal daemon` process for the tests, and a few calls to its API.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use chromacal::daemon::client::{Endpoint, Reply, follow_events, request};
use chromacal::daemon::events::{Event, JobOutcome};

/// A running daemon, killed when dropped.
pub struct TestDaemon {
    pub child: Child,
    pub dir: PathBuf,
    pub state: PathBuf,
    pub socket: PathBuf,
    pub log: PathBuf,
}

impl Drop for TestDaemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Write `config` into `dir` and start a daemon on it (state in `dir/state`, socket
/// `dir/api.sock`); returns once it answers.
pub fn start_daemon(dir: &Path, config: &str) -> TestDaemon {
    start_daemon_with(dir, config, &[])
}

/// The same, with environment variables for the daemon.
pub fn start_daemon_with(dir: &Path, config: &str, env: &[(&str, &str)]) -> TestDaemon {
    let config_path = dir.join("config.toml");
    std::fs::write(&config_path, config).unwrap();
    let log = dir.join("daemon.log");
    let log_file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log)
        .unwrap();
    let state = dir.join("state");
    let socket = dir.join("api.sock");
    let mut command = crate::common::chromacal();
    command
        .arg("daemon")
        .arg("--config")
        .arg(&config_path)
        .arg("--state-dir")
        .arg(&state)
        .arg("--socket")
        .arg(&socket)
        .stdout(Stdio::null())
        .stderr(log_file);
    for (k, v) in env {
        command.env(k, v);
    }
    let child = command.spawn().unwrap();
    let mut daemon = TestDaemon {
        child,
        dir: dir.to_path_buf(),
        state,
        socket,
        log,
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        if let Ok(Some(status)) = daemon.child.try_wait() {
            panic!(
                "the daemon exited ({status}): {}",
                std::fs::read_to_string(&daemon.log).unwrap_or_default()
            );
        }
        if std::os::unix::net::UnixStream::connect(&daemon.socket).is_ok() {
            return daemon;
        }
        assert!(Instant::now() < deadline, "the daemon did not come up");
        std::thread::sleep(Duration::from_millis(10));
    }
}

impl TestDaemon {
    pub fn endpoint(&self) -> Endpoint {
        Endpoint::Unix(self.socket.clone())
    }

    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Send SIGTERM and wait for the exit: (success, how long it took).
    pub fn terminate(&mut self) -> (bool, Duration) {
        let started = Instant::now();
        let status = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let exit = self.child.wait().unwrap();
        (exit.success(), started.elapsed())
    }

    /// SIGKILL, as a crash or a power cut would stop it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

pub async fn get(endpoint: &Endpoint, path: &str) -> Reply {
    request(endpoint, "GET", path, None).await.unwrap()
}

pub async fn post(endpoint: &Endpoint, path: &str, body: &str) -> Reply {
    request(
        endpoint,
        "POST",
        path,
        Some(bytes::Bytes::from(body.to_string())),
    )
    .await
    .unwrap()
}

/// Start a job; panics unless the daemon accepts it. Returns its id.
pub async fn start_job(endpoint: &Endpoint, kind: &str) -> String {
    let reply = post(endpoint, "/jobs", &format!("{{\"kind\": \"{kind}\"}}")).await;
    assert_eq!(reply.status, 202, "{}", reply.text());
    reply.json().unwrap()["id"].as_str().unwrap().to_string()
}

/// Subscribe to the events; they arrive on the returned channel.
pub fn subscribe(endpoint: &Endpoint) -> tokio::sync::mpsc::UnboundedReceiver<Event> {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let endpoint = endpoint.clone();
    tokio::spawn(async move {
        let _ = follow_events(&endpoint, |_, data| {
            let event: Event = serde_json::from_str(data).unwrap();
            tx.send(event).is_ok()
        })
        .await;
    });
    rx
}

/// Events until `stop` says so (the last one included), within `timeout`.
pub async fn events_until(
    events: &mut tokio::sync::mpsc::UnboundedReceiver<Event>,
    timeout: Duration,
    mut stop: impl FnMut(&Event) -> bool,
) -> Vec<Event> {
    let mut seen = Vec::new();
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let event = tokio::time::timeout_at(deadline, events.recv())
            .await
            .unwrap_or_else(|_| panic!("timed out; events so far: {seen:#?}"))
            .expect("the event stream ended");
        let done = stop(&event);
        seen.push(event);
        if done {
            return seen;
        }
    }
}

/// The events up to the end of job `id` (included), and how it ended.
pub async fn events_of_job(
    events: &mut tokio::sync::mpsc::UnboundedReceiver<Event>,
    id: &str,
    timeout: Duration,
) -> (Vec<Event>, JobOutcome) {
    let seen = events_until(
        events,
        timeout,
        |e| matches!(e, Event::JobFinished { job, .. } if job.id == id),
    )
    .await;
    let Some(Event::JobFinished { outcome, .. }) = seen.last() else {
        unreachable!("events_until stops at the job's end")
    };
    let outcome = outcome.clone();
    (seen, outcome)
}

/// Wait until no job runs.
pub async fn wait_idle(endpoint: &Endpoint, timeout: Duration) {
    let deadline = Instant::now() + timeout;
    loop {
        let status = get(endpoint, "/status").await.json().unwrap();
        if status["job"].is_null() {
            return;
        }
        assert!(Instant::now() < deadline, "still busy: {status}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Subscribe to the events at `path` (`/events`: every device's) as JSON, each with
/// its `device`.
pub fn subscribe_json(
    endpoint: &Endpoint,
    path: &str,
) -> tokio::sync::mpsc::UnboundedReceiver<serde_json::Value> {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let endpoint = endpoint.clone();
    let path = path.to_string();
    tokio::spawn(async move {
        let _ = chromacal::daemon::client::follow_events_at(&endpoint, &path, |_, data| {
            let event: serde_json::Value = serde_json::from_str(data).unwrap();
            tx.send(event).is_ok()
        })
        .await;
    });
    rx
}

/// JSON events until `stop` says so (the last one included), within `timeout`.
pub async fn json_events_until(
    events: &mut tokio::sync::mpsc::UnboundedReceiver<serde_json::Value>,
    timeout: Duration,
    mut stop: impl FnMut(&[serde_json::Value]) -> bool,
) -> Vec<serde_json::Value> {
    let mut seen = Vec::new();
    let deadline = tokio::time::Instant::now() + timeout;
    loop {
        let event = tokio::time::timeout_at(deadline, events.recv())
            .await
            .unwrap_or_else(|_| panic!("timed out; events so far: {seen:#?}"))
            .expect("the event stream ended");
        seen.push(event);
        if stop(&seen) {
            return seen;
        }
    }
}

/// The number of `job_finished` events in `seen` per device named.
pub fn finished_on(seen: &[serde_json::Value], device: &str) -> usize {
    seen.iter()
        .filter(|e| e["event"] == "job_finished" && e["device"] == device)
        .count()
}

/// A loopback port nothing listens on now.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A program the test script installs (`scripts/test.sh`), by name on the PATH or in
/// /usr/sbin (where Debian puts mosquitto).
pub fn installed(program: &str) -> PathBuf {
    let found = std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/usr/bin")])
        .map(|dir| dir.join(program))
        .find(|p| p.is_file());
    found.unwrap_or_else(|| {
        panic!("{program} is not installed: scripts/test.sh installs it (Debian's package)")
    })
}

/// A child process killed when dropped.
pub struct Server(pub Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Wait until something accepts connections on `port`.
pub fn wait_for_port(port: u16, what: &str) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "{what} did not listen on {port}");
        std::thread::sleep(Duration::from_millis(20));
    }
}
