//! Von Kries-type chromatic adaptation: scale cone-like responses by the ratio of the
//! destination white to the source white (von Kries 1902), with the cone matrix of
//! either the Hunt–Pointer–Estévez "von Kries" transform or the linearised Bradford
//! transform (Lam 1985; Luo and Hunt 1998).
//!
//! This is what ICC profiles need (Bradford to D50) and what comparing measurements
//! taken under different whites needs.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use super::spaces::Xyz;

/// The cone-response matrix used for the adaptation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AdaptationTransform {
    /// Linearised Bradford matrix (Lam 1985), as ICC.1 Annex E uses.
    Bradford,
    /// Hunt–Pointer–Estévez cone fundamentals normalised to D65 (Hunt 1991),
    /// the classic von Kries transform.
    VonKries,
}

impl AdaptationTransform {
    /// The XYZ → cone-response matrix.
    pub fn cone_matrix(self) -> Matrix3<f64> {
        match self {
            AdaptationTransform::Bradford => Matrix3::new(
                0.8951, 0.2664, -0.1614, //
                -0.7502, 1.7135, 0.0367, //
                0.0389, -0.0685, 1.0296,
            ),
            AdaptationTransform::VonKries => Matrix3::new(
                0.40024, 0.7076, -0.08081, //
                -0.2263, 1.16532, 0.0457, //
                0.0, 0.0, 0.91822,
            ),
        }
    }
}

/// The 3×3 matrix that carries XYZ seen under `source_white` to the corresponding
/// colour under `destination_white`: M⁻¹ · diag(ρ_d / ρ_s) · M (von Kries 1902 in the
/// cone space of `transform`).
///
/// Whites with a zero cone response cannot be adapted from; the identity is returned
/// for them, since no scaling is defined.
pub fn adaptation_matrix(
    transform: AdaptationTransform,
    source_white: &Xyz,
    destination_white: &Xyz,
) -> Matrix3<f64> {
    let cone = transform.cone_matrix();
    let Some(cone_inverse) = cone.try_inverse() else {
        return Matrix3::identity();
    };
    let source = cone * source_white;
    let destination = cone * destination_white;
    if source.iter().any(|v| *v == 0.0 || !v.is_finite()) {
        return Matrix3::identity();
    }
    let gains = Matrix3::from_diagonal(&destination.component_div(&source));
    cone_inverse * gains * cone
}

/// XYZ under `source_white` adapted to `destination_white`.
pub fn adapt(
    xyz: &Xyz,
    transform: AdaptationTransform,
    source_white: &Xyz,
    destination_white: &Xyz,
) -> Xyz {
    adaptation_matrix(transform, source_white, destination_white) * xyz
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_goes_to_white() {
        let d65 = Xyz::new(0.95047, 1.0, 1.08883);
        let d50 = Xyz::new(0.96422, 1.0, 0.82521);
        for t in [AdaptationTransform::Bradford, AdaptationTransform::VonKries] {
            let adapted = adapt(&d65, t, &d65, &d50);
            assert!((adapted - d50).norm() < 1e-12, "{t:?}");
        }
    }

    #[test]
    fn bradford_d65_to_d50_matches_the_published_matrix() {
        // Lindbloom's Bradford D65→D50 matrix (rounded to 7 decimals there).
        let d65 = Xyz::new(0.95047, 1.0, 1.08883);
        let d50 = Xyz::new(0.96422, 1.0, 0.82521);
        let m = adaptation_matrix(AdaptationTransform::Bradford, &d65, &d50);
        let published = Matrix3::new(
            1.0478112, 0.0228866, -0.0501270, //
            0.0295424, 0.9904844, -0.0170491, //
            -0.0092345, 0.0150436, 0.7521316,
        );
        assert!((m - published).abs().max() < 2e-7, "{m}");
    }

    #[test]
    fn the_same_white_gives_the_identity() {
        let w = Xyz::new(1.2, 1.0, 0.7);
        let m = adaptation_matrix(AdaptationTransform::VonKries, &w, &w);
        assert!((m - Matrix3::identity()).abs().max() < 1e-12);
    }
}
