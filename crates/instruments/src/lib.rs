//! Measuring light: the [`Instrument`] trait and the instruments behind it. Each
//! family has its own folder (`pr650`, `pr6xx`, `klein`, `jeti`, `minolta`,
//! `colorcal`) with its protocol apart from its transport (`serial`, `transport`),
//! and an emulator that answers byte for byte as the device does on a
//! pseudo-terminal (`emulator`); `argyll` drives USB instruments through ArgyllCMS's
//! `spotread`; `simulated` reads the virtual monitor in-process; `transcript`
//! replays recorded sessions. Blocking serial I/O; the `tokio` feature adds
//! `driver::AsyncSerialInstrument`, which runs it on tokio's blocking pool.
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

use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;

/// What a reading is lives with the measurements it becomes, below every instrument.
pub use chromacal_model::reading::{Capability, InstrumentInfo, Reading, ReadingStatus};

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
    let own = chromacal_color::spectrum::emission_to_xyz(
        spectrum,
        chromacal_color::spectrum::Observer::default(),
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
