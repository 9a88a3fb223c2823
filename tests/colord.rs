//! Registering an exported profile with colord over D-Bus, against a real colord on a
//! private system bus (`../shared/INTERFACES.md` B4): dbus-daemon on a socket in a
//! temporary directory, and colord run as root in its own mount namespace with a
//! tmpfs over /var/lib/colord, so that the machine's colour database is not touched.
//! colord's own client (`colormgr`) and `gdbus` then read what chromacal registered.

mod common;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{chromacal, in_process_profile};

/// Kills the bus and colord when the test ends, however it ends.
struct Services(Vec<Child>);

impl Drop for Services {
    fn drop(&mut self) {
        for child in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// A system bus and colord on it; returns the bus address.
fn start_colord(dir: &Path) -> (Services, common::bus::SystemBus, String) {
    for (tool, package) in [
        ("dbus-daemon", "dbus-daemon"),
        ("/usr/libexec/colord", "colord"),
        ("colormgr", "colord"),
        ("gdbus", "libglib2.0-bin"),
        ("unshare", "util-linux"),
    ] {
        common::need_tool(tool, package);
    }
    let uid = Command::new("id").arg("-u").output().unwrap();
    assert_eq!(
        String::from_utf8_lossy(&uid.stdout).trim(),
        "0",
        "colord runs as root (polkit lets root through); run the tests as root"
    );
    let bus = common::bus::SystemBus::start(dir);
    let address = bus.address.clone();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut services = Services(vec![]);
    let colord = Command::new("unshare")
        .args([
            "-m",
            "sh",
            "-c",
            "mkdir -p /var/lib/colord && mount -t tmpfs none /var/lib/colord && exec /usr/libexec/colord",
        ])
        .env("DBUS_SYSTEM_BUS_ADDRESS", &address)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    services.0.push(colord);
    // colord is up when its client gets an answer.
    loop {
        let ok = Command::new("colormgr")
            .arg("get-devices")
            .env("DBUS_SYSTEM_BUS_ADDRESS", &address)
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "colord did not come up on the private bus"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    (services, bus, address)
}

#[test]
fn an_exported_profile_becomes_the_default_of_a_display_in_colord() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, "[monitor]\npreset = \"lcd\"\n").unwrap();
    in_process_profile(&config, &dir.path().join("state"));
    let profile = dir.path().join("state/current.toml");
    let icc = dir.path().join("display.icc");
    let export = |address: &str| {
        chromacal()
            .arg("export")
            .arg(&profile)
            .args(["--format", "icc4", "-o"])
            .arg(&icc)
            .args(["--white", "D65", "--tone", "gamma:2.2"])
            .args(["--register-colord", "xrandr-chromacal-test"])
            .env("DBUS_SYSTEM_BUS_ADDRESS", address)
            .output()
            .unwrap()
    };

    // No bus: the file is written, the message says why it was not registered.
    let out = export(&format!(
        "unix:path={}",
        dir.path().join("no-bus").display()
    ));
    assert_eq!(out.status.code(), Some(4));
    let message = String::from_utf8_lossy(&out.stderr);
    assert!(
        message.contains("no system D-Bus") && message.contains("written but not registered"),
        "{message}"
    );
    assert!(icc.exists());

    let (_services, _bus, address) = start_colord(dir.path());
    let out = export(&address);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains("is the default profile of xrandr-chromacal-test"),
        "{said}"
    );

    // colord's own client sees it as the display's default, with its vcgt.
    let device = "/org/freedesktop/ColorManager/devices/xrandr_chromacal_test";
    let shown = Command::new("colormgr")
        .args(["device-get-default-profile", device])
        .env("DBUS_SYSTEM_BUS_ADDRESS", &address)
        .output()
        .unwrap();
    let shown = String::from_utf8_lossy(&shown.stdout);
    let canonical = std::fs::canonicalize(&icc).unwrap();
    assert!(
        shown.contains(&format!("Filename:      {}", canonical.display())),
        "{shown}"
    );
    assert!(shown.contains("Gamma Table:   Yes"), "{shown}");
    // colord read the profile's own `meta` dict (this key is in no D-Bus call).
    assert!(
        shown.contains(&format!("CMF_version={}", env!("CARGO_PKG_VERSION"))),
        "{shown}"
    );
    let bytes = std::fs::read(&icc).unwrap();
    let id = chromacal::export::colord::colord_profile_id(&bytes);
    assert!(shown.contains(&id), "{shown}");

    // colord checks every profile it is given (primaries, white point, grey axis,
    // vcgt monotonicity); it finds nothing wrong with this one.
    let object = format!(
        "/org/freedesktop/ColorManager/profiles/{}",
        id.replace('-', "_")
    );
    let warnings = Command::new("gdbus")
        .args(["call", "--system", "--dest", "org.freedesktop.ColorManager"])
        .args(["--object-path", &object])
        .args(["--method", "org.freedesktop.DBus.Properties.Get"])
        .args(["org.freedesktop.ColorManager.Profile", "Warnings"])
        .env("DBUS_SYSTEM_BUS_ADDRESS", &address)
        .output()
        .unwrap();
    let warnings = String::from_utf8_lossy(&warnings.stdout);
    assert_eq!(warnings.trim(), "(<@as []>,)", "colord warns: {warnings}");

    // Registering again is not an error: the profile and the device are found.
    let out = export(&address);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
