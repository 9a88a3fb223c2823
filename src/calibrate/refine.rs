//! Calibration curves measured into place. The curves from the model's inverse
//! (`model::target`) are only as good as the fitted laws: a law chosen for ΔE00 can be
//! 1 % off in luminance at some level, which ΔE00 does not see and a tone-curve target
//! does. So, as ArgyllCMS's dispcal iterates, the grey ramp is shown through the
//! curves and measured at a few levels; the luminance missing at each level,
//! Y_target / Y_measured, is interpolated over the input and applied to all three
//! channels' excitations alike. The greys below white keep the model's chromaticity,
//! which rests on many readings, while one reading's chromaticity carries the
//! instrument's noise (0.2 % per band moves the white by about 0.5 ΔE00) and would be
//! written into the curves. The white alone is read three times in each pass and its
//! chromaticity corrected too, by per-channel factors applied at every level: a
//! model 0.1 % off at full drive misses the white by 0.4 ΔE00, four times a good
//! instrument's repeatability, and a white that misses the target is what a user
//! checks first. A last pass measures the result (white read three times), so the
//! figures reported are measured, not predicted.
//!
//! What reaches the panel is quantised: the codes at their bit depth, or the video
//! LUT's output at the depth the display takes it (`[target] bit_depth`; unstated, a
//! LUT's curves are left as the passes make them). At 8 bits one code of blue near the
//! top is about 1 % of its light, so a white aimed between two codes lands up to half
//! a step (some 0.5 ΔE00) away, and correcting it pass after pass only hops between
//! the two. So after each pass every curve entry is set to the codes at that depth, on
//! either side of what the pass asks for, whose colour by the model corrected by what
//! was measured at the levels around it (the measured over the predicted XYZ,
//! interpolated over the input) is nearest the target grey of its input in ΔE00, its
//! luminance kept near the tone's (`snap_to_depth`): the white and every grey land on
//! the best colour the display can show, not on a rounding.

use super::run::RunError;
use crate::config::TargetConfig;
use crate::profile::{LevelCheck, StoredCalibration};
use chromacal_color::{Xyz, delta_e_2000, xyz_to_lab};
use chromacal_display::PatchDisplay;
use chromacal_instruments::Instrument;
use chromacal_model::MonitorModel;
use chromacal_model::screen::{Codes, Geometry, Patch};
use chromacal_model::target::{
    CalibrationCurves, TargetError, calibration_curves, target_luminance, white_error,
};

/// Why the curves could not be measured into place.
#[derive(Debug, thiserror::Error)]
pub enum RefineError {
    #[error("{0}")]
    Target(#[from] TargetError),
    #[error("while refining the calibration curves: {0}")]
    Run(#[from] RunError),
    #[error(
        "the instrument gave no XYZ for grey level {input:.3} (a colorimeter or spectroradiometer is needed)"
    )]
    NoXyz { input: f64 },
}

/// How the curves reach the screen while they are measured.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Through {
    /// Applied to the codes sent, at this bit depth (a display without a video LUT).
    Codes(u32),
    /// Loaded in the display's video LUT: the grey codes are sent as they are, at the
    /// plan's bit depth.
    Lut(u32),
}

/// Show the grey of input `x` through `curves` and read it.
async fn read_level<D: PatchDisplay, I: Instrument>(
    curves: &CalibrationCurves,
    x: f64,
    through: Through,
    geometry: Geometry,
    display: &mut D,
    instrument: &mut I,
) -> Result<(Xyz, f64), RefineError> {
    let (codes, bit_depth) = match through {
        Through::Codes(bits) => (Codes::from_drive(curves.apply([x; 3]), bits), bits),
        Through::Lut(bits) => (Codes::from_drive([x; 3], bits), bits),
    };
    let patch = Patch {
        codes,
        background: Codes::from_drive([0.0; 3], bit_depth),
        geometry,
    };
    display.show(&patch).await.map_err(RunError::from)?;
    let reading = instrument
        .measure()
        .await
        .map_err(|source| RunError::Instrument {
            index: 0,
            attempts: 1,
            source,
        })?;
    let xyz = reading
        .xyz
        .filter(|v| v.iter().all(|c| c.is_finite()))
        .ok_or(RefineError::NoXyz { input: x })?;
    Ok((xyz, reading.integration_s))
}

/// The mean of `reads` readings of the grey of input `x` through `curves`, with the
/// instrument time they took.
async fn read_mean<D: PatchDisplay, I: Instrument>(
    curves: &CalibrationCurves,
    x: f64,
    reads: usize,
    through: Through,
    geometry: Geometry,
    display: &mut D,
    instrument: &mut I,
) -> Result<(Xyz, f64), RefineError> {
    let mut mean = Xyz::zeros();
    let mut seconds = 0.0;
    for _ in 0..reads {
        let (xyz, s) = read_level(curves, x, through, geometry, display, instrument).await?;
        mean += xyz / reads as f64;
        seconds += s;
    }
    Ok((mean, seconds))
}

/// Piecewise-linear interpolation through `(x, y)` points sorted by x, constant
/// beyond the ends.
fn interpolate_gain(points: &[(f64, f64)], x: f64) -> f64 {
    match points {
        [] => 1.0,
        [only] => only.1,
        _ => {
            if x <= points[0].0 {
                return points[0].1;
            }
            for w in points.windows(2) {
                if x <= w[1].0 {
                    let t = (x - w[0].0) / (w[1].0 - w[0].0);
                    return w[0].1 * (1.0 - t) + w[1].1 * t;
                }
            }
            points[points.len() - 1].1
        }
    }
}

/// Readings of the white averaged in each pass and in the check.
const WHITE_READS: usize = 3;

/// Per-channel factors on the excitations that move the white measured through the
/// curves onto the target's chromaticity without changing its luminance: the
/// excitations each white needs, through the model's primary matrix (which only has
/// to point the way: the next pass measures again), over what was obtained,
/// each limited to ±20 % a pass, then normalised so that Y stays; `None` when the matrix or the
/// reading gives no answer.
fn white_balance(model: &MonitorModel, measured: &Xyz, target: &Xyz) -> Option<[f64; 3]> {
    let inverse = model.matrix.try_inverse()?;
    let obtained = inverse * (measured - model.black);
    let needed = inverse * (target - model.black);
    if obtained
        .iter()
        .chain(needed.iter())
        .any(|v| !(v.is_finite() && *v > 0.0))
    {
        return None;
    }
    let factors = [0, 1, 2].map(|c| (needed[c] / obtained[c]).clamp(0.8, 1.2));
    let luminance = |f: [f64; 3]| {
        (0..3)
            .map(|c| model.matrix[(1, c)] * obtained[c] * f[c])
            .sum::<f64>()
    };
    let keep = luminance([1.0; 3]) / luminance(factors);
    (keep.is_finite() && keep > 0.0).then(|| factors.map(|f| f * keep))
}

/// The least a curve entry's codes may be further off its grey's luminance (a
/// fraction) than the codes nearest in luminance, for a colour nearer in ΔE00
/// ([`snap_to_depth`]; else half a code's step). Unbounded, a 10-bit OLED's mid grey
/// went 1 % dark for 0.1 ΔE00 of chromaticity.
const TONE_SLACK: f64 = 0.0025;

/// `drive` as the panel gets it at `depth` bits.
fn quantised(drive: [f64; 3], depth: u32) -> [f64; 3] {
    let top = ((1u64 << depth.min(24)) - 1) as f64;
    drive.map(|d| (d.clamp(0.0, 1.0) * top).round() / top)
}

/// Measured over predicted, per component; `None` where either is not positive.
fn ratio(measured: &Xyz, predicted: &Xyz) -> Option<[f64; 3]> {
    let r = [0, 1, 2].map(|c| measured[c] / predicted[c]);
    r.iter().all(|v| v.is_finite() && *v > 0.0).then_some(r)
}

/// The ratio at `x`, linearly between the levels measured and held beyond them.
fn ratio_at(ratios: &[(f64, [f64; 3])], x: f64) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        let points: Vec<(f64, f64)> = ratios.iter().map(|(x, r)| (*x, r[c])).collect();
        interpolate_gain(&points, x)
    })
}

/// The grey the curves aim each input at: the tone's luminance on the line from the
/// black to the white aimed at.
struct Grey {
    tone: chromacal_model::target::ToneCurve,
    black: Xyz,
    white: Xyz,
}

impl Grey {
    fn at(&self, x: f64) -> Xyz {
        let y = target_luminance(self.tone, x, self.black.y, self.white.y);
        let share = (y - self.black.y) / (self.white.y - self.black.y);
        self.black + (self.white - self.black) * share
    }
}

/// Each curve entry above black set to the codes at `depth` bits on either side of what
/// it asks for and no lower than the entry before, whose colour by the model
/// corrected by the measured `ratios` is nearest in ΔE00 the grey `aim` asks for at its
/// input: the best the quantised output can show, chosen rather than rounded to.
fn snap_to_depth(
    curves: &mut CalibrationCurves,
    model: &MonitorModel,
    ratios: &[(f64, [f64; 3])],
    aim: &Grey,
    depth: u32,
) {
    if ratios.is_empty() || depth > 16 {
        return;
    }
    let top = ((1u64 << depth) - 1) as f64;
    let n = curves.curves[0].len();
    let mut floor = [0.0f64; 3];
    for i in 1..n {
        let x = i as f64 / (n - 1) as f64;
        let target = aim.at(x);
        let r = ratio_at(ratios, x);
        let ideal = [0, 1, 2].map(|c| curves.curves[c][i] * top);
        let options = |c: usize| -> Vec<f64> {
            let base = ideal[c].floor();
            (0..=1)
                .map(|k| base + f64::from(k))
                .filter(|q| (0.0..=top).contains(q) && *q >= floor[c])
                .collect()
        };
        let (reds, greens, blues) = (options(0), options(1), options(2));
        // Every combination: its ΔE00 to the grey asked for, and how far its
        // luminance is off that grey's.
        let mut scored: Vec<([f64; 3], f64, f64)> = Vec::new();
        for &qr in &reds {
            for &qg in &greens {
                for &qb in &blues {
                    let codes = [qr, qg, qb];
                    let shown = model.forward_centre(codes.map(|q| q / top));
                    let corrected = Xyz::new(shown.x * r[0], shown.y * r[1], shown.z * r[2]);
                    let de = delta_e_2000(
                        &xyz_to_lab(&corrected, &aim.white),
                        &xyz_to_lab(&target, &aim.white),
                    );
                    scored.push((codes, de, (corrected.y / target.y - 1.0).abs()));
                }
            }
        }
        // The colour nearest in ΔE00 among those whose luminance is within half a
        // code's step (one code more of all three), and no less than TONE_SLACK, of
        // the nearest luminance: ΔE00 weighs a light miss little at mid greys, and
        // left alone trades the tone for chromaticity where the codes are fine.
        let nearest_tone = scored.iter().map(|s| s.2).fold(f64::INFINITY, f64::min);
        let base = ideal.map(|q| q.floor().clamp(0.0, top - 1.0));
        let step = model.forward_centre(base.map(|q| (q + 1.0) / top)).y
            / model.forward_centre(base.map(|q| q / top)).y
            - 1.0;
        let slack = match step.is_finite() {
            true => (0.5 * step).max(TONE_SLACK),
            false => f64::INFINITY,
        };
        let best = scored
            .into_iter()
            .filter(|s| s.2 <= nearest_tone + slack)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((codes, _, _)) = best {
            for c in 0..3 {
                curves.curves[c][i] = codes[c] / top;
                floor[c] = codes[c];
            }
        }
    }
}

/// The model's curves for `config`, measured into place on `display` and `instrument`.
pub async fn refine_curves<D: PatchDisplay, I: Instrument>(
    model: &MonitorModel,
    config: &TargetConfig,
    plan_bit_depth: u32,
    patch_size: f64,
    display: &mut D,
    instrument: &mut I,
) -> Result<StoredCalibration, RefineError> {
    let target = config.target()?;
    let mut curves = calibration_curves(model, &target)?;
    let geometry = Geometry::centred(patch_size);
    // Through a video LUT the grey is a code the plan's depth can send, and the target
    // is that code's, not the ideal level's.
    let lut = display.load_curves(Some(&curves)).map_err(RunError::from)?;
    let through = if lut {
        Through::Lut(plan_bit_depth)
    } else {
        Through::Codes(config.bit_depth.unwrap_or(plan_bit_depth))
    };
    // The depth the curves' output reaches the panel at, where it is known: the codes'
    // (chromacal quantises them itself), or the video LUT's output as `bit_depth`
    // states it (a card's output depth is not something X11 says: unstated, the
    // curves stay as the model and the passes make them).
    let depth = match through {
        Through::Codes(bits) => Some(bits),
        Through::Lut(_) => config.bit_depth,
    };
    let inputs: Vec<f64> = (1..config.levels)
        .map(|k| {
            let x = k as f64 / (config.levels - 1) as f64;
            match through {
                Through::Lut(bits) => Codes::from_drive([x; 3], bits).drive()[0],
                Through::Codes(_) => x,
            }
        })
        .collect();
    let black = model.black;
    // The white asked for, and the one aimed at: lower when balancing the white's
    // chromaticity asks a channel for more than full drive (worked out again from
    // the one asked for in every pass, so that one low reading does not stay).
    let asked = Xyz::new(curves.white[0], curves.white[1], curves.white[2]);
    let mut white = asked;
    let want = |x: f64, white: &Xyz| target_luminance(target.tone, x, black.y, white.y);
    let (mut readings, mut instrument_s) = (0, 0.0);
    for _ in 0..config.refine_passes {
        // The gain of the light above black at each level: what it should have been
        // over what it was.
        let mut gains: Vec<(f64, f64)> = Vec::new();
        let mut balance = [1.0; 3];
        // What the model misses at each level: measured over predicted, per component.
        let mut ratios: Vec<(f64, [f64; 3])> = Vec::new();
        for &x in &inputs {
            // The white three times: its chromaticity is corrected too.
            let reads = if x == 1.0 { WHITE_READS } else { 1 };
            let (measured, seconds) =
                read_mean(&curves, x, reads, through, geometry, display, instrument).await?;
            readings += reads;
            instrument_s += seconds;
            let predicted = model.forward_centre(match depth {
                Some(bits) => quantised(curves.apply([x; 3]), bits),
                None => curves.apply([x; 3]),
            });
            if let Some(r) = ratio(&measured, &predicted) {
                ratios.push((x, r));
            }
            let above = measured.y - black.y;
            if above > 0.0 {
                gains.push((x, ((want(x, &white) - black.y) / above).clamp(0.5, 2.0)));
            }
            if x == 1.0 {
                balance = white_balance(model, &measured, &white).unwrap_or([1.0; 3]);
            }
        }
        // A channel that would need more than full drive at the white asked for: all
        // three give up the same share, so the white keeps its chromaticity and loses
        // luminance, and the tone curve that ends at it comes down with it.
        let asked_above = asked.y - black.y;
        let toward_asked = match asked_above / (white.y - black.y) {
            t if t.is_finite() && t > 0.0 => t,
            _ => 1.0,
        };
        let over = curves
            .curves
            .iter()
            .zip(&model.laws)
            .zip(balance)
            .map(|((curve, law), b)| {
                let last = curve.last().copied().unwrap_or(1.0);
                law.excitation(last) * interpolate_gain(&gains, 1.0) * toward_asked * b
                    / law.full_drive_excitation()
            })
            .fold(1.0, f64::max);
        let share = 1.0 / over;
        let rescale = toward_asked * share;
        for (_, gain) in &mut gains {
            *gain *= rescale;
        }
        white = black + (asked - black) * share;
        curves.white = [white.x, white.y, white.z];
        curves.luminance_limited |= over > 1.0 && target.luminance.is_some();
        for ((curve, law), b) in curves.curves.iter_mut().zip(&model.laws).zip(balance) {
            let top = law.full_drive_excitation();
            let n = curve.len();
            // Kept non-decreasing, as a lookup table must be.
            let mut floor: f64 = 0.0;
            for (i, drive) in curve.iter_mut().enumerate().skip(1) {
                let x = i as f64 / (n - 1) as f64;
                let e = law.excitation(*drive) * interpolate_gain(&gains, x) * b;
                *drive = law.drive(e.clamp(0.0, top)).max(floor);
                floor = *drive;
            }
        }
        let aim = Grey {
            tone: target.tone,
            black,
            white,
        };
        if let Some(bits) = depth {
            snap_to_depth(&mut curves, model, &ratios, &aim, bits);
        }
        display.load_curves(Some(&curves)).map_err(RunError::from)?;
    }
    // The check, through the final curves; white three times, for its chromaticity.
    let mut levels = Vec::new();
    let mut measured_white = white;
    for &x in &inputs {
        let reads = if x == 1.0 { WHITE_READS } else { 1 };
        let (measured, seconds) =
            read_mean(&curves, x, reads, through, geometry, display, instrument).await?;
        readings += reads;
        instrument_s += seconds;
        levels.push(LevelCheck {
            input: x,
            target_luminance: want(x, &white),
            measured_luminance: measured.y,
            measured_xyz: [measured.x, measured.y, measured.z],
            drive: Some(match through {
                Through::Codes(bits) => Codes::from_drive(curves.apply([x; 3]), bits).drive(),
                Through::Lut(_) => curves.apply([x; 3]),
            }),
        });
        if x == 1.0 {
            measured_white = measured;
        }
    }
    let _ = display.blank().await;
    let measured_tone_error = levels
        .iter()
        .map(|l| (l.measured_luminance / l.target_luminance - 1.0).abs())
        .fold(0.0, f64::max);
    Ok(StoredCalibration {
        through_lut: lut,
        measured_white_de00: white_error(&measured_white, &white),
        curves,
        passes: config.refine_passes,
        levels,
        measured_tone_error,
        readings,
        instrument_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gains_are_interpolated_and_held_beyond_the_ends() {
        let points = [(0.25, 1.1), (0.5, 0.9), (1.0, 1.0)];
        assert_eq!(interpolate_gain(&points, 0.0), 1.1);
        assert!((interpolate_gain(&points, 0.375) - 1.0).abs() < 1e-12);
        assert_eq!(interpolate_gain(&points, 1.0), 1.0);
        assert_eq!(interpolate_gain(&[], 0.3), 1.0);
    }

    #[test]
    fn bad_targets_name_the_key() {
        let config = TargetConfig {
            white: "purple".into(),
            tone: "srgb".into(),
            luminance: None,
            peak: None,
            mastering_peak: None,
            refine_passes: 2,
            levels: 9,
            bit_depth: None,
            verify: true,
        };
        let err = config.check().unwrap_err();
        assert!(
            err.starts_with("target:") && err.contains("purple"),
            "{err}"
        );
        let config = TargetConfig {
            white: "D65".into(),
            levels: 2,
            ..config
        };
        assert!(config.check().unwrap_err().contains("target.levels"));
        // HDR: the peak is the luminance by its other name (one of the two), and a
        // mastering peak is for PQ only, within the PQ's range.
        let pq = TargetConfig {
            levels: 9,
            tone: "pq".into(),
            peak: Some(600.0),
            mastering_peak: Some(4000.0),
            ..config
        };
        assert!(pq.check().is_ok());
        assert_eq!(pq.target().unwrap().luminance, Some(600.0));
        assert_eq!(
            pq.target().unwrap().tone,
            chromacal_model::target::ToneCurve::Pq {
                mastering_peak: Some(4000.0)
            }
        );
        let both = TargetConfig {
            luminance: Some(500.0),
            ..pq.clone()
        };
        assert!(both.check().unwrap_err().contains("peak or luminance"));
        let sdr = TargetConfig {
            tone: "srgb".into(),
            ..pq.clone()
        };
        assert!(
            sdr.check()
                .unwrap_err()
                .contains("mastering_peak is for tone")
        );
        let dim = TargetConfig {
            mastering_peak: Some(50.0),
            ..pq
        };
        assert!(dim.check().unwrap_err().contains("100 to 10000"));
    }
}
