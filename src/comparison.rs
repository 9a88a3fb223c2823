//! chromacal against ArgyllCMS's matrix/shaper profile on real measurement sets, on one
//! split (`fit::validate::ramps_and_greys_split`: black, greys and single-channel ramps
//! train, at most `MAX_TRAIN`; every mixture is held out) and by one judge: ArgyllCMS's
//! `profcheck -k` on each tool's ICC profile (chromacal's as it exports it, v2), the
//! held-out readings written against the training set's measured white.
//!
//! `colprof`'s optimiser lands in different optima when its input is renormalised by a
//! hair: multiplying its training XYZ by 1 + k·10⁻⁴ moved its held-out mean on the
//! Dell U2713HM between 0.22 and 0.60. One run of it is a sample, not a baseline, so it
//! is run on the rows as measured and rescaled by s = 1 + k·10⁻⁴, k = −8…8
//! (`RESCALINGS`), and chromacal is compared with the median and the best of them.
//!
//! Beside the judge, chromacal's own score of its model (ΔE00 with L*a*b* against the
//! training white, as `check` and `fit` report) and the model scored in the judge's
//! frame (XYZ over the white's Y, L*a*b* against D50): the second must equal the judge
//! on the exported profile, or the export lost what the model won.

use std::path::Path;
use std::time::Instant;

use crate::argyll::{matrix_shaper_profile, profcheck_delta_e00};
use chromacal_color::Xyz;
use chromacal_formats::cgats::to_ti3_against;
use chromacal_formats::icc::{IccText, IccVersion, encode};
use chromacal_formats::icc_lut::D50;
use chromacal_formats::matrix_trc::MatrixTrc;
use chromacal_model::Drive;
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::{delta_e00_xyz, ramps_and_greys_split};
use chromacal_model::fit::{FitError, FitOptions, FittedModel, fit_monitor};
use chromacal_model::measurement::MeasurementSet;

/// Most readings the training side of the split may have.
pub const MAX_TRAIN: usize = 60;

/// The k of colprof's rescaled inputs, s = 1 + k·`RESCALING_STEP`; k = 0 is the rows as
/// measured.
pub const RESCALINGS: std::ops::RangeInclusive<i32> = -8..=8;
pub const RESCALING_STEP: f64 = 1e-4;

/// Both tools on one display.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub train: usize,
    pub test: usize,
    /// chromacal's own score of its model: L*a*b* against the training set's white.
    pub chromacal: ErrorStats,
    /// The model in the judge's frame (XYZ over the white's Y, L*a*b* against D50).
    pub model_judged: ErrorStats,
    /// The judge on chromacal's exported ICC v2.
    pub chromacal_icc: Result<ErrorStats, String>,
    /// The judge on colprof's profile of each rescaled training set: (k, its errors),
    /// or why ArgyllCMS could not be run.
    pub argyll: Result<Vec<(i32, ErrorStats)>, String>,
    pub fit_seconds: f64,
    pub fitted: FittedModel,
}

/// The least, the median and the largest of colprof's held-out means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

impl Comparison {
    /// colprof's held-out means over its rescaled runs.
    pub fn argyll_spread(&self) -> Option<Spread> {
        let runs = self.argyll.as_ref().ok()?;
        let mut means: Vec<f64> = runs.iter().map(|(_, s)| s.mean).collect();
        if means.is_empty() {
            return None;
        }
        means.sort_by(|a, b| a.total_cmp(b));
        Some(Spread {
            min: means[0],
            median: chromacal_model::fit::stats::percentile(&means, 50.0),
            max: means[means.len() - 1],
        })
    }

    /// chromacal's exported profile over colprof's median run, both judged by
    /// profcheck (below 1: chromacal is better).
    pub fn ratio(&self) -> Option<f64> {
        let ours = self.chromacal_icc.as_ref().ok()?.mean;
        Some(ours / self.argyll_spread()?.median)
    }

    /// The same over colprof's best run.
    pub fn ratio_to_best(&self) -> Option<f64> {
        let ours = self.chromacal_icc.as_ref().ok()?.mean;
        Some(ours / self.argyll_spread()?.min)
    }
}

/// Why a comparison could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ComparisonError {
    #[error("the split left no {0}")]
    Empty(&'static str),
    #[error("the training side has no white reading to normalise to")]
    NoWhite,
    #[error("chromacal's fit: {0}")]
    Fit(#[from] FitError),
}

/// Split `set`, fit chromacal with `options` and ArgyllCMS (in `work`, once for each k
/// of `rescalings`: `RESCALINGS` for the bench) on the training side, and judge both on
/// the held-out side.
pub fn compare_with_argyll(
    set: &MeasurementSet,
    options: &FitOptions,
    rescalings: &[i32],
    work: &Path,
) -> Result<Comparison, ComparisonError> {
    let (train, test) = ramps_and_greys_split(set, MAX_TRAIN);
    compare_on_split(&train, &test, options, rescalings, work)
}

/// A set measured as two (the Psychtoolbox OLED's calibration and, in another session,
/// its linearity check): the split's training side of `train`, its held-out side of
/// `test`.
pub fn compare_with_argyll_across(
    train: &MeasurementSet,
    test: &MeasurementSet,
    options: &FitOptions,
    rescalings: &[i32],
    work: &Path,
) -> Result<Comparison, ComparisonError> {
    let (train, _) = ramps_and_greys_split(train, MAX_TRAIN);
    let (_, test) = ramps_and_greys_split(test, MAX_TRAIN);
    compare_on_split(&train, &test, options, rescalings, work)
}

/// ΔE00 in the judge's frame: both XYZ over the white's Y, L*a*b* against D50 (what
/// `profcheck` does with a `.ti3` normalised to white Y = 100 and an absolute
/// colorimetric lookup).
pub fn judged_delta_e00(measured: &Xyz, predicted: &Xyz, white_y: f64) -> f64 {
    let d50 = Xyz::new(D50[0], D50[1], D50[2]);
    delta_e00_xyz(&(measured / white_y), &(predicted / white_y), &d50)
}

/// Fit both tools on `train` and score them on the usable readings of `test`; colprof
/// once for each k of `rescalings` (none: chromacal alone is judged).
fn compare_on_split(
    train: &MeasurementSet,
    test: &MeasurementSet,
    options: &FitOptions,
    rescalings: &[i32],
    work: &Path,
) -> Result<Comparison, ComparisonError> {
    let held: Vec<(Drive, Xyz)> = test
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition())
        .filter_map(|m| Some((m.drive, m.usable_xyz()?)))
        .collect();
    if held.is_empty() {
        return Err(ComparisonError::Empty("mixture to hold out"));
    }
    let white = train.mean_white().ok_or(ComparisonError::NoWhite)?;
    let started = Instant::now();
    let fitted = fit_monitor(train, options)?;
    let fit_seconds = started.elapsed().as_secs_f64();
    let ours: Vec<Xyz> = held
        .iter()
        .map(|(drive, _)| fitted.model.forward_centre(*drive))
        .collect();
    let score = |judge: &dyn Fn(&Xyz, &Xyz) -> f64| {
        let errors: Vec<f64> = held
            .iter()
            .zip(&ours)
            .map(|((_, measured), p)| judge(measured, p))
            .collect();
        ErrorStats::of(&errors).ok_or(ComparisonError::Empty("prediction"))
    };
    let chromacal = score(&|m, p| delta_e00_xyz(m, p, &white))?;
    let model_judged = score(&|m, p| judged_delta_e00(m, p, white.y))?;

    let judged = |icc: &Path| -> Result<ErrorStats, String> {
        let errors = profcheck_delta_e00(&work.join("test.ti3"), icc).map_err(|e| e.to_string())?;
        if errors.len() != held.len() {
            return Err(format!(
                "profcheck judged {} patches of {}",
                errors.len(),
                held.len()
            ));
        }
        ErrorStats::of(&errors).ok_or_else(|| "profcheck judged no patch".to_string())
    };
    let written = write_judged_files(&fitted, train, test, &white, work);
    let chromacal_icc = written
        .clone()
        .and_then(|_| judged(&work.join("chromacal.icc")));
    let argyll = written.and_then(|_| {
        rescalings
            .iter()
            .map(|&k| {
                let s = 1.0 + k as f64 * RESCALING_STEP;
                let icc = matrix_shaper_profile(
                    &to_ti3_against(train, Some(white), s),
                    work,
                    &format!("colprof{k}"),
                )
                .map_err(|e| e.to_string())?;
                Ok((k, judged(&icc)?))
            })
            .collect::<Result<Vec<_>, String>>()
    });
    Ok(Comparison {
        train: train.measurements.len(),
        test: held.len(),
        chromacal,
        model_judged,
        chromacal_icc,
        argyll,
        fit_seconds,
        fitted,
    })
}

/// In `work`: the held-out readings as `test.ti3` (against the training white) and
/// chromacal's profile of the training set as `chromacal.icc` (ICC v2, as `export`
/// writes it).
fn write_judged_files(
    fitted: &FittedModel,
    train: &MeasurementSet,
    test: &MeasurementSet,
    white: &Xyz,
    work: &Path,
) -> Result<(), String> {
    let write = |name: &str, bytes: &[u8]| {
        let path = work.join(name);
        std::fs::write(&path, bytes).map_err(|e| format!("{}: {e}", path.display()))
    };
    std::fs::create_dir_all(work).map_err(|e| format!("{}: {e}", work.display()))?;
    write(
        "test.ti3",
        to_ti3_against(test, Some(*white), 1.0).as_bytes(),
    )?;
    let text = IccText {
        description: format!("chromacal: {}", train.source),
        details: "fitted for a comparison with ArgyllCMS".into(),
        copyright: "No copyright.".into(),
        created: [2026, 1, 1, 0, 0, 0],
    };
    let measured = fitted.report.white_anchor.as_ref().map(|w| w.measured);
    let profile = MatrixTrc::relative_to(&fitted.model, None, measured);
    write("chromacal.icc", &encode(&profile, &text, IccVersion::V2))
}
