//! `chromacal displays`: the X or Wayland display's outputs, with their monitors' EDID
//! identity, mode, video LUT and the configured device on each.

use super::shared::{out, outln};
use std::path::PathBuf;

use chromacal::calibrate::displays::{
    describe_displays, describe_wayland_displays, list_displays, list_wayland_displays,
};
use chromacal::config::{config_search_paths, load_config_searching};
use chromacal::profile::store::default_state_dir;
use chromacal_display::x11::XDisplay;

use super::shared::Failure;

/// List the screens of a Wayland or X display: each output with its monitor (from its
/// EDID: maker, model, serial, week and year of manufacture, primaries), its mode, its
/// video LUT, and the configured device whose window goes there. On Wayland, also what
/// the compositor offers a calibration.
#[derive(clap::Args)]
pub struct DisplaysArgs {
    /// The X display [default: $DISPLAY, when no Wayland display is named or set].
    #[arg(long, value_name = "DISPLAY", conflicts_with = "wayland_display")]
    x_display: Option<String>,
    /// The Wayland display, e.g. wayland-0 or a socket path [default: $WAYLAND_DISPLAY,
    /// when set and --x-display is not given].
    #[arg(long, value_name = "NAME")]
    wayland_display: Option<String>,
    /// The config whose devices are matched to outputs [default: the user's or the
    /// system's, as `calibrate` finds it].
    #[arg(long)]
    config: Option<PathBuf>,
    /// State directory the devices' profiles are in.
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// JSON instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: DisplaysArgs) -> Result<(), Failure> {
    let loaded = load_config_searching(args.config.as_deref(), &config_search_paths()).ok();
    let state_dir = args.state_dir.unwrap_or_else(default_state_dir);
    // A Wayland session's own display first: $DISPLAY there is XWayland's.
    let wayland = args.wayland_display.clone().or_else(|| {
        std::env::var("WAYLAND_DISPLAY")
            .ok()
            .filter(|v| !v.is_empty() && args.x_display.is_none())
    });
    if let Some(name) = wayland {
        let listing = list_wayland_displays(Some(&name), loaded.as_ref(), &state_dir)?;
        if args.json {
            outln!("{}", serde_json::to_string_pretty(&listing)?)?;
        } else {
            out!("{}", describe_wayland_displays(&listing))?;
        }
        return Ok(());
    }
    let x = XDisplay::open(args.x_display.as_deref())?;
    let entries = list_displays(&x, loaded.as_ref(), &state_dir)?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&entries)?)?;
    } else {
        out!("{}", describe_displays(x.name(), &entries))?;
    }
    Ok(())
}
