//! The screen in front of the user, end to end, against a real X server (Xorg with the
//! dummy driver, `common::xserver`): chromacal's patch window puts exact codes on the
//! screen and waits for the server; the video LUT is loaded, read back by ArgyllCMS
//! `dispwin`, reset, and put back after kill -9; and a whole calibration runs with real
//! bytes at every step — window → X server → emulator looking at the X screen through
//! the CRTC gamma → pty → chromacal → fit → LUT → verification measured through it.

use std::io::{Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use chromacal::profile::Profile;
use chromacal_display::PatchDisplay;
use chromacal_display::window::{PatchWindow, WindowTarget};
use chromacal_display::x11::{GammaRamp, OutputSelector, XDisplay};
use chromacal_model::ScreenPosition;
use chromacal_model::screen::{Codes, Geometry, Patch};
use rand::{Rng, SeedableRng};

mod common;
use common::xserver::XServer;
use common::{chromacal, emulate, succeed};

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .unwrap()
}

fn window_on(x: &XServer) -> PatchWindow {
    PatchWindow::open(
        &WindowTarget {
            x_display: Some(x.display.clone()),
            output: OutputSelector::Primary,
        },
        0.0,
    )
    .unwrap()
}

#[test]
fn the_window_shows_the_codes_asked_for() {
    let x = XServer::start();
    let mut window = window_on(&x);
    assert_eq!(window.channel_bits(), 8);
    let reader = XDisplay::open(Some(&x.display)).unwrap();
    let output = reader.output(&OutputSelector::Primary).unwrap();
    assert_eq!(output.name, "DUMMY0");
    let rt = runtime();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(25);
    for i in 0..50 {
        let codes = [0; 3].map(|_| rng.random_range(0..=255u32));
        let mut background = [0; 3].map(|_| rng.random_range(0..=255u32));
        if background == codes {
            background[0] ^= 1;
        }
        let centre = ScreenPosition::new(rng.random_range(0.3..0.7), rng.random_range(0.3..0.7));
        let geometry = Geometry::around(centre, rng.random_range(0.1..0.4));
        let patch = Patch {
            codes: Codes {
                rgb: codes,
                bit_depth: 8,
            },
            background: Codes {
                rgb: background,
                bit_depth: 8,
            },
            geometry,
        };
        rt.block_on(window.show(&patch)).unwrap();
        let sample = reader.sample(&output, (centre.x, centre.y)).unwrap();
        assert_eq!(sample.patch, codes, "patch {i}");
        assert_eq!(sample.background, background, "patch {i}");
        let expected = [
            geometry.x * 1024.0,
            geometry.y * 768.0,
            geometry.width * 1024.0,
            geometry.height * 768.0,
        ];
        for (got, want) in sample.rect.iter().zip(expected) {
            assert!(
                (*got as f64 - want).abs() <= 1.0,
                "patch {i}: {:?} vs {expected:?}",
                sample.rect
            );
        }
    }
    // Ten-bit codes cannot be shown on an 8-bit visual: said, not rounded.
    let err = rt
        .block_on(window.show(&Patch {
            codes: Codes {
                rgb: [1023, 0, 0],
                bit_depth: 10,
            },
            background: Codes {
                rgb: [0; 3],
                bit_depth: 10,
            },
            geometry: Geometry::centred(0.2),
        }))
        .unwrap_err();
    assert!(err.to_string().contains("plan.bit_depth = 8"), "{err}");
}

/// A proxy in front of the X server's socket that can hold back what the server
/// sends, so that a test sees whether a client waits for the server's reply.
struct HoldingProxy {
    display: String,
    hold: Arc<AtomicBool>,
    path: PathBuf,
}

impl HoldingProxy {
    fn start(server_display: &str) -> HoldingProxy {
        let number: u32 = server_display.trim_start_matches(':').parse().unwrap();
        let (path, listener, display) = (number + 500..number + 600)
            .find_map(|n| {
                let path = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
                if path.exists() || Path::new(&format!("/tmp/.X{n}-lock")).exists() {
                    return None;
                }
                UnixListener::bind(&path)
                    .ok()
                    .map(|l| (path, l, format!(":{n}")))
            })
            .unwrap();
        let hold = Arc::new(AtomicBool::new(false));
        let upstream = format!("/tmp/.X11-unix/X{number}");
        let gate = hold.clone();
        std::thread::spawn(move || {
            for client in listener.incoming().flatten() {
                let Ok(server) = UnixStream::connect(&upstream) else {
                    return;
                };
                let (mut c_in, mut s_out) =
                    (client.try_clone().unwrap(), server.try_clone().unwrap());
                std::thread::spawn(move || {
                    let _ = std::io::copy(&mut c_in, &mut s_out);
                });
                let (mut s_in, mut c_out) = (server, client);
                let gate = gate.clone();
                std::thread::spawn(move || {
                    let mut buffer = [0u8; 65536];
                    while let Ok(n) = s_in.read(&mut buffer) {
                        if n == 0 {
                            return;
                        }
                        while gate.load(Ordering::SeqCst) {
                            std::thread::sleep(Duration::from_millis(5));
                        }
                        if c_out.write_all(&buffer[..n]).is_err() {
                            return;
                        }
                    }
                });
            }
        });
        HoldingProxy {
            display,
            hold,
            path,
        }
    }
}

impl Drop for HoldingProxy {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

#[test]
fn a_patch_is_shown_only_once_the_server_has_answered() {
    let x = XServer::start();
    let proxy = HoldingProxy::start(&x.display);
    let mut window = PatchWindow::open(
        &WindowTarget {
            x_display: Some(proxy.display.clone()),
            output: OutputSelector::Primary,
        },
        0.0,
    )
    .unwrap();
    let reader = XDisplay::open(Some(&x.display)).unwrap();
    let output = reader.output(&OutputSelector::Primary).unwrap();
    let done = Arc::new(AtomicBool::new(false));
    proxy.hold.store(true, Ordering::SeqCst);
    let shown = {
        let done = done.clone();
        std::thread::spawn(move || {
            let patch = Patch {
                codes: Codes {
                    rgb: [200, 100, 50],
                    bit_depth: 8,
                },
                background: Codes {
                    rgb: [0; 3],
                    bit_depth: 8,
                },
                geometry: Geometry::centred(0.3),
            };
            runtime().block_on(window.show(&patch)).unwrap();
            done.store(true, Ordering::SeqCst);
            window
        })
    };
    // The server has drawn the patch (its requests went through) ...
    let deadline = Instant::now() + Duration::from_secs(10);
    while reader.sample(&output, (0.5, 0.5)).unwrap().patch != [200, 100, 50] {
        assert!(Instant::now() < deadline, "the server never drew the patch");
        std::thread::sleep(Duration::from_millis(10));
    }
    // ... but its answer to the round trip is held back: the patch is not shown yet.
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        !done.load(Ordering::SeqCst),
        "show returned before the X server's reply came"
    );
    proxy.hold.store(false, Ordering::SeqCst);
    let _window = shown.join().unwrap();
    assert!(done.load(Ordering::SeqCst));
}

/// The rows of a `.cal` file: input, R, G, B.
fn cal_rows(path: &Path) -> Vec<[f64; 4]> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip_while(|l| l.trim() != "BEGIN_DATA")
        .skip(1)
        .take_while(|l| l.trim() != "END_DATA")
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect()
}

/// A profile with calibration curves, from a quick simulated calibration.
fn profile_with_curves(dir: &Path) -> PathBuf {
    let config = dir.join("curves.toml");
    std::fs::write(
        &config,
        "[monitor]\npreset = \"lcd\"\n[target]\nwhite = \"D65\"\ntone = \"gamma:2.4\"\n",
    )
    .unwrap();
    let state = dir.join("curves-state");
    succeed(
        chromacal()
            .args(["calibrate", "--config"])
            .arg(&config)
            .arg("--state-dir")
            .arg(&state),
    );
    state.join("current.toml")
}

#[test]
fn loaded_curves_read_back_in_argyll_dispwin_and_reset_straightens_them() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let profile_path = profile_with_curves(dir.path());
    let profile = Profile::read(&profile_path).unwrap();
    let curves = profile.calibration.unwrap().curves;
    let state = dir.path().join("state");
    let out = succeed(
        chromacal()
            .args(["lut", "load", "--x-display", &x.display, "--state-dir"])
            .arg(&state)
            .arg(&profile_path),
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("DUMMY0"));
    let back = dir.path().join("back.cal");
    x.run("dispwin", &["-d1", "-s", back.to_str().unwrap()]);
    let rows = cal_rows(&back);
    assert_eq!(rows.len(), 256);
    let step = 1.0 / 65535.0;
    for [input, r, g, b] in &rows {
        let want = curves.apply([*input; 3]);
        for (got, want) in [r, g, b].into_iter().zip(want) {
            assert!(
                (got - want).abs() <= step,
                "at {input}: dispwin read {got}, the profile's curve is {want}"
            );
        }
    }
    // Not the straight ramp: the test would pass on nothing otherwise.
    assert!(rows.iter().any(|r| (r[1] - r[0]).abs() > 0.01));
    // `lut save` writes what dispwin reads.
    let saved = dir.path().join("saved.cal");
    succeed(
        chromacal()
            .args(["lut", "save", "--x-display", &x.display, "--state-dir"])
            .arg(&state)
            .arg(&saved),
    );
    for (ours, theirs) in cal_rows(&saved).iter().zip(&rows) {
        for c in 0..4 {
            assert!(
                (ours[c] - theirs[c]).abs() <= 1e-6,
                "{ours:?} vs {theirs:?}"
            );
        }
    }
    let show = succeed(
        chromacal()
            .args([
                "lut",
                "show",
                "--json",
                "--x-display",
                &x.display,
                "--state-dir",
            ])
            .arg(&state),
    );
    let status: serde_json::Value = serde_json::from_slice(&show.stdout).unwrap();
    assert_eq!(status["identity"], false);
    succeed(
        chromacal()
            .args(["lut", "reset", "--x-display", &x.display, "--state-dir"])
            .arg(&state),
    );
    x.run("dispwin", &["-d1", "-s", back.to_str().unwrap()]);
    for [input, r, g, b] in cal_rows(&back) {
        for v in [r, g, b] {
            assert!((v - input).abs() <= step, "reset left {v} at {input}");
        }
    }
}

/// Journal lines of the newest run under `state`.
fn journal_lines(state: &Path) -> usize {
    let Ok(runs) = std::fs::read_dir(state.join("runs")) else {
        return 0;
    };
    runs.flatten()
        .filter_map(|r| std::fs::read_to_string(r.path().join("journal.jsonl")).ok())
        .map(|t| t.lines().count())
        .max()
        .unwrap_or(0)
}

/// The config of the window calibrations: the CRT at 10 bits behind an 8-bit
/// framebuffer (the LUT's output reaches the panel at 10, as `[target] bit_depth`
/// says), no uniformity grid (the emulated instrument is aimed at the centre and stays
/// there), and a target whose curves are measured into place at 10 grey levels.
const WINDOW_CONFIG: &str = "[monitor]\npreset = \"crt\"\nbit_depth = 10\n[plan]\nuniformity_grid = 0\n[display]\nsettle_s = 0.0\n[target]\nwhite = \"D65\"\ntone = \"gamma:2.2\"\nlevels = 10\nbit_depth = 10\n";

#[test]
fn ctrl_c_puts_the_lut_back_and_after_kill_9_any_start_does() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, WINDOW_CONFIG).unwrap();
    // The user's own ramp, bent so that it cannot be mistaken for another.
    let xd = XDisplay::open(Some(&x.display)).unwrap();
    let output = xd.output(&OutputSelector::Primary).unwrap();
    let users = GammaRamp::from_fn(output.gamma_size, |c, v| v.powf(0.8 + 0.1 * c as f64));
    xd.set_gamma(&output, &users).unwrap();
    let emulator = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.05",
        "--x-display",
        &x.display,
        "--config",
        config.to_str().unwrap(),
    ]);
    let state = dir.path().join("state");
    let calibrate = || {
        let mut command = chromacal();
        command
            .args([
                "calibrate",
                "--display",
                "window",
                "--x-display",
                &x.display,
            ])
            .arg("--config")
            .arg(&config)
            .arg("--instrument")
            .arg(format!("pr670:{}", emulator.device))
            .args(["--timing-scale", "0.05", "--state-dir"])
            .arg(&state);
        command
    };
    let start = || {
        calibrate()
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let measuring = |run: &mut std::process::Child, readings: usize| {
        let deadline = Instant::now() + Duration::from_secs(120);
        while journal_lines(&state) < readings {
            assert!(
                Instant::now() < deadline,
                "the calibration took no readings"
            );
            assert!(
                run.try_wait().unwrap().is_none(),
                "the calibration ended early"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    // Ctrl-C: the run stops after the reading under way and puts the user's ramp back.
    let mut run = start();
    measuring(&mut run, 4);
    assert!(xd.gamma(&output).unwrap().is_identity());
    let interrupted = std::process::Command::new("kill")
        .args(["-INT", &run.id().to_string()])
        .status()
        .unwrap();
    assert!(interrupted.success());
    assert_eq!(run.wait().unwrap().code(), Some(130));
    assert!(
        xd.gamma(&output).unwrap().max_difference(&users) <= 1.0,
        "Ctrl-C left the LUT as it was not"
    );
    assert!(!state.join("lut-saved.json").exists());

    // kill -9: nothing runs on the way out.
    let mut run = start();
    measuring(&mut run, journal_lines(&state) + 4);
    // Characterising through the straight ramp, the user's kept in the state directory.
    assert!(xd.gamma(&output).unwrap().is_identity());
    assert!(state.join("lut-saved.json").exists());
    run.kill().unwrap();
    run.wait().unwrap();
    assert!(
        xd.gamma(&output).unwrap().is_identity(),
        "nothing should have put the LUT back yet"
    );
    // Any chromacal that takes the state directory puts it back.
    succeed(
        chromacal()
            .args(["lut", "show", "--x-display", &x.display, "--state-dir"])
            .arg(&state),
    );
    let now = xd.gamma(&output).unwrap();
    assert!(
        now.max_difference(&users) <= 1.0,
        "the user's ramp was not put back"
    );
    assert!(!state.join("lut-saved.json").exists());

    // A ramp saved for another screen that cannot be reached is never loaded onto
    // this one: the run refuses to start and says how to put it back.
    let foreign = serde_json::json!({
        "x_display": ":4998",
        "output": "HDMI-1",
        "ramp": GammaRamp::identity(4),
        "pid": 1
    });
    std::fs::write(state.join("lut-saved.json"), foreign.to_string()).unwrap();
    let refused = calibrate().output().unwrap();
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("HDMI-1 on :4998") && err.contains("not put back yet"),
        "{err}"
    );
    assert!(xd.gamma(&output).unwrap().max_difference(&users) <= 1.0);
    assert!(state.join("lut-saved.json").exists());
}

/// Calibrate with `args` besides the config and state directory; the profile.
fn calibrate(config: &Path, state: &Path, args: &[&str]) -> (Profile, String) {
    let out = succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(config)
            .arg("--state-dir")
            .arg(state)
            .args(args),
    );
    (
        Profile::read(&state.join("current.toml")).unwrap(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

/// `chromacal measure` readings of what the screen shows now.
fn measure(device: &str, count: usize) -> Vec<[f64; 3]> {
    let out = succeed(chromacal().args([
        "measure",
        "--instrument",
        &format!("pr670:{device}"),
        "--timing-scale",
        "0.002",
        "--count",
        &count.to_string(),
        "--json",
    ]));
    let readings: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    readings
        .iter()
        .map(|r| {
            let xyz = &r["xyz"];
            [0, 1, 2].map(|i| xyz[i].as_f64().unwrap())
        })
        .collect()
}

fn de00(a: [f64; 3], b: [f64; 3], white: [f64; 3]) -> f64 {
    use chromacal_color::Xyz;
    use chromacal_color::difference::delta_e_2000;
    use chromacal_color::spaces::xyz_to_lab;
    let white = Xyz::new(white[0], white[1], white[2]);
    let lab = |v: [f64; 3]| xyz_to_lab(&Xyz::new(v[0], v[1], v[2]), &white);
    delta_e_2000(&lab(a), &lab(b))
}

#[test]
fn a_calibration_in_the_window_matches_the_emulator_screen_and_verifies_through_the_lut() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, WINDOW_CONFIG).unwrap();
    let config_arg = config.to_str().unwrap();

    // The same monitor over the emulator's screen socket.
    let socket_emulator = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--config",
        config_arg,
    ]);
    let (reference, _) = calibrate(
        &config,
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

    // Through the window, an X server and an emulator looking at it; the output
    // carries a wide-gamut monitor's EDID, which the CRT is not.
    let xd = XDisplay::open(Some(&x.display)).unwrap();
    let output = xd.output(&OutputSelector::Primary).unwrap();
    xd.set_edid(
        output.id,
        &std::fs::read(common::fixture("edid/wide_gamut_1440p.bin")).unwrap(),
    )
    .unwrap();
    let emulator = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--config",
        config_arg,
        "--x-display",
        &x.display,
    ]);
    let state = dir.path().join("window");
    let (profile, summary) = calibrate(
        &config,
        &state,
        &[
            "--display",
            "window",
            "--x-display",
            &x.display,
            "--instrument",
            &format!("pr670:{}", emulator.device),
            "--timing-scale",
            "0.002",
        ],
    );
    eprintln!("{summary}");
    assert!(
        profile
            .provenance
            .display
            .as_deref()
            .unwrap()
            .contains("window on DUMMY0")
    );
    // The EDID's Adobe RGB green is far from the CRT's: said at once, and kept.
    assert_eq!(
        profile.provenance.edid.as_ref().unwrap().manufacturer,
        "EIZ"
    );
    assert!(
        summary.contains("is this the display you meant?"),
        "{summary}"
    );
    let shown = succeed(
        chromacal()
            .args(["profile", "show"])
            .arg(state.join("current.toml")),
    );
    let shown = String::from_utf8_lossy(&shown.stdout);
    assert!(
        shown.contains("monitor (EDID): EIZ CS2740 (serial 23150512, week 40 of 2019)"),
        "{shown}"
    );
    assert!(shown.contains("is this the display you meant?"));
    let page = succeed(
        chromacal()
            .arg("report")
            .arg(state.join("current.toml"))
            .args(["-o", "-"]),
    );
    let page = String::from_utf8_lossy(&page.stdout);
    assert!(page.contains("What the monitor's EDID states") && page.contains("0.2100, 0.7100"));
    common::assert_same_model("window", &profile, &reference);
    let (held, reference_held) = (
        profile.report.held_out.unwrap(),
        reference.report.held_out.unwrap(),
    );
    eprintln!("held-out through the window {held:?}, through the socket {reference_held:?}");
    assert!(
        (held.mean - reference_held.mean).abs() < 0.1 && held.mean < 0.3,
        "{held:?} vs {reference_held:?}"
    );

    // The check was measured through the curves in the video LUT.
    let calibration = profile.calibration.as_ref().unwrap();
    assert!(calibration.through_lut);
    assert!(
        summary.contains("through the curves loaded in the video LUT"),
        "{summary}"
    );
    assert_eq!(
        calibration.levels.len(),
        9,
        "10 grey levels, black included"
    );
    assert!(
        calibration.measured_tone_error < 0.01,
        "tone off by {:.2} %",
        100.0 * calibration.measured_tone_error
    );
    let status = succeed(
        chromacal()
            .args([
                "lut",
                "show",
                "--json",
                "--x-display",
                &x.display,
                "--state-dir",
            ])
            .arg(&state),
    );
    let status: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    assert!(
        status["from_profile_steps"].as_f64().unwrap() <= 1.0,
        "{status}"
    );

    // The white hits the target within the instrument's repeatability: the white
    // read again through the LUT, eight times, scatters about as far as it lies
    // from the target.
    let mut window = window_on(&x);
    let white_patch = Patch {
        codes: Codes {
            rgb: [255; 3],
            bit_depth: 8,
        },
        background: Codes {
            rgb: [0; 3],
            bit_depth: 8,
        },
        geometry: Geometry::centred(0.2),
    };
    runtime().block_on(window.show(&white_patch)).unwrap();
    let whites = measure(&emulator.device, 8);
    assert_eq!(whites.len(), 8);
    let mean = [0, 1, 2].map(|c| whites.iter().map(|w| w[c]).sum::<f64>() / 8.0);
    let target = calibration.curves.white;
    let spread = (whites
        .iter()
        .map(|w| de00(*w, mean, target).powi(2))
        .sum::<f64>()
        / 7.0)
        .sqrt();
    let off = de00(mean, target, target);
    eprintln!(
        "white through the LUT: {off:.3} ΔE00 from the target (check: {:.3}); one reading's repeatability {spread:.3}",
        calibration.measured_white_de00
    );
    assert!(
        off <= 3.0 * spread && calibration.measured_white_de00 <= 3.0 * spread,
        "white {off:.3} (check {:.3}) ΔE00 from the target, repeatability {spread:.3}",
        calibration.measured_white_de00
    );
    // The emulator sees the LUT: with it straightened, the same code reads the
    // monitor's native white, well away from D65.
    succeed(
        chromacal()
            .args(["lut", "reset", "--x-display", &x.display, "--state-dir"])
            .arg(&state),
    );
    let native = measure(&emulator.device, 2);
    let native_off = de00(native[0], target, target);
    assert!(
        native_off > off + 1.0,
        "native white {native_off:.3}, calibrated {off:.3}"
    );
    drop(window);
}

/// Where the driver gives an output no EDID (XWayland, some drivers), the kernel's
/// DRM connector of the same name has it: a directory laid out as sysfs
/// (`class/drm/card0-NAME/edid`, chosen by `CHROMACAL_SYSFS_ROOT`) names the monitor,
/// says where its EDID came from, and lets a device find its output by the serial.
/// A connector with an empty file (nothing plugged in) and one of another name are
/// passed over.
#[test]
fn an_output_without_an_edid_takes_its_connector_s_from_the_kernel() {
    let x = XServer::start();
    let xd = XDisplay::open(Some(&x.display)).unwrap();
    let output = xd.output(&OutputSelector::Primary).unwrap();
    assert!(output.edid.is_none() || output.edid_source.is_some());
    let dir = tempfile::tempdir().unwrap();
    let sysfs = dir.path().join("sys");
    let bytes = std::fs::read(common::fixture("edid/srgb_office_1080p.bin")).unwrap();
    for (connector, edid) in [
        (output.name.as_str(), &bytes[..]),
        ("HDMI-A-7", &[][..]),
        ("DP-9", &bytes[..]),
    ] {
        let at = sysfs.join(format!("class/drm/card0-{connector}"));
        std::fs::create_dir_all(&at).unwrap();
        std::fs::write(at.join("edid"), edid).unwrap();
    }
    std::fs::create_dir_all(sysfs.join("class/drm/card0")).unwrap();
    let run = |args: &[&str]| {
        let mut c = chromacal();
        c.env("CHROMACAL_SYSFS_ROOT", &sysfs)
            .args(args)
            .args(["--x-display", &x.display, "--state-dir"])
            .arg(dir.path().join("state"));
        String::from_utf8_lossy(&succeed(&mut c).stdout).into_owned()
    };
    let text = run(&["displays"]);
    let kernel_file = sysfs.join(format!("class/drm/card0-{}/edid", output.name));
    assert!(
        text.contains("monitor: DEL DELL U2415 (serial 7MT0186J1T3L, week 12 of 2016)"),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "EDID from the kernel: {} (the driver gave none)",
            kernel_file.display()
        )),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_str(&run(&["displays", "--json"])).unwrap();
    let first = &json.as_array().unwrap()[0];
    assert_eq!(first["edid_source"], kernel_file.display().to_string());
    assert_eq!(first["edid"]["serial_text"], "7MT0186J1T3L");
    // Disconnected outputs take nothing, whatever the files say.
    assert!(json.as_array().unwrap()[1]["edid"].is_null());
    // The serial finds the output through the kernel's EDID.
    let show = run(&["lut", "show", "--output", "edid_serial=7MT0186J1T3L"]);
    assert!(
        show.contains(&format!("video LUT of {}", output.name)),
        "{show}"
    );
    // Without the directory, no EDID.
    let mut bare = chromacal();
    bare.env("CHROMACAL_SYSFS_ROOT", dir.path().join("nowhere"))
        .args(["displays", "--x-display", &x.display, "--state-dir"])
        .arg(dir.path().join("state"));
    let text = String::from_utf8_lossy(&succeed(&mut bare).stdout).into_owned();
    assert!(text.contains("EDID: none"), "{text}");
}

#[test]
fn displays_name_the_outputs_their_monitors_and_the_device_on_each() {
    let x = XServer::start();
    let xd = XDisplay::open(Some(&x.display)).unwrap();
    let output = xd.output(&OutputSelector::Primary).unwrap();
    xd.set_edid(
        output.id,
        &std::fs::read(common::fixture("edid/srgb_office_1080p.bin")).unwrap(),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    // The device finds its monitor by the serial in its EDID, whatever the connector.
    std::fs::write(
        &config,
        "[instrument]\ndriver = \"pr670\"\nport = \"/dev/null\"\n[display]\nsink = \"window\"\noutput = { edid_serial = \"7MT0186J1T3L\" }\n",
    )
    .unwrap();
    let args = |json: bool| {
        let mut c = chromacal();
        c.args(["displays", "--x-display", &x.display, "--config"])
            .arg(&config)
            .arg("--state-dir")
            .arg(dir.path().join("state"));
        if json {
            c.arg("--json");
        }
        c
    };
    let text = String::from_utf8_lossy(&succeed(&mut args(false)).stdout).into_owned();
    assert!(
        text.contains("DUMMY0 (primary)  1024×768+0+0 at 60.00 Hz"),
        "{text}"
    );
    assert!(
        text.contains("monitor: DEL DELL U2415 (serial 7MT0186J1T3L, week 12 of 2016)"),
        "{text}"
    );
    assert!(text.contains("device default: no profile yet"), "{text}");
    // Outputs with nothing on them share one line.
    assert!(text.contains("  disconnected: DUMMY1, DUMMY2, "), "{text}");
    assert!(!text.contains("DUMMY1  disconnected"), "{text}");
    // A server that nobody has loaded a LUT into holds its own straight ramp (the
    // code shifted up, i << 8, whose top is 255 steps short of full): not curves.
    assert!(
        text.contains("256 entries, straight") && !text.contains("curves loaded"),
        "{text}"
    );
    let json: serde_json::Value = serde_json::from_slice(&succeed(&mut args(true)).stdout).unwrap();
    let outputs = json.as_array().unwrap();
    assert_eq!(outputs[0]["name"], "DUMMY0");
    assert_eq!(outputs[0]["gamma_size"], 256);
    assert_eq!(outputs[0]["edid"]["manufacturer"], "DEL");
    assert_eq!(outputs[0]["devices"][0]["name"], "default");
    assert!(outputs[1]["edid"].is_null() && outputs[1]["devices"].as_array().unwrap().is_empty());
    // The id colord knows each by, as GNOME registers it (the maker by its PNP name
    // where hwdata's pnp.ids is installed, else by its three letters).
    let id = outputs[0]["colord_device_id"].as_str().unwrap();
    assert!(
        id.starts_with("xrandr-") && id.ends_with("-DELL U2415-7MT0186J1T3L"),
        "{id}"
    );
    assert!(text.contains(&format!("colord device: {id}")), "{text}");
    assert_eq!(outputs[1]["colord_device_id"], "xrandr-DUMMY1");
    // The LUT commands take the serial too; an unknown one names what there is.
    let show = succeed(chromacal().args([
        "lut",
        "show",
        "--x-display",
        &x.display,
        "--output",
        "edid_serial=7MT0186J1T3L",
        "--state-dir",
        dir.path().join("state").to_str().unwrap(),
    ]));
    assert!(String::from_utf8_lossy(&show.stdout).contains("video LUT of DUMMY0"));
    // A desktop that loads curves itself (GNOME's colour plugin) is named, so that the
    // user does not fight it.
    let fake = dir.path().join("gsd-color");
    std::fs::copy("/bin/sleep", &fake).unwrap();
    let mut loader = std::process::Command::new(&fake).arg("60").spawn().unwrap();
    let show = chromacal()
        .args(["lut", "show", "--x-display", &x.display, "--state-dir"])
        .arg(dir.path().join("state"))
        .output()
        .unwrap();
    let _ = loader.kill();
    let _ = loader.wait();
    assert!(
        String::from_utf8_lossy(&show.stdout).contains("GNOME's colour plugin (gsd-color"),
        "{}",
        String::from_utf8_lossy(&show.stdout)
    );
    let unknown = chromacal()
        .args([
            "lut",
            "show",
            "--x-display",
            &x.display,
            "--output",
            "HDMI-9",
            "--state-dir",
        ])
        .arg(dir.path().join("state"))
        .output()
        .unwrap();
    assert!(!unknown.status.success());
    let err = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        err.contains("no output named 'HDMI-9'") && err.contains("DUMMY0"),
        "{err}"
    );
    // No X server at all: a clear error, not a panic.
    let none = chromacal()
        .args(["displays", "--x-display", ":4999"])
        .output()
        .unwrap();
    assert_eq!(none.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&none.stderr).contains("cannot open the X display ':4999'"));
}

/// `chromacal verify` with the emulator looking at the X screen, through the LUT as
/// it is: `args` besides the config, state and devices; exit code and JSON.
fn verify_window(
    x: &XServer,
    config: &Path,
    state: &Path,
    device: &str,
    args: &[&str],
) -> (Option<i32>, serde_json::Value) {
    let out = chromacal()
        .arg("verify")
        .arg("--config")
        .arg(config)
        .arg("--state-dir")
        .arg(state)
        .args(["--display", "window", "--x-display", &x.display])
        .args([
            "--instrument",
            &format!("pr670:{device}"),
            "--timing-scale",
            "0.002",
        ])
        .arg("--json")
        .args(args)
        .output()
        .unwrap();
    let json = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    (out.status.code(), json)
}

/// The verdict of each criterion, by statistic.
fn verdicts(report: &serde_json::Value) -> Vec<(String, String)> {
    report["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["statistic"].as_str().unwrap().to_string(),
                r["verdict"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

/// The desk flow's end: calibrated in the window to D65, gamma 2.2 and 80 cd/m² (the
/// CRT's own white is near 8300 K at 100), `verify --against srgb` measures the chart
/// through the curves in the LUT and passes DisplayCAL's recommended set with the
/// white within the instrument's repeatability of D65 and of 80 cd/m²; a ramp set
/// from outside (`xrandr --gamma`) fails it on the white and the greys, and a
/// straight LUT on the tone curve.
#[test]
fn the_calibrated_window_verifies_through_the_lut_and_a_foreign_ramp_fails() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, format!("{WINDOW_CONFIG}luminance = 80.0\n")).unwrap();
    let emulator = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--config",
        config.to_str().unwrap(),
        "--x-display",
        &x.display,
    ]);
    let state = dir.path().join("state");
    let (_, summary) = calibrate(
        &config,
        &state,
        &[
            "--display",
            "window",
            "--x-display",
            &x.display,
            "--instrument",
            &format!("pr670:{}", emulator.device),
            "--timing-scale",
            "0.002",
        ],
    );
    assert!(summary.contains("verified against sRGB"), "{summary}");
    let (code, report) = verify_window(
        &x,
        &config,
        &state,
        &emulator.device,
        &["--against", "srgb", "--criteria", "displaycal-recommended"],
    );
    eprintln!("{:?}", verdicts(&report));
    let s = &report["state"];
    eprintln!(
        "through the LUT: white {} cd/m² at {:?}, {} from D65 {:?}; grey balance {} over {} greys",
        s["luminance"],
        s["xy"],
        s["white_delta_e"],
        s["white_interval"],
        s["grey_balance_mean"],
        s["greys"].as_array().unwrap().len()
    );
    assert_eq!(code, Some(0), "{:?}", verdicts(&report));
    let patches = report["patches"].as_array().unwrap();
    assert!(patches.len() >= 40);
    assert!(
        patches
            .iter()
            .all(|p| p["interval"].as_array().is_some_and(|i| i.len() == 2))
    );
    // D65 within the repeatability: the white's interval reaches the target.
    assert_eq!(s["white_interval"][0].as_f64().unwrap(), 0.0, "{s}");
    let noise = &report["noise"];
    let sigma = noise["floor"]
        .as_f64()
        .unwrap()
        .hypot(noise["relative"].as_f64().unwrap() * 80.0);
    let luminance = s["luminance"].as_f64().unwrap();
    assert!(
        (luminance - 80.0).abs() <= 3.0 * sigma,
        "{luminance} cd/m², σ {sigma}"
    );
    assert!(s["greys"].as_array().unwrap().len() >= 17);
    assert!(s["grey_balance_mean"].as_f64().unwrap() <= 0.5, "{s}");

    // A ramp from outside replaces the curves: the white and the greys move.
    x.run("xrandr", &["--output", "DUMMY0", "--gamma", "1.2:1:1"]);
    let (code, report) = verify_window(&x, &config, &state, &emulator.device, &[]);
    let failed: Vec<String> = verdicts(&report)
        .into_iter()
        .filter(|(_, v)| v == "fail")
        .map(|(s, _)| s)
        .collect();
    eprintln!("with xrandr --gamma 1.2:1:1: {failed:?}");
    assert_eq!(code, Some(5));
    assert!(
        failed.iter().any(|s| s == "white-to-target")
            && failed.iter().any(|s| s.starts_with("grey-balance")),
        "{failed:?}"
    );
    // A straight LUT: the tone curve is the native one.
    succeed(
        chromacal()
            .args(["lut", "reset", "--x-display", &x.display, "--state-dir"])
            .arg(&state),
    );
    let (code, report) = verify_window(&x, &config, &state, &emulator.device, &[]);
    let failed: Vec<String> = verdicts(&report)
        .into_iter()
        .filter(|(_, v)| v == "fail")
        .map(|(s, _)| s)
        .collect();
    eprintln!("with the LUT straight: {failed:?}");
    assert_eq!(code, Some(5));
    assert!(failed.iter().any(|s| s == "tone"), "{failed:?}");
}

/// How far (16-bit steps) the LUT of DUMMY0 on `x` is from `profile`'s curves.
fn lut_distance(x: &XServer, profile: &Path) -> f64 {
    let curves = Profile::read(profile).unwrap().calibration.unwrap().curves;
    let display = XDisplay::open(Some(&x.display)).unwrap();
    let output = display.output(&OutputSelector::default()).unwrap();
    let ramp = display.gamma(&output).unwrap();
    ramp.max_difference(&GammaRamp::from_curves(&curves, ramp.len()))
}

/// The next line the keeper prints that contains `what`, within 20 s.
fn keeper_says(lines: &std::sync::mpsc::Receiver<String>, what: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) if line.contains(what) => return line,
            Ok(_) => {}
            Err(e) => panic!("the keeper never said '{what}': {e}"),
        }
    }
}

#[test]
fn the_keeper_at_login_loads_the_curves_and_again_after_a_mode_change_or_a_new_profile() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let first = profile_with_curves(dir.path());
    let state = dir.path().join("state");
    std::fs::create_dir_all(&state).unwrap();
    std::fs::copy(&first, state.join("current.toml")).unwrap();
    // What the user service and the autostart entry run.
    let mut keeper = chromacal()
        .args([
            "lut",
            "load",
            "--current",
            "--watch",
            "--x-display",
            &x.display,
            "--state-dir",
        ])
        .arg(&state)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = keeper.stdout.take().unwrap();
    let (send, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            let _ = send.send(line);
        }
    });
    let said = keeper_says(&lines, "loaded the curves");
    assert!(
        said.contains("DUMMY0") && said.contains("(start)"),
        "{said}"
    );
    assert!(lut_distance(&x, &first) <= 1.0);

    // Installed both ways, the second keeper sees the first and leaves quietly.
    let second = chromacal()
        .args([
            "lut",
            "load",
            "--current",
            "--watch",
            "--x-display",
            &x.display,
            "--state-dir",
        ])
        .arg(&state)
        .output()
        .unwrap();
    assert!(second.status.success());
    assert!(
        String::from_utf8_lossy(&second.stderr).contains("another chromacal keeps the video LUT"),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );

    // Something else sets a ramp (no RandR event: left alone), then the mode
    // changes: the curves are loaded again.
    x.run("xrandr", &["--output", "DUMMY0", "--gamma", "1.2:1:1"]);
    assert!(lut_distance(&x, &first) > 100.0);
    x.run("xrandr", &["--output", "DUMMY0", "--mode", "800x600"]);
    keeper_says(&lines, "the X screen changed");
    assert!(lut_distance(&x, &first) <= 1.0);

    // A new profile made current (here: one with other curves) is loaded.
    let other_dir = dir.path().join("other");
    std::fs::create_dir_all(&other_dir).unwrap();
    let config = other_dir.join("curves.toml");
    std::fs::write(
        &config,
        "[monitor]\npreset = \"lcd\"\n[target]\nwhite = \"6000K\"\ntone = \"gamma:2.0\"\n",
    )
    .unwrap();
    succeed(
        chromacal()
            .args(["calibrate", "--config"])
            .arg(&config)
            .arg("--state-dir")
            .arg(&other_dir),
    );
    let second_profile = other_dir.join("current.toml");
    assert!(lut_distance(&x, &second_profile) > 100.0);
    std::fs::copy(&second_profile, state.join("current.toml")).unwrap();
    keeper_says(&lines, "a new profile is current");
    assert!(lut_distance(&x, &second_profile) <= 1.0);
    let _ = keeper.kill();
    let _ = keeper.wait();
}

/// Two stumbles of a first run: a mistyped output is named as such (it read "the
/// display is gone"), and a plan deeper than the window paints is refused before a
/// run exists (it left an empty run whose --resume could never work).
#[test]
fn a_mistyped_output_and_a_plan_too_deep_are_refused_before_any_run() {
    let x = XServer::start();
    let dir = tempfile::tempdir().unwrap();
    let emulator = emulate(&[
        "--instrument",
        "pr670",
        "--time-scale",
        "0.002",
        "--x-display",
        &x.display,
    ]);
    let state = dir.path().join("state");
    let attempt = |config_text: &str, display: &str| {
        let config = dir.path().join("config.toml");
        std::fs::write(&config, config_text).unwrap();
        let out = chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(&state)
            .args(["--display", display, "--x-display", &x.display])
            .args(["--instrument", &format!("pr670:{}", emulator.device)])
            .args(["--timing-scale", "0.002"])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = attempt("[plan]\nuniformity_grid = 0\n", "window:HDMI-9");
    assert!(
        err.contains("no output named 'HDMI-9'") && err.contains("DUMMY0"),
        "{err}"
    );
    assert!(!err.contains("gone"), "{err}");
    let err = attempt("[plan]\nuniformity_grid = 0\nbit_depth = 10\n", "window");
    assert!(err.contains("set plan.bit_depth = 8"), "{err}");
    assert!(!err.contains("--resume"), "{err}");
    // An HDR plan on the 24-bit visual: refused for what it is, not told to drop bits.
    let hdr =
        "[plan]\nuniformity_grid = 0\nbit_depth = 10\n[target]\ntone = \"pq\"\nwhite = \"D65\"\n";
    let err = attempt(hdr, "window");
    assert!(err.contains("PQ") && err.contains("depth 30"), "{err}");
    let runs = state.join("runs");
    assert!(
        !runs.exists() || std::fs::read_dir(&runs).unwrap().count() == 0,
        "a run was left"
    );
}
