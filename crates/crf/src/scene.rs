//! Scenes in and display codes out: XYZ lists (CSV), float images (PFM, OpenEXR), and the
//! codes as CSV or a 16-bit PNG.
//!
//! A list names each colour's screen position in optional `screen_x`, `screen_y`
//! columns (fractions of the width and height from the top left; the centre when
//! absent). An image is placed on the screen by a [`Placement`], and each pixel is
//! shown at its centre's position.

use std::io::Write;
use std::path::{Path, PathBuf};

use chromacal_color::Xyz;
use chromacal_formats::numeric_csv::{CsvError, NumericTable};
use chromacal_model::ScreenPosition;

use super::{RenderedPixel, ScenePixel};

/// Why a scene could not be read or its codes written.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    Csv(#[from] CsvError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {what}")]
    Format { path: PathBuf, what: String },
    #[error("placement '{text}': {what}")]
    Placement { text: String, what: String },
}

/// Where an image sits on the screen (or where an observer looks), in fractions of
/// its width and height from the top left.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Placement {
    pub left: f64,
    pub top: f64,
    pub width: f64,
    pub height: f64,
}

impl Placement {
    /// The whole screen.
    pub const FULL: Placement = Placement {
        left: 0.0,
        top: 0.0,
        width: 1.0,
        height: 1.0,
    };

    /// Whether the screen point (`x`, `y`) lies in the rectangle (edges included).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.left..=self.left + self.width).contains(&x)
            && (self.top..=self.top + self.height).contains(&y)
    }

    /// `LEFT,TOP,WIDTH,HEIGHT`, each a fraction, the rectangle within the screen.
    pub fn parse(text: &str) -> Result<Placement, SceneError> {
        let bad = |what: &str| SceneError::Placement {
            text: text.to_string(),
            what: what.to_string(),
        };
        let values: Vec<f64> = text
            .split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| bad("four numbers LEFT,TOP,WIDTH,HEIGHT are needed"))?;
        let [left, top, width, height] = values[..] else {
            return Err(bad("four numbers LEFT,TOP,WIDTH,HEIGHT are needed"));
        };
        if !(values.iter().all(|v| v.is_finite()) && width > 0.0 && height > 0.0) {
            return Err(bad("width and height must be positive"));
        }
        if left < 0.0 || top < 0.0 || left + width > 1.0 + 1e-9 || top + height > 1.0 + 1e-9 {
            return Err(bad("the rectangle must lie within the screen (0 to 1)"));
        }
        Ok(Placement {
            left,
            top,
            width,
            height,
        })
    }

    /// Screen position of the centre of pixel (`column`, `row`) of a `width` ×
    /// `height` image, row 0 at the top.
    pub fn position(
        &self,
        column: usize,
        row: usize,
        width: usize,
        height: usize,
    ) -> ScreenPosition {
        ScreenPosition::new(
            self.left + self.width * (column as f64 + 0.5) / width as f64,
            self.top + self.height * (row as f64 + 0.5) / height as f64,
        )
    }
}

/// A float image of XYZ, rows from the top.
#[derive(Debug, Clone, PartialEq)]
pub struct XyzImage {
    pub width: usize,
    pub height: usize,
    pub xyz: Vec<Xyz>,
}

impl XyzImage {
    /// Its pixels, placed on the screen, row by row from the top.
    /// (Made over all cores: a 2048² image's are 168 MB, most of whose time is the
    /// memory's first touch.)
    pub fn pixels(&self, placement: &Placement, scale: f64) -> Vec<ScenePixel> {
        use rayon::prelude::*;
        (0..self.width * self.height)
            .into_par_iter()
            .map(|k| {
                let (row, column) = (k / self.width, k % self.width);
                ScenePixel {
                    xyz: self.xyz[k] * scale,
                    position: placement.position(column, row, self.width, self.height),
                }
            })
            .collect()
    }
}

/// Bytes a pixel of an image scene may cost at the peak of `render`, the budget's
/// unit: the scene, the rendered pixel, and for the mappings fitted to the whole
/// scene (Stone–Cowan–Beatty, Smith) every pixel's target and gamut too. Measured on a
/// 2048 × 2048 PFM: 440 bytes when every pixel's gamut, target and a copy of the scene
/// were kept for every mapping (1.83 GB peak), 171 since only those two keep them
/// (717 MB), and to a PNG, which keeps only each pixel's codes and ΔE00, 77 (323 MB;
/// codes byte-identical throughout); kept at the worst case, with a margin.
pub const RENDER_BYTES_PER_PIXEL: usize = 480;

/// Most memory an image scene may take to render: 4 GiB.
pub const MAX_RENDER_BYTES: usize = 4 << 30;

/// Largest image read, in pixels: what renders within [`MAX_RENDER_BYTES`] (8.9
/// megapixels: a 3840 × 2160 frame fits). The size comes from the file's header and
/// is checked before any pixel is allocated, so a small compressed file that claims
/// a huge image is refused at once.
pub const MAX_PIXELS: usize = MAX_RENDER_BYTES / RENDER_BYTES_PER_PIXEL;

/// What the process itself needs beside an image's pixels (the binary, its threads'
/// stacks, the allocator's arenas, a decoder's buffers), kept free of the budget.
const BESIDE_THE_IMAGE: usize = 768 << 20;

/// The process's address-space limit (`ulimit -v`, RLIMIT_AS), from
/// `/proc/self/limits`; `None` when unlimited or not known.
fn address_space_limit() -> Option<usize> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    line.split_whitespace()
        .nth(3)
        .and_then(|soft| soft.parse::<usize>().ok())
}

/// The memory an image may take to render here: [`MAX_RENDER_BYTES`], or less under
/// an address-space limit (what is left of it beside the image). A pixel costs
/// [`RENDER_BYTES_PER_PIXEL`]. Checked on the file's header, before any pixel is
/// allocated: an image past it is refused with a message, never an abort when an
/// allocation fails.
pub fn render_budget() -> usize {
    address_space_limit().map_or(MAX_RENDER_BYTES, |limit| {
        MAX_RENDER_BYTES.min(limit.saturating_sub(BESIDE_THE_IMAGE))
    })
}

/// Whether `width` × `height` pixels render within [`render_budget`] (and
/// [`MAX_PIXELS`]).
fn fits(width: usize, height: usize) -> bool {
    let pixels = width.saturating_mul(height);
    pixels <= MAX_PIXELS && pixels.saturating_mul(RENDER_BYTES_PER_PIXEL) <= render_budget()
}

/// The error for an image of `width` × `height` pixels past the budget.
fn too_large(width: usize, height: usize) -> String {
    let gb = width.saturating_mul(height) as f64 * RENDER_BYTES_PER_PIXEL as f64 / 1e9;
    let budget = render_budget();
    let under_limit = if budget < MAX_RENDER_BYTES {
        " under this process's address-space limit (ulimit -v)"
    } else {
        ""
    };
    format!(
        "{width} × {height} pixels would take about {gb:.1} GB to render: at most {} pixels ({:.1} GB){under_limit}",
        budget / RENDER_BYTES_PER_PIXEL,
        budget as f64 / 1e9
    )
}

/// The largest magnitude a scene's X, Y or Z may have: a thousand times the sun's
/// luminance (1.6e9 cd/m²). Beyond it a value is a unit or an exponent gone wrong, and
/// the arithmetic of tone mapping (squares, sums over the image) would overflow to
/// inf and NaN.
pub const MAX_SCENE_VALUE: f64 = 1e12;

/// Why `v` cannot be a colour of a scene, if it cannot.
fn implausible(v: &Xyz) -> Option<String> {
    if !v.iter().all(|c| c.is_finite()) {
        return Some("is not a finite number".into());
    }
    v.iter().find(|c| c.abs() > MAX_SCENE_VALUE).map(|c| {
        format!("holds {c:e}, beyond any light a scene holds (at most {MAX_SCENE_VALUE:e})")
    })
}

/// A list of colours: columns `X`, `Y`, `Z`, optionally `screen_x`, `screen_y`.
/// Values are multiplied by `scale` (1 for cd/m²).
pub fn read_xyz_csv(path: &Path, scale: f64) -> Result<Vec<ScenePixel>, SceneError> {
    let table = NumericTable::read(path)?;
    let exact = |name: &str| -> Result<usize, SceneError> {
        table
            .header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| SceneError::Format {
                path: path.to_path_buf(),
                what: format!(
                    "no column named '{name}' (the header has: {}; X, Y and Z are needed, screen_x and screen_y may be given)",
                    table.header.join(", ")
                ),
            })
    };
    let (x, y, z) = (exact("X")?, exact("Y")?, exact("Z")?);
    let position = match (
        table.column_index("screen_x"),
        table.column_index("screen_y"),
    ) {
        (Ok(sx), Ok(sy)) => Some((sx, sy)),
        (Err(_), Err(_)) => None,
        _ => {
            return Err(SceneError::Format {
                path: path.to_path_buf(),
                what: "screen_x and screen_y go together: one is missing".into(),
            });
        }
    };
    table
        .rows
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let position = match position {
                None => ScreenPosition::CENTRE,
                Some((sx, sy)) => {
                    let p = ScreenPosition::new(row[sx], row[sy]);
                    if !((0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.y)) {
                        return Err(SceneError::Format {
                            path: path.to_path_buf(),
                            what: format!(
                                "row {}: screen position ({}, {}) is not on the screen (0 to 1)",
                                i + 1,
                                p.x,
                                p.y
                            ),
                        });
                    }
                    p
                }
            };
            let xyz = Xyz::new(row[x], row[y], row[z]) * scale;
            if let Some(why) = implausible(&xyz) {
                return Err(SceneError::Format {
                    path: path.to_path_buf(),
                    what: format!("row {}: X, Y, Z {why}", i + 1),
                });
            }
            Ok(ScenePixel { xyz, position })
        })
        .collect()
}

/// A Portable Float Map: `PF` (three channels, here X, Y, Z) or `Pf` (one, taken as
/// Y of a colour with the chromaticity of `grey`), width and height, a scale whose
/// sign gives the byte order (negative: little-endian), then rows of 32-bit floats
/// from the bottom.
pub fn read_pfm(path: &Path, grey: &Xyz) -> Result<XyzImage, SceneError> {
    let bytes = chromacal_formats::durable::read_limited(path, (MAX_PIXELS * 12 + 4096) as u64)
        .map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    let bad = |what: String| SceneError::Format {
        path: path.to_path_buf(),
        what,
    };
    // Three header tokens after the magic, each ended by one whitespace byte.
    let mut fields = Vec::new();
    let mut at = 0;
    while fields.len() < 4 {
        while at < bytes.len() && bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        let start = at;
        while at < bytes.len() && !bytes[at].is_ascii_whitespace() {
            at += 1;
        }
        if start == at || at >= bytes.len() {
            return Err(bad(
                "the header ends early: PF or Pf, width, height and scale are needed".into(),
            ));
        }
        fields.push(String::from_utf8_lossy(&bytes[start..at]).to_string());
        at += 1;
        if start > 64 {
            return Err(bad("not a PFM header".into()));
        }
    }
    let channels = match fields[0].as_str() {
        "PF" => 3,
        "Pf" => 1,
        other => return Err(bad(format!("magic '{other}': a PFM starts with PF or Pf"))),
    };
    let dimension = |text: &str, what: &str| -> Result<usize, SceneError> {
        text.parse::<usize>()
            .ok()
            .filter(|v| *v > 0)
            .ok_or_else(|| bad(format!("{what} '{text}' is not a positive whole number")))
    };
    let width = dimension(&fields[1], "width")?;
    let height = dimension(&fields[2], "height")?;
    let scale: f64 = fields[3]
        .parse()
        .ok()
        .filter(|s: &f64| s.is_finite() && *s != 0.0)
        .ok_or_else(|| bad(format!("scale '{}' is not a non-zero number", fields[3])))?;
    if !fits(width, height) {
        return Err(bad(too_large(width, height)));
    }
    let pixels = width * height;
    let expected = pixels * channels * 4;
    let data = &bytes[at..];
    if data.len() != expected {
        return Err(bad(format!(
            "{} bytes of pixels where {width} × {height} × {channels} floats take {expected}",
            data.len()
        )));
    }
    let little = scale < 0.0;
    let value = |k: usize| {
        let b = [
            data[4 * k],
            data[4 * k + 1],
            data[4 * k + 2],
            data[4 * k + 3],
        ];
        f64::from(if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        })
    };
    let mut xyz = Vec::with_capacity(pixels);
    // PFM rows run from the bottom; the image is kept from the top.
    for row in (0..height).rev() {
        for column in 0..width {
            let k = (row * width + column) * channels;
            let v = if channels == 3 {
                Xyz::new(value(k), value(k + 1), value(k + 2))
            } else {
                grey * (value(k) / grey.y)
            };
            if let Some(why) = implausible(&v) {
                return Err(bad(format!("pixel ({column}, {}) {why}", height - 1 - row)));
            }
            xyz.push(v);
        }
    }
    Ok(XyzImage { width, height, xyz })
}

/// An OpenEXR image of XYZ: the first layer's channels `X`, `Y`, `Z`, or, when it has
/// none of those, its `R`, `G`, `B` read as X, Y, Z (an XYZ image written by a tool
/// that knows only RGB channels). Any sample type is read as 32-bit float.
pub fn read_exr(path: &Path) -> Result<XyzImage, SceneError> {
    use exr::prelude::{ReadChannels, ReadLayers, ReadSpecificChannel, read};
    let bad = |what: String| SceneError::Format {
        path: path.to_path_buf(),
        what,
    };
    let size = chromacal_formats::durable::open_regular(path)
        .and_then(|f| f.metadata())
        .map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    if size.len() > (MAX_PIXELS * 16) as u64 {
        return Err(bad(format!("larger than {} bytes", MAX_PIXELS * 16)));
    }
    // The headers first: a small file may claim a huge image, and the pixels are
    // allocated from what it claims.
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| bad(format!("not an OpenEXR image: {e}")))?;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        if !fits(w, h) {
            return Err(bad(too_large(w, h)));
        }
    }
    let by_names = |names: [&str; 3]| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .specific_channels()
            .required(names[0])
            .required(names[1])
            .required(names[2])
            .collect_pixels(
                |resolution, _| (resolution.width(), vec![Xyz::zeros(); resolution.area()]),
                |(width, pixels): &mut (usize, Vec<Xyz>), position, (x, y, z): (f32, f32, f32)| {
                    pixels[position.y() * *width + position.x()] =
                        Xyz::new(f64::from(x), f64::from(y), f64::from(z));
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_file(path)
    };
    let image = by_names(["X", "Y", "Z"])
        .or_else(|_| by_names(["R", "G", "B"]))
        .map_err(|e| {
            bad(format!(
                "not an OpenEXR image with X, Y, Z (or R, G, B) channels: {e}"
            ))
        })?;
    let size = image.layer_data.size;
    let (width, height) = (size.width(), size.height());
    if width == 0 || height == 0 || !fits(width, height) {
        return Err(bad(too_large(width, height)));
    }
    let xyz = image.layer_data.channel_data.pixels.1;
    if let Some((k, why)) = xyz
        .iter()
        .enumerate()
        .find_map(|(k, v)| implausible(v).map(|why| (k, why)))
    {
        return Err(bad(format!("pixel ({}, {}) {why}", k % width, k / width)));
    }
    Ok(XyzImage { width, height, xyz })
}

/// Write a PFM of XYZ (little-endian), rows from the bottom as the format has them.
pub fn write_pfm(path: &Path, image: &XyzImage) -> Result<(), SceneError> {
    let mut out = format!("PF\n{} {}\n-1.0\n", image.width, image.height).into_bytes();
    for row in (0..image.height).rev() {
        for column in 0..image.width {
            for v in image.xyz[row * image.width + column].iter() {
                out.extend_from_slice(&(*v as f32).to_le_bytes());
            }
        }
    }
    std::fs::write(path, out).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The codes as CSV: one row per pixel, with its position, the colour asked for,
/// what the mapping made of it, and what the display shows.
pub fn write_codes_csv(
    out: &mut dyn Write,
    scene: &[ScenePixel],
    rendered: &[RenderedPixel],
) -> std::io::Result<()> {
    writeln!(
        out,
        "index,screen_x,screen_y,R,G,B,target_X,target_Y,target_Z,shown_X,shown_Y,shown_Z,outside,mapping_de00"
    )?;
    for (i, (s, r)) in scene.iter().zip(rendered).enumerate() {
        writeln!(
            out,
            "{i},{},{},{},{},{},{},{},{},{},{},{},{},{:.4}",
            s.position.x,
            s.position.y,
            r.codes[0],
            r.codes[1],
            r.codes[2],
            r.target[0],
            r.target[1],
            r.target[2],
            r.shown[0],
            r.shown[1],
            r.shown[2],
            u8::from(r.outside),
            r.mapping_delta_e00
        )?;
    }
    Ok(())
}

/// The codes as a 16-bit RGB PNG: each code c of a `bits`-bit display written as
/// round(c · 65535 / (2^bits − 1)), so a reader gets the drive back at 16 bits.
pub fn write_png16(
    path: &Path,
    width: usize,
    height: usize,
    rendered: &[RenderedPixel],
    bits: u32,
) -> Result<(), SceneError> {
    let codes: Vec<[u16; 3]> = rendered.iter().map(|p| p.codes.map(|c| c as u16)).collect();
    write_png16_codes(path, width, height, &codes, bits)
}

/// [`write_png16`] from the codes alone (each at most 16 bits).
pub fn write_png16_codes(
    path: &Path,
    width: usize,
    height: usize,
    rendered: &[[u16; 3]],
    bits: u32,
) -> Result<(), SceneError> {
    let io = |source: std::io::Error| SceneError::Io {
        path: path.to_path_buf(),
        source,
    };
    let format = |e: png::EncodingError| SceneError::Format {
        path: path.to_path_buf(),
        what: e.to_string(),
    };
    let (w, h) = (
        u32::try_from(width).map_err(|_| format(png::EncodingError::LimitsExceeded))?,
        u32::try_from(height).map_err(|_| format(png::EncodingError::LimitsExceeded))?,
    );
    let file = std::fs::File::create(path).map_err(io)?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().map_err(format)?;
    let top = ((1u64 << bits) - 1) as f64;
    let mut data = Vec::with_capacity(rendered.len() * 6);
    for codes in rendered {
        for &c in codes {
            // Held at 65535, as `as u16` held a code above `bits`' top before.
            let v = crate::round_code((f64::from(c) * 65535.0 / top).min(65535.0)) as u16;
            data.extend_from_slice(&v.to_be_bytes());
        }
    }
    writer.write_image_data(&data).map_err(format)?;
    writer.finish().map_err(format)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pfm_round_trips_and_rows_come_from_the_top() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.pfm");
        let image = XyzImage {
            width: 3,
            height: 2,
            xyz: (0..6)
                .map(|i| Xyz::new(i as f64, 2.0 * i as f64, 0.5))
                .collect(),
        };
        write_pfm(&path, &image).unwrap();
        let back = read_pfm(&path, &Xyz::new(95.0, 100.0, 108.9)).unwrap();
        assert_eq!(back, image);
        let pixels = back.pixels(&Placement::FULL, 1.0);
        assert_eq!(pixels[0].position, ScreenPosition::new(1.0 / 6.0, 0.25));
        assert_eq!(pixels[5].xyz, Xyz::new(5.0, 10.0, 0.5));
    }

    #[test]
    fn a_short_pfm_is_refused_naming_the_sizes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("short.pfm");
        std::fs::write(&path, b"PF\n2 2\n-1.0\n\0\0\0\0").unwrap();
        let e = read_pfm(&path, &Xyz::new(1.0, 1.0, 1.0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("4 bytes of pixels where 2 × 2 × 3 floats take 48"),
            "{e}"
        );
    }

    #[test]
    fn an_exr_with_xyz_or_rgb_channels_is_read_as_xyz() {
        use exr::prelude::{Image, SpecificChannels, WritableImage};
        let dir = tempfile::tempdir().unwrap();
        let named = dir.path().join("xyz.exr");
        let pixels = SpecificChannels::build()
            .with_channel("X")
            .with_channel("Y")
            .with_channel("Z")
            .with_pixel_fn(|p| (p.0 as f32, p.1 as f32 * 10.0, 0.5f32));
        Image::from_channels((3, 2), pixels)
            .write()
            .to_file(&named)
            .unwrap();
        let image = read_exr(&named).unwrap();
        assert_eq!((image.width, image.height), (3, 2));
        assert_eq!(image.xyz[5], Xyz::new(2.0, 10.0, 0.5));
        let rgb = dir.path().join("rgb.exr");
        exr::prelude::write_rgb_file(&rgb, 2, 2, |x, y| (x as f32, y as f32, 7.0f32)).unwrap();
        let image = read_exr(&rgb).unwrap();
        assert_eq!(image.xyz[3], Xyz::new(1.0, 1.0, 7.0));
        // A small file whose header claims 100001 × 100001 pixels (its data window
        // patched) is refused before anything that size is made.
        let mut bytes = std::fs::read(&rgb).unwrap();
        let key = b"dataWindow\0box2i\0";
        let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
        bytes[at + 8..at + 12].copy_from_slice(&100_000i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&100_000i32.to_le_bytes());
        let huge = dir.path().join("huge.exr");
        std::fs::write(&huge, bytes).unwrap();
        let e = read_exr(&huge).unwrap_err().to_string();
        assert!(
            e.contains("100001 × 100001 pixels would take about 4800.1 GB to render"),
            "{e}"
        );
        let junk = dir.path().join("junk.exr");
        std::fs::write(&junk, b"not an image").unwrap();
        let e = read_exr(&junk).unwrap_err().to_string();
        assert!(e.contains("not an OpenEXR image"), "{e}");
    }

    #[test]
    fn placement_is_checked() {
        assert!(Placement::parse("0.25,0.25,0.5,0.5").is_ok());
        assert!(Placement::parse("0.75,0,0.5,1").is_err());
        assert!(Placement::parse("0,0,1").is_err());
    }
}
