//! The brightness limiter (automatic brightness limiting, ABL): how much less light a
//! display gives when more of its screen is lit, measured with white and a grey as
//! windows of 1 to 100 % of the screen (`plan::WINDOW_AREAS`).
//!
//! An OLED's supply (and many LCDs' backlight budget) caps the light the whole screen
//! may emit. With p the screen's mean light the additive model predicts (cd/m²: the
//! window's light times its share of the screen, plus the black around it), the
//! limiter scales every emitter by
//!
//! g(p) = (1 + (p / F)^k)^(−1/k),
//!
//! a soft minimum of 1 and F / p: 1 for small windows, F / p once the cap binds, F
//! being the full-field white and k the knee's sharpness. The term is fitted to the
//! ratio of each window's measured luminance to the additive model's, and kept only
//! if it predicts windows left out of its fit (one at a time) better than the additive
//! model does: χ² in units of each reading's noise lower by more than Akaike's 2 per
//! parameter, and the mean error lower by more than twice the relative noise. (A
//! paired test of the mean is blind here: the small windows, which no limiter
//! touches, are most of the pairs.) A display without a limiter keeps the additive
//! model.

use serde::{Deserialize, Serialize};

use super::FitOptions;
use super::least_squares::fit_curve;
use super::noise::NoiseModel;
use super::primaries::Corrected;
use super::stats::mean;
use crate::MonitorModel;
use crate::measurement::Role;
use crate::monitor::{Limiter, screen_mean_light};

/// Fewest window readings the term is fitted on (two parameters, and one left out).
const MIN_WINDOWS: usize = 4;

/// The term's parameters, F and k.
const PARAMETERS: f64 = 2.0;

/// The limiter of parameters θ = [ln F, ln k], bounded so that a display without a
/// limiter (F → ∞) stays finite.
fn limiter_of(t: &[f64]) -> Limiter {
    Limiter {
        full_field: t[0].clamp(-5.0, 14.0).exp(),
        sharpness: t[1].clamp(0.0, 30f64.ln()).exp(),
    }
}

/// One window as measured and as predicted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WindowPoint {
    /// The window's share of the screen.
    pub area: f64,
    /// The grey level shown (1: white).
    pub level: f64,
    /// The screen's mean light the additive model predicts, cd/m².
    pub mean_light: f64,
    pub measured_y: f64,
    pub additive_y: f64,
    /// Predicted with the limiter fitted without this window.
    pub left_out_y: f64,
}

/// The limiter fitted, its cross-validation and whether it was kept.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LimiterReport {
    /// Fitted on every window (`None`: it could not be, as on a display whose light
    /// does not depend on the window at all).
    pub limiter: Option<Limiter>,
    pub kept: bool,
    pub windows: Vec<WindowPoint>,
    /// Mean |Y / Y_measured − 1| of the additive model over the windows.
    pub additive_error: f64,
    /// The same for the limiter fitted without each window in turn.
    pub cross_validated_error: f64,
    pub rule: String,
}

impl LimiterReport {
    /// The full-field white as measured, as the additive model predicts it, and as
    /// the limiter fitted without it predicts it, when it was measured.
    pub fn full_field_white(&self) -> Option<&WindowPoint> {
        self.windows
            .iter()
            .find(|w| w.area >= 0.999 && w.level >= 1.0)
    }
}

/// The limiter fitted to the window readings among `corrected`, and `model` with it
/// among its terms where it was kept and `options` allow terms (it then predicts
/// whole images: `MonitorModel::image_light`).
pub fn keep_limiter(
    mut model: MonitorModel,
    corrected: &[Corrected<'_>],
    noise: &NoiseModel,
    options: &FitOptions,
) -> (MonitorModel, Option<LimiterReport>) {
    let report = fit_limiter(&model, corrected, noise);
    if options.additivity_terms {
        model.terms.limiter = report.as_ref().filter(|r| r.kept).and_then(|r| r.limiter);
    }
    (model, report)
}

/// Fit the limiter to the window readings among `corrected` with `model` (the
/// additive model at the centre); `None` when fewer than `MIN_WINDOWS` were measured.
pub fn fit_limiter(
    model: &MonitorModel,
    corrected: &[Corrected<'_>],
    noise: &NoiseModel,
) -> Option<LimiterReport> {
    let mut points = window_points(model, corrected);
    if points.len() < MIN_WINDOWS {
        return None;
    }
    let all: Vec<&WindowPoint> = points.iter().collect();
    let limiter = fit_to(&all, noise);
    // Each window predicted by the limiter fitted without it.
    let left_out: Vec<f64> = (0..points.len())
        .map(|i| {
            let rest: Vec<&WindowPoint> = points
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, w)| w)
                .collect();
            let w = &points[i];
            fit_to(&rest, noise).map_or(w.additive_y, |l| w.additive_y * l.gain(w.mean_light))
        })
        .collect();
    for (w, y) in points.iter_mut().zip(left_out) {
        w.left_out_y = y;
    }
    let error = |y: f64, w: &WindowPoint| (y / w.measured_y - 1.0).abs();
    let additive: Vec<f64> = points.iter().map(|w| error(w.additive_y, w)).collect();
    let with_term: Vec<f64> = points.iter().map(|w| error(w.left_out_y, w)).collect();
    // Held-out χ² of each, each error in units of its reading's noise.
    let chi2 = |errors: &[f64]| -> f64 {
        errors
            .iter()
            .zip(&points)
            .map(|(e, w)| (e * w.measured_y / noise.sigma(w.measured_y).max(1e-12)).powi(2))
            .sum()
    };
    let drop = chi2(&additive) - chi2(&with_term);
    let better = mean(&additive) - mean(&with_term);
    let kept = limiter.is_some() && drop > 2.0 * PARAMETERS && better > 2.0 * noise.relative;
    let rule = format!(
        "kept only if, on windows left out of its fit, it lowers χ² by more than Akaike's 2 per parameter (by {drop:.1}; {:.1} needed) and the mean error by more than twice the relative noise ({:.2} % lower; {:.2} % needed)",
        2.0 * PARAMETERS,
        100.0 * better,
        200.0 * noise.relative
    );
    Some(LimiterReport {
        limiter,
        kept,
        additive_error: mean(&additive),
        cross_validated_error: mean(&with_term),
        windows: points,
        rule,
    })
}

/// The window readings with the additive model's prediction and the screen's mean
/// light it implies. The prediction is anchored at each grey level's three smallest
/// windows, which no limiter dims (their median measured / additive ratio): what the
/// model gets wrong at that drive, by a percent at mid-grey, is not the limiter's, and
/// left in it would be fitted as one where a display has none (or pull F away where it
/// has).
fn window_points(model: &MonitorModel, corrected: &[Corrected<'_>]) -> Vec<WindowPoint> {
    let black = model.black.y;
    let mut points: Vec<WindowPoint> = corrected
        .iter()
        .filter(|r| r.measurement.role == Role::Window && r.xyz.y > 0.0)
        .filter_map(|r| {
            let area = r.measurement.window?.clamp(0.0, 1.0);
            let additive_y = model.forward_centre(r.measurement.drive).y;
            Some(WindowPoint {
                area,
                level: r.measurement.drive.iter().sum::<f64>() / 3.0,
                mean_light: 0.0,
                measured_y: r.xyz.y,
                additive_y,
                left_out_y: 0.0,
            })
        })
        .filter(|w| w.additive_y > 0.0)
        .collect();
    // Each level's windows, smallest first (the points stay in the run's order).
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&i, &j| {
        let (a, b) = (&points[i], &points[j]);
        a.level.total_cmp(&b.level).then(a.area.total_cmp(&b.area))
    });
    let levels: Vec<Vec<usize>> = order
        .chunk_by(|&i, &j| (points[i].level - points[j].level).abs() < 1e-9)
        .map(<[usize]>::to_vec)
        .collect();
    for level in levels {
        let mut ratios: Vec<f64> = level
            .iter()
            .take(3)
            .map(|&i| points[i].measured_y / points[i].additive_y)
            .collect();
        ratios.sort_by(f64::total_cmp);
        let anchor = ratios[ratios.len() / 2];
        for i in level {
            let w = &mut points[i];
            w.additive_y *= anchor;
            w.mean_light = screen_mean_light(w.area, w.additive_y, black);
            w.left_out_y = w.additive_y;
        }
    }
    points
}

/// The limiter fitted to the ratio measured / additive of `set`, each weighted by its
/// reading's noise; `None` when the fit fails (as it may where nothing is limited).
fn fit_to(set: &[&WindowPoint], noise: &NoiseModel) -> Option<Limiter> {
    let x: Vec<f64> = set.iter().map(|w| w.mean_light).collect();
    let y: Vec<f64> = set.iter().map(|w| w.measured_y / w.additive_y).collect();
    let s: Vec<f64> = set
        .iter()
        .map(|w| (noise.sigma(w.measured_y) / w.additive_y).max(1e-6))
        .collect();
    // Start from the most light the screen gave on average.
    let start = set
        .iter()
        .map(|w| w.area * w.measured_y)
        .fold(f64::MIN_POSITIVE, f64::max);
    let curve = |t: &[f64], p: f64, g: &mut [f64]| {
        for k in 0..2 {
            let h = 1e-6;
            let (mut up, mut down) = ([t[0], t[1]], [t[0], t[1]]);
            up[k] += h;
            down[k] -= h;
            g[k] = (limiter_of(&up).gain(p) - limiter_of(&down).gain(p)) / (2.0 * h);
        }
        limiter_of(t).gain(p)
    };
    let result = fit_curve(&curve, &x, &y, &s, &[start.ln(), 4f64.ln()]).ok()?;
    Some(limiter_of(&result.params))
}
