//! Colorimeter corrections as ArgyllCMS `.ccmx` files: `instrument.correction` names
//! one, and an emulated colorimeter's readings reach the fit through its matrix; a
//! singular or absurd one is refused before anything is measured, naming the file.

use chromacal::ccmx::{Ccmx, ccmx_text};
use chromacal::profile::Profile;
use nalgebra::Matrix3;

mod common;
use common::{chromacal, emulate};

const TIME_SCALE: &str = "0.002";

fn calibrate(
    config: &std::path::Path,
    state: &std::path::Path,
    device: &str,
    screen: &str,
) -> std::process::Output {
    chromacal()
        .args(["calibrate", "--config"])
        .arg(config)
        .args([
            "--instrument",
            &format!("k10a:{device}"),
            "--screen",
            screen,
        ])
        .args(["--timing-scale", TIME_SCALE, "--state-dir"])
        .arg(state)
        .output()
        .unwrap()
}

#[test]
fn a_ccmx_file_corrects_a_colorimeter_and_a_bad_one_is_refused_before_measuring() {
    let dir = tempfile::tempdir().unwrap();
    let base = format!("{}[plan]\nuniformity_grid = 0\n", common::CRT_PRIMARIES);
    let plain = dir.path().join("plain.toml");
    std::fs::write(&plain, &base).unwrap();
    let matrix = Matrix3::new(1.04, 0.02, -0.01, 0.01, 0.98, 0.005, -0.005, 0.01, 0.93);
    let ccmx = Ccmx {
        matrix,
        description: "test correction".into(),
        display: "virtual CRT".into(),
        instrument: "Klein K-10A".into(),
        reference: "Photo Research PR-670".into(),
        technology: "CRT".into(),
    };
    std::fs::write(dir.path().join("crt.ccmx"), ccmx_text(&ccmx, "now")).unwrap();
    let corrected = dir.path().join("corrected.toml");
    std::fs::write(
        &corrected,
        format!("{base}[instrument]\ncorrection = \"crt.ccmx\"\n"),
    )
    .unwrap();

    let emulator = emulate(&["--instrument", "k10a", "--time-scale", TIME_SCALE]);
    let out = calibrate(
        &plain,
        &dir.path().join("plain"),
        &emulator.device,
        &emulator.screen,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = calibrate(
        &corrected,
        &dir.path().join("corrected"),
        &emulator.device,
        &emulator.screen,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let white = |state: &str| {
        Profile::read(&dir.path().join(state).join("current.toml"))
            .unwrap()
            .model
            .white()
    };
    let (raw, fixed) = (white("plain"), white("corrected"));
    let expected = matrix * raw;
    for c in 0..3 {
        assert!(
            (fixed[c] / expected[c] - 1.0).abs() < 0.01,
            "white {fixed:?}, the matrix times the uncorrected white {expected:?}"
        );
    }
    // The correction moved it, by more than the noise.
    assert!((fixed.z / raw.z - 1.0).abs() > 0.04);

    // A singular matrix: refused before any reading, the file named.
    let singular = Ccmx {
        matrix: Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 0.0, 1.0),
        ..ccmx.clone()
    };
    std::fs::write(dir.path().join("crt.ccmx"), ccmx_text(&singular, "now")).unwrap();
    let state = dir.path().join("refused");
    let out = calibrate(&corrected, &state, &emulator.device, &emulator.screen);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("crt.ccmx") && err.contains("singular"),
        "{err}"
    );
    assert!(
        !state.join("runs").exists(),
        "nothing is measured with a bad correction"
    );
    // A matrix written in the config is checked the same way, when the config loads.
    std::fs::write(
        &corrected,
        format!("{base}[instrument]\ncorrection = [[1.0, 0.0, 0.0], [0.1, 0.9, -0.15], [0.0, 0.0, 1.0]]\n"),
    )
    .unwrap();
    let out = failure_text(calibrate(
        &corrected,
        &state,
        &emulator.device,
        &emulator.screen,
    ));
    assert!(out.contains("luminance of a blue primary"), "{out}");
}

/// The stderr of a command that must fail.
fn failure_text(out: std::process::Output) -> String {
    assert!(!out.status.success());
    String::from_utf8_lossy(&out.stderr).into_owned()
}
