//! The video LUT on wlroots compositors (sway, Hyprland, river, labwc):
//! `wlr-gamma-control-unstable-v1`. A client asks for an output's gamma control and is
//! told its ramp's size (or that it failed: another client holds it, or the output
//! has no ramp); the ramp it sets stays only while the client holds the control: the
//! compositor drops it when the client disconnects. So whoever loads curves here must
//! stay (`lut load --hold`), and a size of 0 (headless and nested
//! outputs) is an output without a ramp, never a ramp loaded.

use std::fs::File;
use std::os::fd::AsFd as _;
use std::os::unix::fs::FileExt as _;

use serde::Serialize;
use wayland_client::protocol::wl_output;
use wayland_client::{Connection, Dispatch, EventQueue, QueueHandle};
use wayland_protocols_wlr::gamma_control::v1::client::{
    zwlr_gamma_control_manager_v1, zwlr_gamma_control_v1,
};

use super::{WaylandDisplay, WaylandError, WaylandOutput};
use crate::x11::{GammaRamp, OutputSelector};

/// What an output's gamma control said.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "gamma", content = "size")]
pub enum GammaOffer {
    /// The compositor has no wlr-gamma-control (GNOME, KDE: they apply a profile's
    /// `vcgt` themselves).
    NotOffered,
    /// The control failed: the output has no ramp (wlroots says so for a size of 0),
    /// or another client holds it.
    Failed,
    /// A ramp of this many entries per channel (0: the output has none).
    Size(u32),
}

impl GammaOffer {
    /// A sentence for `displays` and `lut`.
    pub fn describe(&self) -> String {
        match self {
            GammaOffer::NotOffered => {
                "the compositor offers no gamma control (wlr-gamma-control): it applies an output's profile, vcgt included, itself".into()
            }
            // wlroots answers `failed` both for an output whose ramp has size 0 and
            // for one whose control another client holds.
            GammaOffer::Failed => {
                "no gamma ramp to load: the compositor refused its gamma control (a headless or nested output has no ramp, size 0; or another program, such as a night-light tool, holds it)".into()
            }
            GammaOffer::Size(0) => {
                "no gamma ramp (size 0: a headless or nested output)".into()
            }
            GammaOffer::Size(n) => format!("gamma ramp of {n} entries (wlr-gamma-control)"),
        }
    }
}

#[derive(Default)]
struct GammaEvents {
    outputs: Vec<(wl_output::WlOutput, WaylandOutput, bool)>,
    /// Per output index: what its control said.
    offers: Vec<Option<GammaOffer>>,
}

/// A held gamma control: the ramp set through it stays until this is dropped (or the
/// process ends), then the compositor puts its own back.
pub struct HeldGamma {
    _display: WaylandDisplay,
    queue: EventQueue<GammaEvents>,
    events: GammaEvents,
    control: zwlr_gamma_control_v1::ZwlrGammaControlV1,
    /// The output and its ramp size.
    pub output: WaylandOutput,
    pub size: u32,
}

/// Why curves could not be put in a Wayland output's ramp.
#[derive(Debug, thiserror::Error)]
pub enum GammaError {
    #[error(transparent)]
    Wayland(#[from] WaylandError),
    #[error(
        "the Wayland compositor offers no gamma ramp on {output}: {}. There the curves can only be applied in the codes (chromacal's own runs and verifications do so) or by colour-managed programs through the exported ICC profile (`chromacal export --format icc2`)",
        .offer.describe()
    )]
    NoRamp { output: String, offer: GammaOffer },
    #[error("setting the gamma ramp of {output}: {reason}")]
    Set { output: String, reason: String },
}

/// Connect, bind every output and, where offered, ask each for its gamma control.
fn open(
    name: Option<&str>,
) -> Result<
    (
        WaylandDisplay,
        EventQueue<GammaEvents>,
        GammaEvents,
        Vec<zwlr_gamma_control_v1::ZwlrGammaControlV1>,
    ),
    WaylandError,
> {
    let (display, mut queue) = WaylandDisplay::connect::<GammaEvents>(name)?;
    let qh = queue.handle();
    let mut events = GammaEvents::default();
    events.outputs = super::bind_outputs(&display, &qh);
    events.offers = vec![None; events.outputs.len()];
    let manager: Option<zwlr_gamma_control_manager_v1::ZwlrGammaControlManagerV1> =
        display.globals.bind(&qh, 1..=1, ()).ok();
    let controls = match &manager {
        Some(m) => events
            .outputs
            .iter()
            .enumerate()
            .map(|(index, (proxy, _, _))| m.get_gamma_control(proxy, &qh, index))
            .collect(),
        None => {
            for offer in &mut events.offers {
                *offer = Some(GammaOffer::NotOffered);
            }
            Vec::new()
        }
    };
    for _ in 0..2 {
        queue
            .roundtrip(&mut events)
            .map_err(|e| display.protocol_error(format!("asking for gamma control: {e}")))?;
    }
    Ok((display, queue, events, controls))
}

/// What each output's gamma control says, by output name. The controls are given
/// back at once (the compositor's own ramp stays).
pub fn gamma_offers(name: Option<&str>) -> Result<Vec<(String, GammaOffer)>, WaylandError> {
    let (_display, _queue, events, controls) = open(name)?;
    for c in controls {
        c.destroy();
    }
    Ok(super::named(&events.outputs)
        .into_iter()
        .zip(&events.offers)
        .map(|(info, offer)| (info.name, offer.unwrap_or(GammaOffer::Failed)))
        .collect())
}

/// Take the gamma control of the output `selector` names and set `ramp_of(size)` on it;
/// the ramp stays while the returned [`HeldGamma`] lives.
pub fn hold_gamma(
    name: Option<&str>,
    selector: &OutputSelector,
    ramp_of: impl FnOnce(usize) -> GammaRamp,
) -> Result<HeldGamma, GammaError> {
    let (display, queue, events, mut controls) = open(name)?;
    let (index, output) = super::choose(
        &display,
        selector,
        &super::described(&events.outputs, &crate::drm::sysfs_root()),
    )?;
    let offer = events.offers[index].unwrap_or(GammaOffer::Failed);
    let size = match offer {
        GammaOffer::Size(n) if n >= 2 => n,
        offer => {
            return Err(GammaError::NoRamp {
                output: output.name,
                offer,
            });
        }
    };
    let control = controls.swap_remove(index);
    for other in controls {
        other.destroy();
    }
    let mut held = HeldGamma {
        _display: display,
        queue,
        events,
        control,
        output,
        size,
    };
    held.set(&ramp_of(size as usize))?;
    Ok(held)
}

impl HeldGamma {
    /// Set `ramp` (of the control's size) on the output.
    pub fn set(&mut self, ramp: &GammaRamp) -> Result<(), GammaError> {
        let failed = |reason: String| GammaError::Set {
            output: self.output.name.clone(),
            reason,
        };
        if ramp.len() != self.size as usize {
            return Err(failed(format!(
                "a ramp of {} entries for a control of {}",
                ramp.len(),
                self.size
            )));
        }
        // The table: red, green, blue, each `size` native-endian u16 (the protocol's).
        let bytes: Vec<u8> = ramp
            .channels()
            .iter()
            .flat_map(|c| c.iter().flat_map(|v| v.to_ne_bytes()))
            .collect();
        let fd = rustix::fs::memfd_create("chromacal-gamma", rustix::fs::MemfdFlags::CLOEXEC)
            .map_err(|e| failed(format!("memfd_create: {e}")))?;
        let file = File::from(fd);
        file.write_all_at(&bytes, 0)
            .map_err(|e| failed(format!("writing the table: {e}")))?;
        self.control.set_gamma(file.as_fd());
        self.queue
            .roundtrip(&mut self.events)
            .map_err(|e| failed(e.to_string()))?;
        let index = self
            .events
            .outputs
            .iter()
            .position(|o| o.1.global == self.output.global);
        match index.and_then(|i| self.events.offers[i]) {
            Some(GammaOffer::Failed) => Err(failed(
                "the compositor refused the table (the control failed)".into(),
            )),
            _ => Ok(()),
        }
    }

    /// Wait until the compositor goes away or the control fails (another client took
    /// it, the output was unplugged), dispatching its events meanwhile.
    pub fn wait(&mut self) -> Result<(), GammaError> {
        loop {
            self.queue
                .blocking_dispatch(&mut self.events)
                .map_err(|e| GammaError::Set {
                    output: self.output.name.clone(),
                    reason: format!("the compositor went away: {e}"),
                })?;
            let index = self
                .events
                .outputs
                .iter()
                .position(|o| o.1.global == self.output.global);
            if let Some(GammaOffer::Failed) = index.and_then(|i| self.events.offers[i]) {
                return Err(GammaError::Set {
                    output: self.output.name.clone(),
                    reason: "the gamma control failed (another program took it, or the output went away)".into(),
                });
            }
        }
    }
}

super::dispatch_outputs!(GammaEvents);

impl Dispatch<zwlr_gamma_control_v1::ZwlrGammaControlV1, usize> for GammaEvents {
    fn event(
        state: &mut Self,
        _: &zwlr_gamma_control_v1::ZwlrGammaControlV1,
        event: zwlr_gamma_control_v1::Event,
        index: &usize,
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        let offer = match event {
            zwlr_gamma_control_v1::Event::GammaSize { size } => GammaOffer::Size(size),
            zwlr_gamma_control_v1::Event::Failed => GammaOffer::Failed,
            _ => return,
        };
        if let Some(slot) = state.offers.get_mut(*index) {
            *slot = Some(offer);
        }
    }
}

wayland_client::delegate_noop!(GammaEvents: ignore zwlr_gamma_control_manager_v1::ZwlrGammaControlManagerV1);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_offer_serialises_with_its_size_where_it_has_one() {
        let json = |o: GammaOffer| serde_json::to_value(o).unwrap();
        assert_eq!(
            json(GammaOffer::Size(256)),
            serde_json::json!({"gamma": "size", "size": 256})
        );
        assert_eq!(
            json(GammaOffer::Failed),
            serde_json::json!({"gamma": "failed"})
        );
        assert_eq!(
            json(GammaOffer::NotOffered),
            serde_json::json!({"gamma": "not-offered"})
        );
    }
}
