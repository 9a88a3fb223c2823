//! `chromacal report`: a profile as a self-contained HTML page with its figures
//! (`chromacal::html_report`). `calibrate --report` and `fit --report` write the same
//! page through [`write_page`].

use std::path::{Path, PathBuf};

use chromacal::calibrate::verify::{VerifyOutcome, saved_for};
use chromacal::html_report::{ReportInput, readings_of, report_html};
use chromacal::measurement_file::read_measurements;
use chromacal::profile::Profile;
use chromacal::verification::Criteria;
use chromacal_model::measurement::MeasurementSet;

use super::shared::{Failure, is_stdout, write_stdout};

/// Write an HTML report of a profile: transfer curves with the measured points, the
/// primaries on the u′v′ diagram, the uniformity map, the held-out error with the
/// worst patches, the assumption checks and the law selection. One file, no network.
#[derive(clap::Args)]
pub struct ReportArgs {
    /// The profile to report on: a chromacal profile (TOML), e.g. a state directory's
    /// `current.toml` or what `chromacal fit -o` wrote.
    profile: PathBuf,
    /// Where to write the page; `-` writes it to standard output.
    #[arg(short, long)]
    output: PathBuf,
    /// The readings the profile was fitted on (a run journal or a .ti3), for the
    /// measured points [default: the source the profile names, if it is still there].
    #[arg(long)]
    readings: Option<PathBuf>,
    /// What the verified patches must achieve: `strict`, `nominal`, `loose`, or limits
    /// as `mean=1,p95=2,max=4` [default: the default [publish] limits].
    #[arg(long)]
    criteria: Option<Criteria>,
}

pub fn run(args: ReportArgs) -> Result<(), Failure> {
    let profile = Profile::read(&args.profile)?;
    let (readings, note) = match &args.readings {
        Some(path) => (Some(read_measurements(path)?), None),
        None => match readings_of(&profile) {
            Ok(set) => (Some(set), None),
            Err(why) => (None, Some(why)),
        },
    };
    if let Some(why) = &note {
        eprintln!("chromacal: {why}");
    }
    let verified = saved_for(&args.profile, &profile);
    write_page(
        &ReportInput {
            profile: &profile,
            readings: readings.as_ref(),
            readings_note: note,
            history: None,
            device: None,
            checked: None,
            criteria: args.criteria.unwrap_or_else(|| default_criteria(&profile)),
            verified: verified.as_ref(),
        },
        &args.output,
    )
}

/// The criteria a page is judged by unless given: the default `[publish]` limits, with
/// the ΔE ITP one for a profile of an HDR signal in cd/m², as `calibrate` publishes it
/// (ΔE ITP of relative light, white at 100, would judge nothing).
pub fn default_criteria(profile: &Profile) -> Criteria {
    let absolute = profile.units == chromacal_model::measurement::Units::Absolute;
    Criteria::from_publish_for(
        &chromacal::config::PublishConfig::default(),
        profile.provenance.signal.filter(|_| absolute),
    )
}

/// Refuse a report path whose directory does not exist, before a run that would
/// write it at its end (as `write_page` would then).
pub fn check_output_dir(output: &Path) -> Result<(), Failure> {
    if is_stdout(output) {
        return Ok(());
    }
    chromacal_formats::durable::require_parent_dir(output).map_err(|e| {
        Failure::from(format!(
            "cannot write the report to {}: {e}",
            output.display()
        ))
    })
}

/// Render `input` and write it to `output` (`-`: standard output), saying where on
/// standard error so that a page sent to standard output stays clean.
pub fn write_page(input: &ReportInput, output: &Path) -> Result<(), Failure> {
    let page = report_html(input)?;
    if is_stdout(output) {
        return write_stdout(page.as_bytes());
    }
    chromacal_formats::durable::write_atomic_named(output, page.as_bytes())
        .map_err(|e| Failure::from(format!("cannot write {}: {e}", output.display())))?;
    eprintln!("chromacal: report written to {}", output.display());
    Ok(())
}

/// The report of a profile just made from `readings`, for `calibrate` and `fit`, its
/// held-out patches judged by `criteria`.
pub fn write_for(
    profile: &Profile,
    readings: Option<&MeasurementSet>,
    criteria: Criteria,
    verified: Option<&chromacal::verify::VerifyReport>,
    output: &Path,
) -> Result<(), Failure> {
    write_page(
        &ReportInput {
            profile,
            readings,
            readings_note: None,
            history: None,
            device: None,
            checked: None,
            criteria,
            verified,
        },
        output,
    )
}

/// The report of a profile just verified: it opens with the calibrated display.
pub fn write_verification(outcome: &VerifyOutcome, output: &Path) -> Result<(), Failure> {
    let profile = &outcome.profile;
    let (readings, note) = match readings_of(profile) {
        Ok(set) => (Some(set), None),
        Err(why) => (None, Some(why)),
    };
    write_page(
        &ReportInput {
            profile,
            readings: readings.as_ref(),
            readings_note: note,
            history: None,
            device: None,
            checked: None,
            criteria: default_criteria(profile),
            verified: Some(&outcome.report),
        },
        output,
    )
}
