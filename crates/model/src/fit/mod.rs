//! Fitting the monitor model to measurements, choosing among its candidate parts on
//! held-out data, and testing the assumptions it rests on.
//!
//! [`fit_monitor`] runs the whole chain, one function a step, in this file:
//! 1. black (`primaries::estimate_black`);
//! 2. drift of the reference white (`drift_of_reference_white`), the run's noise
//!    (`noise_of_run`), and every reading corrected for drift to the end of the run
//!    (`correct_for_drift`);
//! 3. each channel's direction and excitations from its ramp (`channel_ramps`), and its
//!    share of each grey (`grey_readings`, `primaries::add_grey_excitations`), so the
//!    greys shape the curves where the ramps are sparse;
//! 4. every candidate law fitted and cross-validated, the simplest within noise of the
//!    best kept (`select_law`; `laws`, `law_selection`);
//! 5. the primary matrix, refused if too ill-conditioned to invert (`primary_matrix`);
//!    the assumption checks (`checks`), which need no model; then the terms for what
//!    additivity misses (channel interaction, crosstalk, chromaticity that moves with
//!    drive), each kept only if it lowers the cross-validated error (`terms`) or, with
//!    one grey level beside its channels, on the additivity check's evidence, and if
//!    one is kept the curves fitted again with the greys corrected by it (`refit`);
//! 6. the spatial map from the uniformity grid, chosen the same way (`spatial`), and
//!    the model against the measured white, which every export is normalised to
//!    (`anchor_at_measured_white`);
//! 7. held-out error on the verification patches (`validate_on_held_out`).
//!
//! Readings of luminance alone (a light meter) go through `light_meter`, which gives
//! them chromaticities and runs the same chain twice.

pub mod cancel;
pub mod checks;
pub mod code_correction;
pub mod law_correction;
pub mod law_selection;
pub mod laws;
pub mod least_squares;
pub mod light_meter;
pub mod limiter;
pub mod noise;
pub mod primaries;
pub mod refit;
pub mod select;
pub mod spatial;
pub mod stats;
pub mod terms;
pub mod uncertainty;
pub mod validate;

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use crate::measurement::{Measurement, MeasurementSet, Role, Units, drive_level};
use crate::monitor::matrix_condition_number;
use crate::reading::ReadingStatus;
use crate::transfer::LawKind;
use crate::{CHANNELS, MonitorModel, SpatialMap};
use checks::{AssumptionChecks, check_assumptions};
use chromacal_color::Xyz;
use chromacal_color::spaces::xyz_to_xyy;
use code_correction::CodeCorrectionReport;
use law_selection::{CorrectionReport, LawChoice, LawReport, LawSelection, choose_law};
use noise::{DriftModel, DriftReport, NoiseModel, estimate_drift, estimate_noise};
use primaries::{
    BlackEstimate, ChannelRamp, Corrected, RampError, add_grey_excitations, channel_ramp,
    estimate_black,
};
use refit::{CurveEvidence, CurveRefit, refit_curves_for_terms};
use spatial::{SpatialReport, choose_spatial_map};
use stats::ErrorStats;
use terms::{TermChoice, TermReading, TermReport, choose_terms};
use validate::{Evaluation, PatchError, evaluate};

/// Default largest condition number of the primary matrix that a profile may have.
/// Real displays sit near 3 to 10; beyond 1000 the inverse model turns a 0.1 %
/// measurement error into more than 100 % in some drive.
pub const DEFAULT_MAX_CONDITION_NUMBER: f64 = 1000.0;

/// Choices of the fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FitOptions {
    /// Candidate transfer laws.
    pub laws: Vec<LawKind>,
    /// Correct readings for the drift of the reference white.
    pub correct_drift: bool,
    /// Refuse a primary matrix whose condition number is above this.
    pub max_condition_number: f64,
    /// CIE 1931 x, y of the red, green and blue primaries, for a luminance meter
    /// (Cowan's method: the manufacturer's figures).
    pub primaries_xy: Option<[[f64; 2]; 3]>,
    /// x, y given to black with a luminance meter [default: D65, 0.3127, 0.3290].
    pub white_xy: Option<[f64; 2]>,
    /// Try the terms for what additivity misses (`terms`); off, the model is the
    /// additive one whatever the data show.
    pub additivity_terms: bool,
    /// Make the model pass through the measured white (`anchor_at_measured_white`);
    /// off, the exports still take the measured white, and the model's miss at white
    /// is what device white maps to.
    pub anchor_at_white: bool,
    /// How the transfer law is chosen from the candidates' cross-validated errors.
    pub law_rule: LawRule,
    /// The display decodes an HLG signal: BT.2100's OOTF is tried among the terms
    /// (`terms`). Set for a run whose `plan.signal` is HLG.
    pub hlg_ootf: bool,
}

/// How the transfer law is chosen from the candidates' cross-validated errors
/// (`law_selection`). The laws are alternatives, not a model and its additions: the
/// cross-validated error already charges a law for what its extra parameters cost in
/// variance, and allowing a simpler law one standard error or the noise on top gave
/// up held-out accuracy on mixtures (`chromacal bench law-rule`: on virtual monitors
/// from measured tables, mean ΔE00 0.882 → 0.735 at 24 patches, 0.229 → 0.226 at 48,
/// 0.088 → 0.082 at 160; never worse by more than 0.003 on any monitor).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LawRule {
    /// The simplest law within one standard error (paired) or noise of the best
    /// (Breiman et al.'s one-standard-error rule): the law a paper would name, when
    /// recovering the display's true law matters more than the last 0.01 ΔE00.
    SimplestWithinNoise,
    /// The law with the lowest cross-validated mean, however many parameters.
    #[default]
    LowestError,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            laws: LawKind::ALL.to_vec(),
            correct_drift: true,
            max_condition_number: DEFAULT_MAX_CONDITION_NUMBER,
            primaries_xy: None,
            white_xy: None,
            additivity_terms: true,
            anchor_at_white: false,
            law_rule: LawRule::default(),
            hlg_ootf: false,
        }
    }
}

/// Why no model could be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("the measurements have no usable reading")]
    NoUsableReadings,
    #[error(transparent)]
    Ramp(#[from] RampError),
    #[error("no transfer law could be fitted to all three channels: {0}")]
    NoLaw(String),
    #[error(
        "these readings are luminance only (a light meter): give the primaries' chromaticities in [fit] primaries_xy = [[xr, yr], [xg, yg], [xb, yb]] (the manufacturer's figures)"
    )]
    NeedChromaticities,
    #[error(
        "the primaries are nearly collinear (condition number {condition:.3e}, limit {limit:.0e}): an inverse model would amplify measurement noise that much, so no profile is made; check that each channel was measured, or raise fit.max_condition_number knowingly"
    )]
    IllConditioned { condition: f64, limit: f64 },
    #[error("the fit was stopped before its end (a cancelled job, or the daemon stopping)")]
    Stopped,
    #[error(
        "{file}: patch {index} (counting from 0, in the order of the file) reads {component} = {value:.4e}, beyond what any display emits or any instrument reads (at most {limit:e} in magnitude): the file is damaged or in another unit; remove or correct that reading"
    )]
    ReadingOutOfRange {
        file: String,
        index: usize,
        component: &'static str,
        value: f64,
        limit: f64,
    },
    #[error(
        "{file}: the fit came out with {figure} not a finite number although every reading is in range; please report this with the file"
    )]
    NotFinite { file: String, figure: &'static str },
}

/// The largest reading magnitude the fit accepts, cd/m² (or Y = 100 units). The
/// brightest displays peak near 10⁴ cd/m² and the widest-ranging meter in
/// PROTOCOLS.md (the CS-100A) stops at 299,900 cd/m²; a finite reading far beyond
/// that is a damaged file, and fed to the fit its squares overflow into NaN that
/// would surface, much later, as a profile that cannot be saved.
pub const MAX_READING_MAGNITUDE: f64 = 1e7;

/// Refuse, by patch and component, a usable reading beyond `MAX_READING_MAGNITUDE`.
/// Uniformity grid readings are not looked at: the spatial fit screens its grid and
/// leaves an absurd position out, which costs the map one point, not the profile.
fn check_reading_range(set: &MeasurementSet) -> Result<(), FitError> {
    for m in set
        .measurements
        .iter()
        .filter(|m| m.role != Role::Uniformity)
    {
        let Some(xyz) = m.usable_xyz() else { continue };
        for (component, value) in ["X", "Y", "Z"].into_iter().zip(xyz.iter().copied()) {
            if value.abs() > MAX_READING_MAGNITUDE {
                return Err(FitError::ReadingOutOfRange {
                    file: set.source.clone(),
                    index: m.index,
                    component,
                    value,
                    limit: MAX_READING_MAGNITUDE,
                });
            }
        }
    }
    Ok(())
}

/// The figures a profile is judged by, each finite, or the first that is not.
fn check_fit_finite(set: &MeasurementSet, fitted: &FittedModel) -> Result<(), FitError> {
    let r = &fitted.report;
    let mut figures: Vec<(&'static str, f64)> = vec![("the condition number", r.condition_number)];
    if let Some(h) = &r.held_out {
        figures.extend([
            ("the held-out mean", h.mean),
            ("the held-out 95th percentile", h.p95),
            ("the held-out maximum", h.max),
        ]);
    }
    for p in &r.primaries {
        figures.extend(p.xyz.iter().map(|v| ("a primary's XYZ", *v)));
    }
    match figures.into_iter().find(|(_, v)| !v.is_finite()) {
        Some((figure, _)) => Err(FitError::NotFinite {
            file: set.source.clone(),
            figure,
        }),
        None => Ok(()),
    }
}

/// A primary as fitted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrimaryReport {
    pub channel: String,
    /// XYZ at full drive, black taken off.
    pub xyz: Xyz,
    pub standard_error: Xyz,
    /// CIE 1931 x, y.
    pub chromaticity: [f64; 2],
    /// False when full drive was not measured and the column was extrapolated.
    pub full_drive_measured: bool,
    pub levels: usize,
}

/// How many readings went where.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Counts {
    pub readings: usize,
    pub usable: usize,
    pub below_range: usize,
    pub overload: usize,
    /// Readings of the budgeted kinds: black, ramps, greys, surround, reference.
    pub budget_readings: usize,
    pub held_out: usize,
    pub uniformity: usize,
}

/// Everything a fit found besides the model itself.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    pub units: Units,
    pub noise: NoiseModel,
    pub black: BlackEstimate,
    pub primaries: Vec<PrimaryReport>,
    pub condition_number: f64,
    pub law_rule: String,
    pub laws: Vec<LawReport>,
    /// How the terms for what additivity misses were chosen (empty in profiles made
    /// before there were terms).
    #[serde(default)]
    pub terms_rule: String,
    #[serde(default)]
    pub terms: Vec<TermReport>,
    /// The model against the measured white (absent in profiles made before it was
    /// recorded, and where no white was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white_anchor: Option<WhiteAnchor>,
    /// The chosen law against itself corrected at the measured levels (absent in
    /// profiles made before there was a correction, and where it was not tried).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law_correction: Option<CorrectionReport>,
    /// The curves corrected at the measured codes (absent in profiles made before there
    /// was this correction, and where the chosen law is the table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code_correction: Option<CodeCorrectionReport>,
    pub spatial: SpatialReport,
    pub checks: AssumptionChecks,
    /// ΔE00 on patches held out of every fit.
    pub held_out: Option<ErrorStats>,
    pub held_out_patches: Vec<PatchError>,
    pub counts: Counts,
    /// Set when the instrument measured luminance only: what that means for the figures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub luminance_only: Option<String>,
    /// The brightness limiter, where windows of several sizes were measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limiter: Option<limiter::LimiterReport>,
}

impl FitReport {
    pub fn chosen_law(&self) -> Option<LawKind> {
        self.laws.iter().find(|l| l.chosen).map(|l| l.law)
    }

    /// The cross-validated mean ΔE00 of a set of additivity terms, where it was tried
    /// and could be scored.
    pub fn term_score(&self, set: terms::TermSet) -> Option<f64> {
        self.terms
            .iter()
            .find(|t| t.terms == set)
            .and_then(|t| t.cross_validation.as_ref())
            .map(|s| s.mean)
    }
}

/// A fitted model and its report.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedModel {
    pub model: MonitorModel,
    pub report: FitReport,
}

/// Smallest non-zero drive the data could have been sent: one code step.
fn code_step(set: &MeasurementSet) -> f64 {
    set.measurements
        .iter()
        .find_map(|m| m.codes)
        .map_or(1.0 / 255.0, |c| {
            1.0 / crate::screen::Codes::max(c.bit_depth) as f64
        })
}

/// Fit the monitor model to `set`. Readings of luminance alone (a light meter) take
/// their own path, which gives them chromaticities first (`light_meter`).
///
/// A stop check set with `cancel::with_stop` ends the fit early with
/// `FitError::Stopped`: its iterative parts look at it between steps.
pub fn fit_monitor(set: &MeasurementSet, options: &FitOptions) -> Result<FittedModel, FitError> {
    check_reading_range(set)?;
    let fitted = if light_meter::is_luminance_only(set) {
        light_meter::fit_luminance_only(set, options, fit_measurements)
    } else {
        fit_measurements(set, options)
    };
    if cancel::requested() {
        return Err(FitError::Stopped);
    }
    if let Ok(f) = &fitted {
        check_fit_finite(set, f)?;
        let r = &f.report;
        tracing::debug!(
            readings = r.counts.readings,
            usable = r.counts.usable,
            held_out = r.counts.held_out,
            "fitted {}",
            set.source
        );
        tracing::debug!(
            law = %r.chosen_law().map_or("none", |l| l.name()),
            condition_number = r.condition_number,
            terms = ?r.terms.iter().find(|t| t.kept).map(|t| t.terms.name()),
            spatial = %f.model.spatial.describe(),
            "model chosen"
        );
        if let Some(h) = &r.held_out {
            tracing::debug!(mean = h.mean, p95 = h.p95, max = h.max, "held-out ΔE00");
        }
    }
    fitted
}

/// The chain of the module documentation, one step a call, on readings with XYZ.
fn fit_measurements(set: &MeasurementSet, options: &FitOptions) -> Result<FittedModel, FitError> {
    let all = &set.measurements;
    let black = estimate_black(&standard_readings(all, Role::Black));
    let (drift_model, drift) = drift_of_reference_white(all, &black, options.correct_drift);
    let noise = noise_of_run(all, &black, &drift);
    let corrected = correct_for_drift(all, &black, drift_model.as_ref())?;
    let (ramps, greys) = ramps_with_greys(&corrected, &black, &noise, options)?;
    let white_reference = reference_white(&corrected, &black, &ramps);
    let selection = select_law(
        options,
        &ramps,
        curve_greys(&greys, options),
        &black,
        &white_reference,
        &noise,
        code_step(set),
    )?;
    let (additive, condition_number) = primary_matrix(&ramps, &selection, &black, options)?;
    let checks = check_assumptions(
        &corrected,
        &ramps,
        &black.xyz,
        &noise,
        &drift,
        &white_reference,
    );
    let evidence = CurveEvidence {
        ramps: &ramps,
        greys: &greys,
        readings: &term_readings(&corrected),
        noise: &noise,
    };
    let refit = CurveRefit::as_chosen(&selection, options, code_step(set));
    let (choice, base) = terms_for_what_additivity_misses(
        &additive,
        &evidence,
        &white_reference,
        &checks,
        refit,
        options,
    );
    let grid = readings_of_role(&corrected, Role::Uniformity);
    let (spatial_map, spatial) = choose_spatial_map(&base, &grid, &noise);
    let (model, white_anchor) =
        anchor_at_measured_white(base.with_spatial(spatial_map), &corrected, options);
    let (evaluation, held_out) = validate_on_held_out(&model, &corrected);
    let (model, limiter) = limiter::keep_limiter(model, &corrected, &noise, options);
    Ok(FittedModel {
        report: FitReport {
            limiter,
            units: set.units,
            noise,
            black,
            primaries: primary_reports(&model, &ramps),
            condition_number,
            law_rule: selection.rule.clone(),
            laws: selection.reports(),
            terms_rule: choice.rule,
            terms: choice.reports,
            white_anchor,
            law_correction: selection.correction.clone(),
            code_correction: selection.codes.clone(),
            spatial,
            checks,
            held_out: evaluation.stats,
            held_out_patches: evaluation.patches,
            counts: count_readings(all, corrected.len(), held_out, grid.len()),
            luminance_only: None,
        },
        model,
    })
}

/// A grey reading: its index, its drive level and its XYZ.
type Grey = (usize, f64, Xyz);

/// Steps 3 and 4: each channel's ramp, with the greys' shares of it where they shape
/// the curves (`curve_greys`), and the greys.
fn ramps_with_greys(
    corrected: &[Corrected<'_>],
    black: &BlackEstimate,
    noise: &NoiseModel,
    options: &FitOptions,
) -> Result<([ChannelRamp; 3], Vec<Grey>), FitError> {
    let mut ramps = channel_ramps(corrected, black, noise)?;
    let greys = grey_readings(corrected);
    add_grey_excitations(
        &mut ramps,
        curve_greys(&greys, options),
        &black.xyz,
        noise,
        options.max_condition_number,
    );
    Ok((ramps, greys))
}

/// The greys that shape the curves: all of them, but none on a display decoding HLG
/// whose OOTF may be kept. Such a display is not the sum of its channels by design
/// (BT.2100's OOTF), so its greys would bend the curves by what the OOTF adds: the
/// curves are the ramps' alone, and the greys go to the OOTF term (and, corrected by
/// it, to the curves fitted again: `refit`).
fn curve_greys<'a>(greys: &'a [Grey], options: &FitOptions) -> &'a [Grey] {
    if options.hlg_ootf && options.additivity_terms {
        &[]
    } else {
        greys
    }
}

/// Step 5, after the matrix: the terms for what additivity misses (`terms`), chosen on
/// the readings of `evidence` and the additivity check, and the model with those kept,
/// its curves fitted again for them (`refit`).
fn terms_for_what_additivity_misses(
    additive: &MonitorModel,
    evidence: &CurveEvidence<'_>,
    white_reference: &Xyz,
    checks: &AssumptionChecks,
    refit: CurveRefit,
    options: &FitOptions,
) -> (TermChoice, MonitorModel) {
    let choice = if options.additivity_terms {
        choose_terms(
            additive,
            evidence.readings,
            evidence.noise,
            white_reference,
            &checks.additivity,
            options.hlg_ootf,
        )
    } else {
        TermChoice::additive("switched off (fit.additivity_terms = false)")
    };
    let base = match &choice.model {
        Some(kept) => refit_curves_for_terms(additive, kept, choice.chosen, evidence, refit),
        None => additive.clone(),
    };
    (choice, base)
}

/// The readings of `role` taken under standard conditions (centre, usual surround).
fn standard_readings(all: &[Measurement], role: Role) -> Vec<&Measurement> {
    all.iter()
        .filter(|m| m.role == role && m.is_standard_condition())
        .collect()
}

/// Is this the full white under standard conditions?
fn is_standard_white(m: &Measurement) -> bool {
    m.drive == [1.0; 3] && m.is_standard_condition()
}

/// Step 2a: the drift of the reference white (its signal above black) over the run.
fn drift_of_reference_white(
    all: &[Measurement],
    black: &BlackEstimate,
    correct: bool,
) -> (Option<DriftModel>, DriftReport) {
    let references: Vec<(f64, f64)> = all
        .iter()
        .filter(|m| m.role == Role::Reference && is_standard_white(m))
        .filter_map(|m| Some((m.time_s?, m.usable_xyz()?.y - black.xyz.y)))
        .collect();
    estimate_drift(&references, correct)
}

/// Step 2b: the run's noise model, from the scatter of the references about the drift
/// and of the blacks. White's luminance sets the scale of the assumed noise floor;
/// without a white reading, the brightest reading of each channel stands in for its
/// share.
fn noise_of_run(all: &[Measurement], black: &BlackEstimate, drift: &DriftReport) -> NoiseModel {
    let brightest = |c: usize| {
        all.iter()
            .filter(|m| m.role == Role::Ramp && m.drive[c] > 0.0)
            .filter_map(|m| m.usable_xyz())
            .map(|x| x.y)
            .fold(0.0, f64::max)
    };
    let white_y = all
        .iter()
        .filter(|m| is_standard_white(m))
        .filter_map(|m| m.usable_xyz())
        .map(|x| x.y)
        .fold(0.0, f64::max)
        .max(brightest(0) + brightest(1) + brightest(2));
    let black_ys: Vec<f64> = standard_readings(all, Role::Black)
        .iter()
        .filter_map(|m| m.usable_xyz())
        .map(|x| x.y)
        .collect();
    estimate_noise(
        drift.residual_relative_sd.map(|s| (s, drift.residual_dof)),
        &black_ys,
        white_y.max(black.xyz.y),
    )
}

/// Step 2c: every usable reading brought to the end of the run (the light above black
/// divided by the drift's gain at its time).
fn correct_for_drift<'a>(
    all: &'a [Measurement],
    black: &BlackEstimate,
    drift: Option<&DriftModel>,
) -> Result<Vec<Corrected<'a>>, FitError> {
    let corrected: Vec<Corrected<'_>> = all
        .iter()
        .filter_map(|m| {
            let xyz = m.usable_xyz()?;
            let gain = match (drift, m.time_s) {
                (Some(d), Some(t)) => d.gain(t),
                _ => 1.0,
            };
            Some(Corrected {
                measurement: m,
                xyz: black.xyz + (xyz - black.xyz) / gain,
            })
        })
        .collect();
    if corrected.is_empty() {
        return Err(FitError::NoUsableReadings);
    }
    Ok(corrected)
}

/// Step 3: each channel's direction in XYZ and its excitations, from its ramp.
fn channel_ramps(
    corrected: &[Corrected<'_>],
    black: &BlackEstimate,
    noise: &NoiseModel,
) -> Result<[ChannelRamp; 3], FitError> {
    let ramp_readings: Vec<Corrected<'_>> = corrected
        .iter()
        .filter(|r| r.measurement.role == Role::Ramp && r.measurement.is_standard_condition())
        .cloned()
        .collect();
    Ok([
        channel_ramp(0, &ramp_readings, &black.xyz, noise)?,
        channel_ramp(1, &ramp_readings, &black.xyz, noise)?,
        channel_ramp(2, &ramp_readings, &black.xyz, noise)?,
    ])
}

/// Step 3b: the greys below white as (index, level, XYZ): the channels' curves follow
/// them (`primaries::add_grey_excitations`) and the laws are scored on them.
fn grey_readings(corrected: &[Corrected<'_>]) -> Vec<(usize, f64, Xyz)> {
    corrected
        .iter()
        .filter(|r| r.measurement.role == Role::Grey && r.measurement.is_standard_condition())
        .filter(|r| r.measurement.drive[0] < 1.0)
        .map(|r| (r.measurement.index, r.measurement.drive[0], r.xyz))
        .collect()
}

/// The mean of the white readings (drift-corrected), if white was measured.
fn measured_white(corrected: &[Corrected<'_>]) -> Option<Xyz> {
    let whites: Vec<Xyz> = corrected
        .iter()
        .filter(|r| is_standard_white(r.measurement))
        .map(|r| r.xyz)
        .collect();
    (!whites.is_empty()).then(|| whites.iter().sum::<Xyz>() / whites.len() as f64)
}

/// The white ΔE00 is taken against: the mean of the white readings, else black plus the
/// three channels at full drive.
fn reference_white(
    corrected: &[Corrected<'_>],
    black: &BlackEstimate,
    ramps: &[ChannelRamp; 3],
) -> Xyz {
    measured_white(corrected)
        .unwrap_or_else(|| black.xyz + ramps.iter().map(|r| r.column(1.0)).sum::<Xyz>())
}

/// The model against the measured white, which every export is relative to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WhiteAnchor {
    /// The mean white reading, drift-corrected.
    pub measured: Xyz,
    /// What the model predicted for white before it was anchored.
    pub predicted: Xyz,
    /// What each channel's light is scaled by to reach the measured white (applied
    /// only where `anchored`).
    pub gains: [f64; 3],
    pub anchored: bool,
    /// Why it was not, when it was not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// Largest share by which anchoring may change a channel's light. The ramps' own full
/// drive readings fix each column to within noise, so a white that asks for more is a
/// white the model cannot reach by scaling its channels (a reading gone wrong, or a
/// display far from additive) and is reported, not followed.
pub const MAX_ANCHOR_GAIN_CHANGE: f64 = 0.15;

/// Step 6b: the model and the measured white. Every export is normalised to the
/// measured white (an ICC profile's PCS and `wtpt`, `lumi`), as ArgyllCMS normalises a
/// `.ti3` (`export::matrix_trc::MatrixTrc::relative_to`): normalised to the model's own
/// white, a model that predicts white a little off rescaled every colour it exported
/// (one wide-gamut monitor's ICC lost 20 % against its model that way). Whether the
/// model is also made to pass through the measured white, by scaling each channel's
/// light (`MonitorModel::anchored_at_white`; chromaticity and curve kept), is
/// `FitOptions::anchor_at_white`, off by default: on the shared real sets' held-out
/// mixtures anchoring always cost accuracy (Dell U2713HM 0.151 → 0.155, MacBook
/// 0.240 → 0.241, Samsung TN 0.595 → 0.613, Sony OLED 0.485 → 0.624, judged by
/// profcheck), the most where the white is not the sum of the channels. The report
/// says what the model missed the white by and what anchoring would ask.
fn anchor_at_measured_white(
    model: MonitorModel,
    corrected: &[Corrected<'_>],
    options: &FitOptions,
) -> (MonitorModel, Option<WhiteAnchor>) {
    let Some(measured) = measured_white(corrected) else {
        return (model, None);
    };
    let mut report = WhiteAnchor {
        measured,
        predicted: model.white(),
        gains: [1.0; 3],
        anchored: false,
        note: None,
    };
    let Some((anchored, gains)) = model.anchored_at_white(&measured) else {
        report.note = Some("no positive gains of the channels reach the measured white".into());
        return (model, Some(report));
    };
    report.gains = gains;
    if !options.anchor_at_white {
        report.note = Some("fit.anchor_at_white is off".into());
        return (model, Some(report));
    }
    if let Some(c) = (0..3).find(|c| (gains[*c] - 1.0).abs() > MAX_ANCHOR_GAIN_CHANGE) {
        report.note = Some(format!(
            "the measured white asks {} for × {:.3} of its light, beyond ± {:.0} %: not followed",
            CHANNELS[c],
            gains[c],
            MAX_ANCHOR_GAIN_CHANGE * 100.0
        ));
        return (model, Some(report));
    }
    report.anchored = true;
    (anchored, Some(report))
}

/// Step 4: every candidate law fitted to every channel and scored on readings it was
/// not fitted on (folds of drive levels: the ramps' readings and the greys below full
/// drive left out together).
fn select_law(
    options: &FitOptions,
    ramps: &[ChannelRamp; 3],
    greys: &[(usize, f64, Xyz)],
    black: &BlackEstimate,
    white_reference: &Xyz,
    noise: &NoiseModel,
    toe: f64,
) -> Result<LawSelection, FitError> {
    let greys: Vec<(f64, Xyz)> = greys.iter().map(|g| (g.1, g.2)).collect();
    choose_law(
        LawChoice {
            kinds: &options.laws,
            rule: options.law_rule,
        },
        ramps,
        &greys,
        &black.xyz,
        white_reference,
        noise,
        toe,
    )
    .ok_or_else(|| {
        FitError::NoLaw(
            options
                .laws
                .iter()
                .map(|l| l.name())
                .collect::<Vec<_>>()
                .join(", ")
                + " all failed on at least one channel",
        )
    })
}

/// Step 5: the primary matrix (each channel's direction scaled by its law's amplitude)
/// with the chosen laws, refused when too ill-conditioned to invert. Returns the model
/// without a spatial map and the matrix's condition number.
fn primary_matrix(
    ramps: &[ChannelRamp; 3],
    selection: &LawSelection,
    black: &BlackEstimate,
    options: &FitOptions,
) -> Result<(MonitorModel, f64), FitError> {
    let fits = selection
        .fits_to_publish()
        .ok_or_else(|| FitError::NoLaw("the chosen law has no fit".into()))?;
    let mut matrix = Matrix3::zeros();
    let mut laws = Vec::with_capacity(3);
    for (ramp, fit) in ramps.iter().zip(fits) {
        matrix.set_column(ramp.channel, &ramp.column(fit.amplitude));
        laws.push(fit.law.clone());
    }
    let laws: [_; 3] = laws
        .try_into()
        .map_err(|_| FitError::NoLaw("a channel is missing".into()))?;
    let condition_number = matrix_condition_number(&matrix);
    if !(condition_number <= options.max_condition_number) {
        return Err(FitError::IllConditioned {
            condition: condition_number,
            limit: options.max_condition_number,
        });
    }
    let model = MonitorModel {
        matrix,
        black: black.xyz,
        laws,
        spatial: SpatialMap::Uniform,
        terms: Default::default(),
    };
    Ok((model, condition_number))
}

/// The readings the additivity terms are fitted to: single-channel ramp readings,
/// greys and whites, at the standard condition.
fn term_readings(corrected: &[Corrected<'_>]) -> Vec<TermReading> {
    corrected
        .iter()
        .filter(|r| r.measurement.is_standard_condition())
        .filter(|r| {
            matches!(
                r.measurement.role,
                Role::Ramp | Role::Grey | Role::Reference
            )
        })
        .filter_map(|r| {
            Some(TermReading {
                level: drive_level(r.measurement.drive)?,
                drive: r.measurement.drive,
                xyz: r.xyz,
            })
        })
        .collect()
}

/// The corrected readings of one role.
fn readings_of_role<'a>(corrected: &[Corrected<'a>], role: Role) -> Vec<Corrected<'a>> {
    corrected
        .iter()
        .filter(|r| r.measurement.role == role)
        .cloned()
        .collect()
}

/// Step 7: the model's error on the patches held out of every fit (verification
/// patches and mixtures), and how many there were.
fn validate_on_held_out(model: &MonitorModel, corrected: &[Corrected<'_>]) -> (Evaluation, usize) {
    let held: Vec<&Corrected<'_>> = corrected
        .iter()
        .filter(|r| matches!(r.measurement.role, Role::Verification | Role::Mixture))
        .collect();
    (
        evaluate(model, held.iter().map(|r| (r.measurement, r.xyz))),
        held.len(),
    )
}

/// Each primary as fitted, for the report.
fn primary_reports(model: &MonitorModel, ramps: &[ChannelRamp; 3]) -> Vec<PrimaryReport> {
    ramps
        .iter()
        .map(|ramp| {
            let column = model.matrix.column(ramp.channel).into_owned();
            let xyy = xyz_to_xyy(&column, [0.0, 0.0]);
            PrimaryReport {
                channel: CHANNELS[ramp.channel].into(),
                xyz: column,
                standard_error: ramp.column_se(),
                chromaticity: [xyy.x, xyy.y],
                full_drive_measured: ramp.pinned,
                levels: ramp.levels().len(),
            }
        })
        .collect()
}

/// How many readings went where.
fn count_readings(
    all: &[Measurement],
    usable: usize,
    held_out: usize,
    uniformity: usize,
) -> Counts {
    let count_status = |s: ReadingStatus| all.iter().filter(|m| m.reading.status == s).count();
    Counts {
        readings: all.len(),
        usable,
        below_range: count_status(ReadingStatus::BelowRange),
        overload: count_status(ReadingStatus::Overload),
        budget_readings: all
            .iter()
            .filter(|m| {
                matches!(
                    m.role,
                    Role::Black | Role::Ramp | Role::Grey | Role::Surround | Role::Reference
                )
            })
            .count(),
        held_out,
        uniformity,
    }
}
