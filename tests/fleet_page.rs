//! The fleet page (`GET /`) in a real browser: headless Chromium over the daemon's TCP
//! listener is sent to the login, refused with a wrong token, shown every device with
//! its profile, verification, next verification and white sparkline once logged in,
//! and kept from acting through its session cookie (which no script can read).

#[path = "common/browser.rs"]
mod browser;
mod common;

use std::time::{Duration, Instant};

use browser::Browser;
use common::daemon::{get, post, start_daemon};
use serde_json::{Value, json};

/// Evaluate `expression` in the page, awaiting it if it is a promise.
fn eval(browser: &mut Browser, expression: &str) -> Value {
    let result = browser.call(
        "Runtime.evaluate",
        json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
    );
    assert!(
        result.get("exceptionDetails").is_none(),
        "{expression}: {result}"
    );
    result["result"]["value"].clone()
}

/// Wait until the page at `path` has loaded.
fn wait_for_page(browser: &mut Browser, path: &str) {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let here = eval(
            browser,
            "document.readyState === 'complete' ? location.pathname : ''",
        );
        if here == path {
            return;
        }
        assert!(Instant::now() < deadline, "never reached {path}: at {here}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_fleet_page_works_in_chromium_over_tcp_with_the_login_and_refuses_without_it() {
    let dir = tempfile::tempdir().unwrap();
    let port = common::daemon::free_port();
    let config = format!(
        r#"[daemon]
simulated_time_scale = 0.005
simulated_idle_ages = false
tcp = "127.0.0.1:{port}"
[schedule]
verify_every_s = 3600.0
[[device]]
name = "crt"
[[device]]
name = "lcd"
[device.monitor]
preset = "lcd"
"#
    );
    let daemon = start_daemon(dir.path(), &config);
    let api = daemon.endpoint();
    // crt calibrated and verified; lcd never measured.
    for kind in ["calibrate", "verify"] {
        let reply = post(
            &api,
            "/devices/crt/jobs",
            &format!("{{\"kind\": \"{kind}\"}}"),
        )
        .await;
        assert_eq!(reply.status, 202, "{}", reply.text());
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let status = get(&api, "/devices/crt/status").await.json().unwrap();
            if status["job"].is_null() {
                assert_eq!(status["last_job"]["outcome"]["result"], "ok", "{status}");
                break;
            }
            assert!(Instant::now() < deadline, "{kind} never ended");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
    let status = get(&api, "/devices/crt/status").await.json().unwrap();
    let profile_id = status["current_profile"]["id"]
        .as_str()
        .unwrap()
        .to_string();
    let next = status["next_verification"].as_str().unwrap().to_string();
    let history = get(&api, "/devices/crt/history").await.json().unwrap();
    let verification = history["verifications"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()
        .clone();
    let passed = verification["stats"]["mean"].as_f64().unwrap()
        <= verification["threshold"].as_f64().unwrap();

    // On the owner's unix socket the page needs no login, and has no logout.
    let local = get(&api, "/").await;
    assert_eq!(local.status, 200);
    let text = local.text();
    assert!(text.contains("data-device=\"crt\"") && text.contains("data-device=\"lcd\""));
    assert!(!text.contains("/logout"));

    let token = std::fs::read_to_string(daemon.state.join("api.token")).unwrap();
    let token = token.trim().to_string();
    let base = format!("http://127.0.0.1:{port}");
    let mut browser = tokio::task::spawn_blocking(|| Browser::open("about:blank", 1200, 700))
        .await
        .unwrap();

    // Without a login: sent to it; the API refuses.
    let errors = browser.navigate(&format!("{base}/"));
    assert!(errors.is_empty(), "{errors:?}");
    wait_for_page(&mut browser, "/login");
    assert_eq!(eval(&mut browser, "document.forms.length"), 1);
    assert_eq!(
        eval(&mut browser, "fetch('/status').then(r => r.status)"),
        401
    );
    assert_eq!(
        eval(&mut browser, "fetch('/devices').then(r => r.status)"),
        401
    );

    // A wrong token is refused, saying so.
    eval(
        &mut browser,
        "document.querySelector('input[name=token]').value = 'not-the-token'; \
         document.forms[0].submit(); true",
    );
    std::thread::sleep(Duration::from_millis(300));
    wait_for_page(&mut browser, "/login");
    let said = eval(
        &mut browser,
        "document.getElementById('error') ? document.getElementById('error').textContent : ''",
    );
    assert!(
        said.as_str()
            .unwrap()
            .contains("not the daemon's API token"),
        "{said}"
    );
    assert_eq!(
        eval(&mut browser, "fetch('/status').then(r => r.status)"),
        401
    );

    // The token logs in: the fleet page, every device on it.
    eval(
        &mut browser,
        &format!(
            "document.querySelector('input[name=token]').value = '{token}'; \
             document.forms[0].submit(); true"
        ),
    );
    wait_for_page(&mut browser, "/");
    let rows = eval(
        &mut browser,
        "[...document.querySelectorAll('tr[data-device]')].map(r => ({ \
           name: r.dataset.device, \
           state: r.querySelector('.state').textContent, \
           profile: r.querySelector('.profile').textContent, \
           verification: r.querySelector('.verification').textContent, \
           next: r.querySelector('.next').textContent, \
           white: r.querySelector('.white').textContent, \
           sparkline: r.querySelectorAll('.white polyline').length, \
           report: r.querySelector('a') ? r.querySelector('a').getAttribute('href') : null }))",
    );
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 2, "{rows:?}");
    let (crt_row, lcd_row) = (&rows[0], &rows[1]);
    assert_eq!(crt_row["name"], "crt");
    assert_eq!(crt_row["state"], "idle");
    assert!(
        crt_row["profile"]
            .as_str()
            .unwrap()
            .starts_with(&profile_id),
        "{crt_row}"
    );
    let word = if passed { "pass" } else { "fail" };
    assert!(
        crt_row["verification"].as_str().unwrap().starts_with(word),
        "{crt_row} vs {verification}"
    );
    assert_eq!(crt_row["next"], next.as_str());
    assert!(
        crt_row["white"].as_str().unwrap().contains("cd/m²"),
        "{crt_row}"
    );
    assert_eq!(crt_row["sparkline"], 1, "{crt_row}");
    assert_eq!(crt_row["report"], "/devices/crt/report");
    assert_eq!(lcd_row["name"], "lcd");
    assert!(lcd_row["profile"].as_str().unwrap().contains("none yet"));
    assert!(lcd_row["report"].is_null());
    let screenshot = browser.call("Page.captureScreenshot", json!({"format": "png"}));
    if let Some(data) = screenshot["data"].as_str() {
        use base64::Engine;
        let png = base64::engine::general_purpose::STANDARD
            .decode(data)
            .unwrap();
        let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("fleet_page.png");
        std::fs::write(out, png).unwrap();
    }

    // The cookie is out of any script's reach, and the session only looks: no job can
    // be started through it.
    assert_eq!(eval(&mut browser, "document.cookie"), "");
    assert_eq!(
        eval(&mut browser, "fetch('/devices').then(r => r.status)"),
        200
    );
    let forged = eval(
        &mut browser,
        "fetch('/devices/lcd/jobs', {method: 'POST', headers: {'content-type': 'application/json'}, \
         body: JSON.stringify({kind: 'calibrate'})}).then(r => r.status)",
    );
    assert_eq!(forged, 403);
    assert_eq!(
        eval(
            &mut browser,
            "fetch('/reload', {method: 'POST'}).then(r => r.status)"
        ),
        403
    );
    let lcd = get(&api, "/devices/lcd/status").await.json().unwrap();
    assert!(lcd["job"].is_null() && lcd["last_job"].is_null(), "{lcd}");

    // The report names its device and links back.
    let errors = browser.navigate(&format!("{base}/devices/crt/report"));
    assert!(errors.is_empty(), "{errors:?}");
    let h1 = eval(&mut browser, "document.querySelector('h1').textContent");
    assert!(h1.as_str().unwrap().contains("device crt"), "{h1}");
    assert_eq!(
        eval(
            &mut browser,
            "document.querySelector('a[href=\"/\"]') !== null"
        ),
        true
    );

    // Logging out ends the session.
    let errors = browser.navigate(&format!("{base}/"));
    assert!(errors.is_empty(), "{errors:?}");
    eval(
        &mut browser,
        "document.querySelector('form[action=\"/logout\"]').submit(); true",
    );
    std::thread::sleep(Duration::from_millis(300));
    wait_for_page(&mut browser, "/login");
    assert_eq!(
        eval(&mut browser, "fetch('/status').then(r => r.status)"),
        401
    );
}
