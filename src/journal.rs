//! The run journal: every reading, appended and flushed to disk before the next patch
//! is shown, so a run that is killed loses nothing it measured and resumes where it
//! stopped.
//!
//! Format: JSON Lines. The first line is the [`JournalHeader`] (plan, config, devices);
//! each further line is one [`Measurement`]. A line cut short by a crash can only be
//! the last one; reading the journal drops it (and says so), anything else malformed
//! is an error that names the line.

use std::collections::BTreeSet;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use chromacal_formats::durable::sync_directory;
use chromacal_instruments::InstrumentInfo;
use chromacal_model::measurement::{Measurement, MeasurementSet, Units};
use chromacal_model::plan::Plan;

/// Written in the header so other files are not mistaken for journals.
pub const JOURNAL_FORMAT: &str = "chromacal-journal";
pub const JOURNAL_VERSION: u32 = 1;

/// Why a journal could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} already exists; resume it or choose another run")]
    Exists { path: PathBuf },
    #[error("{path} is being written by another process; one writer per journal")]
    Busy { path: PathBuf },
    #[error("{path}, line 1: not a chromacal journal header: {message}")]
    Header { path: PathBuf, message: String },
    #[error("{path}, line {line}: {message}")]
    BadLine {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}, line {line}: patch {index} was already recorded on line {first_line}")]
    Duplicate {
        path: PathBuf,
        line: usize,
        index: usize,
        first_line: usize,
    },
    #[error("{path}, line {line}: patch {index} is not in the journal's plan")]
    NotInPlan {
        path: PathBuf,
        line: usize,
        index: usize,
    },
    #[error(
        "cannot record a reading with a value that is not finite, or that would not read back as written (patch {index})"
    )]
    NotFinite { index: usize },
}

/// The first line of a journal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JournalHeader {
    pub format: String,
    pub version: u32,
    pub run_id: String,
    /// RFC 3339 time the run started.
    pub started: String,
    /// SHA-256 of the config text.
    pub config_digest: String,
    /// The config the run was started with, as TOML.
    pub config: String,
    /// Directory the config's relative paths are taken from.
    pub config_dir: PathBuf,
    pub display: String,
    pub instrument: InstrumentInfo,
    pub units: Units,
    pub plan: Plan,
}

/// What reading a journal had to repair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recovery {
    /// A torn last line (1-based number) that was dropped, with its length in bytes.
    pub dropped_tail: Option<(usize, usize)>,
}

/// An open journal, ready to append.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
    header: JournalHeader,
    entries: Vec<Measurement>,
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> JournalError + '_ {
    move |source| JournalError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Take the journal's own lock (`flock`, held while the file is open), so a second
/// writer is refused instead of interleaving its lines. Lines are appended with
/// `O_APPEND` as well, so even a writer that ignores the lock cannot overwrite them.
fn lock_journal(file: &File, path: &Path) -> Result<(), JournalError> {
    match file.try_lock() {
        Ok(()) => Ok(()),
        Err(std::fs::TryLockError::WouldBlock) => Err(JournalError::Busy {
            path: path.to_path_buf(),
        }),
        Err(std::fs::TryLockError::Error(e)) => Err(io_error(path)(e)),
    }
}

impl Journal {
    /// Start a new journal at `path` (which must not exist) with `header`.
    pub fn create(path: &Path, header: JournalHeader) -> Result<Self, JournalError> {
        if let Some(dir) = path.parent() {
            chromacal_formats::durable::create_dir(dir).map_err(io_error(dir))?;
        }
        let mut file = chromacal_formats::durable::open_options(path)
            .append(true)
            .create_new(true)
            .open(path)
            .map_err(|e| {
                if e.kind() == std::io::ErrorKind::AlreadyExists {
                    JournalError::Exists {
                        path: path.to_path_buf(),
                    }
                } else {
                    io_error(path)(e)
                }
            })?;
        lock_journal(&file, path)?;
        let line = serde_json::to_string(&header).map_err(|e| JournalError::Header {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        // One write, as `append` makes: a reader never finds the header without its
        // line's end.
        file.write_all(format!("{line}\n").as_bytes())
            .map_err(io_error(path))?;
        file.sync_all().map_err(io_error(path))?;
        if let Some(dir) = path.parent() {
            sync_directory(dir);
        }
        Ok(Journal {
            path: path.to_path_buf(),
            file,
            header,
            entries: Vec::new(),
        })
    }

    /// Open an existing journal to append to it, dropping a torn last line.
    pub fn open(path: &Path) -> Result<(Self, Recovery), JournalError> {
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .open(path)
            .map_err(io_error(path))?;
        lock_journal(&file, path)?;
        let text = chromacal_formats::durable::read_text_limited_from(
            &mut file,
            chromacal_formats::durable::limits::JOURNAL,
        )
        .map_err(io_error(path))?;
        let (header, entries, recovery, good_len) = parse(&text, path)?;
        if recovery.dropped_tail.is_some() {
            file.set_len(good_len as u64).map_err(io_error(path))?;
            file.sync_all().map_err(io_error(path))?;
        }
        file.seek(SeekFrom::End(0)).map_err(io_error(path))?;
        Ok((
            Journal {
                path: path.to_path_buf(),
                file,
                header,
                entries,
            },
            recovery,
        ))
    }

    /// Read a journal without changing it.
    pub fn read(path: &Path) -> Result<(JournalHeader, Vec<Measurement>, Recovery), JournalError> {
        let text = chromacal_formats::durable::read_text_limited(
            path,
            chromacal_formats::durable::limits::JOURNAL,
        )
        .map_err(io_error(path))?;
        let (header, entries, recovery, _) = parse(&text, path)?;
        Ok((header, entries, recovery))
    }

    /// Append one measurement and make it durable before returning.
    pub fn append(&mut self, measurement: Measurement) -> Result<(), JournalError> {
        if let Some(xyz) = measurement.reading.xyz
            && xyz.iter().any(|v| !v.is_finite())
        {
            return Err(JournalError::NotFinite {
                index: measurement.index,
            });
        }
        let line = serde_json::to_string(&measurement).map_err(|e| JournalError::BadLine {
            path: self.path.clone(),
            line: self.entries.len() + 2,
            message: e.to_string(),
        })?;
        // Any other number that is not finite (a time, an integration, a spectrum
        // value) is written by serde_json as null, and would read back as something
        // else or not at all: the line must read back as what it records.
        if serde_json::from_str::<Measurement>(&line).ok().as_ref() != Some(&measurement) {
            return Err(JournalError::NotFinite {
                index: measurement.index,
            });
        }
        self.file
            .write_all(format!("{line}\n").as_bytes())
            .map_err(io_error(&self.path))?;
        self.file.sync_data().map_err(io_error(&self.path))?;
        self.entries.push(measurement);
        Ok(())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &JournalHeader {
        &self.header
    }

    pub fn entries(&self) -> &[Measurement] {
        &self.entries
    }

    /// Plan indices already measured.
    pub fn measured(&self) -> BTreeSet<usize> {
        self.entries.iter().map(|m| m.index).collect()
    }

    /// True when every patch of the plan has a reading.
    pub fn is_complete(&self) -> bool {
        self.entries.len() == self.header.plan.patches.len()
    }

    /// The journal's readings as a measurement set.
    pub fn measurement_set(&self) -> MeasurementSet {
        to_measurement_set(&self.path, &self.header, self.entries.clone())
    }
}

/// A measurement set from a journal's header and entries.
/// A journal's path as a profile stores it: absolute (not resolving links), so that a
/// report made from another directory finds the readings.
pub fn stored_path(path: &Path) -> String {
    absolute_path(path).display().to_string()
}

/// `path` made absolute against the working directory (not resolving links), for paths
/// that are stored or shown and read again from elsewhere; an empty path (the folder
/// of a file named without one) is the working directory; as given if there is none.
pub fn absolute_path(path: &Path) -> PathBuf {
    let path = if path.as_os_str().is_empty() {
        Path::new(".")
    } else {
        path
    };
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

pub fn to_measurement_set(
    path: &Path,
    header: &JournalHeader,
    entries: Vec<Measurement>,
) -> MeasurementSet {
    MeasurementSet {
        source: path.display().to_string(),
        units: header.units,
        instrument: Some(header.instrument.clone()),
        display: Some(header.display.clone()),
        // The run's start: its readings were taken from then on.
        measured_at: Some(format!("from {}", header.started)),
        measurements: entries,
    }
}

/// How many patches a sequential run may add beyond its seed plan (none for a fixed
/// plan): they are numbered on from the plan's end, and never more than its budget.
fn sequential_room(header: &JournalHeader) -> usize {
    header.plan.sequential.as_ref().map_or(0, |s| s.budget)
}

/// Header, entries, what was repaired, and the byte length of the good part.
fn parse(
    text: &str,
    path: &Path,
) -> Result<(JournalHeader, Vec<Measurement>, Recovery, usize), JournalError> {
    let mut recovery = Recovery::default();
    let mut offset = 0;
    let mut lines = Vec::new();
    for piece in text.split_inclusive('\n') {
        lines.push((offset, piece));
        offset += piece.len();
    }
    let Some((_, first)) = lines.first() else {
        return Err(JournalError::Header {
            path: path.to_path_buf(),
            message: "the file is empty".into(),
        });
    };
    let header: JournalHeader =
        serde_json::from_str(first.trim_end()).map_err(|e| JournalError::Header {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
    if header.format != JOURNAL_FORMAT || header.version != JOURNAL_VERSION {
        return Err(JournalError::Header {
            path: path.to_path_buf(),
            message: format!(
                "format '{}' version {} (this program reads '{JOURNAL_FORMAT}' version {JOURNAL_VERSION})",
                header.format, header.version
            ),
        });
    }
    let mut good_len = first.len();
    let mut entries: Vec<Measurement> = Vec::new();
    let mut first_line_of = std::collections::HashMap::new();
    let last = lines.len() - 1;
    for (number, (start, piece)) in lines.iter().enumerate().skip(1) {
        let line = number + 1;
        let complete = piece.ends_with('\n');
        if piece.trim().is_empty() && complete {
            good_len = start + piece.len();
            continue;
        }
        match serde_json::from_str::<Measurement>(piece.trim_end()) {
            Ok(m) if complete => {
                if m.index >= header.plan.patches.len() + sequential_room(&header) {
                    return Err(JournalError::NotInPlan {
                        path: path.to_path_buf(),
                        line,
                        index: m.index,
                    });
                }
                if let Some(first_line) = first_line_of.insert(m.index, line) {
                    return Err(JournalError::Duplicate {
                        path: path.to_path_buf(),
                        line,
                        index: m.index,
                        first_line,
                    });
                }
                entries.push(m);
                good_len = start + piece.len();
            }
            // A torn write can only be the last line.
            _ if number == last => {
                recovery.dropped_tail = Some((line, piece.len()));
            }
            Ok(_) => {
                return Err(JournalError::BadLine {
                    path: path.to_path_buf(),
                    line,
                    message: "the line has no end".into(),
                });
            }
            Err(e) => {
                return Err(JournalError::BadLine {
                    path: path.to_path_buf(),
                    line,
                    message: e.to_string(),
                });
            }
        }
    }
    Ok((header, entries, recovery, good_len))
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_color::Xyz;
    use chromacal_instruments::{Capability, Reading, ReadingStatus};
    use chromacal_model::measurement::Role;
    use chromacal_model::plan::{PlanConfig, make_plan};

    fn header() -> JournalHeader {
        JournalHeader {
            format: JOURNAL_FORMAT.into(),
            version: JOURNAL_VERSION,
            run_id: "test".into(),
            started: "2026-11-23T12:00:00Z".into(),
            config_digest: "0".into(),
            config: String::new(),
            config_dir: PathBuf::from("."),
            display: "test".into(),
            instrument: InstrumentInfo {
                name: "test".into(),
                serial: None,
                capability: Capability::Tristimulus,
            },
            units: Units::Absolute,
            plan: make_plan(&PlanConfig::default()).unwrap(),
        }
    }

    fn measurement(index: usize, y: f64) -> Measurement {
        Measurement {
            index,
            role: Role::Ramp,
            drive: [0.5, 0.0, 0.0],
            codes: None,
            position: Default::default(),
            background: [0.0; 3],
            window: None,
            time_s: Some(index as f64),
            reading: Reading {
                xyz: Some(Xyz::new(y, y, y)),
                spectrum: None,
                status: ReadingStatus::Ok,
                integration_s: 1.0,
                ..Default::default()
            },
        }
    }

    #[test]
    fn lines_are_appended_at_the_end_even_past_a_writer_that_ignores_the_lock() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("journal.jsonl");
        let mut j = Journal::create(&path, header()).unwrap();
        j.append(measurement(0, 1.0)).unwrap();
        // The lock is advisory: a careless writer can still append a line. With
        // O_APPEND the journal's next line goes after it instead of over it.
        let mut other = OpenOptions::new().append(true).open(&path).unwrap();
        other
            .write_all(
                format!("{}\n", serde_json::to_string(&measurement(1, 2.0)).unwrap()).as_bytes(),
            )
            .unwrap();
        drop(other);
        j.append(measurement(2, 3.0)).unwrap();
        drop(j);
        let (_, entries, recovery) = Journal::read(&path).unwrap();
        assert!(recovery.dropped_tail.is_none());
        let indices: Vec<usize> = entries.iter().map(|m| m.index).collect();
        assert_eq!(indices, [0, 1, 2]);
    }

    #[test]
    fn entries_survive_reopening_and_a_torn_tail_is_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("journal.jsonl");
        let mut j = Journal::create(&path, header()).unwrap();
        j.append(measurement(0, 1.0)).unwrap();
        j.append(measurement(1, 2.0)).unwrap();
        drop(j);
        assert!(matches!(
            Journal::create(&path, header()),
            Err(JournalError::Exists { .. })
        ));

        // A crash in the middle of the third line.
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(br#"{"index":2,"role":"ramp","dri"#).unwrap();
        drop(f);

        let (mut j, recovery) = Journal::open(&path).unwrap();
        assert_eq!(recovery.dropped_tail.map(|t| t.0), Some(4));
        assert_eq!(j.measured().into_iter().collect::<Vec<_>>(), vec![0, 1]);
        j.append(measurement(2, 3.0)).unwrap();
        drop(j);
        let (_, entries, recovery) = Journal::read(&path).unwrap();
        assert_eq!(recovery, Recovery::default());
        assert_eq!(entries.len(), 3);
        assert_eq!(entries[2], measurement(2, 3.0));
    }

    #[test]
    fn corruption_inside_the_journal_is_an_error_naming_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("journal.jsonl");
        let mut j = Journal::create(&path, header()).unwrap();
        j.append(measurement(0, 1.0)).unwrap();
        drop(j);
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str("{not json}\n");
        text.push_str(&serde_json::to_string(&measurement(1, 1.0)).unwrap());
        text.push('\n');
        std::fs::write(&path, &text).unwrap();
        let err = Journal::read(&path).unwrap_err();
        assert!(
            matches!(err, JournalError::BadLine { line: 3, .. }),
            "{err}"
        );

        let mut text = std::fs::read_to_string(&path).unwrap();
        text = text.replace(
            "{not json}\n",
            &(serde_json::to_string(&measurement(0, 1.0)).unwrap() + "\n"),
        );
        std::fs::write(&path, &text).unwrap();
        let err = Journal::read(&path).unwrap_err();
        assert!(
            matches!(err, JournalError::Duplicate { index: 0, .. }),
            "{err}"
        );
    }

    #[test]
    fn a_non_finite_reading_is_refused_before_it_reaches_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("journal.jsonl");
        let mut j = Journal::create(&path, header()).unwrap();
        assert!(matches!(
            j.append(measurement(0, f64::NAN)),
            Err(JournalError::NotFinite { index: 0 })
        ));
        // A time that is not a number would be written as null and read back as none.
        let mut timed = measurement(0, 1.0);
        timed.time_s = Some(f64::NAN);
        assert!(matches!(
            j.append(timed),
            Err(JournalError::NotFinite { index: 0 })
        ));
        let mut integrated = measurement(0, 1.0);
        integrated.reading.integration_s = f64::INFINITY;
        assert!(matches!(
            j.append(integrated),
            Err(JournalError::NotFinite { index: 0 })
        ));
        assert!(j.entries().is_empty());
    }
}
