//! Showing the chart and reading it: each patch once, and again where a verdict is
//! still undecided (`verify --until-decided`).

use chromacal_color::Xyz;
use chromacal_display::PatchDisplay;
use chromacal_instruments::{Instrument, ReadingStatus};
use chromacal_model::screen::{Codes, Geometry, Patch};

use chromacal_display::DisplayError;
use chromacal_instruments::InstrumentError;

use super::PlannedPatch;

/// Why a chart could not be read.
#[derive(Debug, thiserror::Error)]
pub enum MeasureError {
    #[error(transparent)]
    Display(#[from] DisplayError),
    #[error("the instrument was not aimed: {0}")]
    Position(String),
    #[error("patch {index} ('{label}'): {source}")]
    Instrument {
        index: usize,
        label: String,
        source: InstrumentError,
    },
}

/// How the patches are shown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasureOptions {
    /// The patch's side, a fraction of the screen.
    pub patch_size: f64,
}

impl Default for MeasureOptions {
    fn default() -> Self {
        MeasureOptions { patch_size: 0.2 }
    }
}

/// Every reading of every patch, in the chart's order, with the instrument time.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Readings {
    pub xyz: Vec<Vec<Xyz>>,
    pub instrument_s: f64,
}

impl Readings {
    /// The mean of a patch's readings.
    pub fn mean(&self, index: usize) -> Option<Xyz> {
        let reads = self.xyz.get(index)?;
        (!reads.is_empty()).then(|| reads.iter().sum::<Xyz>() / reads.len() as f64)
    }

    pub fn count(&self) -> usize {
        self.xyz.iter().map(Vec::len).sum()
    }
}

/// Show `patch` and read it once.
async fn read<D: PatchDisplay, I: Instrument>(
    patch: &PlannedPatch,
    index: usize,
    options: &MeasureOptions,
    display: &mut D,
    instrument: &mut I,
) -> Result<(Xyz, f64), MeasureError> {
    let shown = Patch {
        codes: patch.codes,
        background: Codes::from_drive([0.0; 3], patch.codes.bit_depth),
        geometry: Geometry::centred(options.patch_size),
    };
    display.show(&shown).await?;
    read_shown(patch, index, instrument).await
}

/// Misreads (values no display can emit) read again before verify gives up.
const MISREAD_ATTEMPTS: usize = 3;

/// Read the patch on the screen, `patch` of the chart: again on a misread
/// ([`chromacal_instruments::Reading::implausible`]), up to [`MISREAD_ATTEMPTS`] times.
async fn read_shown<I: Instrument>(
    patch: &PlannedPatch,
    index: usize,
    instrument: &mut I,
) -> Result<(Xyz, f64), MeasureError> {
    let failed = |source| MeasureError::Instrument {
        index,
        label: patch.patch.label.clone(),
        source,
    };
    let mut attempt = 1;
    let reading = loop {
        let reading = instrument.measure().await.map_err(failed)?;
        match reading.implausible() {
            None => break reading,
            Some(why) if attempt >= MISREAD_ATTEMPTS => {
                return Err(failed(InstrumentError::Protocol(format!(
                    "{attempt} misreads, the last: {why}"
                ))));
            }
            Some(why) => tracing::warn!(index, attempt, %why, "a misread; reading again"),
        }
        attempt += 1;
    };
    // Light above the instrument's range has no value; below it, the value it
    // indicated is kept (the black of a good display is there).
    match (reading.status, reading.xyz) {
        (ReadingStatus::Overload, _) | (_, None) => {
            Err(failed(InstrumentError::Protocol(format!(
                "no XYZ ({:?}): verify needs a colorimeter or spectroradiometer within its range",
                reading.status
            ))))
        }
        (_, Some(xyz)) => Ok((xyz, reading.integration_s)),
    }
}

/// Read every planned patch once, calling `progress(done, total)` after each.
pub async fn measure_chart<D: PatchDisplay, I: Instrument>(
    planned: &[PlannedPatch],
    options: &MeasureOptions,
    display: &mut D,
    instrument: &mut I,
    progress: &mut (dyn FnMut(usize, usize) + Send),
) -> Result<Readings, MeasureError> {
    let mut readings = Readings {
        xyz: vec![Vec::new(); planned.len()],
        instrument_s: 0.0,
    };
    for (index, patch) in planned.iter().enumerate() {
        let (xyz, seconds) = read(patch, index, options, display, instrument).await?;
        readings.xyz[index].push(xyz);
        readings.instrument_s += seconds;
        progress(index + 1, planned.len());
    }
    let _ = display.blank().await;
    Ok(readings)
}

/// Read the patches at `indices` once more each, into `readings`.
pub async fn read_again<D: PatchDisplay, I: Instrument>(
    planned: &[PlannedPatch],
    indices: &[usize],
    readings: &mut Readings,
    options: &MeasureOptions,
    display: &mut D,
    instrument: &mut I,
) -> Result<(), MeasureError> {
    for &index in indices {
        let (xyz, seconds) = read(&planned[index], index, options, display, instrument).await?;
        readings.xyz[index].push(xyz);
        readings.instrument_s += seconds;
    }
    let _ = display.blank().await;
    Ok(())
}

/// Asked to aim the instrument at a position before it is read there.
pub type AimPrompt<'a> =
    &'a mut (dyn FnMut(chromacal_model::ScreenPosition) -> Result<(), String> + Send);

/// Read `levels` at every position of a `grid` × `grid` grid, in rows from the top
/// left: `readings[position][level]`. With `aim`, the instrument is asked to be moved
/// to each position once its first patch is shown there.
pub async fn measure_grid<D: PatchDisplay, I: Instrument>(
    levels: &[PlannedPatch],
    grid: usize,
    display: &mut D,
    instrument: &mut I,
    mut aim: Option<AimPrompt<'_>>,
    progress: &mut (dyn FnMut(usize, usize) + Send),
) -> Result<(Vec<Vec<Xyz>>, f64), MeasureError> {
    let size = (1.0 / grid as f64).min(MeasureOptions::default().patch_size);
    let total = grid * grid * levels.len();
    let (mut readings, mut seconds) = (Vec::new(), 0.0);
    for row in 0..grid {
        for column in 0..grid {
            let centre = chromacal_model::ScreenPosition::new(
                (column as f64 + 0.5) / grid as f64,
                (row as f64 + 0.5) / grid as f64,
            );
            let mut here = Vec::new();
            for (k, level) in levels.iter().enumerate() {
                let index = readings.len() * levels.len() + k;
                let shown = Patch {
                    codes: level.codes,
                    background: Codes::from_drive([0.0; 3], level.codes.bit_depth),
                    geometry: Geometry::around(centre, size),
                };
                display.show(&shown).await?;
                if k == 0
                    && let Some(aim) = aim.as_mut()
                    && let Err(message) = aim(centre)
                {
                    let _ = display.blank().await;
                    return Err(MeasureError::Position(message));
                }
                let (xyz, s) = read_shown(level, index, instrument).await?;
                here.push(xyz);
                seconds += s;
                progress(index + 1, total);
            }
            readings.push(here);
        }
    }
    let _ = display.blank().await;
    Ok((readings, seconds))
}
