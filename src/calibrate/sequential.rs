//! The sequential plan: after the seed plan, each next patch where the model is least
//! sure, until the estimated held-out error meets the target or the budget is spent.
//!
//! Each step fits the model to everything in the journal (`fit::fit_monitor`), takes
//! the chosen law's cross-validated mean ΔE00 as the estimate of its held-out error
//! (the verification patches are never looked at: their error stays honest), and stops
//! when it is at most `plan.target_de00`. Otherwise every candidate patch (each channel
//! alone and the grey at 31 levels, 1/32 apart, not measured yet) is scored by the
//! spread of models fitted without folds of levels (`fit::uncertainty`), and the one
//! that buys the most for the instrument's time is measured and journaled before the
//! next step: the largest squared spread (the variance a reading there removes) per
//! second the reading is expected to take. An auto-ranging instrument integrates dim
//! light up to ten times longer, so a dark patch must be worth ten bright ones; the
//! expected seconds come from the durations of the readings already taken at similar
//! luminance (a cost-weighted sequential design: each step buys the most variance
//! removed per unit cost, the rule of thumb of budgeted experimental design).
//!
//! The choice depends on nothing but the journal, so a resumed run (`--resume`) goes
//! on exactly as the run it resumes would have: the same next patch from the same
//! readings.

use super::run::{
    Devices, RunError, RunHooks, RunOptions, RunSummary, Tally, measure_patch, run_plan_with,
};
use crate::config::Config;
use crate::journal::{Journal, JournalHeader};
use chromacal_color::Xyz;
use chromacal_display::PatchDisplay;
use chromacal_instruments::Instrument;
use chromacal_model::Drive;
use chromacal_model::fit::uncertainty::{FoldModels, fold_models, prediction_spread};
use chromacal_model::fit::{FitError, FittedModel, fit_monitor};
use chromacal_model::measurement::{MeasurementSet, Role};
use chromacal_model::plan::{Plan, PlannedPatch};
use chromacal_model::screen::{Codes, Geometry, Patch};

/// Candidate levels: k / `GRID` for k = 1 … GRID − 1.
const GRID: usize = 32;

/// Why a sequential run stopped adding patches.
#[derive(Debug, Clone, PartialEq)]
pub enum Stop {
    /// The estimated held-out mean ΔE00 met the target.
    TargetMet { estimate: f64 },
    /// The counted patches reached the budget.
    BudgetSpent { estimate: Option<f64> },
    /// Every candidate has been measured.
    NoCandidate { estimate: Option<f64> },
    /// The readings so far could not be fitted; the run goes on to the fit, which says
    /// why.
    Unfitted(FitError),
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let said = |e: &Option<f64>| e.map_or(String::new(), |e| format!(" (estimate {e:.3})"));
        match self {
            Stop::TargetMet { estimate } => {
                write!(f, "estimated held-out ΔE00 {estimate:.3} met the target")
            }
            Stop::BudgetSpent { estimate } => write!(f, "budget spent{}", said(estimate)),
            Stop::NoCandidate { estimate } => {
                write!(f, "every candidate level measured{}", said(estimate))
            }
            Stop::Unfitted(e) => write!(f, "the readings so far could not be fitted: {e}"),
        }
    }
}

/// The next step of a sequential run: a patch to measure, or why to stop.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    Measure {
        patch: PlannedPatch,
        /// Its prediction spread, ΔE00.
        spread: f64,
        estimate: Option<f64>,
    },
    Stop(Stop),
}

/// What a sequential run did beyond its seed plan.
#[derive(Debug, Clone, PartialEq)]
pub struct SequentialSummary {
    /// Patches added beyond the seed plan (in this call and before it).
    pub added: usize,
    /// Counted patches at the end (black, ramps, greys, surround, references).
    pub counted: usize,
    pub stop: Stop,
}

/// Readings of the kinds the budget counts.
pub fn counted(set: &MeasurementSet) -> usize {
    set.measurements
        .iter()
        .filter(|m| {
            matches!(
                m.role,
                Role::Black | Role::Ramp | Role::Grey | Role::Surround | Role::Reference
            )
        })
        .count()
}

/// The estimate of held-out error a sequential run stops on, the larger of two: the
/// chosen law's cross-validated mean ΔE00 over ramps and greys left out by level, and
/// the mean prediction spread (`fit::uncertainty`) at the drives of the plan's
/// verification patches (their drives only: their readings are never looked at). The
/// first alone is optimistic where mixtures sit between the levels measured.
pub fn estimated_error(
    fitted: &FittedModel,
    folds: &FoldModels,
    plan: &Plan,
    white: &Xyz,
) -> Option<f64> {
    let cross_validated = fitted
        .report
        .laws
        .iter()
        .find(|l| l.chosen)
        .and_then(|l| l.cross_validation)
        .map(|s| s.mean)?;
    let drives: Vec<Drive> = plan
        .patches
        .iter()
        .filter(|p| p.role == Role::Verification)
        .map(|p| p.patch.codes.drive())
        .collect();
    let spread = drives
        .iter()
        .map(|d| prediction_spread(folds, *d, white))
        .sum::<f64>()
        / drives.len().max(1) as f64;
    Some(cross_validated.max(spread))
}

/// Each usable reading's luminance (log10 cd/m², in the set's units) and the seconds
/// the instrument integrated it for, sorted by luminance: what the next patch will
/// cost is read off these. Readings without a duration (a `.ti3`) are left out.
fn reading_durations(set: &MeasurementSet) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = set
        .measurements
        .iter()
        .filter_map(|m| {
            let y = m.reading.luminance()?;
            let s = m.reading.integration_s;
            (y > 0.0 && s > 0.0 && s.is_finite()).then(|| (y.log10(), s))
        })
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

/// Seconds of integration a patch of luminance `y` is expected to need: the median of
/// the durations of the (up to) three readings nearest to it in log luminance, since
/// an auto-ranging instrument integrates dim light longer. 1 s when nothing is known
/// (then every candidate costs the same and the choice is by spread alone).
fn expected_seconds(durations: &[(f64, f64)], y: f64) -> f64 {
    if durations.is_empty() {
        return 1.0;
    }
    let at = if y > 0.0 {
        y.log10()
    } else {
        f64::NEG_INFINITY
    };
    let mut nearest: Vec<(f64, f64)> = durations
        .iter()
        .map(|(l, s)| ((l - at).abs(), *s))
        .collect();
    nearest.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut seconds: Vec<f64> = nearest.iter().take(3).map(|(_, s)| *s).collect();
    seconds.sort_by(f64::total_cmp);
    seconds[seconds.len() / 2]
}

/// The candidate drives: each channel alone and the grey at k / GRID, in that order,
/// as codes of `bit_depth`, without those measured already.
fn candidates(set: &MeasurementSet, bit_depth: u32) -> Vec<Codes> {
    let measured: Vec<Codes> = set.measurements.iter().filter_map(|m| m.codes).collect();
    let mut out: Vec<Codes> = Vec::new();
    for which in 0..4 {
        for k in 1..GRID {
            let v = k as f64 / GRID as f64;
            let drive: Drive = match which {
                3 => [v; 3],
                c => {
                    let mut d = [0.0; 3];
                    d[c] = v;
                    d
                }
            };
            let codes = Codes::from_drive(drive, bit_depth);
            if !measured.contains(&codes) && !out.contains(&codes) {
                out.push(codes);
            }
        }
    }
    out
}

/// `set` without its uniformity readings (those away from the centre for the spatial
/// map).
fn without_uniformity(set: &MeasurementSet) -> MeasurementSet {
    MeasurementSet {
        source: set.source.clone(),
        units: set.units,
        instrument: set.instrument.clone(),
        display: set.display.clone(),
        measured_at: set.measured_at.clone(),
        measurements: set
            .measurements
            .iter()
            .filter(|m| m.role != Role::Uniformity)
            .cloned()
            .collect(),
    }
}

/// The next step for the readings in `journal`, under `config`: deterministic in the
/// journal's readings.
pub fn next_step(journal: &Journal, config: &Config) -> Step {
    next_step_for(journal.header(), &journal.measurement_set(), config)
}

/// [`next_step`] for a journal's header and its readings.
fn next_step_for(header: &JournalHeader, set: &MeasurementSet, config: &Config) -> Step {
    let Some(limits) = &header.plan.sequential else {
        return Step::Stop(Stop::BudgetSpent { estimate: None });
    };
    // The choice rests on the centre's model: the uniformity grid's readings only
    // shape the spatial map, which a fit of a large grid spends seconds on at every
    // step (a 36 × 36 grid: a minute over a run) without moving the choice.
    let centre = without_uniformity(set);
    let fitted = match fit_monitor(&centre, &config.fit) {
        Ok(f) => f,
        Err(e) => return Step::Stop(Stop::Unfitted(e)),
    };
    let Some(law) = fitted.report.chosen_law() else {
        return Step::Stop(Stop::Unfitted(FitError::NoLaw("no law was chosen".into())));
    };
    let Some(folds) = fold_models(&centre, &config.fit, law) else {
        return Step::Stop(Stop::Unfitted(FitError::NoLaw(format!(
            "{law} alone could not be fitted to the readings so far"
        ))));
    };
    let white: Xyz = set.mean_white().unwrap_or_else(|| fitted.model.white());
    let estimate = estimated_error(&fitted, &folds, &header.plan, &white);
    if let Some(e) = estimate
        && e <= limits.target_de00
    {
        return Step::Stop(Stop::TargetMet { estimate: e });
    }
    if counted(set) >= limits.budget {
        return Step::Stop(Stop::BudgetSpent { estimate });
    }
    let bit_depth = config.plan.bit_depth;
    let added = set
        .measurements
        .iter()
        .filter(|m| m.index >= header.plan.patches.len())
        .count();
    let durations = reading_durations(set);
    let best = candidates(set, bit_depth)
        .into_iter()
        .map(|codes| {
            let spread = prediction_spread(&folds, codes.drive(), &white);
            let y = fitted.model.forward_centre(codes.drive()).y;
            let seconds = expected_seconds(&durations, y) + config.display.settle_s;
            (codes, spread, spread * spread / seconds.max(1e-3))
        })
        .fold(
            None,
            |best: Option<(Codes, f64, f64)>, (codes, spread, value)| match best {
                Some((_, _, v)) if v >= value => best,
                _ => Some((codes, spread, value)),
            },
        );
    let Some((codes, spread, _)) = best else {
        return Step::Stop(Stop::NoCandidate { estimate });
    };
    let role = Role::from_drive(codes.drive());
    Step::Measure {
        patch: PlannedPatch {
            index: header.plan.patches.len() + added,
            role,
            patch: Patch {
                codes,
                background: Codes::from_drive([0.0; 3], bit_depth),
                geometry: Geometry::centred(config.plan.patch_size),
            },
        },
        spread,
        estimate,
    }
}

/// Measure patches chosen one at a time (`next_step`) until the run should stop. The
/// seed plan must be measured first (`run::run_plan`).
pub async fn run_sequential<D: PatchDisplay, I: Instrument>(
    journal: &mut Journal,
    config: &Config,
    mut devices: Devices<'_, D, I>,
    options: &RunOptions,
    hooks: &mut RunHooks<'_>,
    tally: &mut Tally,
) -> Result<SequentialSummary, RunError> {
    let seed_plan = journal.header().plan.patches.len();
    let budget = journal
        .header()
        .plan
        .sequential
        .as_ref()
        .map_or(0, |s| s.budget);
    loop {
        let set = journal.measurement_set();
        let counted_now = counted(&set);
        // A step is half a dozen fits: off the async task, so that a daemon's other
        // work (its API, its schedule) goes on meanwhile.
        let (header, owned) = (journal.header().clone(), config.clone());
        let stop = hooks.stop.clone();
        let step = tokio::task::spawn_blocking(move || {
            chromacal_model::fit::cancel::with_stop(stop, || next_step_for(&header, &set, &owned))
        })
        .await
        .unwrap_or_else(|e| {
            Step::Stop(Stop::Unfitted(FitError::NoLaw(format!(
                "choosing the next patch failed: {e}"
            ))))
        });
        let patch = match step {
            Step::Stop(stop) => {
                devices.display.blank().await?;
                return Ok(SequentialSummary {
                    added: journal.entries().len().saturating_sub(seed_plan),
                    counted: counted_now,
                    stop,
                });
            }
            Step::Measure {
                patch,
                spread,
                estimate,
            } => {
                tracing::info!(
                    index = patch.index,
                    drive = ?patch.patch.codes.drive(),
                    spread,
                    estimate,
                    "sequential plan: next patch"
                );
                patch
            }
        };
        let total = journal.entries().len() + budget.saturating_sub(counted_now);
        let devices = devices.reborrow();
        measure_patch(&patch, total, journal, devices, options, hooks, tally).await?;
    }
}

/// Measure what the journal's plan lacks, then, for a sequential plan, the patches it
/// chooses: the one measuring path of real and simulated runs.
pub async fn measure_run<D: PatchDisplay, I: Instrument>(
    journal: &mut Journal,
    config: &Config,
    mut devices: Devices<'_, D, I>,
    options: &RunOptions,
    hooks: &mut RunHooks<'_>,
) -> Result<RunSummary, RunError> {
    // One tally for both phases: the instrument stays aimed, the counts add up.
    let mut tally = Tally::default();
    let seed = run_plan_with(journal, devices.reborrow(), options, hooks, &mut tally).await?;
    if journal.header().plan.sequential.is_none() {
        return Ok(seed);
    }
    let sequential = run_sequential(journal, config, devices, options, hooks, &mut tally).await?;
    tracing::info!(
        added = sequential.added,
        counted = sequential.counted,
        stop = %sequential.stop,
        "sequential plan done"
    );
    Ok(RunSummary {
        sequential_added: sequential.added,
        sequential_stop: Some(format!(
            "{} ({} counted patches)",
            sequential.stop, sequential.counted
        )),
        ..tally.summary(seed.already_measured)
    })
}

#[cfg(test)]
mod tests {
    use super::expected_seconds;

    #[test]
    fn a_patch_is_expected_to_cost_what_readings_of_like_luminance_cost() {
        // (log10 cd/m², seconds), as an auto-ranging instrument gives them.
        let durations = [
            (-1.2, 10.0),
            (-0.6, 10.0),
            (0.0, 8.0),
            (0.7, 2.0),
            (1.3, 1.0),
            (1.7, 1.0),
            (2.0, 1.0),
        ];
        assert_eq!(expected_seconds(&durations, 0.1), 10.0);
        assert_eq!(expected_seconds(&durations, 60.0), 1.0);
        // Between: the median of the three nearest, not the nearest alone.
        assert_eq!(expected_seconds(&durations, 3.0), 2.0);
        // Black is dimmer than anything read: the dimmest readings' cost.
        assert_eq!(expected_seconds(&durations, 0.0), 10.0);
        // Nothing known: every candidate costs the same.
        assert_eq!(expected_seconds(&[], 5.0), 1.0);
    }
}
