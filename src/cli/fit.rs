//! `chromacal fit`: a profile from recorded measurements (a run journal or a .ti3).

use std::path::{Path, PathBuf};

use clap::ValueEnum;

use chromacal::config::{config_search_paths, fit_options_for_signal, load_config_searching};
use chromacal::measurement_file::read_measurements_and_signal;
use chromacal::profile::{Cost, Profile, Provenance, SCHEMA_VERSION};
use chromacal::report;
use chromacal_model::fit::fit_monitor;
use chromacal_model::transfer::LawKind;

use super::shared::{Failure, absolute_path, is_stdout, out, outln, write_stdout};

/// Fit a profile to recorded measurements: a run journal or an ArgyllCMS .ti3.
#[derive(clap::Args)]
pub struct FitArgs {
    /// The measurements: a run journal (`<state>/runs/<run>/journal.jsonl`) or an
    /// ArgyllCMS .ti3.
    measurements: PathBuf,
    /// Where to write the profile (TOML); `-` writes it to standard output (and what
    /// is said, to standard error).
    #[arg(short, long)]
    output: PathBuf,
    /// Take the [fit] options from this configuration file [default: $XDG_CONFIG_HOME/chromacal/config.toml, else
    /// /etc/chromacal/config.toml, else the built-in config/default.toml; see
    /// `chromacal config show`].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Candidate laws (comma-separated), instead of the config's.
    #[arg(long, value_delimiter = ',', ignore_case = true)]
    laws: Option<Vec<LawArg>>,
    /// Print the fit's whole report as JSON instead of the summary.
    #[arg(long)]
    json: bool,
    /// Also write the HTML report of the profile (`chromacal report`) to this file.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
}

pub fn run(args: FitArgs) -> Result<(), Failure> {
    fit(
        &args.measurements,
        &args.output,
        args.config.as_deref(),
        args.laws,
        args.json,
        args.report.as_deref(),
    )
}

/// A transfer law named on the command line.
#[derive(Clone, Copy, ValueEnum)]
pub enum LawArg {
    Power,
    GainOffsetGamma,
    Cowan,
    ThreeTerm,
    Table,
    /// The PQ law, for a display sent PQ signals.
    Pq,
    /// The PQ law with Cowan's log-quadratic term (docs/hdr.md).
    PqCowan,
    /// The HLG law, for a display sent HLG signals.
    Hlg,
    /// The HLG law with Cowan's log-quadratic term (docs/hdr.md).
    HlgCowan,
}

impl From<LawArg> for LawKind {
    fn from(l: LawArg) -> Self {
        match l {
            LawArg::Power => LawKind::Power,
            LawArg::GainOffsetGamma => LawKind::GainOffsetGamma,
            LawArg::Cowan => LawKind::Cowan,
            LawArg::ThreeTerm => LawKind::ThreeTerm,
            LawArg::Table => LawKind::Table,
            LawArg::Pq => LawKind::Pq,
            LawArg::PqCowan => LawKind::PqCowan,
            LawArg::Hlg => LawKind::Hlg,
            LawArg::HlgCowan => LawKind::HlgCowan,
        }
    }
}

fn fit(
    measurements: &Path,
    output: &Path,
    config: Option<&Path>,
    laws: Option<Vec<LawArg>>,
    json: bool,
    report_path: Option<&Path>,
) -> Result<(), Failure> {
    let (set, signal) = read_measurements_and_signal(measurements)?;
    let loaded = load_config_searching(config, &config_search_paths())?;
    if let (Some(said), Some(taken)) = (loaded.config.plan.signal, signal)
        && said != taken
    {
        eprintln!(
            "chromacal: the readings were taken with {} signals; the config's plan.signal ({}) is not what this fit follows",
            taken.name(),
            said.name()
        );
    }
    let mut options = fit_options_for_signal(&loaded, signal);
    if let Some(laws) = laws {
        options.laws = laws.into_iter().map(LawKind::from).collect();
    }
    let started = std::time::Instant::now();
    let fitted = fit_monitor(&set, &options)?;
    let fit_seconds = started.elapsed().as_secs_f64();
    let to_stdout = is_stdout(output);
    let id = match output.file_stem() {
        Some(stem) if !to_stdout => stem.to_string_lossy().into_owned(),
        _ => "profile".into(),
    };
    let profile = Profile {
        schema_version: SCHEMA_VERSION,
        id,
        created: chromacal_formats::time::now_rfc3339(),
        units: set.units,
        model: fitted.model.clone(),
        provenance: Provenance {
            // Absolute, so that `report` run from another directory finds the readings.
            source: absolute_path(measurements).display().to_string(),
            display: set.display.clone(),
            instrument: set.instrument.clone(),
            measured_at: set.measured_at.clone(),
            config_digest: None,
            program: format!("chromacal {}", env!("CARGO_PKG_VERSION")),
            settings_at_resume: None,
            edid: None,
            correction: None,
            uncorrected: None,
            signal: signal.filter(|s| s.is_hdr()),
        },
        report: fitted.report.clone(),
        calibration: None,
        cost: Some(Cost {
            readings: set.measurements.len(),
            instrument_s: set.instrument_seconds(),
            fit_s: fit_seconds,
        }),
    };
    if to_stdout {
        write_stdout(profile.to_toml()?.as_bytes())?;
    } else {
        profile.write(output)?;
    }
    if let Some(path) = report_path {
        let criteria = super::report::default_criteria(&profile);
        super::report::write_for(&profile, Some(&set), criteria, None, path)?;
    }
    if json && to_stdout {
        eprintln!("{}", serde_json::to_string_pretty(&fitted.report)?);
    } else if json {
        outln!("{}", serde_json::to_string_pretty(&fitted.report)?)?;
    } else {
        let c = &fitted.report.counts;
        let text = format!(
            "chromacal: fitted {} ({} readings, {} usable; {} in the fit's budgeted kinds, {} held out, {} uniformity; XYZ {})\n  fit time {}\n\n{}\nprofile: {}\n",
            measurements.display(),
            c.readings,
            c.usable,
            c.budget_readings,
            c.held_out,
            c.uniformity,
            set.units,
            report::duration(fit_seconds),
            report::fit_summary(&fitted.report),
            if to_stdout {
                "standard output".into()
            } else {
                output.display().to_string()
            }
        );
        // With the profile on standard output, what is said goes to standard error.
        if to_stdout {
            eprint!("{text}");
        } else {
            out!("{text}")?;
        }
    }
    Ok(())
}
