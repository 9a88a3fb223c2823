//! A whole calibration, from config to published profile: plan, journal, measure,
//! fit, validate, publish. Also resumes a run that was cut short.

use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

use super::devices::{Devices, DevicesError, Overrides, open_devices};
use super::run::{PositionPrompt, Progress, RunError, RunHooks, RunOptions, RunSummary};
use super::sequential::measure_run;
use super::video_lut::{self, RunEnd};
use crate::calibrate::rig::SimulatedRig;
use crate::config::digest;
use crate::config::{
    Config, ConfigError, LoadedConfig, PublishConfig, Sink, check_config, parse_config_unchecked,
};
use crate::journal::{JOURNAL_FORMAT, JOURNAL_VERSION, Journal, JournalError, JournalHeader};
use crate::profile::store::ProfileStore;
use crate::profile::{Cost, Profile, ProfileError, Provenance, SCHEMA_VERSION};
use chromacal_display::PatchDisplay;
use chromacal_instruments::Instrument;
use chromacal_model::fit::{FitError, FitOptions, FittedModel, fit_monitor};
use chromacal_model::measurement::{MeasurementSet, Units};
use chromacal_model::plan::{Plan, PlanError, make_plan};
use chromacal_sim::monitor::SimError;

/// Name of the file in a run's directory that says the run ended: the profile's
/// path, or `discarded`.
pub(crate) const DONE_MARKER: &str = "profile";

/// The command that resumes the run whose journal is `journal`
/// (`<state>/runs/<run>/journal.jsonl`): with the state directory it was given, which
/// a plain `--resume` would not find unless it is the default one.
fn resume_command(journal: &Path) -> String {
    match journal
        .parent()
        .and_then(Path::parent)
        .and_then(Path::parent)
    {
        Some(state) => resume_command_in(state),
        None => resume_command_in(Path::new("")),
    }
}

/// The command that resumes the unfinished run in state directory `state`.
pub fn resume_command_in(state: &Path) -> String {
    if state.as_os_str().is_empty() {
        "chromacal calibrate --resume".into()
    } else {
        format!(
            "chromacal calibrate --resume --state-dir {}",
            shell_quoted(&state.display().to_string())
        )
    }
}

/// `text` as one shell word: as it is when it has nothing the shell reads, else in
/// single quotes.
fn shell_quoted(text: &str) -> String {
    if !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+:,@%".contains(c))
    {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', "'\\''"))
    }
}

/// Why a calibration stopped.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("monitor: {0}")]
    Simulation(#[from] SimError),
    #[error("plan: {0}")]
    Plan(#[from] PlanError),
    #[error("journal: {0}")]
    Journal(#[from] JournalError),
    #[error(
        "{source}\nEverything measured is kept in {journal}; run `{}` to go on.",
        resume_command(.journal)
    )]
    Run { source: RunError, journal: PathBuf },
    #[error("fit: {0}")]
    Fit(#[from] FitError),
    #[error("profile: {0}")]
    Profile(#[from] ProfileError),
    #[error(
        "profile store {path}: {source}\nThe run's journal is kept; once the cause is fixed, `chromacal calibrate --resume` fits and publishes it without measuring again."
    )]
    Store {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "no unfinished run to resume in {0} (`chromacal runs` lists them, with any whose fit failed twice and is resumed only by name)"
    )]
    NothingToResume(PathBuf),
    #[error(
        "{origin} differs from the run's own config in {sections}, which decide what is measured: a resumed run keeps its own; only [fit], [publish], [target], [daemon] and [schedule] may change at --resume"
    )]
    ResumeConfig { origin: String, sections: String },
    #[error("no unfinished run is named {id}; unfinished runs: {}", if unfinished.is_empty() { "none".to_string() } else { unfinished.join(", ") })]
    NoSuchRun { id: String, unfinished: Vec<String> },
    #[error(transparent)]
    StoreState(#[from] crate::profile::store::StoreError),
    #[error(transparent)]
    Devices(#[from] DevicesError),
    #[error("video LUT: {0}")]
    Lut(#[from] chromacal_display::lut::LutError),
    #[error("cannot write the config: {0}")]
    Serialize(String),
    #[error(
        "display.prompt_positions is set, but nothing here can ask someone to move the instrument"
    )]
    NoPrompt,
}

/// How to run a calibration.
#[derive(Clone)]
pub struct CalibrateOptions {
    pub state_dir: PathBuf,
    /// Resume an unfinished run instead of starting one.
    pub resume: Option<Resume>,
    /// On resume, take the settings that do not change what is measured (`[fit]`,
    /// `[publish]`, …) from the config given, not the journal's (see
    /// `adopt_settings_at_resume`).
    pub resume_settings: bool,
    /// Real seconds per simulated second (`None`: as fast as possible).
    pub realtime_scale: Option<f64>,
    /// Command-line settings that win over the config's.
    pub overrides: Overrides,
    /// Asked before each patch whether to stop (Ctrl-C): the reading under way is
    /// finished and journaled, the display blanked, and the run left to `--resume`.
    pub stop: Option<chromacal_model::fit::cancel::StopCheck>,
}

/// Which unfinished run to resume.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Resume {
    /// The newest that is resumable (`UnfinishedRun::resumable`).
    Newest,
    /// The one with this id, whatever its state.
    Named(String),
}

/// Check a config again once the command line changed it.
fn check_overridden(config: &Config) -> Result<(), CalibrateError> {
    check_config(config).map_err(|message| {
        CalibrateError::Config(ConfigError::Invalid {
            path: "the config with the command line's settings".into(),
            message,
        })
    })
}

/// What a calibration did and made.
#[derive(Debug, Clone)]
pub struct CalibrationOutcome {
    pub run_id: String,
    pub journal_path: PathBuf,
    pub run: RunSummary,
    pub plan: Plan,
    pub fitted: FittedModel,
    pub profile: Profile,
    pub profile_path: PathBuf,
    /// `None` when the profile became current; otherwise why not.
    pub rejection: Option<String>,
    /// Wall-clock seconds of the fit.
    pub fit_seconds: f64,
    /// Seconds the instrument spent: integration plus settling, every patch, and the
    /// stability check's extra readings (those of this call only, on a resume).
    pub instrument_seconds: f64,
    pub display: String,
    /// Why `[target]`'s calibration curves could not be made (the profile is fine).
    pub calibration_error: Option<String>,
    /// What the run left in the display's video LUT (the native window only).
    pub lut: Option<String>,
    /// The display verified through the new curves (`[target] verify`).
    pub verified: Option<crate::verify::VerifyReport>,
    /// Why that verification could not be made (the profile is fine).
    pub verify_error: Option<String>,
}

pub(crate) use chromacal_formats::time::now_rfc3339;

/// A new run id: the UTC time and a few random-ish hex digits.
pub fn new_run_id() -> String {
    let stamp = chromacal_formats::time::now_rfc3339().replace([':', '-'], "");
    let nanos = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!(
        "{}-{:04x}",
        stamp.trim_end_matches('Z'),
        (nanos >> 8) & 0xffff
    )
}

/// A run whose journal has not ended in a profile.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UnfinishedRun {
    /// Its id: the name of its directory under `runs/`.
    pub id: String,
    pub dir: PathBuf,
    /// Readings in its journal.
    pub readings: usize,
    /// Fits of its readings that failed (not counting fits that were stopped).
    pub fit_failures: u32,
    /// A daemon's calibration job started it: the daemon resumes it at its start.
    pub by_daemon: bool,
}

impl UnfinishedRun {
    /// Is it resumed without being named? Not once its fit has failed
    /// `MAX_FIT_FAILURES` times: resuming it again would fail again.
    pub fn resumable(&self) -> bool {
        self.fit_failures < MAX_FIT_FAILURES
    }
}

/// Failed fits after which a run is no longer resumed unless named.
pub const MAX_FIT_FAILURES: u32 = 2;

/// The file in a run's directory that says a daemon's job started it.
pub const DAEMON_MARKER: &str = "started_by_daemon";

/// Mark the run in `dir` as a daemon's (see [`UnfinishedRun::by_daemon`]).
pub fn mark_daemon_run(dir: &Path) -> std::io::Result<()> {
    chromacal_formats::durable::write_atomic(
        &dir.join(DAEMON_MARKER),
        b"a daemon's calibration job; the daemon resumes it when it starts\n",
    )
}

/// The file in a run's directory that counts its failed fits.
const FIT_FAILURES_FILE: &str = "fit_failures";

/// Every unfinished run of the store, oldest first.
pub fn unfinished_runs(store: &ProfileStore) -> Vec<UnfinishedRun> {
    let Ok(entries) = std::fs::read_dir(store.runs_dir()) else {
        return Vec::new();
    };
    let mut runs: Vec<UnfinishedRun> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("journal.jsonl").is_file() && !p.join(DONE_MARKER).exists())
        .map(|dir| UnfinishedRun {
            id: dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            readings: count_journal_readings(&dir.join("journal.jsonl")),
            fit_failures: fit_failures(&dir),
            by_daemon: dir.join(DAEMON_MARKER).exists(),
            dir,
        })
        .collect();
    runs.sort_by(|a, b| a.id.cmp(&b.id));
    runs
}

/// The newest of `runs` (oldest first, as `unfinished_runs` gives them) that is
/// resumed without being named.
pub fn newest_resumable(runs: &[UnfinishedRun]) -> Option<&UnfinishedRun> {
    runs.iter().rev().find(|run| run.resumable())
}

/// The newest unfinished run that is resumed without being named.
pub fn unfinished_run(store: &ProfileStore) -> Option<PathBuf> {
    newest_resumable(&unfinished_runs(store)).map(|run| run.dir.clone())
}

/// The unfinished run named `id` (its directory name under `runs/`).
pub fn named_run(store: &ProfileStore, id: &str) -> Result<PathBuf, CalibrateError> {
    let runs = unfinished_runs(store);
    runs.iter()
        .find(|run| run.id == id)
        .map(|run| run.dir.clone())
        .ok_or_else(|| CalibrateError::NoSuchRun {
            id: id.to_string(),
            unfinished: runs.iter().map(|r| r.id.clone()).collect(),
        })
}

/// Lines in a journal after its header: the readings (a line cut short by a crash
/// included, which is close enough for a listing). Counted in chunks, never more than
/// a journal's size limit, so a damaged file costs no more than a whole one.
fn count_journal_readings(path: &Path) -> usize {
    use std::io::Read;
    let Ok(file) = std::fs::File::open(path) else {
        return 0;
    };
    let mut reader = file.take(chromacal_formats::durable::limits::JOURNAL);
    let mut buffer = vec![0u8; 1 << 16];
    let mut lines = 0;
    while let Ok(n) = reader.read(&mut buffer) {
        if n == 0 {
            break;
        }
        lines += buffer[..n].iter().filter(|b| **b == b'\n').count();
    }
    lines.saturating_sub(1)
}

fn fit_failures(run_dir: &Path) -> u32 {
    std::fs::read_to_string(run_dir.join(FIT_FAILURES_FILE))
        .ok()
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or(0)
}

/// Count one more failed fit of the run whose journal is at `journal`.
fn count_fit_failure(journal: &Path) {
    let Some(dir) = journal.parent() else {
        return;
    };
    let failures = fit_failures(dir) + 1;
    let path = dir.join(FIT_FAILURES_FILE);
    if let Err(e) =
        chromacal_formats::durable::write_atomic(&path, format!("{failures}\n").as_bytes())
    {
        tracing::warn!(error = %e, "cannot count the failed fit");
    }
    if failures >= MAX_FIT_FAILURES {
        tracing::warn!(
            run = %dir.display(),
            failures,
            "this run's fit has failed {failures} times: it is kept, and no longer resumed unless named (`chromacal calibrate --resume RUN`)"
        );
    }
}

/// Does the fitted profile meet the publishing limits? `None` if it does. A white
/// with a component that is not positive is never light, however small the held-out
/// error (a correction that negated X and Z once published such a white with 0.145).
/// A profile of an HDR `signal` must also meet the ΔE ITP limit.
pub fn publish_rejection(
    fitted: &FittedModel,
    limits: &PublishConfig,
    signal: Option<chromacal_model::plan::Signal>,
) -> Option<String> {
    let white = fitted.model.white();
    if !white.iter().all(|v| *v > 0.0 && v.is_finite()) {
        return Some(format!(
            "the model's white is X, Y, Z = {:.3}, {:.3}, {:.3}: light has no component that is not positive (is a correction turning the readings inside out?)",
            white.x, white.y, white.z
        ));
    }
    limits
        .rejection(fitted.report.held_out.as_ref(), "held-out")
        .or_else(|| limits.hdr_rejection(signal, &fitted.report.held_out_patches))
}

/// Measure every patch of the journal's plan that is missing, on any display and
/// instrument, and fit; the simulated and the real paths both come through here.
pub async fn measure_and_fit<D: PatchDisplay, I: Instrument>(
    journal: &mut Journal,
    config: &Config,
    display: &mut D,
    instrument: &mut I,
    clock: &dyn chromacal_formats::time::TimeSource,
    hooks: &mut RunHooks<'_>,
) -> Result<(RunSummary, FittedModel, f64), CalibrateError> {
    let options = RunOptions {
        stability: config.display.stability,
        ..RunOptions::default()
    };
    let devices = super::run::Devices {
        display,
        instrument,
        clock,
    };
    let run = measure_run(journal, config, devices, &options, hooks)
        .await
        .map_err(|source| CalibrateError::Run {
            source,
            journal: journal.path().to_path_buf(),
        })?;
    let started = Instant::now();
    let fitted = fit_off_the_workers(
        journal.measurement_set(),
        config.fit.clone(),
        hooks.stop.clone(),
    )
    .await;
    if matches!(&fitted, Err(e) if !matches!(e, FitError::Stopped)) {
        count_fit_failure(journal.path());
    }
    let fitted = fitted?;
    Ok((run, fitted, started.elapsed().as_secs_f64()))
}

/// Fit on tokio's blocking pool, so that a fit of seconds never holds an async worker
/// (in the daemon, every API request would wait for it), with `stop` asked between its
/// steps.
pub async fn fit_off_the_workers(
    set: MeasurementSet,
    options: FitOptions,
    stop: Option<chromacal_model::fit::cancel::StopCheck>,
) -> Result<FittedModel, FitError> {
    tokio::task::spawn_blocking(move || {
        chromacal_model::fit::cancel::with_stop(stop, || fit_monitor(&set, &options))
    })
    .await
    .unwrap_or_else(|e| std::panic::resume_unwind(e.into_panic()))
}

/// A calibration run with its journal open, ready to measure what it lacks.
pub struct PreparedRun {
    pub journal: Journal,
    /// The config the run goes on with (a resumed run's own, from its journal).
    pub config: Config,
    pub run_id: String,
    /// Set when `--resume` was given a config whose fit settings replaced the
    /// journal's: where they came from (recorded in the profile's provenance).
    pub settings_at_resume: Option<String>,
}

/// Give a resumed run the settings of `given` that do not change what is measured:
/// `[fit]`, `[publish]`, `[target]`, `[daemon]` and `[schedule]`. A config that differs
/// from the run's in what it measures (`[monitor]`, `[instrument]`, `[display]`,
/// `[plan]`, `[warmup]`) is refused, naming the sections: its readings would not be
/// the run's.
///
/// `overrides` are the command line's, applied to `given` before the comparison as
/// they were to the run's config when it began.
pub fn adopt_settings_at_resume(
    run: &mut PreparedRun,
    given: &LoadedConfig,
    overrides: &Overrides,
) -> Result<(), CalibrateError> {
    let mut now = given.config.clone();
    overrides.apply(&mut now);
    let now = grid_the_instrument_can_see(&now);
    let (was, now) = (&run.config, &now);
    let differ: Vec<&str> = [
        ("monitor", was.monitor == now.monitor),
        ("instrument", was.instrument == now.instrument),
        ("display", was.display == now.display),
        ("plan", was.plan == now.plan),
        ("warmup", was.warmup == now.warmup),
    ]
    .into_iter()
    .filter(|(_, same)| !same)
    .map(|(name, _)| name)
    .collect();
    if !differ.is_empty() {
        return Err(CalibrateError::ResumeConfig {
            origin: given.origin.clone(),
            sections: differ
                .iter()
                .map(|s| format!("[{s}]"))
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    take_settings(&mut run.config, now);
    let note = format!("{} (sha256 {})", given.origin, given.digest());
    if let Some(dir) = run.journal.path().parent() {
        let path = dir.join(SETTINGS_AT_RESUME_FILE);
        chromacal_formats::durable::write_atomic(
            &path,
            format!("# given at --resume: {note}\n{}", given.text).as_bytes(),
        )
        .map_err(|source| CalibrateError::Store { path, source })?;
    }
    run.settings_at_resume = Some(note);
    Ok(())
}

/// Start a new run of `config` in `store`, on devices named `display` and `instrument`.
pub fn start_run(
    store: &ProfileStore,
    config: &Config,
    base_dir: &Path,
    display: String,
    instrument: chromacal_instruments::InstrumentInfo,
) -> Result<PreparedRun, CalibrateError> {
    let as_run = grid_the_instrument_can_see(config);
    if as_run.plan != config.plan {
        tracing::warn!(
            "the uniformity grid (plan.uniformity_grid = {}) is not measured: the window moves the patch off the centre and the instrument stays where it is aimed; --prompt-positions (display.prompt_positions) measures it, asking to move the instrument to each position",
            config.plan.uniformity_grid
        );
    }
    let config = &as_run;
    let text = toml::to_string(config).map_err(|e| CalibrateError::Serialize(e.to_string()))?;
    let run_id = new_run_id();
    let header = JournalHeader {
        format: JOURNAL_FORMAT.into(),
        version: JOURNAL_VERSION,
        run_id: run_id.clone(),
        started: now_rfc3339(),
        config_digest: digest(&text),
        config: text,
        config_dir: base_dir.to_path_buf(),
        display,
        instrument,
        units: Units::Absolute,
        plan: make_plan(&config.plan)?,
    };
    let path = store.runs_dir().join(&run_id).join("journal.jsonl");
    Ok(PreparedRun {
        journal: Journal::create(&path, header)?,
        config: config.clone(),
        run_id,
        settings_at_resume: None,
    })
}

/// `config` without its uniformity grid when nothing would move the instrument to it:
/// chromacal's window is the screen in front of the user, read by an instrument
/// aimed at its centre, and a grid patch off the centre reads the dark surround
/// (a first-time user's run published 8 grid readings at 0.1 % of the white, and a
/// report of ΔE00 99 there). `--prompt-positions` keeps the grid and asks for each
/// move. The journal records the config as run, and a config given at `--resume` is
/// compared as it would run, so a resume agrees.
fn grid_the_instrument_can_see(config: &Config) -> Config {
    let mut config = config.clone();
    if matches!(config.display.sink(), Sink::Window | Sink::Wayland)
        && !config.display.prompt_positions
        && config.plan.uniformity_grid >= 2
    {
        config.plan.uniformity_grid = 0;
    }
    config
}

/// Reopen the unfinished run in `dir`, with the config it started with.
pub fn reopen_run(dir: &Path) -> Result<PreparedRun, CalibrateError> {
    let (journal, recovery) = Journal::open(&dir.join("journal.jsonl"))?;
    if let Some((line, bytes)) = recovery.dropped_tail {
        tracing::warn!(
            line,
            bytes,
            "dropped a reading cut short by the interruption"
        );
    }
    // Checked when the run began; checked again by the caller once `--resume` has
    // put its settings in, so a run begun under other ranges can still be resumed.
    let mut config = parse_config_unchecked(&journal.header().config, "the run's journal header")?;
    let run_id = journal.header().run_id.clone();
    // Settings given at an earlier `--resume` go on applying.
    let mut settings_at_resume = None;
    let saved = dir.join(SETTINGS_AT_RESUME_FILE);
    if saved.exists() {
        let text = chromacal_formats::durable::read_text_limited(
            &saved,
            chromacal_formats::durable::limits::CONFIG,
        )
        .map_err(|source| CalibrateError::Store {
            path: saved.clone(),
            source,
        })?;
        let given = parse_config_unchecked(&text, &saved.display().to_string())?;
        take_settings(&mut config, &given);
        crate::config::hdr_defaults(&mut config);
        settings_at_resume = text
            .lines()
            .next()
            .and_then(|l| l.strip_prefix("# given at --resume: "))
            .map(str::to_string);
    }
    Ok(PreparedRun {
        journal,
        config,
        run_id,
        settings_at_resume,
    })
}

/// Where a run keeps the config given at `--resume`, so that its settings outlive a
/// second interruption.
const SETTINGS_AT_RESUME_FILE: &str = "settings_at_resume.toml";

/// The sections that do not change what is measured, from `given` into `config`.
fn take_settings(config: &mut Config, given: &Config) {
    config.fit = given.fit.clone();
    config.publish = given.publish.clone();
    config.target = given.target.clone();
    config.daemon = given.daemon.clone();
    config.schedule = given.schedule.clone();
}

/// Mark an unfinished run as given up, so that it is not resumed.
pub fn discard_run(dir: &Path) -> std::io::Result<()> {
    chromacal_formats::durable::write_atomic(&dir.join(DONE_MARKER), b"discarded\n")
}

/// Measure what `run` lacks on `devices`, fit, and publish if the profile passes the
/// run's `[publish]` limits (else keep it beside the current one).
pub async fn finish_run(
    mut run: PreparedRun,
    devices: &mut Devices,
    store: &ProfileStore,
    hooks: &mut RunHooks<'_>,
) -> Result<CalibrationOutcome, CalibrateError> {
    let config = &run.config;
    let journal = &mut run.journal;
    // Simulated time goes on from the last reading.
    if let Some(clock) = &devices.virtual_clock
        && let Some(end) = journal
            .entries()
            .iter()
            .filter_map(|m| Some(m.time_s? + m.reading.integration_s / 2.0))
            .reduce(f64::max)
        && clock.now() < end
    {
        clock.set(end);
    }
    let display_name = devices.display.name();
    let (summary, fitted, fit_seconds) = measure_and_fit(
        journal,
        config,
        &mut devices.display,
        &mut devices.instrument,
        devices.clock.as_ref(),
        hooks,
    )
    .await?;

    // A run stopped between publishing and marking itself done is already current:
    // its published profile, curves included, stands.
    let already_current = store
        .history()
        .ok()
        .and_then(|h| h.current)
        .is_some_and(|id| id == run.run_id);
    let published = (already_current && config.target.is_some())
        .then(|| store.profile_path(&run.run_id).ok())
        .flatten()
        .and_then(|path| Profile::read(&path).ok());
    // Calibration curves, measured into place on the devices still held. A failure
    // here costs the curves, not the profile: it is published without them.
    let (calibration, calibration_error) = match (&config.target, published) {
        (None, _) => (None, None),
        (Some(_), Some(published)) => (published.calibration, None),
        (Some(target), None) => match crate::calibrate::refine::refine_curves(
            &fitted.model,
            target,
            config.plan.bit_depth,
            config.plan.patch_size,
            &mut devices.display,
            &mut devices.instrument,
        )
        .await
        {
            Ok(c) => (Some(c), None),
            Err(e) => {
                tracing::warn!(error = %e, "no calibration curves");
                (None, Some(e.to_string()))
            }
        },
    };
    let header = journal.header().clone();
    let instrument_seconds = journal
        .entries()
        .iter()
        .map(|m| m.reading.integration_s + config.display.settle_s)
        .sum::<f64>()
        + summary.extra_read_s
        + calibration.as_ref().map_or(0.0, |c| c.instrument_s);
    let profile = Profile {
        schema_version: SCHEMA_VERSION,
        id: run.run_id.clone(),
        created: now_rfc3339(),
        units: Units::Absolute,
        model: fitted.model.clone(),
        provenance: Provenance {
            source: crate::journal::stored_path(journal.path()),
            display: Some(header.display.clone()),
            instrument: Some(header.instrument.clone()),
            measured_at: Some(format!("from {}", header.started)),
            config_digest: Some(header.config_digest.clone()),
            program: format!("chromacal {}", env!("CARGO_PKG_VERSION")),
            settings_at_resume: run.settings_at_resume.clone(),
            edid: devices
                .display
                .window()
                .and_then(|w| w.output().edid.as_deref())
                .and_then(|bytes| chromacal_formats::edid::Edid::parse(bytes).ok()),
            correction: None,
            uncorrected: None,
            signal: config.plan.signal.filter(|s| s.is_hdr()),
        },
        report: fitted.report.clone(),
        calibration,
        cost: Some(Cost {
            readings: journal.entries().len(),
            instrument_s: Some(instrument_seconds),
            fit_s: fit_seconds,
        }),
    };
    let mut profile = profile;
    profile.provenance.set_correction(
        config
            .instrument
            .correction
            .as_ref()
            .map(|c| c.record(&header.config_dir)),
    );
    let text = profile.to_toml()?;
    let rejection = publish_rejection(&fitted, &config.publish, profile.provenance.signal);
    let store_error = |source| CalibrateError::Store {
        path: store.root().to_path_buf(),
        source,
    };
    let profile_path = if already_current {
        store.profile_path(&run.run_id)?
    } else if rejection.is_none() {
        store
            .publish(
                &run.run_id,
                &text,
                fitted.report.held_out.as_ref(),
                "calibration",
            )
            .map_err(store_error)?
    } else {
        store.keep(&run.run_id, &text).map_err(store_error)?
    };
    let run_dir = journal
        .path()
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    chromacal_formats::durable::write_atomic(
        &run_dir.join(DONE_MARKER),
        profile_path.display().to_string().as_bytes(),
    )
    .map_err(store_error)?;
    Ok(CalibrationOutcome {
        run_id: run.run_id.clone(),
        journal_path: journal.path().to_path_buf(),
        run: summary,
        plan: header.plan,
        fitted,
        profile,
        profile_path,
        rejection,
        fit_seconds,
        instrument_seconds,
        display: display_name,
        calibration_error,
        lut: None,
        verified: None,
        verify_error: None,
    })
}

/// Run (or resume) the calibration `loaded` describes, with `options.overrides`.
/// `prompt` asks for the instrument to be aimed at each new patch position; it is
/// needed when the config sets `display.prompt_positions`.
pub async fn calibrate<'a>(
    loaded: &LoadedConfig,
    options: &CalibrateOptions,
    progress: &'a mut (dyn FnMut(&Progress) + Send),
    prompt: Option<PositionPrompt<'a>>,
) -> Result<CalibrationOutcome, CalibrateError> {
    let store = ProfileStore::new(&options.state_dir);
    // Held for the whole run: one writer per state directory.
    let _store_lock = store.lock("chromacal calibrate")?;
    // A run killed before it put the video LUT back left the ramp it saved.
    chromacal_display::lut::restore_pending_logged(store.root());
    // A resumed run goes on with the config it started with (and the overrides).
    let (run, mut devices) = if let Some(resume) = &options.resume {
        let dir = match resume {
            Resume::Newest => unfinished_run(&store)
                .ok_or_else(|| CalibrateError::NothingToResume(store.runs_dir()))?,
            Resume::Named(id) => named_run(&store, id)?,
        };
        let mut run = reopen_run(&dir)?;
        if options.resume_settings {
            adopt_settings_at_resume(&mut run, loaded, &options.overrides)?;
        }
        options.overrides.apply(&mut run.config);
        check_overridden(&run.config)?;
        let base_dir = run.journal.header().config_dir.clone();
        let devices = open_devices(&run.config, &base_dir, options.realtime_scale).await?;
        (run, devices)
    } else {
        let mut config = loaded.config.clone();
        options.overrides.apply(&mut config);
        check_overridden(&config)?;
        make_plan(&config.plan)?;
        let devices = open_devices(&config, &loaded.base_dir, options.realtime_scale).await?;
        // A plan deeper than the window paints is refused before a run exists: an
        // empty run would offer a --resume that the changed [plan] cannot take.
        if let Some((bits, what)) = devices.display.painted_bits()
            && config.plan.bit_depth > bits
        {
            devices.instrument.close();
            let fix = match config.plan.signal.filter(|s| s.is_hdr()) {
                Some(signal) => format!(
                    "a {} signal needs 10: run the X server at depth 30 (a 30-bit visual), a Wayland compositor that offers XRGB2101010 buffers, or the Resolve sink",
                    signal.describe()
                ),
                None => format!("set plan.bit_depth = {bits}"),
            };
            return Err(CalibrateError::Devices(DevicesError::Config(format!(
                "{what} paints {bits} bits per channel, and plan.bit_depth is {}: {fix}",
                config.plan.bit_depth
            ))));
        }
        let run = start_run(
            &store,
            &config,
            &loaded.base_dir,
            devices.display.name(),
            devices.instrument.info(),
        )?;
        (run, devices)
    };
    let prompt = match (run.config.display.prompt_positions, prompt) {
        (false, _) => None,
        (true, Some(p)) => Some(p),
        (true, None) => return Err(CalibrateError::NoPrompt),
    };
    let mut hooks = RunHooks {
        progress,
        prompt,
        stop: options.stop.clone(),
    };
    // Characterised through a straight LUT; the user's ramp kept until the end.
    if let Err(e) = video_lut::hold(store.root(), &mut devices) {
        let _ = video_lut::release(store.root(), &mut devices, RunEnd::Unpublished);
        devices.instrument.close();
        return Err(e.into());
    }
    let verify_after = run.config.target.as_ref().is_some_and(|t| t.verify);
    let (bits, criteria) = (run.config.plan.bit_depth, run.config.verify.clone());
    let mut outcome = finish_run(run, &mut devices, &store, &mut hooks).await;
    let end = match &outcome {
        Ok(o) if o.rejection.is_none() => RunEnd::Published {
            curves: o.profile.calibration.as_ref().map(|c| &c.curves),
            why_no_curves: o.calibration_error.as_deref(),
        },
        _ => RunEnd::Unpublished,
    };
    match video_lut::release(store.root(), &mut devices, end) {
        Ok(what) => {
            if let Ok(o) = &mut outcome {
                o.lut = what;
            }
        }
        Err(e) => {
            tracing::error!(error = %e, "the video LUT could not be set at the end of the run")
        }
    }
    // The display through its new curves, as `chromacal verify` measures it.
    if let Ok(o) = &mut outcome
        && verify_after
        && o.rejection.is_none()
        && o.profile.calibration.is_some()
    {
        let mut progress = |done: usize, total: usize| {
            (hooks.progress)(&Progress::verification(done, total));
        };
        match super::verify::after_calibration(
            &store,
            &o.profile,
            &criteria,
            bits,
            &mut devices,
            &mut progress,
        )
        .await
        {
            Ok(report) => o.verified = Some(report),
            Err(e) => o.verify_error = Some(e.to_string()),
        }
    }
    devices.instrument.close();
    outcome
}

/// Measure the plan of `config` on its simulated rig into a new journal at
/// `journal_path`, without fitting or publishing: for fixtures, tests and benchmarks.
pub async fn measure_simulated(
    config: &Config,
    config_text: &str,
    base_dir: &Path,
    journal_path: &Path,
) -> Result<Journal, CalibrateError> {
    let mut rig = rig_for(config, base_dir, None)?;
    let header = JournalHeader {
        format: JOURNAL_FORMAT.into(),
        version: JOURNAL_VERSION,
        run_id: journal_path
            .parent()
            .and_then(|p| p.file_name())
            .map_or_else(|| "simulated".into(), |n| n.to_string_lossy().into_owned()),
        started: now_rfc3339(),
        config_digest: String::new(),
        config: config_text.to_string(),
        config_dir: base_dir.to_path_buf(),
        display: rig.display.name(),
        instrument: rig.instrument.info(),
        units: Units::Absolute,
        plan: make_plan(&config.plan)?,
    };
    let mut journal = Journal::create(journal_path, header)?;
    let devices = super::run::Devices {
        display: &mut rig.display,
        instrument: &mut rig.instrument,
        clock: rig.clock.as_ref(),
    };
    measure_run(
        &mut journal,
        config,
        devices,
        &RunOptions::default(),
        &mut RunHooks::progress(&mut |_| {}),
    )
    .await
    .map_err(|source| CalibrateError::Run {
        source,
        journal: journal_path.to_path_buf(),
    })?;
    Ok(journal)
}

/// Run a future to completion on a single-threaded runtime: for the synchronous
/// callers of the simulated rig (benchmarks, tests, tools).
pub fn block_on<F: std::future::Future>(future: F) -> std::io::Result<F::Output> {
    Ok(tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()?
        .block_on(future))
}

/// The simulated rig a config describes.
pub fn rig_for(
    config: &Config,
    base_dir: &Path,
    realtime_scale: Option<f64>,
) -> Result<SimulatedRig, CalibrateError> {
    let spec = config
        .monitor
        .resolve(base_dir)?
        .in_mode(config.plan.signal);
    let instrument = config.instrument.simulated.clone().unwrap_or_default();
    Ok(SimulatedRig::new(
        spec,
        instrument,
        config.display.settle_s,
        realtime_scale,
    )?)
}

#[cfg(test)]
mod tests {
    use super::{ProfileStore, adopt_settings_at_resume, reopen_run, resume_command, start_run};
    use crate::config::{Config, LoadedConfig, Sink};
    use chromacal_model::spatial::ScreenPosition;
    use std::path::Path;

    /// The window sink measures the centre only unless someone moves the instrument.
    #[test]
    fn a_window_run_measures_the_grid_only_when_asked_to_move_the_instrument() {
        let dir = tempfile::tempdir().unwrap();
        let store = ProfileStore::new(dir.path());
        for (sink, prompt, grid_expected) in [
            (Sink::Window, false, false),
            (Sink::Window, true, true),
            (Sink::Web, false, true),
            (Sink::Simulated, false, true),
        ] {
            let mut config = Config::default();
            config.display.sink = Some(sink);
            config.display.prompt_positions = prompt;
            let run = start_run(
                &store,
                &config,
                dir.path(),
                "a screen".into(),
                chromacal_instruments::InstrumentInfo {
                    name: "a meter".into(),
                    serial: None,
                    capability: chromacal_instruments::Capability::Tristimulus,
                },
            )
            .unwrap();
            let off_centre = run
                .journal
                .header()
                .plan
                .patches
                .iter()
                .filter(|p| p.position() != ScreenPosition::CENTRE)
                .count();
            assert_eq!(off_centre > 0, grid_expected, "{sink:?}, prompt {prompt}");
            assert_eq!(run.config.plan.uniformity_grid >= 2, grid_expected);
            // The journal's config is the one run, so a resume measures the same plan.
            assert!(
                run.journal.header().config.contains(&format!(
                    "uniformity_grid = {}",
                    run.config.plan.uniformity_grid
                )),
                "{}",
                run.journal.header().config
            );
            // `--resume --config` with the same file is the same run (a review found
            // it refused: "[plan] differs").
            let run_dir = run.journal.path().parent().unwrap().to_path_buf();
            drop(run);
            let mut reopened = reopen_run(&run_dir).unwrap();
            let given = LoadedConfig {
                config: config.clone(),
                text: String::new(),
                origin: "my.toml".into(),
                base_dir: dir.path().to_path_buf(),
            };
            adopt_settings_at_resume(&mut reopened, &given, &Default::default()).unwrap();
        }
    }

    #[test]
    fn the_resume_command_names_the_state_directory_as_one_shell_word() {
        assert_eq!(
            resume_command(Path::new("/tmp/cc/runs/20261203T1/journal.jsonl")),
            "chromacal calibrate --resume --state-dir /tmp/cc"
        );
        assert_eq!(
            resume_command(Path::new("/home/a b/it's/runs/r/journal.jsonl")),
            "chromacal calibrate --resume --state-dir '/home/a b/it'\\''s'"
        );
        assert_eq!(
            resume_command(Path::new("runs/r/journal.jsonl")),
            "chromacal calibrate --resume"
        );
    }
}
