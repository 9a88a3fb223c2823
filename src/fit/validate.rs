//! Scoring a model on measurements: predict each patch, compare in CIEDE2000 against
//! the model's own white. This is both the held-out error of a fit and what
//! `chromacal check` reports for a profile against any measurements.

use serde::{Deserialize, Serialize};

use super::noise::NoiseModel;
use super::stats::ErrorStats;
use crate::color::{Xyz, delta_e_2000, xyz_to_lab};
use crate::measurement::{Measurement, Role};
use crate::model::{Drive, MonitorModel, ScreenPosition};

/// One patch, measured and predicted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PatchError {
    pub index: usize,
    pub role: Role,
    pub drive: Drive,
    pub position: ScreenPosition,
    pub measured: Xyz,
    pub predicted: Xyz,
    pub delta_e00: f64,
}

/// Errors of a model over a set of patches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    pub stats: Option<ErrorStats>,
    pub patches: Vec<PatchError>,
}

impl Evaluation {
    /// The `n` worst patches, worst first.
    pub fn worst(&self, n: usize) -> Vec<&PatchError> {
        let mut sorted: Vec<&PatchError> = self.patches.iter().collect();
        sorted.sort_by(|a, b| b.delta_e00.total_cmp(&a.delta_e00));
        sorted.truncate(n);
        sorted
    }
}

/// ΔE00 between two XYZ seen against the same white.
pub fn delta_e00_xyz(a: &Xyz, b: &Xyz, white: &Xyz) -> f64 {
    delta_e_2000(&xyz_to_lab(a, white), &xyz_to_lab(b, white))
}

/// Mean ΔE00 that one standard deviation of measurement noise makes to each of
/// `readings` (as a change of luminance): the size of error noise alone explains.
pub fn noise_delta_e00(readings: &[Xyz], noise: &NoiseModel, white: &Xyz) -> f64 {
    if readings.is_empty() {
        return 0.0;
    }
    readings
        .iter()
        .map(|xyz| {
            let y = xyz.y.abs().max(f64::MIN_POSITIVE);
            delta_e00_xyz(xyz, &(xyz * (1.0 + noise.sigma(y) / y)), white)
        })
        .sum::<f64>()
        / readings.len() as f64
}

/// Predict each (measurement, XYZ to compare with) and score it against the model's
/// white. The XYZ given may differ from the raw reading (drift-corrected, say).
pub fn evaluate<'a>(
    model: &MonitorModel,
    readings: impl IntoIterator<Item = (&'a Measurement, Xyz)>,
) -> Evaluation {
    let white = model.white();
    let patches: Vec<PatchError> = readings
        .into_iter()
        .map(|(m, measured)| {
            let predicted = model.forward(m.drive, m.position);
            PatchError {
                index: m.index,
                role: m.role,
                drive: m.drive,
                position: m.position,
                measured,
                predicted,
                delta_e00: delta_e00_xyz(&measured, &predicted, &white),
            }
        })
        .collect();
    let errors: Vec<f64> = patches.iter().map(|p| p.delta_e00).collect();
    Evaluation {
        stats: ErrorStats::of(&errors),
        patches,
    }
}
