//! `chromacal calibrate`: plan, measure, fit, validate and publish, with a progress bar
//! and a summary.

use super::shared::{out, outln};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use chromacal::calibrate::devices::Overrides;
use chromacal::calibrate::run::Progress;
use chromacal::calibrate::session::{CalibrateOptions, Resume, calibrate as calibrate_session};
use chromacal::config::devices::find_device;
use chromacal::config::{
    LoadedConfig, check_config, config_search_paths, device_configs, hdr_mode_advice,
    load_config_searching, where_patches_go,
};
use chromacal::profile::store::default_state_dir;
use chromacal::report;
use chromacal_model::ScreenPosition;

use super::args::DeviceArgs;
use super::shared::{Failure, INTERRUPTED, NOT_PUBLISHED};

/// Run a calibration (by default of the simulated CRT, no hardware needed) and
/// publish the profile to the state directory.
#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// Configuration file (TOML) [default: $XDG_CONFIG_HOME/chromacal/config.toml, else
    /// /etc/chromacal/config.toml, else the built-in config/default.toml; see
    /// `chromacal config show`].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Profile store and run journals [default: $STATE_DIRECTORY, else
    /// $XDG_STATE_HOME/chromacal, else ~/.local/state/chromacal].
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// Resume an unfinished run, measuring only what it lacks: the newest one, or
    /// the run named (`chromacal runs` lists them). With --config, that config's
    /// [fit], [publish], [target], [daemon] and [schedule] replace the run's (what it
    /// measures must be unchanged).
    #[arg(long, value_name = "RUN", num_args = 0..=1, default_missing_value = "")]
    resume: Option<String>,
    /// Take the simulated instrument's time for real (scaled by --time-scale).
    #[arg(long)]
    realtime: bool,
    /// Real seconds per simulated second with --realtime.
    #[arg(long, default_value_t = 1.0, requires = "realtime", value_parser = super::shared::positive_number)]
    time_scale: f64,
    /// Print JSON instead of the summary: run_id, profile_id, profile_path, journal,
    /// published (and not_published_because), readings, instrument_s, fit_s, and the
    /// fit's whole report under `report`.
    #[arg(long)]
    json: bool,
    /// Also write the HTML report of the profile (`chromacal report`) to this file.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// The `[[device]]` of the config to calibrate: its sections, and its store in
    /// <state>/NAME/ (as the daemon keeps it). Needed when the config names devices.
    #[arg(long, value_name = "NAME")]
    device: Option<String>,
    /// First set the monitor's own controls toward the [target] white and luminance
    /// (`chromacal adjust`: a readout until Enter), so that the curves have less to do.
    #[arg(long, conflicts_with = "resume")]
    adjust: bool,
    #[command(flatten)]
    devices: DeviceArgs,
}

pub fn run(args: CalibrateArgs) -> Result<(), Failure> {
    let overrides = args.devices.overrides()?;
    if args.adjust {
        let loaded = load_config_searching(args.config.as_deref(), &config_search_paths())?;
        let target = super::adjust::target(&loaded, None, None)?;
        super::adjust::adjust(&loaded, &args.devices, &target, false)?;
    }
    calibrate(
        args.config.as_deref(),
        args.device.as_deref(),
        args.state_dir,
        args.resume.map(|run| match run.as_str() {
            "" => Resume::Newest,
            _ => Resume::Named(run),
        }),
        args.realtime.then_some(args.time_scale),
        args.json,
        args.report.as_deref(),
        overrides,
    )
}

/// The config and state directory of device `name` of `loaded` (`[[device]]`); a
/// config that names devices needs one named.
fn pick_device(
    loaded: LoadedConfig,
    name: Option<&str>,
    state_dir: PathBuf,
) -> Result<(LoadedConfig, PathBuf), Failure> {
    if name.is_none() && loaded.config.device.is_empty() {
        return Ok((loaded, state_dir));
    }
    let devices =
        device_configs(&loaded).map_err(|e| Failure::from(format!("{}: {e}", loaded.origin)))?;
    let chosen = find_device(&devices, name, |d| d.name.as_str())
        .map_err(|e| Failure::from(format!("{}: {e}", loaded.origin)))?;
    Ok((chosen.loaded.clone(), chosen.store_dir(&state_dir)))
}

#[allow(clippy::too_many_arguments)]
fn calibrate(
    config: Option<&Path>,
    device: Option<&str>,
    state_dir: Option<PathBuf>,
    resume: Option<Resume>,
    realtime_scale: Option<f64>,
    json: bool,
    report_path: Option<&Path>,
    overrides: Overrides,
) -> Result<(), Failure> {
    let (loaded, state_dir) = pick_device(
        load_config_searching(config, &config_search_paths())?,
        device,
        state_dir.unwrap_or_else(default_state_dir),
    )?;
    // The report is written after the run: a directory that is not there is said
    // now, before anything is measured.
    if let Some(path) = report_path {
        super::report::check_output_dir(path)?;
    }
    // Ctrl-C (or SIGTERM) stops after the reading under way; a second one at once.
    let stop_requested = Arc::new(AtomicBool::new(false));
    let flag = stop_requested.clone();
    let options = CalibrateOptions {
        stop: Some(Arc::new(move || flag.load(Ordering::SeqCst))),
        state_dir,
        resume_settings: resume.is_some() && config.is_some(),
        resume,
        realtime_scale,
        overrides,
    };
    let bar = indicatif::ProgressBar::new(0);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} measuring [{bar:40}] {pos}/{len} patches, {elapsed} so far, about {eta} to go  {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let mut on_progress = |p: &Progress| {
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        bar.set_message(match p.luminance {
            Some(y) => format!("{:?} Y {y:.3}", p.role).to_lowercase(),
            None => format!("{:?} {:?}", p.role, p.status).to_lowercase(),
        });
    };
    announce_display(&loaded, &options);
    let mut ask = |position: ScreenPosition| aim_prompt(&bar, position);
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let resume = chromacal::calibrate::session::resume_command_in(&options.state_dir);
    runtime.spawn(stop_on_signal(stop_requested.clone(), bar.clone(), resume));
    let outcome = runtime.block_on(calibrate_session(
        &loaded,
        &options,
        &mut on_progress,
        Some(&mut ask),
    ));
    bar.finish_and_clear();
    // Stopped on request, the error says how many readings the journal keeps and
    // that `--resume` goes on; the exit code is a shell's for an interrupt.
    let outcome = outcome.map_err(|e| Failure {
        message: e.to_string(),
        code: if stop_requested.load(Ordering::SeqCst) {
            INTERRUPTED
        } else {
            1
        },
    })?;
    if let Some(path) = report_path {
        let readings = chromacal::measurement_file::read_measurements(&outcome.journal_path)?;
        // Judged by the limits the run publishes by.
        let criteria = chromacal::verification::Criteria::from_publish_for(
            &loaded.config.publish,
            outcome.profile.provenance.signal,
        );
        super::report::write_for(
            &outcome.profile,
            Some(&readings),
            criteria,
            outcome.verified.as_ref(),
            path,
        )?;
    }
    if json {
        let summary = serde_json::json!({
            "run_id": outcome.run_id,
            "profile_id": outcome.profile.id,
            "profile_path": outcome.profile_path,
            "journal": outcome.journal_path,
            "published": outcome.rejection.is_none(),
            "not_published_because": outcome.rejection,
            "readings": outcome.profile.cost.as_ref().map(|c| c.readings),
            "instrument_s": outcome.instrument_seconds,
            "fit_s": outcome.fit_seconds,
            "report": outcome.profile.report,
        });
        outln!("{}", serde_json::to_string_pretty(&summary)?)?;
    } else {
        out!("{}", report::calibration_outcome(&outcome))?;
    }
    match outcome.rejection {
        None => Ok(()),
        Some(why) => Err(Failure {
            message: format!("the profile was not published: {why}"),
            code: NOT_PUBLISHED,
        }),
    }
}

/// Tell the user where the patches will be, for the sinks that wait for a peer.
fn announce_display(loaded: &LoadedConfig, options: &CalibrateOptions) {
    let mut config = loaded.config.clone();
    options.overrides.apply(&mut config);
    if options.resume.is_some() || check_config(&config).is_err() {
        return; // the session reports the error, or resumes with the journal's config
    }
    if let Some(place) = where_patches_go(&config) {
        eprintln!("chromacal: {place}");
    }
    if let Some(advice) = hdr_mode_advice(&config) {
        eprintln!("chromacal: {advice}");
    }
}

/// Ask on the terminal to aim the instrument at `position`; Enter goes on.
pub(super) fn aim_prompt(
    bar: &indicatif::ProgressBar,
    position: ScreenPosition,
) -> Result<(), String> {
    bar.suspend(|| {
        eprintln!(
            "chromacal: aim the instrument at the patch now shown at ({:.3}, {:.3}) (fractions of the screen's width and height from the top left), then press Enter",
            position.x, position.y
        );
        let mut line = String::new();
        match std::io::stdin().read_line(&mut line) {
            Ok(0) => Err("the terminal closed while waiting for the instrument to be aimed".into()),
            Ok(_) => Ok(()),
            Err(e) => Err(format!("cannot read the terminal: {e}")),
        }
    })
}

/// The first Ctrl-C or SIGTERM asks the run to stop after the reading under way (the
/// display is blanked and the journal keeps every reading); a second one exits at once,
/// which loses nothing either: each reading is in the journal when it is taken.
async fn stop_on_signal(stop: Arc<AtomicBool>, bar: indicatif::ProgressBar, resume: String) {
    use tokio::signal::unix::{SignalKind, signal};
    let Ok(mut terminate) = signal(SignalKind::terminate()) else {
        return;
    };
    loop {
        tokio::select! {
            pressed = tokio::signal::ctrl_c() => if pressed.is_err() { return },
            _ = terminate.recv() => {}
        }
        if stop.swap(true, Ordering::SeqCst) {
            bar.abandon();
            eprintln!(
                "chromacal: stopped at once; every reading taken is in the journal, and `{resume}` goes on"
            );
            std::process::exit(INTERRUPTED.into());
        }
        bar.suspend(|| {
            eprintln!("chromacal: stopping after the reading under way (again to stop at once)")
        });
    }
}
