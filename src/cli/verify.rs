//! `chromacal verify`: measure a chart through what the display holds now and judge
//! it (`chromacal::verify`), with a progress bar, a summary or JSON, a `.ti3` of the
//! readings and an HTML report.

use std::path::PathBuf;

use chromacal::calibrate::verify::{VerifyOptions, verify};
use chromacal::config::{config_search_paths, load_config_searching};
use chromacal::profile::store::default_state_dir;
use chromacal::verify::criteria::{CriteriaSet, PRESETS, preset};
use chromacal::verify::{Against, Metric, Verdict, chart};
use chromacal_crf::lut3d::SourceSpace;

use super::args::DeviceArgs;
use super::shared::{Failure, VERIFICATION_FAILED, VERIFICATION_UNDECIDED, outln};

/// Verify the calibrated display: show a chart through the video LUT as it is now
/// (and the profile's curves where the display has no LUT), read it, and set every
/// patch against what a colour-managed application asked for (--against) and against
/// the profile's prediction; the calibrated white, black, contrast, grey balance and
/// tone; a verdict for each criterion (pass, fail or undecided, from each value's 95 %
/// interval). Exit 0 when it passes, 5 when it fails, 6 when undecided.
#[derive(clap::Args)]
pub struct VerifyArgs {
    /// The profile to verify (a chromacal .toml) [default: the store's current one].
    profile: Option<PathBuf>,
    /// Verify the store's current profile (the default when no profile is named).
    #[arg(long, conflicts_with = "profile")]
    current: bool,
    /// What each patch is set against: srgb, bt709, bt1886, p3, rec2020, rec2100-pq,
    /// rec2100-hlg (what an application asks for in that encoding) or profile (the
    /// profile's prediction) [default: srgb; rec2100-pq for the bt2100 chart,
    /// rec2100-hlg for bt2100-hlg].
    #[arg(long)]
    against: Option<Against>,
    /// default (≥ 17 greys, primaries and secondaries at four levels, the
    /// ColorChecker, white and black read three times), short (26 patches), long
    /// (≥ 100), bt2100 (for a display in PQ mode: PQ greys from 0.1 to 1,000 cd/m²
    /// and the ColorChecker at 203 cd/m², as BT.2100 PQ codes), bt2100-hlg (in HLG
    /// mode: HLG greys and the ColorChecker at 75 % HLG), or a file: a .ti1/.ti3
    /// (RGB_R RGB_G RGB_B, 0–100) or a CSV (R, G, B, 0–1), in the --against encoding.
    #[arg(long, default_value = "default")]
    chart: String,
    /// de00 (CIEDE2000) or itp (ITU-R BT.2124 ΔE ITP) [default: de00; itp for the
    /// bt2100 charts].
    #[arg(long)]
    metric: Option<Metric>,
    /// displaycal (DisplayCAL's default tolerances), displaycal-recommended, iso14861
    /// [default: the config's [verify] criteria, else displaycal].
    #[arg(long)]
    criteria: Option<String>,
    /// Read the patches whose verdict is undecided again, up to N more readings in
    /// all, until every verdict is settled.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "60")]
    until_decided: Option<usize>,
    /// Read white, grey 128 and grey 64 on an N × N grid (N odd, default 5) and judge
    /// the screen's uniformity against its centre as ISO 12646 does (luminance within
    /// 10, 13 and 15 %, Δu′v′ within 0.01). In the window, with --prompt-positions:
    /// you are asked to move the instrument to each position.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "5", value_parser = grid_size)]
    uniformity: Option<usize>,
    /// Print the whole result as JSON.
    #[arg(long)]
    json: bool,
    /// Write the readings as an ArgyllCMS .ti3.
    #[arg(long, value_name = "FILE")]
    ti3: Option<PathBuf>,
    /// Write the verification report (HTML).
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// Configuration file (TOML), for the instrument and the display [default: as for
    /// calibrate].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Profile store [default: as for calibrate].
    #[arg(long)]
    state_dir: Option<PathBuf>,
    #[command(flatten)]
    devices: DeviceArgs,
}

pub fn run(args: VerifyArgs) -> Result<(), Failure> {
    let loaded = load_config_searching(args.config.as_deref(), &config_search_paths())?;
    let chart = chart::chart(&args.chart)?;
    // The HDR charts' encoding: each is codes of one signal.
    let hdr_encoding = match chart.name.as_str() {
        "bt2100" => Some(SourceSpace::Rec2100Pq),
        "bt2100-hlg" => Some(SourceSpace::Rec2100Hlg),
        _ => None,
    };
    let metric = args.metric.unwrap_or(if hdr_encoding.is_some() {
        Metric::Itp
    } else {
        Metric::De00
    });
    let criteria = criteria(args.criteria.as_deref(), &loaded.config.verify, metric)?;
    if let Some(path) = &args.report {
        super::report::check_output_dir(path)?;
    }
    let against = match (hdr_encoding, args.against) {
        (Some(own), None) => Against::Encoding(own),
        (Some(own), Some(a @ Against::Encoding(space))) if space != own => {
            return Err(Failure::from(format!(
                "the {} chart is {} codes: verify it --against {}, not {}",
                chart.name,
                own.name(),
                own.key(),
                a.name()
            )));
        }
        (_, a) => a.unwrap_or(Against::Encoding(SourceSpace::Srgb)),
    };
    let options = VerifyOptions {
        state_dir: args.state_dir.unwrap_or_else(default_state_dir),
        profile: args.profile,
        chart,
        against,
        metric,
        criteria,
        until_decided: args.until_decided,
        overrides: args.devices.overrides()?,
        correction: loaded
            .config
            .instrument
            .correction
            .as_ref()
            .map(|c| c.record(&loaded.base_dir)),
        uniformity: args.uniformity,
    };
    let bar = indicatif::ProgressBar::new(0);
    let mut progress = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let mut aim = |position| super::calibrate::aim_prompt(&bar, position);
    let outcome = runtime.block_on(verify(&loaded, &options, &mut progress, Some(&mut aim)));
    bar.finish_and_clear();
    let outcome = outcome?;
    if let Some(path) = &args.ti3 {
        chromacal_formats::durable::write_atomic_named(path, outcome.ti3.as_bytes())
            .map_err(|e| Failure::from(format!("{}: {e}", path.display())))?;
    }
    if let Some(path) = &args.report {
        super::report::write_verification(&outcome, path)?;
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&outcome.report)?)?;
    } else {
        outln!(
            "{}",
            chromacal::report::verification_summary(&outcome.report)
        )?;
    }
    match outcome.report.verdict {
        Verdict::Pass => Ok(()),
        Verdict::Fail => Err(Failure {
            message: "the display fails the verification".into(),
            code: VERIFICATION_FAILED,
        }),
        Verdict::Undecided => Err(Failure {
            message: "the verification is undecided: read again with --until-decided".into(),
            code: VERIFICATION_UNDECIDED,
        }),
    }
}

/// An odd grid size from 3 to 15.
fn grid_size(text: &str) -> Result<usize, String> {
    let n: usize = text
        .parse()
        .map_err(|_| format!("'{text}' is not a grid size"))?;
    chromacal::verify::uniformity::check_grid(n).map(|()| n)
}

/// The criteria asked for: by name, else the config's, else DisplayCAL's defaults.
fn criteria(
    name: Option<&str>,
    config: &chromacal::config::VerifyConfig,
    metric: Metric,
) -> Result<CriteriaSet, Failure> {
    let name = name.or(config.criteria.as_deref());
    match name {
        Some(name) => preset(name, metric).ok_or_else(|| {
            Failure::from(format!(
                "no criteria '{name}' ({}, or [[verify.criterion]] in the config)",
                PRESETS.join(", ")
            ))
        }),
        None if !config.criterion.is_empty() => Ok(CriteriaSet {
            name: "the config's [[verify.criterion]]".into(),
            criteria: config.criterion.clone(),
        }),
        None => Ok(preset("displaycal", metric).unwrap_or_else(|| CriteriaSet {
            name: "none".into(),
            criteria: Vec::new(),
        })),
    }
}
