//! The curves corrected at the very codes that were measured.
//!
//! A real panel's channel curve is not smooth from one code to the next. On the Dell
//! U2713HM the greys' channel shares wander by 2–4 % between greys 1.8 % of drive
//! apart, the sign changing from one to the next, while a ramp reading and a grey's
//! share of the same code agree within 0.3 %: the panel's look-up tables give each
//! code its own error, and it repeats. No curve through the levels can predict that
//! error at a code that was not measured (cross-validation over levels sees only this,
//! and rightly prefers a smooth law there), but at a code that was measured the
//! readings are its best estimate, and every colour made of measured codes (a chart's
//! mixtures, built on the steps of its ramps) is predicted from them.
//!
//! The correction multiplies the published curve L (the chosen law, or the law as
//! corrected by `law_correction`) near each measured code vᵢ by a tent one code step δ
//! wide: L′(v) = L(v)·(1 + r̂ᵢ·max(0, 1 − |v − vᵢ|/δ)), L itself further than δ from
//! every measured code.
//!
//! - rᵢ = ēᵢ/L(vᵢ) − 1 is the relative residual of the code's readings (the ramp's and
//!   the greys' shares there, `code_estimates`), with noise sᵢ;
//! - r̂ᵢ = rᵢ·τ²/(τ² + sᵢ²) shrinks it by empirical Bayes, τ² = max(0, mean r² −
//!   mean s²) (Efron & Morris 1975; as `law_correction` does);
//! - the noise sᵢ is the run's noise model, scaled by what the replicate codes show
//!   (`noise_scale`): where a code was measured both as a ramp reading and as a
//!   grey, the two estimates' scatter, in units of their stated noise, is χ²/n, and
//!   √(χ²/n) scales every sᵢ. A run whose noise model was assumed rather than measured
//!   (too few repeats of its reference) then shrinks by the noise it really had.
//!
//! Whether to keep it is decided on the replicate codes, each estimate predicted from
//! the other alone ([`judge`]): a ramp reading by the curve corrected from the grey's
//! share of its code, and a grey by the curves corrected from the ramps' readings of
//! its code. The correction is kept only if it lowers the ΔE00 of those predictions by
//! more than two paired standard errors and more than noise alone. With no replicate
//! code it cannot be judged and is not made.

use serde::{Deserialize, Serialize};

use super::law_correction::{prior_spread, shrunk};
use super::laws::{FittedParameter, LawFit, isotonic_regression};
use super::primaries::{ChannelRamp, RampPoint};
use super::select::simplest_within;
use super::stats::ErrorStats;
use super::validate::delta_e00_xyz;
use crate::transfer::{Table, TransferLaw};
use chromacal_color::Xyz;

/// Fewest distinct codes measured twice that the correction is judged on (each is one
/// item of the paired test, whatever number of channels and readings it has).
pub const MIN_REPLICATES: usize = 3;

/// Samples of the curve away from the measured codes: every 1/128 and at (k/64)²,
/// dense near black, so that the cubic through them stays within 0.2 % of the law
/// between codes 1/28 apart from the darkest on (tested).
const GRID: usize = 128;

/// Weight of the law's samples beside a code when the curve is pooled to stay monotone.
const SIDE_WEIGHT: f64 = 1e-6;

/// What the correction at the measured codes found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CodeCorrectionReport {
    pub kept: bool,
    /// Codes measured below full drive, summed over the channels.
    pub codes: usize,
    /// Distinct codes measured both as a ramp reading and as a grey.
    pub replicates: usize,
    /// √(χ²/n) of the replicate codes' scatter against the noise model.
    pub noise_scale: Option<f64>,
    /// ΔE00 of the replicate estimates predicted from the other alone, by the curves
    /// uncorrected and corrected at the codes.
    pub uncorrected: Option<ErrorStats>,
    pub corrected: Option<ErrorStats>,
    pub rule: String,
}

/// How a kept correction is made again (on curves fitted anew, `fit::refit_curves_for_terms`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CodeCorrection {
    pub code_step: f64,
    pub noise_scale: f64,
}

/// One channel's estimate of one code: the weighted mean of its points there.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Estimate {
    excitation: f64,
    sigma: f64,
}

impl Estimate {
    fn of(points: &[&RampPoint]) -> Option<Estimate> {
        let weight: f64 = points.iter().map(|p| p.sigma.powi(-2)).sum();
        if points.is_empty() || !(weight > 0.0 && weight.is_finite()) {
            return None;
        }
        let sum: f64 = points.iter().map(|p| p.excitation * p.sigma.powi(-2)).sum();
        Some(Estimate {
            excitation: sum / weight,
            sigma: weight.sqrt().recip(),
        })
    }

    fn pooled(a: Option<Estimate>, b: Option<Estimate>) -> Option<Estimate> {
        match (a, b) {
            (Some(a), Some(b)) => {
                let (wa, wb) = (a.sigma.powi(-2), b.sigma.powi(-2));
                Some(Estimate {
                    excitation: (a.excitation * wa + b.excitation * wb) / (wa + wb),
                    sigma: (wa + wb).sqrt().recip(),
                })
            }
            (a, b) => a.or(b),
        }
    }
}

/// One measured code of a channel: its drive, and its estimates from the ramp's
/// readings and from the greys' shares.
#[derive(Debug, Clone, Copy, PartialEq)]
struct CodeEstimates {
    drive: f64,
    ramp: Option<Estimate>,
    grey: Option<Estimate>,
}

/// The measured codes of `ramp` strictly between black and full drive, ascending.
/// Drives within half a code step are one code (a chart's 57.1429 % and 57.143 % are
/// the same code); the ramp's own drive names it where there is one.
fn code_estimates(ramp: &ChannelRamp, code_step: f64) -> Vec<CodeEstimates> {
    let mut drives: Vec<f64> = ramp
        .points
        .iter()
        .chain(&ramp.grey_points)
        .map(|p| p.drive)
        .filter(|v| *v > 0.0 && *v < 1.0)
        .collect();
    drives.sort_by(|a, b| a.total_cmp(b));
    drives.dedup_by(|a, b| (*a - *b).abs() < 0.5 * code_step);
    drives
        .into_iter()
        .map(|v| {
            let near = |p: &&RampPoint| (p.drive - v).abs() < 0.5 * code_step;
            let ramp_points: Vec<&RampPoint> = ramp.points.iter().filter(near).collect();
            let grey_points: Vec<&RampPoint> = ramp.grey_points.iter().filter(near).collect();
            CodeEstimates {
                drive: ramp_points.first().map_or(v, |p| p.drive),
                ramp: Estimate::of(&ramp_points),
                grey: Estimate::of(&grey_points),
            }
        })
        .collect()
}

/// Every code measured both as a ramp reading and as a grey, each channel's: its drive
/// and how far its two estimates differ in units of their stated noise, squared (z²).
fn replicate_pairs(codes: &[Vec<CodeEstimates>]) -> Vec<(f64, f64)> {
    codes
        .iter()
        .flatten()
        .filter_map(|c| {
            let (a, b) = (c.ramp?, c.grey?);
            let z2 = (a.excitation - b.excitation).powi(2) / (a.sigma.powi(2) + b.sigma.powi(2));
            z2.is_finite().then_some((c.drive, z2))
        })
        .collect()
}

/// Distinct drives among `pairs` (a code measured twice in several channels is one).
fn distinct_codes(pairs: &[(f64, f64)], code_step: f64) -> Vec<f64> {
    let mut drives: Vec<f64> = pairs.iter().map(|p| p.0).collect();
    drives.sort_by(|a, b| a.total_cmp(b));
    drives.dedup_by(|a, b| (*a - *b).abs() < 0.5 * code_step);
    drives
}

/// How far the replicate codes scatter against their stated noise: √(χ²/n) over
/// `pairs`, leaving out those at drive `except` (the code being judged, so that its own
/// scatter does not set its shrinkage). `None` when no pair is left.
fn noise_scale(pairs: &[(f64, f64)], except: Option<f64>, code_step: f64) -> Option<f64> {
    let z2: Vec<f64> = pairs
        .iter()
        .filter(|p| except.is_none_or(|v| (p.0 - v).abs() >= 0.5 * code_step))
        .map(|p| p.1)
        .collect();
    (!z2.is_empty()).then(|| (z2.iter().sum::<f64>() / z2.len() as f64).sqrt())
}

/// The relative residuals of one channel's codes against a curve: (drive, r, s) with
/// the noise scaled by `noise_scale`, for codes where the curve is above zero.
fn residuals(
    codes: &[CodeEstimates],
    curve: impl Fn(f64) -> f64,
    noise_scale: f64,
    pick: impl Fn(&CodeEstimates) -> Option<Estimate>,
) -> Vec<(f64, f64, f64)> {
    codes
        .iter()
        .filter_map(|c| {
            let e = pick(c)?;
            let predicted = curve(c.drive);
            (predicted > 0.0).then(|| {
                (
                    c.drive,
                    e.excitation / predicted - 1.0,
                    noise_scale * e.sigma / predicted,
                )
            })
        })
        .collect()
}

/// `fit` (a curve fitted to `ramp`) corrected at `ramp`'s measured codes (see the
/// module documentation), as a table in units of the ramp's normaliser. `None` when the
/// ramp is not pinned at full drive or has no code to correct.
pub fn correct_at_codes(
    fit: &LawFit,
    ramp: &ChannelRamp,
    correction: CodeCorrection,
) -> Option<LawFit> {
    let CodeCorrection {
        code_step,
        noise_scale,
    } = correction;
    if !ramp.pinned || !(code_step > 0.0) {
        return None;
    }
    let curve = |v: f64| fit.amplitude * fit.law.excitation(v);
    let codes = code_estimates(ramp, code_step);
    let residuals = residuals(&codes, curve, noise_scale, |c| {
        Estimate::pooled(c.ramp, c.grey)
    });
    if residuals.is_empty() {
        return None;
    }
    let tau2 = prior_spread(&residuals);
    // The curve is sampled at each code, and at one and two steps either side of it
    // (the law's own values, so that the cubic between the samples is back on the law
    // within two steps); the samples away from every code follow the law.
    let near_a_code = |v: f64| residuals.iter().any(|r| (r.0 - v).abs() < 2.0 * code_step);
    // (drive, excitation, weight in the pooling below).
    let mut knots: Vec<(f64, f64, f64)> = (1..=GRID)
        .map(|k| k as f64 / GRID as f64)
        .chain((1..=GRID / 2).map(|k| (k as f64 / (GRID / 2) as f64).powi(2)))
        .filter(|v| *v >= 1.0 || !near_a_code(*v))
        .map(|v| (v, curve(v), 1.0))
        .collect();
    for (level, r, s) in &residuals {
        knots.push((*level, curve(*level) * (1.0 + shrunk(*r, *s, tau2)), 1.0));
        for side in [-2.0, -1.0, 1.0, 2.0].map(|k| level + k * code_step) {
            let clear = residuals
                .iter()
                .all(|o| o.0 == *level || (o.0 - side).abs() >= code_step);
            if side > 0.0 && side < 1.0 && clear {
                knots.push((side, curve(side), SIDE_WEIGHT));
            }
        }
    }
    knots.sort_by(|a, b| a.0.total_cmp(&b.0));
    knots.dedup_by(|a, b| (a.0 - b.0).abs() < 1e-9);
    let drive: Vec<f64> = knots.iter().map(|k| k.0).collect();
    let excitation: Vec<f64> = knots.iter().map(|k| k.1.max(0.0)).collect();
    let weights: Vec<f64> = knots.iter().map(|k| k.2).collect();
    // Where a code's value falls below the law a step under it (or rises above the law
    // a step over it), the curve is pooled to stay monotone (as the table law's knots
    // are); the law's samples beside a code weigh next to nothing there, so they move
    // to the code's value rather than the code to theirs.
    let excitation = isotonic_regression(&excitation, &weights);
    let table = Table::new(drive, excitation).ok()?;
    let mut parameters = fit.parameters.clone();
    parameters.push(FittedParameter {
        name: "code correction spread τ".into(),
        value: tau2.sqrt(),
        standard_error: None,
    });
    let mut notes = fit.notes.clone();
    notes.push(format!(
        "corrected at {} measured codes (spread τ = {:.4}, noise × {noise_scale:.3})",
        residuals.len(),
        tau2.sqrt()
    ));
    Some(LawFit {
        law: TransferLaw::Table(table),
        amplitude: 1.0,
        parameters,
        chi2: 0.0,
        dof: 0,
        free_parameters: fit.free_parameters + residuals.len(),
        notes,
    })
}

/// What [`judge`] compares on: the channels' ramps and the curves fitted to them, the
/// black and the white ΔE00 is taken against, one code step, and the noise tolerance.
pub struct Judged<'a> {
    pub ramps: &'a [ChannelRamp; 3],
    pub fits: [&'a LawFit; 3],
    pub black: &'a Xyz,
    pub white: &'a Xyz,
    pub code_step: f64,
    pub tolerance: f64,
}

/// Whether to correct `fits` at the measured codes (module documentation), and the
/// corrected curves when so.
pub fn judge(input: &Judged<'_>) -> (CodeCorrectionReport, Option<Vec<LawFit>>) {
    let Judged {
        ramps,
        fits,
        code_step,
        tolerance,
        ..
    } = *input;
    let codes: Vec<Vec<CodeEstimates>> =
        ramps.iter().map(|r| code_estimates(r, code_step)).collect();
    let n_codes = codes.iter().map(Vec::len).sum();
    let pairs = replicate_pairs(&codes);
    let replicates = distinct_codes(&pairs, code_step);
    let mut report = CodeCorrectionReport {
        kept: false,
        codes: n_codes,
        replicates: replicates.len(),
        noise_scale: noise_scale(&pairs, None, code_step),
        uncorrected: None,
        corrected: None,
        rule: format!(
            "each code measured both as a ramp reading and as a grey predicted from the other alone; kept only if correcting at the measured codes lowers that ΔE00, averaged code by code, by more than two standard errors (paired, over the codes) and than noise alone ({tolerance:.3})"
        ),
    };
    let Some(noise_scale) = report
        .noise_scale
        .filter(|_| replicates.len() >= MIN_REPLICATES)
    else {
        report.rule = format!(
            "not tried: fewer than {MIN_REPLICATES} codes were measured both as a ramp reading and as a grey, so whether a code's readings repeat cannot be judged"
        );
        return (report, None);
    };
    let by_code = replicate_errors(input, &codes, &pairs);
    let (uncorrected, corrected): (Vec<&Vec<f64>>, Vec<&Vec<f64>>) =
        by_code.iter().map(|(a, b)| (a, b)).unzip();
    let flat = |v: &[&Vec<f64>]| -> Vec<f64> { v.iter().flat_map(|c| c.iter().copied()).collect() };
    report.uncorrected = ErrorStats::of(&flat(&uncorrected));
    report.corrected = ErrorStats::of(&flat(&corrected));
    // The readings of one code share their estimates, so the test's items are codes.
    let code_means =
        |v: &[&Vec<f64>]| -> Vec<f64> { v.iter().map(|c| super::stats::mean(c)).collect() };
    let better = simplest_within(
        &[Some(code_means(&uncorrected)), Some(code_means(&corrected))],
        tolerance,
        2.0,
    );
    if better != Some(1) {
        return (report, None);
    }
    let correction = CodeCorrection {
        code_step,
        noise_scale,
    };
    let fits: Option<Vec<LawFit>> = fits
        .iter()
        .zip(ramps)
        .map(|(fit, ramp)| correct_at_codes(fit, ramp, correction))
        .collect();
    report.kept = fits.is_some();
    (report, fits)
}

/// ΔE00 of each replicate estimate predicted from the other estimate of its code alone,
/// by the curves as they are and corrected there, code by code (uncorrected, corrected).
/// Nothing predicted is in its own prediction: the prior's spread comes from the
/// channel's other codes, and the noise scale from the other codes' pairs.
fn replicate_errors(
    input: &Judged<'_>,
    codes: &[Vec<CodeEstimates>],
    pairs: &[(f64, f64)],
) -> Vec<(Vec<f64>, Vec<f64>)> {
    let Judged {
        ramps,
        fits,
        black,
        white,
        code_step,
        ..
    } = *input;
    let curve = |c: usize, v: f64| fits[c].amplitude * fits[c].law.excitation(v);
    let column = |c: usize| ramps[c].column(1.0);
    let near = |v: f64| move |p: &&RampPoint| (p.drive - v).abs() < 0.5 * code_step;
    let mut by_code = Vec::new();
    for v in distinct_codes(pairs, code_step) {
        let scale = noise_scale(pairs, Some(v), code_step)
            .or_else(|| noise_scale(pairs, None, code_step))
            .unwrap_or(1.0);
        // Each channel's correction at this code from its grey share alone and from its
        // ramp reading alone.
        let from = |c: usize, pick: fn(&CodeEstimates) -> Option<Estimate>| -> f64 {
            let at = codes[c]
                .iter()
                .position(|x| (x.drive - v).abs() < 0.5 * code_step);
            at.and_then(|k| Some((k, pick(&codes[c][k])?)))
                .map_or(0.0, |(k, e)| {
                    left_out_correction(&codes[c], k, e, |u| curve(c, u), scale)
                })
        };
        let (mut uncorrected, mut corrected) = (Vec::new(), Vec::new());
        let (mut alone, mut with) = (*black, *black);
        for (c, ramp) in ramps.iter().enumerate() {
            let light = column(c) * curve(c, v);
            let from_grey = from(c, |x| x.ramp.and(x.grey));
            for p in ramp.points.iter().filter(near(v)) {
                uncorrected.push(delta_e00_xyz(&p.xyz, &(black + light), white));
                corrected.push(delta_e00_xyz(
                    &p.xyz,
                    &(black + light * (1.0 + from_grey)),
                    white,
                ));
            }
            alone += light;
            with += light * (1.0 + from(c, |x| x.grey.and(x.ramp)));
        }
        // The grey of this code, predicted by every channel's curve there, each
        // corrected from its ramp reading of the code where it has one.
        if let Some(first) = ramps
            .iter()
            .find_map(|r| r.grey_points.iter().find(near(v)))
        {
            uncorrected.push(delta_e00_xyz(&first.xyz, &alone, white));
            corrected.push(delta_e00_xyz(&first.xyz, &with, white));
        }
        by_code.push((uncorrected, corrected));
    }
    by_code
}

/// The shrunk residual at code `k` of one channel's `codes` from one `estimate` of it,
/// with the prior's spread from the channel's other codes.
fn left_out_correction(
    codes: &[CodeEstimates],
    k: usize,
    estimate: Estimate,
    curve: impl Fn(f64) -> f64,
    noise_scale: f64,
) -> f64 {
    let others: Vec<CodeEstimates> = codes
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != k)
        .map(|(_, code)| *code)
        .collect();
    let prior = residuals(&others, &curve, noise_scale, |x| {
        Estimate::pooled(x.ramp, x.grey)
    });
    let predicted = curve(codes[k].drive);
    if !(predicted > 0.0) {
        return 0.0;
    }
    let r = estimate.excitation / predicted - 1.0;
    shrunk(
        r,
        noise_scale * estimate.sigma / predicted,
        prior_spread(&prior),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::laws::fit_law;
    use crate::transfer::LawKind;
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    const STEP: f64 = 1.0 / 255.0;

    /// Columns of a display with sRGB-like primaries (Y of white 100).
    fn columns() -> [Xyz; 3] {
        [
            Xyz::new(41.2, 21.3, 1.9),
            Xyz::new(35.8, 71.5, 11.9),
            Xyz::new(18.0, 7.2, 95.0),
        ]
    }

    /// A display whose channel c shows `truth(c, v)` at drive v, read with relative
    /// noise `sigma` (stated to the fit as `stated`): ramps at 1/7 steps, greys at 1/28
    /// steps, each grey's excitations shared out as the fit does, plus `extra` added to
    /// every grey's channel shares (a display that is not additive).
    fn measured(
        truth: impl Fn(usize, f64) -> f64,
        sigma: f64,
        stated: f64,
        extra: f64,
        seed: u64,
    ) -> [ChannelRamp; 3] {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let normal = Normal::new(0.0, 1.0).unwrap();
        let mut noisy = |x: f64| x * (1.0 + sigma * normal.sample(&mut rng));
        let cols = columns();
        let greys: Vec<(f64, [f64; 3])> = (1..28)
            .map(|k| {
                let v = k as f64 / 28.0;
                (v, [0, 1, 2].map(|c| noisy(truth(c, v) * (1.0 + extra))))
            })
            .collect();
        [0, 1, 2].map(|c| {
            let points = (1..=7)
                .map(|k| {
                    let v = k as f64 / 7.0;
                    let e = if k == 7 { 1.0 } else { noisy(truth(c, v)) };
                    RampPoint {
                        index: k,
                        drive: v,
                        excitation: e,
                        sigma: stated * e.max(1e-3),
                        xyz: cols[c] * e,
                    }
                })
                .collect();
            let grey_points = greys
                .iter()
                .enumerate()
                .map(|(index, (v, e))| RampPoint {
                    index: 100 + index,
                    drive: *v,
                    excitation: e[c],
                    sigma: 2.0 * stated * e[c].max(1e-3),
                    xyz: cols[0] * e[0] + cols[1] * e[1] + cols[2] * e[2],
                })
                .collect();
            ChannelRamp {
                channel: c,
                direction: cols[c].normalize(),
                direction_se: Vector3::zeros(),
                normaliser: cols[c].norm(),
                normaliser_se: 0.0,
                pinned: true,
                points,
                grey_points,
            }
        })
    }

    /// A panel's look-up table error: its own for every code, repeating, up to 3 % and
    /// below half a code step's rise (a panel's curve stays monotone).
    fn wiggle(c: usize, v: f64) -> f64 {
        let code = (v * 255.0).round();
        let hash = ((code * 12.9898 + c as f64 * 78.233).sin() * 43758.5453).rem_euclid(1.0);
        (0.003 / v).min(0.03) * (2.0 * hash - 1.0)
    }

    fn judged(ramps: &[ChannelRamp; 3]) -> (CodeCorrectionReport, Option<Vec<LawFit>>) {
        let fits: Vec<LawFit> = ramps
            .iter()
            .map(|r| fit_law(LawKind::Power, r, STEP).unwrap())
            .collect();
        judge(&Judged {
            ramps,
            fits: [&fits[0], &fits[1], &fits[2]],
            black: &Xyz::zeros(),
            white: &(columns()[0] + columns()[1] + columns()[2]),
            code_step: STEP,
            tolerance: 0.05,
        })
    }

    #[test]
    fn errors_that_repeat_at_a_code_are_corrected_there_and_nowhere_else() {
        let truth = |c: usize, v: f64| v.powf(2.2) * (1.0 + wiggle(c, v));
        let ramps = measured(truth, 0.0005, 0.003, 0.0, 1);
        let (report, fits) = judged(&ramps);
        assert!(report.kept, "{report:?}");
        // The stated noise was six times the real one; the replicates say so.
        let scale = report.noise_scale.unwrap();
        assert!(scale < 0.5, "{scale}");
        let fits = fits.unwrap();
        let law = fit_law(LawKind::Power, &ramps[1], STEP).unwrap();
        for k in 1..28 {
            let v = k as f64 / 28.0;
            let (t, corrected) = (truth(1, v), fits[1].law.excitation(v));
            assert!((corrected / t - 1.0).abs() < 0.004, "{v}: {corrected} {t}");
            // Two codes away the correction is gone: the law's own value there, and
            // half-way to the next grey within 0.2 % of it.
            for beside in [v + 2.0 * STEP, v + 0.5 / 28.0] {
                let (a, b) = (fits[1].law.excitation(beside), law.law.excitation(beside));
                assert!((a / b - 1.0).abs() < 2e-3, "{beside}: {a} {b}");
            }
        }
        fits[1].law.monotonicity().unwrap();
    }

    #[test]
    fn greys_that_disagree_with_the_ramps_are_not_taken_for_the_codes() {
        // Smooth curves, greys 3 % brighter than their channels (channel interaction):
        // what a grey says of a code, the ramp reading of the code does not repeat.
        let truth = |_: usize, v: f64| v.powf(2.2);
        let ramps = measured(truth, 0.0005, 0.003, 0.03, 2);
        let (report, fits) = judged(&ramps);
        assert!(!report.kept, "{report:?}");
        assert!(fits.is_none());
        assert!(report.noise_scale.unwrap() > 1.0, "{report:?}");
    }

    #[test]
    fn noise_alone_is_not_corrected() {
        // A smooth display read with the noise the fit was told of: the correction may
        // be kept in no more than 1 of 20 runs.
        let truth = |_: usize, v: f64| v.powf(2.2);
        let kept = (0..20)
            .filter(|seed| {
                let ramps = measured(truth, 0.003, 0.003, 0.0, 100 + seed);
                judged(&ramps).0.kept
            })
            .count();
        assert!(kept <= 1, "kept in {kept} of 20");
    }

    #[test]
    fn without_a_code_measured_twice_nothing_is_judged_or_made() {
        let truth = |c: usize, v: f64| v.powf(2.2) * (1.0 + wiggle(c, v));
        let mut ramps = measured(truth, 0.0005, 0.003, 0.0, 3);
        for r in ramps.iter_mut() {
            // Greys only between the ramp's steps.
            r.grey_points
                .retain(|p| ((p.drive * 7.0).round() - p.drive * 7.0).abs() > 1e-6);
        }
        let (report, fits) = judged(&ramps);
        assert_eq!(report.replicates, 0);
        assert!(!report.kept && fits.is_none(), "{report:?}");
        assert!(report.rule.starts_with("not tried"), "{}", report.rule);
    }

    #[test]
    fn codes_closer_than_half_a_step_are_one_code() {
        let truth = |c: usize, v: f64| v.powf(2.2) * (1.0 + wiggle(c, v));
        for (shift, merged) in [(1e-6, true), (0.4 * STEP, true), (0.6 * STEP, false)] {
            let mut ramps = measured(truth, 0.0005, 0.003, 0.0, 4);
            // A chart's 57.1429 % and 57.143 % are one code; 0.6 of a step is another.
            for p in ramps[0].grey_points.iter_mut() {
                p.drive += shift;
            }
            let codes = code_estimates(&ramps[0], STEP);
            let both = codes
                .iter()
                .filter(|c| c.ramp.is_some() && c.grey.is_some())
                .count();
            assert_eq!(both, if merged { 6 } else { 0 }, "{shift}");
            assert_eq!(codes.len(), if merged { 27 } else { 33 }, "{shift}");
        }
    }

    #[test]
    fn a_code_below_the_law_a_step_under_it_keeps_its_value() {
        // Above half drive one code step raises a power law by about 1 %; a code read
        // 3 % low must stay 3 % low, the law's samples beside it giving way.
        let bright = 5.0 / 7.0;
        let truth = move |c: usize, v: f64| {
            let dip = if (v - bright).abs() < 1e-9 { 0.97 } else { 1.0 };
            v.powf(2.2) * (1.0 + wiggle(c, v)) * dip
        };
        let ramps = measured(truth, 0.0005, 0.003, 0.0, 5);
        let law = fit_law(LawKind::Power, &ramps[2], STEP).unwrap();
        let correction = CodeCorrection {
            code_step: STEP,
            noise_scale: 0.2,
        };
        let fit = correct_at_codes(&law, &ramps[2], correction).unwrap();
        let (t, corrected) = (truth(2, bright), fit.law.excitation(bright));
        assert!((corrected / t - 1.0).abs() < 0.004, "{corrected} {t}");
        fit.law.monotonicity().unwrap();
    }
}
