//! A real Wayland compositor for the tests: sway on wlroots' headless backend with the
//! pixman renderer (no GPU), one output `HEADLESS-1`. sway refuses to run as root, so
//! a test run as root starts it as `nobody` (`setpriv`), with a runtime directory that
//! user owns; root then reaches its socket as any client does.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The unprivileged user sway runs as when the tests run as root.
const NOBODY: u32 = 65534;

/// A running sway; stopped when dropped.
pub struct Sway {
    child: Child,
    /// The directory holding the sockets (`XDG_RUNTIME_DIR` for clients).
    pub runtime_dir: PathBuf,
    /// `wayland-1`: the socket's name in `runtime_dir`.
    pub wayland_display: String,
    /// sway's IPC socket, for `swaymsg`.
    pub ipc: PathBuf,
    pub log: PathBuf,
    _dir: tempfile::TempDir,
}

fn uid() -> u32 {
    let out = Command::new("id").arg("-u").output().unwrap();
    String::from_utf8_lossy(&out.stdout).trim().parse().unwrap()
}

impl Sway {
    pub fn start() -> Sway {
        super::need_tool("sway", "sway");
        let dir = tempfile::tempdir().unwrap();
        let root = uid() == 0;
        let runtime_dir = dir.path().join("runtime");
        std::fs::create_dir(&runtime_dir).unwrap();
        let config = dir.path().join("sway.conf");
        std::fs::write(
            &config,
            "xwayland disable\noutput * bg #000000 solid_color\ndefault_border none\n",
        )
        .unwrap();
        let log = dir.path().join("sway.log");
        use std::os::unix::fs::PermissionsExt as _;
        if root {
            std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
            std::fs::set_permissions(&config, std::fs::Permissions::from_mode(0o644)).unwrap();
            std::os::unix::fs::chown(&runtime_dir, Some(NOBODY), Some(NOBODY)).unwrap();
        }
        std::fs::set_permissions(&runtime_dir, std::fs::Permissions::from_mode(0o700)).unwrap();
        let mut command = if root {
            super::need_tool("setpriv", "util-linux");
            let mut c = Command::new("setpriv");
            c.args([
                &format!("--reuid={NOBODY}"),
                &format!("--regid={NOBODY}"),
                "--clear-groups",
                "sway",
            ]);
            c
        } else {
            Command::new("sway")
        };
        let child = command
            .arg("--config")
            .arg(&config)
            .env_clear()
            .env("PATH", "/usr/bin:/bin")
            .env("HOME", dir.path())
            .env("XDG_RUNTIME_DIR", &runtime_dir)
            .env("WLR_BACKENDS", "headless")
            .env("WLR_RENDERER", "pixman")
            .env("WLR_HEADLESS_OUTPUTS", "1")
            .env("WLR_LIBINPUT_NO_DEVICES", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .expect("sway starts (scripts/test.sh installs it)");
        let mut sway = Sway {
            child,
            runtime_dir,
            wayland_display: String::new(),
            ipc: PathBuf::new(),
            log,
            _dir: dir,
        };
        let deadline = Instant::now() + Duration::from_secs(20);
        while sway.wayland_display.is_empty() || sway.ipc.as_os_str().is_empty() {
            assert!(
                Instant::now() < deadline,
                "sway made no sockets in 20 s; its log:\n{}",
                std::fs::read_to_string(&sway.log).unwrap_or_default()
            );
            if let Ok(Some(status)) = sway.child.try_wait() {
                panic!(
                    "sway exited ({status}); its log:\n{}",
                    std::fs::read_to_string(&sway.log).unwrap_or_default()
                );
            }
            std::thread::sleep(Duration::from_millis(50));
            for entry in std::fs::read_dir(&sway.runtime_dir).unwrap().flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if name.starts_with("wayland-") && !name.ends_with(".lock") {
                    sway.wayland_display = name;
                } else if name.starts_with("sway-ipc") {
                    sway.ipc = entry.path();
                }
            }
        }
        // The output is there once sway answers on its IPC socket.
        while !sway.swaymsg(&["-t", "get_outputs"]).contains("HEADLESS-1") {
            assert!(Instant::now() < deadline, "sway has no output HEADLESS-1");
            std::thread::sleep(Duration::from_millis(50));
        }
        sway
    }

    /// The socket's full path (what `--wayland-display` may name).
    pub fn socket(&self) -> PathBuf {
        self.runtime_dir.join(&self.wayland_display)
    }

    /// A command with the environment of a client of this sway.
    pub fn client(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new(program);
        c.env("XDG_RUNTIME_DIR", &self.runtime_dir)
            .env("WAYLAND_DISPLAY", &self.wayland_display)
            .env("SWAYSOCK", &self.ipc)
            .env_remove("DISPLAY");
        c
    }

    /// `swaymsg ARGS`' output.
    pub fn swaymsg(&self, args: &[&str]) -> String {
        let out = self.client("swaymsg").args(args).output().unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// What `grim` (an independent screenshot tool, through wlr-screencopy) reads of
    /// output `output`: width, height and 8-bit RGB pixels.
    pub fn grim(&self, output: &str, dir: &Path) -> (usize, usize, Vec<[u8; 3]>) {
        super::need_tool("grim", "grim");
        let path = dir.join("grim.ppm");
        let out = self
            .client("grim")
            .args(["-t", "ppm", "-o", output])
            .arg(&path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "grim: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        read_ppm(&std::fs::read(&path).unwrap())
    }

    /// Stop sway's process (SIGSTOP), so that it presents nothing, or let it go on.
    pub fn pause(&self, paused: bool) {
        let signal = if paused { "-STOP" } else { "-CONT" };
        let status = Command::new("kill")
            .args([signal, &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
    }
}

impl Drop for Sway {
    fn drop(&mut self) {
        self.pause(false);
        super::terminate(&mut self.child, Duration::from_secs(5));
    }
}

/// A binary PPM (P6, maxval 255): width, height and pixels.
fn read_ppm(bytes: &[u8]) -> (usize, usize, Vec<[u8; 3]>) {
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 {
        while bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        let start = i;
        while !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[start..i]).into_owned());
    }
    assert_eq!(fields[0], "P6");
    assert_eq!(fields[3], "255");
    let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    let data = &bytes[i + 1..];
    assert_eq!(data.len(), w * h * 3);
    let pixels = data.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    (w, h, pixels)
}
