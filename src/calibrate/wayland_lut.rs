//! The calibration curves on Wayland, where each compositor applies them:
//!
//! - **wlroots** (sway, Hyprland, river): `wlr-gamma-control`. The compositor drops a
//!   client's ramp when it disconnects, so `lut load --hold` stays and holds it,
//!   noting itself in the state directory (`lut show` names it, `lut reset` stops
//!   it). An output without a ramp (gamma size 0: headless and nested outputs) is
//!   said plainly, with what to do instead.
//! - **KDE Plasma 6** (KWin): the profile, exported as ICC with its `vcgt`, set as the
//!   output's colour profile through `kscreen-doctor output.NAME.iccprofile.PATH`
//!   (KWin applies it, curves included); `lut reset` sets the output back to sRGB.
//! - **GNOME** (Mutter): through colord, which Mutter follows: the profile, exported
//!   as ICC with its `vcgt`, registered as the output's monitor's default profile.
//!
//! Which one is found from the compositor's globals (wlroots' gamma control, KWin's
//! `kde_output_device_v2`), or given (`--via`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::export::{ExportOptions, Format, export};
use crate::profile::Profile;
use chromacal_display::wayland::gamma::{GammaError, HeldGamma, hold_gamma};
use chromacal_display::wayland::{self, WaylandError, WaylandOutput};
use chromacal_display::x11::{GammaRamp, OutputSelector};
use chromacal_model::target::{CalibrationCurves, Target};

/// Where a compositor applies calibration curves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CurvesPath {
    Wlroots,
    Kde,
    Colord,
}

impl CurvesPath {
    pub fn parse(text: &str) -> Result<Option<CurvesPath>, String> {
        match text {
            "auto" => Ok(None),
            "wlroots" => Ok(Some(CurvesPath::Wlroots)),
            "kde" => Ok(Some(CurvesPath::Kde)),
            "colord" | "gnome" => Ok(Some(CurvesPath::Colord)),
            other => Err(format!(
                "unknown --via '{other}': auto, wlroots, kde or colord (gnome)"
            )),
        }
    }

    /// The path a compositor with these globals takes.
    pub fn of_interfaces(interfaces: &[(String, u32)]) -> CurvesPath {
        let has = |name: &str| interfaces.iter().any(|(i, _)| i == name);
        if has("zwlr_gamma_control_manager_v1") {
            CurvesPath::Wlroots
        } else if has("kde_output_device_v2") || has("kde_output_management_v2") {
            CurvesPath::Kde
        } else {
            CurvesPath::Colord
        }
    }
}

/// What went wrong putting curves where a compositor applies them.
#[derive(Debug, thiserror::Error)]
pub enum WaylandLutError {
    #[error(transparent)]
    Wayland(#[from] WaylandError),
    #[error(transparent)]
    Gamma(#[from] GammaError),
    #[error(
        "the compositor drops a client's gamma ramp when it disconnects: give --hold (lut load stays and holds it until stopped)"
    )]
    NotHeld,
    #[error("{0}")]
    Export(String),
    #[error("{what}: {reason}")]
    Command { what: String, reason: String },
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}

/// Who holds an output's gamma ramp for chromacal (`lut load --hold`), as noted in the
/// state directory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GammaHolder {
    pub pid: u32,
    pub display: String,
    pub output: String,
    pub profile: String,
}

/// The note of the holder of `output`'s ramp in `state_dir`.
pub fn holder_path(state_dir: &Path, output: &str) -> PathBuf {
    state_dir.join(format!("wayland-gamma-{output}.json"))
}

/// The holder noted for `output`, if its process still runs and is a chromacal that
/// holds a ramp (a process id can be reused after a crash or a reboot).
pub fn holder(state_dir: &Path, output: &str) -> Option<GammaHolder> {
    let text = std::fs::read_to_string(holder_path(state_dir, output)).ok()?;
    let holder: GammaHolder = serde_json::from_str(&text).ok()?;
    let cmdline = std::fs::read(format!("/proc/{}/cmdline", holder.pid)).ok()?;
    let args: Vec<String> = cmdline
        .split(|b| *b == 0)
        .map(|a| String::from_utf8_lossy(a).into_owned())
        .collect();
    let chromacal = args
        .first()
        .and_then(|a| Path::new(a).file_name())
        .is_some_and(|n| n.to_string_lossy().starts_with("chromacal"));
    let holding =
        args.iter().any(|a| a == "lut") && args.iter().any(|a| a == "--hold" || a == "--watch");
    (chromacal && holding).then_some(holder)
}

/// Removes the holder's note when the holder stops holding (an error, the compositor
/// gone); a holder killed leaves it, and [`holder`] then sees no such process.
struct HolderNote(PathBuf);

impl Drop for HolderNote {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The output `selector` names on Wayland display `name`.
pub fn find_output(
    name: Option<&str>,
    selector: &OutputSelector,
) -> Result<WaylandOutput, WaylandError> {
    let outputs = wayland::list_outputs(name, &chromacal_display::drm::sysfs_root())?;
    wayland::pick(selector, &outputs)
        .cloned()
        .ok_or_else(|| WaylandError::NoOutput {
            display: name.unwrap_or("$WAYLAND_DISPLAY").to_string(),
            wanted: selector.describe(),
            outputs: outputs.iter().map(|o| o.name.clone()).collect(),
        })
}

/// wlroots: take the output's gamma control, set `curves` on it and note the holder;
/// the ramp stays while the returned control lives.
pub fn hold_curves(
    name: Option<&str>,
    selector: &OutputSelector,
    curves: &CalibrationCurves,
    profile: &str,
    state_dir: &Path,
) -> Result<HeldGamma, WaylandLutError> {
    let held = hold_gamma(name, selector, |size| GammaRamp::from_curves(curves, size))?;
    let note = GammaHolder {
        pid: std::process::id(),
        display: wayland::socket_path(name)?.display().to_string(),
        output: held.output.name.clone(),
        profile: profile.to_string(),
    };
    let path = holder_path(state_dir, &note.output);
    let text = serde_json::to_string_pretty(&note).unwrap_or_default();
    std::fs::create_dir_all(state_dir)
        .and_then(|_| std::fs::write(&path, text))
        .map_err(|source| WaylandLutError::Io {
            path: path.display().to_string(),
            source,
        })?;
    Ok(held)
}

/// How long `lut load --hold` waits before taking an output's gamma control again
/// after losing it (the output was unplugged, or its mode set anew).
const RETAKE_S: f64 = 2.0;

/// wlroots: hold `curves` on the output `selector` names until the compositor goes
/// away, taking the control again (and loading the curves again) whenever it is lost:
/// the output was unplugged and plugged back, or its mode was set anew. `said` hears
/// each load and each loss.
pub fn hold_until_gone(
    name: Option<&str>,
    selector: &OutputSelector,
    curves: &CalibrationCurves,
    profile: &str,
    state_dir: &Path,
    said: &mut dyn FnMut(&str),
) -> Result<(), WaylandLutError> {
    let mut first = true;
    let mut note = None;
    loop {
        match hold_curves(name, selector, curves, profile, state_dir) {
            Ok(mut held) => {
                note = Some(HolderNote(holder_path(state_dir, &held.output.name)));
                said(&format!(
                    "holding the curves ({}) in the gamma ramp of {} ({} entries){}",
                    curves.describe(),
                    held.output.name,
                    held.size,
                    if first { "" } else { " again" }
                ));
                first = false;
                if let Err(e) = held.wait() {
                    said(&format!("{e}; taking it again"));
                }
            }
            // The first attempt's refusal is the user's to hear at once.
            Err(e) if first => return Err(e),
            Err(_) => {}
        }
        // The compositor gone: nothing to hold any more.
        if wayland::offered_interfaces(name).is_err() {
            said("the compositor is gone: stopping");
            drop(note);
            return Ok(());
        }
        std::thread::sleep(std::time::Duration::from_secs_f64(RETAKE_S));
    }
}

/// The profile as ICC v2 (what every compositor and colord read, ArgyllCMS too) with
/// its curves in `vcgt`, written where the compositor will read it:
/// `<state_dir>/wayland/<output>.icc`.
pub fn write_icc(
    profile: &Profile,
    target: Option<&Target>,
    output: &str,
    state_dir: &Path,
) -> Result<PathBuf, WaylandLutError> {
    let exported = export(
        profile,
        Format::Icc2,
        &ExportOptions {
            target: target.cloned(),
            measurements: None,
            native: false,
        },
    )
    .map_err(|e| WaylandLutError::Export(e.to_string()))?;
    if exported.calibration.is_none() {
        return Err(WaylandLutError::Export(
            "the profile carries no calibration curves: calibrate with a [target], or give --white/--tone".into(),
        ));
    }
    let dir = state_dir.join("wayland");
    let path = dir.join(format!("{output}.icc"));
    std::fs::create_dir_all(&dir)
        .and_then(|_| std::fs::write(&path, &exported.bytes))
        .map_err(|source| WaylandLutError::Io {
            path: path.display().to_string(),
            source,
        })?;
    Ok(std::fs::canonicalize(&path).unwrap_or(path))
}

/// Run `kscreen-doctor` with `settings` (KDE Plasma 6's output tool).
fn kscreen_doctor(settings: &[String]) -> Result<(), WaylandLutError> {
    let what = format!("kscreen-doctor {}", settings.join(" "));
    let out = std::process::Command::new("kscreen-doctor")
        .args(settings)
        .output()
        .map_err(|e| WaylandLutError::Command {
            what: what.clone(),
            reason: format!("{e} (kscreen-doctor comes with KDE Plasma 6's kscreen)"),
        })?;
    if out.status.success() {
        Ok(())
    } else {
        Err(WaylandLutError::Command {
            what,
            reason: format!(
                "{}: {}",
                out.status,
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        })
    }
}

/// KDE: set the ICC at `icc` (with its `vcgt`) as `output`'s colour profile.
pub fn load_kde(output: &str, icc: &Path) -> Result<(), WaylandLutError> {
    kscreen_doctor(&[
        format!("output.{output}.iccprofile.{}", icc.display()),
        format!("output.{output}.colorProfileSource.ICC"),
    ])
}

/// KDE: the output back on sRGB, without a profile.
pub fn reset_kde(output: &str) -> Result<(), WaylandLutError> {
    kscreen_doctor(&[
        format!("output.{output}.colorProfileSource.sRGB"),
        format!("output.{output}.iccprofile."),
    ])
}

/// wlroots: stop chromacal's holder of `output`'s ramp on Wayland display `display`
/// (the compositor then puts its own back); the holder's note, or `None` when nothing
/// of chromacal's holds it there.
pub fn release_held(state_dir: &Path, display: &str, output: &str) -> Option<GammaHolder> {
    let held = holder(state_dir, output).filter(|h| h.display == display)?;
    let _ = std::process::Command::new("kill")
        .args(["-TERM", &held.pid.to_string()])
        .status();
    let _ = std::fs::remove_file(holder_path(state_dir, output));
    Some(held)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_path_follows_the_compositor_s_globals() {
        let with = |names: &[&str]| {
            CurvesPath::of_interfaces(&names.iter().map(|n| (n.to_string(), 1)).collect::<Vec<_>>())
        };
        assert_eq!(
            with(&["wl_output", "zwlr_gamma_control_manager_v1"]),
            CurvesPath::Wlroots
        );
        assert_eq!(with(&["kde_output_device_v2"]), CurvesPath::Kde);
        assert_eq!(with(&["wl_output", "gtk_shell1"]), CurvesPath::Colord);
        assert_eq!(CurvesPath::parse("gnome"), Ok(Some(CurvesPath::Colord)));
        assert!(CurvesPath::parse("x11").is_err());
    }

    #[test]
    fn a_note_whose_process_is_not_a_holding_chromacal_names_no_holder() {
        let dir = tempfile::tempdir().unwrap();
        let note = |pid: u32| {
            let n = GammaHolder {
                pid,
                display: "/run/user/1000/wayland-1".into(),
                output: "DP-1".into(),
                profile: "p".into(),
            };
            std::fs::write(
                holder_path(dir.path(), "DP-1"),
                serde_json::to_string(&n).unwrap(),
            )
            .unwrap();
        };
        // This test's own process: alive, but not `chromacal lut load --hold`.
        note(std::process::id());
        assert_eq!(holder(dir.path(), "DP-1"), None);
        assert_eq!(
            release_held(dir.path(), "/run/user/1000/wayland-1", "DP-1"),
            None
        );
        // No such process.
        note(u32::MAX - 1);
        assert_eq!(holder(dir.path(), "DP-1"), None);
    }
}
