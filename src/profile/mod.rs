//! The native monitor profile: a TOML file with a schema version, holding the model,
//! its uncertainties and diagnostics, the held-out errors, and where it came from.
//!
//! The model is written with names (`primaries.red = [X, Y, Z]`, `laws.red.law =
//! "cowan"`) so a person can read it, and checked when read back: finite numbers,
//! monotone laws.

pub mod store;

use std::borrow::Cow;
use std::path::Path;

use serde::{Deserialize, Serialize};

use chromacal_color::difference::Metric;
use chromacal_instruments::InstrumentInfo;
use chromacal_model::MonitorModel;
use chromacal_model::fit::FitReport;
use chromacal_model::grey_correction::{GreyCorrection, HeldOutMeans};
use chromacal_model::measurement::Units;
use chromacal_model::target::CalibrationCurves;

/// Version of the profile file format. Readers refuse other versions.
pub const SCHEMA_VERSION: u32 = 1;

/// Why a profile could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}:{line}:{column}: {message}")]
    Parse {
        path: String,
        line: usize,
        column: usize,
        message: String,
    },
    #[error(
        "{path} is {what}, not a chromacal profile (a TOML file that `calibrate`, `fit` or the daemon writes, such as <state>/current.toml){hint}"
    )]
    OtherKind {
        path: String,
        what: String,
        hint: &'static str,
    },
    #[error("{path}: schema version {found}, this program reads version {SCHEMA_VERSION}")]
    Version { path: String, found: u32 },
    #[error(
        "{path}: {key} is not a finite number (chromacal never writes one: the file was edited or damaged)"
    )]
    NotFinite { path: String, key: String },
    #[error("cannot write the profile as TOML: {0}")]
    Serialize(String),
}

/// Where a profile came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// The measurements it was fitted on (a journal or a file).
    pub source: String,
    pub display: Option<String>,
    pub instrument: Option<InstrumentInfo>,
    /// When the readings were taken, as their file says (a .ti3's `CREATED`; a run's
    /// journal, "from" the run's start).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_at: Option<String>,
    /// SHA-256 of the config of the run, when it came from a run.
    pub config_digest: Option<String>,
    pub program: String,
    /// Fit and publishing settings given at `--resume` in place of the journal's
    /// (where from, and its digest): the readings were taken with the journal's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings_at_resume: Option<String>,
    /// The EDID of the monitor measured, when the run showed its patches in the
    /// native window on an output that has one: its identity, and the primaries and
    /// white its maker states, set beside the measured ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edid: Option<chromacal_formats::edid::Edid>,
    /// The colorimeter correction the readings went through: its name, file digest,
    /// display type and reference.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction: Option<CorrectionRecord>,
    /// Said when a colorimeter was used without a correction: what that costs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected: Option<String>,
    /// The signal the run's codes were (PQ, HLG), for an HDR run; absent for SDR.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub signal: Option<chromacal_model::plan::Signal>,
}

impl Provenance {
    /// Record the colorimeter correction the readings went through, or, for a
    /// colorimeter without one, the warning.
    pub fn set_correction(&mut self, correction: Option<CorrectionRecord>) {
        self.uncorrected = match (&correction, &self.instrument) {
            (None, Some(i)) if i.capability == chromacal_instruments::Capability::Tristimulus => {
                Some(uncorrected_warning(&i.name))
            }
            _ => None,
        };
        self.correction = correction;
    }
}

/// A correction file, as `chromacal correction list` shows it and a profile records it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CorrectionRecord {
    /// Its file name, or "a matrix in the config".
    pub name: String,
    /// `ccmx`, `ccss`, or `matrix`.
    pub kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<String>,
    /// SHA-256 of the file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
    /// The display (type) it was made on, as the file says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub display: Option<String>,
    /// The instrument it corrects, and the reference it was made against.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
}

impl CorrectionRecord {
    /// A correction in one line: name, kind, display type, reference, digest.
    pub fn describe(&self) -> String {
        let mut parts = vec![format!("{} ({})", self.name, self.kind)];
        if let Some(d) = &self.display {
            parts.push(format!("display {d}"));
        }
        if let Some(r) = &self.reference {
            parts.push(format!("made against {r}"));
        }
        if let Some(s) = &self.sha256 {
            parts.push(format!("SHA-256 {s}"));
        }
        parts.join(", ")
    }
}

/// What a colorimeter reads off without a correction, said beside its readings: its
/// filters are not the CIE's, and the error depends on the display's spectra.
pub fn uncorrected_warning(instrument: &str) -> String {
    format!(
        "the {instrument} is a colorimeter used without a correction: its filters are not the CIE observer's, so its XYZ depends on the display's spectra (chromacal's emulated K-10A, CS-100A and ColorCAL MKII read CRT, LCD and OLED displays 0.3 to 2.7 ΔE00 off; wide-gamut and LED-backlit displays are the worst). Make one against a spectroradiometer with `chromacal correction make`, or name one in [instrument] correction (`chromacal correction list`)"
    )
}

/// A monitor profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    pub schema_version: u32,
    pub id: String,
    /// RFC 3339.
    pub created: String,
    /// Units of the XYZ values in the model.
    pub units: Units,
    pub model: MonitorModel,
    pub provenance: Provenance,
    /// Uncertainties, diagnostics, assumption checks and held-out errors.
    pub report: FitReport,
    /// Calibration curves to a target, with their measured check (`[target]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<StoredCalibration>,
    /// What the profile cost to make (absent in profiles made before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost: Option<Cost>,
}

/// What a profile cost: readings taken, instrument time, fit time. Every claim of
/// accuracy in a report comes with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cost {
    /// Readings the fit was given (the run's, or the file's).
    pub readings: usize,
    /// Seconds the instrument spent: integration and settling of every patch. Unknown
    /// for a measurement file that does not record it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument_s: Option<f64>,
    /// Wall-clock seconds of the fit.
    pub fit_s: f64,
}

/// Line and column (1-based) of a byte offset in `text`.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before
        .rfind('\n')
        .map_or(before.len(), |i| before.len() - i - 1)
        + 1;
    (line, column)
}

/// A TOML error as "line, column, message".
pub fn toml_error_position(text: &str, error: &toml::de::Error) -> (usize, usize, String) {
    let (line, column) = error
        .span()
        .map_or((0, 0), |span| line_column(text, span.start));
    (line, column, error.message().to_string())
}

/// How far the primaries and white an EDID states may lie from the measured ones (xy)
/// before the profile asks whether this is the display meant. Makers' EDID figures
/// are typical values, often a few thousandths off and for wide-gamut panels
/// sometimes a couple of hundredths; a different display is usually further.
pub const EDID_MISMATCH_XY: f64 = 0.03;

/// The EDID's chromaticities beside the measured ones.
#[derive(Debug, Clone, PartialEq)]
pub struct EdidComparison {
    /// Name, EDID xy, measured xy, distance in xy: red, green, blue, white.
    pub rows: Vec<(&'static str, [f64; 2], [f64; 2], f64)>,
    /// The largest distance.
    pub worst: f64,
}

impl EdidComparison {
    /// The rows as a table's text: the light, EDID xy, measured xy, how far apart.
    pub fn table_rows(&self) -> Vec<Vec<String>> {
        self.rows
            .iter()
            .map(|(name, e, m, d)| {
                vec![
                    name.to_string(),
                    format!("{:.4}, {:.4}", e[0], e[1]),
                    format!("{:.4}, {:.4}", m[0], m[1]),
                    format!("{d:.4}"),
                ]
            })
            .collect()
    }

    /// The EDID is grossly unlike what was measured.
    pub fn mismatch(&self) -> bool {
        self.worst > EDID_MISMATCH_XY
    }
}

impl Profile {
    /// The EDID's primaries and white beside the fitted ones, when the profile carries
    /// an EDID.
    pub fn edid_comparison(&self) -> Option<EdidComparison> {
        let edid = self.provenance.edid.as_ref()?;
        let xy = |xyz: chromacal_color::Xyz| {
            let sum = xyz.x + xyz.y + xyz.z;
            (sum > 0.0).then(|| [xyz.x / sum, xyz.y / sum])
        };
        let columns = [0, 1, 2].map(|c| self.model.matrix.column(c).into_owned());
        let measured = [
            xy(columns[0])?,
            xy(columns[1])?,
            xy(columns[2])?,
            xy(self.model.white())?,
        ];
        let stated = [edid.red, edid.green, edid.blue, edid.white];
        let rows: Vec<_> = ["red", "green", "blue", "white"]
            .into_iter()
            .zip(stated.into_iter().zip(measured))
            .map(|(name, (e, m))| (name, e, m, (e[0] - m[0]).hypot(e[1] - m[1])))
            .collect();
        let worst = rows.iter().map(|r| r.3).fold(0.0, f64::max);
        Some(EdidComparison { rows, worst })
    }

    pub fn from_toml(text: &str, path: &str) -> Result<Self, ProfileError> {
        // Look at the version first so an old or new file gets a clear message.
        #[derive(Deserialize)]
        struct VersionOnly {
            schema_version: Option<u32>,
        }
        if let Ok(v) = toml::from_str::<VersionOnly>(text)
            && let Some(found) = v.schema_version
            && found != SCHEMA_VERSION
        {
            return Err(ProfileError::Version {
                path: path.into(),
                found,
            });
        }
        let value: toml::Value = toml::from_str(text).map_err(|e| {
            let (line, column, message) = toml_error_position(text, &e);
            ProfileError::Parse {
                path: path.into(),
                line,
                column,
                message,
            }
        })?;
        // chromacal never writes a number that is not finite; one in a file (TOML
        // allows `nan` and `inf`) is an edit or damage, and would print as NaN.
        if let Some(key) = non_finite_key(&value, "") {
            return Err(ProfileError::NotFinite {
                path: path.into(),
                key,
            });
        }
        toml::from_str(text).map_err(|e| {
            let (line, column, message) = toml_error_position(text, &e);
            ProfileError::Parse {
                path: path.into(),
                line,
                column,
                message,
            }
        })
    }

    pub fn read(path: &Path) -> Result<Self, ProfileError> {
        let other = |(what, hint)| ProfileError::OtherKind {
            path: path.display().to_string(),
            what,
            hint,
        };
        // Binary (an ICC profile) does not read as text: only then is the file's head
        // read again, to say what it is.
        let text = chromacal_formats::durable::read_text_limited(
            path,
            chromacal_formats::durable::limits::PROFILE,
        )
        .map_err(
            |source| match file_head(path).as_deref().and_then(other_kind) {
                Some(kind) => other(kind),
                None => ProfileError::Io {
                    path: path.display().to_string(),
                    source,
                },
            },
        )?;
        let head = &text.as_bytes()[..text.len().min(HEAD_BYTES)];
        if let Some(kind) = other_kind(head) {
            return Err(other(kind));
        }
        Self::from_toml(&text, &path.display().to_string())
    }

    /// The profile as TOML; refused if it holds a number that is not finite, which
    /// `from_toml` would refuse to read back.
    pub fn to_toml(&self) -> Result<String, ProfileError> {
        let value =
            toml::Value::try_from(self).map_err(|e| ProfileError::Serialize(e.to_string()))?;
        if let Some(key) = non_finite_key(&value, "") {
            return Err(ProfileError::NotFinite {
                path: format!("profile {}", self.id),
                key,
            });
        }
        toml::to_string(self).map_err(|e| ProfileError::Serialize(e.to_string()))
    }

    /// Write to `path`, a file the user named, atomically (see
    /// [`chromacal_formats::durable::write_atomic_named`]).
    pub fn write(&self, path: &Path) -> Result<(), ProfileError> {
        let text = self.to_toml()?;
        chromacal_formats::durable::write_atomic_named(path, text.as_bytes()).map_err(|source| {
            ProfileError::Io {
                path: path.display().to_string(),
                source,
            }
        })
    }
}

/// What a file that is not a chromacal profile is, judged from its first bytes, for
/// the files people mistake for one: a run's journal (arguments given the other way
/// round), an ICC profile (ICC.1:2022 §7.2: 'acsp' at byte
/// 36, the version at byte 8, the class at 12, the colour space at 16), an ArgyllCMS
/// CGATS file, or anything that is not text. `None` for text that may be TOML.
fn other_kind(head: &[u8]) -> Option<(String, &'static str)> {
    if head.len() >= 40 && &head[36..40] == b"acsp" {
        let word = |at: usize| {
            String::from_utf8_lossy(&head[at..at + 4])
                .trim()
                .to_string()
        };
        return Some((
            format!(
                "an ICC profile (version {}.{}, class '{}', colour space '{}')",
                head[8],
                head[9] >> 4,
                word(12),
                word(16)
            ),
            ": give the .toml profile it was made from (`chromacal export` writes ICC from it)",
        ));
    }
    let text = String::from_utf8_lossy(head);
    if text.trim_start().starts_with('{')
        && text.contains(&format!(
            "\"format\":\"{}\"",
            crate::journal::JOURNAL_FORMAT
        ))
    {
        return Some((
            "a chromacal run's journal (its readings)".to_string(),
            ": `chromacal fit JOURNAL -o PROFILE.toml` makes a profile from it, and `chromacal check PROFILE JOURNAL` takes the profile first",
        ));
    }
    if let Some(kind) = ["CTI3", "CTI1", "CAL", "CGATS"]
        .into_iter()
        .find(|k| text.trim_start().starts_with(k))
    {
        return Some((
            format!("an ArgyllCMS {kind} file"),
            ": to make a profile from measurements, run `chromacal fit FILE -o PROFILE.toml`",
        ));
    }
    std::str::from_utf8(head)
        .is_err()
        .then(|| ("not text (UTF-8)".to_string(), ""))
        .filter(|_| {
            // A multi-byte character cut at the end of the head is not binary.
            head.len() < HEAD_BYTES || std::str::from_utf8(&head[..HEAD_BYTES - 8]).is_err()
        })
}

/// Bytes of a file's start that [`other_kind`] looks at.
const HEAD_BYTES: usize = 128;

/// The first [`HEAD_BYTES`] of the file at `path`.
fn file_head(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read as _;
    let mut head = Vec::with_capacity(HEAD_BYTES);
    chromacal_formats::durable::open_regular(path)
        .ok()?
        .take(HEAD_BYTES as u64)
        .read_to_end(&mut head)
        .ok()?;
    Some(head)
}

/// The first key under `value` holding a float that is not finite.
fn non_finite_key(value: &toml::Value, key: &str) -> Option<String> {
    match value {
        toml::Value::Float(f) if !f.is_finite() => Some(key.to_string()),
        toml::Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(i, item)| non_finite_key(item, &format!("{key}[{i}]"))),
        toml::Value::Table(table) => table.iter().find_map(|(name, item)| {
            let key = if key.is_empty() {
                name.clone()
            } else {
                format!("{key}.{name}")
            };
            non_finite_key(item, &key)
        }),
        _ => None,
    }
}

/// One grey level as measured through the final curves.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LevelCheck {
    pub input: f64,
    pub target_luminance: f64,
    pub measured_luminance: f64,
    /// The whole reading, in the profile's units.
    pub measured_xyz: [f64; 3],
    /// The drive that reached the panel: the curves' output at the codes' depth
    /// where chromacal sent the codes, the curves' output itself through a video LUT.
    /// (None in files written before it was kept: the curves' output.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drive: Option<[f64; 3]>,
}

impl Profile {
    /// The colour difference this profile is judged in: ΔE ITP (BT.2124) for a
    /// profile of an HDR signal on absolute light, ΔE00 otherwise.
    pub fn judged_in(&self) -> Metric {
        match self.units == Units::Absolute && self.provenance.signal.is_some_and(|s| s.is_hdr()) {
            true => Metric::Itp,
            false => Metric::De00,
        }
    }

    /// The model what the profile makes goes through (`lut3d`, `verify`'s charts,
    /// `render`, the ICC export): the fitted model with its transfer laws corrected
    /// by the calibration's measured greys ([`GreyCorrection`]) where that predicts
    /// the patches held out of the fit better than the model alone by more than the
    /// standard error of the difference (in ΔE ITP for an HDR signal's profile, ΔE00
    /// otherwise), else the fitted model; and a sentence saying whether the greys
    /// are used and why (none where there is nothing to decide).
    pub fn output_model(&self) -> (Cow<'_, MonitorModel>, Option<String>) {
        match self.grey_correction() {
            (Some(correction), said) => (Cow::Owned(correction.into_model()), said),
            (None, said) => (Cow::Borrowed(&self.model), said),
        }
    }

    /// The greys' correction [`Profile::output_model`] uses, if any, and why.
    fn grey_correction(&self) -> (Option<GreyCorrection>, Option<String>) {
        let Some(calibration) = &self.calibration else {
            return (None, None);
        };
        let judged_in = self.judged_in();
        let metric = judged_in.name();
        match calibration.grey_correction(&self.model, &self.report.held_out_patches, judged_in) {
            Some((correction, means)) if means.lowers() => {
                let said = format!(
                    "the calibration's {} measured greys correct the model's transfer laws: held-out mean {metric} {:.3} → {:.3} (± {:.3}) over {} patches",
                    correction.greys(),
                    means.without,
                    means.with,
                    means.standard_error,
                    means.patches
                );
                (Some(correction), Some(said))
            }
            Some((_, means)) => (
                None,
                Some(format!(
                    "the calibration's measured greys are not used: they do not lower the held-out mean {metric} by more than its standard error ({:.3} → {:.3}, ± {:.3}, over {} patches)",
                    means.without, means.with, means.standard_error, means.patches
                )),
            ),
            None => (None, None),
        }
    }
}

impl StoredCalibration {
    /// The greys of the check as (drive, measured XYZ): readings the fit never saw,
    /// for `GreyCorrection`.
    /// A level from a file written before the drive was kept is left out where
    /// chromacal sent the codes: their rounding is not known, and half a code near
    /// black is several per cent of the light.
    pub fn greys(&self) -> Vec<(chromacal_model::Drive, chromacal_color::Xyz)> {
        self.levels
            .iter()
            .filter_map(|l| {
                let [x, y, z] = l.measured_xyz;
                let drive = match (l.drive, self.through_lut) {
                    (Some(d), _) => d,
                    (None, true) => self.curves.apply([l.input; 3]),
                    (None, false) => return None,
                };
                Some((drive, chromacal_color::Xyz::new(x, y, z)))
            })
            .collect()
    }

    /// The calibration's measured greys as a correction of `model`'s transfer laws,
    /// with the held-out means in `metric` that decide whether it is used. None where
    /// there are too few greys or held-out patches.
    pub fn grey_correction(
        &self,
        model: &chromacal_model::MonitorModel,
        held_out: &[chromacal_model::fit::validate::PatchError],
        metric: Metric,
    ) -> Option<(GreyCorrection, HeldOutMeans)> {
        let correction = GreyCorrection::from_greys(model, &self.greys())?;
        let means = correction.held_out_means(model, held_out, metric)?;
        Some((correction, means))
    }
}

/// Calibration curves and how well they did, measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredCalibration {
    pub curves: CalibrationCurves,
    /// Correction passes made before the check.
    pub passes: usize,
    /// The check: every level measured through the final curves.
    pub levels: Vec<LevelCheck>,
    /// ΔE00 of the measured white against the target white.
    pub measured_white_de00: f64,
    /// Largest |Y / Y_target − 1| over the levels above black.
    pub measured_tone_error: f64,
    /// Readings taken, and the instrument time they took, s.
    pub readings: usize,
    pub instrument_s: f64,
    /// The check was measured through the curves loaded in the display's video LUT
    /// (the native window), not through codes the curves were applied to.
    #[serde(default)]
    pub through_lut: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_column_of_offsets() {
        let text = "a = 1\nbb = 2\n";
        assert_eq!(line_column(text, 0), (1, 1));
        assert_eq!(line_column(text, 6), (2, 1));
        assert_eq!(line_column(text, 9), (2, 4));
    }
}
