//! Measurements as the fitting and checking code sees them, whatever they came from:
//! a run's journal, or a measurement file of another tool (`cgats`).

use serde::{Deserialize, Serialize};

use crate::reading::{InstrumentInfo, Reading, ReadingStatus};
use crate::screen::Codes;
use crate::{Drive, ScreenPosition};
use chromacal_color::Xyz;

/// What a patch was measured for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Role {
    /// Zero drive.
    Black,
    /// One channel on, the others at zero (full drive included).
    Ramp,
    /// All channels at the same drive: additivity.
    Grey,
    /// The patch repeated through the run to follow drift (full white).
    Reference,
    /// A patch at a grid position away from the centre: spatial map.
    Uniformity,
    /// The same patch on different backgrounds: spatial independence.
    Surround,
    /// White or a grey as a window of a stated size on black: the brightness limiter.
    Window,
    /// Held out of every fit: the honest error.
    Verification,
    /// Anything else (from files that do not say what a patch is for).
    Mixture,
}

impl Role {
    /// The role a patch plays judged from its drive alone, for files that carry no
    /// roles: black, single-channel ramp, grey (full white included), or mixture.
    pub fn from_drive(drive: Drive) -> Role {
        let on: Vec<usize> = (0..3).filter(|c| drive[*c] > 0.0).collect();
        match on.len() {
            0 => Role::Black,
            1 => Role::Ramp,
            _ if drive[0] == drive[1] && drive[1] == drive[2] => Role::Grey,
            _ => Role::Mixture,
        }
    }
}

/// The level of a drive that shows one channel alone (that channel's drive) or a grey
/// (the grey's); `None` for black and mixtures.
pub fn drive_level(drive: Drive) -> Option<f64> {
    match Role::from_drive(drive) {
        Role::Ramp | Role::Grey => Some(drive.iter().copied().fold(0.0, f64::max)),
        _ => None,
    }
}

/// The unit of the XYZ values of a measurement set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Units {
    /// cd/m².
    Absolute,
    /// Scaled so that white has Y = 100 (ArgyllCMS's `NORMALIZED_TO_Y_100`).
    Relative,
}

impl std::fmt::Display for Units {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Units::Absolute => "cd/m²",
            Units::Relative => "relative (white Y = 100)",
        })
    }
}

/// One measured patch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Index of the patch in its plan or file.
    pub index: usize,
    pub role: Role,
    /// Drive of the patch, normalised.
    pub drive: Drive,
    /// Code values as sent, where known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub codes: Option<Codes>,
    /// Where on the screen it was read.
    #[serde(default)]
    pub position: ScreenPosition,
    /// Drive of the surround.
    #[serde(default)]
    pub background: Drive,
    /// The patch's share of the screen's area, where it was measured for the
    /// brightness limiter (`Role::Window`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<f64>,
    /// Seconds on the run's clock at the middle of the reading, where known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
    pub reading: Reading,
}

impl Measurement {
    /// The XYZ when the reading is within range and finite.
    pub fn usable_xyz(&self) -> Option<Xyz> {
        match (self.reading.status, self.reading.xyz) {
            (ReadingStatus::Ok, Some(xyz)) if xyz.iter().all(|v| v.is_finite()) => Some(xyz),
            _ => None,
        }
    }

    /// A reading of the centre of the screen on a black background, at the plan's
    /// patch size: the condition under which the model's matrix and laws are defined.
    /// (A window of another size is not: a brightness limiter dims a large one.)
    pub fn is_standard_condition(&self) -> bool {
        self.position.is_centre() && self.background == [0.0; 3] && self.window.is_none()
    }
}

/// A set of measurements of one display.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeasurementSet {
    /// Where the set came from (a path).
    pub source: String,
    pub units: Units,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument: Option<InstrumentInfo>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub display: Option<String>,
    /// When the readings were taken, as the file says it (a .ti3's `CREATED`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_at: Option<String>,
    pub measurements: Vec<Measurement>,
}

impl MeasurementSet {
    /// Seconds of integration over every reading, when each records its own (a run
    /// journal does; a .ti3 does not, and then it is unknown).
    pub fn instrument_seconds(&self) -> Option<f64> {
        let known = self
            .measurements
            .iter()
            .all(|m| m.reading.integration_s > 0.0);
        (known && !self.measurements.is_empty()).then(|| {
            self.measurements
                .iter()
                .map(|m| m.reading.integration_s)
                .sum()
        })
    }

    /// Mean of the usable readings of full white at the standard condition (centre,
    /// black surround), the white a set is normalised by and scored against.
    pub fn mean_white(&self) -> Option<Xyz> {
        let whites: Vec<Xyz> = self
            .measurements
            .iter()
            .filter(|m| m.drive == [1.0; 3] && m.is_standard_condition())
            .filter_map(|m| m.usable_xyz())
            .collect();
        (!whites.is_empty()).then(|| whites.iter().sum::<Xyz>() / whites.len() as f64)
    }

    pub fn with_role(&self, role: Role) -> impl Iterator<Item = &Measurement> {
        self.measurements.iter().filter(move |m| m.role == role)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_from_drives() {
        assert_eq!(Role::from_drive([0.0; 3]), Role::Black);
        assert_eq!(Role::from_drive([0.0, 0.4, 0.0]), Role::Ramp);
        assert_eq!(Role::from_drive([1.0; 3]), Role::Grey);
        assert_eq!(Role::from_drive([0.5, 0.5, 0.2]), Role::Mixture);
        assert_eq!(Role::from_drive([0.5, 0.5, 0.0]), Role::Mixture);
    }
}
