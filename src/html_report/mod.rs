//! The calibration report as one self-contained HTML page: the run's identity and
//! cost, the transfer curves with their measured points, the primaries on the u′v′
//! diagram, the uniformity map, the held-out error with swatches of the worst patches,
//! the assumption checks, the law selection, the calibration curves and, from the
//! daemon, the profile history. Figures are inline SVG (`figures`); no script, no
//! network, readable printed.
//!
//! [`report_html`] takes a profile and, when they can be found, the readings it was
//! fitted on (for measured points and residuals): what the page cannot show without
//! them it says, rather than leaving a figure out in silence.

mod calibrated;
pub mod figures;
pub mod fleet;
mod hdr;
mod markup;
mod page;

use std::path::Path;

use crate::profile::Profile;
use crate::profile::store::ProfileStore;
use crate::verification::Criteria;
use chromacal_color::adaptation::{AdaptationTransform, adapt};
use chromacal_color::gamut::{REFERENCE_SPACES, space_uv};
use chromacal_color::spaces::{Xyy, xyy_to_xyz, xyz_to_srgb8, xyz_to_uv_prime};
use chromacal_color::spectrum::Observer;
use chromacal_color::{UvPrime, Xyz};
use chromacal_model::measurement::{MeasurementSet, Role};
use chromacal_model::transfer::{
    Cowan, GainOffsetGamma, Hlg, LawKind, Power, Pq, ThreeTerm, TransferLaw,
};
use chromacal_model::{MonitorModel, ScreenPosition};

use figures::{Chromaticities, Curve, FigureError, GridPoint, TimeSeries};

pub use page::report_html;

/// What a report is made from.
pub struct ReportInput<'a> {
    pub profile: &'a Profile,
    /// The readings the profile was fitted on, for the measured points.
    pub readings: Option<&'a MeasurementSet>,
    /// Why the readings are absent, said on the page where the points would be.
    pub readings_note: Option<String>,
    /// The daemon's profile history and verifications.
    pub history: Option<HistoryView>,
    /// The daemon's device the profile is of: named on the page, with a link back to
    /// the fleet page.
    pub device: Option<String>,
    /// Readings measured to verify the profile (`check --report`): the verification
    /// sections judge these. Without them they judge the patches of `readings` held
    /// out of the fit.
    pub checked: Option<&'a MeasurementSet>,
    /// What the verified patches must achieve.
    pub criteria: Criteria,
    /// The newest verification of the calibrated display (`chromacal verify`): the
    /// page then opens with the display as measured through its calibration.
    pub verified: Option<&'a crate::verify::VerifyReport>,
}

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error(transparent)]
    Figure(#[from] FigureError),
}

/// CIE 1931 xy of D65 (CIE 15:2004 Table T.3), the white the swatches are shown at.
const D65_XY: [f64; 2] = [0.3127, 0.3290];

fn uv(p: UvPrime) -> (f64, f64) {
    (p.u, p.v)
}

/// The spectrum locus of the CIE 1931 2° observer in u′v′, 380 to 700 nm by 1 nm.
pub fn spectrum_locus() -> Curve {
    (380..=700)
        .filter_map(|nm| Observer::Cie1931TwoDegree.cmf_at(nm as f64))
        .map(|[x, y, z]| {
            uv(xyz_to_uv_prime(
                &Xyz::new(x, y, z),
                UvPrime { u: 0.0, v: 0.0 },
            ))
        })
        .collect()
}

/// A channel's share of its full-drive light in a reading: the reading above black
/// projected on the channel's primary (the matrix column), over that column's length.
fn channel_share(model: &MonitorModel, channel: usize, xyz: &Xyz) -> f64 {
    let column = model.matrix.column(channel);
    let above = xyz - model.black;
    column.dot(&above) / column.norm_squared().max(f64::MIN_POSITIVE)
}

/// The single-channel readings of `channel` at the standard condition, as (drive,
/// share), sorted by drive.
pub fn measured_shares(model: &MonitorModel, set: &MeasurementSet, channel: usize) -> Curve {
    let mut points: Curve = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition() && Role::from_drive(m.drive) == Role::Ramp)
        .filter(|m| (0..3).all(|c| (c == channel) == (m.drive[c] > 0.0)))
        .filter_map(|m| {
            Some((
                m.drive[channel],
                channel_share(model, channel, &m.usable_xyz()?),
            ))
        })
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// The smallest drive above zero of `channel` among the single-channel readings and
/// greys: where the fit's lowest level was, and so the toe of its log-domain laws.
pub fn smallest_drive(set: &MeasurementSet, channel: usize) -> f64 {
    set.measurements
        .iter()
        .filter(|m| m.usable_xyz().is_some() && m.is_standard_condition())
        .filter(|m| {
            let grey = m.drive.iter().all(|d| *d == m.drive[0]);
            let alone = (0..3).all(|c| (c == channel) == (m.drive[c] > 0.0));
            grey || alone
        })
        .map(|m| m.drive[channel])
        .filter(|v| *v > 0.0)
        .fold(1.0, f64::min)
}

/// The greys at the standard condition as (drive, Y over the model's white Y, both
/// above black).
fn measured_greys(model: &MonitorModel, set: &MeasurementSet) -> Curve {
    let white = model.white().y - model.black.y;
    let mut points: Curve = set
        .measurements
        .iter()
        .filter(|m| m.is_standard_condition())
        .filter(|m| m.drive[0] > 0.0 && m.drive.iter().all(|d| *d == m.drive[0]))
        .filter_map(|m| Some((m.drive[0], (m.usable_xyz()?.y - model.black.y) / white)))
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// `law` sampled at 101 drives.
fn sampled(law: &TransferLaw) -> Curve {
    (0..=100)
        .map(|i| {
            let v = i as f64 / 100.0;
            (v, law.excitation(v))
        })
        .collect()
}

/// A candidate law's curve rebuilt from the parameters the fit report lists for it,
/// scaled by its fitted amplitude where it has one, sampled at 101 drives. A table's
/// knots are not listed, so a table that was not chosen cannot be drawn; nor is the
/// toe of Cowan's and the three-term law, below which they are linear, so `toe` (the
/// smallest drive measured) stands in for it.
pub fn candidate_curve(
    kind: LawKind,
    parameters: &[chromacal_model::fit::laws::FittedParameter],
    toe: f64,
) -> Option<Curve> {
    let get = |name: &str| parameters.iter().find(|p| p.name == name).map(|p| p.value);
    let amplitude = get("amplitude").unwrap_or(1.0);
    // The curved HDR laws' curvature and toe (the plain ones have neither).
    let curved = || match kind {
        LawKind::PqCowan | LawKind::HlgCowan => Some((get("curvature")?, get("toe")?)),
        _ => Some((0.0, 0.0)),
    };
    let law = match kind {
        LawKind::Power => TransferLaw::Power(Power {
            gamma: get("gamma")?,
        }),
        LawKind::GainOffsetGamma => TransferLaw::GainOffsetGamma(GainOffsetGamma {
            gain: get("gain")?,
            gamma: get("gamma")?,
        }),
        LawKind::Cowan => TransferLaw::Cowan(Cowan {
            a: get("A")?,
            b: get("B")?,
            toe,
        }),
        LawKind::ThreeTerm => TransferLaw::ThreeTerm(ThreeTerm {
            a: get("A")?,
            b: get("B")?,
            c: get("C")?,
            toe,
        }),
        LawKind::Pq | LawKind::PqCowan => {
            let (curvature, toe) = curved()?;
            TransferLaw::Pq(Pq {
                peak: get("peak")?,
                rolloff_from: get("rolloff_from")?,
                exponent: get("exponent")?,
                curvature,
                toe,
            })
        }
        LawKind::Hlg | LawKind::HlgCowan => {
            let (curvature, toe) = curved()?;
            TransferLaw::Hlg(Hlg {
                exponent: get("exponent")?,
                curvature,
                toe,
            })
        }
        LawKind::Table => return None,
    };
    law.monotonicity().ok()?;
    Some(
        sampled(&law)
            .into_iter()
            .map(|(v, e)| (v, amplitude * e))
            .collect(),
    )
}

/// The chromaticity figure's data: primaries and white of the model, the locus, the
/// reference gamuts, and each channel's measured chromaticity at every level bright
/// enough (a tenth of full drive's light) for one.
fn chromaticities(model: &MonitorModel, set: Option<&MeasurementSet>) -> Chromaticities {
    let origin = UvPrime { u: 0.0, v: 0.0 };
    let primaries = [0, 1, 2].map(|c| uv(xyz_to_uv_prime(&model.matrix.column(c).into(), origin)));
    let measured = [0, 1, 2].map(|c| {
        let Some(set) = set else { return Vec::new() };
        let column: Xyz = model.matrix.column(c).into();
        set.measurements
            .iter()
            .filter(|m| m.is_standard_condition() && (0..3).all(|k| (k == c) == (m.drive[k] > 0.0)))
            .filter_map(|m| m.usable_xyz())
            .map(|xyz| xyz - model.black)
            .filter(|above| above.y > 0.1 * column.y)
            .map(|above| uv(xyz_to_uv_prime(&above, origin)))
            .collect()
    });
    Chromaticities {
        locus: spectrum_locus(),
        references: REFERENCE_SPACES
            .iter()
            .map(|space| (space.name, space_uv(space)))
            .collect(),
        primaries,
        white: uv(xyz_to_uv_prime(&model.white(), origin)),
        measured,
    }
}

/// Relative light (luminance-weighted gain) of the model's spatial map at `p`.
fn luminance_gain(model: &MonitorModel, p: ScreenPosition) -> f64 {
    let gains = model.spatial.gains(p);
    let ys = [0, 1, 2].map(|c| model.matrix[(1, c)]);
    let total: f64 = ys.iter().sum();
    if total.abs() < f64::MIN_POSITIVE {
        return 1.0;
    }
    (0..3).map(|c| gains[c] * ys[c]).sum::<f64>() / total
}

/// The fitted surface sampled on a `columns`×`rows` grid (top row first), and the
/// measured uniformity positions with their light relative to the centre's model.
fn uniformity_data(
    model: &MonitorModel,
    set: Option<&MeasurementSet>,
) -> (Vec<Vec<f64>>, Vec<GridPoint>) {
    let (columns, rows) = (32, 20);
    let surface = (0..rows)
        .map(|r| {
            (0..columns)
                .map(|k| {
                    let p = ScreenPosition::new(
                        (k as f64 + 0.5) / columns as f64,
                        (r as f64 + 0.5) / rows as f64,
                    );
                    luminance_gain(model, p)
                })
                .collect()
        })
        .collect();
    let mut sums: Vec<(ScreenPosition, f64, usize)> = Vec::new();
    for m in set.iter().flat_map(|s| s.measurements.iter()) {
        if m.role != Role::Uniformity || m.background != [0.0; 3] {
            continue;
        }
        let Some(xyz) = m.usable_xyz() else { continue };
        let centre = model.forward_centre(m.drive).y - model.black.y;
        if centre <= 0.0 {
            continue;
        }
        let ratio = (xyz.y - model.black.y) / centre;
        match sums.iter_mut().find(|s| s.0 == m.position) {
            Some(s) => {
                s.1 += ratio;
                s.2 += 1;
            }
            None => sums.push((m.position, ratio, 1)),
        }
    }
    let points = sums
        .into_iter()
        .map(|(p, sum, n)| GridPoint {
            x: p.x,
            y: p.y,
            percent: 100.0 * sum / n as f64,
        })
        .collect();
    (surface, points)
}

/// An 8-bit sRGB colour showing `xyz` as the display shows it: adapted from the
/// display's white to D65 (Bradford) with that white at Y = 1.
pub fn swatch(xyz: &Xyz, white: &Xyz) -> [u8; 3] {
    let d65 = xyy_to_xyz(&Xyy {
        x: D65_XY[0],
        y: D65_XY[1],
        big_y: 1.0,
    });
    if !(white.y > 0.0) {
        return [0, 0, 0];
    }
    let scaled = xyz / white.y;
    xyz_to_srgb8(&adapt(
        &scaled,
        AdaptationTransform::Bradford,
        &(white / white.y),
        &d65,
    ))
}

/// One profile of the daemon's history.
#[derive(Debug, Clone)]
pub struct HistoryPoint {
    pub id: String,
    /// Seconds since the Unix epoch.
    pub at_s: f64,
    pub how: String,
    pub held_out_mean: Option<f64>,
    /// The profile's white luminance (its units), where it could be read.
    pub white_luminance: Option<f64>,
}

/// What the daemon knows of past profiles and verifications.
#[derive(Debug, Clone, Default)]
pub struct HistoryView {
    pub profiles: Vec<HistoryPoint>,
    /// (seconds since the epoch, mean ΔE00) of each verification judged in ΔE00.
    pub verifications: Vec<(f64, f64)>,
    /// (seconds since the epoch, mean ΔE ITP) of each verification of a profile of
    /// an HDR signal, judged in ΔE ITP: drawn apart, in its own unit.
    pub verifications_itp: Vec<(f64, f64)>,
}

fn epoch_seconds(rfc3339: &str) -> Option<f64> {
    chromacal_formats::time::parse_rfc3339(rfc3339)?
        .duration_since(std::time::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_secs_f64())
}

impl HistoryView {
    /// The history of a profile store: each profile's held-out error and white
    /// luminance (read from its file), and the verifications' mean ΔE00. Entries whose
    /// date or file cannot be read are shown without the figure they lack.
    pub fn from_store(store: &ProfileStore) -> HistoryView {
        let history = store.history().unwrap_or_default();
        let profiles = history
            .entries
            .iter()
            .filter_map(|e| {
                let white_luminance = store
                    .profile_path(&e.id)
                    .ok()
                    .and_then(|p| Profile::read(&p).ok())
                    .map(|p| p.model.white().y);
                Some(HistoryPoint {
                    id: e.id.clone(),
                    at_s: epoch_seconds(&e.at)?,
                    how: e.how.clone(),
                    held_out_mean: e.held_out.as_ref().map(|s| s.mean),
                    white_luminance,
                })
            })
            .collect();
        let records = store.verifications().unwrap_or_default();
        let means = |metric| {
            records
                .iter()
                .filter(|v| v.metric == metric)
                .filter_map(|v| Some((epoch_seconds(&v.at)?, v.stats.as_ref()?.mean)))
                .collect()
        };
        HistoryView {
            profiles,
            verifications: means(crate::verify::Metric::De00),
            verifications_itp: means(crate::verify::Metric::Itp),
        }
    }

    /// The two history figures' series, in seconds since the Unix epoch: each
    /// profile's held-out error and each verification's, and each profile's white.
    fn series(&self) -> (Vec<TimeSeries>, Vec<TimeSeries>) {
        let errors = vec![
            TimeSeries {
                name: "held-out mean (each profile)".into(),
                points: self
                    .profiles
                    .iter()
                    .filter_map(|p| Some((p.at_s, p.held_out_mean?)))
                    .collect(),
            },
            TimeSeries {
                name: "verification mean".into(),
                points: self.verifications.clone(),
            },
        ];
        let white = vec![TimeSeries {
            name: "white luminance".into(),
            points: self
                .profiles
                .iter()
                .filter_map(|p| Some((p.at_s, p.white_luminance?)))
                .collect(),
        }];
        (errors, white)
    }
}

/// The readings a profile names as its source, when that file is still there and
/// reads; otherwise why not, for the page.
pub fn readings_of(profile: &Profile) -> Result<MeasurementSet, String> {
    let source = Path::new(&profile.provenance.source);
    if !source.exists() {
        return Err(format!(
            "the readings it was fitted on ({}) are not here: measured points are not drawn (give them with --readings)",
            profile.provenance.source
        ));
    }
    crate::measurement_file::read_measurements(source).map_err(|e| {
        format!(
            "the readings it was fitted on could not be read ({e}): measured points are not drawn"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use chromacal_model::fit::laws::FittedParameter;

    fn parameter(name: &str, value: f64) -> FittedParameter {
        FittedParameter {
            name: name.into(),
            value,
            standard_error: None,
        }
    }

    #[test]
    fn the_locus_runs_from_violet_through_green() {
        // CIE 1931 2°: 380 nm at x 0.1741, y 0.0050; 520 nm at x 0.0743, y 0.8338.
        let locus = spectrum_locus();
        assert_eq!(locus.len(), 321);
        let near = |p: (f64, f64), u: f64, v: f64| (p.0 - u).abs() < 2e-4 && (p.1 - v).abs() < 2e-4;
        assert!(near(locus[0], 0.2568, 0.0166), "{:?}", locus[0]);
        assert!(near(locus[140], 0.0231, 0.5837), "{:?}", locus[140]);
    }

    #[test]
    fn a_candidate_is_drawn_from_its_reported_parameters_and_amplitude() {
        let curve = candidate_curve(
            LawKind::Power,
            &[parameter("gamma", 2.2), parameter("amplitude", 0.9)],
            0.05,
        )
        .unwrap();
        assert!((curve[50].1 - 0.9 * 0.5_f64.powf(2.2)).abs() < 1e-12);
        // A law whose parameters are missing or unusable is not drawn.
        assert!(candidate_curve(LawKind::Power, &[parameter("gamma", -1.0)], 0.05).is_none());
        assert!(candidate_curve(LawKind::Cowan, &[parameter("A", 2.0)], 0.05).is_none());
        assert!(candidate_curve(LawKind::Table, &[parameter("knots", 9.0)], 0.05).is_none());
    }

    #[test]
    fn the_display_white_shows_as_page_white_whatever_its_chromaticity() {
        for (x, y) in [(0.3127, 0.3290), (0.2887, 0.3129), (0.3457, 0.3585)] {
            let white = xyy_to_xyz(&Xyy { x, y, big_y: 120.0 });
            assert_eq!(swatch(&white, &white), [255, 255, 255], "{x} {y}");
            let [r, g, b] = swatch(&(white * 0.2), &white);
            assert!(r == g && g == b && r < 255 && r > 100, "{r} {g} {b}");
        }
    }
}
