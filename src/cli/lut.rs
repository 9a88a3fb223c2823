//! `chromacal lut`: the video LUT of an X11 output (its CRTC gamma ramp): load a
//! profile's calibration curves into it, show it, reset it, save it as a `.cal`. On
//! Wayland, where the compositor applies them (`lut_wayland`).

use super::shared::{out, outln};
use std::borrow::Cow;
use std::path::PathBuf;

use clap::Subcommand;

use chromacal::calibrate::keep_lut::{KeepError, KeepEvent, keep_loaded, made_on_another_monitor};
use chromacal::calibrate::video_lut::{desktop_lut_loader, lut_status};
use chromacal::export::calibration_for;
use chromacal::profile::Profile;
use chromacal::profile::store::{ProfileStore, default_state_dir};
use chromacal_display::lut::restore_pending_logged;
use chromacal_display::x11::{GammaRamp, OutputSelector, XDisplay};
use chromacal_formats::cal::curves_cal_text;

use super::args::TargetArgs;
use super::shared::Failure;

/// The video LUT (CRTC gamma ramp) of an X11 output.
#[derive(clap::Args)]
pub struct LutArgs {
    #[command(subcommand)]
    command: LutCommand,
    /// The X display [default: $DISPLAY, when no Wayland display is named or set].
    #[arg(long, global = true, value_name = "DISPLAY")]
    x_display: Option<String>,
    /// The Wayland display, e.g. wayland-0 or a socket path [default:
    /// $WAYLAND_DISPLAY, when set and --x-display is not given].
    #[arg(long, global = true, value_name = "NAME", conflicts_with = "x_display")]
    wayland_display: Option<String>,
    /// On Wayland, where the curves go: wlroots (gamma control, held), kde
    /// (kscreen-doctor sets the profile with its vcgt), colord (GNOME) or auto (from
    /// what the compositor offers).
    #[arg(long, global = true, value_name = "PATH", default_value = "auto")]
    via: String,
    /// The output, by RandR or wl_output name (see `chromacal displays`) [default: the
    /// primary, or the first Wayland output].
    #[arg(long, global = true)]
    output: Option<String>,
    /// State directory (for --current, and to put back a ramp an interrupted
    /// calibration saved).
    #[arg(long, global = true)]
    state_dir: Option<PathBuf>,
}

#[derive(Subcommand)]
enum LutCommand {
    /// Load a profile's calibration curves (interpolated to the ramp's size).
    Load {
        /// A chromacal profile (TOML) with calibration curves.
        #[arg(required_unless_present = "current")]
        profile: Option<PathBuf>,
        /// The state directory's current profile instead.
        #[arg(long, conflicts_with = "profile")]
        current: bool,
        /// Stay, and load the current profile's curves again whenever the X screen
        /// changes (a monitor plugged in, a mode set) or a new profile becomes
        /// current; until the X display goes away. What the user service and the
        /// autostart entry run at login. One keeper a state directory.
        #[arg(long, requires = "current")]
        watch: bool,
        /// On a wlroots compositor, stay and hold the output's gamma ramp until
        /// stopped (the compositor drops a client's ramp when it disconnects).
        #[arg(long, conflicts_with = "watch")]
        hold: bool,
        /// Curves computed now from the profile's model for a target, instead of
        /// the curves it carries.
        #[command(flatten)]
        target: TargetArgs,
    },
    /// Show the ramp: size, straight or not, samples, and whether a desktop program
    /// loads curves itself.
    Show {
        /// JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Load the straight ramp (output = input).
    Reset,
    /// Write the ramp as an ArgyllCMS `.cal` file (256 rows).
    Save {
        /// The file to write.
        file: PathBuf,
    },
}

pub fn run(args: LutArgs) -> Result<(), Failure> {
    let state_dir = args.state_dir.clone().unwrap_or_else(default_state_dir);
    let wayland = args.wayland_display.clone().or_else(|| {
        std::env::var("WAYLAND_DISPLAY")
            .ok()
            .filter(|v| !v.is_empty() && args.x_display.is_none())
    });
    if let Some(name) = wayland {
        use super::lut_wayland::Action;
        let action = match args.command {
            // --watch (the login service's) holds on wlroots, as --hold does: there
            // the curves stay only while a client holds them.
            LutCommand::Load {
                profile,
                hold,
                watch,
                target,
                ..
            } => Action::Load {
                profile,
                hold: hold || watch,
                target: target.target()?,
            },
            LutCommand::Show { json } => Action::Show { json },
            LutCommand::Reset => Action::Reset,
            LutCommand::Save { .. } => Action::Save,
        };
        let via = chromacal::calibrate::wayland_lut::CurvesPath::parse(&args.via)?;
        return super::lut_wayland::run(action, &name, args.output.as_deref(), via, &state_dir);
    }
    if let LutCommand::Load { watch: true, .. } = args.command {
        return watch(&args, &state_dir);
    }
    // A calibration killed while it held the LUT left the user's ramp behind; put it
    // back first, unless a calibration holds the directory now.
    let store = ProfileStore::new(&state_dir);
    let lock = store.lock("chromacal lut");
    if lock.is_ok() {
        restore_pending_logged(&state_dir);
    }
    // A calibration or a daemon holds the directory: it owns the LUT meanwhile.
    if let (Err(e), LutCommand::Load { .. } | LutCommand::Reset) = (&lock, &args.command) {
        return Err(Failure::from(format!(
            "{e}: it sets the video LUT itself; stop it first (or give another --state-dir)"
        )));
    }
    let x = XDisplay::open(args.x_display.as_deref())?;
    let selector = args
        .output
        .as_deref()
        .map(OutputSelector::parse)
        .unwrap_or_default();
    let output = x.output(&selector)?;
    // A daemon of another state directory may keep this output's curves: it would
    // put them back, and report them loaded meanwhile.
    let _owned = match args.command {
        LutCommand::Load { .. } | LutCommand::Reset => Some(
            chromacal::calibrate::keep_lut::own_output(
                args.x_display.as_deref(),
                &output.name,
                "chromacal lut",
            )
            .map_err(|owned| {
                Failure::from(format!(
                    "the video LUT of {} is kept by {}: it would set it back; stop it first",
                    output.name, owned.0
                ))
            })?,
        ),
        _ => None,
    };
    match args.command {
        LutCommand::Load {
            profile,
            target,
            current,
            ..
        } => {
            // Without a path, --current (clap requires one of the two).
            let path = profile.unwrap_or_else(|| store.current_path());
            let profile = Profile::read(&path)?;
            if let Some(why) = made_on_another_monitor(&profile, &output).filter(|_| current) {
                return Err(Failure::from(why));
            }
            let target = target.target()?;
            let (model, said_of_greys) = profile.output_model();
            let curves = calibration_for(&profile, &model, target.as_ref())?.ok_or_else(|| {
                format!(
                    "{} carries no calibration curves: calibrate with a [target], or give --white/--tone to compute them from its model",
                    path.display()
                )
            })?;
            // Curves solved now go through the greys where the model does.
            if let (Some(_), Cow::Owned(_), Some(said)) = (&target, &model, &said_of_greys) {
                eprintln!("chromacal: {said}");
            }
            x.set_gamma(&output, &GammaRamp::from_curves(&curves, output.gamma_size))?;
            if let Some(loader) = desktop_lut_loader() {
                eprintln!(
                    "chromacal: note: {loader} also loads curves into the video LUT and may replace these"
                );
            }
            outln!(
                "loaded the curves of {} ({}) into the video LUT of {} ({} entries)",
                path.display(),
                curves.describe(),
                output.name,
                output.gamma_size
            )?;
        }
        LutCommand::Show { json } => {
            let current = Profile::read(&store.current_path())
                .ok()
                .and_then(|p| p.calibration.map(|c| c.curves));
            let status = lut_status(&x, &output, current.as_ref())?;
            if json {
                outln!("{}", serde_json::to_string_pretty(&status)?)?;
            } else {
                out!("{}", chromacal::report::describe_lut(&status))?;
            }
        }
        LutCommand::Reset => {
            x.set_gamma(&output, &GammaRamp::identity(output.gamma_size))?;
            outln!("the video LUT of {} is straight", output.name)?;
        }
        LutCommand::Save { file } => {
            let ramp = x.gamma(&output)?;
            let created = chromacal_formats::time::now_rfc3339();
            let text = curves_cal_text(
                |v| [ramp.output(0, v), ramp.output(1, v), ramp.output(2, v)],
                &format!("video LUT of {} on {}", output.name, x.name()),
                &created,
            );
            std::fs::write(&file, text).map_err(|e| format!("{}: {e}", file.display()))?;
            outln!(
                "wrote the video LUT of {} ({} entries) to {}",
                output.name,
                ramp.len(),
                file.display()
            )?;
        }
    }
    Ok(())
}

/// `lut load --current --watch`: the keeper, printing what it does.
fn watch(args: &LutArgs, state_dir: &std::path::Path) -> Result<(), Failure> {
    let selector = args
        .output
        .as_deref()
        .map(OutputSelector::parse)
        .unwrap_or_default();
    if let Some(loader) = desktop_lut_loader() {
        eprintln!(
            "chromacal: note: {loader} also loads curves into the video LUT and may replace these"
        );
    }
    let store = ProfileStore::new(state_dir);
    let mut said = Ok(());
    let kept = keep_loaded(
        args.x_display.as_deref(),
        &selector,
        &store,
        &|| false,
        &mut |event| {
            let line = match event {
                KeepEvent::Loaded {
                    output,
                    profile,
                    curves,
                    reason,
                } => format!(
                    "loaded the curves of profile {profile} ({curves}) into the video LUT of {output} ({reason})"
                ),
                KeepEvent::Skipped { reason } => format!("not loaded: {reason}"),
                KeepEvent::DisplayGone { message } => {
                    format!("the X display is gone ({message}): stopping")
                }
            };
            if said.is_ok() {
                said = outln!("{line}");
            }
        },
    );
    match kept {
        // Both the user service and the autostart entry installed: one keeps it.
        Err(e @ KeepError::AlreadyKept { .. }) => eprintln!("chromacal: {e}: nothing to do"),
        other => other?,
    }
    said?;
    Ok(())
}
