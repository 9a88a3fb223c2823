//! The screens of an X or Wayland display as a user picks one: each RandR output or
//! wl_output with its monitor's EDID identity, its mode, its video LUT, and the
//! configured device whose window goes there (with that device's current profile).

use std::path::Path;

use serde::Serialize;

use crate::config::devices::device_configs;
use crate::config::{LoadedConfig, Sink};
use crate::profile::store::ProfileStore;
use chromacal_display::wayland::gamma::GammaOffer;
use chromacal_display::wayland::{self, WaylandError, WaylandOutput};
use chromacal_display::x11::{OutputInfo, X11Error, XDisplay};
use chromacal_formats::edid::{Edid, colord_device_id};

/// Where the desktops' colour plugins look up a monitor maker's name by its PNP id
/// (Debian's hwdata, older systems' misc).
const PNP_IDS: [&str; 2] = ["/usr/share/hwdata/pnp.ids", "/usr/share/misc/pnp.ids"];

/// The maker's name for a three-letter PNP id, from the first `pnp.ids` there is
/// (lines `ABC<tab>Name`); none where there is none or it does not list the id.
pub fn pnp_vendor_name(code: &str) -> Option<String> {
    let text = PNP_IDS
        .iter()
        .find_map(|p| std::fs::read_to_string(p).ok())?;
    text.lines().find_map(|line| {
        let (id, name) = line.split_once('\t')?;
        (id.trim() == code).then(|| name.trim().to_string())
    })
}

/// One output, as `chromacal displays` shows it.
#[derive(Debug, Clone, Serialize)]
pub struct DisplayEntry {
    #[serde(flatten)]
    pub output: OutputInfo,
    /// The parsed EDID, when the output has one that parses.
    pub edid: Option<Edid>,
    /// Why the EDID the output has does not parse.
    pub edid_error: Option<String>,
    /// The video LUT is the straight ramp.
    pub lut_identity: Option<bool>,
    /// The id colord knows the output's monitor by (`export --register-colord`).
    pub colord_device_id: String,
    /// Configured devices whose window is on this output.
    pub devices: Vec<DeviceOnOutput>,
}

/// A device of the config that shows its patches on an output.
#[derive(Debug, Clone, Serialize)]
pub struct DeviceOnOutput {
    pub name: String,
    /// Its current profile's id, if it has one.
    pub profile: Option<String>,
}

/// An output's EDID parsed, or why it does not parse (neither: it has none).
fn parsed_edid(bytes: Option<&[u8]>) -> (Option<Edid>, Option<String>) {
    match bytes.map(Edid::parse) {
        Some(Ok(e)) => (Some(e), None),
        Some(Err(e)) => (None, Some(e.to_string())),
        None => (None, None),
    }
}

/// A line for each configured device on an output, with its current profile.
fn device_lines(devices: &[DeviceOnOutput]) -> String {
    devices
        .iter()
        .map(|d| {
            format!(
                "    device {}: {}\n",
                d.name,
                d.profile
                    .as_deref()
                    .map_or("no profile yet".to_string(), |p| format!(
                        "current profile {p}"
                    ))
            )
        })
        .collect()
}

/// The devices among `devices` whose `[display]` puts their patches here
/// (`shows_here`), each with its current profile (stores under `state_dir`).
fn devices_on(
    devices: &[crate::config::devices::DeviceConfig],
    state_dir: &Path,
    shows_here: impl Fn(&crate::config::DisplayConfig) -> bool,
) -> Vec<DeviceOnOutput> {
    devices
        .iter()
        .filter(|d| shows_here(&d.loaded.config.display))
        .map(|d| DeviceOnOutput {
            name: d.name.clone(),
            profile: ProfileStore::new(&d.store_dir(state_dir))
                .history()
                .ok()
                .and_then(|h| h.current),
        })
        .collect()
}

/// Every output of `x`, with the devices of `loaded` (stores under `state_dir`) that
/// put their window on it.
pub fn list_displays(
    x: &XDisplay,
    loaded: Option<&LoadedConfig>,
    state_dir: &Path,
) -> Result<Vec<DisplayEntry>, X11Error> {
    let outputs = x.outputs()?;
    let devices = loaded
        .and_then(|l| device_configs(l).ok())
        .unwrap_or_default();
    Ok(outputs
        .iter()
        .map(|output| {
            let (edid, edid_error) = parsed_edid(output.edid.as_deref());
            let lut_identity = output
                .crtc
                .and_then(|_| x.gamma(output).ok())
                .map(|r| r.is_identity());
            let devices = devices_on(&devices, state_dir, |display| {
                display.sink() == Sink::Window
                    && display
                        .output
                        .clone()
                        .unwrap_or_default()
                        .pick(&outputs)
                        .is_some_and(|o| o.id == output.id)
            });
            DisplayEntry {
                colord_device_id: colord_device_id(edid.as_ref(), &output.name, pnp_vendor_name),
                output: output.clone(),
                edid,
                edid_error,
                lut_identity,
                devices,
            }
        })
        .collect())
}

/// The lines `chromacal displays` prints for `entries`.
pub fn describe_displays(x_display: &str, entries: &[DisplayEntry]) -> String {
    let mut out = format!("X display {x_display}:\n");
    // An output with nothing on it and nothing of chromacal's gets one word on a
    // shared line: a dummy or docking-station driver has a dozen of them.
    let idle = |e: &DisplayEntry| {
        !e.output.connected
            && e.output.crtc.is_none()
            && e.edid.is_none()
            && e.edid_error.is_none()
            && e.devices.is_empty()
    };
    for e in entries.iter().filter(|e| !idle(e)) {
        let o = &e.output;
        let state = match (o.connected, o.crtc) {
            (_, Some(_)) => format!(
                "{}×{}+{}+{}{}",
                o.width,
                o.height,
                o.x,
                o.y,
                o.refresh_hz
                    .map(|hz| format!(" at {hz:.2} Hz"))
                    .unwrap_or_default()
            ),
            (true, None) => "connected, dark".into(),
            (false, None) => "disconnected".into(),
        };
        out += &format!(
            "  {}{}  {state}\n",
            o.name,
            if o.primary { " (primary)" } else { "" }
        );
        if o.crtc.is_some() {
            out += &format!(
                "    video LUT: {} entries, {}\n",
                o.gamma_size,
                match e.lut_identity {
                    Some(true) => "straight",
                    Some(false) => "curves loaded",
                    None => "unreadable",
                }
            );
        }
        match (&e.edid, &e.edid_error) {
            (Some(edid), _) => {
                out += &format!("    monitor: {}\n", edid.describe());
                if let Some(source) = o.edid_source.as_deref().filter(|s| *s != "RandR") {
                    out += &format!("    EDID from the kernel: {source} (the driver gave none)\n");
                }
                out += &format!(
                    "    EDID primaries xy: R {:.4},{:.4}  G {:.4},{:.4}  B {:.4},{:.4}  white {:.4},{:.4}\n",
                    edid.red[0],
                    edid.red[1],
                    edid.green[0],
                    edid.green[1],
                    edid.blue[0],
                    edid.blue[1],
                    edid.white[0],
                    edid.white[1]
                );
            }
            (None, Some(err)) => out += &format!("    EDID: unreadable ({err})\n"),
            (None, None) => out += "    EDID: none\n",
        }
        out += &format!("    colord device: {}\n", e.colord_device_id);
        out += &device_lines(&e.devices);
    }
    let disconnected: Vec<&str> = entries
        .iter()
        .filter(|e| idle(e))
        .map(|e| e.output.name.as_str())
        .collect();
    if !disconnected.is_empty() {
        out += &format!("  disconnected: {}\n", disconnected.join(", "));
    }
    out
}

/// One Wayland output, as `chromacal displays` shows it.
#[derive(Debug, Clone, Serialize)]
pub struct WaylandEntry {
    #[serde(flatten)]
    pub output: WaylandOutput,
    pub edid: Option<Edid>,
    pub edid_error: Option<String>,
    /// What the output's gamma control says (wlroots compositors).
    pub gamma: GammaOffer,
    /// The id colord knows the output's monitor by (GNOME applies its profile).
    pub colord_device_id: String,
    /// Configured devices whose surface is on this output.
    pub devices: Vec<DeviceOnOutput>,
}

/// A Wayland display's outputs, and what its compositor offers a calibration.
#[derive(Debug, Clone, Serialize)]
pub struct WaylandListing {
    pub display: String,
    /// The protocols chromacal uses or minds, and whether the compositor has each.
    pub protocols: Vec<(&'static str, bool)>,
    pub outputs: Vec<WaylandEntry>,
}

/// What chromacal uses on Wayland, or minds: each protocol and what it is for.
pub const WAYLAND_PROTOCOLS: [(&str, &str); 6] = [
    ("xdg_wm_base", "the full-screen patch surface"),
    ("wp_presentation", "a patch counts as shown once presented"),
    ("zwp_idle_inhibit_manager_v1", "no blanking during a run"),
    (
        "zwlr_gamma_control_manager_v1",
        "the video LUT (lut load --hold)",
    ),
    (
        "zwlr_screencopy_manager_v1",
        "emulate --wayland-display reads the screen",
    ),
    (
        "wp_color_manager_v1",
        "the compositor may convert the patches' codes",
    ),
];

/// Every output of Wayland display `name`, with the devices of `loaded` whose surface
/// goes there.
pub fn list_wayland_displays(
    name: Option<&str>,
    loaded: Option<&LoadedConfig>,
    state_dir: &Path,
) -> Result<WaylandListing, WaylandError> {
    let outputs = wayland::list_outputs(name, &chromacal_display::drm::sysfs_root())?;
    let offers = wayland::gamma::gamma_offers(name)?;
    let interfaces = wayland::offered_interfaces(name)?;
    let protocols = WAYLAND_PROTOCOLS
        .iter()
        .map(|(p, _)| (*p, interfaces.iter().any(|(i, _)| i == p)))
        .collect();
    let devices = loaded
        .and_then(|l| device_configs(l).ok())
        .unwrap_or_default();
    let entries = outputs
        .iter()
        .map(|output| {
            let (edid, edid_error) = parsed_edid(output.edid.as_deref());
            let devices = devices_on(&devices, state_dir, |display| {
                display.sink() == Sink::Wayland
                    && wayland::pick(&display.output.clone().unwrap_or_default(), &outputs)
                        .is_some_and(|o| o.global == output.global)
            });
            WaylandEntry {
                colord_device_id: colord_device_id(edid.as_ref(), &output.name, pnp_vendor_name),
                gamma: offers
                    .iter()
                    .find(|(n, _)| *n == output.name)
                    .map_or(GammaOffer::Failed, |(_, g)| *g),
                output: output.clone(),
                edid,
                edid_error,
                devices,
            }
        })
        .collect();
    Ok(WaylandListing {
        display: wayland::socket_path(name)?.display().to_string(),
        protocols,
        outputs: entries,
    })
}

/// The lines `chromacal displays` prints for a Wayland listing.
pub fn describe_wayland_displays(listing: &WaylandListing) -> String {
    let mut out = format!("Wayland display {}:\n", listing.display);
    for e in &listing.outputs {
        let o = &e.output;
        out += &format!(
            "  {}  {}×{} at {:.2} Hz, scale {}  ({})\n",
            o.name,
            o.width,
            o.height,
            f64::from(o.refresh_mhz) / 1000.0,
            o.scale,
            o.description
        );
        out += &format!("    video LUT: {}\n", e.gamma.describe());
        match (&e.edid, &e.edid_error, &o.edid_source) {
            (Some(edid), _, source) => {
                out += &format!("    monitor: {}\n", edid.describe());
                if let Some(source) = source {
                    out += &format!("    EDID from the kernel: {source}\n");
                }
            }
            (None, Some(err), _) => out += &format!("    EDID: unreadable ({err})\n"),
            (None, None, _) => {
                out += &format!(
                    "    EDID: none (no kernel connector {} with one under {}/class/drm)\n",
                    o.name,
                    chromacal_display::drm::sysfs_root().display()
                )
            }
        }
        out += &format!("    colord device: {}\n", e.colord_device_id);
        out += &device_lines(&e.devices);
    }
    out += "  the compositor offers:\n";
    for ((protocol, offered), (_, what)) in listing.protocols.iter().zip(WAYLAND_PROTOCOLS) {
        out += &format!(
            "    {protocol}: {}  ({what})\n",
            if *offered { "yes" } else { "no" }
        );
    }
    out
}
