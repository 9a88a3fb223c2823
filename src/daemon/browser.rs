//! The daemon in a browser: the fleet page (`GET /`) and, on the TCP listener, a
//! login that trades the API token for a session cookie, since a browser cannot send
//! `Authorization: Bearer`.
//!
//! The cookie is `HttpOnly` (no script reads it), `SameSite=Strict` (no other site's
//! page makes the browser send it) and holds a random session id, never the token. A
//! session may only look: `GET` and `HEAD`, and `POST /logout`. Anything that acts
//! (starting or cancelling a job, a rollback, a reload) still needs the token itself,
//! so no forged request can act through a session (CSRF-safe by construction, and
//! whatever a later page adds). Sessions live 12 hours, in memory: a restart ends them.
//! The cookie has no `Secure` flag because the listener is plain HTTP (loopback by
//! default); put TLS in front for anything else.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::response::{IntoResponse, Response};

use super::Daemon;
use crate::html_report::fleet::{FleetDevice, FleetVerification, fleet_html, login_html};

/// The session cookie's name.
pub const COOKIE: &str = "chromacal_session";

/// How long a session lasts.
pub const SESSION_LIFETIME: Duration = Duration::from_secs(12 * 3600);

/// Sessions at most: past it the oldest goes (a login flood cannot grow memory).
const MAX_SESSIONS: usize = 256;

/// The browser sessions of the TCP listener.
#[derive(Default)]
pub struct Sessions {
    /// Session id → when it ends.
    ends: Mutex<HashMap<String, Instant>>,
}

impl Sessions {
    /// A new session; its id, for the cookie.
    pub fn open(&self) -> String {
        use rand::RngCore;
        let mut bytes = [0u8; 32];
        rand::rng().fill_bytes(&mut bytes);
        let id: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        let now = Instant::now();
        if let Ok(mut ends) = self.ends.lock() {
            ends.retain(|_, end| *end > now);
            if ends.len() >= MAX_SESSIONS
                && let Some(oldest) = ends.iter().min_by_key(|(_, e)| **e).map(|(k, _)| k.clone())
            {
                ends.remove(&oldest);
            }
            ends.insert(id.clone(), now + SESSION_LIFETIME);
        }
        id
    }

    /// Whether the request carries a live session's cookie.
    pub fn valid(&self, headers: &HeaderMap) -> bool {
        let Some(id) = session_id(headers) else {
            return false;
        };
        let now = Instant::now();
        self.ends
            .lock()
            .ok()
            .and_then(|ends| ends.get(id).copied())
            .is_some_and(|end| end > now)
    }

    /// End the request's session.
    pub fn close(&self, headers: &HeaderMap) {
        if let Some(id) = session_id(headers)
            && let Ok(mut ends) = self.ends.lock()
        {
            ends.remove(id);
        }
    }
}

/// The session id in a request's `Cookie` headers (RFC 6265 §4.2: `name=value` pairs
/// separated by `; `).
fn session_id(headers: &HeaderMap) -> Option<&str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .find_map(|pair| {
            let (name, value) = pair.trim().split_once('=')?;
            (name == COOKIE).then_some(value)
        })
}

/// What a session may do: look, and log out.
pub fn session_may(method: &Method, path: &str) -> bool {
    matches!(*method, Method::GET | Method::HEAD) || (*method == Method::POST && path == "/logout")
}

/// Paths a TCP client reaches without the token or a session: the login itself.
pub fn open_path(path: &str) -> bool {
    path == "/login"
}

fn html(status: StatusCode, page: String) -> Response {
    (
        status,
        [(header::CONTENT_TYPE, "text/html; charset=utf-8")],
        page,
    )
        .into_response()
}

/// A `303 See Other` to `to`, with `cookie` set if given.
pub fn see_other(to: &'static str, cookie: Option<String>) -> Response {
    let mut response = (StatusCode::SEE_OTHER, [(header::LOCATION, to)]).into_response();
    if let Some(cookie) = cookie.and_then(|c| HeaderValue::from_str(&c).ok()) {
        response.headers_mut().insert(header::SET_COOKIE, cookie);
    }
    response
}

/// `GET /login`.
pub fn login_page() -> Response {
    html(StatusCode::OK, login_html(&super::host_name(), None))
}

/// `POST /login` with the form's `token`: a session cookie and back to the fleet page,
/// or the form again saying the token was wrong.
pub fn login(sessions: &Sessions, token: Option<&str>, form: &[u8]) -> Response {
    let sent = form_value(form, "token");
    let right = match (token, sent.as_deref()) {
        (Some(token), Some(sent)) => super::access::same_secret(token, sent.trim()),
        _ => false,
    };
    if !right {
        tracing::warn!("refused a browser login with a wrong token");
        return html(
            StatusCode::UNAUTHORIZED,
            login_html(
                &super::host_name(),
                Some("That is not the daemon's API token."),
            ),
        );
    }
    let id = sessions.open();
    see_other(
        "/",
        Some(format!(
            "{COOKIE}={id}; Path=/; HttpOnly; SameSite=Strict; Max-Age={}",
            SESSION_LIFETIME.as_secs()
        )),
    )
}

/// `POST /logout`: the session ends, the cookie is cleared.
pub fn logout(sessions: &Sessions, headers: &HeaderMap) -> Response {
    sessions.close(headers);
    see_other(
        "/login",
        Some(format!(
            "{COOKIE}=; Path=/; HttpOnly; SameSite=Strict; Max-Age=0"
        )),
    )
}

/// A value of an `application/x-www-form-urlencoded` body, as the login form sends it.
fn form_value(body: &[u8], key: &str) -> Option<String> {
    form_urlencoded::parse(body)
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.into_owned())
}

/// `GET /`: the fleet page. (Only what the page shows is read: the current profile
/// and the verifications, not the unfinished runs' journals a status lists.)
pub async fn fleet_page(daemon: &Daemon, logout: bool) -> Response {
    let mut rows = Vec::new();
    for device in daemon.devices() {
        let profile = device.read_current().ok().flatten().map(|(p, _)| p);
        let metrics = &daemon.bus.metrics;
        let (whites, drift) = metrics.whites(&device.name);
        let verification = profile
            .as_ref()
            .and_then(|p| device.last_verification_of(&p.id))
            .map(|v| FleetVerification {
                passed: v.passed(),
                at: v.at,
                metric: v.metric,
                mean: v.stats.map(|s| s.mean),
                threshold: v.threshold,
            });
        rows.push(FleetDevice {
            name: device.name.clone(),
            up: metrics.device_up(&device.name),
            job: device.job().map(|j| {
                let mut text = format!("{}: {}", j.kind.name(), j.phase);
                if j.total > 0 {
                    text += &format!(", {}/{} patches", j.done, j.total);
                }
                text
            }),
            retiring: device.is_retired(),
            profile: profile.map(|p| (p.id, p.report.held_out.map(|h| h.mean))),
            verification,
            next_verification: device
                .next_verification()
                .map(chromacal_formats::time::rfc3339_seconds),
            whites,
            drift,
        });
    }
    html(
        StatusCode::OK,
        fleet_html(
            &super::host_name(),
            env!("CARGO_PKG_VERSION"),
            &rows,
            logout,
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_session_cookie_is_found_among_others_and_only_a_live_one_counts() {
        let sessions = Sessions::default();
        let id = sessions.open();
        let mut headers = HeaderMap::new();
        headers.insert(
            header::COOKIE,
            HeaderValue::from_str(&format!("theme=dark; {COOKIE}={id}; x=1")).unwrap(),
        );
        assert!(sessions.valid(&headers));
        let mut forged = HeaderMap::new();
        forged.insert(
            header::COOKIE,
            HeaderValue::from_str(&format!("{COOKIE}={}", "0".repeat(64))).unwrap(),
        );
        assert!(!sessions.valid(&forged));
        sessions.close(&headers);
        assert!(!sessions.valid(&headers));
    }

    #[test]
    fn sessions_are_bounded_and_may_only_look() {
        let sessions = Sessions::default();
        let first = sessions.open();
        for _ in 0..MAX_SESSIONS {
            sessions.open();
        }
        let mut headers = HeaderMap::new();
        headers.insert(
            header::COOKIE,
            HeaderValue::from_str(&format!("{COOKIE}={first}")).unwrap(),
        );
        assert!(!sessions.valid(&headers), "the oldest went");
        assert!(session_may(&Method::GET, "/status"));
        assert!(session_may(&Method::POST, "/logout"));
        assert!(!session_may(&Method::POST, "/jobs"));
        assert!(!session_may(&Method::POST, "/reload"));
        assert!(!session_may(&Method::DELETE, "/"));
    }

    #[test]
    fn the_form_is_read_as_browsers_encode_it() {
        assert_eq!(
            form_value(b"token=ab%2Bc+d&x=1", "token").as_deref(),
            Some("ab+c d")
        );
        assert_eq!(form_value(b"x=1", "token"), None);
    }
}
