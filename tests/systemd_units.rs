//! The systemd units in `systemd/`: `systemd-analyze verify` accepts them with no
//! warning (with ExecStart pointed at the built binary, which it checks exists), and
//! the service says what the daemon relies on.

use std::path::Path;

fn units_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("systemd")
}

/// `key=value` lines of a unit, in order.
fn settings(text: &str) -> Vec<(String, String)> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.starts_with('#') && !l.starts_with('[') && l.contains('='))
        .filter_map(|l| l.split_once('='))
        .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
        .collect()
}

#[test]
fn systemd_analyze_verifies_the_units_without_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let binary = env!("CARGO_BIN_EXE_chromacal");
    let names = [
        "chromacal.service",
        "chromacal-verify.service",
        "chromacal-verify.timer",
    ];
    for name in names {
        let text = std::fs::read_to_string(units_dir().join(name)).unwrap();
        assert!(text.contains("/usr/bin/chromacal") || name.ends_with(".timer"));
        std::fs::write(
            dir.path().join(name),
            text.replace("/usr/bin/chromacal", binary),
        )
        .unwrap();
    }
    let out = std::process::Command::new("systemd-analyze")
        .arg("verify")
        .args(names.iter().map(|n| dir.path().join(n)))
        .output()
        .expect("systemd-analyze (scripts/test.sh installs systemd when it is missing)");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.trim().is_empty(), "warnings: {stderr}");
}

#[test]
fn the_service_is_a_hardened_notify_service_with_its_own_user_and_state() {
    let text = std::fs::read_to_string(units_dir().join("chromacal.service")).unwrap();
    let s = settings(&text);
    let value = |key: &str| {
        s.iter()
            .filter(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
            .collect::<Vec<_>>()
    };
    assert_eq!(value("Type"), ["notify"]);
    assert_eq!(value("WatchdogSec").len(), 1);
    assert_eq!(value("StateDirectory"), ["chromacal"]);
    assert_eq!(value("RuntimeDirectory"), ["chromacal"]);
    assert_eq!(value("User"), ["chromacal"]);
    for (key, want) in [
        ("ProtectSystem", "strict"),
        ("PrivateTmp", "yes"),
        ("NoNewPrivileges", "yes"),
        ("DevicePolicy", "closed"),
    ] {
        assert_eq!(value(key), [want], "{key}");
    }
    let devices = value("DeviceAllow");
    for family in ["char-ttyUSB rw", "char-ttyACM rw"] {
        assert!(devices.contains(&family), "{devices:?}");
    }
    // The daemon's default socket is where the verify service looks for it.
    let verify = std::fs::read_to_string(units_dir().join("chromacal-verify.service")).unwrap();
    assert!(verify.contains("--socket /run/chromacal/api.sock"));
    let timer = std::fs::read_to_string(units_dir().join("chromacal-verify.timer")).unwrap();
    assert!(timer.contains("Unit=chromacal-verify.service"));
    // sysusers makes the user, in the serial group.
    let sysusers = std::fs::read_to_string(units_dir().join("chromacal.sysusers")).unwrap();
    assert!(sysusers.lines().any(|l| l.starts_with("u chromacal")));
    assert!(sysusers.lines().any(|l| l == "m chromacal dialout"));
}

#[test]
fn under_systemd_the_socket_goes_to_the_runtime_directory() {
    let dir = tempfile::tempdir().unwrap();
    let runtime = dir.path().join("run");
    std::fs::create_dir(&runtime).unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_chromacal"))
        .args(["daemon", "--state-dir"])
        .arg(dir.path().join("state"))
        .env("RUNTIME_DIRECTORY", &runtime)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let socket = runtime.join("api.sock");
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while !socket.exists() {
        assert!(
            std::time::Instant::now() < deadline,
            "no socket at {}",
            socket.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_chromacal"))
        .args(["status", "--socket"])
        .arg(&socket)
        .output()
        .unwrap();
    let _ = child.kill();
    let _ = child.wait();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    assert!(String::from_utf8_lossy(&status.stdout).contains("chromacal daemon"));
}

/// The user unit and the XDG autostart entry that keep the curves at login: systemd
/// (as a user manager) and the freedesktop validator accept them, and both run the
/// same command, one the parser takes.
#[test]
fn the_login_keeper_unit_and_autostart_entry_are_valid_and_run_the_same_command() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let binary = env!("CARGO_BIN_EXE_chromacal");
    let dir = tempfile::tempdir().unwrap();
    let unit = std::fs::read_to_string(units_dir().join("user/chromacal-lut.service")).unwrap();
    let path = dir.path().join("chromacal-lut.service");
    std::fs::write(&path, unit.replace("/usr/bin/chromacal", binary)).unwrap();
    // A user manager needs a runtime directory of its own.
    let runtime = dir.path().join("runtime");
    std::fs::create_dir(&runtime).unwrap();
    let out = std::process::Command::new("systemd-analyze")
        .args(["--user", "--man=no", "verify"])
        .arg(&path)
        .env("XDG_RUNTIME_DIR", &runtime)
        .output()
        .expect("systemd-analyze");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.trim().is_empty(), "warnings: {stderr}");

    let desktop = root.join("xdg/chromacal-lut.desktop");
    let out = std::process::Command::new("desktop-file-validate")
        .arg(&desktop)
        .output()
        .expect("desktop-file-validate (scripts/test.sh installs desktop-file-utils)");
    let said =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && said.trim().is_empty(), "{said}");

    let exec_start = settings(&unit)
        .into_iter()
        .find(|(k, _)| k == "ExecStart")
        .map(|(_, v)| v)
        .unwrap();
    let desktop_text = std::fs::read_to_string(&desktop).unwrap();
    let exec = desktop_text
        .lines()
        .find_map(|l| l.strip_prefix("Exec="))
        .unwrap();
    assert_eq!(exec_start.trim_start_matches("/usr/bin/"), exec);
    // The command is one chromacal takes: its arguments parse (--help stops it
    // before it opens a display).
    let args: Vec<&str> = exec.split_whitespace().skip(1).collect();
    let out = std::process::Command::new(binary)
        .args(&args)
        .arg("--help")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
