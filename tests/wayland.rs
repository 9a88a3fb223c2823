//! chromacal on a real Wayland compositor: sway, headless (wlroots' headless backend,
//! pixman renderer), started as an unprivileged user. The patch surface's pixels are
//! read back by `grim` (an independent reader, through wlr-screencopy), a patch counts
//! as shown only once the compositor has presented it, and `displays` names sway's
//! outputs.

use chromacal_display::PatchDisplay;
use chromacal_display::wayland::surface::{PatchSurface, SurfaceTarget};
use chromacal_display::x11::OutputSelector;
use chromacal_model::screen::{Codes, Geometry, Patch};

mod common;
use common::sway::Sway;

fn target(sway: &Sway) -> SurfaceTarget {
    SurfaceTarget {
        wayland_display: Some(sway.socket().display().to_string()),
        output: OutputSelector::Name("HEADLESS-1".into()),
    }
}

fn patch(rgb: [u32; 3], background: [u32; 3]) -> Patch {
    Patch {
        codes: Codes { rgb, bit_depth: 8 },
        background: Codes {
            rgb: background,
            bit_depth: 8,
        },
        geometry: Geometry::centred(0.3),
    }
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .unwrap()
}

/// 50 random codes, each a patch on a background of other random codes: what grim
/// reads of the output is exactly the codes asked, at the patch and around it.
#[test]
fn the_patch_surface_shows_the_exact_codes_grim_reads_back() {
    let sway = Sway::start();
    let dir = tempfile::tempdir().unwrap();
    let mut surface = PatchSurface::open(&target(&sway), 0.0).unwrap();
    let rt = runtime();
    // A small linear congruential generator: the codes differ each test, reproducibly.
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut random = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) % 256) as u32
    };
    for i in 0..50 {
        let codes = [random(), random(), random()];
        let background = [random(), random(), random()];
        rt.block_on(surface.show(&patch(codes, background)))
            .unwrap();
        let (w, h, pixels) = sway.grim("HEADLESS-1", dir.path());
        let at = |x: usize, y: usize| pixels[y * w + x].map(u32::from);
        eprintln!(
            "{i}: asked {codes:?} on {background:?}; {w}x{h} centre {:?} corner {:?}",
            at(w / 2, h / 2),
            at(2, 2)
        );
        assert_eq!(at(w / 2, h / 2), codes, "patch {i}: the centre");
        assert_eq!(at(2, 2), background, "patch {i}: a corner");
        assert_eq!(at(w - 3, h - 3), background, "patch {i}: the other corner");
    }
    surface.close();
}

/// With sway's process stopped (SIGSTOP), it draws and presents nothing: `show` does
/// not return, so no reading could start on the previous patch. Once sway goes on, it
/// returns, and the screen shows the patch. (On this sway, 1.7 on the headless
/// backend, neither `output dpms off`, which the headless output ignores, nor
/// `output disable` withholds frame callbacks, and it sends no presentation feedback:
/// holding back the whole compositor is what holds its frames back here.)
#[test]
fn no_patch_counts_as_shown_before_the_compositor_presents_it() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let sway = Sway::start();
    let dir = tempfile::tempdir().unwrap();
    let mut surface = PatchSurface::open(&target(&sway), 0.0).unwrap();
    let rt = runtime();
    rt.block_on(surface.show(&patch([10, 20, 30], [0; 3])))
        .unwrap();
    sway.pause(true);
    let shown = Arc::new(AtomicBool::new(false));
    let handle = {
        let shown = shown.clone();
        std::thread::spawn(move || {
            runtime()
                .block_on(surface.show(&patch([200, 100, 50], [0; 3])))
                .unwrap();
            shown.store(true, Ordering::SeqCst);
            surface
        })
    };
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let early = shown.load(Ordering::SeqCst);
    sway.pause(false);
    let mut surface = handle.join().unwrap();
    assert!(!early, "show returned while the compositor was stopped");
    let (w, h, pixels) = sway.grim("HEADLESS-1", dir.path());
    assert_eq!(pixels[(h / 2) * w + w / 2], [200, 100, 50]);
    surface.close();
}

/// `displays` on sway: the headless output by name with its mode, the EDID of the
/// kernel connector of the same name from a sysfs-shaped directory, what the
/// compositor offers, and a gamma ramp of size 0 said as none.
#[test]
fn displays_names_sway_s_output_with_its_edid_from_the_kernel() {
    let sway = Sway::start();
    let dir = tempfile::tempdir().unwrap();
    let sysfs = dir.path().join("sys");
    let connector = sysfs.join("class/drm/card0-HEADLESS-1");
    std::fs::create_dir_all(&connector).unwrap();
    std::fs::write(
        connector.join("edid"),
        std::fs::read(common::fixture("edid/srgb_office_1080p.bin")).unwrap(),
    )
    .unwrap();
    // Another card's connector that no output has.
    std::fs::create_dir_all(sysfs.join("class/drm/card1-DP-3")).unwrap();
    std::fs::write(sysfs.join("class/drm/card1-DP-3/edid"), b"").unwrap();
    let run = |args: &[&str]| {
        let mut c = sway.client(env!("CARGO_BIN_EXE_chromacal"));
        c.env("CHROMACAL_SYSFS_ROOT", &sysfs)
            .env("XDG_CONFIG_HOME", dir.path())
            .arg("displays")
            .args(args);
        common::succeed(&mut c)
    };
    let text = String::from_utf8_lossy(&run(&[]).stdout).into_owned();
    assert!(text.contains("Wayland display"), "{text}");
    assert!(text.contains("HEADLESS-1  1280×720 at 60.00 Hz"), "{text}");
    assert!(text.contains("video LUT: no gamma ramp"), "{text}");
    assert!(text.contains("7MT0186J1T3L"), "{text}");
    assert!(text.contains("zwlr_screencopy_manager_v1: yes"), "{text}");
    let json: serde_json::Value = serde_json::from_slice(
        &run(&[
            "--wayland-display",
            &sway.socket().display().to_string(),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    let output = &json["outputs"][0];
    assert_eq!(output["name"], "HEADLESS-1");
    assert_eq!(output["width"], 1280);
    assert_eq!(output["edid"]["serial_text"], "7MT0186J1T3L");
    assert_eq!(
        output["edid_source"],
        connector.join("edid").display().to_string()
    );
    assert_eq!(output["gamma"]["gamma"], "failed");
    assert_eq!(json["outputs"].as_array().unwrap().len(), 1);
    // The monitor's serial picks the output, by the kernel's EDID.
    let mut lut = sway.client(env!("CARGO_BIN_EXE_chromacal"));
    lut.env("CHROMACAL_SYSFS_ROOT", &sysfs)
        .args([
            "lut",
            "show",
            "--output",
            "edid_serial=7MT0186J1T3L",
            "--state-dir",
        ])
        .arg(dir.path().join("state"));
    let shown = common::succeed(&mut lut);
    assert!(
        String::from_utf8_lossy(&shown.stdout).starts_with("HEADLESS-1 on Wayland"),
        "{}",
        String::from_utf8_lossy(&shown.stdout)
    );
    let mut wrong = sway.client(env!("CARGO_BIN_EXE_chromacal"));
    wrong
        .env("CHROMACAL_SYSFS_ROOT", &sysfs)
        .args(["lut", "show", "--output", "edid_serial=NOPE", "--state-dir"])
        .arg(dir.path().join("state"));
    let refused = wrong.output().unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success()
            && err.contains("whose monitor's EDID serial is 'NOPE'")
            && err.contains("HEADLESS-1"),
        "{err}"
    );
}

/// A whole calibration on Wayland with real bytes at every step: the patches on the
/// surface on sway's output, an emulated PR-670 on a pseudo-terminal whose virtual
/// monitor is shown what `wlr-screencopy` reads under its aim point, the curves put
/// into the codes (the headless output has no gamma ramp). Its profile matches the
/// same monitor's over the emulator's screen socket, within the instrument's noise.
#[test]
fn a_calibration_on_sway_matches_the_same_monitor_over_the_emulator_socket() {
    use chromacal::profile::Profile;
    let sway = Sway::start();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(
        &config,
        "[monitor]\npreset = \"crt\"\n[plan]\nuniformity_grid = 0\n[display]\nsettle_s = 0.0\n\
         [target]\nwhite = \"D65\"\ntone = \"gamma:2.2\"\nlevels = 10\n",
    )
    .unwrap();
    let config_arg = config.to_str().unwrap();
    let calibrate = |state: &std::path::Path, args: &[&str]| {
        let out = common::succeed(
            common::chromacal()
                .arg("calibrate")
                .arg("--config")
                .arg(&config)
                .arg("--state-dir")
                .arg(state)
                .args(args),
        );
        (
            Profile::read(&state.join("current.toml")).unwrap(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
        )
    };
    let socket_emulator = common::emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--config",
        config_arg,
    ]);
    let (reference, _) = calibrate(
        &dir.path().join("socket"),
        &[
            "--instrument",
            &format!("pr670:{}", socket_emulator.device),
            "--screen",
            &socket_emulator.screen,
            "--timing-scale",
            "0.002",
        ],
    );
    let wayland = sway.socket().display().to_string();
    let emulator = common::emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--config",
        config_arg,
        "--wayland-display",
        &wayland,
        "--output",
        "HEADLESS-1",
    ]);
    let (profile, summary) = calibrate(
        &dir.path().join("wayland"),
        &[
            "--display",
            "wayland:HEADLESS-1",
            "--wayland-display",
            &wayland,
            "--instrument",
            &format!("pr670:{}", emulator.device),
            "--timing-scale",
            "0.002",
        ],
    );
    eprintln!("{summary}");
    let shown_on = profile.provenance.display.clone().unwrap_or_default();
    assert!(
        shown_on.contains("Wayland surface on HEADLESS-1"),
        "{shown_on}"
    );
    common::assert_same_model("wayland", &profile, &reference);
    let (held, reference_held) = (
        profile.report.held_out.unwrap(),
        reference.report.held_out.unwrap(),
    );
    eprintln!("held-out on Wayland {held:?}, through the socket {reference_held:?}");
    assert!(
        (held.mean - reference_held.mean).abs() < 0.1 && held.mean < 0.3,
        "{held:?} vs {reference_held:?}"
    );
    // The curves went into the codes, and were measured into place through them.
    let calibration = profile.calibration.as_ref().unwrap();
    assert!(calibration.measured_white_de00 < 1.0, "{calibration:?}");
}

/// `lut` on sway's headless output: without --hold it says the compositor would drop
/// the ramp; with it, that the output has no gamma ramp and what to do instead;
/// `show` says so and that no chromacal process holds it. The KDE path runs a
/// stand-in `kscreen-doctor` that records its arguments (the real one needs Plasma 6):
/// the profile is set with its curves in an ICC `vcgt` that ArgyllCMS's `iccdump`
/// reads, and `reset` puts the output back on sRGB.
#[test]
fn lut_on_wayland_says_where_the_curves_go_and_drives_kscreen_doctor() {
    let sway = Sway::start();
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    common::calibrate_default(&state);
    let lut = |args: &[&str]| {
        let mut c = sway.client(env!("CARGO_BIN_EXE_chromacal"));
        c.arg("lut").args(args).arg("--state-dir").arg(&state);
        c
    };
    let failed = |mut c: std::process::Command| {
        let out = c.output().unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    // The default calibration has no [target]: curves from its model for D65, 2.2.
    let err = failed(lut(&[
        "load",
        "--current",
        "--white",
        "D65",
        "--tone",
        "gamma:2.2",
    ]));
    assert!(err.contains("give --hold"), "{err}");
    let err = failed(lut(&[
        "load",
        "--current",
        "--hold",
        "--white",
        "D65",
        "--tone",
        "gamma:2.2",
    ]));
    assert!(
        err.contains("offers no gamma ramp on HEADLESS-1")
            && err.contains("headless or nested output")
            && err.contains("exported ICC profile"),
        "{err}"
    );
    let shown = common::succeed(&mut lut(&["show"]));
    let shown = String::from_utf8_lossy(&shown.stdout);
    assert!(
        shown.contains("HEADLESS-1 on Wayland: curves go into its gamma ramp")
            && shown.contains("no gamma ramp to load")
            && shown.contains("held by no chromacal process"),
        "{shown}"
    );

    // KDE, through a stand-in kscreen-doctor on the PATH.
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let record = dir.path().join("kscreen-doctor.args");
    let script = bin.join("kscreen-doctor");
    std::fs::write(
        &script,
        format!(
            "#!/bin/sh\nfor a in \"$@\"; do echo \"$a\" >> {}; done\n",
            record.display()
        ),
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = common::succeed(
        lut(&[
            "load",
            "--current",
            "--via",
            "kde",
            "--white",
            "D65",
            "--tone",
            "gamma:2.2",
        ])
        .env("PATH", &path),
    );
    let said = String::from_utf8_lossy(&out.stdout);
    let icc = state.join("wayland/HEADLESS-1.icc").canonicalize().unwrap();
    let args = std::fs::read_to_string(&record).unwrap();
    assert_eq!(
        args.lines().collect::<Vec<_>>(),
        [
            format!("output.HEADLESS-1.iccprofile.{}", icc.display()),
            "output.HEADLESS-1.colorProfileSource.ICC".to_string()
        ],
        "{said}"
    );
    common::need_tool("iccdump", "argyll");
    let dump = common::succeed(
        std::process::Command::new("iccdump")
            .args(["-v", "1"])
            .arg(&icc),
    );
    let dump = String::from_utf8_lossy(&dump.stdout);
    assert!(dump.contains("vcgt"), "{dump}");
    std::fs::remove_file(&record).unwrap();
    common::succeed(lut(&["reset", "--via", "kde"]).env("PATH", &path));
    assert_eq!(
        std::fs::read_to_string(&record)
            .unwrap()
            .lines()
            .collect::<Vec<_>>(),
        [
            "output.HEADLESS-1.colorProfileSource.sRGB",
            "output.HEADLESS-1.iccprofile."
        ]
    );
}
