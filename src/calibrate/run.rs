//! The measuring loop: for each patch of the plan not yet in the journal, show it,
//! let it settle, measure it, and append the reading to the journal (durably) before
//! the next patch. Killed at any point, a run loses at most the reading under way.

use super::journal::{Journal, JournalError};
use crate::display::{DisplayError, PatchDisplay};
use crate::instrument::{Instrument, InstrumentError, ReadingStatus};
use crate::measurement::{Measurement, Role};
use crate::time::TimeSource;

/// Attempts per patch before a run gives up on an instrument error.
pub const DEFAULT_ATTEMPTS: usize = 3;

/// Why a run stopped before its end. The journal keeps everything measured so far.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("display: {0}")]
    Display(#[from] DisplayError),
    #[error("patch {index}: the instrument failed {attempts} times, last: {source}")]
    Instrument {
        index: usize,
        attempts: usize,
        source: InstrumentError,
    },
    #[error("journal: {0}")]
    Journal(#[from] JournalError),
}

/// Where a run is, after each reading.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Readings in the journal now.
    pub done: usize,
    pub total: usize,
    /// The patch just measured.
    pub index: usize,
    pub role: Role,
    pub luminance: Option<f64>,
    pub status: ReadingStatus,
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSummary {
    /// Patches measured by this call.
    pub measured_now: usize,
    /// Patches the journal already had.
    pub already_measured: usize,
}

/// Measure every patch of the journal's plan that it does not have yet.
pub async fn run_plan<D: PatchDisplay, I: Instrument>(
    journal: &mut Journal,
    display: &mut D,
    instrument: &mut I,
    clock: &dyn TimeSource,
    attempts: usize,
    on_progress: &mut dyn FnMut(&Progress),
) -> Result<RunSummary, RunError> {
    let measured = journal.measured();
    let already_measured = measured.len();
    let todo: Vec<_> = journal
        .header()
        .plan
        .patches
        .iter()
        .filter(|p| !measured.contains(&p.index))
        .cloned()
        .collect();
    let total = journal.header().plan.patches.len();
    let mut measured_now = 0;
    for planned in todo {
        if let Err(e) = display.show(&planned.patch).await {
            let _ = display.blank().await;
            return Err(e.into());
        }
        let mut last_error = None;
        let mut reading = None;
        for attempt in 1..=attempts.max(1) {
            match instrument.measure().await {
                Ok(r) if r.xyz.is_none_or(|x| x.iter().all(|v| v.is_finite())) => {
                    reading = Some(r);
                    break;
                }
                Ok(_) => {
                    last_error = Some(InstrumentError::Protocol(
                        "the reading has a value that is not a finite number".into(),
                    ));
                }
                Err(e) => last_error = Some(e),
            }
            tracing::warn!(index = planned.index, attempt, error = ?last_error, "measurement failed");
        }
        let Some(reading) = reading else {
            let _ = display.blank().await;
            return Err(RunError::Instrument {
                index: planned.index,
                attempts: attempts.max(1),
                source: last_error.unwrap_or(InstrumentError::Protocol("no reading".into())),
            });
        };
        let time_s = clock.now() - reading.integration_s / 2.0;
        let progress = Progress {
            done: journal.entries().len() + 1,
            total,
            index: planned.index,
            role: planned.role,
            luminance: reading.xyz.map(|x| x.y),
            status: reading.status,
        };
        journal.append(Measurement {
            index: planned.index,
            role: planned.role,
            drive: planned.patch.codes.drive(),
            codes: Some(planned.patch.codes),
            position: planned.position(),
            background: planned.patch.background.drive(),
            time_s: Some(time_s),
            reading,
        })?;
        measured_now += 1;
        tracing::debug!(index = planned.index, role = ?planned.role, "measured");
        on_progress(&progress);
    }
    display.blank().await?;
    Ok(RunSummary {
        measured_now,
        already_measured,
    })
}
