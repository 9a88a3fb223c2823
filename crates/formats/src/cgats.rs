//! Reading ArgyllCMS CGATS measurement files (`.ti3`), so profiles can be fitted to
//! and checked against measurements made by other tools.
//!
//! Format (ArgyllCMS `doc/ti3_format.html`, `doc/File_Formats.html`): an identifier
//! line, `KEYWORD "value"` lines (with or without `KEYWORD "NAME"` declarations),
//! `BEGIN_DATA_FORMAT` field names `END_DATA_FORMAT`, `NUMBER_OF_SETS n`, and the
//! rows between `BEGIN_DATA` and `END_DATA`. A file may hold further tables (the CAL
//! table of the calibration loaded while measuring); only the first is read.
//! Device values are percent (0–100); XYZ is scaled to white Y = 100 unless
//! `NORMALIZED_TO_Y_100 "NO"`; `LUMINANCE_XYZ_CDM2` gives white in cd/m², which turns
//! relative values into absolute ones. Spectral fields `SPEC_nnn` are read as spectra.

use std::path::Path;

use chromacal_color::Xyz;
use chromacal_color::spectrum::Spectrum;
use chromacal_model::ScreenPosition;
use chromacal_model::measurement::{Measurement, MeasurementSet, Role, Units};
use chromacal_model::reading::{Reading, ReadingStatus};

/// Why a CGATS file could not be read. Each names the file and, where it can, the line.
#[derive(Debug, thiserror::Error)]
pub enum CgatsError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}, line {line}: {message}")]
    Syntax {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{path}: no field {field} (the fields are: {fields})")]
    MissingField {
        path: String,
        field: String,
        fields: String,
    },
    #[error("{path}, line {line}, field {field}: '{text}' is not a finite number")]
    NotANumber {
        path: String,
        line: usize,
        field: String,
        text: String,
    },
    #[error("{path}: {message}")]
    Content { path: String, message: String },
}

/// One table of a CGATS file.
#[derive(Debug, Clone, PartialEq)]
pub struct CgatsTable {
    pub identifier: String,
    pub keywords: Vec<(String, String)>,
    pub fields: Vec<String>,
    /// Rows with the line each came from.
    pub rows: Vec<(usize, Vec<String>)>,
}

impl CgatsTable {
    pub fn keyword(&self, name: &str) -> Option<&str> {
        self.keywords
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
}

/// Split a line into tokens; double-quoted strings are one token without the quotes.
/// A quote left open at the end of the line is an error.
fn tokens(line: &str) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    let mut current = String::new();
    let mut quoted = false;
    let mut in_token = false;
    for ch in line.chars() {
        match ch {
            '"' => {
                quoted = !quoted;
                in_token = true;
            }
            c if c.is_whitespace() && !quoted => {
                if in_token {
                    out.push(std::mem::take(&mut current));
                    in_token = false;
                }
            }
            c => {
                current.push(c);
                in_token = true;
            }
        }
    }
    if quoted {
        return Err("a quoted string is not closed on its line".into());
    }
    if in_token {
        out.push(current);
    }
    Ok(out)
}

/// Parse every table of a CGATS text; `path` names it in errors.
pub fn parse_cgats(text: &str, path: &str) -> Result<Vec<CgatsTable>, CgatsError> {
    #[derive(PartialEq)]
    enum State {
        Identifier,
        Header,
        Format,
        Data,
        ArgBlock,
    }
    let syntax = |line: usize, message: String| CgatsError::Syntax {
        path: path.into(),
        line,
        message,
    };
    let mut tables = Vec::new();
    let mut table: Option<CgatsTable> = None;
    let mut state = State::Identifier;
    let mut expected_sets: Option<(usize, usize)> = None;
    for (i, raw) in text.lines().enumerate() {
        let number = i + 1;
        if raw.contains('\0') {
            return Err(syntax(number, "a NUL byte: not a text file".into()));
        }
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        match state {
            State::Identifier => {
                table = Some(CgatsTable {
                    identifier: line.to_string(),
                    keywords: Vec::new(),
                    fields: Vec::new(),
                    rows: Vec::new(),
                });
                state = State::Header;
            }
            State::ArgBlock => {
                if line.starts_with("END_ARGYLL_") {
                    state = State::Header;
                } else if let Some((_, arguments)) =
                    table.as_mut().and_then(|t| t.keywords.last_mut())
                {
                    // The block's lines, kept as the value of its keyword.
                    arguments.push_str(line);
                    arguments.push(' ');
                }
            }
            State::Header => {
                let t = tokens(line).map_err(|m| syntax(number, m))?;
                let Some(table) = table.as_mut() else {
                    continue;
                };
                match t.first().map(String::as_str) {
                    Some(k) if k.starts_with("BEGIN_ARGYLL_") => {
                        // BEGIN_ARGYLL_COLPROF_ARGS … END_…: held as ARGYLL_COLPROF_ARGS.
                        let name = k.trim_start_matches("BEGIN_").to_string();
                        table.keywords.push((name, String::new()));
                        state = State::ArgBlock;
                    }
                    Some("BEGIN_DATA_FORMAT") => state = State::Format,
                    Some("BEGIN_DATA") => {
                        if table.fields.is_empty() {
                            return Err(syntax(number, "BEGIN_DATA before any data format".into()));
                        }
                        state = State::Data;
                    }
                    Some("NUMBER_OF_SETS") => {
                        let n = t
                            .get(1)
                            .and_then(|v| v.parse().ok())
                            .ok_or_else(|| syntax(number, "NUMBER_OF_SETS needs a count".into()))?;
                        expected_sets = Some((n, number));
                    }
                    Some("KEYWORD") | Some("NUMBER_OF_FIELDS") => {}
                    Some(k) => {
                        let value = t.get(1).cloned().unwrap_or_default();
                        table.keywords.push((k.to_string(), value));
                    }
                    None => {}
                }
            }
            State::Format => {
                if line.starts_with("END_DATA_FORMAT") {
                    state = State::Header;
                } else if let Some(table) = table.as_mut() {
                    for field in tokens(line).map_err(|m| syntax(number, m))? {
                        if table.fields.contains(&field) {
                            return Err(syntax(
                                number,
                                format!("the data format names {field} twice"),
                            ));
                        }
                        table.fields.push(field);
                    }
                }
            }
            State::Data => {
                let Some(current) = table.as_mut() else {
                    continue;
                };
                if line.starts_with("END_DATA") {
                    if let Some((n, at)) = expected_sets
                        && n != current.rows.len()
                    {
                        return Err(syntax(
                            at,
                            format!(
                                "NUMBER_OF_SETS says {n}, the table has {}",
                                current.rows.len()
                            ),
                        ));
                    }
                    expected_sets = None;
                    if let Some(done) = table.take() {
                        tables.push(done);
                    }
                    state = State::Identifier;
                    continue;
                }
                let t = tokens(line).map_err(|m| syntax(number, m))?;
                if t.len() != current.fields.len() {
                    return Err(syntax(
                        number,
                        format!(
                            "{} values where the format has {} fields",
                            t.len(),
                            current.fields.len()
                        ),
                    ));
                }
                current.rows.push((number, t));
            }
        }
    }
    if state == State::Data {
        return Err(syntax(
            text.lines().count(),
            "the file ends inside BEGIN_DATA (no END_DATA)".into(),
        ));
    }
    if tables.is_empty() {
        return Err(CgatsError::Content {
            path: path.into(),
            message: "no complete table (BEGIN_DATA … END_DATA)".into(),
        });
    }
    Ok(tables)
}

/// Read an ArgyllCMS `.ti3` display measurement file.
pub fn read_ti3(path: &Path) -> Result<MeasurementSet, CgatsError> {
    let name = path.display().to_string();
    let bytes =
        crate::durable::read_limited(path, crate::durable::limits::TABLE).map_err(|source| {
            CgatsError::Io {
                path: name.clone(),
                source,
            }
        })?;
    // Argyll writes Latin-1 in places (° and ² in names); read leniently.
    let text = String::from_utf8_lossy(&bytes);
    ti3_from_text(&text, &name)
}

/// A `.ti3` measurement set from its text.
pub fn ti3_from_text(text: &str, name: &str) -> Result<MeasurementSet, CgatsError> {
    let tables = parse_cgats(text, name)?;
    let table = &tables[0];
    let field = |f: &str| {
        table
            .fields
            .iter()
            .position(|x| x == f)
            .ok_or_else(|| CgatsError::MissingField {
                path: name.into(),
                field: f.into(),
                fields: table.fields.join(" "),
            })
    };
    let rgb = [field("RGB_R")?, field("RGB_G")?, field("RGB_B")?];
    let xyz = [field("XYZ_X")?, field("XYZ_Y")?, field("XYZ_Z")?];
    let number = |line: usize, f: usize, text: &str| -> Result<f64, CgatsError> {
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(CgatsError::NotANumber {
                path: name.into(),
                line,
                field: table.fields[f].clone(),
                text: text.into(),
            }),
        }
    };
    let normalised = table.keyword("NORMALIZED_TO_Y_100") != Some("NO");
    let luminance = match table.keyword("LUMINANCE_XYZ_CDM2") {
        Some(v) => {
            let parts: Vec<f64> = v
                .split_whitespace()
                .filter_map(|p| p.parse().ok())
                .collect();
            match parts.as_slice() {
                [_, y, _] if *y > 0.0 && y.is_finite() => Some(*y),
                _ => {
                    return Err(CgatsError::Content {
                        path: name.into(),
                        message: format!(
                            "LUMINANCE_XYZ_CDM2 \"{v}\" is not three numbers with Y > 0"
                        ),
                    });
                }
            }
        }
        None => None,
    };
    let (scale, units) = match (normalised, luminance) {
        (false, _) => (1.0, Units::Absolute),
        (true, Some(y)) => (y / 100.0, Units::Absolute),
        (true, None) => (1.0, Units::Relative),
    };
    // Spectral fields, with wavelengths from the SPECTRAL_* keywords or the names.
    let spectral: Vec<(usize, f64)> = table
        .fields
        .iter()
        .enumerate()
        .filter_map(|(i, f)| Some((i, f.strip_prefix("SPEC_")?.parse::<f64>().ok()?)))
        .collect();
    let keyword_f64 = |k: &str| table.keyword(k).and_then(|v| v.parse::<f64>().ok());
    let wavelengths: Vec<f64> = match (
        keyword_f64("SPECTRAL_START_NM"),
        keyword_f64("SPECTRAL_END_NM"),
        keyword_f64("SPECTRAL_BANDS"),
    ) {
        (Some(a), Some(b), Some(n)) if n as usize == spectral.len() && n >= 2.0 => (0..spectral
            .len())
            .map(|i| a + (b - a) * i as f64 / (n - 1.0))
            .collect(),
        _ => spectral.iter().map(|(_, w)| *w).collect(),
    };
    let mut measurements = Vec::with_capacity(table.rows.len());
    for (index, (line, row)) in table.rows.iter().enumerate() {
        let mut drive = [0.0; 3];
        for c in 0..3 {
            let v = number(*line, rgb[c], &row[rgb[c]])?;
            if !(-1e-9..=100.0 + 1e-9).contains(&v) {
                return Err(CgatsError::Content {
                    path: name.into(),
                    message: format!(
                        "line {line}: {} = {v} is outside 0–100",
                        table.fields[rgb[c]]
                    ),
                });
            }
            drive[c] = (v / 100.0).clamp(0.0, 1.0);
        }
        let mut value = Xyz::zeros();
        for c in 0..3 {
            let read = number(*line, xyz[c], &row[xyz[c]])?;
            value[c] = read * scale;
            // A value that overflows once scaled to cd/m² is named, not dropped.
            if !value[c].is_finite() {
                return Err(CgatsError::Content {
                    path: name.into(),
                    message: format!(
                        "line {line}: {} = {read:e} overflows when scaled to cd/m² (× {scale} from LUMINANCE_XYZ_CDM2)",
                        table.fields[xyz[c]]
                    ),
                });
            }
        }
        let spectrum = if spectral.len() >= 2 {
            let values = spectral
                .iter()
                .map(|(f, _)| {
                    number(*line, *f, &row[*f]).map(|v| v * scale / ARGYLL_SPECTRAL_MILLI)
                })
                .collect::<Result<Vec<f64>, _>>()?;
            Spectrum::new(wavelengths.clone(), values).ok()
        } else {
            None
        };
        measurements.push(Measurement {
            index,
            role: Role::from_drive(drive),
            drive,
            codes: None,
            position: ScreenPosition::CENTRE,
            background: [0.0; 3],
            window: None,
            time_s: None,
            reading: Reading {
                xyz: Some(value),
                spectrum,
                status: ReadingStatus::Ok,
                integration_s: 0.0,
                ..Default::default()
            },
        });
    }
    Ok(MeasurementSet {
        source: name.into(),
        units,
        display: display_name(table),
        measured_at: table.keyword("CREATED").map(str::to_string),
        instrument: table.keyword("TARGET_INSTRUMENT").map(|name| {
            chromacal_model::reading::InstrumentInfo {
                name: name.to_string(),
                serial: None,
                capability: if spectral.is_empty() {
                    chromacal_model::reading::Capability::Tristimulus
                } else {
                    chromacal_model::reading::Capability::Spectral
                },
            }
        }),
        measurements,
    })
}

/// The display a .ti3 is of: its `DISPLAY` keyword, or the manufacturer and model
/// that DisplayCAL passes to `colprof` (`-A "Dell" -M "DELL U2713HM"`) in the
/// file's `ARGYLL_COLPROF_ARGS` block.
fn display_name(table: &CgatsTable) -> Option<String> {
    if let Some(d) = table.keyword("DISPLAY") {
        return Some(d.to_string());
    }
    let arguments = tokens(table.keyword("ARGYLL_COLPROF_ARGS")?).ok()?;
    let after = |flag: &str| {
        let i = arguments.iter().position(|a| a == flag)?;
        arguments.get(i + 1).filter(|v| !v.is_empty()).cloned()
    };
    match (after("-A"), after("-M")) {
        (Some(maker), Some(model)) if model.to_uppercase().starts_with(&maker.to_uppercase()) => {
            Some(model)
        }
        (Some(maker), Some(model)) => Some(format!("{maker} {model}")),
        (None, Some(model)) => Some(model),
        (Some(maker), None) => Some(maker),
        (None, None) => None,
    }
}

/// ArgyllCMS writes a display's spectra in mW·sr⁻¹·m⁻²·nm⁻¹ (its `spec2cie` gives the
/// file's XYZ from them with 683 lm/W over 1000), chromacal holds them in W.
const ARGYLL_SPECTRAL_MILLI: f64 = 1000.0;

/// A `.ti3` text of the usable readings taken at the centre on a black surround (the
/// only condition the format can describe). Absolute sets are written normalised to
/// white Y = 100 with `LUMINANCE_XYZ_CDM2`, as ArgyllCMS writes display files.
pub fn to_ti3(set: &MeasurementSet) -> String {
    to_ti3_against(set, set.mean_white(), 1.0)
}

/// As [`to_ti3`], normalised to `white` (Y = 100) rather than the set's own, and every
/// XYZ multiplied by `factor`. A set of mixtures held out of a fit has no white of its
/// own: written against the training set's white, ArgyllCMS's `profcheck` judges a
/// profile of the training set on it in the frame the profile was made in. `factor`
/// rescales a training set slightly (`comparison`: how much `colprof`'s optimum moves
/// when its white is renormalised).
pub fn to_ti3_against(set: &MeasurementSet, white: Option<Xyz>, factor: f64) -> String {
    let rows: Vec<(&Measurement, Xyz)> = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition())
        .filter_map(|m| Some((m, m.usable_xyz()?)))
        .collect();
    // Relative sets are said to be normalised to white Y = 100 too, so they are made so.
    let (scale, luminance) = match (set.units, white) {
        (Units::Absolute, Some(w)) if w.y > 0.0 => (100.0 / w.y, Some(w)),
        (Units::Relative, Some(w)) if w.y > 0.0 => (100.0 / w.y, None),
        _ => (1.0, None),
    };
    let scale = scale * factor;
    let mut out =
        String::from("CTI3\n\nDESCRIPTOR \"Argyll Calibration Target chart information 3\"\n");
    out += &format!("ORIGINATOR \"chromacal {}\"\n", env!("CARGO_PKG_VERSION"));
    out += "DEVICE_CLASS \"DISPLAY\"\nCOLOR_REP \"RGB_XYZ\"\n";
    match luminance {
        Some(w) => {
            out += &format!("LUMINANCE_XYZ_CDM2 \"{:.6} {:.6} {:.6}\"\n", w.x, w.y, w.z);
            out += "NORMALIZED_TO_Y_100 \"YES\"\n";
        }
        None if set.units == Units::Absolute => out += "NORMALIZED_TO_Y_100 \"NO\"\n",
        None => out += "NORMALIZED_TO_Y_100 \"YES\"\n",
    }
    // A spectral instrument's spectra go along as SPEC_nnn fields (ArgyllCMS's
    // dispread writes them so), in mW and scaled as XYZ is, when every row has one on
    // the same wavelengths.
    let wavelengths = rows
        .first()
        .and_then(|(m, _)| m.reading.spectrum.as_ref())
        .map(|s| s.wavelengths_nm().to_vec())
        .filter(|w| w.len() >= 2)
        .filter(|w| {
            rows.iter().all(|(m, _)| {
                m.reading
                    .spectrum
                    .as_ref()
                    .is_some_and(|s| s.wavelengths_nm() == w.as_slice())
            })
        });
    let mut fields = String::from("SAMPLE_ID RGB_R RGB_G RGB_B XYZ_X XYZ_Y XYZ_Z");
    if let Some(w) = &wavelengths {
        let (first, last) = (w[0], w[w.len() - 1]);
        out += "INSTRUMENT_TYPE_SPECTRAL \"YES\"\n";
        out += &format!(
            "SPECTRAL_BANDS \"{}\"\nSPECTRAL_START_NM \"{first:.6}\"\nSPECTRAL_END_NM \"{last:.6}\"\n",
            w.len()
        );
        for nm in w {
            fields += &format!(" SPEC_{:.0}", nm);
        }
    }
    out += &format!(
        "\nNUMBER_OF_FIELDS {}\nBEGIN_DATA_FORMAT\n{fields}\nEND_DATA_FORMAT\n\n",
        fields.split(' ').count()
    );
    out += &format!("NUMBER_OF_SETS {}\nBEGIN_DATA\n", rows.len());
    for (i, (m, xyz)) in rows.iter().enumerate() {
        let v = xyz * scale;
        out += &format!(
            "{} {:.4} {:.4} {:.4} {:.6} {:.6} {:.6}",
            i + 1,
            m.drive[0] * 100.0,
            m.drive[1] * 100.0,
            m.drive[2] * 100.0,
            v.x,
            v.y,
            v.z
        );
        if let (Some(_), Some(s)) = (&wavelengths, &m.reading.spectrum) {
            for value in s.values() {
                out += &format!(" {:.8e}", value * scale * ARGYLL_SPECTRAL_MILLI);
            }
        }
        out += "\n";
    }
    out += "END_DATA\n";
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "CTI3\n\nKEYWORD \"NORMALIZED_TO_Y_100\"\nNORMALIZED_TO_Y_100 \"YES\"\nLUMINANCE_XYZ_CDM2 \"152.0 160.0 174.0\"\nBEGIN_ARGYLL_COLPROF_ARGS\n-v -qh\nEND_ARGYLL_COLPROF_ARGS\nNUMBER_OF_FIELDS 7\nBEGIN_DATA_FORMAT\nSAMPLE_ID RGB_R RGB_G RGB_B XYZ_X XYZ_Y XYZ_Z\nEND_DATA_FORMAT\nNUMBER_OF_SETS 3\nBEGIN_DATA\n1 100 100 100 95.0 100.0 108.0\n2 0 0 0 0.1 0.1 0.1\n\"3\" 50 0 0 8.9 4.6 0.4\nEND_DATA\nCAL\nBEGIN_DATA_FORMAT\nRGB_I RGB_R RGB_G RGB_B\nEND_DATA_FORMAT\nBEGIN_DATA\n0 0 0 0\nEND_DATA\n";

    #[test]
    fn reads_the_first_table_in_absolute_units() {
        let set = ti3_from_text(SMALL, "small.ti3").unwrap();
        assert_eq!(set.units, Units::Absolute);
        assert_eq!(set.measurements.len(), 3);
        let white = &set.measurements[0];
        assert_eq!(white.role, Role::Grey);
        assert!((white.reading.xyz.unwrap().y - 160.0).abs() < 1e-9);
        assert_eq!(set.measurements[1].role, Role::Black);
        assert_eq!(set.measurements[2].role, Role::Ramp);
        assert_eq!(set.measurements[2].drive, [0.5, 0.0, 0.0]);
    }

    #[test]
    fn what_is_written_reads_back() {
        let set = ti3_from_text(SMALL, "small.ti3").unwrap();
        let again = ti3_from_text(&to_ti3(&set), "again.ti3").unwrap();
        assert_eq!(again.units, Units::Absolute);
        for (a, b) in set.measurements.iter().zip(&again.measurements) {
            assert_eq!(a.drive, b.drive);
            assert!((a.reading.xyz.unwrap() - b.reading.xyz.unwrap()).norm() < 1e-4);
        }
    }

    #[test]
    fn nul_bytes_open_quotes_duplicate_fields_and_overflow_are_refused() {
        let err = |text: &str| ti3_from_text(text, "x").unwrap_err().to_string();
        let e = err(&SMALL.replace("2 0 0 0 0.1", "2 0 0 0\x000.1"));
        assert!(e.contains("line 16") && e.contains("NUL"), "{e}");
        let e = err(&SMALL.replace("\"3\" 50", "\"3 50"));
        assert!(e.contains("line 17") && e.contains("not closed"), "{e}");
        let e = err(&SMALL.replace("RGB_R RGB_G RGB_B XYZ_X", "RGB_R RGB_G RGB_R XYZ_X"));
        assert!(e.contains("names RGB_R twice"), "{e}");
        let e = err(&SMALL.replace("8.9 4.6 0.4", "8.9 1.5e308 0.4"));
        assert!(
            e.contains("line 17") && e.contains("XYZ_Y") && e.contains("overflows"),
            "{e}"
        );
    }

    #[test]
    fn bad_values_name_line_and_field() {
        let broken = SMALL.replace("8.9 4.6 0.4", "8.9 nan 0.4");
        let err = ti3_from_text(&broken, "small.ti3").unwrap_err().to_string();
        assert!(
            err.contains("line 17") && err.contains("XYZ_Y") && err.contains("nan"),
            "{err}"
        );
        let broken = SMALL.replace("8.9 4.6 0.4", "8.9 inf 0.4");
        assert!(matches!(
            ti3_from_text(&broken, "x").unwrap_err(),
            CgatsError::NotANumber { .. }
        ));
        let broken = SMALL.replace("NUMBER_OF_SETS 3", "NUMBER_OF_SETS 4");
        assert!(
            ti3_from_text(&broken, "x")
                .unwrap_err()
                .to_string()
                .contains("NUMBER_OF_SETS says 4")
        );
        let broken = SMALL.replace(" XYZ_Z\n", " XYZ_W\n");
        assert!(matches!(
            ti3_from_text(&broken, "x").unwrap_err(),
            CgatsError::MissingField { .. }
        ));
        let broken = SMALL.replace("0.1 0.1 0.1", "0.1 0.1");
        assert!(
            ti3_from_text(&broken, "x")
                .unwrap_err()
                .to_string()
                .contains("line 16")
        );
        let cut = &SMALL[..SMALL.find("END_DATA\nCAL").unwrap()];
        assert!(
            ti3_from_text(cut, "x")
                .unwrap_err()
                .to_string()
                .contains("no END_DATA")
        );
    }
}
