//! CIE colour spaces derived from tristimulus values: xyY, u′v′ (CIE 1976 UCS),
//! CIE 1976 L*a*b* and L*u*v*. Equations from CIE 15:2004, *Colorimetry*, 3rd ed.
//!
//! Tristimulus values are in any consistent unit (cd/m² or relative); the spaces that
//! need a reference white take it in the same unit.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// CIE XYZ tristimulus values.
pub type Xyz = Vector3<f64>;

/// CIE xyY: chromaticity coordinates and luminance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Xyy {
    pub x: f64,
    pub y: f64,
    #[serde(rename = "Y")]
    pub big_y: f64,
}

/// CIE 1976 UCS chromaticity coordinates u′, v′.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UvPrime {
    pub u: f64,
    pub v: f64,
}

/// CIE 1976 L*a*b*.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Lab {
    pub l: f64,
    pub a: f64,
    pub b: f64,
}

/// CIE 1976 L*u*v*.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Luv {
    pub l: f64,
    pub u: f64,
    pub v: f64,
}

/// ε = (6/29)³ = 216/24389: the CIE's break point between the cube-root and the
/// linear part of L* (CIE 15:2004 eq. 8.3, written with exact fractions).
const LAB_EPSILON: f64 = 216.0 / 24389.0;
/// κ = (29/3)³ = 24389/27: slope of the linear part of L* (CIE 15:2004 eq. 8.3).
const LAB_KAPPA: f64 = 24389.0 / 27.0;

/// xyY from XYZ (CIE 15:2004 eq. 7.3).
///
/// Where X+Y+Z is not positive (a black, or a black-subtracted reading that noise
/// pushed below zero) the chromaticity is undefined; `fallback_xy` (usually the
/// display's white) is returned with the given Y, so callers never divide by zero.
pub fn xyz_to_xyy(xyz: &Xyz, fallback_xy: [f64; 2]) -> Xyy {
    let sum = xyz.x + xyz.y + xyz.z;
    if !(sum > 0.0 && sum.is_finite()) {
        return Xyy {
            x: fallback_xy[0],
            y: fallback_xy[1],
            big_y: xyz.y,
        };
    }
    Xyy {
        x: xyz.x / sum,
        y: xyz.y / sum,
        big_y: xyz.y,
    }
}

/// XYZ from xyY (CIE 15:2004 eq. 7.3, inverted). A chromaticity with y = 0 carries no
/// luminance, so it maps to zero.
pub fn xyy_to_xyz(xyy: &Xyy) -> Xyz {
    if xyy.y == 0.0 {
        return Xyz::zeros();
    }
    let scale = xyy.big_y / xyy.y;
    Xyz::new(xyy.x * scale, xyy.big_y, (1.0 - xyy.x - xyy.y) * scale)
}

/// u′v′ from XYZ (CIE 15:2004 eq. 8.9): u′ = 4X / (X + 15Y + 3Z), v′ = 9Y / (X + 15Y + 3Z).
/// `fallback` is returned where the denominator is not positive.
pub fn xyz_to_uv_prime(xyz: &Xyz, fallback: UvPrime) -> UvPrime {
    let d = xyz.x + 15.0 * xyz.y + 3.0 * xyz.z;
    if !(d > 0.0 && d.is_finite()) {
        return fallback;
    }
    UvPrime {
        u: 4.0 * xyz.x / d,
        v: 9.0 * xyz.y / d,
    }
}

/// u′v′ from xy chromaticity (CIE 15:2004 eq. 8.10).
pub fn xy_to_uv_prime(x: f64, y: f64) -> UvPrime {
    let d = -2.0 * x + 12.0 * y + 3.0;
    UvPrime {
        u: 4.0 * x / d,
        v: 9.0 * y / d,
    }
}

/// f(t) of CIE 15:2004 eq. 8.4–8.5: the cube root above ε, its linear continuation below.
fn lab_f(t: f64) -> f64 {
    if t > LAB_EPSILON {
        cube_root(t)
    } else {
        (LAB_KAPPA * t + 16.0) / 116.0
    }
}

/// The cube root of a positive `t`, within one unit in the last place of the correctly
/// rounded one (`f64::cbrt`, which this build links to Rust's libm, a port of
/// CORE-MATH's correctly rounded cube root, and slow: three of them a colour were a
/// twelfth of a render's time; this takes two fifths of its time). A first guess
/// from the bits (a third of the exponent plus Kahan's constant, as fdlibm's `cbrt`
/// starts, a few per cent off), two steps of Halley's method (cubic: 10⁻⁵, then
/// 10⁻¹⁴) and one of Newton's (quadratic: to the rounding).
/// Outside 10⁻¹⁰⁰…10¹⁰⁰, where a cube in the steps could leave the doubles' range,
/// and for NaN, `f64::cbrt` itself.
#[inline]
pub fn cube_root(t: f64) -> f64 {
    if !(1e-100..=1e100).contains(&t) {
        return t.cbrt();
    }
    let mut y = f64::from_bits(t.to_bits() / 3 + 0x2A9F_7893_782D_A1CE);
    for _ in 0..2 {
        let y3 = y * y * y;
        y *= (y3 + 2.0 * t) / (2.0 * y3 + t);
    }
    y - (y * y * y - t) / (3.0 * y * y)
}

/// Inverse of [`lab_f`].
fn lab_f_inverse(f: f64) -> f64 {
    let t = f * f * f;
    if t > LAB_EPSILON {
        t
    } else {
        (116.0 * f - 16.0) / LAB_KAPPA
    }
}

/// CIE 1976 L* of a relative luminance Y/Yn (CIE 15:2004 eq. 8.3 with eq. 8.5 below ε).
pub fn luminance_to_lightness(y_relative: f64) -> f64 {
    116.0 * lab_f(y_relative) - 16.0
}

/// Relative luminance Y/Yn of a CIE 1976 lightness L* (inverse of CIE 15:2004 eq. 8.3).
pub fn lightness_to_luminance(l_star: f64) -> f64 {
    lab_f_inverse((l_star + 16.0) / 116.0)
}

/// CIE 1976 L*a*b* from XYZ relative to the reference white `white`
/// (CIE 15:2004 eq. 8.3–8.8).
pub fn xyz_to_lab(xyz: &Xyz, white: &Xyz) -> Lab {
    let fx = lab_f(xyz.x / white.x);
    let fy = lab_f(xyz.y / white.y);
    let fz = lab_f(xyz.z / white.z);
    Lab {
        l: 116.0 * fy - 16.0,
        a: 500.0 * (fx - fy),
        b: 200.0 * (fy - fz),
    }
}

/// 2^(5/3): (t/2)^(−5/3) is 2^(5/3) t^(−5/3).
const TWO_TO_THE_FIVE_THIRDS: f64 = 3.174_802_103_936_399;
/// 1/9 ε^(−5/3) = 1/9 (29/6)⁵ = 20511149 / 69984: `LabTangent`'s curvature for a step
/// from the linear part of L* into the cube root.
const LINEAR_PART_CURVATURE: f64 = 20_511_149.0 / 69_984.0;

/// L*a*b* near one colour: CIE 15:2004 eq. 8.3–8.8 differentiated at `xyz`, so that
/// the change of L*a*b* for a small change of XYZ costs a few multiplications, not
/// three cube roots; with a bound on what the first order leaves out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabTangent {
    /// X/Xn, Y/Yn, Z/Zn.
    relative: [f64; 3],
    /// f′(t) of each, over the white's coordinate: ∂f/∂X, ∂f/∂Y, ∂f/∂Z.
    slope: [f64; 3],
    /// 1 / Xn, 1 / Yn, 1 / Zn.
    inverse_white: [f64; 3],
    /// Half the largest |f″| over a step that keeps t above half its value (or above
    /// ε, from below it): 1/9 (t/2)^(−5/3), and 1/9 ε^(−5/3).
    curvature: [f64; 3],
    /// ½ f″(t) on the cube root, −f / 9t² (0 on the linear part), over the white's
    /// coordinate squared: the second-order term per XYZ².
    half_second: [f64; 3],
    /// A sixth of the largest |f‴| over a step that keeps t above half its value,
    /// (10/27) (t/2)^(−8/3) / 6 = (5/81) 2^(8/3) f / t³, 0 on the linear part.
    third: [f64; 3],
}

/// (5/81) · 2^(8/3): `LabTangent`'s third-order remainder per f / t³.
const THIRD_ORDER_REMAINDER: f64 = 0.391_950_877_029_185;

impl LabTangent {
    /// The tangent at `xyz` relative to `white`, `lab` being its L*a*b* (the cube
    /// roots `xyz_to_lab` took, so that they are not taken again).
    pub fn at(xyz: &Xyz, white: &Xyz, lab: &Lab) -> LabTangent {
        let fy = (lab.l + 16.0) / 116.0;
        let f = [fy + lab.a / 500.0, fy, fy - lab.b / 200.0];
        let inverse_white = [1.0 / white.x, 1.0 / white.y, 1.0 / white.z];
        let relative = [
            xyz.x * inverse_white[0],
            xyz.y * inverse_white[1],
            xyz.z * inverse_white[2],
        ];
        let mut slope = [0.0; 3];
        let mut curvature = [0.0; 3];
        let mut half_second = [0.0; 3];
        let mut third = [0.0; 3];
        for c in 0..3 {
            let t = relative[c];
            // f′ = f / 3t on the cube root, κ / 116 on the linear part; t^(−5/3) is
            // f / t² there (f³ = t), t^(−8/3) is f / t³: one division a coordinate,
            // where four were most of the tangent's time.
            if t > LAB_EPSILON {
                let over_t = 1.0 / t;
                let (f_over_t, f_over_t2) = (f[c] * over_t, f[c] * over_t * over_t);
                slope[c] = f_over_t * (1.0 / 3.0) * inverse_white[c];
                curvature[c] = TWO_TO_THE_FIVE_THIRDS / 9.0 * f_over_t2;
                half_second[c] = -f_over_t2 * (1.0 / 9.0) * inverse_white[c] * inverse_white[c];
                third[c] = THIRD_ORDER_REMAINDER * f_over_t2 * over_t;
            } else {
                slope[c] = LAB_KAPPA / 116.0 * inverse_white[c];
                curvature[c] = LINEAR_PART_CURVATURE;
            }
        }
        LabTangent {
            relative,
            slope,
            inverse_white,
            curvature,
            half_second,
            third,
        }
    }

    /// ΔL*, Δa*, Δb* for the XYZ change `step`, to first order.
    #[inline]
    pub fn delta(&self, step: [f64; 3]) -> [f64; 3] {
        let df = [
            self.slope[0] * step[0],
            self.slope[1] * step[1],
            self.slope[2] * step[2],
        ];
        [
            116.0 * df[1],
            500.0 * (df[0] - df[1]),
            200.0 * (df[1] - df[2]),
        ]
    }

    /// A bound on what [`Self::delta`] leaves out, in the largest coordinate, for
    /// every step no larger in X, Y and Z than `reach`: infinite where such a step
    /// could take a coordinate below half its value (too far for the tangent). On the
    /// cube root, the second-order term at the colour itself, |½ f″(t)| dt², and the
    /// third order's bound ([`Self::second_order_error`]): about a third of half the
    /// curvature's largest over the step times dt², which it is where the step may
    /// cross onto L*'s linear part.
    #[inline]
    pub fn error(&self, reach: [f64; 3]) -> f64 {
        let remainder_of = |c: usize| {
            let dt = reach[c].abs() * self.inverse_white[c];
            let first = self.first_order_remainder(c, dt);
            if first == 0.0 || first == f64::INFINITY || self.relative[c] - dt <= LAB_EPSILON {
                first
            } else {
                (self.half_second[c] * reach[c] * reach[c]).abs() + self.third[c] * dt * dt * dt
            }
        };
        in_lab([remainder_of(0), remainder_of(1), remainder_of(2)])
    }

    /// What the first order leaves out of f(t) for coordinate `c` over a step of `dt`
    /// (relative to the white) either way: 0 on L*'s linear part, infinite beyond half
    /// of t, and half the curvature's largest times dt² between.
    #[inline]
    fn first_order_remainder(&self, c: usize, dt: f64) -> f64 {
        let t = self.relative[c];
        if t + dt <= LAB_EPSILON {
            0.0
        } else if t > LAB_EPSILON && dt > 0.5 * t {
            f64::INFINITY
        } else {
            self.curvature[c] * dt * dt
        }
    }

    /// ΔL*, Δa*, Δb* for the XYZ change `step` to second order, with a bound on what
    /// that leaves out in the largest coordinate ([`Self::second_order_error`] of the
    /// step's own size). A code step of an 8-bit display is about 1 % of t, where
    /// this bound is about a hundredth of the first order's ((10/9) dt / t of it).
    #[inline]
    pub fn delta_to_second_order(&self, step: [f64; 3]) -> ([f64; 3], f64) {
        (
            self.second_order_delta(step),
            self.second_order_error(step.map(f64::abs)),
        )
    }

    /// ΔL*, Δa*, Δb* for the XYZ change `step` to second order, without a bound: a few
    /// multiplications, for many steps whose bound [`Self::second_order_error`] takes
    /// once at their largest size in each coordinate.
    #[inline(always)]
    pub fn second_order_delta(&self, step: [f64; 3]) -> [f64; 3] {
        let df = [0, 1, 2].map(|c| (self.slope[c] + self.half_second[c] * step[c]) * step[c]);
        [
            116.0 * df[1],
            500.0 * (df[0] - df[1]),
            200.0 * (df[1] - df[2]),
        ]
    }

    /// A bound on what [`Self::second_order_delta`] leaves out, in the largest
    /// coordinate, for every step no larger in X, Y and Z than `reach`: a sixth of
    /// f‴'s largest over the step, times the step cubed, where the step stays on the
    /// cube root within half of t; where it may cross onto L*'s linear part,
    /// [`Self::error`]'s bound plus the second-order term's size (both parts are then
    /// bounds on their own); 0 on the linear part; infinite where [`Self::error`] is.
    /// It grows with each coordinate of `reach`, so one bound at the largest of many
    /// steps holds for each of them.
    #[inline(always)]
    pub fn second_order_error(&self, reach: [f64; 3]) -> f64 {
        let remainder_of = |c: usize| {
            let dt = reach[c] * self.inverse_white[c];
            let first = self.first_order_remainder(c, dt);
            if first == 0.0 || first == f64::INFINITY {
                first
            } else if self.relative[c] - dt > LAB_EPSILON {
                self.third[c] * dt * dt * dt
            } else {
                first + (self.half_second[c] * reach[c] * reach[c]).abs()
            }
        };
        in_lab([remainder_of(0), remainder_of(1), remainder_of(2)])
    }
}

/// The largest change in L*, a* or b* of changes of at most `remainder` in f(X/Xn),
/// f(Y/Yn) and f(Z/Zn) (CIE 15:2004 eq. 8.3–8.5).
#[inline]
fn in_lab(remainder: [f64; 3]) -> f64 {
    (116.0 * remainder[1])
        .max(500.0 * (remainder[0] + remainder[1]))
        .max(200.0 * (remainder[1] + remainder[2]))
}

/// XYZ from CIE 1976 L*a*b* (inverse of CIE 15:2004 eq. 8.3–8.8).
pub fn lab_to_xyz(lab: &Lab, white: &Xyz) -> Xyz {
    let fy = (lab.l + 16.0) / 116.0;
    let fx = fy + lab.a / 500.0;
    let fz = fy - lab.b / 200.0;
    Xyz::new(
        white.x * lab_f_inverse(fx),
        white.y * lab_f_inverse(fy),
        white.z * lab_f_inverse(fz),
    )
}

/// CIE 1976 L*u*v* from XYZ relative to `white` (CIE 15:2004 eq. 8.3 and 8.9–8.12).
/// A colour with no u′v′ (black) has u* = v* = 0.
pub fn xyz_to_luv(xyz: &Xyz, white: &Xyz) -> Luv {
    let l = luminance_to_lightness(xyz.y / white.y);
    let n = xyz_to_uv_prime(white, UvPrime { u: 0.0, v: 0.0 });
    let uv = xyz_to_uv_prime(xyz, n);
    Luv {
        l,
        u: 13.0 * l * (uv.u - n.u),
        v: 13.0 * l * (uv.v - n.v),
    }
}

/// XYZ from CIE 1976 L*u*v* (inverse of CIE 15:2004 eq. 8.3 and 8.9–8.12): Y from L*,
/// then u′ = u*/(13 L*) + u′ₙ and v′ likewise, and X, Z from Y, u′, v′. L* ≤ 0 is
/// black.
pub fn luv_to_xyz(luv: &Luv, white: &Xyz) -> Xyz {
    if luv.l <= 0.0 {
        return Xyz::zeros();
    }
    let y = white.y * lightness_to_luminance(luv.l);
    let n = xyz_to_uv_prime(white, UvPrime { u: 0.0, v: 0.0 });
    let u = luv.u / (13.0 * luv.l) + n.u;
    let v = luv.v / (13.0 * luv.l) + n.v;
    if v <= 0.0 {
        return Xyz::new(0.0, y, 0.0);
    }
    Xyz::new(
        y * 9.0 * u / (4.0 * v),
        y,
        y * (12.0 - 3.0 * u - 20.0 * v) / (4.0 * v),
    )
}

/// Chroma and hue angle (degrees in [0, 360)) of a L*a*b* colour (CIE 15:2004 eq. 8.13–8.14).
pub fn lab_to_lch(lab: &Lab) -> (f64, f64, f64) {
    let c = lab.a.hypot(lab.b);
    let mut h = lab.b.atan2(lab.a).to_degrees();
    if h < 0.0 {
        h += 360.0;
    }
    (lab.l, c, h)
}

/// XYZ of a D65 scene (white at Y = 1) to linear sRGB: the matrix of IEC
/// 61966-2-1:1999 §5.2, eq. (5), as the standard gives it to four decimals.
const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// 8-bit sRGB of XYZ relative to a D65 white at Y = 1 (IEC 61966-2-1:1999 eqs. 5
/// and 6): linear values clipped to [0, 1], then 12.92·v below 0.0031308 and
/// 1.055·v^(1/2.4) − 0.055 above. For showing a colour on a page, not for measuring it.
pub fn xyz_to_srgb8(xyz: &Xyz) -> [u8; 3] {
    XYZ_TO_LINEAR_SRGB.map(|row| {
        let linear = (row[0] * xyz.x + row[1] * xyz.y + row[2] * xyz.z).clamp(0.0, 1.0);
        let encoded = if linear <= 0.003_130_8 {
            12.92 * linear
        } else {
            1.055 * linear.powf(1.0 / 2.4) - 0.055
        };
        (encoded * 255.0).round() as u8
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn d65() -> Xyz {
        Xyz::new(95.047, 100.0, 108.883)
    }

    /// Units in the last place between two doubles of one sign.
    fn ulps(a: f64, b: f64) -> u64 {
        (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs()
    }

    #[test]
    fn the_cube_root_is_the_correctly_rounded_one_within_an_ulp() {
        // Every millionth of ε…1, evenly in the logarithm over 10⁻¹⁰⁰…10¹⁰⁰, and
        // the ends.
        let even = (0..1_000_000).map(|i| LAB_EPSILON + i as f64 * 1e-6);
        let logarithmic = (0..200_001).map(|i| 10f64.powf(-100.0 + i as f64 * 1e-3));
        let (mut worst, mut exact, mut n) = (0, 0, 0);
        for t in even.chain(logarithmic) {
            let d = ulps(cube_root(t), t.cbrt());
            worst = worst.max(d);
            exact += usize::from(d == 0);
            n += 1;
        }
        assert!(worst <= 1, "{worst} ulps");
        // Most are the same double: a bound of one ulp that is met by rounding
        // alone would pass too, so this asks for it.
        assert!(exact * 4 > n * 3, "{exact} of {n} exact");
        for t in [1e-300, 1e-101, 1e101, 1e300, f64::MAX] {
            assert_eq!(cube_root(t), t.cbrt(), "{t:e}");
        }
        for (cube, root) in [(1.0, 1.0), (8.0, 2.0), (27.0, 3.0), (0.125, 0.5)] {
            assert_eq!(cube_root(cube), root);
        }
        assert_eq!(cube_root(f64::INFINITY), f64::INFINITY);
        assert!(cube_root(f64::NAN).is_nan());
    }

    #[test]
    fn luv_round_trips_through_xyz() {
        for xyz in [
            Xyz::new(41.24, 21.26, 1.93),
            Xyz::new(18.05, 7.22, 95.05),
            Xyz::new(0.5, 0.4, 0.3),
            d65(),
        ] {
            let back = luv_to_xyz(&xyz_to_luv(&xyz, &d65()), &d65());
            assert!(
                (back - xyz).norm() < 1e-9 * xyz.norm(),
                "{xyz:?} -> {back:?}"
            );
        }
    }

    #[test]
    fn white_is_l100_and_neutral() {
        let lab = xyz_to_lab(&d65(), &d65());
        assert!((lab.l - 100.0).abs() < 1e-12);
        assert!(lab.a.abs() < 1e-12 && lab.b.abs() < 1e-12);
        let luv = xyz_to_luv(&d65(), &d65());
        assert!((luv.l - 100.0).abs() < 1e-12 && luv.u.abs() < 1e-12 && luv.v.abs() < 1e-12);
    }

    #[test]
    fn lab_round_trip_including_the_linear_part() {
        for xyz in [
            Xyz::new(41.24, 21.26, 1.93),
            Xyz::new(0.05, 0.04, 0.09),
            Xyz::new(0.0, 0.0, 0.0),
            Xyz::new(80.0, 90.0, 120.0),
        ] {
            let back = lab_to_xyz(&xyz_to_lab(&xyz, &d65()), &d65());
            assert!((back - xyz).norm() < 1e-9, "{xyz:?} came back as {back:?}");
        }
    }

    #[test]
    fn lightness_is_continuous_at_the_break_point() {
        let below = luminance_to_lightness(LAB_EPSILON * (1.0 - 1e-12));
        let above = luminance_to_lightness(LAB_EPSILON * (1.0 + 1e-12));
        assert!((below - above).abs() < 1e-8);
        assert!((luminance_to_lightness(0.18) - 49.496).abs() < 1e-3);
        assert!((lightness_to_luminance(luminance_to_lightness(0.003)) - 0.003).abs() < 1e-15);
    }

    #[test]
    fn black_has_a_chromaticity_that_is_not_nan() {
        let fallback = [0.3127, 0.329];
        for xyz in [Xyz::zeros(), Xyz::new(-1e-6, 2e-7, -3e-6)] {
            let xyy = xyz_to_xyy(&xyz, fallback);
            assert_eq!([xyy.x, xyy.y], fallback);
            let uv = xyz_to_uv_prime(&xyz, UvPrime { u: 0.2, v: 0.4 });
            assert_eq!((uv.u, uv.v), (0.2, 0.4));
        }
        let luv = xyz_to_luv(&Xyz::zeros(), &d65());
        assert!(luv.u.is_finite() && luv.v.is_finite());
    }

    #[test]
    fn xyy_round_trip_and_uv_from_xy_agree() {
        let xyz = Xyz::new(30.0, 40.0, 50.0);
        let xyy = xyz_to_xyy(&xyz, [0.0, 0.0]);
        assert!((xyy_to_xyz(&xyy) - xyz).norm() < 1e-12);
        let a = xyz_to_uv_prime(&xyz, UvPrime { u: 0.0, v: 0.0 });
        let b = xy_to_uv_prime(xyy.x, xyy.y);
        assert!((a.u - b.u).abs() < 1e-12 && (a.v - b.v).abs() < 1e-12);
    }

    #[test]
    fn srgb_of_d65_white_and_of_the_srgb_primaries() {
        // D65 at Y = 1 is sRGB white; half its luminance encodes to 0.7354 (188/255).
        let d65 = xyy_to_xyz(&Xyy {
            x: 0.3127,
            y: 0.3290,
            big_y: 1.0,
        });
        assert_eq!(xyz_to_srgb8(&d65), [255, 255, 255]);
        assert_eq!(xyz_to_srgb8(&(d65 * 0.5)), [188, 188, 188]);
        // The sRGB red primary (x 0.64, y 0.33, Y 0.2126) is pure red.
        let red = xyy_to_xyz(&Xyy {
            x: 0.64,
            y: 0.33,
            big_y: 0.2126,
        });
        assert_eq!(xyz_to_srgb8(&red), [255, 0, 0]);
        assert_eq!(xyz_to_srgb8(&Xyz::zeros()), [0, 0, 0]);
    }

    /// The tangent's constants are the formulas their docs give.
    #[test]
    fn the_tangent_s_constants_are_their_formulas() {
        let epsilon: f64 = 216.0 / 24389.0;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs();
        assert!(close(TWO_TO_THE_FIVE_THIRDS, 2f64.powf(5.0 / 3.0)));
        assert!(close(LINEAR_PART_CURVATURE, epsilon.powf(-5.0 / 3.0) / 9.0));
        assert!(close(
            THIRD_ORDER_REMAINDER,
            5.0 / 81.0 * 2f64.powf(8.0 / 3.0)
        ));
    }

    /// The tangent's step against L*a*b* taken anew, for steps from 10⁻⁶ to 10⁻¹ of
    /// the white on colours from near black (the linear part of L*) to white: the
    /// difference is within the stated bound, and the bound is small for small steps.
    #[test]
    fn the_lab_tangent_is_within_its_bound() {
        let white = Xyz::new(95.047, 100.0, 108.883);
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x9E37_79B9_7F4A_7C15);
        let mut uniform = move || rng.random::<f64>();
        let (mut judged, mut closest, mut closest_third, mut closest_first) =
            (0, 0.0_f64, 0.0_f64, 0.0_f64);
        for i in 0..100_000 {
            let size = 10f64.powf(-6.0 + 5.0 * (i % 6) as f64 / 5.0) * 100.0;
            let y = 100.0 * uniform().powi(4);
            let xyz = Xyz::new(y * (0.5 + uniform()), y, y * (0.5 + uniform()));
            let step = [0, 1, 2].map(|_| size * (2.0 * uniform() - 1.0));
            let lab = xyz_to_lab(&xyz, &white);
            let tangent = LabTangent::at(&xyz, &white, &lab);
            let (delta, error) = (tangent.delta(step), tangent.error(step));
            let moved = Xyz::new(xyz.x + step[0], xyz.y + step[1], xyz.z + step[2]);
            if [moved.x, moved.y, moved.z].iter().any(|v| *v < 0.0) {
                continue;
            }
            let exact = xyz_to_lab(&moved, &white);
            // The largest coordinate of the exact change less `delta`.
            let off_by = |delta: [f64; 3]| {
                (exact.l - lab.l - delta[0])
                    .abs()
                    .max((exact.a - lab.a - delta[1]).abs())
                    .max((exact.b - lab.b - delta[2]).abs())
            };
            let worst = off_by(delta);
            assert!(
                worst <= error + 1e-9,
                "{xyz:?} + {step:?}: off by {worst}, bound {error}"
            );
            if error.is_finite() && error > 1e-9 {
                closest_first = closest_first.max(worst / error);
            }
            if y > 1.0 && size < 1e-3 {
                assert!(error < 1e-6, "{xyz:?} + {step:?}: bound {error}");
            }
            // To second order: within its own bound, and far inside the first
            // order's where the step is small against the colour.
            let (second, second_error) = tangent.delta_to_second_order(step);
            let worst = off_by(second);
            assert!(
                worst <= second_error + 1e-9,
                "{xyz:?} + {step:?}: second order off by {worst}, bound {second_error}"
            );
            // (Above L* 25, so that no step reaches the linear part.)
            if y > 5.0 && size < 1e-3 * y {
                assert!(
                    second_error <= 0.02 * error,
                    "{xyz:?} + {step:?}: bound {second_error} against {error}"
                );
            }
            if second_error.is_finite() && second_error > 1e-9 {
                closest = closest.max(worst / second_error);
                judged += 1;
                // Every coordinate on the cube root over the whole step: the
                // third-order bound alone.
                let relative = [xyz.x / white.x, xyz.y / white.y, xyz.z / white.z];
                let steps = [step[0] / white.x, step[1] / white.y, step[2] / white.z];
                if relative
                    .iter()
                    .zip(steps)
                    .all(|(t, dt)| t - dt.abs() > 216.0 / 24389.0)
                {
                    closest_third = closest_third.max(worst / second_error);
                }
            }
        }
        assert!(judged > 30_000, "{judged}");
        // How near the bound the remainder comes, over all steps and where the
        // third-order bound is the whole of it (its worst, dt = t/2 downward, is 0.24
        // of it): a bound more than 4 times too tight, or 2.4 times too loose on the
        // cube root, fails here; its constant is pinned by the test above.
        eprintln!(
            "closest to the second-order bound: {closest:.3} of it, {closest_third:.3} on the cube root"
        );
        assert!(
            closest > 0.5 && closest_third > 0.1,
            "{closest} {closest_third}"
        );
        // The first order's bound, the second-order term at the colour and the third
        // order's: as near (a bound twice too loose fails).
        eprintln!("closest to the first-order bound: {closest_first:.3} of it");
        assert!(closest_first > 0.5, "{closest_first}");
    }
}
