//! The video LUT across a run on the native window: saved and made straight before
//! the first patch, and on the way out loaded with what the run leaves behind — the
//! published profile's curves, the straight ramp a published profile without curves
//! was measured through, or the ramp the user had when anything else happened. The
//! saved ramp lives in the state directory until then (`display::lut`), so a run
//! killed outright is undone by the next chromacal that opens the directory.

use std::path::Path;

use super::devices::Devices;
use chromacal_display::lut::{self, LutError, SavedLut};
use chromacal_display::x11::GammaRamp;
use chromacal_model::target::CalibrationCurves;

/// Save the window's LUT (unless an earlier run's saved ramp is still waiting to be
/// put back: that one is the user's) and load the straight ramp. Nothing for other
/// displays.
pub fn hold(state_dir: &Path, devices: &mut Devices) -> Result<(), LutError> {
    let Some(window) = devices.display.window() else {
        return Ok(());
    };
    let size = window.output().gamma_size;
    if size < 2 {
        tracing::warn!(output = %window.output().name, "the output has no video LUT chromacal can set: the curves go into the codes");
        return Ok(());
    }
    let display = window.x_display().name().to_string();
    let output = window.output().name.clone();
    match lut::pending(state_dir)? {
        None => lut::save(
            state_dir,
            &SavedLut {
                x_display: display,
                output,
                ramp: window.gamma()?,
                pid: std::process::id(),
            },
        )?,
        // The user's own ramp, saved by a run on this output that did not finish.
        Some(saved) if saved.x_display == display && saved.output == output => {}
        Some(saved) => {
            return Err(LutError::Foreign {
                path: lut::saved_path(state_dir),
                saved_display: saved.x_display,
                saved_output: saved.output,
                display,
                output,
            });
        }
    }
    window.set_gamma(&GammaRamp::identity(size))?;
    Ok(())
}

/// How a run ended, as far as its video LUT is concerned.
#[derive(Debug, Clone, Copy)]
pub enum RunEnd<'a> {
    /// No profile became current (stopped, failed, or rejected by `[publish]`): the
    /// user's ramp goes back.
    Unpublished,
    /// A profile became current, measured through the straight LUT, with these
    /// curves (or none, and why none when `[target]` asked for them).
    Published {
        curves: Option<&'a CalibrationCurves>,
        why_no_curves: Option<&'a str>,
    },
}

/// Load what the run leaves in the LUT and forget the saved ramp; says what was left
/// (for the summary). `None` for a display without a LUT.
pub fn release(
    state_dir: &Path,
    devices: &mut Devices,
    end: RunEnd,
) -> Result<Option<String>, LutError> {
    let Some(window) = devices.display.window() else {
        return Ok(None);
    };
    let output = window.output().clone();
    if output.gamma_size < 2 {
        return Ok(None);
    }
    let (ramp, what) = match end {
        RunEnd::Published {
            curves: Some(curves),
            ..
        } => (
            GammaRamp::from_curves(curves, output.gamma_size),
            format!(
                "the new calibration curves are loaded in the video LUT of {}",
                output.name
            ),
        ),
        RunEnd::Published {
            curves: None,
            why_no_curves,
        } => (
            GammaRamp::identity(output.gamma_size),
            format!(
                "the video LUT of {} is straight, as the profile was measured ({})",
                output.name,
                match why_no_curves {
                    Some(why) => format!("the curves could not be made: {why}"),
                    None => "no [target], so no curves".to_string(),
                }
            ),
        ),
        RunEnd::Unpublished => match lut::pending(state_dir)? {
            Some(saved) if saved.output == output.name => (
                saved.ramp,
                format!("the video LUT of {} is back as it was", output.name),
            ),
            _ => return Ok(None),
        },
    };
    window.set_gamma(&ramp)?;
    lut::forget(state_dir)?;
    Ok(Some(what))
}

/// A desktop program that loads calibration curves itself (from colord's profile for
/// each output), if one runs: chromacal then leaves the LUT to it rather than fight
/// over it. Found by process name in `/proc`.
pub fn desktop_lut_loader() -> Option<String> {
    const LOADERS: [(&str, &str); 2] = [
        (
            "gsd-color",
            "GNOME's colour plugin (gsd-color, from colord's profile)",
        ),
        ("xiccd", "xiccd (from colord's profile)"),
    ];
    let entries = std::fs::read_dir("/proc").ok()?;
    for entry in entries.flatten() {
        let Ok(comm) = std::fs::read_to_string(entry.path().join("comm")) else {
            continue;
        };
        if let Some((_, what)) = LOADERS.iter().find(|(name, _)| comm.trim() == *name) {
            return Some((*what).to_string());
        }
    }
    None
}

/// What an output's video LUT holds now.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LutStatus {
    pub output: String,
    pub x_display: String,
    /// Entries of the CRTC's ramp.
    pub size: usize,
    /// The straight ramp (within one 16-bit step).
    pub identity: bool,
    /// Largest distance from `profile`'s curves, in 16-bit steps, when a profile with
    /// curves was given.
    pub from_profile_steps: Option<f64>,
    /// A desktop program that loads curves itself, if one runs.
    pub desktop_loader: Option<String>,
    /// The ramp at 17 inputs (0, 1/16, …, 1), R, G, B in [0, 1], for a glance.
    pub samples: Vec<[f64; 4]>,
}

/// The LUT of `output` now, set against `curves` when given.
pub fn lut_status(
    x: &chromacal_display::x11::XDisplay,
    output: &chromacal_display::x11::OutputInfo,
    curves: Option<&chromacal_model::target::CalibrationCurves>,
) -> Result<LutStatus, chromacal_display::x11::X11Error> {
    let ramp = x.gamma(output)?;
    Ok(LutStatus {
        output: output.name.clone(),
        x_display: x.name().to_string(),
        size: ramp.len(),
        identity: ramp.is_identity(),
        from_profile_steps: curves
            .map(|c| ramp.max_difference(&GammaRamp::from_curves(c, ramp.len()))),
        desktop_loader: desktop_lut_loader(),
        samples: (0..=16)
            .map(|k| {
                let v = k as f64 / 16.0;
                [v, ramp.output(0, v), ramp.output(1, v), ramp.output(2, v)]
            })
            .collect(),
    })
}
