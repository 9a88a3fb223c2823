//! Scoring a model on measurements: predict each patch, compare in CIEDE2000 against
//! the model's own white. This is both the held-out error of a fit and what
//! `chromacal check` reports for a profile against any measurements.

use serde::{Deserialize, Serialize};

use super::noise::NoiseModel;
use super::stats::ErrorStats;
use crate::measurement::{Measurement, MeasurementSet, Role};
use crate::{Drive, MonitorModel, ScreenPosition};
use chromacal_color::{Xyz, delta_e_2000, xyz_to_lab};

/// One patch, measured and predicted.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PatchError {
    pub index: usize,
    pub role: Role,
    pub drive: Drive,
    pub position: ScreenPosition,
    pub measured: Xyz,
    pub predicted: Xyz,
    pub delta_e00: f64,
}

/// Errors of a model over a set of patches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    pub stats: Option<ErrorStats>,
    pub patches: Vec<PatchError>,
}

impl Evaluation {
    /// The `n` worst patches, worst first.
    pub fn worst(&self, n: usize) -> Vec<&PatchError> {
        let mut sorted: Vec<&PatchError> = self.patches.iter().collect();
        sorted.sort_by(|a, b| b.delta_e00.total_cmp(&a.delta_e00));
        sorted.truncate(n);
        sorted
    }
}

/// ΔE ITP (ITU-R BT.2124) of each patch, measured against predicted, both in cd/m²:
/// the error of a profile of an HDR signal, whose light is absolute, where ΔE00's
/// lightness relative to the white cannot see a 10 % miss at 0.5 cd/m² beside an
/// 800 cd/m² white. `None` for no patches.
pub fn delta_e_itp_stats(patches: &[PatchError]) -> Option<ErrorStats> {
    let values: Vec<f64> = patches
        .iter()
        .map(|p| chromacal_color::ictcp::delta_e_itp(&p.measured, &p.predicted))
        .collect();
    ErrorStats::of(&values)
}

/// ΔE00 between two XYZ seen against the same white.
pub fn delta_e00_xyz(a: &Xyz, b: &Xyz, white: &Xyz) -> f64 {
    delta_e_2000(&xyz_to_lab(a, white), &xyz_to_lab(b, white))
}

/// Mean ΔE00 that one standard deviation of measurement noise makes to each of
/// `readings` (as a change of luminance): the size of error noise alone explains.
pub fn noise_delta_e00(readings: &[Xyz], noise: &NoiseModel, white: &Xyz) -> f64 {
    if readings.is_empty() {
        return 0.0;
    }
    readings
        .iter()
        .map(|xyz| {
            let y = xyz.y.abs().max(f64::MIN_POSITIVE);
            delta_e00_xyz(xyz, &(xyz * (1.0 + noise.sigma(y) / y)), white)
        })
        .sum::<f64>()
        / readings.len() as f64
}

/// Predict each (measurement, XYZ to compare with) and score it against the model's
/// white. The XYZ given may differ from the raw reading (drift-corrected, say).
pub fn evaluate<'a>(
    model: &MonitorModel,
    readings: impl IntoIterator<Item = (&'a Measurement, Xyz)>,
) -> Evaluation {
    let white = model.white();
    let patches: Vec<PatchError> = readings
        .into_iter()
        .map(|(m, measured)| {
            // A window of another size than the plan's patch is dimmed by the
            // display's brightness limiter, where the model has one.
            let predicted = match m.window {
                Some(area) => model.forward_in_window(m.drive, m.position, area),
                None => model.forward(m.drive, m.position),
            };
            PatchError {
                index: m.index,
                role: m.role,
                drive: m.drive,
                position: m.position,
                measured,
                predicted,
                delta_e00: delta_e00_xyz(&measured, &predicted, &white),
            }
        })
        .collect();
    let errors: Vec<f64> = patches.iter().map(|p| p.delta_e00).collect();
    Evaluation {
        stats: ErrorStats::of(&errors),
        patches,
    }
}
/// The split on which chromacal is compared with other tools on a real measurement set:
/// the fit sees the blacks, the greys and the single-channel ramps, at most `max_train`
/// readings, and every mixture of two or three channels is held out. Blacks, whites and
/// each channel at full drive are always kept; when the rest are more than the room
/// left, the greys below white and each channel's ramp below full drive share it
/// equally (what one group cannot use goes to the others), each thinned evenly over its
/// levels. Roles are read from the drives, so a journal splits as a `.ti3` does.
/// Returns (train, test), each in the set's order.
pub fn ramps_and_greys_split(
    set: &MeasurementSet,
    max_train: usize,
) -> (MeasurementSet, MeasurementSet) {
    let role = |m: &Measurement| Role::from_drive(m.drive);
    let (train, test): (Vec<Measurement>, Vec<Measurement>) = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition())
        .cloned()
        .partition(|m| role(m) != Role::Mixture);
    // The thinnable group of a reading: 0 the greys below white, 1 + c channel c's
    // ramp below full drive; `None` for what is always kept.
    let group = |m: &Measurement| match role(m) {
        Role::Grey if m.drive[0] < 1.0 => Some(0),
        Role::Ramp => (0..3)
            .find(|c| m.drive[*c] > 0.0 && m.drive[*c] < 1.0)
            .map(|c| c + 1),
        _ => None,
    };
    let always = train.iter().filter(|m| group(m).is_none()).count();
    let mut groups: Vec<Vec<usize>> = vec![Vec::new(); 4];
    for (i, m) in train.iter().enumerate() {
        if let Some(g) = group(m) {
            groups[g].push(i);
        }
    }
    let sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
    let shares = share_out(&sizes, max_train.saturating_sub(always));
    let level = |i: &usize| train[*i].drive.iter().copied().fold(0.0, f64::max);
    let mut chosen = vec![false; train.len()];
    for (mut members, share) in groups.into_iter().zip(shares) {
        members.sort_by(|a, b| level(a).total_cmp(&level(b)));
        for i in evenly_spread(&members, share) {
            chosen[i] = true;
        }
    }
    let train: Vec<Measurement> = train
        .into_iter()
        .enumerate()
        .filter(|(i, m)| group(m).is_none() || chosen[*i])
        .map(|(_, m)| m)
        .collect();
    let part = |measurements: Vec<Measurement>, what: &str| MeasurementSet {
        source: format!("{} ({what})", set.source),
        units: set.units,
        instrument: set.instrument.clone(),
        display: set.display.clone(),
        measured_at: set.measured_at.clone(),
        measurements,
    };
    (part(train, "train"), part(test, "test"))
}

/// Up to `room` places shared among groups of `sizes`: equal shares, a group that
/// needs less than its share giving the rest to the others.
fn share_out(sizes: &[usize], room: usize) -> Vec<usize> {
    let mut shares = vec![0; sizes.len()];
    let mut left = room;
    loop {
        let hungry: Vec<usize> = (0..sizes.len())
            .filter(|g| shares[*g] < sizes[*g])
            .collect();
        if hungry.is_empty() || left == 0 {
            return shares;
        }
        let each = (left / hungry.len()).max(1);
        for g in hungry {
            let more = each.min(sizes[g] - shares[g]).min(left);
            shares[g] += more;
            left -= more;
        }
    }
}

/// `count` of `sorted`, spread evenly from its first to its last.
fn evenly_spread(sorted: &[usize], count: usize) -> Vec<usize> {
    let n = sorted.len();
    if count >= n {
        return sorted.to_vec();
    }
    (0..count)
        .map(|k| {
            let at = if count > 1 {
                k * (n - 1) / (count - 1)
            } else {
                n / 2
            };
            sorted[at]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_are_equal_and_what_one_group_cannot_use_goes_to_the_others() {
        assert_eq!(share_out(&[100, 100, 100, 100], 40), vec![10, 10, 10, 10]);
        assert_eq!(share_out(&[2, 100, 100, 100], 41), vec![2, 13, 13, 13]);
        assert_eq!(share_out(&[2, 3, 4, 5], 100), vec![2, 3, 4, 5]);
        assert_eq!(share_out(&[5, 5, 5, 5], 3), vec![1, 1, 1, 0]);
        assert_eq!(share_out(&[5, 5], 0), vec![0, 0]);
    }

    #[test]
    fn a_spread_keeps_both_ends() {
        let sorted: Vec<usize> = (0..11).collect();
        assert_eq!(evenly_spread(&sorted, 3), vec![0, 5, 10]);
        assert_eq!(evenly_spread(&sorted, 20).len(), 11);
    }
}
