//! MQTT: the daemon's state and events published to a broker (`[mqtt]`), with the
//! `rumqttc` client.
//!
//! Topics, under `<prefix>/<host>/`:
//!
//! | topic | retained | payload (JSON) |
//! |---|---|---|
//! | `status` | yes | `{"online": true, "pid", "version", "devices"}`; the last will says `{"online": false, "reason": "lost"}` when the daemon dies without a word, a clean stop `"reason": "stopped"` |
//! | `<device>/state` | yes | the device's job, current profile, last verification and last job |
//! | `<device>/event/<name>` | no | each event (`job_started`, `progress`, `job_finished`, `published`, `verification`, `rolled_back`, `device_lost`, …) as `GET /events` gives it, with `device`, `host` and `at` |
//!
//! A broker that is down or slow never holds a job up: events go into the client's
//! bounded queue (`mqtt.queue`), and when it is full they are dropped, counted
//! (`chromacal_mqtt_events_dropped_total`) and warned of (at most every 10 s). The
//! retained status and states are published again at every connection, so a broker
//! that restarted without its store learns them again.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rumqttc::{AsyncClient, LastWill, MqttOptions, QoS};
use serde_json::{Value, json};

use super::events::Event;
use super::metrics::Metrics;
use super::serve::LogThrottle;
use crate::config::MqttConfig;

/// Why MQTT could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum MqttError {
    #[error("mqtt.broker = \"{0}\" is not host:port")]
    Broker(String),
    #[error("mqtt.credentials_file {path}: {message}")]
    Credentials { path: String, message: String },
}

/// One level of a topic: what MQTT gives a meaning to (`/`, `+`, `#`) is replaced.
fn topic_level(text: &str) -> String {
    text.chars()
        .map(|c| match c {
            '/' | '+' | '#' | '\0' => '_',
            c => c,
        })
        .collect()
}

/// This machine's host name (the kernel's), for the topics.
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok().filter(|h| !h.is_empty()))
        .unwrap_or_else(|| "localhost".into())
}

/// A user name on the first line and a password on the second; the file must not be
/// readable by others.
fn read_credentials(path: &Path) -> Result<(String, String), MqttError> {
    use std::os::unix::fs::PermissionsExt;
    let error = |message: String| MqttError::Credentials {
        path: path.display().to_string(),
        message,
    };
    let mode = std::fs::metadata(path)
        .map_err(|e| error(e.to_string()))?
        .permissions()
        .mode();
    if mode & 0o077 != 0 {
        return Err(error(format!(
            "others can read it (mode {:o}): make it 0600",
            mode & 0o777
        )));
    }
    let text = crate::durable::read_text_limited(path, crate::durable::limits::PROFILE)
        .map_err(|e| error(e.to_string()))?;
    let mut lines = text.lines();
    match (lines.next(), lines.next()) {
        (Some(user), Some(password)) if !user.trim().is_empty() => {
            Ok((user.trim().to_string(), password.to_string()))
        }
        _ => Err(error(
            "give the user name on the first line and the password on the second".into(),
        )),
    }
}

/// The daemon's side of MQTT.
pub struct Mqtt {
    client: AsyncClient,
    /// `<prefix>/<host>`.
    root: String,
    host: String,
    progress: bool,
    metrics: Arc<Metrics>,
    /// What is retained, by topic: sent again at every connection.
    retained: Arc<Mutex<BTreeMap<String, String>>>,
    /// Each device's state, as its `state` topic gives it.
    states: Mutex<BTreeMap<String, Value>>,
    dropped: Mutex<LogThrottle>,
    /// The client's event loop, which ends once it has said goodbye.
    task: Mutex<Option<tokio::task::JoinHandle<()>>>,
}

impl Mqtt {
    /// Connect (in the background: a broker that is down is tried again every second)
    /// and publish the daemon's status. `devices` are the device names.
    pub fn start(
        config: &MqttConfig,
        base_dir: &Path,
        devices: &[String],
        metrics: Arc<Metrics>,
    ) -> Result<Arc<Mqtt>, MqttError> {
        let (address, port) = config
            .broker
            .rsplit_once(':')
            .and_then(|(a, p)| Some((a.trim_matches(['[', ']']), p.parse::<u16>().ok()?)))
            .ok_or_else(|| MqttError::Broker(config.broker.clone()))?;
        let host = topic_level(&config.host.clone().unwrap_or_else(host_name));
        let root = format!("{}/{host}", config.prefix.trim_end_matches('/'));
        let client_id = config
            .client_id
            .clone()
            .unwrap_or_else(|| format!("chromacal-{host}"));
        let mut options = MqttOptions::new(client_id, address, port);
        options.set_keep_alive(Duration::from_secs_f64(config.keep_alive_s));
        options.set_clean_session(true);
        let status_topic = format!("{root}/status");
        options.set_last_will(LastWill::new(
            &status_topic,
            json!({"online": false, "reason": "lost"}).to_string(),
            QoS::AtLeastOnce,
            true,
        ));
        if let Some(path) = &config.credentials_file {
            let (user, password) = read_credentials(&base_dir.join(path))?;
            options.set_credentials(user, password);
        }
        let (client, mut eventloop) = AsyncClient::new(options, config.queue);
        let online = json!({
            "online": true,
            "pid": std::process::id(),
            "version": env!("CARGO_PKG_VERSION"),
            "devices": devices,
        })
        .to_string();
        let retained = Arc::new(Mutex::new(BTreeMap::from([(status_topic, online)])));
        let task = {
            let client = client.clone();
            let retained = retained.clone();
            let broker = config.broker.clone();
            tokio::spawn(async move {
                let mut failures = LogThrottle::default();
                loop {
                    match eventloop.poll().await {
                        Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(_))) => {
                            tracing::info!(%broker, "MQTT connected");
                            let topics = retained.lock().map(|r| r.clone()).unwrap_or_default();
                            for (topic, payload) in topics {
                                let _ = client.try_publish(topic, QoS::AtLeastOnce, true, payload);
                            }
                        }
                        Ok(rumqttc::Event::Outgoing(rumqttc::Outgoing::Disconnect)) => return,
                        Ok(_) => {}
                        Err(e) => {
                            if let Some(n) = failures.note() {
                                tracing::warn!(%broker, error = %e, failures = n, "MQTT broker unreachable; trying again every second (events queue, and past mqtt.queue are dropped)");
                            }
                            tokio::time::sleep(Duration::from_secs(1)).await;
                        }
                    }
                }
            })
        };
        Ok(Arc::new(Mqtt {
            client,
            root,
            host,
            progress: config.progress,
            metrics,
            retained,
            states: Mutex::default(),
            dropped: Mutex::default(),
            task: Mutex::new(Some(task)),
        }))
    }

    /// Hand a message to the client's queue; a full queue drops it, counted.
    fn send(&self, topic: String, qos: QoS, retain: bool, payload: String) {
        if retain && let Ok(mut r) = self.retained.lock() {
            r.insert(topic.clone(), payload.clone());
        }
        let sent = self.client.try_publish(topic, qos, retain, payload).is_ok();
        self.metrics.mqtt(sent);
        if !sent
            && let Ok(mut throttle) = self.dropped.lock()
            && let Some(n) = throttle.note()
        {
            tracing::warn!(
                dropped = n,
                total = self.metrics.mqtt_dropped(),
                "MQTT queue full (is the broker down?): events dropped"
            );
        }
    }

    /// A device's state at start: its current profile and last verification.
    pub fn restore(&self, device: &str, state: Value) {
        if let Ok(mut states) = self.states.lock() {
            states.insert(device.to_string(), state);
        }
        self.publish_state(device);
    }

    fn publish_state(&self, device: &str) {
        let Some(state) = self.states.lock().ok().and_then(|s| s.get(device).cloned()) else {
            return;
        };
        self.send(
            format!("{}/{}/state", self.root, topic_level(device)),
            QoS::AtLeastOnce,
            true,
            state.to_string(),
        );
    }

    /// Publish an event of `device`, and its new state when the event changes it.
    pub fn observe(&self, device: &str, event: &Event) {
        if matches!(event, Event::Progress { .. }) && !self.progress {
            return;
        }
        let now = humantime::format_rfc3339_millis(std::time::SystemTime::now()).to_string();
        let mut payload = serde_json::to_value(event).unwrap_or(Value::Null);
        if let Value::Object(map) = &mut payload {
            map.insert("device".into(), device.into());
            map.insert("host".into(), self.host.clone().into());
            map.insert("at".into(), now.clone().into());
        }
        let qos = match event {
            Event::Progress { .. } | Event::Warmup { .. } => QoS::AtMostOnce,
            _ => QoS::AtLeastOnce,
        };
        self.send(
            format!(
                "{}/{}/event/{}",
                self.root,
                topic_level(device),
                event.name()
            ),
            qos,
            false,
            payload.to_string(),
        );
        let changed = {
            let Ok(mut states) = self.states.lock() else {
                return;
            };
            let state = states
                .entry(device.to_string())
                .or_insert_with(|| json!({"device": device}));
            update_state(state, event, &now)
        };
        if changed {
            self.publish_state(device);
        }
    }

    /// Say the daemon stopped (retained), leave the broker, and wait up to `timeout`
    /// for that to go out.
    pub async fn stop(&self, timeout: Duration) {
        self.send(
            format!("{}/status", self.root),
            QoS::AtLeastOnce,
            true,
            json!({"online": false, "reason": "stopped"}).to_string(),
        );
        let _ = self.client.try_disconnect();
        let task = self.task.lock().ok().and_then(|mut t| t.take());
        if let Some(task) = task {
            let abort = task.abort_handle();
            if tokio::time::timeout(timeout, task).await.is_err() {
                abort.abort();
            }
        }
    }
}

/// Update a device's state with `event`; true if it changed what the state says
/// (progress changes only the job's counts, which are not republished each reading).
fn update_state(state: &mut Value, event: &Event, now: &str) -> bool {
    let Value::Object(map) = state else {
        return false;
    };
    let mut set = |key: &str, value: Value| {
        map.insert(key.into(), value);
        true
    };
    let changed = match event {
        Event::JobStarted { job } => set("job", json!(job)),
        Event::JobFinished { job, outcome } => {
            set("job", Value::Null);
            set(
                "last_job",
                json!({"id": job.id, "kind": job.kind, "result": outcome.result, "message": outcome.message}),
            )
        }
        Event::Published {
            profile_id,
            how,
            held_out,
        } => set(
            "current_profile",
            json!({"id": profile_id, "how": how, "held_out": held_out, "at": now}),
        ),
        Event::RolledBack { entry } => set(
            "current_profile",
            json!({"id": entry.id, "how": entry.how, "held_out": entry.held_out, "at": entry.at}),
        ),
        Event::Verification { record } => set(
            "last_verification",
            json!({
                "at": record.at,
                "profile_id": record.profile_id,
                "stats": record.stats,
                "threshold": record.threshold,
                "passed": record.stats.is_some_and(|s| s.mean <= record.threshold),
                "escalated": record.escalated,
            }),
        ),
        Event::DeviceLost { message, fault } => set(
            "device_lost",
            json!({"at": now, "fault": fault, "message": message}),
        ),
        _ => false,
    };
    if changed {
        map.insert("updated".into(), now.into());
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_levels_lose_the_characters_mqtt_gives_a_meaning_to() {
        assert_eq!(topic_level("lab/left+#"), "lab_left__");
        assert_eq!(topic_level("desk-2_a"), "desk-2_a");
    }

    #[test]
    fn credentials_others_can_read_are_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mqtt.credentials");
        std::fs::write(&path, "lab\nsecret\n").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let error = read_credentials(&path).unwrap_err().to_string();
        assert!(error.contains("0600"), "{error}");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(
            read_credentials(&path).unwrap(),
            ("lab".to_string(), "secret".to_string())
        );
        std::fs::write(&path, "lab\n").unwrap();
        assert!(read_credentials(&path).is_err());
    }
}
