//! The colour reproduction function (seed §4): the XYZ a scene asks for, turned into
//! the codes a calibrated display must be sent to show it.
//!
//! The path of one pixel, in order:
//!
//! 1. **tone** (`tone`): the scene's luminance mapped to what the display can give,
//!    chromaticity kept;
//! 2. **gamut** (`gamut`): a colour the display cannot show at that pixel's position
//!    (the spatial map makes a corner's gamut smaller than the centre's) brought in
//!    by the chosen mapping;
//! 3. **inverse model**: linear light per channel (the primary matrix inverted, the
//!    spatial gain of the position divided out, the additivity terms' fixed point
//!    when the profile has them), then each channel's transfer law inverted, exactly
//!    where the law has an inverse and by monotone search for tables;
//! 4. **codes** at the display's bit depth, and what the model says they show, so
//!    every pixel's remaining error (quantisation, mapping) is known.
//!
//! Spectra become XYZ before this (`spectral`), by one of the survey's methods.

pub mod explain;
pub mod gamut;
pub mod gamut_bench;
pub mod inverse_table;
pub mod lut3d;
mod nearest;
pub mod render;
pub mod scene;
pub mod spectral;
pub mod spectral_file;
pub mod spectral_image;
pub mod spectral_table;
pub mod tone;

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use chromacal_color::Xyz;
use chromacal_color::adaptation::{AdaptationTransform, adaptation_matrix};
use chromacal_color::difference::delta_e_2000;
use chromacal_color::spaces::{Lab, xyz_to_lab};
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::{Drive, MonitorModel, ScreenPosition};
use gamut::{GamutAt, GamutMapping, Smith, StoneCowanBeatty};
use inverse_table::{Instructions, InverseTable};
use tone::{SceneLuminance, ToneCurve, ToneOperator};

/// Pixels rendered together over the cores before they are handed on.
const BAND: usize = 1 << 16;

/// Pixels a core renders at a time into a scene's codes (`render_codes`).
const STRETCH: usize = 1 << 12;

/// `[f(0), f(1), f(2)]`: a channel-wise array written out, for the per-pixel paths
/// (`[0, 1, 2].map` was left a call there: a fifth of a render's time).
#[inline(always)]
fn per_channel<T>(mut f: impl FnMut(usize) -> T) -> [T; 3] {
    [f(0), f(1), f(2)]
}

/// The largest code from which the nearest codes are first screened with every
/// candidate's bounds at the largest step's size (`nearest::Neighbourhood::nearest`):
/// 10 bits and more, where the steps are alike enough for that to decide most pixels
/// (callgrind on a render: 7 % fewer instructions at 16 bits, 5 % at 10; at 8 bits it
/// leaves several candidates to be bounded again, and cost 4 % more).
const SCREENED_FROM: f64 = 1023.0;

/// How far inside [0, 1] a cube coordinate must be for [`ColourReproduction::well_inside`]:
/// far above what two ways of computing it differ by (10⁻¹⁵ of it), so that the colour
/// is inside by `GamutAt::contains` too, and far below a code step.
const WELL_INSIDE: f64 = 1e-6;

/// The top code from which the box's corners are screened to first order first
/// ([`nearest::Neighbourhood::sole_corner`]), 12 bits: there it leaves about a fifth
/// of pixels to the second-order screen, which then decides most, and it costs a
/// third less; at 10 bits it left half, and a render took longer.
const FIRST_ORDER_FROM: f64 = 4095.0;

/// `v.round() as u32` for a code `v` from 0 to 65535 (a scaled drive, at most 16
/// bits), −0 or NaN, without the call to `round` that a build for the baseline x86-64
/// makes of it (no SSE4.1): the truncation is the floor there, and `v` less its floor
/// is exact, so a half or more rounds up, as `round` does away from zero. (Not for
/// values from 2³² − ½ up, where the sum overflows and `as` would have saturated.)
/// The calls to `round`, `floor` and `ceil`, three each a pixel, were 5 % of a
/// render's instructions.
#[inline(always)]
pub(crate) fn round_code(v: f64) -> u32 {
    let floor = v as u32;
    floor + u32::from(v - f64::from(floor) >= 0.5)
}

/// `v.ceil() as u32` for a code `v` as [`round_code`] takes, without the call.
#[inline(always)]
fn ceil_code(v: f64) -> u32 {
    let floor = v as u32;
    floor + u32::from(f64::from(floor) < v)
}

/// Pixels whose inversion ΔE00 `render_codes` measures, about (every pixel of a
/// smaller scene): a 2048² image is measured on one pixel in 64.
pub const INVERSION_SAMPLE: usize = 1 << 16;

/// One pixel in how many `render_codes` measures the inversion of, in a scene of
/// `pixels` pixels: 1 up to [`INVERSION_SAMPLE`] pixels.
pub fn inversion_stride(pixels: usize) -> usize {
    pixels.div_ceil(INVERSION_SAMPLE).max(1)
}

/// Whether `render_codes` measures the inversion of pixel `index` when it measures
/// one pixel in `stride`: those whose index times the golden ratio falls in the first
/// 1/`stride` of a unit (a Weyl sequence). Spread over the image, not the same columns
/// in every row as every `stride`-th pixel would be of an image `stride` divides.
pub fn inversion_measured(index: usize, stride: usize) -> bool {
    const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;
    stride <= 1 || ((index as u64).wrapping_mul(GOLDEN) >> 32) < (1u64 << 32) / stride as u64
}

/// One pixel as `render_each` hands it on.
struct PixelOutcome {
    codes: [u32; 3],
    target: Xyz,
    mapped: Xyz,
    outside: bool,
    mapping_delta_e00: f64,
    /// What the codes show and its ΔE00 from `mapped`, where measured.
    inversion: Option<(Xyz, f64)>,
}

/// What every pixel of one render shares (`ColourReproduction::pixel_path`).
struct PixelPath<'s> {
    scene: &'s Scene,
    /// The scene with its white carried to the display's, or the scene itself.
    adapted: std::borrow::Cow<'s, Scene>,
    curve: ToneCurve,
    /// Each pixel's target and gamut, made beforehand only for a mapping fitted to
    /// the whole scene (Stone–Cowan–Beatty, Smith); empty otherwise.
    targets: Vec<Xyz>,
    gamuts: Vec<GamutAt>,
    /// The gamut at the centre: every pixel's on a uniform screen.
    centre: GamutAt,
    uniform: bool,
    /// The mapping leaves a colour inside the gamut as it is (all but SGCK's
    /// compression and the mappings fitted to the whole scene), so a colour well
    /// inside needs no gamut made at its place ([`ColourReproduction::well_inside`]).
    keeps_inside: bool,
    transform: Option<SceneTransform>,
    mapping: GamutMapping,
    quantiser: Quantiser,
    /// One pixel in how many has its inversion measured.
    stride: usize,
}

/// What one core keeps of its stretch of a scene's pixels besides their codes.
#[derive(Default)]
struct Stretch {
    /// How many pixels the mapping left as they were (0 ΔE00).
    unmoved: usize,
    /// The mapping's ΔE00 of the others, in order.
    moved: Vec<f64>,
    /// The mapping's ΔE00 of the pixels outside the gamut, in order.
    outside: Vec<f64>,
    /// The inversion's ΔE00 where measured, in order.
    inversion: Vec<f64>,
}

/// How a run's drives become codes: the largest code, whether the nearest codes are
/// chosen, and for those, in a scene with at least half as many pixels as codes, each
/// channel's excitation at every code: the law evaluated once a code rather than
/// twice a pixel (at 16 bits, 1.5 MB).
struct Quantiser {
    top: f64,
    nearest: bool,
    lights: Option<[Vec<f64>; 3]>,
    /// The instructions the first-order screen is run with (`pulp`).
    arch: pulp::Arch,
}

impl Quantiser {
    fn new(model: &MonitorModel, settings: &RenderSettings, pixels: usize) -> Quantiser {
        let top = ((1u64 << settings.bits) - 1) as f64;
        let nearest = settings.codes == CodeChoice::NearestInDeltaE00;
        let lights = (nearest && 2 * pixels > top as usize).then(|| {
            [0, 1, 2].map(|c| {
                (0..=top as u32)
                    .map(|code| model.laws[c].excitation(code as f64 / top))
                    .collect()
            })
        });
        Quantiser {
            top,
            nearest,
            lights,
            arch: pulp::Arch::new(),
        }
    }

    /// Channel `c`'s excitation at `code`, from the table or the law.
    fn light(&self, model: &MonitorModel, c: usize, code: u32) -> f64 {
        match &self.lights {
            Some(lights) => lights[c][code as usize],
            None => model.laws[c].excitation(code as f64 / self.top),
        }
    }
}

/// Why a scene could not be rendered.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CrfError {
    #[error("the profile's primary matrix is singular: no drive reproduces a given XYZ")]
    SingularMatrix,
    #[error("a bit depth of {0} (1 to 16)")]
    BitDepth(u32),
    #[error("the scene has no lit pixel, so the {0} tone operator has nothing to adapt to")]
    NothingLit(String),
    #[error(
        "no lit pixel of the scene lies in Ward's focus area: give a --focus rectangle the scene covers"
    )]
    NothingLitInFocus,
    #[error("pixel {index}: {what}")]
    BadPixel { index: usize, what: String },
    #[error("chromatic adaptation needs the scene's white, and none was given")]
    NoSceneWhite,
}

/// How a scene is rendered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Carry the scene's white to the display's (von Kries in the cone space of the
    /// transform), for an observer adapted to the screen as in a dark room (seed
    /// §4.2.3, §4.2.5); needs the scene's white. `None`: the XYZ as asked.
    pub adaptation: Option<AdaptationTransform>,
    pub tone: ToneOperator,
    pub gamut: GamutMapping,
    /// Bits per channel of the codes sent to the display.
    pub bits: u32,
    /// How the continuous drive becomes codes.
    pub codes: CodeChoice,
}

/// How a pixel's continuous drive becomes codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CodeChoice {
    /// Each channel rounded on its own.
    Rounded,
    /// Of the 8 codes around the drive (each channel's code below and above it), the
    /// one the forward model shows nearest the colour asked for, in ΔE00. Rounding each
    /// channel on its own is not that: at 8 bits, for 42 of 660 in-gamut colours a
    /// neighbouring code was closer by more than 0.1 ΔE00 (worst 0.89 against 0.38),
    /// since a code step moves the colour by different amounts, in different
    /// directions, in each channel. Eight forward evaluations a pixel, and a ΔE00
    /// only for the corners that could be nearest (`nearest`).
    #[default]
    NearestInDeltaE00,
}

/// One pixel of a scene: its XYZ (in the profile's units, cd/m² for an absolute
/// profile) and where on the screen it is shown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScenePixel {
    pub xyz: Xyz,
    pub position: ScreenPosition,
}

/// A scene: its pixels and, when known, its white (the XYZ of a perfect white in
/// it, in the pixels' units).
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    pub pixels: Vec<ScenePixel>,
    pub white: Option<Xyz>,
}

/// What one pixel became.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RenderedPixel {
    /// Codes per channel, 0 … 2^bits − 1.
    pub codes: [u32; 3],
    /// The colour asked for after tone reproduction.
    pub target: [f64; 3],
    /// What the gamut mapping made of it.
    pub mapped: [f64; 3],
    /// What the display shows for `codes` there, by the profile's forward model.
    pub shown: [f64; 3],
    /// The target lay outside the gamut at this position.
    pub outside: bool,
    /// ΔE00 between target and mapped colour (what the mapping changed).
    pub mapping_delta_e00: f64,
    /// ΔE00 between mapped and shown colour (the codes' quantisation and the
    /// inversion).
    pub inversion_delta_e00: f64,
}

/// What a rendering did, for the user.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RenderSummary {
    pub pixels: usize,
    pub outside: usize,
    pub tone: String,
    pub gamut: String,
    /// ΔE00 the mapping introduced, over every pixel.
    pub mapping_all: Option<ErrorStats>,
    /// The same over the pixels that were outside.
    pub mapping_outside: Option<ErrorStats>,
    /// ΔE00 between mapped colour and what the codes show.
    pub inversion: Option<ErrorStats>,
    /// Stone–Cowan–Beatty's chosen transform, when that mapping was used.
    pub stone_cowan_beatty: Option<StoneCowanBeatty>,
    /// Smith's transform, when that mapping was used.
    pub smith: Option<Smith>,
    /// For an image on a display with a brightness limiter: its mean light and the
    /// gain the limiter puts on all of it (`MonitorModel::image_light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image_light: Option<chromacal_model::monitor::ImageLight>,
}

/// The scene-wide transform a mapping chose, if it is one.
#[derive(Debug, Clone, PartialEq)]
enum SceneTransform {
    StoneCowanBeatty(StoneCowanBeatty),
    Smith(Smith),
    /// SGCK's source gamut, put on the display's centre white and black.
    SgckSource(GamutAt),
}

/// A scene rendered for one display.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendering {
    pub pixels: Vec<RenderedPixel>,
    pub summary: RenderSummary,
}

impl Rendering {
    /// What `model` says the display shows for each pixel's codes, where `scene`
    /// puts it: `shown`, `inversion_delta_e00` and the summary's inversion
    /// recomputed. For codes chosen with a reduced model (`--explain`), this is the
    /// full profile's prediction of what the screen will show.
    pub fn shown_by(&mut self, model: &MonitorModel, scene: &Scene, bits: u32) {
        let top = ((1u64 << bits) - 1) as f64;
        let white = model.white();
        for (pixel, at) in self.pixels.iter_mut().zip(&scene.pixels) {
            let shown = model.forward(pixel.codes.map(|c| f64::from(c) / top), at.position);
            pixel.shown = shown.into();
            pixel.inversion_delta_e00 = delta_e00_xyz(&Xyz::from(pixel.mapped), &shown, &white);
        }
        let inversion: Vec<f64> = self.pixels.iter().map(|p| p.inversion_delta_e00).collect();
        self.summary.inversion = ErrorStats::of(&inversion);
    }
}

/// The colour reproduction function of one display: its model, prepared once.
#[derive(Debug, Clone)]
pub struct ColourReproduction<'a> {
    model: &'a MonitorModel,
    /// M⁻¹, computed once.
    matrix_inverse: Matrix3<f64>,
    /// E_c(1) of each channel.
    full: [f64; 3],
    /// Each channel's gain in white through the HLG OOTF where it is more than alone
    /// (`gamut_with_gains`), 1 without the OOTF: made once, not at every pixel.
    ootf_in_white: [f64; 3],
    /// Each law's inverse, tabulated.
    tables: [InverseTable; 3],
    /// The display's centre white: the reference white of every ΔE00 here.
    white: Xyz,
}

impl<'a> ColourReproduction<'a> {
    pub fn new(model: &'a MonitorModel) -> Result<Self, CrfError> {
        let matrix_inverse = model.matrix.try_inverse().ok_or(CrfError::SingularMatrix)?;
        Ok(ColourReproduction {
            model,
            matrix_inverse,
            full: [0, 1, 2].map(|c| model.laws[c].full_drive_excitation()),
            ootf_in_white: model.ootf_gains(&[1.0; 3]).map(|g| g.max(1.0)),
            tables: [0, 1, 2].map(|c| InverseTable::of(&model.laws[c])),
            white: model.white(),
        })
    }

    pub fn white(&self) -> Xyz {
        self.white
    }

    /// The gamut at `position`: P_c = K_c(p) E_c(1) m_c; `None` where a channel's
    /// spatial gain gives no light (a hand-made map), which no colour can be shown at.
    ///
    /// Through the HLG OOTF (`AdditivityTerms::hlg_ootf`) with γ > 1 a channel gives
    /// more light in a mixture than alone, up to (1 / w_c)^(γ − 1) times in white,
    /// and the colours the display shows are Y_S^(γ−1) Σ_c P_c E_c over the
    /// scene-light cube. The box of P_c (1 / w_c)^(γ − 1) holds them all and meets
    /// them on the grey axis, where they are t^γ times white, and at black and white:
    /// on the box's other corners the OOTF gives less (a secondary (w_a + w_b)^(γ−1)
    /// of the box's), and a colour between is inverted by the model itself, each
    /// channel clipped. With γ < 1 (a dim display, a bright room) a channel gives the
    /// most alone: the box is the channels' own.
    pub fn gamut_at(&self, position: ScreenPosition) -> Option<GamutAt> {
        self.gamut_with_gains(self.model.spatial.gains(position))
    }

    /// The gamut where the spatial map's gains are `k`.
    fn gamut_with_gains(&self, k: [f64; 3]) -> Option<GamutAt> {
        let mut primaries = self.model.matrix;
        // A channel's gain in white, (1 / w_c)^(γ − 1) from the shares (or what its
        // law gives there, through the laws), where it is more than alone.
        let in_white = self.ootf_in_white;
        for (c, ((gain, full), in_white)) in k.iter().zip(self.full).zip(in_white).enumerate() {
            let scale = gain * full * in_white;
            if !(scale > 0.0 && scale.is_finite()) {
                return None;
            }
            primaries.column_mut(c).scale_mut(scale);
        }
        GamutAt::new(self.model.black, primaries)
    }

    /// Whether `xyz` lies inside the gamut where the spatial map's gains are `k` by
    /// more than rounding could move it: each cube coordinate, from M⁻¹ and each
    /// channel's scale as [`Self::gamut_with_gains`] takes them (rather than from the
    /// inverse of the scaled matrix, which `GamutAt::contains` uses), within
    /// [`WELL_INSIDE`] of [0, 1] and inside. On a screen with a spatial map the gamut
    /// at a pixel's place is a 3 × 3 inverse; for a colour inside it, that was the
    /// most of what gamut mapping cost a render.
    fn well_inside(&self, xyz: &Xyz, k: [f64; 3]) -> bool {
        let light = self.matrix_inverse * (xyz - self.model.black);
        (0..3).all(|c| {
            let scale = k[c] * self.full[c] * self.ootf_in_white[c];
            scale > 0.0
                && scale.is_finite()
                && (WELL_INSIDE..=1.0 - WELL_INSIDE).contains(&(light[c] / scale))
        })
    }

    /// The drive that shows `xyz` (inside the gamut) at `position`: cube coordinates
    /// to excitations, each law inverted; through the whole model's fixed point when
    /// the profile has additivity terms.
    /// Each law's inverse comes from its table (`inverse_table`); `drive_exact_for`
    /// inverts the laws themselves.
    pub fn drive_for(&self, xyz: &Xyz, position: ScreenPosition) -> Drive {
        self.drive_with_gains(xyz, position, self.model.spatial.gains(position))
    }

    /// [`Self::drive_for`] where the spatial map's gains are `k` (those at `position`).
    fn drive_with_gains(&self, xyz: &Xyz, position: ScreenPosition, k: [f64; 3]) -> Drive {
        if !self.model.terms.is_empty() {
            return self.drive_exact_for(xyz, position);
        }
        let light = self.matrix_inverse * (xyz - self.model.black);
        per_channel(|c| {
            let scale = k[c] * self.full[c];
            let share = if scale > 0.0 { light[c] / scale } else { 0.0 };
            self.tables[c].drive(share)
        })
    }

    /// 16-bit codes for many colours at one position each, the inner loop of a large
    /// scene: `drive_for` written out for throughput (the matrix rows scaled by each
    /// channel's full light at the position, the tables read in place). Profiles with
    /// additivity terms go through `drive_for`.
    pub fn codes16(
        &self,
        xyz: &[Xyz],
        positions: impl Fn(usize) -> ScreenPosition,
        out: &mut [[u16; 3]],
    ) {
        self.codes16_of(xyz, positions, out, Instructions::Best);
    }

    /// As [`Self::codes16`], for colours held as 32-bit floats, as images carry them
    /// (PFM, OpenEXR) and as other colour engines take them: half the memory `Xyz`'s
    /// doubles take, and memory is what bounds the loop on a large image.
    pub fn codes16_f32(
        &self,
        xyz: &[[f32; 3]],
        positions: impl Fn(usize) -> ScreenPosition,
        out: &mut [[u16; 3]],
    ) {
        self.codes16_of(xyz, positions, out, Instructions::Best);
    }

    /// [`Self::codes16`] for colours of either precision: through `drive_for` with
    /// additivity terms, else the batch loop ([`inverse_table::BatchInverse`]) compiled
    /// for `instructions`.
    fn codes16_of<T: Colour>(
        &self,
        xyz: &[T],
        positions: impl Fn(usize) -> ScreenPosition,
        out: &mut [[u16; 3]],
        instructions: Instructions,
    ) {
        if !self.model.terms.is_empty() {
            for (k, (x, o)) in xyz.iter().zip(out.iter_mut()).enumerate() {
                *o = self
                    .drive_for(&x.xyz(), positions(k))
                    .map(|d| (d * 65535.0 + 0.5) as u16);
            }
            return;
        }
        let m = &self.matrix_inverse;
        let inverse = inverse_table::BatchInverse {
            rows: [0, 1, 2]
                .map(|c| [m[(c, 0)], m[(c, 1)], m[(c, 2)]].map(|v| (v / self.full[c]) as f32)),
            black: [self.model.black.x, self.model.black.y, self.model.black.z].map(|v| v as f32),
            tables: [&self.tables[0], &self.tables[1], &self.tables[2]],
        };
        let uniform = matches!(
            self.model.spatial,
            chromacal_model::spatial::SpatialMap::Uniform
        );
        let gains = (!uniform).then_some(|k| self.model.spatial.gains(positions(k)));
        inverse.codes16(xyz, T::xyz_f32, gains, out, instructions);
    }

    /// As `drive_for`, each law inverted exactly (and the additivity terms' fixed
    /// point when the profile has them): slower, for checking the tables.
    pub fn drive_exact_for(&self, xyz: &Xyz, position: ScreenPosition) -> Drive {
        if !self.model.terms.is_empty() {
            return match self.model.inverse(xyz, position) {
                Ok(r) => r.drive,
                Err(_) => [0.0; 3],
            };
        }
        let k = self.model.spatial.gains(position);
        let light = self.matrix_inverse * (xyz - self.model.black);
        [0, 1, 2].map(|c| {
            let e = if k[c] > 0.0 { light[c] / k[c] } else { 0.0 };
            self.model.laws[c].drive(e.clamp(0.0, self.full[c]))
        })
    }

    /// Render `scene` with `settings`.
    pub fn render(&self, scene: &Scene, settings: &RenderSettings) -> Result<Rendering, CrfError> {
        let mut pixels = Vec::with_capacity(scene.pixels.len());
        let transform = self.render_each(scene, settings, 1, |p| {
            // A stride of 1 measures every pixel's inversion.
            let (shown, inversion_delta_e00) = p.inversion.unwrap_or((p.mapped, f64::NAN));
            pixels.push(RenderedPixel {
                codes: p.codes,
                target: p.target.into(),
                mapped: p.mapped.into(),
                shown: shown.into(),
                outside: p.outside,
                mapping_delta_e00: p.mapping_delta_e00,
                inversion_delta_e00,
            })
        })?;
        let summary = summarise(&pixels, settings, transform);
        Ok(Rendering { pixels, summary })
    }

    /// [`ColourReproduction::render`]'s codes and summary alone, for an image written
    /// as codes: each pixel's codes as 16-bit values (bits ≤ 16), 6 bytes a pixel
    /// where the whole rendered pixel is 112, and the mapping's ΔE00 of the pixels it
    /// moved (those it left are counted). The same codes. The mapping's ΔE00 is
    /// summarised over every pixel; the inversion's, which only the
    /// codes' quantisation makes, is measured on every pixel of a scene up to
    /// [`INVERSION_SAMPLE`] pixels and on about that many of a larger scene, chosen by
    /// [`inversion_measured`] (the summary says how many).
    pub fn render_codes(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
    ) -> Result<(Vec<[u16; 3]>, RenderSummary), CrfError> {
        let n = scene.pixels.len();
        let stride = inversion_stride(n);
        let path = self.pixel_path(scene, settings, stride)?;
        // Each core fills its own stretch of the codes and keeps its own ΔE00s; the
        // stretches are joined in the scene's order, so the summary is the one a
        // pixel-by-pixel render makes (the same sums in the same order) and the bad
        // pixel reported is the first.
        let mut codes = vec![[0u16; 3]; n];
        let stretches: Vec<Result<Stretch, CrfError>> = codes
            .par_chunks_mut(STRETCH)
            .enumerate()
            .map(|(s, out)| {
                let mut stretch = Stretch::default();
                for (k, slot) in out.iter_mut().enumerate() {
                    let p = self.render_pixel(&path, s * STRETCH + k)?;
                    *slot = p.codes.map(|c| c as u16);
                    // A pixel the mapping left as it was is counted, not kept: most
                    // of an image, and 0 in every statistic but the count.
                    if p.mapping_delta_e00 == 0.0 {
                        stretch.unmoved += 1;
                    } else {
                        stretch.moved.push(p.mapping_delta_e00);
                    }
                    if p.outside {
                        stretch.outside.push(p.mapping_delta_e00);
                    }
                    if let Some((_, e)) = p.inversion {
                        stretch.inversion.push(e);
                    }
                }
                Ok(stretch)
            })
            .collect();
        let mut whole = Stretch::default();
        for stretch in stretches {
            let stretch = stretch?;
            whole.unmoved += stretch.unmoved;
            whole.moved.extend(stretch.moved);
            whole.outside.extend(stretch.outside);
            whole.inversion.extend(stretch.inversion);
        }
        let summary = summary_of(
            n,
            ErrorStats::of_with_zeros(&whole.moved, whole.unmoved),
            &whole.outside,
            &whole.inversion,
            settings,
            path.transform,
        );
        Ok((codes, summary))
    }

    /// Render every pixel of `scene`, handing each to `each` in order, its inversion
    /// measured on one pixel in `stride` ([`inversion_measured`]); the scene-wide
    /// transform the mapping was fitted with, if any.
    fn render_each(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        stride: usize,
        mut each: impl FnMut(PixelOutcome),
    ) -> Result<Option<SceneTransform>, CrfError> {
        let path = self.pixel_path(scene, settings, stride)?;
        // Over all cores, a band of pixels at a time, handed on in the scene's order
        // (the first bad pixel is the one reported, as one by one): the memory is one
        // band's, whatever the scene's size.
        let mut band = Vec::with_capacity(BAND);
        for start in (0..scene.pixels.len()).step_by(BAND) {
            let end = (start + BAND).min(scene.pixels.len());
            (start..end)
                .into_par_iter()
                .with_min_len(1024)
                .map(|index| self.render_pixel(&path, index))
                .collect_into_vec(&mut band);
            for pixel in band.drain(..) {
                each(pixel?);
            }
        }
        Ok(path.transform)
    }

    /// What every pixel of a render of `scene` shares, made once: the checks of the
    /// scene and the settings, the scene as adapted, its tone curve, the scene-wide
    /// transform, and the quantiser.
    fn pixel_path<'s>(
        &self,
        scene: &'s Scene,
        settings: &RenderSettings,
        stride: usize,
    ) -> Result<PixelPath<'s>, CrfError> {
        if !(1..=16).contains(&settings.bits) {
            return Err(CrfError::BitDepth(settings.bits));
        }
        if let Some((index, p)) = scene
            .pixels
            .iter()
            .enumerate()
            .find(|(_, p)| !p.xyz.iter().all(|v| v.is_finite()))
        {
            return Err(CrfError::BadPixel {
                index,
                what: format!("XYZ {:?} is not finite", p.xyz.as_slice()),
            });
        }
        // Per pixel, what is needed is made as the pixel is mapped: the adapted scene
        // only when it differs, each pixel's gamut and target in the loop. Only the
        // mappings fitted to the whole scene (Stone–Cowan–Beatty, Smith) keep them all.
        // (A 2048² image peaked at 1.83 GB holding them; the codes are the same.)
        let adapted = self.adapt(scene, settings.adaptation)?;
        let curve = self.tone_curve(&adapted, settings.tone)?;
        let whole_scene = matches!(
            settings.gamut,
            GamutMapping::StoneCowanBeatty(_) | GamutMapping::Smith
        );
        let targets: Vec<Xyz> = if whole_scene {
            adapted
                .pixels
                .iter()
                .map(|p| p.xyz * curve.factor(p.xyz.y))
                .collect()
        } else {
            Vec::new()
        };
        let gamuts: Vec<GamutAt> = if whole_scene {
            scene
                .pixels
                .iter()
                .enumerate()
                .map(|(index, p)| self.gamut_of(index, p))
                .collect::<Result<_, _>>()?
        } else {
            Vec::new()
        };
        let centre = self
            .gamut_at(ScreenPosition::CENTRE)
            .ok_or(CrfError::SingularMatrix)?;
        // The scene's white after tone reproduction: its neutrals' direction and the
        // level above which a colour is a highlight.
        let scene_white = adapted.white.map(|w| w * curve.factor(w.y));
        let transform = match settings.gamut {
            GamutMapping::StoneCowanBeatty(options) => {
                let with: Vec<(Xyz, &GamutAt)> =
                    targets.iter().copied().zip(gamuts.iter()).collect();
                let grey = scene_white.filter(|w| w.y > 0.0).unwrap_or(self.white);
                StoneCowanBeatty::fit(&with, &centre, &grey, scene_white.map(|w| w.y), options)
                    .map(SceneTransform::StoneCowanBeatty)
            }
            GamutMapping::Smith => {
                Smith::fit(targets.iter().map(|t| t.y), scene_white.map(|w| w.y))
                    .map(SceneTransform::Smith)
            }
            GamutMapping::Sgck(source) => source
                .gamut(&centre.white(), &centre.black())
                .map(SceneTransform::SgckSource),
            _ => None,
        };
        // A uniform screen has one gamut everywhere: made once.
        let uniform = matches!(
            self.model.spatial,
            chromacal_model::spatial::SpatialMap::Uniform
        );
        Ok(PixelPath {
            scene,
            adapted,
            curve,
            targets,
            gamuts,
            centre,
            uniform,
            keeps_inside: matches!(
                settings.gamut,
                GamutMapping::Clip
                    | GamutMapping::GreyAxis(_)
                    | GamutMapping::Perpendicular
                    | GamutMapping::PerpendicularLab
                    | GamutMapping::Hpminde
            ),
            transform,
            mapping: settings.gamut,
            quantiser: Quantiser::new(self.model, settings, scene.pixels.len()),
            stride,
        })
    }

    /// The gamut at pixel `index` (`p`) of a scene, or why it has none.
    fn gamut_of(&self, index: usize, p: &ScenePixel) -> Result<GamutAt, CrfError> {
        self.gamut_at(p.position).ok_or_else(|| no_gamut(index, p))
    }

    /// Pixel `index` of `path`'s scene through the whole path: tone, gamut, inverse
    /// model and codes.
    #[inline]
    fn render_pixel(&self, path: &PixelPath, index: usize) -> Result<PixelOutcome, CrfError> {
        let pixel = &path.scene.pixels[index];
        // The spatial map's gains at the pixel, for its gamut, its drive and its codes.
        let gains = self.model.spatial.gains(pixel.position);
        let made;
        // Targets made beforehand are those of a mapping fitted to the whole scene.
        // `None` for a colour well inside the gamut at its place, which a mapping
        // that leaves such colours as they are does not need.
        let (target, gamut) = if path.targets.is_empty() {
            let xyz = path.adapted.pixels[index].xyz;
            let target = xyz * path.curve.factor(xyz.y);
            if path.uniform {
                (target, Some(&path.centre))
            } else if path.keeps_inside && self.well_inside(&target, gains) {
                (target, None)
            } else {
                // Made in place (a gamut is 168 bytes, and copies of it were a
                // twelfth of a render's time).
                made = self.gamut_with_gains(gains);
                match &made {
                    Some(gamut) => (target, Some(gamut)),
                    None => return Err(no_gamut(index, pixel)),
                }
            }
        } else {
            (path.targets[index], Some(&path.gamuts[index]))
        };
        let (mut outside, mut mapped) = match gamut {
            Some(gamut) => (
                !gamut.contains(&target),
                self.map(path.mapping, path.transform.as_ref(), gamut, &target),
            ),
            None => (false, target),
        };
        let drive = match self.model.terms.hlg_ootf {
            // The HLG OOTF's box holds colours the display cannot show (`gamut_at`):
            // those the model's own inverse has to clip are outside too, and become
            // what their clipped drive shows.
            Some(_) => match self.model.inverse(&mapped, pixel.position) {
                Ok(r) => {
                    if r.clipped {
                        outside = true;
                        mapped = self.model.forward(r.drive, pixel.position);
                    }
                    r.drive
                }
                Err(_) => [0.0; 3],
            },
            None => self.drive_with_gains(&mapped, pixel.position, gains),
        };
        let measured = inversion_measured(index, path.stride);
        let quantiser = &path.quantiser;
        // Each colour's L*a*b* made once for the ΔE00 it takes part in, and only
        // where one is wanted.
        let mapped_lab = (quantiser.nearest || measured || mapped != target)
            .then(|| xyz_to_lab(&mapped, &self.white));
        let (codes, inversion) = self.codes_for(
            drive,
            &mapped,
            mapped_lab.as_ref(),
            (pixel.position, gains),
            quantiser,
            measured,
        );
        Ok(PixelOutcome {
            codes,
            target,
            mapped,
            outside,
            // A colour the mapping left as it was is 0 away from itself.
            mapping_delta_e00: match mapped_lab {
                Some(lab) if mapped != target => {
                    delta_e_2000(&xyz_to_lab(&target, &self.white), &lab)
                }
                _ => 0.0,
            },
            inversion,
        })
    }

    /// The codes for `drive`, chosen as `quantiser` says to show the colour `mapped`
    /// (its L*a*b* `mapped_lab`, which the nearest codes and a measured pixel need) at
    /// `position`, where the spatial map's gains are `gains`; when `measured`, what the
    /// display shows for them and its ΔE00 from `mapped`. For the nearest codes each
    /// channel's light at the code below and above the drive comes from the quantiser,
    /// once each; every corner's ΔE00 is bounded from its step from `mapped`
    /// ([`nearest::Neighbourhood::nearest`]) and only the corners that could be
    /// nearest are measured.
    fn codes_for(
        &self,
        drive: Drive,
        mapped: &Xyz,
        mapped_lab: Option<&Lab>,
        (position, gains): (ScreenPosition, [f64; 3]),
        quantiser: &Quantiser,
        measured: bool,
    ) -> ([u32; 3], Option<(Xyz, f64)>) {
        let top = quantiser.top;
        let scaled = per_channel(|c| drive[c].clamp(0.0, 1.0) * top);
        let rounded = per_channel(|c| round_code(scaled[c]));
        let (true, Some(mapped_lab)) = (quantiser.nearest, mapped_lab) else {
            let inversion = mapped_lab.filter(|_| measured).map(|lab| {
                let shown = self
                    .model
                    .forward(rounded.map(|c| c as f64 / top), position);
                (shown, delta_e_2000(lab, &xyz_to_lab(&shown, &self.white)))
            });
            return (rounded, inversion);
        };
        let low = per_channel(|c| scaled[c] as u32);
        let high = per_channel(|c| ceil_code(scaled[c]).min(top as u32));
        let low_light = per_channel(|c| quantiser.light(self.model, c, low[c]));
        let high_light = per_channel(|c| {
            if high[c] == low[c] {
                low_light[c]
            } else {
                quantiser.light(self.model, c, high[c])
            }
        });
        // `MonitorModel::forward` of the codes, from their channels' excitations.
        let shows = |codes: [u32; 3]| {
            let e = per_channel(|c| {
                let light = if codes[c] == low[c] {
                    low_light[c]
                } else {
                    high_light[c]
                };
                gains[c] * light
            });
            self.model.light_above_black(&Vector3::from(e)) + self.model.black
        };
        let corner_codes = |corner: usize| {
            per_channel(|c| {
                if corner >> c & 1 == 1 {
                    high[c]
                } else {
                    low[c]
                }
            })
        };
        // The rounded codes first, then the corners in order: the literal search's.
        // (Each channel's rounded code is its low or high one.) A corner whose codes
        // an earlier one has is left out: with the same ΔE00 it cannot be strictly
        // nearer. That is every corner high in a channel whose drive is on a code, as
        // a colour clipped to the gamut's faces has.
        let rounded_corner = (0..3).fold(0, |k, c| k | usize::from(rounded[c] != low[c]) << c);
        let on_a_code = (0..3).fold(0, |k, c| k | usize::from(high[c] == low[c]) << c);
        let mut corners = [rounded_corner; 9];
        let mut count = 1;
        for corner in 0..8 {
            if corner & on_a_code == 0 && corner_codes(corner) != rounded {
                corners[count] = corner;
                count += 1;
            }
        }
        let neighbourhood = nearest::Neighbourhood::at(mapped, mapped_lab, &self.white);
        // The ΔE00 of a candidate that must be measured: from what its codes show,
        // as `MonitorModel::forward` gives it.
        let exact = |k: usize| {
            let shown = shows(corner_codes(corners[k]));
            delta_e_2000(mapped_lab, &xyz_to_lab(&shown, &self.white))
        };
        // Each corner's step from the colour asked: without additivity terms, what
        // the display shows is linear in the channels' light, so the low corner's step
        // and the box's three edges, added, give every corner's.
        let box_steps = || {
            let low_step = shows(low) - mapped;
            let edges = per_channel(|c| {
                self.model.matrix.column(c) * (gains[c] * (high_light[c] - low_light[c]))
            });
            (low_step, edges)
        };
        // From 12 bits, the box's corners screened from those four steps first.
        if top >= FIRST_ORDER_FROM && self.model.terms.is_empty() {
            let (low_step, edges) = box_steps();
            let edges = edges.map(|e| [e[0], e[1], e[2]]);
            let low_step = [low_step[0], low_step[1], low_step[2]];
            if let Some(k) =
                neighbourhood.sole_corner(low_step, &edges, &corners[..count], quantiser.arch)
            {
                let codes = corner_codes(corners[k]);
                return (codes, measured.then(|| (shows(codes), exact(k))));
            }
        }
        let steps: [[f64; 8]; 3] = if self.model.terms.is_empty() {
            let (low_step, edges) = box_steps();
            per_channel(|axis| {
                std::array::from_fn(|corner| {
                    let mut step = low_step[axis];
                    for (c, edge) in edges.iter().enumerate() {
                        if corner >> c & 1 == 1 {
                            step += edge[axis];
                        }
                    }
                    step
                })
            })
        } else {
            let shown: [Xyz; 8] = std::array::from_fn(|corner| shows(corner_codes(corner)));
            per_channel(|axis| std::array::from_fn(|corner| shown[corner][axis] - mapped[axis]))
        };
        let (k, error) = neighbourhood.nearest(
            &steps,
            &corners[..count],
            exact,
            measured,
            top >= SCREENED_FROM,
        );
        let codes = corner_codes(corners[k]);
        (codes, error.filter(|_| measured).map(|e| (shows(codes), e)))
    }

    /// The scene with its white carried to the display's chromaticity (luminance
    /// kept), or as it is.
    fn adapt<'s>(
        &self,
        scene: &'s Scene,
        transform: Option<AdaptationTransform>,
    ) -> Result<std::borrow::Cow<'s, Scene>, CrfError> {
        let Some(transform) = transform else {
            return Ok(std::borrow::Cow::Borrowed(scene));
        };
        let source = scene.white.ok_or(CrfError::NoSceneWhite)?;
        let destination = self.white * (source.y / self.white.y);
        let m = adaptation_matrix(transform, &source, &destination);
        Ok(std::borrow::Cow::Owned(Scene {
            pixels: scene
                .pixels
                .iter()
                .map(|p| ScenePixel {
                    xyz: m * p.xyz,
                    position: p.position,
                })
                .collect(),
            white: Some(destination),
        }))
    }

    fn tone_curve(&self, scene: &Scene, tone: ToneOperator) -> Result<ToneCurve, CrfError> {
        if tone == ToneOperator::Colorimetric {
            return Ok(ToneCurve::Scale(1.0));
        }
        let mut stats = SceneLuminance::of(
            scene.pixels.iter().map(|p| p.xyz.y),
            scene.white.map(|w| w.y),
        )
        .ok_or_else(|| CrfError::NothingLit(tone.name()))?;
        if let ToneOperator::Ward { focus: Some(area) } = tone {
            let looked_at = SceneLuminance::of(
                scene
                    .pixels
                    .iter()
                    .filter(|p| area.contains(p.position.x, p.position.y))
                    .map(|p| p.xyz.y),
                None,
            )
            .ok_or(CrfError::NothingLitInFocus)?;
            stats.mean = looked_at.mean;
        }
        Ok(tone.curve(&stats, self.white.y))
    }

    fn map(
        &self,
        mapping: GamutMapping,
        transform: Option<&SceneTransform>,
        gamut: &GamutAt,
        target: &Xyz,
    ) -> Xyz {
        match mapping {
            GamutMapping::Clip => gamut::clip(gamut, target),
            GamutMapping::GreyAxis(space) => {
                gamut::grey_axis_clip(gamut, target, space, &self.white)
            }
            GamutMapping::Perpendicular => gamut::perpendicular(gamut, target),
            GamutMapping::PerpendicularLab => gamut::perpendicular_lab(gamut, target, &self.white),
            GamutMapping::Hpminde => gamut::hpminde(gamut, target, &self.white),
            GamutMapping::Sgck(_) => match transform {
                Some(SceneTransform::SgckSource(source)) => {
                    gamut::sgck(gamut, source, target, &self.white)
                }
                _ => gamut::clip(gamut, target),
            },
            GamutMapping::Smith => match transform {
                Some(SceneTransform::Smith(t)) => t.apply(gamut, target),
                _ => gamut::clip(gamut, target),
            },
            GamutMapping::StoneCowanBeatty(_) => {
                let moved = match transform {
                    Some(SceneTransform::StoneCowanBeatty(t)) => t.apply(target),
                    _ => *target,
                };
                gamut::perpendicular_lab(gamut, &moved, &self.white)
            }
        }
    }
}

/// Why pixel `index` (`p`) has no gamut.
fn no_gamut(index: usize, p: &ScenePixel) -> CrfError {
    CrfError::BadPixel {
        index,
        what: format!(
            "the profile's spatial map gives a channel no light at ({}, {})",
            p.position.x, p.position.y
        ),
    }
}

fn summarise(
    pixels: &[RenderedPixel],
    settings: &RenderSettings,
    transform: Option<SceneTransform>,
) -> RenderSummary {
    let all: Vec<f64> = pixels.iter().map(|p| p.mapping_delta_e00).collect();
    let outside: Vec<f64> = pixels
        .iter()
        .filter(|p| p.outside)
        .map(|p| p.mapping_delta_e00)
        .collect();
    let inversion: Vec<f64> = pixels.iter().map(|p| p.inversion_delta_e00).collect();
    summary_of(
        pixels.len(),
        ErrorStats::of(&all),
        &outside,
        &inversion,
        settings,
        transform,
    )
}

/// The summary of `pixels` pixels: the mapping's ΔE00 over all of them (`mapping_all`), its
/// ΔE00 over those outside the gamut, and the inversion's.
fn summary_of(
    pixels: usize,
    mapping_all: Option<ErrorStats>,
    outside: &[f64],
    inversion: &[f64],
    settings: &RenderSettings,
    transform: Option<SceneTransform>,
) -> RenderSummary {
    RenderSummary {
        pixels,
        outside: outside.len(),
        tone: settings.tone.name(),
        gamut: settings.gamut.name(),
        mapping_all,
        mapping_outside: ErrorStats::of(outside),
        inversion: ErrorStats::of(inversion),
        stone_cowan_beatty: match transform {
            Some(SceneTransform::StoneCowanBeatty(t)) => Some(t),
            _ => None,
        },
        smith: match transform {
            Some(SceneTransform::Smith(t)) => Some(t),
            _ => None,
        },
        image_light: None,
    }
}

/// A colour as the batch loop takes it: XYZ in doubles (`Xyz`) or in 32-bit floats.
trait Colour {
    fn xyz(&self) -> Xyz;
    fn xyz_f32(&self) -> [f32; 3];
}

impl Colour for Xyz {
    fn xyz(&self) -> Xyz {
        *self
    }

    #[inline(always)]
    fn xyz_f32(&self) -> [f32; 3] {
        [self.x as f32, self.y as f32, self.z as f32]
    }
}

impl Colour for [f32; 3] {
    fn xyz(&self) -> Xyz {
        Xyz::new(self[0].into(), self[1].into(), self[2].into())
    }

    #[inline(always)]
    fn xyz_f32(&self) -> [f32; 3] {
        *self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::monitor::AdditivityTerms;
    use chromacal_model::spatial::{SpatialMap, Surface};

    /// sRGB-like primaries (white Y = 100), one law of each kind, black 0.1, and a
    /// spatial map or none.
    fn model(spatial: SpatialMap) -> MonitorModel {
        MonitorModel {
            matrix: Matrix3::new(
                41.24, 35.76, 18.05, //
                21.26, 71.52, 7.22, //
                1.93, 11.92, 95.05,
            ),
            black: Xyz::new(0.1, 0.11, 0.12),
            laws: inverse_table::tests::laws(),
            spatial,
            terms: AdditivityTerms::default(),
        }
    }

    /// Colours as asked, clipped to the gamut, each channel's 16-bit code rounded.
    fn clipped_and_rounded() -> RenderSettings {
        RenderSettings {
            adaptation: None,
            tone: ToneOperator::Colorimetric,
            gamut: GamutMapping::Clip,
            bits: 16,
            codes: CodeChoice::Rounded,
        }
    }

    /// A colour taken as well inside the gamut without the gamut at its place is
    /// inside by the gamut there, and a render leaves it as the mapping would: on a
    /// screen whose channels dim by different amounts towards the edges, colours
    /// inside, outside and within 10⁻⁹ to 10⁻³ of the gamut's faces, every pixel's
    /// `outside` and mapped colour are the gamut's own test and clip.
    #[test]
    fn a_colour_well_inside_is_inside_and_left_as_it_is() {
        use rand::{Rng, SeedableRng};
        let surface = |a: f64| Surface {
            degree: 2,
            coefficients: vec![0.0, 0.0, a, 0.0, a],
        };
        let model = model(SpatialMap::PerChannel {
            surfaces: [surface(-0.1), surface(-0.2), surface(-0.05)],
        });
        let crf = ColourReproduction::new(&model).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x0DD_BA11);
        let mut pixels = Vec::new();
        for i in 0..20_000 {
            let position = ScreenPosition {
                x: rng.random::<f64>(),
                y: rng.random::<f64>(),
            };
            let gamut = crf.gamut_at(position).unwrap();
            // Cube coordinates inside, outside, or a hair from a face either way.
            let mut a: [f64; 3] = std::array::from_fn(|_| rng.random::<f64>());
            match i % 3 {
                0 => {}
                1 => a[i % 2] = -0.2 + 1.4 * rng.random::<f64>(),
                _ => {
                    // Each channel's face in turn, from inside or outside.
                    let (c, hair) = ((i / 3) % 3, 10f64.powf(-9.0 + 6.0 * rng.random::<f64>()));
                    a[c] = if i % 2 == 0 { hair } else { 1.0 - hair };
                    if i % 4 == 0 {
                        a[c] = if i % 2 == 0 { -hair } else { 1.0 + hair };
                    }
                }
            }
            let xyz = gamut.from_cube(&Vector3::from(a));
            pixels.push(ScenePixel { xyz, position });
        }
        let scene = Scene {
            pixels,
            white: None,
        };
        let settings = clipped_and_rounded();
        let rendering = crf.render(&scene, &settings).unwrap();
        let (mut inside, mut outside, mut wells) = (0, 0, 0);
        for (pixel, asked) in rendering.pixels.iter().zip(&scene.pixels) {
            let gamut = crf.gamut_at(asked.position).unwrap();
            assert_eq!(pixel.outside, !gamut.contains(&asked.xyz), "{asked:?}");
            assert_eq!(
                Xyz::from(pixel.mapped),
                gamut::clip(&gamut, &asked.xyz),
                "{asked:?}"
            );
            if pixel.outside {
                outside += 1;
            } else {
                inside += 1;
            }
            let well = crf.well_inside(&asked.xyz, model.spatial.gains(asked.position));
            assert!(!well || gamut.contains(&asked.xyz), "{asked:?}");
            wells += usize::from(well);
        }
        assert!(
            inside > 10_000 && outside > 2_000 && wells > 5_000,
            "{inside} inside, {outside} outside, {wells} well inside"
        );
        // Through the HLG OOTF the gamut's channels are scaled by their gains in
        // white: so is the test.
        let mut hlg = model.clone();
        hlg.terms.hlg_ootf = Some(1.2);
        let through = ColourReproduction::new(&hlg).unwrap();
        let mut wells = 0;
        for asked in &scene.pixels {
            // The same cube coordinates in the gamut through the OOTF.
            let a = crf.gamut_at(asked.position).unwrap().to_cube(&asked.xyz);
            let gamut = through.gamut_at(asked.position).unwrap();
            let xyz = gamut.from_cube(&a);
            if through.well_inside(&xyz, hlg.spatial.gains(asked.position)) {
                assert!(gamut.contains(&xyz), "{asked:?}");
                wells += 1;
            }
        }
        assert!(wells > 5_000, "{wells} well inside through the OOTF");
    }

    /// The codes rounded and raised without `round` and `ceil` are theirs: on every
    /// quarter code from 0 to 16 bits' top and their neighbouring doubles either way
    /// (where a sum with a half would round up wrongly), random values, and NaN.
    #[test]
    fn codes_rounded_and_raised_are_round_s_and_ceil_s() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0xC0DE_5EED);
        let step = |v: f64, up: bool| {
            let bits = v.to_bits();
            f64::from_bits(if up { bits + 1 } else { bits.saturating_sub(1) })
        };
        let mut values: Vec<f64> = (0..=4 * 65535)
            .map(|k| f64::from(k) / 4.0)
            .flat_map(|v| [v, step(v, true), step(v, false)])
            .collect();
        values.extend((0..100_000).map(|_| rng.random::<f64>() * 65535.0));
        values.extend([0.499_999_999_999_999_94, f64::NAN, 0.0, 65535.0]);
        for v in values {
            assert_eq!(round_code(v), v.round() as u32, "{v:e}");
            assert_eq!(ceil_code(v), v.ceil() as u32, "{v:e}");
            assert_eq!(v as u32, v.floor() as u32, "{v:e}");
        }
    }

    /// With the HLG OOTF the display's colours are not the box of its channels alone:
    /// with γ > 1 its greys reach further (a white 1.3 times the channels' sum in
    /// blue), with γ < 1 the channels alone do. The render keeps the greys up to
    /// white inside and shown as asked, takes the channels alone as inside whatever
    /// γ, and counts a colour the model's inverse has to clip as outside, mapped to
    /// what its clipped drive shows.
    #[test]
    fn an_hlg_ootf_model_renders_its_greys_and_clips_what_it_cannot_show() {
        let settings = clipped_and_rounded();
        for gamma in [0.9, 1.2] {
            let m = MonitorModel {
                terms: AdditivityTerms {
                    hlg_ootf: Some(gamma),
                    ..AdditivityTerms::default()
                },
                ..model(SpatialMap::Uniform)
            };
            let crf = ColourReproduction::new(&m).unwrap();
            let white = m.white();
            let p = ScreenPosition::CENTRE;
            let at = |xyz: Xyz| ScenePixel { xyz, position: p };
            let mut asked: Vec<Xyz> = [0.2, 0.787, 0.95, 1.0]
                .iter()
                .map(|f| (white - m.black) * *f + m.black)
                .collect();
            asked.extend((0..3).map(|c| {
                let mut d = [0.0; 3];
                d[c] = 1.0;
                m.forward(d, p)
            }));
            // A red brighter than the display's: outside.
            asked.push((m.forward([1.0, 0.0, 0.0], p) - m.black) * 1.2 + m.black);
            let scene = Scene {
                pixels: asked.iter().map(|x| at(*x)).collect(),
                white: None,
            };
            let rendered = crf.render(&scene, &settings).unwrap();
            let (inside, beyond) = rendered.pixels.split_at(asked.len() - 1);
            for (x, px) in asked.iter().zip(inside) {
                assert!(!px.outside, "γ {gamma}: {x:?} {px:?}");
                let shown = m.forward(px.codes.map(|c| f64::from(c) / 65535.0), p);
                let miss = delta_e00_xyz(x, &shown, &white);
                assert!(miss < 0.01, "γ {gamma}: {x:?} shown {shown:?} ({miss})");
            }
            let px = &beyond[0];
            assert!(px.outside, "γ {gamma}: {px:?}");
            let shown = m.forward(px.codes.map(|c| f64::from(c) / 65535.0), p);
            let mapped = Xyz::from(px.mapped);
            assert!(
                delta_e00_xyz(&mapped, &shown, &white) < 0.01,
                "γ {gamma}: {px:?}"
            );
        }
    }

    #[test]
    fn the_batch_loop_is_compiled_for_avx2_where_the_processor_has_it() {
        // Otherwise the test below compares the baseline build with itself. `pulp`
        // takes its AVX2 build where the processor has all of x86-64-v3 (a virtual
        // machine may hide one of them while it shows AVX2).
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            let v3 = has!("avx")
                && has!("avx2")
                && has!("fma")
                && has!("bmi1")
                && has!("bmi2")
                && has!("lzcnt")
                && has!("popcnt")
                && has!("sse4.2")
                && has!("ssse3")
                && has!("sse3")
                && has!("fxsr");
            assert_eq!(!matches!(pulp::Arch::new(), pulp::Arch::Scalar), v3);
        }
    }

    #[test]
    fn the_batch_loop_gives_the_same_codes_for_every_instruction_set() {
        // Colours from below black to beyond white, NaN and infinities among them, at
        // a block's edge and over the screen: the loop built for the processor's best
        // instructions and the one built for the baseline agree code for code, and
        // both show the colours they were asked for.
        let n = 3 * inverse_table::BLOCK + 17;
        let spread = |k: usize, s: usize| ((k * 7919 + s * 104_729) % 1000) as f64 / 999.0;
        let colour = |k: usize| Xyz::from([0, 1, 2].map(|s| 125.0 * spread(k, s) - 10.0));
        let drive = |k: usize| [0, 1, 2].map(|s| 0.03 + 0.94 * spread(k, s));
        let at = |k: usize| ScreenPosition::new((k % 29) as f64 / 28.0, (k % 31) as f64 / 30.0);
        let surface = Surface {
            degree: 2,
            coefficients: vec![0.0, 0.0, -0.1, 0.0, -0.1],
        };
        for spatial in [SpatialMap::Uniform, SpatialMap::Scalar { surface }] {
            let model = model(spatial);
            // Every other colour one the display makes where it is shown.
            let mut asked: Vec<Xyz> = (0..n)
                .map(|k| match k % 2 {
                    0 => model.forward(drive(k), at(k)),
                    _ => colour(k),
                })
                .collect();
            // A NaN of all ones bits (its payload would be the last entry: white), a
            // quiet NaN, and infinities.
            asked[5] = Xyz::new(f64::from_bits(u64::MAX), 1.0, 1.0);
            asked[6] = Xyz::new(1.0, f64::NAN, 1.0);
            asked[7] = Xyz::new(f64::INFINITY, 1.0, f64::NEG_INFINITY);
            let crf = ColourReproduction::new(&model).unwrap();
            let mut best = vec![[0u16; 3]; n];
            let mut baseline = vec![[1u16; 3]; n];
            crf.codes16_of(&asked, at, &mut best, Instructions::Best);
            crf.codes16_of(&asked, at, &mut baseline, Instructions::Baseline);
            assert_eq!(best, baseline);
            // The public paths, f64 and f32, are the same loop.
            let mut from_f64 = vec![[2u16; 3]; n];
            crf.codes16(&asked, at, &mut from_f64);
            let as_f32: Vec<[f32; 3]> = asked.iter().map(Colour::xyz_f32).collect();
            let mut from_f32 = vec![[3u16; 3]; n];
            crf.codes16_f32(&as_f32, at, &mut from_f32);
            assert_eq!(from_f64, best);
            assert_eq!(from_f32, best);
            assert_eq!(best[5], [0; 3], "a NaN, whatever its bits, gives black");
            assert_eq!(best[6], [0; 3], "a NaN gives black");
            assert_eq!(best[7][1], 0, "−∞ gives black");
            // As many codes as colours: a longer output keeps what is past them, a
            // shorter one takes the first.
            let mut longer = vec![[9u16; 3]; n + 5];
            crf.codes16(&asked, at, &mut longer);
            assert_eq!(longer[..n], best[..]);
            assert!(longer[n..].iter().all(|c| *c == [9; 3]));
            let mut shorter = vec![[9u16; 3]; n - 3];
            crf.codes16(&asked, at, &mut shorter);
            assert_eq!(shorter[..], best[..n - 3]);
            // Inside the gamut the codes show the colour to within 0.05 ΔE00.
            let white = model.white();
            let mut inside = 0;
            for (k, (x, c)) in asked.iter().zip(&best).enumerate() {
                let drive = crf.drive_exact_for(x, at(k));
                if !x.iter().all(|v| v.is_finite())
                    || drive.iter().any(|d| !(0.02..0.98).contains(d))
                {
                    continue;
                }
                let shown = model.forward(c.map(|v| f64::from(v) / 65535.0), at(k));
                assert!(delta_e00_xyz(x, &shown, &white) < 0.05, "{x:?} {c:?}");
                inside += 1;
            }
            assert!(inside > n / 3, "{inside}");
        }
    }
}
