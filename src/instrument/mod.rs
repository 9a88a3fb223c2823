//! Measuring light: the instrument trait, what a reading is, and the instruments.
//!
//! A reading never hides a failure: light below the instrument's range or above it
//! is flagged in [`ReadingStatus`], never turned into a zero.

pub mod argyll;
pub mod colorcal;
pub mod devices;
pub mod driver;
pub mod emulator;
pub mod filters;
pub mod jeti;
pub mod klein;
pub mod minolta;
pub mod pr650;
pub mod pr6xx;
pub mod scan;
pub mod serial;
pub mod simulated;
pub mod transcript;
pub mod transport;

use std::future::Future;

use serde::{Deserialize, Serialize};

use crate::color::Xyz;
use crate::color::spectrum::Spectrum;

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

/// Check that a spectrum an instrument sent belongs with the XYZ it sent: the grid is
/// the one expected (`first_nm`, `step_nm`, `count`) and the spectrum's own XYZ agrees
/// with the instrument's within 5 % (plus 0.01 cd/m²). A reply that came late, from an
/// earlier command, fails this check instead of passing for a measurement.
pub fn check_spectrum(
    spectrum: &Spectrum,
    xyz: &Xyz,
    first_nm: f64,
    step_nm: f64,
    count: usize,
) -> Result<(), InstrumentError> {
    let w = spectrum.wavelengths_nm();
    if w.len() != count
        || w.iter()
            .enumerate()
            .any(|(i, nm)| (nm - (first_nm + step_nm * i as f64)).abs() > 1e-6)
    {
        return Err(InstrumentError::Protocol(format!(
            "the spectrum is not on the {first_nm} nm + {step_nm} nm × {count} grid"
        )));
    }
    let own = crate::color::spectrum::emission_to_xyz(
        spectrum,
        crate::color::spectrum::Observer::default(),
    )
    .map_err(|e| InstrumentError::Protocol(format!("spectrum: {e}")))?;
    for k in 0..3 {
        if (own[k] - xyz[k]).abs() > 0.05 * xyz[k].abs() + 0.01 {
            return Err(InstrumentError::Protocol(format!(
                "the spectrum (XYZ {:.4}, {:.4}, {:.4}) does not match the XYZ sent with it ({:.4}, {:.4}, {:.4})",
                own.x, own.y, own.z, xyz.x, xyz.y, xyz.z
            )));
        }
    }
    Ok(())
}

/// Who the instrument is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentInfo {
    pub name: String,
    pub serial: Option<String>,
    pub capability: Capability,
}

/// Why a measurement failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InstrumentError {
    #[error("the instrument did not answer within {seconds} s")]
    Timeout { seconds: f64 },
    #[error("the instrument is gone: {0}")]
    Disconnected(String),
    #[error("the instrument's reply made no sense: {0}")]
    Protocol(String),
    #[error("the instrument reports error {code}: {meaning}")]
    Device { code: String, meaning: String },
    /// The instrument cannot be used at all (its program missing, no such port, its
    /// options refused): trying again will not help.
    #[error("{0}")]
    Unavailable(String),
}

/// A light meter, colorimeter or spectroradiometer.
pub trait Instrument {
    fn info(&self) -> InstrumentInfo;

    /// Measure what the screen shows at the instrument's spot.
    fn measure(&mut self) -> impl Future<Output = Result<Reading, InstrumentError>> + Send;
}
