//! The `chromacal` command, run as a user runs it.

use std::path::Path;

use chromacal::profile::Profile;
use chromacal_color::spectrum::{
    Illuminant, Observer, Spectrum, emission_to_xyz, reflectance_to_xyz,
};
use chromacal_model::transfer::LawKind;

mod common;
use common::{chromacal, fixture, shared_path, shared_table};

fn run(args: &[&str]) -> (bool, String, String) {
    let out = chromacal().args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn calibrate_runs_the_default_simulation_and_publishes_a_profile() {
    let state = tempfile::tempdir().unwrap();
    let (ok, stdout, stderr) = run(&["calibrate", "--state-dir", path(state.path())]);
    assert!(ok, "{stderr}");
    for expected in [
        "patches measured: 20 counted",
        "sequential plan:",
        "simulated instrument time",
        "fit time",
        "transfer laws",
        "← chosen",
        "held-out ΔE00",
        "primary constancy",
        "published as current",
    ] {
        assert!(
            stdout.contains(expected),
            "missing '{expected}' in:\n{stdout}"
        );
    }
    let profile = Profile::read(&state.path().join("current.toml")).unwrap();
    assert_eq!(profile.report.chosen_law(), Some(LawKind::GainOffsetGamma));
    let held = profile.report.held_out.unwrap();
    assert!(held.mean <= 0.5 && held.p95 <= 1.0, "{held:?}");
    assert_eq!(held.n, 12);
    // The default is a sequential plan with a 3 × 3 grid and its held-out patches
    // within two minutes of instrument time, every assumption tested.
    let cost = profile.cost.clone().unwrap();
    let seconds = cost.instrument_s.unwrap();
    assert!(seconds <= 120.0, "{seconds} s of instrument time");
    for assumption in [
        "additivity             holds",
        "spatial independence   holds",
        "temporal stability     holds",
    ] {
        assert!(stdout.contains(assumption), "'{assumption}' in:\n{stdout}");
    }
    assert!(stdout.contains("spatial map (8 grid positions"), "{stdout}");
    // A second run publishes a second profile; both stay in the store.
    let (ok, _, _) = run(&["calibrate", "--state-dir", path(state.path())]);
    assert!(ok);
    assert_eq!(
        std::fs::read_dir(state.path().join("profiles"))
            .unwrap()
            .count(),
        2
    );
}

#[test]
fn calibrate_json_and_a_profile_that_fails_the_limits() {
    let state = tempfile::tempdir().unwrap();
    let config = state.path().join("strict.toml");
    std::fs::write(&config, "[publish]\nmax_mean_de00 = 0.001\n").unwrap();
    let out = chromacal()
        .args([
            "calibrate",
            "--json",
            "--config",
            path(&config),
            "--state-dir",
            path(state.path()),
        ])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(3),
        "a profile over the limits is not published"
    );
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(summary["report"]["held_out"]["mean"].as_f64().unwrap() > 0.001);
    assert_eq!(summary["published"], false);
    assert!(
        summary["not_published_because"]
            .as_str()
            .unwrap()
            .contains("0.001"),
        "{summary}"
    );
    // The run, the profile and where they are, for a script to go on with.
    let id = summary["run_id"].as_str().unwrap();
    assert_eq!(summary["profile_id"], id);
    let profile_path = std::path::PathBuf::from(summary["profile_path"].as_str().unwrap());
    assert!(
        profile_path.ends_with(format!("profiles/{id}.toml")),
        "{summary}"
    );
    assert!(profile_path.exists());
    assert!(std::path::Path::new(summary["journal"].as_str().unwrap()).exists());
    assert!(summary["readings"].as_u64().unwrap() > 0);
    assert!(!state.path().join("current.toml").exists());
    assert_eq!(
        std::fs::read_dir(state.path().join("profiles"))
            .unwrap()
            .count(),
        1
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("not published"));
}

#[test]
fn config_errors_name_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("typo.toml");
    std::fs::write(&config, "[plan]\nbudget = 48\nbugdet = 12\n").unwrap();
    let (ok, _, stderr) = run(&[
        "calibrate",
        "--config",
        path(&config),
        "--state-dir",
        path(dir.path()),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("typo.toml:3:1") && stderr.contains("bugdet"),
        "{stderr}"
    );
    std::fs::write(&config, "[monitor]\npreset = \"plasma\"\n").unwrap();
    let (ok, _, stderr) = run(&[
        "calibrate",
        "--config",
        path(&config),
        "--state-dir",
        path(dir.path()),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("plasma") && stderr.contains("crt, lcd"),
        "{stderr}"
    );
}

#[test]
fn fit_and_check_a_journal_and_a_ti3() {
    let dir = tempfile::tempdir().unwrap();
    let from_journal = dir.path().join("crt.toml");
    let (ok, stdout, stderr) = run(&[
        "fit",
        fixture("journals/crt-default.jsonl").to_str().unwrap(),
        "-o",
        path(&from_journal),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("held-out ΔE00") && stdout.contains("transfer laws"),
        "{stdout}"
    );
    let profile = Profile::read(&from_journal).unwrap();
    assert_eq!(profile.report.chosen_law(), Some(LawKind::GainOffsetGamma));

    let from_ti3 = dir.path().join("crt-ti3.toml");
    let (ok, _, stderr) = run(&[
        "fit",
        fixture("ti3/crt-default.ti3").to_str().unwrap(),
        "-o",
        path(&from_ti3),
        "--laws",
        "power,cowan",
    ]);
    assert!(ok, "{stderr}");
    let ti3_profile = Profile::read(&from_ti3).unwrap();
    let laws: Vec<LawKind> = ti3_profile.report.laws.iter().map(|l| l.law).collect();
    assert_eq!(laws, vec![LawKind::Power, LawKind::Cowan]);

    // The journal's profile predicts the .ti3 readings of the same run well...
    let out = chromacal()
        .args([
            "check",
            path(&from_journal),
            fixture("ti3/crt-default.ti3").to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let check: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let patches = check["patches"].as_array().unwrap();
    // Every reading at the centre on a black surround: 96 less the 24 grid positions
    // and the patch on a white surround.
    assert_eq!(patches.len(), 71);
    assert!(
        patches
            .iter()
            .all(|p| p["predicted"].as_array().unwrap().len() == 3)
    );
    assert!(
        check["stats"]["mean"].as_f64().unwrap() < 0.3,
        "{}",
        check["stats"]
    );
    // The .ti3 carries LUMINANCE_XYZ_CDM2, so both are in cd/m² and nothing is scaled.
    assert!(check["note"].is_null());

    // ...and a different display badly: check tells them apart.
    let (ok, stdout, _) = run(&[
        "check",
        path(&from_journal),
        fixture("ti3/lcd-seed12.ti3").to_str().unwrap(),
    ]);
    assert!(ok);
    let mean: f64 = stdout
        .split("mean ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap();
    assert!(mean > 2.0, "{stdout}");
    assert!(stdout.contains("worst patches"));

    let (ok, stdout, _) = run(&["profile", "show", path(&from_journal)]);
    assert!(ok);
    for expected in [
        "primary matrix",
        "gain-offset-gamma",
        "± ",
        "spatial map",
        "condition number",
    ] {
        assert!(stdout.contains(expected), "missing '{expected}':\n{stdout}");
    }
}

#[test]
fn bad_measurement_files_get_errors_that_name_the_place() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(fixture("ti3/crt-default.ti3")).unwrap();
    let broken = dir.path().join("broken.ti3");
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let row = lines.iter().position(|l| l.starts_with("5 ")).unwrap();
    let mut fields: Vec<String> = lines[row].split(' ').map(str::to_string).collect();
    fields[5] = "NaN".into();
    lines[row] = fields.join(" ");
    std::fs::write(&broken, lines.join("\n")).unwrap();
    let (ok, _, stderr) = run(&["fit", path(&broken), "-o", path(&dir.path().join("p.toml"))]);
    assert!(!ok);
    assert!(
        stderr.contains(&format!("line {}", row + 1))
            && stderr.contains("XYZ_Y")
            && stderr.contains("NaN"),
        "{stderr}"
    );
    assert!(!dir.path().join("p.toml").exists());

    let bad_profile = dir.path().join("bad.toml");
    std::fs::write(&bad_profile, "schema_version = 99\n").unwrap();
    let (ok, _, stderr) = run(&["profile", "show", path(&bad_profile)]);
    assert!(!ok && stderr.contains("schema version 99"), "{stderr}");
    let (ok, _, stderr) = run(&[
        "check",
        path(&dir.path().join("missing.toml")),
        path(&broken),
    ]);
    assert!(!ok && stderr.contains("missing.toml"), "{stderr}");
}

/// `spectrum` against sums computed here from the CIE tables in ../shared/data.
#[test]
fn spectrum_integrates_emission_and_reflectance() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("spectra.csv");
    // Two 5 nm radiance spectra in W·sr⁻¹·m⁻²·nm⁻¹.
    let mut text = String::from("wavelength_nm,flat,ramp\n");
    for i in 0..=80 {
        let w = 380 + 5 * i;
        text += &format!("{w},0.001,{}\n", 0.00002 * i as f64);
    }
    std::fs::write(&csv, &text).unwrap();
    let out = chromacal()
        .args(["spectrum", path(&csv), "--json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let result: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Y = 683 Σ S ȳ Δλ from the CIE 1931 5 nm table.
    let cmf = shared_table("cie/cie1931_2deg_xyz_cmf_5nm.csv");
    let y: f64 = cmf
        .iter()
        .filter(|r| (380.0..=780.0).contains(&r[0]))
        .map(|r| 683.0 * 0.001 * r[2] * 5.0)
        .sum();
    let got = result[0]["xyz"][1].as_f64().unwrap();
    assert!((got - y).abs() < 1e-9 * y, "{got} vs {y}");
    assert_eq!(result[1]["sample"], "ramp");
    assert!(result[0]["photopic_cd_m2"].as_f64().unwrap() > 0.0);

    let out = chromacal()
        .args([
            "spectrum",
            path(&csv),
            "--json",
            "--relative",
            "--observer",
            "10",
        ])
        .output()
        .unwrap();
    let relative: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((relative[0]["xyz"][1].as_f64().unwrap() - 100.0).abs() < 1e-9);
    assert_ne!(relative[0]["x"], result[0]["x"], "the 10° observer differs");

    // Reflectance: the ColorChecker under D65 matches the library call (the
    // illuminant written as the README writes it: either case is taken).
    let checker = shared_path("colorchecker/colorchecker_n_ohta_5nm.csv");
    let out = chromacal()
        .args([
            "spectrum",
            checker.to_str().unwrap(),
            "--reflectance",
            "--illuminant",
            "D65",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let result: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(result.as_array().unwrap().len(), 24);
    let table = shared_table("colorchecker/colorchecker_n_ohta_5nm.csv");
    let dark_skin = Spectrum::new(
        table.iter().map(|r| r[0]).collect(),
        table.iter().map(|r| r[1]).collect(),
    )
    .unwrap();
    let xyz = reflectance_to_xyz(&dark_skin, Illuminant::D65, Observer::Cie1931TwoDegree).unwrap();
    assert!((result[0]["xyz"][0].as_f64().unwrap() - xyz.x).abs() < 1e-9);
    // Neutral 5 is neutral against the D65 white.
    let neutral = &result[21]["lab"];
    assert!(
        neutral[1].as_f64().unwrap().abs() < 0.3 && neutral[2].as_f64().unwrap().abs() < 0.3,
        "{neutral}"
    );

    // A 3.333 nm grid over 380–730 nm (finer than 5 nm, not on whole nanometres) is
    // extended to 780 nm and put on the 1 nm grid: a flat one gives what the flat
    // 1 nm spectrum over 380–780 nm gives.
    let fine = Spectrum::new((380..=780).map(f64::from).collect(), vec![0.001; 401]).unwrap();
    let uneven_csv = dir.path().join("uneven.csv");
    let mut text = String::from("wavelength_nm,flat\n");
    for i in 0..106 {
        text += &format!("{},0.001\n", 380.0 + i as f64 * 350.0 / 105.0);
    }
    std::fs::write(&uneven_csv, text).unwrap();
    let out = chromacal()
        .args(["spectrum", path(&uneven_csv), "--json"])
        .output()
        .unwrap();
    let uneven: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let expected = emission_to_xyz(&fine, Observer::Cie1931TwoDegree).unwrap();
    assert!((uneven[0]["xyz"][1].as_f64().unwrap() - expected.y).abs() < 1e-9 * expected.y);

    // Errors name the file and the column.
    std::fs::write(&csv, "nm,a\n400,1\n500,2\n").unwrap();
    let (ok, _, stderr) = run(&["spectrum", path(&csv)]);
    assert!(!ok && stderr.contains("wavelength_nm"), "{stderr}");
    std::fs::write(&csv, "wavelength_nm,a\n400,1\n400,2\n700,1\n").unwrap();
    let (ok, _, stderr) = run(&["spectrum", path(&csv)]);
    assert!(
        !ok && stderr.contains("data row 2") && stderr.contains("must rise"),
        "{stderr}"
    );
    // Help says how spectra meet the CMF grid.
    let (_, help, _) = run(&["spectrum", "--help"]);
    assert!(
        help.contains("1 nm") && help.contains("weighted ordinates"),
        "{help}"
    );
}

#[test]
fn a_stopped_emulator_leaves_no_screen_socket_behind() {
    for signal in ["-TERM", "-INT"] {
        let mut emulator = common::emulate(&["--instrument", "pr670"]);
        let screen = std::path::PathBuf::from(&emulator.screen);
        assert!(screen.exists(), "{}", screen.display());
        let status = std::process::Command::new("kill")
            .args([signal, &emulator.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let exit = emulator.child.wait().unwrap();
        assert!(exit.success(), "{signal}: {exit}");
        assert!(!screen.exists(), "{signal}: {} is left", screen.display());
    }
    // The tests' own harness stops it the same way when a test ends.
    let emulator = common::emulate(&["--instrument", "k10a"]);
    let screen = std::path::PathBuf::from(&emulator.screen);
    assert!(screen.exists(), "{}", screen.display());
    drop(emulator);
    assert!(!screen.exists(), "the harness left {}", screen.display());
}

/// An output in a directory that does not exist is a mistyped path: refused, naming
/// the directory, and nothing created (the report made `/nonexistent` and said
/// "written").
#[test]
fn an_output_in_a_missing_directory_is_refused_not_created() {
    let dir = tempfile::tempdir().unwrap();
    let ti3 = fixture("ti3/crt-default.ti3");
    let missing = dir.path().join("no-such-dir");
    let profile = dir.path().join("crt.toml");
    let (ok, _, stderr) = run(&["fit", path(&ti3), "-o", path(&missing.join("crt.toml"))]);
    assert!(!ok && stderr.contains("no such directory"), "{stderr}");
    let (ok, _, stderr) = run(&["fit", path(&ti3), "-o", path(&profile)]);
    assert!(ok, "{stderr}");
    let (ok, _, stderr) = run(&[
        "report",
        path(&profile),
        "-o",
        path(&missing.join("r.html")),
    ]);
    assert!(
        !ok && stderr.contains("no such directory") && stderr.contains("no-such-dir"),
        "{stderr}"
    );
    assert!(!missing.exists());
    // `calibrate --report` says it before measuring, not after publishing.
    let state = dir.path().join("state");
    let (ok, _, stderr) = run(&[
        "calibrate",
        "--state-dir",
        path(&state),
        "--report",
        path(&missing.join("r.html")),
    ]);
    assert!(!ok && stderr.contains("no such directory"), "{stderr}");
    assert!(!state.exists(), "a run was started");
}

#[test]
fn a_file_that_is_not_a_profile_is_named_for_what_it_is() {
    let dir = tempfile::tempdir().unwrap();
    let ti3 = fixture("ti3/crt-default.ti3");
    let profile = dir.path().join("crt.toml");
    let (ok, _, stderr) = run(&["fit", path(&ti3), "-o", path(&profile)]);
    assert!(ok, "{stderr}");
    let icc = dir.path().join("crt.icc");
    let (ok, _, stderr) = run(&[
        "export",
        path(&profile),
        "--format",
        "icc4",
        "-o",
        path(&icc),
    ]);
    assert!(ok, "{stderr}");
    for command in ["profile show", "report", "check"] {
        let mut args: Vec<&str> = command.split(' ').collect();
        args.push(path(&icc));
        match command {
            "report" => args.extend(["-o", "/dev/null"]),
            "check" => args.push(path(&ti3)),
            _ => {}
        }
        let (ok, _, stderr) = run(&args);
        assert!(!ok);
        assert!(
            stderr.contains("is an ICC profile (version 4.")
                && stderr.contains("class 'mntr'")
                && stderr.contains("not a chromacal profile")
                && stderr.contains("chromacal export"),
            "{command}: {stderr}"
        );
        assert!(!stderr.contains("UTF-8"), "{stderr}");
    }
    let (ok, _, stderr) = run(&["profile", "show", path(&ti3)]);
    assert!(!ok);
    assert!(
        stderr.contains("is an ArgyllCMS CTI3 file") && stderr.contains("chromacal fit"),
        "{stderr}"
    );
    // `check` given the journal first and the profile second.
    let journal = fixture("journals/crt-default.jsonl");
    let (ok, _, stderr) = run(&["check", path(&journal), path(&profile)]);
    assert!(!ok);
    assert!(
        stderr.contains("is a chromacal run's journal")
            && stderr.contains("`chromacal check PROFILE JOURNAL` takes the profile first"),
        "{stderr}"
    );
}

#[test]
fn verbosity_flags_and_log_variables_set_what_reaches_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let ti3 = fixture("ti3/crt-default.ti3");
    let profile = dir.path().join("p.toml");
    let fit = |extra: &[&str], env: &[(&str, &str)]| {
        let mut command = chromacal();
        command
            .args(extra)
            .args(["fit", path(&ti3), "-o", path(&profile)])
            .env_remove("CHROMACAL_LOG")
            .env_remove("RUST_LOG");
        for (k, v) in env {
            command.env(k, v);
        }
        let out = command.output().unwrap();
        assert!(out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    // Quiet by default; -vv and RUST_LOG=debug say what the fit does, in debug lines.
    assert!(!fit(&[], &[]).contains("DEBUG"));
    assert!(fit(&["-vv"], &[]).contains("DEBUG"));
    assert!(fit(&[], &[("RUST_LOG", "debug")]).contains("DEBUG"));
    // CHROMACAL_LOG wins over -vv; -q with -v is refused.
    assert!(!fit(&["-vv"], &[("CHROMACAL_LOG", "error")]).contains("DEBUG"));
    let out = chromacal()
        .args(["-q", "-v", "fit", path(&ti3), "-o", path(&profile)])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    // No escape sequences with NO_COLOR, even when forced to log.
    let said = fit(&["-vv"], &[("NO_COLOR", "1")]);
    assert!(!said.contains('\u{1b}'), "{said:?}");
}

#[test]
fn config_show_says_what_is_in_effect_and_the_user_config_is_found() {
    let dir = tempfile::tempdir().unwrap();
    let show = |xdg: &Path, extra: &[&str]| {
        let out = chromacal()
            .env("XDG_CONFIG_HOME", xdg)
            .args(["config", "show"])
            .args(extra)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    let built_in = show(dir.path(), &[]);
    assert!(
        built_in.contains("read from built-in config/default.toml"),
        "{built_in}"
    );
    assert!(
        built_in.contains("chromacal/config.toml (absent)"),
        "{built_in}"
    );
    assert!(built_in.contains("budget = 40"), "{built_in}");
    assert!(built_in.contains("strategy = \"sequential\""), "{built_in}");
    // What it prints is a config that reads back as itself.
    let printed = dir.path().join("printed.toml");
    std::fs::write(&printed, &built_in).unwrap();
    let again = show(dir.path(), &["--config", path(&printed)]);
    let body = |s: &str| {
        s.lines()
            .filter(|l| !l.starts_with('#'))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(body(&again), body(&built_in));
    // Given by a relative name, the config's folder is said in full (it used to read
    // "taken from ." with the folder empty).
    let relative = chromacal()
        .env("XDG_CONFIG_HOME", dir.path())
        .args(["config", "show", "--config", "printed.toml"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let relative = String::from_utf8_lossy(&relative.stdout);
    assert!(
        relative.contains(&format!(
            "# Relative paths are taken from {}.\n",
            dir.path().display()
        )),
        "{relative}"
    );

    // A user config in $XDG_CONFIG_HOME/chromacal/ is found and used by the commands.
    let user = dir.path().join("chromacal/config.toml");
    std::fs::create_dir_all(user.parent().unwrap()).unwrap();
    std::fs::write(&user, "[fit]\nlaws = [\"power\"]\n").unwrap();
    let found = show(dir.path(), &[]);
    assert!(
        found.contains(&format!("read from {}", user.display())),
        "{found}"
    );
    assert!(found.contains("laws = [\"power\"]"), "{found}");
    let profile = dir.path().join("p.toml");
    let out = chromacal()
        .env("XDG_CONFIG_HOME", dir.path())
        .arg("fit")
        .arg(fixture("ti3/crt-default.ti3"))
        .arg("-o")
        .arg(&profile)
        .output()
        .unwrap();
    assert!(out.status.success());
    let fitted = chromacal::profile::Profile::read(&profile).unwrap();
    let laws: Vec<_> = fitted.report.laws.iter().map(|l| l.law.name()).collect();
    assert_eq!(laws, ["power"]);
}

/// A realtime calibration into `state`, once its journal holds `lines` lines (the
/// header and readings: the run is under way, its signal handler in place); and that
/// journal.
fn calibrate_until(
    state: &Path,
    time_scale: &str,
    lines: usize,
) -> (std::process::Child, std::path::PathBuf) {
    let mut child = chromacal()
        .args([
            "calibrate",
            "--realtime",
            "--time-scale",
            time_scale,
            "--state-dir",
        ])
        .arg(state)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let journal = || {
        let run = std::fs::read_dir(state.join("runs")).ok()?.next()?.ok()?;
        Some(run.path().join("journal.jsonl"))
    };
    let count = |path: &Path| std::fs::read_to_string(path).map_or(0, |t| t.lines().count());
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let ready = loop {
        let ready = journal().filter(|j| count(j) >= lines);
        if ready.is_some() || std::time::Instant::now() > deadline {
            break ready;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    match ready {
        Some(j) => (child, j),
        None => {
            let _ = child.kill();
            let _ = child.wait();
            panic!("no readings in {}", state.display())
        }
    }
}

#[test]
fn ctrl_c_stops_a_calibration_keeping_its_readings_for_resume() {
    let state = tempfile::tempdir().unwrap();
    // A few readings in the journal, then Ctrl-C.
    let (child, journal) = calibrate_until(state.path(), "0.05", 6);
    let lines = |path: &Path| std::fs::read_to_string(path).map_or(0, |t| t.lines().count());
    let status = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("stopping after the reading under way"),
        "{stderr}"
    );
    // It says how many readings are kept, where, and how to go on; the journal holds
    // exactly that many.
    let kept = lines(&journal) - 1;
    assert!(
        stderr.contains(&format!("stopped on request after {kept} of ")),
        "{kept}: {stderr}"
    );
    assert!(stderr.contains("chromacal calibrate --resume"), "{stderr}");
    assert!(!state.path().join("current.toml").exists());
    let (ok, stdout, stderr) = run(&["calibrate", "--resume", "--state-dir", path(state.path())]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains(&format!("resumed: {kept} patches were in the journal")),
        "{stdout}"
    );
    assert!(state.path().join("current.toml").exists());
}

/// A second Ctrl-C exits at once, and its hint names the state directory as the
/// first one's does (it said a plain `--resume`, which would not find this run).
#[test]
fn a_second_ctrl_c_names_the_state_directory_to_resume_in() {
    let state = tempfile::tempdir().unwrap();
    let (child, _) = calibrate_until(state.path(), "0.5", 2);
    // Twice within a reading (half a second at this time scale).
    for _ in 0..2 {
        let status = std::process::Command::new("kill")
            .args(["-INT", &child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(&format!(
            "stopped at once; every reading taken is in the journal, and `chromacal calibrate --resume --state-dir {}` goes on",
            state.path().display()
        )),
        "{stderr}"
    );
}

#[test]
fn completions_and_manual_pages_come_from_the_command_line_definitions() {
    // bash takes the script and completes the subcommands from it.
    let out = chromacal().args(["completions", "bash"]).output().unwrap();
    assert!(out.status.success());
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("chromacal.bash");
    std::fs::write(&script, &out.stdout).unwrap();
    let probe = format!(
        "source {}; COMP_WORDS=(chromacal rep); COMP_CWORD=1; _chromacal chromacal rep chromacal; echo \"${{COMPREPLY[@]}}\"",
        script.display()
    );
    let completed = std::process::Command::new("bash")
        .args(["-c", &probe])
        .output()
        .unwrap();
    let words = String::from_utf8_lossy(&completed.stdout);
    assert!(
        words.split_whitespace().any(|w| w == "report"),
        "bash completed 'rep' to {words:?}: {}",
        String::from_utf8_lossy(&completed.stderr)
    );
    for shell in ["zsh", "fish", "Elvish", "powershell"] {
        let out = chromacal().args(["completions", shell]).output().unwrap();
        assert!(out.status.success() && out.stdout.len() > 1000, "{shell}");
    }
    // The manual pages read back through groff: a page a command, the options there.
    let pages = dir.path().join("man");
    let out = chromacal()
        .args(["man", "-o"])
        .arg(&pages)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for page in ["chromacal.1", "chromacal-calibrate.1", "chromacal-report.1"] {
        assert!(pages.join(page).exists(), "no {page}");
    }
    let rendered = std::process::Command::new("groff")
        .args(["-man", "-Tascii"])
        .arg(pages.join("chromacal-calibrate.1"))
        .output()
        .unwrap();
    // groff overstrikes bold as "c\bc": keep the last of each.
    let mut text = String::new();
    for c in String::from_utf8_lossy(&rendered.stdout).chars() {
        if c == '\u{8}' {
            text.pop();
        } else {
            text.push(c);
        }
    }
    assert!(rendered.status.success());
    assert!(
        text.contains("--resume") && text.contains("--report"),
        "{text}"
    );
}

#[test]
fn help_names_the_exit_codes() {
    let (ok, stdout, _) = run(&["--help"]);
    assert!(ok);
    for code in [
        "Exit codes",
        "0 done",
        "3 a profile was made",
        "4 an export",
        "130 stopped",
    ] {
        assert!(stdout.contains(code), "{code}: {stdout}");
    }
}

/// `config show` checks what the daemon checks: a fleet config with a device named
/// twice prints, says it would be refused, and exits 1, as `chromacal daemon` would.
#[test]
fn config_show_refuses_what_the_daemon_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("fleet.toml");
    std::fs::write(
        &config,
        "[[device]]\nname = \"a\"\n[[device]]\nname = \"a\"\n",
    )
    .unwrap();
    let out = chromacal()
        .args(["config", "show", "--config", path(&config)])
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stdout.contains("# It would be refused: device \"a\" is named twice"),
        "{stdout}"
    );
    assert!(stderr.contains("would be refused"), "{stderr}");
    let daemon = chromacal()
        .args(["daemon", "--config", path(&config), "--state-dir"])
        .arg(dir.path().join("state"))
        .output()
        .unwrap();
    assert_eq!(daemon.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&daemon.stderr).contains("named twice"));
}

/// The example configs in `config/examples/` (virtual monitors built from real
/// displays' measured spectra and transfer tables) each run a calibration as the
/// README says, reading the shared data by their own relative paths.
#[test]
fn the_example_configs_calibrate_virtual_monitors_from_real_displays() {
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/examples");
    let mut configs: Vec<std::path::PathBuf> = std::fs::read_dir(&examples)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    configs.sort();
    assert!(configs.len() >= 3, "{configs:?}");
    for config in configs {
        let state = tempfile::tempdir().unwrap();
        // From another working directory: the paths are the config's own.
        let out = chromacal()
            .args(["calibrate", "--json", "--config"])
            .arg(&config)
            .arg("--state-dir")
            .arg(state.path())
            .current_dir(state.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}",
            config.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let held_out = summary["report"]["held_out"]["mean"].as_f64().unwrap();
        assert!(
            summary["published"].as_bool().unwrap() && held_out < 0.5,
            "{}: held-out {held_out}",
            config.display()
        );
    }
}
