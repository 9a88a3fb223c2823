//! The measuring loop: for each patch of the plan not yet in the journal, show it,
//! let it settle, measure it, and append the reading to the journal (durably) before
//! the next patch. Killed at any point, a run loses at most the reading under way.

use crate::config::Stability;
use crate::journal::{Journal, JournalError};
use chromacal_display::{DisplayError, PatchDisplay};
use chromacal_formats::time::TimeSource;
use chromacal_instruments::{Instrument, InstrumentError, Reading, ReadingStatus};
use chromacal_model::ScreenPosition;
use chromacal_model::measurement::{Measurement, Role};
use chromacal_model::plan::PlannedPatch;

/// Attempts per patch before a run gives up on an instrument error.
pub const DEFAULT_ATTEMPTS: usize = 3;

/// How the loop measures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOptions {
    /// Attempts per reading before giving up on an instrument error.
    pub attempts: usize,
    pub stability: Option<Stability>,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            attempts: DEFAULT_ATTEMPTS,
            stability: None,
        }
    }
}

/// Called when the patch moves to another place on the screen, before it is measured
/// there: a real instrument has to be moved by hand. An error stops the run.
pub type PositionPrompt<'a> = &'a mut (dyn FnMut(ScreenPosition) -> Result<(), String> + Send);

/// What the caller of a run hears and says while it measures.
pub struct RunHooks<'a> {
    /// Told after each reading is in the journal.
    pub progress: &'a mut (dyn FnMut(&Progress) + Send),
    /// Asked to aim the instrument when the patch moves (see [`PositionPrompt`]).
    pub prompt: Option<PositionPrompt<'a>>,
    /// Asked before each patch whether to stop (a cancelled job, SIGTERM): the
    /// reading under way is finished and journaled first. The fit after the readings
    /// asks it between its steps.
    pub stop: Option<chromacal_model::fit::cancel::StopCheck>,
}

impl<'a> RunHooks<'a> {
    /// Progress only.
    pub fn progress(progress: &'a mut (dyn FnMut(&Progress) + Send)) -> Self {
        RunHooks {
            progress,
            prompt: None,
            stop: None,
        }
    }
}

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
    #[error("patch {index}: {message}")]
    Position { index: usize, message: String },
    #[error("stopped on request after {done} of {total} patches")]
    Stopped { done: usize, total: usize },
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
    pub xyz: Option<chromacal_color::Xyz>,
    pub drive: chromacal_model::Drive,
    pub position: ScreenPosition,
    pub status: ReadingStatus,
}

impl Progress {
    /// A reading of a verification chart: `done` of `total`.
    pub fn verification(done: usize, total: usize) -> Progress {
        Progress {
            done,
            total,
            index: done,
            role: Role::Verification,
            luminance: None,
            xyz: None,
            drive: [0.0; 3],
            position: ScreenPosition::CENTRE,
            status: ReadingStatus::Ok,
        }
    }
}

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// Patches measured by this call.
    pub measured_now: usize,
    /// Patches the journal already had.
    pub already_measured: usize,
    /// Readings taken beyond one per patch by the stability check.
    pub extra_reads: usize,
    /// Patches whose readings never settled within `max_reads`.
    pub unsettled: usize,
    /// Integration seconds those extra readings took.
    pub extra_read_s: f64,
    /// Readings no display could have given ([`Reading::implausible`]), read again.
    pub misreads: usize,
    /// For a sequential plan: patches it added beyond its seed plan (in every call),
    /// and why it stopped adding, in words.
    pub sequential_added: usize,
    pub sequential_stop: Option<String>,
}

/// One reading, retried on instrument errors and on misreads (values no display can
/// emit: [`Reading::implausible`]), each misread counted in `misreads`.
async fn read<I: Instrument>(
    instrument: &mut I,
    attempts: usize,
    index: usize,
    misreads: &mut usize,
) -> Result<Reading, RunError> {
    let mut last_error = None;
    for attempt in 1..=attempts.max(1) {
        match instrument.measure().await {
            Ok(r) => match r.implausible() {
                None => return Ok(r),
                Some(why) => {
                    *misreads += 1;
                    let raw = r
                        .raw
                        .map(|raw| format!(" (it sent: {raw})"))
                        .unwrap_or_default();
                    last_error = Some(InstrumentError::Protocol(format!("a misread: {why}{raw}")));
                }
            },
            Err(e) => last_error = Some(e),
        }
        tracing::warn!(index, attempt, error = ?last_error, "measurement failed");
    }
    Err(RunError::Instrument {
        index,
        attempts: attempts.max(1),
        source: last_error.unwrap_or(InstrumentError::Protocol("no reading".into())),
    })
}

/// What a run has done so far, across patches (and across the seed plan and the
/// sequential patches of a sequential run).
#[derive(Debug, Clone, Copy, Default)]
pub struct Tally {
    pub measured_now: usize,
    pub extra_reads: usize,
    pub unsettled: usize,
    pub extra_read_s: f64,
    /// Readings no display could have given, read again.
    pub misreads: usize,
    /// Where the instrument was last aimed (asked again only when the patch moves).
    aimed_at: Option<ScreenPosition>,
}

impl Tally {
    pub fn summary(&self, already_measured: usize) -> RunSummary {
        RunSummary {
            measured_now: self.measured_now,
            already_measured,
            extra_reads: self.extra_reads,
            unsettled: self.unsettled,
            extra_read_s: self.extra_read_s,
            misreads: self.misreads,
            sequential_added: 0,
            sequential_stop: None,
        }
    }
}

/// Measure every patch of the journal's plan that it does not have yet.
pub async fn run_plan<D: PatchDisplay, I: Instrument>(
    journal: &mut Journal,
    display: &mut D,
    instrument: &mut I,
    clock: &dyn TimeSource,
    options: &RunOptions,
    hooks: &mut RunHooks<'_>,
) -> Result<RunSummary, RunError> {
    let devices = Devices {
        display,
        instrument,
        clock,
    };
    run_plan_with(journal, devices, options, hooks, &mut Tally::default()).await
}

/// [`run_plan`], counting into `tally` (which a sequential run goes on with); the
/// summary is of everything `tally` holds.
pub async fn run_plan_with<D: PatchDisplay, I: Instrument>(
    journal: &mut Journal,
    devices: Devices<'_, D, I>,
    options: &RunOptions,
    hooks: &mut RunHooks<'_>,
    tally: &mut Tally,
) -> Result<RunSummary, RunError> {
    let mut devices = devices;
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
    for planned in todo {
        let devices = devices.reborrow();
        measure_patch(&planned, total, journal, devices, options, hooks, tally).await?;
    }
    devices.display.blank().await?;
    Ok(tally.summary(already_measured))
}

/// The display, instrument and clock a patch is measured with.
pub struct Devices<'d, D, I> {
    pub display: &'d mut D,
    pub instrument: &'d mut I,
    pub clock: &'d dyn TimeSource,
}

impl<D, I> Devices<'_, D, I> {
    /// The same devices, lent for one call.
    pub fn reborrow(&mut self) -> Devices<'_, D, I> {
        Devices {
            display: &mut *self.display,
            instrument: &mut *self.instrument,
            clock: self.clock,
        }
    }
}

/// Show `planned`, let it settle, read it (again until two readings agree, with a
/// stability check) and append the reading to the journal before returning. `total`
/// is what progress reports count to. On an error the screen is blanked.
pub async fn measure_patch<D: PatchDisplay, I: Instrument>(
    planned: &PlannedPatch,
    total: usize,
    journal: &mut Journal,
    devices: Devices<'_, D, I>,
    options: &RunOptions,
    hooks: &mut RunHooks<'_>,
    tally: &mut Tally,
) -> Result<(), RunError> {
    let Devices {
        display,
        instrument,
        clock,
    } = devices;
    if hooks.stop.as_ref().is_some_and(|stop| stop()) {
        let _ = display.blank().await;
        return Err(RunError::Stopped {
            done: journal.entries().len(),
            total,
        });
    }
    let position = planned.patch.geometry.centre();
    if let Err(e) = display.show(&planned.patch).await {
        let _ = display.blank().await;
        return Err(e.into());
    }
    // With the patch already where it will be read, so that it can be aimed at.
    if let Some(prompt) = hooks.prompt.as_mut()
        && tally.aimed_at != Some(position)
    {
        if let Err(message) = prompt(position) {
            let _ = display.blank().await;
            return Err(RunError::Position {
                index: planned.index,
                message,
            });
        }
        tally.aimed_at = Some(position);
    }
    let mut reading = match read(
        instrument,
        options.attempts,
        planned.index,
        &mut tally.misreads,
    )
    .await
    {
        Ok(r) => r,
        Err(e) => {
            let _ = display.blank().await;
            return Err(e);
        }
    };
    if let Some(stability) = options.stability {
        let (mut reads, mut agreed, mut earlier) = (1, false, None);
        while reads < stability.max_reads.max(2) {
            let next = match read(
                instrument,
                options.attempts,
                planned.index,
                &mut tally.misreads,
            )
            .await
            {
                Ok(r) => r,
                Err(e) => {
                    let _ = display.blank().await;
                    return Err(e);
                }
            };
            reads += 1;
            tally.extra_read_s += reading.integration_s;
            agreed = stability.settled(earlier.as_ref(), &reading, &next);
            earlier = Some(std::mem::replace(&mut reading, next));
            if agreed {
                break;
            }
        }
        tally.extra_reads += reads - 1;
        if !agreed {
            tally.unsettled += 1;
            tracing::warn!(
                index = planned.index,
                reads,
                "readings never settled; kept the last"
            );
        }
    }
    let time_s = clock.now() - reading.integration_s / 2.0;
    let progress = Progress {
        done: journal.entries().len() + 1,
        total,
        index: planned.index,
        role: planned.role,
        luminance: reading.luminance(),
        xyz: reading.xyz,
        drive: planned.patch.codes.drive(),
        position: planned.position(),
        status: reading.status,
    };
    journal.append(Measurement {
        index: planned.index,
        role: planned.role,
        drive: planned.patch.codes.drive(),
        codes: Some(planned.patch.codes),
        position: planned.position(),
        background: planned.patch.background.drive(),
        window: (planned.role == Role::Window).then(|| planned.patch.geometry.area()),
        time_s: Some(time_s),
        reading,
    })?;
    tally.measured_now += 1;
    tracing::debug!(index = planned.index, role = ?planned.role, "measured");
    (hooks.progress)(&progress);
    Ok(())
}
