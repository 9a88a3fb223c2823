//! Serving the API's connections, with the limits that keep one client from wedging
//! the daemon.
//!
//! `axum::serve` reads request headers for as long as a client cares to send them and
//! keeps idle connections for ever, so a local user without a token could hold every
//! descriptor the daemon has with half-open TCP connections (then the owner's
//! requests time out and a calibration fails at publish with "Too many open files").
//! Here each listener has its own cap on connections, so the unix socket's owner
//! always gets through however the TCP listener is used; headers must arrive within
//! `header_timeout_s`; a connection on which nothing is read or written for
//! `idle_timeout_s` is closed; and a handler (with its request body) must be done
//! within `request_timeout_s` (in `api.rs`).
//!
//! On TCP, a connection is *anonymous* until one of its requests shows the token (or
//! a browser session): anonymous connections have a budget of their own
//! (`max_connections`), and when it is full the oldest anonymous connection is closed
//! to make room for the newcomer, so that clients without the token who hold every
//! slot (idle, trickling headers, or scraping the open `/metrics`) cannot keep a
//! token holder out: the holder's connection gets in, shows the token with its first
//! request, and moves to the token holders' budget (another `max_connections`).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tower::ServiceExt;

use super::access::Peer;
use crate::config::daemon::DaemonConfig;

/// The per-connection limits, from `[daemon]`.
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// Connections open at once on one listener.
    pub max_connections: usize,
    /// Time to receive a request's whole header block (also the time an idle
    /// keep-alive connection waits for its next request).
    pub header_timeout: Duration,
    /// Time with nothing read or written before a connection is closed.
    pub idle_timeout: Duration,
}

impl ConnectionLimits {
    /// The TCP listener's limits.
    pub fn tcp(config: &DaemonConfig) -> Self {
        Self::with_cap(config, config.max_connections)
    }

    /// The unix socket's limits: its own cap, so TCP clients cannot use it up.
    pub fn local(config: &DaemonConfig) -> Self {
        Self::with_cap(config, config.max_local_connections)
    }

    fn with_cap(config: &DaemonConfig, max_connections: usize) -> Self {
        ConnectionLimits {
            max_connections,
            header_timeout: Duration::from_secs_f64(config.header_timeout_s),
            idle_timeout: Duration::from_secs_f64(config.idle_timeout_s),
        }
    }
}

/// A listener the API serves on.
pub enum Listener {
    Unix(tokio::net::UnixListener),
    Tcp(tokio::net::TcpListener),
}

impl Listener {
    fn name(&self) -> &'static str {
        match self {
            Listener::Unix(_) => "unix socket",
            Listener::Tcp(_) => "TCP listener",
        }
    }
}

/// Raise the soft limit on open descriptors to the hard limit, so that the caps on
/// connections, not the descriptor table, are what a flood of clients meets.
pub fn raise_descriptor_limit() {
    match rlimit::increase_nofile_limit(u64::MAX) {
        Ok(limit) => tracing::debug!(limit, "open descriptor limit"),
        Err(e) => tracing::warn!(error = %e, "cannot raise the open descriptor limit"),
    }
}

/// The TCP listener's two budgets of connections.
struct Budgets {
    /// Anonymous connections, oldest first.
    anonymous: std::sync::Mutex<std::collections::VecDeque<Arc<TcpSlot>>>,
    max_anonymous: usize,
    /// Token holders' connections.
    holders: Arc<Semaphore>,
}

/// A TCP connection's place in the budgets; in each request's extensions, so that the
/// API's guard can say when the connection has shown the token.
pub struct TcpSlot {
    budgets: Arc<Budgets>,
    /// Told when an anonymous connection is closed to make room.
    evicted: tokio::sync::Notify,
    /// Its place among the token holders, once it has one.
    holder: std::sync::Mutex<Option<OwnedSemaphorePermit>>,
}

impl TcpSlot {
    /// The connection showed the token (or a session): it moves to the token holders'
    /// budget when there is room there (else it stays anonymous).
    pub fn promote(self: &Arc<Self>) {
        let Ok(mut holder) = self.holder.lock() else {
            return;
        };
        if holder.is_some() {
            return;
        }
        if let Ok(permit) = self.budgets.holders.clone().try_acquire_owned() {
            *holder = Some(permit);
            drop(holder);
            self.leave_anonymous();
        }
    }

    fn leave_anonymous(self: &Arc<Self>) {
        if let Ok(mut anonymous) = self.budgets.anonymous.lock() {
            anonymous.retain(|s| !Arc::ptr_eq(s, self));
        }
    }
}

impl Budgets {
    /// A slot for a new connection, closing the oldest anonymous one if the budget is
    /// full (true in the second value when it did).
    fn admit(self: &Arc<Self>) -> (Arc<TcpSlot>, bool) {
        let slot = Arc::new(TcpSlot {
            budgets: self.clone(),
            evicted: tokio::sync::Notify::new(),
            holder: std::sync::Mutex::new(None),
        });
        let mut evicted = false;
        if let Ok(mut anonymous) = self.anonymous.lock() {
            while anonymous.len() >= self.max_anonymous.max(1) {
                if let Some(oldest) = anonymous.pop_front() {
                    // A permit is stored: the connection's loop sees it even if it is
                    // not waiting right now.
                    oldest.evicted.notify_one();
                    evicted = true;
                }
            }
            anonymous.push_back(slot.clone());
        }
        (slot, evicted)
    }
}

/// Accept and serve connections until the process ends.
pub async fn serve(listener: Listener, app: Router, limits: ConnectionLimits) {
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let budgets = Arc::new(Budgets {
        anonymous: Default::default(),
        max_anonymous: limits.max_connections,
        holders: Arc::new(Semaphore::new(limits.max_connections)),
    });
    let mut refused = LogThrottle::default();
    loop {
        let admitted = match &listener {
            Listener::Unix(l) => l.accept().await.map(|(stream, _)| {
                let peer = Peer::Local {
                    uid: stream.peer_cred().ok().map(|c| c.uid()),
                };
                admit(stream, peer, &app, limits, &slots)
            }),
            Listener::Tcp(l) => l.accept().await.map(|(stream, addr)| {
                let (slot, evicted) = budgets.admit();
                let app = app.clone();
                tokio::spawn(async move {
                    serve_connection(stream, Peer::Tcp(addr), app, limits, Some(slot.clone()))
                        .await;
                    slot.leave_anonymous();
                });
                !evicted
            }),
        };
        match admitted {
            Ok(true) => {}
            Ok(false) => {
                if let Some(count) = refused.note() {
                    tracing::warn!(
                        listener = listener.name(),
                        cap = limits.max_connections,
                        refused = count,
                        "connections over the cap were closed (on TCP: the oldest without the token; this one and those since the last such line)"
                    );
                }
            }
            Err(e) => {
                // Out of descriptors, or the peer gone before accept: wait a little
                // rather than spin.
                tracing::warn!(listener = listener.name(), error = %e, "accept failed");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
}

/// Serve an accepted connection if the listener has a free slot; otherwise close it
/// at once (rather than leave it waiting in the kernel's backlog) and say so.
fn admit<I>(
    io: I,
    peer: Peer,
    app: &Router,
    limits: ConnectionLimits,
    slots: &Arc<Semaphore>,
) -> bool
where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let Ok(permit) = slots.clone().try_acquire_owned() else {
        return false;
    };
    let app = app.clone();
    tokio::spawn(async move {
        serve_connection(io, peer, app, limits, None).await;
        drop::<OwnedSemaphorePermit>(permit);
    });
    true
}

/// Counts events that are logged at most once per `LogThrottle::EVERY`, so that a
/// flood of bad clients cannot flood the log: each line says how many there were.
#[derive(Default)]
pub(super) struct LogThrottle {
    last: Option<Instant>,
    count: u64,
}

impl LogThrottle {
    const EVERY: Duration = Duration::from_secs(10);

    /// Count one event; the count since the last line when one is due now.
    pub(super) fn note(&mut self) -> Option<u64> {
        self.count += 1;
        let now = Instant::now();
        if self
            .last
            .is_some_and(|last| now.duration_since(last) < Self::EVERY)
        {
            return None;
        }
        self.last = Some(now);
        Some(std::mem::take(&mut self.count))
    }
}

/// Serve one connection's requests (HTTP/1.1, keep-alive) until the client closes it,
/// it breaks a limit, or it is idle too long.
async fn serve_connection<I>(
    io: I,
    peer: Peer,
    app: Router,
    limits: ConnectionLimits,
    slot: Option<Arc<TcpSlot>>,
) where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let activity = Arc::new(Activity::new());
    let io = TokioIo::new(Watched {
        inner: io,
        activity: activity.clone(),
        pending: Vec::new(),
    });
    let service = {
        let activity = activity.clone();
        let slot = slot.clone();
        hyper::service::service_fn(move |mut request: hyper::Request<Incoming>| {
            request.extensions_mut().insert(ConnectInfo(peer));
            if let Some(slot) = &slot {
                request.extensions_mut().insert(slot.clone());
            }
            // A request being answered is not idleness (the request timeout bounds it).
            let busy = Busy::start(activity.clone());
            let answer = app.clone().oneshot(request);
            async move {
                let response = answer.await;
                drop(busy);
                response
            }
        })
    };
    let connection = hyper::server::conn::http1::Builder::new()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_timeout)
        .serve_connection(io, service);
    tokio::pin!(connection);
    let check_every = (limits.idle_timeout / 4).max(Duration::from_millis(50));
    let evicted = async {
        match &slot {
            Some(slot) => slot.evicted.notified().await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(evicted);
    loop {
        tokio::select! {
            () = &mut evicted => {
                tracing::debug!(?peer, "closing the oldest API connection without the token, to make room");
                return;
            }
            result = connection.as_mut() => {
                if let Err(e) = result {
                    tracing::debug!(error = %e, "API connection ended");
                }
                return;
            }
            () = tokio::time::sleep(check_every) => {
                if activity.idle_for() >= limits.idle_timeout {
                    tracing::debug!(?peer, "closing an idle API connection");
                    return;
                }
            }
        }
    }
}

/// When a connection last read or wrote a byte, and how many of its requests are
/// being answered.
struct Activity {
    start: Instant,
    last_ms: AtomicU64,
    in_flight: AtomicU64,
}

/// A request in flight on a connection, for as long as it lives.
struct Busy(Arc<Activity>);

impl Busy {
    fn start(activity: Arc<Activity>) -> Self {
        activity.in_flight.fetch_add(1, Ordering::SeqCst);
        Busy(activity)
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.touch();
        self.0.in_flight.fetch_sub(1, Ordering::SeqCst);
    }
}

impl Activity {
    fn new() -> Self {
        Activity {
            start: Instant::now(),
            last_ms: AtomicU64::new(0),
            in_flight: AtomicU64::new(0),
        }
    }

    fn touch(&self) {
        let ms = u64::try_from(self.start.elapsed().as_millis()).unwrap_or(u64::MAX);
        self.last_ms.store(ms, Ordering::Relaxed);
    }

    /// Time since the last byte, or zero while a request is being answered.
    fn idle_for(&self) -> Duration {
        if self.in_flight.load(Ordering::SeqCst) > 0 {
            return Duration::ZERO;
        }
        let last = Duration::from_millis(self.last_ms.load(Ordering::Relaxed));
        self.start.elapsed().saturating_sub(last)
    }
}

/// A stream that records its activity, and gives hyper's own refusals a JSON body.
///
/// hyper answers a request it cannot parse (a malformed request line or header: 400;
/// headers over its limit: 431; a URI too long: 414) itself, before any handler sees
/// it, with an empty body and no hook to change that. Every other refusal of the API
/// is JSON `{"error": …}`, so such a head is replaced, as it is written, by the same
/// status with a body that says what was wrong.
struct Watched<I> {
    inner: I,
    activity: Arc<Activity>,
    /// Bytes of a replacement answer not yet written.
    pending: Vec<u8>,
}

/// Longest head of hyper's own refusals looked at: status line, `content-length`,
/// `date`, with room to spare.
const MAX_REFUSAL_HEAD: usize = 512;

/// The JSON answer for one of hyper's own bodiless refusals, or `None` when `head`
/// is anything else (every answer of the API's handlers has a body).
fn refusal_with_a_body(head: &[u8]) -> Option<Vec<u8>> {
    // Every write of every answer passes here: bodies and long heads are let through
    // before any text is looked at (hyper's own heads are under 200 bytes).
    if head.len() > MAX_REFUSAL_HEAD || !head.starts_with(b"HTTP/1.1 4") {
        return None;
    }
    let text = std::str::from_utf8(head).ok()?;
    let status_line = text.strip_prefix("HTTP/1.1 ")?;
    let (status, _) = status_line.split_once("\r\n")?;
    let why = match status.get(..3)? {
        "400" => "the request could not be read as HTTP/1.1 (a malformed request line or header)",
        "431" => "the request's headers are larger than the daemon reads",
        "414" => "the request's URI is longer than the daemon reads",
        _ => return None,
    };
    let only_a_head = text.ends_with("\r\n\r\n") && text.matches("\r\n\r\n").count() == 1;
    let empty = text
        .to_ascii_lowercase()
        .contains("\r\ncontent-length: 0\r\n");
    if !(only_a_head && empty) {
        return None;
    }
    let body = serde_json::json!({ "error": why }).to_string();
    Some(
        format!(
            "HTTP/1.1 {status}\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
            body.len()
        )
        .into_bytes(),
    )
}

impl<I: AsyncWrite + Unpin> Watched<I> {
    /// Write what is left of a replacement answer; ready when none is left.
    fn drain_pending(
        &mut self,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        while !self.pending.is_empty() {
            match std::pin::Pin::new(&mut self.inner).poll_write(cx, &self.pending) {
                std::task::Poll::Ready(Ok(0)) => {
                    return std::task::Poll::Ready(Err(std::io::ErrorKind::WriteZero.into()));
                }
                std::task::Poll::Ready(Ok(n)) => {
                    self.pending.drain(..n);
                    self.activity.touch();
                }
                std::task::Poll::Ready(Err(e)) => return std::task::Poll::Ready(Err(e)),
                std::task::Poll::Pending => return std::task::Poll::Pending,
            }
        }
        std::task::Poll::Ready(Ok(()))
    }
}

impl<I: AsyncRead + Unpin> AsyncRead for Watched<I> {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        let poll = std::pin::Pin::new(&mut self.inner).poll_read(cx, buf);
        if buf.filled().len() > before {
            self.activity.touch();
        }
        poll
    }
}

impl<I: AsyncWrite + Unpin> AsyncWrite for Watched<I> {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        std::task::ready!(self.drain_pending(cx))?;
        if let Some(answer) = refusal_with_a_body(buf) {
            self.pending = answer;
            // The replacement is written now or by the flush hyper does next.
            if let std::task::Poll::Ready(Err(e)) = self.drain_pending(cx) {
                return std::task::Poll::Ready(Err(e));
            }
            return std::task::Poll::Ready(Ok(buf.len()));
        }
        let poll = std::pin::Pin::new(&mut self.inner).poll_write(cx, buf);
        if matches!(poll, std::task::Poll::Ready(Ok(n)) if n > 0) {
            self.activity.touch();
        }
        poll
    }

    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::task::ready!(self.drain_pending(cx))?;
        std::pin::Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::task::ready!(self.drain_pending(cx))?;
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::refusal_with_a_body;

    #[test]
    fn only_hyper_s_bodiless_refusals_are_given_a_body() {
        let hyper_400 = b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\ndate: Wed, 02 Dec 2026 05:00:00 GMT\r\n\r\n";
        let answer = refusal_with_a_body(hyper_400).expect("a refusal");
        let text = String::from_utf8(answer).expect("text");
        assert!(text.starts_with("HTTP/1.1 400 Bad Request\r\n"), "{text}");
        assert!(text.contains("content-type: application/json"), "{text}");
        let body = text.split("\r\n\r\n").nth(1).expect("a body");
        let json: serde_json::Value = serde_json::from_str(body).expect("JSON");
        assert!(
            json["error"]
                .as_str()
                .is_some_and(|e| e.contains("HTTP/1.1")),
            "{json}"
        );
        let hyper_431 =
            b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\n\r\n";
        assert!(refusal_with_a_body(hyper_431).is_some());
        // The API's own answers, with bodies or of other statuses, pass untouched.
        let own = b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/json\r\ncontent-length: 12\r\n\r\n{\"error\":1}";
        assert!(refusal_with_a_body(own).is_none());
        let ok = b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n";
        assert!(refusal_with_a_body(ok).is_none());
        assert!(refusal_with_a_body(b"{\"error\":\"HTTP/1.1 400\"}").is_none());
    }
}
