//! The Wayland screen: a connection to a compositor, its outputs (`wl_output`: name,
//! description, make, model, mode, scale) with each monitor's EDID from the kernel
//! (`crate::drm`: compositors give clients none), and what it offers for calibration
//! (presentation feedback, idle inhibition, colour management, gamma control, screen
//! copy). The patch surface is in [`surface`].
//!
//! Everything here is the plain client protocol through `wayland-client` (a pure-Rust
//! implementation of the wire protocol: no libwayland is needed at build or run time),
//! with the protocol extensions of `wayland-protocols` and `wayland-protocols-wlr`.

pub mod capture;
pub mod gamma;
pub mod surface;

use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::time::Duration;

use serde::Serialize;
use wayland_client::globals::{GlobalList, GlobalListContents, registry_queue_init};
use wayland_client::protocol::{wl_output, wl_registry};
use wayland_client::{Connection, Dispatch, EventQueue, QueueHandle, WEnum};

use crate::drm;
use crate::x11::OutputSelector;

/// What went wrong talking to a Wayland compositor.
#[derive(Debug, thiserror::Error)]
pub enum WaylandError {
    #[error(
        "cannot reach the Wayland compositor at {socket}: {reason} (is a Wayland session running, and WAYLAND_DISPLAY and XDG_RUNTIME_DIR set as in it?)"
    )]
    Connect { socket: String, reason: String },
    #[error("Wayland compositor {display}: {what}")]
    Protocol { display: String, what: String },
    #[error(
        "Wayland compositor {display} has no output {wanted}; it has: {}",
        if .outputs.is_empty() { "none".to_string() } else { .outputs.join(", ") }
    )]
    NoOutput {
        display: String,
        wanted: String,
        outputs: Vec<String>,
    },
    #[error("Wayland compositor {display} does not offer {interface}, which {why}")]
    Missing {
        display: String,
        interface: &'static str,
        why: &'static str,
    },
}

/// One `wl_output` as the compositor describes it, with the kernel's EDID of its
/// connector where there is one.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct WaylandOutput {
    /// The compositor's name (wl_output v4): the DRM connector's on wlroots, GNOME and
    /// KDE (`DP-1`, `HDMI-A-1`), `HEADLESS-1` on a headless backend.
    pub name: String,
    pub description: String,
    pub make: String,
    pub model: String,
    /// The current mode, pixels.
    pub width: i32,
    pub height: i32,
    /// mHz as the protocol gives it; 0 when the compositor says none.
    pub refresh_mhz: i32,
    pub scale: i32,
    /// The registry name the output was bound from.
    #[serde(skip)]
    pub global: u32,
    /// The EDID of the kernel connector of the same name.
    #[serde(skip)]
    pub edid: Option<Vec<u8>>,
    /// The file `edid` was read from.
    pub edid_source: Option<String>,
}

impl WaylandOutput {
    /// One frame of the current mode, s (60 Hz when the compositor gives no refresh).
    pub fn frame_s(&self) -> f64 {
        match self.refresh_mhz {
            r if r >= 1000 => 1000.0 / f64::from(r),
            _ => 1.0 / 60.0,
        }
    }

    /// The mode as `1920x1080@60.000Hz`.
    pub fn mode(&self) -> String {
        format!(
            "{}x{}@{:.3}Hz",
            self.width,
            self.height,
            f64::from(self.refresh_mhz) / 1000.0
        )
    }
}

/// Which output a selector means among Wayland outputs: by name, by the EDID's serial,
/// or (`Primary`) the first the compositor lists.
pub fn pick<'a>(
    selector: &OutputSelector,
    outputs: &'a [WaylandOutput],
) -> Option<&'a WaylandOutput> {
    match selector {
        OutputSelector::Primary => outputs.first(),
        OutputSelector::Name(name) => outputs.iter().find(|o| {
            &o.name == name || o.description == *name || format!("{} {}", o.make, o.model) == *name
        }),
        OutputSelector::Edid { edid_serial } => outputs.iter().find(|o| {
            o.edid
                .as_deref()
                .and_then(|bytes| chromacal_formats::edid::Edid::parse(bytes).ok())
                .is_some_and(|e| e.matches_serial(edid_serial))
        }),
    }
}

/// The socket of Wayland display `name` (`wayland-0`, or an absolute path), or of
/// `$WAYLAND_DISPLAY` when `None`, as libwayland finds it: relative names under
/// `$XDG_RUNTIME_DIR`.
pub fn socket_path(name: Option<&str>) -> Result<PathBuf, WaylandError> {
    let name = match name {
        Some(n) if !n.is_empty() => n.to_string(),
        _ => std::env::var("WAYLAND_DISPLAY").unwrap_or_else(|_| "wayland-0".into()),
    };
    let path = PathBuf::from(&name);
    if path.is_absolute() {
        return Ok(path);
    }
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|v| !v.is_empty()) {
        Some(dir) => Ok(PathBuf::from(dir).join(name)),
        None => Err(WaylandError::Connect {
            socket: name,
            reason: "XDG_RUNTIME_DIR is not set".into(),
        }),
    }
}

/// The registry's and the outputs' events, taken in the same way by every state of
/// this module's connections (`$state` has `outputs`, as [`bind_outputs`] makes them):
/// an output plugged in meanwhile is seen by the next connection; each bound output's
/// events fill in its entry.
macro_rules! dispatch_outputs {
    ($state:ty) => {
        impl
            wayland_client::Dispatch<
                wayland_client::protocol::wl_registry::WlRegistry,
                wayland_client::globals::GlobalListContents,
            > for $state
        {
            fn event(
                _: &mut Self,
                _: &wayland_client::protocol::wl_registry::WlRegistry,
                _: wayland_client::protocol::wl_registry::Event,
                _: &wayland_client::globals::GlobalListContents,
                _: &wayland_client::Connection,
                _: &wayland_client::QueueHandle<Self>,
            ) {
            }
        }

        impl wayland_client::Dispatch<wayland_client::protocol::wl_output::WlOutput, usize>
            for $state
        {
            fn event(
                state: &mut Self,
                _: &wayland_client::protocol::wl_output::WlOutput,
                event: wayland_client::protocol::wl_output::Event,
                index: &usize,
                _: &wayland_client::Connection,
                _: &wayland_client::QueueHandle<Self>,
            ) {
                if let Some((_, info, done)) = state.outputs.get_mut(*index) {
                    $crate::wayland::apply_output_event(info, done, event);
                }
            }
        }
    };
}
pub(crate) use dispatch_outputs;

/// What the outputs' events have said so far.
#[derive(Default)]
pub(crate) struct OutputEvents {
    pub(crate) outputs: Vec<(wl_output::WlOutput, WaylandOutput, bool)>,
}

dispatch_outputs!(OutputEvents);

/// One `wl_output` event into what is known of the output.
pub(crate) fn apply_output_event(
    info: &mut WaylandOutput,
    done: &mut bool,
    event: wl_output::Event,
) {
    match event {
        wl_output::Event::Geometry { make, model, .. } => {
            info.make = make;
            info.model = model;
        }
        wl_output::Event::Mode {
            flags,
            width,
            height,
            refresh,
        } => {
            let current = matches!(flags, WEnum::Value(f) if f.contains(wl_output::Mode::Current));
            if current {
                (info.width, info.height, info.refresh_mhz) = (width, height, refresh);
            }
        }
        wl_output::Event::Scale { factor } => info.scale = factor,
        wl_output::Event::Name { name } => info.name = name,
        wl_output::Event::Description { description } => info.description = description,
        wl_output::Event::Done => *done = true,
        _ => {}
    }
}

/// A connection to a compositor: the socket it came through and its globals.
pub struct WaylandDisplay {
    pub(crate) globals: GlobalList,
    name: String,
}

/// How long a reply from the compositor may take before it counts as gone.
pub(crate) const REPLY_TIMEOUT: Duration = Duration::from_secs(10);

impl WaylandDisplay {
    /// Connect to display `name` (see [`socket_path`]) and read its globals; events go
    /// to a queue of `State`.
    pub fn connect<State>(name: Option<&str>) -> Result<(Self, EventQueue<State>), WaylandError>
    where
        State: Dispatch<wl_registry::WlRegistry, GlobalListContents> + 'static,
    {
        let socket = socket_path(name)?;
        let shown = socket.display().to_string();
        let stream = UnixStream::connect(&socket).map_err(|e| WaylandError::Connect {
            socket: shown.clone(),
            reason: e.to_string(),
        })?;
        let connection = Connection::from_socket(stream).map_err(|e| WaylandError::Connect {
            socket: shown.clone(),
            reason: e.to_string(),
        })?;
        let (globals, queue) =
            registry_queue_init::<State>(&connection).map_err(|e| WaylandError::Protocol {
                display: shown.clone(),
                what: format!("reading its globals: {e}"),
            })?;
        Ok((
            WaylandDisplay {
                globals,
                name: shown,
            },
            queue,
        ))
    }

    /// The socket's path, for messages.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The interfaces the compositor offers, with their versions.
    pub fn interfaces(&self) -> Vec<(String, u32)> {
        self.globals.contents().with_list(|list| {
            list.iter()
                .map(|g| (g.interface.clone(), g.version))
                .collect()
        })
    }

    /// Whether the compositor offers `interface`.
    pub fn offers(&self, interface: &str) -> bool {
        self.interfaces().iter().any(|(i, _)| i == interface)
    }

    pub(crate) fn protocol_error(&self, what: impl std::fmt::Display) -> WaylandError {
        WaylandError::Protocol {
            display: self.name.clone(),
            what: what.to_string(),
        }
    }
}

/// The interfaces Wayland display `name` offers, with their versions.
pub fn offered_interfaces(name: Option<&str>) -> Result<Vec<(String, u32)>, WaylandError> {
    let (display, _queue) = WaylandDisplay::connect::<OutputEvents>(name)?;
    Ok(display.interfaces())
}

/// Every `wl_output` of `display` bound on `qh` (up to version 4, user data its index),
/// with what is known of it so far: the outputs' events fill it in.
pub(crate) fn bind_outputs<State>(
    display: &WaylandDisplay,
    qh: &QueueHandle<State>,
) -> Vec<(wl_output::WlOutput, WaylandOutput, bool)>
where
    State: Dispatch<wl_output::WlOutput, usize> + 'static,
{
    let globals: Vec<(u32, u32)> = display.globals.contents().with_list(|list| {
        list.iter()
            .filter(|g| g.interface == "wl_output")
            .map(|g| (g.name, g.version))
            .collect()
    });
    globals
        .iter()
        .enumerate()
        .map(|(index, (global, version))| {
            let proxy: wl_output::WlOutput =
                display
                    .globals
                    .registry()
                    .bind(*global, (*version).min(4), qh, index);
            let info = WaylandOutput {
                global: *global,
                scale: 1,
                ..WaylandOutput::default()
            };
            (proxy, info, false)
        })
        .collect()
}

/// The outputs as their events left them, each named (an output of wl_output before
/// version 4 has no name: `wl_output-N` by its registry name).
pub(crate) fn named(outputs: &[(wl_output::WlOutput, WaylandOutput, bool)]) -> Vec<WaylandOutput> {
    outputs
        .iter()
        .map(|(_, info, _)| {
            let mut info = info.clone();
            if info.name.is_empty() {
                info.name = format!("wl_output-{}", info.global);
            }
            info
        })
        .collect()
}

/// [`named`], each with its kernel EDID from under `sysfs`.
pub(crate) fn described(
    outputs: &[(wl_output::WlOutput, WaylandOutput, bool)],
    sysfs: &std::path::Path,
) -> Vec<WaylandOutput> {
    let mut infos = named(outputs);
    attach_edids(&mut infos, sysfs);
    infos
}

/// The output `selector` names among `outputs`, with its index, or why there is none.
pub(crate) fn choose(
    display: &WaylandDisplay,
    selector: &OutputSelector,
    outputs: &[WaylandOutput],
) -> Result<(usize, WaylandOutput), WaylandError> {
    let chosen = pick(selector, outputs).ok_or_else(|| WaylandError::NoOutput {
        display: display.name().to_string(),
        wanted: selector.describe(),
        outputs: outputs.iter().map(|o| o.name.clone()).collect(),
    })?;
    let index = outputs
        .iter()
        .position(|o| o.global == chosen.global)
        .unwrap_or(0);
    Ok((index, chosen.clone()))
}

/// Each output's EDID from the kernel connector of the same name (under the sysfs
/// root), so that an output can be picked by its monitor's serial.
pub fn attach_edids(outputs: &mut [WaylandOutput], sysfs: &std::path::Path) {
    let edids = drm::connector_edids(sysfs);
    for info in outputs {
        if let Some(found) = drm::edid_for_output(&edids, &info.name) {
            info.edid = Some(found.edid.clone());
            info.edid_source = Some(found.path.display().to_string());
        }
    }
}

/// Dispatch `queue`'s events into `state` until `done` says so (`Ok(true)`) or
/// `deadline` passes (`Ok(false)`), waiting on the socket in between, never longer
/// than the deadline: a compositor that stopped answering times out rather than
/// hanging its client.
pub(crate) fn dispatch_until<State>(
    queue: &mut EventQueue<State>,
    state: &mut State,
    deadline: std::time::Instant,
    done: impl Fn(&State) -> bool,
) -> Result<bool, String> {
    loop {
        queue.dispatch_pending(state).map_err(|e| e.to_string())?;
        if done(state) {
            return Ok(true);
        }
        queue.flush().map_err(|e| e.to_string())?;
        let Some(guard) = queue.prepare_read() else {
            continue;
        };
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return Ok(false);
        }
        let timespec = rustix::event::Timespec {
            tv_sec: i64::try_from(left.as_secs()).unwrap_or(i64::MAX),
            tv_nsec: i64::from(left.subsec_nanos()),
        };
        let fd = guard.connection_fd();
        let mut fds = [rustix::event::PollFd::new(
            &fd,
            rustix::event::PollFlags::IN,
        )];
        match rustix::event::poll(&mut fds, Some(&timespec)) {
            Ok(n) if n > 0 => match guard.read() {
                Ok(_) => {}
                // A batch of events only for objects already gone (delete_id, a
                // destroyed pool's): nothing to dispatch, nothing wrong.
                Err(wayland_client::backend::WaylandError::Io(e))
                    if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) => return Err(e.to_string()),
            },
            Ok(_) | Err(rustix::io::Errno::INTR) => drop(guard),
            Err(e) => return Err(e.to_string()),
        }
    }
}

/// Every output of Wayland display `name`, in the compositor's order, each with the
/// kernel's EDID of its connector where `sysfs` has one.
pub fn list_outputs(
    name: Option<&str>,
    sysfs: &std::path::Path,
) -> Result<Vec<WaylandOutput>, WaylandError> {
    let (display, mut queue) = WaylandDisplay::connect::<OutputEvents>(name)?;
    let qh = queue.handle();
    let mut state = OutputEvents {
        outputs: bind_outputs(&display, &qh),
    };
    // Two round trips: the binds, then every output's events up to `done`.
    for _ in 0..2 {
        queue
            .roundtrip(&mut state)
            .map_err(|e| display.protocol_error(format!("listing outputs: {e}")))?;
    }
    let outputs = described(&state.outputs, sysfs);
    for (proxy, _, _) in &state.outputs {
        if proxy.version() >= 3 {
            proxy.release();
        }
    }
    Ok(outputs)
}

use wayland_client::Proxy as _;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_display_names_are_under_the_runtime_dir_and_absolute_ones_stay() {
        assert_eq!(
            socket_path(Some("/run/x/wayland-9")).unwrap(),
            PathBuf::from("/run/x/wayland-9")
        );
    }

    #[test]
    fn outputs_are_picked_by_name_description_or_make_and_model() {
        let outputs = vec![
            WaylandOutput {
                name: "DP-1".into(),
                make: "Dell".into(),
                model: "U2713HM".into(),
                description: "Dell U2713HM (DP-1)".into(),
                ..WaylandOutput::default()
            },
            WaylandOutput {
                name: "HDMI-A-1".into(),
                ..WaylandOutput::default()
            },
        ];
        let name =
            |s: &str| pick(&OutputSelector::Name(s.into()), &outputs).map(|o| o.name.clone());
        assert_eq!(name("HDMI-A-1").as_deref(), Some("HDMI-A-1"));
        assert_eq!(name("Dell U2713HM").as_deref(), Some("DP-1"));
        assert_eq!(name("DP-2"), None);
        assert_eq!(
            pick(&OutputSelector::Primary, &outputs).map(|o| o.name.as_str()),
            Some("DP-1")
        );
    }

    #[test]
    fn the_frame_follows_the_mode_and_defaults_to_60_hz() {
        let mut o = WaylandOutput {
            refresh_mhz: 120_000,
            ..WaylandOutput::default()
        };
        assert!((o.frame_s() - 1.0 / 120.0).abs() < 1e-12);
        o.refresh_mhz = 0;
        assert!((o.frame_s() - 1.0 / 60.0).abs() < 1e-12);
    }
}
