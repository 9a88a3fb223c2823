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

impl Reading {
    /// Luminance Y in cd/m², from XYZ or from a light meter.
    pub fn luminance(&self) -> Option<f64> {
        self.xyz.map(|x| x.y).or(self.luminance)
    }
}

/// Who the instrument is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentInfo {
    pub name: String,
    pub serial: Option<String>,
    pub capability: Capability,
}
