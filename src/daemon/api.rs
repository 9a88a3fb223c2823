//! The control API: HTTP/1.1 over the daemon's unix socket (mode 0600, and only the
//! socket's owner or root are answered), and optionally over loopback TCP with a
//! bearer token.
//!
//! | method and path | what |
//! |---|---|
//! | `GET /status` | daemon, running job (progress, ETA, last reading), last outcome, current profile |
//! | `POST /jobs` `{"kind": "calibrate"\|"verify"\|"uniformity"}` | start a job: 202, or 409 while one runs |
//! | `POST /jobs/cancel` | stop the running job after its reading: 202, or 404 |
//! | `GET /events` | server-sent events (`events.rs`) |
//! | `GET /profile[?format=toml\|json\|icc4\|icc2\|ti3\|cal\|psychopy&white=…&tone=…&luminance=…]` | the current profile, in any export format |
//! | `GET /history` | profiles made current, and every verification |
//! | `POST /rollback` `{"to": ID}` (or `{}`) | make an earlier profile current |
//! | `GET /devices` | the daemon's devices, each with its job and current profile |
//! | `GET /metrics` | Prometheus metrics of every device (`metrics.rs`); on TCP without the token unless `daemon.metrics_token` |
//!
//! Every route but the last two is a device's: `/devices/NAME/status`, `/devices/NAME/jobs`
//! and so on. Without `/devices/NAME` they are the only device's, and a daemon with
//! several refuses them (400) except `GET /events`, which then carries every
//! device's events (each names its `device`).
//!
//! Every refusal is JSON `{"error": "…"}` with a status that says which: 401 (no or
//! wrong token), 403 (not the socket's owner), 404 (no such endpoint, listing the real
//! ones), 405, 409, 413
//! (body over `daemon.max_body_bytes`), 429 (over `daemon.requests_per_s` on TCP, where
//! token holders and clients without a token each have their own bucket; the owner's
//! unix socket has none), 503 (too many event streams, or shutting down).

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use axum::Router;
use axum::extract::{
    ConnectInfo, DefaultBodyLimit, FromRequestParts, OriginalUri, Query, Request, State,
};
use axum::http::request::Parts;
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::{Deserialize, Serialize};
use serde_json::json;
use tokio_stream::StreamExt;
use tokio_stream::wrappers::BroadcastStream;

use super::access::{Access, Peer, bearer_credentials, same_secret};
use super::browser;
use super::events::{JobKind, JobOutcome, JobStatus};
use super::{Daemon, Device, JobRefused};
use crate::config::devices::NoDevice;

/// A token bucket. Token holders on TCP share one, and clients without a token (who
/// may only read `/metrics`, when `daemon.metrics_token` is off) another, so that a
/// flood of unauthenticated scrapes never starves a token holder. The owner on the
/// unix socket has none: its requests are its own, and the socket's connection cap
/// protects the daemon.
struct RateLimit {
    state: Mutex<(f64, Instant)>,
    per_s: f64,
    burst: f64,
}

impl RateLimit {
    fn allow(&self) -> bool {
        let Ok(mut state) = self.state.lock() else {
            return true;
        };
        let now = Instant::now();
        let (tokens, last) = *state;
        let tokens = (tokens + now.duration_since(last).as_secs_f64() * self.per_s).min(self.burst);
        if tokens >= 1.0 {
            *state = (tokens - 1.0, now);
            true
        } else {
            *state = (tokens, now);
            false
        }
    }
}

struct ApiState {
    daemon: Arc<Daemon>,
    access: Access,
    /// The TCP listener's buckets: token holders', and everyone else's.
    limit_tcp: RateLimit,
    limit_anonymous: RateLimit,
    streams: AtomicUsize,
    /// Refused TCP clients, logged at most once per 10 s.
    refusals: Mutex<super::serve::LogThrottle>,
    /// Browsers logged in on the TCP listener (see `browser`).
    sessions: super::browser::Sessions,
}

impl ApiState {
    /// Log a refused TCP client, at most once per 10 s with the count since.
    fn log_refusal(&self, addr: &SocketAddr) {
        let Ok(mut refusals) = self.refusals.lock() else {
            return;
        };
        if let Some(count) = refusals.note() {
            tracing::warn!(%addr, refused = count, "refused TCP clients without the right token (this one and those since the last such line)");
        }
    }
}

type Shared = Arc<ApiState>;

fn refusal(status: StatusCode, message: impl Into<String>) -> Response {
    (status, axum::Json(json!({ "error": message.into() }))).into_response()
}

/// A refusal of a client that may not use the API at all: the connection is closed
/// after it, so that no slot of the listener is held by a client without the token.
fn refusal_and_close(status: StatusCode, message: impl Into<String>) -> Response {
    let mut response = refusal(status, message);
    response.headers_mut().insert(
        header::CONNECTION,
        axum::http::HeaderValue::from_static("close"),
    );
    response
}

/// The router, for both listeners.
pub fn router(daemon: Arc<Daemon>, access: Access) -> Router {
    let config = &daemon.loaded.config.daemon;
    let bucket = || RateLimit {
        state: Mutex::new((config.burst as f64, Instant::now())),
        per_s: config.requests_per_s,
        burst: config.burst as f64,
    };
    let state = Arc::new(ApiState {
        limit_tcp: bucket(),
        limit_anonymous: bucket(),
        access,
        streams: AtomicUsize::new(0),
        refusals: Mutex::default(),
        sessions: Default::default(),
        daemon: daemon.clone(),
    });
    let max_body = config.max_body_bytes;
    // A device's routes, answered at the top for the only device and under
    // /devices/NAME for any.
    let device_routes = || {
        Router::new()
            .route("/status", get(status))
            .route("/jobs", post(start_job))
            .route("/jobs/cancel", post(cancel_job))
            .route("/events", get(events))
            .route("/profile", get(profile))
            .route("/history", get(history))
            .route("/report", get(report))
            .route("/rollback", post(rollback))
    };
    Router::new()
        .merge(device_routes())
        .nest("/devices/{device}", device_routes())
        .route("/devices", get(devices))
        .route("/metrics", get(metrics))
        .route("/reload", post(reload))
        .route("/", get(fleet))
        .route("/login", get(login_page).post(login))
        .route("/logout", post(logout))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(max_body))
        .layer(middleware::from_fn_with_state(state.clone(), guard))
        .with_state(state)
}

/// Who may call, how often, and how much they may send.
async fn guard(
    State(state): State<Shared>,
    ConnectInfo(peer): ConnectInfo<Peer>,
    request: Request,
    next: Next,
) -> Response {
    match peer {
        Peer::Local { uid } => {
            let allowed = uid.is_some_and(|u| u == state.access.owner || u == 0);
            if !allowed {
                let who = uid.map_or("an unknown user".to_string(), |u| format!("uid {u}"));
                tracing::warn!(who, "refused a local client that does not own the socket");
                return refusal_and_close(
                    StatusCode::FORBIDDEN,
                    format!(
                        "{who} may not use this daemon: only its owner (uid {}) and root may",
                        state.access.owner
                    ),
                );
            }
        }
        Peer::Tcp(_) => {}
    }
    let limit = match peer {
        Peer::Local { .. } => None,
        Peer::Tcp(addr) => {
            let sent = request
                .headers()
                .get(header::AUTHORIZATION)
                .and_then(|v| v.to_str().ok())
                .and_then(bearer_credentials);
            let holder = match (&state.access.token, sent) {
                (Some(token), Some(sent)) => same_secret(token, sent.trim()),
                _ => false,
            };
            let path = request.uri().path();
            let session = !holder && state.sessions.valid(request.headers());
            // A browser session only looks: whatever acts needs the token.
            if session && !browser::session_may(request.method(), path) {
                return refusal(
                    StatusCode::FORBIDDEN,
                    format!(
                        "a browser session may only look (GET); {} {path} needs the API token as 'Authorization: Bearer <token>'",
                        request.method()
                    ),
                );
            }
            let open = (path == "/metrics" && !state.daemon.loaded.config.daemon.metrics_token)
                || browser::open_path(path);
            if !holder && !session && !open {
                // A browser asking for the fleet page is shown the way in.
                if path == "/" && request.method() == axum::http::Method::GET {
                    return browser::see_other("/login", None);
                }
                state.log_refusal(&addr);
                return refusal_and_close(
                    StatusCode::UNAUTHORIZED,
                    "send the API token as 'Authorization: Bearer <token>' (daemon.token_file)",
                );
            }
            if (holder || session)
                && let Some(slot) = request.extensions().get::<Arc<super::serve::TcpSlot>>()
            {
                slot.promote();
            }
            Some(if holder || session {
                &state.limit_tcp
            } else {
                &state.limit_anonymous
            })
        }
    };
    if let Some(limit) = limit
        && !limit.allow()
    {
        return (
            StatusCode::TOO_MANY_REQUESTS,
            [(header::RETRY_AFTER, "1")],
            axum::Json(json!({"error": format!(
                "more than {} requests a second; slow down",
                limit.per_s
            )})),
        )
            .into_response();
    }
    let max = state.daemon.loaded.config.daemon.max_body_bytes;
    if let Some(length) = content_length(request.headers())
        && length > max
    {
        return refusal(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("the body has {length} bytes; the limit is {max} (daemon.max_body_bytes)"),
        );
    }
    let timeout =
        std::time::Duration::from_secs_f64(state.daemon.loaded.config.daemon.request_timeout_s);
    let Ok(mut response) = tokio::time::timeout(timeout, next.run(request)).await else {
        return refusal(
            StatusCode::REQUEST_TIMEOUT,
            format!(
                "the request took over {} s (daemon.request_timeout_s)",
                timeout.as_secs_f64()
            ),
        );
    };
    // The body limit of the extractors answers in plain text; say it in JSON too.
    if response.status() == StatusCode::PAYLOAD_TOO_LARGE && !is_json(response.headers()) {
        response = refusal(
            StatusCode::PAYLOAD_TOO_LARGE,
            format!("the body is over the limit of {max} bytes (daemon.max_body_bytes)"),
        );
    }
    response
}

fn content_length(headers: &HeaderMap) -> Option<usize> {
    headers
        .get(header::CONTENT_LENGTH)?
        .to_str()
        .ok()?
        .trim()
        .parse()
        .ok()
}

fn is_json(headers: &HeaderMap) -> bool {
    headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"))
}

/// A device's endpoints (`router`'s `device_routes`), answered at the top for the only
/// device and under `/devices/NAME` for any; listed in a 404.
pub const DEVICE_ENDPOINTS: [&str; 8] = [
    "GET /status",
    "POST /jobs",
    "POST /jobs/cancel",
    "GET /events",
    "GET /profile",
    "GET /history",
    "GET /report",
    "POST /rollback",
];

/// The daemon's own endpoints, listed in a 404.
pub const DAEMON_ENDPOINTS: [&str; 7] = [
    "GET /devices",
    "GET /metrics",
    "POST /reload",
    "GET /",
    "GET /login",
    "POST /login",
    "POST /logout",
];

async fn not_found(request: Request) -> Response {
    refusal(
        StatusCode::NOT_FOUND,
        format!(
            "no such endpoint: {} {}; the endpoints are {} (a device's also under /devices/NAME), {}",
            request.method(),
            request.uri().path(),
            DEVICE_ENDPOINTS.join(", "),
            DAEMON_ENDPOINTS.join(", ")
        ),
    )
}

async fn method_not_allowed(request: Request) -> Response {
    refusal(
        StatusCode::METHOD_NOT_ALLOWED,
        format!(
            "{} is not allowed on {}",
            request.method(),
            request.uri().path()
        ),
    )
}

/// The device a request is for: `/devices/NAME/…`, or the only one.
struct Dev(Arc<Device>);

/// The `NAME` of a path `/devices/NAME/…`.
fn device_in_path(path: &str) -> Option<&str> {
    path.strip_prefix("/devices/")?.split('/').next()
}

/// The `NAME` of `/devices/NAME/…`, from the path as the client sent it.
fn device_segment(parts: &Parts) -> Option<String> {
    let path = parts
        .extensions
        .get::<OriginalUri>()
        .map_or_else(|| parts.uri.path(), |u| u.0.path());
    device_in_path(path).map(String::from)
}

impl FromRequestParts<Shared> for Dev {
    type Rejection = Response;

    async fn from_request_parts(parts: &mut Parts, state: &Shared) -> Result<Self, Response> {
        let name = device_segment(parts);
        match state.daemon.device(name.as_deref()) {
            Ok(device) => Ok(Dev(device.clone())),
            Err(e @ NoDevice::Unknown { .. }) => Err(refusal(StatusCode::NOT_FOUND, e.to_string())),
            Err(e @ NoDevice::Ambiguous(_)) => Err(refusal(StatusCode::BAD_REQUEST, e.to_string())),
        }
    }
}

/// The job that ended last on a device, and how it ended.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LastJob {
    pub job: JobStatus,
    pub outcome: JobOutcome,
}

/// `GET /status`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StatusReply {
    /// The device this status is of.
    #[serde(default)]
    pub device: String,
    pub version: String,
    pub pid: u32,
    pub uptime_s: f64,
    pub state_dir: String,
    pub shutting_down: bool,
    /// A reload removed or changed the device: it takes no new job and leaves (or
    /// starts again on its new config) when its running job ends.
    #[serde(default)]
    pub retiring: bool,
    pub job: Option<JobStatus>,
    pub last_job: Option<LastJob>,
    pub current_profile: Option<CurrentProfile>,
    /// RFC 3339.
    pub next_verification: Option<String>,
    /// Calibration runs not ended in a profile (the one a running calibration
    /// measures included), oldest first; those whose fit failed twice are not resumed.
    #[serde(default)]
    pub unfinished_runs: Vec<crate::calibrate::session::UnfinishedRun>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CurrentProfile {
    pub id: String,
    pub created: String,
    pub held_out: Option<chromacal_model::fit::stats::ErrorStats>,
    pub path: String,
}

/// A device's status.
async fn device_status(daemon: &Daemon, device: &Arc<Device>) -> Result<StatusReply, String> {
    // Listing the runs reads their journals: off the async workers.
    let unfinished_runs = {
        let device = device.clone();
        tokio::task::spawn_blocking(move || {
            crate::calibrate::session::unfinished_runs(device.store())
        })
        .await
        .unwrap_or_default()
    };
    let current = device.read_current()?.map(|(p, _)| CurrentProfile {
        id: p.id,
        created: p.created,
        held_out: p.report.held_out,
        path: device.store().current_path().display().to_string(),
    });
    Ok(StatusReply {
        device: device.name.clone(),
        version: env!("CARGO_PKG_VERSION").into(),
        pid: std::process::id(),
        uptime_s: daemon.uptime_s(),
        state_dir: device.store().root().display().to_string(),
        shutting_down: daemon.is_shutting_down(),
        retiring: device.is_retired(),
        job: device.job(),
        last_job: device
            .last_outcome()
            .map(|(job, outcome)| LastJob { job, outcome }),
        current_profile: current,
        next_verification: device
            .next_verification()
            .map(chromacal_formats::time::rfc3339_seconds),
        unfinished_runs,
    })
}

async fn status(State(state): State<Shared>, Dev(device): Dev) -> Response {
    match device_status(&state.daemon, &device).await {
        Ok(reply) => axum::Json(reply).into_response(),
        Err(e) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e),
    }
}

/// `GET /devices`: every device's status, and which instrument it shares.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DevicesReply {
    pub devices: Vec<DeviceEntry>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DeviceEntry {
    pub name: String,
    /// `[instruments.NAME]` it takes turns on with other devices.
    pub shared_instrument: Option<String>,
    pub status: StatusReply,
}

async fn devices(State(state): State<Shared>) -> Response {
    let mut devices = Vec::new();
    for device in state.daemon.devices() {
        match device_status(&state.daemon, &device).await {
            Ok(status) => devices.push(DeviceEntry {
                name: device.name.clone(),
                shared_instrument: device.shared_instrument.as_ref().map(|(n, _)| n.clone()),
                status,
            }),
            Err(e) => return refusal(StatusCode::INTERNAL_SERVER_ERROR, e),
        }
    }
    axum::Json(DevicesReply { devices }).into_response()
}

/// `GET /metrics`: OpenMetrics to a client that asks for it (Prometheus does), the
/// classic text format to any other (`curl`, `promtool check metrics`).
async fn metrics(State(state): State<Shared>, headers: HeaderMap) -> Response {
    let open_metrics = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .any(|v| v.contains("application/openmetrics-text"));
    match state.daemon.bus.metrics.render() {
        Ok(text) if open_metrics => {
            ([(header::CONTENT_TYPE, super::metrics::CONTENT_TYPE)], text).into_response()
        }
        Ok(text) => (
            [(header::CONTENT_TYPE, super::metrics::CLASSIC_CONTENT_TYPE)],
            super::metrics::to_classic_text(&text),
        )
            .into_response(),
        Err(e) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StartJob {
    kind: String,
}

async fn start_job(Dev(device): Dev, body: axum::body::Bytes) -> Response {
    let request: StartJob = match serde_json::from_slice(&body) {
        Ok(r) => r,
        Err(e) => {
            return refusal(
                StatusCode::BAD_REQUEST,
                format!(
                    "the body must be {{\"kind\": \"calibrate\"|\"verify\"|\"uniformity\"}}: {e}"
                ),
            );
        }
    };
    let kind = match JobKind::parse(&request.kind) {
        Ok(k) => k,
        Err(e) => return refusal(StatusCode::BAD_REQUEST, e),
    };
    match device.start_job(kind, "api", None) {
        Ok(job) => (StatusCode::ACCEPTED, axum::Json(job)).into_response(),
        Err(e @ JobRefused::Busy { .. }) => refusal(StatusCode::CONFLICT, e.to_string()),
        Err(e @ (JobRefused::ShuttingDown | JobRefused::Retired(_))) => {
            refusal(StatusCode::SERVICE_UNAVAILABLE, e.to_string())
        }
    }
}

/// `GET /`: the fleet page; over TCP with a logout button (the session's).
async fn fleet(State(state): State<Shared>, ConnectInfo(peer): ConnectInfo<Peer>) -> Response {
    browser::fleet_page(&state.daemon, matches!(peer, Peer::Tcp(_))).await
}

async fn login_page() -> Response {
    browser::login_page()
}

/// `POST /login` with `token=…` (a form): a session cookie.
async fn login(State(state): State<Shared>, body: axum::body::Bytes) -> Response {
    browser::login(&state.sessions, state.access.token.as_deref(), &body)
}

async fn logout(State(state): State<Shared>, headers: HeaderMap) -> Response {
    browser::logout(&state.sessions, &headers)
}

/// `POST /reload`: reread the config (as SIGHUP does). 200 with what changed, or 422
/// with why the config was refused (the daemon runs on with the one it had).
async fn reload(State(state): State<Shared>) -> Response {
    match state.daemon.reload("api").await {
        Ok(reloaded) => axum::Json(reloaded).into_response(),
        Err(e) => refusal(StatusCode::UNPROCESSABLE_ENTITY, e),
    }
}

async fn cancel_job(Dev(device): Dev) -> Response {
    match device.cancel_job() {
        Some(job) => (StatusCode::ACCEPTED, axum::Json(job)).into_response(),
        None => refusal(StatusCode::NOT_FOUND, "no job is running"),
    }
}

/// Keeps the count of open event streams.
struct StreamSlot(Shared);

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.streams.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The event stream's keep-alive interval: 15 s, or a third of the idle timeout if
/// that is shorter.
fn keep_alive_interval(idle_timeout_s: f64) -> std::time::Duration {
    std::time::Duration::from_secs_f64((idle_timeout_s / 3.0).min(15.0))
}

/// `GET /events`: every device's events; `GET /devices/NAME/events`: that device's.
async fn events(State(state): State<Shared>, uri: OriginalUri) -> Response {
    let only = match device_in_path(uri.0.path()) {
        Some(name) => match state.daemon.device(Some(name)) {
            Ok(device) => Some(device.name.clone()),
            Err(e) => return refusal(StatusCode::NOT_FOUND, e.to_string()),
        },
        None => None,
    };
    let max = state.daemon.loaded.config.daemon.max_event_streams;
    if state.streams.fetch_add(1, Ordering::SeqCst) >= max {
        state.streams.fetch_sub(1, Ordering::SeqCst);
        return refusal(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{max} event streams are open already (daemon.max_event_streams)"),
        );
    }
    let slot = StreamSlot(state.clone());
    let stream = BroadcastStream::new(state.daemon.bus.events.subscribe())
        .filter(move |item| match (item, &only) {
            (Ok(event), Some(name)) => event.device == *name,
            _ => true,
        })
        .map(move |item| {
            let _held = &slot;
            Ok::<_, std::convert::Infallible>(match item {
                Ok(event) => SseEvent::default()
                    .event(event.event.name())
                    .data(event.to_json().to_string()),
                Err(tokio_stream::wrappers::errors::BroadcastStreamRecvError::Lagged(n)) => {
                    SseEvent::default()
                        .event("lagged")
                        .data(json!({ "missed": n }).to_string())
                }
            })
        });
    Sse::new(stream)
        // Often enough that a quiet stream is never taken for an idle connection.
        .keep_alive(KeepAlive::new().interval(keep_alive_interval(
            state.daemon.loaded.config.daemon.idle_timeout_s,
        )))
        .into_response()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProfileQuery {
    format: Option<String>,
    /// Calibration target, as `chromacal export` takes it (for `cal` and `vcgt`).
    white: Option<String>,
    tone: Option<String>,
    luminance: Option<String>,
}

/// `GET /profile[?format=…&white=…&tone=…&luminance=…]`: the current profile in any
/// export format. What the format cannot carry is listed in `x-chromacal-not-carried`.
async fn profile(
    Dev(device): Dev,
    query: Result<Query<ProfileQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    use crate::export::{ExportOptions, Format, export, parse_target};
    // Refused in JSON like every other refusal (axum's own answer is plain text).
    let Query(query) = match query {
        Ok(q) => q,
        Err(e) => {
            return refusal(
                StatusCode::BAD_REQUEST,
                format!("the query string: {}", e.body_text()),
            );
        }
    };
    let (profile, text) = match device.read_current() {
        Ok(Some(c)) => c,
        Ok(None) => return refusal(StatusCode::NOT_FOUND, "there is no current profile yet"),
        Err(e) => return refusal(StatusCode::INTERNAL_SERVER_ERROR, e),
    };
    let format = match Format::parse(query.format.as_deref().unwrap_or("toml")) {
        Ok(f) => f,
        Err(e) => return refusal(StatusCode::BAD_REQUEST, e.to_string()),
    };
    if format == Format::Toml {
        return ([(header::CONTENT_TYPE, "application/toml")], text).into_response();
    }
    let target = match parse_target(
        query.white.as_deref(),
        query.tone.as_deref(),
        query.luminance.as_deref(),
    ) {
        Ok(t) => t,
        Err(e) => return refusal(StatusCode::BAD_REQUEST, e.to_string()),
    };
    let options = ExportOptions {
        target,
        measurements: None,
        native: false,
    };
    let id = profile.id.clone();
    let exported = tokio::task::spawn_blocking(move || export(&profile, format, &options)).await;
    match exported {
        Ok(Ok(exported)) => {
            let notes = header_text(exported.not_carried.iter().chain(&exported.warnings));
            let carried = header_text(&exported.carried);
            let disposition = format!("attachment; filename=\"{id}.{}\"", format.extension());
            let mut response = exported.bytes.into_response();
            let headers = response.headers_mut();
            let mut set = |name: &'static str, value: &str| {
                if let Ok(v) = header::HeaderValue::from_str(value) {
                    headers.insert(name, v);
                }
            };
            set("content-type", format.content_type());
            set("content-disposition", &disposition);
            if !notes.is_empty() {
                set("x-chromacal-not-carried", &notes);
            }
            if !carried.is_empty() {
                set("x-chromacal-carried", &carried);
            }
            response
        }
        Ok(Err(e)) => refusal(StatusCode::UNPROCESSABLE_ENTITY, e.to_string()),
        Err(e) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

/// `notes` joined by "; " as a header value, which is ASCII: anything else becomes '?'.
fn header_text<'a>(notes: impl IntoIterator<Item = &'a String>) -> String {
    notes
        .into_iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .join("; ")
        .chars()
        .map(|c| {
            if c.is_ascii() && !c.is_ascii_control() {
                c
            } else {
                '?'
            }
        })
        .collect()
}

/// `GET /report`: the current profile's HTML report, with the readings of its run
/// and the store's history of profiles and verifications.
async fn report(Dev(device): Dev) -> Response {
    use crate::html_report::{HistoryView, ReportInput, readings_of, report_html};
    use crate::verification::Criteria;
    let profile = match device.read_current() {
        Ok(Some((profile, _))) => profile,
        Ok(None) => return refusal(StatusCode::NOT_FOUND, "there is no current profile yet"),
        Err(e) => return refusal(StatusCode::INTERNAL_SERVER_ERROR, e),
    };
    // Reading the journal and drawing the figures take tens of milliseconds: off the
    // async workers, as a fit is.
    let page = tokio::task::spawn_blocking(move || {
        let (readings, readings_note) = match readings_of(&profile) {
            Ok(set) => (Some(set), None),
            Err(why) => (None, Some(why)),
        };
        // The verification sections judge the newest verification of this profile,
        // measured after it was made, when its readings are still there.
        let checked = device
            .store()
            .verifications()
            .unwrap_or_default()
            .into_iter()
            .rev()
            .filter(|v| v.profile_id == profile.id)
            .find_map(|v| {
                crate::measurement_file::read_measurements(std::path::Path::new(&v.journal?)).ok()
            });
        let verified = crate::calibrate::verify::saved_in(device.store().root(), &profile.id);
        report_html(&ReportInput {
            profile: &profile,
            readings: readings.as_ref(),
            readings_note,
            verified: verified.as_ref(),
            history: Some(HistoryView::from_store(device.store())),
            device: Some(device.name.clone()),
            checked: checked.as_ref(),
            // Judged as its verify jobs and the fleet page judge it.
            criteria: Criteria::verification_threshold_for(
                &device.loaded.config.schedule,
                profile.provenance.signal,
            ),
        })
    })
    .await;
    match page {
        Ok(Ok(page)) => {
            ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], page).into_response()
        }
        Ok(Err(e)) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
        Err(e) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

async fn history(Dev(device): Dev) -> Response {
    let store = device.store();
    match (store.history(), store.verifications()) {
        (Ok(history), Ok(verifications)) => axum::Json(json!({
            "current": history.current,
            "profiles": history.entries,
            "verifications": verifications,
        }))
        .into_response(),
        (Err(e), _) | (_, Err(e)) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct Rollback {
    to: Option<String>,
}

async fn rollback(Dev(device): Dev, body: axum::body::Bytes) -> Response {
    let request: Rollback = if body.iter().all(|b| b.is_ascii_whitespace()) {
        Rollback::default()
    } else {
        match serde_json::from_slice(&body) {
            Ok(r) => r,
            Err(e) => {
                return refusal(
                    StatusCode::BAD_REQUEST,
                    format!("the body must be {{\"to\": \"<profile id>\"}} or empty: {e}"),
                );
            }
        }
    };
    match device.store().rollback(request.to.as_deref()) {
        Ok(entry) => {
            tracing::info!(device = %device.name, profile = %entry.id, "rolled back");
            device.emit(super::events::Event::RolledBack {
                entry: entry.clone(),
            });
            axum::Json(entry).into_response()
        }
        Err(e @ crate::profile::store::StoreError::NoRollback(_)) => {
            refusal(StatusCode::CONFLICT, e.to_string())
        }
        Err(e @ crate::profile::store::StoreError::InvalidId(_)) => {
            refusal(StatusCode::BAD_REQUEST, e.to_string())
        }
        Err(e) => refusal(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}
