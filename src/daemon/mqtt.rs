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
//! A broker that is down or slow never holds a job up, and loses no outcome:
//! - outcome events (everything but `progress` and `warmup`) go into the client's
//!   bounded queue (`mqtt.queue`), and past it into a backlog of their own (up to
//!   [`MAX_BACKLOG`]), sent in order once the broker is back;
//! - progress is coalesced while the broker is away or the queue is full: only each
//!   device's newest is kept, sent on reconnection, and forgotten when the device's
//!   job ends (what it said is stale by then). What is coalesced away is counted
//!   (`chromacal_mqtt_messages_dropped_total`) and warned of (at most every 10 s).
//!
//! The retained status and states are published again at every connection, so a
//! broker that restarted without its store learns them again. A clean stop publishes
//! the `"stopped"` status, disconnects, and reads until the broker closes the
//! connection: closing with the broker's acknowledgements unread would reset the
//! connection, and a broker that sees a reset before the DISCONNECT sends the will.

use std::collections::{BTreeMap, VecDeque};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rumqttc::{AsyncClient, LastWill, MqttOptions, QoS};
use serde_json::{Value, json};

use super::events::Event;
use super::metrics::Metrics;
use super::serve::LogThrottle;
use crate::config::MqttConfig;
use crate::profile::store::VerificationRecord;
use chromacal_model::fit::stats::ErrorStats;

/// The largest packet sent or taken, bytes.
const MAX_PACKET: usize = 1 << 20;

/// Most outcome events kept beyond the client's queue while the broker is away; past
/// it the oldest are dropped, counted. A day of a busy fleet's outcomes fits.
pub const MAX_BACKLOG: usize = 10_000;

/// A message for the broker.
#[derive(Debug, Clone)]
struct Message {
    topic: String,
    qos: QoS,
    retain: bool,
    payload: String,
}

/// What waits for the broker: outcome events in order, and each device's newest
/// progress (by its topic).
#[derive(Default)]
struct Waiting {
    outcomes: VecDeque<Message>,
    progress: BTreeMap<String, Message>,
    /// A connection's catch-up is sending `outcomes`: new ones only join the end.
    catching_up: bool,
}

/// At each connection: the newest of each retained topic, then the outcome events
/// that waited, in order, then each device's newest progress, each waiting for room
/// in the client's queue (which the event loop empties) rather than dropped.
async fn catch_up(
    client: AsyncClient,
    retained: Arc<Mutex<BTreeMap<String, String>>>,
    waiting: Arc<Mutex<Waiting>>,
) {
    let topics = retained.lock().map(|r| r.clone()).unwrap_or_default();
    for (topic, payload) in topics {
        if client
            .publish(topic, QoS::AtLeastOnce, true, payload)
            .await
            .is_err()
        {
            return;
        }
    }
    loop {
        let next = {
            let Ok(mut w) = waiting.lock() else {
                return;
            };
            match w.outcomes.pop_front() {
                Some(m) => {
                    w.catching_up = true;
                    m
                }
                None => {
                    w.catching_up = false;
                    break;
                }
            }
        };
        if client
            .publish(next.topic, next.qos, next.retain, next.payload)
            .await
            .is_err()
        {
            if let Ok(mut w) = waiting.lock() {
                w.catching_up = false;
            }
            return;
        }
    }
    let progress = match waiting.lock() {
        Ok(mut w) => std::mem::take(&mut w.progress),
        Err(_) => return,
    };
    for m in progress.into_values() {
        let _ = client.try_publish(m.topic, m.qos, m.retain, m.payload);
    }
}

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

/// A user name on the first line and a password on the second; the file must not be
/// readable by others.
/// What a broker's refusal of the connection (its CONNACK code, MQTT 3.1.1 §3.2.2.3)
/// means for the config; `None` when the broker was not reached at all.
fn refusal_reason(error: &rumqttc::ConnectionError) -> Option<&'static str> {
    use rumqttc::ConnectReturnCode as Code;
    let rumqttc::ConnectionError::ConnectionRefused(code) = error else {
        return None;
    };
    Some(match code {
        Code::BadUserNamePassword => "wrong user name or password (mqtt.credentials_file)",
        Code::NotAuthorized => {
            "not authorised: the broker wants credentials (mqtt.credentials_file) or its ACL refuses this client"
        }
        Code::BadClientId => "it refuses the client id (mqtt.client_id)",
        Code::RefusedProtocolVersion => "it does not speak MQTT 3.1.1",
        Code::ServiceUnavailable => "it is unavailable",
        Code::Success => "no reason given",
    })
}

/// The uid this process runs as: the owner of its `/proc/self`.
fn own_uid() -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").ok().map(|m| m.uid())
}

fn read_credentials(path: &Path) -> Result<(String, String), MqttError> {
    use std::os::unix::fs::PermissionsExt;
    let error = |message: String| MqttError::Credentials {
        path: path.display().to_string(),
        message,
    };
    let metadata = std::fs::metadata(path).map_err(|e| error(e.to_string()))?;
    let mode = metadata.permissions().mode();
    {
        // A secret in a file another user owns is theirs to change or read.
        use std::os::unix::fs::MetadataExt;
        if let Some(me) = own_uid()
            && metadata.uid() != me
        {
            return Err(error(format!(
                "it belongs to uid {}, not to the daemon's user (uid {me}): give the daemon its own copy, mode 0600",
                metadata.uid()
            )));
        }
    }
    if mode & 0o077 != 0 {
        return Err(error(format!(
            "others can read it (mode {:o}): make it 0600",
            mode & 0o777
        )));
    }
    let text = chromacal_formats::durable::read_text_limited(
        path,
        chromacal_formats::durable::limits::PROFILE,
    )
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
    /// Whether the client is connected to the broker (its event loop says).
    connected: Arc<AtomicBool>,
    waiting: Arc<Mutex<Waiting>>,
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
        let host = topic_level(&config.host.clone().unwrap_or_else(super::host_name));
        let root = format!("{}/{host}", config.prefix.trim_end_matches('/'));
        let client_id = config
            .client_id
            .clone()
            .unwrap_or_else(|| format!("chromacal-{host}"));
        let mut options = MqttOptions::new(client_id, address, port);
        options.set_keep_alive(Duration::from_secs_f64(config.keep_alive_s));
        // A verification's event carries each patch's ΔE00: past rumqttc's default of
        // 10 KiB with a few hundred patches.
        options.set_max_packet_size(MAX_PACKET, MAX_PACKET);
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
        let online = online_status(devices);
        let retained = Arc::new(Mutex::new(BTreeMap::from([(status_topic, online)])));
        let connected = Arc::new(AtomicBool::new(false));
        let waiting = Arc::new(Mutex::new(Waiting::default()));
        let task = {
            let client = client.clone();
            let retained = retained.clone();
            let connected = connected.clone();
            let waiting = waiting.clone();
            let broker = config.broker.clone();
            tokio::spawn(async move {
                let mut failures = LogThrottle::default();
                let mut leaving = false;
                loop {
                    match eventloop.poll().await {
                        Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(_))) => {
                            tracing::info!(%broker, "MQTT connected");
                            connected.store(true, Ordering::SeqCst);
                            let client = client.clone();
                            let retained = retained.clone();
                            let waiting = waiting.clone();
                            tokio::spawn(catch_up(client, retained, waiting));
                        }
                        // Said goodbye: read on until the broker closes the connection,
                        // so that its acknowledgements are not left unread.
                        Ok(rumqttc::Event::Outgoing(rumqttc::Outgoing::Disconnect)) => {
                            leaving = true;
                        }
                        Ok(_) => {}
                        Err(_) if leaving => return,
                        Err(e) => {
                            connected.store(false, Ordering::SeqCst);
                            if let Some(n) = failures.note() {
                                match refusal_reason(&e) {
                                    Some(why) => {
                                        tracing::error!(%broker, error = %e, failures = n, "the MQTT broker refused the connection: {why}; trying again every second (outcome events wait, progress is coalesced)")
                                    }
                                    None => {
                                        tracing::warn!(%broker, error = %e, failures = n, "MQTT broker unreachable; trying again every second (outcome events wait, progress is coalesced)")
                                    }
                                }
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
            connected,
            waiting,
            task: Mutex::new(Some(task)),
        }))
    }

    /// Hand a retained message or an outcome event to the client's queue, behind any
    /// that wait already; what the queue has no room for waits (see the module's doc).
    fn send(&self, topic: String, qos: QoS, retain: bool, payload: String) {
        if retain && let Ok(mut r) = self.retained.lock() {
            r.insert(topic.clone(), payload.clone());
        }
        let Ok(mut waiting) = self.waiting.lock() else {
            return;
        };
        if retain {
            // Sent again, newest, at every connection: a full queue loses nothing.
            if waiting.outcomes.is_empty()
                && self.client.try_publish(topic, qos, retain, payload).is_ok()
            {
                self.metrics.mqtt(true);
            }
            return;
        }
        waiting.outcomes.push_back(Message {
            topic,
            qos,
            retain,
            payload,
        });
        if waiting.outcomes.len() > MAX_BACKLOG {
            waiting.outcomes.pop_front();
            self.note_dropped();
        }
        while !waiting.catching_up
            && let Some(m) = waiting.outcomes.front()
        {
            let m = m.clone();
            if self
                .client
                .try_publish(m.topic, m.qos, m.retain, m.payload)
                .is_err()
            {
                break;
            }
            waiting.outcomes.pop_front();
            self.metrics.mqtt(true);
        }
    }

    /// Send a progress event now if the broker is there and the queue has room, else
    /// keep it as its device's newest (the one it replaces is dropped, counted).
    fn send_progress(&self, topic: String, payload: String) {
        let Ok(mut waiting) = self.waiting.lock() else {
            return;
        };
        if self.connected.load(Ordering::SeqCst)
            && waiting.outcomes.is_empty()
            && !waiting.catching_up
            && self
                .client
                .try_publish(topic.clone(), QoS::AtMostOnce, false, payload.clone())
                .is_ok()
        {
            self.metrics.mqtt(true);
            return;
        }
        let message = Message {
            topic: topic.clone(),
            qos: QoS::AtMostOnce,
            retain: false,
            payload,
        };
        if waiting.progress.insert(topic, message).is_some() {
            self.note_dropped();
        }
    }

    /// Count a message that will never be sent, and warn (at most every 10 s).
    fn note_dropped(&self) {
        self.metrics.mqtt(false);
        if let Ok(mut throttle) = self.dropped.lock()
            && let Some(n) = throttle.note()
        {
            tracing::warn!(
                dropped = n,
                total = self.metrics.mqtt_dropped(),
                "MQTT broker away or slow: progress coalesced, older progress dropped"
            );
        }
    }

    /// A device's state at start: its current profile (id, held-out error, when
    /// made) and its last verification.
    pub fn restore(
        &self,
        device: &str,
        profile: Option<(&str, Option<ErrorStats>, &str)>,
        verification: Option<&VerificationRecord>,
    ) {
        let state = json!({
            "device": device,
            "job": null,
            "last_job": null,
            "current_profile": profile.map(|(id, held_out, at)| profile_state(id, "store", held_out, at)),
            "last_verification": verification.map(verification_state),
            "updated": now(),
        });
        if let Ok(mut states) = self.states.lock() {
            self.send_state(device, &state);
            states.insert(device.to_string(), state);
        }
    }

    fn send_state(&self, device: &str, state: &Value) {
        self.send(
            format!("{}/{}/state", self.root, topic_level(device)),
            QoS::AtLeastOnce,
            true,
            state.to_string(),
        );
    }

    /// Publish an event of `device`, and its new state when the event changes it.
    pub fn observe(&self, device: &str, event: &Event) {
        let now = now();
        if self.progress || !matches!(event, Event::Progress { .. }) {
            self.publish_event(device, event, &now);
        }
        // Changed and sent under one lock, so that two events of one device cannot
        // leave the older state retained.
        let Ok(mut states) = self.states.lock() else {
            return;
        };
        let state = states
            .entry(device.to_string())
            .or_insert_with(|| json!({"device": device}));
        if update_state(state, event, &now) {
            self.send_state(device, state);
        }
    }

    fn publish_event(&self, device: &str, event: &Event, now: &str) {
        let mut payload = super::events::event_json(device, event);
        if let Value::Object(map) = &mut payload {
            map.insert("host".into(), self.host.clone().into());
            map.insert("at".into(), now.into());
        }
        let topic = format!(
            "{}/{}/event/{}",
            self.root,
            topic_level(device),
            event.name()
        );
        match event {
            Event::Progress { .. } | Event::Warmup { .. } => {
                self.send_progress(topic, payload.to_string())
            }
            _ => {
                if matches!(event, Event::JobFinished { .. })
                    && let Ok(mut waiting) = self.waiting.lock()
                {
                    // The job is over: what its progress said is stale.
                    let mine = format!("{}/{}/event/", self.root, topic_level(device));
                    let before = waiting.progress.len();
                    waiting.progress.retain(|t, _| !t.starts_with(&mine));
                    for _ in waiting.progress.len()..before {
                        self.note_dropped();
                    }
                }
                self.send(topic, QoS::AtLeastOnce, false, payload.to_string())
            }
        }
    }

    /// The devices serving changed (a reload): the retained status names them.
    pub fn set_devices(&self, devices: &[String]) {
        self.send(
            format!("{}/status", self.root),
            QoS::AtLeastOnce,
            true,
            online_status(devices),
        );
    }

    /// A device left the daemon: its retained state is cleared (an empty retained
    /// message, which the broker takes as "delete").
    pub fn forget_device(&self, device: &str) {
        if let Ok(mut states) = self.states.lock() {
            states.remove(device);
        }
        self.send(
            format!("{}/{}/state", self.root, topic_level(device)),
            QoS::AtLeastOnce,
            true,
            String::new(),
        );
    }

    /// Publish an event of the whole daemon (a reload) under `<prefix>/<host>/event/`.
    pub fn observe_daemon(&self, event: &Event) {
        let mut payload = super::events::event_json("", event);
        if let Value::Object(map) = &mut payload {
            map.remove("device");
            map.insert("host".into(), self.host.clone().into());
            map.insert("at".into(), now().into());
        }
        self.send(
            format!("{}/event/{}", self.root, event.name()),
            QoS::AtLeastOnce,
            false,
            payload.to_string(),
        );
    }

    /// Say the daemon stopped (retained), leave the broker, and wait up to `timeout`
    /// for that to go out.
    pub async fn stop(&self, timeout: Duration) {
        let topic = format!("{}/status", self.root);
        let stopped = json!({"online": false, "reason": "stopped"}).to_string();
        if let Ok(mut r) = self.retained.lock() {
            r.insert(topic.clone(), stopped.clone());
        }
        let Some(task) = self.task.lock().ok().and_then(|mut t| t.take()) else {
            return;
        };
        let abort = task.abort_handle();
        let goodbye = async {
            // Waiting for room in the queue, behind what is queued: the status and
            // the DISCONNECT go out last, in that order; then the event loop reads
            // until the broker closes the connection.
            let _ = self
                .client
                .publish(topic, QoS::AtLeastOnce, true, stopped)
                .await;
            let _ = self.client.disconnect().await;
            let _ = task.await;
        };
        if tokio::time::timeout(timeout, goodbye).await.is_err() {
            tracing::warn!(
                "MQTT: the broker did not take the goodbye within {timeout:?}; it gives out the last will"
            );
            abort.abort();
        }
    }
}

/// The daemon's retained status while it runs, naming its devices.
fn online_status(devices: &[String]) -> String {
    json!({
        "online": true,
        "pid": std::process::id(),
        "version": env!("CARGO_PKG_VERSION"),
        "devices": devices,
    })
    .to_string()
}

/// The current profile as a device's state gives it: `how` it became current
/// (`calibration`, `uniformity`, `rollback`; `store` for what the store held at
/// start) and `at` when.
fn profile_state(id: &str, how: &str, held_out: Option<ErrorStats>, at: &str) -> Value {
    json!({"id": id, "how": how, "held_out": held_out, "at": at})
}

/// A verification as a device's state gives it.
fn verification_state(record: &VerificationRecord) -> Value {
    json!({
        "at": record.at,
        "profile_id": record.profile_id,
        "metric": record.metric,
        "stats": record.stats,
        "threshold": record.threshold,
        "passed": record.passed(),
        "escalated": record.escalated,
    })
}

fn now() -> String {
    chromacal_formats::time::now_rfc3339_millis()
}

/// Update a device's state with `event`; true if it changed what the state says
/// (progress changes only the job's counts, which are not republished each reading).
fn update_state(state: &mut Value, event: &Event, now: &str) -> bool {
    let Value::Object(map) = state else {
        return false;
    };
    let changes: Vec<(&str, Value)> = match event {
        Event::JobStarted { job } => vec![("job", json!(job))],
        Event::JobFinished { job, outcome } => {
            let last_job = json!({"id": job.id, "kind": job.kind, "result": outcome.result, "message": outcome.message});
            let mut changes = vec![("job", Value::Null), ("last_job", last_job)];
            // A job that went well says the devices are back.
            if outcome.result == "ok" {
                changes.push(("device_lost", Value::Null));
            }
            changes
        }
        // A new current profile: the last verification was of another.
        Event::Published {
            profile_id,
            how,
            held_out,
        } => vec![
            (
                "current_profile",
                profile_state(profile_id, how, *held_out, now),
            ),
            ("last_verification", Value::Null),
        ],
        Event::RolledBack { entry } => vec![
            (
                "current_profile",
                profile_state(&entry.id, &entry.how, entry.held_out, &entry.at),
            ),
            ("last_verification", Value::Null),
        ],
        Event::Verification { record } => vec![("last_verification", verification_state(record))],
        // A running job's state is republished when its phase changes (not at every
        // reading: the counts are in the progress events).
        Event::Progress { job }
            if map
                .get("job")
                .is_some_and(|j| j.is_object() && j["phase"] != job.phase.as_str()) =>
        {
            vec![("job", json!(job))]
        }
        Event::Warmup { job_id, .. }
            if map
                .get("job")
                .is_some_and(|j| j["id"] == job_id.as_str() && j["phase"] != "warming up") =>
        {
            let mut job = map.get("job").cloned().unwrap_or_default();
            job["phase"] = "warming up".into();
            vec![("job", job)]
        }
        Event::DeviceLost { message, fault } => vec![(
            "device_lost",
            json!({"at": now, "fault": fault, "message": message}),
        )],
        _ => Vec::new(),
    };
    if changes.is_empty() {
        return false;
    }
    for (key, value) in changes {
        map.insert(key.into(), value);
    }
    map.insert("updated".into(), now.into());
    true
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
    fn a_new_profile_forgets_the_old_verification_and_a_good_job_the_lost_device() {
        let mut state = json!({"device": "a"});
        let record = VerificationRecord {
            at: "t".into(),
            profile_id: "p".into(),
            metric: crate::verify::Metric::Itp,
            stats: ErrorStats::of(&[2.0]),
            delta_e: vec![2.0],
            threshold: 1.0,
            escalated: false,
            journal: None,
            verdict: None,
        };
        assert!(update_state(
            &mut state,
            &Event::Verification { record },
            "t1"
        ));
        assert_eq!(state["last_verification"]["passed"], false);
        assert_eq!(state["last_verification"]["metric"], "itp");
        let lost = Event::DeviceLost {
            fault: "instrument".into(),
            message: "timeout".into(),
        };
        assert!(update_state(&mut state, &lost, "t2"));
        assert_eq!(state["device_lost"]["fault"], "instrument");
        let published = Event::Published {
            profile_id: "q".into(),
            how: "calibration".into(),
            held_out: None,
        };
        assert!(update_state(&mut state, &published, "t3"));
        assert!(state["last_verification"].is_null());
        assert_eq!(state["current_profile"]["id"], "q");
        let job = crate::daemon::events::JobStatus {
            id: "j".into(),
            kind: crate::daemon::events::JobKind::Calibrate,
            origin: "api".into(),
            started: String::new(),
            phase: String::new(),
            done: 0,
            total: 0,
            eta_s: None,
            last: None,
        };
        let finished = |result: &str| Event::JobFinished {
            job: job.clone(),
            outcome: crate::daemon::events::JobOutcome {
                result: result.into(),
                message: String::new(),
                profile_id: None,
                published: false,
                escalated: false,
            },
        };
        assert!(update_state(&mut state, &finished("failed"), "t4"));
        assert_eq!(state["device_lost"]["fault"], "instrument");
        assert!(update_state(&mut state, &finished("ok"), "t5"));
        assert!(state["device_lost"].is_null());
        assert_eq!(state["updated"], "t5");
        // Progress changes nothing that is republished, but a job's new phase is.
        assert!(!update_state(
            &mut state,
            &Event::Progress { job: job.clone() },
            "t6"
        ));
        let mut measuring = job.clone();
        measuring.phase = "measuring".into();
        assert!(update_state(&mut state, &Event::JobStarted { job }, "t7"));
        assert!(update_state(
            &mut state,
            &Event::Progress {
                job: measuring.clone()
            },
            "t8"
        ));
        assert_eq!(state["job"]["phase"], "measuring");
        measuring.done += 1;
        assert!(!update_state(
            &mut state,
            &Event::Progress { job: measuring },
            "t9"
        ));
    }

    #[test]
    fn mqtt_settings_that_cannot_work_are_refused_with_the_key() {
        let ok = MqttConfig::default();
        assert!(ok.check().is_ok());
        for (config, said) in [
            (
                MqttConfig {
                    tls: true,
                    ..ok.clone()
                },
                "plain MQTT",
            ),
            (
                MqttConfig {
                    broker: "localhost".into(),
                    ..ok.clone()
                },
                "mqtt.broker",
            ),
            (
                MqttConfig {
                    prefix: "lab/#".into(),
                    ..ok.clone()
                },
                "mqtt.prefix",
            ),
            (
                MqttConfig {
                    prefix: "$SYS/lab".into(),
                    ..ok.clone()
                },
                "the broker's own",
            ),
            (
                MqttConfig {
                    prefix: "p".repeat(70_000),
                    ..ok.clone()
                },
                "mqtt.prefix = \"pppppppppppppppppppppppppppppppppppppppp…\" has 70000 bytes",
            ),
            (
                MqttConfig {
                    client_id: Some("c".repeat(300)),
                    ..ok.clone()
                },
                "mqtt.client_id",
            ),
            (
                MqttConfig {
                    host: Some(String::new()),
                    ..ok.clone()
                },
                "mqtt.host",
            ),
        ] {
            let error = config.check().unwrap_err();
            assert!(error.contains(said), "{error}");
        }
        // The numbers' ranges are the config's (`config/ranges.rs`).
        let error = crate::config::parse_config("[mqtt]\nqueue = 0\n", "t").unwrap_err();
        assert!(error.to_string().contains("mqtt.queue"), "{error}");
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
        // Another user's file is refused, naming the owner (as root: chown it).
        if own_uid() == Some(0) {
            std::fs::write(&path, "lab\nsecret\n").unwrap();
            std::os::unix::fs::chown(&path, Some(65534), None).unwrap();
            let error = read_credentials(&path).unwrap_err().to_string();
            assert!(error.contains("uid 65534"), "{error}");
        }
    }

    #[test]
    fn a_broker_refusing_the_login_is_named_as_such() {
        let refused = |code| rumqttc::ConnectionError::ConnectionRefused(code);
        let why = refusal_reason(&refused(rumqttc::ConnectReturnCode::BadUserNamePassword));
        assert!(why.unwrap().contains("password"));
        let why = refusal_reason(&refused(rumqttc::ConnectReturnCode::NotAuthorized));
        assert!(why.unwrap().contains("not authorised"));
        let io = rumqttc::ConnectionError::Io(std::io::Error::other("refused"));
        assert_eq!(refusal_reason(&io), None);
    }
}
