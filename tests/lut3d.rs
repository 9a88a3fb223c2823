//! `chromacal lut3d` read by an independent reader: ffmpeg's `lut3d` filter applies
//! the `.cube` (and the `.3dl`) to a 16-bit image of 1,000 source colours, and what the
//! display shows for its output codes (the profile's forward model) is compared with
//! the colour each source code stands for, computed here from the standards
//! (BT.1886's EOTF, the BT.709 matrix, Bradford to the display's white).

mod common;

use std::path::Path;

use chromacal::profile::Profile;
use chromacal_color::Xyz;
use chromacal_color::adaptation::{AdaptationTransform, adapt};
use chromacal_crf::ColourReproduction;
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::{MonitorModel, ScreenPosition};
use common::images::{ffmpeg_lut3d, write_png16};
use common::{chromacal, succeed};

/// The simulated LCD, calibrated with the fixed plan: its profile.
fn lcd_profile(dir: &Path) -> std::path::PathBuf {
    let config = dir.join("config.toml");
    std::fs::write(
        &config,
        format!("[monitor]\npreset = \"lcd\"\n{}", common::FIXED_PLAN),
    )
    .unwrap();
    succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(dir.join("state")),
    );
    dir.join("state/current.toml")
}

/// 1,000 source code triples: a seeded spread over the cube, its corners included.
fn source_codes() -> Vec<[u16; 3]> {
    let mut state = 0x2545_f491_u64;
    let mut next = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) % 65536) as u16
    };
    let mut codes: Vec<[u16; 3]> = (0..8)
        .map(|k| [0, 1, 2].map(|c| if k >> c & 1 == 1 { 65535 } else { 0 }))
        .collect();
    while codes.len() < 1000 {
        codes.push([next(), next(), next()]);
    }
    codes
}

/// What BT.709 code `rgb` stands for on this display (ITU-R BT.1886 Annex 1 with the
/// display's white and black; the BT.709 / sRGB matrix of IEC 61966-2-1 eq. 5's
/// inverse; Bradford from D65 to the display's white), in the model's units.
fn bt1886_target(rgb: [u16; 3], model: &MonitorModel) -> Xyz {
    let white = model.white();
    let (lw, lb) = (1.0_f64, model.black.y / white.y);
    let a = (lw.powf(1.0 / 2.4) - lb.powf(1.0 / 2.4)).powf(2.4);
    let b = lb.powf(1.0 / 2.4) / (lw.powf(1.0 / 2.4) - lb.powf(1.0 / 2.4));
    let linear = rgb.map(|v| a * (f64::from(v) / 65535.0 + b).max(0.0).powf(2.4));
    let m = nalgebra::Matrix3::new(
        0.4124, 0.3576, 0.1805, //
        0.2126, 0.7152, 0.0722, //
        0.0193, 0.1192, 0.9505,
    );
    let xyz = m * Xyz::new(linear[0], linear[1], linear[2]);
    let d65 = m * Xyz::new(1.0, 1.0, 1.0);
    adapt(
        &xyz,
        AdaptationTransform::Bradford,
        &d65,
        &(white / white.y),
    ) * white.y
}

/// ΔE00 of what the display shows for each output against each target, over the
/// targets inside the display's gamut: (mean, max, how many inside).
fn in_gamut_errors(
    model: &MonitorModel,
    codes: &[[u16; 3]],
    out: &[[u16; 3]],
) -> (f64, f64, usize) {
    let crf = ColourReproduction::new(model).unwrap();
    let white = model.white();
    let errors: Vec<f64> = codes
        .iter()
        .zip(out)
        .filter_map(|(c, o)| {
            let target = bt1886_target(*c, model);
            let drive = crf.drive_exact_for(&target, ScreenPosition::CENTRE);
            // Inside: the exact drive within the cube (and not at its very edge,
            // where the target is the boundary itself).
            if !drive.iter().all(|d| (1e-3..=1.0 - 1e-3).contains(d)) {
                return None;
            }
            let shown = model.forward(o.map(|v| f64::from(v) / 65535.0), ScreenPosition::CENTRE);
            Some(delta_e00_xyz(&target, &shown, &white))
        })
        .collect();
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    (
        mean,
        errors.iter().copied().fold(0.0, f64::max),
        errors.len(),
    )
}

#[test]
fn ffmpeg_applies_the_cube_and_the_display_shows_the_bt1886_colours() {
    let dir = tempfile::tempdir().unwrap();
    let profile_path = lcd_profile(dir.path());
    let model = Profile::read(&profile_path).unwrap().model;
    let codes = source_codes();
    let image = dir.path().join("colours.png");
    write_png16(&image, 40, &codes);

    let mut results = Vec::new();
    for size in [65, 33] {
        let cube = dir.path().join(format!("lcd{size}.cube"));
        let out = succeed(
            chromacal()
                .arg("lut3d")
                .arg(&profile_path)
                .args(["--source", "bt1886", "--size", &size.to_string(), "-o"])
                .arg(&cube),
        );
        let said = String::from_utf8_lossy(&out.stderr);
        assert!(
            said.contains(&format!("{size}³ LUT from BT.709 through BT.1886")),
            "{said}"
        );
        let text = std::fs::read_to_string(&cube).unwrap();
        assert!(text.contains(&format!("LUT_3D_SIZE {size}\n")));
        let shown = ffmpeg_lut3d(&image, &cube, &dir.path().join(format!("out{size}.png")));
        assert_eq!(shown.len(), codes.len());
        results.push((size, in_gamut_errors(&model, &codes, &shown)));
    }
    eprintln!("in-gamut ΔE00 (mean, max, colours): {results:?}");
    let (_, (mean65, max65, inside)) = results[0];
    assert!(
        inside > 300,
        "only {inside} of 1000 colours inside the gamut"
    );
    assert!(
        max65 < 0.5 && mean65 < 0.1,
        "65³: mean {mean65}, max {max65}"
    );
    // The coarser grid interpolates over wider cells: worse, and not by a little.
    let (_, (mean33, _, _)) = results[1];
    assert!(mean33 > mean65, "33³ {mean33} against 65³ {mean65}");
}

#[test]
fn ffmpeg_reads_the_3dl_as_the_cube_of_the_same_grid() {
    let dir = tempfile::tempdir().unwrap();
    let profile_path = lcd_profile(dir.path());
    let codes = source_codes();
    let image = dir.path().join("colours.png");
    write_png16(&image, 40, &codes);
    // ffmpeg reads a .3dl as 17 points a side, 12 bits (over 4096).
    let mut outputs = Vec::new();
    // The .3dl at its default size, the .cube asked for the same.
    for (name, size) in [("lcd.3dl", &[][..]), ("lcd.cube", &["--size", "17"][..])] {
        let lut = dir.path().join(name);
        let out = succeed(
            chromacal()
                .arg("lut3d")
                .arg(&profile_path)
                .args(["--source", "srgb"])
                .args(size)
                .arg("-o")
                .arg(&lut),
        );
        assert!(String::from_utf8_lossy(&out.stderr).contains("17³ LUT"));
        outputs.push(ffmpeg_lut3d(
            &image,
            &lut,
            &dir.path().join(format!("{name}.png")),
        ));
    }
    for (a, b) in outputs[0].iter().zip(&outputs[1]) {
        for c in 0..3 {
            // 12-bit steps, and ffmpeg's 4096 where the format's top is 4095.
            let apart = (i32::from(a[c]) - i32::from(b[c])).abs();
            assert!(apart <= 48, "{a:?} against {b:?}");
        }
    }
}

#[test]
fn a_lut_through_calibration_needs_curves_and_a_bad_name_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let profile_path = lcd_profile(dir.path());
    let out = chromacal()
        .arg("lut3d")
        .arg(&profile_path)
        .args(["--source", "p3", "--through-calibration", "-o"])
        .arg(dir.path().join("x.cube"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("the profile has none"), "{said}");
    for (args, expected) in [
        (
            vec!["--source", "srgb", "-o", "x.lut"],
            "name the LUT .cube or .3dl",
        ),
        (
            vec!["--source", "adobe", "-o", "x.cube"],
            "no source space 'adobe'",
        ),
        (
            vec!["--source", "srgb", "--gamut", "scb", "-o", "x.cube"],
            "Stone–Cowan–Beatty",
        ),
        (
            vec!["--source", "srgb", "--size", "1", "-o", "x.cube"],
            "a LUT of 1 points",
        ),
        (
            vec![
                "--source",
                "srgb",
                "--gamut",
                "sgck",
                "--absolute",
                "-o",
                "x.cube",
            ],
            "SGCK maps from the source space",
        ),
    ] {
        let out = chromacal()
            .current_dir(dir.path())
            .arg("lut3d")
            .arg(&profile_path)
            .args(&args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        let said = String::from_utf8_lossy(&out.stderr);
        assert!(said.contains(expected), "{args:?}: {said}");
        assert!(!dir.path().join("x.cube").exists() && !dir.path().join("x.lut").exists());
    }
}

/// The `.cube`'s output triples, in file order (red fastest).
fn cube_rows(path: &Path) -> Vec<[f64; 3]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .map(str::parse)
                .collect::<Result<_, _>>()
                .ok()?;
            (v.len() == 3).then(|| [v[0], v[1], v[2]])
        })
        .collect()
}

#[test]
fn sgck_keeps_rec2020_reds_apart_where_clipping_merges_them() {
    let dir = tempfile::tempdir().unwrap();
    let profile_path = lcd_profile(dir.path());
    let size = 17;
    let lut = |gamut: &str| {
        let path = dir.path().join(format!("{gamut}.cube"));
        succeed(
            chromacal()
                .arg("lut3d")
                .arg(&profile_path)
                .args([
                    "--source", "rec2020", "--size", "17", "--gamut", gamut, "-o",
                ])
                .arg(&path),
        );
        let rows = cube_rows(&path);
        assert_eq!(rows.len(), size * size * size);
        rows
    };
    // The red axis (green and blue at code 0) from half drive up: Rec. 2020's reds
    // beyond the display's.
    let distinct = |rows: &[[f64; 3]]| {
        let mut seen: Vec<[i64; 3]> = (size / 2..size)
            .map(|i| rows[i].map(|v| (v * 1e4).round() as i64))
            .collect();
        seen.dedup();
        seen.len()
    };
    let (clip, sgck) = (lut("clip"), lut("sgck"));
    let top = size - size / 2;
    assert!(
        distinct(&clip) < top,
        "clipping kept {} of {top} apart",
        distinct(&clip)
    );
    assert_eq!(distinct(&sgck), top, "SGCK merged reds");
    // Along the axis SGCK's red drive never falls.
    for i in 1..size {
        assert!(sgck[i][0] >= sgck[i - 1][0] - 1e-9, "red falls at {i}");
    }
}

/// The usual desk set-up: calibration curves in the video card, a 3D LUT in the
/// player. Calibrated to D65 at 80 cd/m² (the simulated CRT's own white is near 8300 K
/// at 100), the LUT made `--through-calibration`, applied by ffmpeg to a ramp of sRGB
/// greys 16 to 235 (at 16 bits), and the codes it gives shown through the curves:
/// every grey keeps a* and b* within 0.5 of the calibrated white's, with and without
/// `--absolute` (the source's white is D65, the white the curves make). The grey was
/// turned blue by some 7 ΔE when the source white was carried to the native white.
#[test]
fn greys_through_a_lut_and_the_calibration_curves_stay_neutral() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    // A 10-bit panel, the curves set at its depth: what the LUT's interpolation is
    // judged on here is continuous, and at 8 bits the greys' own steps (the best an
    // 8-bit panel can show, some tenths of b*) would be judged with it.
    std::fs::write(
        &config,
        "[monitor]\nbit_depth = 10\n[target]\nwhite = \"D65\"\ntone = \"gamma:2.2\"\nluminance = 80.0\nbit_depth = 10\n",
    )
    .unwrap();
    let state = dir.path().join("state");
    succeed(
        chromacal()
            .arg("calibrate")
            .arg("--config")
            .arg(&config)
            .arg("--state-dir")
            .arg(&state),
    );
    let profile = Profile::read(&state.join("current.toml")).unwrap();
    let calibration = profile.calibration.as_ref().expect("curves to D65");
    let curves = &calibration.curves;
    let white = Xyz::new(curves.white[0], curves.white[1], curves.white[2]);
    // sRGB greys 16…235 in 8-bit steps of 1, at 16 bits (code × 257).
    let greys: Vec<[u16; 3]> = (16..=235u16).map(|g| [g * 257; 3]).collect();
    let image = dir.path().join("greys.png");
    write_png16(&image, greys.len() as u32, &greys);
    for absolute in [false, true] {
        let cube = dir.path().join(format!("through-{absolute}.cube"));
        let mut command = chromacal();
        command.arg("lut3d").arg(state.join("current.toml")).args([
            "--source",
            "srgb",
            "--size",
            "33",
            "--through-calibration",
        ]);
        if absolute {
            command.arg("--absolute");
        }
        succeed(command.arg("-o").arg(&cube));
        let shown = ffmpeg_lut3d(
            &image,
            &cube,
            &dir.path().join(format!("out-{absolute}.png")),
        );
        let mut worst: f64 = 0.0;
        for (grey, codes) in greys.iter().zip(&shown) {
            let input = codes.map(|c| f64::from(c) / 65535.0);
            let drive = curves.apply(input);
            let xyz = profile.model.forward(drive, ScreenPosition::CENTRE);
            let lab = chromacal_color::xyz_to_lab(&xyz, &white);
            let off = lab.a.abs().max(lab.b.abs());
            assert!(
                off <= 0.5,
                "absolute {absolute}: sRGB grey {} shows a* {:.2}, b* {:.2} (L* {:.1})",
                grey[0] / 257,
                lab.a,
                lab.b,
                lab.l
            );
            worst = worst.max(off);
        }
        eprintln!("absolute {absolute}: greys 16–235 within {worst:.3} of neutral");
    }
}
