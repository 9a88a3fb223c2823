//! Which transfer law to keep. Every candidate law is scored on readings it was not
//! fitted on, in ΔE00 against the display's white, by cross-validation over drive
//! levels: the levels below full drive (of the ramps and of the greys, whose channel
//! shares the laws are fitted to as well) are dealt into at most `MAX_FOLDS` folds; each
//! fold is left out in turn, every channel's direction, normaliser and law are fitted
//! again without it, and its ramp readings and greys are predicted.
//!
//! When some law cannot be cross-validated (too few levels to leave one out), the laws
//! are compared by Akaike's criterion instead, so the comparison stays like with like.
//! The simplest law within noise of the best is kept (`select`).
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
    /// Cross-validated ΔE00 of each left-out ramp reading and grey, all channels.
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

/// Most cross-validation folds: beyond ten, more folds cost fits and change little.
pub const MAX_FOLDS: usize = 10;

/// Cross-validated errors of one law (see the module documentation): the ΔE00 of each
/// left-out ramp reading and of each left-out grey, or why there are none.
fn cross_validate(
    kind: LawKind,
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
    black: &Xyz,
    white: &Xyz,
    noise: &NoiseModel,
    toe: f64,
) -> Result<(Vec<f64>, Vec<f64>), String> {
    if ramps.iter().any(|r| r.law_points().all(|p| p.drive >= 1.0)) {
        return Err("no level below full drive to hold out".into());
    }
    let mut levels: Vec<f64> = ramps
        .iter()
        .flat_map(|r| r.law_points().map(|p| p.drive))
        .chain(greys.iter().map(|g| g.0))
        .filter(|l| *l < 1.0)
        .collect();
    levels.sort_by(|a, b| a.total_cmp(b));
    levels.dedup();
    let folds = levels.len().min(MAX_FOLDS);
    let (mut ramp_errors, mut grey_errors) = (Vec::new(), Vec::new());
    for fold in 0..folds {
        let held: Vec<f64> = levels.iter().skip(fold).step_by(folds).copied().collect();
        let mut curves = Vec::with_capacity(3);
        for ramp in ramps {
            let training = ramp
                .without_levels(&held, black, noise)
                .ok_or("a training fold had no light")?;
            let fit = fit_law(kind, &training, toe).map_err(|e| format!("a training fold: {e}"))?;
            curves.push((training.column(fit.amplitude), fit.law));
        }
        let light = |c: usize, level: f64| curves[c].0 * curves[c].1.excitation(level);
        for (c, ramp) in ramps.iter().enumerate() {
            for p in ramp.points.iter().filter(|p| held.contains(&p.drive)) {
                ramp_errors.push(delta_e00_xyz(&p.xyz, &(black + light(c, p.drive)), white));
            }
        }
        for (level, measured) in greys.iter().filter(|g| held.contains(&g.0)) {
            let predicted = black + (0..3).map(|c| light(c, *level)).sum::<Xyz>();
            grey_errors.push(delta_e00_xyz(measured, &predicted, white));
        }
    }
    Ok((ramp_errors, grey_errors))
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

/// One law fitted to all three channels, and cross-validated where every channel fits.
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
    let (cv_errors, grey_errors, cv_note) = if fits.iter().all(|f| f.is_ok()) {
        match cross_validate(kind, ramps, greys, black, white, noise, toe) {
            Ok((ramp_errors, grey_errors)) => {
                let all = ramp_errors.iter().chain(&grey_errors).copied().collect();
                (Some(all), Some(grey_errors), None)
            }
            Err(note) => (None, None, Some(format!("not cross-validated: {note}"))),
        }
    } else {
        (None, None, None)
    };
    LawCandidate {
        kind,
        fits,
        cv_errors,
        grey_errors,
        cv_note,
        score: None,
    }
}

/// Give every fitted candidate the errors it is compared on, its cross-validated errors,
/// when every candidate could be cross-validated (so the comparison stays like with
/// like). Returns what the scores rest on, in words, and the XYZ of the readings
/// scored (for the noise tolerance).
fn score_candidates(
    candidates: &mut [LawCandidate],
    ramps: &[ChannelRamp; 3],
    greys: &[(f64, Xyz)],
) -> (&'static str, Vec<Xyz>) {
    let fitted: Vec<&LawCandidate> = candidates.iter().filter(|c| c.fitted()).collect();
    let all_cross_validated = !fitted.is_empty() && fitted.iter().all(|c| c.cv_errors.is_some());
    if !all_cross_validated {
        return (
            "nothing (some law could not be cross-validated)",
            Vec::new(),
        );
    }
    let held: Vec<Xyz> = ramps
        .iter()
        .flat_map(|r| r.points.iter().filter(|p| p.drive < 1.0).map(|p| p.xyz))
        .chain(greys.iter().filter(|g| g.0 < 1.0).map(|g| g.1))
        .collect();
    for c in candidates.iter_mut().filter(|c| c.fitted()) {
        c.score = c.cv_errors.clone();
    }
    ("ramp readings and greys left out by level", held)
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
