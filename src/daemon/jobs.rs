//! What the daemon's jobs do, on a device's display and instrument: calibrate (or resume a
//! calibration), verify the current profile, measure the uniformity grid again; the
//! warm-up wait before each; and the scheduler that starts verifications.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime};

use super::Device;
use super::events::{Event, JobKind, JobOutcome, LastReading};
use crate::calibrate::devices::{Devices, open_devices, release_instrument, reopen_instrument};
use crate::calibrate::run::{Progress, RunError, RunHooks, RunOptions, run_plan};
use crate::calibrate::session::{
    CalibrateError, discard_run, finish_run, new_run_id, now_rfc3339, reopen_run, start_run,
};
use crate::calibrate::warmup::wait_for_warmup;
use crate::journal::{JOURNAL_FORMAT, JOURNAL_VERSION, Journal, JournalHeader};
use crate::profile::store::VerificationRecord;
use crate::profile::{Profile, Provenance, SCHEMA_VERSION};
use crate::verify::Metric;
use chromacal_color::ictcp::delta_e_itp;
use chromacal_color::spaces::xyz_to_xyy;
use chromacal_display::PatchDisplay;
use chromacal_formats::time::TimeSource;
use chromacal_instruments::{Instrument, ReadingStatus};
use chromacal_model::fit::FitError;
use chromacal_model::fit::cancel::StopCheck;
use chromacal_model::fit::primaries::Corrected;
use chromacal_model::fit::spatial::choose_spatial_map;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::{delta_e00_xyz, evaluate};
use chromacal_model::measurement::{Role, Units};
use chromacal_model::plan::{Plan, Signal, make_uniformity_plan, make_verification_plan};
use chromacal_model::{MonitorModel, ScreenPosition};

/// A job id: the kind and a run id.
pub fn new_job_id(kind: JobKind) -> String {
    format!("{}-{}", kind.name(), new_run_id())
}

/// Why a job failed; the message is what the API reports.
struct JobFailure {
    message: String,
    /// What of the devices failed (`open`, `warmup`, `instrument`, `display`): they
    /// are opened again before the next job, and the fault is counted and told.
    fault: Option<&'static str>,
    /// Stopped on request rather than failed.
    stopped: bool,
}

impl From<CalibrateError> for JobFailure {
    fn from(e: CalibrateError) -> Self {
        let stopped = matches!(
            &e,
            CalibrateError::Run {
                source: RunError::Stopped { .. },
                ..
            } | CalibrateError::Fit(FitError::Stopped)
        );
        let fault = match &e {
            CalibrateError::Run {
                source: RunError::Display(_),
                ..
            } => Some("display"),
            CalibrateError::Run {
                source: RunError::Instrument { .. },
                ..
            } => Some("instrument"),
            CalibrateError::Devices(_) => Some("open"),
            _ => None,
        };
        let message = match &e {
            // The journal's whereabouts and `--resume` are for the command line; the
            // daemon resumes by itself.
            CalibrateError::Run { source, .. } => source.to_string(),
            other => other.to_string(),
        };
        JobFailure {
            message,
            fault,
            stopped,
        }
    }
}

impl From<String> for JobFailure {
    fn from(message: String) -> Self {
        JobFailure {
            message,
            fault: None,
            stopped: false,
        }
    }
}

/// What a job made.
#[derive(Default)]
struct JobSuccess {
    message: String,
    profile_id: Option<String>,
    published: bool,
    escalated: bool,
}

/// Run one job to its end and say how it ended.
pub(crate) async fn run_job(
    device: &Arc<Device>,
    kind: JobKind,
    id: &str,
    resume: Option<PathBuf>,
    cancel: &Arc<AtomicBool>,
) -> JobOutcome {
    let stop: StopCheck = {
        let device = device.clone();
        let cancel = cancel.clone();
        Arc::new(move || cancel.load(Ordering::SeqCst) || device.is_shutting_down())
    };
    // A shared instrument is one device's at a time: wait for its turn (or a stop).
    let turn = match &device.shared_instrument {
        Some((name, turn)) => match wait_for_turn(device, name, turn, &stop).await {
            Some(guard) => Some(guard),
            None => {
                return stopped_outcome(kind, cancel, "stopped while waiting for the instrument");
            }
        },
        None => None,
    };
    let mut guard = device.hardware.lock().await;
    let result = match ensure_devices(device, &mut guard).await {
        Err(message) => Err(JobFailure {
            message,
            fault: Some("open"),
            stopped: false,
        }),
        Ok(devices) => {
            age_while_idle(device, devices);
            // A window follows its output (a mode may have changed since the last
            // job), saves the ramp it finds and measures through the straight one;
            // the ramp goes back when the job ends, and the LUT keeper loads the
            // current curves after that.
            if let Some(window) = devices.display.window()
                && let Err(e) = window.refresh()
            {
                tracing::warn!(device = %device.name, error = %e, "the window's output");
            }
            if let Err(e) = crate::calibrate::video_lut::hold(device.store.root(), devices) {
                tracing::warn!(device = %device.name, error = %e, "cannot hold the video LUT for the job");
            }
            match warm_up(device, id, devices, &stop).await {
                Err(message) => Err(JobFailure {
                    message,
                    fault: Some("warmup"),
                    stopped: false,
                }),
                Ok(()) => match kind {
                    JobKind::Calibrate => calibrate(device, id, devices, resume, &stop).await,
                    JobKind::Verify => verify(device, id, devices, &stop).await,
                    JobKind::Uniformity => uniformity(device, id, devices, &stop).await,
                },
            }
        }
    };
    // A shared instrument lets go of its port for the next device that takes its
    // turn (which opens it again, as a meter moved by hand is plugged in again); the
    // display stays.
    if turn.is_some()
        && let Some(hardware) = guard.as_mut()
    {
        release_instrument(hardware);
    }
    drop(turn);
    // The window leaves the screen, and its LUT, to the user between jobs.
    if let Some(hardware) = guard.as_mut() {
        if let Err(e) = crate::calibrate::video_lut::release(
            device.store.root(),
            hardware,
            crate::calibrate::video_lut::RunEnd::Unpublished,
        ) {
            tracing::warn!(device = %device.name, error = %e, "cannot put the video LUT back after the job");
        }
        if let Some(window) = hardware.display.window() {
            window.hide();
        }
    }
    match result {
        Ok(success) => JobOutcome {
            result: "ok".into(),
            message: success.message,
            profile_id: success.profile_id,
            published: success.published,
            escalated: success.escalated,
        },
        Err(failure) => {
            if let Some(fault) = failure.fault {
                if let Some(devices) = guard.take() {
                    devices.instrument.close();
                }
                device.emit(Event::DeviceLost {
                    fault: fault.to_string(),
                    message: failure.message.clone(),
                });
            }
            match failure.stopped {
                true => stopped_outcome(kind, cancel, &failure.message),
                false => JobOutcome {
                    result: "failed".into(),
                    message: failure.message,
                    profile_id: None,
                    published: false,
                    escalated: false,
                },
            }
        }
    }
}

/// How a job stopped on request ended: `cancelled` (given up) or, stopped by the
/// daemon's shutdown, `interrupted` (a calibration then resumes at the next start).
fn stopped_outcome(kind: JobKind, cancel: &AtomicBool, why: &str) -> JobOutcome {
    let cancelled = cancel.load(Ordering::SeqCst);
    let message = match (cancelled, kind) {
        (false, JobKind::Calibrate) => {
            format!("{why}; the calibration resumes when the daemon starts again")
        }
        _ => why.to_string(),
    };
    JobOutcome {
        result: if cancelled {
            "cancelled"
        } else {
            "interrupted"
        }
        .into(),
        message,
        profile_id: None,
        published: false,
        escalated: false,
    }
}

/// Wait for the turn on a shared instrument; `None` if the job is stopped first. A
/// job that waits says so in its phase, and tells the subscribers.
async fn wait_for_turn<'a>(
    device: &Device,
    name: &str,
    turn: &'a tokio::sync::Mutex<()>,
    stop: &StopCheck,
) -> Option<tokio::sync::MutexGuard<'a, ()>> {
    if let Ok(guard) = turn.try_lock() {
        return Some(guard);
    }
    if let Some(job) = device.update_job(|j| j.phase = format!("waiting for the instrument {name}"))
    {
        device.emit(Event::Progress { job });
    }
    // The same lock future throughout, so the job keeps its place in the queue.
    let lock = turn.lock();
    tokio::pin!(lock);
    loop {
        tokio::select! {
            guard = &mut lock => return (!stop()).then_some(guard),
            _ = tokio::time::sleep(Duration::from_millis(100)) => {
                if stop() {
                    return None;
                }
            }
        }
    }
}

/// The held devices, opened now if they are not open.
async fn ensure_devices<'a>(
    device: &Device,
    slot: &'a mut Option<Devices>,
) -> Result<&'a mut Devices, String> {
    if let Some(devices) = slot.as_mut() {
        // An instrument shared with other displays was let go of after the last job.
        reopen_instrument(devices, &device.loaded.config)
            .await
            .map_err(|e| format!("cannot open the instrument: {e}"))?;
    }
    if slot.is_none() {
        let config = &device.loaded.config;
        let devices = open_devices(
            config,
            &device.loaded.base_dir,
            Some(config.daemon.simulated_time_scale),
        )
        .await
        .map_err(|e| format!("cannot open the devices: {e}"))?;
        tracing::info!(device = %device.name, display = %devices.display.name(), instrument = %devices.instrument.info().name, "devices open");
        *slot = Some(devices);
    }
    slot.as_mut()
        .ok_or_else(|| "the devices are not open".to_string())
}

/// Let the simulated monitor's clock catch up with the time no job ran.
fn age_while_idle(device: &Device, devices: &Devices) {
    let config = &device.loaded.config.daemon;
    if !config.simulated_idle_ages {
        return;
    }
    if let (Some(clock), Ok(idle)) = (&devices.virtual_clock, device.idle_since.lock()) {
        clock.advance(idle.elapsed().as_secs_f64() / config.simulated_time_scale);
    }
}

/// Wait for warm-up if the config asks for it.
async fn warm_up(
    device: &Arc<Device>,
    id: &str,
    devices: &mut Devices,
    stop: &StopCheck,
) -> Result<(), String> {
    let config = &device.loaded.config;
    if !config.warmup.enabled {
        return Ok(());
    }
    device.update_job(|j| j.phase = "warming up".into());
    let clock = devices.clock.clone();
    let virtual_clock = devices.virtual_clock.clone();
    let now = move || clock.now();
    let wait = |s: f64| {
        let virtual_clock = virtual_clock.clone();
        async move {
            match virtual_clock {
                Some(c) => c.wait(s).await,
                None => tokio::time::sleep(Duration::from_secs_f64(s.max(0.0))).await,
            }
        }
    };
    let job_id = id.to_string();
    let mut on_step = |step: &crate::calibrate::warmup::WarmupStep| {
        device.emit(Event::Warmup {
            job_id: job_id.clone(),
            step: *step,
        });
    };
    let outcome = wait_for_warmup(
        &config.warmup,
        config.plan.bit_depth,
        &mut devices.display,
        &mut devices.instrument,
        &now,
        wait,
        &mut on_step,
        stop.as_ref(),
    )
    .await?;
    tracing::info!(
        device = %device.name,
        readings = outcome.steps.len(),
        settled = outcome.settled,
        "warm-up done"
    );
    Ok(())
}

/// The current profile, if there is one that reads.
pub(crate) fn current_profile(device: &Device) -> Option<Profile> {
    let path = device.store.current_path();
    if !path.exists() {
        return None;
    }
    match Profile::read(&path) {
        Ok(p) => Some(p),
        Err(e) => {
            tracing::warn!(device = %device.name, error = %e, "the current profile does not read");
            None
        }
    }
}

/// A progress handler that updates the job status (with an ETA from this job's pace
/// and the ΔE00 against the current profile) and tells subscribers; `after_last` is
/// the phase once every planned patch is read (the job then fits, or compares), until
/// another is planned.
fn progress_handler<'a>(
    device: &'a Arc<Device>,
    current: Option<&'a MonitorModel>,
    clock: Arc<dyn TimeSource>,
    after_last: &'static str,
) -> impl FnMut(&Progress) + Send + 'a {
    let started = Instant::now();
    let mut measured_here = 0usize;
    move |p: &Progress| {
        measured_here += 1;
        // Full white at the centre: the white luminance, and its drift on the device's
        // own clock (simulated seconds for a simulated monitor).
        let white = (p.status == ReadingStatus::Ok
            && p.drive.iter().all(|d| *d >= 1.0 - 1e-9)
            && p.position == ScreenPosition::CENTRE)
            .then(|| p.luminance.or(p.xyz.map(|x| x.y)))
            .flatten();
        device
            .bus
            .metrics
            .reading(&device.name, p.status, white, clock.now());
        let per_patch = started.elapsed().as_secs_f64() / measured_here as f64;
        let delta_e00 = match (current, p.xyz) {
            (Some(model), Some(xyz)) if p.status == ReadingStatus::Ok => {
                let predicted = model.forward(p.drive, p.position);
                Some(delta_e00_xyz(&xyz, &predicted, &model.white()))
            }
            _ => None,
        };
        let last = LastReading {
            index: p.index,
            role: p.role,
            luminance: p.luminance,
            xy: p.xyz.map(|x| {
                let v = xyz_to_xyy(&x, [0.3127, 0.3290]);
                [v.x, v.y]
            }),
            delta_e00,
        };
        if let Some(job) = device.update_job(|j| {
            j.phase = match p.total > 0 && p.done >= p.total {
                true => after_last.into(),
                false => "measuring".into(),
            };
            j.done = p.done;
            j.total = p.total;
            j.eta_s = Some(per_patch * p.total.saturating_sub(p.done) as f64);
            j.last = Some(last);
        }) {
            device.emit(Event::Progress { job });
        }
    }
}

async fn calibrate(
    device: &Arc<Device>,
    _id: &str,
    devices: &mut Devices,
    resume: Option<PathBuf>,
    stop: &StopCheck,
) -> Result<JobSuccess, JobFailure> {
    let store = &device.store;
    let run = match &resume {
        Some(dir) => reopen_run(dir)?,
        None => start_run(
            store,
            &device.loaded.config,
            &device.loaded.base_dir,
            devices.display.name(),
            devices.instrument.info(),
        )?,
    };
    let already = run.journal.entries().len();
    let run_dir = run.journal.path().parent().map(PathBuf::from);
    if let Some(dir) = &run_dir
        && let Err(e) = crate::calibrate::session::mark_daemon_run(dir)
    {
        tracing::warn!(error = %e, "cannot mark the run as the daemon's");
    }
    let current = current_profile(device);
    let mut progress = progress_handler(
        device,
        current.as_ref().map(|p| &p.model),
        devices.clock.clone(),
        "fitting",
    );
    let mut hooks = RunHooks {
        progress: &mut progress,
        prompt: None,
        stop: Some(stop.clone()),
    };
    device.update_job(|j| {
        j.phase = "measuring".into();
        j.done = already;
    });
    match finish_run(run, devices, store, &mut hooks).await {
        Ok(outcome) => {
            let published = outcome.rejection.is_none();
            if published {
                device.emit(Event::Published {
                    profile_id: outcome.run_id.clone(),
                    how: "calibration".into(),
                    held_out: outcome.fitted.report.held_out,
                });
            }
            Ok(JobSuccess {
                message: match &outcome.rejection {
                    None => format!(
                        "published {} ({} patches, {} measured now)",
                        outcome.run_id,
                        outcome.plan.patches.len(),
                        outcome.run.measured_now
                    ),
                    Some(why) => format!("kept {} but not published: {why}", outcome.run_id),
                },
                profile_id: Some(outcome.run_id),
                published,
                escalated: false,
            })
        }
        Err(e) => {
            let failure = JobFailure::from(e);
            // A cancelled run is given up; one stopped by shutdown resumes at start.
            if failure.stopped
                && !device.is_shutting_down()
                && let Some(dir) = &run_dir
            {
                let _ = discard_run(dir);
            }
            Err(failure)
        }
    }
}

/// Measure `plan` into a fresh journal under `<state>/<folder>/<id>/`.
async fn measure_plan(
    device: &Arc<Device>,
    id: &str,
    folder: &str,
    plan: Plan,
    devices: &mut Devices,
    current: &MonitorModel,
    stop: &StopCheck,
) -> Result<Journal, JobFailure> {
    let config = &device.loaded.config;
    let header = JournalHeader {
        format: JOURNAL_FORMAT.into(),
        version: JOURNAL_VERSION,
        run_id: id.to_string(),
        started: now_rfc3339(),
        config_digest: device.loaded.digest(),
        config: device.loaded.text.clone(),
        config_dir: device.loaded.base_dir.clone(),
        display: devices.display.name(),
        instrument: devices.instrument.info(),
        units: Units::Absolute,
        plan,
    };
    let path = device
        .store
        .root()
        .join(folder)
        .join(id)
        .join("journal.jsonl");
    let mut journal = Journal::create(&path, header).map_err(|e| e.to_string())?;
    let after_last = match folder {
        "verifications" => "comparing with the profile",
        _ => "fitting",
    };
    let mut progress = progress_handler(device, Some(current), devices.clock.clone(), after_last);
    let mut hooks = RunHooks {
        progress: &mut progress,
        prompt: None,
        stop: Some(stop.clone()),
    };
    let options = RunOptions {
        stability: config.display.stability,
        ..RunOptions::default()
    };
    run_plan(
        &mut journal,
        &mut devices.display,
        &mut devices.instrument,
        devices.clock.as_ref(),
        &options,
        &mut hooks,
    )
    .await
    .map_err(|source| {
        JobFailure::from(CalibrateError::Run {
            source,
            journal: path.clone(),
        })
    })?;
    Ok(journal)
}

async fn verify(
    device: &Arc<Device>,
    id: &str,
    devices: &mut Devices,
    stop: &StopCheck,
) -> Result<JobSuccess, JobFailure> {
    let config = &device.loaded.config;
    let profile = current_profile(device)
        .ok_or_else(|| "there is no current profile to verify: calibrate first".to_string())?;
    // The readings are taken in the signal the config drives the display in; a
    // profile of another one (the config reloaded from PQ to HLG, say) cannot be
    // compared with them.
    let signal = config.plan.signal.filter(|s| s.is_hdr());
    let profiled = profile.provenance.signal.filter(|s| s.is_hdr());
    if signal != profiled {
        let name = |s: Option<Signal>| s.unwrap_or(Signal::Sdr).describe();
        return Err(format!(
            "the current profile {} is of a {} signal and the config drives the display as {}: calibrate again in this mode",
            profile.id,
            name(profiled),
            name(signal)
        )
        .into());
    }
    let mut plan = make_verification_plan(&config.plan, config.schedule.verify_patches)
        .map_err(|e| e.to_string())?;
    plan.signal = signal;
    let journal = measure_plan(
        device,
        id,
        "verifications",
        plan,
        devices,
        &profile.model,
        stop,
    )
    .await?;
    let usable: Vec<_> = journal
        .entries()
        .iter()
        .filter(|m| m.reading.status == ReadingStatus::Ok)
        .filter_map(|m| m.reading.xyz.map(|xyz| (m, xyz)))
        .collect();
    let evaluation = evaluate(&profile.model, usable);
    // A profile of an HDR signal is judged in ΔE ITP on absolute light, as it was
    // published: ΔE00 relative to an 800 cd/m² white does not see a 10 % change at
    // 0.5 cd/m².
    let metric = profile.judged_in();
    let (delta_e, threshold): (Vec<f64>, _) = match metric {
        Metric::Itp => (
            evaluation
                .patches
                .iter()
                .map(|p| delta_e_itp(&p.measured, &p.predicted))
                .collect(),
            config.schedule.threshold_itp,
        ),
        Metric::De00 => (
            evaluation.patches.iter().map(|p| p.delta_e00).collect(),
            config.schedule.threshold_de00,
        ),
    };
    let stats = ErrorStats::of(&delta_e);
    let past = stats.is_some_and(|s| !(s.mean <= threshold));
    // A profile with curves: the display as its user sees it, through them, judged
    // as `chromacal verify` judges it (and kept beside the profile).
    let through = match &profile.calibration {
        Some(_) if config.target.as_ref().is_none_or(|t| t.verify) => {
            Some(verify_through_curves(device, &profile, devices).await)
        }
        _ => None,
    };
    let failed =
        matches!(&through, Some(Ok(r)) if r.verdict == crate::verify::criteria::Verdict::Fail);
    let record = VerificationRecord {
        at: now_rfc3339(),
        profile_id: profile.id.clone(),
        metric,
        stats,
        delta_e,
        threshold,
        escalated: (past || failed) && config.schedule.escalate,
        journal: Some(crate::journal::stored_path(journal.path())),
        verdict: None,
    };
    device
        .store
        .append_verification(&record)
        .map_err(|e| e.to_string())?;
    device.emit(Event::Verification {
        record: record.clone(),
    });
    let mean = record.stats.map_or(f64::NAN, |s| s.mean);
    let calibrated = match &through {
        None => String::new(),
        Some(Ok(report)) => format!(
            "; through the curves: {} under {} (white {:.2} {} from the target, grey balance {:.2})",
            report.verdict.name(),
            report.criteria,
            report.state.white_delta_e,
            report.metric.name(),
            report.state.grey_balance_mean
        ),
        Some(Err(e)) => format!("; not verified through the curves: {e}"),
    };
    Ok(JobSuccess {
        message: format!(
            "profile {}: mean {} {mean:.3} over {} patches (threshold {threshold}){calibrated}{}",
            profile.id,
            metric.name(),
            record.delta_e.len(),
            if record.escalated {
                "; recalibrating"
            } else if past || failed {
                "; past the threshold (schedule.escalate is off)"
            } else {
                ""
            }
        ),
        profile_id: None,
        published: false,
        escalated: record.escalated,
    })
}

/// The current curves loaded (a window's video LUT; elsewhere they go in the codes),
/// then the default chart through them against sRGB under `[verify]`'s criteria.
async fn verify_through_curves(
    device: &Arc<Device>,
    profile: &Profile,
    devices: &mut Devices,
) -> Result<crate::verify::VerifyReport, String> {
    let config = &device.loaded.config;
    let curves = profile.calibration.as_ref().map(|c| &c.curves);
    crate::calibrate::video_lut::release(
        device.store.root(),
        devices,
        crate::calibrate::video_lut::RunEnd::Published {
            curves,
            why_no_curves: None,
        },
    )
    .map_err(|e| e.to_string())?;
    device.update_job(|j| j.phase = "verifying through the curves".into());
    let mut progress = |done: usize, total: usize| {
        device.update_job(|j| j.phase = format!("verifying through the curves: {done}/{total}"));
    };
    crate::calibrate::verify::after_calibration(
        &device.store,
        profile,
        &config.verify,
        config.plan.bit_depth,
        devices,
        &mut progress,
    )
    .await
    .map_err(|e| e.to_string())
}

/// Measure the uniformity grid again and give the current profile a new spatial map.
/// The grid readings are divided by the centre white of their time (interpolated
/// between the references around them), so the map carries no change of the whole
/// screen since the calibration.
async fn uniformity(
    device: &Arc<Device>,
    id: &str,
    devices: &mut Devices,
    stop: &StopCheck,
) -> Result<JobSuccess, JobFailure> {
    let config = &device.loaded.config;
    let profile = current_profile(device).ok_or_else(|| {
        "there is no current profile to give a spatial map: calibrate first".to_string()
    })?;
    let plan = make_uniformity_plan(&config.plan).map_err(|e| e.to_string())?;
    let journal = measure_plan(
        device,
        id,
        "uniformity",
        plan,
        devices,
        &profile.model,
        stop,
    )
    .await?;
    device.update_job(|j| j.phase = "fitting".into());
    let model = &profile.model;
    let predicted_white = model.forward([1.0; 3], ScreenPosition::CENTRE);
    // Ratio of measured to predicted centre white, at each reference's time.
    let references: Vec<(f64, f64)> = journal
        .entries()
        .iter()
        .filter(|m| m.role == Role::Reference && m.reading.status == ReadingStatus::Ok)
        .filter_map(|m| Some((m.time_s?, m.reading.xyz?.y / predicted_white.y)))
        .collect();
    if references.is_empty() || !(predicted_white.y > 0.0) {
        return Err("no usable reference white: the grid cannot be scaled"
            .to_string()
            .into());
    }
    let ratio_at = |t: Option<f64>| -> f64 {
        let Some(t) = t else {
            return references.iter().map(|r| r.1).sum::<f64>() / references.len() as f64;
        };
        let after = references.iter().position(|r| r.0 >= t);
        match after {
            Some(0) => references[0].1,
            None => references[references.len() - 1].1,
            Some(i) => {
                let (a, b) = (references[i - 1], references[i]);
                let w = if b.0 > a.0 {
                    (t - a.0) / (b.0 - a.0)
                } else {
                    0.5
                };
                a.1 + w * (b.1 - a.1)
            }
        }
    };
    // The grid readings, scaled to the centre white of their time.
    let grid: Vec<(
        chromacal_model::measurement::Measurement,
        chromacal_color::Xyz,
    )> = journal
        .entries()
        .iter()
        .filter(|m| m.role == Role::Uniformity && m.reading.status == ReadingStatus::Ok)
        .filter_map(|m| Some((m.clone(), m.reading.xyz? / ratio_at(m.time_s))))
        .collect();
    // A large grid takes seconds to fit: off the async workers, and stoppable.
    let (map, report) = {
        let model = model.clone();
        let noise = profile.report.noise.clone();
        let stop = stop.clone();
        tokio::task::spawn_blocking(move || {
            chromacal_model::fit::cancel::with_stop(Some(stop), || {
                let grid: Vec<Corrected<'_>> = grid
                    .iter()
                    .map(|(measurement, xyz)| Corrected {
                        measurement,
                        xyz: *xyz,
                    })
                    .collect();
                let chosen = choose_spatial_map(&model, &grid, &noise);
                (!chromacal_model::fit::cancel::requested()).then_some(chosen)
            })
        })
        .await
        .map_err(|e| format!("the spatial fit failed: {e}"))?
        .ok_or(JobFailure {
            message: "stopped while fitting the spatial map".into(),
            fault: None,
            stopped: true,
        })?
    };
    let chosen: Option<ErrorStats> = report
        .candidates
        .iter()
        .find(|c| c.chosen)
        .and_then(|c| c.cross_validation);
    let new_id = format!("{}-uniformity", new_run_id());
    let mut updated = profile.clone();
    updated.id = new_id.clone();
    updated.created = now_rfc3339();
    updated.model.spatial = map;
    updated.report.spatial = report;
    updated.provenance = Provenance {
        source: crate::journal::stored_path(journal.path()),
        program: format!("chromacal {}", env!("CARGO_PKG_VERSION")),
        ..profile.provenance.clone()
    };
    updated.schema_version = SCHEMA_VERSION;
    let text = updated.to_toml().map_err(|e| e.to_string())?;
    let limits = &config.publish;
    // The profile it replaces was held to the HDR half of the gate when published; a
    // profile published before that limit is held to it here.
    let rejection = limits
        .rejection(chosen.as_ref(), "the spatial map's cross-validated")
        .or_else(|| {
            limits.hdr_rejection(profile.provenance.signal, &profile.report.held_out_patches)
        });
    let passes = rejection.is_none();
    let store_error = |e: std::io::Error| format!("profile store: {e}");
    if passes {
        device
            .store
            .publish(
                &new_id,
                &text,
                profile.report.held_out.as_ref(),
                "uniformity",
            )
            .map_err(store_error)?;
        device.emit(Event::Published {
            profile_id: new_id.clone(),
            how: "uniformity".into(),
            held_out: profile.report.held_out,
        });
    } else {
        device.store.keep(&new_id, &text).map_err(store_error)?;
    }
    let cv = chosen.map_or("no score".to_string(), |s| {
        format!("leave-one-position-out mean ΔE00 {:.3}", s.mean)
    });
    Ok(JobSuccess {
        message: match &rejection {
            None => format!("published {new_id}: a new spatial map ({cv})"),
            Some(why) => {
                format!("kept {new_id} but not published: it misses the [publish] limits ({why})")
            }
        },
        profile_id: Some(new_id),
        published: passes,
        escalated: false,
    })
}

/// Start a verification every `schedule.verify_every_s`, skipping a turn while a job
/// runs; ends when the daemon stops or a reload retires the device.
pub(crate) async fn scheduler(device: Arc<Device>) {
    let Some(every) = device.loaded.config.schedule.verify_every_s else {
        return;
    };
    let every = Duration::from_secs_f64(every);
    loop {
        if let Ok(mut next) = device.next_verification.lock() {
            *next = Some(SystemTime::now() + every);
        }
        // Made before the flag is read: a retirement in between still wakes it.
        let retired = device.retired_notify.notified();
        if device.is_retired() {
            return;
        }
        tokio::select! {
            () = tokio::time::sleep(every) => {}
            () = retired => return,
        }
        if device.is_shutting_down() {
            return;
        }
        match device.start_job(JobKind::Verify, "schedule", None) {
            Ok(_) => {}
            Err(e) => {
                tracing::info!(device = %device.name, reason = %e, "scheduled verification skipped")
            }
        }
    }
}
