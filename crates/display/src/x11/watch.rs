//! An output watched for RandR changes (a monitor plugged in, a mode changed), on an
//! X connection of its own: what the daemon's video LUT keeper reloads the curves on.

use x11rb::connection::Connection;
use x11rb::protocol::Event as XEvent;
use x11rb::protocol::randr::{ConnectionExt as _, NotifyMask};

use super::{OutputInfo, OutputSelector, X11Error, XDisplay};

/// The X connection the keeper watches RandR events on, and its output.
pub struct Watch {
    pub x: XDisplay,
    pub output: OutputInfo,
}

impl Watch {
    pub fn open(x_display: Option<&str>, selector: &OutputSelector) -> Result<Self, X11Error> {
        let x = XDisplay::open(x_display)?;
        let output = x.output(selector)?;
        x.conn
            .randr_select_input(
                x.root,
                NotifyMask::SCREEN_CHANGE | NotifyMask::CRTC_CHANGE | NotifyMask::OUTPUT_CHANGE,
            )
            .map_err(|e| x.protocol(e))?;
        x.sync()?;
        Ok(Watch { x, output })
    }

    /// Whether a RandR event came since the last call; an error when the
    /// connection is gone.
    pub fn randr_changed(&self) -> Result<bool, X11Error> {
        let mut changed = false;
        while let Some(event) = self
            .x
            .conn
            .poll_for_event()
            .map_err(|e| self.x.protocol(e))?
        {
            if matches!(
                event,
                XEvent::RandrScreenChangeNotify(_) | XEvent::RandrNotify(_)
            ) {
                changed = true;
            }
        }
        Ok(changed)
    }
}
