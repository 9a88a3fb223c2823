//! The calibration's measured greys as a correction of the model's transfer laws.
//!
//! A calibration measures its grey levels through the final curves (`LevelCheck`):
//! readings the fit never saw, at the drives the curves send. Where the fitted law is
//! a compromise over the range (one exponent for a panel whose own curve bends), or
//! the panel's curve departs from any smooth law, the greys land a few per cent off
//! what the model predicts, and the curves were measured into place for exactly that
//! (ArgyllCMS's dispcal iterates the same way). A 3D LUT that goes through the
//! model's inverse alone would undo what the curves learnt.
//!
//! The correction carries it over: each grey's light above black, measured over
//! predicted, is a gain on the excitation of every channel at the drive that channel
//! had in it (the assumption the curves' refinement makes: the greys' miss is the
//! channels' laws', alike), interpolated linearly in drive between the greys and held
//! at the ends. The corrected laws are written as [`Table`] laws through every 16-bit
//! code and each grey's drive ([`GreyCorrection::model`]), as the law correction of
//! the fit writes its own (`fit::law_correction`): the corrected model is then a model
//! like any other, and `lut3d`, `verify`'s charts, `render` and the ICC export go
//! through it by the paths they take for any model, forward and inverse. It is a
//! measured table, not a law: whether it is used is decided on patches held out of
//! the fit, which it must predict better by more than the difference's standard
//! error (`Profile::output_model`).

use chromacal_color::Xyz;
use chromacal_color::difference::Metric;

use crate::fit::validate::{PatchError, delta_e00_xyz};
use crate::transfer::{Table, TransferLaw};
use crate::{Drive, MonitorModel};

/// Greys whose gain falls outside this range are left out: a grey measured at half or
/// twice what the model predicts is not a law's miss but a reading the model cannot
/// speak to (a grey at black, where what the display adds near black, such as a
/// dimming backlight's floor, over a prediction of almost nothing is any ratio).
const GAIN_RANGE: (f64, f64) = (0.5, 2.0);

/// Held-out patches fewer than this decide nothing: their standard error says
/// little.
const MIN_HELD_OUT: usize = 5;

/// Drive steps of the corrected laws' tables: a knot at every 16-bit code, where a
/// LUT or a render sends its drives, so the table is the correction itself there.
const TABLE_STEPS: usize = 65_535;

/// Per channel, the gain on the law's excitation at the drives of the greys measured,
/// and the model with its laws so corrected.
#[derive(Debug, Clone, PartialEq)]
pub struct GreyCorrection {
    /// Per channel: (drive, gain), drive strictly ascending.
    points: [Vec<(f64, f64)>; 3],
    /// The model the correction was made for, each law replaced by its corrected
    /// excitation as a table.
    model: MonitorModel,
}

impl GreyCorrection {
    /// From greys shown at `drives` and measured as `measured` (the same order), on
    /// `model`'s centre. None when fewer than two greys have light above black both
    /// predicted and measured, when a law has no positive full-drive excitation, or
    /// when the gains would make a channel's light fall as its drive rises between
    /// two knots of its table (a 16-bit code or a grey's drive: a LUT through it would
    /// fold back). None too for a model whose terms invert its laws inside their
    /// fixed point (crosstalk in drive, the HLG OOTF through the laws): a table's
    /// inverse is a bisection, hundreds of times a colour there, and an HLG law's
    /// light beyond full signal goes on by its own form, which a table has not.
    pub fn from_greys(model: &MonitorModel, greys: &[(Drive, Xyz)]) -> Option<GreyCorrection> {
        if model.terms.drive_crosstalk.is_some() || model.terms.hlg_ootf_through_laws {
            return None;
        }
        if !model.laws.iter().all(|l| {
            let top = l.full_drive_excitation();
            top.is_finite() && top > 0.0
        }) {
            return None;
        }
        let black = model.black.y;
        let mut points: [Vec<(f64, f64)>; 3] = Default::default();
        for (drive, measured) in greys {
            if !drive.iter().all(|d| (0.0..=1.0).contains(d)) {
                continue;
            }
            let predicted = model.forward_centre(*drive).y - black;
            let seen = measured.y - black;
            // A grey predicted at less than twice the black is mostly black: its
            // reading's noise, and any change of the black since the fit, is most of
            // its light above black (an LCD's 7 cd/m² black under a 0.04 cd/m² step).
            // Judged on the prediction, so that noise does not choose which greys stay.
            if !(predicted >= black && predicted > 0.0 && seen > 0.0) {
                continue;
            }
            let gain = seen / predicted;
            if !(GAIN_RANGE.0..=GAIN_RANGE.1).contains(&gain) {
                continue;
            }
            for (c, channel) in points.iter_mut().enumerate() {
                channel.push((drive[c], gain));
            }
        }
        for channel in &mut points {
            channel.sort_by(|a, b| a.0.total_cmp(&b.0));
            // Two greys at one drive (a channel clipped at black or at full drive):
            // their mean.
            let mut merged: Vec<(f64, f64, usize)> = Vec::new();
            for &(d, g) in channel.iter() {
                match merged.last_mut() {
                    Some(last) if last.0 == d => {
                        last.1 += g;
                        last.2 += 1;
                    }
                    _ => merged.push((d, g, 1)),
                }
            }
            *channel = merged
                .into_iter()
                .map(|(d, g, n)| (d, g / n as f64))
                .collect();
        }
        if !points.iter().all(|p| p.len() >= 2) {
            return None;
        }
        let mut corrected = model.clone();
        for (c, law) in model.laws.iter().enumerate() {
            // Knots at every 16-bit code and at each grey's own drive, where the gain
            // bends (greys closer than a code apart can fold the light between
            // codes). `Table::new` refuses light that falls from one knot to the next.
            let mut drives: Vec<f64> = (0..=TABLE_STEPS)
                .map(|i| i as f64 / TABLE_STEPS as f64)
                .chain(points[c].iter().map(|p| p.0))
                .collect();
            drives.sort_by(f64::total_cmp);
            // A grey's drive read back through a video LUT may lie within rounding of a
            // code: one knot there.
            drives.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            let mut excitation: Vec<f64> = drives
                .iter()
                .map(|&d| corrected_excitation(&points[c], law, d))
                .collect();
            // Where the light stops rising to the top (a PQ law above its peak's
            // code, with the gain held beyond the top grey) the table ends: a table
            // holds its last knot's light beyond it, and its inverse sends the top
            // light at the drive that first reaches it rather than at full drive.
            let top = excitation.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let end = excitation.iter().position(|&e| e >= top)? + 1;
            drives.truncate(end);
            excitation.truncate(end);
            corrected.laws[c] = TransferLaw::Table(Table::new(drives, excitation).ok()?);
        }
        Some(GreyCorrection {
            points,
            model: corrected,
        })
    }

    /// The model with its transfer laws corrected: what the display shows, forward,
    /// and the drives to send, inverse, for `lut3d`, `verify`'s charts, `render` and
    /// the ICC export.
    pub fn model(&self) -> &MonitorModel {
        &self.model
    }

    /// The corrected model, kept.
    pub fn into_model(self) -> MonitorModel {
        self.model
    }

    /// The greys the correction rests on (those left after the ones it leaves out).
    pub fn greys(&self) -> usize {
        self.points.iter().map(Vec::len).max().unwrap_or(0)
    }

    /// The gain on channel `c`'s excitation at `drive`.
    pub fn gain(&self, c: usize, drive: f64) -> f64 {
        gain_at(&self.points[c], drive)
    }
}

/// A channel's gain at `drive` from its greys' (drive, gain): linear between them,
/// held at the ends.
fn gain_at(points: &[(f64, f64)], drive: f64) -> f64 {
    let i = points.partition_point(|q| q.0 < drive);
    if i == 0 {
        return points[0].1;
    }
    if i == points.len() {
        return points[points.len() - 1].1;
    }
    let ((d0, g0), (d1, g1)) = (points[i - 1], points[i]);
    g0 + (g1 - g0) * (drive - d0) / (d1 - d0)
}

/// A channel's corrected excitation at `drive`: its law's times the gain there.
fn corrected_excitation(points: &[(f64, f64)], law: &TransferLaw, drive: f64) -> f64 {
    (law.excitation(drive) * gain_at(points, drive)).max(0.0)
}

/// The held-out patches' mean error without and with a correction, and the standard
/// error of the mean of their differences patch by patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOutMeans {
    pub without: f64,
    pub with: f64,
    pub standard_error: f64,
    pub patches: usize,
}

impl HeldOutMeans {
    /// The correction predicts the held-out patches better than the model alone, by
    /// more than one standard error of the difference: a gain of a thousandth over a
    /// dozen patches is the patches' luck, not the greys'.
    pub fn lowers(&self) -> bool {
        self.with < self.without - self.standard_error
    }
}

impl GreyCorrection {
    /// The mean error of `model` (the one the correction was made for) on `held_out`
    /// (each patch predicted again at its drive and place) without and with the
    /// correction, in `metric`: ΔE ITP
    /// (BT.2124, on absolute light), as an HDR profile is judged, or ΔE00 against
    /// the model's white. None with fewer than 5 held-out patches.
    pub fn held_out_means(
        &self,
        model: &MonitorModel,
        held_out: &[PatchError],
        metric: Metric,
    ) -> Option<HeldOutMeans> {
        if held_out.len() < MIN_HELD_OUT {
            return None;
        }
        let white = model.white();
        let error = |a: &Xyz, b: &Xyz| match metric {
            Metric::Itp => chromacal_color::ictcp::delta_e_itp(a, b),
            Metric::De00 => delta_e00_xyz(a, b, &white),
        };
        let pairs: Vec<(f64, f64)> = held_out
            .iter()
            .map(|p| {
                let corrected = self.model.forward(p.drive, p.position);
                (
                    error(&p.measured, &model.forward(p.drive, p.position)),
                    error(&p.measured, &corrected),
                )
            })
            .collect();
        let n = pairs.len() as f64;
        let without = pairs.iter().map(|p| p.0).sum::<f64>() / n;
        let with = pairs.iter().map(|p| p.1).sum::<f64>() / n;
        let difference = with - without;
        let variance = match pairs.len() {
            1 => 0.0,
            _ => {
                pairs
                    .iter()
                    .map(|p| (p.1 - p.0 - difference).powi(2))
                    .sum::<f64>()
                    / (n - 1.0)
            }
        };
        Some(HeldOutMeans {
            without,
            with,
            standard_error: (variance / n).sqrt(),
            patches: pairs.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::AdditivityTerms;
    use crate::spatial::SpatialMap;
    use crate::transfer::{Power, TransferLaw};

    fn model() -> MonitorModel {
        MonitorModel {
            matrix: nalgebra::Matrix3::new(
                41.24, 35.76, 18.05, //
                21.26, 71.52, 7.22, //
                1.93, 11.92, 95.05,
            ),
            black: Xyz::new(0.1, 0.11, 0.12),
            laws: [2.2, 2.3, 2.1].map(|gamma| TransferLaw::Power(Power { gamma })),
            spatial: SpatialMap::default(),
            terms: AdditivityTerms::default(),
        }
    }

    #[test]
    fn greys_that_read_brighter_are_corrected_and_inverted() {
        let m = model();
        // The display shows 10 % more above black at mid grey, as much as the model at
        // the ends.
        let greys: Vec<(Drive, Xyz)> = [0.1, 0.5, 1.0]
            .iter()
            .map(|&d| {
                let p = m.forward_centre([d; 3]);
                let gain = if d == 0.5 { 1.1 } else { 1.0 };
                ([d; 3], m.black + (p - m.black) * gain)
            })
            .collect();
        let k = GreyCorrection::from_greys(&m, &greys).unwrap();
        assert!((k.gain(0, 0.5) - 1.1).abs() < 1e-9);
        assert!((k.gain(1, 0.3) - 1.05).abs() < 1e-9);
        assert_eq!(k.gain(2, 0.0), 1.0);
        // The corrected model predicts the mid grey as measured.
        let shown = k.model().forward_centre([0.5; 3]);
        assert!((shown.y / greys[1].1.y - 1.0).abs() < 1e-9, "{shown:?}");
        // And its inverse sends a lower drive for each channel's light at the
        // model's drive, which the corrected display shows as the model's.
        let wanted = [0.5, 0.6, 0.45];
        for (c, wanted) in wanted.into_iter().enumerate() {
            let light = m.laws[c].excitation(wanted);
            let sent = k.model().laws[c].drive(light);
            assert!(sent < wanted, "{c}: {sent}");
            let back = k.model().laws[c].excitation(sent);
            assert!((back / light - 1.0).abs() < 1e-9, "{c}: {back} {light}");
        }
    }

    /// The table is the correction at every 16-bit code, and between codes within
    /// what no drive can show, on a PQ law, whose light near black rises steeply from
    /// nothing.
    #[test]
    fn the_corrected_laws_follow_the_correction_between_codes() {
        use crate::transfer::Pq;
        let mut m = model();
        m.laws = [1.0, 0.95, 1.05].map(|exponent| {
            TransferLaw::Pq(Pq {
                peak: 600.0,
                rolloff_from: 600.0,
                exponent,
                curvature: 0.0,
                toe: 0.0,
            })
        });
        let greys: Vec<(Drive, Xyz)> = [0.1, 0.3, 0.5, 0.75]
            .iter()
            .zip([0.9, 1.04, 0.97, 1.02])
            .map(|(&d, gain)| {
                let p = m.forward_centre([d; 3]);
                ([d; 3], m.black + (p - m.black) * gain)
            })
            .collect();
        let k = GreyCorrection::from_greys(&m, &greys).unwrap();
        for c in 0..3 {
            let (law, table) = (&m.laws[c], &k.model().laws[c]);
            let exact = |d: f64| corrected_excitation(&k.points[c], law, d);
            for i in (0..=TABLE_STEPS).step_by(97) {
                let code = i as f64 / TABLE_STEPS as f64;
                assert_eq!(table.excitation(code), exact(code), "{c} at code {i}");
                let between = (i as f64 + 0.5) / TABLE_STEPS as f64;
                let (t, e) = (table.excitation(between), exact(between));
                // A millionth of the light, or a billionth of the peak (0.6 µcd/m²)
                // near black.
                assert!(
                    (t - e).abs() <= 1e-6 * e + 1e-9,
                    "{c} at {between}: {t} against {e}"
                );
            }
            // The law is flat above its peak's code (about 0.70), the gain rises to
            // the top grey at 0.75 and is held beyond it: the table ends there, and
            // its full light, the law's times 1.02, is sent at 0.75, not at 1.
            let full = table.full_drive_excitation();
            assert!(law.drive(law.full_drive_excitation()) < 0.72, "{c}");
            assert!(
                (full / law.full_drive_excitation() - 1.02).abs() < 1e-12,
                "{c}"
            );
            assert!((table.drive(full) - 0.75).abs() < 1e-9, "{c}");
            assert_eq!(table.excitation(0.9), full, "{c}");
        }
    }

    /// Terms that invert the laws inside their fixed point keep the fitted laws.
    #[test]
    fn no_correction_under_crosstalk_in_drive() {
        let mut m = model();
        let greys: Vec<(Drive, Xyz)> = [0.2, 0.5, 1.0]
            .iter()
            .map(|&d| {
                (
                    [d; 3],
                    m.black + (m.forward_centre([d; 3]) - m.black) * 1.05,
                )
            })
            .collect();
        assert!(GreyCorrection::from_greys(&m, &greys).is_some());
        m.terms.drive_crosstalk = Some([0.01; 3]);
        assert!(GreyCorrection::from_greys(&m, &greys).is_none());
        m.terms.drive_crosstalk = None;
        m.terms.hlg_ootf_through_laws = true;
        assert!(GreyCorrection::from_greys(&m, &greys).is_none());
    }

    #[test]
    fn the_held_out_patches_decide_whether_it_is_used() {
        let m = model();
        let bumped = |d: f64| if (0.3..0.7).contains(&d) { 1.08 } else { 1.0 };
        let greys: Vec<(Drive, Xyz)> = [0.2, 0.5, 0.8, 1.0]
            .iter()
            .map(|&d| {
                let p = m.forward_centre([d; 3]);
                ([d; 3], m.black + (p - m.black) * bumped(d))
            })
            .collect();
        let k = GreyCorrection::from_greys(&m, &greys).unwrap();
        let drives = [
            [0.5, 0.45, 0.55],
            [0.4, 0.6, 0.5],
            [0.9, 0.5, 0.1],
            [0.35, 0.65, 0.6],
            [0.55, 0.3, 0.45],
        ];
        let patch = |drive: Drive, measured: Xyz| PatchError {
            index: 0,
            role: crate::measurement::Role::Verification,
            drive,
            position: crate::ScreenPosition::CENTRE,
            measured,
            predicted: m.forward_centre(drive),
            delta_e00: 0.0,
        };
        // A display whose channels have the greys' bump: the correction predicts it,
        // by more than the difference's standard error.
        let bumped_display: Vec<PatchError> = drives
            .iter()
            .map(|&d| patch(d, k.model().forward_centre(d)))
            .collect();
        let means = k.held_out_means(&m, &bumped_display, Metric::De00).unwrap();
        assert!(means.lowers() && means.with < 1e-9, "{means:?}");
        // One whose greys alone were off (the channels follow the model): it does not.
        let model_display: Vec<PatchError> = drives
            .iter()
            .map(|&d| patch(d, m.forward_centre(d)))
            .collect();
        let means = k.held_out_means(&m, &model_display, Metric::Itp).unwrap();
        assert!(!means.lowers() && means.without < 1e-9, "{means:?}");
        assert!(
            k.held_out_means(&m, &model_display[..2], Metric::De00)
                .is_none()
        );
    }

    #[test]
    fn a_grey_under_twice_the_black_is_left_out() {
        let m = model();
        // Predicted 0.02 above a 0.11 black, read 50 % high: noise on black, not the
        // law.
        let low = m.forward_centre([0.02; 3]);
        let greys = [
            ([0.02; 3], m.black + (low - m.black) * 1.5),
            ([0.5; 3], m.forward_centre([0.5; 3])),
            ([1.0; 3], m.forward_centre([1.0; 3])),
        ];
        let k = GreyCorrection::from_greys(&m, &greys).unwrap();
        assert_eq!(k.gain(0, 0.02), 1.0);
    }

    #[test]
    fn gains_that_fold_a_law_back_are_refused_and_a_steep_one_inverted() {
        let m = model();
        let grey = |d: f64, gain: f64| {
            let p = m.forward_centre([d; 3]);
            ([d; 3], m.black + (p - m.black) * gain)
        };
        // Light that falls from 0.6 to 0.61 would fold the LUT back.
        let folded = [grey(0.6, 1.9), grey(0.61, 0.6), grey(1.0, 1.0)];
        assert!(GreyCorrection::from_greys(&m, &folded).is_none());
        // So would a fall of 3 % between greys closer than a 16-bit code.
        let close = [
            grey(0.5, 1.0),
            grey(0.99991, 1.0),
            grey(0.999_92, 0.97),
            grey(1.0, 1.0),
        ];
        assert!(GreyCorrection::from_greys(&m, &close).is_none());
        // A steep but rising change, which fixed-point steps did not settle: the
        // corrected law's inverse lands where its light is the model's at the drive
        // wanted.
        let steep = [grey(0.3, 0.7), grey(0.36, 1.3), grey(1.0, 1.0)];
        let k = GreyCorrection::from_greys(&m, &steep).unwrap();
        let (law, table) = (&m.laws[0], &k.model().laws[0]);
        for wanted in [0.001, 0.31, 0.33, 0.35, 0.5, 0.999, 1.0] {
            let light = law.excitation(wanted);
            let sent = table.drive(light);
            let back = table.excitation(sent);
            assert!(
                (back / light - 1.0).abs() < 1e-9,
                "{wanted}: {sent} shows {back} for {light}"
            );
        }
        assert_eq!(table.drive(0.0), 0.0);
    }

    #[test]
    fn no_correction_without_two_greys_above_black() {
        let m = model();
        let black = [([0.0; 3], m.black), ([0.5; 3], m.forward_centre([0.5; 3]))];
        assert!(GreyCorrection::from_greys(&m, &black).is_none());
    }
}
