//! The curves fitted again (step 5b of `fit`) once a term for what additivity misses is
//! kept, with the greys corrected by it (`refit_curves_for_terms`).

use super::FitOptions;
use super::code_correction::{CodeCorrection, correct_at_codes};
use super::law_correction;
use super::law_selection::LawSelection;
use super::laws;
use super::noise::NoiseModel;
use super::primaries::{ChannelRamp, add_grey_excitations};
use super::terms::{TermReading, TermSet, fit_terms};
use crate::MonitorModel;
use crate::transfer::LawKind;
use chromacal_color::Xyz;

/// What the curves are fitted to: each channel's ramp, the greys (index, level, XYZ),
/// and the readings the terms are fitted to, with the run's noise.
#[derive(Debug, Clone, Copy)]
pub struct CurveEvidence<'a> {
    pub ramps: &'a [ChannelRamp; 3],
    pub greys: &'a [(usize, f64, Xyz)],
    pub readings: &'a [TermReading],
    pub noise: &'a NoiseModel,
}

/// How the curves are fitted again once a term is kept: as the law was chosen.
#[derive(Debug, Clone, Copy)]
pub struct CurveRefit {
    max_condition: f64,
    toe: f64,
    law: LawKind,
    /// The law was corrected at the measured levels, with this kernel width.
    corrected: Option<f64>,
    /// The curves were corrected at the measured codes, so.
    codes: Option<CodeCorrection>,
}

impl CurveRefit {
    pub fn as_chosen(selection: &LawSelection, options: &FitOptions, toe: f64) -> Self {
        CurveRefit {
            max_condition: options.max_condition_number,
            toe,
            law: selection.chosen,
            corrected: selection
                .correction
                .as_ref()
                .filter(|c| c.kept)
                .map(|c| c.bandwidth),
            codes: selection
                .codes
                .as_ref()
                .filter(|c| c.kept)
                .and_then(|c| c.noise_scale)
                .map(|noise_scale| CodeCorrection {
                    code_step: toe,
                    noise_scale,
                }),
        }
    }
}

/// Step 5b: with a term kept, the curves again. The greys shaped them as if the display
/// were additive (`add_grey_excitations`), so each grey is first corrected by what the
/// terms add at its level; the law kept is fitted again to every channel, and the terms'
/// coefficients of `set` again on the new curves. When a channel's law no longer fits,
/// `kept` (the terms on the additive curves) is returned as it is.
pub fn refit_curves_for_terms(
    additive: &MonitorModel,
    kept: &MonitorModel,
    set: TermSet,
    evidence: &CurveEvidence<'_>,
    refit: CurveRefit,
) -> MonitorModel {
    let corrected_greys: Vec<(usize, f64, Xyz)> = evidence
        .greys
        .iter()
        .map(|(index, level, xyz)| {
            let added = kept.forward_centre([*level; 3]) - additive.forward_centre([*level; 3]);
            (*index, *level, xyz - added)
        })
        .collect();
    let mut ramps = evidence.ramps.clone();
    for ramp in ramps.iter_mut() {
        ramp.grey_points.clear();
    }
    add_grey_excitations(
        &mut ramps,
        &corrected_greys,
        &additive.black,
        evidence.noise,
        refit.max_condition,
    );
    let Some(refitted) = fit_curves(additive, &ramps, refit) else {
        return kept.clone();
    };
    let all: Vec<&TermReading> = evidence.readings.iter().collect();
    fit_terms(&refitted, set, &all, evidence.noise).unwrap_or_else(|| kept.clone())
}

/// The additive model of `ramps`: the law kept fitted to each channel (with the
/// corrections kept), the matrix from the ramps' directions, the rest of `additive`.
/// `None` when a channel's law does not fit.
fn fit_curves(
    additive: &MonitorModel,
    ramps: &[ChannelRamp; 3],
    refit: CurveRefit,
) -> Option<MonitorModel> {
    let mut fits = Vec::with_capacity(3);
    for ramp in ramps {
        let mut fit = laws::fit_law(refit.law, ramp, refit.toe).ok()?;
        if let Some(c) = refit
            .corrected
            .and_then(|h| law_correction::correct_law(&fit, ramp, h))
        {
            fit = c;
        }
        fits.push(fit);
    }
    // The correction at the codes, as it was kept: on all three channels or none.
    let at_codes: Option<Vec<laws::LawFit>> = refit.codes.and_then(|codes| {
        fits.iter()
            .zip(ramps)
            .map(|(fit, ramp)| correct_at_codes(fit, ramp, codes))
            .collect()
    });
    let mut refitted = additive.clone();
    for (c, (ramp, fit)) in ramps.iter().zip(at_codes.unwrap_or(fits)).enumerate() {
        refitted.matrix.set_column(c, &ramp.column(fit.amplitude));
        refitted.laws[c] = fit.law;
    }
    Some(refitted)
}
