//! The X server a real screen hangs on: its RandR outputs (name, CRTC, mode, EDID), the
//! CRTC gamma ramps that are the video card's LUT, and the pixels it shows.
//!
//! Everything here speaks the X protocol through `x11rb`'s pure-Rust connection (no
//! Xlib), so it runs the same against a desktop's Xorg, XWayland and the Xvfb the
//! tests start. RandR 1.3 or later is needed (gamma per CRTC, primary output).

pub mod capture;
pub mod gamma;
pub mod outputs;
pub mod watch;

use x11rb::connection::Connection;
use x11rb::protocol::randr::ConnectionExt as _;
use x11rb::protocol::xproto::Window;
use x11rb::rust_connection::RustConnection;

pub use gamma::GammaRamp;
pub use outputs::{OutputInfo, OutputSelector};

/// Why the X server could not do what was asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum X11Error {
    #[error(
        "cannot open the X display '{display}': {reason} (is DISPLAY set, or give --x-display)"
    )]
    Connect { display: String, reason: String },
    #[error(
        "the X server {display} has no RandR {major}.{minor} or later (needed for outputs and gamma ramps)"
    )]
    NoRandr {
        display: String,
        major: u32,
        minor: u32,
    },
    #[error("no output {wanted} on the X display {display}: it has {have}")]
    NoOutput {
        wanted: String,
        display: String,
        have: String,
    },
    #[error("the output {output} is not lit (it drives no CRTC): switch it on first")]
    Unlit { output: String },
    #[error("the output {output} has a gamma ramp of {size} entries; at least 2 are needed")]
    NoGamma { output: String, size: usize },
    #[error("the X display {display}: {reason}")]
    Protocol { display: String, reason: String },
}

/// A connection to one X display, with the root window of its default screen.
pub struct XDisplay {
    pub(crate) conn: RustConnection,
    pub(crate) root: Window,
    pub(crate) screen: usize,
    name: String,
}

impl XDisplay {
    /// Connect to `display` (such as `:0`), or to `$DISPLAY` when `None`, and check
    /// that it has RandR 1.3.
    pub fn open(display: Option<&str>) -> Result<Self, X11Error> {
        let name = display
            .map(str::to_string)
            .or_else(|| std::env::var("DISPLAY").ok())
            .unwrap_or_default();
        let (conn, screen) = x11rb::connect(
            Some(&name).filter(|n| !n.is_empty()).map(String::as_str),
        )
        .map_err(|e| X11Error::Connect {
            display: name.clone(),
            reason: e.to_string(),
        })?;
        let root = conn
            .setup()
            .roots
            .get(screen)
            .map(|s| s.root)
            .ok_or_else(|| X11Error::Protocol {
                display: name.clone(),
                reason: format!("the server has no screen {screen}"),
            })?;
        let x = XDisplay {
            conn,
            root,
            screen,
            name,
        };
        let version = x
            .conn
            .randr_query_version(1, 3)
            .map_err(|e| x.protocol(e))?
            .reply()
            .map_err(|_| X11Error::NoRandr {
                display: x.name.clone(),
                major: 1,
                minor: 3,
            })?;
        if (version.major_version, version.minor_version) < (1, 3) {
            return Err(X11Error::NoRandr {
                display: x.name.clone(),
                major: 1,
                minor: 3,
            });
        }
        Ok(x)
    }

    /// The display's name as it was opened (`:1`, `localhost:10.0`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// An X error as this crate's, naming the display.
    pub(crate) fn protocol(&self, e: impl std::fmt::Display) -> X11Error {
        X11Error::Protocol {
            display: self.name.clone(),
            reason: e.to_string(),
        }
    }

    /// The atom named `name`; with `only_if_exists`, 0 when the server has none.
    pub(crate) fn atom(&self, name: &[u8], only_if_exists: bool) -> Result<u32, X11Error> {
        Ok(
            x11rb::protocol::xproto::ConnectionExt::intern_atom(&self.conn, only_if_exists, name)
                .map_err(|e| self.protocol(e))?
                .reply()
                .map_err(|e| self.protocol(e))?
                .atom,
        )
    }

    /// Wait until the server has handled every request sent so far (a round trip).
    pub fn sync(&self) -> Result<(), X11Error> {
        x11rb::protocol::xproto::ConnectionExt::get_input_focus(&self.conn)
            .map_err(|e| self.protocol(e))?
            .reply()
            .map_err(|e| self.protocol(e))?;
        Ok(())
    }
}
