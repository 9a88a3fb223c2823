//! What the commands put out: a reader that stops early is not a failure, `-o -` is
//! standard output for every command that writes a file, what a profile stores of a
//! path still finds it from elsewhere, and a calibration target is stated as reached
//! (issue 29's newcomer stumbles 3, 4 and 5).

mod common;

use std::io::Read;
use std::process::Stdio;

use common::{chromacal, shared_path, succeed};

const DELL: &str = "measurements/dell_u2713hm_i1d3_912.ti3";

/// Run chromacal with its standard output read for 16 bytes and then closed, as
/// `| head -c 16` does, and return its exit status and standard error. Each command
/// here writes far more than a pipe holds (64 KiB), so it meets the closed pipe
/// whatever the timing.
fn with_reader_gone(args: &[&str], dir: &std::path::Path) -> (Option<i32>, String) {
    let mut child = chromacal()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("chromacal starts");
    let mut stdout = child.stdout.take().expect("piped");
    let mut first = [0u8; 16];
    stdout.read_exact(&mut first).expect("some output first");
    drop(stdout);
    let output = child.wait_with_output().expect("chromacal ends");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn a_reader_that_stops_early_ends_the_command_quietly_with_success() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dell = shared_path(DELL);
    let profile = dir.path().join("dell.toml");
    succeed(chromacal().arg("fit").arg(&dell).arg("-o").arg(&profile));
    // 20,000 colours to render: about 1.4 MB of codes.
    let colours: String = (0..20_000)
        .map(|i| format!("{},{},{}\n", 5 + i % 31, 5 + i % 29, 5 + i % 37))
        .collect();
    std::fs::write(dir.path().join("xyz.csv"), format!("X,Y,Z\n{colours}")).expect("write");
    let dell = dell.to_str().expect("utf-8 path");
    let profile = profile.to_str().expect("utf-8 path");
    let cases: [&[&str]; 5] = [
        &["check", "--json", profile, dell],
        &["completions", "bash"],
        &["report", profile, "-o", "-"],
        &["fit", dell, "-o", "-"],
        &["render", profile, "--xyz", "xyz.csv", "-o", "-"],
    ];
    for args in cases {
        let (code, stderr) = with_reader_gone(args, dir.path());
        assert_eq!(
            code,
            Some(0),
            "`chromacal {}` with its reader gone: exit {code:?}, stderr {stderr}",
            args.join(" ")
        );
        for said in ["panicked", "Broken pipe", "os error 32"] {
            assert!(
                !stderr.contains(said),
                "`chromacal {}` said {said:?}: {stderr}",
                args.join(" ")
            );
        }
    }
}

#[test]
fn fit_writes_the_profile_to_standard_output_for_dash() {
    let dir = tempfile::tempdir().expect("tempdir");
    let output = succeed(
        chromacal()
            .arg("fit")
            .arg(shared_path(DELL))
            .args(["-o", "-"])
            .current_dir(dir.path()),
    );
    assert!(
        !dir.path().join("-").exists(),
        "`fit -o -` wrote a file named -"
    );
    let text = String::from_utf8(output.stdout).expect("utf-8");
    let profile = chromacal::profile::Profile::from_toml(&text, "standard output")
        .expect("standard output holds the profile, and only it");
    assert_eq!(profile.report.counts.readings, 912);
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(
        said.contains("profile: standard output"),
        "the summary goes to standard error and names where the profile went: {said}"
    );
}

#[test]
fn a_profile_made_from_a_relative_path_finds_its_readings_from_elsewhere() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = shared_path("measurements");
    succeed(
        chromacal()
            .args(["fit", "dell_u2713hm_i1d3_912.ti3", "-o"])
            .arg(dir.path().join("dell.toml"))
            .current_dir(&data),
    );
    let profile = chromacal::profile::Profile::read(&dir.path().join("dell.toml"))
        .expect("the profile reads back");
    let source = std::path::Path::new(&profile.provenance.source);
    assert!(
        source.is_absolute(),
        "stored as typed: {}",
        source.display()
    );
    // `report` run from the profile's folder, not the data's, still draws the readings.
    let page = succeed(
        chromacal()
            .args(["report", "dell.toml", "-o", "-"])
            .current_dir(dir.path()),
    );
    let page = String::from_utf8(page.stdout).expect("utf-8");
    assert!(
        !page.contains("not found") && !page.contains("cannot be read"),
        "the report lost the readings"
    );
}

#[test]
fn a_luminance_the_white_cannot_give_is_stated_as_reached_not_as_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let profile = dir.path().join("dell.toml");
    succeed(
        chromacal()
            .arg("fit")
            .arg(shared_path(DELL))
            .arg("-o")
            .arg(&profile),
    );
    let cal = dir.path().join("dell.cal");
    let icc = dir.path().join("dell.icc");
    let said = succeed(
        chromacal()
            .arg("export")
            .arg(&profile)
            .args(["--format", "cal", "--luminance", "500", "-o"])
            .arg(&cal),
    );
    succeed(
        chromacal()
            .arg("export")
            .arg(&profile)
            .args(["--format", "icc2", "--luminance", "500", "-o"])
            .arg(&icc),
    );
    // The most the Dell's white allows, from the profile's own model.
    let model = chromacal::profile::Profile::read(&profile)
        .expect("profile")
        .model;
    let target = chromacal_model::target::Target {
        white: chromacal_model::target::WhiteTarget::Native,
        tone: chromacal_model::target::ToneCurve::Power(2.2),
        luminance: Some(500.0),
    };
    let curves = chromacal_model::target::calibration_curves(&model, &target).expect("curves");
    assert!(curves.luminance_limited);
    let reached = format!(
        "luminance {:.2} (the most the white allows; 500 was asked)",
        curves.white[1]
    );
    let cal_text = std::fs::read_to_string(&cal).expect("cal");
    let description = cal_text
        .lines()
        .find(|l| l.starts_with("TARGET_DESCRIPTION"))
        .expect("the .cal describes its target");
    let icc_bytes = std::fs::read(&icc).expect("icc");
    let icc_text = String::from_utf8_lossy(&icc_bytes);
    let stdout = String::from_utf8_lossy(&said.stdout);
    for (place, text) in [
        (".cal", description),
        ("ICC", icc_text.as_ref()),
        ("standard output", stdout.as_ref()),
    ] {
        assert!(
            text.contains(&reached),
            "{place} does not say {reached:?}: {text}"
        );
        assert!(
            !text.contains("luminance 500,") && !text.contains("luminance 500 "),
            "{place} states the luminance asked for as reached"
        );
    }
}

#[test]
fn bench_says_where_it_looked_for_the_reference_data() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("no-data-here");
    let out = succeed(
        chromacal()
            .args(["bench", "fit-time", "--quick", "--data"])
            .arg(&missing),
    );
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(&format!("no reference data at {}", missing.display()))
            && said.contains("--data"),
        "{said}"
    );
    let data = std::fs::canonicalize(shared_path("")).expect("the shared data");
    let out = succeed(
        chromacal()
            .args(["bench", "fit-time", "--quick", "--data"])
            .arg(&data),
    );
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(&format!(
            "reference data (real displays, measured tables) from {}",
            data.display()
        )),
        "{said}"
    );
}
