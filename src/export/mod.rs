//! Publishing a profile to other tools: ICC v4 and v2 display profiles (with `vcgt`
//! when there are calibration curves), ArgyllCMS CGATS `.ti3` (the run's
//! measurements) and `.cal` (calibration curves), PsychoPy monitor files, and the
//! native profile as JSON.
//!
//! Each format says what it cannot carry: an ICC profile describes the centre of the
//! screen (the additivity terms in its LUT tags, `icc_lut`), a PsychoPy file an
//! additive display; the spatial map, a failed additivity or
//! primary-constancy check, and a surround dependence are listed in the profile's
//! description and returned as notes.

pub mod colord;

use std::borrow::Cow;
use std::path::Path;

use crate::measurement_file::read_measurements;
use crate::profile::Profile;
use chromacal_formats::icc::{self, IccText, IccVersion};
use chromacal_formats::matrix_trc::MatrixTrc;
use chromacal_formats::{cal, psychopy};
use chromacal_model::fit::checks::Verdict;
use chromacal_model::measurement::{MeasurementSet, Units};
use chromacal_model::target::{CalibrationCurves, Target, TargetError, calibration_curves};

/// The formats `export` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Icc4,
    Icc2,
    Ti3,
    Cal,
    Psychopy,
    Json,
    Toml,
}

impl Format {
    pub const NAMES: &'static str = "icc4, icc2, ti3, cal, psychopy, json, toml";

    pub fn parse(text: &str) -> Result<Format, ExportError> {
        Ok(match text.to_ascii_lowercase().as_str() {
            "icc4" | "icc" => Format::Icc4,
            "icc2" => Format::Icc2,
            "ti3" => Format::Ti3,
            "cal" => Format::Cal,
            "psychopy" => Format::Psychopy,
            "json" => Format::Json,
            "toml" => Format::Toml,
            _ => return Err(ExportError::UnknownFormat(text.to_string())),
        })
    }

    /// The formats with a place for calibration curves: the ICC `vcgt` tag, the
    /// ArgyllCMS `.cal` file, and the CAL table a `.ti3` ends with.
    pub fn carries_curves(self) -> bool {
        matches!(
            self,
            Format::Icc4 | Format::Icc2 | Format::Cal | Format::Ti3
        )
    }

    pub fn name(self) -> &'static str {
        match self {
            Format::Icc4 => "icc4",
            Format::Icc2 => "icc2",
            Format::Ti3 => "ti3",
            Format::Cal => "cal",
            Format::Psychopy => "psychopy",
            Format::Json => "json",
            Format::Toml => "toml",
        }
    }

    /// The MIME type an HTTP answer carries.
    pub fn content_type(self) -> &'static str {
        match self {
            Format::Icc4 | Format::Icc2 => "application/vnd.iccprofile",
            Format::Json | Format::Psychopy => "application/json",
            Format::Toml => "application/toml",
            Format::Ti3 | Format::Cal => "text/plain; charset=utf-8",
        }
    }

    /// The usual file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Icc4 | Format::Icc2 => "icc",
            Format::Ti3 => "ti3",
            Format::Cal => "cal",
            Format::Psychopy | Format::Json => "json",
            Format::Toml => "toml",
        }
    }
}

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("unknown format '{0}': one of {names}", names = Format::NAMES)]
    UnknownFormat(String),
    #[error(
        "calibration curves need a target: give a white point, a tone curve or a luminance (or calibrate with [target])"
    )]
    NoTarget,
    #[error("{0}")]
    Target(#[from] TargetError),
    #[error(
        "a .ti3 needs the run's measurements, and {path} cannot be read ({reason}); give them with --measurements"
    )]
    NoMeasurements { path: String, reason: String },
    #[error("the profile's model has a singular primary matrix")]
    Singular,
    #[error("cannot write the profile: {0}")]
    Serialize(String),
    #[error(
        "--native writes the display without calibration curves, and a target asks for curves: give one or the other"
    )]
    NativeWithTarget,
}

/// What the export needs besides the profile.
#[derive(Debug, Clone, Default)]
pub struct ExportOptions {
    /// Calibration curves to this target (for `.cal`, and `vcgt` in ICC).
    pub target: Option<Target>,
    /// The measurements (default: the journal named in the profile's provenance).
    pub measurements: Option<MeasurementSet>,
    /// The display as measured, without the curves the profile has (an ICC of the
    /// uncalibrated screen, a `.ti3` of its readings as they were taken).
    pub native: bool,
}

/// An exported file and what it could not carry.
#[derive(Debug, Clone)]
pub struct Exported {
    pub bytes: Vec<u8>,
    /// What the profile knows that the file does not carry.
    pub not_carried: Vec<String>,
    /// What else the user should know (a target that was not reachable, say).
    pub warnings: Vec<String>,
    /// What the file carries beyond the fitted model (the calibration's measured
    /// greys, where they correct its laws).
    pub carried: Vec<String>,
    pub calibration: Option<CalibrationCurves>,
}

/// What a description of this profile leaves out: a PsychoPy gamma grid, or an ICC
/// profile, which carries the additivity terms in its LUT tags (`carries_terms`).
/// (Calibration curves solved at export go through the whole model, terms included:
/// `model::target::calibration_curves`.)
pub fn limitations(profile: &Profile, carries_terms: bool) -> Vec<String> {
    let report = &profile.report;
    let mut notes = Vec::new();
    if !matches!(profile.model.spatial, chromacal_model::SpatialMap::Uniform) {
        let falloff = report
            .spatial
            .largest_falloff_percent
            .map_or(String::new(), |f| {
                format!("; elsewhere up to {f:.1} % less light")
            });
        notes.push(format!(
            "the spatial map (the profile describes the centre of the screen{falloff})"
        ));
    }
    let checks = &report.checks;
    let terms = &profile.model.terms;
    if let Some(gamma) = terms.interaction.filter(|_| !carries_terms) {
        notes.push(format!(
            "the model's channel-interaction term (each channel's light changes by γ = {:+.4}, {:+.4}, {:+.4} per full channel beside it); the curves and matrix are exact without it",
            gamma[0], gamma[1], gamma[2]
        ));
    }
    if let Some(kappa) = terms.crosstalk.filter(|_| !carries_terms) {
        notes.push(format!(
            "the model's crosstalk term (each channel's light changes by κ = {:+.4}, {:+.4}, {:+.4} per full channel beside it, less as the channel nears full drive); the curves and matrix are exact without it",
            kappa[0], kappa[1], kappa[2]
        ));
    }
    if let Some(lambda) = terms.drive_crosstalk.filter(|_| !carries_terms) {
        notes.push(format!(
            "the model's crosstalk term in drive (each channel's light changes by λ = {:+.4}, {:+.4}, {:+.4} per channel beside it at full drive, less as the channel nears full drive); the curves and matrix are exact without it",
            lambda[0], lambda[1], lambda[2]
        ));
    }
    if terms.chromaticity_shift.is_some() && !carries_terms {
        notes.push(
            "the model's drive-dependent primary chromaticity term (the primaries are those of full drive)"
                .into(),
        );
    }
    if let Some(gamma) = terms.hlg_ootf.filter(|_| !carries_terms) {
        let gain = if terms.hlg_ootf_through_laws && terms.hlg_ootf_beyond.is_some() {
            "what its law gives at the code whose OOTF output alone is the same (beyond full signal, a power of its scene light measured on the greys and whites)"
        } else if terms.hlg_ootf_through_laws {
            "what its law gives at the code whose OOTF output alone is the same"
        } else {
            "its light alone times (Y_S / (w_c E_c))^(γ − 1)"
        };
        notes.push(format!(
            "the model's HLG OOTF (BT.2100, system gamma {gamma:.3}): each channel's light in a mixture is {gain}, a grey's more than its channels' sum; the curves and matrix are each channel's alone"
        ));
    }
    if !terms.is_empty() && carries_terms {
        notes.push(
            "the terms in the matrix/TRC tags, which hold the additive part for readers that do not read the LUT tags"
                .into(),
        );
    }
    // The interaction carries every grey's departure; crosstalk, which vanishes at full
    // drive, only those below it.
    let uncarried: Vec<_> = checks
        .additivity
        .iter()
        .filter(|a| a.verdict == Verdict::Fails)
        .filter(|a| {
            let crosstalk = terms.crosstalk.is_some() || terms.drive_crosstalk.is_some();
            // The HLG OOTF is a display's greys departing from their channels by design,
            // and the LUT tags carry it.
            terms.interaction.is_none()
                && terms.hlg_ootf.is_none()
                && (!crosstalk || a.drive >= 1.0)
        })
        .collect();
    // The largest departure in X, Y or Z (a white can add up in luminance and not in Z).
    let worst = uncarried
        .iter()
        .flat_map(|a| {
            let xyz = a
                .xyz_departure_percent
                .unwrap_or([0.0, a.luminance_departure_percent, 0.0]);
            (0..3).map(move |j| (a.drive, j, xyz[j]))
        })
        .max_by(|a, b| a.2.abs().total_cmp(&b.2.abs()));
    if let (Verdict::Fails, Some((drive, j, departure))) = (checks.additivity_verdict, worst) {
        let what = if drive >= 1.0 {
            "the white's".to_string()
        } else {
            format!("the grey's at {:.0} % drive", drive * 100.0)
        };
        notes.push(format!(
            "channel interaction ({what} {} {departure:+.1} % off the sum of its channels)",
            ["X", "Y", "Z"][j]
        ));
    }
    if checks.primary_constancy_verdict == Verdict::Fails && terms.chromaticity_shift.is_none() {
        notes.push("primary chromaticities that change with drive".into());
    }
    if checks.spatial_independence_verdict == Verdict::Fails {
        notes.push("the dependence of the light on the surround".into());
    }
    if report.luminance_only.is_some() {
        notes.push(
            "measured primary chromaticities (a light meter read luminance only; they were given)"
                .into(),
        );
    }
    notes
}

/// When the profile was made (its RFC 3339 `created`; now if that cannot be read).
fn created_time(created: &str) -> jiff::Timestamp {
    created
        .trim()
        .parse::<jiff::Timestamp>()
        .unwrap_or_else(|_| jiff::Timestamp::now())
}

/// An ICC dateTimeNumber (ICC.1:2022 §4.2): year, month, day, hours, minutes and
/// seconds, in UTC.
fn icc_date_time(time: jiff::Timestamp) -> [u16; 6] {
    let t = time.to_zoned(jiff::tz::TimeZone::UTC);
    [
        t.year() as u16,
        t.month() as u16,
        t.day() as u16,
        t.hour() as u16,
        t.minute() as u16,
        t.second() as u16,
    ]
}

/// The profile's own measurements: `options.measurements`, else the journal its
/// provenance names.
fn measurements(profile: &Profile, options: &ExportOptions) -> Result<MeasurementSet, ExportError> {
    if let Some(set) = &options.measurements {
        return Ok(set.clone());
    }
    let source = &profile.provenance.source;
    read_measurements(Path::new(source)).map_err(|e| ExportError::NoMeasurements {
        path: source.clone(),
        reason: e.to_string(),
    })
}

/// The ICC `desc`, which system pickers show as the profile's name: short, the
/// display, the day it was made and what it is calibrated to (`native` without
/// curves). The rest goes to [`details`].
fn short_description(profile: &Profile, calibration: Option<&CalibrationCurves>) -> String {
    let display = shortened(
        profile.provenance.display.as_deref().unwrap_or("display"),
        40,
    );
    let day = created_time(&profile.created)
        .to_zoned(jiff::tz::TimeZone::UTC)
        .date();
    let calibrated = calibration.map_or("native".to_string(), |k| {
        use chromacal_model::target::WhiteTarget;
        let white = match k.target.white {
            WhiteTarget::Native => "native white".to_string(),
            WhiteTarget::Chromaticity([x, y])
                if (x - 0.3127).abs() < 5e-5 && (y - 0.3290).abs() < 5e-5 =>
            {
                "D65".to_string()
            }
            WhiteTarget::Chromaticity([x, y]) => format!("x{x:.3} y{y:.3}"),
            WhiteTarget::Daylight(t) => format!("{t:.0}K"),
        };
        format!("{white} {}", k.target.tone.describe())
    });
    format!("{display} {day} {calibrated}")
}

/// `name` in at most `max` characters for a menu: whole when it fits, else without a
/// closing parenthetical ("window on DUMMY0 of X display :0 (8 bits)" lost only its
/// closing parenthesis to a plain cut), else cut with "...".
fn shortened(name: &str, max: usize) -> String {
    if name.chars().count() <= max {
        return name.to_string();
    }
    if let Some(open) = name.rfind(" (")
        && name.ends_with(')')
        && name[..open].chars().count() <= max
    {
        return name[..open].to_string();
    }
    let mut cut: String = name.chars().take(max.saturating_sub(3)).collect();
    cut += "...";
    cut
}

/// The long description: profile id, held-out error, target, what is not carried.
fn details(profile: &Profile, notes: &[String], calibration: Option<&CalibrationCurves>) -> String {
    let display = profile
        .provenance
        .display
        .clone()
        .unwrap_or_else(|| "display".into());
    let mut text = format!("chromacal {} ({display})", profile.id);
    if let Some(held) = &profile.report.held_out {
        text += &format!(", held-out mean dE00 {:.2}", held.mean);
    }
    if let Some(k) = calibration {
        text += &format!(", calibrated to {}", k.describe());
    }
    if !notes.is_empty() {
        text += "; not carried: ";
        text += &notes.join("; ");
    }
    text
}

/// The calibration curves of `profile` for `target`: computed now from `model` (the
/// profile's `output_model`, which an ICC's curves describe too) when a target is
/// given, otherwise the curves its calibration measured into place, if it made any.
pub fn calibration_for(
    profile: &Profile,
    model: &chromacal_model::MonitorModel,
    target: Option<&Target>,
) -> Result<Option<CalibrationCurves>, TargetError> {
    Ok(match target {
        Some(target) => Some(calibration_curves(model, target)?),
        None => profile.calibration.as_ref().map(|c| c.curves.clone()),
    })
}

/// The readings of `set` as readings through `curves`: each was taken at a drive the
/// panel got straight, which through the curves is the input that gives that drive
/// (every channel's curve inverted), so the device values become the curves' inputs
/// and the colours stay as measured. Readings at drives no input gives are left out,
/// and counted.
fn through_curves(set: &MeasurementSet, curves: &CalibrationCurves) -> (MeasurementSet, usize) {
    // Within a 16-bit step of a curve's ends still counts as reached.
    const REACH: f64 = 1.0 / 65535.0;
    let mut through = set.clone();
    through.measurements.clear();
    let mut unreachable = 0;
    for m in &set.measurements {
        let reachable = (0..3).all(|c| {
            let curve = &curves.curves[c];
            let (lo, hi) = (curve[0], curve[curve.len() - 1]);
            m.drive[c] >= lo - REACH && m.drive[c] <= hi + REACH
        });
        if !reachable {
            unreachable += 1;
            continue;
        }
        let mut m = m.clone();
        m.drive =
            [0, 1, 2].map(|c| chromacal_crf::lut3d::curve_input(&curves.curves[c], m.drive[c]));
        m.codes = None;
        through.measurements.push(m);
    }
    (through, unreachable)
}

/// The grey levels a calibration measured through its curves, as readings at their
/// inputs, numbered from `first`.
fn checked_levels(
    stored: &crate::profile::StoredCalibration,
    first: usize,
) -> Vec<chromacal_model::measurement::Measurement> {
    use chromacal_model::measurement::{Measurement, Role};
    stored
        .levels
        .iter()
        .enumerate()
        .map(|(k, level)| Measurement {
            index: first + k,
            role: Role::Grey,
            drive: [level.input; 3],
            codes: None,
            position: chromacal_model::ScreenPosition::CENTRE,
            background: [0.0; 3],
            window: None,
            time_s: None,
            reading: chromacal_instruments::Reading {
                xyz: Some(chromacal_color::Xyz::from(level.measured_xyz)),
                ..Default::default()
            },
        })
        .collect()
}

/// Export `profile` as `format`.
pub fn export(
    profile: &Profile,
    format: Format,
    options: &ExportOptions,
) -> Result<Exported, ExportError> {
    if options.native && options.target.is_some() {
        return Err(ExportError::NativeWithTarget);
    }
    // The model corrected by the calibration's measured greys, where they predict the
    // held-out patches better (as `lut3d`, `render` and `verify`'s charts go through
    // it): curves solved now and an ICC's curves and matrix describe it.
    let (model, said_of_greys) = profile.output_model();
    let calibration = match options.native {
        true => None,
        false => calibration_for(profile, &model, options.target.as_ref())?,
    };
    let mut notes = limitations(profile, matches!(format, Format::Icc4 | Format::Icc2));
    let mut warnings = Vec::new();
    let mut carried = Vec::new();
    if let Some(k) = &calibration
        && k.luminance_limited
    {
        warnings.push(format!(
            "the white point allows at most {:.2} {}; the target luminance was lowered to it",
            k.white_luminance(),
            units_name(profile.units)
        ));
    }
    if let Some(k) = &calibration
        && (k.predicted_white_de00 > 0.5 || k.predicted_grey_de00 > 1.0)
    {
        warnings.push(format!(
            "the model predicts these curves miss the target: white by {:.2} ΔE00, greys by up to {:.2} (a channel that would have to go below zero near black, or a curve held to keep rising)",
            k.predicted_white_de00, k.predicted_grey_de00
        ));
    }
    let created_at = created_time(&profile.created);
    let created = icc_date_time(created_at);
    let bytes = match format {
        Format::Icc4 | Format::Icc2 => {
            if profile.model.matrix.try_inverse().is_none() {
                return Err(ExportError::Singular);
            }
            // Through calibration curves the display's white is the calibrated one;
            // without, the measured white the `.ti3` is normalised to.
            let measured = match calibration {
                None => profile.report.white_anchor.as_ref().map(|w| w.measured),
                Some(_) => None,
            };
            if let (Cow::Owned(_), Some(said)) = (&model, &said_of_greys) {
                carried.push(said.clone());
            }
            let matrix_trc = MatrixTrc::relative_to(&model, calibration.as_ref(), measured);
            if matrix_trc.black_clipped && matrix_trc.luts.is_none() {
                notes.push("the black's chromaticity (outside the primaries' triangle)".into());
            }
            let text = IccText {
                description: short_description(profile, calibration.as_ref()),
                details: details(profile, &notes, calibration.as_ref()),
                copyright: "No copyright. Made by chromacal from measurements of this display."
                    .into(),
                created,
            };
            let version = if format == Format::Icc4 {
                IccVersion::V4
            } else {
                IccVersion::V2
            };
            icc::encode(&matrix_trc, &text, version)
        }
        Format::Ti3 => {
            let set = measurements(profile, options)?;
            match &calibration {
                None => chromacal_formats::cgats::to_ti3(&set).into_bytes(),
                Some(curves) => {
                    let (mut through, unreachable) = through_curves(&set, curves);
                    // The readings the calibration took through its own curves (the
                    // grey ramp up to the calibrated white) are through them already.
                    if options.target.is_none()
                        && let Some(stored) = &profile.calibration
                    {
                        through
                            .measurements
                            .extend(checked_levels(stored, through.measurements.len()));
                    }
                    if unreachable > 0 {
                        warnings.push(format!(
                            "{unreachable} readings at drives the curves never send (beyond the calibrated white, or below what they start at) are left out"
                        ));
                    }
                    // As dispread writes it: the readings, then the CAL table of the
                    // curves they are through.
                    let mut text = chromacal_formats::cgats::to_ti3(&through);
                    text.push('\n');
                    text += &cal::cal_text(curves, &profile.created);
                    text.into_bytes()
                }
            }
        }
        Format::Cal => {
            let curves = calibration.as_ref().ok_or(ExportError::NoTarget)?;
            cal::cal_text(curves, &profile.created).into_bytes()
        }
        Format::Psychopy => {
            let set = measurements(profile, options).ok();
            let mut text = details(profile, &notes, None);
            if profile.units == Units::Relative {
                text += "; luminances are relative (white = 100), not cd/m²";
            }
            psychopy::monitor_file(
                &profile.model,
                set.as_ref(),
                &psychopy::calibration_name(created_at, &jiff::tz::TimeZone::system()),
                created_at.as_millisecond() as f64 / 1000.0,
                &text,
            )
            .into_bytes()
        }
        Format::Json => {
            serde_json::to_vec_pretty(profile).map_err(|e| ExportError::Serialize(e.to_string()))?
        }
        Format::Toml => profile
            .to_toml()
            .map_err(|e| ExportError::Serialize(e.to_string()))?
            .into_bytes(),
    };
    if matches!(
        format,
        Format::Ti3 | Format::Cal | Format::Json | Format::Toml
    ) {
        // These carry measurements, curves or the whole profile, not a model that
        // leaves things out.
        notes.clear();
    }

    Ok(Exported {
        bytes,
        not_carried: notes,
        carried,
        warnings,
        calibration,
    })
}

fn units_name(units: Units) -> &'static str {
    match units {
        Units::Absolute => "cd/m²",
        Units::Relative => "(relative units)",
    }
}

/// A target from the words a user gives (`--white`, `--tone`, `--luminance`; the same
/// as the API's query): none given, no target. Unset parts default to the native
/// white, gamma 2.2 and the most luminance the white allows.
pub fn parse_target(
    white: Option<&str>,
    tone: Option<&str>,
    luminance: Option<&str>,
) -> Result<Option<Target>, ExportError> {
    use chromacal_model::target::{ToneCurve, WhiteTarget, parse_tone, parse_white};
    if white.is_none() && tone.is_none() && luminance.is_none() {
        return Ok(None);
    }
    let luminance = match luminance.map(str::trim) {
        None | Some("max") => None,
        Some(text) => match text.parse::<f64>() {
            Ok(v) if v > 0.0 && v.is_finite() => Some(v),
            _ => {
                return Err(TargetError::Parse {
                    what: "luminance",
                    text: text.into(),
                    expected: "a positive number in the profile's units, or max",
                }
                .into());
            }
        },
    };
    Ok(Some(Target {
        white: white
            .map(parse_white)
            .transpose()?
            .unwrap_or(WhiteTarget::Native),
        tone: tone
            .map(parse_tone)
            .transpose()?
            .unwrap_or(ToneCurve::Power(2.2)),
        luminance,
    }))
}

#[cfg(test)]
mod tests {
    use super::shortened;

    #[test]
    fn a_long_display_name_is_shortened_without_a_broken_parenthesis() {
        assert_eq!(
            shortened("virtual monitor 'crt'", 40),
            "virtual monitor 'crt'"
        );
        assert_eq!(
            shortened("window on DUMMY0 of X display :0 (8 bits)", 40),
            "window on DUMMY0 of X display :0"
        );
        let long = "emulator screen at /tmp/chromacal-emulate-pr670-24644.sock";
        let short = shortened(long, 40);
        assert_eq!(short.chars().count(), 40);
        assert!(short.ends_with("...") && long.starts_with(&short[..37]));
    }
}
