//! "Model only what a scene needs": which parts of the monitor model a given scene's
//! rendering depends on, measured by rendering it without each and looking at what
//! the display would then show.
//!
//! A part's cost is the ΔE00, pixel by pixel, between what the display shows for
//! the codes of the full model and for the codes of the model without that part (both
//! judged by the full model, which is the best knowledge of the display). A part whose
//! largest cost over the scene is below the threshold is dropped; parts are dropped in
//! order of cost while the combined cost stays below it, so what is dropped together
//! is also checked together.

use std::time::Instant;

use serde::Serialize;

use chromacal_color::Xyz;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::monitor::AdditivityTerms;
use chromacal_model::spatial::SpatialMap;
use chromacal_model::transfer::{Power, TransferLaw};
use chromacal_model::{MonitorModel, ScreenPosition};

use super::{ColourReproduction, CrfError, RenderSettings, Rendering, Scene, ScenePixel};

/// A part of the monitor model that a rendering may do without.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Part {
    /// The spatial gain map (K = 1 everywhere without it).
    SpatialMap,
    /// The black and flare offset (zero without it).
    BlackOffset,
    /// Channel interaction and drive-dependent chromaticity.
    AdditivityTerms,
    /// Each transfer law beyond a power law (a power law fitted to it without it).
    LawFineStructure,
}

impl Part {
    pub fn name(self) -> &'static str {
        match self {
            Part::SpatialMap => "spatial map",
            Part::BlackOffset => "black offset",
            Part::AdditivityTerms => "additivity terms",
            Part::LawFineStructure => "transfer laws' fine structure",
        }
    }

    /// Whether `model` has this part at all.
    fn present(self, model: &MonitorModel) -> bool {
        match self {
            Part::SpatialMap => !matches!(model.spatial, SpatialMap::Uniform),
            Part::BlackOffset => model.black != Xyz::zeros(),
            Part::AdditivityTerms => !model.terms.is_empty(),
            Part::LawFineStructure => !model
                .laws
                .iter()
                .all(|l| matches!(l, TransferLaw::Power(_))),
        }
    }

    /// `model` without this part.
    fn remove(self, model: &MonitorModel) -> MonitorModel {
        let mut reduced = model.clone();
        match self {
            Part::SpatialMap => reduced.spatial = SpatialMap::Uniform,
            Part::BlackOffset => reduced.black = Xyz::zeros(),
            Part::AdditivityTerms => reduced.terms = AdditivityTerms::default(),
            Part::LawFineStructure => {
                for c in 0..3 {
                    let law = &model.laws[c];
                    let full = law.full_drive_excitation();
                    reduced.laws[c] = TransferLaw::Power(Power {
                        gamma: power_exponent(law),
                    });
                    // A power law gives 1 at full drive: the column carries E(1).
                    let column = model.matrix.column(c) * full;
                    reduced.matrix.set_column(c, &column);
                }
            }
        }
        reduced
    }
}

/// The exponent of the power law nearest to `law` in log–log, over drives 0.05 … 1
/// where the light is above a thousandth of full (least squares through the origin of
/// log E/E(1) against log v).
fn power_exponent(law: &TransferLaw) -> f64 {
    let full = law.full_drive_excitation();
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for k in 1..=20 {
        let v = k as f64 / 20.0;
        let e = law.excitation(v) / full;
        // Below a thousandth of full light a cut-off or a toe dominates the logarithm
        // (a gain-offset-gamma law at its cut-off gives 1e-41): those drives say
        // nothing of the power the rest of the curve follows.
        if v < 1.0 && e > 1e-3 && e.is_finite() {
            let (x, y) = (v.ln(), e.ln());
            sxy += x * y;
            sxx += x * x;
        }
    }
    if sxx > 0.0 && (sxy / sxx).is_finite() {
        (sxy / sxx).clamp(0.1, 10.0)
    } else {
        2.2
    }
}

/// What one part costs the scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartCost {
    pub part: Part,
    pub present: bool,
    /// ΔE00 over the scene's pixels without this part (alone).
    pub cost: Option<ErrorStats>,
    pub dropped: bool,
}

/// The analysis of a scene, and the model it leaves.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Explanation {
    pub threshold: f64,
    pub parts: Vec<PartCost>,
    /// ΔE00 of everything dropped together.
    pub combined: Option<ErrorStats>,
    /// Seconds to render the scene with the full model and with what is kept.
    pub full_seconds: f64,
    pub reduced_seconds: f64,
    #[serde(skip)]
    pub reduced: MonitorModel,
}

const PARTS: [Part; 4] = [
    Part::SpatialMap,
    Part::BlackOffset,
    Part::AdditivityTerms,
    Part::LawFineStructure,
];

/// What the display shows, by `truth`, for the codes of `rendering`.
fn shown_by(truth: &MonitorModel, scene: &Scene, rendering: &Rendering, bits: u32) -> Vec<Xyz> {
    let top = ((1u64 << bits) - 1) as f64;
    scene
        .pixels
        .iter()
        .zip(&rendering.pixels)
        .map(|(p, r)| truth.forward(r.codes.map(|c| c as f64 / top), p.position))
        .collect()
}

fn render_timed(
    model: &MonitorModel,
    scene: &Scene,
    settings: &RenderSettings,
) -> Result<(Rendering, f64), CrfError> {
    let start = Instant::now();
    let rendering = ColourReproduction::new(model)?.render(scene, settings)?;
    Ok((rendering, start.elapsed().as_secs_f64()))
}

/// Analyse `scene` for `model` and drop what costs it less than `threshold` ΔE00.
pub fn explain(
    model: &MonitorModel,
    scene: &Scene,
    settings: &RenderSettings,
    threshold: f64,
) -> Result<Explanation, CrfError> {
    let (full, full_seconds) = render_timed(model, scene, settings)?;
    let reference = shown_by(model, scene, &full, settings.bits);
    let white = model.white();
    let cost_of = |reduced: &MonitorModel| -> Result<Option<ErrorStats>, CrfError> {
        let rendering = ColourReproduction::new(reduced)?.render(scene, settings)?;
        let shown = shown_by(model, scene, &rendering, settings.bits);
        let errors: Vec<f64> = shown
            .iter()
            .zip(&reference)
            .map(|(s, r)| delta_e00_xyz(s, r, &white))
            .collect();
        Ok(ErrorStats::of(&errors))
    };
    let mut parts = Vec::new();
    for part in PARTS {
        let present = part.present(model);
        let cost = if present {
            cost_of(&part.remove(model))?
        } else {
            None
        };
        parts.push(PartCost {
            part,
            present,
            cost,
            dropped: false,
        });
    }
    // Cheapest first, each kept out only if everything dropped so far stays below.
    let mut order: Vec<usize> = (0..parts.len())
        .filter(|k| parts[*k].cost.as_ref().is_some_and(|c| c.max < threshold))
        .collect();
    order.sort_by(|a, b| {
        let cost = |k: &usize| parts[*k].cost.as_ref().map_or(0.0, |c| c.max);
        cost(a).total_cmp(&cost(b))
    });
    let mut reduced = model.clone();
    let mut combined = None;
    for k in order {
        let candidate = parts[k].part.remove(&reduced);
        let cost = cost_of(&candidate)?;
        if cost.as_ref().is_some_and(|c| c.max < threshold) {
            reduced = candidate;
            combined = cost;
            parts[k].dropped = true;
        }
    }
    let (_, reduced_seconds) = render_timed(&reduced, scene, settings)?;
    Ok(Explanation {
        threshold,
        parts,
        combined,
        full_seconds,
        reduced_seconds,
        reduced,
    })
}

/// A verification's error as a scene sees it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneWeighted {
    /// Scene colours weighed.
    pub colours: usize,
    /// Measured patches that are the nearest of at least one scene colour.
    pub patches_used: usize,
    /// Screen positions the measurements were taken at, and how many of them the
    /// scene's colours were weighed at.
    pub positions_measured: usize,
    pub positions_used: usize,
    /// Σ w ΔE00 / Σ w, w the number of scene colours nearest each patch.
    pub mean: f64,
    /// Largest ΔE00 of a patch some scene colour is nearest to.
    pub max: f64,
}

/// A measured patch for [`scene_weighted`]: its reading, where it was shown, and the
/// profile's ΔE00 on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeighedPatch {
    pub measured: Xyz,
    pub position: ScreenPosition,
    pub delta_e00: f64,
}

/// Weigh each measured patch's ΔE00 by how many of the scene's colours it stands for:
/// the error the scene's own colours would see, as far as the verification sampled
/// them. A scene colour stands at its screen position, so it is taken to the measured
/// position nearest to it, and there to the patch nearest in CIELAB (against
/// `white`). Where a position was measured only with greys (a uniformity grid), the
/// scene's colours there count for those greys: that is all the readings say of
/// that place.
pub fn scene_weighted(
    patches: &[WeighedPatch],
    scene: &[ScenePixel],
    white: &Xyz,
) -> Option<SceneWeighted> {
    use chromacal_color::xyz_to_lab;
    if patches.is_empty() || scene.is_empty() {
        return None;
    }
    let mut positions: Vec<ScreenPosition> = Vec::new();
    for p in patches {
        if !positions.contains(&p.position) {
            positions.push(p.position);
        }
    }
    let labs: Vec<_> = patches
        .iter()
        .map(|p| xyz_to_lab(&p.measured, white))
        .collect();
    let mut weights = vec![0usize; patches.len()];
    let mut used_positions = vec![false; positions.len()];
    for colour in scene {
        let screen = |q: &ScreenPosition| {
            (q.x - colour.position.x).powi(2) + (q.y - colour.position.y).powi(2)
        };
        let Some(place) = (0..positions.len())
            .min_by(|a, b| screen(&positions[*a]).total_cmp(&screen(&positions[*b])))
        else {
            continue;
        };
        used_positions[place] = true;
        let lab = xyz_to_lab(&colour.xyz, white);
        let distance = |k: usize| {
            let p = &labs[k];
            (p.l - lab.l).powi(2) + (p.a - lab.a).powi(2) + (p.b - lab.b).powi(2)
        };
        if let Some(nearest) = (0..patches.len())
            .filter(|k| patches[*k].position == positions[place])
            .min_by(|a, b| distance(*a).total_cmp(&distance(*b)))
        {
            weights[nearest] += 1;
        }
    }
    let used: Vec<usize> = (0..patches.len()).filter(|k| weights[*k] > 0).collect();
    let total: usize = weights.iter().sum();
    Some(SceneWeighted {
        colours: scene.len(),
        patches_used: used.len(),
        positions_measured: positions.len(),
        positions_used: used_positions.iter().filter(|u| **u).count(),
        mean: used
            .iter()
            .map(|k| weights[*k] as f64 * patches[*k].delta_e00)
            .sum::<f64>()
            / total as f64,
        max: used
            .iter()
            .map(|k| patches[*k].delta_e00)
            .fold(0.0, f64::max),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::transfer::GainOffsetGamma;

    #[test]
    fn scene_weighting_follows_the_scene_colours() {
        let white = Xyz::new(95.0, 100.0, 109.0);
        let dark = Xyz::new(5.0, 5.0, 5.5);
        let light = Xyz::new(80.0, 84.0, 92.0);
        let at = |measured: Xyz, position: ScreenPosition, delta_e00: f64| WeighedPatch {
            measured,
            position,
            delta_e00,
        };
        let centre = ScreenPosition::CENTRE;
        let patches = [at(dark, centre, 2.0), at(light, centre, 0.2)];
        let shown = |colours: &[Xyz], position: ScreenPosition| -> Vec<ScenePixel> {
            colours
                .iter()
                .map(|xyz| ScenePixel {
                    xyz: *xyz,
                    position,
                })
                .collect()
        };
        // A dark scene sees the dark patch's error, a light one the light patch's.
        let near_dark = shown(&[Xyz::new(4.0, 4.2, 4.6), Xyz::new(6.0, 6.1, 6.8)], centre);
        let w = scene_weighted(&patches, &near_dark, &white).unwrap();
        assert_eq!((w.patches_used, w.mean), (1, 2.0));
        let mixed = shown(&[Xyz::new(4.0, 4.2, 4.6), light, light, light], centre);
        let w = scene_weighted(&patches, &mixed, &white).unwrap();
        assert!((w.mean - (2.0 + 3.0 * 0.2) / 4.0).abs() < 1e-12);
        assert_eq!(w.max, 2.0);
    }

    #[test]
    fn scene_colours_count_where_they_are_shown() {
        let white = Xyz::new(95.0, 100.0, 109.0);
        let grey = Xyz::new(19.0, 20.0, 21.8);
        let corner = ScreenPosition::new(0.1, 0.1);
        // The same grey measured at the centre (ΔE00 0.3) and in a corner (1.5).
        let patches = [
            WeighedPatch {
                measured: grey,
                position: ScreenPosition::CENTRE,
                delta_e00: 0.3,
            },
            WeighedPatch {
                measured: grey * 0.9,
                position: corner,
                delta_e00: 1.5,
            },
        ];
        let scene_at = |position: ScreenPosition| {
            vec![ScenePixel {
                xyz: grey,
                position,
            }]
        };
        let middle = scene_weighted(&patches, &scene_at(ScreenPosition::CENTRE), &white).unwrap();
        let near_corner =
            scene_weighted(&patches, &scene_at(ScreenPosition::new(0.05, 0.2)), &white).unwrap();
        assert_eq!(middle.mean, 0.3);
        assert_eq!(near_corner.mean, 1.5);
        assert_eq!(
            (near_corner.positions_measured, near_corner.positions_used),
            (2, 1)
        );
    }

    #[test]
    fn the_power_law_nearest_a_power_law_is_itself() {
        let law = TransferLaw::Power(Power { gamma: 2.35 });
        assert!((power_exponent(&law) - 2.35).abs() < 1e-12);
        let gog = TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.05, 2.4));
        let g = power_exponent(&gog);
        assert!(g > 2.4 && g < 4.0, "{g}");
    }
}
