//! Colorimeter corrections as ArgyllCMS `.ccmx` files: `instrument.correction` names
//! one, and an emulated colorimeter's readings reach the fit through its matrix; a
//! singular or absurd one is refused before anything is measured, naming the file.

use chromacal::profile::Profile;
use chromacal_formats::ccmx::{Ccmx, ccmx_text};
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
    // X and Z swapped, X and Z negated, a row zeroed: each refused before measuring,
    // naming the light it spoils (a negated one once published a white of negative X).
    for (matrix, named) in [
        (
            Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0),
            "moves the chromaticity of a red primary",
        ),
        (
            Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0),
            "turns a red primary into X, Y, Z",
        ),
        (
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
            "singular",
        ),
    ] {
        let bad = Ccmx {
            matrix,
            ..ccmx.clone()
        };
        std::fs::write(dir.path().join("crt.ccmx"), ccmx_text(&bad, "now")).unwrap();
        let out = calibrate(&corrected, &state, &emulator.device, &emulator.screen);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains("crt.ccmx") && err.contains(named), "{err}");
        assert!(!state.join("runs").exists(), "measured with {matrix}");
    }
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

/// A `.ccss` of a display's primaries and white, written as ArgyllCMS writes one
/// (CGATS `CCSS`, `SPEC_NNN` fields), corrects a colorimeter whose sensitivities are
/// known (here the emulated K-10A's filters) on that display's other colours; a
/// `.ccss` with too few samples, or a native colorimeter given one, is refused.
#[test]
fn a_ccss_corrects_a_colorimeter_of_known_sensitivities() {
    use chromacal_color::difference::delta_e_2000;
    use chromacal_color::spaces::xyz_to_lab;
    use chromacal_color::spectrum::{Observer, emission_to_xyz};
    use chromacal_formats::ccss::{correction_from_samples, parse_ccss};
    use chromacal_instruments::filters::{ColorimeterFilters, FilterModel};
    use chromacal_model::ScreenPosition;
    use chromacal_sim::monitor::{VirtualMonitor, centre_patch};

    let text = common::isetbio_monitor("isetbio_lcd_dell", "");
    let config = chromacal::config::parse_config(&text, "lcd").unwrap();
    let spec = config.monitor.resolve(std::path::Path::new(".")).unwrap();
    let clock = std::sync::Arc::new(chromacal_sim::clock::VirtualClock::new(None));
    let mut monitor = VirtualMonitor::new(spec, clock).unwrap();
    let mut radiance = |drive: [f64; 3]| {
        monitor.show(centre_patch(drive));
        monitor.radiance_at(ScreenPosition::CENTRE).unwrap()
    };
    let samples: Vec<_> = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0; 3]]
        .iter()
        .map(|d| radiance(*d))
        .collect();
    // On the spectra's own grid: the CCFL's lines are narrow, and a coarser one would
    // not hold them.
    let grid: Vec<f64> = samples[0].wavelengths_nm().to_vec();
    let mut ccss = String::from(
        "CCSS\n\nDESCRIPTOR \"test\"\nKEYWORD \"DISPLAY\"\nDISPLAY \"ISETBio Dell LCD\"\nKEYWORD \"TECHNOLOGY\"\nTECHNOLOGY \"LCD CCFL\"\n\n",
    );
    ccss += &format!(
        "NUMBER_OF_FIELDS {}\nBEGIN_DATA_FORMAT\nSAMPLE_ID {}\nEND_DATA_FORMAT\n\nNUMBER_OF_SETS {}\nBEGIN_DATA\n",
        grid.len() + 1,
        grid.iter()
            .map(|nm| format!("SPEC_{nm:.0}"))
            .collect::<Vec<_>>()
            .join(" "),
        samples.len()
    );
    for (i, s) in samples.iter().enumerate() {
        let values: Vec<String> = grid
            .iter()
            .map(|nm| format!("{:.6e}", s.value_at(*nm).unwrap_or(0.0)))
            .collect();
        ccss += &format!("{} {}\n", i + 1, values.join(" "));
    }
    ccss += "END_DATA\n";
    let parsed = parse_ccss(&ccss, "lcd.ccss").unwrap();
    assert_eq!(parsed.display, "ISETBio Dell LCD");
    assert_eq!(parsed.samples.len(), 4);

    let filters = ColorimeterFilters::new(FilterModel::K10a).unwrap();
    let m = correction_from_samples(&parsed.samples, |s| Some(filters.xyz(s))).unwrap();
    let white = emission_to_xyz(&samples[3], Observer::default()).unwrap();
    let (mut before, mut after) = (0.0f64, 0.0f64);
    for drive in [
        [0.8, 0.5, 0.4],
        [0.4, 0.7, 0.6],
        [0.5, 0.4, 0.8],
        [0.2, 0.6, 0.3],
    ] {
        let s = radiance(drive);
        let truth = emission_to_xyz(&s, Observer::default()).unwrap();
        let read = filters.xyz(&s);
        let lab = |x| xyz_to_lab(&x, &white);
        before = before.max(delta_e_2000(&lab(truth), &lab(read)));
        after = after.max(delta_e_2000(&lab(truth), &lab(m * read)));
    }
    eprintln!("K-10A on the Dell LCD through a .ccss: max ΔE00 {before:.3} → {after:.3}");
    assert!(before > 0.5, "{before}");
    assert!(after < 0.1, "{after}");

    // Two samples cannot fix a matrix.
    let short: String = ccss
        .lines()
        .filter(|l| !l.starts_with("3 ") && !l.starts_with("4 "))
        .map(|l| l.replace("NUMBER_OF_SETS 4", "NUMBER_OF_SETS 2") + "\n")
        .collect();
    let err = parse_ccss(&short, "short.ccss").unwrap_err().to_string();
    assert!(
        err.contains("short.ccss") && err.contains("2 spectral samples"),
        "{err}"
    );

    // A native colorimeter has no known sensitivities: refused, naming the remedy.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("lcd.ccss"), &ccss).unwrap();
    let config = dir.path().join("config.toml");
    std::fs::write(&config, "[instrument]\ncorrection = \"lcd.ccss\"\n").unwrap();
    let emulator = emulate(&["--instrument", "k10a", "--time-scale", TIME_SCALE]);
    let out = calibrate(
        &config,
        &dir.path().join("state"),
        &emulator.device,
        &emulator.screen,
    );
    let text = failure_text(out);
    assert!(
        text.contains("correction make") && text.contains(".ccss"),
        "{text}"
    );
}
