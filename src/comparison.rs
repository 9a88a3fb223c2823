//! chromacal against ArgyllCMS's matrix/shaper profile on real measurement sets, on one
//! split (`fit::validate::ramps_and_greys_split`: black, greys and single-channel ramps
//! train, every mixture is held out) and with one score: ΔE00 of each held-out patch
//! against the measured white of the training set, for both tools' predictions.

use std::path::Path;
use std::time::Instant;

use crate::argyll::{ArgyllError, matrix_shaper_predictions};
use crate::color::Xyz;
use crate::fit::stats::ErrorStats;
use crate::fit::validate::{delta_e00_xyz, ramps_and_greys_split};
use crate::fit::{FitError, FitOptions, FittedModel, fit_monitor};
use crate::measurement::MeasurementSet;

/// Most readings the training side of the split may have.
pub const MAX_TRAIN: usize = 60;

/// Both tools on one display.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub train: usize,
    pub test: usize,
    pub chromacal: ErrorStats,
    /// `None` with the reason when ArgyllCMS could not be run.
    pub argyll: Result<ErrorStats, String>,
    pub fit_seconds: f64,
    pub fitted: FittedModel,
}

impl Comparison {
    /// chromacal's held-out mean over ArgyllCMS's (below 1: chromacal is better).
    pub fn ratio(&self) -> Option<f64> {
        self.argyll
            .as_ref()
            .ok()
            .map(|a| self.chromacal.mean / a.mean)
    }
}

/// Why a comparison could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ComparisonError {
    #[error("the split left no {0}")]
    Empty(&'static str),
    #[error("chromacal's fit: {0}")]
    Fit(#[from] FitError),
}

/// Split `set`, fit chromacal with `options` and ArgyllCMS (in `work`) on the training
/// side, and score both on the held-out side.
pub fn compare_with_argyll(
    set: &MeasurementSet,
    options: &FitOptions,
    work: &Path,
) -> Result<Comparison, ComparisonError> {
    let (train, test) = ramps_and_greys_split(set, MAX_TRAIN);
    compare_on_split(&train, &test, options, work)
}

/// A set measured as two (the Psychtoolbox OLED's calibration and, in another session,
/// its linearity check): the split's training side of `train`, its held-out side of
/// `test`.
pub fn compare_with_argyll_across(
    train: &MeasurementSet,
    test: &MeasurementSet,
    options: &FitOptions,
    work: &Path,
) -> Result<Comparison, ComparisonError> {
    let (train, _) = ramps_and_greys_split(train, MAX_TRAIN);
    let (_, test) = ramps_and_greys_split(test, MAX_TRAIN);
    compare_on_split(&train, &test, options, work)
}

/// Fit both tools on `train` and score them on the usable readings of `test`.
fn compare_on_split(
    train: &MeasurementSet,
    test: &MeasurementSet,
    options: &FitOptions,
    work: &Path,
) -> Result<Comparison, ComparisonError> {
    let held: Vec<_> = test
        .measurements
        .iter()
        .filter_map(|m| Some((m.drive, m.usable_xyz()?)))
        .collect();
    if held.is_empty() {
        return Err(ComparisonError::Empty("mixture to hold out"));
    }
    let started = Instant::now();
    let fitted = fit_monitor(train, options)?;
    let fit_seconds = started.elapsed().as_secs_f64();
    let white = train.mean_white().unwrap_or_else(|| fitted.model.white());
    let score = |predicted: &[Xyz]| {
        let errors: Vec<f64> = held
            .iter()
            .zip(predicted)
            .map(|((_, measured), p)| delta_e00_xyz(measured, p, &white))
            .collect();
        ErrorStats::of(&errors)
    };
    let ours: Vec<Xyz> = held
        .iter()
        .map(|(drive, _)| fitted.model.forward_centre(*drive))
        .collect();
    let chromacal = score(&ours).ok_or(ComparisonError::Empty("prediction"))?;
    let drives: Vec<_> = held.iter().map(|h| h.0).collect();
    let argyll = matrix_shaper_predictions(train, &drives, work)
        .map_err(|e: ArgyllError| e.to_string())
        .and_then(|p| score(&p).ok_or_else(|| "no prediction".to_string()));
    Ok(Comparison {
        train: train.measurements.len(),
        test: held.len(),
        chromacal,
        argyll,
        fit_seconds,
        fitted,
    })
}
