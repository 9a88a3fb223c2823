//! The patch surface on Wayland: a full-screen `xdg_toplevel` on one `wl_output`,
//! painted from `wl_shm` buffers that hold the exact codes (XRGB8888, or XRGB2101010
//! for 10 bits where the compositor offers it), so that nothing between chromacal and
//! the compositor rounds or dithers them.
//!
//! A patch counts as shown only when the compositor says the frame that carries it
//! was presented (`wp_presentation` feedback; where that protocol is missing, the
//! frame callback and one refresh more), never after a fixed sleep: a compositor busy
//! elsewhere, or a powered-down output, holds the reading back rather than letting it
//! read the previous patch. Then the display's settle time (the panel's response).
//! Idle is inhibited while the surface is up (`zwp_idle_inhibit_manager_v1`), so no
//! screen blanker or DPMS starts in a run, and on wlroots the output's gamma ramp is
//! held straight (`gamma`): the compositor puts its own back when the process lets
//! go, however the run ends.
//!
//! Colour management: where the compositor offers `wp_color_manager_v1` a surface
//! without an image description is, by that protocol, sRGB-encoded content that the
//! compositor may convert to the output's profile; chromacal says so and recommends
//! turning the output's colour management off for the run (per compositor, see
//! docs/wayland.md). Where it is missing, the codes reach the output as they are.

use std::fs::File;
use std::os::fd::AsFd as _;
use std::os::unix::fs::FileExt as _;
use std::time::{Duration, Instant};

use wayland_client::protocol::{
    wl_buffer, wl_callback, wl_compositor, wl_output, wl_shm, wl_shm_pool, wl_surface,
};
use wayland_client::{Connection, Dispatch, EventQueue, QueueHandle, WEnum};
use wayland_protocols::wp::idle_inhibit::zv1::client::{
    zwp_idle_inhibit_manager_v1, zwp_idle_inhibitor_v1,
};
use wayland_protocols::wp::presentation_time::client::{wp_presentation, wp_presentation_feedback};
use wayland_protocols::xdg::shell::client::{xdg_surface, xdg_toplevel, xdg_wm_base};
use wayland_protocols_wlr::output_power_management::v1::client::{
    zwlr_output_power_manager_v1, zwlr_output_power_v1,
};

use super::gamma::{GammaError, GammaOffer, HeldGamma, hold_gamma};
use super::{REPLY_TIMEOUT, WaylandDisplay, WaylandError, WaylandOutput};
use crate::x11::{GammaRamp, OutputSelector};
use crate::{BLACK, DisplayError, PatchDisplay};
use chromacal_model::screen::{Codes, Patch};
use chromacal_model::target::CalibrationCurves;

/// Where the surface goes: a Wayland display and one of its outputs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceTarget {
    /// `wayland-1` or a socket path; `$WAYLAND_DISPLAY` when unset.
    pub wayland_display: Option<String>,
    pub output: OutputSelector,
}

/// How long a frame may take to be presented before the compositor counts as stuck.
pub const PRESENT_TIMEOUT: Duration = Duration::from_secs(30);

/// How long the compositor is given to make the surface full-screen.
const FULLSCREEN_WAIT: Duration = Duration::from_secs(2);

/// Refreshes after the frame callback within which presentation feedback must come
/// before the surface stops waiting for it.
const FEEDBACK_GRACE_FRAMES: f64 = 6.0;

/// Frames running without feedback before the surface stops asking for it.
const FEEDBACK_MISSES: u32 = 3;

/// Most times one patch is drawn again because the compositor configured the surface
/// anew meanwhile.
const MOST_REDRAWS: usize = 5;

/// One shared-memory buffer and whether the compositor still reads it.
struct Buffer {
    buffer: wl_buffer::WlBuffer,
    file: File,
    busy: bool,
}

/// What the compositor has told the surface.
#[derive(Default)]
pub struct SurfaceEvents {
    outputs: Vec<(wl_output::WlOutput, WaylandOutput, bool)>,
    formats: Vec<wl_shm::Format>,
    /// The toplevel's size, surface coordinates (0: the client chooses).
    size: (i32, i32),
    /// Has been configured at least once.
    configured: bool,
    /// The last configure made the toplevel full-screen.
    fullscreen: bool,
    /// A configure came since the last commit: the frame must be made again.
    reconfigured: bool,
    closed: bool,
    buffers_busy: Vec<bool>,
    /// The frames presented, and those the compositor discarded, by frame number.
    presented: Vec<u64>,
    discarded: Vec<u64>,
    /// Frame callbacks done (the fallback without wp_presentation).
    callbacks_done: Vec<u64>,
    /// The output is powered off (wlr-output-power-management, where offered).
    powered_off: bool,
    /// It was off at some time since this was last cleared.
    was_off: bool,
}

/// The patch surface.
pub struct PatchSurface {
    display: WaylandDisplay,
    queue: EventQueue<SurfaceEvents>,
    events: SurfaceEvents,
    output: WaylandOutput,
    surface: wl_surface::WlSurface,
    toplevel: xdg_toplevel::XdgToplevel,
    xdg_surface: xdg_surface::XdgSurface,
    shm: wl_shm::WlShm,
    presentation: Option<wp_presentation::WpPresentation>,
    inhibitor: Option<zwp_idle_inhibitor_v1::ZwpIdleInhibitorV1>,
    /// The output's gamma ramp held straight for the run (wlroots): the compositor
    /// puts its own back when the surface's process lets go, however it ends.
    _straight: Option<HeldGamma>,
    buffers: Vec<Buffer>,
    /// Buffer size, pixels, and its format.
    pixels: (i32, i32),
    format: wl_shm::Format,
    frame: u64,
    /// The compositor offers wp_presentation but sends no feedback.
    feedback_silent: bool,
    /// Frames drawn running for which no feedback came.
    feedback_misses: u32,
    /// The 10-bit caveat was said.
    said_depth: bool,
    settle_s: f64,
    closed: bool,
}

impl From<WaylandError> for DisplayError {
    fn from(e: WaylandError) -> Self {
        match e {
            WaylandError::Protocol { .. } => DisplayError::Lost(e.to_string()),
            _ => DisplayError::Unavailable(e.to_string()),
        }
    }
}

impl PatchSurface {
    /// Open the surface full-screen on the output `target` names, black, and wait
    /// until the compositor has presented it.
    pub fn open(target: &SurfaceTarget, settle_s: f64) -> Result<Self, DisplayError> {
        let (display, mut queue) =
            WaylandDisplay::connect::<SurfaceEvents>(target.wayland_display.as_deref())?;
        let qh = queue.handle();
        let mut events = SurfaceEvents::default();
        let globals = &display.globals;
        let missing = |interface: &'static str, why: &'static str| WaylandError::Missing {
            display: display.name().to_string(),
            interface,
            why,
        };
        let compositor: wl_compositor::WlCompositor = globals
            .bind(&qh, 4..=6, ())
            .map_err(|_| missing("wl_compositor (version 4)", "every surface needs"))?;
        let shm: wl_shm::WlShm = globals
            .bind(&qh, 1..=1, ())
            .map_err(|_| missing("wl_shm", "the patch's pixels are written into"))?;
        let wm_base: xdg_wm_base::XdgWmBase = globals
            .bind(&qh, 1..=6, ())
            .map_err(|_| missing("xdg_wm_base", "a full-screen surface needs (xdg-shell)"))?;
        let presentation: Option<wp_presentation::WpPresentation> =
            globals.bind(&qh, 1..=1, ()).ok();
        let idle: Option<zwp_idle_inhibit_manager_v1::ZwpIdleInhibitManagerV1> =
            globals.bind(&qh, 1..=1, ()).ok();
        let power: Option<zwlr_output_power_manager_v1::ZwlrOutputPowerManagerV1> =
            globals.bind(&qh, 1..=1, ()).ok();
        events.outputs = super::bind_outputs(&display, &qh);
        for _ in 0..2 {
            queue
                .roundtrip(&mut events)
                .map_err(|e| display.protocol_error(format!("reading its outputs: {e}")))?;
        }
        let (index, output) = super::choose(
            &display,
            &target.output,
            &super::described(&events.outputs, &crate::drm::sysfs_root()),
        )?;
        let output_proxy = events.outputs[index].0.clone();
        // Whether the output is powered: a frame drawn while it is off is not seen.
        let _power = power.map(|m| m.get_output_power(&output_proxy, &qh, ()));
        if display.offers("wp_color_manager_v1") {
            tracing::warn!(
                output = %output.name,
                "the compositor manages colour (wp_color_manager_v1): it may convert the patches' codes through the output's profile; turn the output's colour management (ICC profile, HDR, night light) off for the run"
            );
        }
        let straight = straight_ramp(target, &output);
        let surface = compositor.create_surface(&qh, ());
        let xdg_surface = wm_base.get_xdg_surface(&surface, &qh, ());
        let toplevel = xdg_surface.get_toplevel(&qh, ());
        toplevel.set_title("chromacal patches".into());
        toplevel.set_app_id("chromacal".into());
        toplevel.set_fullscreen(Some(&output_proxy));
        let inhibitor = idle.map(|m| m.create_inhibitor(&surface, &qh, ()));
        surface.set_buffer_scale(output.scale.max(1));
        surface.commit();
        let mut s = PatchSurface {
            display,
            queue,
            events,
            output,
            surface,
            toplevel,
            xdg_surface,
            shm,
            presentation,
            inhibitor,
            _straight: straight,
            buffers: Vec::new(),
            pixels: (0, 0),
            format: wl_shm::Format::Xrgb8888,
            frame: 0,
            feedback_silent: false,
            feedback_misses: 0,
            said_depth: false,
            settle_s,
            closed: false,
        };
        s.wait("the first configure", |e| e.configured)?;
        // A compositor that makes the surface full-screen says so in a configure of
        // its own; one that will not is given a moment, then the surface is used as
        // it is (with a warning: its patches may not cover the output).
        if !s.wait_for("making the surface full-screen", FULLSCREEN_WAIT, |e| {
            e.fullscreen
        })? {
            tracing::warn!(output = %s.output.name, "the compositor did not make the patch surface full-screen");
        }
        s.draw(&BLACK)?;
        Ok(s)
    }

    /// The output the surface is on.
    pub fn output(&self) -> &WaylandOutput {
        &self.output
    }

    /// Most bits per channel the surface's buffers can hold: 10 where the compositor
    /// offers XRGB2101010 buffers, else 8.
    pub fn channel_bits(&self) -> u32 {
        if self.events.formats.contains(&wl_shm::Format::Xrgb2101010) {
            10
        } else {
            8
        }
    }

    /// The buffer format for codes of `bits`: XRGB8888 up to 8 bits (the codes as
    /// they are, whatever the output's own depth), XRGB2101010 above.
    fn format_for(&self, bits: u32) -> wl_shm::Format {
        if bits <= 8 {
            wl_shm::Format::Xrgb8888
        } else {
            wl_shm::Format::Xrgb2101010
        }
    }

    /// Dispatch events until `done` says so, or fail after the timeout naming `what`.
    fn wait(
        &mut self,
        what: &str,
        done: impl Fn(&SurfaceEvents) -> bool,
    ) -> Result<(), DisplayError> {
        let timeout = REPLY_TIMEOUT.max(PRESENT_TIMEOUT);
        if self.wait_for(what, timeout, done)? {
            Ok(())
        } else {
            Err(self.timed_out(what, timeout))
        }
    }

    /// Dispatch events until `done` says so (`Ok(true)`) or `timeout` passes
    /// (`Ok(false)`); the compositor closing the surface or the connection failing is
    /// an error.
    fn wait_for(
        &mut self,
        what: &str,
        timeout: Duration,
        done: impl Fn(&SurfaceEvents) -> bool,
    ) -> Result<bool, DisplayError> {
        let deadline = Instant::now() + timeout;
        let finished = super::dispatch_until(&mut self.queue, &mut self.events, deadline, |e| {
            e.closed || done(e)
        })
        .map_err(|e| self.lost(format!("{what}: {e}")))?;
        if self.events.closed {
            return Err(self.lost("the compositor closed the patch surface"));
        }
        Ok(finished)
    }

    fn timed_out(&self, what: &str, timeout: Duration) -> DisplayError {
        self.lost(format!(
            "{what}: the compositor did not answer within {} s (is the output {} on and not locked?)",
            timeout.as_secs(),
            self.output.name
        ))
    }

    fn lost(&self, what: impl std::fmt::Display) -> DisplayError {
        DisplayError::Lost(format!("{}: {what}", self.name()))
    }

    /// The codes at the buffer format's depth for codes at `codes.bit_depth`.
    fn surface_codes(&self, codes: &Codes) -> Result<[u32; 3], DisplayError> {
        let bits = match self.format {
            wl_shm::Format::Xrgb2101010 => 10,
            _ => 8,
        };
        if codes.bit_depth > self.channel_bits() {
            return Err(DisplayError::Unsupported(format!(
                "the surface on {} holds 8 bits per channel (the compositor offers no XRGB2101010 buffers), not {}: set plan.bit_depth = 8",
                self.output.name, codes.bit_depth
            )));
        }
        let (from, to) = (Codes::max(codes.bit_depth), Codes::max(bits));
        Ok(codes.rgb.map(|c| {
            ((u64::from(c.min(from)) * u64::from(to) + u64::from(from) / 2) / u64::from(from))
                as u32
        }))
    }

    /// The buffer size the configured surface needs, pixels.
    fn wanted_pixels(&self) -> (i32, i32) {
        let scale = self.output.scale.max(1);
        let (w, h) = match self.events.size {
            (w, h) if w > 0 && h > 0 => (w, h),
            _ => (self.output.width / scale, self.output.height / scale),
        };
        (w.max(1) * scale, h.max(1) * scale)
    }

    /// A buffer the compositor is not reading, of the wanted size (new ones when the
    /// size changed).
    fn free_buffer(&mut self, format: wl_shm::Format) -> Result<usize, DisplayError> {
        let wanted = self.wanted_pixels();
        if wanted != self.pixels || format != self.format {
            self.format = format;
            for b in self.buffers.drain(..) {
                b.buffer.destroy();
            }
            self.events.buffers_busy.clear();
            self.pixels = wanted;
        }
        if self.buffers.len() < 2 {
            let index = self.buffers.len();
            let buffer = self.create_buffer(index)?;
            self.buffers.push(buffer);
            self.events.buffers_busy.push(false);
            return Ok(index);
        }
        self.wait("a buffer the compositor has let go", |e| {
            e.buffers_busy.iter().any(|b| !b)
        })?;
        for (b, busy) in self.buffers.iter_mut().zip(&self.events.buffers_busy) {
            b.busy = *busy;
        }
        self.buffers
            .iter()
            .position(|b| !b.busy)
            .ok_or_else(|| self.lost("no free buffer"))
    }

    fn create_buffer(&self, index: usize) -> Result<Buffer, DisplayError> {
        let (w, h) = self.pixels;
        let stride = w * 4;
        let bytes = u64::try_from(stride)
            .ok()
            .zip(u64::try_from(h).ok())
            .map(|(s, h)| s * h)
            .ok_or_else(|| self.lost("a buffer of negative size"))?;
        let fd = rustix::fs::memfd_create("chromacal-patch", rustix::fs::MemfdFlags::CLOEXEC)
            .map_err(|e| self.lost(format!("memfd_create: {e}")))?;
        let file = File::from(fd);
        file.set_len(bytes)
            .map_err(|e| self.lost(format!("sizing a buffer of {bytes} bytes: {e}")))?;
        let qh = self.queue.handle();
        let size = i32::try_from(bytes).map_err(|_| self.lost("a buffer over 2 GiB"))?;
        let pool = self.shm.create_pool(file.as_fd(), size, &qh, ());
        let buffer = pool.create_buffer(0, w, h, stride, self.format, &qh, index);
        pool.destroy();
        Ok(Buffer {
            buffer,
            file,
            busy: false,
        })
    }

    /// Paint `patch` into a free buffer, commit it with a presentation feedback, and
    /// wait until the compositor says it was presented; drawn again (at the new size)
    /// when the compositor configures the surface anew before presenting it.
    fn draw(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        for _ in 0..MOST_REDRAWS {
            if self.paint_and_present(patch)? {
                return Ok(());
            }
        }
        Err(self.lost(format!(
            "the compositor configured the surface anew {MOST_REDRAWS} times without presenting it"
        )))
    }

    /// One attempt of [`Self::draw`]: `false` when a configure came first.
    fn paint_and_present(&mut self, patch: &Patch) -> Result<bool, DisplayError> {
        // A configure that comes while a free buffer is awaited may change the size:
        // then the frame is painted again at it.
        self.events.reconfigured = false;
        let bits = patch.codes.bit_depth.max(patch.background.bit_depth);
        let index = self.free_buffer(self.format_for(bits))?;
        if self.events.reconfigured {
            return Ok(false);
        }
        if bits > 8 && !self.said_depth {
            self.said_depth = true;
            tracing::warn!(output = %self.output.name, "the patches are 10-bit buffers (XRGB2101010); whether the compositor composites and scans them out at 10 bits is its setting (sway: output NAME render_bit_depth 10)");
        }
        let (w, h) = self.pixels;
        let patch_pixel = shm_pixel(self.format, self.surface_codes(&patch.codes)?);
        let background = shm_pixel(self.format, self.surface_codes(&patch.background)?);
        let g = patch.geometry;
        let (wf, hf) = (f64::from(w), f64::from(h));
        // The patch's rectangle from its top left, as the X11 window places it.
        let x0 = (g.x * wf).round().clamp(0.0, wf) as usize;
        let y0 = (g.y * hf).round().clamp(0.0, hf) as usize;
        let x1 = (x0 + ((g.width * wf).round() as usize).max(1)).min(w as usize);
        let y1 = (y0 + ((g.height * hf).round() as usize).max(1)).min(h as usize);
        let (w, h) = (w as usize, h as usize);
        let mut row_background = Vec::with_capacity(w * 4);
        let mut row_patch = Vec::with_capacity(w * 4);
        for x in 0..w {
            row_background.extend_from_slice(&background);
            row_patch.extend_from_slice(if (x0..x1).contains(&x) {
                &patch_pixel
            } else {
                &background
            });
        }
        let mut image = Vec::with_capacity(w * h * 4);
        for y in 0..h {
            image.extend_from_slice(if (y0..y1).contains(&y) {
                &row_patch
            } else {
                &row_background
            });
        }
        self.buffers[index]
            .file
            .write_all_at(&image, 0)
            .map_err(|e| self.lost(format!("writing the patch's pixels: {e}")))?;
        self.present(index)
    }

    /// Attach buffer `index`, commit, and wait for the compositor to present it; a
    /// frame it discards (superseded, or the output was off) is committed again.
    /// `false` when the compositor configured the surface anew first.
    ///
    /// Each commit asks for presentation feedback (where offered) and a frame
    /// callback. The feedback decides; the callback (sent once the compositor has
    /// drawn the frame that carries the patch) plus one refresh stands in where the
    /// protocol is missing, or where a compositor offers it and then sends nothing
    /// (sway 1.7 on its headless backend): a few refreshes after the callback
    /// without feedback, the surface stops waiting for feedback, and says so once.
    fn present(&mut self, index: usize) -> Result<bool, DisplayError> {
        // One deadline for the patch, however often the compositor discards it.
        let deadline = Instant::now() + PRESENT_TIMEOUT;
        let what = "presenting the patch";
        loop {
            self.frame += 1;
            let frame = self.frame;
            let qh = self.queue.handle();
            self.buffers[index].busy = true;
            self.events.buffers_busy[index] = true;
            self.surface.attach(Some(&self.buffers[index].buffer), 0, 0);
            self.surface.damage_buffer(0, 0, i32::MAX, i32::MAX);
            let feedback = self.presentation.as_ref().filter(|_| !self.feedback_silent);
            if let Some(p) = feedback {
                p.feedback(&self.surface, &qh, frame);
            }
            self.surface.frame(&qh, frame);
            self.surface.commit();
            let heard = |e: &SurfaceEvents| {
                e.presented.contains(&frame) || e.discarded.contains(&frame) || e.reconfigured
            };
            let left = deadline.saturating_duration_since(Instant::now());
            if feedback.is_some() {
                if !self.wait_for(what, left, |e| {
                    heard(e) || e.callbacks_done.contains(&frame)
                })? {
                    return Err(self.timed_out(what, PRESENT_TIMEOUT));
                }
                if !heard(&self.events) {
                    // Drawn: the feedback follows within a refresh or two. A compositor
                    // that misses it several frames running sends none at all.
                    let grace =
                        Duration::from_secs_f64(FEEDBACK_GRACE_FRAMES * self.output.frame_s());
                    if self.wait_for(what, grace, heard)? {
                        self.feedback_misses = 0;
                    } else {
                        self.feedback_misses += 1;
                        if self.feedback_misses >= FEEDBACK_MISSES {
                            tracing::warn!(output = %self.output.name, "the compositor offers wp_presentation but sent no feedback for {FEEDBACK_MISSES} frames running: a patch counts as shown a refresh after the compositor has drawn it");
                            self.feedback_silent = true;
                        }
                    }
                }
            } else if !self.wait_for(what, left, |e| {
                e.callbacks_done.contains(&frame) || e.reconfigured
            })? {
                return Err(self.timed_out(what, PRESENT_TIMEOUT));
            }
            // A frame drawn while the output was off (DPMS) was seen by no one: once
            // the output is on again, it is committed anew.
            if self.events.powered_off || self.events.was_off {
                let left = deadline.saturating_duration_since(Instant::now());
                if !self.wait_for("waiting for the output to be powered on", left, |e| {
                    !e.powered_off
                })? {
                    return Err(self.timed_out(what, PRESENT_TIMEOUT));
                }
                self.events.was_off = false;
                continue;
            }
            let presented = self.events.presented.contains(&frame);
            let discarded = self.events.discarded.contains(&frame);
            self.events.presented.retain(|f| *f > frame);
            self.events.discarded.retain(|f| *f > frame);
            self.events.callbacks_done.retain(|f| *f > frame);
            if presented {
                return Ok(true);
            }
            if self.events.reconfigured {
                return Ok(false);
            }
            if discarded {
                tracing::debug!(
                    frame,
                    "the compositor discarded the frame; committing it again"
                );
                continue;
            }
            // Drawn, with no feedback to wait for: scanned out a refresh later.
            std::thread::sleep(Duration::from_secs_f64(self.output.frame_s()));
            return Ok(true);
        }
    }

    /// Take the surface down, give back idle.
    pub fn close(&mut self) {
        if self.closed {
            return;
        }
        self.closed = true;
        if let Some(i) = self.inhibitor.take() {
            i.destroy();
        }
        self.toplevel.destroy();
        self.xdg_surface.destroy();
        self.surface.destroy();
        for b in self.buffers.drain(..) {
            b.buffer.destroy();
        }
        let _ = self.queue.roundtrip(&mut self.events);
    }
}

impl Drop for PatchSurface {
    fn drop(&mut self) {
        self.close();
    }
}

/// Characterisation measures the panel with nothing between the codes and it: on a
/// wlroots compositor the output's gamma ramp is taken and held straight for the run
/// (the compositor restores its own when the process lets go, on every exit path).
/// Where it cannot be taken, or the compositor applies a profile itself, the run is
/// told what to turn off.
fn straight_ramp(target: &SurfaceTarget, output: &WaylandOutput) -> Option<HeldGamma> {
    let selector = OutputSelector::Name(output.name.clone());
    match hold_gamma(
        target.wayland_display.as_deref(),
        &selector,
        GammaRamp::identity,
    ) {
        Ok(held) => Some(held),
        Err(GammaError::NoRamp {
            offer: GammaOffer::NotOffered,
            ..
        }) => {
            tracing::warn!(output = %output.name, "the compositor applies the output's colour profile itself (KDE, GNOME): set the output's profile to none (sRGB) for the characterisation (chromacal lut reset), or the patches are measured through its curves");
            None
        }
        Err(e) => {
            tracing::warn!(output = %output.name, "the gamma ramp could not be held straight ({e}): if another program holds it (a night-light tool, or chromacal lut load --hold: stop it with chromacal lut reset), the patches are measured through its curves");
            None
        }
    }
}

/// Run `work`, which waits on the compositor, without holding up the other tasks of
/// a multi-threaded runtime (the daemon's): there it moves the worker's other tasks
/// elsewhere first. A single-threaded runtime (a command's) has nothing else to run.
fn blocking<T>(work: impl FnOnce() -> T) -> T {
    match tokio::runtime::Handle::try_current().map(|h| h.runtime_flavor()) {
        Ok(tokio::runtime::RuntimeFlavor::MultiThread) => tokio::task::block_in_place(work),
        _ => work(),
    }
}

/// One pixel's bytes in `format` (little-endian, as wl_shm formats are): codes at 8
/// bits for XRGB8888, at 10 for XRGB2101010.
fn shm_pixel(format: wl_shm::Format, rgb: [u32; 3]) -> [u8; 4] {
    let value = match format {
        wl_shm::Format::Xrgb2101010 => (rgb[0] << 20) | (rgb[1] << 10) | rgb[2],
        _ => (rgb[0] << 16) | (rgb[1] << 8) | rgb[2],
    };
    value.to_le_bytes()
}

impl PatchDisplay for PatchSurface {
    fn name(&self) -> String {
        format!(
            "Wayland surface on {} of {} ({} bits)",
            self.output.name,
            self.display.name(),
            self.channel_bits()
        )
    }

    async fn show(&mut self, patch: &Patch) -> Result<(), DisplayError> {
        blocking(|| self.draw(patch))?;
        tokio::time::sleep(Duration::from_secs_f64(self.settle_s)).await;
        Ok(())
    }

    async fn blank(&mut self) -> Result<(), DisplayError> {
        // Black at the depth shown last, so that the buffers are not made anew.
        let bit_depth = match self.format {
            wl_shm::Format::Xrgb2101010 => 10,
            _ => 8,
        };
        let black = Codes {
            rgb: [0; 3],
            bit_depth,
        };
        blocking(|| {
            self.draw(&Patch {
                codes: black,
                background: black,
                ..BLACK
            })
        })
    }

    fn load_curves(&mut self, _curves: Option<&CalibrationCurves>) -> Result<bool, DisplayError> {
        // The run holds the output's ramp straight where it can (wlroots), and the
        // compositor owns it elsewhere: the curves go into the codes (`lut load`
        // puts them where the compositor applies them, after the run).
        Ok(false)
    }
}

super::dispatch_outputs!(SurfaceEvents);

impl Dispatch<wl_shm::WlShm, ()> for SurfaceEvents {
    fn event(
        state: &mut Self,
        _: &wl_shm::WlShm,
        event: wl_shm::Event,
        _: &(),
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        if let wl_shm::Event::Format {
            format: WEnum::Value(f),
        } = event
        {
            state.formats.push(f);
        }
    }
}

impl Dispatch<wl_buffer::WlBuffer, usize> for SurfaceEvents {
    fn event(
        state: &mut Self,
        _: &wl_buffer::WlBuffer,
        event: wl_buffer::Event,
        index: &usize,
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        if let (wl_buffer::Event::Release, Some(busy)) = (event, state.buffers_busy.get_mut(*index))
        {
            *busy = false;
        }
    }
}

impl Dispatch<xdg_wm_base::XdgWmBase, ()> for SurfaceEvents {
    fn event(
        _: &mut Self,
        base: &xdg_wm_base::XdgWmBase,
        event: xdg_wm_base::Event,
        _: &(),
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        if let xdg_wm_base::Event::Ping { serial } = event {
            base.pong(serial);
        }
    }
}

impl Dispatch<xdg_surface::XdgSurface, ()> for SurfaceEvents {
    fn event(
        state: &mut Self,
        surface: &xdg_surface::XdgSurface,
        event: xdg_surface::Event,
        _: &(),
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        // Acknowledged at once: the next commit answers it, and a commit made before
        // the frame was painted anew at the configured size is drawn again
        // (`reconfigured`).
        if let xdg_surface::Event::Configure { serial } = event {
            surface.ack_configure(serial);
            state.configured = true;
            state.reconfigured = true;
        }
    }
}

impl Dispatch<xdg_toplevel::XdgToplevel, ()> for SurfaceEvents {
    fn event(
        state: &mut Self,
        _: &xdg_toplevel::XdgToplevel,
        event: xdg_toplevel::Event,
        _: &(),
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        match event {
            xdg_toplevel::Event::Configure {
                width,
                height,
                states,
            } => {
                state.size = (width, height);
                // The states are a wl_array of u32 (xdg_toplevel.state: 2 is fullscreen).
                state.fullscreen = states
                    .chunks_exact(4)
                    .any(|c| u32::from_ne_bytes([c[0], c[1], c[2], c[3]]) == 2);
            }
            xdg_toplevel::Event::Close => state.closed = true,
            _ => {}
        }
    }
}

impl Dispatch<wp_presentation_feedback::WpPresentationFeedback, u64> for SurfaceEvents {
    fn event(
        state: &mut Self,
        _: &wp_presentation_feedback::WpPresentationFeedback,
        event: wp_presentation_feedback::Event,
        frame: &u64,
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        match event {
            wp_presentation_feedback::Event::Presented { .. } => state.presented.push(*frame),
            wp_presentation_feedback::Event::Discarded => state.discarded.push(*frame),
            _ => {}
        }
    }
}

impl Dispatch<wl_callback::WlCallback, u64> for SurfaceEvents {
    fn event(
        state: &mut Self,
        _: &wl_callback::WlCallback,
        event: wl_callback::Event,
        frame: &u64,
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        if let wl_callback::Event::Done { .. } = event {
            state.callbacks_done.push(*frame);
        }
    }
}

impl Dispatch<zwlr_output_power_v1::ZwlrOutputPowerV1, ()> for SurfaceEvents {
    fn event(
        state: &mut Self,
        _: &zwlr_output_power_v1::ZwlrOutputPowerV1,
        event: zwlr_output_power_v1::Event,
        _: &(),
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        if let zwlr_output_power_v1::Event::Mode {
            mode: WEnum::Value(mode),
        } = event
        {
            state.powered_off = mode == zwlr_output_power_v1::Mode::Off;
            state.was_off |= state.powered_off;
        }
    }
}

wayland_client::delegate_noop!(SurfaceEvents: ignore zwlr_output_power_manager_v1::ZwlrOutputPowerManagerV1);
wayland_client::delegate_noop!(SurfaceEvents: ignore wl_compositor::WlCompositor);
wayland_client::delegate_noop!(SurfaceEvents: ignore wl_surface::WlSurface);
wayland_client::delegate_noop!(SurfaceEvents: ignore wl_shm_pool::WlShmPool);
wayland_client::delegate_noop!(SurfaceEvents: ignore wp_presentation::WpPresentation);
wayland_client::delegate_noop!(SurfaceEvents: ignore zwp_idle_inhibit_manager_v1::ZwpIdleInhibitManagerV1);
wayland_client::delegate_noop!(SurfaceEvents: ignore zwp_idle_inhibitor_v1::ZwpIdleInhibitorV1);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_bit_pixels_pack_as_xrgb2101010_and_eight_bit_as_xrgb8888() {
        assert_eq!(shm_pixel(wl_shm::Format::Xrgb8888, [1, 2, 3]), [3, 2, 1, 0]);
        assert_eq!(
            u32::from_le_bytes(shm_pixel(wl_shm::Format::Xrgb2101010, [1023, 0, 1])),
            (1023 << 20) | 1
        );
    }
}
