//! What a Wayland output shows, read back through `wlr-screencopy-unstable-v1`
//! (wlroots compositors: sway, Hyprland, river; what `grim` uses): the screen an
//! emulated instrument looks at (`chromacal emulate --wayland-display`), as
//! `x11::capture` reads an X screen.
//!
//! Screencopy copies the composited frame before the output's gamma ramp, and the
//! gamma control protocol gives no way to read a ramp back: the monitor behind a
//! Wayland output is sent the pixels as they are (a calibration characterises with
//! the ramp straight, and puts its curves into the codes).

use std::fs::File;
use std::os::fd::AsFd as _;
use std::os::unix::fs::FileExt as _;
use std::time::{Duration, Instant};

use wayland_client::protocol::{wl_buffer, wl_output, wl_shm, wl_shm_pool};
use wayland_client::{Connection, Dispatch, EventQueue, Proxy as _, QueueHandle, WEnum};
use wayland_protocols_wlr::screencopy::v1::client::{
    zwlr_screencopy_frame_v1, zwlr_screencopy_manager_v1,
};

use super::{WaylandDisplay, WaylandError, WaylandOutput};
use crate::x11::capture::Sample;
use crate::x11::{GammaRamp, OutputSelector};
use chromacal_model::screen::ScreenContent;

/// How long one copy may take.
const COPY_TIMEOUT: Duration = Duration::from_secs(10);

/// The buffer a frame asks for.
#[derive(Debug, Clone, Copy)]
struct BufferSpec {
    format: wl_shm::Format,
    width: u32,
    height: u32,
    stride: u32,
}

impl BufferSpec {
    /// Pixels to copy, rows that hold them, and a size a shared-memory pool takes.
    fn is_sound(&self) -> bool {
        self.width > 0
            && self.height > 0
            && u64::from(self.stride) >= u64::from(self.width) * 4
            && u64::from(self.stride) * u64::from(self.height) <= i32::MAX as u64
    }
}

#[derive(Default)]
struct CopyEvents {
    outputs: Vec<(wl_output::WlOutput, WaylandOutput, bool)>,
    /// The shm buffer offered for the frame in flight (one chromacal can read).
    spec: Option<BufferSpec>,
    /// Every shm format offered for it.
    offered: Vec<WEnum<wl_shm::Format>>,
    /// All buffer types announced (version 3's buffer_done, or at once before it).
    specs_done: bool,
    y_invert: bool,
    ready: bool,
    failed: bool,
}

/// A connection that copies one output's frames.
pub struct OutputCopier {
    display: WaylandDisplay,
    queue: EventQueue<CopyEvents>,
    events: CopyEvents,
    manager: zwlr_screencopy_manager_v1::ZwlrScreencopyManagerV1,
    shm: wl_shm::WlShm,
    output: wl_output::WlOutput,
    pub info: WaylandOutput,
}

/// One copied frame: rows of pixels, top first, each a `u32` in `format`.
pub struct Frame {
    pub width: u32,
    pub height: u32,
    format: wl_shm::Format,
    pixels: Vec<u32>,
}

impl Frame {
    fn pixel(&self, x: u32, y: u32) -> u32 {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Bits per channel of the frame's format.
    pub fn channel_bits(&self) -> u32 {
        match self.format {
            wl_shm::Format::Xrgb2101010
            | wl_shm::Format::Argb2101010
            | wl_shm::Format::Xbgr2101010
            | wl_shm::Format::Abgr2101010 => 10,
            _ => 8,
        }
    }

    /// A pixel's red, green and blue codes.
    pub fn codes(&self, pixel: u32) -> [u32; 3] {
        let (bits, rgb_order) = match self.format {
            wl_shm::Format::Xrgb2101010 | wl_shm::Format::Argb2101010 => (10, true),
            wl_shm::Format::Xbgr2101010 | wl_shm::Format::Abgr2101010 => (10, false),
            wl_shm::Format::Xbgr8888 | wl_shm::Format::Abgr8888 => (8, false),
            _ => (8, true),
        };
        let mask = (1u32 << bits) - 1;
        let [high, mid, low] = [2 * bits, bits, 0].map(|shift| (pixel >> shift) & mask);
        if rgb_order {
            [high, mid, low]
        } else {
            [low, mid, high]
        }
    }

    /// The codes at pixel (x, y).
    pub fn codes_at(&self, x: u32, y: u32) -> [u32; 3] {
        self.codes(self.pixel(x, y))
    }

    /// What the frame shows under `aim` (fractions of its width and height).
    pub fn sample(&self, aim: (f64, f64)) -> Sample {
        let (w, h) = (self.width.max(1), self.height.max(1));
        let ax = ((aim.0.clamp(0.0, 1.0) * f64::from(w)) as u32).min(w - 1);
        let ay = ((aim.1.clamp(0.0, 1.0) * f64::from(h)) as u32).min(h - 1);
        let row: Vec<u32> = (0..w).map(|x| self.pixel(x, ay)).collect();
        let column: Vec<u32> = (0..h).map(|y| self.pixel(ax, y)).collect();
        Sample::of_lines(
            &row,
            &column,
            (ax, ay),
            |p| self.codes(p),
            self.channel_bits(),
        )
    }
}

impl OutputCopier {
    /// Connect to Wayland display `name` and find the output `selector` names.
    pub fn open(name: Option<&str>, selector: &OutputSelector) -> Result<Self, WaylandError> {
        let (display, mut queue) = WaylandDisplay::connect::<CopyEvents>(name)?;
        let qh = queue.handle();
        let mut events = CopyEvents::default();
        let missing = |interface: &'static str, why: &'static str| WaylandError::Missing {
            display: display.name().to_string(),
            interface,
            why,
        };
        let manager: zwlr_screencopy_manager_v1::ZwlrScreencopyManagerV1 =
            display.globals.bind(&qh, 1..=3, ()).map_err(|_| {
                missing(
                    "zwlr_screencopy_manager_v1",
                    "reading the screen needs (wlroots compositors have it; GNOME and KDE do not)",
                )
            })?;
        let shm: wl_shm::WlShm = display
            .globals
            .bind(&qh, 1..=1, ())
            .map_err(|_| missing("wl_shm", "a copy of the screen is written into"))?;
        events.outputs = super::bind_outputs(&display, &qh);
        for _ in 0..2 {
            queue
                .roundtrip(&mut events)
                .map_err(|e| display.protocol_error(format!("reading its outputs: {e}")))?;
        }
        let (index, info) = super::choose(
            &display,
            selector,
            &super::described(&events.outputs, &crate::drm::sysfs_root()),
        )?;
        let output = events.outputs[index].0.clone();
        Ok(OutputCopier {
            display,
            queue,
            events,
            manager,
            shm,
            output,
            info,
        })
    }

    fn dispatch_until(
        &mut self,
        what: &str,
        done: impl Fn(&CopyEvents) -> bool,
    ) -> Result<(), WaylandError> {
        let deadline = Instant::now() + COPY_TIMEOUT;
        match super::dispatch_until(&mut self.queue, &mut self.events, deadline, done) {
            Ok(true) => Ok(()),
            Ok(false) => Err(self.display.protocol_error(format!(
                "{what}: no answer within {} s",
                COPY_TIMEOUT.as_secs()
            ))),
            Err(e) => Err(self.display.protocol_error(format!("{what}: {e}"))),
        }
    }

    /// Copy the output's next frame.
    pub fn copy(&mut self) -> Result<Frame, WaylandError> {
        let qh = self.queue.handle();
        self.events.spec = None;
        self.events.offered.clear();
        self.events.specs_done = false;
        self.events.ready = false;
        self.events.failed = false;
        self.events.y_invert = false;
        let version = self.manager.version();
        let frame = self.manager.capture_output(0, &self.output, &qh, ());
        // Version 3 says when it has offered every buffer type; before it, the shm
        // buffer is the one offer.
        self.dispatch_until("waiting for the copy's buffer", |e| {
            e.failed || e.specs_done || (version < 3 && !e.offered.is_empty())
        })?;
        let spec = match (self.events.failed, self.events.spec) {
            (false, Some(spec)) if spec.is_sound() => spec,
            (false, Some(spec)) => {
                frame.destroy();
                return Err(self.display.protocol_error(format!(
                    "the compositor offered a copy of {}×{} pixels with {} bytes a row",
                    spec.width, spec.height, spec.stride
                )));
            }
            (false, None) => {
                frame.destroy();
                return Err(self.display.protocol_error(format!(
                    "the compositor offered the copy only in formats chromacal does not read: {:?}",
                    self.events.offered
                )));
            }
            (true, _) => {
                frame.destroy();
                return Err(self
                    .display
                    .protocol_error("the compositor could not copy the output"));
            }
        };
        let bytes = u64::from(spec.stride) * u64::from(spec.height);
        let fd = rustix::fs::memfd_create("chromacal-copy", rustix::fs::MemfdFlags::CLOEXEC)
            .map_err(|e| self.display.protocol_error(format!("memfd_create: {e}")))?;
        let file = File::from(fd);
        file.set_len(bytes)
            .map_err(|e| self.display.protocol_error(e.to_string()))?;
        let size =
            i32::try_from(bytes).map_err(|_| self.display.protocol_error("a frame over 2 GiB"))?;
        let to_i32 = |v: u32| i32::try_from(v).unwrap_or(i32::MAX);
        let pool = self.shm.create_pool(file.as_fd(), size, &qh, ());
        let buffer = pool.create_buffer(
            0,
            to_i32(spec.width),
            to_i32(spec.height),
            to_i32(spec.stride),
            spec.format,
            &qh,
            (),
        );
        pool.destroy();
        frame.copy(&buffer);
        let copied = self.dispatch_until("copying the output", |e| e.ready || e.failed);
        frame.destroy();
        buffer.destroy();
        copied?;
        if self.events.failed {
            return Err(self.display.protocol_error("the copy of the output failed"));
        }
        let mut data = vec![0u8; bytes as usize];
        file.read_exact_at(&mut data, 0).map_err(|e| {
            self.display
                .protocol_error(format!("reading the copy: {e}"))
        })?;
        let (w, h) = (spec.width as usize, spec.height as usize);
        let mut pixels = Vec::with_capacity(w * h);
        for row in 0..h {
            let source = if self.events.y_invert {
                h - 1 - row
            } else {
                row
            };
            let start = source * spec.stride as usize;
            pixels.extend(
                data[start..start + w * 4]
                    .chunks_exact(4)
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            );
        }
        Ok(Frame {
            width: spec.width,
            height: spec.height,
            format: spec.format,
            pixels,
        })
    }
}

/// What a monitor on `output` of Wayland display `name` is sent now, read under `aim`
/// each time it is called: the screen an emulated instrument looks at.
pub fn watch_wayland_output(
    name: Option<&str>,
    output: &OutputSelector,
    aim: (f64, f64),
) -> Result<impl FnMut() -> Result<ScreenContent, WaylandError> + Send + use<>, WaylandError> {
    let mut copier = OutputCopier::open(name, output)?;
    Ok(move || {
        let frame = copier.copy()?;
        let sample = frame.sample(aim);
        let ramp = GammaRamp::identity(256);
        Ok(sample.content_on(&ramp, frame.width, frame.height))
    })
}

super::dispatch_outputs!(CopyEvents);

/// The shm formats a copy can be decoded from.
fn decodable(format: wl_shm::Format) -> bool {
    matches!(
        format,
        wl_shm::Format::Xrgb8888
            | wl_shm::Format::Argb8888
            | wl_shm::Format::Xbgr8888
            | wl_shm::Format::Abgr8888
            | wl_shm::Format::Xrgb2101010
            | wl_shm::Format::Argb2101010
            | wl_shm::Format::Xbgr2101010
            | wl_shm::Format::Abgr2101010
    )
}

impl Dispatch<zwlr_screencopy_frame_v1::ZwlrScreencopyFrameV1, ()> for CopyEvents {
    fn event(
        state: &mut Self,
        _: &zwlr_screencopy_frame_v1::ZwlrScreencopyFrameV1,
        event: zwlr_screencopy_frame_v1::Event,
        _: &(),
        _: &Connection,
        _: &QueueHandle<Self>,
    ) {
        use zwlr_screencopy_frame_v1::Event;
        match event {
            Event::Buffer {
                format,
                width,
                height,
                stride,
            } => {
                state.offered.push(format);
                if let WEnum::Value(format) = format
                    && decodable(format)
                {
                    state.spec = Some(BufferSpec {
                        format,
                        width,
                        height,
                        stride,
                    });
                }
            }
            Event::BufferDone => state.specs_done = true,
            Event::Flags {
                flags: WEnum::Value(flags),
            } => state.y_invert = flags.contains(zwlr_screencopy_frame_v1::Flags::YInvert),
            Event::Ready { .. } => state.ready = true,
            Event::Failed => state.failed = true,
            _ => {}
        }
    }
}

wayland_client::delegate_noop!(CopyEvents: ignore zwlr_screencopy_manager_v1::ZwlrScreencopyManagerV1);
wayland_client::delegate_noop!(CopyEvents: ignore wl_shm::WlShm);
wayland_client::delegate_noop!(CopyEvents: ignore wl_shm_pool::WlShmPool);
wayland_client::delegate_noop!(CopyEvents: ignore wl_buffer::WlBuffer);

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(format: wl_shm::Format, pixels: Vec<u32>, width: u32) -> Frame {
        Frame {
            width,
            height: pixels.len() as u32 / width,
            format,
            pixels,
        }
    }

    #[test]
    fn pixels_decode_in_each_channel_order_and_depth() {
        let f = frame(wl_shm::Format::Xrgb8888, vec![0x0001_0203], 1);
        assert_eq!(f.codes_at(0, 0), [1, 2, 3]);
        let f = frame(wl_shm::Format::Abgr8888, vec![0xff01_0203], 1);
        assert_eq!(f.codes_at(0, 0), [3, 2, 1]);
        let f = frame(
            wl_shm::Format::Xrgb2101010,
            vec![(1023 << 20) | (512 << 10) | 7],
            1,
        );
        assert_eq!((f.codes_at(0, 0), f.channel_bits()), ([1023, 512, 7], 10));
    }

    #[test]
    fn the_sample_finds_the_patch_and_its_surround() {
        // 6 × 4: a 2 × 2 patch at (2, 1) on a surround.
        let (bg, patch) = (0x0010_2030, 0x00c8_6432);
        let mut pixels = vec![bg; 24];
        for (x, y) in [(2, 1), (3, 1), (2, 2), (3, 2)] {
            pixels[y * 6 + x] = patch;
        }
        let s = frame(wl_shm::Format::Xrgb8888, pixels, 6).sample((0.5, 0.5));
        assert_eq!(s.patch, [200, 100, 50]);
        assert_eq!(s.background, [16, 32, 48]);
        assert_eq!(s.rect, [2, 1, 2, 2]);
    }
}
