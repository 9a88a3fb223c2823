//! Colorimeter correction matrices as ArgyllCMS keeps them: a `.ccmx` file, a CGATS
//! table `CCMX` of three rows `XYZ_X XYZ_Y XYZ_Z`, the matrix that takes a
//! colorimeter's XYZ of one display to the reference spectroradiometer's
//! (XYZ_reference = M · XYZ_colorimeter), with keywords naming the display, the
//! instrument and the reference.
//!
//! A matrix is only taken when it is plausible for that job: finite, well conditioned
//! (a correction undoes filters that are near the CIE functions, so it is near a
//! scaled identity), and keeping every ordinary light's luminance positive and within
//! a factor of two. A singular or absurd matrix would silently wreck every reading.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use crate::cgats::parse_cgats;

/// The most a correction may stretch one direction against another (2-norm condition
/// number). Matrices from real colorimeters against a spectroradiometer are 1.0–1.5;
/// 20 leaves room for poor filters and refuses nonsense.
pub const MAX_CONDITION: f64 = 20.0;

/// Why a correction was not taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CcmxError {
    #[error("{path}: {reason}")]
    Read { path: String, reason: String },
    #[error("{path}: not a .ccmx: {reason}")]
    Format { path: String, reason: String },
    #[error(
        "{what}: the matrix is singular (determinant {determinant:.3e}): it would map different colours to one"
    )]
    Singular { what: String, determinant: f64 },
    #[error(
        "{what}: the matrix's condition number is {condition:.1} (more than {MAX_CONDITION}): no colorimeter's filters need that, so the matrix is wrong"
    )]
    IllConditioned { what: String, condition: f64 },
    #[error(
        "{what}: the matrix turns the luminance of {light} into {corrected:.3} of what was measured (it must stay positive and within 0.5 to 2)"
    )]
    Luminance {
        what: String,
        light: &'static str,
        corrected: f64,
    },
    #[error(
        "{what}: the matrix turns {light} into X, Y, Z = {corrected:?}: light has no negative component, so the matrix is wrong (rows swapped or negated?)"
    )]
    Negative {
        what: String,
        light: &'static str,
        corrected: [f64; 3],
    },
    #[error(
        "{what}: the matrix moves the chromaticity of {light} by Δu′v′ {shift:.3} (more than {MAX_CHROMATICITY_SHIFT}, which no colorimeter's filters need: rows swapped?)"
    )]
    Chromaticity {
        what: String,
        light: &'static str,
        shift: f64,
    },
    #[error("{what}: the matrix holds a value that is not a finite number")]
    NotFinite { what: String },
}

/// A correction matrix and what it was made for.
#[derive(Debug, Clone, PartialEq)]
pub struct Ccmx {
    pub matrix: Matrix3<f64>,
    pub description: String,
    /// The display (make and model) it was made on.
    pub display: String,
    /// The colorimeter it corrects.
    pub instrument: String,
    /// The reference spectroradiometer.
    pub reference: String,
    /// Display technology, free text ("LCD White LED").
    pub technology: String,
}

/// The lights a correction is tried on: CIE XYZ of the sRGB primaries and D65 white
/// at Y = 1 (IEC 61966-2-1), spanning what displays show.
const TEST_LIGHTS: [(&str, [f64; 3]); 4] = [
    ("a red primary", [1.9154, 1.0, 0.0874]),
    ("a green primary", [0.5000, 1.0, 0.1667]),
    ("a blue primary", [2.5000, 1.0, 13.1667]),
    ("a D65 white", [0.9505, 1.0, 1.0890]),
];

/// Lights whose colour a correction must keep light and near where it was: the
/// sRGB and Rec. 2020 primaries (the latter near the spectrum locus: 630, 532 and
/// 467 nm; ITU-R BT.2020 Table 4), D65 and illuminant A (CIE 15:2004 Table T.3), as
/// CIE XYZ at Y = 1.
const COLOUR_LIGHTS: [(&str, [f64; 3]); 8] = [
    ("a red primary", [1.9154, 1.0, 0.0874]),
    ("a green primary", [0.5000, 1.0, 0.1667]),
    ("a blue primary", [2.5000, 1.0, 13.1667]),
    ("a D65 white", [0.9505, 1.0, 1.0890]),
    ("illuminant A", [1.0985, 1.0, 0.3558]),
    ("a 630 nm red", [2.4247, 1.0, 0.0]),
    ("a 532 nm green", [0.2133, 1.0, 0.0414]),
    ("a 467 nm blue", [2.8478, 1.0, 17.8913]),
];

/// The most a correction may move a light's chromaticity (CIE 1976 u′v′). A
/// colorimeter's filters are near the CIE functions: the corrections
/// `tests/correction_make.rs` fits for the emulated colorimeters on measured display
/// spectra move D65 by at most 0.0023 and any of these
/// lights by at most 0.014 (the 630 nm red); a correction of the size published for an
/// i1 Display Pro on a wide-gamut panel moves the 467 nm blue by about 0.06. Swapping X
/// and Z moves a red primary by 0.44.
pub const MAX_CHROMATICITY_SHIFT: f64 = 0.15;

/// How far below zero a corrected component may go, as a share of the light's
/// X + Y + Z.
const NEGATIVE_SHARE: f64 = 0.05;

/// CIE 1976 u′v′ of `xyz` (CIE 15:2004 eq. 8.11, 8.12).
fn uv_prime(xyz: &Vector3<f64>) -> [f64; 2] {
    let d = xyz.x + 15.0 * xyz.y + 3.0 * xyz.z;
    [4.0 * xyz.x / d, 9.0 * xyz.y / d]
}

/// Refuse a matrix that cannot be a colorimeter correction; `what` names it in errors.
/// It must be finite, invertible and well conditioned; keep the luminance of ordinary
/// lights positive and within a factor of two; keep every component of
/// [`COLOUR_LIGHTS`] positive; and move none of their chromaticities by more than
/// [`MAX_CHROMATICITY_SHIFT`].
pub fn check_matrix(matrix: &Matrix3<f64>, what: &str) -> Result<(), CcmxError> {
    let what = what.to_string();
    if matrix.iter().any(|v| !v.is_finite()) {
        return Err(CcmxError::NotFinite { what });
    }
    let determinant = matrix.determinant();
    let scale = matrix.norm().powi(3).max(f64::MIN_POSITIVE);
    if determinant.abs() <= 1e-9 * scale {
        return Err(CcmxError::Singular { what, determinant });
    }
    let singular_values = matrix.singular_values();
    let condition = singular_values.max() / singular_values.min();
    if !(condition <= MAX_CONDITION) {
        return Err(CcmxError::IllConditioned { what, condition });
    }
    for (light, xyz) in TEST_LIGHTS {
        let corrected = (matrix * Vector3::from(xyz)).y / xyz[1];
        if !(0.5..=2.0).contains(&corrected) {
            return Err(CcmxError::Luminance {
                what,
                light,
                corrected,
            });
        }
    }
    for (light, xyz) in COLOUR_LIGHTS {
        let xyz = Vector3::from(xyz);
        let corrected = matrix * xyz;
        // A deep red's Z is nought, and a good matrix may take it a little below
        // (the emulated colorimeters' corrections take a 630 nm red's to −1.8 % of X + Y + Z);
        // a swapped or negated row takes a component far below.
        if corrected.iter().any(|v| *v < -NEGATIVE_SHARE * xyz.sum()) {
            return Err(CcmxError::Negative {
                what,
                light,
                corrected: [corrected.x, corrected.y, corrected.z],
            });
        }
        let (a, b) = (uv_prime(&xyz), uv_prime(&corrected));
        let shift = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
        if !(shift <= MAX_CHROMATICITY_SHIFT) {
            return Err(CcmxError::Chromaticity { what, light, shift });
        }
    }
    Ok(())
}

/// Parse the text of a `.ccmx`; `path` names it in errors. The matrix is checked.
pub fn parse_ccmx(text: &str, path: &str) -> Result<Ccmx, CcmxError> {
    let format = |reason: String| CcmxError::Format {
        path: path.to_string(),
        reason,
    };
    let tables = parse_cgats(text, path).map_err(|e| format(e.to_string()))?;
    let table = tables
        .iter()
        .find(|t| t.identifier.trim() == "CCMX")
        .ok_or_else(|| format("it has no CCMX table".into()))?;
    let columns: Vec<usize> = ["XYZ_X", "XYZ_Y", "XYZ_Z"]
        .iter()
        .map(|f| {
            table
                .fields
                .iter()
                .position(|g| g == f)
                .ok_or_else(|| format(format!("the CCMX table has no {f} field")))
        })
        .collect::<Result<_, _>>()?;
    if table.rows.len() != 3 {
        return Err(format(format!(
            "the matrix has {} rows, not 3",
            table.rows.len()
        )));
    }
    let mut matrix = Matrix3::zeros();
    for (r, (line, row)) in table.rows.iter().enumerate() {
        for (c, &column) in columns.iter().enumerate() {
            let text = row
                .get(column)
                .ok_or_else(|| format(format!("line {line} is short")))?;
            matrix[(r, c)] = text
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format(format!("line {line}: '{text}' is not a finite number")))?;
        }
    }
    check_matrix(&matrix, path)?;
    let keyword = |k: &str| table.keyword(k).unwrap_or("").to_string();
    Ok(Ccmx {
        matrix,
        description: keyword("DESCRIPTOR"),
        display: keyword("DISPLAY"),
        instrument: keyword("INSTRUMENT"),
        reference: keyword("REFERENCE"),
        technology: keyword("TECHNOLOGY"),
    })
}

/// Read and check a `.ccmx` file.
pub fn read_ccmx(path: &Path) -> Result<Ccmx, CcmxError> {
    let name = path.display().to_string();
    let text = crate::durable::read_text_limited(path, 1 << 20).map_err(|e| CcmxError::Read {
        path: name.clone(),
        reason: e.to_string(),
    })?;
    parse_ccmx(&text, &name)
}

/// Quotes cannot appear inside a CGATS string.
fn quoted(text: &str) -> String {
    format!("\"{}\"", text.replace('"', "'"))
}

/// The `.ccmx` text of `ccmx`; `created` is the CREATED keyword's text.
pub fn ccmx_text(ccmx: &Ccmx, created: &str) -> String {
    let mut out = String::from("CCMX   \n\n");
    out += &format!("DESCRIPTOR {}\n", quoted(&ccmx.description));
    out += &format!(
        "ORIGINATOR {}\n",
        quoted(&format!("chromacal {}", env!("CARGO_PKG_VERSION")))
    );
    out += &format!("CREATED {}\n", quoted(created));
    for (key, value) in [
        ("INSTRUMENT", &ccmx.instrument),
        ("DISPLAY", &ccmx.display),
        ("TECHNOLOGY", &ccmx.technology),
        ("REFERENCE", &ccmx.reference),
    ] {
        out += &format!("KEYWORD \"{key}\"\n{key} {}\n", quoted(value));
    }
    // ArgyllCMS applies a matrix only on the base calibration it was made in (its
    // "cbid"): chromacal's colorimeters read in their default calibration, which is
    // Argyll's base 1. The display is taken as not refreshing (an LCD's or OLED's);
    // Argyll does the same when it is not told.
    out += "KEYWORD \"DISPLAY_TYPE_BASE_ID\"\nDISPLAY_TYPE_BASE_ID \"1\"\n";
    out += "KEYWORD \"DISPLAY_TYPE_REFRESH\"\nDISPLAY_TYPE_REFRESH \"NO\"\n";
    out += "KEYWORD \"COLOR_REP\"\nCOLOR_REP \"XYZ\"\n\n";
    out += "NUMBER_OF_FIELDS 3\nBEGIN_DATA_FORMAT\nXYZ_X XYZ_Y XYZ_Z\nEND_DATA_FORMAT\n\n";
    out += "NUMBER_OF_SETS 3\nBEGIN_DATA\n";
    for r in 0..3 {
        out += &format!(
            "{:.9} {:.9} {:.9}\n",
            ccmx.matrix[(r, 0)],
            ccmx.matrix[(r, 1)],
            ccmx.matrix[(r, 2)]
        );
    }
    out += "END_DATA\n";
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Ccmx {
        Ccmx {
            matrix: Matrix3::new(1.02, 0.01, -0.005, 0.0, 0.99, 0.01, 0.003, -0.02, 1.05),
            description: "K-10A on an LCD".into(),
            display: "Dell \"U2415\"".into(),
            instrument: "Klein K-10A".into(),
            reference: "Photo Research PR-670".into(),
            technology: "LCD White LED".into(),
        }
    }

    #[test]
    fn a_ccmx_round_trips_through_its_text() {
        let ccmx = sample();
        let text = ccmx_text(&ccmx, "2026-12-03T00:00:00Z");
        let back = parse_ccmx(&text, "test.ccmx").unwrap();
        assert!((back.matrix - ccmx.matrix).abs().max() < 1e-9);
        assert_eq!(back.instrument, "Klein K-10A");
        assert_eq!(back.display, "Dell 'U2415'");
    }

    #[test]
    fn singular_ill_conditioned_and_absurd_matrices_are_refused() {
        let singular = Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 0.0, 1.0);
        assert!(matches!(
            check_matrix(&singular, "m"),
            Err(CcmxError::Singular { .. })
        ));
        let stretched = Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 40.0);
        let err = check_matrix(&stretched, "m").unwrap_err();
        assert!(
            err.to_string().contains("condition number is 40.0"),
            "{err}"
        );
        // Near the identity, but Y takes 0.15 Z off: negative for blue light.
        let negative = Matrix3::new(1.0, 0.0, 0.0, 0.1, 0.9, -0.15, 0.0, 0.0, 1.0);
        let err = check_matrix(&negative, "m").unwrap_err();
        assert!(
            err.to_string().contains("luminance of a blue primary"),
            "{err}"
        );
        assert!(check_matrix(&sample().matrix, "m").is_ok());
        // A wide-gamut correction of the size real ones have passes.
        let wide = Matrix3::new(
            1.0386, -0.0098, -0.0194, 0.0267, 1.0032, -0.0312, 0.0015, -0.0168, 1.0542,
        );
        assert!(
            check_matrix(&wide, "m").is_ok(),
            "{:?}",
            check_matrix(&wide, "m")
        );
        // X and Z swapped, X and Z negated, one row zeroed: refused, naming the light.
        let swapped = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
        let err = check_matrix(&swapped, "m").unwrap_err();
        assert!(
            matches!(
                err,
                CcmxError::Chromaticity {
                    light: "a red primary",
                    ..
                }
            ),
            "{err}"
        );
        let negated = Matrix3::new(-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0);
        let err = check_matrix(&negated, "m").unwrap_err();
        assert!(
            err.to_string()
                .contains("a red primary into X, Y, Z = [-1.9154"),
            "{err}"
        );
        let zeroed = Matrix3::new(0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        assert!(check_matrix(&zeroed, "m").is_err());
        let text = ccmx_text(&sample(), "now").replace("0.990000000", "nan");
        assert!(
            parse_ccmx(&text, "bad.ccmx")
                .unwrap_err()
                .to_string()
                .contains("'nan'")
        );
        let text = ccmx_text(&sample(), "now").replace("NUMBER_OF_SETS 3", "NUMBER_OF_SETS 2");
        assert!(parse_ccmx(&text, "short.ccmx").is_err());
    }
}
