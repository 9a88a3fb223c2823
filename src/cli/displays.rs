//! `chromacal displays`: the X display's outputs, with their monitors' EDID identity,
//! mode, video LUT and the configured device on each.

use super::shared::{out, outln};
use std::path::PathBuf;

use chromacal::calibrate::displays::{describe_displays, list_displays};
use chromacal::config::{config_search_paths, load_config_searching};
use chromacal::profile::store::default_state_dir;
use chromacal_display::x11::XDisplay;

use super::shared::Failure;

/// List the screens of an X display: each output with its monitor (from its EDID:
/// maker, model, serial, week and year of manufacture, primaries), its mode, its video
/// LUT, and the configured device whose window goes there.
#[derive(clap::Args)]
pub struct DisplaysArgs {
    /// The X display [default: $DISPLAY].
    #[arg(long, value_name = "DISPLAY")]
    x_display: Option<String>,
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
    let x = XDisplay::open(args.x_display.as_deref())?;
    let loaded = load_config_searching(args.config.as_deref(), &config_search_paths()).ok();
    let state_dir = args.state_dir.unwrap_or_else(default_state_dir);
    let entries = list_displays(&x, loaded.as_ref(), &state_dir)?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&entries)?)?;
    } else {
        out!("{}", describe_displays(x.name(), &entries))?;
    }
    Ok(())
}
