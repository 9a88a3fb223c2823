//! The spatial gain map K(p), from the uniformity grid.
//!
//! Each grid reading gives an observed gain: its light above black over what the
//! model predicts at the centre for the same drive. Candidate maps (none; one surface
//! for all channels of degree 2 or 4; a surface per channel when the grid measured the
//! channels apart) are fitted by weighted linear least squares and scored by
//! leave-one-position-out ΔE00; the simplest within noise of the best is kept. Cells
//! that were not measured (or not usable) are simply absent: any subset of the grid
//! works, and a candidate with more terms than the grid can support is not tried.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::least_squares::fit_linear;
use super::noise::NoiseModel;
use super::primaries::Corrected;
use super::select::simplest_within_noise;
use super::stats::ErrorStats;
use super::validate::{delta_e00_xyz, noise_delta_e00};
use crate::spatial::{SpatialMap, Surface, surface_basis, surface_term_count};
use crate::{MonitorModel, ScreenPosition};

/// A candidate map and its held-out error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpatialCandidateReport {
    pub name: String,
    pub chosen: bool,
    pub cross_validation: Option<ErrorStats>,
    pub note: Option<String>,
}

/// What the spatial fit found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpatialReport {
    /// Grid positions with usable readings.
    pub positions: usize,
    pub readings: usize,
    /// Largest drop of light at a measured position, percent of the centre.
    pub largest_falloff_percent: Option<f64>,
    pub candidates: Vec<SpatialCandidateReport>,
    /// Grid readings left out as darker than any screen's corner (under
    /// [`MIN_PLAUSIBLE_GAIN`] of the centre): the instrument did not see the patch.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub unseen: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Shape {
    Uniform,
    Scalar(u32),
    PerChannel(u32),
}

impl Shape {
    fn name(self) -> String {
        match self {
            Shape::Uniform => "uniform".into(),
            Shape::Scalar(d) => format!("one surface, degree {d}"),
            Shape::PerChannel(d) => format!("surface per channel, degree {d}"),
        }
    }
}

/// Largest gain (grid reading over the centre's prediction) taken as a reading.
const MAX_PLAUSIBLE_GAIN: f64 = 10.0;

/// Smallest gain taken as a reading of the patch. The worst screens lose 30 to 50 %
/// of the centre's light in a corner; a fifth of it is the dark surround, read by an
/// instrument that was not moved to the patch (a run on the window sink read 0.07 %).
pub const MIN_PLAUSIBLE_GAIN: f64 = 0.2;

/// One grid reading as an observed gain.
struct GainPoint<'a> {
    reading: &'a Corrected<'a>,
    position: ScreenPosition,
    /// Channel measured alone, if the patch was a single primary.
    channel: Option<usize>,
    gain: f64,
    sigma: f64,
}

/// The grid readings as gains, and how many were under [`MIN_PLAUSIBLE_GAIN`] (said in
/// the log when there are any).
fn gain_points<'a>(
    base: &MonitorModel,
    grid: &'a [Corrected<'a>],
    noise: &NoiseModel,
) -> (Vec<GainPoint<'a>>, usize) {
    let mut unseen = 0;
    let points = grid
        .iter()
        .filter_map(|r| {
            let m = r.measurement;
            let centre = base.forward_centre(m.drive);
            let above = centre.y - base.black.y;
            let gain = (r.xyz.y - base.black.y) / above;
            // A grid patch is bright, and no screen's corner is ten times its centre:
            // a gain above 10 is a reading out of all range (1e308, a unit slip), and
            // one under a fifth a reading of something else (the instrument not moved
            // to the patch, counted as unseen); neither says anything about the
            // falloff. Left out, not fitted.
            if above > 0.0 && gain < MIN_PLAUSIBLE_GAIN {
                unseen += 1;
            }
            if !(above > 0.0 && (MIN_PLAUSIBLE_GAIN..MAX_PLAUSIBLE_GAIN).contains(&gain)) {
                return None;
            }
            let on: Vec<usize> = (0..3).filter(|c| m.drive[*c] > 0.0).collect();
            Some(GainPoint {
                reading: r,
                position: m.position,
                channel: (on.len() == 1).then(|| on[0]),
                gain,
                sigma: noise.sigma(r.xyz.y) / above,
            })
        })
        .collect();
    if unseen > 0 {
        tracing::warn!(
            unseen,
            "uniformity-grid readings under {:.0} % of the centre's light are left out: the instrument did not see the patch there (--prompt-positions asks to move it to each position)",
            100.0 * MIN_PLAUSIBLE_GAIN
        );
    }
    (points, unseen)
}

/// Fit a surface of `degree` to the points' gains, or `None` if they cannot carry it.
fn fit_surface(points: &[&GainPoint<'_>], degree: u32) -> Option<Surface> {
    let terms = surface_term_count(degree);
    let positions = distinct_positions(points.iter().map(|p| p.position));
    if positions.len() <= terms {
        return None;
    }
    let design = DMatrix::from_fn(points.len(), terms, |i, k| {
        surface_basis(points[i].position, degree)[k]
    });
    let y: Vec<f64> = points.iter().map(|p| p.gain - 1.0).collect();
    let s: Vec<f64> = points.iter().map(|p| p.sigma).collect();
    let fit = fit_linear(&design, &y, &s).ok()?;
    Some(Surface {
        degree,
        coefficients: fit.params,
    })
}

fn distinct_positions(positions: impl Iterator<Item = ScreenPosition>) -> Vec<ScreenPosition> {
    let mut out: Vec<ScreenPosition> = Vec::new();
    for p in positions {
        if !out
            .iter()
            .any(|q| (q.x - p.x).abs() < 1e-9 && (q.y - p.y).abs() < 1e-9)
        {
            out.push(p);
        }
    }
    out
}

fn fit_shape(shape: Shape, points: &[&GainPoint<'_>]) -> Option<SpatialMap> {
    match shape {
        Shape::Uniform => Some(SpatialMap::Uniform),
        Shape::Scalar(d) => fit_surface(points, d).map(|surface| SpatialMap::Scalar { surface }),
        Shape::PerChannel(d) => {
            let per: Vec<Surface> = (0..3)
                .map(|c| {
                    let own: Vec<&GainPoint<'_>> = points
                        .iter()
                        .copied()
                        .filter(|p| p.channel == Some(c))
                        .collect();
                    fit_surface(&own, d)
                })
                .collect::<Option<Vec<_>>>()?;
            let surfaces: [Surface; 3] = per.try_into().ok()?;
            Some(SpatialMap::PerChannel { surfaces })
        }
    }
}

/// The ΔE00 a map's prediction makes on one grid reading, counting only what a map
/// models: the light at that position. The reading is compared with itself, its light
/// above black scaled by the predicted over the observed gain.
///
/// Why not the ΔE00 of reading against prediction: the base model's own colour error
/// at the patch's drive is the same for every candidate map, and ΔE00 does not add, so
/// a constant chromatic error of 0.35 hid most of a 1.2 % luminance bias at the
/// corners (a degree-2 surface on a falloff that is quartic in the radius), and the
/// simpler map passed as "within noise". Scored this way, the error and the noise
/// tolerance ([`noise_delta_e00`], a 1σ scaling of the light) are the same kind of
/// quantity.
fn gain_error_delta_e00(
    point: &GainPoint<'_>,
    predicted: &chromacal_color::Xyz,
    black: &chromacal_color::Xyz,
    white: &chromacal_color::Xyz,
) -> f64 {
    let measured = point.reading.xyz;
    let above = measured.y - black.y;
    // Gain points have positive light above black (see `gain_points`).
    let scale = (predicted.y - black.y) / above;
    let as_the_map_has_it = black + (measured - black) * scale;
    delta_e00_xyz(&measured, &as_the_map_has_it, white)
}

/// Choose and fit the spatial map of `base` (whose map is ignored) from grid readings.
pub fn choose_spatial_map(
    base: &MonitorModel,
    grid: &[Corrected<'_>],
    noise: &NoiseModel,
) -> (SpatialMap, SpatialReport) {
    let (points, unseen) = gain_points(base, grid, noise);
    let positions = distinct_positions(points.iter().map(|p| p.position));
    let white = base.white();
    let per_channel_data = (0..3).all(|c| points.iter().any(|p| p.channel == Some(c)));
    let mut shapes = vec![Shape::Uniform, Shape::Scalar(2), Shape::Scalar(4)];
    if per_channel_data {
        shapes.push(Shape::PerChannel(2));
    }
    let all: Vec<&GainPoint<'_>> = points.iter().collect();
    let mut scores = Vec::new();
    let mut notes = Vec::new();
    for shape in &shapes {
        let mut errors = Vec::new();
        let mut note = None;
        for held in &positions {
            if crate::fit::cancel::requested() {
                note = Some("stopped".to_string());
                break;
            }
            let at = |p: &&GainPoint<'_>| {
                (p.position.x - held.x).abs() < 1e-9 && (p.position.y - held.y).abs() < 1e-9
            };
            let training: Vec<&GainPoint<'_>> = all.iter().copied().filter(|p| !at(p)).collect();
            let Some(map) = fit_shape(*shape, &training) else {
                note = Some("the grid has too few positions for it".to_string());
                break;
            };
            let model = MonitorModel {
                spatial: map,
                ..base.clone()
            };
            for p in all.iter().filter(|p| at(p)) {
                let predicted = model.forward(p.reading.measurement.drive, p.position);
                errors.push(gain_error_delta_e00(p, &predicted, &base.black, &white));
            }
        }
        if positions.is_empty() {
            note = Some("no uniformity readings".into());
        }
        let complete = note.is_none();
        scores.push(complete.then_some(errors));
        notes.push(note);
    }
    let grid_xyz: Vec<chromacal_color::Xyz> = points.iter().map(|p| p.reading.xyz).collect();
    let tolerance = noise_delta_e00(&grid_xyz, noise, &white);
    let chosen_index = simplest_within_noise(&scores, tolerance).unwrap_or(0);
    let chosen = fit_shape(shapes[chosen_index], &all).unwrap_or_default();
    let largest_falloff_percent = points
        .iter()
        .map(|p| (1.0 - p.gain) * 100.0)
        .reduce(f64::max);
    let candidates = shapes
        .iter()
        .enumerate()
        .map(|(k, shape)| SpatialCandidateReport {
            name: shape.name(),
            chosen: k == chosen_index,
            cross_validation: scores[k].as_deref().and_then(ErrorStats::of),
            note: notes[k].clone(),
        })
        .collect();
    (
        chosen,
        SpatialReport {
            positions: positions.len(),
            readings: points.len(),
            largest_falloff_percent,
            candidates,
            unseen,
        },
    )
}
