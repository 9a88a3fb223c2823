//! `chromacal check`: predict every measured patch from a profile.

use super::shared::{out, outln};
use std::path::{Path, PathBuf};

use chromacal::html_report::{ReportInput, readings_of};
use chromacal::measurement_file::read_measurements;
use chromacal::profile::Profile;
use chromacal::report;
use chromacal::verification::{Criteria, verify};
use chromacal_crf::ScenePixel;
use chromacal_crf::explain::{SceneWeighted, WeighedPatch, scene_weighted};
use chromacal_crf::scene::read_xyz_csv;
use chromacal_crf::spectral_file::SpectralFile;
use chromacal_formats::numeric_csv::NumericTable;
use chromacal_model::ScreenPosition;
use chromacal_model::fit::checks::AssumptionChecks;
use chromacal_model::fit::validate::{Evaluation, evaluate};
use chromacal_model::measurement::Units;

use super::shared::{Failure, is_stdout};

/// Predict every measured patch from a profile and report the ΔE00.
#[derive(clap::Args)]
pub struct CheckArgs {
    /// The profile to check: a chromacal profile (TOML).
    profile: PathBuf,
    /// Measurements to predict: a run journal or an ArgyllCMS .ti3.
    measurements: PathBuf,
    /// Machine-readable output with every patch's prediction.
    #[arg(long)]
    json: bool,
    /// How many of the worst patches to list.
    #[arg(long, default_value_t = 10)]
    worst: usize,
    /// Weigh the error by a scene's colours: an XYZ list (X, Y, Z columns, in the
    /// measurements' units, and screen_x, screen_y where each is shown [default: the
    /// centre]) or a spectral CSV of radiances (wavelength_nm first, read as
    /// `spectrum` reads it). Each colour counts for the measured screen position
    /// nearest to it, and there for the patch nearest it in CIELAB.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Also write the verification report (`chromacal report`, its verification
    /// sections judging these measurements) to this file; `-` for standard output.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
    /// What the patches must achieve in the report: `strict`, `nominal`, `loose`, or
    /// limits as `mean=1,p95=2,max=4` [default: the default [publish] limits].
    #[arg(long, requires = "report")]
    criteria: Option<Criteria>,
}

pub fn run(args: CheckArgs) -> Result<(), Failure> {
    check(&args)
}

fn check(args: &CheckArgs) -> Result<(), Failure> {
    let (profile_path, measurements) = (args.profile.as_path(), args.measurements.as_path());
    let (json, worst, scene) = (args.json, args.worst, args.scene.as_deref());
    let profile = Profile::read(profile_path)?;
    let set = read_measurements(measurements)?;
    let mut model = profile.model.clone();
    let mut note = None;
    if profile.units != set.units {
        // Compare like with like: bring the profile to the measurements' scale.
        if set.units == Units::Relative {
            let y = model.white().y;
            if y > 0.0 {
                model = model.scaled(100.0 / y);
            }
        } else {
            return Err(Failure::from(
                "the profile is relative (white Y = 100) but the measurements are in cd/m²; \
                 fit the profile from measurements in cd/m², or check against relative ones",
            ));
        }
        note = Some(
            "the profile is in cd/m² and the measurements relative: the profile was scaled to white Y = 100",
        );
    }
    let evaluation = evaluate(
        &model,
        set.measurements
            .iter()
            .filter_map(|m| Some((m, m.usable_xyz()?))),
    );
    // A reading out of all range gives a ΔE00 that is not a number: name it rather
    // than print NaN as a result.
    let unscorable: Vec<String> = evaluation
        .patches
        .iter()
        .filter(|p| !p.delta_e00.is_finite())
        .map(|p| {
            format!(
                "patch {} (measured X Y Z {:e} {:e} {:e})",
                p.index, p.measured.x, p.measured.y, p.measured.z
            )
        })
        .collect();
    if !unscorable.is_empty() {
        return Err(Failure::from(format!(
            "{}: the ΔE00 of {} cannot be computed (a value out of all range): {}",
            measurements.display(),
            if unscorable.len() == 1 {
                "one reading".to_string()
            } else {
                format!("{} readings", unscorable.len())
            },
            unscorable.join(", ")
        )));
    }
    let scene_weighted = match scene {
        None => None,
        Some(path) => {
            let colours = read_check_scene(path, set.units)?;
            let patches: Vec<_> = evaluation
                .patches
                .iter()
                .map(|p| WeighedPatch {
                    measured: p.measured,
                    position: p.position,
                    delta_e00: p.delta_e00,
                })
                .collect();
            scene_weighted(&patches, &colours, &model.white())
        }
    };
    if let Some(path) = &args.report {
        if json && is_stdout(path) {
            return Err(Failure::from(
                "--json and --report - both want standard output: write the report to a file",
            ));
        }
        // The page shows the profile as it was compared: scaled to the readings' units.
        let compared = Profile {
            model: model.clone(),
            units: set.units,
            ..profile.clone()
        };
        let criteria = args
            .criteria
            .clone()
            .unwrap_or_else(|| super::report::default_criteria(&compared));
        let (readings, readings_note) = match readings_of(&profile) {
            Ok(_) if note.is_some() => (
                None,
                Some("the profile was scaled to the measurements' units, so its own readings are not drawn".to_string()),
            ),
            Ok(set) => (Some(set), None),
            Err(why) => (None, Some(why)),
        };
        let readings_note = match (readings_note, note) {
            (Some(why), Some(scaled)) => Some(format!("{scaled}; {why}")),
            (why, scaled) => why.or(scaled.map(str::to_string)),
        };
        super::report::write_page(
            &ReportInput {
                profile: &compared,
                readings: readings.as_ref(),
                readings_note,
                history: None,
                device: None,
                checked: Some(&set),
                verified: None,
                criteria: criteria.clone(),
            },
            path,
        )?;
        let verification = verify(&compared.model, &set, None, &criteria);
        eprintln!(
            "chromacal: judged by {}: {}",
            criteria.describe(),
            if verification.judgement.passes {
                "passes"
            } else {
                "fails"
            }
        );
        if is_stdout(path) {
            // The page is standard output: the summary would corrupt it.
            return Ok(());
        }
    }
    if json {
        #[derive(serde::Serialize)]
        struct Output<'a> {
            #[serde(skip_serializing_if = "Option::is_none")]
            scene_weighted: Option<&'a SceneWeighted>,
            profile: String,
            measurements: String,
            note: Option<&'a str>,
            #[serde(flatten)]
            evaluation: &'a Evaluation,
            /// The profile's assumption checks, each with the ΔE00 it costs.
            assumptions: &'a AssumptionChecks,
        }
        outln!(
            "{}",
            serde_json::to_string_pretty(&Output {
                scene_weighted: scene_weighted.as_ref(),
                profile: profile_path.display().to_string(),
                measurements: measurements.display().to_string(),
                note,
                evaluation: &evaluation,
                assumptions: &profile.report.checks,
            })?
        )?;
    } else {
        outln!(
            "chromacal: {} against {} ({} usable readings of {})",
            profile_path.display(),
            measurements.display(),
            evaluation.patches.len(),
            set.measurements.len()
        )?;
        if let Some(n) = note {
            outln!("  note: {n}")?;
        }
        out!("{}", report::check_summary(&evaluation, worst))?;
        if let Some(w) = &scene_weighted {
            outln!(
                "  weighted by the scene's {} colours ({} of the patches nearest them, at {} of the {} measured screen positions): mean ΔE00 {:.3}, max {:.3}",
                w.colours,
                w.patches_used,
                w.positions_used,
                w.positions_measured,
                w.mean,
                w.max
            )?;
            if w.positions_measured == 1 {
                outln!(
                    "  (every reading was taken at one place: where the scene's colours are shown cannot change this)"
                )?;
            }
        }
    }
    Ok(())
}

/// A scene for `--scene`: an XYZ list (X, Y, Z and optionally screen_x, screen_y, in
/// the measurements' units), or a spectral CSV (`wavelength_nm` first: radiances,
/// integrated to cd/m² by the same reader as `spectrum` and `render`, shown at the
/// centre).
fn read_check_scene(path: &Path, units: Units) -> Result<Vec<ScenePixel>, Failure> {
    let first = NumericTable::read(path)?.header[0].clone();
    if !first.eq_ignore_ascii_case("wavelength_nm") {
        return Ok(read_xyz_csv(path, 1.0).map_err(|e| e.to_string())?);
    }
    if units != Units::Absolute {
        return Err(Failure::from(format!(
            "{}: spectra integrate to cd/m², and the measurements are relative: give the scene as X, Y, Z in their units",
            path.display()
        )));
    }
    let file = SpectralFile::read(path).map_err(|e| e.to_string())?;
    Ok(file
        .emission_xyz()
        .map_err(|e| e.to_string())?
        .into_iter()
        .map(|xyz| ScenePixel {
            xyz,
            position: ScreenPosition::CENTRE,
        })
        .collect())
}
