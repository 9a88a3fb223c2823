//! Fitting each transfer law to a channel's excitations by weighted nonlinear least
//! squares (each reading weighted by its own noise, see `least_squares`), with
//! standard errors from the Jacobian.
//!
//! Power, Cowan and gain-offset-gamma pass through the full-drive reading (E(1) = 1,
//! "pinned"); the three-term law's C frees it from that point. Their standard errors
//! include the uncertainty of the full-drive reading they pass through. The table law
//! is a weighted isotonic regression of the levels (pool-adjacent-violators, Ayer et
//! al. 1955) joined by a monotone cubic.
//!
//! A log law that turns back near zero (B > 0 with its turning point above the toe)
//! is refitted with the slope of ln E against ln v at the toe held at a small positive
//! value, so the published curve rises everywhere it is used; the fit says so.

use serde::{Deserialize, Serialize};

use super::least_squares::{Curve, LeastSquares, LeastSquaresError, fit_curve, fit_linear};
use super::primaries::ChannelRamp;
use crate::transfer::{
    Cowan, GainOffsetGamma, Hlg, LawKind, Power, Pq, Table, ThreeTerm, TransferError, TransferLaw,
};
use chromacal_color::hdr::hlg_scene_light;
use chromacal_color::ictcp::{PQ_PEAK, pq_eotf};
use nalgebra::DMatrix;

/// Slope d ln E / d ln v held at the toe when a log law has to be constrained.
const TOE_SLOPE: f64 = 0.1;
/// Largest exponent allowed in the log laws (beyond it exp overflows).
const MAX_EXPONENT: f64 = 700.0;

/// A fitted parameter with its standard error (`None` when it cannot be estimated,
/// e.g. as many levels as parameters).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FittedParameter {
    pub name: String,
    pub value: f64,
    pub standard_error: Option<f64>,
}

/// One law fitted to one channel.
#[derive(Debug, Clone, PartialEq)]
pub struct LawFit {
    pub law: TransferLaw,
    /// Excitation 1 is this many times the ramp's normaliser (1 when pinned).
    pub amplitude: f64,
    pub parameters: Vec<FittedParameter>,
    pub chi2: f64,
    pub dof: usize,
    /// Number of parameters fitted (levels, for the table).
    pub free_parameters: usize,
    pub notes: Vec<String>,
}

/// Why a law could not be fitted to a channel.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LawFitError {
    #[error("{law} needs {need} drive levels, the ramp has {have}")]
    TooFewLevels {
        law: LawKind,
        need: usize,
        have: usize,
    },
    #[error("{law} needs a full-drive reading, and full drive was not measured")]
    NeedsFullDrive { law: LawKind },
    #[error("{law}: {source}")]
    LeastSquares {
        law: LawKind,
        source: LeastSquaresError,
    },
    #[error("{law} is not monotone even when constrained: {source}")]
    NotMonotone { law: LawKind, source: TransferError },
}

/// The points a law is fitted to.
struct Points {
    drive: Vec<f64>,
    excitation: Vec<f64>,
    sigma: Vec<f64>,
}

impl Points {
    fn from_ramp(ramp: &ChannelRamp, include_full: bool) -> Self {
        let chosen: Vec<_> = ramp
            .law_points()
            .filter(|p| include_full || p.drive < 1.0)
            .collect();
        Points {
            drive: chosen.iter().map(|p| p.drive).collect(),
            excitation: chosen.iter().map(|p| p.excitation).collect(),
            sigma: chosen.iter().map(|p| p.sigma).collect(),
        }
    }

    fn distinct_levels(&self) -> usize {
        let mut v = self.drive.clone();
        v.sort_by(|a, b| a.total_cmp(b));
        v.dedup();
        v.len()
    }

    /// Fit `curve` to these points from `start`, errors named for `law`.
    fn fit(
        &self,
        law: LawKind,
        curve: Curve<'_>,
        start: &[f64],
    ) -> Result<LeastSquares, LawFitError> {
        fit_curve(curve, &self.drive, &self.excitation, &self.sigma, start)
            .map_err(|source| LawFitError::LeastSquares { law, source })
    }

    /// Points bright enough (5σ) to take a logarithm of.
    fn loggable(&self) -> Vec<usize> {
        (0..self.drive.len())
            .filter(|i| self.excitation[*i] > 5.0 * self.sigma[*i] && self.drive[*i] > 0.0)
            .collect()
    }
}

fn clamp_exp(x: f64) -> f64 {
    x.min(MAX_EXPONENT).exp()
}

/// Starting values for ln e = Σ θₖ·basisₖ(ln v) from the loggable points, weighted by
/// the relative noise of each (σ of ln e ≈ σ/e).
fn log_linear_start(
    points: &Points,
    basis: &dyn Fn(f64) -> Vec<f64>,
    fallback: &[f64],
) -> Vec<f64> {
    let idx = points.loggable();
    let p = fallback.len();
    if idx.len() < p {
        return fallback.to_vec();
    }
    let design = DMatrix::from_fn(idx.len(), p, |r, k| basis(points.drive[idx[r]].ln())[k]);
    let y: Vec<f64> = idx.iter().map(|i| points.excitation[*i].ln()).collect();
    let s: Vec<f64> = idx
        .iter()
        .map(|i| points.sigma[*i] / points.excitation[*i])
        .collect();
    match fit_linear(&design, &y, &s) {
        Ok(f) if f.params.iter().all(|v| v.is_finite()) => f.params,
        _ => fallback.to_vec(),
    }
}

/// Fit law `kind` to `ramp`. `toe` is the smallest non-zero drive the display can be
/// sent (one code step); log laws are linear below it.
pub fn fit_law(kind: LawKind, ramp: &ChannelRamp, toe: f64) -> Result<LawFit, LawFitError> {
    let pinned = ramp.pinned;
    match kind {
        LawKind::Table => fit_table(ramp),
        LawKind::ThreeTerm if !pinned => Err(LawFitError::NeedsFullDrive { law: kind }),
        LawKind::ThreeTerm => fit_log_law(kind, ramp, toe),
        LawKind::Cowan => fit_log_law(kind, ramp, toe),
        LawKind::Power => fit_power(ramp),
        LawKind::GainOffsetGamma => fit_gog(ramp),
        LawKind::Pq if !pinned => Err(LawFitError::NeedsFullDrive { law: kind }),
        LawKind::Pq => fit_pq(ramp),
        LawKind::PqCowan if !pinned => Err(LawFitError::NeedsFullDrive { law: kind }),
        LawKind::PqCowan => fit_pq_cowan(ramp),
        LawKind::Hlg if !pinned => Err(LawFitError::NeedsFullDrive { law: kind }),
        LawKind::Hlg => fit_hlg(ramp),
        LawKind::HlgCowan if !pinned => Err(LawFitError::NeedsFullDrive { law: kind }),
        LawKind::HlgCowan => fit_hlg_cowan(ramp),
    }
}

fn need_levels(law: LawKind, points: &Points, need: usize) -> Result<(), LawFitError> {
    let have = points.distinct_levels();
    if have < need {
        return Err(LawFitError::TooFewLevels { law, need, have });
    }
    Ok(())
}

/// Standard errors including the uncertainty of the normaliser the data were divided
/// by: dθ/dδ = −(J̃ᵀJ̃)⁻¹ J̃ᵀ (e/σ) for a relative change δ of the normaliser.
fn standard_errors_with_pin(
    fit: &LeastSquares,
    points: &Points,
    ramp: &ChannelRamp,
) -> Vec<Option<f64>> {
    let base = fit.standard_errors();
    let (Some(cov), Some(sens)) = (&fit.covariance, &fit.sensitivity) else {
        return base;
    };
    if !ramp.pinned {
        return base;
    }
    let delta_sd = ramp.normaliser_se / ramp.normaliser;
    let weighted = nalgebra::DVector::from_iterator(
        points.excitation.len(),
        points
            .excitation
            .iter()
            .zip(&points.sigma)
            .map(|(e, s)| e / s),
    );
    let d = sens * weighted;
    (0..fit.params.len())
        .map(|k| Some((cov[(k, k)] + (d[k] * delta_sd).powi(2)).max(0.0).sqrt()))
        .collect()
}

fn parameter(name: &str, value: f64, se: Option<f64>) -> FittedParameter {
    FittedParameter {
        name: name.to_string(),
        value,
        standard_error: se,
    }
}

fn fit_power(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::Power;
    let pinned = ramp.pinned;
    let points = Points::from_ramp(ramp, !pinned);
    need_levels(kind, &points, if pinned { 1 } else { 2 })?;
    let (fit, gamma, amplitude, ses) = if pinned {
        let start = log_linear_start(&points, &|u| vec![u], &[2.2]);
        // v^γ as exp(γ ln v): one logarithm serves the value and the derivative.
        let curve = |t: &[f64], v: f64, g: &mut [f64]| {
            let ln_v = v.ln();
            let f = (t[0] * ln_v).exp();
            g[0] = f * ln_v;
            f
        };
        let fit = points.fit(kind, &curve, &start)?;
        let ses = standard_errors_with_pin(&fit, &points, ramp);
        (fit.clone(), fit.params[0], 1.0, ses)
    } else {
        let start = log_linear_start(&points, &|u| vec![u, 1.0], &[2.2, 0.0]);
        let curve = |t: &[f64], v: f64, g: &mut [f64]| {
            let ln_v = v.ln();
            let p = (t[0] * ln_v).exp();
            g[0] = t[1] * p * ln_v;
            g[1] = p;
            t[1] * p
        };
        let start = [start[0], start[1].exp()];
        let fit = points.fit(kind, &curve, &start)?;
        let ses = fit.standard_errors();
        (fit.clone(), fit.params[0], fit.params[1], ses)
    };
    let law = TransferLaw::Power(Power { gamma });
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let mut parameters = vec![parameter("gamma", gamma, ses[0])];
    if !pinned {
        parameters.push(parameter("amplitude", amplitude, ses[1]));
    }
    Ok(LawFit {
        law,
        amplitude,
        parameters,
        chi2: fit.chi2,
        dof: fit.dof,
        free_parameters: fit.params.len(),
        notes: Vec::new(),
    })
}

fn fit_gog(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::GainOffsetGamma;
    let pinned = ramp.pinned;
    let points = Points::from_ramp(ramp, !pinned);
    need_levels(kind, &points, if pinned { 2 } else { 3 })?;
    let curve = move |t: &[f64], v: f64, g: &mut [f64]| gog_curve(pinned, t, v, g);
    let start = gog_start(&points, pinned, &curve);
    if start[1] == 0.0 && pinned {
        // The optimum under the constraint may be on its boundary: then no search.
        if let Ok(power) = fit_power(ramp)
            && cutoff_wants_below_zero(&points, &power, &curve)
        {
            return Ok(gog_with_cutoff_at_zero(ramp, power, None));
        }
    }
    let fit = points.fit(kind, &curve, &start)?;
    if fit.params[1] < 0.0 {
        return Ok(gog_with_cutoff_at_zero(
            ramp,
            fit_power(ramp)?,
            Some(fit.params[1]),
        ));
    }
    let ses = standard_errors_with_pin(&fit, &points, ramp);
    let (gamma, cutoff) = (fit.params[0], fit.params[1]);
    let amplitude = if pinned { 1.0 } else { fit.params[2] };
    let law = TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(cutoff, gamma));
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    Ok(LawFit {
        law,
        amplitude,
        parameters: gog_parameters(gamma, cutoff, amplitude, &ses, pinned),
        chi2: fit.chi2,
        dof: fit.dof,
        free_parameters: fit.params.len(),
        notes: Vec::new(),
    })
}

/// The gain-offset-gamma curve and its gradient, θ = [γ, v₀] (+ amplitude):
/// E = a·((v − v₀)/(1 − v₀))^γ above the cut-off v₀, 0 below it (Berns 1996).
fn gog_curve(pinned: bool, t: &[f64], v: f64, g: &mut [f64]) -> f64 {
    let (gamma, cutoff) = (t[0], t[1].min(0.95));
    let amplitude = if pinned { 1.0 } else { t[2] };
    let base = (v - cutoff) / (1.0 - cutoff);
    if base <= 0.0 {
        g.iter_mut().for_each(|x| *x = 0.0);
        return 0.0;
    }
    let ln_base = base.ln();
    let p = (gamma * ln_base).exp();
    g[0] = amplitude * p * ln_base;
    // base^(γ−1) = p / base, without a second power.
    g[1] = amplitude * gamma * (p / base) * (v - 1.0) / (1.0 - cutoff).powi(2);
    if !pinned {
        g[2] = p;
    }
    amplitude * p
}

/// Masters a PQ display's roll-off may start from, cd/m² (`None`: it clips at its
/// peak); the one of least χ² is kept.
const PQ_ROLLOFFS: [Option<f64>; 5] = [
    None,
    Some(1000.0),
    Some(2000.0),
    Some(4000.0),
    Some(10_000.0),
];

/// The PQ law (`transfer::Pq`), θ = [ln peak, exponent], fitted for each roll-off in
/// `PQ_ROLLOFFS` (those above the peak), the least χ² kept. The gradient is by
/// central differences: the EETF's spline has no tidy derivative in θ.
fn fit_pq(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::Pq;
    let points = Points::from_ramp(ramp, false);
    need_levels(kind, &points, 2)?;
    let peak0 = pq_start_peak(&points);
    let (fit, rolloff) =
        least_chi2_over_rolloffs(|rolloff| fit_pq_with_rolloff(&points, rolloff, peak0))?;
    let pq = pq_law(&fit.params, rolloff);
    let (peak, rolloff_from, exponent) = (pq.peak, pq.rolloff_from, pq.exponent);
    let law = TransferLaw::Pq(pq);
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let ses = standard_errors_with_pin(&fit, &points, ramp);
    Ok(LawFit {
        law,
        amplitude: 1.0,
        parameters: vec![
            parameter("peak", peak, ses[0].map(|s| s * peak)),
            parameter("exponent", exponent, ses[1]),
            parameter("rolloff_from", rolloff_from, None),
        ],
        chi2: fit.chi2,
        dof: fit.dof,
        free_parameters: 2,
        notes: vec![rolloff_note(rolloff_from, peak)],
    })
}

/// What a PQ law does at its top: rolled off from a master's peak, or clipped.
fn rolloff_note(rolloff_from: f64, peak: f64) -> String {
    if rolloff_from > peak {
        format!("rolled off from {rolloff_from} cd/m² (BT.2390)")
    } else {
        "clipped at the peak".into()
    }
}

/// `f` at `t` (its value returned) and its gradient in `g` by central differences,
/// steps of 10⁻⁶ of each parameter's size: for laws whose derivative in θ is not tidy
/// (the EETF's spline).
fn central_differences(f: impl Fn(&[f64]) -> f64, t: &[f64], g: &mut [f64]) -> f64 {
    let mut moved = t.to_vec();
    for k in 0..t.len() {
        let h = 1e-6 * (1.0 + t[k].abs());
        moved[k] = t[k] + h;
        let up = f(&moved);
        moved[k] = t[k] - h;
        let down = f(&moved);
        moved[k] = t[k];
        g[k] = (up - down) / (2.0 * h);
    }
    f(t)
}

/// The PQ law with Cowan's log-quadratic term (`transfer::Pq::curvature`), θ = [ln
/// peak, a, b], fitted for each roll-off in `PQ_ROLLOFFS` from the plain PQ law's
/// peak and exponent (b = 0), the least χ² kept. Its toe is the least relative light
/// among the readings (below it the law is a power of the light, as Cowan's is linear
/// below the least drive): what lies below was not measured.
fn fit_pq_cowan(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::PqCowan;
    let points = Points::from_ramp(ramp, false);
    need_levels(kind, &points, 3)?;
    let plain = fit_pq(ramp)?;
    let TransferLaw::Pq(start) = &plain.law else {
        unreachable!("fit_pq gives a PQ law");
    };
    let least_light = least_lit(&points, pq_eotf);
    let law_of = |t: &[f64], rolloff: Option<f64>| {
        let pq = pq_law(&t[..2], rolloff);
        let toe = (least_light / pq.peak).clamp(1e-9, 0.5);
        Pq {
            curvature: t[2].clamp(-1.0, 1.0),
            toe,
            ..pq
        }
    };
    let (fit, rolloff) = least_chi2_over_rolloffs(|rolloff| {
        let curve = move |t: &[f64], v: f64, g: &mut [f64]| {
            central_differences(|t| law_of(t, rolloff).excitation(v), t, g)
        };
        points.fit(kind, &curve, &[start.peak.ln(), start.exponent, 0.0])
    })?;
    let pq = law_of(&fit.params, rolloff);
    let notes = vec![format!(
        "ln E = {:.4} ln x + {:.5} ln² x of the relative light x, a power of x below {:.2e}; {}",
        pq.exponent,
        pq.curvature,
        pq.toe,
        rolloff_note(pq.rolloff_from, pq.peak)
    )];
    let law = TransferLaw::Pq(pq.clone());
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let ses = standard_errors_with_pin(&fit, &points, ramp);
    Ok(LawFit {
        law,
        amplitude: 1.0,
        parameters: vec![
            parameter("peak", pq.peak, ses[0].map(|s| s * pq.peak)),
            parameter("exponent", pq.exponent, ses[1]),
            parameter("curvature", pq.curvature, ses[2]),
            parameter("rolloff_from", pq.rolloff_from, None),
            parameter("toe", pq.toe, None),
        ],
        chi2: fit.chi2,
        dof: fit.dof,
        free_parameters: 3,
        notes,
    })
}

/// Of `fit` with each roll-off in `PQ_ROLLOFFS`, the fit of least χ² and its roll-off;
/// the last failure when none fits.
fn least_chi2_over_rolloffs(
    fit: impl Fn(Option<f64>) -> Result<LeastSquares, LawFitError>,
) -> Result<(LeastSquares, Option<f64>), LawFitError> {
    let mut best: Option<(LeastSquares, Option<f64>)> = None;
    let mut failure = None;
    for rolloff in PQ_ROLLOFFS {
        match fit(rolloff) {
            Ok(fit) if best.as_ref().is_none_or(|(b, _)| fit.chi2 < b.chi2) => {
                best = Some((fit, rolloff))
            }
            Ok(_) => {}
            Err(e) => failure = Some(e),
        }
    }
    match (best, failure) {
        (Some(best), _) => Ok(best),
        (None, Some(e)) => Err(e),
        (None, None) => unreachable!("PQ_ROLLOFFS is not empty"),
    }
}

/// The start of the PQ law's peak: the median of the peaks each mid-range reading
/// implies with exact tracking, L(v) / E.
fn pq_start_peak(points: &Points) -> f64 {
    let mut implied: Vec<f64> = (0..points.drive.len())
        .filter(|&i| points.excitation[i] > 0.01 && points.excitation[i] < 0.6)
        .map(|i| pq_eotf(points.drive[i]) / points.excitation[i])
        .filter(|p| p.is_finite() && *p > 0.0)
        .collect();
    implied.sort_by(|a, b| a.total_cmp(b));
    implied
        .get(implied.len() / 2)
        .copied()
        .unwrap_or(1000.0)
        .clamp(1.0, PQ_PEAK)
}

/// The PQ law of θ = [ln peak, exponent] with its roll-off from `rolloff` (`None`:
/// clipped), bounded to what the law allows.
fn pq_law(t: &[f64], rolloff: Option<f64>) -> Pq {
    let peak = t[0].clamp(0.0, PQ_PEAK.ln()).exp();
    Pq {
        peak,
        rolloff_from: rolloff.map_or(peak, |m| m.max(peak)),
        exponent: t[1].clamp(0.05, 20.0),
        curvature: 0.0,
        toe: 0.0,
    }
}

/// The PQ law fitted with one roll-off, from a peak of `peak0`.
fn fit_pq_with_rolloff(
    points: &Points,
    rolloff: Option<f64>,
    peak0: f64,
) -> Result<LeastSquares, LawFitError> {
    let curve = move |t: &[f64], v: f64, g: &mut [f64]| {
        central_differences(|t| pq_law(t, rolloff).excitation(v), t, g)
    };
    points.fit(LawKind::Pq, &curve, &[peak0.ln(), 1.0])
}

/// The HLG law (`transfer::Hlg`), θ = [p], from BT.2100's system gamma at 1,000
/// cd/m² (1.2): E(v)^p as exp(p ln E(v)), whose derivative is E(v)^p ln E(v).
fn fit_hlg(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::Hlg;
    let points = Points::from_ramp(ramp, false);
    need_levels(kind, &points, 1)?;
    let curve = |t: &[f64], v: f64, g: &mut [f64]| {
        let ln_e = hlg_scene_light(v.clamp(0.0, 1.0))
            .max(f64::MIN_POSITIVE)
            .ln();
        let f = (t[0] * ln_e).exp();
        g[0] = f * ln_e;
        f
    };
    let fit = points.fit(kind, &curve, &[1.2])?;
    let law = TransferLaw::Hlg(Hlg {
        exponent: fit.params[0],
        curvature: 0.0,
        toe: 0.0,
    });
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let ses = standard_errors_with_pin(&fit, &points, ramp);
    Ok(LawFit {
        law,
        amplitude: 1.0,
        parameters: vec![parameter("exponent", fit.params[0], ses[0])],
        chi2: fit.chi2,
        dof: fit.dof,
        free_parameters: 1,
        notes: Vec::new(),
    })
}

/// A start for the gain-offset-gamma fit: the best (least χ²) of a few cut-offs, each
/// with its log-linear gamma.
fn gog_start(points: &Points, pinned: bool, curve: Curve<'_>) -> Vec<f64> {
    let mut best: Option<(f64, Vec<f64>)> = None;
    for cutoff in [0.0, 0.02, 0.05, 0.1, 0.15] {
        let shifted = Points {
            drive: points
                .drive
                .iter()
                .map(|v| ((v - cutoff) / (1.0 - cutoff)).max(1e-9))
                .collect(),
            excitation: points.excitation.clone(),
            sigma: points.sigma.clone(),
        };
        let (gamma, amplitude) = if pinned {
            (log_linear_start(&shifted, &|u| vec![u], &[2.2])[0], 1.0)
        } else {
            let s = log_linear_start(&shifted, &|u| vec![u, 1.0], &[2.2, 0.0]);
            (s[0], s[1].exp())
        };
        let mut start = vec![gamma, cutoff];
        if !pinned {
            start.push(amplitude);
        }
        let mut g = vec![0.0; start.len()];
        let chi2: f64 = (0..points.drive.len())
            .map(|i| {
                ((curve(&start, points.drive[i], &mut g) - points.excitation[i]) / points.sigma[i])
                    .powi(2)
            })
            .sum();
        if best.as_ref().is_none_or(|b| chi2 < b.0) {
            best = Some((chi2, start));
        }
    }
    best.map(|b| b.1).unwrap_or_else(|| vec![2.2, 0.0, 1.0])
}

/// Karush–Kuhn–Tucker at the boundary: at the power law's γ and a cut-off of 0, does
/// χ² fall as the cut-off goes below zero (∂χ²/∂v₀ ≥ 0)? Then, the best start being
/// at 0 as well, the constrained fit is the power law and the search is skipped; on a
/// dense ramp this halves the cost of the gain-offset-gamma candidate.
fn cutoff_wants_below_zero(points: &Points, power: &LawFit, curve: Curve<'_>) -> bool {
    let at = [power.parameters[0].value, 0.0];
    let mut g = [0.0; 2];
    let slope: f64 = (0..points.drive.len())
        .map(|i| {
            let f = curve(&at, points.drive[i], &mut g);
            2.0 * (f - points.excitation[i]) * g[1] / points.sigma[i].powi(2)
        })
        .sum();
    slope >= 0.0
}

/// A negative cut-off means light at zero drive above the measured black: not a law of
/// light above black. The cut-off is held at zero, which is the power law (`power`,
/// fitted to the same ramp).
fn gog_with_cutoff_at_zero(
    ramp: &ChannelRamp,
    power: LawFit,
    unconstrained: Option<f64>,
) -> LawFit {
    let gamma = power.parameters[0].value;
    let ses: Vec<Option<f64>> = vec![
        power.parameters[0].standard_error,
        None,
        power.parameters.get(1).and_then(|p| p.standard_error),
    ];
    LawFit {
        law: TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.0, gamma)),
        amplitude: power.amplitude,
        parameters: gog_parameters(gamma, 0.0, power.amplitude, &ses, ramp.pinned),
        chi2: power.chi2,
        dof: power.dof,
        free_parameters: power.free_parameters,
        notes: vec![match unconstrained {
            Some(c) => format!("the unconstrained cut-off was negative ({c:.4}); held at 0"),
            None => "the cut-off would go below 0 (χ² falls that way from 0); held at 0".into(),
        }],
    }
}

fn gog_parameters(
    gamma: f64,
    cutoff: f64,
    amplitude: f64,
    ses: &[Option<f64>],
    pinned: bool,
) -> Vec<FittedParameter> {
    let gain = 1.0 / (1.0 - cutoff);
    let gain_se = ses
        .get(1)
        .copied()
        .flatten()
        .map(|s| s / (1.0 - cutoff).powi(2));
    let mut p = vec![
        parameter("gamma", gamma, ses.first().copied().flatten()),
        parameter("gain", gain, gain_se),
        parameter("cutoff", cutoff, ses.get(1).copied().flatten()),
    ];
    if !pinned {
        p.push(parameter(
            "amplitude",
            amplitude,
            ses.get(2).copied().flatten(),
        ));
    }
    p
}

/// Cowan (pinned or with a free amplitude) and three-term laws.
fn fit_log_law(kind: LawKind, ramp: &ChannelRamp, toe: f64) -> Result<LawFit, LawFitError> {
    let pinned = ramp.pinned;
    let three = kind == LawKind::ThreeTerm;
    // Three-term fits C, so it needs the full-drive point; pinned Cowan does not.
    let points = Points::from_ramp(ramp, three || !pinned);
    let free_scale = three || !pinned; // third parameter: C or amplitude (as ln a)
    let n_params = if free_scale { 3 } else { 2 };
    need_levels(kind, &points, n_params)?;
    let basis = move |u: f64| {
        if free_scale {
            vec![u, u * u, 1.0]
        } else {
            vec![u, u * u]
        }
    };
    let fallback: Vec<f64> = if free_scale {
        vec![2.2, 0.0, 0.0]
    } else {
        vec![2.2, 0.0]
    };
    let start = log_linear_start(&points, &basis, &fallback);
    // θ = [A, B] or [A, B, C]: E = exp(A u + B u² + C), u = ln v. (For unpinned Cowan
    // C is ln of the amplitude; the law itself is stored without it.)
    let curve = move |t: &[f64], v: f64, g: &mut [f64]| {
        let u = v.ln();
        let c = if free_scale { t[2] } else { 0.0 };
        let f = clamp_exp(t[0] * u + t[1] * u * u + c);
        g[0] = f * u;
        g[1] = f * u * u;
        if free_scale {
            g[2] = f;
        }
        f
    };
    let fit = points.fit(kind, &curve, &start)?;
    let ses = standard_errors_with_pin(&fit, &points, ramp);
    let c = if free_scale { fit.params[2] } else { 0.0 };
    let (law, amplitude) = log_law(kind, fit.params[0], fit.params[1], c, toe);
    match law.monotonicity() {
        Ok(()) => Ok(LawFit {
            law,
            amplitude,
            parameters: log_parameters(kind, &fit.params, &ses, pinned),
            chi2: fit.chi2,
            dof: fit.dof,
            free_parameters: fit.params.len(),
            notes: Vec::new(),
        }),
        Err(TransferError::TurnsBack { at, .. })
            if fit.params[1] > 0.0 && fit.params[0] > TOE_SLOPE =>
        {
            let mut refit = log_law_with_toe_slope_held(kind, ramp, &points, &fit.params, toe)?;
            refit.notes.push(format!(
                "the unconstrained fit turned back at drive {at:.4} (B > 0); refitted with the slope at the toe held at {TOE_SLOPE}"
            ));
            Ok(refit)
        }
        Err(source) => Err(LawFitError::NotMonotone { law: kind, source }),
    }
}

/// The law of `kind` with ln E = A u + B u² (+ C for three-term), and the amplitude
/// (e^C for an unpinned Cowan, whose law is stored without it; 1 otherwise).
fn log_law(kind: LawKind, a: f64, b: f64, c: f64, toe: f64) -> (TransferLaw, f64) {
    if kind == LawKind::ThreeTerm {
        (TransferLaw::ThreeTerm(ThreeTerm { a, b, c, toe }), 1.0)
    } else {
        (TransferLaw::Cowan(Cowan { a, b, toe }), c.exp())
    }
}

/// Refit a log law that turned back near zero (B > 0) with its slope at the toe held:
/// A + 2B ln(toe) = TOE_SLOPE, so B = (TOE_SLOPE − A) / (2 ln toe) and only A (and C)
/// are free. `unconstrained` is the fit that turned back, the start.
fn log_law_with_toe_slope_held(
    kind: LawKind,
    ramp: &ChannelRamp,
    points: &Points,
    unconstrained: &[f64],
    toe: f64,
) -> Result<LawFit, LawFitError> {
    let free_scale = kind == LawKind::ThreeTerm || !ramp.pinned;
    let ln_toe = toe.ln();
    let db_da = -1.0 / (2.0 * ln_toe);
    let b_of = move |a: f64| (TOE_SLOPE - a) / (2.0 * ln_toe);
    let curve = move |t: &[f64], v: f64, g: &mut [f64]| {
        let u = v.ln();
        let c = if free_scale { t[1] } else { 0.0 };
        let f = clamp_exp(t[0] * u + b_of(t[0]) * u * u + c);
        g[0] = f * (u + u * u * db_da);
        if free_scale {
            g[1] = f;
        }
        f
    };
    let start: Vec<f64> = if free_scale {
        vec![unconstrained[0], unconstrained[2]]
    } else {
        vec![unconstrained[0]]
    };
    let constrained = points.fit(kind, &curve, &start)?;
    let cses = standard_errors_with_pin(&constrained, points, ramp);
    let a = constrained.params[0];
    let b = b_of(a);
    let c = if free_scale {
        constrained.params[1]
    } else {
        0.0
    };
    let (law, amplitude) = log_law(kind, a, b, c, toe);
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let b_se = cses[0].map(|s| s * db_da.abs());
    let (full, full_ses) = if free_scale {
        (vec![a, b, c], vec![cses[0], b_se, cses[1]])
    } else {
        (vec![a, b], vec![cses[0], b_se])
    };
    Ok(LawFit {
        law,
        amplitude,
        parameters: log_parameters(kind, &full, &full_ses, ramp.pinned),
        chi2: constrained.chi2,
        dof: constrained.dof,
        free_parameters: constrained.params.len(),
        notes: Vec::new(),
    })
}

fn log_parameters(
    kind: LawKind,
    params: &[f64],
    ses: &[Option<f64>],
    pinned: bool,
) -> Vec<FittedParameter> {
    let mut p = vec![
        parameter("A", params[0], ses[0]),
        parameter("B", params[1], ses[1]),
    ];
    if kind == LawKind::ThreeTerm {
        p.push(parameter("C", params[2], ses[2]));
    } else if !pinned {
        let a = params[2].exp();
        p.push(parameter("amplitude", a, ses[2].map(|s| s * a)));
    }
    p
}

/// Weighted pool-adjacent-violators: the non-decreasing sequence closest to `values`
/// in weighted least squares (Ayer et al. 1955). Returns the fitted values.
pub fn isotonic_regression(values: &[f64], weights: &[f64]) -> Vec<f64> {
    // Blocks of (weighted mean, total weight, count).
    let mut blocks: Vec<(f64, f64, usize)> = Vec::with_capacity(values.len());
    for (v, w) in values.iter().zip(weights) {
        blocks.push((*v, *w, 1));
        while blocks.len() >= 2 && blocks[blocks.len() - 2].0 > blocks[blocks.len() - 1].0 {
            let (v2, w2, n2) = blocks.pop().unwrap_or((0.0, 0.0, 0));
            let (v1, w1, n1) = blocks.pop().unwrap_or((0.0, 0.0, 0));
            let w = w1 + w2;
            blocks.push(((v1 * w1 + v2 * w2) / w, w, n1 + n2));
        }
    }
    blocks
        .into_iter()
        .flat_map(|(v, _, n)| std::iter::repeat_n(v, n))
        .collect()
}

/// One drive level of a ramp: the weighted mean of its points (the ramp's readings
/// and the greys' channel shares there) and that mean's standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelMean {
    pub drive: f64,
    pub excitation: f64,
    pub sigma: f64,
}

/// The levels of `ramp`'s law points, ascending, each the mean of its points weighted
/// by 1/σ².
pub fn level_means(ramp: &ChannelRamp) -> Vec<LevelMean> {
    let mut levels: Vec<(f64, f64, f64)> = Vec::new(); // drive, Σ w e, Σ w
    for p in ramp.law_points() {
        let w = 1.0 / (p.sigma * p.sigma);
        match levels.iter_mut().find(|l| l.0 == p.drive) {
            Some(l) => {
                l.1 += w * p.excitation;
                l.2 += w;
            }
            None => levels.push((p.drive, w * p.excitation, w)),
        }
    }
    levels.sort_by(|a, b| a.0.total_cmp(&b.0));
    levels
        .into_iter()
        .map(|(drive, sum, weight)| LevelMean {
            drive,
            excitation: sum / weight,
            sigma: weight.sqrt().recip(),
        })
        .collect()
}

/// The table law: one knot per level of the ramp and of the greys' channel shares, the
/// weighted mean of its points, pooled to be monotone and joined by the monotone cubic
/// of `Table`.
fn fit_table(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::Table;
    if !ramp.pinned {
        return Err(LawFitError::NeedsFullDrive { law: kind });
    }
    let levels = level_means(ramp);
    let drive: Vec<f64> = levels.iter().map(|l| l.drive).collect();
    let means: Vec<f64> = levels.iter().map(|l| l.excitation).collect();
    let weights: Vec<f64> = levels.iter().map(|l| l.sigma.powi(-2)).collect();
    let monotone = isotonic_regression(&means, &weights);
    let pooled = means
        .iter()
        .zip(&monotone)
        .filter(|(a, b)| (*a - *b).abs() > 1e-15)
        .count();
    // Excitation never falls below zero (black subtracted noise can push it there).
    let monotone: Vec<f64> = monotone.into_iter().map(|e| e.max(0.0)).collect();
    let table = Table::new(drive.clone(), monotone)
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let mut notes = Vec::new();
    if pooled > 0 {
        notes.push(format!(
            "{pooled} level(s) fell below a dimmer one and were pooled to keep the curve monotone"
        ));
    }
    Ok(LawFit {
        law: TransferLaw::Table(table),
        amplitude: 1.0,
        parameters: vec![parameter("knots", drive.len() as f64, None)],
        chi2: 0.0,
        dof: 0,
        free_parameters: drive.len(),
        notes,
    })
}

/// The least `light` (of a drive) among the readings that show any: where a curved HDR
/// law's toe goes (infinite when none does).
fn least_lit(points: &Points, light: impl Fn(f64) -> f64) -> f64 {
    points
        .drive
        .iter()
        .zip(&points.excitation)
        .filter(|(v, e)| **v > 0.0 && **e > 0.0)
        .map(|(v, _)| light(*v))
        .fold(f64::INFINITY, f64::min)
}

/// The HLG law with Cowan's log-quadratic term, ln E = p ln E_s + b ln²E_s of the
/// scene light E_s (`Hlg::curvature`), a power of E_s below the least scene light
/// fitted. Started from the plain HLG law's exponent and no curvature.
fn fit_hlg_cowan(ramp: &ChannelRamp) -> Result<LawFit, LawFitError> {
    let kind = LawKind::HlgCowan;
    let points = Points::from_ramp(ramp, false);
    need_levels(kind, &points, 2)?;
    let plain = fit_hlg(ramp)?;
    let TransferLaw::Hlg(start) = &plain.law else {
        unreachable!("fit_hlg gives an HLG law");
    };
    let toe = least_lit(&points, |v| hlg_scene_light(v.min(1.0))).clamp(1e-9, 0.5);
    let law_of = |t: &[f64]| Hlg {
        exponent: t[0],
        curvature: t[1].clamp(-1.0, 1.0),
        toe,
    };
    let curve =
        |t: &[f64], v: f64, g: &mut [f64]| central_differences(|t| law_of(t).excitation(v), t, g);
    let fit = points.fit(kind, &curve, &[start.exponent, 0.0])?;
    let hlg = law_of(&fit.params);
    let notes = vec![format!(
        "ln E = {:.4} ln E_s + {:.5} ln² E_s of the scene light E_s, a power of it below {:.2e}",
        hlg.exponent, hlg.curvature, hlg.toe
    )];
    let law = TransferLaw::Hlg(hlg.clone());
    law.monotonicity()
        .map_err(|source| LawFitError::NotMonotone { law: kind, source })?;
    let ses = standard_errors_with_pin(&fit, &points, ramp);
    Ok(LawFit {
        law,
        amplitude: 1.0,
        parameters: vec![
            parameter("exponent", hlg.exponent, ses[0]),
            parameter("curvature", hlg.curvature, ses[1]),
            parameter("toe", hlg.toe, None),
        ],
        chi2: fit.chi2,
        dof: fit.dof,
        free_parameters: 2,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::primaries::RampPoint;
    use chromacal_color::Xyz;
    use nalgebra::Vector3;

    fn ramp(levels: &[f64], e: impl Fn(f64) -> f64, wiggle: &[f64], pinned: bool) -> ChannelRamp {
        let points = levels
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let clean = e(*v);
                let sigma = (1e-5f64.powi(2) + (0.003 * clean).powi(2)).sqrt();
                RampPoint {
                    index: i,
                    drive: *v,
                    excitation: clean + sigma * wiggle[i % wiggle.len()],
                    sigma,
                    xyz: Xyz::zeros(),
                }
            })
            .collect();
        ChannelRamp {
            channel: 0,
            direction: Vector3::new(0.8, 0.5, 0.3).normalize(),
            direction_se: Vector3::zeros(),
            normaliser: 50.0,
            normaliser_se: 0.1,
            pinned,
            points,
            grey_points: Vec::new(),
        }
    }

    const WIGGLE: [f64; 7] = [0.4, -1.1, 0.7, 0.2, -0.5, 1.3, -0.8];

    /// The largest miss of a fitted law from the `display` it was fitted to, over 199
    /// drives between 0 and 1.
    fn worst_miss(fit: &LawFit, display: impl Fn(f64) -> f64) -> f64 {
        (1..200)
            .map(|k| k as f64 / 200.0)
            .map(|v| (fit.law.excitation(v) - display(v)).abs())
            .fold(0.0, f64::max)
    }

    /// A display in PQ mode whose panel is not the law's: the processing inverts a
    /// 2.2 gamma, the panel follows a gain-offset-gamma of 2.3 with a small cut-off,
    /// and the roll-off starts from a 4,000 cd/m² master onto a 750 cd/m² peak. The PQ
    /// law finds the peak and the roll-off and is far closer than any SDR law.
    #[test]
    fn the_pq_law_finds_a_pq_display_s_peak_and_roll_off() {
        use chromacal_color::hdr::bt2390_eetf;
        let panel = GainOffsetGamma::from_cutoff(0.01, 2.3);
        let display = |v: f64| {
            let relative = bt2390_eetf(v, 4000.0, 750.0, 0.0) / 750.0;
            panel.excitation(relative.powf(1.0 / 2.2))
        };
        let levels: Vec<f64> = (1..=16).map(|k| k as f64 / 16.0).collect();
        let r = ramp(&levels, display, &WIGGLE, true);
        let fit = fit_law(LawKind::Pq, &r, 1.0 / 1023.0).unwrap();
        let TransferLaw::Pq(law) = &fit.law else {
            panic!("{:?}", fit.law)
        };
        // The panel's own departure trades against the peak: within a tenth.
        assert!((law.peak / 750.0 - 1.0).abs() < 0.1, "{law:?}");
        assert!(
            law.rolloff_from > law.peak,
            "{law:?}: the roll-off was found"
        );
        let worst = |f: &LawFit| worst_miss(f, display);
        let power = fit_law(LawKind::Power, &r, 1.0 / 1023.0).unwrap();
        assert!(worst(&fit) < 0.02, "pq {}", worst(&fit));
        assert!(worst(&power) > 5.0 * worst(&fit), "power {}", worst(&power));
        // Without a full-drive reading there is nothing to pin the peak to.
        let unpinned = ramp(&levels, display, &WIGGLE, false);
        assert!(matches!(
            fit_law(LawKind::Pq, &unpinned, 1.0 / 1023.0),
            Err(LawFitError::NeedsFullDrive { .. })
        ));
    }

    /// One channel of a display in HLG mode, shown alone: BT.2100's inverse OETF, the
    /// OOTF on the channel's own luminance (γ 1.16 at 800 cd/m²) and a panel a little
    /// off the gamma its processing inverts (2.3 for 2.2). The HLG law's exponent is
    /// the system gamma times that departure, and it follows the channel far closer
    /// than a power of the code does; its inverse is its inverse.
    #[test]
    fn the_hlg_law_follows_a_channel_of_an_hlg_display() {
        let gamma = 1.16;
        let display = |v: f64| {
            chromacal_color::hdr::hlg_scene_light(v)
                .powf(gamma)
                .powf(2.3 / 2.2)
        };
        let levels: Vec<f64> = (1..=16).map(|k| k as f64 / 16.0).collect();
        let r = ramp(&levels, display, &WIGGLE, true);
        let fit = fit_law(LawKind::Hlg, &r, 1.0 / 1023.0).unwrap();
        let TransferLaw::Hlg(law) = &fit.law else {
            panic!("{:?}", fit.law)
        };
        check(&fit, "exponent", gamma * 2.3 / 2.2);
        assert!((law.exponent - gamma * 2.3 / 2.2).abs() < 0.01, "{law:?}");
        let worst = |f: &LawFit| worst_miss(f, display);
        let power = fit_law(LawKind::Power, &r, 1.0 / 1023.0).unwrap();
        assert!(worst(&fit) < 0.005, "hlg {}", worst(&fit));
        assert!(worst(&power) > 5.0 * worst(&fit), "power {}", worst(&power));
        for v in [0.0, 0.05, 0.3, 0.5, 0.51, 0.9, 1.0] {
            let back = fit.law.drive(fit.law.excitation(v));
            assert!((back - v).abs() < 1e-9, "{v}: {back}");
        }
        assert!(matches!(
            fit_law(
                LawKind::Hlg,
                &ramp(&levels, display, &WIGGLE, false),
                1.0 / 1023.0
            ),
            Err(LawFitError::NeedsFullDrive { .. })
        ));
    }

    fn levels() -> Vec<f64> {
        (1..=12).map(|k| k as f64 / 12.0).collect()
    }

    fn check(fit: &LawFit, name: &str, truth: f64) {
        let p = fit.parameters.iter().find(|p| p.name == name).unwrap();
        let se = p.standard_error.unwrap();
        assert!(
            (p.value - truth).abs() < 3.0 * se,
            "{name}: {} ± {se}, truth {truth}",
            p.value
        );
    }

    #[test]
    fn each_parametric_law_recovers_its_own_truth() {
        let toe = 1.0 / 255.0;
        let truth_gog = GainOffsetGamma::from_cutoff(0.05, 2.4);
        let r = ramp(&levels(), |v| truth_gog.excitation(v), &WIGGLE, true);
        let fit = fit_law(LawKind::GainOffsetGamma, &r, toe).unwrap();
        check(&fit, "gamma", 2.4);
        check(&fit, "cutoff", 0.05);

        let truth_cowan = Cowan {
            a: 2.3,
            b: 0.05,
            toe,
        };
        let r = ramp(&levels(), |v| truth_cowan.excitation(v), &WIGGLE, true);
        let fit = fit_law(LawKind::Cowan, &r, toe).unwrap();
        check(&fit, "A", 2.3);
        check(&fit, "B", 0.05);

        let r = ramp(&levels(), |v| v.powf(2.2), &WIGGLE, true);
        let fit = fit_law(LawKind::Power, &r, toe).unwrap();
        check(&fit, "gamma", 2.2);
        let fit = fit_law(LawKind::ThreeTerm, &r, toe).unwrap();
        check(&fit, "C", 0.0);
    }

    #[test]
    fn without_full_drive_the_amplitude_is_extrapolated() {
        let r = ramp(
            &levels()[..10],
            |v| (v / (10.0 / 12.0)).powf(2.2) * 1.0,
            &WIGGLE,
            false,
        );
        // Excitations are relative to the top level measured (10/12): the law must
        // find that full drive is (12/10)^2.2 times brighter.
        let fit = fit_law(LawKind::Power, &r, 1.0 / 255.0).unwrap();
        let expected = (12.0f64 / 10.0).powf(2.2);
        assert!(
            (fit.amplitude - expected).abs() / expected < 0.01,
            "{}",
            fit.amplitude
        );
        assert!(matches!(
            fit_law(LawKind::Table, &r, 1.0 / 255.0),
            Err(LawFitError::NeedsFullDrive { .. })
        ));
        assert!(matches!(
            fit_law(LawKind::ThreeTerm, &r, 1.0 / 255.0),
            Err(LawFitError::NeedsFullDrive { .. })
        ));
    }

    #[test]
    fn a_cowan_fit_that_would_turn_back_is_constrained_and_monotone() {
        // Data that rise again near black (a lifted toe plus flare-like excess):
        // an unconstrained Cowan fit wants B large enough to turn back above the toe.
        let toe = 1.0 / 255.0;
        let lv = [0.02, 0.04, 0.08, 0.15, 0.3, 0.5, 0.75, 1.0];
        let r = ramp(
            &lv,
            |v| v.powf(2.2) + 0.02 * (1.0 - v).powi(6) * (v < 1.0) as i32 as f64,
            &WIGGLE,
            true,
        );
        let fit = fit_law(LawKind::Cowan, &r, toe).unwrap();
        fit.law.monotonicity().unwrap();
        assert!(
            fit.notes.iter().any(|n| n.contains("turned back")),
            "{:?}",
            fit.notes
        );
    }

    #[test]
    fn too_few_levels_are_refused_not_guessed() {
        let r = ramp(&[0.5, 1.0], |v| v.powf(2.2), &WIGGLE, true);
        assert!(fit_law(LawKind::Power, &r, 1.0 / 255.0).is_ok());
        assert!(matches!(
            fit_law(LawKind::Cowan, &r, 1.0 / 255.0),
            Err(LawFitError::TooFewLevels {
                need: 2,
                have: 1,
                ..
            })
        ));
        // One level below full drive: gamma exact through it, no standard error.
        let fit = fit_law(LawKind::Power, &r, 1.0 / 255.0).unwrap();
        assert!(fit.parameters[0].standard_error.is_none());
    }

    #[test]
    fn pava_pools_violations_and_leaves_monotone_data_alone() {
        assert_eq!(
            isotonic_regression(&[1.0, 2.0, 3.0], &[1.0; 3]),
            vec![1.0, 2.0, 3.0]
        );
        assert_eq!(
            isotonic_regression(&[1.0, 3.0, 2.0], &[1.0; 3]),
            vec![1.0, 2.5, 2.5]
        );
        let weighted = isotonic_regression(&[1.0, 3.0, 2.0], &[1.0, 1.0, 3.0]);
        assert!((weighted[1] - 2.25).abs() < 1e-12 && weighted[1] == weighted[2]);
        let r = ramp(
            &[0.25, 0.5, 0.6, 1.0],
            |v| if v == 0.6 { 0.17 } else { v.powf(2.2) },
            &[0.0],
            true,
        );
        let fit = fit_law(LawKind::Table, &r, 1.0 / 255.0).unwrap();
        assert!(fit.notes[0].contains("pooled"));
        fit.law.monotonicity().unwrap();
    }
}
