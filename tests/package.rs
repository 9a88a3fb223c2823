//! The Debian package (`scripts/package.sh`, `cargo deb`): built from the binary under
//! test, installed into a scratch root by dpkg itself, and the installed units checked
//! by `systemd-analyze verify` against what was installed (issue 29, item 3).

mod common;

use std::path::Path;
use std::process::Command;

use common::need_tool;

fn run(command: &mut Command) -> String {
    let out = command.output().expect("the command starts");
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{command:?}: {said}");
    said
}

#[test]
fn the_package_installs_the_binary_units_user_config_manuals_and_completions() {
    need_tool("cargo-deb", "none: `cargo install --locked cargo-deb`");
    need_tool("dpkg", "dpkg");
    need_tool("systemd-analyze", "systemd");
    let scratch = tempfile::tempdir().expect("tempdir");
    // The binary under test, where cargo-deb looks for a release build.
    let release = scratch.path().join("release");
    std::fs::create_dir_all(&release).expect("mkdir");
    std::fs::copy(env!("CARGO_BIN_EXE_chromacal"), release.join("chromacal")).expect("copy");
    let out = scratch.path().join("out");
    run(
        Command::new(Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/package.sh"))
            .args(["--no-build", "--fast", "-o"])
            .arg(&out)
            .env("CARGO_TARGET_DIR", scratch.path()),
    );
    let deb = std::fs::read_dir(&out)
        .expect("the output folder")
        .map(|e| e.expect("entry").path())
        .find(|p| p.extension().is_some_and(|e| e == "deb"))
        .expect("a .deb was made");

    // Installed by dpkg into an empty root; its postinst runs outside a chroot with
    // DPKG_ROOT set, so the user is made in the scratch root, not this machine's.
    let root = scratch.path().join("root");
    for dir in ["var/lib/dpkg/updates", "var/lib/dpkg/info"] {
        std::fs::create_dir_all(root.join(dir)).expect("mkdir");
    }
    std::fs::write(root.join("var/lib/dpkg/status"), "").expect("status");
    let mut dpkg = Command::new("dpkg");
    dpkg.arg(format!("--root={}", root.display()))
        .args([
            "--force-script-chrootless",
            "--force-not-root",
            "--force-depends",
            "--log=/dev/null",
            "-i",
        ])
        .arg(&deb);
    run(&mut dpkg);
    let status = run(Command::new("dpkg")
        .arg(format!("--root={}", root.display()))
        .args(["-s", "chromacal"]));
    assert!(status.contains("Status: install ok installed"), "{status}");
    // USB instruments need ArgyllCMS: the package says so.
    assert!(
        status
            .lines()
            .any(|l| l.starts_with("Suggests:") && l.contains("argyll")),
        "{status}"
    );

    for file in [
        "usr/bin/chromacal",
        "etc/chromacal/config.toml",
        "usr/lib/systemd/system/chromacal.service",
        "usr/lib/systemd/system/chromacal-verify.service",
        "usr/lib/systemd/system/chromacal-verify.timer",
        "usr/lib/sysusers.d/chromacal.conf",
        "usr/lib/systemd/user/chromacal-lut.service",
        "etc/xdg/autostart/chromacal-lut.desktop",
        "usr/share/man/man1/chromacal.1.gz",
        "usr/share/man/man1/chromacal-calibrate.1.gz",
        "usr/share/bash-completion/completions/chromacal",
        "usr/share/zsh/vendor-completions/_chromacal",
        "usr/share/fish/vendor_completions.d/chromacal.fish",
    ] {
        assert!(root.join(file).is_file(), "the package leaves out /{file}");
    }
    // The config is a conffile: an administrator's edits survive an upgrade.
    let conffiles = std::fs::read_to_string(root.join("var/lib/dpkg/info/chromacal.conffiles"))
        .expect("conffiles");
    assert!(
        conffiles.contains("/etc/chromacal/config.toml"),
        "{conffiles}"
    );
    // The installed binary runs, and its default config is the one it loads.
    let version = run(Command::new(root.join("usr/bin/chromacal")).arg("--version"));
    assert!(version.contains(env!("CARGO_PKG_VERSION")), "{version}");
    run(Command::new(root.join("usr/bin/chromacal"))
        .args(["config", "show", "--config"])
        .arg(root.join("etc/chromacal/config.toml")));
    // The user the service runs as, in the group that may open serial ports.
    let passwd = std::fs::read_to_string(root.join("etc/passwd")).unwrap_or_default();
    let group = std::fs::read_to_string(root.join("etc/group")).unwrap_or_default();
    assert!(
        passwd.lines().any(|l| l.starts_with("chromacal:")),
        "{passwd}"
    );
    assert!(
        group
            .lines()
            .any(|l| l.starts_with("dialout:") && l.contains("chromacal")),
        "{group}"
    );

    // systemd-analyze verify on the installed units, against the installed tree: the
    // units they need (sysinit.target, …) and /bin/kill are copied in from this
    // machine, /usr/bin/chromacal is the package's.
    let units = root.join("usr/lib/systemd/system");
    run(Command::new("cp")
        .arg("-rn")
        .arg("/usr/lib/systemd/system/.")
        .arg(&units));
    std::fs::create_dir_all(root.join("bin")).expect("mkdir");
    let kill = ["/bin/kill", "/usr/bin/kill"]
        .into_iter()
        .find(|k| Path::new(k).exists())
        .expect("kill");
    std::fs::copy(kill, root.join("bin/kill")).expect("copy kill");
    let verify = Command::new("systemd-analyze")
        .arg("verify")
        .arg(format!("--root={}", root.display()))
        .args([
            "chromacal.service",
            "chromacal-verify.service",
            "chromacal-verify.timer",
        ])
        .output()
        .expect("systemd-analyze");
    let said = String::from_utf8_lossy(&verify.stderr);
    assert!(verify.status.success(), "{said}");
    assert!(
        !said.contains("chromacal"),
        "warnings on the installed units: {said}"
    );
}
