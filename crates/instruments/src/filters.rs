//! A tristimulus colorimeter's filters: three detector responses that only approach
//! the CIE 1931 colour-matching functions, and the matrix its maker calibrated them
//! with. This is why a colorimeter's XYZ of a display is off by an amount that
//! depends on the display's spectra, and why labs correct it against a reference
//! spectroradiometer on the very display (a `.ccmx`).
//!
//! The responses are a smooth deviation of realistic size from the CIE functions
//! (Luther's condition not met): each channel's function shifted by a few nanometres
//! and tilted across the spectrum, and x̄'s short-wavelength lobe only partly realised
//! (one filter cannot follow both humps; makers mix in the z̄-like channel). The
//! calibration is the one such instruments get at the factory: the best linear map
//! from the responses to the CIE functions over the spectrum, then per-channel gains
//! that make an illuminant A lamp read its CIE XYZ exactly. Broadband light then reads
//! well; a display's narrow primaries (LED phosphors, OLED, laser-like wide-gamut
//! panels) read off by a few ΔE00.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use chromacal_color::Xyz;
use chromacal_color::spectrum::{
    Illuminant, KM_PHOTOPIC, Observer, Spectrum, SpectrumError, emission_to_xyz,
};

/// Which instrument's filters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FilterModel {
    /// Klein K-10A.
    K10a,
    /// Konica Minolta CS-100A.
    Cs100a,
    /// Cambridge Research Systems ColorCAL MKII.
    Colorcal2,
}

/// The deviation of one instrument's filters from the CIE functions.
struct Deviation {
    /// Wavelength shift of each channel's response, nm.
    shift_nm: [f64; 3],
    /// Relative slope of each response across the spectrum, per 100 nm from 560 nm.
    tilt: [f64; 3],
    /// How much of x̄'s short-wavelength lobe the x channel realises (1: all).
    blue_lobe: f64,
}

impl FilterModel {
    fn deviation(self) -> Deviation {
        match self {
            FilterModel::K10a => Deviation {
                shift_nm: [3.0, -2.0, 4.0],
                tilt: [0.05, -0.03, 0.08],
                blue_lobe: 0.6,
            },
            FilterModel::Cs100a => Deviation {
                shift_nm: [-4.0, 3.0, -3.0],
                tilt: [-0.06, 0.04, -0.05],
                blue_lobe: 0.8,
            },
            FilterModel::Colorcal2 => Deviation {
                shift_nm: [5.0, 4.0, -5.0],
                tilt: [0.08, 0.05, 0.1],
                blue_lobe: 0.5,
            },
        }
    }
}

/// The filters of one colorimeter, sampled every 5 nm, and its factory matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct ColorimeterFilters {
    wavelengths_nm: Vec<f64>,
    /// Response of each channel at each wavelength.
    responses: Vec<[f64; 3]>,
    /// Factory calibration: XYZ = matrix · (Km Σ response S Δλ).
    matrix: Matrix3<f64>,
}

/// The wavelength where x̄'s two lobes meet.
const X_LOBES_MEET_NM: f64 = 505.0;

impl ColorimeterFilters {
    pub fn new(model: FilterModel) -> Result<Self, SpectrumError> {
        let observer = Observer::default();
        let d = model.deviation();
        let cmf = |nm: f64| observer.cmf_at(nm).unwrap_or([0.0; 3]);
        let wavelengths_nm: Vec<f64> = (0..=80).map(|i| 380.0 + 5.0 * i as f64).collect();
        let responses: Vec<[f64; 3]> = wavelengths_nm
            .iter()
            .map(|&nm| {
                [0, 1, 2].map(|c| {
                    let source = (nm - d.shift_nm[c]).round();
                    let mut value = cmf(source)[c];
                    if c == 0 && source < X_LOBES_MEET_NM {
                        value *= d.blue_lobe;
                    }
                    (value * (1.0 + d.tilt[c] * (nm - 560.0) / 100.0)).max(0.0)
                })
            })
            .collect();
        // The designer's map: least squares from responses to the CIE functions.
        let (mut rr, mut rc) = (Matrix3::<f64>::zeros(), Matrix3::<f64>::zeros());
        for (r, &nm) in responses.iter().zip(&wavelengths_nm) {
            let r = Vector3::from(*r);
            let c = Vector3::from(cmf(nm));
            rr += r * r.transpose();
            rc += c * r.transpose();
        }
        let design = rc * rr.try_inverse().unwrap_or_else(Matrix3::identity);
        let mut filters = ColorimeterFilters {
            wavelengths_nm,
            responses,
            matrix: design,
        };
        // The factory's gains: illuminant A reads its CIE XYZ.
        let lamp = Illuminant::A.spectrum();
        let truth = emission_to_xyz(&lamp, observer)?;
        let read = filters.xyz(&lamp);
        let gains = Matrix3::from_diagonal(&Vector3::from_fn(|i, _| truth[i] / read[i]));
        filters.matrix = gains * design;
        Ok(filters)
    }

    /// The responses to `spectrum` (W·sr⁻¹·m⁻²·nm⁻¹), Km Σ r S Δλ, before the matrix.
    fn raw(&self, spectrum: &Spectrum) -> Vector3<f64> {
        let mut sums = Vector3::zeros();
        for (r, &nm) in self.responses.iter().zip(&self.wavelengths_nm) {
            if let Some(s) = spectrum.value_at(nm) {
                sums += Vector3::from(*r) * (s * 5.0);
            }
        }
        sums * KM_PHOTOPIC
    }

    /// The XYZ this colorimeter reports for `spectrum`.
    pub fn xyz(&self, spectrum: &Spectrum) -> Xyz {
        self.matrix * self.raw(spectrum)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_color::spectrum::Illuminant;

    #[test]
    fn a_lamp_reads_true_and_a_narrow_line_does_not() {
        for model in [
            FilterModel::K10a,
            FilterModel::Cs100a,
            FilterModel::Colorcal2,
        ] {
            let f = ColorimeterFilters::new(model).unwrap();
            let lamp = Illuminant::A.spectrum();
            let truth = emission_to_xyz(&lamp, Observer::default()).unwrap();
            let read = f.xyz(&lamp);
            assert!((read - truth).norm() / truth.norm() < 1e-9, "{model:?}");
            // A 10 nm wide green line: the filters' deviation shows.
            let w: Vec<f64> = (0..=80).map(|i| 380.0 + 5.0 * i as f64).collect();
            let v: Vec<f64> = w
                .iter()
                .map(|nm| (-((nm - 530.0) / 6.0f64).powi(2)).exp())
                .collect();
            let line = Spectrum::new(w, v).unwrap();
            let truth = emission_to_xyz(&line, Observer::default()).unwrap();
            let read = f.xyz(&line);
            let off = (read - truth).norm() / truth.norm();
            assert!(off > 0.005 && off < 0.2, "{model:?}: {off}");
        }
    }
}
