//! The web patch page: chromacal serves a page that a browser shows full-screen on the
//! display being measured (`../shared/INTERFACES.md` A2).
//!
//! * `GET /`: the page, a black body with one absolutely placed patch, no controls.
//! * `GET /events`: server-sent events, one per patch: id, colours, geometry.
//! * `POST /ack?id=N`: the page says patch N is painted. It sends this after two
//!   animation frames following the style change, so the frame with the patch has been
//!   produced; `show` resolves on it, then waits the display's settle time.
//! * `GET /ajax/messages`: long-poll compatibility with ArgyllCMS `-d web` (`#RRGGBB`)
//!   and DisplayCAL's web display (`#RRGGBB|#RRGGBB|x|y|w|h`). There a client's next
//!   poll is the acknowledgement, which proves receipt rather than paint, as in those
//!   tools.
//!
//! Anything else is 404. The page can acknowledge patches and nothing more: it cannot
//! start, stop or change anything in chromacal.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{RawQuery, State};
use axum::http::{StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::{Deserialize, Serialize};
use tokio::sync::watch;
use tokio_stream::StreamExt;
use tokio_stream::wrappers::WatchStream;

use super::resolve::code_value;
use super::{DisplayError, PatchDisplay};
use chromacal_model::screen::{Codes, Geometry, Patch};

/// `[display.web]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WebConfig {
    /// Where to serve the page; loopback unless the browser runs on another machine.
    pub address: String,
    /// Video levels (16–235) instead of full range.
    pub video_levels: bool,
    /// A connected browser that has not confirmed painting a patch after this many
    /// seconds is taken as lost (a hidden tab paints nothing).
    pub ack_timeout_s: f64,
    /// Give up when no browser is connected for this long; none: wait forever.
    pub connect_timeout_s: Option<f64>,
}

impl Default for WebConfig {
    fn default() -> Self {
        WebConfig {
            address: "127.0.0.1:8080".into(),
            video_levels: false,
            ack_timeout_s: 30.0,
            connect_timeout_s: None,
        }
    }
}

/// A long-poll is answered after this long even when nothing changed, so that no proxy
/// or browser times it out.
const POLL_HOLD: Duration = Duration::from_secs(20);

/// A poller counts as connected for this long after its last request.
const POLLER_PRESENCE: Duration = Duration::from_secs(30);

/// One patch as the page receives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PageState {
    /// 0 before the first patch.
    pub id: u64,
    /// `#RRGGBB`, uppercase hex.
    pub patch: String,
    pub background: String,
    pub x: f64,
    pub y: f64,
    pub w: f64,
    pub h: f64,
}

impl PageState {
    /// The grey both Argyll and DisplayCAL start with.
    fn initial() -> Self {
        PageState {
            id: 0,
            patch: "#808080".into(),
            background: "#808080".into(),
            x: 0.0,
            y: 0.0,
            w: 1.0,
            h: 1.0,
        }
    }

    /// DisplayCAL's six fields, geometry with 4 decimals.
    pub fn displaycal_fields(&self) -> String {
        format!(
            "{}|{}|{:.4}|{:.4}|{:.4}|{:.4}",
            self.patch, self.background, self.x, self.y, self.w, self.h
        )
    }
}

/// `#RRGGBB` (uppercase) of 8-bit codes, mapped onto video levels if asked.
pub fn hex_colour(codes: &Codes, video_levels: bool) -> String {
    let c = if video_levels {
        codes.drive().map(|v| code_value(v, 8, true))
    } else {
        codes.rgb
    };
    format!("#{:02X}{:02X}{:02X}", c[0], c[1], c[2])
}

struct Shared {
    /// What the page should show (the display holds the sender: when it goes, event
    /// streams end and held polls return).
    current: watch::Receiver<PageState>,
    /// The newest patch id a browser confirmed.
    acked: watch::Sender<u64>,
    /// Event streams open now.
    streams: AtomicUsize,
    /// The last id handed to an Argyll-style poller, and when any poller last asked.
    served: Mutex<(u64, Option<Instant>)>,
}

impl Shared {
    fn acknowledge(&self, id: u64) {
        self.acked.send_if_modified(|a| {
            let newer = id > *a;
            if newer {
                *a = id;
            }
            newer
        });
    }

    fn browser_present(&self) -> bool {
        self.streams.load(Ordering::SeqCst) > 0
            || self
                .served
                .lock()
                .ok()
                .and_then(|s| s.1)
                .is_some_and(|t| t.elapsed() < POLLER_PRESENCE)
    }
}

/// Keeps the count of open event streams.
struct StreamGuard(Arc<Shared>);

impl Drop for StreamGuard {
    fn drop(&mut self) {
        self.0.streams.fetch_sub(1, Ordering::SeqCst);
    }
}

const PAGE: &str = r#"<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>chromacal patch</title>
<style>
html, body { margin: 0; padding: 0; width: 100%; height: 100%; overflow: hidden; cursor: none; background: #000000; }
#patch { position: absolute; left: 0; top: 0; width: 0; height: 0; }
</style></head>
<body><div id="patch"></div>
<script>
"use strict";
const patch = document.getElementById("patch");
const events = new EventSource("/events");
events.onmessage = function (message) {
  const p = JSON.parse(message.data);
  document.body.style.background = p.background;
  patch.style.background = p.patch;
  patch.style.left = (p.x * 100) + "%";
  patch.style.top = (p.y * 100) + "%";
  patch.style.width = (p.w * 100) + "%";
  patch.style.height = (p.h * 100) + "%";
  if (p.id > 0) {
    // The first callback runs before the frame with the new style is produced, the
    // second after it: only then is the patch on the screen.
    requestAnimationFrame(function () {
      requestAnimationFrame(function () {
        fetch("/ack?id=" + p.id, { method: "POST" });
      });
    });
  }
};
</script></body></html>
"#;

fn no_cache(content_type: &'static str, body: String) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

async fn page() -> Response {
    no_cache("text/html; charset=UTF-8", PAGE.to_string())
}

async fn events(State(shared): State<Arc<Shared>>) -> impl IntoResponse {
    shared.streams.fetch_add(1, Ordering::SeqCst);
    let guard = StreamGuard(shared.clone());
    let stream = WatchStream::new(shared.current.clone()).map(move |state| {
        let _alive = &guard;
        let data = serde_json::to_string(&state).unwrap_or_default();
        Ok::<_, std::convert::Infallible>(Event::default().id(state.id.to_string()).data(data))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

async fn ack(State(shared): State<Arc<Shared>>, RawQuery(query): RawQuery) -> Response {
    let id = query
        .as_deref()
        .and_then(|q| q.split('&').find_map(|kv| kv.strip_prefix("id=")))
        .and_then(|v| v.parse::<u64>().ok());
    let current = shared.current.borrow().id;
    match id {
        Some(id) if (1..=current).contains(&id) => {
            shared.acknowledge(id);
            StatusCode::NO_CONTENT.into_response()
        }
        Some(id) => (
            StatusCode::BAD_REQUEST,
            format!("no patch {id} was shown\n"),
        )
            .into_response(),
        None => (StatusCode::BAD_REQUEST, "give ?id=N\n").into_response(),
    }
}

/// Decode `%XX` escapes and `+` of a query string (invalid escapes stay as they are).
fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'%' if i + 2 < bytes.len() => {
                let hex = |b: u8| (b as char).to_digit(16);
                match (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                    (Some(h), Some(l)) => {
                        out.push((h * 16 + l) as u8);
                        i += 3;
                        continue;
                    }
                    _ => out.push(b'%'),
                }
            }
            b'+' => out.push(b' '),
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `/ajax/messages`: DisplayCAL's form when the query carries `|`-separated fields,
/// Argyll's otherwise (its query is ignored, as Argyll does).
async fn ajax_messages(State(shared): State<Arc<Shared>>, RawQuery(query): RawQuery) -> Response {
    let query = percent_decode(query.as_deref().unwrap_or(""));
    let fields: Vec<&str> = query.split('|').collect();
    let mut current = shared.current.clone();
    if fields.len() >= 6 {
        let client = fields[..6].join("|");
        if let Ok(mut s) = shared.served.lock() {
            s.1 = Some(Instant::now());
        }
        let state = current.borrow_and_update().clone();
        if state.displaycal_fields() == client {
            // The client shows the current patch: that is its acknowledgement. Hold
            // the request until there is something new.
            shared.acknowledge(state.id);
            let _ = tokio::time::timeout(POLL_HOLD, current.changed()).await;
        }
        let state = current.borrow().clone();
        return no_cache("text/plain; charset=UTF-8", state.displaycal_fields());
    }
    // Argyll: each request acknowledges the colour served before it, then waits for a
    // newer one.
    let last_served = match shared.served.lock() {
        Ok(mut s) => {
            s.1 = Some(Instant::now());
            s.0
        }
        Err(_) => 0,
    };
    if last_served > 0 {
        shared.acknowledge(last_served);
    }
    let deadline = tokio::time::Instant::now() + POLL_HOLD;
    loop {
        let id = current.borrow_and_update().id;
        if id > last_served || last_served == 0 {
            break;
        }
        match tokio::time::timeout_at(deadline, current.changed()).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) | Err(_) => break, // the display closed, or held long enough
        }
    }
    let state = current.borrow().clone();
    if let Ok(mut s) = shared.served.lock() {
        s.0 = state.id;
    }
    no_cache("text/plain", state.patch)
}

async fn not_found() -> Response {
    (StatusCode::NOT_FOUND, "404 Not Found\n").into_response()
}

/// The web patch page as a patch display.
pub struct WebDisplay {
    current: watch::Sender<PageState>,
    shared: Arc<Shared>,
    address: SocketAddr,
    config: WebConfig,
    settle_s: f64,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    /// Times the run waited for a browser to (re)connect.
    pub waits_for_browser: usize,
}

impl Drop for WebDisplay {
    /// Stop serving: new connections are refused, open event streams end.
    fn drop(&mut self) {
        if let Some(stop) = self.shutdown.take() {
            let _ = stop.send(());
        }
    }
}

impl WebDisplay {
    /// Serve the page on `config.address` (port 0 picks a free one).
    pub async fn bind(config: WebConfig, settle_s: f64) -> Result<Self, DisplayError> {
        let listener = tokio::net::TcpListener::bind(&config.address)
            .await
            .map_err(|e| DisplayError::Lost(format!("cannot listen on {}: {e}", config.address)))?;
        let address = listener
            .local_addr()
            .map_err(|e| DisplayError::Lost(e.to_string()))?;
        if !address.ip().is_loopback() {
            tracing::warn!(%address, "the patch page is served beyond this machine: any host that can reach it can watch the patches");
        }
        let (current, receiver) = watch::channel(PageState::initial());
        let (acked, _) = watch::channel(0);
        let shared = Arc::new(Shared {
            current: receiver,
            acked,
            streams: AtomicUsize::new(0),
            served: Mutex::new((0, None)),
        });
        let app = Router::new()
            .route("/", get(page))
            .route("/events", get(events))
            .route("/ack", post(ack))
            .route("/ajax/messages", get(ajax_messages))
            .fallback(not_found)
            .with_state(shared.clone());
        let (shutdown, stop) = tokio::sync::oneshot::channel::<()>();
        tokio::spawn(async move {
            let serve = axum::serve(listener, app).with_graceful_shutdown(async move {
                let _ = stop.await;
            });
            if let Err(e) = serve.await {
                tracing::error!(error = %e, "the patch page's server stopped");
            }
        });
        tracing::info!(
            "patch page at http://{address}/ : open it full-screen on the display to measure"
        );
        Ok(WebDisplay {
            current,
            shared,
            address,
            config,
            settle_s,
            shutdown: Some(shutdown),
            waits_for_browser: 0,
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.address
    }

    /// The URL to open in the browser.
    pub fn url(&self) -> String {
        format!("http://{}/", self.address)
    }

    /// The newest patch id a browser confirmed.
    pub fn acknowledged(&self) -> u64 {
        *self.shared.acked.borrow()
    }

    fn publish(&self, patch: &Patch) -> Result<u64, DisplayError> {
        for codes in [&patch.codes, &patch.background] {
            if codes.bit_depth != 8 {
                return Err(DisplayError::Unsupported(format!(
                    "the web page paints 8 bits per channel, the patch has {} (set plan.bit_depth = 8)",
                    codes.bit_depth
                )));
            }
        }
        let id = self.current.borrow().id + 1;
        let g = patch.geometry;
        self.current.send_replace(PageState {
            id,
            patch: hex_colour(&patch.codes, self.config.video_levels),
            background: hex_colour(&patch.background, self.config.video_levels),
            x: g.x,
            y: g.y,
            w: g.width,
            h: g.height,
        });
        Ok(id)
    }

    /// Wait until a browser confirms patch `id`: indefinitely (or up to the connect
    /// timeout) while no browser is there, up to the acknowledgement timeout while one is.
    async fn wait_for_ack(&mut self, id: u64, ack_timeout: Duration) -> Result<(), DisplayError> {
        let mut acked = self.shared.acked.subscribe();
        let mut present_since: Option<Instant> = None;
        let mut absent_since: Option<Instant> = None;
        loop {
            if *acked.borrow_and_update() >= id {
                return Ok(());
            }
            if self.shared.browser_present() {
                absent_since = None;
                let since = *present_since.get_or_insert_with(Instant::now);
                if since.elapsed() > ack_timeout {
                    return Err(DisplayError::Lost(format!(
                        "the browser at {} did not confirm painting patch {id} within {:.0} s (a hidden or minimised tab paints nothing)",
                        self.url(),
                        ack_timeout.as_secs_f64()
                    )));
                }
            } else {
                present_since = None;
                let since = *absent_since.get_or_insert_with(|| {
                    self.waits_for_browser += 1;
                    tracing::warn!(url = %self.url(), "no browser shows the patch page; the run waits for one");
                    Instant::now()
                });
                if let Some(t) = self.config.connect_timeout_s
                    && since.elapsed().as_secs_f64() > t
                {
                    return Err(DisplayError::Lost(format!(
                        "no browser opened {} within {t} s",
                        self.url()
                    )));
                }
            }
            let _ = tokio::time::timeout(Duration::from_millis(100), acked.changed()).await;
        }
    }
}

impl PatchDisplay for WebDisplay {
    fn name(&self) -> String {
        format!("web patch page at {}", self.url())
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        let id = self.publish(patch)?;
        let timeout = Duration::from_secs_f64(self.config.ack_timeout_s.max(0.1));
        self.wait_for_ack(id, timeout).await?;
        tokio::time::sleep(Duration::from_secs_f64(self.settle_s)).await;
        Ok(())
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        let black = Codes::from_drive([0.0; 3], 8);
        let id = self.publish(&Patch {
            codes: black,
            background: black,
            geometry: Geometry {
                x: 0.0,
                y: 0.0,
                width: 1.0,
                height: 1.0,
            },
        })?;
        // Blanking is best effort: a browser that is gone cannot be blanked.
        if self.shared.browser_present() {
            let _ = self.wait_for_ack(id, Duration::from_secs(2)).await;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_are_uppercase_hex_of_the_codes() {
        let c = Codes {
            rgb: [26, 128, 230],
            bit_depth: 8,
        };
        assert_eq!(hex_colour(&c, false), "#1A80E6");
        let white = Codes::from_drive([1.0; 3], 8);
        assert_eq!(hex_colour(&white, true), "#EBEBEB");
        assert_eq!(hex_colour(&Codes::from_drive([0.0; 3], 8), true), "#101010");
    }

    #[test]
    fn queries_decode() {
        assert_eq!(
            percent_decode("%23808080%7C%23808080%7C0%7C0%7C1%7C1%7C0.5"),
            "#808080|#808080|0|0|1|1|0.5"
        );
        assert_eq!(percent_decode("a+b%2"), "a b%2");
        assert_eq!(percent_decode("%zz"), "%zz");
    }
}
