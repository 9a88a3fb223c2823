//! CIE 156:2004's second reference algorithm, SGCK: sigmoidal lightness mapping and
//! cusp knee scaling (Morovič's GCUSP with Braun and Fairchild's sigmoid).
//!
//! SGCK maps a *source gamut* onto the display's, so it needs one: here an RGB
//! space (sRGB, Adobe RGB, Display P3, Rec. 2020) put on the display the way
//! `lut3d` puts it, its white carried to the display's white (Bradford) and its
//! black on the display's black (black point compensation). It works in CIELAB
//! against the display's white (CIE 156 specifies CIECAM97s; CIELAB keeps it beside
//! the other mappings here and is what most published comparisons use), in three
//! steps:
//!
//! 1. **Lightness**: the colour's L* is normalised over the source's lightness range
//!    and passed through Braun and Fairchild's (1999) sigmoid, a cumulative normal
//!    with mean x₀ and deviation Σ chosen from the display's black, scaled onto the
//!    display's lightness range. The result L_s is blended with the original by
//!    chroma, L = (1 − p_C) L₀ + p_C L_s with p_C = 1 − √(C³ / (C³ + 5·10⁵)), so that
//!    greys follow the sigmoid fully and vivid colours keep their lightness.
//! 2. **Focal point**: the grey at the lightness of the display's cusp (its most
//!    chromatic colour) at the colour's hue.
//! 3. **Knee**: along the line from that grey through the colour, distances up to
//!    90 % of the display's boundary are kept; the rest of the way to the
//!    (lightness-mapped) source boundary is compressed linearly into the last 10 %.
//!    Where the source ends inside the display there is nothing to compress.
//!
//! One deviation, stated: CIE 156 applies the sigmoid whatever the two lightness
//! ranges. Here it is applied only when the source's range reaches beyond the
//! display's; with equal ranges the sigmoid would still bend every grey, and a
//! source that fits the display should pass unchanged. So SGCK moves an in-gamut
//! colour only when the source reaches beyond the display along that colour's line
//! (the knee), or in lightness (the sigmoid): that is what it is for. At the
//! screen's centre, with the source's black on the display's, the two lightness
//! ranges are equal and the sigmoid has nothing to do; it acts where the display's
//! range is the smaller (a dimmer corner, or a source whose black is deeper).

use std::cell::RefCell;
use std::rc::Rc;

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use super::{GamutAt, UniformSpace, clip, grey_axis_clip, last_inside_within};
use chromacal_color::Xyz;
use chromacal_color::adaptation::{AdaptationTransform, adapt};
use chromacal_color::gamut::{ADOBE_RGB, AdditiveGamut, DISPLAY_P3, REC_2020, RgbSpace, SRGB};
use chromacal_color::spaces::{Lab, lab_to_xyz, xyz_to_lab};

/// The source gamut SGCK compresses from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SgckSource {
    Srgb,
    AdobeRgb,
    P3,
    Rec2020,
}

impl SgckSource {
    pub fn space(self) -> RgbSpace {
        match self {
            SgckSource::Srgb => SRGB,
            SgckSource::AdobeRgb => ADOBE_RGB,
            SgckSource::P3 => DISPLAY_P3,
            SgckSource::Rec2020 => REC_2020,
        }
    }

    /// The space on a display with white `white` and black `black`: its primaries
    /// adapted from the space's white to the display's (Bradford) and scaled so that
    /// full drive is the display's white, its black the display white's chromaticity
    /// at the black's luminance (black point compensation, as `lut3d` does).
    pub fn gamut(self, white: &Xyz, black: &Xyz) -> Option<GamutAt> {
        let space = AdditiveGamut::of_space(&self.space())?;
        if white.y <= 0.0 {
            return None;
        }
        let source_white = space.primaries * Xyz::new(1.0, 1.0, 1.0);
        let share = (black.y / white.y).clamp(0.0, 1.0);
        let column = |c: usize| {
            let p: Xyz = space.primaries.column(c).into_owned();
            adapt(
                &p,
                AdaptationTransform::Bradford,
                &source_white,
                &(white / white.y),
            ) * (white.y * (1.0 - share))
        };
        GamutAt::new(
            white * share,
            Matrix3::from_columns(&[column(0), column(1), column(2)]),
        )
    }
}

/// Braun and Fairchild (1999), J. Electronic Imaging 8(4), Table 3 (normal lightness
/// class): x₀ and Σ of the sigmoid for a reproduction black of L* 5, 10, 15 and 20,
/// the rows as Morovič's public reference code (PGMA 2.1) reads them. Between rows
/// linearly; below the first the first, above the last the last.
const SIGMOID_TABLE: [(f64, f64, f64); 4] = [
    (5.0, 53.7, 43.0),
    (10.0, 56.8, 40.0),
    (15.0, 58.2, 35.0),
    (20.0, 60.6, 34.5),
];

/// x₀ and Σ of Braun and Fairchild's sigmoid for a display whose black is at L*
/// `black_lightness`.
pub fn sigmoid_parameters(black_lightness: f64) -> (f64, f64) {
    let first = SIGMOID_TABLE[0];
    let last = SIGMOID_TABLE[SIGMOID_TABLE.len() - 1];
    if !(black_lightness > first.0) {
        return (first.1, first.2);
    }
    if black_lightness >= last.0 {
        return (last.1, last.2);
    }
    let i = SIGMOID_TABLE
        .windows(2)
        .position(|w| black_lightness < w[1].0)
        .unwrap_or(0);
    let (a, b) = (SIGMOID_TABLE[i], SIGMOID_TABLE[i + 1]);
    let t = (black_lightness - a.0) / (b.0 - a.0);
    (a.1 + t * (b.1 - a.1), a.2 + t * (b.2 - a.2))
}

/// Abramowitz and Stegun (1964) 7.1.26: erf(x) within 1.5·10⁻⁷.
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let y = 1.0 - poly * (-x * x).exp();
    if x < 0.0 { -y } else { y }
}

/// The cumulative normal distribution at `x` with mean `mean` and deviation `sd`.
fn normal_cdf(x: f64, mean: f64, sd: f64) -> f64 {
    0.5 * (1.0 + erf((x - mean) / (sd * std::f64::consts::SQRT_2)))
}

/// CIE 156's chroma weight of the sigmoid: p_C = 1 − √(C³ / (C³ + 5·10⁵)).
pub fn chroma_weight(chroma: f64) -> f64 {
    let c3 = chroma.max(0.0).powi(3);
    1.0 - (c3 / (c3 + 5.0e5)).sqrt()
}

/// SGCK's lightness mapping from a source lightness range onto a display's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightnessMap {
    source: (f64, f64),
    display: (f64, f64),
    x0: f64,
    sigma: f64,
    /// The source's range fits the display's: lightness is left alone.
    identity: bool,
}

/// Slack in L* for "the source's range fits the display's".
const RANGE_SLACK: f64 = 1e-6;

impl LightnessMap {
    pub fn new(source: (f64, f64), display: (f64, f64)) -> LightnessMap {
        let (x0, sigma) = sigmoid_parameters(display.0);
        LightnessMap {
            source,
            display,
            x0,
            sigma,
            identity: source.0 >= display.0 - RANGE_SLACK && source.1 <= display.1 + RANGE_SLACK,
        }
    }

    /// Braun and Fairchild's sigmoid: L normalised to 0–100 over the source's range,
    /// the cumulative normal there normalised to its values at 0 and 100, scaled
    /// onto the display's range.
    fn sigmoid(&self, l: f64) -> f64 {
        let (o_min, o_max) = self.source;
        let (r_min, r_max) = self.display;
        let span = o_max - o_min;
        if span <= 0.0 {
            return 0.5 * (r_min + r_max);
        }
        let x = 100.0 * (l.clamp(o_min, o_max) - o_min) / span;
        let at = |v: f64| normal_cdf(v, self.x0, self.sigma);
        let (lo, hi) = (at(0.0), at(100.0));
        r_min + (at(x) - lo) / (hi - lo) * (r_max - r_min)
    }

    /// The mapped lightness of a colour at L* `l` and chroma `chroma`.
    pub fn apply(&self, l: f64, chroma: f64) -> f64 {
        if self.identity {
            return l;
        }
        let p = chroma_weight(chroma);
        (1.0 - p) * l + p * self.sigmoid(l)
    }

    /// The source lightness that maps to `l` at `chroma`, or `None` when none in the
    /// source's range does. The map is increasing in L, so bisection finds it.
    fn invert(&self, l: f64, chroma: f64) -> Option<f64> {
        if self.identity {
            return Some(l);
        }
        let (mut lo, mut hi) = self.source;
        let (at_lo, at_hi) = (self.apply(lo, chroma), self.apply(hi, chroma));
        if l < at_lo - RANGE_SLACK || l > at_hi + RANGE_SLACK {
            return None;
        }
        for _ in 0..BISECTION_STEPS {
            let mid = 0.5 * (lo + hi);
            if self.apply(mid, chroma) < l {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(0.5 * (lo + hi))
    }
}

/// Bisection steps for boundaries and inverses: 2⁻⁴⁰ of the interval.
const BISECTION_STEPS: usize = 40;

/// Where the knee starts, as a share of the display's boundary distance (CIE 156).
pub const KNEE: f64 = 0.9;

/// A point of one CIELAB hue plane: lightness and chroma.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HuePoint {
    l: f64,
    c: f64,
}

/// The display's cusp at a hue (an angle in radians, as `atan2` gives it). A gamut
/// asked for again (a 3D LUT's, a uniform screen's) gets its table of cusps
/// ([`CuspTable`]) on the second call and reads it from then on; a gamut asked for
/// once (each pixel's own, on a screen with a spatial map) gets the exact search, as
/// building a table for one colour would cost thousands of searches.
fn cusp(gamut: &GamutAt, white: &Xyz, hue: f64) -> Option<HuePoint> {
    let (samples, table) = CUSPS_KEPT.with(|kept| {
        let mut kept = kept.borrow_mut();
        match kept.as_mut() {
            Some(k) if k.gamut == *gamut && k.white == *white => {
                let samples = k.samples.clone();
                let table = k
                    .table
                    .get_or_insert_with(|| Rc::new(CuspTable::new(gamut, white, &samples)))
                    .clone();
                (samples, Some(table))
            }
            _ => {
                let samples = Rc::new(loop_samples(gamut, white));
                *kept = Some(CuspsKept {
                    gamut: gamut.clone(),
                    white: *white,
                    samples: samples.clone(),
                    table: None,
                });
                (samples, None)
            }
        }
    });
    match table {
        Some(table) => table.at(gamut, white, &samples, hue),
        None => cusp_exact(gamut, white, &samples, hue).map(|found| found.point),
    }
}

/// What each thread keeps of the last gamut and white it asked `cusp` for: the edge
/// loop's samples, and the table of cusps once that gamut is asked for again.
struct CuspsKept {
    gamut: GamutAt,
    white: Xyz,
    samples: Rc<Vec<(Lab, f64)>>,
    table: Option<Rc<CuspTable>>,
}

thread_local! {
    static CUSPS_KEPT: RefCell<Option<CuspsKept>> = const { RefCell::new(None) };
}

/// A cusp as found: the point, and the segment of the edge loop it lies in (0 … 6 ×
/// `LOOP_STEPS` − 1; a segment's edge is `segment / LOOP_STEPS`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct FoundCusp {
    point: HuePoint,
    segment: usize,
}

/// The display's cusp at a hue: where the hue plane crosses the cube's edge loop
/// red–yellow–green–cyan–blue–magenta (each of those edges has one channel at full
/// drive and one at none: the upper faces meet the lower ones there, and there the
/// chroma at a hue is largest); and the loop's segment it lies in. `samples` are the
/// loop's (`loop_samples`).
fn cusp_exact(gamut: &GamutAt, white: &Xyz, samples: &[(Lab, f64)], hue: f64) -> Option<FoundCusp> {
    let at = |s: f64| -> Lab { edge_loop_lab(gamut, white, s) };
    // Signed hue difference in (−π, π].
    let wrap = |d: f64| {
        (d + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    };
    let offset = |lab: &Lab| wrap(lab.b.atan2(lab.a) - hue);
    let mut best: Option<FoundCusp> = None;
    let n = 6 * LOOP_STEPS;
    for k in 0..n {
        let (s0, s1) = (
            k as f64 / LOOP_STEPS as f64,
            (k + 1) as f64 / LOOP_STEPS as f64,
        );
        let (d0, d1) = (wrap(samples[k].1 - hue), wrap(samples[k + 1].1 - hue));
        // A crossing of the hue, not of its opposite (where the offset jumps by 2π).
        if d0.signum() == d1.signum() || (d0 - d1).abs() > std::f64::consts::PI {
            continue;
        }
        let (mut lo, mut hi) = (s0, s1);
        for _ in 0..BISECTION_STEPS {
            let mid = 0.5 * (lo + hi);
            if offset(&at(mid)).signum() == d0.signum() {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let lab = at(0.5 * (lo + hi));
        let point = HuePoint {
            l: lab.l,
            c: lab.a.hypot(lab.b),
        };
        if best.is_none_or(|b| point.c > b.point.c) {
            best = Some(FoundCusp { point, segment: k });
        }
    }
    best
}

/// Hues the cusp is tabulated at, evenly over the circle.
const CUSP_HUES: usize = 4096;

/// The display's cusp at `CUSP_HUES` hues, made once for a gamut and white: SGCK
/// asks for the cusp at every colour's hue, and finding it is a search along the
/// cube's edge loop (most of SGCK's time when it was done for each colour). Between
/// two neighbouring hues whose cusps lie on one edge, in the same or neighbouring
/// segments of the loop, L* and C* are interpolated linearly (there they change
/// smoothly with hue: within 3·10⁻⁴ in L* and C* at this spacing, measured; the test
/// holds 10⁻³); where the cusp passes a corner of the cube, or jumps between two
/// crossings of a folded loop, it is found exactly.
struct CuspTable {
    entries: Vec<Option<FoundCusp>>,
}

impl CuspTable {
    fn new(gamut: &GamutAt, white: &Xyz, samples: &[(Lab, f64)]) -> CuspTable {
        CuspTable {
            entries: (0..CUSP_HUES)
                .map(|k| cusp_exact(gamut, white, samples, Self::hue(k)))
                .collect(),
        }
    }

    /// The hue of entry `k`: −π … π (the last entry's neighbour is the first).
    fn hue(k: usize) -> f64 {
        -std::f64::consts::PI + std::f64::consts::TAU * k as f64 / CUSP_HUES as f64
    }

    fn at(
        &self,
        gamut: &GamutAt,
        white: &Xyz,
        samples: &[(Lab, f64)],
        hue: f64,
    ) -> Option<HuePoint> {
        let position = (hue + std::f64::consts::PI) / std::f64::consts::TAU * CUSP_HUES as f64;
        if !position.is_finite() {
            return None;
        }
        let below = (position.floor() as usize).min(CUSP_HUES - 1);
        let t = position - below as f64;
        match (self.entries[below], self.entries[(below + 1) % CUSP_HUES]) {
            (Some(a), Some(b)) if continuous(a.segment, b.segment) => Some(HuePoint {
                l: a.point.l + t * (b.point.l - a.point.l),
                c: a.point.c + t * (b.point.c - a.point.c),
            }),
            _ => cusp_exact(gamut, white, samples, hue).map(|found| found.point),
        }
    }
}

/// Two cusps a linear interpolation may join: on one edge of the cube, in the same
/// segment of the loop or in neighbouring ones.
fn continuous(a: usize, b: usize) -> bool {
    a / LOOP_STEPS == b / LOOP_STEPS && a.abs_diff(b) <= 1
}

/// The six edges of the cube's loop as (start corner, channel that moves, direction).
const LOOP: [([f64; 3], usize, f64); 6] = [
    ([1.0, 0.0, 0.0], 1, 1.0),
    ([1.0, 1.0, 0.0], 0, -1.0),
    ([0.0, 1.0, 0.0], 2, 1.0),
    ([0.0, 1.0, 1.0], 1, -1.0),
    ([0.0, 0.0, 1.0], 0, 1.0),
    ([1.0, 0.0, 1.0], 2, -1.0),
];

/// Samples an edge of the loop is cut into before the crossing is bisected.
const LOOP_STEPS: usize = 32;

/// CIELAB of the point `s` (0 … 6) along the edge loop of `gamut`.
fn edge_loop_lab(gamut: &GamutAt, white: &Xyz, s: f64) -> Lab {
    let edge = (s.floor() as usize).min(5);
    let (start, channel, direction) = LOOP[edge];
    let mut a = nalgebra::Vector3::from(start);
    a[channel] += direction * (s - edge as f64);
    xyz_to_lab(&gamut.from_cube(&a), white)
}

/// The loop's samples `k / LOOP_STEPS` (k = 0 … 6·LOOP_STEPS) for `gamut` and `white`,
/// each with its hue angle: the same for every hue, so made once for a gamut and white
/// (`CUSPS_KEPT`).
fn loop_samples(gamut: &GamutAt, white: &Xyz) -> Vec<(Lab, f64)> {
    (0..=6 * LOOP_STEPS)
        .map(|k| {
            let lab = edge_loop_lab(gamut, white, k as f64 / LOOP_STEPS as f64);
            (lab, lab.b.atan2(lab.a))
        })
        .collect()
}

/// SGCK (CIE 156:2004) of `xyz` from the `source` gamut into `gamut`, in CIELAB
/// against `white`. What the knee leaves outside (a colour beyond the source gamut
/// itself) is clipped toward the grey axis at constant hue and lightness.
pub fn sgck(gamut: &GamutAt, source: &GamutAt, xyz: &Xyz, white: &Xyz) -> Xyz {
    sgck_with_cusp(
        gamut,
        source,
        xyz,
        white,
        |hue| cusp(gamut, white, hue),
        LINE_STEPS,
    )
}

/// Bisection steps for where a line from the focal point leaves the display's and the
/// source's gamut: 2⁻²⁴ of the line (about 10⁻⁵ in L* and C* on a line of 200, far
/// below a code step; 40 steps took a third of SGCK's time).
const LINE_STEPS: usize = 24;

/// [`sgck`] with the display's cusp at a hue from `cusp`.
fn sgck_with_cusp(
    gamut: &GamutAt,
    source: &GamutAt,
    xyz: &Xyz,
    white: &Xyz,
    cusp: impl Fn(f64) -> Option<HuePoint>,
    line_steps: usize,
) -> Xyz {
    let lab = xyz_to_lab(xyz, white);
    if ![lab.l, lab.a, lab.b].iter().all(|v| v.is_finite()) {
        return clip(gamut, xyz);
    }
    let lightness = |g: &GamutAt| {
        (
            xyz_to_lab(&g.black(), white).l,
            xyz_to_lab(&g.white(), white).l,
        )
    };
    let map = LightnessMap::new(lightness(source), lightness(gamut));
    // Where nothing is to be compressed a colour inside comes back as it went in,
    // not through a round trip to CIELAB.
    let unchanged = map.identity && gamut.contains(xyz);
    let chroma = lab.a.hypot(lab.b);
    let hue = lab.b.atan2(lab.a);
    let (cos, sin) = (hue.cos(), hue.sin());
    let to_xyz = |p: HuePoint| {
        lab_to_xyz(
            &Lab {
                l: p.l,
                a: p.c * cos,
                b: p.c * sin,
            },
            white,
        )
    };
    let mapped = HuePoint {
        l: map.apply(lab.l, chroma),
        c: chroma,
    };
    let finish = |p: HuePoint| {
        if unchanged && p == mapped {
            return *xyz;
        }
        let x = to_xyz(p);
        if gamut.contains(&x) {
            x
        } else {
            grey_axis_clip(gamut, &x, UniformSpace::Lab, white)
        }
    };
    let Some(focus) = cusp(hue) else {
        return finish(mapped);
    };
    let origin = HuePoint { l: focus.l, c: 0.0 };
    let along = |t: f64| HuePoint {
        l: origin.l + t * (mapped.l - origin.l),
        c: t * mapped.c,
    };
    if (mapped.l - origin.l).abs() + mapped.c < 1e-9 {
        return finish(mapped);
    }
    let in_display = |t: f64| gamut.contains(&to_xyz(along(t)));
    // The source gamut after the lightness mapping: a point is in it when the source
    // lightness that maps to it, at its chroma, gives a colour of the source.
    let in_source = |t: f64| {
        let p = along(t);
        map.invert(p.l, p.c)
            .is_some_and(|l| source.contains(&to_xyz(HuePoint { l, c: p.c })))
    };
    let (Some(display_edge), Some(source_edge)) = (
        last_inside_within(in_display, 1.0, line_steps),
        last_inside_within(in_source, 1.0, line_steps),
    ) else {
        return finish(mapped);
    };
    let knee = KNEE * display_edge;
    if source_edge <= display_edge || 1.0 <= knee {
        // Nothing to compress on this line: only the lightness mapping moved it.
        return finish(mapped);
    }
    finish(along(
        knee + (display_edge - knee) * (1.0 - knee) / (source_edge - knee),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erf_matches_known_values() {
        // erf(0.5) = 0.5204998778, erf(1) = 0.8427007929, erf(2) = 0.9953222650.
        for (x, want) in [
            (0.5, 0.520_499_877_8),
            (1.0, 0.842_700_792_9),
            (2.0, 0.995_322_265_0),
        ] {
            assert!((erf(x) - want).abs() < 2e-7, "erf({x}) = {}", erf(x));
            assert!((erf(-x) + want).abs() < 2e-7);
        }
    }

    #[test]
    fn sigmoid_parameters_follow_the_table() {
        assert_eq!(sigmoid_parameters(0.0), (53.7, 43.0));
        assert_eq!(sigmoid_parameters(10.0), (56.8, 40.0));
        let (x0, sigma) = sigmoid_parameters(12.5);
        assert!((x0 - 57.5).abs() < 1e-12 && (sigma - 37.5).abs() < 1e-12);
        assert_eq!(sigmoid_parameters(40.0), (60.6, 34.5));
    }

    #[test]
    fn the_chroma_weight_is_one_for_greys_and_falls_with_chroma() {
        assert_eq!(chroma_weight(0.0), 1.0);
        assert!(chroma_weight(50.0) > chroma_weight(100.0));
        // C = (5·10⁵)^(1/3) ≈ 79.4 gives p = 1 − √½.
        let c = 5.0e5f64.cbrt();
        assert!((chroma_weight(c) - (1.0 - 0.5f64.sqrt())).abs() < 1e-12);
    }

    #[test]
    fn the_sigmoid_runs_from_the_display_black_to_its_white_and_rises() {
        let map = LightnessMap::new((0.0, 100.0), (8.0, 100.0));
        assert!((map.apply(0.0, 0.0) - 8.0).abs() < 1e-9);
        assert!((map.apply(100.0, 0.0) - 100.0).abs() < 1e-9);
        let mut last = f64::NEG_INFINITY;
        for k in 0..=100 {
            let l = map.apply(k as f64, 0.0);
            assert!(l > last);
            last = l;
            let back = map.invert(l, 0.0).unwrap();
            assert!((back - k as f64).abs() < 1e-6);
        }
        // A source that fits leaves lightness alone.
        let fits = LightnessMap::new((8.0, 100.0), (5.0, 100.0));
        assert_eq!(fits.apply(37.0, 0.0), 37.0);
    }

    fn hue_degrees(xyz: &Xyz, white: &Xyz) -> f64 {
        let lab = xyz_to_lab(xyz, white);
        lab.b.atan2(lab.a).to_degrees()
    }

    /// The cube's points on a 9-level grid.
    fn cube_grid() -> Vec<nalgebra::Vector3<f64>> {
        let s = |i: usize| i as f64 / 8.0;
        (0..729)
            .map(|k| nalgebra::Vector3::new(s(k % 9), s(k / 9 % 9), s(k / 81)))
            .collect()
    }

    #[test]
    fn a_source_inside_the_display_moves_nothing() {
        let display = crate::gamut::tests::gamut();
        let (white, black) = (display.white(), display.black());
        // The display's own gamut as the source, then sRGB on a P3 display.
        let p3 = SgckSource::P3.gamut(&white, &black).unwrap();
        let srgb = SgckSource::Srgb.gamut(&white, &black).unwrap();
        for (source, target) in [(&display, &display), (&srgb, &p3)] {
            for a in cube_grid() {
                let xyz = source.from_cube(&a);
                assert!(target.contains(&xyz));
                assert_eq!(sgck(target, source, &xyz, &white), xyz, "cube {a:?}");
            }
        }
    }

    #[test]
    fn a_wider_source_is_compressed_inside_keeping_hue_and_order() {
        let display = crate::gamut::tests::gamut();
        let (white, black) = (display.white(), display.black());
        let source = SgckSource::Rec2020.gamut(&white, &black).unwrap();
        let mut moved_inside = 0;
        for a in cube_grid() {
            let xyz = source.from_cube(&a);
            let out = sgck(&display, &source, &xyz, &white);
            assert!(display.contains(&out), "cube {a:?} left outside");
            let lab = xyz_to_lab(&xyz, &white);
            if lab.a.hypot(lab.b) > 1.0 {
                let turn = (hue_degrees(&out, &white) - hue_degrees(&xyz, &white) + 540.0)
                    .rem_euclid(360.0)
                    - 180.0;
                assert!(turn.abs() < 1.0, "cube {a:?} turned {turn}°");
            }
            if display.contains(&xyz) && out != xyz {
                moved_inside += 1;
            }
        }
        // The knee takes room inside the display for what comes from outside.
        assert!(moved_inside > 0);
        // Along a line of rising chroma beyond the display, the order is kept
        // (clipping would send them all to one point).
        let hue: f64 = 150f64.to_radians();
        let mut last = 0.0;
        for c in [60.0, 70.0, 80.0, 90.0] {
            let lab = Lab {
                l: 60.0,
                a: c * hue.cos(),
                b: c * hue.sin(),
            };
            let xyz = lab_to_xyz(&lab, &white);
            if !source.contains(&xyz) {
                continue;
            }
            let out = xyz_to_lab(&sgck(&display, &source, &xyz, &white), &white);
            let chroma = out.a.hypot(out.b);
            assert!(chroma > last + 0.1, "C* {c} went to {chroma}, after {last}");
            last = chroma;
        }
        assert!(last > 0.0);
        // Below the knee nothing moves: a pale colour keeps its place.
        let pale = lab_to_xyz(
            &Lab {
                l: 60.0,
                a: 5.0,
                b: -5.0,
            },
            &white,
        );
        assert_eq!(sgck(&display, &source, &pale, &white), pale);
    }

    /// The tabulated cusp is the exact one within 10⁻³ in L* and C* between the
    /// table's hues; SGCK through it (and its lines bisected 24 times) is SGCK as it
    /// was (the cusp searched for each colour, 40 steps) within 0.01 ΔE00
    /// on every point of a 33³ grid of each source, on the display's centre and on a
    /// dimmer corner (where the sigmoid acts too).
    #[test]
    fn the_tabulated_cusp_is_the_exact_one() {
        let display = crate::gamut::tests::gamut();
        let white = display.white();
        let samples = loop_samples(&display, &white);
        let table = CuspTable::new(&display, &white, &samples);
        let (mut exact_lookups, mut worst) = (0, 0.0f64);
        for k in 0..20_000 {
            let hue = -std::f64::consts::PI + std::f64::consts::TAU * (k as f64 + 0.37) / 20_000.0;
            let want = cusp_exact(&display, &white, &samples, hue).unwrap().point;
            let got = table.at(&display, &white, &samples, hue).unwrap();
            worst = worst
                .max((got.l - want.l).abs())
                .max((got.c - want.c).abs());
            let position = (hue + std::f64::consts::PI) / std::f64::consts::TAU * CUSP_HUES as f64;
            let below = position.floor() as usize % CUSP_HUES;
            let (a, b) = (table.entries[below], table.entries[(below + 1) % CUSP_HUES]);
            if !a
                .zip(b)
                .is_some_and(|(a, b)| continuous(a.segment, b.segment))
            {
                exact_lookups += 1;
            }
        }
        assert!(worst < 1e-3, "tabulated cusp off by {worst}");
        // The cusp passes the cube's six corners: found exactly there, and only there.
        assert!((6..60).contains(&exact_lookups), "{exact_lookups}");
        let dimmer = GamutAt::new(display.black(), display.primaries * 0.8).unwrap();
        let s = |i: usize| i as f64 / 32.0;
        let mut largest = 0.0f64;
        for target in [&display, &dimmer] {
            let target_samples = loop_samples(target, &white);
            for source in [SgckSource::Srgb, SgckSource::Rec2020] {
                let source = source.gamut(&white, &display.black()).unwrap();
                for k in 0..33 * 33 * 33 {
                    let a = nalgebra::Vector3::new(s(k % 33), s(k / 33 % 33), s(k / 1089));
                    let xyz = source.from_cube(&a);
                    let fast = sgck(target, &source, &xyz, &white);
                    // As SGCK was before the table: the cusp searched for each
                    // colour, the lines bisected 40 times.
                    let exact = sgck_with_cusp(
                        target,
                        &source,
                        &xyz,
                        &white,
                        |hue| cusp_exact(target, &white, &target_samples, hue).map(|f| f.point),
                        BISECTION_STEPS,
                    );
                    let de = chromacal_model::fit::validate::delta_e00_xyz(&fast, &exact, &white);
                    assert!(de < 0.01, "cube {a:?}: ΔE00 {de}");
                    largest = largest.max(de);
                }
            }
        }
        eprintln!("SGCK through the table: largest ΔE00 {largest:.2e} from SGCK as it was");
    }

    /// A gamut asked for once (each pixel's own on a screen with a spatial map) gets
    /// the exact search and no table (a table for one colour cost thousands of
    /// searches: a 300 × 200 SGCK render went from 7 s to over 5 min); asked again, its
    /// table is made and read.
    #[test]
    fn only_a_gamut_asked_for_again_gets_a_table() {
        let display = crate::gamut::tests::gamut();
        let white = display.white();
        let has_table =
            || CUSPS_KEPT.with(|k| k.borrow().as_ref().is_some_and(|k| k.table.is_some()));
        for scale in [0.9, 0.8, 0.7] {
            let gamut = GamutAt::new(display.black(), display.primaries * scale).unwrap();
            let hue = 0.7;
            let exact =
                cusp_exact(&gamut, &white, &loop_samples(&gamut, &white), hue).map(|f| f.point);
            assert_eq!(cusp(&gamut, &white, hue), exact);
            assert!(!has_table(), "a table for a gamut asked for once");
        }
        let gamut = GamutAt::new(display.black(), display.primaries * 0.6).unwrap();
        assert!(cusp(&gamut, &white, 0.7).is_some());
        assert!(cusp(&gamut, &white, 0.71).is_some());
        assert!(has_table());
    }

    #[test]
    fn a_source_with_a_deeper_black_is_mapped_onto_the_display_greys() {
        let display = crate::gamut::tests::gamut();
        let white = display.white();
        // The source reaches true black; the display's black is at L* 4.5.
        let source = SgckSource::Srgb.gamut(&white, &Xyz::zeros()).unwrap();
        let black_l = xyz_to_lab(&display.black(), &white).l;
        let mut last = f64::NEG_INFINITY;
        for k in 0..=20 {
            let grey = source.from_cube(&nalgebra::Vector3::repeat(k as f64 / 20.0));
            let out = sgck(&display, &source, &grey, &white);
            assert!(display.contains(&out));
            let l = xyz_to_lab(&out, &white).l;
            assert!(l > last, "grey {k} at L* {l} after {last}");
            last = l;
            if k == 0 {
                // Within the step the display's slightly bluish black takes.
                assert!(
                    (l - black_l).abs() < 0.05,
                    "black at L* {l}, display {black_l}"
                );
            }
        }
        assert!((last - 100.0).abs() < 1e-6);
    }
}
