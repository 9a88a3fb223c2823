//! `GET /metrics`: what the daemon knows of each device, in the Prometheus (OpenMetrics)
//! text format, written by the `prometheus-client` crate.
//!
//! Every figure is labelled with its `device`. They are kept up to date from the
//! daemon's own events (`observe`) and readings (`reading`), so a scrape costs no
//! file reads; the ages ("seconds since") are worked out at the scrape. A figure
//! the daemon does not know yet (no verification so far, say) has no series, rather
//! than a made-up value: `config/prometheus/alerts.yml` says how its rules treat that.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::AtomicU64;
use std::time::SystemTime;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;

use super::events::Event;
use crate::profile::store::VerificationRecord;
use crate::verify::Metric;
use chromacal_instruments::ReadingStatus;
use chromacal_model::fit::stats::ErrorStats;

/// The content type of the answer (OpenMetrics text, which Prometheus reads).
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// The content type of the classic text format (Prometheus exposition format 0.0.4).
pub const CLASSIC_CONTENT_TYPE: &str = "text/plain; version=0.0.4; charset=utf-8";

/// OpenMetrics text as the classic Prometheus text format reads it: a counter's
/// family is named with its `_total`, an info metric is a gauge named with its
/// `_info`, and OpenMetrics' own lines (`# UNIT`, `# EOF`) go. The samples are the
/// same lines.
pub fn to_classic_text(open_metrics: &str) -> String {
    let mut out = String::with_capacity(open_metrics.len());
    let mut help: Option<&str> = None;
    for line in open_metrics.lines() {
        if line == "# EOF" || line.starts_with("# UNIT ") {
            continue;
        }
        if line.starts_with("# HELP ") {
            help = Some(line);
            continue;
        }
        if let Some(rest) = line.strip_prefix("# TYPE ") {
            let (name, kind) = rest.split_once(' ').unwrap_or((rest, "untyped"));
            let (name, kind) = match kind {
                "counter" => (format!("{name}_total"), "counter"),
                "info" => (format!("{name}_info"), "gauge"),
                "gauge" | "histogram" | "summary" => (name.to_string(), kind),
                _ => (name.to_string(), "untyped"),
            };
            if let Some(h) = help.take() {
                let text = h
                    .strip_prefix("# HELP ")
                    .and_then(|r| r.split_once(' '))
                    .map_or("", |(_, text)| text);
                out.push_str(&format!("# HELP {name} {text}\n"));
            }
            out.push_str(&format!("# TYPE {name} {kind}\n"));
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// White readings kept per device for the drift.
const DRIFT_POINTS: usize = 64;
/// Only whites within this many seconds (of the device's clock) of the newest count.
const DRIFT_WINDOW_S: f64 = 24.0 * 3600.0;
/// The whites must span at least this many seconds before a drift is given.
const DRIFT_MIN_SPAN_S: f64 = 60.0;

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct DeviceLabel {
    device: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StatLabels {
    device: String,
    /// `mean` or `max`.
    stat: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct JobLabels {
    device: String,
    kind: String,
    /// `ok`, `failed`, `cancelled`, `interrupted`.
    outcome: String,
}

/// A reading's status (`ok`, `below_range`, `overload`).
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StatusLabels {
    device: String,
    status: String,
}

/// The part of a device that failed a job: opening the instrument, its warm-up, the
/// instrument during the job, or the display.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct FaultLabels {
    device: String,
    fault: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct EventLabels {
    device: String,
    event: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct BuildLabels {
    version: String,
}

type FloatGauge = Gauge<f64, AtomicU64>;

/// A least-squares slope and its standard error.
pub type Drift = (f64, f64);

/// Job kinds and outcomes, reading statuses and device faults, as the counters label
/// them: each series exists at 0 from the start, so that `increase()` counts its
/// first event (a series born at 1 has, to Prometheus, not increased).
const JOB_KINDS: [&str; 3] = ["calibrate", "verify", "uniformity"];
const JOB_OUTCOMES: [&str; 4] = ["ok", "failed", "cancelled", "interrupted"];
const READING_STATUSES: [&str; 3] = ["ok", "below_range", "overload"];
const FAULTS: [&str; 4] = ["open", "warmup", "instrument", "display"];

/// When things last happened to a device, and its recent whites.
#[derive(Debug, Default)]
struct DeviceTimes {
    calibrated: Option<SystemTime>,
    verified: Option<SystemTime>,
    /// (device clock seconds, cd/m²), oldest first.
    whites: Vec<(f64, f64)>,
    /// The events counted for the device: their series go with it.
    events: std::collections::BTreeSet<&'static str>,
}

/// The daemon's metrics.
pub struct Metrics {
    registry: Registry,
    up: Family<DeviceLabel, Gauge>,
    verification: Family<StatLabels, FloatGauge>,
    threshold: Family<DeviceLabel, FloatGauge>,
    verification_itp: Family<StatLabels, FloatGauge>,
    threshold_itp: Family<DeviceLabel, FloatGauge>,
    held_out: Family<StatLabels, FloatGauge>,
    white: Family<DeviceLabel, FloatGauge>,
    drift: Family<DeviceLabel, FloatGauge>,
    drift_error: Family<DeviceLabel, FloatGauge>,
    calibrated_at: Family<DeviceLabel, FloatGauge>,
    verified_at: Family<DeviceLabel, FloatGauge>,

    jobs: Family<JobLabels, Counter>,
    job_running: Family<DeviceLabel, Gauge>,
    progress: Family<DeviceLabel, FloatGauge>,
    readings: Family<StatusLabels, Counter>,
    faults: Family<FaultLabels, Counter>,
    events: Family<EventLabels, Counter>,
    lut_loaded: Family<DeviceLabel, Gauge>,
    lut_overwritten: Family<DeviceLabel, Counter>,
    mqtt_published: Counter,
    mqtt_dropped: Counter,
    reload_ok: Gauge,
    reload_ok_at: FloatGauge,
    times: Mutex<BTreeMap<String, DeviceTimes>>,
}

/// A `stat` label set.
fn stat(device: &str, stat: &str) -> StatLabels {
    StatLabels {
        device: device.into(),
        stat: stat.into(),
    }
}

fn label(device: &str) -> DeviceLabel {
    DeviceLabel {
        device: device.into(),
    }
}

fn status_labels(device: &str, status: &str) -> StatusLabels {
    StatusLabels {
        device: device.into(),
        status: status.into(),
    }
}

fn fault_labels(device: &str, fault: &str) -> FaultLabels {
    FaultLabels {
        device: device.into(),
        fault: fault.into(),
    }
}

/// Least-squares slope of `points` (y per unit of x) and its standard error,
/// √(s² / Sxx) with s² the residual variance on n − 2 degrees of freedom (the
/// ordinary least-squares line: e.g. Draper & Smith, *Applied Regression Analysis*,
/// 3rd ed., §1.4); `None` under three points or when they span less than `min_span`.
/// The error is what tells a drift from the scatter of single readings: over one
/// calibration's whites, minutes apart, the slope alone swings by percent per hour.
fn slope(points: &[(f64, f64)], min_span: f64) -> Option<(f64, f64)> {
    if points.len() < 3 {
        return None;
    }
    let n = points.len() as f64;
    let mean_x = points.iter().map(|p| p.0).sum::<f64>() / n;
    let mean_y = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = points.iter().map(|p| (p.0 - mean_x).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mean_x) * (p.1 - mean_y)).sum();
    let span = points.last()?.0 - points.first()?.0;
    if !(span >= min_span && sxx > 0.0) {
        return None;
    }
    let b = sxy / sxx;
    let residual: f64 = points
        .iter()
        .map(|p| (p.1 - mean_y - b * (p.0 - mean_x)).powi(2))
        .sum();
    Some((b, (residual / (n - 2.0) / sxx).sqrt()))
}

/// A device's mean and max in `family`; none known, no series.
fn set_stats(family: &Family<StatLabels, FloatGauge>, device: &str, stats: Option<ErrorStats>) {
    for (name, value) in [
        ("mean", stats.map(|s| s.mean)),
        ("max", stats.map(|s| s.max)),
    ] {
        match value {
            Some(v) => {
                family.get_or_create(&stat(device, name)).set(v);
            }
            None => {
                family.remove(&stat(device, name));
            }
        }
    }
}

impl Metrics {
    /// Metrics for the devices named.
    pub fn new<'a>(devices: impl IntoIterator<Item = &'a str>) -> Metrics {
        let mut registry = Registry::with_prefix("chromacal");
        let metrics = Metrics {
            up: Family::default(),
            verification: Family::default(),
            threshold: Family::default(),
            verification_itp: Family::default(),
            threshold_itp: Family::default(),
            held_out: Family::default(),
            white: Family::default(),
            drift: Family::default(),
            drift_error: Family::default(),
            calibrated_at: Family::default(),
            verified_at: Family::default(),
            jobs: Family::default(),
            job_running: Family::default(),
            progress: Family::default(),
            readings: Family::default(),
            faults: Family::default(),
            events: Family::default(),
            lut_loaded: Family::default(),
            lut_overwritten: Family::default(),
            mqtt_published: Counter::default(),
            mqtt_dropped: Counter::default(),
            reload_ok: Gauge::default(),
            reload_ok_at: FloatGauge::default(),
            times: Mutex::default(),
            registry: Registry::default(),
        };
        let r = &mut registry;
        r.register(
            "device_up",
            "The device's instrument and display answered its last job (1), or one of them failed it (0, with a device_lost event); 1 at start",
            metrics.up.clone(),
        );
        r.register(
            "verification_delta_e00",
            "The last verification's ΔE00 between readings and the current profile (stat: mean, max)",
            metrics.verification.clone(),
        );
        r.register(
            "verification_threshold_delta_e00",
            "The mean ΔE00 past which a verification fails (schedule.threshold_de00)",
            metrics.threshold.clone(),
        );
        r.register(
            "verification_delta_e_itp",
            "The last verification's ΔE ITP (BT.2124) between readings and the current profile, for a profile of an HDR signal, which is judged in it (stat: mean, max)",
            metrics.verification_itp.clone(),
        );
        r.register(
            "verification_threshold_delta_e_itp",
            "The mean ΔE ITP past which a verification of a profile of an HDR signal fails (schedule.threshold_itp)",
            metrics.threshold_itp.clone(),
        );
        r.register(
            "held_out_delta_e00",
            "The current profile's ΔE00 on patches held out of its fit (stat: mean, max)",
            metrics.held_out.clone(),
        );
        r.register(
            "white_luminance_cd_m2",
            "The last full-white reading at the centre, cd/m²",
            metrics.white.clone(),
        );
        r.register(
            "white_luminance_drift_cd_m2_per_second",
            "Least-squares slope of the recent full-white readings (up to 64 within 24 h of the device's clock), cd/m² per second",
            metrics.drift.clone(),
        );
        r.register(
            "white_luminance_drift_standard_error_cd_m2_per_second",
            "Standard error of that slope: a drift is told from the readings' scatter only when the slope is several times it",
            metrics.drift_error.clone(),
        );
        r.register(
            "last_calibration_timestamp_seconds",
            "When the current calibration was published, Unix time (none: never calibrated)",
            metrics.calibrated_at.clone(),
        );
        r.register(
            "last_verification_timestamp_seconds",
            "When the last verification ended, Unix time (none: never verified)",
            metrics.verified_at.clone(),
        );
        r.register(
            "build",
            "The daemon's version",
            prometheus_client::metrics::info::Info::new(BuildLabels {
                version: env!("CARGO_PKG_VERSION").into(),
            }),
        );
        r.register(
            "jobs",
            "Jobs ended, by kind and outcome",
            metrics.jobs.clone(),
        );
        r.register(
            "job_running",
            "A job runs on the device (1) or none (0)",
            metrics.job_running.clone(),
        );
        r.register(
            "job_progress_ratio",
            "Readings of the running job taken over those it plans (0 when none runs)",
            metrics.progress.clone(),
        );
        r.register(
            "readings",
            "Readings taken, by status (ok, below_range, overload)",
            metrics.readings.clone(),
        );
        r.register(
            "device_faults",
            "Jobs the devices failed, by the fault (open, warmup, instrument, display)",
            metrics.faults.clone(),
        );
        r.register(
            "events",
            "Events the daemon emitted",
            metrics.events.clone(),
        );
        r.register(
            "lut_loaded",
            "The current profile's curves are in the window device's video LUT as the daemon loaded them (1), or not (0: never loaded, a job holds it, or overwritten)",
            metrics.lut_loaded.clone(),
        );
        r.register(
            "lut_overwritten",
            "Times the daemon found its curves in the video LUT overwritten by something else",
            metrics.lut_overwritten.clone(),
        );
        r.register(
            "mqtt_messages_queued",
            "Messages (events, states, status) handed to the MQTT client to send",
            metrics.mqtt_published.clone(),
        );
        r.register(
            "mqtt_messages_dropped",
            "Messages never sent: progress coalesced while the broker was away, outcomes past the backlog",
            metrics.mqtt_dropped.clone(),
        );
        r.register(
            "config_last_reload_successful",
            "The last config reload (SIGHUP, POST /reload) was applied (1; also at start) or refused (0: the daemon runs on the config it had)",
            metrics.reload_ok.clone(),
        );
        r.register(
            "config_last_reload_success_timestamp_seconds",
            "When the config was last loaded (at start or by a reload), Unix time",
            metrics.reload_ok_at.clone(),
        );
        let metrics = Metrics {
            registry,
            ..metrics
        };
        metrics.reloaded(true);
        for device in devices {
            metrics.add_device(device);
        }
        metrics
    }

    /// A config load's outcome.
    fn reloaded(&self, ok: bool) {
        self.reload_ok.set(i64::from(ok));
        if ok {
            let now = SystemTime::now()
                .duration_since(SystemTime::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64());
            self.reload_ok_at.set(now);
        }
    }

    /// Count an event of the whole daemon.
    pub fn observe_daemon(&self, event: &Event) {
        match event {
            Event::ConfigReloaded { .. } => self.reloaded(true),
            Event::ConfigRefused { .. } => self.reloaded(false),
            _ => {}
        }
    }

    /// A device's series, its counters at 0 (at start, and when a reload adds it).
    pub fn add_device(&self, device: &str) {
        self.up.get_or_create(&label(device)).set(1);
        self.job_running.get_or_create(&label(device)).set(0);
        self.progress.get_or_create(&label(device)).set(0.0);
        self.lut_overwritten.get_or_create(&label(device)).inc_by(0);
        for kind in JOB_KINDS {
            for outcome in JOB_OUTCOMES {
                self.jobs
                    .get_or_create(&JobLabels {
                        device: device.into(),
                        kind: kind.into(),
                        outcome: outcome.into(),
                    })
                    .inc_by(0);
            }
        }
        for status in READING_STATUSES {
            self.readings
                .get_or_create(&status_labels(device, status))
                .inc_by(0);
        }
        for fault in FAULTS {
            self.faults
                .get_or_create(&fault_labels(device, fault))
                .inc_by(0);
        }
    }

    /// A device a reload removed: its series go (a scrape no longer shows it).
    pub fn remove_device(&self, device: &str) {
        for family in [&self.up, &self.job_running, &self.lut_loaded] {
            family.remove(&label(device));
        }
        for family in [
            &self.threshold,
            &self.threshold_itp,
            &self.white,
            &self.drift,
            &self.drift_error,
            &self.calibrated_at,
            &self.verified_at,
            &self.progress,
        ] {
            family.remove(&label(device));
        }
        self.lut_overwritten.remove(&label(device));
        self.set_verification(device, None);
        set_stats(&self.held_out, device, None);
        for kind in JOB_KINDS {
            for outcome in JOB_OUTCOMES {
                self.jobs.remove(&JobLabels {
                    device: device.into(),
                    kind: kind.into(),
                    outcome: outcome.into(),
                });
            }
        }
        for status in READING_STATUSES {
            self.readings.remove(&status_labels(device, status));
        }
        for fault in FAULTS {
            self.faults.remove(&fault_labels(device, fault));
        }
        let Ok(mut times) = self.times.lock() else {
            return;
        };
        if let Some(gone) = times.remove(device) {
            for event in gone.events {
                self.events.remove(&EventLabels {
                    device: device.into(),
                    event: event.into(),
                });
            }
        }
    }

    fn with_times(&self, device: &str, f: impl FnOnce(&mut DeviceTimes)) {
        if let Ok(mut times) = self.times.lock() {
            f(times.entry(device.to_string()).or_default());
        }
    }

    /// What the store held at start: the current profile's held-out error and when
    /// it was made, the last verification, the threshold.
    pub fn restore(
        &self,
        device: &str,
        held_out: Option<ErrorStats>,
        calibrated: Option<SystemTime>,
        verification: Option<(SystemTime, &VerificationRecord)>,
        schedule: &crate::config::ScheduleConfig,
    ) {
        self.threshold
            .get_or_create(&label(device))
            .set(schedule.threshold_de00);
        self.threshold_itp
            .get_or_create(&label(device))
            .set(schedule.threshold_itp);
        self.set_held_out(device, held_out);
        if let Some((at, record)) = verification {
            self.set_verification(device, Some(record));
            self.with_times(device, |t| t.verified = Some(at));
        }
        self.with_times(device, |t| t.calibrated = calibrated);
    }

    fn set_held_out(&self, device: &str, held_out: Option<ErrorStats>) {
        set_stats(&self.held_out, device, held_out);
    }

    /// The last verification's error, in the family of its metric (the other one
    /// cleared); `None`: no verification of the current profile.
    fn set_verification(&self, device: &str, record: Option<&VerificationRecord>) {
        let in_metric = |metric| record.filter(|r| r.metric == metric).and_then(|r| r.stats);
        set_stats(&self.verification, device, in_metric(Metric::De00));
        set_stats(&self.verification_itp, device, in_metric(Metric::Itp));
    }

    /// Count an event of `device` and update what it tells.
    pub fn observe(&self, device: &str, event: &Event) {
        self.with_times(device, |t| {
            t.events.insert(event.name());
        });
        self.events
            .get_or_create(&EventLabels {
                device: device.into(),
                event: event.name().into(),
            })
            .inc();
        match event {
            Event::Progress { job } if job.total > 0 => {
                self.progress
                    .get_or_create(&label(device))
                    .set(job.done as f64 / job.total as f64);
            }
            Event::JobFinished { job, outcome } => {
                self.jobs
                    .get_or_create(&JobLabels {
                        device: device.into(),
                        kind: job.kind.name().into(),
                        outcome: outcome.result.clone(),
                    })
                    .inc();
                self.job_running.get_or_create(&label(device)).set(0);
                self.progress.get_or_create(&label(device)).set(0.0);
                if outcome.result == "ok" {
                    // Both devices answered the whole job.
                    self.up.get_or_create(&label(device)).set(1);
                }
            }
            // A new current profile: the last verification was of another one.
            Event::Published { how, held_out, .. } => {
                self.set_held_out(device, *held_out);
                self.set_verification(device, None);
                if how == "calibration" {
                    self.with_times(device, |t| t.calibrated = Some(SystemTime::now()));
                }
            }
            Event::RolledBack { entry } => {
                self.set_held_out(device, entry.held_out);
                self.set_verification(device, None);
            }
            Event::Verification { record } => {
                self.set_verification(device, Some(record));
                match record.metric {
                    Metric::De00 => &self.threshold,
                    Metric::Itp => &self.threshold_itp,
                }
                .get_or_create(&label(device))
                .set(record.threshold);
                self.with_times(device, |t| t.verified = Some(SystemTime::now()));
            }
            Event::LutLoaded { .. } => {
                self.lut_loaded.get_or_create(&label(device)).set(1);
            }
            Event::LutOverwritten { .. } => {
                self.lut_loaded.get_or_create(&label(device)).set(0);
                self.lut_overwritten.get_or_create(&label(device)).inc();
            }
            Event::JobStarted { .. } => {
                self.job_running.get_or_create(&label(device)).set(1);
                self.progress.get_or_create(&label(device)).set(0.0);
                if let Some(loaded) = self.lut_loaded.get(&label(device)) {
                    loaded.set(0);
                }
            }
            Event::DeviceLost { fault, .. } => {
                self.up.get_or_create(&label(device)).set(0);
                self.faults
                    .get_or_create(&fault_labels(device, fault))
                    .inc();
            }
            _ => {}
        }
    }

    /// Count a reading; a full white at the centre also updates the white luminance
    /// and its drift (`time_s` is the device's clock).
    pub fn reading(&self, device: &str, status: ReadingStatus, white: Option<f64>, time_s: f64) {
        let status = match status {
            ReadingStatus::Ok => "ok",
            ReadingStatus::BelowRange => "below_range",
            ReadingStatus::Overload => "overload",
        };
        self.readings
            .get_or_create(&status_labels(device, status))
            .inc();
        let Some(y) = white.filter(|y| y.is_finite() && *y > 0.0) else {
            return;
        };
        self.white.get_or_create(&label(device)).set(y);
        let mut drift = None;
        self.with_times(device, |t| {
            // A clock that went back (devices opened again) starts a new series.
            if t.whites.last().is_some_and(|last| time_s < last.0) {
                t.whites.clear();
            }
            t.whites.push((time_s, y));
            t.whites.retain(|p| p.0 >= time_s - DRIFT_WINDOW_S);
            let excess = t.whites.len().saturating_sub(DRIFT_POINTS);
            t.whites.drain(..excess);
            drift = slope(&t.whites, DRIFT_MIN_SPAN_S);
        });
        match drift {
            Some((per_s, error)) => {
                self.drift.get_or_create(&label(device)).set(per_s);
                self.drift_error.get_or_create(&label(device)).set(error);
            }
            // Too few whites since the series began again: no drift to tell.
            None => {
                self.drift.remove(&label(device));
                self.drift_error.remove(&label(device));
            }
        }
    }

    /// A device's recent full whites at the centre, (device clock s, cd/m²) oldest
    /// first, and their drift (slope per second, standard error) if it can be told.
    pub fn whites(&self, device: &str) -> (Vec<(f64, f64)>, Option<Drift>) {
        let whites = self
            .times
            .lock()
            .ok()
            .and_then(|t| t.get(device).map(|t| t.whites.clone()))
            .unwrap_or_default();
        let drift = slope(&whites, DRIFT_MIN_SPAN_S);
        (whites, drift)
    }

    /// Whether the device's instrument and display answered its last job.
    pub fn device_up(&self, device: &str) -> bool {
        self.up.get(&label(device)).is_none_or(|g| g.get() == 1)
    }

    /// Count an event handed to MQTT, or one dropped.
    pub fn mqtt(&self, published: bool) {
        if published {
            self.mqtt_published.inc();
        } else {
            self.mqtt_dropped.inc();
        }
    }

    /// Events dropped for MQTT so far.
    pub fn mqtt_dropped(&self) -> u64 {
        self.mqtt_dropped.get()
    }

    /// The text a scrape gets.
    pub fn render(&self) -> Result<String, std::fmt::Error> {
        let unix = |t: SystemTime| {
            t.duration_since(SystemTime::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64())
        };
        if let Ok(times) = self.times.lock() {
            for (device, t) in times.iter() {
                if let Some(at) = t.calibrated {
                    self.calibrated_at
                        .get_or_create(&label(device))
                        .set(unix(at));
                }
                if let Some(at) = t.verified {
                    self.verified_at.get_or_create(&label(device)).set(unix(at));
                }
            }
        }
        let mut text = String::new();
        prometheus_client::encoding::text::encode(&mut text, &self.registry)?;
        Ok(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::events::{JobKind, JobOutcome, JobStatus};

    fn job(kind: JobKind) -> JobStatus {
        JobStatus {
            id: "x".into(),
            kind,
            origin: "api".into(),
            started: String::new(),
            phase: "measuring".into(),
            done: 3,
            total: 12,
            eta_s: None,
            last: None,
        }
    }

    fn line<'a>(text: &'a str, start: &str) -> Option<&'a str> {
        text.lines().find(|l| l.starts_with(start))
    }

    #[test]
    fn events_and_readings_become_labelled_series() {
        let metrics = Metrics::new(["a", "b"]);
        metrics.observe(
            "a",
            &Event::JobStarted {
                job: job(JobKind::Calibrate),
            },
        );
        metrics.observe(
            "a",
            &Event::Progress {
                job: job(JobKind::Calibrate),
            },
        );
        let text = metrics.render().unwrap();
        assert!(
            line(&text, "chromacal_job_progress_ratio{device=\"a\"} 0.25").is_some(),
            "{text}"
        );
        assert!(line(&text, "chromacal_job_running{device=\"b\"} 0").is_some());
        metrics.observe(
            "a",
            &Event::JobFinished {
                job: job(JobKind::Calibrate),
                outcome: JobOutcome {
                    result: "failed".into(),
                    message: String::new(),
                    profile_id: None,
                    published: false,
                    escalated: false,
                },
            },
        );
        // White readings one simulated minute apart, falling 0.5 cd/m² a minute.
        for i in 0..5 {
            metrics.reading(
                "b",
                ReadingStatus::Ok,
                Some(100.0 - 0.5 * i as f64),
                60.0 * i as f64,
            );
        }
        metrics.reading("b", ReadingStatus::Overload, None, 300.0);
        let text = metrics.render().unwrap();
        assert!(
            line(
                &text,
                "chromacal_jobs_total{device=\"a\",kind=\"calibrate\",outcome=\"failed\"} 1"
            )
            .is_some(),
            "{text}"
        );
        let drift = line(
            &text,
            "chromacal_white_luminance_drift_cd_m2_per_second{device=\"b\"}",
        )
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap();
        assert!((drift * 3600.0 + 30.0).abs() < 1e-9, "{drift}");
        assert!(line(&text, "chromacal_white_luminance_cd_m2{device=\"b\"} 98").is_some());
        assert!(
            line(
                &text,
                "chromacal_readings_total{device=\"b\",status=\"overload\"} 1"
            )
            .is_some()
        );
        // Nothing is said of what is not known yet.
        assert!(line(&text, "chromacal_last_calibration_timestamp_seconds").is_none());
        assert!(line(&text, "chromacal_verification_delta_e00{").is_none());
        assert!(text.trim_end().ends_with("# EOF"));
        // A verification is of the current profile: a new one makes it old news.
        let stats = ErrorStats::of(&[0.5, 1.5]);
        metrics.observe(
            "a",
            &Event::Verification {
                record: crate::profile::store::VerificationRecord {
                    at: String::new(),
                    profile_id: "p".into(),
                    metric: Metric::De00,
                    stats,
                    delta_e: vec![0.5, 1.5],
                    threshold: 1.0,
                    escalated: false,
                    journal: None,
                    verdict: None,
                },
            },
        );
        let text = metrics.render().unwrap();
        assert!(
            line(
                &text,
                "chromacal_verification_delta_e00{device=\"a\",stat=\"max\"} 1.5"
            )
            .is_some(),
            "{text}"
        );
        let verified = line(
            &text,
            "chromacal_last_verification_timestamp_seconds{device=\"a\"}",
        )
        .and_then(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .unwrap();
        let now = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap()
            .as_secs_f64();
        assert!((now - verified).abs() < 60.0, "{verified} against {now}");
        metrics.observe(
            "a",
            &Event::Published {
                profile_id: "q".into(),
                how: "calibration".into(),
                held_out: stats,
            },
        );
        let text = metrics.render().unwrap();
        assert!(
            line(&text, "chromacal_verification_delta_e00{").is_none(),
            "{text}"
        );
        assert!(
            line(
                &text,
                "chromacal_held_out_delta_e00{device=\"a\",stat=\"mean\"} 1"
            )
            .is_some(),
            "{text}"
        );
        assert!(
            line(
                &text,
                "chromacal_last_calibration_timestamp_seconds{device=\"a\"}"
            )
            .is_some()
        );
    }

    #[test]
    fn the_drift_comes_with_its_standard_error_and_noise_alone_stays_within_it() {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        // 24 whites a minute apart, 0.3 % noise (a spectroradiometer's repeatability),
        // 200 runs: on a flat line the slope alone passes 1 %/h in several percent of
        // runs, but three standard errors only about as often as a t statistic on 22
        // degrees of freedom does (0.7 %); a real drift of 3 %/h passes nearly always.
        let noise = rand_distr::Normal::new(0.0, 0.3).unwrap();
        let (mut large, mut false_alarms, mut found) = (0, 0, 0);
        for seed in 0..200 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let whites: Vec<(f64, f64)> = (0..24)
                .map(|k| (60.0 * k as f64, 100.0 + noise.sample(&mut rng)))
                .collect();
            let (b, se) = slope(&whites, 60.0).unwrap();
            large += usize::from((b * 3600.0).abs() > 1.0);
            false_alarms += usize::from(b.abs() > 3.0 * se);
            let drifting: Vec<(f64, f64)> = whites
                .iter()
                .map(|(t, y)| (*t, y + 3.0 * t / 3600.0))
                .collect();
            let (b, se) = slope(&drifting, 60.0).unwrap();
            found += usize::from(b > 3.0 * se);
        }
        eprintln!(
            "of 200: flat past 1 %/h {large}, flat past 3 SE {false_alarms}, 3 %/h past 3 SE {found}"
        );
        assert!(large >= 10, "{large} of 200 flat runs past 1 %/h");
        assert!(
            false_alarms <= 6,
            "{false_alarms} of 200 flat runs past 3 SE"
        );
        assert!(found >= 190, "{found} of 200 drifting runs past 3 SE");
    }

    #[test]
    fn the_classic_format_names_counters_with_total_and_the_build_as_info() {
        let text = to_classic_text(&Metrics::new(["a"]).render().unwrap());
        for expected in [
            "# TYPE chromacal_jobs_total counter",
            "# HELP chromacal_jobs_total Jobs ended",
            "# TYPE chromacal_build_info gauge",
            "# TYPE chromacal_device_up gauge",
            "chromacal_jobs_total{device=\"a\",kind=\"verify\",outcome=\"ok\"} 0",
        ] {
            assert!(text.contains(expected), "no {expected} in {text}");
        }
        assert!(!text.contains("# EOF") && !text.contains("# TYPE chromacal_jobs counter"));
    }

    #[test]
    fn a_device_is_down_from_its_lost_devices_to_its_next_good_job() {
        let metrics = Metrics::new(["a"]);
        let up = |m: &Metrics| {
            let text = m.render().unwrap();
            line(&text, "chromacal_device_up{device=\"a\"} ")
                .and_then(|l| l.rsplit(' ').next()?.parse::<i64>().ok())
        };
        assert_eq!(up(&metrics), Some(1));
        metrics.observe(
            "a",
            &Event::DeviceLost {
                fault: "instrument".into(),
                message: "no reply".into(),
            },
        );
        assert_eq!(up(&metrics), Some(0));
        let finished = |result: &str| Event::JobFinished {
            job: job(JobKind::Calibrate),
            outcome: JobOutcome {
                result: result.into(),
                message: String::new(),
                profile_id: None,
                published: false,
                escalated: false,
            },
        };
        metrics.observe("a", &finished("failed"));
        assert_eq!(up(&metrics), Some(0));
        metrics.observe("a", &finished("ok"));
        assert_eq!(up(&metrics), Some(1));
    }

    #[test]
    fn counters_exist_at_zero_before_their_first_event() {
        let metrics = Metrics::new(["a"]);
        let text = metrics.render().unwrap();
        for series in [
            "chromacal_device_faults_total{device=\"a\",fault=\"instrument\"} 0",
            "chromacal_device_faults_total{device=\"a\",fault=\"display\"} 0",
            "chromacal_jobs_total{device=\"a\",kind=\"calibrate\",outcome=\"failed\"} 0",
            "chromacal_readings_total{device=\"a\",status=\"overload\"} 0",
            "chromacal_lut_overwritten_total{device=\"a\"} 0",
            "chromacal_build_info{version=",
        ] {
            assert!(line(&text, series).is_some(), "no {series} in {text}");
        }
    }

    #[test]
    fn a_drift_needs_three_whites_a_minute_apart_and_a_clock_that_went_back_restarts_it() {
        assert_eq!(slope(&[(0.0, 1.0), (100.0, 2.0)], 60.0), None);
        assert_eq!(slope(&[(0.0, 1.0), (10.0, 2.0), (20.0, 3.0)], 60.0), None);
        let metrics = Metrics::new(["a"]);
        for (t, y) in [(0.0, 100.0), (60.0, 101.0), (120.0, 102.0)] {
            metrics.reading("a", ReadingStatus::Ok, Some(y), t);
        }
        let text = metrics.render().unwrap();
        // 1 cd/m² a minute, exactly on a line: no scatter, no standard error.
        let per_s = line(
            &text,
            "chromacal_white_luminance_drift_cd_m2_per_second{device=\"a\"} ",
        )
        .and_then(|l| l.rsplit(' ').next()?.parse::<f64>().ok());
        assert!((per_s.unwrap() - 1.0 / 60.0).abs() < 1e-12, "{text}");
        assert!(
            line(
                &text,
                "chromacal_white_luminance_drift_standard_error_cd_m2_per_second{device=\"a\"} 0.0"
            )
            .is_some(),
            "{text}"
        );
        metrics.reading("a", ReadingStatus::Ok, Some(50.0), 5.0);
        let text = metrics.render().unwrap();
        assert!(
            line(&text, "chromacal_white_luminance_drift_cd_m2_per_second").is_none(),
            "{text}"
        );
        let times = metrics.times.lock().unwrap();
        assert_eq!(times["a"].whites, vec![(5.0, 50.0)]);
    }
}
