//! `chromacal correction make` between an emulated PR-670 and emulated colorimeters
//! aimed at one virtual monitor (`chromacal emulate --also`): the colorimeters read
//! through filters that are not the CIE functions, and the correction made against the
//! reference removes their error on patches held out of the fit, down to their noise.
//! The matrix is checked against ArgyllCMS: `ccxxmake` fed the same readings as
//! `.ti3` files, and `spotread -X` applying chromacal's `.ccmx`.

use std::path::{Path, PathBuf};

use chromacal::calibrate::correction::{PairedReading, pairs_path};
use chromacal_color::Xyz;
use chromacal_color::difference::delta_e_2000;
use chromacal_color::spaces::xyz_to_lab;
use chromacal_formats::ccmx::{parse_ccmx, read_ccmx};
use nalgebra::Matrix3;

mod common;
use common::argyll::SpotreadWrapper;
use common::{chromacal, isetbio_monitor, need_tool, succeed};

const TIME_SCALE: &str = "0.002";

/// `chromacal emulate` of a PR-670 with `colorimeters` beside it; their devices.
struct Bench {
    emulator: common::Emulator,
    colorimeters: Vec<(String, String)>,
}

fn emulate_bench(config: Option<&Path>, monitor: Option<&str>, colorimeters: &[&str]) -> Bench {
    use std::io::BufRead;
    let mut command = chromacal();
    command.args([
        "emulate",
        "--instrument",
        "pr670",
        "--time-scale",
        TIME_SCALE,
    ]);
    if let Some(c) = config {
        command.arg("--config").arg(c);
    }
    if let Some(m) = monitor {
        command.args(["--monitor", m]);
    }
    for c in colorimeters {
        command.args(["--also", c]);
    }
    let mut child = command
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let mut next = || lines.next().unwrap().unwrap();
    let device = next().trim_start_matches("device ").to_string();
    let screen = next().trim_start_matches("screen ").to_string();
    let colorimeters = colorimeters
        .iter()
        .map(|_| {
            let line = next();
            let mut words = line.split_whitespace().skip(1);
            (
                words.next().unwrap().to_string(),
                words.next().unwrap().to_string(),
            )
        })
        .collect();
    std::thread::spawn(move || lines.for_each(drop));
    Bench {
        emulator: common::Emulator {
            child,
            device,
            screen,
        },
        colorimeters,
    }
}

/// Run `correction make --json` for `colorimeter` (KIND:PORT); the fit's JSON.
fn make(bench: &Bench, colorimeter: &str, output: &Path, extra: &[&str]) -> serde_json::Value {
    let out = succeed(
        chromacal()
            .args(["correction", "make", "--json", "--timing-scale", TIME_SCALE])
            .args(["--reference", &format!("pr670:{}", bench.emulator.device)])
            .args(["--instrument", colorimeter])
            .args(["--screen", &bench.emulator.screen, "-o"])
            .arg(output)
            .args(extra),
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn mean(fit: &serde_json::Value, key: &str) -> f64 {
    fit[key]["mean"].as_f64().unwrap()
}

fn read_pairs(output: &Path) -> Vec<PairedReading> {
    std::fs::read_to_string(pairs_path(output))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// The first readings of the patches as ArgyllCMS `.ti3` (what `ccxxmake -f` reads):
/// the reference's, then the colorimeter's.
fn write_ti3(pairs: &[PairedReading], dir: &Path) -> (PathBuf, PathBuf) {
    let write = |name: &str, spectral: bool, instrument: &str| {
        let rows: Vec<&PairedReading> = pairs
            .iter()
            .filter(|p| p.patch.repeat_of.is_none())
            .collect();
        let mut text = format!(
            "CTI3\n\nDESCRIPTOR \"chromacal test\"\nORIGINATOR \"chromacal test\"\nDEVICE_CLASS \"DISPLAY\"\nCOLOR_REP \"RGB_XYZ\"\nTARGET_INSTRUMENT \"{instrument}\"\nINSTRUMENT_TYPE_SPECTRAL \"{}\"\nDISPLAY_TYPE_REFRESH \"NO\"\nDISPLAY_TYPE_BASE_ID \"1\"\n\nNUMBER_OF_FIELDS 7\nBEGIN_DATA_FORMAT\nSAMPLE_ID RGB_R RGB_G RGB_B XYZ_X XYZ_Y XYZ_Z\nEND_DATA_FORMAT\n\nNUMBER_OF_SETS {}\nBEGIN_DATA\n",
            if spectral { "YES" } else { "NO" },
            rows.len()
        );
        for (i, p) in rows.iter().enumerate() {
            let xyz = if spectral {
                p.reference.xyz
            } else {
                p.colorimeter.xyz
            }
            .unwrap();
            let d = p.patch.drive;
            text += &format!(
                "{} {:.4} {:.4} {:.4} {:.6} {:.6} {:.6}\n",
                i + 1,
                d[0] * 100.0,
                d[1] * 100.0,
                d[2] * 100.0,
                xyz.x,
                xyz.y,
                xyz.z
            );
        }
        text += "END_DATA\n";
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    (
        write("reference.ti3", true, "JETI specbos"),
        write("colorimeter.ti3", false, "Klein K-10"),
    )
}

/// ArgyllCMS `ccxxmake -f reference.ti3,colorimeter.ti3`, in a mount namespace
/// without ttys (its instrument scan would otherwise read every serial port).
fn ccxxmake(reference: &Path, colorimeter: &Path, output: &Path) {
    need_tool("ccxxmake", "argyll");
    let dev = output.with_extension("dev");
    std::fs::create_dir_all(&dev).unwrap();
    let script = format!(
        r#"set -e
mount --make-rprivate /
mount -t tmpfs tmpfs "{dev}"
for n in null urandom; do touch "{dev}/$n"; mount --bind "/dev/$n" "{dev}/$n"; done
mount --rbind "{dev}" /dev
exec ccxxmake -t l -E "chromacal test" -I "virtual LCD" -f "{r},{c}" "{o}""#,
        dev = dev.display(),
        r = reference.display(),
        c = colorimeter.display(),
        o = output.display()
    );
    succeed(
        std::process::Command::new("unshare")
            .args(["-m", "sh", "-c", &script])
            .stdin(std::process::Stdio::null()),
    );
}

#[test]
fn a_correction_made_against_the_reference_removes_the_filters_error_and_agrees_with_ccxxmake() {
    let dir = tempfile::tempdir().unwrap();
    let bench = emulate_bench(None, Some("lcd"), &["k10a"]);
    let (kind, device) = &bench.colorimeters[0];
    let output = dir.path().join("lcd-k10a.ccmx");
    let fit = make(&bench, &format!("{kind}:{device}"), &output, &[]);
    let (uncorrected, corrected, repeatability) = (
        mean(&fit, "held_out_uncorrected"),
        mean(&fit, "held_out_corrected"),
        mean(&fit, "colorimeter_repeatability"),
    );
    eprintln!(
        "K-10A on the LCD preset: held-out ΔE00 {uncorrected:.3} → {corrected:.3}, repeatability {repeatability:.3}"
    );
    assert!(corrected < 0.5 * uncorrected, "{fit}");
    assert!(corrected <= 1.5 * repeatability, "{fit}");

    // The file reads back, names what it was made with, and holds the fitted matrix.
    let ccmx = read_ccmx(&output).unwrap();
    assert!(ccmx.instrument.contains("K-10"), "{ccmx:?}");
    assert!(ccmx.reference.contains("PR-670"), "{ccmx:?}");
    let fitted = fit["matrix"].as_array().unwrap();
    assert!((ccmx.matrix[(0, 0)] - fitted[0].as_f64().unwrap()).abs() < 1e-6);

    // ccxxmake, fed the same readings, makes a matrix that predicts the same: the two
    // disagree by less than either's error against the reference.
    let pairs = read_pairs(&output);
    let (reference_ti3, colorimeter_ti3) = write_ti3(&pairs, dir.path());
    let argyll_output = dir.path().join("argyll.ccmx");
    ccxxmake(&reference_ti3, &colorimeter_ti3, &argyll_output);
    let argyll = parse_ccmx(
        &std::fs::read_to_string(&argyll_output).unwrap(),
        "argyll.ccmx",
    )
    .unwrap();
    let white = pairs[0].reference.xyz.unwrap();
    let disagreement: Vec<f64> = pairs
        .iter()
        .map(|p| {
            let c: Xyz = p.colorimeter.xyz.unwrap();
            delta_e_2000(
                &xyz_to_lab(&(ccmx.matrix * c), &white),
                &xyz_to_lab(&(argyll.matrix * c), &white),
            )
        })
        .collect();
    let mean_disagreement = disagreement.iter().sum::<f64>() / disagreement.len() as f64;
    eprintln!(
        "chromacal vs ccxxmake: mean ΔE00 {mean_disagreement:.3} between their predictions; fitted error {:.3}\nchromacal {}\nccxxmake {}",
        mean(&fit, "fitted_corrected"),
        ccmx.matrix,
        argyll.matrix
    );
    assert!(mean_disagreement < mean(&fit, "fitted_corrected"));
}

#[test]
fn spotread_applies_chromacals_ccmx() {
    let dir = tempfile::tempdir().unwrap();
    let bench = emulate_bench(None, Some("lcd"), &[]);
    // A correction that is plainly not the identity, within what is plausible.
    let m = Matrix3::new(1.10, 0.05, 0.0, -0.02, 0.95, 0.01, 0.0, 0.03, 1.05);
    let ccmx = chromacal_formats::ccmx::Ccmx {
        matrix: m,
        description: "test".into(),
        display: "virtual LCD".into(),
        instrument: "Klein K-10".into(),
        reference: "PR-670".into(),
        technology: "LCD".into(),
    };
    let file = dir.path().join("test.ccmx");
    std::fs::write(&file, chromacal_formats::ccmx::ccmx_text(&ccmx, "now")).unwrap();
    // The K-10A beside it, through ArgyllCMS, reads a white patch with and without it.
    drop(bench);
    let emulator = common::emulate(&[
        "--instrument",
        "k10a",
        "--monitor",
        "lcd",
        "--time-scale",
        "0.05",
    ]);
    let mut screen = std::os::unix::net::UnixStream::connect(&emulator.screen).unwrap();
    use std::io::{BufRead, Write};
    writeln!(
        screen,
        "{}",
        serde_json::json!({"content": {"patch": [0.9, 0.6, 0.3], "background": [0.0, 0.0, 0.0], "geometry": {"x": 0.4, "y": 0.4, "width": 0.2, "height": 0.2}}, "settle_s": 0.0})
    )
    .unwrap();
    let mut ok = String::new();
    std::io::BufReader::new(screen.try_clone().unwrap())
        .read_line(&mut ok)
        .unwrap();
    let wrapper = SpotreadWrapper::new(dir.path(), &emulator.device);
    let read = |config: Option<&Path>| -> Xyz {
        let mut command = chromacal();
        command
            .args([
                "measure",
                "--instrument",
                "argyll",
                "--count",
                "4",
                "--json",
            ])
            .env("CHROMACAL_SPOTREAD", &wrapper.path);
        if let Some(c) = config {
            command.arg("--config").arg(c);
        }
        let out = succeed(&mut command);
        let readings: Vec<chromacal_instruments::Reading> =
            serde_json::from_slice(&out.stdout).unwrap();
        readings.iter().map(|r| r.xyz.unwrap()).sum::<Xyz>() / readings.len() as f64
    };
    let plain = read(None);
    let config = dir.path().join("config.toml");
    std::fs::write(
        &config,
        "[instrument.options]\nargyll_correction = \"test.ccmx\"\n",
    )
    .unwrap();
    let corrected = read(Some(&config));
    let expected = m * plain;
    eprintln!("plain {plain:?}\ncorrected {corrected:?}\nM · plain {expected:?}");
    for k in 0..3 {
        assert!(
            (corrected[k] - expected[k]).abs() < 0.01 * expected[k].abs(),
            "{k}: {corrected:?} vs {expected:?}"
        );
        // And it did move: the matrix is 5-10 % off the identity.
        assert!((corrected[k] - plain[k]).abs() > 0.02 * plain[k].abs());
    }
}

#[test]
fn a_stopped_correction_resumes_from_its_readings() {
    let dir = tempfile::tempdir().unwrap();
    let bench = emulate_bench(None, Some("crt"), &["colorcal2"]);
    let (kind, device) = &bench.colorimeters[0];
    let colorimeter = format!("{kind}:{device}");
    let output = dir.path().join("crt.ccmx");
    make(&bench, &colorimeter, &output, &[]);
    let journal = pairs_path(&output);
    let all = std::fs::read_to_string(&journal).unwrap();
    let kept: String = all.lines().take(10).map(|l| format!("{l}\n")).collect();
    // Ten pairs and half of the eleventh, as a crash leaves it.
    let torn = &all.lines().nth(10).unwrap()[..40];
    std::fs::write(&journal, format!("{kept}{torn}")).unwrap();
    std::fs::remove_file(&output).unwrap();

    // Without --resume the readings are not thrown away: the run refuses.
    let out = chromacal()
        .args(["correction", "make", "--timing-scale", TIME_SCALE])
        .args(["--reference", &format!("pr670:{}", bench.emulator.device)])
        .args([
            "--instrument",
            &colorimeter,
            "--screen",
            &bench.emulator.screen,
            "-o",
        ])
        .arg(&output)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("--resume"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(&journal).unwrap(),
        format!("{kept}{torn}")
    );

    make(&bench, &colorimeter, &output, &["--resume"]);
    let after = std::fs::read_to_string(&journal).unwrap();
    assert!(after.starts_with(&kept));
    assert_eq!(after.lines().count(), all.lines().count());
    assert!(read_ccmx(&output).is_ok());
}

/// The bench table: each emulated colorimeter on virtual monitors made of ISETBio's
/// measured CRT, LCD and OLED spectra, uncorrected and corrected held-out ΔE00.
#[test]
fn corrections_on_real_display_spectra_reach_the_colorimeters_noise() {
    let dir = tempfile::tempdir().unwrap();
    let mut rows = Vec::new();
    for (name, stem) in [
        ("CRT (ISETBio Dell)", "isetbio_crt_dell"),
        ("LCD (ISETBio Dell)", "isetbio_lcd_dell"),
        ("OLED (ISETBio Sony)", "isetbio_oled_sony"),
    ] {
        let config = dir.path().join(format!("{stem}.toml"));
        std::fs::write(&config, isetbio_monitor(stem, "")).unwrap();
        let bench = emulate_bench(Some(&config), None, &["k10a", "cs100a", "colorcal2"]);
        for (kind, device) in &bench.colorimeters {
            let output = dir.path().join(format!("{stem}-{kind}.ccmx"));
            let fit = make(&bench, &format!("{kind}:{device}"), &output, &[]);
            let (u, c, r) = (
                mean(&fit, "held_out_uncorrected"),
                mean(&fit, "held_out_corrected"),
                mean(&fit, "colorimeter_repeatability"),
            );
            rows.push(format!("{name:<22} {kind:<10} {u:>8.3} {c:>8.3} {r:>8.3}"));
            assert!(
                c <= 1.5 * r,
                "{name} {kind}: corrected {c} vs repeatability {r}"
            );
            assert!(c < u, "{name} {kind}: {u} → {c}");
        }
    }
    eprintln!(
        "display                colorimeter  uncorr.  correct.  repeat.  (held-out mean ΔE00)\n{}",
        rows.join("\n")
    );
}

/// `chromacal bench corrections` prints the table in process (in-memory emulators on
/// virtual time): nine rows, every correction within 1.5 × the colorimeter's
/// repeatability and below the uncorrected error.
#[test]
fn the_corrections_bench_prints_its_table() {
    let out = succeed(chromacal().args(["bench", "corrections", "--quick"]));
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<Vec<&str>> = text
        .lines()
        .filter(|l| l.contains("(ISETBio"))
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert_eq!(rows.len(), 9, "{text}");
    for row in rows {
        let n = row.len();
        let (uncorrected, corrected, ratio): (f64, f64, f64) = (
            row[n - 5].parse().unwrap(),
            row[n - 4].parse().unwrap(),
            row[n - 2].parse().unwrap(),
        );
        assert!(corrected < uncorrected && ratio <= 1.5, "{row:?}");
    }
}
