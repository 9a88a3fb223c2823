//! The daemon's sections: `[daemon]` (its API, limits and start-up) and `[schedule]`
//! (verification on a timer). The daemon itself is in `daemon`.

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// What to do at start with a calibration a stop cut short.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum OnStart {
    /// Go on measuring where it stopped.
    #[default]
    Resume,
    /// Give it up (its journal is kept, marked discarded).
    Discard,
}

/// `[daemon]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// The API's unix socket (default: `$RUNTIME_DIRECTORY/api.sock` under systemd,
    /// else `<state>/api.sock`). Created with mode 0600.
    pub socket: Option<PathBuf>,
    /// Also serve the API on this TCP address (loopback; a bearer token is required).
    pub tcp: Option<String>,
    /// Let `tcp` be an address other machines can reach (warned about at start).
    pub allow_remote: bool,
    /// The bearer token for TCP clients (default: `<state>/api.token`, made at first
    /// start with mode 0600).
    pub token_file: Option<PathBuf>,
    pub on_start: OnStart,
    /// Seconds SIGTERM waits for the reading under way before the daemon exits.
    pub stop_timeout_s: f64,
    /// Real seconds per simulated second, for the simulated monitor and instrument.
    pub simulated_time_scale: f64,
    /// The simulated monitor ages while no job runs (warm-up fades, drift goes on), as
    /// a real one does. Off, its readings depend on nothing but the seeds.
    pub simulated_idle_ages: bool,
    /// Profiles kept in the history (at least 2).
    pub keep_profiles: usize,
    /// Largest request body, bytes.
    pub max_body_bytes: usize,
    /// Sustained requests per second, and the burst above it.
    pub requests_per_s: f64,
    pub burst: usize,
    /// Event streams open at once.
    pub max_event_streams: usize,
    /// Connections open at once on the TCP listener; more are closed at once.
    pub max_connections: usize,
    /// Connections open at once on the unix socket (its own cap, so TCP clients
    /// cannot use it up).
    pub max_local_connections: usize,
    /// Seconds a client has to send a request's headers (and an idle keep-alive
    /// connection waits for its next request).
    pub header_timeout_s: f64,
    /// Seconds with nothing read or written after which a connection is closed.
    pub idle_timeout_s: f64,
    /// Seconds a request (with its body) may take to be answered.
    pub request_timeout_s: f64,
    /// `GET /metrics` on TCP wants the bearer token too (off: Prometheus scrapes
    /// without one, as it does unless told otherwise; the figures are not secret).
    pub metrics_token: bool,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        DaemonConfig {
            socket: None,
            tcp: None,
            allow_remote: false,
            token_file: None,
            on_start: OnStart::Resume,
            stop_timeout_s: 20.0,
            simulated_time_scale: 1.0,
            simulated_idle_ages: true,
            keep_profiles: crate::profile::store::DEFAULT_KEEP,
            max_body_bytes: 64 * 1024,
            requests_per_s: 50.0,
            burst: 200,
            max_event_streams: 32,
            max_connections: 64,
            max_local_connections: 64,
            header_timeout_s: 10.0,
            idle_timeout_s: 60.0,
            request_timeout_s: 30.0,
            metrics_token: false,
        }
    }
}

impl DaemonConfig {
    pub fn check(&self) -> Result<(), String> {
        if !(self.stop_timeout_s >= 0.0 && self.simulated_time_scale > 0.0) {
            return Err(
                "daemon: stop_timeout_s must not be negative and simulated_time_scale must be positive"
                    .into(),
            );
        }
        if !(self.requests_per_s > 0.0) || self.burst == 0 || self.max_event_streams == 0 {
            return Err(
                "daemon: requests_per_s, burst and max_event_streams must be positive".into(),
            );
        }
        if self.max_connections == 0 || self.max_local_connections == 0 {
            return Err(
                "daemon: max_connections and max_local_connections must be positive".into(),
            );
        }
        for (key, value) in [
            ("header_timeout_s", self.header_timeout_s),
            ("idle_timeout_s", self.idle_timeout_s),
            ("request_timeout_s", self.request_timeout_s),
        ] {
            if !(0.1..=86_400.0).contains(&value) {
                return Err(format!(
                    "daemon.{key} = {value} is out of range: from 0.1 to 86400 seconds"
                ));
            }
        }
        if let Some(address) = &self.tcp {
            let addr: SocketAddr = address
                .parse()
                .map_err(|_| format!("daemon.tcp = \"{address}\" is not an IP address and port"))?;
            if !addr.ip().is_loopback() && !self.allow_remote {
                return Err(format!(
                    "daemon.tcp = \"{address}\" can be reached from other machines: set daemon.allow_remote = true if that is meant"
                ));
            }
        }
        Ok(())
    }
}

/// `[schedule]`: verification on a timer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScheduleConfig {
    /// Seconds between verifications (none: only on request).
    pub verify_every_s: Option<f64>,
    /// Patches a verification measures (at least 5).
    pub verify_patches: usize,
    /// Mean ΔE00 past which a verification starts a recalibration.
    pub threshold_de00: f64,
    /// Mean ΔE ITP (BT.2124) past which a verification of a profile of an HDR
    /// signal (PQ, HLG) starts a recalibration: such a profile is judged in ΔE ITP
    /// on absolute light, as it was published (`publish.max_mean_itp`), not in ΔE00
    /// relative to its white. 1 is DisplayCAL's recommended HDR limit.
    pub threshold_itp: f64,
    /// Start the recalibration (false: only record and report).
    pub escalate: bool,
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        ScheduleConfig {
            verify_every_s: None,
            verify_patches: 8,
            threshold_de00: 1.0,
            threshold_itp: 1.0,
            escalate: true,
        }
    }
}

impl ScheduleConfig {
    pub fn check(&self) -> Result<(), String> {
        if self.verify_every_s.is_some_and(|s| !(s > 0.0)) {
            return Err("schedule.verify_every_s must be positive".into());
        }
        if self.verify_patches < 5 {
            return Err("schedule.verify_patches must be at least 5".into());
        }
        if !(self.threshold_de00 > 0.0) {
            return Err("schedule.threshold_de00 must be positive".into());
        }
        if !(self.threshold_itp > 0.0) {
            return Err("schedule.threshold_itp must be positive".into());
        }
        Ok(())
    }
}

/// `[mqtt]`: the daemon's state and events on an MQTT broker (`daemon::mqtt`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MqttConfig {
    /// The broker, `host:port`.
    pub broker: String,
    /// The first topic level.
    pub prefix: String,
    /// The second topic level (default: this machine's host name).
    pub host: Option<String>,
    /// The client id (default: `chromacal-<host>`); one per broker.
    pub client_id: Option<String>,
    /// A file with the user name on its first line and the password on its second,
    /// mode 0600 (relative to the config file).
    pub credentials_file: Option<PathBuf>,
    /// TLS to the broker. This build speaks plain MQTT only, for a broker on
    /// loopback or behind a TLS-terminating bridge: `true` is refused.
    pub tls: bool,
    /// Messages queued for the broker; past them, events are dropped and counted.
    pub queue: usize,
    /// Seconds between keep-alive pings; the broker sends the last will after 1.5 ×
    /// this without a word (at once when the connection drops).
    pub keep_alive_s: f64,
    /// Publish each reading's progress event too (QoS 0).
    pub progress: bool,
}

/// Longest MQTT prefix, host level or client id taken: topics of a device's events
/// stay far within MQTT's 65,535 bytes, and brokers take client ids this long
/// (MQTT 3.1.1 promises only 23).
pub const MAX_MQTT_NAME: usize = 256;

/// A value as an error message quotes it: at most 40 characters.
fn short(value: &str) -> String {
    match value.char_indices().nth(40) {
        Some((at, _)) => format!("{}…", &value[..at]),
        None => value.to_string(),
    }
}

impl Default for MqttConfig {
    fn default() -> Self {
        MqttConfig {
            broker: "127.0.0.1:1883".into(),
            prefix: "chromacal".into(),
            host: None,
            client_id: None,
            credentials_file: None,
            tls: false,
            queue: 1000,
            keep_alive_s: 30.0,
            progress: true,
        }
    }
}

impl MqttConfig {
    pub fn check(&self) -> Result<(), String> {
        if self.tls {
            return Err("mqtt.tls = true: this build speaks plain MQTT only (use a broker on loopback, or a TLS bridge such as mosquitto's)".into());
        }
        let port = self.broker.rsplit_once(':').map(|(_, p)| p.parse::<u16>());
        if !matches!(port, Some(Ok(p)) if p > 0) {
            return Err(format!(
                "mqtt.broker = \"{}\" is not host:port",
                self.broker
            ));
        }
        if self.prefix.is_empty() || self.prefix.contains(['+', '#']) {
            return Err(format!(
                "mqtt.prefix = \"{}\" must be a topic without wildcards (+, #)",
                self.prefix
            ));
        }
        // Topics starting with `$` are the broker's own (`$SYS/…`, MQTT 3.1.1 §4.7.2):
        // a client's publications there are refused or never reach subscribers.
        if self.prefix.starts_with('$') {
            return Err(format!(
                "mqtt.prefix = \"{}\" starts with '$': such topics are the broker's own",
                short(&self.prefix)
            ));
        }
        for (key, value) in [
            ("mqtt.prefix", Some(&self.prefix)),
            ("mqtt.host", self.host.as_ref()),
            ("mqtt.client_id", self.client_id.as_ref()),
        ] {
            if let Some(value) = value
                && (value.is_empty() || value.len() > MAX_MQTT_NAME)
            {
                return Err(format!(
                    "{key} = \"{}\" has {} bytes: give 1 to {MAX_MQTT_NAME}",
                    short(value),
                    value.len()
                ));
            }
        }
        Ok(())
    }
}
