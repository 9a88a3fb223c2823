//! Tests of the assumptions the monitor model rests on (Brainard 1989), each reported
//! with its figure, the figure noise alone would give, and a verdict:
//!
//! * primary constancy: a channel's chromaticity (u′v′) at every level it was measured,
//!   against full drive; and, where spectra exist, how much of the ramp's spectra one
//!   spectral shape explains (first singular value of the normalised spectra);
//! * additivity: each grey against the sum of its channels measured alone at the same
//!   drive, and white against the sum of the primaries (no model involved), in each of
//!   X, Y and Z against its noise, with the ΔE00 the departure costs;
//! * spatial independence: the same patch on a black and on a white surround;
//! * temporal stability: the drift of the reference white (see `noise`);
//! * monotonicity: levels whose excitation falls below a dimmer level's by more than
//!   the noise.
//!
//! Verdicts: within noise; beyond noise but below visibility (ΔE00 < 1 or Δu′v′ below
//! 0.004, about one just-noticeable difference); or failed.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::noise::{DriftReport, NoiseModel};
use super::primaries::{ChannelRamp, Corrected};
use super::validate::delta_e00_xyz;
use crate::CHANNELS;
use crate::measurement::Role;
use chromacal_color::Xyz;
use chromacal_color::spaces::{UvPrime, xyz_to_uv_prime};

/// Δu′v′ of about one just-noticeable difference.
pub const UV_VISIBILITY: f64 = 0.004;
/// ΔE00 below which a departure is taken as not visible.
pub const DE00_VISIBILITY: f64 = 1.0;

/// How an assumption fared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// The departure is within what noise explains.
    WithinNoise,
    /// Real, but too small to see.
    BelowVisibility,
    Fails,
    /// Nothing was measured to test it.
    NotMeasured,
}

impl Verdict {
    fn judge(within_noise: bool, below_visibility: bool) -> Verdict {
        if within_noise {
            Verdict::WithinNoise
        } else if below_visibility {
            Verdict::BelowVisibility
        } else {
            Verdict::Fails
        }
    }

    /// The worst of several verdicts (not-measured counts as nothing).
    fn worst(verdicts: impl IntoIterator<Item = Verdict>) -> Verdict {
        let rank = |v: &Verdict| match v {
            Verdict::NotMeasured => 0,
            Verdict::WithinNoise => 1,
            Verdict::BelowVisibility => 2,
            Verdict::Fails => 3,
        };
        verdicts
            .into_iter()
            .max_by_key(rank)
            .unwrap_or(Verdict::NotMeasured)
    }
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Verdict::WithinNoise => "holds (within noise)",
            Verdict::BelowVisibility => "departs, below visibility",
            Verdict::Fails => "FAILS",
            Verdict::NotMeasured => "not measured",
        })
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelConstancy {
    pub channel: String,
    /// Levels bright enough for a chromaticity (≥ 50 σ above black).
    pub levels: usize,
    /// Largest Δu′v′ from full drive.
    pub max_delta_uv: f64,
    /// What noise alone would give at the dimmest level used (3σ).
    pub noise_delta_uv: f64,
    /// Fraction of the ramp's spectral energy in its first singular vector.
    pub spectral_first_component: Option<f64>,
    /// What assuming constancy costs: the largest ΔE00 between a level's reading and
    /// the same luminance at full drive's chromaticity. Absent from profiles made
    /// before it was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_e00: Option<f64>,
    pub verdict: Verdict,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GreyAdditivity {
    pub drive: f64,
    /// ΔE00 between the grey and the sum of its channels.
    pub delta_e00: f64,
    /// Grey luminance over the sum of the channels' luminances, minus one, percent.
    pub luminance_departure_percent: f64,
    /// The same for X, Y and Z, each above black: a display can add up in luminance
    /// and still fall short in Z. Absent from profiles made before it was judged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub xyz_departure_percent: Option<[f64; 3]>,
    /// The grey's X, Y and Z above black over what the greys measured on either side
    /// give at its drive (`between_neighbours`), minus one, percent. A grey reading
    /// that is off on its own departs from its neighbours as it departs from its
    /// channels; what the display does (crosstalk, a limiter) moves the greys
    /// together. Absent without a grey on both sides.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub neighbour_departure_percent: Option<[f64; 3]>,
    pub verdict: Verdict,
}

impl GreyAdditivity {
    /// Whether this grey's departure from its channels looks like a reading off on its
    /// own: in the component (X, Y or Z) where it departs most from its channels, it
    /// departs from its neighbouring greys the same way by half as much or more.
    /// Unknown (no neighbours) counts as not.
    pub fn stands_alone(&self) -> bool {
        let (Some(channels), Some(neighbours)) =
            (self.xyz_departure_percent, self.neighbour_departure_percent)
        else {
            return false;
        };
        let j = (0..3)
            .max_by(|a, b| channels[*a].abs().total_cmp(&channels[*b].abs()))
            .unwrap_or(1);
        channels[j] * neighbours[j] > 0.0 && neighbours[j].abs() >= 0.5 * channels[j].abs()
    }
}

/// X, Y and Z above black at `level` as the greys on either side give them: the
/// nearest measured level below and above, each component interpolated linearly in
/// log light over log drive (a power law's straight line). `greys` holds (drive,
/// XYZ above black), sorted by drive. `None` without a grey with light in all three
/// on both sides.
pub fn between_neighbours(greys: &[(f64, Xyz)], level: f64) -> Option<Xyz> {
    let lit = |g: &&(f64, Xyz)| g.0 > 0.0 && g.1.iter().all(|v| *v > 0.0);
    let below = greys.iter().filter(lit).rfind(|g| g.0 < level)?;
    let above = greys.iter().filter(lit).find(|g| g.0 > level)?;
    let t = (level.ln() - below.0.ln()) / (above.0.ln() - below.0.ln());
    Some(
        below
            .1
            .zip_map(&above.1, |b, a| (b.ln() * (1.0 - t) + a.ln() * t).exp()),
    )
}

/// `above_black` over what the greys on either side give at `level`, minus one, in
/// percent, for X, Y and Z (`GreyAdditivity::neighbour_departure_percent`).
fn neighbour_departure(greys: &[(f64, Xyz)], level: f64, above_black: Xyz) -> Option<[f64; 3]> {
    let between = between_neighbours(greys, level)?;
    Some([0, 1, 2].map(|j| (above_black[j] / between[j] - 1.0) * 100.0))
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurroundCheck {
    pub delta_e00: f64,
    /// Luminance on white surround over on black, minus one, percent.
    pub luminance_change_percent: f64,
    pub noise_percent: f64,
    pub verdict: Verdict,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelMonotonicity {
    pub channel: String,
    /// Level pairs where the brighter drive gave less light by more than 3σ.
    pub reversals_beyond_noise: usize,
    pub verdict: Verdict,
}

/// All assumption checks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssumptionChecks {
    pub primary_constancy: Vec<ChannelConstancy>,
    pub primary_constancy_verdict: Verdict,
    pub additivity: Vec<GreyAdditivity>,
    pub additivity_verdict: Verdict,
    pub spatial_independence: Option<SurroundCheck>,
    pub spatial_independence_verdict: Verdict,
    pub temporal_stability: DriftReport,
    pub temporal_stability_verdict: Verdict,
    pub monotonicity: Vec<ChannelMonotonicity>,
    pub monotonicity_verdict: Verdict,
}

/// Mean XYZ of the readings of one drive among `readings`.
fn mean_at<'a>(readings: impl Iterator<Item = &'a Corrected<'a>>) -> Option<(Xyz, usize)> {
    let v: Vec<Xyz> = readings.map(|r| r.xyz).collect();
    (!v.is_empty()).then(|| (v.iter().sum::<Xyz>() / v.len() as f64, v.len()))
}

fn primary_constancy(
    ramps: &[ChannelRamp; 3],
    readings: &[Corrected<'_>],
    black: &Xyz,
    black_spectrum: Option<&[f64]>,
    noise: &NoiseModel,
    white: &Xyz,
) -> Vec<ChannelConstancy> {
    ramps
        .iter()
        .map(|ramp| {
            let full_above = ramp.column(1.0);
            let reference = xyz_to_uv_prime(&full_above, UvPrime { u: 0.0, v: 0.0 });
            let mut max_delta: f64 = 0.0;
            let mut max_cost: f64 = 0.0;
            let mut noise_at_dimmest: f64 = 0.0;
            let mut levels = 0;
            for level in ramp.levels() {
                let at: Vec<_> = ramp.points.iter().filter(|p| p.drive == level).collect();
                let above = at.iter().map(|p| p.xyz - black).sum::<Xyz>() / at.len() as f64;
                let sigma = noise.sigma(above.y + black.y) / (at.len() as f64).sqrt();
                if above.y < 50.0 * sigma {
                    continue;
                }
                levels += 1;
                let uv = xyz_to_uv_prime(&above, reference);
                max_delta = max_delta.max((uv.u - reference.u).hypot(uv.v - reference.v));
                let constant = full_above * (above.y / full_above.y);
                max_cost =
                    max_cost.max(delta_e00_xyz(&(black + above), &(black + constant), white));
                // Relative errors of the tristimulus values move u′v′ by about their size
                // times the chromaticity (≈ 0.5); three standard deviations, two readings.
                let relative = sigma / above.y.max(f64::MIN_POSITIVE);
                noise_at_dimmest = noise_at_dimmest.max(3.0 * 0.5 * relative * 2f64.sqrt());
            }
            let spectral_first_component = black_spectrum.and_then(|bs| {
                let spectra: Vec<Vec<f64>> = ramp
                    .points
                    .iter()
                    .filter_map(|p| {
                        let m = readings.iter().find(|r| r.measurement.index == p.index)?;
                        let s = m.measurement.reading.spectrum.as_ref()?;
                        let above: Vec<f64> =
                            s.values().iter().zip(bs).map(|(v, b)| v - b).collect();
                        let norm = above.iter().map(|v| v * v).sum::<f64>().sqrt();
                        (norm > 0.0 && s.values().len() == bs.len() && p.excitation > 0.05)
                            .then(|| above.iter().map(|v| v / norm).collect())
                    })
                    .collect();
                if spectra.len() < 2 {
                    return None;
                }
                let rows = spectra[0].len();
                let m = DMatrix::from_fn(rows, spectra.len(), |i, j| spectra[j][i]);
                let sv = chromacal_color::linalg::bounded_svd(m)?.singular_values;
                let total: f64 = sv.iter().map(|s| s * s).sum();
                (total > 0.0).then(|| sv.max().powi(2) / total)
            });
            ChannelConstancy {
                channel: CHANNELS[ramp.channel].into(),
                levels,
                max_delta_uv: max_delta,
                noise_delta_uv: noise_at_dimmest,
                spectral_first_component,
                delta_e00: Some(max_cost),
                verdict: if levels < 2 {
                    Verdict::NotMeasured
                } else {
                    Verdict::judge(
                        max_delta <= noise_at_dimmest.max(1e-4),
                        max_delta < UV_VISIBILITY,
                    )
                },
            }
        })
        .collect()
}

fn additivity(
    readings: &[Corrected<'_>],
    black: &Xyz,
    noise: &NoiseModel,
    white_reference: &Xyz,
) -> Vec<GreyAdditivity> {
    let standard = |r: &&Corrected<'_>| r.measurement.is_standard_condition();
    let mut levels: Vec<f64> = readings
        .iter()
        .filter(standard)
        .filter(|r| matches!(r.measurement.role, Role::Grey | Role::Reference))
        .map(|r| r.measurement.drive)
        .filter(|d| d[0] == d[1] && d[1] == d[2] && d[0] > 0.0)
        .map(|d| d[0])
        .collect();
    levels.sort_by(|a, b| a.total_cmp(b));
    levels.dedup();
    let grey_at = |level: f64| {
        mean_at(
            readings
                .iter()
                .filter(standard)
                .filter(|r| r.measurement.drive == [level; 3]),
        )
    };
    let greys: Vec<(f64, Xyz)> = levels
        .iter()
        .filter_map(|level| Some((*level, grey_at(*level)?.0 - black)))
        .collect();
    levels
        .into_iter()
        .filter_map(|level| {
            let (grey, n_grey) = grey_at(level)?;
            let mut sum = *black;
            let mut worst_n = usize::MAX;
            for c in 0..3 {
                let mut d = [0.0; 3];
                d[c] = level;
                let (channel, n) = mean_at(
                    readings
                        .iter()
                        .filter(standard)
                        .filter(|r| r.measurement.drive == d),
                )?;
                sum += channel - black;
                worst_n = worst_n.min(n);
            }
            // Each of X, Y, Z above black: the grey's over the channels' sum, against
            // the noise of that ratio (the grey's, the three channels' and the black's
            // noise, the noise model read at each tristimulus value). A value with no
            // light above black (a channel's Z near zero) cannot be judged and passes.
            let sigma = |v: f64, n: usize| noise.sigma(v.abs()) / (n as f64).sqrt();
            let mut departures = [0.0; 3];
            let mut within_noise = true;
            for j in 0..3 {
                let above = sum[j] - black[j];
                let noise_above = (sigma(sum[j], worst_n).powi(2) * 3.0
                    + sigma(black[j], 1).powi(2) * 4.0)
                    .sqrt();
                if !(above > 3.0 * noise_above) {
                    continue;
                }
                departures[j] = (grey[j] - black[j]) / above - 1.0;
                let noise_ratio =
                    (sigma(grey[j], n_grey).powi(2) + noise_above.powi(2)).sqrt() / above;
                within_noise &= departures[j].abs() <= 3.0 * noise_ratio;
            }
            let de = delta_e00_xyz(&grey, &sum, white_reference);
            Some(GreyAdditivity {
                drive: level,
                delta_e00: de,
                luminance_departure_percent: departures[1] * 100.0,
                xyz_departure_percent: Some(departures.map(|d| d * 100.0)),
                neighbour_departure_percent: neighbour_departure(&greys, level, grey - black),
                verdict: Verdict::judge(within_noise, de < DE00_VISIBILITY),
            })
        })
        .collect()
}

fn spatial_independence(
    readings: &[Corrected<'_>],
    noise: &NoiseModel,
    white: &Xyz,
) -> Option<SurroundCheck> {
    let surround: Vec<&Corrected<'_>> = readings
        .iter()
        .filter(|r| r.measurement.role == Role::Surround)
        .collect();
    let on_black = mean_at(
        surround
            .iter()
            .copied()
            .filter(|r| r.measurement.background == [0.0; 3]),
    )?
    .0;
    let (on_white, _) = mean_at(
        surround
            .iter()
            .copied()
            .filter(|r| r.measurement.background.iter().all(|b| *b > 0.5)),
    )?;
    // A surround reading with no light has no relative change to give.
    if !(on_black.y > 0.0) {
        return None;
    }
    let change = on_white.y / on_black.y - 1.0;
    let noise_percent = 3.0 * 2f64.sqrt() * noise.sigma(on_black.y) / on_black.y * 100.0;
    let de = delta_e00_xyz(&on_white, &on_black, white);
    Some(SurroundCheck {
        delta_e00: de,
        luminance_change_percent: change * 100.0,
        noise_percent,
        verdict: Verdict::judge(
            (change * 100.0).abs() <= noise_percent,
            de < DE00_VISIBILITY,
        ),
    })
}

fn monotonicity(ramps: &[ChannelRamp; 3]) -> Vec<ChannelMonotonicity> {
    ramps
        .iter()
        .map(|ramp| {
            let levels: Vec<(f64, f64)> = ramp
                .levels()
                .into_iter()
                .map(|l| {
                    let at: Vec<_> = ramp.points.iter().filter(|p| p.drive == l).collect();
                    let e = at.iter().map(|p| p.excitation).sum::<f64>() / at.len() as f64;
                    let s = (at.iter().map(|p| p.sigma * p.sigma).sum::<f64>()).sqrt()
                        / at.len() as f64;
                    (e, s)
                })
                .collect();
            let reversals = levels
                .windows(2)
                .filter(|w| w[1].0 < w[0].0 - 3.0 * (w[0].1.powi(2) + w[1].1.powi(2)).sqrt())
                .count();
            ChannelMonotonicity {
                channel: CHANNELS[ramp.channel].into(),
                reversals_beyond_noise: reversals,
                verdict: if reversals == 0 {
                    Verdict::WithinNoise
                } else {
                    Verdict::Fails
                },
            }
        })
        .collect()
}

/// Run every check.
pub fn check_assumptions(
    readings: &[Corrected<'_>],
    ramps: &[ChannelRamp; 3],
    black: &Xyz,
    noise: &NoiseModel,
    drift: &DriftReport,
    white_reference: &Xyz,
) -> AssumptionChecks {
    // The black's spectrum, for the spectral constancy test.
    let black_spectra: Vec<&[f64]> = readings
        .iter()
        .filter(|r| r.measurement.role == Role::Black && r.measurement.is_standard_condition())
        .filter_map(|r| r.measurement.reading.spectrum.as_ref().map(|s| s.values()))
        .collect();
    let black_spectrum: Option<Vec<f64>> = black_spectra.first().map(|first| {
        (0..first.len())
            .map(|i| {
                black_spectra
                    .iter()
                    .map(|s| s.get(i).copied().unwrap_or(0.0))
                    .sum::<f64>()
                    / black_spectra.len() as f64
            })
            .collect()
    });
    let primary_constancy = primary_constancy(
        ramps,
        readings,
        black,
        black_spectrum.as_deref(),
        noise,
        white_reference,
    );
    let additivity = additivity(readings, black, noise, white_reference);
    let spatial_independence = spatial_independence(readings, noise, white_reference);
    let monotonicity = monotonicity(ramps);
    let temporal_stability_verdict = match drift.degree {
        None => Verdict::NotMeasured,
        Some(0) => Verdict::WithinNoise,
        Some(_) if drift.amplitude_percent < 1.0 => Verdict::BelowVisibility,
        Some(_) => Verdict::Fails,
    };
    AssumptionChecks {
        primary_constancy_verdict: Verdict::worst(primary_constancy.iter().map(|c| c.verdict)),
        additivity_verdict: Verdict::worst(additivity.iter().map(|c| c.verdict)),
        spatial_independence_verdict: spatial_independence
            .as_ref()
            .map_or(Verdict::NotMeasured, |s| s.verdict),
        monotonicity_verdict: Verdict::worst(monotonicity.iter().map(|c| c.verdict)),
        primary_constancy,
        additivity,
        spatial_independence,
        temporal_stability: drift.clone(),
        temporal_stability_verdict,
        monotonicity,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measurement::Measurement;
    use crate::reading::{Reading, ReadingStatus};

    fn reading(drive: [f64; 3], xyz: Xyz) -> Measurement {
        Measurement {
            index: 0,
            role: Role::from_drive(drive),
            drive,
            codes: None,
            position: Default::default(),
            background: [0.0; 3],
            window: None,
            time_s: None,
            reading: Reading {
                xyz: Some(xyz),
                spectrum: None,
                status: ReadingStatus::Ok,
                integration_s: 1.0,
                ..Default::default()
            },
        }
    }

    /// Black, the three primaries and white, whose Z is `z_factor` of the sum's.
    fn additivity_of_white(z_factor: f64) -> GreyAdditivity {
        let black = Xyz::new(0.2, 0.2, 0.3);
        let primaries = [
            Xyz::new(41.0, 21.0, 2.0),
            Xyz::new(36.0, 72.0, 12.0),
            Xyz::new(18.0, 7.0, 95.0),
        ];
        let sum: Xyz = black + primaries.iter().sum::<Xyz>();
        let white = Xyz::new(sum.x, sum.y, black.z + (sum.z - black.z) * z_factor);
        let mut measurements = vec![reading([0.0; 3], black), reading([1.0; 3], white)];
        for (c, p) in primaries.iter().enumerate() {
            let mut d = [0.0; 3];
            d[c] = 1.0;
            measurements.push(reading(d, black + p));
        }
        let corrected: Vec<Corrected<'_>> = measurements
            .iter()
            .map(|m| Corrected {
                measurement: m,
                xyz: m.reading.xyz.unwrap(),
            })
            .collect();
        let noise = NoiseModel {
            relative: 0.003,
            floor: 0.005,
            relative_from: String::new(),
            floor_from: String::new(),
        };
        let checks = additivity(&corrected, &black, &noise, &white);
        assert_eq!(checks.len(), 1);
        checks[0].clone()
    }

    #[test]
    fn a_grey_is_judged_against_its_neighbours_on_a_power_law() {
        let light = |d: f64| Xyz::new(95.0, 100.0, 108.0) * d.powf(2.2);
        let greys: Vec<(f64, Xyz)> = [0.25, 0.375, 0.625, 0.75]
            .iter()
            .map(|d| (*d, light(*d)))
            .collect();
        // A power law is a straight line in log over log: exact between neighbours.
        let between = between_neighbours(&greys, 0.5).unwrap();
        for j in 0..3 {
            assert!((between[j] / light(0.5)[j] - 1.0).abs() < 1e-12);
        }
        // None beyond the measured greys.
        assert_eq!(between_neighbours(&greys, 0.8), None);
        assert_eq!(between_neighbours(&greys, 0.25), None);
        let grey = |channels: [f64; 3], neighbours: Option<[f64; 3]>| GreyAdditivity {
            drive: 0.5,
            delta_e00: 1.0,
            luminance_departure_percent: channels[1],
            xyz_departure_percent: Some(channels),
            neighbour_departure_percent: neighbours,
            verdict: Verdict::Fails,
        };
        // Off its neighbours as off its channels: a reading off on its own.
        assert!(grey([4.0; 3], Some([3.9; 3])).stands_alone());
        assert!(grey([-4.0; 3], Some([-2.0; 3])).stands_alone());
        // The display: the greys move together (the shared Samsung's grey), or its
        // neighbours depart further the same way.
        assert!(!grey([4.9; 3], Some([-1.7; 3])).stands_alone());
        assert!(!grey([4.0; 3], Some([-2.5; 3])).stands_alone());
        assert!(!grey([4.0; 3], None).stands_alone());
        // Judged where it departs most: Z, not luminance.
        assert!(!grey([0.3, 0.3, -5.0], Some([0.2, 0.2, 0.1])).stands_alone());
        assert!(grey([0.3, 0.3, -5.0], Some([0.0, 0.0, -4.0])).stands_alone());
    }

    #[test]
    fn additivity_is_judged_in_x_y_and_z_not_luminance_alone() {
        // 6.7 % short in Z at full drive: luminance adds up, the colour does not.
        let short = additivity_of_white(0.933);
        assert!(short.luminance_departure_percent.abs() < 1e-9);
        assert!((short.xyz_departure_percent.unwrap()[2] + 6.7).abs() < 1e-6);
        assert!(short.delta_e00 > 1.0, "{short:?}");
        assert_eq!(short.verdict, Verdict::Fails);
        // An additive display stays within noise.
        let additive = additivity_of_white(1.0);
        assert_eq!(additive.verdict, Verdict::WithinNoise);
        assert!(additive.delta_e00 < 1e-9);
    }
}
