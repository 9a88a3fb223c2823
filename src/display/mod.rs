//! Showing patches: the patch-display trait and its sinks.
//!
//! A sink resolves `show` once the patch is on the screen and settled, so the run
//! measures straight after it returns.

pub mod emulator_link;
pub mod lut;
pub mod resolve;
pub mod simulated;
pub mod web;
pub mod window;

use std::future::Future;

use crate::model::target::CalibrationCurves;
use crate::screen::Patch;

/// Why a display could not show a patch.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DisplayError {
    #[error("the display is gone: {0}")]
    Lost(String),
    #[error("the display cannot show this patch: {0}")]
    Unsupported(String),
}

/// Something that puts patches on the screen being measured.
pub trait PatchDisplay {
    /// A short name for logs and provenance.
    fn name(&self) -> String;

    /// Show `patch`; resolves when it is on the screen and settled.
    fn show(&mut self, patch: &Patch) -> impl Future<Output = Result<(), DisplayError>> + Send;

    /// Blank the screen (black), as when a run stops.
    fn blank(&mut self) -> impl Future<Output = Result<(), DisplayError>> + Send;

    /// Load calibration curves (identity for `None`) into the video LUT behind the
    /// patches, for a display that has one it may set (the native window's CRTC
    /// gamma). `Ok(false)`: it has none, and curves must go into the codes instead.
    fn load_curves(&mut self, _curves: Option<&CalibrationCurves>) -> Result<bool, DisplayError> {
        Ok(false)
    }
}
