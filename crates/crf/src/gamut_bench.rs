//! The gamut mappings side by side (`chromacal bench gamut`): each on the scenes that
//! need them, with what it costs the colours (ΔE00 to the original, hue turned, share
//! moved) and the time it takes.

use std::time::Instant;

use super::gamut::{GamutMapping, ScbOptions, SgckSource, UniformSpace};
use super::spectral_table::colorchecker_xyz;
use super::tone::ToneOperator;
use super::{CodeChoice, ColourReproduction, CrfError, RenderSettings, Scene, ScenePixel};
use chromacal_color::Xyz;
use chromacal_color::adaptation::AdaptationTransform;
use chromacal_color::spaces::{Lab, lab_to_xyz, xyz_to_lab};
use chromacal_color::spectrum::{Illuminant, Observer, white_point};
use chromacal_model::{MonitorModel, ScreenPosition};

/// One mapping on one scene.
#[derive(Debug, Clone, PartialEq)]
pub struct GamutBenchRow {
    pub scene: String,
    pub mapping: String,
    /// ΔE00 between each colour asked for and what the mapping made of it.
    pub mean_delta_e00: f64,
    pub max_delta_e00: f64,
    /// Mean |Δh_ab| in degrees over the colours moved that had chroma (C*ab > 1).
    pub mean_hue_turn: f64,
    /// Share of the scene's colours the mapping moved.
    pub moved: f64,
    /// Microseconds per colour, the whole rendering (mapping and inversion).
    pub microseconds: f64,
}

/// The mappings compared.
pub fn mappings() -> Vec<GamutMapping> {
    vec![
        GamutMapping::Clip,
        GamutMapping::GreyAxis(UniformSpace::Lab),
        GamutMapping::Perpendicular,
        GamutMapping::PerpendicularLab,
        GamutMapping::Hpminde,
        GamutMapping::Sgck(SgckSource::Rec2020),
        GamutMapping::Smith,
        GamutMapping::StoneCowanBeatty(ScbOptions::default()),
    ]
}

/// The scenes: the ColorChecker under D65 at 1.3 × the display's white (its light
/// patches above what the display can show), and 48 saturated colours of C*ab 110
/// round the hue circle at lightness 30 to 90 (beyond any display's primaries).
pub fn scenes(model: &MonitorModel) -> Vec<(String, Scene)> {
    let white = model.white();
    let centre = |xyz: Vec<Xyz>| -> Vec<ScenePixel> {
        xyz.into_iter()
            .map(|xyz| ScenePixel {
                xyz,
                position: ScreenPosition::CENTRE,
            })
            .collect()
    };
    let d65 = white_point(Illuminant::D65, Observer::default())
        .ok()
        .map(|w| w * (1.3 * white.y / 100.0));
    let mut list = Vec::new();
    if let (Some(chart), Some(d65)) = (colorchecker_xyz(Illuminant::D65, 1.3 * white.y), d65) {
        list.push((
            "ColorChecker, D65 at 1.3 × white".to_string(),
            Scene {
                pixels: centre(chart),
                white: Some(d65),
            },
        ));
    }
    let ring: Vec<Xyz> = (0..48)
        .map(|k| {
            let h = (k as f64 * 7.5).to_radians();
            let lab = Lab {
                l: 30.0 + 60.0 * (k % 8) as f64 / 7.0,
                a: 110.0 * h.cos(),
                b: 110.0 * h.sin(),
            };
            lab_to_xyz(&lab, &white)
        })
        .collect();
    list.push((
        "48 saturated colours, C*ab 110".to_string(),
        Scene {
            pixels: centre(ring),
            white: Some(white),
        },
    ));
    list
}

/// Every mapping on every scene, each rendering timed `rounds` times (the median).
pub fn gamut_table(model: &MonitorModel, rounds: usize) -> Result<Vec<GamutBenchRow>, CrfError> {
    let crf = ColourReproduction::new(model)?;
    let reference = crf.white();
    let mut rows = Vec::new();
    for (name, scene) in scenes(model) {
        for mapping in mappings() {
            let settings = RenderSettings {
                adaptation: Some(AdaptationTransform::Bradford),
                tone: ToneOperator::Colorimetric,
                gamut: mapping,
                bits: 16,
                codes: CodeChoice::Rounded,
            };
            let mut times = Vec::new();
            let mut rendering = None;
            for _ in 0..rounds.max(1) {
                let start = Instant::now();
                let r = crf.render(&scene, &settings)?;
                times.push(start.elapsed().as_secs_f64());
                rendering = Some(r);
            }
            let Some(r) = rendering else { continue };
            times.sort_by(f64::total_cmp);
            let errors: Vec<f64> = r.pixels.iter().map(|p| p.mapping_delta_e00).collect();
            let moved = r
                .pixels
                .iter()
                .filter(|p| p.mapping_delta_e00 > 1e-9)
                .count();
            let turns: Vec<f64> = r
                .pixels
                .iter()
                .filter(|p| p.mapping_delta_e00 > 1e-9)
                .filter_map(|p| {
                    let (a, b) = (
                        xyz_to_lab(&Xyz::from(p.target), &reference),
                        xyz_to_lab(&Xyz::from(p.mapped), &reference),
                    );
                    (a.a.hypot(a.b) > 1.0 && b.a.hypot(b.b) > 1.0).then(|| {
                        let d = b.b.atan2(b.a).to_degrees() - a.b.atan2(a.a).to_degrees();
                        ((d + 540.0) % 360.0 - 180.0).abs()
                    })
                })
                .collect();
            let n = r.pixels.len().max(1) as f64;
            rows.push(GamutBenchRow {
                scene: name.clone(),
                mapping: mapping.name(),
                mean_delta_e00: errors.iter().sum::<f64>() / n,
                max_delta_e00: errors.iter().copied().fold(0.0, f64::max),
                mean_hue_turn: if turns.is_empty() {
                    0.0
                } else {
                    turns.iter().sum::<f64>() / turns.len() as f64
                },
                moved: moved as f64 / n,
                microseconds: times[times.len() / 2] / n * 1e6,
            });
        }
    }
    Ok(rows)
}
