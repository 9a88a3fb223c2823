//! `chromacal adjust`: the monitor's own controls set toward the target before
//! calibrating (`chromacal::calibrate::adjust`), with a readout until Enter.

use std::io::BufRead;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use chromacal::calibrate::adjust::{
    AdjustTarget, Advice, Readout, adjust_white, describe, measure_primaries,
};
use chromacal::calibrate::devices::open_devices;
use chromacal::config::{LoadedConfig, config_search_paths, load_config_searching};
use chromacal_display::PatchDisplay;
use chromacal_model::fit::noise::ASSUMED_RELATIVE_NOISE;
use chromacal_model::target::{WhiteTarget, daylight_xy, parse_white};

use super::args::DeviceArgs;
use super::shared::{Failure, outln};

/// Set the monitor's own controls (brightness, RGB gains) toward the target before
/// calibrating: shows white and reads it again and again, printing its luminance, xy,
/// CCT and ΔE00 to the target and which control to move which way, until Enter.
#[derive(clap::Args)]
pub struct AdjustArgs {
    /// Target white: D50, D55, D65, D75, 6500K or x,y [default: the config's
    /// [target] white, else D65].
    #[arg(long)]
    white: Option<String>,
    /// Target white luminance in cd/m² [default: the config's [target] luminance,
    /// else as bright as the monitor is].
    #[arg(long)]
    luminance: Option<f64>,
    /// One JSON object a reading, on a line of its own.
    #[arg(long)]
    json: bool,
    /// Configuration file (TOML), for the instrument, the display and the target
    /// [default: as for calibrate].
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    devices: DeviceArgs,
}

pub fn run(args: AdjustArgs) -> Result<(), Failure> {
    let loaded = load_config_searching(args.config.as_deref(), &config_search_paths())?;
    let target = target(&loaded, args.white.as_deref(), args.luminance)?;
    adjust(&loaded, &args.devices, &target, args.json).map(|_| ())
}

/// The white aimed at: given, else the config's [target], else D65.
pub fn target(
    loaded: &LoadedConfig,
    white: Option<&str>,
    luminance: Option<f64>,
) -> Result<AdjustTarget, Failure> {
    let configured = loaded.config.target.as_ref();
    let text = white
        .map(str::to_string)
        .or_else(|| configured.map(|t| t.white.clone()))
        .unwrap_or_else(|| "D65".into());
    let white_xy = match parse_white(&text).map_err(|e| Failure::from(e.to_string()))? {
        WhiteTarget::Chromaticity(xy) => xy,
        WhiteTarget::Daylight(k) => daylight_xy(k).map_err(|e| Failure::from(e.to_string()))?,
        WhiteTarget::Native => {
            return Err(Failure::from(
                "adjusting toward the native white moves nothing: give --white (D65, 6500K or x,y)",
            ));
        }
    };
    if let Some(l) = luminance
        && !(l > 0.0 && l.is_finite())
    {
        return Err(Failure::from(format!(
            "--luminance must be a positive luminance, not {l}"
        )));
    }
    Ok(AdjustTarget {
        white_xy,
        luminance: luminance.or(configured.and_then(|t| t.luminance)),
    })
}

/// Read the primaries, then the white until Enter on standard input; the last advice.
pub fn adjust(
    loaded: &LoadedConfig,
    device_args: &DeviceArgs,
    target: &AdjustTarget,
    json: bool,
) -> Result<Advice, Failure> {
    let mut config = loaded.config.clone();
    device_args.overrides()?.apply(&mut config);
    let bits = config.plan.bit_depth;
    // Enter (or the end of standard input) ends the step.
    let done = Arc::new(AtomicBool::new(false));
    let flag = done.clone();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = std::io::stdin().lock().read_line(&mut line);
        flag.store(true, Ordering::SeqCst);
    });
    if !json {
        eprintln!(
            "chromacal: reading the primaries, then the white: move the monitor's controls as the readout says, and press Enter when it says it is on target"
        );
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let outcome: Result<Advice, Failure> = runtime.block_on(async {
        let mut devices = open_devices(&config, &loaded.base_dir, None).await?;
        let primaries =
            measure_primaries(&mut devices.display, &mut devices.instrument, bits).await?;
        let mut printed: Result<(), Failure> = Ok(());
        let mut report = |advice: &Advice| {
            let line = if json {
                serde_json::to_string(advice).unwrap_or_default()
            } else {
                describe(advice)
            };
            if printed.is_ok() {
                printed = outln!("{line}");
            }
        };
        let stop = || done.load(Ordering::SeqCst);
        let readout = Readout {
            primaries,
            target: *target,
            bits,
            noise: ASSUMED_RELATIVE_NOISE,
        };
        let advice = adjust_white(
            &mut devices.display,
            &mut devices.instrument,
            &readout,
            &stop,
            &mut report,
        )
        .await;
        let _ = devices.display.blank().await;
        devices.instrument.close();
        printed?;
        Ok(advice?)
    });
    outcome
}
