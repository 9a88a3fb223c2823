//! Reading a measurement file: a run journal (JSON Lines, `journal`) or an ArgyllCMS
//! `.ti3` (CGATS, `cgats`), told apart by their first line. This sits above both
//! formats so that `measurement` holds only the data they are read into.

use std::path::Path;

use crate::journal::{Journal, JournalError, to_measurement_set};
use chromacal_formats::cgats::{CgatsError, ti3_from_text};
use chromacal_model::measurement::MeasurementSet;
use chromacal_model::plan::Signal;

/// Why a measurement file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadMeasurementsError {
    #[error("{path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error(transparent)]
    Journal(#[from] JournalError),
    #[error(transparent)]
    Cgats(#[from] CgatsError),
}

/// Read measurements from a run journal (JSON Lines) or an ArgyllCMS `.ti3` file,
/// told apart by their first line.
pub fn read_measurements(path: &Path) -> Result<MeasurementSet, ReadMeasurementsError> {
    read_measurements_and_signal(path).map(|(set, _)| set)
}

/// The same, with the signal the display was sent when the file says (a journal's
/// plan does, none there meaning SDR; a `.ti3` does not): a fit of HDR readings needs
/// it to know the HLG OOTF couples the channels and which HDR law to try.
pub fn read_measurements_and_signal(
    path: &Path,
) -> Result<(MeasurementSet, Option<Signal>), ReadMeasurementsError> {
    let bytes =
        chromacal_formats::durable::read_limited(path, chromacal_formats::durable::limits::TABLE)
            .map_err(|source| ReadMeasurementsError::Io {
            path: path.display().to_string(),
            source,
        })?;
    let text = String::from_utf8_lossy(&bytes);
    if text.trim_start().starts_with('{') {
        let (header, entries, recovery) = Journal::read(path)?;
        if let Some((line, _)) = recovery.dropped_tail {
            tracing::warn!(line, "the journal's last line was cut short and is ignored");
        }
        let signal = Some(header.plan.signal.unwrap_or_default());
        Ok((to_measurement_set(path, &header, entries), signal))
    } else {
        Ok((ti3_from_text(&text, &path.display().to_string())?, None))
    }
}
