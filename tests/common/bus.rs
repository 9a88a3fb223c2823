//! A private D-Bus system bus for the tests: dbus-daemon on a socket in a temporary
//! directory, open to every user, killed when dropped. Programs reach it through
//! `DBUS_SYSTEM_BUS_ADDRESS`.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BUS_CONFIG: &str = r#"<!DOCTYPE busconfig PUBLIC "-//freedesktop//DTD D-Bus Bus Configuration 1.0//EN"
 "http://www.freedesktop.org/standards/dbus/1.0/busconfig.dtd">
<busconfig><type>system</type>
  <listen>unix:path=SOCKET</listen><auth>EXTERNAL</auth>
  <policy context="default"><allow user="*"/><allow own="*"/><allow send_type="method_call"/>
   <allow send_type="signal"/><allow send_requested_reply="true" send_type="method_return"/>
   <allow send_requested_reply="true" send_type="error"/><allow receive_type="method_call"/>
   <allow receive_type="method_return"/><allow receive_type="error"/><allow receive_type="signal"/></policy>
</busconfig>
"#;

/// A running private system bus.
pub struct SystemBus {
    child: Child,
    /// `unix:path=…`, for `DBUS_SYSTEM_BUS_ADDRESS`.
    pub address: String,
}

impl SystemBus {
    /// Start one with its socket in `dir`.
    pub fn start(dir: &Path) -> SystemBus {
        super::need_tool("dbus-daemon", "dbus-daemon");
        let socket = dir.join("system_bus_socket");
        let config = dir.join("bus.conf");
        std::fs::write(
            &config,
            BUS_CONFIG.replace("SOCKET", socket.to_str().unwrap()),
        )
        .unwrap();
        let child = Command::new("dbus-daemon")
            .arg(format!("--config-file={}", config.display()))
            .args(["--nofork", "--print-address=1"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let bus = SystemBus {
            child,
            address: format!("unix:path={}", socket.display()),
        };
        let deadline = Instant::now() + Duration::from_secs(10);
        while !socket.exists() {
            assert!(Instant::now() < deadline, "dbus-daemon made no socket");
            std::thread::sleep(Duration::from_millis(20));
        }
        bus
    }
}

impl Drop for SystemBus {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
