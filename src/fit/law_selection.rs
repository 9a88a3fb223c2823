//! Which transfer law to keep. Every candidate law is scored on readings it was not
//! fitted on, in ΔE00 against the display's white:
//! * leave-one-level-out cross-validation on the ramps: each level below full drive is
//!   left out in turn, the channel's direction, normaliser and law are fitted again
//!   without it, and the left-out readings are predicted;
//! * the greys, which no law is fitted on, predicted from all three channels.
//!
//! When some law cannot be cross-validated (too few levels to leave one out), all are
//! compared on the greys alone, so the comparison stays like with like. The simplest
//! law within noise of the best is kept (`select`).
//!
//! One law family is kept for all three channels, so the profile says one thing.

use serde::{Deserialize, Serialize};

use super::laws::{FittedParameter, LawFit, LawFitError, fit_law};
use super::noise::NoiseModel;
use super::primaries::ChannelRamp;
use super::select::simplest_within_noise;
use super::stats::ErrorStats;
use super::validate::{delta_e00_xyz, noise_delta_e00};
use crate::color::Xyz;
use crate::model::transfer::LawKind;

/// A law tried, fitted on all the data, with its cross-validated error.
#[derive(Debug, Clone)]
pub struct LawCandidate {
    pub kind: LawKind,
    /// The fit to each channel on all levels.
    pub fits: [Result<LawFit, LawFitError>; 3],
    /// Held-out ΔE00 of each left-out ramp reading, all channels.
    pub cv_errors: Option<Vec<f64>>,
    /// ΔE00 of each grey, predicted from the fits on all ramp readings.
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
}

impl LawSelection {
    pub fn chosen_candidate(&self) -> Option<&LawCandidate> {
        self.candidates.iter().find(|c| c.kind == self.chosen)
    }
}

/// A law's report in a profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LawReport {
    pub law: LawKind,
    pub chosen: bool,
    /// Leave-one-level-out ΔE00 on the ramps.
    pub cross_validation: Option<ErrorStats>,
    /// ΔE00 of the greys (never fitted on).
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
                            notes.push(format!("{}: {note}", crate::model::CHANNELS[ch]));
                        }
                        f.parameters.clone()
                    }
                    Err(e) => {
                        notes.push(format!("{}: {e}", crate::model::CHANNELS[ch]));
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

/// Cross-validated error of one law over all three channels, or why there is none.
fn cross_validate(
    kind: LawKind,
    ramps: &[ChannelRamp; 3],
    black: &Xyz,
    white: &Xyz,
    noise: &NoiseModel,
    toe: f64,
) -> Result<Vec<f64>, String> {
    let mut errors = Vec::new();
    for ramp in ramps {
        let held_levels: Vec<f64> = ramp.levels().into_iter().filter(|l| *l < 1.0).collect();
        if held_levels.is_empty() {
            return Err("no level below full drive to hold out".into());
        }
        for level in held_levels {
            let Some(training) = ramp.without_level(level, black, noise) else {
                return Err("a training fold had no light".into());
            };
            let fit = fit_law(kind, &training, toe).map_err(|e| format!("a training fold: {e}"))?;
            let column = training.column(fit.amplitude);
            let predicted = black + column * fit.law.excitation(level);
            for p in ramp.points.iter().filter(|p| p.drive == level) {
                errors.push(delta_e00_xyz(&p.xyz, &predicted, white));
            }
        }
    }
    Ok(errors)
}

/// ΔE00 of each grey predicted by a candidate fitted on all ramp readings.
fn grey_errors(
    fits: &[Result<LawFit, LawFitError>; 3],
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
    black: &Xyz,
    white: &Xyz,
) -> Option<Vec<f64>> {
    let fits: Vec<&LawFit> = fits
        .iter()
        .map(|f| f.as_ref().ok())
        .collect::<Option<_>>()?;
    Some(
        greys
            .iter()
            .map(|(level, measured)| {
                let predicted = black
                    + (0..3)
                        .map(|c| {
                            ramps[c].column(fits[c].amplitude) * fits[c].law.excitation(*level)
                        })
                        .sum::<Xyz>();
                delta_e00_xyz(measured, &predicted, white)
            })
            .collect(),
    )
}

/// Fit every law in `kinds` to every channel, score each on held-out readings (see the
/// module documentation), and keep the simplest within noise of the best. `greys` are
/// (drive level, XYZ) of grey readings below full drive. `None` when no law fits all
/// three channels.
pub fn choose_law(
    kinds: &[LawKind],
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
    black: &Xyz,
    white: &Xyz,
    noise: &NoiseModel,
    toe: f64,
) -> Option<LawSelection> {
    let mut kinds = kinds.to_vec();
    kinds.sort();
    kinds.dedup();
    let mut candidates: Vec<LawCandidate> = kinds
        .iter()
        .map(|kind| fit_candidate(*kind, ramps, greys, black, white, noise, toe))
        .collect();
    let (basis, held) = score_candidates(&mut candidates, ramps, greys);
    let scores: Vec<Option<Vec<f64>>> = candidates.iter().map(|c| c.score.clone()).collect();
    let tolerance = noise_delta_e00(&held, noise, white);
    let (chosen, rule) = match simplest_within_noise(&scores, tolerance) {
        Some(k) => (
            candidates[k].kind,
            format!(
                "simplest law whose ΔE00 on {basis} exceeds the best's by no more than one standard error (paired) or than noise alone ({tolerance:.3})"
            ),
        ),
        None => (
            simplest_by_akaike(&candidates)?,
            "too few levels to cross-validate and no greys: the simplest law within 2 of the lowest Akaike criterion (χ² + 2k)"
                .to_string(),
        ),
    };
    Some(LawSelection {
        candidates,
        chosen,
        rule,
    })
}

/// One law fitted to all three channels, cross-validated where every channel fits, and
/// scored on the greys.
fn fit_candidate(
    kind: LawKind,
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
    black: &Xyz,
    white: &Xyz,
    noise: &NoiseModel,
    toe: f64,
) -> LawCandidate {
    let fits = [0, 1, 2].map(|c| fit_law(kind, &ramps[c], toe));
    let (cv_errors, cv_note) = if fits.iter().all(|f| f.is_ok()) {
        match cross_validate(kind, ramps, black, white, noise, toe) {
            Ok(e) => (Some(e), None),
            Err(note) => (None, Some(format!("not cross-validated: {note}"))),
        }
    } else {
        (None, None)
    };
    let grey_errors = grey_errors(&fits, ramps, greys, black, white);
    LawCandidate {
        kind,
        fits,
        cv_errors,
        grey_errors,
        cv_note,
        score: None,
    }
}

/// Give every fitted candidate the errors it is compared on: its cross-validated ramp
/// errors and the greys when every candidate could be cross-validated, the greys alone
/// otherwise (so the comparison stays like with like). Returns what the scores rest on,
/// in words, and the XYZ of the readings scored (for the noise tolerance).
fn score_candidates(
    candidates: &mut [LawCandidate],
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
) -> (&'static str, Vec<Xyz>) {
    let fitted: Vec<&LawCandidate> = candidates.iter().filter(|c| c.fitted()).collect();
    let all_cross_validated = !fitted.is_empty() && fitted.iter().all(|c| c.cv_errors.is_some());
    let (basis, mut held): (&str, Vec<Xyz>) = if all_cross_validated {
        (
            "leave-one-level-out ramp readings and the greys",
            ramps
                .iter()
                .flat_map(|r| r.points.iter().filter(|p| p.drive < 1.0).map(|p| p.xyz))
                .collect(),
        )
    } else {
        (
            "the greys alone (some law could not be cross-validated)",
            Vec::new(),
        )
    };
    held.extend(greys.iter().map(|g| g.1));
    for c in candidates.iter_mut().filter(|c| c.fitted()) {
        c.score = if all_cross_validated {
            let mut e = c.cv_errors.clone().unwrap_or_default();
            e.extend(c.grey_errors.clone().unwrap_or_default());
            Some(e)
        } else if !greys.is_empty() {
            c.grey_errors.clone()
        } else {
            None
        };
    }
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
