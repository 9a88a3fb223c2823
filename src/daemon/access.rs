//! Who may use the API: the socket's owner and root on the unix socket, token holders
//! (by bearer token or a browser session) on TCP. The pieces the listener
//! (`serve`), the API (`api`) and the browser's pages (`browser`) share.

use std::net::SocketAddr;

/// Who may use the API.
#[derive(Debug, Clone)]
pub struct Access {
    /// The uid that owns the socket (the daemon's); it and root are answered.
    pub owner: u32,
    /// The bearer token TCP clients must send.
    pub token: Option<String>,
}

/// Who is calling: a local process (with its uid) or a TCP peer.
#[derive(Debug, Clone, Copy)]
pub enum Peer {
    Local { uid: Option<u32> },
    Tcp(SocketAddr),
}

/// The credentials of an `Authorization` value in the Bearer scheme: the scheme's
/// name is case-insensitive (RFC 9110 §11.1, RFC 6750 §2.1), so `bearer` and `BEARER`
/// are accepted as `Bearer` is; `None` for any other scheme.
pub fn bearer_credentials(value: &str) -> Option<&str> {
    let (scheme, credentials) = value.trim_start().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then(|| credentials.trim())
}

/// Compare without an early exit, so that timing tells nothing of the token.
pub fn same_secret(a: &str, b: &str) -> bool {
    a.len() == b.len()
        && a.bytes()
            .zip(b.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0
}
