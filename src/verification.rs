//! A verification of a profile against measurements, in the terms calibration people
//! use (DisplayCAL's verification report, ArgyllCMS `profcheck` and `dispcal -r`):
//! every patch measured against its prediction with ΔL*, ΔC*, ΔH* and ΔE00 and a
//! pass or fail against named criteria; the white's luminance, correlated colour
//! temperature and Duv, the black and the contrast ratio; the gamut's coverage of the
//! reference spaces; grey balance and effective gamma along the grey ramp; and colour
//! uniformity against the centre where a grid was measured.
//!
//! Plain data, computed here and drawn by `html_report`; the patches' ΔE00 are
//! [`chromacal_model::fit::validate::evaluate`]'s, the very figures `chromacal check` prints.

use serde::Serialize;

use crate::config::PublishConfig;
use chromacal_color::gamut::{self, AdditiveGamut, GamutComparison};
use chromacal_color::spaces::{Lab, lab_to_lch, xyz_to_uv_prime, xyz_to_xyy};
use chromacal_color::temperature::{ColourTemperature, xyz_to_cct_duv};
use chromacal_color::{UvPrime, Xyz, delta_e_2000, xyz_to_lab};
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::validate::{PatchError, evaluate};
use chromacal_model::measurement::{MeasurementSet, Role};
use chromacal_model::{Drive, MonitorModel, ScreenPosition};

/// What a verification must achieve to pass, by name.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Criteria {
    pub name: String,
    /// Largest mean ΔE00 over the judged patches.
    pub max_mean: f64,
    /// Largest 95th-percentile ΔE00.
    pub max_p95: f64,
    /// Largest ΔE00 of any one patch: a patch above it fails.
    pub max_patch: f64,
    /// Largest mean ΔE ITP (BT.2124) over the judged patches: the `[publish]` limits
    /// of a profile of an HDR signal, whose light is absolute.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_mean_itp: Option<f64>,
}

/// The named presets of `--criteria`: (name, mean, p95, any one patch).
pub const CRITERIA_PRESETS: [(&str, f64, f64, f64); 3] = [
    // Good enough to proof against: most patches below one just-noticeable difference.
    ("strict", 0.5, 1.0, 2.0),
    // The default [publish] limits, with a patch limit of twice the p95 limit.
    ("nominal", 1.0, 2.0, 4.0),
    // A display used for work that tolerates visible but small errors.
    ("loose", 2.0, 4.0, 6.0),
];

impl Default for Criteria {
    fn default() -> Self {
        Criteria::from_publish(&PublishConfig::default())
    }
}

impl Criteria {
    /// The limits a profile is published by (`[publish]`): its mean and p95 limits,
    /// and a patch limit of twice the p95 limit.
    pub fn from_publish(publish: &PublishConfig) -> Criteria {
        Criteria {
            name: "the [publish] limits".into(),
            max_mean: publish.max_mean_de00,
            max_p95: publish.max_p95_de00,
            max_patch: 2.0 * publish.max_p95_de00,
            max_mean_itp: None,
        }
    }

    /// [`Criteria::from_publish`] for a profile of `signal`: an HDR one is held to
    /// `max_mean_itp` as well, as `calibrate` publishes it.
    pub fn from_publish_for(
        publish: &PublishConfig,
        signal: Option<chromacal_model::plan::Signal>,
    ) -> Criteria {
        Criteria {
            max_mean_itp: signal.filter(|s| s.is_hdr()).map(|_| publish.max_mean_itp),
            ..Criteria::from_publish(publish)
        }
    }

    /// What the criteria ask, in a sentence for the page.
    pub fn describe(&self) -> String {
        let limits: Vec<String> = [
            ("mean ΔE00", self.max_mean),
            ("95th percentile", self.max_p95),
            ("every patch", self.max_patch),
        ]
        .iter()
        .filter(|(_, limit)| limit.is_finite())
        .map(|(what, limit)| format!("{what} ≤ {limit}"))
        .chain(self.max_mean_itp.map(|l| format!("mean ΔE ITP ≤ {l}")))
        .collect();
        format!("{}: {}", self.name, limits.join(", "))
    }

    /// The daemon's verification threshold (`[schedule] threshold_de00`) alone, the
    /// pass mark of its `verify` jobs and its fleet page: a mean, no other limit.
    pub fn verification_threshold(threshold: f64) -> Criteria {
        Criteria {
            name: "the verification threshold ([schedule] threshold_de00)".into(),
            max_mean: threshold,
            max_p95: f64::INFINITY,
            max_patch: f64::INFINITY,
            max_mean_itp: None,
        }
    }

    /// The pass mark of the daemon's `verify` jobs for a profile of `signal`: an HDR
    /// one is judged by its mean ΔE ITP against `[schedule] threshold_itp` alone (as
    /// the job judges it), any other by [`Criteria::verification_threshold`].
    pub fn verification_threshold_for(
        schedule: &crate::config::ScheduleConfig,
        signal: Option<chromacal_model::plan::Signal>,
    ) -> Criteria {
        match signal.filter(|s| s.is_hdr()) {
            Some(_) => Criteria {
                name: "the verification threshold ([schedule] threshold_itp)".into(),
                max_mean: f64::INFINITY,
                max_p95: f64::INFINITY,
                max_patch: f64::INFINITY,
                max_mean_itp: Some(schedule.threshold_itp),
            },
            None => Criteria::verification_threshold(schedule.threshold_de00),
        }
    }
}

impl std::str::FromStr for Criteria {
    type Err = String;

    /// A preset's name (`strict`, `nominal`, `loose`) or limits as
    /// `mean=1,p95=2,max=4` (any omitted limit is the nominal one).
    fn from_str(s: &str) -> Result<Criteria, String> {
        if let Some((name, mean, p95, patch)) = CRITERIA_PRESETS.iter().find(|p| p.0 == s) {
            return Ok(Criteria {
                name: (*name).into(),
                max_mean: *mean,
                max_p95: *p95,
                max_patch: *patch,
                max_mean_itp: None,
            });
        }
        let names: Vec<&str> = CRITERIA_PRESETS.iter().map(|p| p.0).collect();
        let (_, mut max_mean, mut max_p95, mut max_patch) = CRITERIA_PRESETS[1];
        for part in s.split(',') {
            let (key, value) = part.split_once('=').ok_or_else(|| {
                format!(
                    "criteria '{s}': give a preset ({}) or limits as mean=1,p95=2,max=4",
                    names.join(", ")
                )
            })?;
            let value: f64 = value
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite() && *v > 0.0)
                .ok_or_else(|| format!("criteria '{s}': {key} must be a positive number"))?;
            match key.trim() {
                "mean" => max_mean = value,
                "p95" => max_p95 = value,
                "max" => max_patch = value,
                other => {
                    return Err(format!(
                        "criteria '{s}': no limit '{other}' (mean, p95 or max)"
                    ));
                }
            }
        }
        Ok(Criteria {
            name: "given limits".into(),
            max_mean,
            max_p95,
            max_patch,
            max_mean_itp: None,
        })
    }
}

/// Whether a patch was in the fit, held out of it, or measured to verify it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PatchUse {
    Fit,
    HeldOut,
    Verification,
}

impl PatchUse {
    pub fn name(self) -> &'static str {
        match self {
            PatchUse::Fit => "fit",
            PatchUse::HeldOut => "held out",
            PatchUse::Verification => "verification",
        }
    }
}

/// One patch: measured against the profile's prediction (the nominal), in CIELAB
/// against the model's white.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchRow {
    pub index: usize,
    pub drive: Drive,
    pub position: ScreenPosition,
    pub used: PatchUse,
    pub nominal: Xyz,
    pub measured: Xyz,
    pub nominal_lab: Lab,
    pub measured_lab: Lab,
    /// CIE 15:2004 eq. 8.8–8.10: ΔL*, ΔC*ab and ΔH*ab, measured less nominal (ΔH*
    /// signed with the hue angle's difference).
    pub delta_l: f64,
    pub delta_c: f64,
    pub delta_h: f64,
    pub delta_e00: f64,
    /// Judged against the criteria (fit patches are shown, not judged), and whether
    /// it is within the patch limit.
    pub judged: bool,
    pub passes: bool,
}

/// The judged patches' statistics against the criteria.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Judgement {
    pub criteria: Criteria,
    pub stats: Option<ErrorStats>,
    /// ΔE ITP of the judged patches, where the criteria have a limit on it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub itp: Option<ErrorStats>,
    pub failing_patches: usize,
    pub passes: bool,
}

/// The white, the black and the contrast between them, measured where the set has
/// them and otherwise the model's.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WhiteAndBlack {
    pub white: Xyz,
    pub white_xy: [f64; 2],
    pub white_measured: bool,
    pub temperature: Option<ColourTemperature>,
    pub black: Xyz,
    pub black_measured: bool,
    /// White Y over black Y; `None` for a black of zero light.
    pub contrast: Option<f64>,
}

/// One grey of the ramp (mean of its readings at the centre).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GreyStep {
    pub drive: f64,
    pub luminance: f64,
    /// (Y − Y black) / (Y white − Y black), measured and as the model predicts it.
    pub relative: f64,
    pub model_relative: f64,
    /// ln(relative) / ln(drive): the exponent of a power law through this grey.
    pub effective_gamma: Option<f64>,
    pub model_effective_gamma: Option<f64>,
    /// a*, b* against the white (a neutral grey has both zero).
    pub a: f64,
    pub b: f64,
    /// Δu′v′ from the white's chromaticity.
    pub delta_uv: f64,
    pub temperature: Option<ColourTemperature>,
}

/// One position of the uniformity grid against the centre at the same drive.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UniformityCell {
    pub position: ScreenPosition,
    pub drive: Drive,
    pub luminance_percent: f64,
    pub delta_uv: f64,
    /// ΔE00 against the centre, both in CIELAB relative to the centre's reading.
    pub delta_e00: f64,
}

/// Everything the verification sections of the report show.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verification {
    pub patches: Vec<PatchRow>,
    /// Readings whose ΔE00 cannot be computed (a value out of all range), left out.
    pub unscorable: usize,
    pub judgement: Judgement,
    pub white: WhiteAndBlack,
    /// The model's gamut in L*a*b* (cubic ΔE*ab), and against each reference space.
    pub volume: Option<f64>,
    pub gamut: Vec<GamutComparison>,
    pub greys: Vec<GreyStep>,
    pub uniformity: Vec<UniformityCell>,
}

/// CIE 15:2004 eq. 8.8–8.10: ΔL*, ΔC*ab and ΔH*ab of `sample` from `reference`,
/// ΔH*ab = 2 √(C₁C₂) sin(Δh/2), signed with Δh.
pub fn lab_differences(reference: &Lab, sample: &Lab) -> (f64, f64, f64) {
    let (l1, c1, h1) = lab_to_lch(reference);
    let (l2, c2, h2) = lab_to_lch(sample);
    let mut dh = h2 - h1;
    if dh > 180.0 {
        dh -= 360.0;
    } else if dh < -180.0 {
        dh += 360.0;
    }
    let delta_h = 2.0 * (c1 * c2).sqrt() * (dh.to_radians() / 2.0).sin();
    (l2 - l1, c2 - c1, delta_h)
}

/// Verify `model` against `set`. `held_out` gives the patches held out of the fit,
/// as the fit scored them (on its drift-corrected readings), when `set` is the fit's
/// own readings: those rows are the fit's own figures, and the others are fit
/// patches, shown but not judged. `None` when every patch was measured to verify.
pub fn verify(
    model: &MonitorModel,
    set: &MeasurementSet,
    held_out: Option<&[PatchError]>,
    criteria: &Criteria,
) -> Verification {
    let evaluation = evaluate(
        model,
        set.measurements
            .iter()
            .filter_map(|m| Some((m, m.usable_xyz()?))),
    );
    let white = model.white();
    let row = |p: &PatchError, used: PatchUse| {
        let (nominal_lab, measured_lab) = (
            xyz_to_lab(&p.predicted, &white),
            xyz_to_lab(&p.measured, &white),
        );
        let (delta_l, delta_c, delta_h) = lab_differences(&nominal_lab, &measured_lab);
        PatchRow {
            index: p.index,
            drive: p.drive,
            position: p.position,
            used,
            nominal: p.predicted,
            measured: p.measured,
            nominal_lab,
            measured_lab,
            delta_l,
            delta_c,
            delta_h,
            delta_e00: p.delta_e00,
            judged: used != PatchUse::Fit,
            passes: p.delta_e00 <= criteria.max_patch,
        }
    };
    // A reading out of all range has no ΔE00: counted and left out, not shown as NaN.
    let (scorable, unscorable): (Vec<&PatchError>, Vec<&PatchError>) = evaluation
        .patches
        .iter()
        .partition(|p| p.delta_e00.is_finite());
    let patches: Vec<PatchRow> = scorable
        .into_iter()
        .map(|p| match held_out {
            None => row(p, PatchUse::Verification),
            Some(list) => match list.iter().find(|h| h.index == p.index) {
                Some(h) if h.delta_e00.is_finite() => row(h, PatchUse::HeldOut),
                Some(_) => row(p, PatchUse::HeldOut),
                None => row(p, PatchUse::Fit),
            },
        })
        .collect();
    let judged: Vec<f64> = patches
        .iter()
        .filter(|p| p.judged)
        .map(|p| p.delta_e00)
        .collect();
    let stats = ErrorStats::of(&judged);
    let failing_patches = patches.iter().filter(|p| p.judged && !p.passes).count();
    let itp = criteria.max_mean_itp.and_then(|_| {
        let values: Vec<f64> = patches
            .iter()
            .filter(|p| p.judged)
            .map(|p| chromacal_color::ictcp::delta_e_itp(&p.measured, &p.nominal))
            .collect();
        ErrorStats::of(&values)
    });
    let itp_passes = match criteria.max_mean_itp {
        Some(limit) => itp.as_ref().is_some_and(|s| s.mean <= limit),
        None => true,
    };
    let passes = itp_passes
        && stats.as_ref().is_some_and(|s| {
            s.mean <= criteria.max_mean && s.p95 <= criteria.max_p95 && failing_patches == 0
        });
    let gamut_solid = AdditiveGamut::of_display(&model.matrix, &model.black);
    Verification {
        patches,
        unscorable: unscorable.len(),
        judgement: Judgement {
            criteria: criteria.clone(),
            stats,
            itp,
            failing_patches,
            passes,
        },
        white: white_and_black(model, set),
        volume: gamut_solid.as_ref().and_then(gamut::lab_volume),
        gamut: gamut_solid
            .map(|g| {
                gamut::REFERENCE_SPACES
                    .iter()
                    .filter_map(|space| gamut::compare(&g, space))
                    .collect()
            })
            .unwrap_or_default(),
        greys: grey_steps(model, set),
        uniformity: uniformity_cells(set),
    }
}

/// Mean of the usable readings at the centre on a black surround driven at `drive`.
fn mean_at(set: &MeasurementSet, drive: Drive) -> Option<Xyz> {
    let readings: Vec<Xyz> = set
        .measurements
        .iter()
        .filter(|m| m.drive == drive && m.is_standard_condition())
        .filter_map(|m| m.usable_xyz())
        .collect();
    (!readings.is_empty()).then(|| readings.iter().sum::<Xyz>() / readings.len() as f64)
}

fn white_and_black(model: &MonitorModel, set: &MeasurementSet) -> WhiteAndBlack {
    let measured_white = mean_at(set, [1.0; 3]);
    let measured_black = mean_at(set, [0.0; 3]);
    let white = measured_white.unwrap_or_else(|| model.white());
    let black = measured_black.unwrap_or(model.black);
    let xy = xyz_to_xyy(&white, [0.3127, 0.3290]);
    WhiteAndBlack {
        white,
        white_xy: [xy.x, xy.y],
        white_measured: measured_white.is_some(),
        temperature: xyz_to_cct_duv(&white),
        black,
        black_measured: measured_black.is_some(),
        contrast: (black.y > 0.0).then(|| white.y / black.y),
    }
}

fn delta_uv(a: &Xyz, b: &Xyz) -> f64 {
    let origin = UvPrime { u: 0.0, v: 0.0 };
    let (p, q) = (xyz_to_uv_prime(a, origin), xyz_to_uv_prime(b, origin));
    (p.u - q.u).hypot(p.v - q.v)
}

/// ln(relative) / ln(drive) where both are strictly inside (0, 1).
fn effective_gamma(drive: f64, relative: f64) -> Option<f64> {
    (drive > 0.0 && drive < 1.0 && relative > 0.0).then(|| relative.ln() / drive.ln())
}

/// The greys between black and white, each drive's readings averaged.
fn grey_steps(model: &MonitorModel, set: &MeasurementSet) -> Vec<GreyStep> {
    let white = mean_at(set, [1.0; 3]).unwrap_or_else(|| model.white());
    let black = mean_at(set, [0.0; 3]).unwrap_or(model.black);
    let span = white.y - black.y;
    let model_span = model.white().y - model.black.y;
    let mut drives: Vec<f64> = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition() && m.drive.iter().all(|d| *d == m.drive[0]))
        .map(|m| m.drive[0])
        .filter(|d| *d > 0.0 && *d < 1.0)
        .collect();
    drives.sort_by(f64::total_cmp);
    drives.dedup();
    if !(span > 0.0 && model_span > 0.0) {
        return Vec::new();
    }
    drives
        .into_iter()
        .filter_map(|d| {
            let xyz = mean_at(set, [d; 3])?;
            let relative = (xyz.y - black.y) / span;
            let model_relative = (model.forward_centre([d; 3]).y - model.black.y) / model_span;
            let lab = xyz_to_lab(&xyz, &white);
            Some(GreyStep {
                drive: d,
                luminance: xyz.y,
                relative,
                model_relative,
                effective_gamma: effective_gamma(d, relative),
                model_effective_gamma: effective_gamma(d, model_relative),
                a: lab.a,
                b: lab.b,
                delta_uv: delta_uv(&xyz, &white),
                temperature: xyz_to_cct_duv(&xyz),
            })
        })
        .collect()
}

/// Each uniformity position's readings (mean per position and drive) against the
/// centre's at the same drive.
fn uniformity_cells(set: &MeasurementSet) -> Vec<UniformityCell> {
    let mut groups: Vec<(ScreenPosition, Drive, Xyz, usize)> = Vec::new();
    for m in &set.measurements {
        if m.role != Role::Uniformity || m.background != [0.0; 3] {
            continue;
        }
        let Some(xyz) = m.usable_xyz() else { continue };
        match groups
            .iter_mut()
            .find(|g| g.0 == m.position && g.1 == m.drive)
        {
            Some(g) => {
                g.2 += xyz;
                g.3 += 1;
            }
            None => groups.push((m.position, m.drive, xyz, 1)),
        }
    }
    // Row by row, top first, as the screen reads.
    groups.sort_by(|a, b| a.0.y.total_cmp(&b.0.y).then(a.0.x.total_cmp(&b.0.x)));
    groups
        .into_iter()
        .filter_map(|(position, drive, sum, n)| {
            let centre = mean_at(set, drive)?;
            let xyz = sum / n as f64;
            (centre.y > 0.0).then(|| UniformityCell {
                position,
                drive,
                luminance_percent: 100.0 * xyz.y / centre.y,
                delta_uv: delta_uv(&xyz, &centre),
                delta_e00: delta_e_2000(&xyz_to_lab(&xyz, &centre), &xyz_to_lab(&centre, &centre)),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pure_hue_shift_is_all_delta_h() {
        let reference = Lab {
            l: 50.0,
            a: 30.0,
            b: 0.0,
        };
        let turned = Lab {
            l: 50.0,
            a: 0.0,
            b: 30.0,
        };
        let (dl, dc, dh) = lab_differences(&reference, &turned);
        assert!(dl.abs() < 1e-12 && dc.abs() < 1e-12, "{dl} {dc}");
        // ΔE*ab² = ΔL² + ΔC² + ΔH² (CIE 15:2004 eq. 8.10).
        assert!((dh - 30.0 * 2.0_f64.sqrt()).abs() < 1e-9, "{dh}");
        assert!(lab_differences(&turned, &reference).2 < 0.0);
    }

    #[test]
    fn a_hue_difference_across_zero_is_the_short_way_round() {
        let at = |h: f64| Lab {
            l: 50.0,
            a: 20.0 * h.to_radians().cos(),
            b: 20.0 * h.to_radians().sin(),
        };
        // 350° to 10°: +20° of hue, not −340°.
        let (_, dc, dh) = lab_differences(&at(350.0), &at(10.0));
        assert!(dc.abs() < 1e-9, "{dc}");
        assert!(
            (dh - 2.0 * 20.0 * 10.0_f64.to_radians().sin()).abs() < 1e-9,
            "{dh}"
        );
        assert!(lab_differences(&at(10.0), &at(350.0)).2 < 0.0);
    }

    #[test]
    fn a_threshold_alone_states_only_its_mean() {
        let c = Criteria::verification_threshold(1.5);
        assert_eq!(
            c.describe(),
            "the verification threshold ([schedule] threshold_de00): mean ΔE00 ≤ 1.5"
        );
    }

    #[test]
    fn criteria_from_presets_and_limits_and_bad_ones_named() {
        let strict: Criteria = "strict".parse().unwrap();
        assert_eq!(
            (strict.max_mean, strict.max_p95, strict.max_patch),
            (0.5, 1.0, 2.0)
        );
        let given: Criteria = "mean=0.8, max=3".parse().unwrap();
        assert_eq!(
            (given.max_mean, given.max_p95, given.max_patch),
            (0.8, 2.0, 3.0)
        );
        let e = "tight".parse::<Criteria>().unwrap_err();
        assert!(e.contains("strict, nominal, loose"), "{e}");
        let e = "mean=-1".parse::<Criteria>().unwrap_err();
        assert!(e.contains("mean must be a positive number"), "{e}");
        let e = "avg=1".parse::<Criteria>().unwrap_err();
        assert!(e.contains("no limit 'avg'"), "{e}");
        assert_eq!(Criteria::default().max_patch, 4.0);
    }

    #[test]
    fn effective_gamma_of_a_power_law_is_its_exponent() {
        let g = effective_gamma(0.5, 0.5_f64.powf(2.2)).unwrap();
        assert!((g - 2.2).abs() < 1e-12);
        assert!(effective_gamma(1.0, 1.0).is_none());
        assert!(effective_gamma(0.5, 0.0).is_none());
    }
}
