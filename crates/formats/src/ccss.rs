//! Colorimeter calibration spectral samples as ArgyllCMS keeps them: a `.ccss` file, a
//! CGATS table `CCSS` whose rows are emission spectra of one display type (its
//! primaries and white, typically), `SPEC_NNN` fields on a regular grid.
//!
//! A colorimeter whose three spectral sensitivities are known turns such samples into
//! its correction for that display type: the matrix that takes what it reads of each
//! sample to the sample's CIE 1931 XYZ, fitted by least squares over the samples
//! (ArgyllCMS, `ccss` and the i1d3 driver, do the same). chromacal knows the
//! sensitivities of its emulated colorimeters only; a real one's come from its maker,
//! which is why the bridge hands a `.ccss` to ArgyllCMS.

use std::path::Path;

use nalgebra::Matrix3;

use crate::cgats::parse_cgats;
use chromacal_color::Xyz;
use chromacal_color::spectrum::{Observer, Spectrum, emission_to_xyz};

/// Why a `.ccss` was not taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CcssError {
    #[error("{path}: {reason}")]
    Read { path: String, reason: String },
    #[error("{path}: not a .ccss: {reason}")]
    Format { path: String, reason: String },
    #[error(
        "{path}: {count} spectral samples cannot fix a 3×3 matrix (at least 3 independent ones)"
    )]
    TooFew { path: String, count: usize },
}

/// The spectral samples of one display type.
#[derive(Debug, Clone, PartialEq)]
pub struct Ccss {
    pub description: String,
    /// The display (or display type) measured.
    pub display: String,
    pub technology: String,
    pub samples: Vec<Spectrum>,
}

/// Whether `path` names a `.ccss` (by its extension, either case).
pub fn is_ccss_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("ccss"))
}

/// Parse the text of a `.ccss`; `path` names it in errors.
pub fn parse_ccss(text: &str, path: &str) -> Result<Ccss, CcssError> {
    let format = |reason: String| CcssError::Format {
        path: path.to_string(),
        reason,
    };
    let tables = parse_cgats(text, path).map_err(|e| format(e.to_string()))?;
    let table = tables
        .iter()
        .find(|t| t.identifier.trim() == "CCSS")
        .ok_or_else(|| format("it has no CCSS table".into()))?;
    // SPEC_380, SPEC_385, … in the order of the fields.
    let mut bands: Vec<(usize, f64)> = Vec::new();
    for (i, field) in table.fields.iter().enumerate() {
        if let Some(nm) = field.strip_prefix("SPEC_") {
            let nm = nm
                .parse::<f64>()
                .map_err(|_| format(format!("the field {field} names no wavelength")))?;
            bands.push((i, nm));
        }
    }
    if bands.len() < 2 {
        return Err(format("it has no SPEC_ fields".into()));
    }
    if bands.windows(2).any(|w| !(w[1].1 > w[0].1)) {
        return Err(format("its SPEC_ fields are not in rising order".into()));
    }
    let wavelengths: Vec<f64> = bands.iter().map(|(_, nm)| *nm).collect();
    // Argyll scales spectra by SPECTRAL_NORM (absent: 1); the matrix needs only their
    // shapes and relative sizes, so the scale is kept as it is.
    let mut samples = Vec::with_capacity(table.rows.len());
    for (line, row) in &table.rows {
        let values: Vec<f64> = bands
            .iter()
            .map(|(i, _)| {
                row.get(*i)
                    .and_then(|t| t.parse::<f64>().ok())
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        format(format!(
                            "line {line}: a spectral value is missing or not a number"
                        ))
                    })
            })
            .collect::<Result<_, _>>()?;
        samples.push(
            Spectrum::new(wavelengths.clone(), values)
                .map_err(|e| format(format!("line {line}: {e}")))?,
        );
    }
    if samples.len() < 3 {
        return Err(CcssError::TooFew {
            path: path.to_string(),
            count: samples.len(),
        });
    }
    let keyword = |k: &str| table.keyword(k).unwrap_or("").to_string();
    Ok(Ccss {
        description: keyword("DESCRIPTOR"),
        display: keyword("DISPLAY"),
        technology: keyword("TECHNOLOGY"),
        samples,
    })
}

/// Read a `.ccss` file.
pub fn read_ccss(path: &Path) -> Result<Ccss, CcssError> {
    let name = path.display().to_string();
    let text = crate::durable::read_text_limited(path, 8 << 20).map_err(|e| CcssError::Read {
        path: name.clone(),
        reason: e.to_string(),
    })?;
    parse_ccss(&text, &name)
}

/// The correction of a colorimeter that reads `sensitivities(spectrum)` for the
/// samples' display type: M minimising Σ‖M·reading − XYZ‖² over the samples, each
/// weighted by 1/Y² so that a dim primary counts as much as the white (the error that
/// matters is relative). `None` when the samples do not span three dimensions.
pub fn correction_from_samples(
    samples: &[Spectrum],
    sensitivities: impl Fn(&Spectrum) -> Option<Xyz>,
) -> Option<Matrix3<f64>> {
    let mut pairs = Vec::new();
    for s in samples {
        let truth = emission_to_xyz(s, Observer::default()).ok()?;
        let read = sensitivities(s)?;
        let w = 1.0 / truth.y.abs().max(1e-9).powi(2);
        pairs.push((read, truth, w));
    }
    chromacal_color::linalg::weighted_linear_map(&pairs)
}
