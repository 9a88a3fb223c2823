//! Verifying the calibrated display as calibration users judge it (DisplayCAL's
//! measurement report, ArgyllCMS's `dispcal -v`/`dispread` with `profcheck`): a chart
//! shown through what the display holds now (its video LUT as it is, never a straight
//! one), each patch read and set against the colour it should be, with every ΔE given
//! its 95 % interval and every criterion a verdict of pass, fail or undecided.
//!
//! Each patch is set against two colours:
//! - the profile's prediction of what the codes sent show through the video LUT as
//!   it is now: is the profile still true of the panel?
//! - the reference (`--against`): what a colour-managed application asked for. For a
//!   reference encoding (`srgb`, `bt709`, `bt1886`, `p3`, `rec2020`) that is the
//!   encoding's colour carried to the calibrated white, sent as the application
//!   would: through the profile's inverse and the inverse of the calibration curves
//!   the profile says are loaded (`lut3d --through-calibration`'s transform), and
//!   where the display cannot show that colour, the nearest it can (clipped, as a
//!   colour-managed application's relative colorimetric rendering asks for it); the
//!   white, the black and the calibration greys are set against the calibration's
//!   target. With `--against profile` the reference is the prediction.
//!
//! The calibrated state is read off the same chart: the white (luminance, xy, CCT,
//! Duv, ΔE00 to the target), the black and the contrast, grey balance (a*, b*,
//! Δu′v′ against the measured white, for every grey of at least 1 % luminance), and
//! the tone curve against the target's. The uncertainty comes from the session's own
//! repeats: the white's scatter gives the relative noise and the black's the floor
//! (pooled with a prior, as the fit does: `fit::noise::estimate_noise`); each ΔE's
//! interval, and each criterion's, is the 2.5–97.5 % range of that statistic over
//! seeded draws of the readings within that noise.

pub mod chart;
pub mod criteria;
mod evaluate;
mod measure;
pub mod uniformity;

use serde::Serialize;

use chromacal_color::Xyz;
use chromacal_crf::gamut::GamutMapping;
use chromacal_crf::lut3d::{LutOptions, SourceSpace, curve_input, source_target};
use chromacal_crf::tone::ToneOperator;
use chromacal_crf::{CodeChoice, ColourReproduction, RenderSettings, Scene, ScenePixel};
use chromacal_display::x11::GammaRamp;
use chromacal_model::screen::Codes;
use chromacal_model::target::{CalibrationCurves, ToneCurve, target_luminance};
use chromacal_model::{MonitorModel, ScreenPosition};

pub use chart::{Chart, ChartPatch, Input, Kind};
pub use criteria::{CriteriaSet, Criterion, Statistic, Verdict};
pub use evaluate::{
    CalibratedState, CriterionResult, GreyBalance, PatchResult, ToneLevel, VerifyReport, evaluate,
    grey_chroma,
};
pub use measure::{
    AimPrompt, MeasureError, MeasureOptions, Readings, measure_chart, measure_grid, read_again,
};

/// What each patch is set against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Against {
    /// The profile's prediction through the video LUT as it is.
    Profile,
    /// What an application sends for codes of this encoding.
    Encoding(SourceSpace),
}

impl std::str::FromStr for Against {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "profile" => Ok(Against::Profile),
            other => other.parse().map(Against::Encoding).map_err(|_| {
                let keys: Vec<&str> = SourceSpace::ALL.iter().map(|s| s.key()).collect();
                format!("no reference '{s}' ({}, profile)", keys.join(", "))
            }),
        }
    }
}

impl Against {
    pub fn name(self) -> String {
        match self {
            Against::Profile => "the profile's prediction".into(),
            Against::Encoding(space) => space.name().to_string(),
        }
    }
}

impl Serialize for Against {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&match self {
            Against::Profile => "profile".to_string(),
            Against::Encoding(space) => space.key().to_string(),
        })
    }
}

/// The colour difference the verdicts use (kept in the profile store's records too).
pub use chromacal_color::difference::Metric;

/// What the display holds between the codes sent and the panel.
#[derive(Debug, Clone, PartialEq)]
pub enum Loaded {
    /// A video LUT, as read back from the display now.
    Ramp(GammaRamp),
    /// No video LUT: chromacal applies the profile's calibration curves to the codes
    /// itself, as the calibration did.
    Curves(CalibrationCurves),
    /// Nothing: the codes reach the panel as they are.
    Straight,
}

impl Loaded {
    /// The drive the panel gets for codes sent as `drive`.
    pub fn output(&self, drive: [f64; 3]) -> [f64; 3] {
        match self {
            Loaded::Ramp(ramp) => [0, 1, 2].map(|c| ramp.output(c, drive[c])),
            Loaded::Curves(curves) => curves.apply(drive),
            Loaded::Straight => drive,
        }
    }
}

/// A patch ready to be shown: the codes sent, and what they are set against.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlannedPatch {
    pub patch: ChartPatch,
    /// The application's codes, drive in [0, 1] (before anything chromacal applies).
    pub application: [f64; 3],
    /// The codes sent to the display.
    pub codes: Codes,
    /// What the patch should show, in the profile's units.
    pub reference: [f64; 3],
    /// What the profile says the codes show through what is loaded.
    pub predicted: [f64; 3],
    /// The colour asked for lies outside what the display can show: the reference
    /// is then the nearest it can (clipped), and this the colour asked for.
    pub outside: bool,
    pub asked: Option<[f64; 3]>,
}

/// What a verification is set against: the profile's model and curves, and the
/// white and black the display shows.
pub struct Setting<'a> {
    pub model: &'a MonitorModel,
    pub curves: Option<&'a CalibrationCurves>,
    pub against: Against,
    /// Bits of the codes sent.
    pub bits: u32,
}

impl Setting<'_> {
    /// The white the display shows: the calibration's target, else the native one.
    pub fn white(&self) -> Xyz {
        match self.curves {
            Some(k) => Xyz::new(k.white[0], k.white[1], k.white[2]),
            None => self.model.white(),
        }
    }

    pub fn black(&self) -> Xyz {
        match self.curves {
            Some(k) => Xyz::new(k.black[0], k.black[1], k.black[2]),
            None => self.model.black,
        }
    }

    /// What the calibration aimed the display grey of input `x` at: the target tone's
    /// luminance at the white's chromaticity (the prediction without curves).
    fn target_grey(&self, x: f64, predicted: Xyz) -> Xyz {
        let Some(curves) = self.curves else {
            return predicted;
        };
        let (white, black) = (self.white(), self.black());
        if x <= 0.0 {
            return black;
        }
        let y = target_luminance(curves.target.tone, x, black.y, white.y);
        black + (white - black) * ((y - black.y) / (white.y - black.y))
    }
}

/// The chart's patches with their codes and references.
pub fn plan(
    chart: &Chart,
    setting: &Setting,
    loaded: &Loaded,
) -> Result<Vec<PlannedPatch>, String> {
    let white = setting.white();
    let black = setting.black();
    // What the application asks for each patch given as a colour or as codes of the
    // reference encoding.
    let asked: Vec<Option<Xyz>> = chart
        .patches
        .iter()
        .map(|p| match (p.input, setting.against) {
            (Input::Encoded(rgb), Against::Encoding(source)) => Some(source_target(
                rgb,
                &white,
                &black,
                &LutOptions {
                    source,
                    size: 2,
                    gamut: GamutMapping::Clip,
                    absolute: false,
                    through_calibration: setting.curves.is_some(),
                    // A PQ reference as the calibration's target rolls it off.
                    mastering_peak: setting.curves.and_then(|k| match k.target.tone {
                        ToneCurve::Pq { mastering_peak } => mastering_peak,
                        _ => None,
                    }),
                },
            )),
            (Input::Colour(c), _) => Some(relative_colour(chart::colour_xyz(c), &white, &black)),
            _ => None,
        })
        .collect();
    // Their drives through the profile's inverse (clipped to the gamut, 16 bits).
    let crf = ColourReproduction::new(setting.model).map_err(|e| e.to_string())?;
    let scene = Scene {
        pixels: asked
            .iter()
            .map(|xyz| ScenePixel {
                xyz: xyz.unwrap_or(white),
                position: ScreenPosition::CENTRE,
            })
            .collect(),
        white: None,
    };
    let rendering = crf
        .render(
            &scene,
            &RenderSettings {
                adaptation: None,
                tone: ToneOperator::Colorimetric,
                gamut: GamutMapping::Clip,
                bits: 16,
                codes: CodeChoice::Rounded,
            },
        )
        .map_err(|e| e.to_string())?;
    let mut planned = Vec::new();
    for ((patch, asked), pixel) in chart.patches.iter().zip(&asked).zip(&rendering.pixels) {
        // The ColorChecker's colours the display cannot show are left out.
        if patch.kind == Kind::ColorChecker && pixel.outside {
            continue;
        }
        let application = match (patch.input, asked) {
            (Input::Display(rgb), _) | (Input::Encoded(rgb), None) => rgb,
            (_, _) => {
                let drive = pixel.codes.map(|c| f64::from(c) / 65535.0);
                match setting.curves {
                    Some(k) => [0, 1, 2].map(|c| curve_input(&k.curves[c], drive[c])),
                    None => drive,
                }
            }
        };
        let sent = match loaded {
            Loaded::Curves(curves) => curves.apply(application),
            _ => application,
        };
        let codes = Codes::from_drive(sent, setting.bits);
        let panel = match loaded {
            Loaded::Curves(_) => codes.drive(),
            _ => loaded.output(codes.drive()),
        };
        let predicted = setting.model.forward(panel, ScreenPosition::CENTRE);
        // What colour management makes of the colour asked for: the colour itself,
        // or where the display cannot show it, the nearest it can (clipped).
        let reference = match (setting.against, patch.input, asked) {
            (Against::Profile, _, _) => predicted,
            (_, Input::Display(rgb), _) => setting.target_grey(rgb[0], predicted),
            (_, _, Some(_)) => Xyz::from(pixel.mapped),
            (_, _, None) => predicted,
        };
        let outside = asked.is_some() && pixel.outside;
        planned.push(PlannedPatch {
            patch: patch.clone(),
            application,
            codes,
            reference: reference.into(),
            predicted: predicted.into(),
            outside,
            asked: asked.filter(|_| outside).map(Into::into),
        });
    }
    Ok(planned)
}

/// A colour relative to a D65 white of Y = 1, as the display shows it relative to
/// its white (Bradford) with black point compensation.
fn relative_colour(colour: Xyz, white: &Xyz, black: &Xyz) -> Xyz {
    use chromacal_color::adaptation::{AdaptationTransform, adapt};
    let d65 = Xyz::new(0.95047, 1.0, 1.08883);
    let adapted = adapt(
        &colour,
        AdaptationTransform::Bradford,
        &d65,
        &(white / white.y),
    );
    let share = (black.y / white.y).clamp(0.0, 1.0);
    (adapted * (1.0 - share) + white / white.y * share) * white.y
}
