//! Issue 12, item 3: no client can wedge the daemon. A thousand idle and trickling
//! TCP connections without a token must not keep the owner's unix-socket requests
//! waiting, nor make a running calibration fail, nor hold the daemon's descriptors.

mod common;

use std::time::{Duration, Instant};

use common::daemon::{events_of_job, get, start_daemon, start_job, subscribe};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Open descriptors of a process.
fn open_descriptors(pid: u32) -> usize {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| d.count())
        .unwrap_or(0)
}

/// Wait until the daemon closes `stream` (EOF or reset), up to `within`; how long it
/// took, or `None` if it stayed open.
async fn closed_within(stream: &mut tokio::net::TcpStream, within: Duration) -> Option<Duration> {
    let started = Instant::now();
    let mut buffer = [0u8; 512];
    loop {
        match tokio::time::timeout_at(
            tokio::time::Instant::from_std(started + within),
            stream.read(&mut buffer),
        )
        .await
        {
            Err(_) => return None,
            Ok(Ok(0)) | Ok(Err(_)) => return Some(started.elapsed()),
            // A reply (e.g. 408) before the close: keep reading to the end.
            Ok(Ok(_)) => continue,
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_thousand_idle_connections_neither_starve_the_owner_nor_fail_a_job() {
    let dir = tempfile::tempdir().unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let daemon = start_daemon(
        dir.path(),
        &format!(
            "[daemon]\nsimulated_time_scale = 0.001\ntcp = \"127.0.0.1:{port}\"\nheader_timeout_s = 2.0\nidle_timeout_s = 3.0\n"
        ),
    );
    let pid = daemon.child.id();
    let before = open_descriptors(pid);
    let address = format!("127.0.0.1:{port}");

    // 1,000 connections that never send a byte, and 20 that trickle a header one
    // byte at a time.
    let mut idle = Vec::new();
    for _ in 0..1000 {
        idle.push(tokio::net::TcpStream::connect(&address).await.unwrap());
    }
    let trickle_started = Instant::now();
    let mut tricklers = Vec::new();
    for _ in 0..20 {
        let address = address.clone();
        tricklers.push(tokio::spawn(async move {
            let mut stream = tokio::net::TcpStream::connect(&address).await.unwrap();
            let header = b"GET /status HTTP/1.1\r\nHost: x\r\nX-Slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\r\n";
            for byte in header {
                if stream.write_all(&[*byte]).await.is_err() {
                    return Some(trickle_started.elapsed());
                }
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            None
        }));
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let during = open_descriptors(pid);
    assert!(
        during < before + 64 + 16,
        "the daemon holds {during} descriptors with 1,020 clients connected (it had {before}): the TCP cap is 64"
    );

    // The owner starts a calibration over the unix socket and polls its status while
    // the flood is connected.
    let api = daemon.endpoint();
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let id = start_job(&api, "calibrate").await;
    let mut latencies = Vec::new();
    let polling = Instant::now();
    while polling.elapsed() < Duration::from_secs(3) {
        let asked = Instant::now();
        let reply = get(&api, "/status").await;
        latencies.push(asked.elapsed());
        assert_eq!(reply.status, 200, "{}", reply.text());
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    latencies.sort();
    let slowest = *latencies.last().unwrap();
    eprintln!(
        "/status over the socket with 1,020 TCP clients connected and a calibration running: {} requests, p95 {:?}, max {slowest:?}",
        latencies.len(),
        latencies[latencies.len() * 95 / 100]
    );
    assert!(
        slowest < Duration::from_secs(1),
        "the owner's /status took {slowest:?} under the flood"
    );
    let (_, outcome) = events_of_job(&mut events, &id, Duration::from_secs(120)).await;
    assert_eq!(outcome.result, "ok", "{outcome:?}");
    assert!(outcome.published, "{outcome:?}");

    // Every flood connection has been closed by the daemon: those over the cap at
    // once, the rest within the header timeout.
    for (i, stream) in idle.iter_mut().enumerate() {
        assert!(
            closed_within(stream, Duration::from_secs(5))
                .await
                .is_some(),
            "idle connection {i} is still open"
        );
    }
    for trickler in tricklers {
        let closed_after = trickler.await.unwrap();
        let closed_after = closed_after.expect("a trickled header was read to its end");
        assert!(
            closed_after < Duration::from_secs(6),
            "a trickling client was closed only after {closed_after:?}"
        );
    }
    // Its slots are free again: a token holder is answered.
    let token = std::fs::read_to_string(daemon.state.join("api.token")).unwrap();
    let tcp = chromacal::daemon::client::Endpoint::Tcp {
        address: address.clone(),
        token: token.trim().to_string(),
    };
    assert_eq!(get(&tcp, "/status").await.status, 200);
    let after = open_descriptors(pid);
    assert!(
        after <= before + 4,
        "descriptors: {before} before the flood, {after} after it"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idle_keep_alive_connection_is_closed_and_a_live_one_is_not() {
    let dir = tempfile::tempdir().unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let daemon = start_daemon(
        dir.path(),
        &format!(
            "[daemon]\nsimulated_time_scale = 0.001\ntcp = \"127.0.0.1:{port}\"\nheader_timeout_s = 1.0\nidle_timeout_s = 1.5\nrequest_timeout_s = 1.0\n"
        ),
    );
    let token = std::fs::read_to_string(daemon.state.join("api.token")).unwrap();
    let address = format!("127.0.0.1:{port}");
    let request = format!(
        "GET /status HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {}\r\n\r\n",
        token.trim()
    );
    // A keep-alive client that asks once and then goes quiet is closed.
    let mut quiet = tokio::net::TcpStream::connect(&address).await.unwrap();
    quiet.write_all(request.as_bytes()).await.unwrap();
    let mut first = [0u8; 64];
    let n = quiet.read(&mut first).await.unwrap();
    assert!(first[..n].starts_with(b"HTTP/1.1 200"));
    let closed = closed_within(&mut quiet, Duration::from_secs(5)).await;
    assert!(
        closed.is_some(),
        "an idle keep-alive connection stayed open"
    );

    // A client without the token is answered 401 and its connection closed: it holds
    // no slot of the listener by asking again and again.
    let mut stranger = tokio::net::TcpStream::connect(&address).await.unwrap();
    stranger
        .write_all(b"GET /status HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .unwrap();
    let mut head = [0u8; 12];
    stranger.read_exact(&mut head).await.unwrap();
    assert_eq!(&head, b"HTTP/1.1 401");
    assert!(
        closed_within(&mut stranger, Duration::from_millis(500))
            .await
            .is_some(),
        "a refused client's connection stayed open"
    );

    // A body trickled in one byte at a time is cut off at the request timeout, in JSON.
    let mut slow = tokio::net::TcpStream::connect(&address).await.unwrap();
    slow.write_all(
        format!(
            "POST /jobs HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {}\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n",
            token.trim()
        )
        .as_bytes(),
    )
    .await
    .unwrap();
    let started = Instant::now();
    let mut reply = Vec::new();
    for _ in 0..40 {
        if slow.write_all(b" ").await.is_err() {
            break;
        }
        let mut buffer = [0u8; 512];
        if let Ok(Ok(n)) =
            tokio::time::timeout(Duration::from_millis(200), slow.read(&mut buffer)).await
        {
            reply.extend_from_slice(&buffer[..n]);
            if n == 0 || reply.ends_with(b"}") {
                break;
            }
        }
    }
    let reply = String::from_utf8_lossy(&reply);
    assert!(reply.starts_with("HTTP/1.1 408"), "{reply}");
    assert!(reply.contains("request_timeout_s"), "{reply}");
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );

    // Requests hyper itself refuses, before any handler, are answered in JSON too.
    for (bytes, status) in [
        (b"NOT HTTP AT ALL\r\n\r\n".to_vec(), "400"),
        (
            // More header fields than the parser takes (its limit is 100).
            format!(
                "GET /status HTTP/1.1\r\nHost: x\r\n{}\r\n",
                (0..200)
                    .map(|k| format!("X-{k}: a\r\n"))
                    .collect::<String>()
            )
            .into_bytes(),
            "431",
        ),
    ] {
        let mut client = tokio::net::TcpStream::connect(&address).await.unwrap();
        // The daemon may answer and close before it has read the whole of a huge head.
        let _ = client.write_all(&bytes).await;
        let mut reply = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(3), client.read_to_end(&mut reply)).await;
        let reply = String::from_utf8_lossy(&reply);
        assert!(reply.starts_with(&format!("HTTP/1.1 {status}")), "{reply}");
        assert!(reply.contains("application/json"), "{reply}");
        let body = reply.split("\r\n\r\n").nth(1).unwrap_or_default();
        let json: serde_json::Value = serde_json::from_str(body).expect(&reply);
        assert!(
            json["error"].as_str().is_some_and(|e| !e.is_empty()),
            "{reply}"
        );
    }

    // An event stream stays open past the idle timeout: its keep-alives are traffic.
    let events = chromacal::daemon::client::Endpoint::Tcp {
        address: address.clone(),
        token: token.trim().to_string(),
    };
    let mut stream = tokio::net::TcpStream::connect(&address).await.unwrap();
    stream
        .write_all(
            format!(
                "GET /events HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {}\r\n\r\n",
                token.trim()
            )
            .as_bytes(),
        )
        .await
        .unwrap();
    assert!(
        closed_within(&mut stream, Duration::from_secs(4))
            .await
            .is_none(),
        "an event stream was closed as idle"
    );
    // And the daemon still answers the same client on a new connection.
    assert_eq!(get(&events, "/status").await.status, 200);
}

/// Issue 12, item 4: a fit of seconds (a 36-position uniformity grid) runs off the
/// async workers, so the API answers throughout it; SIGTERM stops it at once, and the
/// next start resumes the run (it only fits again).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_long_fit_neither_stalls_the_api_nor_outlives_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let config = "[plan]\nuniformity_grid = 36\n[daemon]\nsimulated_time_scale = 0.0001\nrequests_per_s = 1000.0\nburst = 1000\n";
    let mut daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    start_job(&api, "calibrate").await;
    // Wait for the last reading: the fit follows.
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let status = get(&api, "/status").await.json().unwrap();
        let job = &status["job"];
        if !job.is_null() && job["done"] == job["total"] && job["total"].as_u64() > Some(0) {
            break;
        }
        assert!(Instant::now() < deadline, "{status}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let fit_started = Instant::now();
    let mut latencies = Vec::new();
    while fit_started.elapsed() < Duration::from_millis(1500) {
        let asked = Instant::now();
        let status = get(&api, "/status").await.json().unwrap();
        latencies.push(asked.elapsed());
        assert!(
            !status["job"].is_null(),
            "the fit ended within 1.5 s: {status}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    latencies.sort();
    let slowest = *latencies.last().unwrap();
    eprintln!(
        "/status during a 36 × 36 uniformity fit: {} requests, p95 {:?}, max {slowest:?}",
        latencies.len(),
        latencies[latencies.len() * 95 / 100]
    );
    assert!(
        slowest < Duration::from_millis(500),
        "/status took up to {slowest:?} during the fit"
    );
    let (exited_cleanly, took) = daemon.terminate();
    assert!(exited_cleanly, "{}", daemon.log_text());
    assert!(
        took < Duration::from_secs(3),
        "SIGTERM during the fit took {took:?}"
    );
    let runs = common::daemon_runs(&daemon.state);
    assert_eq!(runs.len(), 1);
    let run = runs[0].parent().unwrap();
    assert!(run.exists());
    assert!(
        !run.join("profile").exists(),
        "the stopped run is still unfinished"
    );
    assert!(
        !run.join("fit_failures").exists(),
        "a stopped fit is not a failed one"
    );
    drop(daemon);
    // The next start resumes it: nothing left to measure, so it fits and publishes.
    let daemon = start_daemon(dir.path(), config);
    let api = daemon.endpoint();
    tokio::time::sleep(Duration::from_millis(300)).await;
    common::daemon::wait_idle(&api, Duration::from_secs(120)).await;
    let status = get(&api, "/status").await.json().unwrap();
    assert_eq!(status["last_job"]["outcome"]["result"], "ok", "{status}");
    assert!(
        status["last_job"]["outcome"]["published"]
            .as_bool()
            .unwrap(),
        "{status}"
    );
}

/// Send one keep-alive request on `stream` and read its answer's status (the body is
/// read to its `content-length`).
async fn ask(stream: &mut tokio::net::TcpStream, path: &str, token: Option<&str>) -> Option<u16> {
    let auth = token.map_or(String::new(), |t| format!("Authorization: Bearer {t}\r\n"));
    let request = format!("GET {path} HTTP/1.1\r\nHost: x\r\n{auth}\r\n");
    stream.write_all(request.as_bytes()).await.ok()?;
    let mut got = Vec::new();
    let mut buffer = [0u8; 8192];
    loop {
        let n = tokio::time::timeout(Duration::from_secs(5), stream.read(&mut buffer))
            .await
            .ok()?
            .ok()?;
        if n == 0 {
            return None;
        }
        got.extend_from_slice(&buffer[..n]);
        let text = String::from_utf8_lossy(&got).to_string();
        if let Some((head, body)) = text.split_once("\r\n\r\n") {
            let length: usize = head
                .lines()
                .find_map(|l| {
                    let (k, v) = l.split_once(':')?;
                    k.eq_ignore_ascii_case("content-length")
                        .then(|| v.trim().parse().ok())?
                })
                .unwrap_or(0);
            if body.len() >= length {
                return head.split(' ').nth(1)?.parse().ok();
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clients_without_the_token_holding_every_tcp_slot_do_not_keep_a_token_holder_out() {
    let dir = tempfile::tempdir().unwrap();
    let port = common::daemon::free_port();
    let daemon = start_daemon(
        dir.path(),
        &format!("[daemon]\ntcp = \"127.0.0.1:{port}\"\nidle_timeout_s = 60.0\n"),
    );
    let token = std::fs::read_to_string(daemon.state.join("api.token")).unwrap();
    let token = token.trim();
    let address = format!("127.0.0.1:{port}");

    // 64 clients hold every slot of the cap with keep-alive scrapes of the open
    // /metrics, and 64 more sit idle.
    let mut scrapers = Vec::new();
    for _ in 0..64 {
        let mut stream = tokio::net::TcpStream::connect(&address).await.unwrap();
        assert_eq!(ask(&mut stream, "/metrics", None).await, Some(200));
        scrapers.push(stream);
    }
    let mut idle = Vec::new();
    for _ in 0..64 {
        idle.push(tokio::net::TcpStream::connect(&address).await.unwrap());
    }
    tokio::time::sleep(Duration::from_millis(200)).await;

    // A token holder gets in, and keeps its connection while more clients without
    // the token arrive.
    let mut holder = tokio::net::TcpStream::connect(&address).await.unwrap();
    assert_eq!(ask(&mut holder, "/status", Some(token)).await, Some(200));
    for _ in 0..128 {
        idle.push(tokio::net::TcpStream::connect(&address).await.unwrap());
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(
        ask(&mut holder, "/status", Some(token)).await,
        Some(200),
        "the token holder's connection was closed for clients without the token"
    );
    // Each new token holder too, ten times over.
    for _ in 0..10 {
        let mut again = tokio::net::TcpStream::connect(&address).await.unwrap();
        assert_eq!(ask(&mut again, "/status", Some(token)).await, Some(200));
        idle.push(tokio::net::TcpStream::connect(&address).await.unwrap());
    }
    // The scrapers, the oldest without the token, were closed to make room.
    let mut closed = 0;
    for stream in &mut scrapers {
        if ask(stream, "/metrics", None).await.is_none() {
            closed += 1;
        }
    }
    assert_eq!(
        closed,
        64,
        "scrapers still served past the cap: {}",
        64 - closed
    );
}
