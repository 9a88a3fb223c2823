//! What a reading is: the light an instrument measured, how far it can be trusted, and
//! who measured it. Plain data, below every instrument, so that the measurements, the
//! fit and the file formats can hold readings without depending on any driver.
//!
//! A reading never hides a failure: light below the instrument's range or above it
//! is flagged in [`ReadingStatus`], never turned into a zero.

use serde::{Deserialize, Serialize};

use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;

/// What an instrument can measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Capability {
    /// A light meter: luminance only (Cowan's case).
    Luminance,
    /// A colorimeter: XYZ.
    Tristimulus,
    /// A spectroradiometer: a spectrum, and XYZ from it.
    Spectral,
}

/// How far a reading can be trusted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ReadingStatus {
    #[default]
    Ok,
    /// Less light than the instrument can measure reliably; the value, if any, is
    /// only an indication.
    BelowRange,
    /// More light than the instrument can take; there is no value.
    Overload,
}

/// One measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Reading {
    /// CIE 1931 XYZ in cd/m²; `None` from a light meter and on overload.
    pub xyz: Option<Xyz>,
    /// Luminance in cd/m² from a light meter, which gives nothing else.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub luminance: Option<f64>,
    /// Spectral radiance, W·sr⁻¹·m⁻²·nm⁻¹, where the instrument gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spectrum: Option<Spectrum>,
    pub status: ReadingStatus,
    /// Integration time used, seconds.
    pub integration_s: f64,
    /// The instrument's own quality or status code, as it sent it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device_code: Option<String>,
    /// The reply the reading was parsed from, with control bytes escaped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw: Option<String>,
}

/// More light than any display emits, cd/m²: ten times the brightest signage and
/// HDR panels (about 10,000). A reading above it is a misread (a unit lost, a
/// correction gone wrong, a program printing nonsense), not light.
pub const MOST_LIGHT_OF_A_DISPLAY: f64 = 100_000.0;

/// How far below zero an instrument's noise can take a component of a reading:
/// an absolute part (a colorimeter's dark noise at black is some thousandths of a
/// cd/m²; 5 is five times the floor of the noisiest instrument the tests simulate,
/// whose black readings go to −1.2) and a part of the luminance (a filter's noise).
const NEGATIVE_NOISE_ABSOLUTE: f64 = 5.0;
const NEGATIVE_NOISE_RELATIVE: f64 = 0.05;

impl Reading {
    /// Luminance Y in cd/m², from XYZ or from a light meter.
    pub fn luminance(&self) -> Option<f64> {
        self.xyz.map(|x| x.y).or(self.luminance)
    }

    /// Why this reading cannot be light a display emitted, if it cannot: a value
    /// that is not a number, a luminance beyond [`MOST_LIGHT_OF_A_DISPLAY`], or a
    /// component further below zero than noise takes it. Light is never negative, so a
    /// negative X, Y or Z beyond the noise is a misread however it came.
    pub fn implausible(&self) -> Option<String> {
        let values: Vec<(&str, f64)> = match (self.xyz, self.luminance) {
            (Some(xyz), _) => vec![("X", xyz.x), ("Y", xyz.y), ("Z", xyz.z)],
            (None, Some(l)) => vec![("luminance", l)],
            (None, None) => return None,
        };
        let luminance = self.luminance().unwrap_or(0.0);
        let floor = -(NEGATIVE_NOISE_ABSOLUTE + NEGATIVE_NOISE_RELATIVE * luminance.max(0.0));
        for (name, v) in values {
            if !v.is_finite() {
                return Some(format!("{name} = {v} is not a finite number"));
            }
            if v > MOST_LIGHT_OF_A_DISPLAY {
                return Some(format!(
                    "{name} = {v:.3e} cd/m² is more light than any display emits (at most {MOST_LIGHT_OF_A_DISPLAY:e})"
                ));
            }
            if v < floor {
                return Some(format!(
                    "{name} = {v} cd/m² is negative beyond an instrument's noise (light is never negative)"
                ));
            }
        }
        None
    }
}

/// Who the instrument is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentInfo {
    pub name: String,
    pub serial: Option<String>,
    pub capability: Capability,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn of(x: f64, y: f64, z: f64) -> Reading {
        Reading {
            xyz: Some(Xyz::new(x, y, z)),
            ..Reading::default()
        }
    }

    #[test]
    fn light_a_display_can_emit_is_plausible_and_the_rest_is_named() {
        assert_eq!(of(95.0, 100.0, 108.9).implausible(), None);
        // Black, with an instrument's noise below zero.
        assert_eq!(of(-0.004, 0.002, -0.01).implausible(), None);
        // A very noisy instrument's black.
        assert_eq!(of(0.3, -1.2, -1.22).implausible(), None);
        assert_eq!(of(4000.0, 4200.0, 4500.0).implausible(), None);
        for (reading, named) in [
            (of(1e30, 1e30, 1e30), "X = 1.000e30"),
            (of(20.0, 1e9, 22.0), "Y = 1.000e9"),
            (of(-90.9, 99.9, -120.3), "X = -90.9"),
            (of(1.0, -8.0, 1.0), "Y = -8"),
            (of(f64::NAN, 1.0, 1.0), "X = NaN"),
        ] {
            let why = reading.implausible().unwrap_or_default();
            assert!(why.starts_with(named), "{why}");
        }
        let meter = Reading {
            luminance: Some(-8.0),
            ..Reading::default()
        };
        assert!(
            meter
                .implausible()
                .unwrap_or_default()
                .contains("luminance")
        );
    }
}
