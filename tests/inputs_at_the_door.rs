//! Issue 12, item 6: every input is checked where it comes in, with a message that
//! names it, an exit code that says failure, and no panic, hang or runaway read.
//! Each case is one of the reproductions, run through the real command.

use std::path::Path;
use std::time::{Duration, Instant};

mod common;
use common::chromacal;

/// `dir/state` with the simulated default calibrated into it (within two minutes).
fn calibrated(dir: &std::path::Path) -> std::path::PathBuf {
    let state = dir.join("state");
    let (code, _, stderr) = run(
        &["calibrate", "--state-dir", state.to_str().unwrap()],
        Duration::from_secs(120),
    );
    assert_eq!(code, Some(0), "{stderr}");
    state
}

/// Run `chromacal args…` with a time limit; (exit code, stdout, stderr).
fn run(args: &[&str], limit: Duration) -> (Option<i32>, String, String) {
    let mut child = chromacal()
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            panic!("chromacal {args:?} ran past {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

#[test]
fn config_values_out_of_range_are_refused_before_anything_is_measured() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("state");
    let cases = [
        (
            "[plan]\nstrategy = \"fixed\"\nbudget = 9223372036854775807\n",
            "plan.budget",
        ),
        (
            "[plan]\nverification = 9223372036854775807\n",
            "plan.verification",
        ),
        ("[plan]\nuniformity_grid = 1000\n", "plan.uniformity_grid"),
        (
            "[instrument.simulated]\nintegration_s = nan\n",
            "integration_s = NaN",
        ),
        (
            "[instrument.simulated]\nmax_integration_s = nan\n",
            "max_integration_s = NaN",
        ),
        (
            "[instrument.simulated]\nrelative_noise = -0.1\n",
            "relative_noise",
        ),
        (
            "[instrument.simulated]\noverload_limit = -5.0\n",
            "overload_limit",
        ),
        (
            "[display.stability]\ntolerance = 0.0\nmax_reads = 1000000000\n",
            "max_reads",
        ),
        (
            "[fit]\nmax_condition_number = 0.0\n",
            "max_condition_number",
        ),
        (
            "[monitor]\nwhite_luminance = 10.0\nblack_luminance = 20.0\n",
            "black_luminance = 20 is not below",
        ),
        (
            "[monitor]\npreset = \"crt\"\nprimaries_csv = \"/dev/zero\"\n",
            "/dev/zero",
        ),
    ];
    for (text, named) in cases {
        let config = write(dir.path(), "c.toml", text);
        let (code, stdout, stderr) = run(
            &[
                "calibrate",
                "--config",
                &config,
                "--state-dir",
                state.to_str().unwrap(),
            ],
            Duration::from_secs(30),
        );
        assert!(
            code.is_some_and(|c| c != 0 && c != 101),
            "{text}: exit {code:?}\n{stderr}"
        );
        assert!(stderr.contains(named), "{text}: {stderr}");
        assert!(!stdout.contains("published"), "{text}: {stdout}");
    }
    // Nothing was measured: no run was started.
    let runs = state.join("runs");
    assert!(
        !runs.exists() || std::fs::read_dir(&runs).unwrap().next().is_none(),
        "a refused config left a run behind"
    );
}

#[test]
fn a_profile_with_a_runaway_degree_or_a_nan_is_refused_when_read() {
    let dir = tempfile::tempdir().unwrap();
    let state = calibrated(dir.path());
    let good = std::fs::read_to_string(state.join("current.toml")).unwrap();
    assert!(
        good.contains("degree = "),
        "the default run fits a spatial map"
    );

    // A degree of 2^32 − 1 once hung `profile show`, `check` and the exports.
    let mut degree = String::new();
    for line in good.lines() {
        if line.trim_start().starts_with("degree = ") {
            degree.push_str("degree = 4294967295\n");
        } else {
            degree.push_str(line);
            degree.push('\n');
        }
    }
    let degree = write(dir.path(), "degree.toml", &degree);
    // A coefficient that is not a number.
    let nan = good.replacen("coefficients = [", "coefficients = [nan, ", 1);
    let nan = write(dir.path(), "nan.toml", &nan);
    // A surface coefficient that is finite but makes every prediction infinite.
    let huge = good.replacen("coefficients = [", "coefficients = [1e308, ", 1);
    let huge = {
        // Keep the count: the coefficient put first replaces the one that was.
        let at = huge.find("coefficients = [1e308, ").unwrap() + "coefficients = [1e308, ".len();
        let next = huge[at..].find(", ").map(|i| at + i + 2).unwrap();
        format!("{}{}", &huge[..at], &huge[next..])
    };
    let huge = write(dir.path(), "huge.toml", &huge);
    // A figure of the report that is not a number.
    let report_nan = good.replacen("mean = ", "mean = nan # was ", 1);
    let report_nan = write(dir.path(), "report-nan.toml", &report_nan);
    for (file, named) in [
        (&degree, "degree 4294967295"),
        (&nan, "not a finite number"),
        (&huge, "a surface coefficient of 1e308"),
        (&report_nan, "not a finite number"),
    ] {
        for args in [
            vec!["profile", "show", file.as_str()],
            vec![
                "export",
                file.as_str(),
                "--format",
                "cal",
                "-o",
                "/dev/null",
            ],
        ] {
            let (code, stdout, stderr) = run(&args, Duration::from_secs(10));
            assert!(
                code.is_some_and(|c| c != 0 && c != 101),
                "{args:?}: exit {code:?}: {stderr}"
            );
            assert!(stderr.contains(named), "{args:?}: {stderr}");
            assert!(!stdout.contains("NaN"), "{args:?}: {stdout}");
        }
    }
}

#[test]
fn outputs_are_never_nan_with_success() {
    let dir = tempfile::tempdir().unwrap();
    let spectra = write(
        dir.path(),
        "s.csv",
        "wavelength_nm,lamp,dark\n400,0.5,0\n500,1,0\n550,2,0\n600,1,0\n700,0.5,0\n",
    );
    // A reference white of Y = 0 makes L*a*b* infinite: refused.
    let (code, stdout, stderr) = run(
        &["spectrum", &spectra, "--white-y", "0"],
        Duration::from_secs(10),
    );
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(stderr.contains("--white-y"), "{stderr}");
    // A sample with no light has no chromaticity: it says so.
    let (code, stdout, stderr) = run(&["spectrum", &spectra], Duration::from_secs(10));
    assert_eq!(code, Some(0), "{stderr}");
    let dark = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("dark"))
        .unwrap();
    assert!(dark.contains("undefined"), "{dark}");
    assert!(
        !stdout.contains("NaN") && !stdout.contains("inf"),
        "{stdout}"
    );
    let (_, json, _) = run(&["spectrum", &spectra, "--json"], Duration::from_secs(10));
    let json: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(json[1]["x"].is_null(), "{json}");
    // Nothing but darkness: L*a*b* has no white.
    let dark_only = write(
        dir.path(),
        "d.csv",
        "wavelength_nm,dark\n400,0\n550,0\n700,0\n",
    );
    let (code, _, stderr) = run(&["spectrum", &dark_only], Duration::from_secs(10));
    assert_eq!(code, Some(1));
    assert!(stderr.contains("no sample has any light"), "{stderr}");

    // `check` against a file with a reading out of all range names it.
    let ti3 = common::shared_text("measurements/macbookpro15_2014_colormunki_spectral_57.ti3");
    let (_, _, stderr) = run(
        &[
            "fit",
            common::shared_path("measurements/macbookpro15_2014_colormunki_spectral_57.ti3")
                .to_str()
                .unwrap(),
            "-o",
            dir.path().join("mac.toml").to_str().unwrap(),
        ],
        Duration::from_secs(60),
    );
    assert!(dir.path().join("mac.toml").exists(), "{stderr}");
    let white = "1 100.0000000 100.0000000 100.0000000 95.07730000 100.0000000 109.9800000";
    assert!(ti3.contains(white));
    let huge = write(
        dir.path(),
        "huge.ti3",
        &ti3.replacen(
            white,
            "1 100.0000000 100.0000000 100.0000000 1e300 1e300 1e300",
            1,
        ),
    );
    let (code, stdout, stderr) = run(
        &[
            "check",
            dir.path().join("mac.toml").to_str().unwrap(),
            &huge,
        ],
        Duration::from_secs(30),
    );
    assert_eq!(code, Some(1), "{stdout}");
    assert!(stderr.contains("patch 0"), "{stderr}");
    assert!(!stdout.contains("NaN"), "{stdout}");
    // `fit` on it names the reading, not a NaN found later in what it made (it
    // used to fit, then fail to save a profile whose held-out mean was NaN).
    let (code, stdout, stderr) = run(
        &[
            "fit",
            &huge,
            "-o",
            dir.path().join("huge.toml").to_str().unwrap(),
        ],
        Duration::from_secs(60),
    );
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains("patch 0") && stderr.contains("beyond what any display emits"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("NaN") && !stderr.contains("not a finite"),
        "{stderr}"
    );
    assert!(!dir.path().join("huge.toml").exists());
    // One that overflows when scaled to cd/m² is named at the line it is on.
    let overflow = write(
        dir.path(),
        "overflow.ti3",
        &ti3.replacen(
            white,
            "1 100.0000000 100.0000000 100.0000000 1e308 1e308 1e308",
            1,
        ),
    );
    let (code, _, stderr) = run(
        &[
            "check",
            dir.path().join("mac.toml").to_str().unwrap(),
            &overflow,
        ],
        Duration::from_secs(30),
    );
    assert_eq!(code, Some(1));
    assert!(
        stderr.contains("overflows when scaled to cd/m²"),
        "{stderr}"
    );
}

/// A FIFO given as an input file: opening it would wait for a writer for ever. Each
/// command says it is not a regular file, naming it, and exits at once.
#[test]
fn a_fifo_given_as_an_input_is_refused_not_waited_on() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = |name: &str| {
        let path = dir.path().join(name);
        let made = std::process::Command::new("mkfifo")
            .arg(&path)
            .status()
            .unwrap();
        assert!(made.success());
        path.display().to_string()
    };
    let (ti3, exr, toml) = (fifo("run.ti3"), fifo("scene.exr"), fifo("config.toml"));
    let profile = dir.path().join("p.toml").display().to_string();
    let fixture = common::fixture("ti3/crt-default.ti3").display().to_string();
    let (code, _, stderr) = run(&["fit", &fixture, "-o", &profile], Duration::from_secs(60));
    assert_eq!(code, Some(0), "{stderr}");
    let out = dir.path().join("out.png").display().to_string();
    for args in [
        vec!["fit", ti3.as_str(), "-o", "/dev/null"],
        vec!["check", profile.as_str(), ti3.as_str()],
        vec![
            "render",
            profile.as_str(),
            "--image",
            exr.as_str(),
            "-o",
            out.as_str(),
        ],
        vec!["config", "show", "--config", toml.as_str()],
        vec!["report", ti3.as_str(), "-o", out.as_str()],
    ] {
        let (code, _, stderr) = run(&args, Duration::from_secs(20));
        assert_eq!(code, Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains("not a regular file") && stderr.contains("FIFO"),
            "{args:?}: {stderr}"
        );
    }
}

/// Issue 28, item 7: numbers of the command line that would be printed back as NaN or
/// infinity with success (`render --display-contrast inf` gave "mean NaN, max -inf",
/// exit 0) are refused by clap, naming the argument (exit 2).
#[test]
fn command_line_numbers_that_make_nan_or_infinity_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "x.csv", "X,Y,Z\n20,20,20\n");
    let profile = dir.path().join("crt.toml");
    let (code, _, stderr) = run(
        &[
            "fit",
            common::fixture("ti3/crt-default.ti3").to_str().unwrap(),
            "-o",
            profile.to_str().unwrap(),
        ],
        Duration::from_secs(120),
    );
    assert_eq!(code, Some(0), "{stderr}");
    let profile = profile.to_str().unwrap();
    let render = |extra: &[&str]| {
        let mut args = vec!["render", profile, "--xyz", &scene, "-o", "-"];
        args.extend_from_slice(extra);
        run(&args, Duration::from_secs(30))
    };
    for (argument, value) in [
        ("--display-contrast", "inf"),
        ("--display-contrast", "nan"),
        ("--display-contrast", "-1"),
        ("--display-contrast", "1"),
        ("--white-luminance", "1e308"),
        ("--white-luminance", "0"),
        ("--scb-outside", "2"),
        ("--max-de00", "NaN"),
    ] {
        let pair = format!("{argument}={value}");
        let (code, stdout, stderr) = render(&["--tone", "tumblin-rushmeier", &pair]);
        assert_eq!(code, Some(2), "{pair}: {stdout}{stderr}");
        assert!(stderr.contains(argument), "{pair}: {stderr}");
        assert!(stdout.is_empty(), "{pair}: {stdout}");
    }
    // The same scene with sane numbers renders, and prints no NaN.
    let (code, stdout, stderr) =
        render(&["--tone", "tumblin-rushmeier", "--display-contrast", "50"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stdout.contains("NaN") && !stderr.contains("NaN") && !stderr.contains("inf"));
    for args in [
        ["daemon", "--time-scale", "inf"],
        ["emulate", "--time-scale=-0.5", "--instrument=pr670"],
    ] {
        let (code, _, stderr) = run(&args, Duration::from_secs(10));
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains("--time-scale"), "{args:?}: {stderr}");
    }
}

/// Scene and spectrum values beyond any light (1e300: a unit or exponent gone wrong)
/// are refused with the row named, not carried to "mean NaN, max -inf" or a Y of
/// 3e302 cd/m² with success.
#[test]
fn scene_and_spectrum_values_beyond_any_light_are_refused_with_their_row() {
    let dir = tempfile::tempdir().unwrap();
    let state = calibrated(dir.path());
    let profile = state.join("current.toml");
    let scene = write(dir.path(), "scene.csv", "X,Y,Z\n20,21,22\n1e300,1,1\n");
    let (code, stdout, stderr) = run(
        &[
            "render",
            profile.to_str().unwrap(),
            "--xyz",
            &scene,
            "-o",
            "-",
        ],
        Duration::from_secs(30),
    );
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains("row 2") && stderr.contains("beyond any light"),
        "{stderr}"
    );
    // The sun's luminance is a scene's; it renders.
    let sunny = write(
        dir.path(),
        "sunny.csv",
        "X,Y,Z\n20,21,22\n1.5e9,1.6e9,1.7e9\n",
    );
    let (code, stdout, stderr) = run(
        &[
            "render",
            profile.to_str().unwrap(),
            "--xyz",
            &sunny,
            "-o",
            "-",
        ],
        Duration::from_secs(30),
    );
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        !stdout.contains("NaN") && !stderr.contains("NaN"),
        "{stdout}{stderr}"
    );
    let spectra = write(
        dir.path(),
        "huge.csv",
        "wavelength_nm,lamp\n380,0.5\n500,1e300\n780,0.5\n",
    );
    let (code, stdout, stderr) = run(&["spectrum", &spectra], Duration::from_secs(10));
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains("row 2, column 'lamp'") && stderr.contains("beyond any spectrum"),
        "{stderr}"
    );
}

/// Under an address-space limit (`ulimit -v 4000000`, 4 GB), an image that would not
/// render within what is left is refused from its header with a message and exit 1:
/// it used to abort (SIGABRT) when an allocation failed.
#[test]
fn an_image_past_the_address_space_limit_is_refused_not_aborted() {
    let dir = tempfile::tempdir().unwrap();
    let state = calibrated(dir.path());
    // 2976 × 2976 XYZ, 106 MB.
    let image = dir.path().join("big.pfm");
    let (w, h) = (2976usize, 2976usize);
    let mut bytes = format!("PF\n{w} {h}\n-1.0\n").into_bytes();
    let pixel: Vec<u8> = [20.0f32, 21.0, 22.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    bytes.extend(pixel.iter().cycle().take(w * h * 12));
    std::fs::write(&image, bytes).unwrap();
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 4000000 && exec \"{}\" render \"{}\" --image \"{}\" -o \"{}\"",
            env!("CARGO_BIN_EXE_chromacal"),
            state.join("current.toml").display(),
            image.display(),
            dir.path().join("big.png").display()
        ))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("2976 × 2976 pixels would take about")
            && stderr.contains("address-space limit"),
        "{stderr}"
    );
}
