//! ICtCp (ITU-R BT.2100-2, Table 6) and the colour difference ΔE ITP built on it
//! (ITU-R BT.2124-0), with the perceptual quantiser of SMPTE ST 2084 they rest on.
//!
//! ICtCp is defined on absolute light: XYZ in cd/m², taken to BT.2020 RGB (D65), to
//! the LMS cone space of BT.2100, each through the PQ's inverse EOTF (10,000 cd/m² at
//! 1), then mixed into intensity I and the two chroma axes Ct and Cp. BT.2124 scales Ct
//! by one half and the whole difference by 720, so that ΔE ITP = 1 is about one just
//! noticeable difference, for SDR and HDR alike.

use nalgebra::Matrix3;

use crate::Xyz;
use crate::gamut::{AdditiveGamut, REC_2020};

/// SMPTE ST 2084:2014 eq. 5.1 constants.
const M1: f64 = 2610.0 / 16384.0;
const M2: f64 = 2523.0 / 4096.0 * 128.0;
const C1: f64 = 3424.0 / 4096.0;
const C2: f64 = 2413.0 / 4096.0 * 32.0;
const C3: f64 = 2392.0 / 4096.0 * 32.0;

/// The PQ's peak, cd/m².
pub const PQ_PEAK: f64 = 10_000.0;

/// SMPTE ST 2084 inverse EOTF: the signal in [0, 1] of luminance `y` cd/m² (0 and
/// below at 0, 10,000 and above at 1).
pub fn pq_inverse_eotf(y: f64) -> f64 {
    let v = (y / PQ_PEAK).clamp(0.0, 1.0).powf(M1);
    ((C1 + C2 * v) / (1.0 + C3 * v)).powf(M2)
}

/// SMPTE ST 2084 EOTF: the luminance in cd/m² of signal `e` in [0, 1].
pub fn pq_eotf(e: f64) -> f64 {
    let p = e.clamp(0.0, 1.0).powf(1.0 / M2);
    PQ_PEAK * ((p - C1).max(0.0) / (C2 - C3 * p)).powf(1.0 / M1)
}

/// BT.2100 Table 6: linear BT.2020 RGB to LMS.
fn rgb_to_lms() -> Matrix3<f64> {
    Matrix3::new(
        1688.0, 2146.0, 262.0, //
        683.0, 2951.0, 462.0, //
        99.0, 309.0, 3688.0,
    ) / 4096.0
}

/// BT.2100 Table 6: L′M′S′ to ICtCp.
fn lms_to_ictcp() -> Matrix3<f64> {
    Matrix3::new(
        2048.0, 2048.0, 0.0, //
        6610.0, -13613.0, 7003.0, //
        17933.0, -17390.0, -543.0,
    ) / 4096.0
}

/// XYZ to linear BT.2020 RGB with the BT.2020 white (D65) at R = G = B = Y.
fn xyz_to_bt2020() -> Matrix3<f64> {
    AdditiveGamut::of_space(&REC_2020)
        .and_then(|g| g.primaries.try_inverse())
        .unwrap_or_else(Matrix3::identity)
}

/// ICtCp of `xyz` in cd/m² (BT.2100, PQ), as [I, Ct, Cp].
pub fn xyz_to_ictcp(xyz: &Xyz) -> [f64; 3] {
    let lms = rgb_to_lms() * xyz_to_bt2020() * xyz;
    let encoded = lms.map(pq_inverse_eotf);
    let ictcp = lms_to_ictcp() * encoded;
    [ictcp.x, ictcp.y, ictcp.z]
}

/// ITU-R BT.2124-0 eq. (1): ΔE ITP = 720 √(ΔI² + ΔT² + ΔP²) with T = Ct / 2 and
/// P = Cp, between two colours in cd/m².
pub fn delta_e_itp(a: &Xyz, b: &Xyz) -> f64 {
    let (p, q) = (xyz_to_ictcp(a), xyz_to_ictcp(b));
    let di = p[0] - q[0];
    let dt = 0.5 * (p[1] - q[1]);
    let dp = p[2] - q[2];
    720.0 * (di * di + dt * dt + dp * dp).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spaces::{Xyy, xyy_to_xyz};

    #[test]
    fn the_pq_round_trips_and_meets_its_fixed_points() {
        assert_eq!(pq_inverse_eotf(0.0), C1.powf(M2));
        assert!((pq_inverse_eotf(10_000.0) - 1.0).abs() < 1e-12);
        // ST 2084's reference: 100 cd/m² at about 0.5081, 1000 at about 0.7518.
        assert!((pq_inverse_eotf(100.0) - 0.5081).abs() < 1e-4);
        assert!((pq_inverse_eotf(1000.0) - 0.7518).abs() < 1e-4);
        for y in [0.005, 0.1, 1.0, 80.0, 600.0, 4000.0] {
            assert!((pq_eotf(pq_inverse_eotf(y)) / y - 1.0).abs() < 1e-9, "{y}");
        }
    }

    #[test]
    fn grey_has_no_chroma_and_the_difference_is_a_metric() {
        // D65 at any luminance: Ct = Cp = 0, as BT.2100 builds them.
        for y in [1.0, 80.0, 1000.0] {
            let grey = xyy_to_xyz(&Xyy {
                x: 0.3127,
                y: 0.3290,
                big_y: y,
            });
            let [_, ct, cp] = xyz_to_ictcp(&grey);
            assert!(ct.abs() < 2e-4 && cp.abs() < 2e-4, "{y}: {ct} {cp}");
        }
        let a = Xyz::new(40.0, 42.0, 30.0);
        let b = Xyz::new(41.0, 42.0, 30.0);
        assert_eq!(delta_e_itp(&a, &a), 0.0);
        assert!((delta_e_itp(&a, &b) - delta_e_itp(&b, &a)).abs() < 1e-12);
        // At 100 cd/m², 1 % more light is under one ΔE ITP (BT.2124 puts the just
        // noticeable difference near 1) and 2 % is over it.
        let white = xyy_to_xyz(&Xyy {
            x: 0.3127,
            y: 0.3290,
            big_y: 100.0,
        });
        let one = delta_e_itp(&white, &(white * 1.01));
        let two = delta_e_itp(&white, &(white * 1.02));
        assert!(one > 0.5 && one < 1.0 && two > 1.0, "{one} {two}");
    }
}
