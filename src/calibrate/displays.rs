//! The screens of an X display as a user picks one: each RandR output with its
//! monitor's EDID identity, its mode, its video LUT, and the configured device whose
//! window goes there (with that device's current profile).

use std::path::Path;

use serde::Serialize;

use crate::config::devices::device_configs;
use crate::config::{LoadedConfig, Sink};
use crate::profile::store::ProfileStore;
use chromacal_display::x11::{OutputInfo, X11Error, XDisplay};
use chromacal_formats::edid::{Edid, colord_device_id};

/// Where the desktops' colour plugins look up a monitor maker's name by its PNP id
/// (Debian's hwdata, older systems' misc).
const PNP_IDS: [&str; 2] = ["/usr/share/hwdata/pnp.ids", "/usr/share/misc/pnp.ids"];

/// The maker's name for a three-letter PNP id, from the first `pnp.ids` there is
/// (lines `ABC<tab>Name`); none where there is none or it does not list the id.
fn pnp_vendor_name(code: &str) -> Option<String> {
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
            let (edid, edid_error) = match output.edid.as_deref().map(Edid::parse) {
                Some(Ok(e)) => (Some(e), None),
                Some(Err(e)) => (None, Some(e.to_string())),
                None => (None, None),
            };
            let lut_identity = output
                .crtc
                .and_then(|_| x.gamma(output).ok())
                .map(|r| r.is_identity());
            let devices = devices
                .iter()
                .filter(|d| {
                    let display = &d.loaded.config.display;
                    display.sink() == Sink::Window
                        && display
                            .output
                            .clone()
                            .unwrap_or_default()
                            .pick(&outputs)
                            .is_some_and(|o| o.id == output.id)
                })
                .map(|d| DeviceOnOutput {
                    name: d.name.clone(),
                    profile: ProfileStore::new(&d.store_dir(state_dir))
                        .history()
                        .ok()
                        .and_then(|h| h.current),
                })
                .collect();
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
        for d in &e.devices {
            out += &format!(
                "    device {}: {}\n",
                d.name,
                d.profile
                    .as_deref()
                    .map_or("no profile yet".to_string(), |p| format!(
                        "current profile {p}"
                    ))
            );
        }
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
