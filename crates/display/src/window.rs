//! A native patch window: a borderless full-screen X11 window on one RandR output,
//! with a child window as the patch. Both are filled by the X server from their
//! background pixels, so the codes reach the framebuffer exactly (no colour
//! management, no dithering, no compositing hint ignored: `_NET_WM_BYPASS_COMPOSITOR`
//! is set) and the server repaints them itself after anything covered them.
//!
//! A patch counts as shown once the server has handled the requests that drew it (a
//! round trip) and one frame of the output's mode has passed (scan-out), then the
//! display's settle time (the panel's response). The cursor is hidden on the window;
//! the screen saver is suspended (MIT-SCREEN-SAVER 1.1) and DPMS switched off for the
//! run, and both are given back when the window closes.
//!
//! The window also holds the output's video LUT (its CRTC gamma ramp) for the run:
//! see [`crate::lut`].

use std::sync::Arc;

use x11rb::connection::Connection;
use x11rb::protocol::dpms::ConnectionExt as _;
use x11rb::protocol::screensaver::ConnectionExt as _;
use x11rb::protocol::xproto::{
    AtomEnum, ChangeWindowAttributesAux, ConfigureWindowAux, ConnectionExt as _, CreateWindowAux,
    EventMask, PropMode, WindowClass,
};
use x11rb::wrapper::ConnectionExt as _;

use super::{BLACK, DisplayError, PatchDisplay};
use crate::x11::capture::PixelFormat;
use crate::x11::{GammaRamp, OutputInfo, OutputSelector, X11Error, XDisplay};
use chromacal_model::screen::{Codes, Patch};
use chromacal_model::target::CalibrationCurves;

/// Where the window goes: an X display and one of its outputs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WindowTarget {
    /// `:0`, or `$DISPLAY` when unset.
    pub x_display: Option<String>,
    pub output: OutputSelector,
}

/// The patch window.
pub struct PatchWindow {
    x: Arc<XDisplay>,
    target: WindowTarget,
    output: OutputInfo,
    format: PixelFormat,
    window: u32,
    patch: u32,
    settle_s: f64,
    /// DPMS was on before the run (switched back on at close).
    dpms_was_on: bool,
    closed: bool,
    /// Unmapped between a daemon's jobs; mapped again at the next patch.
    hidden: bool,
}

impl From<X11Error> for DisplayError {
    /// An X display that cannot be reached or an output that is not there is one the
    /// user named wrong (a mistyped output read "the display is gone"); anything else
    /// is the display going away under a run.
    fn from(e: X11Error) -> Self {
        match e {
            X11Error::Connect { .. }
            | X11Error::NoRandr { .. }
            | X11Error::NoOutput { .. }
            | X11Error::Unlit { .. }
            | X11Error::NoGamma { .. } => DisplayError::Unavailable(e.to_string()),
            X11Error::Protocol { .. } => DisplayError::Lost(e.to_string()),
        }
    }
}

impl PatchWindow {
    /// Open the window full-screen on the output `target` names, black.
    pub fn open(target: &WindowTarget, settle_s: f64) -> Result<Self, DisplayError> {
        let x = Arc::new(XDisplay::open(target.x_display.as_deref())?);
        let output = x.output(&target.output)?;
        output.lit_crtc()?;
        let format = x.pixel_format()?;
        let (window, patch) = create_windows(&x, &output)?;
        let dpms_was_on = hold_screen_saver(&x)?;
        let mut w = PatchWindow {
            x,
            target: target.clone(),
            output,
            format,
            window,
            patch,
            settle_s,
            dpms_was_on,
            closed: false,
            hidden: false,
        };
        w.draw(&BLACK)?;
        Ok(w)
    }

    /// The output the window is on.
    pub fn output(&self) -> &OutputInfo {
        &self.output
    }

    pub fn x_display(&self) -> &Arc<XDisplay> {
        &self.x
    }

    /// Bits per channel the window paints (the root visual's).
    pub fn channel_bits(&self) -> u32 {
        self.format.channel_bits()
    }

    /// The codes at the window's depth for codes at `codes.bit_depth`.
    fn window_codes(&self, codes: &Codes) -> Result<[u32; 3], DisplayError> {
        let bits = self.channel_bits();
        if codes.bit_depth > bits {
            return Err(DisplayError::Unsupported(format!(
                "the window on {} paints {bits} bits per channel, not {}: set plan.bit_depth = {bits}",
                self.output.name, codes.bit_depth
            )));
        }
        let (from, to) = (Codes::max(codes.bit_depth), Codes::max(bits));
        Ok(codes.rgb.map(|c| {
            // Exact for equal depths; a shorter code is spread over the longer range.
            ((u64::from(c.min(from)) * u64::from(to) + u64::from(from) / 2) / u64::from(from))
                as u32
        }))
    }

    /// Send the requests that put `patch` up, and wait until the server has done them.
    fn draw(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        if self.hidden {
            self.x
                .conn
                .map_window(self.window)
                .map_err(|e| DisplayError::Lost(e.to_string()))?;
            self.dpms_was_on = hold_screen_saver(&self.x)?;
            self.hidden = false;
        }
        let lost = |e: &dyn std::fmt::Display| DisplayError::Lost(format!("{}: {e}", self.name()));
        let patch_pixel = self.format.pixel(self.window_codes(&patch.codes)?);
        let background_pixel = self.format.pixel(self.window_codes(&patch.background)?);
        let (w, h) = (f64::from(self.output.width), f64::from(self.output.height));
        let g = patch.geometry;
        let px = (g.x * w).round() as i32;
        let py = (g.y * h).round() as i32;
        let pw = ((g.width * w).round() as u32).max(1);
        let ph = ((g.height * h).round() as u32).max(1);
        let conn = &self.x.conn;
        conn.change_window_attributes(
            self.window,
            &ChangeWindowAttributesAux::new().background_pixel(background_pixel),
        )
        .map_err(|e| lost(&e))?;
        conn.change_window_attributes(
            self.patch,
            &ChangeWindowAttributesAux::new().background_pixel(patch_pixel),
        )
        .map_err(|e| lost(&e))?;
        conn.configure_window(
            self.patch,
            &ConfigureWindowAux::new().x(px).y(py).width(pw).height(ph),
        )
        .map_err(|e| lost(&e))?;
        // Changing a background repaints nothing by itself: clear both to it.
        conn.clear_area(false, self.window, 0, 0, 0, 0)
            .map_err(|e| lost(&e))?;
        conn.clear_area(false, self.patch, 0, 0, 0, 0)
            .map_err(|e| lost(&e))?;
        // Keep the screen saver from starting between patches.
        let _ = conn.force_screen_saver(x11rb::protocol::xproto::ScreenSaver::RESET);
        self.x.sync()?;
        Ok(())
    }

    /// The output's gamma ramp now.
    pub fn gamma(&self) -> Result<GammaRamp, X11Error> {
        self.x.gamma(&self.output)
    }

    /// Load `ramp` into the output's CRTC.
    pub fn set_gamma(&self, ramp: &GammaRamp) -> Result<(), X11Error> {
        self.x.set_gamma(&self.output, ramp)
    }

    /// Take the window off the screen until the next patch (a daemon between jobs),
    /// and give back the screen saver and DPMS meanwhile.
    pub fn hide(&mut self) {
        if !self.hidden && !self.closed {
            let _ = self.x.conn.unmap_window(self.window);
            release_screen_saver(&self.x, self.dpms_was_on);
            self.hidden = true;
        }
    }

    /// Look the output up again (a daemon's window lives across jobs, and a monitor
    /// may have been plugged in or its mode changed meanwhile), and cover it anew.
    pub fn refresh(&mut self) -> Result<(), DisplayError> {
        let output = self.x.output(&self.target.output)?;
        output.lit_crtc()?;
        if output != self.output {
            let to_i16 = |v: i32| i16::try_from(v).map_err(|e| DisplayError::Lost(e.to_string()));
            let to_u16 =
                |v: u32| u16::try_from(v.max(1)).map_err(|e| DisplayError::Lost(e.to_string()));
            self.x
                .conn
                .configure_window(
                    self.window,
                    &ConfigureWindowAux::new()
                        .x(i32::from(to_i16(output.x)?))
                        .y(i32::from(to_i16(output.y)?))
                        .width(u32::from(to_u16(output.width)?))
                        .height(u32::from(to_u16(output.height)?)),
                )
                .map_err(|e| DisplayError::Lost(e.to_string()))?;
            self.x.sync()?;
            tracing::info!(output = %output.name, width = output.width, height = output.height, "the patch window follows its output");
            self.output = output;
        }
        Ok(())
    }

    /// Unmap and destroy the window, give back the screen saver and DPMS.
    pub fn close(&mut self) {
        if self.closed {
            return;
        }
        self.closed = true;
        let _ = self.x.conn.destroy_window(self.window);
        if !self.hidden {
            release_screen_saver(&self.x, self.dpms_was_on);
        }
        let _ = self.x.sync();
    }
}

impl Drop for PatchWindow {
    fn drop(&mut self) {
        self.close();
    }
}

/// Hold off the screen saver and switch DPMS off, where the server has them; whether
/// DPMS was on (to switch it on again).
fn hold_screen_saver(x: &XDisplay) -> Result<bool, DisplayError> {
    let lost = |e: &dyn std::fmt::Display| DisplayError::Lost(format!("{}: {e}", x.name()));
    let conn = &x.conn;
    let has = |name: &[u8]| {
        conn.query_extension(name)
            .ok()
            .and_then(|c| c.reply().ok())
            .is_some_and(|r| r.present)
    };
    if has(b"MIT-SCREEN-SAVER") {
        conn.screensaver_suspend(1).map_err(|e| lost(&e))?;
    } else {
        tracing::warn!(
            display = x.name(),
            "no MIT-SCREEN-SAVER extension: the screen saver is not held off"
        );
    }
    let mut dpms_was_on = false;
    if has(b"DPMS")
        && let Ok(info) = conn.dpms_info().map_err(|e| lost(&e))?.reply()
        && info.state
    {
        dpms_was_on = true;
        conn.dpms_disable().map_err(|e| lost(&e))?;
    }
    x.sync()?;
    Ok(dpms_was_on)
}

/// Give back what [`hold_screen_saver`] held off.
fn release_screen_saver(x: &XDisplay, dpms_was_on: bool) {
    let _ = x.conn.screensaver_suspend(0);
    if dpms_was_on {
        let _ = x.conn.dpms_enable();
    }
    let _ = x.sync();
}

/// Create the full-screen window and its patch child, map them and hide the cursor.
/// Returns the two window ids.
fn create_windows(x: &XDisplay, output: &OutputInfo) -> Result<(u32, u32), DisplayError> {
    let lost = |e: &dyn std::fmt::Display| DisplayError::Lost(format!("{}: {e}", x.name()));
    let conn = &x.conn;
    let screen = &conn.setup().roots[x.screen];
    let to_i16 = |v: i32| i16::try_from(v).map_err(|e| lost(&e));
    let to_u16 = |v: u32| u16::try_from(v.max(1)).map_err(|e| lost(&e));
    // An invisible cursor: one pixel, masked out.
    let pixmap = conn.generate_id().map_err(|e| lost(&e))?;
    conn.create_pixmap(1, pixmap, screen.root, 1, 1)
        .map_err(|e| lost(&e))?;
    let cursor = conn.generate_id().map_err(|e| lost(&e))?;
    conn.create_cursor(cursor, pixmap, pixmap, 0, 0, 0, 0, 0, 0, 0, 0)
        .map_err(|e| lost(&e))?;
    let window = conn.generate_id().map_err(|e| lost(&e))?;
    conn.create_window(
        screen.root_depth,
        window,
        screen.root,
        to_i16(output.x)?,
        to_i16(output.y)?,
        to_u16(output.width)?,
        to_u16(output.height)?,
        0,
        WindowClass::INPUT_OUTPUT,
        screen.root_visual,
        &CreateWindowAux::new()
            .background_pixel(screen.black_pixel)
            // Full-screen without a window manager's frame or placement.
            .override_redirect(1)
            .cursor(cursor)
            .event_mask(EventMask::EXPOSURE),
    )
    .map_err(|e| lost(&e))?;
    let patch = conn.generate_id().map_err(|e| lost(&e))?;
    conn.create_window(
        screen.root_depth,
        patch,
        window,
        0,
        0,
        1,
        1,
        0,
        WindowClass::INPUT_OUTPUT,
        screen.root_visual,
        &CreateWindowAux::new()
            .background_pixel(screen.black_pixel)
            .cursor(cursor),
    )
    .map_err(|e| lost(&e))?;
    let title = b"chromacal patches";
    conn.change_property8(
        PropMode::REPLACE,
        window,
        AtomEnum::WM_NAME,
        AtomEnum::STRING,
        title,
    )
    .map_err(|e| lost(&e))?;
    // Ask a compositor to leave the window's pixels alone (EWMH 1.5).
    conn.change_property32(
        PropMode::REPLACE,
        window,
        x.atom(b"_NET_WM_BYPASS_COMPOSITOR", false)?,
        AtomEnum::CARDINAL,
        &[1],
    )
    .map_err(|e| lost(&e))?;
    conn.map_window(patch).map_err(|e| lost(&e))?;
    conn.map_window(window).map_err(|e| lost(&e))?;
    conn.free_pixmap(pixmap).map_err(|e| lost(&e))?;
    x.sync()?;
    Ok((window, patch))
}

impl PatchDisplay for PatchWindow {
    fn name(&self) -> String {
        format!(
            "window on {} of X display {} ({} bits)",
            self.output.name,
            self.x.name(),
            self.channel_bits()
        )
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        self.draw(patch)?;
        // Scan-out of one frame, then the panel's response.
        tokio::time::sleep(std::time::Duration::from_secs_f64(
            self.output.frame_s() + self.settle_s,
        ))
        .await;
        Ok(())
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        self.draw(&BLACK)
    }

    fn load_curves(&mut self, curves: Option<&CalibrationCurves>) -> Result<bool, DisplayError> {
        let size = self.output.gamma_size;
        // An output without a settable ramp (XWayland, some VNC servers): the curves
        // go into the codes instead.
        if size < 2 {
            return Ok(false);
        }
        let ramp = match curves {
            Some(c) => GammaRamp::from_curves(c, size),
            None => GammaRamp::identity(size),
        };
        self.set_gamma(&ramp)?;
        Ok(true)
    }
}
