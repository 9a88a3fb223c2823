//! The daemon keeps a window device's curves in the video LUT of a real X server
//! (Xorg with the dummy driver): loaded after a calibration job and at start, read back
//! every second and put back when `xrandr --gamma` overwrites them, loaded again after
//! a mode change (RandR) and after logind says the machine resumed (a
//! `PrepareForSleep(false)` signal on a private system bus), with
//! `chromacal_lut_loaded` and the overwrite counter in `/metrics`.

use std::time::Duration;

use chromacal::daemon::events::Event;
use chromacal::profile::Profile;
use chromacal_display::x11::{GammaRamp, OutputSelector, XDisplay};

mod common;
use common::daemon::{TestDaemon, events_until, get, start_daemon_with, start_job, subscribe};
use common::emulate;
use common::xserver::XServer;

/// Whether the LUT of the X server's primary output holds `profile`'s curves.
fn holds_curves(x: &XServer, profile: &Profile) -> f64 {
    let xd = XDisplay::open(Some(&x.display)).unwrap();
    let output = xd.output(&OutputSelector::Primary).unwrap();
    let ramp = xd.gamma(&output).unwrap();
    let curves = &profile.calibration.as_ref().unwrap().curves;
    ramp.max_difference(&GammaRamp::from_curves(curves, ramp.len()))
}

/// Wait (20 s at most) until the LUT holds `profile`'s curves.
async fn until_curves_loaded(x: &XServer, profile: &Profile, daemon: &TestDaemon) {
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while holds_curves(x, profile) > 1.0 {
        assert!(
            std::time::Instant::now() < deadline,
            "{}",
            daemon.log_text()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

fn loaded_for(seen: &Event, why: &str) -> bool {
    matches!(seen, Event::LutLoaded { reason, .. } if reason.contains(why))
}

/// A metric's value for the default device, from `/metrics`' text.
fn metric(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find(|l| l.starts_with(&format!("{name}{{")))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_daemon_keeps_the_curves_in_the_video_lut() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let monitor = "[monitor]\npreset = \"crt\"\nbit_depth = 10\n";
    let emulator_config = dir.path().join("emulator.toml");
    std::fs::write(&emulator_config, monitor).unwrap();
    let emulator = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--x-display",
        &x.display,
        "--config",
        emulator_config.to_str().unwrap(),
    ]);
    let config = format!(
        r#"{monitor}[instrument]
driver = "pr670"
port = "{}"
[instrument.options]
timing_scale = 0.002
[display]
sink = "window"
x_display = "{}"
settle_s = 0.0
keep_lut = true
lut_check_s = 1.0
[plan]
uniformity_grid = 0
[target]
white = "D65"
tone = "gamma:2.2"
"#,
        emulator.device, x.display
    );
    let bus = common::bus::SystemBus::start(dir.path());
    let daemon = start_daemon_with(
        dir.path(),
        &config,
        &[("DBUS_SYSTEM_BUS_ADDRESS", bus.address.as_str())],
    );
    let api = daemon.endpoint();
    let mut events = subscribe(&api);
    tokio::time::sleep(Duration::from_millis(200)).await;

    // A calibration: the keeper loads its curves when the job ends.
    let id = start_job(&api, "calibrate").await;
    events_until(&mut events, Duration::from_secs(300), |e| {
        loaded_for(e, "a job ended")
    })
    .await;
    let profile = Profile::read(&daemon.state.join("current.toml")).unwrap();
    assert!(!id.is_empty());
    assert!(holds_curves(&x, &profile) <= 1.0);
    let metrics = get(&api, "/metrics").await.text();
    assert_eq!(
        metric(&metrics, "chromacal_lut_loaded"),
        Some(1.0),
        "{metrics}"
    );
    // `lut reset` from another state directory is refused while the daemon keeps
    // this output: it would put the curves back, and say them loaded meanwhile.
    let other = dir.path().join("other-state");
    let out = common::chromacal()
        .args(["lut", "reset", "--x-display", &x.display, "--state-dir"])
        .arg(&other)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("is kept by chromacal daemon on") && stderr.contains("stop it first"),
        "{stderr}"
    );
    assert!(holds_curves(&x, &profile) <= 1.0);

    // A night-light tool writes its own ramp: seen within a second or two, said, and
    // replaced (keep_lut).
    x.run("xrandr", &["--output", "DUMMY0", "--gamma", "1.0:0.7:0.4"]);
    let seen = events_until(&mut events, Duration::from_secs(20), |e| {
        loaded_for(e, "overwritten")
    })
    .await;
    assert!(
        seen.iter().any(
            |e| matches!(e, Event::LutOverwritten { steps, reloading: true, .. } if *steps > 1000.0)
        ),
        "{seen:#?}"
    );
    assert!(holds_curves(&x, &profile) <= 1.0);
    let metrics = get(&api, "/metrics").await.text();
    assert_eq!(
        metric(&metrics, "chromacal_lut_overwritten_total"),
        Some(1.0),
        "{metrics}"
    );
    assert_eq!(metric(&metrics, "chromacal_lut_loaded"), Some(1.0));

    // A mode change is a RandR event: the curves are loaded again, and the next job's
    // window covers the output at its new size (the instrument, aimed at the
    // centre, reads the patch there: the verification passes).
    x.run("xrandr", &["--output", "DUMMY0", "--mode", "800x600"]);
    events_until(&mut events, Duration::from_secs(20), |e| {
        loaded_for(e, "RandR")
    })
    .await;
    assert!(holds_curves(&x, &profile) <= 1.0);
    start_job(&api, "verify").await;
    let seen = events_until(&mut events, Duration::from_secs(120), |e| {
        matches!(e, Event::Verification { .. })
    })
    .await;
    let Some(Event::Verification { record }) = seen.last() else {
        unreachable!()
    };
    let stats = record.stats.unwrap();
    assert!(
        stats.mean < 0.5,
        "verification after the mode change: {stats:?}"
    );
    // The job measured through the straight ramp; the curves are back after it.
    events_until(&mut events, Duration::from_secs(20), |e| {
        loaded_for(e, "a job ended")
    })
    .await;
    assert!(holds_curves(&x, &profile) <= 1.0);

    // logind says the machine woke up.
    let emitted = std::process::Command::new("gdbus")
        .args([
            "emit",
            "--system",
            "--object-path",
            "/org/freedesktop/login1",
            "--signal",
            "org.freedesktop.login1.Manager.PrepareForSleep",
            "false",
        ])
        .env("DBUS_SYSTEM_BUS_ADDRESS", &bus.address)
        .output()
        .unwrap();
    assert!(
        emitted.status.success(),
        "{}",
        String::from_utf8_lossy(&emitted.stderr)
    );
    events_until(&mut events, Duration::from_secs(20), |e| {
        loaded_for(e, "resume")
    })
    .await;
    drop(daemon);

    // A daemon that starts loads the current curves at once.
    x.run("xrandr", &["--output", "DUMMY0", "--gamma", "1:1:1"]);
    assert!(holds_curves(&x, &profile) > 100.0);
    let daemon = start_daemon_with(
        dir.path(),
        &config,
        &[("DBUS_SYSTEM_BUS_ADDRESS", bus.address.as_str())],
    );
    until_curves_loaded(&x, &profile, &daemon).await;
    // And without keep_lut an overwrite is said but left alone. (Straightened before
    // the start, whose load is then seen.)
    drop(daemon);
    x.run("xrandr", &["--output", "DUMMY0", "--gamma", "1:1:1"]);
    let daemon = start_daemon_with(
        dir.path(),
        &config.replace("keep_lut = true", "keep_lut = false"),
        &[("DBUS_SYSTEM_BUS_ADDRESS", bus.address.as_str())],
    );
    let mut events = subscribe(&daemon.endpoint());
    until_curves_loaded(&x, &profile, &daemon).await;
    x.run("xrandr", &["--output", "DUMMY0", "--gamma", "0.8:0.8:0.8"]);
    let seen = events_until(&mut events, Duration::from_secs(20), |e| {
        matches!(e, Event::LutOverwritten { .. })
    })
    .await;
    assert!(
        matches!(
            seen.last(),
            Some(Event::LutOverwritten {
                reloading: false,
                ..
            })
        ),
        "{seen:#?}"
    );
    tokio::time::sleep(Duration::from_millis(2500)).await;
    assert!(
        holds_curves(&x, &profile) > 100.0,
        "keep_lut = false reloaded"
    );
}
