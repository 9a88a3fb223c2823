//! The one reader of spectral CSV files, for `spectrum`, `render` (`--spectra`,
//! `--reflectance`) and `check --scene`: one rule for what a file must cover and
//! for what is done where it stops, so that the commands cannot disagree about the
//! same file.
//!
//! A file is a `wavelength_nm` column, rising from row to row, then one column a
//! sample. The rule for coverage:
//!
//! - the samples must cover at least [`REQUIRED_NM`] (400–700 nm, where the CIE
//!   colour-matching functions carry nearly all their weight); a file that stops
//!   inside it is refused, not guessed at;
//! - where they stop inside [`EXTENDED_NM`] (380–780 nm), each sample is extended
//!   by repeating its nearest measured value (the extrapolation CIE 15:2004
//!   recommends when nothing better is known), and the reader says so; a file on a
//!   uniform grid is extended on that grid, so it stays uniform;
//! - beyond that nothing is extrapolated: each sum runs over the samples' own range.
//!
//! And one rule for resampling: a file on a uniform grid of whole nanometres no
//! coarser than 5 nm keeps its grid; any other is interpolated linearly, onto the
//! 5 nm grid when it is coarser (10 nm data such as an i1Pro's, as CIE 15 asks for
//! data measured more coarsely), onto 1 nm when it is finer (a spectrometer's
//! 0.4 nm steps), within 360–830 nm. Wavelengths outside 200–2500 nm are refused. `spectrum` then sums on that grid (CIE 15 weighted
//! ordinates) and `render`'s spectral methods read it on their own 5 nm grid
//! ([`super::spectral::onto_grid`]), so the two give the same XYZ; only a file finer
//! than 5 nm is summed more finely by `spectrum` than `render` samples it.

use std::path::{Path, PathBuf};

use chromacal_color::Xyz;
use chromacal_color::spectrum::{Observer, Spectrum, SpectrumError, emission_to_xyz};
use chromacal_formats::numeric_csv::{CsvError, NumericTable};

/// Wavelengths every file must cover, in nm.
pub const REQUIRED_NM: (f64, f64) = (400.0, 700.0);

/// Wavelengths a file is extended to by repeating its end values, in nm.
pub const EXTENDED_NM: (f64, f64) = (380.0, 780.0);

/// Wavelengths a file may hold at all, in nm: from the near ultraviolet to the near
/// infrared, beyond anything the colour-matching functions (360–830 nm) weigh.
pub const PLAUSIBLE_NM: (f64, f64) = (200.0, 2500.0);

/// The colour-matching functions' range, in nm: a resampled grid stops there.
const CMF_NM: (f64, f64) = (360.0, 830.0);

/// Why a spectral file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum SpectralFileError {
    #[error(transparent)]
    Csv(#[from] CsvError),
    #[error("{path}: the first column must be wavelength_nm, not '{found}'")]
    NotSpectral { path: PathBuf, found: String },
    #[error("{path}: no sample columns after wavelength_nm")]
    NoSamples { path: PathBuf },
    #[error(
        "{path}, data row {row}: wavelengths must rise from row to row ({previous} nm, then {this} nm)"
    )]
    NotRising {
        path: PathBuf,
        row: usize,
        previous: f64,
        this: f64,
    },
    #[error(
        "{path}, data row {row}: {nm} nm is not a wavelength of light a colorimeter reads ({} to {} nm)",
        PLAUSIBLE_NM.0,
        PLAUSIBLE_NM.1
    )]
    Implausible { path: PathBuf, row: usize, nm: f64 },
    #[error("{path}: {}", too_narrow(*from, *to))]
    TooNarrow { path: PathBuf, from: f64, to: f64 },
    #[error(
        "{path}, row {row}, column '{column}': {value:e} is beyond any spectrum (at most {MAX_SPECTRAL_VALUE:e}: the sun's radiance peaks near 2e7 W·sr⁻¹·m⁻²·nm⁻¹)"
    )]
    ValueOutOfRange {
        path: PathBuf,
        row: usize,
        column: String,
        value: f64,
    },
    #[error("{path}, column '{column}': {source}")]
    Sample {
        path: PathBuf,
        column: String,
        source: SpectrumError,
    },
}

/// Why samples covering `from` to `to` nm are refused: the one sentence every
/// spectral input says.
pub fn too_narrow(from: f64, to: f64) -> String {
    format!(
        "the samples cover {from} to {to} nm, and at least {} to {} nm is needed (a single row covers nothing); the file is refused rather than extrapolated that far",
        REQUIRED_NM.0, REQUIRED_NM.1
    )
}

/// Whether samples covering `from` to `to` nm meet the rule.
pub fn covers_required(from: f64, to: f64) -> bool {
    from <= REQUIRED_NM.0 && to >= REQUIRED_NM.1
}

/// A spectral file as read: its samples, each on the same (possibly extended)
/// wavelengths.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralFile {
    pub path: PathBuf,
    /// Column names, one a sample.
    pub names: Vec<String>,
    pub spectra: Vec<Spectrum>,
    /// The range the file itself covers, before any extension.
    pub measured_nm: (f64, f64),
    /// The range the samples were extended to, when they were.
    pub extended_nm: Option<(f64, f64)>,
    /// Whether the file's grid was interpolated onto the 5 nm grid.
    pub resampled: bool,
}

/// The largest magnitude a sample may have, in any unit a file here uses (radiance in
/// W·sr⁻¹·m⁻²·nm⁻¹, reflectance, relative power): beyond it a value is a unit or an
/// exponent gone wrong, and its integral would print as ∞ or 1e302 cd/m².
pub const MAX_SPECTRAL_VALUE: f64 = 1e10;

/// The coarsest uniform step a file keeps; others go onto the 5 nm grid.
pub const COARSEST_KEPT_STEP_NM: f64 = 5.0;

impl SpectralFile {
    /// Read `path` by the rule of this module; what was extended is said as a
    /// warning, the same from every command.
    pub fn read(path: &Path) -> Result<SpectralFile, SpectralFileError> {
        let table = NumericTable::read(path)?;
        let file = SpectralFile::from_table(&table, path)?;
        if let Some(warning) = file.warning() {
            tracing::warn!("{warning}");
        }
        Ok(file)
    }

    /// The same from text already read (`path` names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<SpectralFile, SpectralFileError> {
        let table = NumericTable::parse(text, path)?;
        SpectralFile::from_table(&table, path)
    }

    fn from_table(table: &NumericTable, path: &Path) -> Result<SpectralFile, SpectralFileError> {
        let path_buf = path.to_path_buf();
        if !table.header[0].eq_ignore_ascii_case("wavelength_nm") {
            return Err(SpectralFileError::NotSpectral {
                path: path_buf,
                found: table.header[0].clone(),
            });
        }
        if table.header.len() < 2 {
            return Err(SpectralFileError::NoSamples { path: path_buf });
        }
        let measured = table.column(0);
        if let Some(k) = measured
            .iter()
            .position(|nm| !(PLAUSIBLE_NM.0..=PLAUSIBLE_NM.1).contains(nm))
        {
            return Err(SpectralFileError::Implausible {
                path: path_buf,
                row: k + 1,
                nm: measured[k],
            });
        }
        if let Some(k) = measured.windows(2).position(|w| w[1] <= w[0]) {
            return Err(SpectralFileError::NotRising {
                path: path_buf,
                row: k + 2,
                previous: measured[k],
                this: measured[k + 1],
            });
        }
        let (from, to) = (measured[0], measured[measured.len() - 1]);
        if !covers_required(from, to) {
            return Err(SpectralFileError::TooNarrow {
                path: path_buf,
                from,
                to,
            });
        }
        for k in 1..table.header.len() {
            if let Some((row, &value)) = table
                .column(k)
                .iter()
                .enumerate()
                .find(|(_, v)| v.abs() > MAX_SPECTRAL_VALUE)
            {
                return Err(SpectralFileError::ValueOutOfRange {
                    path: path_buf,
                    row: row + 1,
                    column: table.header[k].clone(),
                    value,
                });
            }
        }
        let (below, above) = extension(&measured);
        let wavelengths: Vec<f64> = below
            .iter()
            .chain(&measured)
            .chain(&above)
            .copied()
            .collect();
        let extended_nm = (!below.is_empty() || !above.is_empty())
            .then(|| (wavelengths[0], wavelengths[wavelengths.len() - 1]));
        let target = resampling_grid(&wavelengths);
        let spectra = (1..table.header.len())
            .map(|k| {
                let values = table.column(k);
                let (first, last) = (values[0], values[values.len() - 1]);
                let all: Vec<f64> = std::iter::repeat_n(first, below.len())
                    .chain(values)
                    .chain(std::iter::repeat_n(last, above.len()))
                    .collect();
                let in_column = |source| SpectralFileError::Sample {
                    path: path_buf.clone(),
                    column: table.header[k].clone(),
                    source,
                };
                let extended = Spectrum::new(wavelengths.clone(), all).map_err(in_column)?;
                if keeps_its_grid(&extended) {
                    return Ok(extended);
                }
                // Linear between samples; the target grid lies within their range.
                let on = target
                    .iter()
                    .map(|nm| extended.value_at(*nm).unwrap_or(0.0))
                    .collect();
                Spectrum::new(target.clone(), on).map_err(in_column)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let resampled = spectra
            .first()
            .is_some_and(|s| s.wavelengths_nm() != wavelengths.as_slice());
        Ok(SpectralFile {
            path: path_buf,
            names: table.header[1..].to_vec(),
            spectra,
            measured_nm: (from, to),
            extended_nm,
            resampled,
        })
    }

    /// Each sample as a radiance (W·sr⁻¹·m⁻²·nm⁻¹) integrated to XYZ in cd/m²
    /// (CIE 1931 2°), as `spectrum` does by default.
    pub fn emission_xyz(&self) -> Result<Vec<Xyz>, SpectralFileError> {
        self.spectra
            .iter()
            .zip(&self.names)
            .map(|(s, name)| {
                emission_to_xyz(s, Observer::default()).map_err(|source| {
                    SpectralFileError::Sample {
                        path: self.path.clone(),
                        column: name.clone(),
                        source,
                    }
                })
            })
            .collect()
    }

    /// What the reader did beyond reading, for the user: `None` when the file covered
    /// the whole extended range itself.
    pub fn warning(&self) -> Option<String> {
        let (from, to) = self.extended_nm?;
        Some(format!(
            "{}: the samples cover {} to {} nm; extended to {from} to {to} nm by repeating the nearest measured value",
            self.path.display(),
            self.measured_nm.0,
            self.measured_nm.1
        ))
    }
}

/// Wavelengths to add below and above `measured` (rising, covering REQUIRED_NM) so
/// that it reaches EXTENDED_NM: on the file's own step when it is uniform, else the
/// range's ends themselves.
fn extension(measured: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (from, to) = (measured[0], measured[measured.len() - 1]);
    let step = uniform_step(measured);
    let mut below = Vec::new();
    let mut above = Vec::new();
    match step {
        Some(step) => {
            // Multiples of the step from the ends that stay within the range, rounded
            // to 10⁻⁶ nm so that a 3.333… nm grid lands on 780, not on
            // 779.9999999999989; then the range's end itself if no step lands on it
            // (the grid is then uneven, and resampled).
            let at = |nm: f64| (nm * 1e6).round() / 1e6;
            let mut k = 1.0;
            while at(from - k * step) >= EXTENDED_NM.0 {
                below.push(at(from - k * step));
                k += 1.0;
            }
            if below.last().copied().unwrap_or(from) > EXTENDED_NM.0 {
                below.push(EXTENDED_NM.0);
            }
            below.reverse();
            let mut k = 1.0;
            while at(to + k * step) <= EXTENDED_NM.1 {
                above.push(at(to + k * step));
                k += 1.0;
            }
            if above.last().copied().unwrap_or(to) < EXTENDED_NM.1 {
                above.push(EXTENDED_NM.1);
            }
        }
        None => {
            if from > EXTENDED_NM.0 {
                below.push(EXTENDED_NM.0);
            }
            if to < EXTENDED_NM.1 {
                above.push(EXTENDED_NM.1);
            }
        }
    }
    (below, above)
}

/// Whether `spectrum` is on a uniform grid of whole nanometres no coarser than
/// [`COARSEST_KEPT_STEP_NM`].
fn keeps_its_grid(spectrum: &Spectrum) -> bool {
    spectrum
        .whole_nm_step()
        .is_some_and(|step| step <= COARSEST_KEPT_STEP_NM + 1e-6)
}

/// The grid a file that does not keep its own is put on: 1 nm when its samples are
/// finer than 5 nm on average (a spectrometer's narrow peaks are not to be point
/// sampled away), else 5 nm; in both cases within its range and the
/// colour-matching functions'.
fn resampling_grid(wavelengths: &[f64]) -> Vec<f64> {
    let (from, to) = (wavelengths[0], wavelengths[wavelengths.len() - 1]);
    let mean_step = (to - from) / (wavelengths.len() - 1) as f64;
    let step = if mean_step < COARSEST_KEPT_STEP_NM {
        1.0
    } else {
        5.0
    };
    let (from, to) = (from.max(CMF_NM.0), to.min(CMF_NM.1));
    let (first, last) = (
        (from / step - 1e-9).ceil() as i64,
        (to / step + 1e-9).floor() as i64,
    );
    (first..=last).map(|k| k as f64 * step).collect()
}

/// The step of a grid whose steps are all equal (within 10⁻⁶ nm).
fn uniform_step(wavelengths: &[f64]) -> Option<f64> {
    let step = wavelengths.get(1)? - wavelengths[0];
    wavelengths
        .windows(2)
        .all(|w| ((w[1] - w[0]) - step).abs() < 1e-6)
        .then_some(step)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SpectralFile, SpectralFileError> {
        SpectralFile::parse(text, Path::new("s.csv"))
    }

    #[test]
    fn the_required_range_holds_nearly_all_of_y() {
        // Σ ȳ over 400–700 nm against 360–830 nm, CIE 1931 at 1 nm.
        let observer = Observer::Cie1931TwoDegree;
        let sum = |lo: i32, hi: i32| -> f64 {
            (lo..=hi)
                .filter_map(|nm| observer.cmf_at(nm as f64))
                .map(|c| c[1])
                .sum()
        };
        let share = sum(400, 700) / sum(360, 830);
        assert!(share > 0.995 && share < 1.0, "{share}");
    }

    #[test]
    fn a_file_on_a_uniform_grid_is_extended_on_its_grid() {
        let mut text = String::from("wavelength_nm,a\n");
        for nm in (400..=730).step_by(10) {
            text.push_str(&format!("{nm},{}\n", nm as f64 / 1000.0));
        }
        let file = parse(&text).unwrap();
        let s = &file.spectra[0];
        // Extended on its 10 nm grid, then onto the 5 nm grid.
        assert!(file.resampled);
        assert_eq!(s.range_nm(), (380.0, 780.0));
        assert_eq!(s.wavelengths_nm()[1] - s.wavelengths_nm()[0], 5.0);
        assert_eq!(s.value_at(380.0), Some(0.4));
        assert_eq!(s.value_at(390.0), Some(0.4));
        assert!((s.value_at(405.0).unwrap() - 0.405).abs() < 1e-12);
        assert_eq!(s.value_at(780.0), Some(0.73));
        assert_eq!(file.measured_nm, (400.0, 730.0));
        let said = file.warning().unwrap();
        assert!(
            said.contains("400 to 730 nm") && said.contains("380 to 780 nm"),
            "{said}"
        );
    }

    #[test]
    fn a_file_that_covers_the_range_is_left_alone_and_an_uneven_one_gets_the_ends() {
        let mut text = String::from("wavelength_nm,a,b\n");
        for nm in (380..=780).step_by(5) {
            text.push_str(&format!("{nm},0.5,1\n"));
        }
        let file = parse(&text).unwrap();
        assert!(file.warning().is_none());
        assert_eq!(file.spectra.len(), 2);
        assert_eq!(file.spectra[1].wavelengths_nm().len(), 81);
        assert!(!file.resampled);
        // An uneven grid: its ends added at 380 and 780 nm, then onto 5 nm.
        let uneven = parse("wavelength_nm,a\n390,1\n500,2\n703.3,3\n").unwrap();
        let s = &uneven.spectra[0];
        assert_eq!(s.range_nm(), (380.0, 780.0));
        assert_eq!(s.wavelengths_nm().len(), 81);
        assert_eq!(s.value_at(385.0), Some(1.0));
        assert!((s.value_at(445.0).unwrap() - 1.5).abs() < 1e-12);
    }

    #[test]
    fn bad_files_are_refused_by_name() {
        let cases = [
            ("wavelength_nm,a\n550,0.5\n", "cover 550 to 550 nm"),
            (
                "wavelength_nm,a\n450,0.5\n650,0.5\n",
                "at least 400 to 700 nm",
            ),
            ("nm,a\n400,1\n700,1\n", "must be wavelength_nm, not 'nm'"),
            (
                "wavelength_nm,a\n400,1\n700,1\n1e12,1\n",
                "data row 3: 1000000000000 nm is not a wavelength",
            ),
            ("wavelength_nm,a\n-5,1\n400,1\n700,1\n", "data row 1: -5 nm"),
            ("wavelength_nm\n400\n700\n", "no sample columns"),
            (
                "wavelength_nm,a\n400,1\n500,1\n500,1\n700,1\n",
                "data row 3: wavelengths must rise",
            ),
        ];
        for (text, expected) in cases {
            let said = parse(text).unwrap_err().to_string();
            assert!(said.contains(expected), "{text:?}: {said}");
            assert!(said.starts_with("s.csv"), "{said}");
        }
    }

    #[test]
    fn extension_stays_within_380_to_780_nm() {
        // A two-row file (step 300 nm), a 30 nm grid and a 3 nm grid.
        let mut thirty = String::from("wavelength_nm,a\n");
        for nm in (400..=700).step_by(30) {
            thirty.push_str(&format!("{nm},1\n"));
        }
        let mut three = String::from("wavelength_nm,a\n");
        for nm in (400..=700).step_by(3) {
            three.push_str(&format!("{nm},1\n"));
        }
        for text in ["wavelength_nm,a\n400,1\n700,1\n".to_string(), thirty, three] {
            let file = parse(&text).unwrap();
            let s = &file.spectra[0];
            assert_eq!(s.range_nm(), (380.0, 780.0), "{text}");
        }
        // Fine uneven data goes onto 1 nm, keeping a narrow peak's power.
        let mut fine = String::from("wavelength_nm,a\n");
        for k in 0..=1000 {
            let nm = 380.3 + k as f64 * 0.4;
            let v = if (nm - 546.1).abs() < 0.5 { 100.0 } else { 0.0 };
            fine.push_str(&format!("{nm},{v}\n"));
        }
        let file = parse(&fine).unwrap();
        let s = &file.spectra[0];
        assert_eq!(s.wavelengths_nm()[1] - s.wavelengths_nm()[0], 1.0);
        assert!(s.values().iter().any(|v| *v > 10.0));
    }
}
