//! Which transfer law to keep. Every candidate law is scored on readings it was not
//! fitted on, in ΔE00 against the display's white, by cross-validation over drive
//! levels: the levels below full drive (of the ramps and of the greys, whose channel
//! shares the laws are fitted to as well) are dealt into at most `MAX_FOLDS` folds; each
//! fold is left out in turn, every channel's direction, normaliser and law are fitted
//! again without it, and its ramp readings and greys are predicted.
//!
//! When some law cannot be cross-validated (too few levels to leave one out), the laws
//! are compared by Akaike's criterion instead, so the comparison stays like with like.
//! By default the law of lowest cross-validated error is kept (ties go to the
//! simpler); `LawRule::SimplestWithinNoise` keeps the simplest within noise of the
//! best instead (`select`).
//!
//! One law family is kept for all three channels, so the profile says one thing.

use serde::{Deserialize, Serialize};

use super::code_correction::{CodeCorrectionReport, Judged, judge};
use super::law_correction::{BANDWIDTHS, Residuals, correct_law};
use super::laws::{FittedParameter, LawFit, LawFitError, fit_law};
use super::noise::NoiseModel;
use super::primaries::ChannelRamp;
use super::select::{simplest_within, simplest_within_noise};
use super::stats::{ErrorStats, mean};
use super::validate::{delta_e00_xyz, noise_delta_e00};
use crate::transfer::{LawKind, TransferLaw};
use chromacal_color::Xyz;

/// A law tried, fitted on all the data, with its cross-validated error.
#[derive(Debug, Clone)]
pub struct LawCandidate {
    pub kind: LawKind,
    /// The fit to each channel on all levels.
    pub fits: [Result<LawFit, LawFitError>; 3],
    /// Each fold's errors, `None` where the law could not be fitted without it (empty
    /// when it was not cross-validated at all).
    pub folds: Vec<Option<FoldErrors>>,
    /// Each fold's fits, where it could be fitted (what `folds` were scored with).
    pub fold_fits: Vec<Option<FoldFit>>,
    /// Cross-validated ΔE00 of each left-out ramp reading and grey, all channels, when
    /// every fold could be fitted.
    pub cv_errors: Option<Vec<f64>>,
    /// The greys' share of `cv_errors`.
    pub grey_errors: Option<Vec<f64>>,
    /// The errors the law was compared on.
    pub score: Option<Vec<f64>>,
    /// Why it could not be cross-validated, if it could not.
    pub cv_note: Option<String>,
}

impl LawCandidate {
    pub fn fitted(&self) -> bool {
        self.fits.iter().all(|f| f.is_ok())
    }
}

/// The outcome of choosing a law.
#[derive(Debug, Clone)]
pub struct LawSelection {
    pub candidates: Vec<LawCandidate>,
    pub chosen: LawKind,
    pub rule: String,
    /// Whether the chosen law was corrected at the measured levels
    /// (`law_correction`), and why; `None` where it was not tried.
    pub correction: Option<CorrectionReport>,
    /// Whether the curves were corrected at the measured codes (`code_correction`), and
    /// why; `None` where it was not tried.
    pub codes: Option<CodeCorrectionReport>,
    /// The corrected laws of the three channels, when a correction was kept.
    pub corrected: Option<Vec<LawFit>>,
}

/// The chosen law against the same law corrected at the measured levels, on the same
/// folds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CorrectionReport {
    pub law: LawKind,
    pub kept: bool,
    /// Cross-validated ΔE00 of the law alone and corrected, on the folds both could be
    /// fitted on.
    pub law_cv: Option<ErrorStats>,
    pub corrected_cv: Option<ErrorStats>,
    /// The kernel width the correction was cross-validated best with.
    #[serde(default)]
    pub bandwidth: f64,
    pub rule: String,
}

impl LawSelection {
    /// The laws a profile is made of: the corrected ones when the correction was kept,
    /// else the chosen law's fits.
    pub fn fits_to_publish(&self) -> Option<Vec<&LawFit>> {
        if let Some(corrected) = &self.corrected {
            return Some(corrected.iter().collect());
        }
        self.chosen_candidate()?
            .fits
            .iter()
            .map(|f| f.as_ref().ok())
            .collect()
    }

    pub fn chosen_candidate(&self) -> Option<&LawCandidate> {
        self.candidates.iter().find(|c| c.kind == self.chosen)
    }
}

/// A law's report in a profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LawReport {
    pub law: LawKind,
    pub chosen: bool,
    /// Cross-validated ΔE00 on the ramps and greys, left out by level.
    pub cross_validation: Option<ErrorStats>,
    /// The greys' part of it.
    pub greys: Option<ErrorStats>,
    /// Parameters of R, G, B (empty for a channel the law could not fit).
    pub parameters: [Vec<FittedParameter>; 3],
    pub notes: Vec<String>,
}

impl LawSelection {
    pub fn reports(&self) -> Vec<LawReport> {
        self.candidates
            .iter()
            .map(|c| {
                let mut notes = Vec::new();
                if let Some(n) = &c.cv_note {
                    notes.push(n.clone());
                }
                let parameters = [0, 1, 2].map(|ch| match &c.fits[ch] {
                    Ok(f) => {
                        for note in &f.notes {
                            notes.push(format!("{}: {note}", crate::CHANNELS[ch]));
                        }
                        f.parameters.clone()
                    }
                    Err(e) => {
                        notes.push(format!("{}: {e}", crate::CHANNELS[ch]));
                        Vec::new()
                    }
                });
                LawReport {
                    law: c.kind,
                    chosen: c.kind == self.chosen,
                    cross_validation: c.cv_errors.as_deref().and_then(ErrorStats::of),
                    greys: c.grey_errors.as_deref().and_then(ErrorStats::of),
                    parameters,
                    notes,
                }
            })
            .collect()
    }
}

/// What every law is fitted to and scored on: the channels' ramps (with their grey
/// shares), the greys below white as (level, XYZ), the black, the white ΔE00 is taken
/// against, the run's noise, and the toe of the log laws.
#[derive(Clone, Copy)]
struct Evidence<'a> {
    ramps: &'a [ChannelRamp; 3],
    greys: &'a [(f64, Xyz)],
    black: &'a Xyz,
    white: &'a Xyz,
    noise: &'a NoiseModel,
    toe: f64,
}

/// Most cross-validation folds: beyond ten, more folds cost fits and change little.
pub const MAX_FOLDS: usize = 10;

/// Distinct `levels` dealt into at most `max_folds` folds, in turn from the lowest, so
/// that each fold spans the range (what every cross-validation over levels leaves out).
pub fn level_folds(mut levels: Vec<f64>, max_folds: usize) -> Vec<Vec<f64>> {
    levels.sort_by(|a, b| a.total_cmp(b));
    levels.dedup();
    let n = levels.len().min(max_folds);
    (0..n)
        .map(|fold| levels.iter().skip(fold).step_by(n).copied().collect())
        .collect()
}

/// The ΔE00 of one fold's left-out ramp readings and of its left-out greys.
pub type FoldErrors = (Vec<f64>, Vec<f64>);

/// One fold's fit: the levels it left out, and each channel's training ramp with the
/// law fitted to it (kept so that the correction is cross-validated on the same fits).
#[derive(Debug, Clone)]
pub struct FoldFit {
    pub held: Vec<f64>,
    pub channels: Vec<(ChannelRamp, LawFit)>,
}

/// One fold's fit and errors, or why the law could not be fitted without it.
type FoldOutcome = Result<(FoldFit, FoldErrors), String>;

/// Cross-validated errors of one law (see the module documentation), fold by fold: a
/// fold's fit and errors, or why the law could not be fitted without it; `Err` when
/// there is no level to leave out at all.
fn cross_validate(kind: LawKind, evidence: &Evidence<'_>) -> Result<Vec<FoldOutcome>, String> {
    let Evidence { ramps, greys, .. } = *evidence;
    if ramps.iter().any(|r| r.law_points().all(|p| p.drive >= 1.0)) {
        return Err("no level below full drive to hold out".into());
    }
    let levels: Vec<f64> = ramps
        .iter()
        .flat_map(|r| r.law_points().map(|p| p.drive))
        .chain(greys.iter().map(|g| g.0))
        .filter(|l| *l < 1.0)
        .collect();
    Ok(level_folds(levels, MAX_FOLDS)
        .into_iter()
        .map(|held| {
            let fit = fold_fit(kind, evidence, held)?;
            let errors = fold_errors(&fit, evidence);
            Ok((fit, errors))
        })
        .collect())
}

/// One fold: every channel fitted without the levels `held`.
fn fold_fit(kind: LawKind, evidence: &Evidence<'_>, held: Vec<f64>) -> Result<FoldFit, String> {
    let mut channels = Vec::with_capacity(3);
    for ramp in evidence.ramps {
        let training = ramp
            .without_levels(&held, evidence.black, evidence.noise)
            .ok_or("a training fold had no light")?;
        let fit =
            fit_law(kind, &training, evidence.toe).map_err(|e| format!("a training fold: {e}"))?;
        channels.push((training, fit));
    }
    Ok(FoldFit { held, channels })
}

/// A fold's left-out ramp readings and greys, predicted by its laws.
fn fold_errors(fold: &FoldFit, evidence: &Evidence<'_>) -> FoldErrors {
    let curves: Vec<(Xyz, TransferLaw)> = fold
        .channels
        .iter()
        .map(|(training, fit)| (training.column(fit.amplitude), fit.law.clone()))
        .collect();
    fold_errors_with(fold, evidence, |c, level| {
        curves[c].0 * curves[c].1.excitation(level)
    })
}

/// A fold's left-out ramp readings and greys, predicted by `light` (each channel's
/// light above black at a drive level).
fn fold_errors_with(
    fold: &FoldFit,
    evidence: &Evidence<'_>,
    light: impl Fn(usize, f64) -> Xyz,
) -> FoldErrors {
    let Evidence {
        ramps,
        greys,
        black,
        white,
        ..
    } = *evidence;
    let held = &fold.held;
    let mut ramp_errors = Vec::new();
    for (c, ramp) in ramps.iter().enumerate() {
        for p in ramp.points.iter().filter(|p| held.contains(&p.drive)) {
            ramp_errors.push(delta_e00_xyz(&p.xyz, &(black + light(c, p.drive)), white));
        }
    }
    let grey_errors = greys
        .iter()
        .filter(|g| held.contains(&g.0))
        .map(|(level, measured)| {
            let predicted = black + (0..3).map(|c| light(c, *level)).sum::<Xyz>();
            delta_e00_xyz(measured, &predicted, white)
        })
        .collect();
    (ramp_errors, grey_errors)
}

/// The candidate laws and the rule that picks among them.
#[derive(Debug, Clone, Copy)]
pub struct LawChoice<'a> {
    pub kinds: &'a [LawKind],
    pub rule: super::LawRule,
}

/// Fit every law in `kinds` to every channel, score each on held-out readings (see the
/// module documentation), and keep one by `choice.rule`. `greys` are
/// (drive level, XYZ) of grey readings below full drive. `None` when no law fits all
/// three channels.
pub fn choose_law(
    choice: LawChoice<'_>,
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
    black: &Xyz,
    white: &Xyz,
    noise: &NoiseModel,
    toe: f64,
) -> Option<LawSelection> {
    let evidence = Evidence {
        ramps,
        greys,
        black,
        white,
        noise,
        toe,
    };
    let mut kinds = choice.kinds.to_vec();
    kinds.sort();
    kinds.dedup();
    let mut candidates: Vec<LawCandidate> = kinds
        .iter()
        .map(|kind| fit_candidate(*kind, &evidence))
        .collect();
    let (basis, held) = score_candidates(&mut candidates, ramps, greys);
    let scores: Vec<Option<Vec<f64>>> = candidates.iter().map(|c| c.score.clone()).collect();
    let tolerance = noise_delta_e00(&held, noise, white);
    let (picked, rule) = match choice.rule {
        super::LawRule::SimplestWithinNoise => (
            simplest_within_noise(&scores, tolerance),
            format!(
                "simplest law whose ΔE00 on {basis} exceeds the best's by no more than one standard error (paired) or than noise alone ({tolerance:.3})"
            ),
        ),
        super::LawRule::LowestError => (
            simplest_within(&scores, 0.0, 0.0),
            format!(
                "the law of lowest mean ΔE00 on {basis} (a simpler one only when equal; noise alone: {tolerance:.3})"
            ),
        ),
    };
    let (chosen, rule) = match picked {
        Some(k) => (candidates[k].kind, rule),
        None => (
            simplest_by_akaike(&candidates)?,
            "too few levels to cross-validate and no greys: the simplest law within 2 of the lowest Akaike criterion (χ² + 2k)"
                .to_string(),
        ),
    };
    let (correction, corrected) = try_correction(&candidates, chosen, &evidence, tolerance);
    let (codes, corrected) =
        try_code_correction(&candidates, chosen, corrected, &evidence, tolerance);
    Some(LawSelection {
        candidates,
        chosen,
        rule,
        correction,
        codes,
        corrected,
    })
}

/// The published curves (the chosen law's, or as corrected at the measured levels)
/// corrected at the measured codes too, when the replicate codes say it pays
/// (`code_correction`). Not tried for the table, whose knots are the codes already.
fn try_code_correction(
    candidates: &[LawCandidate],
    chosen: LawKind,
    corrected: Option<Vec<LawFit>>,
    evidence: &Evidence<'_>,
    tolerance: f64,
) -> (Option<CodeCorrectionReport>, Option<Vec<LawFit>>) {
    if chosen == LawKind::Table {
        return (None, corrected);
    }
    let base: Option<Vec<&LawFit>> = match &corrected {
        Some(fits) => Some(fits.iter().collect()),
        None => candidates
            .iter()
            .find(|c| c.kind == chosen)
            .and_then(|c| c.fits.iter().map(|f| f.as_ref().ok()).collect()),
    };
    let Some([r, g, b]) = base.and_then(|b| <[&LawFit; 3]>::try_from(b).ok()) else {
        return (None, corrected);
    };
    let (report, fits) = judge(&Judged {
        ramps: evidence.ramps,
        fits: [r, g, b],
        black: evidence.black,
        white: evidence.white,
        code_step: evidence.toe,
        tolerance,
    });
    (Some(report), fits.or(corrected))
}

/// The chosen law corrected at the measured levels (`law_correction`), cross-validated
/// on the folds of the law alone and kept only if it lowers their error by more than
/// two paired standard errors and more than `tolerance` (noise alone). Not tried for
/// the table, exact at every level already, nor for a law that was not
/// cross-validated.
fn try_correction(
    candidates: &[LawCandidate],
    chosen: LawKind,
    evidence: &Evidence<'_>,
    tolerance: f64,
) -> (Option<CorrectionReport>, Option<Vec<LawFit>>) {
    let Some(law) = candidates.iter().find(|c| c.kind == chosen) else {
        return (None, None);
    };
    if chosen == LawKind::Table || law.folds.is_empty() {
        return (None, None);
    }
    // Each fold's errors alone, and corrected with each width (the widths share one
    // correction of each channel's fold fit).
    let mut alone = Vec::new();
    let mut with: Vec<Vec<f64>> = vec![Vec::new(); BANDWIDTHS.len()];
    for (errors, fold) in law.folds.iter().zip(&law.fold_fits) {
        let (Some(errors), Some(fold)) = (errors, fold) else {
            continue;
        };
        alone.extend(errors.0.iter().chain(&errors.1));
        // Scored directly at the left-out levels: the law times the correction's
        // factor there, the value the published table interpolates.
        let residuals: Vec<Option<Residuals>> = fold
            .channels
            .iter()
            .map(|(training, fit)| Residuals::of(fit, training))
            .collect();
        for (bandwidth, errors) in BANDWIDTHS.iter().zip(with.iter_mut()) {
            let light = |c: usize, level: f64| {
                let (training, fit) = &fold.channels[c];
                let factor = residuals[c]
                    .as_ref()
                    .map_or(1.0, |r| r.factor(*bandwidth, level));
                training.column(fit.amplitude) * (fit.law.excitation(level) * factor).max(0.0)
            };
            let (ramp, grey) = fold_errors_with(fold, evidence, light);
            errors.extend(ramp.into_iter().chain(grey));
        }
    }
    let Some((bandwidth, with)) = BANDWIDTHS
        .iter()
        .copied()
        .zip(with)
        .min_by(|a, b| mean(&a.1).total_cmp(&mean(&b.1)))
    else {
        return (None, None);
    };
    if alone.is_empty() || alone.len() != with.len() {
        return (None, None);
    }
    let better = simplest_within(&[Some(alone.clone()), Some(with.clone())], tolerance, 2.0);
    // The correction of the fits on all the data, made only when it is to be kept.
    let fits: Option<Vec<LawFit>> = (better == Some(1))
        .then(|| {
            law.fits
                .iter()
                .zip(evidence.ramps)
                .map(|(fit, ramp)| correct_law(fit.as_ref().ok()?, ramp, bandwidth))
                .collect()
        })
        .flatten();
    let kept = fits.is_some();
    let report = CorrectionReport {
        law: chosen,
        kept,
        law_cv: ErrorStats::of(&alone),
        corrected_cv: ErrorStats::of(&with),
        bandwidth,
        rule: format!(
            "{chosen} corrected at the measured levels (kernel width {bandwidth}, the best of {BANDWIDTHS:?}), kept only if it lowers the ΔE00 of the same left-out levels by more than two standard errors (paired) and than noise alone ({tolerance:.3})"
        ),
    };
    (Some(report), fits)
}

/// One law fitted to all three channels, and cross-validated where every channel fits.
fn fit_candidate(kind: LawKind, evidence: &Evidence<'_>) -> LawCandidate {
    let Evidence { ramps, toe, .. } = *evidence;
    let fits = [0, 1, 2].map(|c| fit_law(kind, &ramps[c], toe));
    let (folds, cv_note) = if fits.iter().all(|f| f.is_ok()) {
        match cross_validate(kind, evidence) {
            Ok(folds) => {
                let failed: Vec<&String> = folds.iter().filter_map(|f| f.as_ref().err()).collect();
                let note = failed.first().map(|why| {
                    format!(
                        "could not be fitted on {} of {} folds ({why})",
                        failed.len(),
                        folds.len()
                    )
                });
                (folds.into_iter().map(Result::ok).collect(), note)
            }
            Err(note) => (Vec::new(), Some(format!("not cross-validated: {note}"))),
        }
    } else {
        (Vec::new(), None)
    };
    let (fold_fits, folds): (Vec<Option<FoldFit>>, Vec<Option<FoldErrors>>) = folds
        .into_iter()
        .map(|f: Option<(FoldFit, FoldErrors)>| match f {
            Some((fit, errors)) => (Some(fit), Some(errors)),
            None => (None, None),
        })
        .unzip();
    let complete = !folds.is_empty() && folds.iter().all(Option::is_some);
    let (cv_errors, grey_errors) = if complete {
        let all: Vec<&FoldErrors> = folds.iter().flatten().collect();
        (
            Some(
                all.iter()
                    .flat_map(|f| f.0.iter().chain(&f.1))
                    .copied()
                    .collect(),
            ),
            Some(all.iter().flat_map(|f| f.1.iter()).copied().collect()),
        )
    } else {
        (None, None)
    };
    LawCandidate {
        kind,
        fits,
        folds,
        fold_fits,
        cv_errors,
        grey_errors,
        cv_note,
        score: None,
    }
}

/// Give the candidates their scores, all on the same folds so the comparison stays like
/// with like: the folds every cross-validated law could be fitted on (a law with many
/// parameters may not fit where a fold leaves a channel few levels; its note says so).
/// With no such fold nothing is scored and Akaike's criterion chooses. Returns what the
/// scores rest on, in words, and the XYZ of the readings scored (for the noise
/// tolerance).
fn score_candidates(
    candidates: &mut [LawCandidate],
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
) -> (String, Vec<Xyz>) {
    let n_folds = candidates.iter().map(|c| c.folds.len()).max().unwrap_or(0);
    let crossed: Vec<usize> = (0..candidates.len())
        .filter(|k| candidates[*k].fitted() && !candidates[*k].folds.is_empty())
        .collect();
    if crossed.is_empty() {
        return (
            "nothing (no law could be cross-validated)".into(),
            Vec::new(),
        );
    }
    let common: Vec<usize> = (0..n_folds)
        .filter(|f| {
            crossed
                .iter()
                .all(|k| candidates[*k].folds.get(*f).is_some_and(Option::is_some))
        })
        .collect();
    let held: Vec<Xyz> = ramps
        .iter()
        .flat_map(|r| r.points.iter().filter(|p| p.drive < 1.0).map(|p| p.xyz))
        .chain(greys.iter().filter(|g| g.0 < 1.0).map(|g| g.1))
        .collect();
    if common.is_empty() {
        return (
            "nothing (no fold could be fitted by every law)".into(),
            Vec::new(),
        );
    }
    for k in crossed {
        let c = &mut candidates[k];
        c.score = Some(
            common
                .iter()
                .filter_map(|f| c.folds[*f].as_ref())
                .flat_map(|(ramp, grey)| ramp.iter().chain(grey))
                .copied()
                .collect(),
        );
    }
    let basis = if common.len() == n_folds {
        "ramp readings and greys left out by level".to_string()
    } else {
        format!(
            "ramp readings and greys left out by level ({} of {n_folds} folds, those every law could be fitted on)",
            common.len()
        )
    };
    (basis, held)
}

/// With nothing held out to score on: Akaike's criterion, χ² + 2k summed over the
/// channels (Akaike 1974), with the run's own noise model behind χ²; the simplest law
/// within 2 of the lowest (Burnham & Anderson 2002) is kept.
fn simplest_by_akaike(candidates: &[LawCandidate]) -> Option<LawKind> {
    let aic: Vec<Option<f64>> = candidates
        .iter()
        .map(|c| {
            c.fits
                .iter()
                .map(|f| {
                    f.as_ref()
                        .ok()
                        .map(|f| f.chi2 + 2.0 * f.free_parameters as f64)
                })
                .sum()
        })
        .collect();
    let best = aic.iter().flatten().copied().fold(f64::INFINITY, f64::min);
    let k = aic
        .iter()
        .position(|a| a.is_some_and(|a| a <= best + 2.0))?;
    Some(candidates[k].kind)
}
