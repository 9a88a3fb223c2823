//! `chromacal measure`: read what the screen shows now with a serial instrument.

use super::shared::outln;
use chromacal_color::spaces::xyz_to_xyy;
use chromacal_instruments::driver::DriverOptions;

use super::args::parse_instrument;
use super::shared::Failure;

/// Measure what the display shows now with a serial instrument.
#[derive(clap::Args)]
pub struct MeasureArgs {
    /// KIND:PORT, e.g. pr670:/dev/ttyACM0, or argyll[:N].
    #[arg(long)]
    instrument: String,
    /// How many readings to take.
    #[arg(long, default_value_t = 1)]
    count: usize,
    /// Multiplies the protocol's timeouts (for emulators run faster than real time).
    #[arg(long, default_value_t = 1.0, value_parser = super::shared::positive_number)]
    timing_scale: f64,
    /// Print each reading (XYZ, spectrum, the instrument's code and reply) as JSON.
    #[arg(long)]
    json: bool,
    /// Take [instrument.options] from this config (e.g. an ArgyllCMS display type or
    /// argyll_correction).
    #[arg(long)]
    config: Option<std::path::PathBuf>,
}

pub fn run(args: MeasureArgs) -> Result<(), Failure> {
    let (options, base_dir) = match &args.config {
        Some(path) => {
            let loaded = chromacal::config::load_config(Some(path))?;
            (loaded.config.instrument.options, loaded.base_dir)
        }
        None => (DriverOptions::default(), std::path::PathBuf::from(".")),
    };
    let options = DriverOptions {
        timing_scale: args.timing_scale,
        ..options
    };
    measure(&args.instrument, args.count, options, &base_dir, args.json)
}

fn measure(
    spec: &str,
    count: usize,
    options: DriverOptions,
    base_dir: &std::path::Path,
    json: bool,
) -> Result<(), Failure> {
    let address = parse_instrument(spec)?;
    let mut instrument = address.open(options, base_dir)?;
    let info = instrument.info().clone();
    if !json {
        outln!(
            "{} (serial {}), {address}",
            info.name,
            info.serial.as_deref().unwrap_or("unknown")
        )?;
    }
    let mut readings = Vec::new();
    for _ in 0..count.max(1) {
        let reading = instrument.measure()?;
        if !json {
            // What a display cannot emit is shown, and named as a misread.
            let status = match reading.implausible() {
                Some(why) => format!("misread: {why}"),
                None => format!("{:?}", reading.status).to_lowercase(),
            };
            match (reading.xyz, reading.luminance()) {
                (Some(xyz), _) => {
                    let xyy = xyz_to_xyy(&xyz, [0.0, 0.0]);
                    outln!(
                        "  XYZ {:.4} {:.4} {:.4}  x {:.4} y {:.4}  [{status}, code {}]",
                        xyz.x,
                        xyz.y,
                        xyz.z,
                        xyy.x,
                        xyy.y,
                        reading.device_code.as_deref().unwrap_or("-")
                    )?
                }
                (None, Some(y)) => outln!(
                    "  Y {y:.4} cd/m²  [{status}, code {}]",
                    reading.device_code.as_deref().unwrap_or("-")
                )?,
                (None, None) => outln!(
                    "  no value  [{status}, code {}]",
                    reading.device_code.as_deref().unwrap_or("-")
                )?,
            }
        }
        readings.push(reading);
    }
    instrument.close();
    if json {
        outln!("{}", serde_json::to_string_pretty(&readings)?)?;
    }
    Ok(())
}
