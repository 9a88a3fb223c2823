//! Numeric CSV tables: one header row, then rows of numbers. Spectra
//! (`wavelength_nm, ...`), display primaries and measured transfer tables all come
//! in this form.

use std::path::{Path, PathBuf};

/// Why a numeric CSV could not be read; each names the file and, where it can, the
/// line and column.
#[derive(Debug, thiserror::Error)]
pub enum CsvError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Syntax { path: PathBuf, message: String },
    #[error("{path}, line {line}, column '{column}': '{text}' is not a finite number")]
    NotANumber {
        path: PathBuf,
        line: u64,
        column: String,
        text: String,
    },
    #[error("{path}, line {line}: {found} fields where the header has {expected}")]
    WrongWidth {
        path: PathBuf,
        line: u64,
        found: usize,
        expected: usize,
    },
    #[error("{path}: no column named '{column}' (the header has: {header})")]
    MissingColumn {
        path: PathBuf,
        column: String,
        header: String,
    },
    #[error("{path}: no data rows")]
    Empty { path: PathBuf },
}

/// A table of finite numbers with named columns.
#[derive(Debug, Clone, PartialEq)]
pub struct NumericTable {
    pub path: PathBuf,
    pub header: Vec<String>,
    /// Rows in file order; each has as many values as the header has names.
    pub rows: Vec<Vec<f64>>,
}

impl NumericTable {
    pub fn read(path: &Path) -> Result<Self, CsvError> {
        let text = crate::durable::read_text_limited(path, crate::durable::limits::TABLE).map_err(
            |source| CsvError::Io {
                path: path.to_path_buf(),
                source,
            },
        )?;
        Self::parse(&text, path)
    }

    /// Parse `text`; `path` is used only to name the source in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, CsvError> {
        let syntax = |e: csv::Error| CsvError::Syntax {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let mut reader = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .flexible(true)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let header: Vec<String> = reader
            .headers()
            .map_err(syntax)?
            .iter()
            .map(str::to_string)
            .collect();
        let mut rows = Vec::new();
        for record in reader.records() {
            let record = record.map_err(syntax)?;
            let line = record.position().map_or(0, |p| p.line());
            if record.iter().all(str::is_empty) {
                continue;
            }
            if record.len() != header.len() {
                return Err(CsvError::WrongWidth {
                    path: path.to_path_buf(),
                    line,
                    found: record.len(),
                    expected: header.len(),
                });
            }
            let mut row = Vec::with_capacity(record.len());
            for (field, name) in record.iter().zip(&header) {
                match field.parse::<f64>() {
                    Ok(v) if v.is_finite() => row.push(v),
                    _ => {
                        return Err(CsvError::NotANumber {
                            path: path.to_path_buf(),
                            line,
                            column: name.clone(),
                            text: field.to_string(),
                        });
                    }
                }
            }
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(CsvError::Empty {
                path: path.to_path_buf(),
            });
        }
        Ok(NumericTable {
            path: path.to_path_buf(),
            header,
            rows,
        })
    }

    /// Index of the column called `name` (case-insensitive).
    pub fn column_index(&self, name: &str) -> Result<usize, CsvError> {
        self.header
            .iter()
            .position(|h| h.eq_ignore_ascii_case(name))
            .ok_or_else(|| CsvError::MissingColumn {
                path: self.path.clone(),
                column: name.to_string(),
                header: self.header.join(", "),
            })
    }

    /// All values of column `index`.
    pub fn column(&self, index: usize) -> Vec<f64> {
        self.rows.iter().map(|r| r[index]).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_numbers_and_names_bad_fields() {
        let p = Path::new("spd.csv");
        let t = NumericTable::parse("wavelength_nm,R\n380, 0.1\n\n385,0.2\n", p).unwrap();
        assert_eq!(t.rows, vec![vec![380.0, 0.1], vec![385.0, 0.2]]);
        assert_eq!(t.column_index("r").unwrap(), 1);
        assert!(matches!(
            t.column_index("G"),
            Err(CsvError::MissingColumn { .. })
        ));

        let err = NumericTable::parse("wavelength_nm,R\n380,0.1\n385,NaN\n", p).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("line 3") && text.contains("'R'") && text.contains("NaN"),
            "{text}"
        );
        let err = NumericTable::parse("wavelength_nm,R\n380,inf\n", p).unwrap_err();
        assert!(matches!(err, CsvError::NotANumber { .. }));
        let err = NumericTable::parse("wavelength_nm,R\n380\n", p).unwrap_err();
        assert!(matches!(err, CsvError::WrongWidth { line: 2, .. }), "{err}");
        assert!(matches!(
            NumericTable::parse("wavelength_nm,R\n", p),
            Err(CsvError::Empty { .. })
        ));
    }
}
