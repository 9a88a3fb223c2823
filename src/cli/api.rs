//! How the commands that talk to a running daemon reach it (`--socket`,
//! `--state-dir`, `--tcp` with `--token-file`, `--device`), and their requests.

use std::path::PathBuf;

use bytes::Bytes;
use chromacal::daemon::client::{Endpoint, Reply, request};
use chromacal::daemon::default_socket;
use chromacal::profile::store::default_state_dir;

/// How to reach the daemon.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ApiArgs {
    /// The daemon's unix socket [default: as the daemon's: $RUNTIME_DIRECTORY/api.sock,
    /// else <state>/api.sock].
    #[arg(long, global = true)]
    socket: Option<PathBuf>,
    /// The daemon's state directory, to find its socket.
    #[arg(long, global = true)]
    state_dir: Option<PathBuf>,
    /// Talk TCP to this address instead (the daemon's `daemon.tcp`).
    #[arg(long, global = true, value_name = "ADDR")]
    tcp: Option<String>,
    /// The token file for TCP [default: <state>/api.token].
    #[arg(long, global = true)]
    token_file: Option<PathBuf>,
    /// The device of a daemon that runs several (`[[device]]`), by name.
    #[arg(long, global = true, value_name = "NAME")]
    pub device: Option<String>,
}

impl ApiArgs {
    /// The state directory to read on disk when no daemon answers on its socket:
    /// the device's folder with `--device` where it has one. None over TCP (the
    /// daemon is elsewhere).
    pub fn store_on_disk(&self) -> Option<PathBuf> {
        if self.tcp.is_some() {
            return None;
        }
        let state = self.state_dir.clone().unwrap_or_else(default_state_dir);
        Some(match &self.device {
            Some(name) if state.join(name).is_dir() => state.join(name),
            _ => state,
        })
    }

    /// A device's route: `/devices/NAME/…` with `--device`, else the route itself
    /// (which a daemon of one device answers).
    pub fn route(&self, path: &str) -> String {
        match &self.device {
            Some(name) => format!("/devices/{}{path}", query_value(name)),
            None => path.to_string(),
        }
    }

    pub fn endpoint(&self) -> Result<Endpoint, String> {
        let state = self.state_dir.clone().unwrap_or_else(default_state_dir);
        match &self.tcp {
            Some(address) => {
                let path = self
                    .token_file
                    .clone()
                    .unwrap_or_else(|| state.join("api.token"));
                let token = std::fs::read_to_string(&path)
                    .map_err(|e| format!("the API token {}: {e}", path.display()))?;
                Ok(Endpoint::Tcp {
                    address: address.clone(),
                    token: token.trim().to_string(),
                })
            }
            None => Ok(Endpoint::Unix(
                self.socket
                    .clone()
                    .unwrap_or_else(|| default_socket(&state)),
            )),
        }
    }
}

pub fn runtime() -> Result<tokio::runtime::Runtime, String> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())
}

/// A reply that must be 2xx, else its error as ours.
fn expect_ok(reply: Reply) -> Result<Reply, String> {
    if (200..300).contains(&reply.status) {
        Ok(reply)
    } else {
        Err(format!(
            "the daemon refused ({}): {}",
            reply.status,
            reply.error_message()
        ))
    }
}

/// [`get`], or `None` when no daemon answers at `endpoint` (nothing listens on its
/// socket): a reader of the store may then read it on disk.
pub async fn get_if_running(endpoint: &Endpoint, path: &str) -> Result<Option<Reply>, String> {
    match request(endpoint, "GET", path, None).await {
        Err(chromacal::daemon::client::ClientError::Connect { .. }) => Ok(None),
        Err(e) => Err(e.to_string()),
        Ok(reply) => expect_ok(reply).map(Some),
    }
}

pub async fn get(endpoint: &Endpoint, path: &str) -> Result<Reply, String> {
    expect_ok(
        request(endpoint, "GET", path, None)
            .await
            .map_err(|e| e.to_string())?,
    )
}

pub async fn post(
    endpoint: &Endpoint,
    path: &str,
    body: serde_json::Value,
) -> Result<Reply, String> {
    expect_ok(
        request(endpoint, "POST", path, Some(Bytes::from(body.to_string())))
            .await
            .map_err(|e| e.to_string())?,
    )
}

/// `text` percent-encoded for a query string (RFC 3986 §2.1): every byte but the
/// unreserved ones and the few a target is written with (`,`, `:`, `.`).
pub fn query_value(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' | b',' | b':' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}
