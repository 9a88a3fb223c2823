//! `chromacal bench render`: the colour reproduction function's speed against its
//! error, beside two colour management systems doing the same transform with
//! chromacal's exported ICC profile: moxcms (pure Rust) and Little CMS (the `lcms2`
//! crate over the C library).
//!
//! The scene is a 2048 × 2048 XYZ image (4.2 megapixels) of colours inside the
//! display's gamut. The ICC profile carries the matrix and the curves, not the spatial
//! map, so the tools are compared on that part (every pixel at the centre); chromacal
//! also renders the image over the whole screen through the spatial map. Each tool's
//! codes (16 bits) are judged by chromacal's exact model: the ΔE00 between the colour
//! asked for and what the display shows for them.

use std::time::Instant;

use rayon::prelude::*;

use chromacal::color::Xyz;
use chromacal::color::adaptation::{AdaptationTransform, adaptation_matrix};
use chromacal::crf::ColourReproduction;
use chromacal::export::{ExportOptions, Format, export};
use chromacal::fit::stats::ErrorStats;
use chromacal::fit::validate::delta_e00_xyz;
use chromacal::model::spatial::SpatialMap;
use chromacal::model::{MonitorModel, ScreenPosition};
use chromacal::profile::Profile;
use chromacal::report::table;

/// Side of the square image.
const SIDE: usize = 2048;
/// Pixels whose error is computed (a spread sample; the time covers them all).
const ERROR_SAMPLE: usize = 20_000;

const D50: [f64; 3] = [0.9642, 1.0, 0.8249];

/// Calibrate the simulated default into a temporary state directory and return its
/// profile (the bench runs this very program, as a user would).
fn default_profile() -> Result<Profile, String> {
    let state = std::env::temp_dir().join(format!("chromacal-bench-render-{}", std::process::id()));
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let out = std::process::Command::new(exe)
        .args(["calibrate", "--state-dir"])
        .arg(&state)
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(format!(
            "the calibration for the bench failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let profile = Profile::read(&state.join("current.toml")).map_err(|e| e.to_string());
    let _ = std::fs::remove_dir_all(&state);
    profile
}

/// A seeded spread of drives inside the cube (away from its faces, so every colour is
/// inside the gamut everywhere on the screen).
fn drives(n: usize) -> Vec<[f64; 3]> {
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        0.05 + 0.8 * (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n).map(|_| [next(), next(), next()]).collect()
}

struct Row {
    tool: String,
    cores: String,
    pixels_per_second: f64,
    error: ErrorStats,
}

/// Time `work` over the image (best of `repeats`), in pixels per second.
fn throughput(repeats: usize, mut work: impl FnMut()) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let start = Instant::now();
        work();
        best = best.min(start.elapsed().as_secs_f64());
    }
    (SIDE * SIDE) as f64 / best
}

/// ΔE00 of the codes (0–1) at a sample of pixels, judged by `model`.
fn error_of(
    model: &MonitorModel,
    asked: &[Xyz],
    positions: &dyn Fn(usize) -> ScreenPosition,
    drive: &dyn Fn(usize) -> [f64; 3],
) -> ErrorStats {
    let white = model.white();
    let step = (asked.len() / ERROR_SAMPLE).max(1);
    let errors: Vec<f64> = (0..asked.len())
        .step_by(step)
        .map(|k| {
            let d = drive(k).map(|v| (v * 65535.0).round().clamp(0.0, 65535.0) / 65535.0);
            delta_e00_xyz(&asked[k], &model.forward(d, positions(k)), &white)
        })
        .collect();
    ErrorStats::of(&errors).unwrap_or(ErrorStats {
        n: 0,
        mean: f64::NAN,
        p95: f64::NAN,
        max: f64::NAN,
    })
}

pub fn render_table(quick: bool) -> Result<(), String> {
    let repeats = if quick { 1 } else { 3 };
    let profile = default_profile()?;
    let full = profile.model.clone();
    let centre_only = MonitorModel {
        spatial: SpatialMap::Uniform,
        ..full.clone()
    };
    let n = SIDE * SIDE;
    let asked_centre: Vec<Xyz> = drives(n)
        .into_iter()
        .map(|d| centre_only.forward(d, ScreenPosition::CENTRE))
        .collect();
    let at = |k: usize| {
        ScreenPosition::new(
            ((k % SIDE) as f64 + 0.5) / SIDE as f64,
            ((k / SIDE) as f64 + 0.5) / SIDE as f64,
        )
    };
    let asked_screen: Vec<Xyz> = drives(n)
        .into_iter()
        .enumerate()
        .map(|(k, d)| full.forward(d, at(k)))
        .collect();
    let centre = |_: usize| ScreenPosition::CENTRE;
    let mut rows = Vec::new();
    let mut codes = vec![[0u16; 3]; n];
    let to_codes = |d: [f64; 3]| d.map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16);
    let from_codes = |c: [u16; 3]| c.map(|v| v as f64 / 65535.0);

    // chromacal, the part an ICC profile carries (laws inverted exactly, then by
    // their tables, as `render` does), then the whole model.
    let crf = ColourReproduction::new(&centre_only).map_err(|e| e.to_string())?;
    let exact = throughput(repeats, || {
        for (c, x) in codes.iter_mut().zip(&asked_centre) {
            *c = to_codes(crf.drive_exact_for(x, ScreenPosition::CENTRE));
        }
    });
    let error = error_of(&full, &asked_centre, &centre, &|k| from_codes(codes[k]));
    rows.push(Row {
        tool: "chromacal (matrix and laws, each law inverted exactly)".into(),
        cores: "1".into(),
        pixels_per_second: exact,
        error,
    });
    let chunk = 4096;
    let one = throughput(repeats, || {
        crf.codes16(&asked_centre, centre, &mut codes);
    });
    let error = error_of(&full, &asked_centre, &centre, &|k| from_codes(codes[k]));
    rows.push(Row {
        tool: "chromacal (matrix and laws, tabulated inverse)".into(),
        cores: "1".into(),
        pixels_per_second: one,
        error,
    });
    let all = throughput(repeats, || {
        codes
            .par_chunks_mut(chunk)
            .zip(asked_centre.par_chunks(chunk))
            .for_each(|(c, x)| crf.codes16(x, centre, c));
    });
    let error = error_of(&full, &asked_centre, &centre, &|k| from_codes(codes[k]));
    rows.push(Row {
        tool: "chromacal (matrix and laws, tabulated inverse)".into(),
        cores: format!("{}", rayon::current_num_threads()),
        pixels_per_second: all,
        error,
    });
    let whole = ColourReproduction::new(&full).map_err(|e| e.to_string())?;
    for parallel in [false, true] {
        let speed = throughput(repeats, || {
            if parallel {
                codes
                    .par_chunks_mut(chunk)
                    .zip(asked_screen.par_chunks(chunk))
                    .enumerate()
                    .for_each(|(i, (c, x))| whole.codes16(x, |k| at(i * chunk + k), c));
            } else {
                whole.codes16(&asked_screen, at, &mut codes);
            }
        });
        let error = error_of(&full, &asked_screen, &at, &|k| from_codes(codes[k]));
        rows.push(Row {
            tool: "chromacal (with the spatial map, whole screen)".into(),
            cores: if parallel {
                format!("{}", rayon::current_num_threads())
            } else {
                "1".into()
            },
            pixels_per_second: speed,
            error,
        });
    }

    // The same colours as the ICC profile's connection space sees them: relative to
    // the display's white, adapted to D50 (Bradford), as the v4 profile's chad says.
    let exported = export(
        &Profile {
            model: centre_only.clone(),
            ..profile.clone()
        },
        Format::Icc4,
        &ExportOptions {
            target: None,
            measurements: None,
        },
    )
    .map_err(|e| e.to_string())?;
    let white = centre_only.white();
    let chad = adaptation_matrix(
        AdaptationTransform::Bradford,
        &(white / white.y),
        &Xyz::from(D50),
    );
    let pcs: Vec<[f64; 3]> = asked_centre
        .iter()
        .map(|x| (chad * (x / white.y)).into())
        .collect();
    rows.push(moxcms_row(
        &exported.bytes,
        &pcs,
        repeats,
        &full,
        &asked_centre,
    )?);
    rows.push(lcms_row(
        &exported.bytes,
        &pcs,
        repeats,
        &full,
        &asked_centre,
    )?);

    let ours = rows[1].pixels_per_second;
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.tool.clone(),
                r.cores.clone(),
                format!("{:.1}", r.pixels_per_second / 1e6),
                format!("{:.2}", ours / r.pixels_per_second),
                format!("{:.4} / {:.4}", r.error.mean, r.error.max),
            ]
        })
        .collect();
    println!(
        "XYZ → display codes (16 bits), {SIDE} × {SIDE} = {:.1} megapixels, colours inside the gamut; ΔE00 judged by chromacal's exact model on {} pixels\n",
        n as f64 / 1e6,
        rows[0].error.n
    );
    println!(
        "{}",
        table(
            &[
                "tool",
                "cores",
                "Mpixel/s",
                "chromacal 1 core ÷ this",
                "ΔE00 mean / max",
            ],
            &cells
        )
    );
    Ok(())
}

/// moxcms: a source profile whose "RGB" is PCS XYZ itself (identity colorants,
/// linear curves), to the display's profile, 32-bit float.
fn moxcms_row(
    icc: &[u8],
    pcs: &[[f64; 3]],
    repeats: usize,
    model: &MonitorModel,
    asked: &[Xyz],
) -> Result<Row, String> {
    use moxcms::{ColorProfile, Layout, ToneReprCurve, TransformOptions, Xyzd};
    let display = ColorProfile::new_from_slice(icc).map_err(|e| format!("moxcms: {e:?}"))?;
    let mut source = ColorProfile::new_srgb();
    source.cicp = None;
    source.red_colorant = Xyzd::new(1.0, 0.0, 0.0);
    source.green_colorant = Xyzd::new(0.0, 1.0, 0.0);
    source.blue_colorant = Xyzd::new(0.0, 0.0, 1.0);
    let linear = ToneReprCurve::Parametric(vec![1.0]);
    source.red_trc = Some(linear.clone());
    source.green_trc = Some(linear.clone());
    source.blue_trc = Some(linear);
    source.media_white_point = Some(Xyzd::new(D50[0], D50[1], D50[2]));
    let transform = source
        .create_transform_f32(
            Layout::Rgb,
            &display,
            Layout::Rgb,
            TransformOptions::default(),
        )
        .map_err(|e| format!("moxcms: {e:?}"))?;
    let input: Vec<f32> = pcs.iter().flat_map(|p| p.map(|v| v as f32)).collect();
    let mut output = vec![0f32; input.len()];
    let speed = throughput(repeats, || {
        let _ = transform.transform(&input, &mut output);
    });
    transform
        .transform(&input, &mut output)
        .map_err(|e| format!("moxcms: {e:?}"))?;
    let error = error_of(model, asked, &|_| ScreenPosition::CENTRE, &|k| {
        [0, 1, 2].map(|c| f64::from(output[3 * k + c]))
    });
    Ok(Row {
        tool: "moxcms 0.8 (the exported ICC v4, f32)".into(),
        cores: "1".into(),
        pixels_per_second: speed,
        error,
    })
}

/// Little CMS: its built-in XYZ profile (doubles, Y = 1 at white) to the display's
/// profile, relative colorimetric, doubles out.
fn lcms_row(
    icc: &[u8],
    pcs: &[[f64; 3]],
    repeats: usize,
    model: &MonitorModel,
    asked: &[Xyz],
) -> Result<Row, String> {
    use lcms2::{Intent, PixelFormat, Profile as LcmsProfile, Transform};
    let display = LcmsProfile::new_icc(icc).map_err(|e| format!("Little CMS: {e}"))?;
    let xyz = LcmsProfile::new_xyz();
    let transform: Transform<[f64; 3], [f64; 3]> = Transform::new(
        &xyz,
        PixelFormat::XYZ_DBL,
        &display,
        PixelFormat::RGB_DBL,
        Intent::RelativeColorimetric,
    )
    .map_err(|e| format!("Little CMS: {e}"))?;
    let mut output = vec![[0f64; 3]; pcs.len()];
    let speed = throughput(repeats, || transform.transform_pixels(pcs, &mut output));
    let error = error_of(model, asked, &|_| ScreenPosition::CENTRE, &|k| output[k]);
    Ok(Row {
        // Little CMS numbers its versions as 1000 × major + 10 × minor: 2190 is 2.19.
        tool: format!(
            "Little CMS {}.{} (the exported ICC v4, double)",
            lcms2::version() / 1000,
            lcms2::version() % 1000 / 10
        ),
        cores: "1".into(),
        pixels_per_second: speed,
        error,
    })
}
