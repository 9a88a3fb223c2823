//! Colour-difference formulas: CIE 1976 ΔE*ab and ΔE*uv, CIE 1994 ΔE*94 and
//! CIEDE2000 ΔE00.
//!
//! ΔE00 is the figure chromacal reports everywhere (held-out error, verification),
//! because it is the one that tracks what observers see over the whole range, dark
//! colours included.

use super::spaces::{Lab, Luv};

/// A colour difference a verification is judged in: ΔE00, or ΔE ITP where the
/// light is absolute (an HDR signal).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Metric {
    /// CIEDE2000 in CIELAB against the calibrated white.
    #[default]
    De00,
    /// ITU-R BT.2124 ΔE ITP, on absolute light.
    Itp,
}

impl std::str::FromStr for Metric {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "de00" | "de2000" | "ciede2000" => Ok(Metric::De00),
            "itp" | "ictcp" => Ok(Metric::Itp),
            _ => Err(format!("no metric '{s}' (de00, itp)")),
        }
    }
}

impl Metric {
    pub fn name(self) -> &'static str {
        match self {
            Metric::De00 => "ΔE00",
            Metric::Itp => "ΔE ITP",
        }
    }
}

/// CIE 1976 colour difference ΔE*ab: the Euclidean distance in L*a*b*
/// (CIE 15:2004 eq. 8.11).
pub fn delta_e_1976(lab1: &Lab, lab2: &Lab) -> f64 {
    ((lab1.l - lab2.l).powi(2) + (lab1.a - lab2.a).powi(2) + (lab1.b - lab2.b).powi(2)).sqrt()
}

/// CIE 1976 colour difference ΔE*uv: the Euclidean distance in L*u*v*
/// (CIE 15:2004 eq. 8.12).
pub fn delta_e_uv(luv1: &Luv, luv2: &Luv) -> f64 {
    ((luv1.l - luv2.l).powi(2) + (luv1.u - luv2.u).powi(2) + (luv1.v - luv2.v).powi(2)).sqrt()
}

/// CIE 1994 colour difference ΔE*94 with the graphic-arts weights
/// (kL = kC = kH = 1, K1 = 0.045, K2 = 0.015), CIE 116-1995 eq. 1–4.
///
/// The formula is not symmetric: `reference` supplies the chroma in the weighting
/// functions S_C and S_H.
pub fn delta_e_1994(reference: &Lab, sample: &Lab) -> f64 {
    let c1 = reference.a.hypot(reference.b);
    let c2 = sample.a.hypot(sample.b);
    let dl = reference.l - sample.l;
    let dc = c1 - c2;
    let da = reference.a - sample.a;
    let db = reference.b - sample.b;
    // ΔH*² = Δa*² + Δb*² − ΔC*², which rounding can push a hair below zero.
    let dh_squared = (da * da + db * db - dc * dc).max(0.0);
    let s_c = 1.0 + 0.045 * c1;
    let s_h = 1.0 + 0.015 * c1;
    (dl * dl + (dc / s_c).powi(2) + dh_squared / (s_h * s_h)).sqrt()
}

/// Cosines and sines of the angles in CIEDE2000's T (eq. 15) and Δθ (eq. 20).
const COS_30: f64 = 0.866_025_403_784_438_6;
const SIN_30: f64 = 0.5;
const COS_6: f64 = 0.994_521_895_368_273_3;
const SIN_6: f64 = 0.104_528_463_267_653_47;
const COS_63: f64 = 0.453_990_499_739_546_8;
const SIN_63: f64 = 0.891_006_524_188_367_9;
const COS_275: f64 = 0.087_155_742_747_657_89;
const SIN_275: f64 = -0.996_194_698_091_745_5;
const COS_140: f64 = -0.766_044_443_118_978;

/// √(a² + b²), as `f64::hypot` gives it where the squares stay in range (`hypot`,
/// which guards against their overflow at every call, was a thirtieth of a render's
/// time), within an ulp or two of it; `hypot` itself where they do not.
#[inline]
fn chroma(a: f64, b: f64) -> f64 {
    let squares = a * a + b * b;
    if squares.is_finite() && squares > 1e-200 {
        squares.sqrt()
    } else {
        a.hypot(b)
    }
}

/// 25⁷, which recurs in the CIEDE2000 chroma terms.
const TWENTY_FIVE_TO_THE_SEVENTH: f64 = 6_103_515_625.0;

/// CIEDE2000 colour difference ΔE00 with kL = kC = kH = 1, following the
/// implementation notes of Sharma, Wu and Dalal (2005), *Color Res. Appl.* 30(1),
/// eq. 1–22, including their rules for the hue of neutral colours and for hue
/// differences of exactly 180°.
pub fn delta_e_2000(lab1: &Lab, lab2: &Lab) -> f64 {
    // Eq. 2–4: a′ stretched by G, which depends on the mean chroma.
    let c_star_mean = (chroma(lab1.a, lab1.b) + chroma(lab2.a, lab2.b)) / 2.0;
    let c7 = c_star_mean.powi(7);
    let g = 0.5 * (1.0 - (c7 / (c7 + TWENTY_FIVE_TO_THE_SEVENTH)).sqrt());
    let a1 = (1.0 + g) * lab1.a;
    let a2 = (1.0 + g) * lab2.a;
    // Eq. 5: C′.
    let c1 = chroma(a1, lab1.b);
    let c2 = chroma(a2, lab2.b);
    // Eq. 6: h′ in degrees in [0, 360); 0 for a neutral colour.
    let hue = |b: f64, a: f64| -> f64 {
        if a == 0.0 && b == 0.0 {
            0.0
        } else {
            let h = b.atan2(a).to_degrees();
            if h < 0.0 { h + 360.0 } else { h }
        }
    };
    let h1 = hue(lab1.b, a1);
    let h2 = hue(lab2.b, a2);

    // Eq. 8–10: differences.
    let dl = lab2.l - lab1.l;
    let dc = c2 - c1;
    let chroma_product = c1 * c2;
    let dh_angle = if chroma_product == 0.0 {
        0.0
    } else {
        let d = h2 - h1;
        if d > 180.0 {
            d - 360.0
        } else if d < -180.0 {
            d + 360.0
        } else {
            d
        }
    };
    let dh = 2.0 * chroma_product.sqrt() * (dh_angle.to_radians() / 2.0).sin();

    // Eq. 11–14: means.
    let l_mean = (lab1.l + lab2.l) / 2.0;
    let c_mean = (c1 + c2) / 2.0;
    let h_mean = if chroma_product == 0.0 {
        h1 + h2
    } else if (h1 - h2).abs() <= 180.0 {
        (h1 + h2) / 2.0
    } else if h1 + h2 < 360.0 {
        (h1 + h2 + 360.0) / 2.0
    } else {
        (h1 + h2 - 360.0) / 2.0
    };

    // Eq. 15–21: weighting functions and the rotation term.
    let t = 1.0 - 0.17 * (h_mean - 30.0).to_radians().cos()
        + 0.24 * (2.0 * h_mean).to_radians().cos()
        + 0.32 * (3.0 * h_mean + 6.0).to_radians().cos()
        - 0.20 * (4.0 * h_mean - 63.0).to_radians().cos();
    let d_theta = 30.0 * (-((h_mean - 275.0) / 25.0).powi(2)).exp();
    let c_mean7 = c_mean.powi(7);
    let r_c = 2.0 * (c_mean7 / (c_mean7 + TWENTY_FIVE_TO_THE_SEVENTH)).sqrt();
    let l50 = (l_mean - 50.0).powi(2);
    let s_l = 1.0 + 0.015 * l50 / (20.0 + l50).sqrt();
    let s_c = 1.0 + 0.045 * c_mean;
    let s_h = 1.0 + 0.015 * c_mean * t;
    let r_t = -(2.0 * d_theta).to_radians().sin() * r_c;

    // Eq. 22.
    let tl = dl / s_l;
    let tc = dc / s_c;
    let th = dh / s_h;
    (tl * tl + tc * tc + th * th + r_t * tc * th).sqrt()
}

/// CIEDE2000 about one colour: eq. 2–22 of Sharma, Wu and Dalal (2005) with every
/// weight (G, S_L, S_C, S_H, R_T) and the hue taken at `lab` itself, and ΔC′, ΔH′ to
/// first order in the difference: ΔE00 to a colour δ away is then the root of a
/// quadratic form in δ, a few multiplications where the formula takes an arctangent,
/// five cosines and an exponential.
///
/// It is for choosing among close candidates (a pixel's neighbouring codes), not for
/// reporting: its relative error is below 1.2 · (|δ|∞ / C′ + 0.01 |δ|∞) (measured
/// over 8 million random pairs with C′ > 5 |δ|∞, and in an adversarial search over
/// hues and chromas for |δ|∞ from 10⁻⁴ to 20), plus 5 × 10⁻⁶ where the mean hue
/// crosses 0°: eq. 20 takes h̄′ − 275° without going round the circle, so Δθ jumps
/// there by 3 × 10⁻⁴ degrees whatever the step. [`LocalDeltaE2000::bound`] takes
/// about twice each (2.5 × the first, 2 × 10⁻⁵). Near the neutral axis, where the hue
/// has no direction, it gives none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalDeltaE2000 {
    /// 1 + G (eq. 3).
    one_plus_g: f64,
    /// a′ and b of the colour, over C′: the chroma's direction (eq. 2, 5).
    along: [f64; 2],
    /// C′ (eq. 5).
    chroma: f64,
    /// 1 / S_L, 1 / S_C, 1 / S_H (eq. 17–19).
    inverse_weights: [f64; 3],
    /// R_T (eq. 21).
    rotation: f64,
}

impl LocalDeltaE2000 {
    /// The form about `lab`; `None` on the neutral axis (C′ = 0) or for a colour that
    /// is not finite.
    pub fn at(lab: &Lab) -> Option<LocalDeltaE2000> {
        let c_star = (lab.a * lab.a + lab.b * lab.b).sqrt();
        let c7 = c_star.powi(7);
        let one_plus_g = 1.5 - 0.5 * (c7 / (c7 + TWENTY_FIVE_TO_THE_SEVENTH)).sqrt();
        let a_prime = one_plus_g * lab.a;
        let chroma = (a_prime * a_prime + lab.b * lab.b).sqrt();
        if !(chroma > 0.0 && chroma.is_finite() && lab.l.is_finite()) {
            return None;
        }
        // Eq. 15's cosines of multiples of h′ from cos h′ and sin h′ (the chroma's
        // direction) rather than from h′: no arctangent, no cosine.
        let (cos_h, sin_h) = (a_prime / chroma, lab.b / chroma);
        let (cos_2h, sin_2h) = (cos_h * cos_h - sin_h * sin_h, 2.0 * sin_h * cos_h);
        let (cos_3h, sin_3h) = (
            cos_h * cos_2h - sin_h * sin_2h,
            sin_h * cos_2h + cos_h * sin_2h,
        );
        let (cos_4h, sin_4h) = (cos_2h * cos_2h - sin_2h * sin_2h, 2.0 * sin_2h * cos_2h);
        let t = 1.0 - 0.17 * (cos_h * COS_30 + sin_h * SIN_30)
            + 0.24 * cos_2h
            + 0.32 * (cos_3h * COS_6 - sin_3h * SIN_6)
            - 0.20 * (cos_4h * COS_63 + sin_4h * SIN_63);
        // Eq. 20: Δθ is below 10⁻¹² more than 140° from 275° (h′ − 275° is not taken
        // round the circle there, so from 0° to 35° it is smaller still).
        let d_theta = if cos_h * COS_275 + sin_h * SIN_275 < COS_140 {
            0.0
        } else {
            let hue = lab.b.atan2(a_prime).to_degrees().rem_euclid(360.0);
            30.0 * (-((hue - 275.0) / 25.0).powi(2)).exp()
        };
        let chroma7 = chroma.powi(7);
        let r_c = 2.0 * (chroma7 / (chroma7 + TWENTY_FIVE_TO_THE_SEVENTH)).sqrt();
        let l50 = (lab.l - 50.0).powi(2);
        Some(LocalDeltaE2000 {
            one_plus_g,
            along: [cos_h, sin_h],
            chroma,
            inverse_weights: [
                1.0 / (1.0 + 0.015 * l50 / (20.0 + l50).sqrt()),
                1.0 / (1.0 + 0.045 * chroma),
                1.0 / (1.0 + 0.015 * chroma * t),
            ],
            // (No sine of 0: R_T is 0 there.)
            rotation: if d_theta == 0.0 {
                0.0
            } else {
                -(2.0 * d_theta).to_radians().sin() * r_c
            },
        })
    }

    /// ΔE00 from the colour to the one `delta` (ΔL*, Δa*, Δb*) away, to first order.
    #[inline]
    pub fn delta_e(&self, delta: [f64; 3]) -> f64 {
        self.delta_e_squared(delta).sqrt()
    }

    /// [`Self::delta_e`] squared: without the square root, for comparing steps.
    #[inline]
    pub fn delta_e_squared(&self, delta: [f64; 3]) -> f64 {
        self.squared(self.weighted(delta))
    }

    /// The step `delta` (ΔL*, Δa*, Δb*) weighted, ΔL′ / S_L, ΔC′ / S_C and ΔH′ / S_H
    /// (eq. 22 without the rotation): linear in the step, so that the weighted steps
    /// of sums of steps are sums of weighted steps.
    #[inline(always)]
    pub fn weighted(&self, delta: [f64; 3]) -> [f64; 3] {
        let da_prime = self.one_plus_g * delta[1];
        // ΔC′ and ΔH′: the step along the chroma's direction and across it.
        let dc = self.along[0] * da_prime + self.along[1] * delta[2];
        let dh = self.along[0] * delta[2] - self.along[1] * da_prime;
        [
            delta[0] * self.inverse_weights[0],
            dc * self.inverse_weights[1],
            dh * self.inverse_weights[2],
        ]
    }

    /// [`Self::delta_e_squared`] of a step weighted by [`Self::weighted`]: eq. 22 with
    /// its rotation term.
    #[inline(always)]
    pub fn squared(&self, [tl, tc, th]: [f64; 3]) -> f64 {
        (tl * tl + tc * tc + th * th + self.rotation * tc * th).max(0.0)
    }

    /// The bound on |ΔE00 − [`Self::delta_e`]| / ΔE00 for differences up to `size`
    /// (|δ|∞): twice the measured worst, infinite where the colour is too near
    /// neutral for the form (C′ < 5 |δ|∞).
    #[inline]
    pub fn bound(&self, size: f64) -> f64 {
        if self.chroma < 5.0 * size {
            return f64::INFINITY;
        }
        2.5 * (size / self.chroma + 0.01 * size) + 2e-5
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lab(l: f64, a: f64, b: f64) -> Lab {
        Lab { l, a, b }
    }

    #[test]
    fn chroma_is_hypot_within_two_ulps_and_hypot_itself_at_the_extremes() {
        for (a, b) in [(3.0, 4.0), (-20.5, 77.25), (1e-3, -2e-4), (127.0, -128.0)] {
            let (c, h) = (chroma(a, b), a.hypot(b));
            assert!(
                (c.to_bits() as i64 - h.to_bits() as i64).abs() <= 2,
                "{c} {h}"
            );
        }
        for (a, b) in [
            (1e200, 1e200),
            (1e-160, 0.0),
            (0.0, 0.0),
            (f64::INFINITY, 1.0),
        ] {
            assert_eq!(chroma(a, b), a.hypot(b), "{a:e} {b:e}");
        }
    }

    #[test]
    fn identical_colours_have_no_difference() {
        let c = lab(50.0, 20.0, -30.0);
        assert_eq!(delta_e_2000(&c, &c), 0.0);
        assert_eq!(delta_e_1976(&c, &c), 0.0);
        assert_eq!(delta_e_1994(&c, &c), 0.0);
    }

    #[test]
    fn ciede2000_is_symmetric() {
        let a = lab(50.0, 2.5, 0.0);
        let b = lab(73.0, 25.0, -18.0);
        assert!((delta_e_2000(&a, &b) - delta_e_2000(&b, &a)).abs() < 1e-12);
    }

    #[test]
    fn lightness_only_differences_reduce_to_the_lightness_weights() {
        // Two neutrals differ only in L*: ΔE*ab is ΔL*, ΔE94 too (S_L = 1).
        let a = lab(40.0, 0.0, 0.0);
        let b = lab(45.0, 0.0, 0.0);
        assert!((delta_e_1976(&a, &b) - 5.0).abs() < 1e-12);
        assert!((delta_e_1994(&a, &b) - 5.0).abs() < 1e-12);
        // ΔE00 divides by S_L at L̄′ = 42.5: 1 + 0.015·56.25/√76.25.
        let s_l = 1.0 + 0.015 * 56.25 / 76.25_f64.sqrt();
        assert!((delta_e_2000(&a, &b) - 5.0 / s_l).abs() < 1e-12);
    }

    #[test]
    fn cie94_uses_the_reference_chroma() {
        let reference = lab(50.0, 40.0, 0.0);
        let sample = lab(50.0, 38.0, 0.0);
        // Pure chroma difference of 2 divided by S_C = 1 + 0.045·40.
        assert!((delta_e_1994(&reference, &sample) - 2.0 / 2.8).abs() < 1e-12);
    }

    /// The local form against the formula over random colours and differences from
    /// 10⁻⁶ to 20 in each coordinate, a third of them where the bound is tightest
    /// (hue within 0.1° of 0°, where eq. 20's Δθ jumps; C* near 25 at 270°, where G
    /// and R_T change fastest): within half its own bound everywhere the bound is
    /// finite, and the bound finite for most of them.
    #[test]
    fn the_local_form_stays_within_its_bound_of_the_formula() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x2545_F491_4F6C_DD1D);
        let mut uniform = move || rng.random::<f64>();
        let (mut judged, mut worst) = (0, 0.0_f64);
        for i in 0..200_000 {
            let size = 10f64.powf(-6.0 + 7.3 * (i % 8) as f64 / 7.0);
            let (chroma, angle) = match i % 6 {
                0 => (100.0 * uniform(), (0.2 * uniform() - 0.1).to_radians()),
                1 => (
                    20.0 + 10.0 * uniform(),
                    (265.0 + 10.0 * uniform()).to_radians(),
                ),
                _ => (100.0 * uniform().powi(2), std::f64::consts::TAU * uniform()),
            };
            let one = lab(
                100.0 * uniform(),
                chroma * angle.cos(),
                chroma * angle.sin(),
            );
            let delta = [0, 1, 2].map(|_| size * (2.0 * uniform() - 1.0));
            let two = lab(one.l + delta[0], one.a + delta[1], one.b + delta[2]);
            let local = LocalDeltaE2000::at(&one).unwrap();
            let bound = local.bound(delta.iter().fold(0.0_f64, |m, d| m.max(d.abs())));
            if bound.is_finite() {
                let exact = delta_e_2000(&one, &two);
                worst = worst.max((local.delta_e(delta) / exact - 1.0).abs() / bound);
                judged += 1;
            }
        }
        assert!(judged > 120_000, "{judged}");
        assert!(worst < 0.5, "{worst} of the bound");
        assert!(LocalDeltaE2000::at(&lab(50.0, 0.0, 0.0)).is_none());
    }
}
