//! Arguments several commands share: the devices of a calibration, a calibration
//! target, an instrument's address, an illuminant, a gamut mapping.

use std::path::PathBuf;

use chromacal::calibrate::devices::Overrides;
use chromacal::config::Sink;
use chromacal_crf::gamut::{GamutMapping, ScbOptions, SgckSource, UniformSpace};
use chromacal_instruments::devices::InstrumentAddress;

use super::shared::{Failure, positive_number};

/// Which instrument and display a calibration uses, when not the config's.
#[derive(clap::Args, Default)]
pub struct DeviceArgs {
    /// A serial instrument as KIND:PORT, e.g. pr670:/dev/ttyACM0, or argyll[:N] for
    /// what ArgyllCMS drives on its port N (see `chromacal instruments`).
    #[arg(long)]
    instrument: Option<String>,
    /// The screen socket of `chromacal emulate`, whose virtual monitor shows the patches.
    #[arg(long)]
    screen: Option<PathBuf>,
    /// Multiplies the instrument protocol's timeouts (for emulators run faster than real time).
    #[arg(long, value_parser = positive_number)]
    timing_scale: Option<f64>,
    /// Where patches go: window[:OUTPUT] (chromacal's full-screen window on an X11
    /// output, the primary by default; see `chromacal displays`), wayland[:OUTPUT]
    /// (a full-screen surface on a Wayland output, the first by default), resolve (a
    /// pattern generator connects to chromacal), web (a browser opens chromacal's
    /// patch page), emulator or simulated.
    #[arg(long, value_name = "SINK")]
    display: Option<String>,
    /// The X display of the window sink, e.g. :0 [default: $DISPLAY].
    #[arg(long, value_name = "DISPLAY")]
    x_display: Option<String>,
    /// The Wayland display of the wayland sink, e.g. wayland-0 or a socket path
    /// [default: $WAYLAND_DISPLAY].
    #[arg(long, value_name = "NAME")]
    wayland_display: Option<String>,
    /// Address the Resolve server or the web page listens on, e.g. 127.0.0.1:20002.
    #[arg(long, value_name = "ADDR")]
    listen: Option<String>,
    /// Ask on the terminal to aim the instrument each time the patch moves.
    #[arg(long)]
    prompt_positions: bool,
}

impl DeviceArgs {
    pub fn overrides(&self) -> Result<Overrides, Failure> {
        Ok(Overrides {
            instrument: match &self.instrument {
                Some(spec) => Some(parse_instrument(spec)?),
                None => None,
            },
            screen: self.screen.clone(),
            timing_scale: self.timing_scale,
            sink: parse_sink(self.display.as_deref())?,
            listen: self.listen.clone(),
            prompt_positions: self.prompt_positions,
            output: parse_sink_output(self.display.as_deref()),
            x_display: self.x_display.clone(),
            wayland_display: self.wayland_display.clone(),
        })
    }
}

/// `--display SINK[:OUTPUT]`: the sink.
pub fn parse_sink(display: Option<&str>) -> Result<Option<Sink>, Failure> {
    display
        .map(|text| Sink::parse(text.split_once(':').map_or(text, |(s, _)| s)))
        .transpose()
        .map_err(Failure::from)
}

/// `--display window:OUTPUT` or `wayland:OUTPUT`: the output, when one is named.
pub fn parse_sink_output(display: Option<&str>) -> Option<chromacal_display::x11::OutputSelector> {
    display
        .and_then(|t| t.split_once(':'))
        .filter(|(_, output)| !output.is_empty())
        .map(|(_, output)| chromacal_display::x11::OutputSelector::parse(output))
}

/// A calibration target on the command line (`export`, `profile current`, `lut load`).
#[derive(clap::Args, Default)]
pub struct TargetArgs {
    /// Calibration target white: native, D50, D55, D65, D75, 6500K or x,y (either
    /// case). Any of --white, --tone, --luminance asks for curves computed from the
    /// profile's model; without them, the curves the profile measured into place, if
    /// it has them.
    #[arg(long)]
    pub white: Option<String>,
    /// Calibration target tone curve: gamma:G, srgb, bt1886 or lstar (gamma:2.2 when
    /// --white or --luminance is given alone).
    #[arg(long)]
    pub tone: Option<String>,
    /// Calibration target white luminance in cd/m², or max (max when --white or
    /// --tone is given alone).
    #[arg(long)]
    pub luminance: Option<String>,
}

impl TargetArgs {
    /// The target, if any part of one was given.
    pub fn target(&self) -> Result<Option<chromacal_model::target::Target>, Failure> {
        chromacal::export::parse_target(
            self.white.as_deref(),
            self.tone.as_deref(),
            self.luminance.as_deref(),
        )
        .map_err(Failure::from)
    }
}

/// KIND:PORT, or argyll[:N].
pub fn parse_instrument(spec: &str) -> Result<InstrumentAddress, Failure> {
    InstrumentAddress::parse(spec).map_err(Failure::from)
}

/// A CIE illuminant on the command line (either case: D65 or d65).
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum IlluminantArg {
    A,
    C,
    D50,
    D65,
    F2,
    F7,
    F11,
}

impl From<IlluminantArg> for chromacal_color::spectrum::Illuminant {
    fn from(i: IlluminantArg) -> Self {
        match i {
            IlluminantArg::A => chromacal_color::spectrum::Illuminant::A,
            IlluminantArg::C => chromacal_color::spectrum::Illuminant::C,
            IlluminantArg::D50 => chromacal_color::spectrum::Illuminant::D50,
            IlluminantArg::D65 => chromacal_color::spectrum::Illuminant::D65,
            IlluminantArg::F2 => chromacal_color::spectrum::Illuminant::F2,
            IlluminantArg::F7 => chromacal_color::spectrum::Illuminant::F7,
            IlluminantArg::F11 => chromacal_color::spectrum::Illuminant::F11,
        }
    }
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum GamutArg {
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
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum SgckSourceArg {
    Srgb,
    AdobeRgb,
    P3,
    Rec2020,
}

impl SgckSourceArg {
    pub fn source(self) -> SgckSource {
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
    pub fn mapping(self, scb: ScbOptions, sgck: SgckSource) -> GamutMapping {
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
