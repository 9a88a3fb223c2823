//! Scoring a model on measurements: predict each patch, compare in CIEDE2000 against
//! the model's own white. This is both the held-out error of a fit and what
//! `chromacal check` reports for a profile against any measurements.

use serde::{Deserialize, Serialize};

use super::noise::NoiseModel;
use super::stats::ErrorStats;
use crate::color::{Xyz, delta_e_2000, xyz_to_lab};
use crate::measurement::{Measurement, MeasurementSet, Role};
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
/// The split on which chromacal is compared with other tools on a real measurement set:
/// the fit sees the blacks, the greys and the single-channel ramps, at most `max_train`
/// readings (the greys below white thinned evenly over their levels when there are
/// more), and every mixture of two or three channels is held out. Roles are read from
/// the drives, so a journal splits as a `.ti3` does. Returns (train, test).
pub fn ramps_and_greys_split(
    set: &MeasurementSet,
    max_train: usize,
) -> (MeasurementSet, MeasurementSet) {
    let role = |m: &Measurement| Role::from_drive(m.drive);
    let (mut train, test): (Vec<Measurement>, Vec<Measurement>) = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition())
        .cloned()
        .partition(|m| role(m) != Role::Mixture);
    let is_thinnable = |m: &Measurement| role(m) == Role::Grey && m.drive[0] < 1.0;
    let fixed = train.iter().filter(|m| !is_thinnable(m)).count();
    let mut greys: Vec<Measurement> = train.iter().filter(|m| is_thinnable(m)).cloned().collect();
    let room = max_train.saturating_sub(fixed);
    if greys.len() > room {
        greys.sort_by(|a, b| a.drive[0].total_cmp(&b.drive[0]));
        let n = greys.len();
        // Indices spread evenly from the darkest grey to the brightest.
        let kept: Vec<Measurement> = (0..room)
            .map(|k| {
                let at = if room > 1 {
                    k * (n - 1) / (room - 1)
                } else {
                    n / 2
                };
                greys[at].clone()
            })
            .collect();
        train.retain(|m| !is_thinnable(m));
        train.extend(kept);
    }
    let part = |measurements: Vec<Measurement>, what: &str| MeasurementSet {
        source: format!("{} ({what})", set.source),
        units: set.units,
        instrument: set.instrument.clone(),
        display: set.display.clone(),
        measurements,
    };
    (part(train, "train"), part(test, "test"))
}
