//! The video LUT across a calibration: characterise through a straight ramp, and put
//! back what the user had — or the new curves — on every way out.
//!
//! A run on a real output first writes the output's ramp to `<state>/lut-saved.json`
//! (atomically, before touching the card), then loads the identity. When the run
//! ends it loads the new curves (published) or the saved ramp (any failure, Ctrl-C),
//! and removes the file. A run killed with SIGKILL leaves the file: the next chromacal
//! that takes the state directory ([`restore_pending`]) puts the ramp back.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::x11::{GammaRamp, OutputSelector, X11Error, XDisplay};

/// The file a run's saved ramp is kept in.
pub fn saved_path(state_dir: &Path) -> PathBuf {
    state_dir.join("lut-saved.json")
}

/// A ramp saved before a run set the LUT, and where it came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SavedLut {
    /// The X display, as opened (`:0`).
    pub x_display: String,
    /// The RandR output's name.
    pub output: String,
    pub ramp: GammaRamp,
    /// The process that saved it.
    pub pid: u32,
}

/// Why a saved ramp could not be kept or put back.
#[derive(Debug, thiserror::Error)]
pub enum LutError {
    #[error("{path}: {source}")]
    File {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} is not a saved LUT: {reason}")]
    Corrupt { path: PathBuf, reason: String },
    #[error(
        "{path} keeps the video LUT of {saved_output} on {saved_display}, saved by a calibration that did not finish and not put back yet (that display cannot be reached); it is not this run's ({output} on {display}). Put it back with `chromacal lut show --x-display {saved_display}`, or remove the file to give it up"
    )]
    Foreign {
        path: PathBuf,
        saved_display: String,
        saved_output: String,
        display: String,
        output: String,
    },
    #[error(transparent)]
    X11(#[from] X11Error),
}

/// Save `saved` in `state_dir`, durably, before the LUT is changed.
pub fn save(state_dir: &Path, saved: &SavedLut) -> Result<(), LutError> {
    let path = saved_path(state_dir);
    let text = serde_json::to_vec_pretty(saved).map_err(|e| LutError::Corrupt {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    chromacal_formats::durable::write_atomic(&path, &text)
        .map_err(|source| LutError::File { path, source })
}

/// The ramp a run saved and did not put back, if any.
pub fn pending(state_dir: &Path) -> Result<Option<SavedLut>, LutError> {
    let path = saved_path(state_dir);
    let bytes = match chromacal_formats::durable::read_limited(&path, 4 << 20) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(LutError::File { path, source }),
    };
    let saved: SavedLut = serde_json::from_slice(&bytes).map_err(|e| LutError::Corrupt {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    let n = saved.ramp.len();
    if n < 2 || saved.ramp.green.len() != n || saved.ramp.blue.len() != n {
        return Err(LutError::Corrupt {
            path,
            reason: format!(
                "its ramps have {}, {} and {} entries",
                n,
                saved.ramp.green.len(),
                saved.ramp.blue.len()
            ),
        });
    }
    Ok(Some(saved))
}

/// Forget the saved ramp (it has been put back, or replaced by new curves).
pub fn forget(state_dir: &Path) -> Result<(), LutError> {
    let path = saved_path(state_dir);
    match std::fs::remove_file(&path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(LutError::File { path, source }),
    }
}

/// Put back the ramp an interrupted run saved, if there is one; call with the state
/// directory's lock held. Returns what was restored ("screen on :1"). A display that
/// cannot be reached keeps the file for the next start.
pub fn restore_pending(state_dir: &Path) -> Result<Option<String>, LutError> {
    let Some(saved) = pending(state_dir)? else {
        return Ok(None);
    };
    let x = XDisplay::open(Some(&saved.x_display))?;
    let output = x.output(&OutputSelector::Name(saved.output.clone()))?;
    x.set_gamma(&output, &saved.ramp)?;
    forget(state_dir)?;
    Ok(Some(format!("{} on {}", saved.output, saved.x_display)))
}

/// Restore a pending ramp, logging rather than failing: for commands whose own work
/// does not depend on it.
pub fn restore_pending_logged(state_dir: &Path) {
    match restore_pending(state_dir) {
        Ok(Some(what)) => tracing::warn!(
            "put back the video LUT of {what}, saved by a calibration that did not finish"
        ),
        Ok(None) => {}
        Err(e) => {
            tracing::warn!(error = %e, "a calibration's saved video LUT could not be put back yet")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_saved_ramp_round_trips_and_a_broken_one_is_named() {
        let dir = tempfile::tempdir().unwrap();
        assert!(pending(dir.path()).unwrap().is_none());
        let saved = SavedLut {
            x_display: ":5".into(),
            output: "DP-1".into(),
            ramp: GammaRamp::from_fn(1024, |c, x| x.powf(1.0 + c as f64 / 10.0)),
            pid: 42,
        };
        save(dir.path(), &saved).unwrap();
        assert_eq!(pending(dir.path()).unwrap(), Some(saved));
        forget(dir.path()).unwrap();
        assert!(pending(dir.path()).unwrap().is_none());
        std::fs::write(saved_path(dir.path()), "{\"x_display\": 3}").unwrap();
        let err = pending(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("lut-saved.json") && err.contains("not a saved LUT"),
            "{err}"
        );
    }
}
