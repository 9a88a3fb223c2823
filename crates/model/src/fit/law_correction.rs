//! The chosen law, corrected at the levels that were measured.
//!
//! A law of two or three parameters follows a channel's curve in the large but not the
//! wiggles a real panel's look-up tables leave in it (the Dell U2713HM's grey shares
//! wander by several per cent from one level to the next), while the table law, exact
//! at every level, chases the noise of the dark ones too. The correction keeps the
//! law's shape and multiplies it by a factor that follows the residuals where the data
//! are sure of them and shrinks to 1 where they are not:
//!
//! - at each measured level v (the ramp's readings and the greys' channel shares,
//!   `laws::level_means`) the relative residual is rᵢ = ēᵢ / L(vᵢ) − 1, with noise
//!   sᵢ = σᵢ / L(vᵢ);
//! - the spread of the true residuals is estimated by moments, τ² = max(0, mean(rᵢ²) −
//!   mean(sᵢ²)) (the empirical Bayes prior of Efron & Morris 1975);
//! - each residual is shrunk to r̂ᵢ = rᵢ·τ² / (τ² + sᵢ²) (the empirical Bayes estimate
//!   of a mean under normal noise, ibid. eq. 1.6), and the residual at any drive v is
//!   the mean of the r̂ᵢ weighted by a kernel of width h in drive (Nadaraya 1964,
//!   Watson 1964; the tricube weight of Cleveland 1979). Residuals within the noise
//!   (τ² = 0) give no correction; a wiggle narrower than h is smoothed rather than
//!   chased;
//! - the corrected curve L(v)·(1 + r̂(v)) is written as a [`Table`] through dense
//!   samples, so every export and inverse handles it as it does any table.
//!
//! Whether to keep it, and with which width h ([`BANDWIDTHS`]), is the
//! cross-validation's question (`law_selection`): the same folds of levels as the laws,
//! each fold's law and correction fitted without it. The width with the lowest error is
//! taken, and the correction kept only when it lowers that error by more than two
//! paired standard errors and more than noise alone.

use super::laws::{FittedParameter, LawFit, isotonic_regression, level_means};
use super::primaries::ChannelRamp;
use crate::transfer::{Table, TransferLaw};

/// Samples of the corrected curve between the measured levels: every 1/64, and at
/// (k/32)² for k = 1 … 32, dense near black where a law's curvature is largest relative
/// to its value (the table through them stays within 0.1 % of the curve there).
const GRID: usize = 64;

/// Widths (in drive) of the kernel the residuals are pooled over; cross-validation
/// chooses among them (`law_selection`).
pub const BANDWIDTHS: [f64; 3] = [0.02, 0.05, 0.1];

/// `fit` (a law fitted to `ramp`) corrected at `ramp`'s measured levels with kernel
/// width `bandwidth`, as a table in units of the ramp's normaliser (amplitude 1).
/// `None` when the ramp is not pinned at full drive, no level is bright enough to take
/// a ratio at, or the corrected curve would not be monotone.
pub fn correct_law(fit: &LawFit, ramp: &ChannelRamp, bandwidth: f64) -> Option<LawFit> {
    let residuals = Residuals::of(fit, ramp)?;
    let law = |v: f64| fit.amplitude * fit.law.excitation(v);
    let mut drives: Vec<f64> = (1..=GRID)
        .map(|k| k as f64 / GRID as f64)
        .chain((1..=GRID / 2).map(|k| (k as f64 / (GRID / 2) as f64).powi(2)))
        .chain(residuals.levels.iter().map(|r| r.0))
        .filter(|v| *v > 0.0 && *v <= 1.0)
        .collect();
    drives.sort_by(|a, b| a.total_cmp(b));
    drives.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let excitation: Vec<f64> = drives
        .iter()
        .map(|v| (law(*v) * residuals.factor(bandwidth, *v)).max(0.0))
        .collect();
    // Where shrunk residuals of neighbouring levels fall faster than the law rises
    // (only near black), the samples are pooled to stay monotone, as the table law's
    // are.
    let excitation = isotonic_regression(&excitation, &vec![1.0; excitation.len()]);
    let table = Table::new(drives, excitation).ok()?;
    Some(corrected_fit(
        fit,
        table,
        residuals.levels.len(),
        residuals.tau2,
        bandwidth,
    ))
}

/// A law's relative residuals at a ramp's measured levels, and the spread of the true
/// ones (the correction before it is written as a table).
#[derive(Debug, Clone)]
pub struct Residuals {
    /// (level, residual r, its noise s), ascending in level, where the law and the
    /// data are clear of black.
    levels: Vec<(f64, f64, f64)>,
    tau2: f64,
}

impl Residuals {
    /// The residuals of `fit` on `ramp`; `None` when the ramp is not pinned at full
    /// drive or no level is bright enough to take a ratio at.
    pub fn of(fit: &LawFit, ramp: &ChannelRamp) -> Option<Residuals> {
        if !ramp.pinned {
            return None;
        }
        let law = |v: f64| fit.amplitude * fit.law.excitation(v);
        let levels: Vec<(f64, f64, f64)> = level_means(ramp)
            .into_iter()
            .filter(|l| l.drive > 0.0 && l.excitation > 5.0 * l.sigma && law(l.drive) > 0.0)
            .map(|l| {
                let predicted = law(l.drive);
                (l.drive, l.excitation / predicted - 1.0, l.sigma / predicted)
            })
            .collect();
        if levels.is_empty() {
            return None;
        }
        Some(Residuals {
            tau2: prior_spread(&levels),
            levels,
        })
    }

    /// The factor 1 + r̂(v) the law is multiplied by at drive `v`, with kernel width
    /// `bandwidth` (what the table through the samples interpolates; cross-validation
    /// scores it directly at the levels it left out).
    pub fn factor(&self, bandwidth: f64, v: f64) -> f64 {
        1.0 + pooled_residual(&self.levels, self.tau2, bandwidth, v)
    }
}

/// τ² of the empirical Bayes prior (Efron & Morris 1975): the spread of residuals
/// (level, r, s) beyond their noise, mean r² − mean s², not below 0.
pub fn prior_spread(residuals: &[(f64, f64, f64)]) -> f64 {
    if residuals.is_empty() {
        return 0.0;
    }
    let n = residuals.len() as f64;
    let spread = residuals.iter().map(|r| r.1 * r.1).sum::<f64>() / n;
    let noise = residuals.iter().map(|r| r.2 * r.2).sum::<f64>() / n;
    (spread - noise).max(0.0)
}

/// A residual `r` of noise `s` shrunk towards zero against the prior's spread `tau2`:
/// r·τ²/(τ² + s²) (ibid. eq. 1.6); zero when τ² is.
pub fn shrunk(r: f64, s: f64, tau2: f64) -> f64 {
    if tau2 > 0.0 {
        r * tau2 / (tau2 + s * s)
    } else {
        0.0
    }
}

/// The law fit that a corrected table stands for.
fn corrected_fit(fit: &LawFit, table: Table, levels: usize, tau2: f64, bandwidth: f64) -> LawFit {
    let mut parameters = fit.parameters.clone();
    parameters.push(FittedParameter {
        name: "correction spread τ".into(),
        value: tau2.sqrt(),
        standard_error: None,
    });
    let mut notes = fit.notes.clone();
    notes.push(format!(
        "{} corrected at {levels} measured levels (spread τ = {:.4}, kernel width {bandwidth})",
        fit.law.kind(),
        tau2.sqrt()
    ));
    LawFit {
        law: TransferLaw::Table(table),
        amplitude: 1.0,
        parameters,
        chi2: 0.0,
        dof: 0,
        free_parameters: fit.free_parameters + levels,
        notes,
    }
}

/// The residual at drive `v`: the measured residuals (level, r, noise s; ascending in
/// level), each first shrunk to r·τ²/(τ² + s²), averaged with the weights of a
/// tricube kernel (1 − |z/3|³)³ of z = (v − level)/`bandwidth`, zero beyond three
/// widths (Cleveland 1979's weight; its standard deviation is 1.14 widths, near a
/// Gaussian of that width, and it needs no exponential). With τ² = 0 (residuals within the noise)
/// it is zero everywhere.
fn pooled_residual(residuals: &[(f64, f64, f64)], tau2: f64, bandwidth: f64, v: f64) -> f64 {
    if !(tau2 > 0.0) {
        return 0.0;
    }
    let reach = 3.0 * bandwidth;
    let first = residuals.partition_point(|r| r.0 < v - reach);
    let (mut weighted, mut weights) = (0.0, 0.0);
    for (level, r, s) in residuals[first..].iter().take_while(|r| r.0 <= v + reach) {
        let u = ((v - level) / reach).abs();
        let k = (1.0 - u * u * u).powi(3);
        weighted += k * shrunk(*r, *s, tau2);
        weights += k;
    }
    if weights > 0.0 {
        weighted / weights
    } else {
        // No level within reach: the nearest one's residual, shrunk.
        let nearest = residuals
            .iter()
            .min_by(|a, b| (a.0 - v).abs().total_cmp(&(b.0 - v).abs()));
        nearest.map_or(0.0, |(_, r, s)| shrunk(*r, *s, tau2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::laws::fit_law;
    use crate::fit::primaries::RampPoint;
    use crate::transfer::LawKind;
    use chromacal_color::Xyz;
    use nalgebra::Vector3;

    /// A pinned ramp whose excitations are `truth` at `levels`, with noise σ.
    fn ramp(levels: &[f64], truth: impl Fn(f64) -> f64, sigma: f64) -> ChannelRamp {
        ChannelRamp {
            channel: 0,
            direction: Vector3::new(1.0, 0.0, 0.0),
            direction_se: Vector3::zeros(),
            normaliser: 1.0,
            normaliser_se: 0.0,
            pinned: true,
            points: levels
                .iter()
                .enumerate()
                .map(|(index, v)| RampPoint {
                    index,
                    drive: *v,
                    excitation: truth(*v),
                    sigma,
                    xyz: Xyz::new(truth(*v), 0.0, 0.0),
                })
                .collect(),
            grey_points: Vec::new(),
        }
    }

    fn levels() -> Vec<f64> {
        (1..=16).map(|k| k as f64 / 16.0).collect()
    }

    #[test]
    fn a_curve_the_law_follows_is_left_as_the_law() {
        let sigma = 1e-3;
        let r = ramp(&levels(), |v| v.powf(2.2), sigma);
        let fit = fit_law(LawKind::Power, &r, 1.0 / 255.0).unwrap();
        let corrected = correct_law(&fit, &r, 0.05).unwrap();
        // The correction moves nothing by more than 1 % of the noise or 0.1 %.
        for k in 1..100 {
            let v = k as f64 / 100.0;
            let (a, b) = (fit.law.excitation(v), corrected.law.excitation(v));
            assert!((a - b).abs() < 0.01 * sigma + 1e-3 * a, "{v}: {a} {b}");
        }
    }

    #[test]
    fn wiggles_the_law_misses_are_followed_at_the_measured_levels() {
        let truth = |v: f64| v.powf(2.2) * (1.0 + 0.04 * (9.0 * v).sin());
        let r = ramp(&levels(), truth, 1e-5);
        let fit = fit_law(LawKind::Power, &r, 1.0 / 255.0).unwrap();
        let corrected = correct_law(&fit, &r, BANDWIDTHS[0]).unwrap();
        let mut worst_law: f64 = 0.0;
        let mut worst_corrected: f64 = 0.0;
        for v in levels() {
            worst_law = worst_law.max((fit.law.excitation(v) / truth(v) - 1.0).abs());
            worst_corrected =
                worst_corrected.max((corrected.law.excitation(v) / truth(v) - 1.0).abs());
        }
        assert!(worst_law > 0.02, "{worst_law}");
        assert!(worst_corrected < 0.002, "{worst_corrected}");
        corrected.law.monotonicity().unwrap();
    }

    #[test]
    fn residuals_within_the_noise_are_shrunk_to_nothing() {
        // Alternate ±0.1 % about the law, with σ of 1 %: noise, not shape.
        let r = ramp(
            &levels(),
            |v| v.powf(2.2) * (1.0 + 0.001 * (16.0 * v).cos()),
            0.01,
        );
        let fit = fit_law(LawKind::Power, &r, 1.0 / 255.0).unwrap();
        let corrected = correct_law(&fit, &r, 0.05).unwrap();
        for v in levels() {
            let (a, b) = (fit.law.excitation(v), corrected.law.excitation(v));
            assert!((a - b).abs() < 1e-9 + 1e-6 * a, "{v}: {a} {b}");
        }
    }

    #[test]
    fn an_unpinned_ramp_is_not_corrected() {
        let mut r = ramp(&levels(), |v| v.powf(2.2), 1e-3);
        r.pinned = false;
        let fit = fit_law(LawKind::Power, &r, 1.0 / 255.0).unwrap();
        assert!(correct_law(&fit, &r, 0.05).is_none());
    }
}
