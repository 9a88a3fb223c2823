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

use super::api::Peer;
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

/// Accept and serve connections until the process ends.
pub async fn serve(listener: Listener, app: Router, limits: ConnectionLimits) {
    let slots = Arc::new(Semaphore::new(limits.max_connections));
    let mut refused = LogThrottle::default();
    loop {
        let admitted = match &listener {
            Listener::Unix(l) => l.accept().await.map(|(stream, _)| {
                let peer = Peer::Local {
                    uid: stream.peer_cred().ok().map(|c| c.uid()),
                };
                admit(stream, peer, &app, limits, &slots)
            }),
            Listener::Tcp(l) => l
                .accept()
                .await
                .map(|(stream, addr)| admit(stream, Peer::Tcp(addr), &app, limits, &slots)),
        };
        match admitted {
            Ok(true) => {}
            Ok(false) => {
                if let Some(count) = refused.note() {
                    tracing::warn!(
                        listener = listener.name(),
                        cap = limits.max_connections,
                        refused = count,
                        "connections over the cap were closed (this one and those since the last such line)"
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
        serve_connection(io, peer, app, limits).await;
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
async fn serve_connection<I>(io: I, peer: Peer, app: Router, limits: ConnectionLimits)
where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let activity = Arc::new(Activity::new());
    let io = TokioIo::new(Watched {
        inner: io,
        activity: activity.clone(),
    });
    let service = {
        let activity = activity.clone();
        hyper::service::service_fn(move |mut request: hyper::Request<Incoming>| {
            request.extensions_mut().insert(ConnectInfo(peer));
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
    loop {
        tokio::select! {
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

/// A stream that records its activity.
struct Watched<I> {
    inner: I,
    activity: Arc<Activity>,
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
        std::pin::Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
