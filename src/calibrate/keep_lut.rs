//! The calibration kept in the video LUT without the daemon: what `chromacal lut load
//! --current --watch` does from a user service or an XDG autostart entry at login. The
//! current profile's curves are loaded, and loaded again when the X screen changes
//! (RandR: a monitor plugged in, a mode changed, both of which may hand the output a
//! new CRTC with a straight ramp) and when a new profile becomes current.
//!
//! One keeper a state directory (a lock file beside the store's own), so the systemd
//! user unit and the autostart entry, both installed, never run two. The store's lock
//! is taken only for the moment of a load: a calibration holds it for its whole run,
//! sets the LUT itself meanwhile, and its end publishes a profile, which the keeper
//! then loads.

use std::fs::File;
use std::path::PathBuf;
use std::time::{Duration, SystemTime};

use crate::profile::Profile;
use crate::profile::store::ProfileStore;
use chromacal_display::x11::watch::Watch;
use chromacal_display::x11::{GammaRamp, OutputInfo, OutputSelector, X11Error};
use chromacal_formats::durable::Lock;
use chromacal_formats::edid::Edid;

/// How often the keeper looks for RandR events and a new current profile.
const TICK: Duration = Duration::from_millis(200);

/// Why the keeper could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum KeepError {
    #[error(transparent)]
    X11(#[from] X11Error),
    #[error("another chromacal keeps the video LUT for {dir} ({holder})")]
    AlreadyKept { dir: PathBuf, holder: String },
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
}

/// What the keeper did, for the caller to print.
#[derive(Debug, Clone, PartialEq)]
pub enum KeepEvent {
    /// The curves of `profile` went into `output`'s LUT.
    Loaded {
        output: String,
        profile: String,
        curves: String,
        reason: &'static str,
    },
    /// Nothing was loaded, and why (no current profile, no curves, another monitor,
    /// a calibration holds the directory).
    Skipped { reason: String },
    /// The X display went away (the session ended): the keeper stops.
    DisplayGone { message: String },
}

/// Why `profile` is not for the monitor on `output`: made on another one (by their
/// EDIDs' maker, product and serial), as after docking a laptop.
pub fn made_on_another_monitor(profile: &Profile, output: &OutputInfo) -> Option<String> {
    let made_on = profile.provenance.edid.as_ref()?;
    let here = output.edid.as_deref().and_then(|b| Edid::parse(b).ok())?;
    let same = made_on.manufacturer == here.manufacturer
        && made_on.product_code == here.product_code
        && made_on.serial() == here.serial();
    (!same).then(|| {
        format!(
            "the current profile was made on {} but {} now shows {}: its curves are not loaded",
            made_on.describe(),
            output.name,
            here.describe()
        )
    })
}

/// Where the owner of an output's video LUT is written down: one lock a user, an X
/// display and an output (`$XDG_RUNTIME_DIR/chromacal`, else the temporary directory),
/// whatever state directory the owner runs on. A daemon keeping an output's curves
/// holds it; `lut load` and `lut reset` look at it first.
pub fn output_lock_path(x_display: Option<&str>, output: &str) -> PathBuf {
    let display = x_display
        .map(str::to_string)
        .or_else(|| std::env::var("DISPLAY").ok())
        .unwrap_or_default();
    let safe = |s: &str| -> String {
        s.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    };
    let dir = std::env::var_os("XDG_RUNTIME_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join(format!("chromacal-{}", user_id())))
        .join("chromacal");
    dir.join(format!("lut-{}-{}.lock", safe(&display), safe(output)))
}

/// This user's id, for a per-user folder in the temporary directory.
fn user_id() -> u32 {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").map_or(0, |m| m.uid())
}

/// Who owns an output's video LUT: the holder's words, when another process holds it.
#[derive(Debug)]
pub struct OutputOwned(pub String);

/// Take the ownership of `output`'s video LUT for `holder` (held while the file
/// lives), or say who has it.
pub fn own_output(
    x_display: Option<&str>,
    output: &str,
    holder: &str,
) -> Result<File, OutputOwned> {
    let path = output_lock_path(x_display, output);
    let fail = |e: std::io::Error| OutputOwned(format!("{}: {e}", path.display()));
    if let Some(dir) = path.parent() {
        chromacal_formats::durable::keep_private(dir).map_err(fail)?;
    }
    match chromacal_formats::durable::lock_file(&path, holder).map_err(fail)? {
        Lock::Taken(file) => Ok(file),
        Lock::HeldBy(words) => Err(OutputOwned(words)),
    }
}

/// The keeper's own lock, held while it runs.
fn keeper_lock(store: &ProfileStore) -> Result<File, KeepError> {
    let dir = store.root().to_path_buf();
    let io = |path: &PathBuf, e: std::io::Error| KeepError::Io {
        path: path.clone(),
        message: e.to_string(),
    };
    chromacal_formats::durable::create_dir(&dir).map_err(|e| io(&dir, e))?;
    let path = dir.join("lut-keeper.lock");
    match chromacal_formats::durable::lock_file(&path, "chromacal lut load --watch")
        .map_err(|e| io(&path, e))?
    {
        Lock::Taken(file) => Ok(file),
        Lock::HeldBy(holder) => Err(KeepError::AlreadyKept { dir, holder }),
    }
}

/// When the current profile file last changed (none: there is none).
fn current_stamp(store: &ProfileStore) -> Option<SystemTime> {
    std::fs::metadata(store.current_path())
        .and_then(|m| m.modified())
        .ok()
}

/// Load the current profile's curves into `w`'s output, or say why not.
fn load_current(
    w: &Watch,
    store: &ProfileStore,
    reason: &'static str,
) -> Result<KeepEvent, X11Error> {
    let skipped = |reason: String| Ok(KeepEvent::Skipped { reason });
    // A calibration holds the directory: it owns the LUT until it publishes.
    let _lock = match store.lock("chromacal lut load --watch") {
        Ok(lock) => lock,
        Err(e) => return skipped(e.to_string()),
    };
    let path = store.current_path();
    let profile = match Profile::read(&path) {
        Ok(p) => p,
        Err(e) => return skipped(format!("no current profile to load ({e})")),
    };
    let Some(stored) = &profile.calibration else {
        return skipped(format!(
            "{} carries no calibration curves (calibrate with a [target])",
            path.display()
        ));
    };
    if let Some(why) = made_on_another_monitor(&profile, &w.output) {
        return skipped(why);
    }
    if w.output.gamma_size < 2 {
        return skipped(format!(
            "{} has no video LUT chromacal can set",
            w.output.name
        ));
    }
    w.x.set_gamma(
        &w.output,
        &GammaRamp::from_curves(&stored.curves, w.output.gamma_size),
    )?;
    Ok(KeepEvent::Loaded {
        output: w.output.name.clone(),
        profile: profile.id,
        curves: stored.curves.describe(),
        reason,
    })
}

/// Keep the current profile of `store` in the LUT of the output `selector` picks on
/// `x_display`, telling `report` what happened, until the display goes away (then
/// `Ok`) or `stop` says so.
pub fn keep_loaded(
    x_display: Option<&str>,
    selector: &OutputSelector,
    store: &ProfileStore,
    stop: &dyn Fn() -> bool,
    report: &mut dyn FnMut(&KeepEvent),
) -> Result<(), KeepError> {
    let _keeper = keeper_lock(store)?;
    let mut w = Watch::open(x_display, selector)?;
    let mut due = Some("start");
    let mut stamp = current_stamp(store);
    while !stop() {
        let changed = match w.randr_changed() {
            Ok(changed) => changed,
            Err(e) => {
                report(&KeepEvent::DisplayGone {
                    message: e.to_string(),
                });
                return Ok(());
            }
        };
        if changed {
            // The output may have a new CRTC, or be another monitor now.
            w.output = w.x.output(selector)?;
            due = Some("the X screen changed (RandR)");
        }
        let now = current_stamp(store);
        if now != stamp {
            stamp = now;
            due = Some("a new profile is current");
        }
        if let Some(reason) = due.take() {
            match load_current(&w, store, reason) {
                Ok(event) => report(&event),
                Err(e) => {
                    report(&KeepEvent::DisplayGone {
                        message: e.to_string(),
                    });
                    return Ok(());
                }
            }
        }
        std::thread::sleep(TICK);
    }
    Ok(())
}
