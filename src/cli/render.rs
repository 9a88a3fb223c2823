//! `chromacal render`: a scene through a profile, the colour reproduction function
//! (seed §4). XYZ or spectra in, the codes a calibrated display must be sent out.

use std::path::{Path, PathBuf};

use clap::ValueEnum;

use chromacal::color::Xyz;
use chromacal::color::adaptation::AdaptationTransform;
use chromacal::color::spaces::{Xyy, xyy_to_xyz};
use chromacal::color::spectrum::{KM_PHOTOPIC, Observer};
use chromacal::crf::explain::explain;
use chromacal::crf::gamut::{GamutMapping, ScbOptions, SgckSource, UniformSpace};
use chromacal::crf::scene::{
    Placement, XyzImage, read_exr, read_pfm, read_xyz_csv, write_codes_csv, write_png16,
};
use chromacal::crf::spectral::{GRID_LEN, MethodKind, SpectralMethod, onto_grid};
use chromacal::crf::spectral_file::SpectralFile;
use chromacal::crf::spectral_image::SpectralImage;
use chromacal::crf::spectral_table::standard_methods;
use chromacal::crf::tone::{TUMBLIN_RUSHMEIER_CONTRAST, ToneOperator};
use chromacal::crf::{
    CodeChoice, ColourReproduction, RenderSettings, RenderSummary, Scene, ScenePixel,
};
use chromacal::fit::validate::delta_e00_xyz;
use chromacal::measurement::Units;
use chromacal::model::ScreenPosition;
use chromacal::model::target::{WhiteTarget, daylight_xy, parse_white};
use chromacal::profile::Profile;

use super::shared::{
    Failure, IlluminantArg, contrast_ratio, non_negative_number, positive_number, share,
};
use super::shared::{is_stdout, outln, write_stdout};

/// Render a scene for a calibrated display: XYZ (a CSV list or a PFM image) or
/// spectra (emission, reflectance under an illuminant, or a stack of per-wavelength
/// images) through tone reproduction, gamut mapping and the profile's inverse model
/// (matrix, laws, black, and the spatial map at each pixel's place on the screen).
#[derive(clap::Args)]
pub struct RenderArgs {
    /// The profile (a chromacal .toml).
    profile: PathBuf,
    /// XYZ list: columns X, Y, Z, optionally screen_x, screen_y (0–1 from the top left).
    #[arg(long, group = "scene")]
    xyz: Option<PathBuf>,
    /// XYZ image: a PFM (PF: X, Y, Z per pixel; Pf: Y alone, at the display white's
    /// chromaticity) or an OpenEXR (.exr: channels X, Y, Z, or R, G, B holding X, Y, Z).
    #[arg(long, group = "scene")]
    image: Option<PathBuf>,
    /// Emission spectra: wavelength_nm, then one column of radiance
    /// (W·sr⁻¹·m⁻²·nm⁻¹) per colour.
    #[arg(long, group = "scene")]
    spectra: Option<PathBuf>,
    /// Reflectance factors (0–1): wavelength_nm, then one column per colour, seen
    /// under --illuminant with its white at --white-luminance.
    #[arg(long, group = "scene")]
    reflectance: Option<PathBuf>,
    /// A spectral image: a directory of single-channel PFMs (Pf) named by wavelength
    /// (380.pfm, 390.pfm, …), radiance in W·sr⁻¹·m⁻²·nm⁻¹.
    #[arg(long, group = "scene")]
    spectral_image: Option<PathBuf>,
    /// Where the codes go: .csv, .png (16-bit, images only), or - for CSV on standard
    /// output.
    #[arg(short, long)]
    output: PathBuf,
    /// Units of --xyz and --image values.
    #[arg(long, value_enum, ignore_case = true, default_value = "absolute")]
    units: UnitsArg,
    /// Luminance (cd/m²) of Y = 100 in a relative scene and of the white of a
    /// reflectance scene [default: the display's white].
    #[arg(long, value_parser = positive_number)]
    white_luminance: Option<f64>,
    /// Illuminant of --reflectance.
    #[arg(long, value_enum, ignore_case = true, default_value = "d65")]
    illuminant: IlluminantArg,
    /// Spectral method: direct, sampling:STEP_NM, gauss:POINTS, raso-fournier:DEGREE
    /// or cva:M (characteristic vectors of the scene's own spectra).
    #[arg(long, default_value = "direct")]
    method: MethodKind,
    /// Where an image sits on the screen: LEFT,TOP,WIDTH,HEIGHT in fractions.
    #[arg(long, default_value = "0,0,1,1")]
    at: String,
    /// Lay a list (--xyz without positions, --spectra, --reflectance) out as an image
    /// of COLUMNSxROWS, row by row from the top left, placed by --at: e.g. 6x4 for
    /// the ColorChecker. Then a PNG can be written.
    #[arg(long)]
    grid: Option<String>,
    /// Tone reproduction.
    #[arg(long, value_enum, ignore_case = true, default_value = "colorimetric")]
    tone: ToneArg,
    /// Ward: the area the observer looks at, LEFT,TOP,WIDTH,HEIGHT in fractions of
    /// the screen; its mean luminance is the scene's adaptation [default: the whole
    /// scene].
    #[arg(long, value_name = "RECT")]
    focus: Option<String>,
    /// Usable contrast of the display for Tumblin–Rushmeier (the survey's 35).
    #[arg(long, default_value_t = TUMBLIN_RUSHMEIER_CONTRAST, value_parser = contrast_ratio)]
    display_contrast: f64,
    /// Gamut mapping of colours the display cannot show where they are.
    #[arg(long, value_enum, ignore_case = true, default_value = "clip")]
    gamut: GamutArg,
    /// Stone–Cowan–Beatty: the share of colours its transform may leave outside
    /// (then projected); colours brighter than the scene's white are highlights and
    /// never count.
    #[arg(long, default_value_t = 0.01, value_parser = share)]
    scb_outside: f64,
    /// Stone–Cowan–Beatty's umbrella transformation: distance from the scene's grey
    /// axis multiplied by this before the transform (above 1 saturates, below 1
    /// desaturates).
    #[arg(long, default_value_t = 1.0, value_parser = positive_number)]
    scb_umbrella: f64,
    /// SGCK's source gamut: the RGB space the scene's colours are taken to come
    /// from, on the display's white and black.
    #[arg(long, value_enum, ignore_case = true, default_value = "rec2020")]
    sgck_source: SgckSourceArg,
    /// Bits per channel of the codes.
    #[arg(long, default_value_t = 8)]
    bits: u32,
    /// How codes are chosen: nearest (of the 8 codes around the exact drive, the one
    /// the profile shows nearest the colour, in ΔE00) or rounded (each channel on its
    /// own).
    #[arg(long, value_enum, ignore_case = true, default_value = "nearest")]
    codes: CodesArg,
    /// The scene's white, for --tone linear and --adapt: D50, D65, 6500K or x,y, at
    /// --white-luminance [default: a reflectance scene's illuminant].
    #[arg(long)]
    scene_white: Option<String>,
    /// Carry the scene's white to the display's (Bradford), for a viewer adapted to
    /// the screen, as in a dark room.
    #[arg(long)]
    adapt: bool,
    /// The summary as JSON.
    #[arg(long)]
    json: bool,
    /// Before rendering, measure what each part of the monitor model (spatial map,
    /// black, additivity terms, the laws beyond a power law) and, for spectra, the
    /// spectral method is worth to this scene, and drop what costs less than
    /// --max-de00.
    #[arg(long)]
    explain: bool,
    /// Largest ΔE00 (over the scene's pixels) a part may cost and still be dropped.
    #[arg(long, default_value_t = 0.5, value_parser = non_negative_number)]
    max_de00: f64,
}

#[derive(Clone, Copy, ValueEnum)]
enum UnitsArg {
    Absolute,
    Relative,
}

#[derive(Clone, Copy, ValueEnum)]
enum ToneArg {
    Colorimetric,
    Linear,
    Ward,
    TumblinRushmeier,
}

#[derive(Clone, Copy, ValueEnum)]
pub(super) enum GamutArg {
    /// Each channel clipped on its own.
    Clip,
    /// Toward the grey axis at constant CIELAB lightness and hue.
    GreyLab,
    /// Toward the grey axis at constant CIELUV lightness and hue.
    GreyLuv,
    /// The nearest point of the gamut in XYZ.
    Perpendicular,
    /// The nearest point of the gamut's boundary in ΔE00.
    PerpendicularLab,
    /// CIE 156's hue-preserving minimum ΔE*ab clipping.
    Hpminde,
    /// Smith's global transformation (the survey's α = β = 0.75, γ = 5).
    Smith,
    /// Stone–Cowan–Beatty's global transformation, then the CIELAB projection.
    Scb,
    /// CIE 156's SGCK: sigmoidal lightness mapping and knee scaling toward the
    /// cusp, from the source gamut of --sgck-source.
    Sgck,
}

/// The RGB space whose gamut SGCK compresses from.
#[derive(Clone, Copy, ValueEnum)]
pub(super) enum SgckSourceArg {
    Srgb,
    AdobeRgb,
    P3,
    Rec2020,
}

impl SgckSourceArg {
    fn source(self) -> SgckSource {
        match self {
            SgckSourceArg::Srgb => SgckSource::Srgb,
            SgckSourceArg::AdobeRgb => SgckSource::AdobeRgb,
            SgckSourceArg::P3 => SgckSource::P3,
            SgckSourceArg::Rec2020 => SgckSource::Rec2020,
        }
    }
}

impl GamutArg {
    /// The mapping named, Stone–Cowan–Beatty with `scb`, SGCK from `sgck`.
    pub(super) fn mapping(self, scb: ScbOptions, sgck: SgckSource) -> GamutMapping {
        match self {
            GamutArg::Clip => GamutMapping::Clip,
            GamutArg::GreyLab => GamutMapping::GreyAxis(UniformSpace::Lab),
            GamutArg::GreyLuv => GamutMapping::GreyAxis(UniformSpace::Luv),
            GamutArg::Perpendicular => GamutMapping::Perpendicular,
            GamutArg::PerpendicularLab => GamutMapping::PerpendicularLab,
            GamutArg::Hpminde => GamutMapping::Hpminde,
            GamutArg::Smith => GamutMapping::Smith,
            GamutArg::Scb => GamutMapping::StoneCowanBeatty(scb),
            GamutArg::Sgck => GamutMapping::Sgck(sgck),
        }
    }
}

/// A scene as read: its pixels, and its image size when it is an image.
#[derive(Clone)]
struct ReadScene {
    scene: Scene,
    size: Option<(usize, usize)>,
    spectral: Option<String>,
}

pub fn run(args: RenderArgs) -> Result<(), Failure> {
    let profile = Profile::read(&args.profile)?;
    let display_white = ColourReproduction::new(&profile.model)
        .map_err(|e| e.to_string())?
        .white();
    let white_luminance = match args.white_luminance {
        Some(w) if !(w > 0.0 && w.is_finite()) => {
            return Err(Failure::from(format!(
                "--white-luminance must be a positive luminance, not {w}"
            )));
        }
        Some(w) => w,
        None => display_white.y,
    };
    if !(args.max_de00 > 0.0 && args.max_de00.is_finite()) {
        return Err(Failure::from(format!(
            "--max-de00 must be a positive ΔE00, not {}",
            args.max_de00
        )));
    }
    let placement = Placement::parse(&args.at).map_err(|e| e.to_string())?;
    let settings = settings_of(&args)?;
    let source = read_source(&args, &profile, white_luminance, &display_white, &placement)?;
    let read_with = |method: &MethodKind| source.scene(method, &placement);
    let mut lines = Vec::new();
    let method = if args.explain && matches!(source, Source::Spectra { .. }) {
        let (method, report) = choose_method(
            &read_with,
            args.reflectance.is_some(),
            &display_white,
            args.max_de00,
        )?;
        lines.extend(report);
        method
    } else {
        args.method.clone()
    };
    let mut read = read_with(&method)?;
    if let Some(grid) = &args.grid {
        lay_out(&mut read, grid, &placement)?;
    }
    let model = if args.explain {
        let explanation = explain(&profile.model, &read.scene, &settings, args.max_de00)
            .map_err(|e| e.to_string())?;
        lines.extend(describe_explanation(&explanation));
        explanation.reduced
    } else {
        profile.model.clone()
    };
    let mut rendering = ColourReproduction::new(&model)
        .and_then(|crf| crf.render(&read.scene, &settings))
        .map_err(|e| e.to_string())?;
    if args.explain {
        // The codes come from the reduced model; what they show is the whole
        // profile's prediction.
        rendering.shown_by(&profile.model, &read.scene, settings.bits);
    }
    write_codes(&args, &read, &rendering)?;
    lines.push(describe(
        &rendering.summary,
        read.spectral.as_deref(),
        &args.output,
    ));
    let text = if args.json {
        serde_json::to_string_pretty(&rendering.summary).map_err(|e| e.to_string())?
    } else {
        lines.join("\n")
    };
    // The codes may be on standard output: the summary then goes to standard error.
    if is_stdout(&args.output) {
        eprintln!("{text}");
    } else {
        outln!("{text}")?;
    }
    Ok(())
}

/// Place a list's colours as a COLUMNSxROWS image.
fn lay_out(read: &mut ReadScene, grid: &str, placement: &Placement) -> Result<(), Failure> {
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
        return Err(Failure::from(format!(
            "--grid '{grid}': COLUMNSxROWS is needed, e.g. 6x4"
        )));
    };
    if read.size.is_some() {
        return Err(Failure::from(
            "--grid lays out a list; the scene is an image already",
        ));
    }
    let n = read.scene.pixels.len();
    if width.checked_mul(height) != Some(n) {
        return Err(Failure::from(format!(
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

fn settings_of(args: &RenderArgs) -> Result<RenderSettings, Failure> {
    if args.focus.is_some() && !matches!(args.tone, ToneArg::Ward) {
        return Err(Failure::from(
            "--focus is the area Ward's operator adapts to: give it with --tone ward",
        ));
    }
    let tone = match args.tone {
        ToneArg::Colorimetric => ToneOperator::Colorimetric,
        ToneArg::Linear => ToneOperator::Linear,
        ToneArg::Ward => ToneOperator::Ward {
            focus: args
                .focus
                .as_deref()
                .map(Placement::parse)
                .transpose()
                .map_err(|e| Failure::from(format!("--focus: {e}")))?,
        },
        ToneArg::TumblinRushmeier => ToneOperator::TumblinRushmeier {
            display_contrast: args.display_contrast,
        },
    };
    if !(0.0..1.0).contains(&args.scb_outside) {
        return Err(Failure::from(format!(
            "--scb-outside is a share from 0 to below 1, not {}",
            args.scb_outside
        )));
    }
    let gamut = args.gamut.mapping(
        ScbOptions {
            outside: args.scb_outside,
            umbrella: args.scb_umbrella,
        },
        args.sgck_source.source(),
    );
    Ok(RenderSettings {
        adaptation: args.adapt.then_some(AdaptationTransform::Bradford),
        tone,
        gamut,
        bits: args.bits,
        codes: match args.codes {
            CodesArg::Nearest => CodeChoice::NearestInDeltaE00,
            CodesArg::Rounded => CodeChoice::Rounded,
        },
    })
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum CodesArg {
    Nearest,
    Rounded,
}

fn write_codes(
    args: &RenderArgs,
    read: &ReadScene,
    rendering: &chromacal::crf::Rendering,
) -> Result<(), Failure> {
    if args
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
    {
        let Some((width, height)) = read.size else {
            return Err(Failure::from(
                "a PNG needs an image scene (--image, --spectral-image, or a list laid out with --grid); write a .csv for a list",
            ));
        };
        return write_png16(&args.output, width, height, &rendering.pixels, args.bits)
            .map_err(|e| Failure::from(e.to_string()));
    }
    let mut text = Vec::new();
    write_codes_csv(&mut text, &read.scene.pixels, &rendering.pixels).map_err(|e| e.to_string())?;
    if is_stdout(&args.output) {
        return write_stdout(&text);
    }
    std::fs::write(&args.output, text)
        .map_err(|e| Failure::from(format!("{}: {e}", args.output.display())))
}

/// The cheapest of the survey's methods whose largest ΔE00 on this scene, against
/// the direct sum, is below `limit`; and the lines that say so.
fn choose_method(
    read_with: &dyn Fn(&MethodKind) -> Result<ReadScene, Failure>,
    reflective: bool,
    white: &Xyz,
    limit: f64,
) -> Result<(MethodKind, Vec<String>), Failure> {
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

fn describe_explanation(e: &chromacal::crf::explain::Explanation) -> Vec<String> {
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
    args: &RenderArgs,
    profile: &Profile,
    white_luminance: f64,
    display_white: &Xyz,
    placement: &Placement,
) -> Result<Source, Failure> {
    // Relative values (white Y = 100) scaled to the profile's units.
    let relative_scale = match profile.units {
        Units::Absolute => white_luminance / 100.0,
        Units::Relative => 1.0,
    };
    let xyz_scale = match (args.units, profile.units) {
        (UnitsArg::Absolute, Units::Absolute) => 1.0,
        (UnitsArg::Relative, _) => relative_scale,
        (UnitsArg::Absolute, Units::Relative) => {
            return Err(Failure::from(
                "the profile is relative (white Y = 100) and the scene in cd/m²: give --units relative, or a profile in cd/m²",
            ));
        }
    };
    let absolute_spectra = |what: &str| -> Result<f64, Failure> {
        match profile.units {
            Units::Absolute => Ok(KM_PHOTOPIC),
            Units::Relative => Err(Failure::from(format!(
                "{what} are radiances (cd/m² once integrated), and the profile is relative: use a profile in cd/m²"
            ))),
        }
    };
    // The scene's white at the luminance of its Y = 100, in the profile's units.
    let white = match &args.scene_white {
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
    if let Some(path) = &args.xyz {
        let pixels = read_xyz_csv(path, xyz_scale).map_err(|e| e.to_string())?;
        return Ok(Source::Colours(ReadScene {
            scene: Scene { pixels, white },
            size: None,
            spectral: None,
        }));
    }
    if let Some(path) = &args.image {
        let exr = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        let image = if exr {
            read_exr(path)
        } else {
            read_pfm(path, display_white)
        }
        .map_err(|e| e.to_string())?;
        return Ok(Source::Colours(image_scene(
            &image, placement, xyz_scale, white, None,
        )));
    }
    if let Some(path) = &args.spectra {
        return Ok(Source::Spectra {
            spectra: read_spectra(path)?,
            light: None,
            scale: absolute_spectra("--spectra")?,
            white,
        });
    }
    if let Some(path) = &args.reflectance {
        let illuminant = chromacal::color::spectrum::Illuminant::from(args.illuminant).spectrum();
        return Ok(Source::Spectra {
            spectra: read_spectra(path)?,
            light: Some(onto_grid(illuminant.wavelengths_nm(), illuminant.values())),
            scale: relative_scale,
            white,
        });
    }
    if let Some(dir) = &args.spectral_image {
        let image = SpectralImage::read(dir).map_err(|e| e.to_string())?;
        if let Some(warning) = image.warning() {
            tracing::warn!("{}: {warning}", dir.display());
        }
        return Ok(Source::SpectralImage {
            image,
            scale: absolute_spectra("--spectral-image")?,
            white,
        });
    }
    Err(Failure::from(
        "no scene: give --xyz, --image, --spectra, --reflectance or --spectral-image",
    ))
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
    /// The scene, spectra turned into XYZ by `method`.
    fn scene(&self, method: &MethodKind, placement: &Placement) -> Result<ReadScene, Failure> {
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

/// The samples of a spectral CSV (read by the one rule of
/// `crf::spectral_file`), each on the 5 nm grid.
fn read_spectra(path: &Path) -> Result<Vec<Vec<f64>>, Failure> {
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
) -> Result<(Vec<Xyz>, Option<Xyz>), Failure> {
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
                return Err(Failure::from("the illuminant has no luminance"));
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
fn describe(summary: &RenderSummary, spectral: Option<&str>, output: &Path) -> String {
    let mut lines = vec![format!(
        "rendered {} pixels to {}",
        summary.pixels,
        if is_stdout(output) {
            "standard output".to_string()
        } else {
            output.display().to_string()
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
        lines.push(format!(
            "ΔE00 of the codes against the mapped colour (quantisation, inversion): mean {:.3}, max {:.3}",
            s.mean, s.max
        ));
    }
    lines.join("\n")
}
