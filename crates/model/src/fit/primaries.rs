//! The black and the primary matrix.
//!
//! The black is the mean of the black readings. Each column of the primary matrix is
//! the channel's full-drive reading, black subtracted: its direction is that of the
//! mean full-drive reading and its length that reading's. Each reading of the ramp is
//! then an excitation: its length along that direction divided by full drive's.
//!
//! Why full drive, and not the principal axis of every level (Rougeron & Péroche
//! eq. 3; Brainard 1989, which chromacal used before): the axis through all levels is
//! the better estimate only while the primary's chromaticity is truly constant. On
//! real panels it is not quite (a TN panel's blue moves with drive; at dim levels the
//! black subtracted dominates the error), and then the axis, weighting every level
//! alike, tilts the column away from what the channel gives at full drive, where the
//! white, the gamut's corners and every bright mixture are. On the four real sets of
//! `chromacal bench --only argyll` the axis missed the Samsung TN's own full-drive
//! primaries by up to 1.8 ΔE00 (its blue), and its held-out mixtures came out 85 %
//! worse than with the full-drive column, the MacBook's 20 % worse; the axis was
//! better by 3 % on the Dell and 7 % on the OLED. On simulated displays with constant
//! primaries the two agree within the noise of the full-drive readings.
//!
//! When full drive was not measured (the instrument overloaded), the direction is the
//! principal axis of the levels there are, the excitations are taken relative to the
//! brightest level measured, and the transfer law, fitted with a free amplitude,
//! extrapolates to full drive ("unpinned").

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::noise::NoiseModel;
use crate::measurement::Measurement;
use crate::reading::ReadingStatus;
use chromacal_color::Xyz;

/// A usable reading with its drift-corrected XYZ.
#[derive(Debug, Clone)]
pub struct Corrected<'a> {
    pub measurement: &'a Measurement,
    pub xyz: Xyz,
}

/// The black level and how it was found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlackEstimate {
    pub xyz: Xyz,
    pub readings: usize,
    pub note: String,
}

/// Mean of the black readings at the standard condition. Readings flagged below range
/// are used only when there is nothing else, and the estimate says so; with none at
/// all the black is taken as zero, also said.
pub fn estimate_black(blacks: &[&Measurement]) -> BlackEstimate {
    let in_range: Vec<Xyz> = blacks.iter().filter_map(|m| m.usable_xyz()).collect();
    if !in_range.is_empty() {
        let xyz = in_range.iter().sum::<Xyz>() / in_range.len() as f64;
        return BlackEstimate {
            xyz,
            readings: in_range.len(),
            note: format!("mean of {} black readings", in_range.len()),
        };
    }
    let indicated: Vec<Xyz> = blacks
        .iter()
        .filter(|m| m.reading.status == ReadingStatus::BelowRange)
        .filter_map(|m| m.reading.xyz)
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .collect();
    if !indicated.is_empty() {
        let xyz = (indicated.iter().sum::<Xyz>() / indicated.len() as f64).map(|v| v.max(0.0));
        return BlackEstimate {
            xyz,
            readings: indicated.len(),
            note: format!(
                "black is below the instrument's range: taken from the values it indicated ({} readings), clamped at zero",
                indicated.len()
            ),
        };
    }
    BlackEstimate {
        xyz: Xyz::zeros(),
        readings: 0,
        note: "no black reading: black taken as zero".into(),
    }
}

/// One reading of a ramp, as an excitation.
#[derive(Debug, Clone, PartialEq)]
pub struct RampPoint {
    pub index: usize,
    pub drive: f64,
    pub excitation: f64,
    pub sigma: f64,
    /// The drift-corrected reading.
    pub xyz: Xyz,
}

/// A channel's ramp reduced to a direction and excitations.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelRamp {
    pub channel: usize,
    /// Unit vector of the primary's XYZ.
    pub direction: Vector3<f64>,
    pub direction_se: Vector3<f64>,
    /// Length along `direction` that excitation 1 stands for.
    pub normaliser: f64,
    pub normaliser_se: f64,
    /// True when `normaliser` is the full-drive reading.
    pub pinned: bool,
    pub points: Vec<RampPoint>,
    /// This channel's share of each grey reading below white (`grey_excitations`):
    /// more levels for the law to follow where the ramp is sparse. `xyz` is the grey's.
    pub grey_points: Vec<RampPoint>,
}

impl ChannelRamp {
    /// The matrix column for a law of amplitude `amplitude` (1 when pinned).
    pub fn column(&self, amplitude: f64) -> Xyz {
        self.direction * self.normaliser * amplitude
    }

    /// Standard errors of the column's elements (pinned case).
    pub fn column_se(&self) -> Xyz {
        Vector3::from_fn(|j, _| {
            ((self.direction[j] * self.normaliser_se).powi(2)
                + (self.normaliser * self.direction_se[j]).powi(2))
            .sqrt()
        })
    }

    /// Every point a law is fitted to: the ramp's own readings and the channel's share
    /// of the greys.
    pub fn law_points(&self) -> impl Iterator<Item = &RampPoint> {
        self.points.iter().chain(&self.grey_points)
    }

    /// Distinct drive levels above zero, ascending.
    pub fn levels(&self) -> Vec<f64> {
        let mut v: Vec<f64> = self.points.iter().map(|p| p.drive).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v.dedup();
        v
    }

    /// The same ramp without its readings and grey shares at the drives `levels` (for
    /// cross-validation).
    pub fn without_levels(
        &self,
        levels: &[f64],
        black: &Xyz,
        noise: &NoiseModel,
    ) -> Option<ChannelRamp> {
        let kept: Vec<(usize, f64, Xyz)> = self
            .points
            .iter()
            .filter(|p| !levels.contains(&p.drive))
            .map(|p| (p.index, p.drive, p.xyz))
            .collect();
        let mut ramp = reduce_ramp(self.channel, &kept, black, noise)?;
        // The grey shares are in units of this ramp's normaliser; without its top level
        // (an unpinned ramp) the training ramp normalises by another.
        let rescale = self.normaliser / ramp.normaliser;
        ramp.grey_points = self
            .grey_points
            .iter()
            .filter(|p| !levels.contains(&p.drive))
            .map(|p| RampPoint {
                excitation: p.excitation * rescale,
                sigma: p.sigma * rescale,
                ..p.clone()
            })
            .collect();
        Some(ramp)
    }
}

/// Why a channel's ramp could not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RampError {
    #[error("the {channel} channel has no usable ramp reading")]
    NoReadings { channel: &'static str },
    #[error("the {channel} channel's ramp gives no light above black")]
    NoLight { channel: &'static str },
}

/// The ramp of `channel` from its single-channel readings at the standard condition.
pub fn channel_ramp(
    channel: usize,
    readings: &[Corrected<'_>],
    black: &Xyz,
    noise: &NoiseModel,
) -> Result<ChannelRamp, RampError> {
    let name = crate::CHANNELS[channel];
    let points: Vec<(usize, f64, Xyz)> = readings
        .iter()
        .filter(|r| {
            let d = r.measurement.drive;
            d[channel] > 0.0 && (0..3).all(|k| k == channel || d[k] == 0.0)
        })
        .map(|r| (r.measurement.index, r.measurement.drive[channel], r.xyz))
        .collect();
    if points.is_empty() {
        return Err(RampError::NoReadings { channel: name });
    }
    reduce_ramp(channel, &points, black, noise).ok_or(RampError::NoLight { channel: name })
}

/// The direction of a channel's primary: that of its mean full-drive reading (`full`
/// indexes them in `points`) or, without one, the principal axis of Σ wᵢ rᵢ rᵢᵀ over
/// every level (see the module's doc). `None` when neither gives a finite direction.
fn primary_direction(
    points: &[(usize, f64, Xyz)],
    full: &[usize],
    black: &Xyz,
    noise: &NoiseModel,
) -> Option<Vector3<f64>> {
    let full_mean =
        full.iter().map(|i| points[*i].2 - black).sum::<Xyz>() / full.len().max(1) as f64;
    let u = if !full.is_empty() && full_mean.norm() > 0.0 {
        full_mean / full_mean.norm()
    } else {
        let mut scatter = Matrix3::zeros();
        for (_, _, xyz) in points {
            let r = xyz - black;
            scatter += r * r.transpose() / noise.sigma(xyz.norm()).powi(2);
        }
        let eigen = chromacal_color::linalg::bounded_symmetric_eigen(scatter)?;
        let (k, _) = eigen
            .eigenvalues
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))?;
        let u: Vector3<f64> = eigen.eigenvectors.column(k).into_owned();
        if u.sum() < 0.0 { -u } else { u }
    };
    u.iter().all(|v| v.is_finite()).then_some(u)
}

fn reduce_ramp(
    channel: usize,
    points: &[(usize, f64, Xyz)],
    black: &Xyz,
    noise: &NoiseModel,
) -> Option<ChannelRamp> {
    let sigma_of = |xyz: &Xyz| noise.sigma(xyz.norm());
    let full: Vec<usize> = (0..points.len()).filter(|i| points[*i].1 >= 1.0).collect();
    let u = primary_direction(points, &full, black, noise)?;
    let lengths: Vec<f64> = points
        .iter()
        .map(|(_, _, xyz)| u.dot(&(xyz - black)))
        .collect();
    // The readings the direction rests on: full drive when pinned, else every level.
    let direction_from: Vec<usize> = if full.is_empty() {
        (0..points.len()).collect()
    } else {
        full.clone()
    };
    let weight_sum: f64 = direction_from
        .iter()
        .map(|i| lengths[*i].powi(2) / sigma_of(&points[*i].2).powi(2))
        .sum();
    let direction_se = Vector3::repeat(1.0 / weight_sum.max(f64::MIN_POSITIVE).sqrt());

    let (top_indices, pinned) = if full.is_empty() {
        let top = points.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        (
            (0..points.len())
                .filter(|i| points[*i].1 == top)
                .collect::<Vec<_>>(),
            false,
        )
    } else {
        (full, true)
    };
    let normaliser =
        top_indices.iter().map(|i| lengths[*i]).sum::<f64>() / top_indices.len() as f64;
    if !(normaliser > 0.0) {
        return None;
    }
    let normaliser_se = noise.sigma(normaliser) / (top_indices.len() as f64).sqrt();
    let points = points
        .iter()
        .zip(&lengths)
        .map(|((index, drive, xyz), s)| RampPoint {
            index: *index,
            drive: *drive,
            excitation: s / normaliser,
            sigma: sigma_of(xyz) / normaliser,
            xyz: *xyz,
        })
        .collect();
    Some(ChannelRamp {
        channel,
        direction: u,
        direction_se,
        normaliser,
        normaliser_se,
        pinned,
        points,
        grey_points: Vec::new(),
    })
}

/// Each channel's share of each grey reading below white, added to its ramp so that the
/// greys shape the curves where the ramps are sparse (ArgyllCMS's shapers learn from
/// the greys too). Through the additive model a grey at level v reads
/// XYZ − black = M·e(v), so e(v) = M⁻¹(XYZ − black), with M the ramps' columns at their
/// normalising level; the noise of the reading reaches e_c through row c of M⁻¹. Nothing
/// is added when M cannot be inverted (its condition number is above `max_condition`).
pub fn add_grey_excitations(
    ramps: &mut [ChannelRamp; 3],
    greys: &[(usize, f64, Xyz)],
    black: &Xyz,
    noise: &NoiseModel,
    max_condition: f64,
) {
    let matrix = Matrix3::from_columns(&[
        ramps[0].column(1.0),
        ramps[1].column(1.0),
        ramps[2].column(1.0),
    ]);
    if !(crate::monitor::matrix_condition_number(&matrix) <= max_condition) {
        return;
    }
    let Some(inverse) = matrix.try_inverse() else {
        return;
    };
    for (index, level, xyz) in greys.iter().filter(|g| g.1 > 0.0 && g.1 < 1.0) {
        let e = inverse * (xyz - black);
        let sigma = noise.sigma(xyz.norm());
        for (c, ramp) in ramps.iter_mut().enumerate() {
            ramp.grey_points.push(RampPoint {
                index: *index,
                drive: *level,
                excitation: e[c],
                sigma: sigma * inverse.row(c).norm(),
                xyz: *xyz,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise() -> NoiseModel {
        NoiseModel {
            relative: 0.002,
            floor: 0.001,
            relative_from: String::new(),
            floor_from: String::new(),
        }
    }

    #[test]
    fn direction_and_excitations_of_a_clean_ramp() {
        let primary = Xyz::new(40.0, 21.0, 2.0);
        let black = Xyz::new(0.1, 0.1, 0.1);
        let points: Vec<(usize, f64, Xyz)> = [0.25, 0.5, 0.75, 1.0]
            .iter()
            .enumerate()
            .map(|(i, v): (usize, &f64)| (i, *v, black + primary * v.powf(2.2)))
            .collect();
        let ramp = reduce_ramp(0, &points, &black, &noise()).unwrap();
        assert!(ramp.pinned);
        assert!((ramp.column(1.0) - primary).norm() < 1e-9);
        for p in &ramp.points {
            assert!((p.excitation - p.drive.powf(2.2)).abs() < 1e-12);
        }
        // Without full drive the brightest level normalises and the ramp is unpinned.
        let ramp = reduce_ramp(0, &points[..3], &black, &noise()).unwrap();
        assert!(!ramp.pinned);
        assert!((ramp.points[2].excitation - 1.0).abs() < 1e-12);
    }

    #[test]
    fn black_prefers_in_range_readings_and_never_invents_values() {
        use crate::reading::Reading;
        let m = |y: f64, status| Measurement {
            index: 0,
            role: crate::measurement::Role::Black,
            drive: [0.0; 3],
            codes: None,
            position: Default::default(),
            background: [0.0; 3],
            window: None,
            time_s: None,
            reading: Reading {
                xyz: Some(Xyz::new(y, y, y)),
                spectrum: None,
                status,
                integration_s: 1.0,
                ..Default::default()
            },
        };
        let a = m(0.2, ReadingStatus::Ok);
        let b = m(-0.001, ReadingStatus::BelowRange);
        let est = estimate_black(&[&a, &b]);
        assert_eq!(est.xyz, Xyz::new(0.2, 0.2, 0.2));
        let est = estimate_black(&[&b]);
        assert_eq!(est.xyz, Xyz::zeros());
        assert!(est.note.contains("below the instrument's range"));
        assert!(estimate_black(&[]).note.contains("no black"));
    }
}
