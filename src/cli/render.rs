//! `chromacal render`: a scene through a profile, the colour reproduction function
//! (seed §4). XYZ or spectra in, the codes a calibrated display must be sent out.

use std::path::PathBuf;

use clap::ValueEnum;

use chromacal::profile::Profile;
use chromacal_color::adaptation::AdaptationTransform;
use chromacal_crf::gamut::ScbOptions;
use chromacal_crf::render::{CodesOutput, RenderRequest, SceneSource, SceneUnits, render};
use chromacal_crf::scene::Placement;
use chromacal_crf::spectral::MethodKind;
use chromacal_crf::tone::{TUMBLIN_RUSHMEIER_CONTRAST, ToneOperator};
use chromacal_crf::{CodeChoice, RenderSettings};

use super::args::{GamutArg, IlluminantArg, SgckSourceArg};
use super::shared::{Failure, contrast_ratio, non_negative_number, positive_number, share};
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
    /// An image may take 4 GiB to render (counted at 480 bytes a pixel, the most a
    /// mapping needs: 8.9 megapixels, a 3840 × 2160 frame), less under an
    /// address-space limit (ulimit -v), which keeps 768 MiB beside the image; a larger
    /// one is refused from its header, before anything is allocated.
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

pub fn run(args: RenderArgs) -> Result<(), Failure> {
    let profile = Profile::read(&args.profile)?;
    let at = Placement::parse(&args.at).map_err(|e| e.to_string())?;
    let settings = settings_of(&args)?;
    let source = if let Some(path) = args.xyz {
        SceneSource::Xyz(path)
    } else if let Some(path) = args.image {
        SceneSource::Image(path)
    } else if let Some(path) = args.spectra {
        SceneSource::Spectra(path)
    } else if let Some(path) = args.reflectance {
        SceneSource::Reflectance(path, args.illuminant.into())
    } else if let Some(dir) = args.spectral_image {
        SceneSource::SpectralImage(dir)
    } else {
        return Err(Failure::from(
            "no scene: give --xyz, --image, --spectra, --reflectance or --spectral-image",
        ));
    };
    let request = RenderRequest {
        source,
        units: match args.units {
            UnitsArg::Absolute => SceneUnits::Absolute,
            UnitsArg::Relative => SceneUnits::Relative,
        },
        white_luminance: args.white_luminance,
        scene_white: args.scene_white,
        at,
        grid: args.grid,
        method: args.method,
        explain: args.explain,
        max_de00: args.max_de00,
        settings,
        output: if is_stdout(&args.output) {
            CodesOutput::Stdout
        } else {
            CodesOutput::File(args.output)
        },
    };
    // The model corrected by the calibration's measured greys where they predict
    // the held-out patches better, as `lut3d` and `verify`'s charts go through it.
    let (model, said_of_greys) = profile.output_model();
    if let Some(said) = said_of_greys {
        eprintln!("chromacal: {said}");
    }
    let outcome = render(&model, profile.units, &request)?;
    if let Some(csv) = &outcome.stdout {
        write_stdout(csv)?;
    }
    let text = if args.json {
        serde_json::to_string_pretty(&outcome.summary).map_err(|e| e.to_string())?
    } else {
        outcome.lines.join("\n")
    };
    // The codes may be on standard output: the summary then goes to standard error.
    if outcome.stdout.is_some() {
        eprintln!("{text}");
    } else {
        outln!("{text}")?;
    }
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
