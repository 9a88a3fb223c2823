//! What the daemon tells its subscribers (`GET /events`, MQTT), and the job status
//! that `GET /status` shows. On the wire each event also names its `device`.

use serde::{Deserialize, Serialize};

use crate::calibrate::warmup::WarmupStep;
use crate::profile::store::{HistoryEntry, VerificationRecord};
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::measurement::Role;

/// The jobs the daemon runs, one at a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobKind {
    /// A whole calibration, published if it passes the limits.
    Calibrate,
    /// A few patches compared with the current profile; past the threshold it starts a
    /// calibration.
    Verify,
    /// The uniformity grid alone: a new spatial map for the current profile.
    Uniformity,
}

impl JobKind {
    pub fn name(self) -> &'static str {
        match self {
            JobKind::Calibrate => "calibrate",
            JobKind::Verify => "verify",
            JobKind::Uniformity => "uniformity",
        }
    }

    pub fn parse(text: &str) -> Result<JobKind, String> {
        match text {
            "calibrate" => Ok(JobKind::Calibrate),
            "verify" => Ok(JobKind::Verify),
            "uniformity" => Ok(JobKind::Uniformity),
            _ => Err(format!(
                "unknown job '{text}': calibrate, verify or uniformity"
            )),
        }
    }
}

/// The last reading of a running job.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LastReading {
    pub index: usize,
    pub role: Role,
    pub luminance: Option<f64>,
    /// CIE 1931 x, y.
    pub xy: Option<[f64; 2]>,
    /// ΔE00 between the reading and the current profile's prediction for it: how far
    /// the screen is from its profile now.
    pub delta_e00: Option<f64>,
}

/// A running job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobStatus {
    pub id: String,
    pub kind: JobKind,
    /// Who started it: `api`, `schedule`, `escalation`, `resume`.
    pub origin: String,
    /// RFC 3339.
    pub started: String,
    /// `starting`, `warming up`, `measuring`, `fitting`.
    pub phase: String,
    /// Readings in the job's journal, and how many it plans.
    pub done: usize,
    pub total: usize,
    /// Seconds left, from the pace of this job's readings so far.
    pub eta_s: Option<f64>,
    pub last: Option<LastReading>,
}

/// How a job ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobOutcome {
    /// `ok`, `failed`, `cancelled` (by request; not resumed) or `interrupted` (by
    /// shutdown; resumed at the next start).
    pub result: String,
    pub message: String,
    /// The profile a calibration or uniformity job made.
    pub profile_id: Option<String>,
    /// That profile became current.
    pub published: bool,
    /// A verification past its threshold started a calibration.
    pub escalated: bool,
}

/// One event on `GET /events` (the SSE event name is `event`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    JobStarted {
        job: JobStatus,
    },
    Warmup {
        job_id: String,
        step: WarmupStep,
    },
    Progress {
        job: JobStatus,
    },
    JobFinished {
        job: JobStatus,
        outcome: JobOutcome,
    },
    Published {
        profile_id: String,
        how: String,
        held_out: Option<ErrorStats>,
    },
    Verification {
        record: VerificationRecord,
    },
    RolledBack {
        entry: HistoryEntry,
    },
    /// A job failed because the display or the instrument did (`fault`: `open`,
    /// `warmup`, `instrument`, `display`); they are opened again for the next job.
    DeviceLost {
        fault: String,
        message: String,
    },
    /// The keeper loaded the current profile's curves into a window device's video
    /// LUT (`reason`: start, a job ended, published, rolled back, the X screen changed,
    /// resume from suspend, the LUT was overwritten).
    LutLoaded {
        output: String,
        profile_id: String,
        reason: String,
    },
    /// Something else wrote the video LUT: it was `steps` (of 65535) away from the
    /// curves loaded; `reloading` with `display.keep_lut`.
    LutOverwritten {
        output: String,
        steps: f64,
        reloading: bool,
    },
    ShuttingDown,
    /// The daemon reread its config (`origin`: `SIGHUP` or `api`): devices `added`
    /// (started now), `removed` and `changed` (each retired after its running job, a
    /// changed one then started on its new config), and the sections whose changes
    /// wait for a restart (`[daemon]`'s listeners and limits, `[mqtt]`). A daemon-wide
    /// event: its `device` is empty.
    ConfigReloaded {
        origin: String,
        added: Vec<String>,
        removed: Vec<String>,
        changed: Vec<String>,
        restart_needed: Vec<String>,
    },
    /// The config reread was refused; the daemon runs on with the one it had.
    ConfigRefused {
        origin: String,
        error: String,
    },
}

impl Event {
    /// The SSE event name.
    pub fn name(&self) -> &'static str {
        match self {
            Event::JobStarted { .. } => "job_started",
            Event::Warmup { .. } => "warmup",
            Event::Progress { .. } => "progress",
            Event::JobFinished { .. } => "job_finished",
            Event::Published { .. } => "published",
            Event::Verification { .. } => "verification",
            Event::RolledBack { .. } => "rolled_back",
            Event::DeviceLost { .. } => "device_lost",
            Event::LutLoaded { .. } => "lut_loaded",
            Event::LutOverwritten { .. } => "lut_overwritten",
            Event::ShuttingDown => "shutting_down",
            Event::ConfigReloaded { .. } => "config_reloaded",
            Event::ConfigRefused { .. } => "config_refused",
        }
    }
}

/// An event as JSON with the `device` it is of: what `GET /events` and MQTT send.
pub fn event_json(device: &str, event: &Event) -> serde_json::Value {
    let mut value = serde_json::to_value(event).unwrap_or_default();
    if let serde_json::Value::Object(map) = &mut value {
        map.insert("device".into(), device.into());
    }
    value
}
