//! The monitor model as a matrix/TRC display profile: XYZ = A · T(rgb), three
//! colorant columns and one tone curve per channel, relative to white, with the
//! colorants adapted to D50 by Bradford (ICC.1:2022 Annex E, and the
//! `ComputeChromaticAdaptation` rule that Little CMS and ArgyllCMS follow).
//!
//! The model has an additive black, XYZ = M·E(v) + XYZ_black, that a matrix/TRC
//! profile has no term for. It is folded into the curves: with t₀ = M⁻¹ XYZ_black (the
//! black in excitations), M·E(v) + XYZ_black = M·(E(v) + t₀), so channel c gets the
//! colorant M_c·(E_c(1) + t₀_c) and the curve T_c(v) = (E_c(v) + t₀_c) / (E_c(1) + t₀_c).
//! This is exact while every t₀_c ≥ 0 (the black's chromaticity inside the
//! primaries' triangle). Otherwise the negative share is clipped at 0 and the
//! profile's black is a little off; `black_clipped` says so.

use nalgebra::{Matrix3, Vector3};

use super::icc_lut::{D50, ModelLuts};
use chromacal_color::Xyz;
use chromacal_color::adaptation::{AdaptationTransform, adaptation_matrix};
use chromacal_model::MonitorModel;
use chromacal_model::target::CalibrationCurves;
use chromacal_model::transfer::TransferLaw;

/// Entries of a sampled tone curve: enough that linear interpolation between them
/// stays far below 0.1 ΔE00 for any law the fits choose (tested).
pub const CURVE_SAMPLES: usize = 1024;

/// One channel's tone curve.
#[derive(Debug, Clone, PartialEq)]
pub enum Trc {
    /// ICC parametric curve type 2, Y = (aX + b)^g + c for X ≥ −b/a, else c
    /// (ICC.1:2022 Table 68): exact for the power and gain-offset-gamma laws.
    Parametric { g: f64, a: f64, b: f64, c: f64 },
    /// Values at inputs evenly spaced on [0, 1], read with linear interpolation.
    Sampled(Vec<f64>),
}

impl Trc {
    /// T(x).
    pub fn eval(&self, x: f64) -> f64 {
        let x = x.clamp(0.0, 1.0);
        match self {
            Trc::Parametric { g, a, b, c } => {
                if x >= -b / a {
                    (a * x + b).max(0.0).powf(*g) + c
                } else {
                    *c
                }
            }
            Trc::Sampled(values) => chromacal_model::target::interpolate(values, x),
        }
    }

    /// The curve sampled at `n` evenly spaced inputs (what an ICC v2 `curv` holds).
    pub fn sampled(&self, n: usize) -> Vec<f64> {
        match self {
            Trc::Sampled(values) if values.len() == n => values.clone(),
            _ => (0..n)
                .map(|i| self.eval(i as f64 / (n - 1) as f64))
                .collect(),
        }
    }
}

/// A matrix/TRC description of a display.
#[derive(Debug, Clone, PartialEq)]
pub struct MatrixTrc {
    /// White and black in the profile's units (cd/m² for absolute profiles).
    pub white: Xyz,
    pub black: Xyz,
    /// Colorant columns relative to white (their sum is the white with Y = 1), not
    /// yet adapted.
    pub colorants: Matrix3<f64>,
    pub trcs: [Trc; 3],
    /// The black's chromaticity lies outside the primaries' triangle and was clipped.
    pub black_clipped: bool,
    /// Calibration curves the description is of the display through (for `vcgt`).
    pub calibration: Option<CalibrationCurves>,
    /// The whole model as LUT tags, when it has terms the matrix/TRC cannot hold.
    pub luts: Option<ModelLuts>,
}

impl MatrixTrc {
    /// The display at the centre of the screen, through `calibration` when given.
    ///
    /// A matrix/TRC cannot hold the model's additivity terms: its additive part is
    /// exported, each channel scaled so that the description still passes through the
    /// model's white (which the fit anchored at the measured one), since everything in
    /// the profile is relative to that white. The whole model, terms included, goes
    /// into `luts` (`icc_lut`), which readers prefer.
    pub fn from_model(model: &MonitorModel, calibration: Option<&CalibrationCurves>) -> Self {
        Self::relative_to(model, calibration, None)
    }

    /// As [`MatrixTrc::from_model`], everything relative to `white` (the measured
    /// white) when given rather than to the model's own: an absolute lookup through the
    /// profile then gives exactly what the model gives, the normalisation the `.ti3`
    /// and every reader of the profile use. Where the model does not pass through the
    /// measured white (`fit::WhiteAnchor`), device white maps to the model's white
    /// relative to the measured one, not exactly to the PCS white.
    pub fn relative_to(
        model: &MonitorModel,
        calibration: Option<&CalibrationCurves>,
        white: Option<Xyz>,
    ) -> Self {
        let full = model;
        let additive;
        let model = if model.terms.is_empty() {
            model
        } else {
            let part = MonitorModel {
                terms: Default::default(),
                ..model.clone()
            };
            // The drive device white is shown with: through curves, the calibrated one.
            let top = [0, 1, 2].map(|c| {
                calibration.map_or(1.0, |k| {
                    chromacal_model::target::interpolate(&k.curves[c], 1.0)
                })
            });
            additive = part
                .anchored_at(top, &model.forward_centre(top))
                .map_or(part, |(anchored, _)| anchored);
            &additive
        };
        let inverse = model.matrix.try_inverse().unwrap_or_else(Matrix3::zeros);
        let t0 = inverse * model.black;
        // The excitation each channel gives at input x, through the curves if any.
        let excitation = |c: usize, x: f64| -> f64 {
            let drive =
                calibration.map_or(x, |k| chromacal_model::target::interpolate(&k.curves[c], x));
            model.laws[c].excitation(drive)
        };
        let mut colorants = Matrix3::zeros();
        let mut black_clipped = false;
        let trcs = [0, 1, 2].map(|c| {
            let offset = t0[c].max(0.0);
            black_clipped |= t0[c] < 0.0;
            let scale = excitation(c, 1.0) + offset;
            colorants.set_column(c, &(model.matrix.column(c) * scale));
            match (&model.laws[c], calibration, t0[c] >= 0.0) {
                (TransferLaw::Power(p), None, true) => {
                    let s = scale.powf(-1.0 / p.gamma);
                    Trc::Parametric {
                        g: p.gamma,
                        a: s,
                        b: 0.0,
                        c: offset / scale,
                    }
                }
                (TransferLaw::GainOffsetGamma(l), None, true) => {
                    let s = scale.powf(-1.0 / l.gamma);
                    Trc::Parametric {
                        g: l.gamma,
                        a: l.gain * s,
                        b: (1.0 - l.gain) * s,
                        c: offset / scale,
                    }
                }
                _ => Trc::Sampled(
                    (0..CURVE_SAMPLES)
                        .map(|i| {
                            let x = i as f64 / (CURVE_SAMPLES - 1) as f64;
                            ((excitation(c, x) + offset) / scale).clamp(0.0, 1.0)
                        })
                        .collect(),
                ),
            }
        });
        let white_vector = colorants * Vector3::new(1.0, 1.0, 1.0);
        let white = white
            .filter(|w| w.y > 0.0 && w.iter().all(|v| v.is_finite()))
            .unwrap_or(Xyz::new(white_vector.x, white_vector.y, white_vector.z));
        let mut profile = MatrixTrc {
            white,
            black: model.black,
            colorants: colorants / white.y,
            trcs,
            black_clipped,
            calibration: calibration.cloned(),
            luts: None,
        };
        profile.luts = ModelLuts::of(full, calibration, white.y, &profile.chad());
        profile
    }

    /// The white relative to itself: Y = 1.
    pub fn relative_white(&self) -> Xyz {
        self.white / self.white.y
    }

    /// Bradford from the display's white to D50.
    pub fn chad(&self) -> Matrix3<f64> {
        let d50 = Xyz::new(D50[0], D50[1], D50[2]);
        adaptation_matrix(AdaptationTransform::Bradford, &self.relative_white(), &d50)
    }

    /// The colorant tags: columns of chad · A.
    pub fn colorants_d50(&self) -> Matrix3<f64> {
        self.chad() * self.colorants
    }

    /// The black relative to white, adapted to D50 (the `bkpt` tag).
    pub fn black_d50(&self) -> Xyz {
        self.chad() * (self.black / self.white.y)
    }

    /// PCS XYZ (D50, relative, white Y = 1) of device values `rgb`.
    pub fn pcs_xyz(&self, rgb: [f64; 3]) -> Xyz {
        let t = Vector3::new(
            self.trcs[0].eval(rgb[0]),
            self.trcs[1].eval(rgb[1]),
            self.trcs[2].eval(rgb[2]),
        );
        self.colorants_d50() * t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::SpatialMap;
    use chromacal_model::transfer::{Cowan, GainOffsetGamma, Power};

    fn model(laws: [TransferLaw; 3], black: Xyz) -> MonitorModel {
        MonitorModel {
            matrix: Matrix3::new(
                41.24, 35.76, 18.05, //
                21.26, 71.52, 7.22, //
                1.93, 11.92, 95.05,
            ),
            black,
            laws,
            spatial: SpatialMap::Uniform,
            terms: Default::default(),
        }
    }

    /// The profile's PCS XYZ against the model's XYZ adapted the same way.
    fn worst_relative_error(m: &MonitorModel) -> f64 {
        let p = MatrixTrc::from_model(m, None);
        let chad = p.chad();
        let mut worst: f64 = 0.0;
        for r in 0..=8 {
            for g in [0, 3, 8] {
                for b in [0, 5, 8] {
                    let rgb = [r as f64 / 8.0, g as f64 / 8.0, b as f64 / 8.0];
                    let want = chad * (m.forward_centre(rgb) / p.white.y);
                    let got = p.pcs_xyz(rgb);
                    worst = worst.max((want - got).norm());
                }
            }
        }
        worst
    }

    #[test]
    fn power_and_gog_are_exact_parametric_curves_with_the_black_folded_in() {
        let black = Xyz::new(0.3, 0.32, 0.4);
        let m = model(
            [
                TransferLaw::Power(Power { gamma: 2.2 }),
                TransferLaw::GainOffsetGamma(GainOffsetGamma::from_cutoff(0.05, 2.4)),
                TransferLaw::Power(Power { gamma: 1.9 }),
            ],
            black,
        );
        let p = MatrixTrc::from_model(&m, None);
        assert!(p.trcs.iter().all(|t| matches!(t, Trc::Parametric { .. })));
        assert!(!p.black_clipped);
        assert!(worst_relative_error(&m) < 1e-12);
        // The colorants adapted to D50 sum to D50.
        let sum = p.colorants_d50() * Vector3::new(1.0, 1.0, 1.0);
        for k in 0..3 {
            assert!((sum[k] - D50[k]).abs() < 1e-9, "{sum}");
        }
    }

    #[test]
    fn other_laws_are_sampled_densely_enough() {
        let cowan = TransferLaw::Cowan(Cowan {
            a: 2.3,
            b: 0.05,
            toe: 0.02,
        });
        let m = model(
            [cowan.clone(), cowan.clone(), cowan],
            Xyz::new(0.1, 0.1, 0.12),
        );
        let p = MatrixTrc::from_model(&m, None);
        assert!(matches!(p.trcs[0], Trc::Sampled(ref v) if v.len() == CURVE_SAMPLES));
        assert!(
            worst_relative_error(&m) < 2e-4,
            "{}",
            worst_relative_error(&m)
        );
    }

    #[test]
    fn a_black_outside_the_primaries_is_clipped_and_said() {
        // A very red black: the blue and green shares would be negative.
        let m = model(
            [0, 1, 2].map(|_| TransferLaw::Power(Power { gamma: 2.2 })),
            Xyz::new(0.5, 0.2, 0.0),
        );
        let p = MatrixTrc::from_model(&m, None);
        assert!(p.black_clipped);
    }
}
