//! The readings of a chart judged: each patch's ΔE against its reference and against
//! the profile's prediction, the calibrated state (white, black, contrast, grey
//! balance, tone), and every criterion's value with its 95 % interval and verdict.
//!
//! The intervals are a parametric bootstrap. A reading's noise has three parts, all
//! from the session's own repeats pooled with the fit's priors
//! (`fit::noise::estimate_noise`): a gain common to X, Y and Z (which moves the
//! luminance, not the chromaticity), a relative noise of each component on its own
//! (from the scatter of the white's X/Y and Z/Y), and a floor (from the black's
//! scatter); a patch read n times has each divided by √n. The readings are drawn
//! [`DRAWS`] times within that noise (seeded) and every statistic computed on each
//! draw. Noise makes a colour difference larger on average, so the interval is the
//! basic bootstrap's, [2v − q97.5, 2v − q2.5] for a value v and the draws' quantiles
//! q, which takes that bias back out; it never reaches below 0, and never ends below
//! v (a value measured above a limit never passes it).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::Serialize;

use chromacal_color::ictcp::{delta_e_itp, xyz_to_ictcp};
use chromacal_color::spaces::{xyz_to_uv_prime, xyz_to_xyy};
use chromacal_color::temperature::xyz_to_cct_duv;
use chromacal_color::{Lab, UvPrime, Xyz, delta_e_2000, xyz_to_lab};
use chromacal_model::fit::noise::{NoiseModel, estimate_noise};
use chromacal_model::fit::stats::percentile;

use super::criteria::{CriteriaSet, Statistic, Verdict};
use super::{Kind, Metric, PlannedPatch, Readings};

/// Draws of the readings for the intervals.
pub const DRAWS: usize = 400;
/// Greys darker than this share of the white's luminance are left out of grey
/// balance (DisplayCAL's "≥ 1 % luminance").
const GREY_BALANCE_FLOOR: f64 = 0.01;

/// One patch, judged.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct PatchResult {
    pub label: String,
    pub kind: Kind,
    /// The codes sent, at their bit depth.
    pub codes: [u32; 3],
    pub bit_depth: u32,
    pub reference: [f64; 3],
    pub predicted: [f64; 3],
    /// The mean of its readings.
    pub measured: [f64; 3],
    pub reads: usize,
    /// Against the reference, in the chosen metric, with its 95 % interval.
    pub delta_e: f64,
    pub interval: [f64; 2],
    /// Against the profile's prediction (the same metric).
    pub delta_e_to_profile: f64,
    /// CIELAB of the measured colour and of the reference, against the calibrated white.
    pub lab: [f64; 3],
    pub reference_lab: [f64; 3],
    /// The colour asked for lay outside what the display can show: the reference is
    /// the nearest colour it can, and `asked` the colour asked for.
    pub outside: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub asked: Option<[f64; 3]>,
    /// Against the largest-ΔE criterion, when the set has one.
    pub verdict: Option<Verdict>,
}

/// A grey's balance against the measured white.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct GreyBalance {
    pub label: String,
    pub luminance: f64,
    pub a: f64,
    pub b: f64,
    /// CIEDE2000's weighted chroma difference from the neutral of the same L*
    /// (|ΔC′| / S_C), or the CtCp distance for ΔE ITP.
    pub delta_c: f64,
    /// Distance in u′v′ from the white's chromaticity.
    pub delta_uv: f64,
}

/// A grey of the calibration against the target's tone curve.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct ToneLevel {
    pub input: f64,
    pub target: f64,
    pub measured: f64,
}

/// The display as measured through what it holds.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct CalibratedState {
    pub white: [f64; 3],
    pub luminance: f64,
    pub xy: [f64; 2],
    pub cct_k: Option<f64>,
    pub duv: Option<f64>,
    /// The target white (the calibration's, else the profile's native one).
    pub target_white: [f64; 3],
    /// Between the measured and the target white (the verification's metric), with
    /// its 95 % interval.
    pub white_delta_e: f64,
    pub white_interval: [f64; 2],
    pub black: [f64; 3],
    pub black_luminance: f64,
    pub contrast: Option<f64>,
    pub greys: Vec<GreyBalance>,
    /// Mean of the greys' chroma, and the ranges of a* and b* together.
    pub grey_balance_mean: f64,
    pub grey_balance_range: f64,
    pub tone: Vec<ToneLevel>,
    /// Largest |measured / target − 1| over the calibration greys.
    pub tone_error: f64,
}

/// One criterion, judged.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct CriterionResult {
    pub statistic: Statistic,
    pub description: String,
    pub limit: f64,
    pub value: f64,
    pub interval: [f64; 2],
    pub verdict: Verdict,
}

/// A whole verification.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct VerifyReport {
    pub chart: String,
    pub against: String,
    pub metric: Metric,
    pub criteria: String,
    pub patches: Vec<PatchResult>,
    pub state: CalibratedState,
    pub results: Vec<CriterionResult>,
    pub verdict: Verdict,
    /// The relative noise and floor the intervals rest on, and where they came from.
    pub noise: NoiseModel,
    /// The part of the relative noise that moves each of X, Y, Z on its own.
    pub independent_noise: f64,
    /// The instrument, the correction its readings went through, or the warning that
    /// a colorimeter had none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub instrument: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction: Option<crate::profile::CorrectionRecord>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrected: Option<String>,
    /// Whether the chart's colours went through the model corrected by the
    /// calibration's measured greys, as `lut3d` sends them, and why (or why not).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub greys: Option<String>,
    pub readings: usize,
    pub instrument_s: f64,
    /// The screen's uniformity, where it was measured (`verify --uniformity`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uniformity: Option<super::uniformity::Uniformity>,
}

/// The colour difference `metric` measures between `a` and `b`; CIELAB against `white`.
fn difference(metric: Metric, a: &Xyz, b: &Xyz, white: &Xyz) -> f64 {
    match metric {
        Metric::De00 => delta_e_2000(&xyz_to_lab(a, white), &xyz_to_lab(b, white)),
        Metric::Itp => delta_e_itp(a, b),
    }
}

/// A grey's chroma against `white`: CIEDE2000's weighted chroma difference from the
/// neutral of its L* (CIE 142:2001 eq. 5 and 15 with C′ = 0 for the neutral), or its
/// distance from the white's Ct, Cp (BT.2124's T = Ct / 2, P = Cp, × 720).
pub fn grey_chroma(metric: Metric, grey: &Xyz, white: &Xyz) -> (f64, [f64; 2]) {
    match metric {
        Metric::De00 => {
            let lab = xyz_to_lab(grey, white);
            let c = lab.a.hypot(lab.b);
            let c7 = (c / 2.0).powi(7);
            let g = 0.5 * (1.0 - (c7 / (c7 + 6_103_515_625.0)).sqrt());
            let c_prime = ((1.0 + g) * lab.a).hypot(lab.b);
            let s_c = 1.0 + 0.045 * c_prime / 2.0;
            (c_prime / s_c, [lab.a, lab.b])
        }
        Metric::Itp => {
            // The grey's chroma against the white's, at the grey's own intensity.
            let [_, ct, cp] = xyz_to_ictcp(grey);
            let [_, ct_w, cp_w] = xyz_to_ictcp(white);
            let (t, p) = (0.5 * (ct - ct_w) * 720.0, (cp - cp_w) * 720.0);
            (t.hypot(p), [t, p])
        }
    }
}

/// Every statistic of one set of patch colours (the measured means, or one draw).
struct Statistics {
    delta_e: Vec<f64>,
    white_to_target: f64,
    white_to_profile: f64,
    mean: f64,
    max: f64,
    percentile99: f64,
    grey_mean: f64,
    grey_range: f64,
    tone: f64,
}

struct Judge<'a> {
    planned: &'a [PlannedPatch],
    metric: Metric,
    /// The calibrated white CIELAB is taken against.
    white: Xyz,
    whites: Vec<usize>,
    greys: Vec<usize>,
    /// The calibration greys (and the white) judged for the tone curve.
    tone: Vec<usize>,
    judged: Vec<usize>,
}

impl Judge<'_> {
    fn statistics(&self, colours: &[Xyz]) -> Statistics {
        let delta_e: Vec<f64> = self
            .planned
            .iter()
            .zip(colours)
            .map(|(p, m)| difference(self.metric, m, &Xyz::from(p.reference), &self.white))
            .collect();
        let measured_white = mean_of(colours, &self.whites).unwrap_or(self.white);
        let judged: Vec<f64> = self.judged.iter().map(|&i| delta_e[i]).collect();
        let predicted_white = self
            .whites
            .first()
            .map_or(self.white, |&i| Xyz::from(self.planned[i].predicted));
        let mut grey_chroma_values = Vec::new();
        let mut ab_range = (f64::MAX, f64::MIN);
        for &i in &self.greys {
            if colours[i].y < GREY_BALANCE_FLOOR * measured_white.y {
                continue;
            }
            let (c, [a, b]) = grey_chroma(self.metric, &colours[i], &measured_white);
            grey_chroma_values.push(c);
            ab_range = (ab_range.0.min(a).min(b), ab_range.1.max(a).max(b));
        }
        Statistics {
            white_to_target: difference(self.metric, &measured_white, &self.white, &self.white),
            white_to_profile: difference(
                self.metric,
                &measured_white,
                &predicted_white,
                &self.white,
            ),
            mean: mean(&judged),
            max: judged.iter().copied().fold(0.0, f64::max),
            percentile99: if judged.is_empty() {
                0.0
            } else {
                percentile(&judged, 99.0)
            },
            grey_mean: mean(&grey_chroma_values),
            grey_range: if ab_range.1 >= ab_range.0 {
                ab_range.1 - ab_range.0
            } else {
                0.0
            },
            tone: self
                .tone
                .iter()
                .map(|&i| {
                    let target = self.planned[i].reference[1];
                    100.0 * (colours[i].y / target - 1.0).abs()
                })
                .fold(0.0, f64::max),
            delta_e,
        }
    }
}

fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        0.0
    } else {
        values.iter().sum::<f64>() / values.len() as f64
    }
}

fn mean_of(colours: &[Xyz], indices: &[usize]) -> Option<Xyz> {
    (!indices.is_empty())
        .then(|| indices.iter().map(|&i| colours[i]).sum::<Xyz>() / indices.len() as f64)
}

/// The basic bootstrap's 95 % interval of `value` from its `draws`, kept at or above
/// 0 and with its top at or above the value.
fn interval(draws: &mut [f64], value: f64) -> [f64; 2] {
    if draws.is_empty() {
        return [value, value];
    }
    let lo = percentile(draws, 2.5);
    let hi = percentile(draws, 97.5);
    [
        (2.0 * value - hi).max(0.0).min(value),
        (2.0 * value - lo).max(value),
    ]
}

/// The instrument's noise in this session, and the share of its relative noise that
/// moves each component on its own.
struct SessionNoise {
    model: NoiseModel,
    /// Relative noise of each component alone; the rest of `model.relative` is a
    /// gain common to all three.
    independent: f64,
}

impl SessionNoise {
    /// `value` (one reading's mean over `n`) drawn once within the noise, given the
    /// common gain's standard normal draw `g` and the components' `z`.
    fn draw(&self, value: &Xyz, n: f64, g: f64, z: [f64; 3]) -> Xyz {
        let gain = (self.model.relative.powi(2) - self.independent.powi(2))
            .max(0.0)
            .sqrt();
        let scale = 1.0 / n.sqrt();
        let mut out = *value * (1.0 + gain * scale * g);
        for c in 0..3 {
            let sigma = (self.model.floor.powi(2) + (self.independent * value[c]).powi(2)).sqrt();
            out[c] += sigma * scale * z[c];
        }
        out
    }
}

/// The relative noise of each component alone: the scatter of ln(X/Y) and ln(Z/Y)
/// over the white's readings is √2 times it, pooled with a prior of half the assumed
/// relative variance worth two readings, as the fit pools the relative noise.
fn independent_noise(whites: &[Xyz]) -> f64 {
    use chromacal_model::fit::noise::{ASSUMED_RELATIVE_NOISE, PRIOR_DEGREES_OF_FREEDOM};
    let prior = ASSUMED_RELATIVE_NOISE / 2f64.sqrt();
    let ratios: Vec<[f64; 2]> = whites
        .iter()
        .filter(|w| w.iter().all(|v| *v > 0.0))
        .map(|w| [(w.x / w.y).ln(), (w.z / w.y).ln()])
        .collect();
    if ratios.len() < 2 {
        return prior;
    }
    let n = ratios.len() as f64;
    let mut sum_squares = 0.0;
    for k in 0..2 {
        let m = ratios.iter().map(|r| r[k]).sum::<f64>() / n;
        sum_squares += ratios.iter().map(|r| (r[k] - m).powi(2)).sum::<f64>();
    }
    let dof = 2.0 * (n - 1.0);
    let s2 = sum_squares / dof / 2.0;
    ((dof * s2 + PRIOR_DEGREES_OF_FREEDOM * prior * prior) / (dof + PRIOR_DEGREES_OF_FREEDOM))
        .sqrt()
}

/// The instrument's noise in this session: the white's relative scatter and the
/// black's, pooled with the prior the fit uses.
fn session_noise(planned: &[PlannedPatch], readings: &Readings) -> SessionNoise {
    let of_kind = |kind: Kind| -> Vec<f64> {
        planned
            .iter()
            .zip(&readings.xyz)
            .filter(|(p, _)| p.patch.kind == kind)
            .flat_map(|(_, reads)| reads.iter().map(|x| x.y))
            .collect()
    };
    let whites = of_kind(Kind::White);
    let blacks = of_kind(Kind::Black);
    let white_y = mean(&whites);
    let relative = (whites.len() >= 2 && white_y > 0.0).then(|| {
        let var =
            whites.iter().map(|y| (y - white_y).powi(2)).sum::<f64>() / (whites.len() - 1) as f64;
        (var.sqrt() / white_y, whites.len() - 1)
    });
    let model = estimate_noise(relative, &blacks, white_y);
    let white_readings: Vec<Xyz> = planned
        .iter()
        .zip(&readings.xyz)
        .filter(|(p, _)| p.patch.kind == Kind::White)
        .flat_map(|(_, reads)| reads.iter().copied())
        .collect();
    let independent = independent_noise(&white_readings).min(model.relative);
    SessionNoise { model, independent }
}

/// Judge `readings` of the `planned` chart by `criteria` in `metric`.
pub fn evaluate(
    planned: &[PlannedPatch],
    readings: &Readings,
    metric: Metric,
    criteria: &CriteriaSet,
    white: Xyz,
    chart: &str,
    against: &str,
) -> Result<VerifyReport, String> {
    let measured: Vec<Xyz> = (0..planned.len())
        .map(|i| readings.mean(i).ok_or("a patch has no reading"))
        .collect::<Result<_, _>>()?;
    let index_of = |kind: Kind| -> Vec<usize> {
        planned
            .iter()
            .enumerate()
            .filter(|(_, p)| p.patch.kind == kind)
            .map(|(i, _)| i)
            .collect()
    };
    let whites = index_of(Kind::White);
    let blacks = index_of(Kind::Black);
    if whites.is_empty() {
        return Err("the chart has no white: the calibrated state needs one".into());
    }
    let greys: Vec<usize> = planned
        .iter()
        .enumerate()
        .filter(|(_, p)| matches!(p.patch.kind, Kind::Grey | Kind::EncodedGrey))
        .map(|(i, _)| i)
        .collect();
    // Every patch counts for the ΔE statistics, the white and the black once each.
    let mut judged: Vec<usize> = (0..planned.len())
        .filter(|i| !whites.contains(i) && !blacks.contains(i))
        .collect();
    judged.extend(whites.first());
    judged.extend(blacks.first());
    judged.sort_unstable();
    let judge = Judge {
        planned,
        metric,
        white,
        whites: whites.clone(),
        greys: greys.clone(),
        tone: planned
            .iter()
            .enumerate()
            .filter(|(_, p)| {
                matches!(p.patch.kind, Kind::Grey | Kind::White)
                    && p.reference[1] >= GREY_BALANCE_FLOOR * white.y
            })
            .map(|(i, _)| i)
            .collect(),
        judged,
    };
    let value = judge.statistics(&measured);
    // The draws.
    let noise = session_noise(planned, readings);
    let mut rng = ChaCha8Rng::seed_from_u64(0x7e21_f1ed);
    let standard = Normal::new(0.0, 1.0).map_err(|e| e.to_string())?;
    let draws: Vec<Statistics> = (0..DRAWS)
        .map(|_| {
            let colours: Vec<Xyz> = measured
                .iter()
                .zip(&readings.xyz)
                .map(|(m, reads)| {
                    let n = reads.len().max(1) as f64;
                    let g = standard.sample(&mut rng);
                    let z = [0, 1, 2].map(|_| standard.sample(&mut rng));
                    noise.draw(m, n, g, z)
                })
                .collect();
            judge.statistics(&colours)
        })
        .collect();
    let column = |f: &dyn Fn(&Statistics) -> f64, v: f64| {
        let mut values: Vec<f64> = draws.iter().map(f).collect();
        interval(&mut values, v)
    };
    let results: Vec<CriterionResult> = criteria
        .criteria
        .iter()
        .map(|c| {
            let pick: &dyn Fn(&Statistics) -> f64 = match c.statistic {
                Statistic::WhiteToTarget => &|s| s.white_to_target,
                Statistic::WhiteToProfile => &|s| s.white_to_profile,
                Statistic::Mean => &|s| s.mean,
                Statistic::Max => &|s| s.max,
                Statistic::Percentile99 => &|s| s.percentile99,
                Statistic::GreyBalanceMean => &|s| s.grey_mean,
                Statistic::GreyBalanceRange => &|s| s.grey_range,
                Statistic::Tone => &|s| s.tone,
            };
            let v = pick(&value);
            let iv = column(pick, v);
            CriterionResult {
                statistic: c.statistic,
                description: c.statistic.describe().to_string(),
                limit: c.limit,
                value: v,
                interval: iv,
                verdict: Verdict::of(iv, c.limit),
            }
        })
        .collect();
    let max_limit = criteria
        .criteria
        .iter()
        .filter(|c| c.statistic == Statistic::Max)
        .map(|c| c.limit)
        .reduce(f64::min);
    let patches: Vec<PatchResult> = planned
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let iv = column(&|s| s.delta_e[i], value.delta_e[i]);
            let m = measured[i];
            let lab = |x: &Xyz| -> [f64; 3] {
                let Lab { l, a, b } = xyz_to_lab(x, &white);
                [l, a, b]
            };
            PatchResult {
                label: p.patch.label.clone(),
                kind: p.patch.kind,
                codes: p.codes.rgb,
                bit_depth: p.codes.bit_depth,
                reference: p.reference,
                predicted: p.predicted,
                measured: m.into(),
                reads: readings.xyz[i].len(),
                delta_e: value.delta_e[i],
                interval: iv,
                delta_e_to_profile: difference(metric, &m, &Xyz::from(p.predicted), &white),
                lab: lab(&m),
                reference_lab: lab(&Xyz::from(p.reference)),
                outside: p.outside,
                asked: p.asked,
                verdict: max_limit.map(|limit| Verdict::of(iv, limit)),
            }
        })
        .collect();
    let state = calibrated_state(
        planned,
        &measured,
        &whites,
        &blacks,
        &greys,
        metric,
        white,
        (
            value.white_to_target,
            column(&|s| s.white_to_target, value.white_to_target),
        ),
        (value.grey_mean, value.grey_range),
    );
    Ok(VerifyReport {
        chart: chart.to_string(),
        against: against.to_string(),
        metric,
        criteria: criteria.describe(metric),
        verdict: Verdict::all(results.iter().map(|r| r.verdict)),
        patches,
        state,
        results,
        noise: noise.model,
        independent_noise: noise.independent,
        instrument: None,
        correction: None,
        uncorrected: None,
        greys: None,
        readings: readings.count(),
        instrument_s: readings.instrument_s,
        uniformity: None,
    })
}

#[allow(clippy::too_many_arguments)]
fn calibrated_state(
    planned: &[PlannedPatch],
    measured: &[Xyz],
    whites: &[usize],
    blacks: &[usize],
    greys: &[usize],
    metric: Metric,
    target_white: Xyz,
    (white_de, white_interval): (f64, [f64; 2]),
    (grey_mean, grey_range): (f64, f64),
) -> CalibratedState {
    let white = mean_of(measured, whites).unwrap_or(target_white);
    let black = mean_of(measured, blacks).unwrap_or_else(Xyz::zeros);
    let xyy = xyz_to_xyy(&white, [0.3127, 0.3290]);
    let temperature = xyz_to_cct_duv(&white);
    let white_uv = xyz_to_uv_prime(&white, UvPrime { u: 0.0, v: 0.0 });
    let greys_out: Vec<GreyBalance> = greys
        .iter()
        .filter(|&&i| measured[i].y >= GREY_BALANCE_FLOOR * white.y)
        .map(|&i| {
            let m = measured[i];
            let (delta_c, [a, b]) = grey_chroma(metric, &m, &white);
            let uv = xyz_to_uv_prime(&m, white_uv);
            GreyBalance {
                label: planned[i].patch.label.clone(),
                luminance: m.y,
                a,
                b,
                delta_c,
                delta_uv: (uv.u - white_uv.u).hypot(uv.v - white_uv.v),
            }
        })
        .collect();
    let tone: Vec<ToneLevel> = planned
        .iter()
        .zip(measured)
        .filter(|(p, _)| matches!(p.patch.kind, Kind::Grey | Kind::White))
        .map(|(p, m)| ToneLevel {
            input: p.application[0],
            target: p.reference[1],
            measured: m.y,
        })
        .collect();
    let tone_error = tone
        .iter()
        .filter(|t| t.target > 0.0)
        .map(|t| (t.measured / t.target - 1.0).abs())
        .fold(0.0, f64::max);
    CalibratedState {
        white: white.into(),
        luminance: white.y,
        xy: [xyy.x, xyy.y],
        cct_k: temperature.map(|t| t.cct_k),
        duv: temperature.map(|t| t.duv),
        target_white: target_white.into(),
        white_delta_e: white_de,
        white_interval,
        black: black.into(),
        black_luminance: black.y,
        contrast: (black.y > 0.0).then(|| white.y / black.y),
        greys: greys_out,
        grey_balance_mean: grey_mean,
        grey_balance_range: grey_range,
        tone,
        tone_error,
    }
}
