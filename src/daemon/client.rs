//! The client side of the control API, for the `chromacal status`, `job`, `history`,
//! `rollback` commands and for tests: HTTP/1.1 (hyper) over the unix socket or TCP.

use std::path::PathBuf;

use bytes::Bytes;
use http_body_util::{BodyExt, Full};
use hyper::Request;
use hyper::header;
use hyper_util::rt::TokioIo;

/// Where the daemon listens.
#[derive(Debug, Clone)]
pub enum Endpoint {
    Unix(PathBuf),
    Tcp { address: String, token: String },
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Endpoint::Unix(path) => write!(f, "{}", path.display()),
            Endpoint::Tcp { address, .. } => write!(f, "http://{address}"),
        }
    }
}

/// Why a request got no answer.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot reach the daemon at {endpoint}: {source} (is `chromacal daemon` running?)")]
    Connect {
        endpoint: String,
        source: std::io::Error,
    },
    #[error("the daemon at {endpoint} broke off: {message}")]
    Http { endpoint: String, message: String },
}

/// An answer.
#[derive(Debug, Clone)]
pub struct Reply {
    pub status: u16,
    pub body: Bytes,
    /// The answer's headers whose values are text (names in lower case).
    pub headers: Vec<(String, String)>,
}

impl Reply {
    /// The value of header `name` (lower case), if the answer has it.
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }

    pub fn json(&self) -> Result<serde_json::Value, String> {
        serde_json::from_slice(&self.body).map_err(|e| format!("not JSON ({e}): {}", self.text()))
    }

    /// The `error` of a refusal, or the whole body.
    pub fn error_message(&self) -> String {
        self.json()
            .ok()
            .and_then(|v| v.get("error").and_then(|e| e.as_str()).map(String::from))
            .unwrap_or_else(|| self.text())
    }
}

type Sender = hyper::client::conn::http1::SendRequest<Full<Bytes>>;

async fn connect(endpoint: &Endpoint) -> Result<Sender, ClientError> {
    let connect_error = |source| ClientError::Connect {
        endpoint: endpoint.to_string(),
        source,
    };
    let http_error = |e: hyper::Error| ClientError::Http {
        endpoint: endpoint.to_string(),
        message: e.to_string(),
    };
    match endpoint {
        Endpoint::Unix(path) => {
            let stream = tokio::net::UnixStream::connect(path)
                .await
                .map_err(connect_error)?;
            handshake(stream).await.map_err(http_error)
        }
        Endpoint::Tcp { address, .. } => {
            let stream = tokio::net::TcpStream::connect(address)
                .await
                .map_err(connect_error)?;
            handshake(stream).await.map_err(http_error)
        }
    }
}

/// HTTP/1.1 on a connected stream; the connection is driven on its own task.
async fn handshake<S>(stream: S) -> Result<Sender, hyper::Error>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
{
    let (sender, connection) = hyper::client::conn::http1::handshake(TokioIo::new(stream)).await?;
    tokio::spawn(connection);
    Ok(sender)
}

fn build(
    endpoint: &Endpoint,
    method: &str,
    path: &str,
    body: Option<Bytes>,
) -> Result<Request<Full<Bytes>>, ClientError> {
    let mut request = Request::builder()
        .method(method)
        .uri(path)
        .header(header::HOST, "chromacal");
    if let Endpoint::Tcp { token, .. } = endpoint {
        request = request.header(header::AUTHORIZATION, format!("Bearer {token}"));
    }
    if body.is_some() {
        request = request.header(header::CONTENT_TYPE, "application/json");
    }
    request
        .body(Full::new(body.unwrap_or_default()))
        .map_err(|e| ClientError::Http {
            endpoint: endpoint.to_string(),
            message: e.to_string(),
        })
}

/// Send one request and read the whole answer.
pub async fn request(
    endpoint: &Endpoint,
    method: &str,
    path: &str,
    body: Option<Bytes>,
) -> Result<Reply, ClientError> {
    let http_error = |message: String| ClientError::Http {
        endpoint: endpoint.to_string(),
        message,
    };
    let mut sender = connect(endpoint).await?;
    let response = sender
        .send_request(build(endpoint, method, path, body)?)
        .await
        .map_err(|e| http_error(e.to_string()))?;
    let status = response.status().as_u16();
    let headers = response
        .headers()
        .iter()
        .filter_map(|(n, v)| Some((n.as_str().to_string(), v.to_str().ok()?.to_string())))
        .collect();
    let body = response
        .into_body()
        .collect()
        .await
        .map_err(|e| http_error(e.to_string()))?
        .to_bytes();
    Ok(Reply {
        status,
        body,
        headers,
    })
}

/// `GET /events` and call `on_event(name, data)` for each event until it returns
/// false or the stream ends. A refusal is returned as the reply.
pub async fn follow_events(
    endpoint: &Endpoint,
    on_event: impl FnMut(&str, &str) -> bool,
) -> Result<Option<Reply>, ClientError> {
    follow_events_at(endpoint, "/events", on_event).await
}

/// The same on another path (`/devices/NAME/events`: one device's).
pub async fn follow_events_at(
    endpoint: &Endpoint,
    path: &str,
    mut on_event: impl FnMut(&str, &str) -> bool,
) -> Result<Option<Reply>, ClientError> {
    let http_error = |message: String| ClientError::Http {
        endpoint: endpoint.to_string(),
        message,
    };
    let mut sender = connect(endpoint).await?;
    let response = sender
        .send_request(build(endpoint, "GET", path, None)?)
        .await
        .map_err(|e| http_error(e.to_string()))?;
    let status = response.status().as_u16();
    let mut body = response.into_body();
    if status != 200 {
        let bytes = body
            .collect()
            .await
            .map_err(|e| http_error(e.to_string()))?
            .to_bytes();
        return Ok(Some(Reply {
            status,
            body: bytes,
            headers: Vec::new(),
        }));
    }
    let mut parser = EventStreamParser::default();
    while let Some(frame) = body.frame().await {
        let frame = frame.map_err(|e| http_error(e.to_string()))?;
        let Ok(chunk) = frame.into_data() else {
            continue;
        };
        for (name, data) in parser.push(&chunk) {
            if !on_event(&name, &data) {
                return Ok(None);
            }
        }
    }
    Ok(None)
}

/// Server-sent events (the WHATWG HTML standard, §9.2 "Server-sent events") from
/// the body's chunks as they come. Bytes are kept until a line is whole, so a
/// character that HTTP split between two chunks ("Δ" is two bytes) is decoded whole:
/// a line break never falls inside a UTF-8 sequence.
#[derive(Debug, Default)]
pub struct EventStreamParser {
    pending: Vec<u8>,
    name: String,
    data: String,
}

impl EventStreamParser {
    /// Feed a chunk; returns the events it completed, as (name, data).
    pub fn push(&mut self, chunk: &[u8]) -> Vec<(String, String)> {
        self.pending.extend_from_slice(chunk);
        let mut events = Vec::new();
        while let Some(end) = self.pending.iter().position(|b| *b == b'\n') {
            let raw: Vec<u8> = self.pending.drain(..=end).collect();
            let line = String::from_utf8_lossy(&raw);
            let line = line.trim_end_matches(['\r', '\n']);
            if line.is_empty() {
                if !self.data.is_empty() {
                    events.push((
                        std::mem::take(&mut self.name),
                        std::mem::take(&mut self.data),
                    ));
                }
                self.name.clear();
            } else if let Some(v) = line.strip_prefix("event:") {
                self.name = v.trim().to_string();
            } else if let Some(v) = line.strip_prefix("data:") {
                if !self.data.is_empty() {
                    self.data.push('\n');
                }
                self.data.push_str(v.strip_prefix(' ').unwrap_or(v));
            }
        }
        events
    }
}

#[cfg(test)]
mod tests {
    use super::EventStreamParser;

    #[test]
    fn an_event_split_inside_a_character_is_decoded_whole() {
        let stream = "event: progress\ndata: {\"de\": \"ΔE00 0.2 cd/m²\"}\n\nevent: done\ndata: a\ndata: b\n\n";
        let bytes = stream.as_bytes();
        let delta = stream.find('Δ').unwrap();
        let squared = stream.find('²').unwrap();
        // Cut inside "Δ" and inside "²" (both two bytes), and byte by byte.
        for cuts in [vec![delta + 1, squared + 1], (1..bytes.len()).collect()] {
            let mut parser = EventStreamParser::default();
            let mut events = Vec::new();
            let mut start = 0;
            for cut in cuts.into_iter().chain([bytes.len()]) {
                events.extend(parser.push(&bytes[start..cut]));
                start = cut;
            }
            assert_eq!(
                events,
                vec![
                    (
                        "progress".to_string(),
                        "{\"de\": \"ΔE00 0.2 cd/m²\"}".to_string()
                    ),
                    ("done".to_string(), "a\nb".to_string()),
                ]
            );
        }
    }
}
