//! `chromacal export`: the profile for other tools (ICC, .ti3, .cal, PsychoPy, JSON,
//! TOML), optionally registered with colord.

use std::path::PathBuf;

use chromacal::export::{ExportOptions, Format};
use chromacal::measurement_file::read_measurements;
use chromacal::profile::Profile;

use super::args::TargetArgs;
use super::shared::{COLORD_UNAVAILABLE, Failure, is_stdout, outln, write_stdout};

/// Write a profile for other tools: ICC v4 or v2 display profiles (with vcgt when a
/// target is given), ArgyllCMS .ti3 (the run's measurements) and .cal (calibration
/// curves to a target), a PsychoPy monitor file, or the profile as JSON or TOML.
/// Curves go into icc4, icc2 (vcgt) and cal; cal needs a target or curves the profile
/// measured into place.
#[derive(clap::Args)]
pub struct ExportArgs {
    /// The profile (a chromacal .toml).
    profile: PathBuf,
    /// icc4, icc2 (display profiles), ti3 (the measurements), cal (calibration
    /// curves), psychopy (a monitor file), json or toml (the whole profile).
    #[arg(long, ignore_case = true, value_parser = ["icc4", "icc2", "ti3", "cal", "psychopy", "json", "toml"])]
    format: String,
    /// Where to write it; `-` writes it to standard output (and what is said, to
    /// standard error).
    #[arg(short, long)]
    output: PathBuf,
    /// The measurements for .ti3 and PsychoPy spectra [default: the run journal the
    /// profile names].
    #[arg(long)]
    measurements: Option<PathBuf>,
    #[command(flatten)]
    target: TargetArgs,
    /// Also make the ICC file the default profile of this display in colord
    /// (e.g. xrandr-Dell-U2713HM-SN123, the id GNOME or KDE gave it), over the system
    /// D-Bus ($DBUS_SYSTEM_BUS_ADDRESS). Exit 4 when colord cannot be reached.
    #[arg(long, value_name = "DEVICE_ID")]
    register_colord: Option<String>,
    /// The display as it was measured, without the profile's calibration curves: an
    /// ICC of the uncalibrated screen (no vcgt), a .ti3 of the readings as taken.
    /// Without it a profile with curves is written through them (a .ti3 as dispread
    /// writes it: the readings at the curves' inputs, and the CAL table).
    #[arg(long)]
    native: bool,
}

pub fn run(args: ExportArgs) -> Result<(), Failure> {
    export(&args)
}

fn export(args: &ExportArgs) -> Result<(), Failure> {
    let (profile_path, format, output) = (&args.profile, args.format.as_str(), &args.output);
    let (measurements, target) = (args.measurements.as_deref(), &args.target);
    let (register_colord, native) = (args.register_colord.as_deref(), args.native);
    let profile = Profile::read(profile_path).map_err(Failure::from)?;
    let format = Format::parse(format).map_err(|e| Failure::from(e.to_string()))?;
    if register_colord.is_some() && is_stdout(output) {
        return Err(Failure::from(
            "--register-colord needs the profile in a file (-o FILE), not on standard output"
                .to_string(),
        ));
    }
    if register_colord.is_some() && !matches!(format, Format::Icc4 | Format::Icc2) {
        return Err(Failure::from(
            "--register-colord needs an ICC format (icc4 or icc2)".to_string(),
        ));
    }
    let target = target.target()?;
    let measurements = match measurements {
        Some(path) => Some(read_measurements(path).map_err(|e| Failure::from(e.to_string()))?),
        None => None,
    };
    let options = ExportOptions {
        target,
        measurements,
        native,
    };
    let exported = chromacal::export::export(&profile, format, &options)
        .map_err(|e| Failure::from(e.to_string()))?;
    // What was written goes to standard output, unless the file itself does.
    let to_stdout = is_stdout(output);
    let say = |line: String| {
        if to_stdout {
            eprintln!("{line}");
            Ok(())
        } else {
            outln!("{line}")
        }
    };
    if to_stdout {
        write_stdout(&exported.bytes)?;
    } else {
        std::fs::write(output, &exported.bytes)
            .map_err(|e| Failure::from(format!("{}: {e}", output.display())))?;
        say(format!(
            "wrote {} ({}, {} bytes)",
            output.display(),
            format.name(),
            exported.bytes.len()
        ))?;
    }
    let curves = exported.calibration.as_ref();
    match (&options.target, &profile.calibration, curves) {
        (Some(_), _, Some(k)) if !format.carries_curves() => eprintln!(
            "not carried: calibration curves to {} (a {} file has no place for them: icc4, icc2, cal and ti3 do)",
            k.describe(),
            format.name()
        ),
        (None, _, _) if !format.carries_curves() => {}
        (None, Some(stored), Some(_)) => say(format!(
            "calibration curves to {} (the profile's, measured into place): measured white ΔE00 {:.3}, tone within {:.2} % at {} levels",
            stored.curves.describe(),
            stored.measured_white_de00,
            100.0 * stored.measured_tone_error,
            stored.levels.len()
        ))?,
        (_, _, Some(k)) => say(format!(
            "calibration curves to {} (from the model): predicted white ΔE00 {:.3}, greys within {:.3} ΔE00 and tone within {:.2} % at 8 levels",
            k.describe(),
            k.predicted_white_de00,
            k.predicted_grey_de00,
            100.0 * k.predicted_tone_error
        ))?,
        _ => {}
    }
    for note in &exported.not_carried {
        eprintln!("not carried: {note}");
    }
    for warning in &exported.warnings {
        eprintln!("warning: {warning}");
    }
    for said in &exported.carried {
        eprintln!("chromacal: {said}");
    }
    if let Some(device) = register_colord {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let registered = runtime
            .block_on(chromacal::export::colord::register(output, device))
            .map_err(|e| Failure {
                message: format!("colord: {e}"),
                code: COLORD_UNAVAILABLE,
            })?;
        say(format!(
            "colord: {} is the default profile of {} ({}{})",
            registered.profile_id,
            device,
            registered.device_object,
            if registered.device_existed {
                ""
            } else {
                ", a device chromacal created"
            }
        ))?;
    }
    Ok(())
}
