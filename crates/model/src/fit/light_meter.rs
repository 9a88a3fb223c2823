//! Fitting with a luminance meter (Cowan 1983's case): the meter gives Y only, so the
//! primaries' chromaticities come from the configuration (the manufacturer's figures)
//! and only luminance is fitted.
//!
//! Each reading is given an XYZ so the rest of the fit can run unchanged: a black gets
//! the configured white's chromaticity, a single-channel reading its primary's, and any
//! other patch the chromaticity the model predicts for it (a first pass with a nominal
//! model, a second with the fitted one), always at the luminance measured. So every
//! comparison of measured and predicted colours is a comparison of luminance, and the
//! profile says so.

use crate::MonitorModel;
use crate::measurement::{Measurement, MeasurementSet, Role};
use crate::reading::ReadingStatus;
use chromacal_color::Xyz;
use chromacal_color::spaces::{Xyy, xyy_to_xyz};

use super::{FitError, FitOptions, FittedModel};

/// The whole luminance-meter path: give every reading an XYZ from the configured
/// primaries' chromaticities and a nominal model, fit (`fit`: the ordinary chain), give
/// the readings the fitted model's chromaticities, fit again, and say in the report
/// what was given.
pub fn fit_luminance_only(
    set: &MeasurementSet,
    options: &FitOptions,
    fit: impl Fn(&MeasurementSet, &FitOptions) -> Result<FittedModel, FitError>,
) -> Result<FittedModel, FitError> {
    let primaries = options.primaries_xy.ok_or(FitError::NeedChromaticities)?;
    let white = options.white_xy.unwrap_or([0.3127, 0.3290]);
    let first = fit(&synthesize(set, &primaries, white, None), options)?;
    let mut second = fit(
        &synthesize(set, &primaries, white, Some(&first.model)),
        options,
    )?;
    second.report.luminance_only = Some(format!(
        "measured with a luminance meter: the primaries' chromaticities are the configured ({:.4}, {:.4}), ({:.4}, {:.4}), ({:.4}, {:.4}), not measured; only luminance was fitted, and the ΔE00 figures compare luminance only",
        primaries[0][0],
        primaries[0][1],
        primaries[1][0],
        primaries[1][1],
        primaries[2][0],
        primaries[2][1]
    ));
    Ok(second)
}

/// True when the readings carry luminance but no XYZ.
pub fn is_luminance_only(set: &MeasurementSet) -> bool {
    let usable: Vec<&Measurement> = set
        .measurements
        .iter()
        .filter(|m| m.reading.status != ReadingStatus::Overload)
        .collect();
    !usable.is_empty()
        && usable
            .iter()
            .all(|m| m.reading.xyz.is_none() && m.reading.luminance.is_some())
}

fn xyz_of(xy: [f64; 2], y: f64) -> Xyz {
    xyy_to_xyz(&Xyy {
        x: xy[0],
        y: xy[1],
        big_y: y,
    })
}

/// The chromaticity a nominal display with these primaries shows for `drive` (power
/// law 2.2, primaries of equal luminance share as in `white_y`).
fn nominal_chromaticity(drive: [f64; 3], primaries: &[[f64; 2]; 3], full_y: [f64; 3]) -> [f64; 2] {
    let mut sum = Xyz::zeros();
    for c in 0..3 {
        sum += xyz_of(primaries[c], full_y[c] * drive[c].powf(2.2));
    }
    let s = sum.x + sum.y + sum.z;
    if s > 0.0 {
        [sum.x / s, sum.y / s]
    } else {
        [1.0 / 3.0; 2]
    }
}

/// The set with XYZ in place of luminance (see the module documentation). `model`, when
/// given, supplies the chromaticity of patches other than blacks and single channels.
pub fn synthesize(
    set: &MeasurementSet,
    primaries: &[[f64; 2]; 3],
    white_xy: [f64; 2],
    model: Option<&MonitorModel>,
) -> MeasurementSet {
    let y_of = |m: &Measurement| m.reading.luminance;
    let black_ys: Vec<f64> = set
        .measurements
        .iter()
        .filter(|m| m.role == Role::Black && m.reading.status == ReadingStatus::Ok)
        .filter_map(y_of)
        .collect();
    let black_y = if black_ys.is_empty() {
        0.0
    } else {
        black_ys.iter().sum::<f64>() / black_ys.len() as f64
    };
    let black = xyz_of(white_xy, black_y.max(0.0));
    // Full-drive luminance of each channel (for the nominal model).
    let mut full_y = [1.0; 3];
    for (c, slot) in full_y.iter_mut().enumerate() {
        if let Some(y) = set
            .measurements
            .iter()
            .filter(|m| m.role == Role::Ramp && m.drive[c] >= 1.0)
            .filter_map(y_of)
            .reduce(f64::max)
        {
            *slot = (y - black_y).max(1e-9);
        }
    }
    let mut out = set.clone();
    for m in &mut out.measurements {
        let Some(y) = m.reading.luminance else {
            continue;
        };
        let on: Vec<usize> = (0..3).filter(|c| m.drive[*c] > 0.0).collect();
        let xyz = if on.is_empty() {
            xyz_of(white_xy, y)
        } else if on.len() == 1 && m.role == Role::Ramp {
            black + xyz_of(primaries[on[0]], y - black_y)
        } else {
            let xy = match model {
                Some(model) => {
                    let p = model.forward(m.drive, m.position);
                    let s = p.x + p.y + p.z;
                    if s > 0.0 {
                        [p.x / s, p.y / s]
                    } else {
                        white_xy
                    }
                }
                None => nominal_chromaticity(m.drive, primaries, full_y),
            };
            xyz_of(xy, y)
        };
        m.reading.xyz = Some(xyz);
    }
    out
}
