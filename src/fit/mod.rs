//! Fitting the monitor model to measurements, choosing among its candidate parts on
//! held-out data, and testing the assumptions it rests on.
//!
//! [`fit_monitor`] runs the whole chain:
//! 1. black (`primaries::estimate_black`);
//! 2. drift of the reference white and the run's noise (`noise`); every reading is
//!    corrected for drift to the end of the run;
//! 3. each channel's direction and excitations from its ramp (`primaries`);
//! 4. every candidate law fitted and cross-validated, the simplest within noise of the
//!    best kept (`laws`, `law_selection`);
//! 5. the primary matrix, refused if too ill-conditioned to invert;
//! 6. the spatial map from the uniformity grid, chosen the same way (`spatial`);
//! 7. held-out error on the verification patches (`validate`), and the assumption
//!    checks (`checks`).

pub mod checks;
pub mod law_selection;
pub mod laws;
pub mod least_squares;
pub mod light_meter;
pub mod noise;
pub mod primaries;
pub mod select;
pub mod spatial;
pub mod stats;
pub mod validate;

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use crate::color::Xyz;
use crate::color::spaces::xyz_to_xyy;
use crate::instrument::ReadingStatus;
use crate::measurement::{MeasurementSet, Role, Units};
use crate::model::monitor::matrix_condition_number;
use crate::model::transfer::LawKind;
use crate::model::{CHANNELS, MonitorModel, SpatialMap};
use checks::{AssumptionChecks, check_assumptions};
use law_selection::{LawReport, choose_law};
use noise::{NoiseModel, estimate_drift, estimate_noise};
use primaries::{BlackEstimate, ChannelRamp, Corrected, RampError, channel_ramp, estimate_black};
use spatial::{SpatialReport, choose_spatial_map};
use stats::ErrorStats;
use validate::{PatchError, evaluate};

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
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            laws: LawKind::ALL.to_vec(),
            correct_drift: true,
            max_condition_number: DEFAULT_MAX_CONDITION_NUMBER,
            primaries_xy: None,
            white_xy: None,
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
    pub spatial: SpatialReport,
    pub checks: AssumptionChecks,
    /// ΔE00 on patches held out of every fit.
    pub held_out: Option<ErrorStats>,
    pub held_out_patches: Vec<PatchError>,
    pub counts: Counts,
    /// Set when the instrument measured luminance only: what that means for the figures.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub luminance_only: Option<String>,
}

impl FitReport {
    pub fn chosen_law(&self) -> Option<LawKind> {
        self.laws.iter().find(|l| l.chosen).map(|l| l.law)
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

/// Fit the monitor model to `set`.
pub fn fit_monitor(set: &MeasurementSet, options: &FitOptions) -> Result<FittedModel, FitError> {
    if !light_meter::is_luminance_only(set) {
        return fit_measurements(set, options);
    }
    let primaries = options.primaries_xy.ok_or(FitError::NeedChromaticities)?;
    let white = options.white_xy.unwrap_or([0.3127, 0.3290]);
    let first = fit_measurements(
        &light_meter::synthesize(set, &primaries, white, None),
        options,
    )?;
    let mut second = fit_measurements(
        &light_meter::synthesize(set, &primaries, white, Some(&first.model)),
        options,
    )?;
    second.report.luminance_only = Some(format!(
        "measured with a luminance meter: the primaries' chromaticities are the configured ({:.4}, {:.4}), ({:.4}, {:.4}), ({:.4}, {:.4}), not measured; only luminance was fitted, and the ΔE00 figures compare luminance only",
        primaries[0][0],
        primaries[0][1],
        primaries[1][0],
        primaries[1][1],
        primaries[2][0],
        primaries[2][1]
    ));
    Ok(second)
}

fn fit_measurements(set: &MeasurementSet, options: &FitOptions) -> Result<FittedModel, FitError> {
    let all = &set.measurements;
    let standard = |m: &&crate::measurement::Measurement| m.is_standard_condition();

    // 1. Black.
    let blacks: Vec<_> = all
        .iter()
        .filter(|m| m.role == Role::Black)
        .filter(standard)
        .collect();
    let black = estimate_black(&blacks);

    // 2. Drift from the reference white, then the noise model.
    let is_white =
        |m: &&crate::measurement::Measurement| m.drive == [1.0; 3] && m.is_standard_condition();
    let references: Vec<(f64, f64)> = all
        .iter()
        .filter(|m| m.role == Role::Reference)
        .filter(is_white)
        .filter_map(|m| Some((m.time_s?, m.usable_xyz()?.y - black.xyz.y)))
        .collect();
    let (drift_model, drift) = estimate_drift(&references, options.correct_drift);
    // White's luminance sets the scale of the assumed noise floor. Without a white
    // reading, the brightest reading of each channel stands in for its share.
    let brightest = |c: usize| {
        all.iter()
            .filter(|m| m.role == Role::Ramp && m.drive[c] > 0.0)
            .filter_map(|m| m.usable_xyz())
            .map(|x| x.y)
            .fold(0.0, f64::max)
    };
    let white_y = all
        .iter()
        .filter(is_white)
        .filter_map(|m| m.usable_xyz())
        .map(|x| x.y)
        .fold(0.0, f64::max)
        .max(brightest(0) + brightest(1) + brightest(2));
    let black_ys: Vec<f64> = blacks
        .iter()
        .filter_map(|m| m.usable_xyz())
        .map(|x| x.y)
        .collect();
    let noise = estimate_noise(
        drift.residual_relative_sd.map(|s| (s, drift.residual_dof)),
        &black_ys,
        white_y.max(black.xyz.y),
    );

    let corrected: Vec<Corrected<'_>> = all
        .iter()
        .filter_map(|m| {
            let xyz = m.usable_xyz()?;
            let gain = match (&drift_model, m.time_s) {
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

    // 3. Ramps.
    let ramp_readings: Vec<Corrected<'_>> = corrected
        .iter()
        .filter(|r| r.measurement.role == Role::Ramp && r.measurement.is_standard_condition())
        .cloned()
        .collect();
    let ramps: [ChannelRamp; 3] = [
        channel_ramp(0, &ramp_readings, &black.xyz, &noise)?,
        channel_ramp(1, &ramp_readings, &black.xyz, &noise)?,
        channel_ramp(2, &ramp_readings, &black.xyz, &noise)?,
    ];
    let whites: Vec<Xyz> = corrected
        .iter()
        .filter(|r| is_white(&r.measurement))
        .map(|r| r.xyz)
        .collect();
    let white_reference = if whites.is_empty() {
        black.xyz + ramps.iter().map(|r| r.column(1.0)).sum::<Xyz>()
    } else {
        whites.iter().sum::<Xyz>() / whites.len() as f64
    };

    // 4. Laws.
    let greys: Vec<(f64, Xyz)> = corrected
        .iter()
        .filter(|r| r.measurement.role == Role::Grey && r.measurement.is_standard_condition())
        .filter(|r| r.measurement.drive[0] < 1.0)
        .map(|r| (r.measurement.drive[0], r.xyz))
        .collect();
    let selection = choose_law(
        &options.laws,
        &ramps,
        &greys,
        &black.xyz,
        &white_reference,
        &noise,
        code_step(set),
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
    })?;
    let chosen = selection
        .chosen_candidate()
        .ok_or_else(|| FitError::NoLaw("the chosen law has no fit".into()))?;
    let mut matrix = Matrix3::zeros();
    let mut laws = Vec::with_capacity(3);
    for (c, ramp) in ramps.iter().enumerate() {
        let fit = chosen.fits[c]
            .as_ref()
            .map_err(|e| FitError::NoLaw(e.to_string()))?;
        matrix.set_column(c, &ramp.column(fit.amplitude));
        laws.push(fit.law.clone());
    }
    let laws: [_; 3] = laws
        .try_into()
        .map_err(|_| FitError::NoLaw("a channel is missing".into()))?;

    // 5. The matrix must be invertible in practice.
    let condition_number = matrix_condition_number(&matrix);
    if !(condition_number <= options.max_condition_number) {
        return Err(FitError::IllConditioned {
            condition: condition_number,
            limit: options.max_condition_number,
        });
    }
    let base = MonitorModel {
        matrix,
        black: black.xyz,
        laws,
        spatial: SpatialMap::Uniform,
    };

    // 6. Spatial map.
    let grid: Vec<Corrected<'_>> = corrected
        .iter()
        .filter(|r| r.measurement.role == Role::Uniformity)
        .cloned()
        .collect();
    let (spatial_map, spatial) = choose_spatial_map(&base, &grid, &noise);
    let model = MonitorModel {
        spatial: spatial_map,
        ..base
    };

    // 7. Held-out error and checks.
    let held: Vec<&Corrected<'_>> = corrected
        .iter()
        .filter(|r| matches!(r.measurement.role, Role::Verification | Role::Mixture))
        .collect();
    let evaluation = evaluate(&model, held.iter().map(|r| (r.measurement, r.xyz)));
    let checks = check_assumptions(
        &corrected,
        &ramps,
        &black.xyz,
        &noise,
        &drift,
        &white_reference,
    );

    let primaries = ramps
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
        .collect();
    let count_status = |s: ReadingStatus| all.iter().filter(|m| m.reading.status == s).count();
    let counts = Counts {
        readings: all.len(),
        usable: corrected.len(),
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
        held_out: held.len(),
        uniformity: grid.len(),
    };
    Ok(FittedModel {
        report: FitReport {
            units: set.units,
            noise,
            black,
            primaries,
            condition_number,
            law_rule: selection.rule.clone(),
            laws: selection.reports(),
            spatial,
            checks,
            held_out: evaluation.stats,
            held_out_patches: evaluation.patches,
            counts,
            luminance_only: None,
        },
        model,
    })
}
