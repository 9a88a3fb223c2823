//! What an output shows, read back from the X server (`GetImage`): the codes of its
//! pixels, and what a monitor behind the output is sent once the CRTC's gamma ramp has
//! been applied to them, as a video card does.

use x11rb::connection::Connection;
use x11rb::protocol::xproto::{ConnectionExt as _, ImageFormat, ImageOrder};

use super::{GammaRamp, OutputInfo, X11Error, XDisplay};
use chromacal_model::screen::{Geometry, ScreenContent};

/// How the root visual packs a pixel: bits per pixel and each channel's mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelFormat {
    pub bits_per_pixel: u8,
    pub masks: [u32; 3],
    pub msb_first: bool,
}

impl PixelFormat {
    /// Bits of each channel (8 for depth 24, 10 for depth 30).
    pub fn channel_bits(&self) -> u32 {
        self.masks[0].count_ones()
    }

    /// The pixel value for channel codes at this format's depth.
    pub fn pixel(&self, codes: [u32; 3]) -> u32 {
        let mut pixel = 0;
        for (code, mask) in codes.iter().zip(self.masks) {
            pixel |= (code << mask.trailing_zeros()) & mask;
        }
        pixel
    }

    /// The channel codes of a pixel value.
    pub fn codes(&self, pixel: u32) -> [u32; 3] {
        self.masks
            .map(|mask| (pixel & mask) >> mask.trailing_zeros())
    }
}

/// What the pixels under an aim point show: the patch there, the rectangle it fills
/// (pixels, on the output), and the surround.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub patch: [u32; 3],
    pub background: [u32; 3],
    /// x, y, width, height of the patch on the output.
    pub rect: [u32; 4],
    pub channel_bits: u32,
}

impl XDisplay {
    /// The root visual's pixel format (TrueColor or DirectColor at 32 bits per pixel:
    /// depth 24 or 30).
    pub fn pixel_format(&self) -> Result<PixelFormat, X11Error> {
        let setup = self.conn.setup();
        let screen = &setup.roots[self.screen];
        let visual = screen
            .allowed_depths
            .iter()
            .flat_map(|d| d.visuals.iter().map(move |v| (d.depth, v)))
            .find(|(_, v)| v.visual_id == screen.root_visual)
            .ok_or_else(|| self.protocol("the root visual is not listed among its depths"))?;
        let bits_per_pixel = setup
            .pixmap_formats
            .iter()
            .find(|f| f.depth == visual.0)
            .map(|f| f.bits_per_pixel)
            .unwrap_or(0);
        let masks = [visual.1.red_mask, visual.1.green_mask, visual.1.blue_mask];
        if bits_per_pixel != 32 || masks.iter().any(|m| m.count_ones() < 6) {
            return Err(self.protocol(format!(
                "the root visual (depth {}, {bits_per_pixel} bits per pixel) is not a true-colour visual of 32 bits per pixel",
                visual.0
            )));
        }
        Ok(PixelFormat {
            bits_per_pixel,
            masks,
            msb_first: setup.image_byte_order == ImageOrder::MSB_FIRST,
        })
    }

    /// The pixels of a rectangle of the root window, row by row, in `format` (the root
    /// visual's, [`XDisplay::pixel_format`]).
    pub fn pixels(
        &self,
        format: &PixelFormat,
        x: i16,
        y: i16,
        width: u16,
        height: u16,
    ) -> Result<Vec<u32>, X11Error> {
        let reply = self
            .conn
            .get_image(ImageFormat::Z_PIXMAP, self.root, x, y, width, height, !0)
            .map_err(|e| self.protocol(e))?
            .reply()
            .map_err(|e| self.protocol(e))?;
        let expected = usize::from(width) * usize::from(height) * 4;
        if reply.data.len() < expected {
            return Err(self.protocol(format!(
                "GetImage gave {} bytes for {width}×{height} pixels",
                reply.data.len()
            )));
        }
        Ok(reply.data[..expected]
            .chunks_exact(4)
            .map(|b| {
                let b = [b[0], b[1], b[2], b[3]];
                if format.msb_first {
                    u32::from_be_bytes(b)
                } else {
                    u32::from_le_bytes(b)
                }
            })
            .collect())
    }

    /// What `output` shows under `aim` (fractions of its width and height): the code
    /// there, the extent of the run of equal pixels through it along its row and
    /// column (the patch), and the first other pixel found on them (the surround).
    pub fn sample(&self, output: &OutputInfo, aim: (f64, f64)) -> Result<Sample, X11Error> {
        let format = self.pixel_format()?;
        let (w, h) = (output.width, output.height);
        if w == 0 || h == 0 {
            return Err(X11Error::Unlit {
                output: output.name.clone(),
            });
        }
        let ax = ((aim.0.clamp(0.0, 1.0) * f64::from(w)) as u32).min(w - 1);
        let ay = ((aim.1.clamp(0.0, 1.0) * f64::from(h)) as u32).min(h - 1);
        let to_i16 = |v: i64| i16::try_from(v).map_err(|e| self.protocol(e));
        let to_u16 = |v: u32| u16::try_from(v).map_err(|e| self.protocol(e));
        let row = self.pixels(
            &format,
            to_i16(i64::from(output.x))?,
            to_i16(i64::from(output.y) + i64::from(ay))?,
            to_u16(w)?,
            1,
        )?;
        let column = self.pixels(
            &format,
            to_i16(i64::from(output.x) + i64::from(ax))?,
            to_i16(i64::from(output.y))?,
            1,
            to_u16(h)?,
        )?;
        Ok(Sample::of_lines(
            &row,
            &column,
            (ax, ay),
            |p| format.codes(p),
            format.channel_bits(),
        ))
    }
}

impl Sample {
    /// The sample of the pixels of one `row` and one `column` of an output crossing at
    /// `at` (x, y): the code there, the run of equal pixels through it along each (the
    /// patch), and the first other pixel found on them (the surround). `codes` decodes
    /// a pixel at `channel_bits`.
    pub fn of_lines(
        row: &[u32],
        column: &[u32],
        at: (u32, u32),
        codes: impl Fn(u32) -> [u32; 3],
        channel_bits: u32,
    ) -> Sample {
        let (ax, ay) = at;
        let here = row[ax as usize];
        let run = |line: &[u32], at: usize| {
            let start = line[..at]
                .iter()
                .rposition(|&p| p != here)
                .map_or(0, |i| i + 1);
            let end = line[at..]
                .iter()
                .position(|&p| p != here)
                .map_or(line.len(), |i| at + i);
            (start as u32, end as u32)
        };
        let (x0, x1) = run(row, ax as usize);
        let (y0, y1) = run(column, ay as usize);
        let surround = row
            .iter()
            .chain(column)
            .find(|&&p| p != here)
            .copied()
            .unwrap_or(here);
        Sample {
            patch: codes(here),
            background: codes(surround),
            rect: [x0, y0, x1 - x0, y1 - y0],
            channel_bits,
        }
    }

    /// What the monitor is sent: the codes through `ramp` (the CRTC's gamma), as drives
    /// in [0, 1], with the patch's place as a fraction of the output.
    pub fn content(&self, ramp: &GammaRamp, output: &OutputInfo) -> ScreenContent {
        self.content_on(ramp, output.width, output.height)
    }

    /// [`Self::content`] on an output of `width` × `height` pixels.
    pub fn content_on(&self, ramp: &GammaRamp, width: u32, height: u32) -> ScreenContent {
        let max = f64::from((1u32 << self.channel_bits) - 1);
        let through =
            |codes: [u32; 3]| [0, 1, 2].map(|c| ramp.output(c, f64::from(codes[c]) / max));
        let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
        ScreenContent {
            patch: through(self.patch),
            background: through(self.background),
            geometry: Geometry {
                x: f64::from(self.rect[0]) / w,
                y: f64::from(self.rect[1]) / h,
                width: f64::from(self.rect[2]) / w,
                height: f64::from(self.rect[3]) / h,
            },
        }
    }
}

/// What a monitor on `output` of the X display `display` is sent now, read under `aim`
/// each time it is called (the pixels through the CRTC's current gamma ramp): the
/// screen an emulated instrument looks at.
pub fn watch_output(
    display: Option<&str>,
    output: &super::OutputSelector,
    aim: (f64, f64),
) -> Result<impl FnMut() -> Result<ScreenContent, X11Error> + Send + use<>, X11Error> {
    let x = XDisplay::open(display)?;
    let selector = output.clone();
    x.output(&selector)?.lit_crtc()?;
    Ok(move || {
        // Looked up at every reading: the instrument stays on the monitor when its
        // mode changes.
        let output = x.output(&selector)?;
        let sample = x.sample(&output, aim)?;
        let ramp = x.gamma(&output)?;
        Ok(sample.content(&ramp, &output))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_pack_and_unpack_at_8_and_10_bits() {
        let eight = PixelFormat {
            bits_per_pixel: 32,
            masks: [0xff0000, 0x00ff00, 0x0000ff],
            msb_first: false,
        };
        assert_eq!(eight.pixel([1, 2, 3]), 0x010203);
        assert_eq!(eight.codes(0x010203), [1, 2, 3]);
        let ten = PixelFormat {
            bits_per_pixel: 32,
            masks: [0x3ff << 20, 0x3ff << 10, 0x3ff],
            msb_first: false,
        };
        assert_eq!(ten.channel_bits(), 10);
        assert_eq!(ten.codes(ten.pixel([1023, 512, 7])), [1023, 512, 7]);
    }
}
