//! `chromacal daemon`: a service that holds the instrument and the patch display, runs
//! one job at a time (calibrate, verify, uniformity), verifies on a schedule and
//! recalibrates when the screen has moved, and answers a control API while it works.
//!
//! * `api.rs`: the HTTP control API (unix socket, optionally loopback TCP with a token).
//! * `jobs.rs`: what each job does, on the held devices.
//! * `events.rs`: the events subscribers hear and the job status.
//! * `client.rs`: the client the `chromacal status`/`job`/… commands use.
//! * `notify.rs`: systemd's readiness and watchdog notifications.
//!
//! A job's readings go to a journal as they are taken (see `calibrate::run`), so a
//! daemon stopped any way (SIGTERM, a crash, a power cut) resumes the calibration at its
//! next start with nothing lost or measured twice.

pub mod access;
pub mod api;
pub mod browser;
pub mod client;
pub mod events;
pub mod jobs;
pub mod lut;
pub mod metrics;
pub mod mqtt;
pub mod notify;
pub mod reload;
pub mod serve;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::{Duration, Instant};

use tokio::sync::broadcast;

use crate::calibrate::devices::Devices;
use crate::calibrate::session::{discard_run, newest_resumable, unfinished_runs};
use crate::config::devices::{NoDevice, find_device};
use crate::config::{DeviceConfig, LoadedConfig, OnStart, device_configs};
use crate::profile::Profile;
use crate::profile::store::ProfileStore;
use events::{Event, JobKind, JobStatus};

/// Why the daemon could not start or run.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{0}")]
    Config(String),
    #[error("another daemon already answers on {0}")]
    AlreadyRunning(PathBuf),
    #[error(transparent)]
    Store(#[from] crate::profile::store::StoreError),
}

/// Where the API socket is by default.
pub fn default_socket(state_dir: &Path) -> PathBuf {
    match std::env::var_os("RUNTIME_DIRECTORY").filter(|d| !d.is_empty()) {
        // systemd may give several directories, separated by ':'.
        Some(dirs) => {
            let dirs = dirs.to_string_lossy().into_owned();
            PathBuf::from(dirs.split(':').next().unwrap_or(&dirs)).join("api.sock")
        }
        None => state_dir.join("api.sock"),
    }
}

/// A job slot: the running job's status and its cancel flag.
struct RunningJob {
    status: JobStatus,
    cancel: Arc<AtomicBool>,
}

/// An event and the device it is of, as the bus carries it.
#[derive(Debug, Clone)]
pub struct DeviceEvent {
    pub device: String,
    pub event: Event,
}

impl DeviceEvent {
    /// The event as JSON, with its device: what `GET /events` and MQTT send.
    pub fn to_json(&self) -> serde_json::Value {
        events::event_json(&self.device, &self.event)
    }
}

/// What every device of the daemon shares: where events go (subscribers, metrics,
/// MQTT) and whether the daemon is stopping.
pub struct Bus {
    pub(crate) events: broadcast::Sender<DeviceEvent>,
    shutting_down: AtomicBool,
    pub(crate) metrics: Arc<metrics::Metrics>,
    /// Set once the devices' stores are locked and the socket bound: a daemon that
    /// cannot start never says it is online.
    mqtt: std::sync::OnceLock<Arc<mqtt::Mqtt>>,
    /// Resumes from suspend logind has told of: each LUT keeper loads its curves
    /// again when the count moves.
    pub(crate) resumes: AtomicU64,
}

impl Bus {
    /// A bus for `devices` devices: subscribers may fall behind by 256 events a
    /// device (and at least 1024) before they are told they missed some.
    pub fn new(metrics: Arc<metrics::Metrics>, devices: usize) -> Arc<Bus> {
        let (events, _) = broadcast::channel((256 * devices).max(1024));
        Arc::new(Bus {
            events,
            shutting_down: AtomicBool::new(false),
            metrics,
            mqtt: std::sync::OnceLock::new(),
            resumes: AtomicU64::new(0),
        })
    }

    /// Tell of an event of the whole daemon (a reload): counted by the metrics, sent
    /// on MQTT under the daemon's own topic, and to subscribers with no device.
    fn publish_daemon(&self, event: Event) {
        self.metrics.observe_daemon(&event);
        if let Some(mqtt) = self.mqtt.get() {
            mqtt.observe_daemon(&event);
        }
        let _ = self.events.send(DeviceEvent {
            device: String::new(),
            event,
        });
    }

    /// Tell the metrics, MQTT and the subscribers (in that order: a subscriber that
    /// hears of a job's end finds the metrics counting it).
    fn publish(&self, device: &str, event: Event) {
        tracing::debug!(device, event = event.name(), "event");
        self.metrics.observe(device, &event);
        if let Some(mqtt) = self.mqtt.get() {
            mqtt.observe(device, &event);
        }
        let _ = self.events.send(DeviceEvent {
            device: device.to_string(),
            event,
        });
    }
}

/// This machine's host name (the kernel's): the daemon's name in MQTT topics and on
/// the fleet's login page.
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok().filter(|h| !h.is_empty()))
        .unwrap_or_else(|| "localhost".into())
}

/// One display–instrument pair of the daemon, with its own config, store, schedule
/// and job slot (`[[device]]`; a config without them is one device).
pub struct Device {
    pub name: String,
    pub(crate) loaded: LoadedConfig,
    pub(crate) store: ProfileStore,
    /// Opened at the first job, kept between jobs, reopened after a device failure
    /// (and after every job when the instrument is shared).
    pub(crate) hardware: tokio::sync::Mutex<Option<Devices>>,
    /// A shared instrument's name and its turn: one job at a time on it.
    pub(crate) shared_instrument: Option<(String, Arc<tokio::sync::Mutex<()>>)>,
    job: Mutex<Option<RunningJob>>,
    last_outcome: Mutex<Option<(JobStatus, events::JobOutcome)>>,
    pub(crate) bus: Arc<Bus>,
    /// Told when the running job ends.
    job_done: tokio::sync::Notify,
    /// When the last job ended (or the daemon started).
    pub(crate) idle_since: Mutex<Instant>,
    next_verification: Mutex<Option<std::time::SystemTime>>,
    /// Set when a reload removed or changed the device: it takes no new job, and once
    /// its running job ends it leaves the daemon (and a changed one starts again).
    retired: AtomicBool,
    /// Told when the device is retired: its scheduler stops waiting.
    pub(crate) retired_notify: tokio::sync::Notify,
    /// The store's lock: held while the device serves, given back when a reload
    /// retires it (so that its successor can take it).
    store_lock: Mutex<Option<crate::profile::store::StoreLock>>,
}

/// Why a job was not started.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JobRefused {
    #[error("a {kind} job ({id}) is running on {device}; one job runs at a time on a device")]
    Busy {
        device: String,
        kind: &'static str,
        id: String,
    },
    #[error("the daemon is shutting down")]
    ShuttingDown,
    #[error("{0} is leaving the daemon: the config was reloaded without it or with it changed")]
    Retired(String),
}

impl Device {
    /// The current profile and its text; an error says why it does not read.
    pub fn read_current(&self) -> Result<Option<(Profile, String)>, String> {
        let path = self.store().current_path();
        let text = match chromacal_formats::durable::read_text_limited(
            &path,
            chromacal_formats::durable::limits::PROFILE,
        ) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("{}: {e}", path.display())),
        };
        let profile =
            Profile::from_toml(&text, &path.display().to_string()).map_err(|e| e.to_string())?;
        // Its id names files in the store (its verification, its history entry): one
        // another hand wrote must not reach outside it.
        if !crate::profile::store::is_valid_id(&profile.id) {
            return Err(format!(
                "{}: {}",
                path.display(),
                crate::profile::store::StoreError::InvalidId(profile.id)
            ));
        }
        Ok(Some((profile, text)))
    }

    /// A device on `store`, holding its lock (`ProfileStore::lock`) while it lives.
    pub fn new(
        config: DeviceConfig,
        store: ProfileStore,
        store_lock: crate::profile::store::StoreLock,
        instrument_turn: Option<Arc<tokio::sync::Mutex<()>>>,
        bus: Arc<Bus>,
    ) -> Arc<Self> {
        Arc::new(Device {
            shared_instrument: config.shared_instrument.zip(instrument_turn),
            name: config.name,
            loaded: config.loaded,
            store,
            hardware: tokio::sync::Mutex::new(None),
            job: Mutex::new(None),
            last_outcome: Mutex::new(None),
            bus,
            job_done: tokio::sync::Notify::new(),
            idle_since: Mutex::new(Instant::now()),
            next_verification: Mutex::new(None),
            retired: AtomicBool::new(false),
            retired_notify: tokio::sync::Notify::new(),
            store_lock: Mutex::new(Some(store_lock)),
        })
    }

    /// Whether a reload retired it.
    pub fn is_retired(&self) -> bool {
        self.retired.load(Ordering::SeqCst)
    }

    /// Take no new job; the running one carries on to its end.
    fn retire(&self) {
        self.retired.store(true, Ordering::SeqCst);
        self.retired_notify.notify_waiters();
    }

    pub fn store(&self) -> &ProfileStore {
        &self.store
    }

    pub(crate) fn emit(&self, event: Event) {
        self.bus.publish(&self.name, event);
    }

    pub fn is_shutting_down(&self) -> bool {
        self.bus.shutting_down.load(Ordering::SeqCst)
    }

    /// The running job's status.
    pub fn job(&self) -> Option<JobStatus> {
        self.job
            .lock()
            .ok()
            .and_then(|j| j.as_ref().map(|r| r.status.clone()))
    }

    pub(crate) fn update_job(&self, update: impl FnOnce(&mut JobStatus)) -> Option<JobStatus> {
        let mut slot = self.job.lock().ok()?;
        let running = slot.as_mut()?;
        update(&mut running.status);
        Some(running.status.clone())
    }

    pub fn last_outcome(&self) -> Option<(JobStatus, events::JobOutcome)> {
        self.last_outcome.lock().ok().and_then(|o| o.clone())
    }

    pub fn next_verification(&self) -> Option<std::time::SystemTime> {
        self.next_verification.lock().ok().and_then(|n| *n)
    }

    /// The store's last verification, if it is of profile `id` (one of an earlier
    /// profile says nothing of this one).
    pub fn last_verification_of(
        &self,
        id: &str,
    ) -> Option<crate::profile::store::VerificationRecord> {
        self.store
            .verifications()
            .ok()
            .and_then(|v| v.last().cloned())
            .filter(|v| v.profile_id == id)
    }

    /// Give the metrics and MQTT what the store holds: the current profile, the last
    /// calibration, and the last verification if it is of the current profile.
    fn restore_figures(&self) {
        let profile = jobs::current_profile(self);
        // The last calibration published (the current profile may be a new spatial
        // map of it, or one rolled back to).
        let calibrated = self.store.history().ok().and_then(|h| {
            let entry = h.entries.iter().rev().find(|e| e.how == "calibration")?;
            chromacal_formats::time::parse_rfc3339(&entry.at)
        });
        let verification = profile
            .as_ref()
            .and_then(|p| self.last_verification_of(&p.id));
        let held_out = profile.as_ref().and_then(|p| p.report.held_out);
        self.bus.metrics.restore(
            &self.name,
            held_out,
            calibrated,
            verification
                .as_ref()
                .and_then(|v| Some((chromacal_formats::time::parse_rfc3339(&v.at)?, v))),
            &self.loaded.config.schedule,
        );
        if let Some(mqtt) = self.bus.mqtt.get() {
            mqtt.restore(
                &self.name,
                profile
                    .as_ref()
                    .map(|p| (p.id.as_str(), held_out, p.created.as_str())),
                verification.as_ref(),
            );
        }
    }

    /// Start a job unless one runs. `resume` names an unfinished calibration run.
    pub fn start_job(
        self: &Arc<Self>,
        kind: JobKind,
        origin: &str,
        resume: Option<PathBuf>,
    ) -> Result<JobStatus, JobRefused> {
        if self.is_shutting_down() {
            return Err(JobRefused::ShuttingDown);
        }
        if self.is_retired() {
            return Err(JobRefused::Retired(self.name.clone()));
        }
        let mut slot = self.job.lock().map_err(|_| JobRefused::ShuttingDown)?;
        if let Some(running) = slot.as_ref() {
            return Err(JobRefused::Busy {
                device: self.name.clone(),
                kind: running.status.kind.name(),
                id: running.status.id.clone(),
            });
        }
        let status = JobStatus {
            id: jobs::new_job_id(kind),
            kind,
            origin: origin.to_string(),
            started: chromacal_formats::time::now_rfc3339(),
            phase: "starting".into(),
            done: 0,
            total: 0,
            eta_s: None,
            last: None,
        };
        let cancel = Arc::new(AtomicBool::new(false));
        *slot = Some(RunningJob {
            status: status.clone(),
            cancel: cancel.clone(),
        });
        drop(slot);
        tracing::info!(device = %self.name, job = %status.id, kind = kind.name(), origin, "job started");
        self.emit(Event::JobStarted {
            job: status.clone(),
        });
        let device = self.clone();
        let id = status.id.clone();
        tokio::spawn(async move {
            let outcome = jobs::run_job(&device, kind, &id, resume, &cancel).await;
            // Old job folders go once the job is over (none of this device's runs).
            {
                let device = device.clone();
                let _ = tokio::task::spawn_blocking(move || {
                    crate::calibrate::retention::prune_finished(device.store())
                })
                .await;
            }
            if let Ok(mut idle) = device.idle_since.lock() {
                *idle = Instant::now();
            }
            let finished = device.job.lock().ok().and_then(|mut s| s.take());
            let status = finished.map(|r| r.status);
            if let Some(status) = &status {
                tracing::info!(
                    device = %device.name,
                    job = %status.id,
                    result = %outcome.result,
                    message = %outcome.message,
                    "job finished"
                );
                if let Ok(mut last) = device.last_outcome.lock() {
                    *last = Some((status.clone(), outcome.clone()));
                }
                device.emit(Event::JobFinished {
                    job: status.clone(),
                    outcome: outcome.clone(),
                });
            }
            device.job_done.notify_waiters();
            if outcome.escalated
                && let Err(e) = device.start_job(JobKind::Calibrate, "escalation", None)
            {
                tracing::warn!(device = %device.name, error = %e, "the verification asked for a recalibration that could not start");
            }
        });
        Ok(status)
    }

    /// Ask the running job to stop after the reading under way. Its run is given up.
    pub fn cancel_job(&self) -> Option<JobStatus> {
        let slot = self.job.lock().ok()?;
        let running = slot.as_ref()?;
        running.cancel.store(true, Ordering::SeqCst);
        Some(running.status.clone())
    }

    /// Wait until no job runs, at most until `deadline`. True if none runs.
    pub async fn wait_idle(&self, deadline: tokio::time::Instant) -> bool {
        loop {
            let notified = self.job_done.notified();
            if self.job().is_none() {
                return true;
            }
            if tokio::time::timeout_at(deadline, notified).await.is_err() {
                return self.job().is_none();
            }
        }
    }
}

/// The daemon: its devices and what they share.
pub struct Daemon {
    /// The config the daemon started with (its `[daemon]` and `[mqtt]` sections are
    /// the daemon's; a reload changes only the devices).
    pub(crate) loaded: LoadedConfig,
    /// The devices serving, in the config's order; a reload changes the list.
    devices: RwLock<Vec<Arc<Device>>>,
    pub(crate) bus: Arc<Bus>,
    started: Instant,
    /// Where the config came from, to read it again.
    options: DaemonOptions,
    /// The devices the newest accepted config describes: a retired device's successor
    /// is started from it when the retired one's job ends.
    wanted: Mutex<Vec<DeviceConfig>>,
    /// Each shared instrument's turn, kept across reloads.
    turns: Mutex<BTreeMap<String, Arc<tokio::sync::Mutex<()>>>>,
    /// One reload (or a retired device's replacement) at a time.
    reloading: tokio::sync::Mutex<()>,
}

impl Daemon {
    /// The devices serving now.
    pub fn devices(&self) -> Vec<Arc<Device>> {
        self.devices.read().map(|d| d.clone()).unwrap_or_default()
    }

    fn names(&self) -> String {
        self.devices()
            .iter()
            .map(|d| d.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The device named, or with `None` the only one.
    pub fn device(&self, name: Option<&str>) -> Result<Arc<Device>, NoDevice> {
        let devices = self.devices();
        find_device(&devices, name, |d| d.name.as_str()).cloned()
    }

    pub fn is_shutting_down(&self) -> bool {
        self.bus.shutting_down.load(Ordering::SeqCst)
    }

    pub fn uptime_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Stop taking jobs and ask the running ones to stop after their reading.
    pub fn begin_shutdown(&self) {
        self.bus.shutting_down.store(true, Ordering::SeqCst);
        for device in self.devices() {
            device.emit(Event::ShuttingDown);
        }
    }

    /// Wait until no job runs on any device, at most `timeout`. True if none runs.
    pub async fn wait_idle(&self, timeout: Duration) -> bool {
        let deadline = tokio::time::Instant::now() + timeout;
        let mut all = true;
        for device in self.devices() {
            all &= device.wait_idle(deadline).await;
        }
        all
    }
}

/// Options from the command line.
#[derive(Debug, Clone, Default)]
pub struct DaemonOptions {
    /// `--config`; none: the search paths, else the built-in config.
    pub config: Option<PathBuf>,
    pub state_dir: PathBuf,
    pub socket: Option<PathBuf>,
    pub tcp: Option<String>,
    /// `--time-scale`: `daemon.simulated_time_scale`.
    pub time_scale: Option<f64>,
}

impl DaemonOptions {
    /// Read the config the options name, with the options laid over it and checked as
    /// the daemon checks it: at the start and at every reload.
    pub fn load_config(&self) -> Result<LoadedConfig, String> {
        let mut loaded = crate::config::load_config_searching(
            self.config.as_deref(),
            &crate::config::config_search_paths(),
        )
        .map_err(|e| e.to_string())?;
        let daemon = &mut loaded.config.daemon;
        if let Some(socket) = &self.socket {
            daemon.socket = Some(socket.clone());
        }
        if let Some(tcp) = &self.tcp {
            daemon.tcp = Some(tcp.clone());
        }
        if let Some(scale) = self.time_scale {
            daemon.simulated_time_scale = scale;
        }
        crate::config::check_config(&loaded.config)?;
        Ok(loaded)
    }
}

/// Bind the unix socket at `path` with mode 0600, replacing a stale one.
fn bind_socket(path: &Path) -> Result<tokio::net::UnixListener, DaemonError> {
    use std::os::unix::fs::PermissionsExt;
    let io = |source| DaemonError::Io {
        path: path.to_path_buf(),
        source,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.exists()
    {
        std::fs::create_dir_all(dir).map_err(io)?;
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700)).map_err(io)?;
    }
    if path.exists() {
        if std::os::unix::net::UnixStream::connect(path).is_ok() {
            return Err(DaemonError::AlreadyRunning(path.to_path_buf()));
        }
        std::fs::remove_file(path).map_err(io)?;
    }
    let listener = tokio::net::UnixListener::bind(path).map_err(io)?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).map_err(io)?;
    Ok(listener)
}

/// The bearer token for TCP clients: read it, or make one (mode 0600).
fn load_or_create_token(path: &Path) -> Result<String, DaemonError> {
    use rand::RngCore;
    use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
    let io = |source| DaemonError::Io {
        path: path.to_path_buf(),
        source,
    };
    // A token others could read is no secret: an existing file is made 0600 before
    // its token is used or a new one is written into it. Says whether others could.
    let private = || -> Result<bool, DaemonError> {
        let mode = std::fs::metadata(path).map_err(io)?.permissions().mode();
        if mode & 0o077 == 0 {
            return Ok(false);
        }
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).map_err(|e| {
            DaemonError::Config(format!(
                "the API token file {} can be read by others (mode {:o}) and could not be made 0600: {e}",
                path.display(),
                mode & 0o777
            ))
        })?;
        tracing::warn!(path = %path.display(), "the API token file could be read by others; made it 0600");
        Ok(true)
    };
    if std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
        return Err(DaemonError::Config(format!(
            "the API token file {} is a symbolic link; give a regular file",
            path.display()
        )));
    }
    match chromacal_formats::durable::read_text_limited(
        path,
        chromacal_formats::durable::limits::PROFILE,
    ) {
        Ok(text) if !text.trim().is_empty() => {
            // Others could read it, so it may be known; but it is the user's, and
            // clients may hold it: never overwritten, the start refused instead.
            let mode = std::fs::metadata(path).map_err(io)?.permissions().mode();
            if mode & 0o077 != 0 {
                return Err(DaemonError::Config(format!(
                    "the API token file {} can be read by others (mode {:o}): if the token is still secret, `chmod 600 {}`; if not, delete the file and a new token is made",
                    path.display(),
                    mode & 0o777,
                    path.display()
                )));
            }
            return Ok(text.trim().to_string());
        }
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(io(e)),
    }
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    let token: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)
        .map_err(io)?;
    // `mode` applies only when the file is created; an empty one already there keeps
    // its mode unless changed here, before the secret is written.
    private()?;
    use std::io::Write;
    file.write_all(format!("{token}\n").as_bytes())
        .and_then(|()| file.sync_all())
        .map_err(io)?;
    Ok(token)
}

/// Open a device's store (its own folder with `[[device]]`, else the state directory
/// itself), holding its lock; `turns` gives devices sharing an instrument one turn.
fn open_device(
    config: DeviceConfig,
    keep_profiles: usize,
    state_dir: &Path,
    turns: &Mutex<BTreeMap<String, Arc<tokio::sync::Mutex<()>>>>,
    bus: &Arc<Bus>,
) -> Result<Arc<Device>, DaemonError> {
    let root = config.store_dir(state_dir);
    chromacal_formats::durable::keep_private(&root).map_err(|source| DaemonError::Io {
        path: root.clone(),
        source,
    })?;
    let store = ProfileStore::new(&root).keeping(keep_profiles);
    // Held while the device serves: no `calibrate` or second daemon writes this store
    // meanwhile.
    let lock = store.lock("chromacal daemon")?;
    refuse_a_simulation_over_a_measured_screen(&config, &store)?;
    // A calibration killed while it held a window's LUT left the user's ramp.
    chromacal_display::lut::restore_pending_logged(store.root());
    let turn = config.shared_instrument.as_ref().map(|name| {
        let mut turns = turns.lock().unwrap_or_else(|e| e.into_inner());
        turns.entry(name.clone()).or_default().clone()
    });
    Ok(Device::new(config, store, lock, turn, bus.clone()))
}

/// A config that measures the in-process simulated monitor, started on a store whose
/// current profile was measured on a real screen (`calibrate --display window
/// --instrument …` given on the command line, then `daemon` with the same file but
/// without them), would verify the simulation against that profile and report it
/// good, and recalibrate the simulation over it. Refused at start, naming both.
fn refuse_a_simulation_over_a_measured_screen(
    config: &DeviceConfig,
    store: &ProfileStore,
) -> Result<(), DaemonError> {
    if config.loaded.config.display.sink() != crate::config::Sink::Simulated {
        return Ok(());
    }
    let Ok(profile) = crate::profile::Profile::read(&store.current_path()) else {
        return Ok(());
    };
    let Some(display) = profile.provenance.display.as_deref() else {
        return Ok(());
    };
    if chromacal_display::simulated::is_simulated_display(display) {
        return Ok(());
    }
    let instrument = profile
        .provenance
        .instrument
        .as_ref()
        .map_or(String::new(), |i| format!(" with the {}", i.name));
    Err(DaemonError::Config(format!(
        "device {}: the current profile ({}, in {}) was measured on {display}{instrument}, but the config measures the in-process simulated monitor: give the daemon that screen's [display] sink and [instrument] driver and port (what --display and --instrument gave `calibrate`), or another --state-dir for a simulation",
        config.name,
        profile.id,
        store.root().display()
    )))
}

/// What a device tells before the API answers: its figures from the store (metrics,
/// MQTT), and its curves kept in the video LUT of a window device.
fn restore_device(device: &Arc<Device>) {
    device.restore_figures();
    lut::start(device);
}

/// A device's jobs: the calibration a stop cut short resumed, the schedule started.
fn start_device_jobs(device: &Arc<Device>) {
    resume_unfinished(device);
    tokio::spawn(jobs::scheduler(device.clone()));
}

/// Resume (or discard) the calibration a stop cut short on `device`.
fn resume_unfinished(device: &Arc<Device>) {
    let unfinished = unfinished_runs(&device.store);
    let resumed = newest_resumable(&unfinished).map(|run| run.dir.clone());
    let name = &device.name;
    for run in &unfinished {
        if !run.resumable() {
            tracing::warn!(device = %name, run = %run.id, failures = run.fit_failures, "not resuming a run whose fit failed twice (it is kept; `chromacal calibrate --resume RUN --device NAME` names it)");
        } else if Some(&run.dir) != resumed.as_ref() {
            tracing::warn!(device = %name, run = %run.id, readings = run.readings, "an older unfinished run is not resumed (`chromacal calibrate --resume RUN --device NAME` names it)");
        }
    }
    let Some(dir) = resumed else {
        return;
    };
    match device.loaded.config.daemon.on_start {
        OnStart::Resume => {
            tracing::info!(device = %name, run = %dir.display(), "resuming the calibration a stop cut short");
            if let Err(e) = device.start_job(JobKind::Calibrate, "resume", Some(dir)) {
                tracing::warn!(device = %name, error = %e, "cannot resume");
            }
        }
        OnStart::Discard => {
            tracing::warn!(device = %name, run = %dir.display(), "discarding the calibration a stop cut short (daemon.on_start = \"discard\")");
            if let Err(e) = discard_run(&dir) {
                tracing::warn!(device = %name, error = %e, "cannot mark the run discarded");
            }
        }
    }
}

/// Run the daemon until SIGTERM or SIGINT, rereading its config at each SIGHUP.
pub async fn run(loaded: LoadedConfig, options: DaemonOptions) -> Result<(), DaemonError> {
    crate::config::check_config(&loaded.config).map_err(DaemonError::Config)?;
    let config = loaded.config.daemon.clone();
    chromacal_formats::durable::keep_private(&options.state_dir).map_err(|source| {
        DaemonError::Io {
            path: options.state_dir.clone(),
            source,
        }
    })?;
    let configs = device_configs(&loaded).map_err(DaemonError::Config)?;
    let names: Vec<String> = configs.iter().map(|d| d.name.clone()).collect();
    let metrics = Arc::new(metrics::Metrics::new(names.iter().map(String::as_str)));
    let bus = Bus::new(metrics.clone(), names.len());
    let turns = Mutex::default();
    let devices = configs
        .iter()
        .map(|c| {
            open_device(
                c.clone(),
                config.keep_profiles,
                &options.state_dir,
                &turns,
                &bus,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let daemon = Arc::new(Daemon {
        loaded,
        devices: RwLock::new(devices),
        bus,
        started: Instant::now(),
        options: options.clone(),
        wanted: Mutex::new(configs),
        turns,
        reloading: tokio::sync::Mutex::new(()),
    });

    // The TCP listener is bound and its token written before the unix socket exists:
    // a client that finds the socket may go straight to TCP.
    let tcp =
        match &config.tcp {
            Some(address) => Some(tokio::net::TcpListener::bind(address).await.map_err(
                |source| DaemonError::Io {
                    path: PathBuf::from(address),
                    source,
                },
            )?),
            None => None,
        };
    let token = match &config.tcp {
        Some(_) => Some(load_or_create_token(
            &config
                .token_file
                .clone()
                .unwrap_or_else(|| options.state_dir.join("api.token")),
        )?),
        None => None,
    };
    let socket_path = config
        .socket
        .clone()
        .unwrap_or_else(|| default_socket(&options.state_dir));
    let unix = bind_socket(&socket_path)?;
    let owner = {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(&socket_path)
            .map_err(|source| DaemonError::Io {
                path: socket_path.clone(),
                source,
            })?
            .uid()
    };
    // MQTT once nothing else can stop the start: the stores are locked and the
    // socket is bound.
    let mqtt = match &daemon.loaded.config.mqtt {
        Some(mqtt) => Some(
            mqtt::Mqtt::start(mqtt, &daemon.loaded.base_dir, &names, metrics)
                .map_err(|e| DaemonError::Config(e.to_string()))?,
        ),
        None => None,
    };
    if let Some(mqtt) = &mqtt {
        let _ = daemon.bus.mqtt.set(mqtt.clone());
    }
    for device in daemon.devices() {
        restore_device(&device);
    }
    tokio::spawn(lut::watch_resume(daemon.bus.clone()));
    let app = api::router(daemon.clone(), access::Access { owner, token });
    serve::raise_descriptor_limit();
    tokio::spawn(serve::serve(
        serve::Listener::Unix(unix),
        app.clone(),
        serve::ConnectionLimits::local(&config),
    ));
    if let Some(listener) = tcp {
        if let Ok(addr) = listener.local_addr() {
            if !addr.ip().is_loopback() {
                tracing::warn!(%addr, "the control API listens beyond this machine (daemon.allow_remote)");
            }
            tracing::info!(%addr, "control API on TCP (bearer token required)");
        }
        tokio::spawn(serve::serve(
            serve::Listener::Tcp(listener),
            app,
            serve::ConnectionLimits::tcp(&config),
        ));
    }
    tracing::info!(socket = %socket_path.display(), state = %options.state_dir.display(), devices = %daemon.names(), "chromacal daemon ready");

    // Calibrations a stop cut short: on each device the newest that can be resumed.
    // The others are said, and listed in its status.
    for device in daemon.devices() {
        start_device_jobs(&device);
    }
    if let Some(interval) = notify::watchdog_interval() {
        tokio::spawn(async move {
            loop {
                notify::notify("WATCHDOG=1");
                tokio::time::sleep(interval / 2).await;
            }
        });
    }
    notify::notify("READY=1\nSTATUS=waiting for jobs");

    wait_for_stop_signal(&daemon).await;
    tracing::info!("stopping: finishing the readings under way");
    notify::notify("STOPPING=1\nSTATUS=stopping");
    daemon.begin_shutdown();
    let stopped = daemon
        .wait_idle(Duration::from_secs_f64(config.stop_timeout_s))
        .await;
    if !stopped {
        tracing::warn!(
            timeout_s = config.stop_timeout_s,
            "a job did not stop in time; exiting (its journal holds every reading taken)"
        );
    }
    // Leave the screens black and the instruments out of remote mode.
    for device in daemon.devices() {
        if let Ok(mut hardware) = device.hardware.try_lock()
            && let Some(hardware) = hardware.as_mut()
        {
            use chromacal_display::PatchDisplay;
            let _ = tokio::time::timeout(Duration::from_secs(2), hardware.display.blank()).await;
            hardware.instrument.close();
        }
    }
    if let Some(mqtt) = &mqtt {
        mqtt.stop(Duration::from_secs(2)).await;
    }
    let _ = std::fs::remove_file(&socket_path);
    tracing::info!("stopped");
    Ok(())
}

/// SIGTERM (systemd's stop) or SIGINT (Ctrl-C); each SIGHUP meanwhile rereads the
/// config (systemd's `ExecReload`).
async fn wait_for_stop_signal(daemon: &Arc<Daemon>) {
    use tokio::signal::unix::{SignalKind, signal};
    match (
        signal(SignalKind::terminate()),
        signal(SignalKind::interrupt()),
        signal(SignalKind::hangup()),
    ) {
        (Ok(mut term), Ok(mut int), Ok(mut hup)) => loop {
            tokio::select! {
                _ = term.recv() => return,
                _ = int.recv() => return,
                _ = hup.recv() => {
                    notify::notify("RELOADING=1\nSTATUS=reloading the config");
                    // The outcome is logged and told as an event either way.
                    let _ = daemon.reload("SIGHUP").await;
                    notify::notify("READY=1\nSTATUS=waiting for jobs");
                }
            }
        },
        _ => {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn mode(path: &Path) -> u32 {
        std::fs::metadata(path).unwrap().permissions().mode() & 0o777
    }

    #[test]
    fn the_token_file_is_always_0600() {
        let dir = tempfile::tempdir().unwrap();
        // Made fresh.
        let fresh = dir.path().join("fresh.token");
        let token = load_or_create_token(&fresh).unwrap();
        assert_eq!(token.len(), 64);
        assert_eq!(mode(&fresh), 0o600);
        // An empty file others can read gets the secret only once it is private.
        let empty = dir.path().join("empty.token");
        std::fs::write(&empty, "").unwrap();
        std::fs::set_permissions(&empty, std::fs::Permissions::from_mode(0o644)).unwrap();
        let token = load_or_create_token(&empty).unwrap();
        assert_eq!(mode(&empty), 0o600);
        assert_eq!(std::fs::read_to_string(&empty).unwrap().trim(), token);
        // A private token already there is used as it is.
        assert_eq!(load_or_create_token(&fresh).unwrap().len(), 64);
        std::fs::write(&fresh, "abc123\n").unwrap();
        assert_eq!(load_or_create_token(&fresh).unwrap(), "abc123");
        // One others could read may be known, but it is never overwritten: the start
        // is refused, saying what to do, and the file stays as it was.
        let open = dir.path().join("open.token");
        std::fs::write(&open, "abc123\n").unwrap();
        std::fs::set_permissions(&open, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = load_or_create_token(&open).unwrap_err().to_string();
        assert!(e.contains("mode 644") && e.contains("chmod 600"), "{e}");
        assert_eq!(std::fs::read_to_string(&open).unwrap(), "abc123\n");
        assert_eq!(mode(&open), 0o644);
        // A symbolic link is not followed to wherever it points.
        let link = dir.path().join("link.token");
        std::os::unix::fs::symlink(&open, &link).unwrap();
        assert!(load_or_create_token(&link).is_err());
    }
}
