//! A scene from its files to the codes a calibrated display is sent, as `chromacal
//! render` runs it: the scene read once (an XYZ list, an XYZ image, emission or
//! reflectance spectra, a spectral image), laid out on the screen, its spectra turned
//! into XYZ by the method asked for (or, with `explain`, the cheapest accurate enough
//! for this scene), the model reduced to the parts the scene needs (`explain`), the
//! colour reproduction function run, and the codes written as CSV or a 16-bit PNG,
//! with the summary a person reads.

use std::path::{Path, PathBuf};

use chromacal_color::Xyz;
use chromacal_color::spaces::{Xyy, xyy_to_xyz};
use chromacal_color::spectrum::{Illuminant, KM_PHOTOPIC, Observer};
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::measurement::Units;
use chromacal_model::monitor::ImageLight;
use chromacal_model::target::{WhiteTarget, daylight_xy, parse_white};
use chromacal_model::{MonitorModel, ScreenPosition};

use crate::explain::{Explanation, explain};
use crate::scene::{
    Placement, XyzImage, read_exr, read_pfm, read_xyz_csv, write_codes_csv, write_png16,
    write_png16_codes,
};
use crate::spectral::{GRID_LEN, MethodKind, SpectralMethod, onto_grid};
use crate::spectral_file::SpectralFile;
use crate::spectral_image::SpectralImage;
use crate::spectral_table::standard_methods;
use crate::{
    ColourReproduction, RenderSettings, RenderSummary, Rendering, Scene, ScenePixel,
    inversion_stride,
};

/// Why a scene could not be rendered: the message names the input that was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct RenderError(String);

impl From<String> for RenderError {
    fn from(message: String) -> Self {
        RenderError(message)
    }
}

impl From<&str> for RenderError {
    fn from(message: &str) -> Self {
        RenderError(message.to_string())
    }
}

/// The scene's files.
#[derive(Debug, Clone)]
pub enum SceneSource {
    /// An XYZ list: X, Y, Z, optionally screen_x, screen_y.
    Xyz(PathBuf),
    /// An XYZ image: PFM, or OpenEXR by its extension.
    Image(PathBuf),
    /// Emission spectra (radiance).
    Spectra(PathBuf),
    /// Reflectance factors under an illuminant.
    Reflectance(PathBuf, Illuminant),
    /// A directory of single-channel PFMs named by wavelength.
    SpectralImage(PathBuf),
}

/// The units of an XYZ scene's values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneUnits {
    /// cd/m².
    Absolute,
    /// White Y = 100, at `white_luminance`.
    Relative,
}

/// Where the codes go.
#[derive(Debug, Clone)]
pub enum CodesOutput {
    /// A `.png` (16-bit, images only) or any other name for CSV.
    File(PathBuf),
    /// CSV, handed back to be printed.
    Stdout,
}

/// A render as `chromacal render` asks for it.
#[derive(Debug, Clone)]
pub struct RenderRequest {
    pub source: SceneSource,
    pub units: SceneUnits,
    /// Luminance of Y = 100 in a relative scene and of a reflectance scene's white
    /// [default: the display's white].
    pub white_luminance: Option<f64>,
    /// The scene's white (`D65`, `6500K`, `x,y`) at `white_luminance`.
    pub scene_white: Option<String>,
    /// Where an image sits on the screen.
    pub at: Placement,
    /// A list laid out as an image of `COLUMNSxROWS`.
    pub grid: Option<String>,
    /// Spectra to XYZ by this method (unless `explain` chooses).
    pub method: MethodKind,
    /// Measure what each part of the model and the spectral method is worth to this
    /// scene, and drop what costs less than `max_de00`.
    pub explain: bool,
    pub max_de00: f64,
    pub settings: RenderSettings,
    pub output: CodesOutput,
}

/// What a render did.
#[derive(Debug, Clone)]
pub struct RenderOutcome {
    pub summary: RenderSummary,
    /// The summary as a person reads it, line by line.
    pub lines: Vec<String>,
    /// The CSV for standard output, when that is where the codes go.
    pub stdout: Option<Vec<u8>>,
}

/// A scene as read: its pixels, and its image size when it is an image.
#[derive(Clone)]
struct ReadScene {
    scene: Scene,
    size: Option<(usize, usize)>,
    spectral: Option<String>,
}

/// Render `request` for the display `model` describes (its readings in `units`).
pub fn render(
    model: &MonitorModel,
    units: Units,
    request: &RenderRequest,
) -> Result<RenderOutcome, RenderError> {
    let display_white = ColourReproduction::new(model)
        .map_err(|e| e.to_string())?
        .white();
    let white_luminance = match request.white_luminance {
        Some(w) if !(w > 0.0 && w.is_finite()) => {
            return Err(RenderError::from(format!(
                "--white-luminance must be a positive luminance, not {w}"
            )));
        }
        Some(w) => w,
        None => display_white.y,
    };
    if !(request.max_de00 > 0.0 && request.max_de00.is_finite()) {
        return Err(RenderError::from(format!(
            "--max-de00 must be a positive ΔE00, not {}",
            request.max_de00
        )));
    }
    let placement = &request.at;
    let settings = &request.settings;
    let source = read_source(request, units, white_luminance, &display_white)?;
    let read_with = |method: &MethodKind| source.scene(method, placement);
    let mut lines = Vec::new();
    let method = if request.explain && matches!(source, Source::Spectra { .. }) {
        let (method, report) = choose_method(
            &read_with,
            matches!(request.source, SceneSource::Reflectance(..)),
            &display_white,
            request.max_de00,
        )?;
        lines.extend(report);
        method
    } else {
        request.method.clone()
    };
    // The colours read are the scene itself, not a copy of it (an image's pixels
    // twice over).
    let mut read = source.into_scene(&method, placement)?;
    if let Some(grid) = &request.grid {
        lay_out(&mut read, grid, placement)?;
    }
    let reduced = if request.explain {
        let explanation =
            explain(model, &read.scene, settings, request.max_de00).map_err(|e| e.to_string())?;
        lines.extend(describe_explanation(&explanation));
        explanation.reduced
    } else {
        model.clone()
    };
    // An image written as a PNG needs the codes alone: kept as such, not as whole
    // rendered pixels (a 2048² image in under 400 MB).
    if let (CodesOutput::File(path), Some((width, height)), false) =
        (&request.output, read.size, request.explain)
        && is_png(path)
    {
        let (codes, mut summary) = ColourReproduction::new(&reduced)
            .and_then(|crf| crf.render_codes(&read.scene, settings))
            .map_err(|e| e.to_string())?;
        summary.image_light = image_light(model, codes.len(), placement, settings.bits, |i| {
            codes[i].map(u32::from)
        });
        drop(read.scene);
        write_png16_codes(path, width, height, &codes, settings.bits)
            .map_err(|e| RenderError::from(e.to_string()))?;
        lines.push(describe(
            &summary,
            read.spectral.as_deref(),
            &request.output,
        ));
        return Ok(RenderOutcome {
            summary,
            lines,
            stdout: None,
        });
    }
    let mut rendering = ColourReproduction::new(&reduced)
        .and_then(|crf| crf.render(&read.scene, settings))
        .map_err(|e| e.to_string())?;
    if request.explain {
        // The codes come from the reduced model; what they show is the whole
        // profile's prediction.
        rendering.shown_by(model, &read.scene, settings.bits);
    }
    if read.size.is_some() {
        let pixels = &rendering.pixels;
        rendering.summary.image_light =
            image_light(model, pixels.len(), placement, settings.bits, |i| {
                pixels[i].codes
            });
    }
    let stdout = write_codes(&request.output, &read, &rendering, settings.bits)?;
    lines.push(describe(
        &rendering.summary,
        read.spectral.as_deref(),
        &request.output,
    ));
    Ok(RenderOutcome {
        summary: rendering.summary,
        lines,
        stdout,
    })
}

/// What the display's brightness limiter makes of the rendered image (None without
/// one): the screen's mean light over every pixel, pixel i shown at `bits`-bit codes
/// `codes(i)`, the image on the share of the screen `placement` gives it and black
/// around it.
fn image_light(
    model: &MonitorModel,
    pixels: usize,
    placement: &Placement,
    bits: u32,
    codes: impl Fn(usize) -> [u32; 3],
) -> Option<ImageLight> {
    let top = f64::from((1u32 << bits) - 1);
    let drives = (0..pixels).map(|i| codes(i).map(|v| f64::from(v) / top));
    model.image_light(drives, placement.width * placement.height)
}

/// Place a list's colours as a COLUMNSxROWS image.
fn lay_out(read: &mut ReadScene, grid: &str, placement: &Placement) -> Result<(), RenderError> {
    let size = grid
        .split_once(['x', 'X'])
        .and_then(|(w, h)| {
            Some((
                w.trim().parse::<usize>().ok()?,
                h.trim().parse::<usize>().ok()?,
            ))
        })
        .filter(|(w, h)| *w > 0 && *h > 0);
    let Some((width, height)) = size else {
        return Err(RenderError::from(format!(
            "--grid '{grid}': COLUMNSxROWS is needed, e.g. 6x4"
        )));
    };
    if read.size.is_some() {
        return Err(RenderError::from(
            "--grid lays out a list; the scene is an image already",
        ));
    }
    let n = read.scene.pixels.len();
    if width.checked_mul(height) != Some(n) {
        return Err(RenderError::from(format!(
            "--grid {width}x{height} holds {} colours, and the scene has {n}",
            width.saturating_mul(height)
        )));
    }
    for (k, pixel) in read.scene.pixels.iter_mut().enumerate() {
        pixel.position = placement.position(k % width, k / width, width, height);
    }
    read.size = Some((width, height));
    Ok(())
}

/// Codes to `path` go into a 16-bit PNG (by its extension), else a CSV.
fn is_png(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
}

/// Write the codes where they go; the CSV back when that is standard output.
fn write_codes(
    output: &CodesOutput,
    read: &ReadScene,
    rendering: &Rendering,
    bits: u32,
) -> Result<Option<Vec<u8>>, RenderError> {
    if let CodesOutput::File(path) = output
        && is_png(path)
    {
        let Some((width, height)) = read.size else {
            return Err(RenderError::from(
                "a PNG needs an image scene (--image, --spectral-image, or a list laid out with --grid); write a .csv for a list",
            ));
        };
        write_png16(path, width, height, &rendering.pixels, bits)
            .map_err(|e| RenderError::from(e.to_string()))?;
        return Ok(None);
    }
    let mut text = Vec::new();
    write_codes_csv(&mut text, &read.scene.pixels, &rendering.pixels).map_err(|e| e.to_string())?;
    match output {
        CodesOutput::Stdout => Ok(Some(text)),
        CodesOutput::File(path) => std::fs::write(path, text)
            .map(|()| None)
            .map_err(|e| RenderError::from(format!("{}: {e}", path.display()))),
    }
}

/// The cheapest of the survey's methods whose largest ΔE00 on this scene, against
/// the direct sum, is below `limit`; and the lines that say so.
fn choose_method(
    read_with: &dyn Fn(&MethodKind) -> Result<ReadScene, RenderError>,
    reflective: bool,
    white: &Xyz,
    limit: f64,
) -> Result<(MethodKind, Vec<String>), RenderError> {
    let reference = read_with(&MethodKind::Direct)?;
    let mut best: Option<(usize, MethodKind, f64)> = None;
    let mut lines = vec![format!(
        "spectral method: the cheapest whose largest ΔE00 on this scene is below {limit}"
    )];
    for kind in standard_methods() {
        let Ok(read) = read_with(&kind) else { continue };
        let worst = read
            .scene
            .pixels
            .iter()
            .zip(&reference.scene.pixels)
            .map(|(a, b)| delta_e00_xyz(&a.xyz, &b.xyz, white))
            .fold(0.0, f64::max);
        // Operations do not depend on the spectra (a flat one stands in for the
        // family of characteristic vectors).
        let method = SpectralMethod::new(kind.clone(), Observer::default(), &[vec![1.0; GRID_LEN]])
            .map_err(|e| e.to_string())?;
        let (p, i) = (method.product_operations(), method.integration_operations());
        let operations = i.multiplications
            + i.additions
            + if reflective {
                p.multiplications + p.additions
            } else {
                0
            };
        lines.push(format!(
            "  {} ({}): {operations} operations, largest ΔE00 {worst:.3}",
            kind.name(),
            kind.parameter()
        ));
        if worst < limit && best.as_ref().is_none_or(|b| operations < b.0) {
            best = Some((operations, kind, worst));
        }
    }
    let (_, kind, _) = best.unwrap_or((0, MethodKind::Direct, 0.0));
    lines.push(format!("  chosen: {} ({})", kind.name(), kind.parameter()));
    Ok((kind, lines))
}

fn describe_explanation(e: &Explanation) -> Vec<String> {
    let mut lines = vec![format!(
        "model parts this scene needs (a part costing less than ΔE00 {} everywhere is dropped):",
        e.threshold
    )];
    for p in &e.parts {
        let cost = match (&p.cost, p.present) {
            (_, false) => "not in the profile".to_string(),
            (Some(c), true) => format!("without it mean {:.3}, max {:.3}", c.mean, c.max),
            (None, true) => "no pixels".to_string(),
        };
        let verdict = match (p.present, p.dropped) {
            (false, _) => "",
            (true, true) => " → dropped",
            (true, false) => " → kept",
        };
        lines.push(format!("  {}: {cost}{verdict}", p.part.name()));
    }
    if let Some(c) = &e.combined {
        lines.push(format!(
            "  all dropped together: mean {:.3}, max {:.3}",
            c.mean, c.max
        ));
    }
    lines.push(format!(
        "  render time: {:.1} ms with the full model, {:.1} ms with what is kept",
        e.full_seconds * 1e3,
        e.reduced_seconds * 1e3
    ));
    lines
}

/// Read the scene's files, once.
fn read_source(
    request: &RenderRequest,
    units: Units,
    white_luminance: f64,
    display_white: &Xyz,
) -> Result<Source, RenderError> {
    // Relative values (white Y = 100) scaled to the profile's units.
    let relative_scale = match units {
        Units::Absolute => white_luminance / 100.0,
        Units::Relative => 1.0,
    };
    let xyz_scale = match (request.units, units) {
        (SceneUnits::Absolute, Units::Absolute) => 1.0,
        (SceneUnits::Relative, _) => relative_scale,
        (SceneUnits::Absolute, Units::Relative) => {
            return Err(RenderError::from(
                "the profile is relative (white Y = 100) and the scene in cd/m²: give --units relative, or a profile in cd/m²",
            ));
        }
    };
    let absolute_spectra = |what: &str| -> Result<f64, RenderError> {
        match units {
            Units::Absolute => Ok(KM_PHOTOPIC),
            Units::Relative => Err(RenderError::from(format!(
                "{what} are radiances (cd/m² once integrated), and the profile is relative: use a profile in cd/m²"
            ))),
        }
    };
    // The scene's white at the luminance of its Y = 100, in the profile's units.
    let white = match &request.scene_white {
        Some(text) => {
            let xy = match parse_white(text).map_err(|e| e.to_string())? {
                WhiteTarget::Chromaticity(xy) => xy,
                WhiteTarget::Daylight(k) => daylight_xy(k).map_err(|e| e.to_string())?,
                WhiteTarget::Native => {
                    let w = display_white;
                    let sum = w.x + w.y + w.z;
                    [w.x / sum, w.y / sum]
                }
            };
            Some(xyy_to_xyz(&Xyy {
                x: xy[0],
                y: xy[1],
                big_y: 100.0 * relative_scale,
            }))
        }
        // A reflectance scene's white is its illuminant's, integrated with the
        // scene (`Source::scene`).
        None => None,
    };
    let placement = &request.at;
    Ok(match &request.source {
        SceneSource::Xyz(path) => {
            let pixels = read_xyz_csv(path, xyz_scale).map_err(|e| e.to_string())?;
            Source::Colours(ReadScene {
                scene: Scene { pixels, white },
                size: None,
                spectral: None,
            })
        }
        SceneSource::Image(path) => {
            let exr = path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
            let image = if exr {
                read_exr(path)
            } else {
                read_pfm(path, display_white)
            }
            .map_err(|e| e.to_string())?;
            Source::Colours(image_scene(&image, placement, xyz_scale, white, None))
        }
        SceneSource::Spectra(path) => Source::Spectra {
            spectra: read_spectra(path)?,
            light: None,
            scale: absolute_spectra("--spectra")?,
            white,
        },
        SceneSource::Reflectance(path, illuminant) => {
            let illuminant = illuminant.spectrum();
            Source::Spectra {
                spectra: read_spectra(path)?,
                light: Some(onto_grid(illuminant.wavelengths_nm(), illuminant.values())),
                scale: relative_scale,
                white,
            }
        }
        SceneSource::SpectralImage(dir) => {
            let image = SpectralImage::read(dir).map_err(|e| e.to_string())?;
            if let Some(warning) = image.warning() {
                tracing::warn!("{}: {warning}", dir.display());
            }
            Source::SpectralImage {
                image,
                scale: absolute_spectra("--spectral-image")?,
                white,
            }
        }
    })
}

/// A scene's files as read, once: its colours, or its spectra still to be turned
/// into colours by a method (which `--explain` tries one after another).
enum Source {
    Colours(ReadScene),
    Spectra {
        /// On the 5 nm grid: radiances, or reflectances under `light`.
        spectra: Vec<Vec<f64>>,
        light: Option<Vec<f64>>,
        /// From the method's integral to the profile's units.
        scale: f64,
        white: Option<Xyz>,
    },
    /// A spectral image, integrated pixel by pixel (placed by --at).
    SpectralImage {
        image: SpectralImage,
        scale: f64,
        white: Option<Xyz>,
    },
}

impl Source {
    /// [`Source::scene`], taking the colours read rather than copying them.
    fn into_scene(
        self,
        method: &MethodKind,
        placement: &Placement,
    ) -> Result<ReadScene, RenderError> {
        match self {
            Source::Colours(read) => Ok(read),
            other => other.scene(method, placement),
        }
    }

    /// The scene, spectra turned into XYZ by `method`.
    fn scene(&self, method: &MethodKind, placement: &Placement) -> Result<ReadScene, RenderError> {
        let (spectra, light, scale, white) = match self {
            Source::Colours(read) => return Ok(read.clone()),
            Source::SpectralImage {
                image,
                scale,
                white,
            } => {
                let xyz = image.integrate(method).map_err(|e| e.to_string())?;
                let spectral = Some(format!("{} ({})", method.name(), method.parameter()));
                return Ok(image_scene(&xyz, placement, *scale, *white, spectral));
            }
            Source::Spectra {
                spectra,
                light,
                scale,
                white,
            } => (spectra, light, *scale, *white),
        };
        let (xyz, reflector) = integrate_all(method, spectra, light.as_ref())?;
        Ok(ReadScene {
            scene: Scene {
                pixels: at_centre(xyz, scale),
                // A reflectance scene's white: the perfect reflector under its light,
                // by the same method on the same wavelengths as its colours.
                white: white.or(reflector.map(|w| w * scale)),
            },
            size: None,
            spectral: Some(format!("{} ({})", method.name(), method.parameter())),
        })
    }
}

fn image_scene(
    image: &XyzImage,
    placement: &Placement,
    scale: f64,
    white: Option<Xyz>,
    spectral: Option<String>,
) -> ReadScene {
    ReadScene {
        scene: Scene {
            pixels: image.pixels(placement, scale),
            white,
        },
        size: Some((image.width, image.height)),
        spectral,
    }
}

fn at_centre(xyz: Vec<Xyz>, scale: f64) -> Vec<ScenePixel> {
    xyz.into_iter()
        .map(|xyz| ScenePixel {
            xyz: xyz * scale,
            position: ScreenPosition::CENTRE,
        })
        .collect()
}

/// The samples of a spectral CSV (read by the one rule of `spectral_file`), each on
/// the 5 nm grid.
fn read_spectra(path: &Path) -> Result<Vec<Vec<f64>>, RenderError> {
    let file = SpectralFile::read(path).map_err(|e| e.to_string())?;
    Ok(file
        .spectra
        .iter()
        .map(|s| onto_grid(s.wavelengths_nm(), s.values()))
        .collect())
}

/// XYZ (in units of ∫ S f dλ) of each spectrum, or of each reflectance under `light`
/// with the light's Y = 100, by `kind`, and then the perfect reflector's under that
/// light. Characteristic vectors are computed from these spectra themselves (and
/// the light).
fn integrate_all(
    kind: &MethodKind,
    spectra: &[Vec<f64>],
    light: Option<&Vec<f64>>,
) -> Result<(Vec<Xyz>, Option<Xyz>), RenderError> {
    debug_assert!(spectra.iter().all(|s| s.len() == GRID_LEN));
    let family: Vec<Vec<f64>> = match light {
        Some(l) => std::iter::once(l.clone())
            .chain(
                spectra
                    .iter()
                    .map(|r| r.iter().zip(l).map(|(r, s)| r * s).collect()),
            )
            .collect(),
        None => spectra.to_vec(),
    };
    let method = SpectralMethod::new(kind.clone(), Observer::default(), &family)
        .map_err(|e| e.to_string())?;
    Ok(match light {
        None => (
            spectra
                .iter()
                .map(|s| method.integrate(&method.represent(s)))
                .collect(),
            None,
        ),
        Some(l) => {
            let light = method.represent(l);
            let y = method.integrate(&light).y;
            if y.is_nan() || y <= 0.0 {
                return Err(RenderError::from("the illuminant has no luminance"));
            }
            let colours = spectra
                .iter()
                .map(|r| {
                    method.integrate(&method.product(&method.reflectance(r), &light)) * (100.0 / y)
                })
                .collect();
            (colours, Some(method.integrate(&light) * (100.0 / y)))
        }
    })
}

/// The summary a person reads.
fn describe(summary: &RenderSummary, spectral: Option<&str>, output: &CodesOutput) -> String {
    let mut lines = vec![format!(
        "rendered {} pixels to {}",
        summary.pixels,
        match output {
            CodesOutput::Stdout => "standard output".to_string(),
            CodesOutput::File(path) => path.display().to_string(),
        }
    )];
    if let Some(method) = spectral {
        lines.push(format!("spectra to XYZ: {method}"));
    }
    lines.push(format!("tone: {}", summary.tone));
    lines.push(format!("gamut mapping: {}", summary.gamut));
    lines.push(format!(
        "outside the gamut where shown: {} of {}",
        summary.outside, summary.pixels
    ));
    if let Some(scb) = &summary.stone_cowan_beatty {
        lines.push(format!(
            "Stone–Cowan–Beatty: black shift {:.4}, contrast scale {:.4}; the scene's grey axis lands at L* {:.1} to {:.1}; {} left outside for the projection ({} of them highlights above the scene's white)",
            scb.black_shift,
            scb.contrast_scale,
            scb.lightness[0],
            scb.lightness[1],
            scb.left_outside,
            scb.highlights
        ));
    }
    if let Some(smith) = &summary.smith {
        lines.push(format!(
            "Smith: Y_max {:.4} (the scene's white, or its lightest colour), α {}, β {}, γ {}",
            smith.y_max, smith.alpha, smith.beta, smith.gamma
        ));
    }
    if let Some(s) = &summary.mapping_all {
        lines.push(format!(
            "ΔE00 the mapping introduced: mean {:.3}, max {:.3} over all pixels",
            s.mean, s.max
        ));
    }
    if let Some(s) = &summary.mapping_outside {
        lines.push(format!(
            "  over the {} outside: mean {:.3}, p95 {:.3}, max {:.3}",
            s.n, s.mean, s.p95, s.max
        ));
    }
    if let Some(s) = &summary.inversion {
        // A large image's inversion is measured on a sample of its pixels
        // (`ColourReproduction::render_codes`); its codes on every one.
        let over = if s.n < summary.pixels {
            format!(
                " over {} pixels spread over the image (one in {})",
                s.n,
                inversion_stride(summary.pixels)
            )
        } else {
            String::new()
        };
        lines.push(format!(
            "ΔE00 of the codes against the mapped colour (quantisation, inversion){over}: mean {:.3}, max {:.3}",
            s.mean, s.max
        ));
    }
    if let Some(light) = &summary.image_light {
        lines.push(format!(
            "brightness limiter: the image's mean light {:.1} (full-field white {:.1}) dims all of it to {:.1} % of what the codes show on a small patch",
            light.mean_light,
            light.full_field,
            100.0 * light.gain
        ));
    }
    lines.join("\n")
}
