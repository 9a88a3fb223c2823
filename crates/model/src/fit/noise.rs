//! How noisy the readings are, and how the display drifted during the run: both from
//! the repeats the plan builds in (the reference white shown through the run, and
//! repeated blacks), so weights and corrections come from this run's own data.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::least_squares::fit_linear;
use super::select::simplest_within_noise;
use super::stats::{mean, standard_deviation};

/// Relative noise assumed when the readings cannot tell (fewer than three repeats),
/// and the prior the measured value is shrunk towards.
pub const ASSUMED_RELATIVE_NOISE: f64 = 0.003;
/// Weight of [`ASSUMED_RELATIVE_NOISE`] in degrees of freedom. A handful of reference
/// readings can, by chance, scatter ten times less than the instrument's real noise;
/// pooling them with a prior worth two readings keeps the uncertainties honest.
pub const PRIOR_DEGREES_OF_FREEDOM: f64 = 2.0;
/// Noise floor assumed when fewer than two blacks were read, as a fraction of white.
pub const ASSUMED_FLOOR_OF_WHITE: f64 = 5e-5;

/// σ(Y) = √(floor² + (relative · Y)²): the standard deviation of a reading of
/// luminance Y. Used to weight every fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseModel {
    pub relative: f64,
    /// Same unit as the readings.
    pub floor: f64,
    /// Where the numbers come from.
    pub relative_from: String,
    pub floor_from: String,
}

impl NoiseModel {
    pub fn sigma(&self, y: f64) -> f64 {
        (self.floor * self.floor + (self.relative * y).powi(2))
            .sqrt()
            .max(f64::MIN_POSITIVE)
    }
}

/// Noise model from the relative scatter of the reference white about its drift
/// (with its degrees of freedom), if known, and the scatter of repeated blacks.
///
/// The relative noise is the pooled variance of the measured scatter and the prior:
/// σ² = (ν s² + ν₀ σ₀²) / (ν + ν₀), with σ₀ = [`ASSUMED_RELATIVE_NOISE`] and
/// ν₀ = [`PRIOR_DEGREES_OF_FREEDOM`].
pub fn estimate_noise(
    relative: Option<(f64, usize)>,
    black_ys: &[f64],
    white_y: f64,
) -> NoiseModel {
    let (relative, relative_from) = match relative {
        Some((s, dof)) if s > 0.0 && dof > 0 => {
            let nu = dof as f64;
            let pooled = ((nu * s * s
                + PRIOR_DEGREES_OF_FREEDOM * ASSUMED_RELATIVE_NOISE * ASSUMED_RELATIVE_NOISE)
                / (nu + PRIOR_DEGREES_OF_FREEDOM))
                .sqrt();
            (
                pooled,
                format!(
                    "scatter of the reference white about its drift ({s:.5}, {dof} degrees of freedom) pooled with a prior of {ASSUMED_RELATIVE_NOISE}"
                ),
            )
        }
        _ => (
            ASSUMED_RELATIVE_NOISE,
            format!("assumed ({ASSUMED_RELATIVE_NOISE}): too few reference repeats"),
        ),
    };
    let assumed_floor = ASSUMED_FLOOR_OF_WHITE * white_y.abs();
    let (floor, floor_from) = if black_ys.len() >= 2 {
        let sd = standard_deviation(black_ys);
        let black = mean(black_ys);
        let floor = (sd * sd - (relative * black).powi(2)).max(0.0).sqrt();
        // Two readings leave one degree of freedom; never trust a floor far below
        // what the assumption would give.
        let floor = floor.max(0.1 * assumed_floor);
        (
            floor,
            format!("scatter of {} black readings", black_ys.len()),
        )
    } else {
        (
            assumed_floor,
            format!("assumed ({ASSUMED_FLOOR_OF_WHITE} of white): fewer than two blacks"),
        )
    };
    NoiseModel {
        relative,
        floor,
        relative_from,
        floor_from,
    }
}

/// A smooth drift of the display's light over the run: a polynomial in normalised
/// time, read as a gain relative to the end of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftModel {
    pub t_first: f64,
    pub t_last: f64,
    /// Polynomial coefficients in τ = (t − t_first)/(t_last − t_first), constant first.
    pub coefficients: Vec<f64>,
}

impl DriftModel {
    fn level(&self, t: f64) -> f64 {
        let span = self.t_last - self.t_first;
        let tau = if span > 0.0 {
            ((t - self.t_first) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.coefficients
            .iter()
            .rev()
            .fold(0.0, |acc, c| acc * tau + c)
    }

    /// Gain at time `t` relative to the end of the run: a reading at `t` is divided by
    /// this to say what the display would have given at the end.
    pub fn gain(&self, t: f64) -> f64 {
        let end = self.level(self.t_last);
        if end > 0.0 { self.level(t) / end } else { 1.0 }
    }
}

/// What the drift analysis found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DriftReport {
    pub references: usize,
    /// Degree of the polynomial kept (0: no drift beyond noise).
    pub degree: Option<usize>,
    /// Largest departure of the fitted gain from the end-of-run value, percent.
    pub amplitude_percent: f64,
    pub corrected: bool,
    /// Relative scatter of the references about the drift curve, from their
    /// leave-one-out prediction errors, and its degrees of freedom.
    pub residual_relative_sd: Option<f64>,
    pub residual_dof: usize,
    pub note: String,
}

/// Fit the drift of the reference signal (reference luminance minus black) over time,
/// choosing the polynomial degree by leave-one-out error (simplest within noise).
/// Returns the model (`None` when no correction is due) and the report.
pub fn estimate_drift(
    references: &[(f64, f64)],
    correct: bool,
) -> (Option<DriftModel>, DriftReport) {
    let n = references.len();
    let report = |degree: Option<usize>, amplitude, corrected, sd, note: String| DriftReport {
        references: n,
        degree,
        amplitude_percent: amplitude,
        corrected,
        residual_relative_sd: sd,
        residual_dof: degree.map_or(0, |d| n.saturating_sub(d + 1)),
        note,
    };
    let not_followed = |note: String| (None, report(None, 0.0, false, None, note));
    if n < 3 {
        return not_followed(format!("{n} reference readings: too few to follow drift"));
    }
    let t_first = references.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
    let t_last = references
        .iter()
        .map(|r| r.0)
        .fold(f64::NEG_INFINITY, f64::max);
    let span = (t_last - t_first).max(f64::MIN_POSITIVE);
    let level = mean(&references.iter().map(|r| r.1).collect::<Vec<_>>());
    if !(level > 0.0) {
        return not_followed("the reference gave no light above black".into());
    }
    let errors: Vec<Option<Vec<f64>>> = (0..=3.min(n - 3))
        .map(|degree| leave_one_out_drift_errors(references, degree, t_first, t_last, level))
        .collect();
    let degree = simplest_within_noise(&errors, 0.0).unwrap_or(0);
    let Some(coefficients) = fit_drift_polynomial(references, degree, t_first, span) else {
        return not_followed("the drift fit failed".into());
    };
    // Leave-one-out errors are honest even when the polynomial nearly interpolates
    // the few references; their variance is σ²(1 + p/n) for p coefficients.
    let sd = errors[degree].as_ref().map(|e| {
        let rms = (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
        rms / (1.0 + (degree + 1) as f64 / n as f64).sqrt()
    });
    let model = DriftModel {
        t_first,
        t_last,
        coefficients,
    };
    let amplitude = references
        .iter()
        .map(|r| (model.gain(r.0) - 1.0).abs())
        .fold(0.0, f64::max)
        * 100.0;
    if degree == 0 {
        return (
            None,
            report(
                Some(0),
                0.0,
                false,
                sd,
                "no drift beyond the noise of the reference readings".into(),
            ),
        );
    }
    let note = if correct {
        format!("degree-{degree} drift of up to {amplitude:.2} %, corrected to the end of the run")
    } else {
        format!("degree-{degree} drift of up to {amplitude:.2} %, not corrected (switched off)")
    };
    (
        correct.then_some(model),
        report(Some(degree), amplitude, correct, sd, note),
    )
}

/// Least-squares polynomial of `degree` in normalised time through `points`.
fn fit_drift_polynomial(
    points: &[(f64, f64)],
    degree: usize,
    t_first: f64,
    span: f64,
) -> Option<Vec<f64>> {
    let design = DMatrix::from_fn(points.len(), degree + 1, |i, k| {
        ((points[i].0 - t_first) / span).powi(k as i32)
    });
    let y: Vec<f64> = points.iter().map(|p| p.1).collect();
    fit_linear(&design, &y, &vec![1.0; points.len()])
        .ok()
        .map(|f| f.params)
}

/// Each reference predicted by the polynomial of `degree` fitted to the others, as a
/// relative error; `None` if some fit failed.
fn leave_one_out_drift_errors(
    references: &[(f64, f64)],
    degree: usize,
    t_first: f64,
    t_last: f64,
    level: f64,
) -> Option<Vec<f64>> {
    let span = (t_last - t_first).max(f64::MIN_POSITIVE);
    (0..references.len())
        .map(|held| {
            let training: Vec<(f64, f64)> = references
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != held)
                .map(|(_, p)| *p)
                .collect();
            let model = DriftModel {
                t_first,
                t_last,
                coefficients: fit_drift_polynomial(&training, degree, t_first, span)?,
            };
            Some((model.level(references[held].0) - references[held].1).abs() / level)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_display_needs_no_drift_model() {
        let wiggle = [0.2, -0.5, 0.4, -0.1, 0.3, -0.4, 0.1, -0.2];
        let refs: Vec<(f64, f64)> = wiggle
            .iter()
            .enumerate()
            .map(|(i, w)| (i as f64 * 60.0, 100.0 * (1.0 + 0.002 * w)))
            .collect();
        let (model, report) = estimate_drift(&refs, true);
        assert!(model.is_none(), "{report:?}");
        assert_eq!(report.degree, Some(0));
        let sd = report.residual_relative_sd.unwrap();
        assert!(sd > 0.0005 && sd < 0.004, "{sd}");
    }

    #[test]
    fn a_linear_drift_is_found_and_corrected_to_the_end() {
        let wiggle = [0.2, -0.5, 0.4, -0.1, 0.3, -0.4, 0.1, -0.2];
        let refs: Vec<(f64, f64)> = wiggle
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let t = i as f64 * 60.0;
                (t, 100.0 * (1.0 + 0.0001 * t) * (1.0 + 0.001 * w))
            })
            .collect();
        let (model, report) = estimate_drift(&refs, true);
        let model = model.expect("drift must be found");
        assert!(report.degree.unwrap() >= 1);
        // The start is about 4 % below the end.
        assert!(
            (model.gain(0.0) - 1.0 / 1.042).abs() < 0.003,
            "{}",
            model.gain(0.0)
        );
        assert!((model.gain(420.0) - 1.0).abs() < 1e-12);
        assert!(report.amplitude_percent > 3.0 && report.amplitude_percent < 5.0);
    }

    #[test]
    fn noise_floor_comes_from_black_repeats() {
        let noise = estimate_noise(Some((0.002, 1000)), &[0.050, 0.052, 0.048], 100.0);
        assert!((noise.floor - 0.002).abs() < 0.0005, "{noise:?}");
        assert!((noise.sigma(100.0) - 0.2).abs() < 0.01);
        // Three references that happen to agree closely do not make a quiet instrument.
        let lucky = estimate_noise(Some((0.0002, 2)), &[0.05, 0.05], 100.0);
        assert!(lucky.relative > 0.002, "{lucky:?}");
        let assumed = estimate_noise(None, &[0.05], 100.0);
        assert_eq!(assumed.relative, ASSUMED_RELATIVE_NOISE);
        assert!(assumed.floor_from.starts_with("assumed"));
    }
}
