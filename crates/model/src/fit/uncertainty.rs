//! Where the model is least sure of its prediction, for a sequential plan to measure
//! next. The measurement set's ramp readings and greys are dealt by drive level into a
//! few folds, as for cross-validation (`law_selection`); the model is fitted again
//! without each fold, with the law already chosen; the spread of those models'
//! predictions of a drive about the full model's, in ΔE00 against the white, is its
//! uncertainty (a delete-a-group jackknife: Efron & Tibshirani 1993, ch. 11). It is
//! large between and beyond the levels measured, where the curves are interpolated or
//! extrapolated, and small where readings sit close together.

use super::law_selection::level_folds;
use super::{FitOptions, fit_monitor};
use crate::fit::validate::delta_e00_xyz;
use crate::measurement::{Measurement, MeasurementSet, Role, drive_level};
use crate::transfer::LawKind;
use crate::{Drive, MonitorModel};
use chromacal_color::Xyz;

/// Most folds the set is fitted without: each costs a whole fit.
pub const UNCERTAINTY_FOLDS: usize = 5;

/// The drive level a ramp reading or a grey below full drive is left out with: its
/// lit channel's drive, or the grey's. `None` for every other reading.
fn level_of(m: &Measurement) -> Option<f64> {
    if !matches!(m.role, Role::Ramp | Role::Grey) || !m.is_standard_condition() {
        return None;
    }
    drive_level(m.drive).filter(|level| *level < 1.0)
}

/// Models fitted the same way (the law `law` only, without the additivity terms: the
/// curves are what the next patch is for): one to the whole set, the reference the
/// spread is taken about, and one without each fold of drive levels. `None` when the
/// whole set cannot be fitted so; folds that cannot be are left out.
pub struct FoldModels {
    pub reference: MonitorModel,
    pub folds: Vec<MonitorModel>,
}

/// See [`FoldModels`].
pub fn fold_models(set: &MeasurementSet, options: &FitOptions, law: LawKind) -> Option<FoldModels> {
    let levels = set.measurements.iter().filter_map(level_of).collect();
    let options = FitOptions {
        laws: vec![law],
        additivity_terms: false,
        ..options.clone()
    };
    let reference = fit_monitor(set, &options).ok()?.model;
    let folds = level_folds(levels, UNCERTAINTY_FOLDS)
        .iter()
        .filter_map(|held| {
            let kept = MeasurementSet {
                measurements: set
                    .measurements
                    .iter()
                    .filter(|m| level_of(m).is_none_or(|l| !held.contains(&l)))
                    .cloned()
                    .collect(),
                source: set.source.clone(),
                units: set.units,
                instrument: set.instrument.clone(),
                display: set.display.clone(),
                measured_at: set.measured_at.clone(),
            };
            fit_monitor(&kept, &options).ok().map(|f| f.model)
        })
        .collect();
    Some(FoldModels { reference, folds })
}

/// Root-mean-square ΔE00 between the fold models' predictions of `drive` and the
/// reference's, against `white`; 0 without fold models.
pub fn prediction_spread(models: &FoldModels, drive: Drive, white: &Xyz) -> f64 {
    let folds = &models.folds;
    if folds.is_empty() {
        return 0.0;
    }
    let centre = models.reference.forward_centre(drive);
    let squares: f64 = folds
        .iter()
        .map(|m| delta_e00_xyz(&m.forward_centre(drive), &centre, white).powi(2))
        .sum();
    (squares / folds.len() as f64).sqrt()
}
