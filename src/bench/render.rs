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

use std::fmt::Write as _;

use super::{BenchError, Tables};
use std::cell::RefCell;
#[cfg(feature = "peer-engines")]
use std::rc::Rc;
use std::time::Instant;

use rayon::prelude::*;

use crate::profile::Profile;
use crate::report::table;
use chromacal_color::Xyz;
use chromacal_crf::gamut::GamutMapping;
use chromacal_crf::tone::ToneOperator;
use chromacal_crf::{CodeChoice, ColourReproduction, RenderSettings, Scene, ScenePixel};
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::spatial::SpatialMap;
use chromacal_model::{MonitorModel, ScreenPosition};

/// Side of the square image.
const SIDE: usize = 2048;
/// Pixels whose error is computed (a spread sample; the time covers them all).
const ERROR_SAMPLE: usize = 20_000;

/// The ICC profile connection space's white (ISO 15076-1 §7.2.16).
#[cfg(feature = "peer-engines")]
const D50: [f64; 3] = [0.9642, 1.0, 0.8249];

/// Calibrate the simulated default into a temporary state directory and return its
/// profile (the bench runs this very program, as a user would).
pub(super) fn default_profile() -> Result<Profile, String> {
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

/// Rounds the tools are timed over, each tool once a round beside the reference, in an
/// order that turns round by round: one machine's background load then lands on every
/// tool alike, and each ratio is taken between neighbouring samples. Timed one after another, once each, the ratio
/// to moxcms swung from 0.69 to 1.30 across four runs on a quiet machine.
const ROUNDS: usize = 11;

/// Shortest time one sample of a tool takes: passes are repeated until it is reached,
/// so a fast tool's sample is not one 40 ms pass at the mercy of the scheduler.
const MIN_SAMPLE_S: f64 = 0.3;

/// A tool as timed: one pass over the image, and the ΔE00 of what its last pass gave.
struct Tool<'a> {
    name: String,
    cores: String,
    run: Box<dyn FnMut() + 'a>,
    error: Box<dyn Fn() -> ErrorStats + 'a>,
}

/// Seconds of one sample of `tool`: passes repeated until `MIN_SAMPLE_S`, per pass.
fn sample(tool: &mut Tool<'_>) -> f64 {
    let start = Instant::now();
    let mut passes = 0;
    while passes == 0 || start.elapsed().as_secs_f64() < MIN_SAMPLE_S {
        (tool.run)();
        passes += 1;
    }
    start.elapsed().as_secs_f64() / passes as f64
}

/// Each tool's seconds a pass and its time over the reference's (tool 0), round by
/// round: `(seconds[round][tool], ratios[round][tool])`. Within a round every tool is
/// sampled next to a sample of the reference (before it in even rounds, after it in
/// odd ones), in an order that turns round by round, so each ratio is of two tools
/// timed under the same load.
fn interleaved_rounds(tools: &mut [Tool<'_>], rounds: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let n = tools.len();
    let mut seconds = vec![vec![0.0; n]; rounds];
    let mut ratios = vec![vec![1.0; n]; rounds];
    for round in 0..rounds {
        let mut reference = Vec::new();
        for i in 0..n.saturating_sub(1) {
            let t = 1 + (i + round) % (n - 1);
            let (r, s) = if round % 2 == 0 {
                let r = sample(&mut tools[0]);
                (r, sample(&mut tools[t]))
            } else {
                let s = sample(&mut tools[t]);
                (sample(&mut tools[0]), s)
            };
            reference.push(r);
            seconds[round][t] = s;
            ratios[round][t] = s / r;
        }
        seconds[round][0] = reference.iter().sum::<f64>() / reference.len().max(1) as f64;
    }
    (seconds, ratios)
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

pub(super) fn render_table(out: &mut Tables, quick: bool) -> Result<(), BenchError> {
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
    let to_codes = |d: [f64; 3]| d.map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16);
    let from_codes = |c: [u16; 3]| c.map(|v| v as f64 / 65535.0);
    let chunk = 4096;
    let threads = format!("{}", rayon::current_num_threads());

    // chromacal, the part an ICC profile carries (laws inverted exactly, then by
    // their tables, as `render` does), then the whole model.
    let crf = ColourReproduction::new(&centre_only).map_err(|e| e.to_string())?;
    let whole = ColourReproduction::new(&full).map_err(|e| e.to_string())?;
    let codes_buffer = || RefCell::new(vec![[0u16; 3]; n]);
    let buffers: Vec<RefCell<Vec<[u16; 3]>>> = (0..6).map(|_| codes_buffer()).collect();
    let judged = |codes: &RefCell<Vec<[u16; 3]>>, asked: &[Xyz], on_screen: bool| {
        let codes = codes.borrow();
        if on_screen {
            error_of(&full, asked, &at, &|k| from_codes(codes[k]))
        } else {
            error_of(&full, asked, &centre, &|k| from_codes(codes[k]))
        }
    };
    // The same colours as 32-bit floats, as moxcms is given them.
    let asked_f32: Vec<[f32; 3]> = asked_centre
        .iter()
        .map(|x| [x.x as f32, x.y as f32, x.z as f32])
        .collect();
    let mut tools: Vec<Tool<'_>> = Vec::new();
    tools.push(Tool {
        name: "chromacal (matrix and laws, tabulated inverse, f32 XYZ)".into(),
        cores: "1".into(),
        run: Box::new(|| crf.codes16_f32(&asked_f32, centre, &mut buffers[5].borrow_mut())),
        error: Box::new(|| judged(&buffers[5], &asked_centre, false)),
    });
    tools.push(Tool {
        name: "chromacal (matrix and laws, tabulated inverse, f64 XYZ)".into(),
        cores: "1".into(),
        run: Box::new(|| crf.codes16(&asked_centre, centre, &mut buffers[0].borrow_mut())),
        error: Box::new(|| judged(&buffers[0], &asked_centre, false)),
    });
    tools.push(Tool {
        name: "chromacal (matrix and laws, each law inverted exactly)".into(),
        cores: "1".into(),
        run: Box::new(|| {
            for (c, x) in buffers[1].borrow_mut().iter_mut().zip(&asked_centre) {
                *c = to_codes(crf.drive_exact_for(x, ScreenPosition::CENTRE));
            }
        }),
        error: Box::new(|| judged(&buffers[1], &asked_centre, false)),
    });
    tools.push(Tool {
        name: "chromacal (matrix and laws, tabulated inverse)".into(),
        cores: threads.clone(),
        run: Box::new(|| {
            buffers[2]
                .borrow_mut()
                .par_chunks_mut(chunk)
                .zip(asked_centre.par_chunks(chunk))
                .for_each(|(c, x)| crf.codes16(x, centre, c));
        }),
        error: Box::new(|| judged(&buffers[2], &asked_centre, false)),
    });
    tools.push(Tool {
        name: "chromacal (with the spatial map, whole screen)".into(),
        cores: "1".into(),
        run: Box::new(|| whole.codes16(&asked_screen, at, &mut buffers[3].borrow_mut())),
        error: Box::new(|| judged(&buffers[3], &asked_screen, true)),
    });
    tools.push(Tool {
        name: "chromacal (with the spatial map, whole screen)".into(),
        cores: threads,
        run: Box::new(|| {
            buffers[4]
                .borrow_mut()
                .par_chunks_mut(chunk)
                .zip(asked_screen.par_chunks(chunk))
                .enumerate()
                .for_each(|(i, (c, x))| whole.codes16(x, |k| at(i * chunk + k), c));
        }),
        error: Box::new(|| judged(&buffers[4], &asked_screen, true)),
    });

    tools.extend(peer_tools(
        out,
        &profile,
        &centre_only,
        &full,
        &asked_centre,
    )?);

    let rounds = if quick { ROUNDS.min(3) } else { ROUNDS };
    let (seconds, ratios) = interleaved_rounds(&mut tools, rounds);
    let median = |v: Vec<f64>| chromacal_model::fit::stats::percentile(&v, 50.0);
    let cells: Vec<Vec<String>> = tools
        .iter()
        .enumerate()
        .map(|(t, tool)| {
            // The ratio within each round, to chromacal on one core (tool 0).
            let ratios: Vec<f64> = ratios.iter().map(|r| r[t]).collect();
            let (low, high) = ratios
                .iter()
                .fold((f64::INFINITY, 0.0f64), |(l, h), r| (l.min(*r), h.max(*r)));
            let error = (tool.error)();
            vec![
                tool.name.clone(),
                tool.cores.clone(),
                format!(
                    "{:.1}",
                    n as f64 / median(seconds.iter().map(|r| r[t]).collect()) / 1e6
                ),
                format!("{:.2} ({low:.2}–{high:.2})", median(ratios)),
                format!("{:.4} / {:.4}", error.mean, error.max),
            ]
        })
        .collect();
    writeln!(
        out.text,
        "XYZ → display codes (16 bits), {SIDE} × {SIDE} = {:.1} megapixels, colours inside the gamut; each tool timed beside chromacal on one core, interleaved over {rounds} rounds (the median, and each ratio's spread over the rounds); ΔE00 judged by chromacal's exact model on {} pixels\n",
        n as f64 / 1e6,
        ERROR_SAMPLE.min(n)
    )?;
    writeln!(
        out.text,
        "{}",
        table(
            &[
                "tool",
                "cores",
                "Mpixel/s",
                "this ÷ chromacal 1 core (time)",
                "ΔE00 mean / max",
            ],
            &cells
        )
    )?;
    code_choice_table(out, &full, rounds)?;
    // The loop over the screen (the spatial map at each pixel) on one core.
    let over_screen = tools
        .iter()
        .position(|t| t.name.contains("spatial map") && t.cores == "1")
        .ok_or("the loop over the screen is not among the tools")?;
    let loop_seconds = median(seconds.iter().map(|r| r[over_screen]).collect());
    // A quick look renders a 256 × 256 corner of it (the loop's time scaled to it).
    let side = if quick { 256 } else { SIDE };
    let scale = (side * side) as f64 / n as f64;
    command_table(out, &profile, &asked_screen, side, loop_seconds * scale)
}

/// The whole `render` command on the same image as a `side` × `side` PFM (2048 × 2048;
/// the top left corner of it when smaller) to a 16-bit PNG,
/// as a user runs it (read, map over all cores, write, summary), beside what reading
/// the file and writing the PNG take on their own and the loop above: what the user
/// waits for, not the inner loop.
fn command_table(
    out: &mut Tables,
    profile: &Profile,
    asked: &[Xyz],
    side: usize,
    loop_seconds: f64,
) -> Result<(), BenchError> {
    let dir = std::env::temp_dir().join(format!("chromacal-bench-command-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let timed = command_rows(profile, asked, side, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    let (read, write, rows) = timed?;
    let rows: Vec<Vec<String>> = rows
        .into_iter()
        .map(|(name, whole)| {
            let rest = whole - read - write;
            vec![
                name.to_string(),
                format!("{whole:.3}"),
                format!("{rest:.3}"),
                format!("{:.0}", rest / loop_seconds),
            ]
        })
        .collect();
    writeln!(
        out.text,
        "\nthe whole `render` command, a {side} × {side} PFM (the image above, over the screen) to a PNG, on {} cores: reading the PFM alone {read:.3} s, writing the 16-bit PNG alone {write:.3} s; the rest against the tabulated loop over the screen on one core ({:.3} s):\n",
        rayon::current_num_threads(),
        loop_seconds
    )?;
    writeln!(
        out.text,
        "{}",
        table(
            &[
                "render",
                "seconds",
                "without reading and writing",
                "÷ the loop"
            ],
            &rows
        )
    )?;
    Ok(())
}

/// What reading the PFM takes alone, writing the PNG alone, and the whole command
/// for each code choice, in `dir`.
#[allow(clippy::type_complexity)]
fn command_rows(
    profile: &Profile,
    asked: &[Xyz],
    side: usize,
    dir: &std::path::Path,
) -> Result<(f64, f64, Vec<(&'static str, f64)>), String> {
    use chromacal_crf::render::{CodesOutput, RenderRequest, SceneSource, SceneUnits, render};
    use chromacal_crf::scene::{Placement, read_pfm, write_png16_codes};
    use chromacal_crf::spectral::MethodKind;
    let image = dir.join("scene.pfm");
    let mut bytes = format!("PF\n{side} {side}\n-1.0\n").into_bytes();
    // PFM rows run from the bottom up.
    for row in (0..side).rev() {
        for x in &asked[row * SIDE..row * SIDE + side] {
            for v in [x.x, x.y, x.z] {
                bytes.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
    }
    std::fs::write(&image, bytes).map_err(|e| e.to_string())?;
    let png = dir.join("codes.png");
    let timed = |f: &mut dyn FnMut() -> Result<(), String>| -> Result<f64, String> {
        let start = Instant::now();
        f()?;
        Ok(start.elapsed().as_secs_f64())
    };
    let white = profile.model.white();
    let read = timed(&mut || {
        read_pfm(&image, &white)
            .map(|_| ())
            .map_err(|e| e.to_string())
    })?;
    // Codes with an image's variety (all-zero codes would compress to nothing).
    let codes: Vec<[u16; 3]> = asked[..side * side]
        .iter()
        .map(|x| {
            [x.x / white.x, x.y / white.y, x.z / white.z]
                .map(|v| (v.clamp(0.0, 1.0) * 65535.0) as u16)
        })
        .collect();
    let write =
        timed(&mut || write_png16_codes(&png, side, side, &codes, 16).map_err(|e| e.to_string()))?;
    // The model the command renders through (`Profile::output_model`).
    let (model, _) = profile.output_model();
    let mut rows = Vec::new();
    for (bits, choice, name) in [
        (16, CodeChoice::NearestInDeltaE00, "16 bits, nearest codes"),
        (16, CodeChoice::Rounded, "16 bits, --codes rounded"),
        (
            8,
            CodeChoice::NearestInDeltaE00,
            "8 bits, nearest codes (the defaults)",
        ),
    ] {
        let request = RenderRequest {
            source: SceneSource::Image(image.clone()),
            units: SceneUnits::Absolute,
            white_luminance: None,
            scene_white: None,
            at: Placement::FULL,
            grid: None,
            method: MethodKind::Direct,
            explain: false,
            max_de00: 0.5,
            settings: RenderSettings {
                adaptation: None,
                tone: ToneOperator::Colorimetric,
                gamut: GamutMapping::Clip,
                bits,
                codes: choice,
            },
            output: CodesOutput::File(png.clone()),
        };
        let whole = timed(&mut || {
            render(&model, profile.units, &request)
                .map(|_| ())
                .map_err(|e| e.to_string())
        })?;
        rows.push((name, whole));
    }
    Ok((read, write, rows))
}

/// What choosing the nearest of the 8 codes around each drive costs and gains over
/// rounding each channel, at 8 bits, through `render` (the whole chain, gamut test and
/// summary included), timed alternately over `ROUNDS` rounds.
fn code_choice_table(
    out: &mut Tables,
    model: &MonitorModel,
    rounds: usize,
) -> Result<(), BenchError> {
    let crf = ColourReproduction::new(model).map_err(|e| e.to_string())?;
    let n = 100_000;
    let scene = Scene {
        pixels: drives(n)
            .into_iter()
            .map(|d| ScenePixel {
                xyz: model.forward(d, ScreenPosition::CENTRE),
                position: ScreenPosition::CENTRE,
            })
            .collect(),
        white: None,
    };
    let settings = |codes| RenderSettings {
        adaptation: None,
        tone: ToneOperator::Colorimetric,
        gamut: GamutMapping::Clip,
        bits: 8,
        codes,
    };
    let choices = [CodeChoice::Rounded, CodeChoice::NearestInDeltaE00];
    let mut seconds = [Vec::new(), Vec::new()];
    let mut last = Vec::new();
    for round in 0..rounds {
        last.clear();
        for i in 0..2 {
            let k = (i + round) % 2;
            let start = Instant::now();
            let r = crf
                .render(&scene, &settings(choices[k]))
                .map_err(|e| e.to_string())?;
            seconds[k].push(start.elapsed().as_secs_f64());
            last.push((k, r));
        }
    }
    last.sort_by_key(|(k, _)| *k);
    let median = |v: &[f64]| chromacal_model::fit::stats::percentile(v, 50.0);
    let better = last[0]
        .1
        .pixels
        .iter()
        .zip(&last[1].1.pixels)
        .filter(|(r, n)| n.inversion_delta_e00 < r.inversion_delta_e00 - 0.1)
        .count();
    let cells: Vec<Vec<String>> = last
        .iter()
        .map(|(k, r)| {
            let e = r.summary.inversion.unwrap_or(ErrorStats {
                n: 0,
                mean: f64::NAN,
                p95: f64::NAN,
                max: f64::NAN,
            });
            vec![
                match choices[*k] {
                    CodeChoice::Rounded => "each channel rounded".to_string(),
                    CodeChoice::NearestInDeltaE00 => "nearest of the 8 in ΔE00".to_string(),
                },
                format!("{:.2}", median(&seconds[*k]) / n as f64 * 1e6),
                format!("{:.4} / {:.4} / {:.4}", e.mean, e.p95, e.max),
            ]
        })
        .collect();
    writeln!(
        out.text,
        "codes at 8 bits, {n} in-gamut colours through `render` ({rounds} rounds, alternating); {better} colours ({:.1} %) nearer by more than 0.1 ΔE00 with the nearest codes\n",
        better as f64 / n as f64 * 100.0
    )?;
    writeln!(
        out.text,
        "{}",
        table(&["codes", "µs a pixel", "ΔE00 mean / p95 / max"], &cells)
    )?;
    Ok(())
}

/// Why `bench render` has no rows for moxcms and Little CMS in a build without the
/// `peer-engines` feature, and how to get them.
#[cfg(not(feature = "peer-engines"))]
const PEERS_LEFT_OUT: &str = "bench render: moxcms and Little CMS are left out of this build (cargo feature `peer-engines`, off by default: lcms2 compiles Little CMS's C); for their rows run `cargo run --release --features peer-engines -- bench --only render`";

/// The colour management systems beside chromacal: none in a default build.
#[cfg(not(feature = "peer-engines"))]
fn peer_tools<'a>(
    out: &mut Tables,
    _profile: &Profile,
    _centre_only: &MonitorModel,
    _model: &'a MonitorModel,
    _asked: &'a [Xyz],
) -> Result<Vec<Tool<'a>>, String> {
    out.notes.push(format!("chromacal: {PEERS_LEFT_OUT}"));
    Ok(Vec::new())
}

/// moxcms and Little CMS, each transforming with the ICC v4 profile chromacal exports
/// of `centre_only`, judged against `full`.
#[cfg(feature = "peer-engines")]
fn peer_tools<'a>(
    _out: &mut Tables,
    profile: &Profile,
    centre_only: &MonitorModel,
    full: &'a MonitorModel,
    asked_centre: &'a [Xyz],
) -> Result<Vec<Tool<'a>>, String> {
    use crate::export::{ExportOptions, Format, export};
    use chromacal_color::adaptation::{AdaptationTransform, adaptation_matrix};
    // The same colours as the ICC profile's connection space sees them: relative to
    // the display's white, adapted to D50 (Bradford), as the v4 profile's chad says.
    let exported = export(
        // Without calibration curves, as `export` then writes the ICC relative to
        // the measured white (below).
        &Profile {
            model: centre_only.clone(),
            calibration: None,
            ..profile.clone()
        },
        Format::Icc4,
        &ExportOptions {
            target: None,
            measurements: None,
            native: false,
        },
    )
    .map_err(|e| e.to_string())?;
    // The white the ICC profile is relative to: the measured one, where the fit kept
    // it (`export`'s rule); relative to the model's own white instead, every colour
    // would be off by the white's difference (0.06 ΔE00 on the simulated default).
    let white = profile
        .report
        .white_anchor
        .as_ref()
        .map_or(centre_only.white(), |w| w.measured);
    let chad = adaptation_matrix(
        AdaptationTransform::Bradford,
        &(white / white.y),
        &Xyz::from(D50),
    );
    let pcs: Vec<[f64; 3]> = asked_centre
        .iter()
        .map(|x| (chad * (x / white.y)).into())
        .collect();
    Ok(vec![
        moxcms_tool(&exported.bytes, &pcs, full, asked_centre)?,
        lcms_tool(&exported.bytes, &pcs, full, asked_centre)?,
    ])
}

#[cfg(feature = "peer-engines")]
/// moxcms: a source profile whose "RGB" is PCS XYZ itself (identity colorants,
/// linear curves), to the display's profile, 32-bit float.
fn moxcms_tool<'a>(
    icc: &[u8],
    pcs: &[[f64; 3]],
    model: &'a MonitorModel,
    asked: &'a [Xyz],
) -> Result<Tool<'a>, String> {
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
    let output = Rc::new(RefCell::new(vec![0f32; input.len()]));
    transform
        .transform(&input, &mut output.borrow_mut())
        .map_err(|e| format!("moxcms: {e:?}"))?;
    let judged = Rc::clone(&output);
    Ok(Tool {
        name: "moxcms 0.8 (the exported ICC v4, f32)".into(),
        cores: "1".into(),
        run: Box::new(move || {
            let _ = transform.transform(&input, &mut output.borrow_mut());
        }),
        error: Box::new(move || {
            let output = judged.borrow();
            error_of(model, asked, &|_| ScreenPosition::CENTRE, &|k| {
                [0, 1, 2].map(|c| f64::from(output[3 * k + c]))
            })
        }),
    })
}

#[cfg(feature = "peer-engines")]
/// Little CMS: its built-in XYZ profile (doubles, Y = 1 at white) to the display's
/// profile, relative colorimetric, doubles out.
fn lcms_tool<'a>(
    icc: &[u8],
    pcs: &[[f64; 3]],
    model: &'a MonitorModel,
    asked: &'a [Xyz],
) -> Result<Tool<'a>, String> {
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
    let input = pcs.to_vec();
    let output = Rc::new(RefCell::new(vec![[0f64; 3]; pcs.len()]));
    transform.transform_pixels(&input, &mut output.borrow_mut());
    let judged = Rc::clone(&output);
    Ok(Tool {
        // Little CMS numbers its versions as 1000 × major + 10 × minor: 2190 is 2.19.
        name: format!(
            "Little CMS {}.{} (the exported ICC v4, double)",
            lcms2::version() / 1000,
            lcms2::version() % 1000 / 10
        ),
        cores: "1".into(),
        run: Box::new(move || transform.transform_pixels(&input, &mut output.borrow_mut())),
        error: Box::new(move || {
            let output = judged.borrow();
            error_of(model, asked, &|_| ScreenPosition::CENTRE, &|k| output[k])
        }),
    })
}
