//! Showing patches: the patch-display trait and its sinks (the simulated display, a
//! Resolve pattern generator over TCP, a browser page, chromacal's own full-screen
//! X11 window or Wayland surface, an emulator's screen socket), and the screen in front
//! of the user through X11 (`x11`: outputs, EDID, the CRTC gamma ramp, pixels) and
//! Wayland (`wayland`: outputs, the patch surface), with the video LUT the calibration
//! curves go into (`lut`).
//!
//! A sink resolves `show` once the patch is on the screen and settled, so the run
//! measures straight after it returns.

pub mod drm;
pub mod emulator_link;
pub mod lut;
pub mod resolve;
pub mod simulated;
pub mod wayland;
pub mod web;
pub mod window;
pub mod x11;

use std::future::Future;

use chromacal_model::screen::Patch;
use chromacal_model::target::CalibrationCurves;

/// A black screen at 8 bits: what chromacal's window and surface show when they open
/// and when blanked.
pub const BLACK: Patch = Patch {
    codes: chromacal_model::screen::Codes {
        rgb: [0; 3],
        bit_depth: 8,
    },
    background: chromacal_model::screen::Codes {
        rgb: [0; 3],
        bit_depth: 8,
    },
    geometry: chromacal_model::screen::Geometry {
        x: 0.5,
        y: 0.5,
        width: 0.0,
        height: 0.0,
    },
};

/// Why a display could not show a patch.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DisplayError {
    #[error("the display is gone: {0}")]
    Lost(String),
    #[error("the display cannot show this patch: {0}")]
    Unsupported(String),
    /// The display named cannot be had at all (an X display that does not answer, an
    /// output that is not there): the name is wrong, or the screen is off.
    #[error("{0}")]
    Unavailable(String),
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
