//! Correlated colour temperature and the distance from the Planckian locus (Duv).
//!
//! CIE 15:2004 §9.5 defines the correlated colour temperature of a stimulus as the
//! temperature of the Planckian radiator whose chromaticity is nearest to it in the
//! CIE 1960 UCS (u, v) diagram. Rather than an approximation (McCamy's cubic) or a
//! tabulated interpolation (Robertson 1968), the locus is computed here from Planck's
//! law and the CIE 1931 colour-matching functions, and the nearest point is found by
//! search: the definition itself, accurate to well under a kelvin. Duv is the signed
//! distance to that point, positive above the locus (towards green), as ANSI
//! C78.377-2017 and Ohno (2014, LEUKOS 10(1) 47–55) use it.

use super::spaces::Xyz;
use super::spectrum::Observer;

/// The second radiation constant c₂ = hc/k in m·K, as CIE 15:2004 §9.5 gives it for
/// computing the Planckian locus (1.4388 × 10⁻² m·K; the ITS-90 value).
const C2_M_K: f64 = 1.4388e-2;

/// The range searched, in kelvin: where displays' whites lie, and well beyond.
const SEARCH_K: (f64, f64) = (1000.0, 100_000.0);

/// A white's correlated colour temperature and its distance from the Planckian locus.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ColourTemperature {
    /// Kelvin.
    pub cct_k: f64,
    /// Signed distance in CIE 1960 (u, v) to the locus, positive above it.
    pub duv: f64,
}

/// CIE 1960 UCS (u, v) of XYZ (CIE 15:2004 eq. 9.1 note: u = 4X/(X+15Y+3Z),
/// v = 6Y/(X+15Y+3Z)); `None` where the denominator is not positive.
pub fn xyz_to_uv_1960(xyz: &Xyz) -> Option<(f64, f64)> {
    let d = xyz.x + 15.0 * xyz.y + 3.0 * xyz.z;
    (d > 0.0 && d.is_finite()).then(|| (4.0 * xyz.x / d, 6.0 * xyz.y / d))
}

/// The chromaticity (CIE 1960 u, v) of a Planckian radiator at `kelvin`: Planck's
/// spectral radiance (the c₁ factor cancels in a chromaticity) weighted by the CIE
/// 1931 2° colour-matching functions at every nanometre of their table.
pub fn planckian_uv(kelvin: f64) -> Option<(f64, f64)> {
    let observer = Observer::Cie1931TwoDegree;
    let (start, end) = observer.range_nm();
    let mut xyz = Xyz::zeros();
    let mut nm = start;
    while nm <= end {
        if let Some([x, y, z]) = observer.cmf_at(nm) {
            let metres = nm * 1e-9;
            let radiance = metres.powi(-5) / ((C2_M_K / (metres * kelvin)).exp_m1());
            xyz += Xyz::new(x, y, z) * radiance;
        }
        nm += 1.0;
    }
    xyz_to_uv_1960(&xyz)
}

/// The correlated colour temperature and Duv of `xyz` (CIE 15:2004 §9.5): the
/// Planckian point nearest in (u, v), found by a scan in reciprocal temperature
/// (where the locus is spaced most evenly) refined by golden-section search. `None`
/// for a stimulus without a chromaticity or further than 0.05 from the locus, where
/// CIE 15 says a correlated colour temperature has no meaning.
pub fn xyz_to_cct_duv(xyz: &Xyz) -> Option<ColourTemperature> {
    let (u, v) = xyz_to_uv_1960(xyz)?;
    let distance = |mired: f64| {
        planckian_uv(1e6 / mired).map_or(f64::INFINITY, |(pu, pv)| (u - pu).hypot(v - pv))
    };
    let (lo, hi) = (1e6 / SEARCH_K.1, 1e6 / SEARCH_K.0);
    let steps = 200;
    let step = (hi - lo) / steps as f64;
    let best = (0..=steps)
        .map(|i| lo + step * i as f64)
        .min_by(|a, b| distance(*a).total_cmp(&distance(*b)))?;
    // Golden-section search on the bracket around the best scanned point.
    let (mut a, mut b) = ((best - step).max(lo), (best + step).min(hi));
    let ratio = (5.0_f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - ratio * (b - a), a + ratio * (b - a));
    let (mut fc, mut fd) = (distance(c), distance(d));
    while b - a > 1e-4 {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - ratio * (b - a);
            fc = distance(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + ratio * (b - a);
            fd = distance(d);
        }
    }
    let mired = (a + b) / 2.0;
    let (pu, pv) = planckian_uv(1e6 / mired)?;
    let magnitude = (u - pu).hypot(v - pv);
    if magnitude > 0.05 {
        return None;
    }
    Some(ColourTemperature {
        cct_k: 1e6 / mired,
        duv: magnitude.copysign(v - pv),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spaces::{Xyy, xyy_to_xyz};

    fn xy(x: f64, y: f64) -> Xyz {
        xyy_to_xyz(&Xyy { x, y, big_y: 1.0 })
    }

    #[test]
    fn illuminant_a_is_2856_k_on_the_locus() {
        // CIE 15:2004 Table T.3: A at x 0.44757, y 0.40745, a Planckian radiator at
        // 2856 K (with c₂ = 1.4388e-2 m·K).
        let t = xyz_to_cct_duv(&xy(0.44757, 0.40745)).unwrap();
        assert!((t.cct_k - 2856.0).abs() < 1.5, "{t:?}");
        assert!(t.duv.abs() < 1e-4, "{t:?}");
    }

    #[test]
    fn d65_is_6504_k_above_the_locus() {
        // D65: CCT 6504 K, Duv +0.0032 (Ohno 2014, Table 2).
        let t = xyz_to_cct_duv(&xy(0.3127, 0.3290)).unwrap();
        assert!((t.cct_k - 6504.0).abs() < 3.0, "{t:?}");
        assert!((t.duv - 0.0032).abs() < 2e-4, "{t:?}");
    }

    #[test]
    fn a_pink_white_is_below_the_locus_and_a_pure_colour_has_no_cct() {
        let pink = xyz_to_cct_duv(&xy(0.3127, 0.3150)).unwrap();
        assert!(pink.duv < -0.003, "{pink:?}");
        assert!(xyz_to_cct_duv(&xy(0.30, 0.60)).is_none());
        assert!(xyz_to_cct_duv(&Xyz::zeros()).is_none());
    }
}
