//! ArgyllCMS `spotread` on chromacal's emulators. Argyll lists only serial device
//! names (`ttyUSB*`, `ttyACM*`, `ttyS*`), never `/dev/pts/N`, and its port scan reads
//! every tty it lists. So spotread runs through a wrapper that gives it a private
//! mount namespace (`unshare -m`, as root) whose `/dev` holds the basics and
//! `ttyUSB0` → the emulator's pseudo-terminal, set to `min 0 time 1` so that the scan's
//! blocking read returns. chromacal finds the wrapper through `CHROMACAL_SPOTREAD`.

use std::path::{Path, PathBuf};

use super::need_tool;

/// A `spotread` wrapper whose ArgyllCMS port 1 is the pseudo-terminal `pty`.
pub struct SpotreadWrapper {
    pub path: PathBuf,
    dev: PathBuf,
}

impl SpotreadWrapper {
    /// Write the wrapper into `dir`.
    pub fn new(dir: &Path, pty: &str) -> Self {
        need_tool("spotread", "argyll");
        need_tool("unshare", "util-linux");
        let ok = std::process::Command::new("unshare")
            .args(["-m", "true"])
            .status()
            .is_ok_and(|s| s.success());
        assert!(
            ok,
            "the ArgyllCMS tests run spotread in a private mount namespace (unshare -m), which needs root"
        );
        let dev = dir.join("argyll-dev");
        std::fs::create_dir_all(&dev).unwrap();
        let wrapper = SpotreadWrapper {
            path: dir.join("spotread"),
            dev,
        };
        wrapper.point_at(pty);
        wrapper
    }

    /// Port 1 is now `pty` (an emulator started again).
    pub fn point_at(&self, pty: &str) {
        let dev = self.dev.display();
        let script = format!(
            r#"#!/bin/sh
exec unshare -m /bin/sh -c '
set -e
d="{dev}"
mount --make-rprivate /
mount -t tmpfs tmpfs "$d"
for n in null urandom; do touch "$d/$n"; mount --bind "/dev/$n" "$d/$n"; done
mkdir "$d/pts"; mount --bind /dev/pts "$d/pts"
ln -s "{pty}" "$d/ttyUSB0"
mount --rbind "$d" /dev
stty -F /dev/ttyUSB0 min 0 time 1
exec spotread "$@"' sh "$@"
"#
        );
        let tmp = self.path.with_extension("new");
        std::fs::write(&tmp, script).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&tmp, std::fs::Permissions::from_mode(0o755)).unwrap();
        std::fs::rename(&tmp, &self.path).unwrap();
    }
}
