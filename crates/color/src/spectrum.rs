//! Spectra to tristimulus values by weighted ordinates (the seed survey's eq. 1 and 2;
//! CIE 15:2004 §7.1), with the CIE observers, V(λ), V′(λ) and the CIE illuminants.
//!
//! How a spectrum meets the colour-matching functions:
//! * A spectrum sampled on a uniform grid of whole nanometres (5 nm, 4 nm, 1 nm, ...)
//!   is summed on its own grid: the CMFs are read at its wavelengths and Δλ is its
//!   step. This is the CIE's weighted-ordinate sum at the measurement interval.
//! * Any other spectrum (an uneven grid, or steps such as 3.333 nm) is linearly
//!   interpolated onto the 1 nm grid of the CMFs and summed with Δλ = 1 nm.
//!
//! In both cases the sum runs over the wavelengths where the spectrum, the CMFs and
//! (for reflectances) the illuminant are all defined; nothing is extrapolated.

use serde::{Deserialize, Serialize};

use super::spaces::Xyz;
use super::tables;

/// Maximum photopic luminous efficacy Km (lm/W), CIE 15:2004 §7.2.
pub const KM_PHOTOPIC: f64 = 683.0;
/// Maximum scotopic luminous efficacy K′m (lm/W), CIE 15:2004 §7.2.
pub const KM_SCOTOPIC: f64 = 1700.0;

/// Why a spectrum could not be built or integrated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpectrumError {
    #[error("a spectrum needs at least two samples, this one has {0}")]
    TooFewSamples(usize),
    #[error("{wavelengths} wavelengths but {values} values")]
    LengthMismatch { wavelengths: usize, values: usize },
    #[error("wavelengths must increase, but {previous} nm is followed by {next} nm")]
    NotIncreasing { previous: f64, next: f64 },
    #[error("the value at {wavelength_nm} nm is not a finite number ({value})")]
    NotFinite { wavelength_nm: f64, value: f64 },
    #[error(
        "the spectrum ({from_nm}–{to_nm} nm) shares fewer than two wavelengths with the {what}"
    )]
    NoOverlap {
        from_nm: f64,
        to_nm: f64,
        what: &'static str,
    },
}

/// A spectrum sampled at increasing wavelengths (nm): a radiance, a relative power or
/// a reflectance factor, depending on use.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Spectrum {
    wavelengths_nm: Vec<f64>,
    values: Vec<f64>,
}

impl Spectrum {
    /// A spectrum from its wavelengths and values, checked: at least two samples,
    /// strictly increasing wavelengths, finite numbers.
    pub fn new(wavelengths_nm: Vec<f64>, values: Vec<f64>) -> Result<Self, SpectrumError> {
        if wavelengths_nm.len() != values.len() {
            return Err(SpectrumError::LengthMismatch {
                wavelengths: wavelengths_nm.len(),
                values: values.len(),
            });
        }
        if wavelengths_nm.len() < 2 {
            return Err(SpectrumError::TooFewSamples(wavelengths_nm.len()));
        }
        for (w, v) in wavelengths_nm.iter().zip(&values) {
            if !w.is_finite() || !v.is_finite() {
                return Err(SpectrumError::NotFinite {
                    wavelength_nm: *w,
                    value: *v,
                });
            }
        }
        for pair in wavelengths_nm.windows(2) {
            if pair[1] <= pair[0] {
                return Err(SpectrumError::NotIncreasing {
                    previous: pair[0],
                    next: pair[1],
                });
            }
        }
        Ok(Spectrum {
            wavelengths_nm,
            values,
        })
    }

    /// A spectrum from rows `[wavelength, value]` of a table compiled into the program.
    fn from_table_column<const N: usize>(rows: &[[f64; N]], column: usize) -> Self {
        Spectrum {
            wavelengths_nm: rows.iter().map(|r| r[0]).collect(),
            values: rows.iter().map(|r| r[column]).collect(),
        }
    }

    pub fn wavelengths_nm(&self) -> &[f64] {
        &self.wavelengths_nm
    }

    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// First and last wavelength.
    pub fn range_nm(&self) -> (f64, f64) {
        (
            self.wavelengths_nm[0],
            self.wavelengths_nm[self.wavelengths_nm.len() - 1],
        )
    }

    /// The value at `nm` by linear interpolation, or `None` outside the sampled range.
    pub fn value_at(&self, nm: f64) -> Option<f64> {
        let (lo, hi) = self.range_nm();
        if !(lo..=hi).contains(&nm) {
            return None;
        }
        let upper = self.wavelengths_nm.partition_point(|w| *w < nm);
        if upper == 0 {
            return Some(self.values[0]);
        }
        let (w0, w1) = (self.wavelengths_nm[upper - 1], self.wavelengths_nm[upper]);
        let (v0, v1) = (self.values[upper - 1], self.values[upper]);
        Some(v0 + (v1 - v0) * (nm - w0) / (w1 - w0))
    }

    /// A spectrum on the same wavelengths with other values (checked like [`Self::new`]).
    pub fn with_values(&self, values: Vec<f64>) -> Result<Spectrum, SpectrumError> {
        Spectrum::new(self.wavelengths_nm.clone(), values)
    }

    /// This spectrum with every value multiplied by `factor`.
    pub fn scaled(&self, factor: f64) -> Spectrum {
        Spectrum {
            wavelengths_nm: self.wavelengths_nm.clone(),
            values: self.values.iter().map(|v| v * factor).collect(),
        }
    }

    /// The step of a uniform grid of whole nanometres, if this spectrum is on one.
    pub fn whole_nm_step(&self) -> Option<f64> {
        let step = self.wavelengths_nm[1] - self.wavelengths_nm[0];
        let whole = |w: f64| (w - w.round()).abs() < 1e-6;
        let uniform = self
            .wavelengths_nm
            .windows(2)
            .all(|p| ((p[1] - p[0]) - step).abs() < 1e-6);
        (uniform && whole(step) && self.wavelengths_nm.iter().all(|w| whole(*w)))
            .then_some(step.round())
    }
}

/// The standard colorimetric observers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Observer {
    /// CIE 1931 2° standard colorimetric observer.
    #[default]
    #[serde(rename = "1931-2")]
    Cie1931TwoDegree,
    /// CIE 1964 10° supplementary standard colorimetric observer.
    #[serde(rename = "1964-10")]
    Cie1964TenDegree,
}

impl std::fmt::Display for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Observer::Cie1931TwoDegree => "CIE 1931 2°",
            Observer::Cie1964TenDegree => "CIE 1964 10°",
        })
    }
}

impl Observer {
    fn table(self) -> &'static [[f64; 4]] {
        match self {
            Observer::Cie1931TwoDegree => tables::CIE1931_2DEG_CMF_1NM,
            Observer::Cie1964TenDegree => tables::CIE1964_10DEG_CMF_1NM,
        }
    }

    /// x̄, ȳ, z̄ at a whole wavelength inside the table (360–830 nm).
    pub fn cmf_at(self, nm: f64) -> Option<[f64; 3]> {
        row_at(self.table(), nm).map(|r| [r[1], r[2], r[3]])
    }

    /// Wavelength range of the tabulated functions.
    pub fn range_nm(self) -> (f64, f64) {
        table_range(self.table())
    }
}

/// A CIE illuminant, for reflectance colorimetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Illuminant {
    A,
    C,
    D50,
    D65,
    F2,
    F7,
    F11,
}

impl Illuminant {
    /// Its relative spectral power distribution (CIE 15:2004 tables, 5 nm).
    pub fn spectrum(self) -> Spectrum {
        match self {
            Illuminant::A => Spectrum::from_table_column(tables::ILLUMINANT_A_5NM, 1),
            Illuminant::C => Spectrum::from_table_column(tables::ILLUMINANT_C_5NM, 1),
            Illuminant::D50 => Spectrum::from_table_column(tables::ILLUMINANT_D50_5NM, 1),
            Illuminant::D65 => Spectrum::from_table_column(tables::ILLUMINANT_D65_5NM, 1),
            Illuminant::F2 => Spectrum::from_table_column(tables::ILLUMINANT_F2_F7_F11_5NM, 1),
            Illuminant::F7 => Spectrum::from_table_column(tables::ILLUMINANT_F2_F7_F11_5NM, 2),
            Illuminant::F11 => Spectrum::from_table_column(tables::ILLUMINANT_F2_F7_F11_5NM, 3),
        }
    }
}

fn table_range<const N: usize>(rows: &[[f64; N]]) -> (f64, f64) {
    (rows[0][0], rows[rows.len() - 1][0])
}

/// The row of a 1 nm table at a whole wavelength.
fn row_at<const N: usize>(rows: &'static [[f64; N]], nm: f64) -> Option<&'static [f64; N]> {
    let first = rows[0][0];
    let offset = nm - first;
    if offset < 0.0 || (offset - offset.round()).abs() > 1e-6 {
        return None;
    }
    rows.get(offset.round() as usize)
}

/// The wavelengths a sum runs over, and Δλ (see the module documentation).
fn integration_grid(
    sample: &Spectrum,
    (lo, hi): (f64, f64),
    what: &'static str,
) -> Result<(Vec<f64>, f64), SpectrumError> {
    let (s_lo, s_hi) = sample.range_nm();
    let (grid, step) = match sample.whole_nm_step() {
        Some(step) => (
            sample
                .wavelengths_nm
                .iter()
                .copied()
                .filter(|w| (lo..=hi).contains(w))
                .collect::<Vec<_>>(),
            step,
        ),
        None => {
            let start = s_lo.max(lo).ceil() as i64;
            let end = s_hi.min(hi).floor() as i64;
            ((start..=end).map(|w| w as f64).collect(), 1.0)
        }
    };
    if grid.len() < 2 {
        return Err(SpectrumError::NoOverlap {
            from_nm: s_lo,
            to_nm: s_hi,
            what,
        });
    }
    Ok((grid, step))
}

/// Σ S(λ)·x̄(λ)Δλ, Σ S(λ)·ȳ(λ)Δλ, Σ S(λ)·z̄(λ)Δλ, where S is `sample` times `weight`
/// (when given).
fn weighted_ordinate_sums(
    sample: &Spectrum,
    weight: Option<&Spectrum>,
    observer: Observer,
) -> Result<Xyz, SpectrumError> {
    let (mut lo, mut hi) = observer.range_nm();
    if let Some(w) = weight {
        let (w_lo, w_hi) = w.range_nm();
        lo = lo.max(w_lo);
        hi = hi.min(w_hi);
    }
    let what = if weight.is_some() {
        "colour-matching functions and illuminant"
    } else {
        "colour-matching functions"
    };
    let (grid, step) = integration_grid(sample, (lo, hi), what)?;
    let mut sums = Xyz::zeros();
    for nm in grid {
        let (Some(s), Some(cmf)) = (sample.value_at(nm), observer.cmf_at(nm)) else {
            continue;
        };
        let w = match weight {
            Some(w) => w.value_at(nm).unwrap_or(0.0),
            None => 1.0,
        };
        sums += Xyz::new(cmf[0], cmf[1], cmf[2]) * (s * w * step);
    }
    Ok(sums)
}

/// Absolute XYZ of a spectral radiance in W·sr⁻¹·m⁻²·nm⁻¹: X = Km Σ S x̄ Δλ and so on
/// (seed eq. 1 with K = 683 lm/W), so that Y is a luminance in cd/m².
pub fn emission_to_xyz(sample: &Spectrum, observer: Observer) -> Result<Xyz, SpectrumError> {
    Ok(weighted_ordinate_sums(sample, None, observer)? * KM_PHOTOPIC)
}

/// Relative XYZ of an emission spectrum in any unit, scaled so that Y = 100
/// (seed eq. 2: K = 1 / Σ S ȳ Δλ, times 100). A spectrum with no luminance gives zeros.
pub fn emission_to_relative_xyz(
    sample: &Spectrum,
    observer: Observer,
) -> Result<Xyz, SpectrumError> {
    let sums = weighted_ordinate_sums(sample, None, observer)?;
    Ok(if sums.y > 0.0 {
        sums * (100.0 / sums.y)
    } else {
        Xyz::zeros()
    })
}

/// XYZ of a reflectance factor (0–1) under `illuminant`, with the perfect reflecting
/// diffuser at Y = 100 (seed eq. 1 with K of eq. 2, times 100; CIE 15:2004 eq. 7.1–7.2).
pub fn reflectance_to_xyz(
    reflectance: &Spectrum,
    illuminant: Illuminant,
    observer: Observer,
) -> Result<Xyz, SpectrumError> {
    let source = illuminant.spectrum();
    let reflected = weighted_ordinate_sums(reflectance, Some(&source), observer)?;
    // The normalisation uses the same grid as the sample, so that a perfect reflector
    // sampled like the sample gives Y = 100 exactly.
    let ones = Spectrum {
        wavelengths_nm: reflectance.wavelengths_nm.clone(),
        values: vec![1.0; reflectance.values.len()],
    };
    let white = weighted_ordinate_sums(&ones, Some(&source), observer)?;
    Ok(reflected * (100.0 / white.y))
}

/// XYZ of an illuminant's white (Y = 100), from its own tabulated spectrum
/// (CIE 15:2004 eq. 7.1–7.2 with R = 1).
pub fn white_point(illuminant: Illuminant, observer: Observer) -> Result<Xyz, SpectrumError> {
    emission_to_relative_xyz(&illuminant.spectrum(), observer)
}

/// Photopic luminance in cd/m² of a spectral radiance: Km Σ S V Δλ (CIE 15:2004 §7.2,
/// with the CIE 1924 V(λ)).
pub fn photopic_luminance(sample: &Spectrum) -> Result<f64, SpectrumError> {
    luminance_with(sample, tables::CIE1924_PHOTOPIC_V_1NM, KM_PHOTOPIC, "V(λ)")
}

/// Scotopic luminance in scotopic cd/m² of a spectral radiance: K′m Σ S V′ Δλ
/// (CIE 1951 V′(λ), defined over 380–780 nm).
pub fn scotopic_luminance(sample: &Spectrum) -> Result<f64, SpectrumError> {
    luminance_with(
        sample,
        tables::CIE1951_SCOTOPIC_VPRIME_1NM,
        KM_SCOTOPIC,
        "V′(λ)",
    )
}

fn luminance_with(
    sample: &Spectrum,
    efficiency: &'static [[f64; 2]],
    km: f64,
    what: &'static str,
) -> Result<f64, SpectrumError> {
    let (grid, step) = integration_grid(sample, table_range(efficiency), what)?;
    let sum: f64 = grid
        .iter()
        .filter_map(|nm| Some(sample.value_at(*nm)? * row_at(efficiency, *nm)?[1]))
        .sum();
    Ok(km * sum * step)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(from: f64, to: f64, step: f64, value: f64) -> Spectrum {
        let n = ((to - from) / step).round() as usize + 1;
        let w: Vec<f64> = (0..n).map(|i| from + step * i as f64).collect();
        Spectrum::new(w, vec![value; n]).unwrap()
    }

    #[test]
    fn rejects_bad_spectra_with_reasons() {
        assert_eq!(
            Spectrum::new(vec![400.0], vec![1.0]),
            Err(SpectrumError::TooFewSamples(1))
        );
        assert!(matches!(
            Spectrum::new(vec![400.0, 400.0], vec![1.0, 1.0]),
            Err(SpectrumError::NotIncreasing { .. })
        ));
        assert!(matches!(
            Spectrum::new(vec![400.0, 410.0], vec![1.0, f64::NAN]),
            Err(SpectrumError::NotFinite { .. })
        ));
        let far = Spectrum::new(vec![900.0, 950.0], vec![1.0, 1.0]).unwrap();
        assert!(matches!(
            emission_to_xyz(&far, Observer::Cie1931TwoDegree),
            Err(SpectrumError::NoOverlap { .. })
        ));
    }

    #[test]
    fn perfect_white_under_d65_matches_the_tabulated_white_point() {
        // data/README: D65, 2°, 5 nm sums over 380–780 nm = 95.04297, 100, 108.88005.
        let white = flat(380.0, 780.0, 5.0, 1.0);
        let xyz = reflectance_to_xyz(&white, Illuminant::D65, Observer::Cie1931TwoDegree).unwrap();
        assert!((xyz.x - 95.04297).abs() < 1e-4, "{xyz:?}");
        assert!((xyz.y - 100.0).abs() < 1e-9);
        assert!((xyz.z - 108.88005).abs() < 1e-4);
    }

    #[test]
    fn white_points_of_illuminants() {
        let d65 = white_point(Illuminant::D65, Observer::Cie1931TwoDegree).unwrap();
        assert!(
            (d65.x - 95.04).abs() < 0.02 && (d65.z - 108.88).abs() < 0.02,
            "{d65:?}"
        );
        let d65_10 = white_point(Illuminant::D65, Observer::Cie1964TenDegree).unwrap();
        assert!(
            (d65_10.x - 94.81).abs() < 0.05 && (d65_10.z - 107.32).abs() < 0.05,
            "{d65_10:?}"
        );
    }

    #[test]
    fn uneven_grids_are_resampled_to_1nm() {
        // An equal-energy emission on a 3.333 nm grid must land near the 1 nm result.
        let even = flat(380.0, 730.0, 1.0, 1.0);
        let w: Vec<f64> = (0..106).map(|i| 380.0 + i as f64 * 350.0 / 105.0).collect();
        let uneven = Spectrum::new(w, vec![1.0; 106]).unwrap();
        let a = emission_to_xyz(&even, Observer::Cie1931TwoDegree).unwrap();
        let b = emission_to_xyz(&uneven, Observer::Cie1931TwoDegree).unwrap();
        assert!(((a - b).norm() / a.norm()) < 1e-9, "{a:?} vs {b:?}");
    }

    #[test]
    fn photopic_luminance_equals_y_of_the_2_degree_observer() {
        let s = flat(400.0, 700.0, 4.0, 0.01);
        let y = emission_to_xyz(&s, Observer::Cie1931TwoDegree).unwrap().y;
        let v = photopic_luminance(&s).unwrap();
        assert!((y - v).abs() < 1e-9 * y);
        assert!(scotopic_luminance(&s).unwrap() > 0.0);
    }

    #[test]
    fn relative_emission_has_y_100() {
        let s = flat(380.0, 780.0, 5.0, 3.7);
        let xyz = emission_to_relative_xyz(&s, Observer::Cie1964TenDegree).unwrap();
        assert!((xyz.y - 100.0).abs() < 1e-9);
    }
}
