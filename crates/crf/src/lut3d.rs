//! 3D LUTs: the colour reproduction function sampled on a source space's grid, for
//! video players and grading tools (mpv, madVR, Resolve, ffmpeg's `lut3d`), as
//! ArgyllCMS `collink` and DisplayCAL make them.
//!
//! Each grid point is a code triple of the source encoding. It is decoded by the
//! source's EOTF, taken to XYZ by its primaries, carried from the source white (D65)
//! to the display's white (Bradford, relative colorimetric) or kept absolute, put at
//! the display's luminance with its black (BT.1886 places black itself; the other
//! encodings get black point compensation), gamut-mapped, and inverted through the
//! profile's model at the centre of the screen. The LUT's output is the display drive,
//! or, for a LUT applied while the profile's calibration curves are in the video LUT,
//! the input to those curves that gives that drive.

use nalgebra::Matrix3;

use super::gamut::{GamutMapping, SgckSource};
use super::tone::ToneOperator;
use super::{CodeChoice, ColourReproduction, CrfError, RenderSettings, Scene, ScenePixel};
use chromacal_color::Xyz;
use chromacal_color::adaptation::{AdaptationTransform, adapt};
use chromacal_color::gamut::{AdditiveGamut, DISPLAY_P3, REC_2020, RgbSpace, SRGB};
use chromacal_color::hdr::{HLG_REFERENCE_AMBIENT, bt2390_eetf, hlg_eotf, hlg_system_gamma};
use chromacal_color::ictcp::{pq_eotf, pq_inverse_eotf};
use chromacal_color::spaces::{Xyy, xyy_to_xyz};
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::target::CalibrationCurves;
use chromacal_model::{MonitorModel, ScreenPosition};

/// The encoding of the LUT's input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceSpace {
    /// IEC 61966-2-1 sRGB: its piecewise curve, BT.709 primaries, D65.
    Srgb,
    /// BT.709 primaries through a pure 2.4 power (BT.1886 on a display with a black
    /// of zero light).
    Bt709,
    /// BT.709 primaries through ITU-R BT.1886 Annex 1 with the display's own white
    /// and black: the EOTF video is mastered for.
    Bt1886,
    /// Display P3: the sRGB curve on DCI-P3 primaries with a D65 white.
    P3,
    /// ITU-R BT.2020 primaries through BT.1886 with the display's white and black.
    Rec2020,
    /// ITU-R BT.2100 PQ (SMPTE ST 2084) on BT.2020 primaries: absolute light, brought
    /// onto the display's peak and black by BT.2390's EETF from the mastering peak.
    Rec2100Pq,
    /// ITU-R BT.2100 HLG on BT.2020 primaries: scene light, shown through the HLG
    /// EOTF of the display's peak and black (system gamma for BT.2100's 5 cd/m² room).
    Rec2100Hlg,
}

impl std::str::FromStr for SourceSpace {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let wanted = s.to_ascii_lowercase();
        SourceSpace::ALL
            .into_iter()
            .find(|space| space.key() == wanted)
            .ok_or_else(|| {
                let keys: Vec<&str> = SourceSpace::ALL.iter().map(|s| s.key()).collect();
                format!("no source space '{s}' ({})", keys.join(", "))
            })
    }
}

impl SourceSpace {
    pub const ALL: [SourceSpace; 7] = [
        SourceSpace::Srgb,
        SourceSpace::Bt709,
        SourceSpace::Bt1886,
        SourceSpace::P3,
        SourceSpace::Rec2020,
        SourceSpace::Rec2100Pq,
        SourceSpace::Rec2100Hlg,
    ];

    /// The name on the command line (`--source`, `verify --against`).
    pub fn key(self) -> &'static str {
        match self {
            SourceSpace::Srgb => "srgb",
            SourceSpace::Bt709 => "bt709",
            SourceSpace::Bt1886 => "bt1886",
            SourceSpace::P3 => "p3",
            SourceSpace::Rec2020 => "rec2020",
            SourceSpace::Rec2100Pq => "rec2100-pq",
            SourceSpace::Rec2100Hlg => "rec2100-hlg",
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SourceSpace::Srgb => "sRGB",
            SourceSpace::Bt709 => "BT.709 (gamma 2.4)",
            SourceSpace::Bt1886 => "BT.709 through BT.1886",
            SourceSpace::P3 => "Display P3",
            SourceSpace::Rec2020 => "Rec. 2020 through BT.1886",
            SourceSpace::Rec2100Pq => "BT.2100 PQ",
            SourceSpace::Rec2100Hlg => "BT.2100 HLG",
        }
    }

    fn primaries(self) -> RgbSpace {
        match self {
            SourceSpace::Srgb | SourceSpace::Bt709 | SourceSpace::Bt1886 => SRGB,
            SourceSpace::P3 => DISPLAY_P3,
            SourceSpace::Rec2020 | SourceSpace::Rec2100Pq | SourceSpace::Rec2100Hlg => REC_2020,
        }
    }

    /// The source gamut SGCK maps from for this encoding.
    pub fn sgck_source(self) -> SgckSource {
        match self {
            SourceSpace::Srgb | SourceSpace::Bt709 | SourceSpace::Bt1886 => SgckSource::Srgb,
            SourceSpace::P3 => SgckSource::P3,
            SourceSpace::Rec2020 | SourceSpace::Rec2100Pq | SourceSpace::Rec2100Hlg => {
                SgckSource::Rec2020
            }
        }
    }

    /// Whether the EOTF itself lifts code 0 to the display's black (BT.1886); the
    /// others are given black point compensation.
    fn places_black(self) -> bool {
        !matches!(
            self,
            SourceSpace::Srgb | SourceSpace::Bt709 | SourceSpace::P3
        )
    }

    /// An HDR signal: its light is set in cd/m² by the signal and the display's peak,
    /// not relative to the display's white.
    pub fn is_hdr(self) -> bool {
        matches!(self, SourceSpace::Rec2100Pq | SourceSpace::Rec2100Hlg)
    }

    /// Linear light of code `v` of an SDR encoding relative to white, with the
    /// display's black at `black` (its luminance over the white's).
    pub fn decode_relative(self, v: f64, black: f64) -> f64 {
        let v = v.clamp(0.0, 1.0);
        match self {
            SourceSpace::Srgb | SourceSpace::P3 => srgb_eotf(v),
            SourceSpace::Bt709 => v.powf(BT1886_GAMMA),
            SourceSpace::Bt1886 | SourceSpace::Rec2020 => bt1886_eotf(v, 1.0, black),
            // Absolute light, relative only to a peak: see `decode`.
            SourceSpace::Rec2100Pq | SourceSpace::Rec2100Hlg => {
                self.decode([v; 3], 1.0, black, None)[0]
            }
        }
    }

    /// Linear light of codes `rgb` in cd/m² on a display of white luminance `white`
    /// and black `black`. The HDR encodings' light is their own, brought onto that
    /// range: PQ by BT.2390's EETF from `mastering_peak` (which also lifts the
    /// black), or without one clipped at the black and the white as the calibration's
    /// `tone = "pq"` is; HLG by its EOTF for that peak.
    pub fn decode(
        self,
        rgb: [f64; 3],
        white: f64,
        black: f64,
        mastering_peak: Option<f64>,
    ) -> [f64; 3] {
        let share = (black / white).clamp(0.0, 1.0);
        match self {
            SourceSpace::Rec2100Pq => rgb.map(|v| match mastering_peak {
                Some(m) if m > white => bt2390_eetf(v, m, white, black),
                _ => pq_eotf(v).clamp(black.max(0.0), white),
            }),
            SourceSpace::Rec2100Hlg => hlg_eotf(
                rgb,
                white,
                black,
                hlg_system_gamma(white, HLG_REFERENCE_AMBIENT),
            ),
            sdr => rgb.map(|v| white * sdr.decode_relative(v, share)),
        }
    }
}

/// BT.1886's exponent.
const BT1886_GAMMA: f64 = 2.4;

/// IEC 61966-2-1:1999 §5.2 eq. (5) inverse: the sRGB encoding decoded.
pub fn srgb_eotf(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// ITU-R BT.1886 Annex 1: L = a · max(V + b, 0)^2.4 with a = (Lw^(1/2.4) −
/// Lb^(1/2.4))^2.4 and b = Lb^(1/2.4) / (Lw^(1/2.4) − Lb^(1/2.4)), so that V = 0 gives
/// the display's black Lb and V = 1 its white Lw.
pub fn bt1886_eotf(v: f64, white: f64, black: f64) -> f64 {
    let (w, b) = (
        white.powf(1.0 / BT1886_GAMMA),
        black.max(0.0).powf(1.0 / BT1886_GAMMA),
    );
    let a = (w - b).powf(BT1886_GAMMA);
    let offset = b / (w - b);
    a * (v + offset).max(0.0).powf(BT1886_GAMMA)
}

/// How a LUT is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LutOptions {
    pub source: SourceSpace,
    /// Points along each axis.
    pub size: usize,
    pub gamut: GamutMapping,
    /// Keep the source's D65 white as it is rather than carry it to the display's.
    pub absolute: bool,
    /// The LUT is applied while the profile's calibration curves are in the video
    /// LUT: its output is the curves' input that gives each drive.
    pub through_calibration: bool,
    /// For a PQ source: the peak of the display it was mastered on, cd/m², from
    /// which BT.2390's EETF rolls it off to this display's (None: clipped).
    pub mastering_peak: Option<f64>,
}

/// A 3D LUT: `size`³ output triples in [0, 1], red varying fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct Lut3d {
    pub size: usize,
    pub table: Vec<[f64; 3]>,
    /// What the gamut mapping changed over the grid, and how many points it moved.
    pub outside: usize,
    pub mapping: Option<ErrorStats>,
    pub source: SourceSpace,
    /// What the file says about its input beyond the source's name (an HDR source's
    /// range and the peak it is brought to), one comment line each.
    pub notes: Vec<String>,
}

/// Why a LUT could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LutError {
    #[error("a LUT of {0} points a side (2 to 129)")]
    Size(usize),
    #[error(
        "Stone–Cowan–Beatty and Smith map a whole scene, not a LUT's grid: give clip, grey-lab, grey-luv, perpendicular, perpendicular-lab, hpminde or sgck"
    )]
    SceneMapping,
    #[error(
        "SGCK maps from the source space put on the display's white; --absolute keeps the source's own white: give one or the other"
    )]
    SgckAbsolute,
    #[error("the LUT is to run through calibration curves, but the profile has none")]
    NoCalibration,
    #[error(transparent)]
    Crf(#[from] CrfError),
}

/// The colour the display is asked to show for source codes `rgb`, in the model's
/// units: decoded, to XYZ by the source's primaries, to the display's `white` (or kept
/// absolute) and its luminance, with the display's `black`. The white is the one the
/// display shows: the native white, or, through calibration curves, the calibrated one.
pub fn source_target(rgb: [f64; 3], white: &Xyz, black: &Xyz, options: &LutOptions) -> Xyz {
    let white = *white;
    let black_share = (black.y / white.y).clamp(0.0, 1.0);
    let space = options.source.primaries();
    let to_xyz = space_matrix(&space);
    let linear = if options.source.is_hdr() {
        let light = options
            .source
            .decode(rgb, white.y, black.y, options.mastering_peak);
        light.map(|v| v / white.y)
    } else {
        rgb.map(|v| options.source.decode_relative(v, black_share))
    };
    let xyz = to_xyz * Xyz::new(linear[0], linear[1], linear[2]);
    let source_white = to_xyz * Xyz::new(1.0, 1.0, 1.0);
    let relative = if options.absolute {
        xyz
    } else {
        adapt(
            &xyz,
            AdaptationTransform::Bradford,
            &source_white,
            &(white / white.y),
        )
    };
    if options.source.places_black() {
        // Code 0 already decodes to the black's share of the white.
        relative * white.y
    } else {
        // Black point compensation: the source's black on the display's, its white
        // on the display's, linearly between.
        (relative * (1.0 - black_share) + white / white.y * black_share) * white.y
    }
}

/// A space's RGB-to-XYZ matrix with its white at Y = 1.
fn space_matrix(space: &RgbSpace) -> Matrix3<f64> {
    match AdditiveGamut::of_space(space) {
        Some(g) => g.primaries,
        // The built-in spaces are not degenerate; a zero matrix would show black.
        None => {
            let [x, y] = space.white;
            Matrix3::from_diagonal(&xyy_to_xyz(&Xyy { x, y, big_y: 1.0 }))
        }
    }
}

/// The grid's source code triples, red fastest.
fn grid(size: usize) -> Vec<[f64; 3]> {
    let step = |i: usize| i as f64 / (size - 1) as f64;
    (0..size * size * size)
        .map(|k| {
            [
                step(k % size),
                step(k / size % size),
                step(k / (size * size)),
            ]
        })
        .collect()
}

/// Input of a monotone curve (sampled at i/(n−1)) that gives `drive`: the
/// calibration curve inverted by bisection and linear interpolation between samples.
pub fn curve_input(curve: &[f64], drive: f64) -> f64 {
    let n = curve.len();
    if n < 2 {
        return drive;
    }
    if drive <= curve[0] {
        return 0.0;
    }
    if drive >= curve[n - 1] {
        return 1.0;
    }
    let i = curve.partition_point(|v| *v < drive).clamp(1, n - 1);
    let (lo, hi) = (curve[i - 1], curve[i]);
    let t = if hi > lo {
        (drive - lo) / (hi - lo)
    } else {
        0.0
    };
    ((i - 1) as f64 + t) / (n - 1) as f64
}

/// Build the LUT of `model` (and its calibration `curves` when the LUT is to run
/// through them).
pub fn build_lut(
    model: &MonitorModel,
    curves: Option<&CalibrationCurves>,
    options: &LutOptions,
) -> Result<Lut3d, LutError> {
    // 129³ is 2.1 million points, a 60 MB .cube: enough for any player.
    if !(2..=129).contains(&options.size) {
        return Err(LutError::Size(options.size));
    }
    if options.gamut.is_scene_wide() {
        return Err(LutError::SceneMapping);
    }
    let curves = match (options.through_calibration, curves) {
        (true, None) => return Err(LutError::NoCalibration),
        (true, Some(c)) => Some(c),
        (false, _) => None,
    };
    // SGCK compresses from the LUT's own source gamut, on the display's white.
    if options.absolute && matches!(options.gamut, GamutMapping::Sgck(_)) {
        return Err(LutError::SgckAbsolute);
    }
    let gamut = match options.gamut {
        GamutMapping::Sgck(_) => GamutMapping::Sgck(options.source.sgck_source()),
        other => other,
    };
    let crf = ColourReproduction::new(model)?;
    // The white the display shows: through calibration curves, the one they make,
    // which a source white is carried to (the native white is not on the screen).
    let (white, black) = match curves {
        Some(k) => (
            Xyz::new(k.white[0], k.white[1], k.white[2]),
            Xyz::new(k.black[0], k.black[1], k.black[2]),
        ),
        None => (model.white(), model.black),
    };
    let scene = Scene {
        pixels: grid(options.size)
            .into_iter()
            .map(|rgb| ScenePixel {
                xyz: source_target(rgb, &white, &black, options),
                position: ScreenPosition::CENTRE,
            })
            .collect(),
        white: None,
    };
    let rendering = crf.render(
        &scene,
        &RenderSettings {
            adaptation: None,
            tone: ToneOperator::Colorimetric,
            gamut,
            bits: 16,
            codes: CodeChoice::Rounded,
        },
    )?;
    let table = rendering
        .pixels
        .iter()
        .map(|p| {
            let drive = p.codes.map(|c| f64::from(c) / 65535.0);
            match curves {
                Some(k) => [0, 1, 2].map(|c| curve_input(&k.curves[c], drive[c])),
                None => drive,
            }
        })
        .collect();
    Ok(Lut3d {
        size: options.size,
        table,
        outside: rendering.summary.outside,
        mapping: rendering.summary.mapping_outside,
        source: options.source,
        notes: hdr_notes(options, &white, &black),
    })
}

/// What an HDR LUT's file says of its input and of the light it is brought to.
fn hdr_notes(options: &LutOptions, white: &Xyz, black: &Xyz) -> Vec<String> {
    let input = "Input: full-range R'G'B' codes over 0-1 (10-bit 0-1023); narrow-range video (64-940) must be expanded first";
    match options.source {
        SourceSpace::Rec2100Pq => vec![
            format!("{input}; SMPTE ST 2084 PQ, 1.0 = 10000 cd/m2, BT.2020 primaries, D65"),
            match options.mastering_peak {
                Some(m) if m > white.y => format!(
                    "BT.2390 EETF from a {m} cd/m2 mastering peak to the display's {:.1} cd/m2 (black {:.4}); the PQ itself from the lifted black to the knee at {:.1} cd/m2",
                    white.y,
                    black.y,
                    eetf_knee(m, white.y)
                ),
                _ => format!(
                    "PQ as it is from the display's black {1:.4} to its {0:.1} cd/m2, clipped outside",
                    white.y, black.y
                ),
            },
        ],
        SourceSpace::Rec2100Hlg => vec![
            format!("{input}; BT.2100 HLG, BT.2020 primaries, D65"),
            format!(
                "HLG EOTF for a {:.1} cd/m2 peak, black {:.4}, system gamma {:.3} (5 cd/m2 surround)",
                white.y,
                black.y,
                hlg_system_gamma(white.y, HLG_REFERENCE_AMBIENT)
            ),
        ],
        _ => Vec::new(),
    }
}

/// Luminance of BT.2390's knee (KS = 1.5 · maxLum − 0.5 in the mastering range's PQ,
/// §5.4.1 eq. 6) for a PQ mastered at `mastering_peak` shown on a `display_peak`
/// display: below it the EETF is the PQ itself.
pub fn eetf_knee(mastering_peak: f64, display_peak: f64) -> f64 {
    let (bottom, top) = (pq_inverse_eotf(0.0), pq_inverse_eotf(mastering_peak));
    let max_lum = ((pq_inverse_eotf(display_peak) - bottom) / (top - bottom)).min(1.0);
    pq_eotf((1.5 * max_lum - 0.5) * (top - bottom) + bottom)
}

impl Lut3d {
    /// The Adobe Cube LUT Specification 1.0 text: `LUT_3D_SIZE`, the domain, then the
    /// triples with red varying fastest.
    pub fn to_cube(&self, title: &str) -> String {
        let mut out = format!(
            "# Made by chromacal {}: {} to this display\n",
            env!("CARGO_PKG_VERSION"),
            self.source.name(),
        );
        for note in &self.notes {
            out += &format!("# {}\n", note.replace('\n', " "));
        }
        out += &format!(
            "TITLE \"{}\"\nLUT_3D_SIZE {}\nDOMAIN_MIN 0.0 0.0 0.0\nDOMAIN_MAX 1.0 1.0 1.0\n",
            title.replace('"', "'"),
            self.size
        );
        for [r, g, b] in &self.table {
            out += &format!("{r:.6} {g:.6} {b:.6}\n");
        }
        out
    }

    /// The Autodesk Lustre `.3dl` text: a line of the input mesh (10-bit codes), then
    /// 12-bit output triples with blue varying fastest and red slowest.
    pub fn to_3dl(&self) -> String {
        let n = self.size;
        let mesh: Vec<String> = (0..n)
            // 0, 64, …, 960, 1023 for 17 points: steps of 1024 / (n − 1), the last
            // at the 10-bit top.
            .map(|i| format!("{}", (i * 1024 / (n - 1)).min(1023)))
            .collect();
        let mut out = mesh.join(" ") + "\n";
        for r in 0..n {
            for g in 0..n {
                for b in 0..n {
                    let v = self.table[r + n * g + n * n * b];
                    let [x, y, z] = v.map(|c| (c.clamp(0.0, 1.0) * 4095.0).round() as u32);
                    out += &format!("{x} {y} {z}\n");
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hdr_sources_decode_to_the_display_s_light_and_every_key_parses_back() {
        for space in SourceSpace::ALL {
            assert_eq!(space.key().parse::<SourceSpace>(), Ok(space));
        }
        let pq = SourceSpace::Rec2100Pq;
        // Below the knee the PQ's own light; the master's peak lands on the display's.
        let hundred = pq.decode([pq_inverse_eotf(100.0); 3], 600.0, 0.0, Some(1000.0));
        assert!((hundred[0] / 100.0 - 1.0).abs() < 1e-6, "{hundred:?}");
        let top = pq.decode([pq_inverse_eotf(1000.0); 3], 600.0, 0.0, Some(1000.0));
        assert!((top[0] / 600.0 - 1.0).abs() < 1e-6, "{top:?}");
        // Unmastered: clipped at the peak.
        let clipped = pq.decode([pq_inverse_eotf(4000.0); 3], 600.0, 0.0, None);
        assert!((clipped[0] / 600.0 - 1.0).abs() < 1e-9, "{clipped:?}");
        assert!(eetf_knee(1000.0, 600.0) < 600.0 && eetf_knee(1000.0, 600.0) > 300.0);
        let hlg = SourceSpace::Rec2100Hlg.decode([1.0; 3], 1000.0, 0.0, None);
        assert!((hlg[1] / 1000.0 - 1.0).abs() < 1e-6, "{hlg:?}");
    }

    #[test]
    fn bt1886_runs_from_the_black_to_the_white() {
        assert!((bt1886_eotf(0.0, 1.0, 0.001) - 0.001).abs() < 1e-12);
        assert!((bt1886_eotf(1.0, 1.0, 0.001) - 1.0).abs() < 1e-12);
        // With no black it is a plain 2.4 power.
        assert!((bt1886_eotf(0.5, 1.0, 0.0) - 0.5_f64.powf(2.4)).abs() < 1e-12);
    }

    #[test]
    fn the_srgb_curve_meets_itself_at_the_break() {
        let below = srgb_eotf(0.04045);
        let above = ((0.04045_f64 + 0.055) / 1.055).powf(2.4);
        assert!((below - above).abs() < 1e-6, "{below} {above}");
        assert!((srgb_eotf(1.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_calibration_curve_is_inverted() {
        let curve: Vec<f64> = (0..256)
            .map(|i| (i as f64 / 255.0).powf(1.2) * 0.9)
            .collect();
        for drive in [0.0, 0.1, 0.45, 0.9] {
            let input = curve_input(&curve, drive);
            assert!(
                (input.powf(1.2) * 0.9 - drive).abs() < 1e-4,
                "{drive} {input}"
            );
        }
        assert_eq!(curve_input(&curve, 0.95), 1.0);
    }

    #[test]
    fn the_grid_runs_red_fastest_and_the_3dl_blue_fastest() {
        let g = grid(3);
        assert_eq!(g[1], [0.5, 0.0, 0.0]);
        assert_eq!(g[3], [0.0, 0.5, 0.0]);
        assert_eq!(g[9], [0.0, 0.0, 0.5]);
        let lut = Lut3d {
            size: 3,
            table: g,
            outside: 0,
            mapping: None,
            source: SourceSpace::Srgb,
            notes: Vec::new(),
        };
        let text = lut.to_3dl();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "0 512 1023");
        let lut17 = Lut3d {
            size: 17,
            table: grid(17),
            ..lut.clone()
        };
        assert!(
            lut17
                .to_3dl()
                .starts_with("0 64 128 192 256 320 384 448 512 576 640 704 768 832 896 960 1023\n")
        );
        assert_eq!(lines[2], "0 0 2048", "blue second");
        assert_eq!(lines[10], "2048 0 0", "red slowest");
        let cube = lut.to_cube("t");
        assert!(cube.contains("LUT_3D_SIZE 3\n"));
        assert!(
            cube.lines()
                .nth(6)
                .unwrap()
                .starts_with("0.500000 0.000000 0.000000")
        );
    }
}
