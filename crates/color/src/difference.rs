//! Colour-difference formulas: CIE 1976 ΔE*ab and ΔE*uv, CIE 1994 ΔE*94 and
//! CIEDE2000 ΔE00.
//!
//! ΔE00 is the figure chromacal reports everywhere (held-out error, verification),
//! because it is the one that tracks what observers see over the whole range, dark
//! colours included.

use super::spaces::{Lab, Luv};

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

/// 25⁷, which recurs in the CIEDE2000 chroma terms.
const TWENTY_FIVE_TO_THE_SEVENTH: f64 = 6_103_515_625.0;

/// CIEDE2000 colour difference ΔE00 with kL = kC = kH = 1, following the
/// implementation notes of Sharma, Wu and Dalal (2005), *Color Res. Appl.* 30(1),
/// eq. 1–22, including their rules for the hue of neutral colours and for hue
/// differences of exactly 180°.
pub fn delta_e_2000(lab1: &Lab, lab2: &Lab) -> f64 {
    // Eq. 2–4: a′ stretched by G, which depends on the mean chroma.
    let c_star_mean = (lab1.a.hypot(lab1.b) + lab2.a.hypot(lab2.b)) / 2.0;
    let c7 = c_star_mean.powi(7);
    let g = 0.5 * (1.0 - (c7 / (c7 + TWENTY_FIVE_TO_THE_SEVENTH)).sqrt());
    let a1 = (1.0 + g) * lab1.a;
    let a2 = (1.0 + g) * lab2.a;
    // Eq. 5: C′.
    let c1 = a1.hypot(lab1.b);
    let c2 = a2.hypot(lab2.b);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn lab(l: f64, a: f64, b: f64) -> Lab {
        Lab { l, a, b }
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
}
