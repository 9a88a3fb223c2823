//! RandR outputs: the connectors of the X screen, each with the CRTC that drives it
//! (its place on the screen, its mode and refresh) and the EDID the monitor gave
//! (RandR 1.3 output property `EDID`).

use serde::{Deserialize, Serialize};
use x11rb::protocol::randr::ConnectionExt as _;
use x11rb::protocol::xproto::AtomEnum;

use super::{X11Error, XDisplay};

/// Which output a display means: the primary, one by connector name, or the one whose
/// monitor's EDID carries a serial (so that a cable can move).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(untagged)]
pub enum OutputSelector {
    /// The primary output (or the first lit one when none is primary).
    #[default]
    #[serde(skip)]
    Primary,
    /// A connector name such as `DP-1` or `HDMI-A-0`.
    Name(String),
    /// `{ edid_serial = "…" }`: the monitor's serial, numeric or text, from its EDID.
    Edid { edid_serial: String },
}

impl OutputSelector {
    /// A name on the command line: empty is the primary.
    pub fn parse(text: &str) -> Self {
        if text.is_empty() {
            OutputSelector::Primary
        } else if let Some(serial) = text.strip_prefix("edid_serial=") {
            OutputSelector::Edid {
                edid_serial: serial.to_string(),
            }
        } else {
            OutputSelector::Name(text.to_string())
        }
    }

    /// The output this selector means among `outputs`.
    pub fn pick<'a>(&self, outputs: &'a [OutputInfo]) -> Option<&'a OutputInfo> {
        match self {
            OutputSelector::Primary => outputs
                .iter()
                .find(|o| o.primary && o.crtc.is_some())
                .or_else(|| outputs.iter().find(|o| o.crtc.is_some())),
            OutputSelector::Name(name) => outputs.iter().find(|o| &o.name == name),
            OutputSelector::Edid { edid_serial } => outputs.iter().find(|o| {
                o.edid
                    .as_deref()
                    .and_then(|bytes| chromacal_formats::edid::Edid::parse(bytes).ok())
                    .is_some_and(|e| e.matches_serial(edid_serial))
            }),
        }
    }

    pub fn describe(&self) -> String {
        match self {
            OutputSelector::Primary => "the primary output".into(),
            OutputSelector::Name(n) => format!("named '{n}'"),
            OutputSelector::Edid { edid_serial } => {
                format!("whose monitor's EDID serial is '{edid_serial}'")
            }
        }
    }
}

/// One output as RandR reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutputInfo {
    pub name: String,
    pub id: u32,
    /// A monitor is plugged in.
    pub connected: bool,
    pub primary: bool,
    /// The CRTC that drives it, when lit.
    pub crtc: Option<u32>,
    /// Its rectangle on the X screen, pixels.
    pub x: i32,
    pub y: i32,
    pub width: u32,
    pub height: u32,
    /// Refresh of the current mode from its timings, Hz (none when the server gives no
    /// timings, as Xvfb does).
    pub refresh_hz: Option<f64>,
    /// Entries of the CRTC's gamma ramp (the video LUT).
    pub gamma_size: usize,
    /// The monitor's EDID, as the driver read it (or, where the driver gives none, as
    /// the kernel read it: `drm`).
    #[serde(skip)]
    pub edid: Option<Vec<u8>>,
    /// Where `edid` came from: `RandR`, or the kernel's file for the output's connector
    /// (`/sys/class/drm/card0-DP-1/edid`).
    pub edid_source: Option<String>,
    /// Physical size the monitor reports, mm.
    pub mm_width: u32,
    pub mm_height: u32,
}

impl OutputInfo {
    /// The CRTC, or an error saying the output is dark.
    pub fn lit_crtc(&self) -> Result<u32, X11Error> {
        self.crtc.ok_or_else(|| X11Error::Unlit {
            output: self.name.clone(),
        })
    }

    /// One frame of the current mode, s (60 Hz when the mode gives no timings).
    pub fn frame_s(&self) -> f64 {
        1.0 / self.refresh_hz.filter(|hz| *hz >= 1.0).unwrap_or(60.0)
    }
}

/// The kernel's EDID for each connected output the driver gave none (`drm`), matched
/// by the output's name.
fn with_kernel_edids(outputs: &mut [OutputInfo], sysfs_root: &std::path::Path) {
    if outputs.iter().all(|o| o.edid.is_some() || !o.connected) {
        return;
    }
    let edids = crate::drm::connector_edids(sysfs_root);
    for output in outputs
        .iter_mut()
        .filter(|o| o.edid.is_none() && o.connected)
    {
        if let Some(found) = crate::drm::edid_for_output(&edids, &output.name) {
            output.edid = Some(found.edid.clone());
            output.edid_source = Some(found.path.display().to_string());
        }
    }
}

impl XDisplay {
    /// Every output of the screen, lit or not; an output the driver gives no EDID
    /// takes its connector's from the kernel (`with_kernel_edids`).
    pub fn outputs(&self) -> Result<Vec<OutputInfo>, X11Error> {
        let err = |e: &dyn std::fmt::Display| self.protocol(e);
        let resources = self
            .conn
            .randr_get_screen_resources_current(self.root)
            .map_err(|e| err(&e))?
            .reply()
            .map_err(|e| err(&e))?;
        let primary = self
            .conn
            .randr_get_output_primary(self.root)
            .map_err(|e| err(&e))?
            .reply()
            .map_err(|e| err(&e))?
            .output;
        let edid_atom = self.atom(b"EDID", true)?;
        let mut outputs = Vec::new();
        for &output in &resources.outputs {
            let info = self
                .conn
                .randr_get_output_info(output, resources.config_timestamp)
                .map_err(|e| err(&e))?
                .reply()
                .map_err(|e| err(&e))?;
            let name = String::from_utf8_lossy(&info.name).into_owned();
            let mut out = OutputInfo {
                name,
                id: output,
                connected: info.connection == x11rb::protocol::randr::Connection::CONNECTED,
                primary: output == primary,
                crtc: (info.crtc != 0).then_some(info.crtc),
                x: 0,
                y: 0,
                width: 0,
                height: 0,
                refresh_hz: None,
                gamma_size: 0,
                edid: None,
                edid_source: None,
                mm_width: info.mm_width,
                mm_height: info.mm_height,
            };
            if let Some(crtc) = out.crtc {
                let c = self
                    .conn
                    .randr_get_crtc_info(crtc, resources.config_timestamp)
                    .map_err(|e| err(&e))?
                    .reply()
                    .map_err(|e| err(&e))?;
                out.x = c.x.into();
                out.y = c.y.into();
                out.width = c.width.into();
                out.height = c.height.into();
                out.refresh_hz = resources
                    .modes
                    .iter()
                    .find(|m| m.id == c.mode)
                    .and_then(|m| {
                        let pixels = f64::from(m.htotal) * f64::from(m.vtotal);
                        (m.dot_clock > 0 && pixels > 0.0).then(|| f64::from(m.dot_clock) / pixels)
                    });
                out.gamma_size = self
                    .conn
                    .randr_get_crtc_gamma_size(crtc)
                    .map_err(|e| err(&e))?
                    .reply()
                    .map_err(|e| err(&e))?
                    .size
                    .into();
            }
            if edid_atom != 0 {
                let property = self
                    .conn
                    .randr_get_output_property(
                        output,
                        edid_atom,
                        AtomEnum::ANY,
                        0,
                        // 32-bit units: 1 KiB holds a base block and three extensions.
                        256,
                        false,
                        false,
                    )
                    .map_err(|e| err(&e))?
                    .reply()
                    .map_err(|e| err(&e))?;
                if property.format == 8 && !property.data.is_empty() {
                    out.edid = Some(property.data);
                    out.edid_source = Some("RandR".into());
                }
            }
            outputs.push(out);
        }
        with_kernel_edids(&mut outputs, &crate::drm::sysfs_root());
        Ok(outputs)
    }

    /// The output `selector` names. An EDID serial is matched against the parsed EDID
    /// (the numeric serial or the serial text descriptor).
    pub fn output(&self, selector: &OutputSelector) -> Result<OutputInfo, X11Error> {
        let outputs = self.outputs()?;
        let have = || {
            let names: Vec<String> = outputs
                .iter()
                .map(|o| {
                    format!(
                        "{}{}",
                        o.name,
                        if o.crtc.is_some() { "" } else { " (dark)" }
                    )
                })
                .collect();
            if names.is_empty() {
                "no outputs".to_string()
            } else {
                names.join(", ")
            }
        };
        selector
            .pick(&outputs)
            .cloned()
            .ok_or_else(|| X11Error::NoOutput {
                wanted: selector.describe(),
                display: self.name().to_string(),
                have: have(),
            })
    }

    /// Put `edid` on `output` as its `EDID` property: what a driver does when a monitor
    /// is plugged in. For tests and for servers (Xvfb, some virtual machines) that have
    /// no monitor to read one from.
    pub fn set_edid(&self, output: u32, edid: &[u8]) -> Result<(), X11Error> {
        let err = |e: &dyn std::fmt::Display| self.protocol(e);
        let atom = self.atom(b"EDID", false)?;
        let units = u32::try_from(edid.len()).map_err(|e| err(&e))?;
        self.conn
            .randr_change_output_property(
                output,
                atom,
                AtomEnum::INTEGER.into(),
                8,
                x11rb::protocol::xproto::PropMode::REPLACE,
                units,
                edid,
            )
            .map_err(|e| err(&e))?
            .check()
            .map_err(|e| err(&e))?;
        Ok(())
    }
}
