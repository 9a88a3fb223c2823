//! A real X server for the tests: Xorg with the `dummy` video driver, headless, on a
//! display number it picks itself (`-displayfd`). Unlike Xvfb 21.1 (whose CRTC gamma
//! ramp reads back freed memory), its RandR CRTCs keep the gamma ramps set on them,
//! its modes have real timings (60 Hz), and it has several outputs, as a desktop does.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

const CONFIG: &str = r#"Section "Device"
    Identifier "dummy"
    Driver "dummy"
    VideoRam 64000
EndSection
Section "Monitor"
    Identifier "monitor"
    HorizSync 5.0-1000.0
    VertRefresh 5.0-200.0
    Modeline "1024x768" 65.00 1024 1048 1184 1344 768 771 777 806 -hsync -vsync
    Modeline "800x600" 40.00 800 840 968 1056 600 601 605 628 +hsync +vsync
EndSection
Section "Screen"
    Identifier "screen"
    Device "dummy"
    Monitor "monitor"
    DefaultDepth 24
    SubSection "Display"
        Depth 24
        Modes "1024x768" "800x600"
    EndSubSection
EndSection
"#;

/// A running Xorg; stopped when dropped.
pub struct XServer {
    child: Child,
    /// `:N`.
    pub display: String,
    _dir: tempfile::TempDir,
    pub log: PathBuf,
}

impl XServer {
    pub fn start() -> XServer {
        super::need_tool("Xorg", "xserver-xorg-core");
        assert!(
            std::path::Path::new("/usr/lib/xorg/modules/drivers/dummy_drv.so").exists(),
            "the tests need Xorg's dummy driver: scripts/test.sh installs xserver-xorg-video-dummy"
        );
        let dir = tempfile::tempdir().unwrap();
        let config = dir.path().join("xorg.conf");
        std::fs::write(&config, CONFIG).unwrap();
        let log = dir.path().join("Xorg.log");
        let mut child = Command::new("Xorg")
            .arg("-config")
            .arg(&config)
            .args(["-configdir", "/nonexistent", "-noreset", "-nolisten", "tcp"])
            .arg("-logfile")
            .arg(&log)
            .args(["-displayfd", "1"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .stdin(Stdio::null())
            .spawn()
            .expect(
                "Xorg starts (scripts/test.sh installs xserver-xorg-core and the dummy driver)",
            );
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let number = line.trim();
        assert!(
            !number.is_empty(),
            "Xorg said no display number; its log: {}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        XServer {
            child,
            display: format!(":{number}"),
            _dir: dir,
            log,
        }
    }

    /// A command with DISPLAY set to this server.
    pub fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("DISPLAY", &self.display);
        c
    }

    /// Run a command against this server; the test fails if it does.
    pub fn run(&self, program: &str, args: &[&str]) -> String {
        let out = self.command(program).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{program} {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }
}

impl Drop for XServer {
    /// SIGTERM, so that Xorg removes its lock file and socket.
    fn drop(&mut self) {
        super::terminate(&mut self.child, std::time::Duration::from_secs(5));
    }
}
