//! The hard cases of the numerics: each gives a usable profile or a clear error that
//! names its cause, and none panics.

use std::path::Path;

use chromacal::measurement_file::read_measurements;
use chromacal::profile::{Profile, Provenance, SCHEMA_VERSION};
use chromacal_instruments::ReadingStatus;
use chromacal_model::ScreenPosition;
use chromacal_model::fit::{FitError, FitOptions, fit_monitor};
use chromacal_model::measurement::Role;
use chromacal_model::transfer::LawKind;

mod common;
use common::{chromacal, fixture, isetbio_monitor, simulate};

fn laws(kinds: &[LawKind]) -> FitOptions {
    FitOptions {
        laws: kinds.to_vec(),
        ..FitOptions::default()
    }
}

/// The profile of a fit, as the store would keep it.
fn profile_of(fit: &chromacal_model::fit::FittedModel) -> Profile {
    Profile {
        schema_version: SCHEMA_VERSION,
        id: "test".into(),
        created: "now".into(),
        units: fit.report.units,
        model: fit.model.clone(),
        provenance: Provenance {
            source: "test".into(),
            display: None,
            instrument: None,
            measured_at: None,
            config_digest: None,
            program: "test".into(),
            settings_at_resume: None,
            edid: None,
            correction: None,
            uncorrected: None,
            signal: None,
        },
        report: fit.report.clone(),
        calibration: None,
        cost: None,
    }
}

/// The profile a fit makes, as TOML: no NaN or infinity anywhere in it.
fn assert_finite_profile(fit: &chromacal_model::fit::FittedModel) {
    let text = profile_of(fit).to_toml().unwrap();
    fn all_finite(value: &toml::Value, path: &str) {
        match value {
            toml::Value::Float(f) => assert!(f.is_finite(), "{path} = {f}"),
            toml::Value::Array(a) => a
                .iter()
                .enumerate()
                .for_each(|(i, v)| all_finite(v, &format!("{path}[{i}]"))),
            toml::Value::Table(t) => t
                .iter()
                .for_each(|(k, v)| all_finite(v, &format!("{path}.{k}"))),
            _ => {}
        }
    }
    all_finite(&toml::from_str::<toml::Value>(&text).unwrap(), "profile");
    let back = Profile::from_toml(&text, "memory").unwrap();
    for law in &back.model.laws {
        law.monotonicity().unwrap();
    }
}

#[test]
fn zero_and_negative_readings_after_black_subtraction() {
    // A noise floor of 1 cd/m² against a 0.2 cd/m² black: the dimmest ramp levels
    // read below black.
    let config = "[monitor]\npreset = \"lcd\"\n[instrument.simulated]\nnoise_floor = 1.0\nlow_light_limit = 0.0\n";
    let (set, truth) = simulate(config, Path::new("."));
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    let black_y = fit.report.black.xyz.y;
    let below = set
        .measurements
        .iter()
        .filter(|m| m.role == Role::Ramp)
        .filter(|m| m.reading.xyz.is_some_and(|x| x.y < black_y))
        .count();
    assert!(
        below > 0,
        "the case must really have ramp readings below black"
    );
    // Dark patches are as uncertain as the floor makes them; the profile is still right
    // where the light is.
    let (white, true_white) = (fit.model.white(), truth.white());
    assert!(
        (white - true_white).norm() / true_white.norm() < 0.03, // each primary rests on one full-drive reading with ±1 cd/m² of noise
        "{white:?} vs {true_white:?}"
    );
    assert!(fit.report.held_out.unwrap().mean.is_finite());
    assert_finite_profile(&fit);
}

#[test]
fn zero_drive_inside_log_laws_is_black_and_inverts_to_zero() {
    let set = read_measurements(&fixture("journals/crt-default.jsonl")).unwrap();
    for kind in [LawKind::Cowan, LawKind::ThreeTerm] {
        let fit = fit_monitor(&set, &laws(&[kind])).unwrap();
        let model = &fit.model;
        assert_eq!(model.forward_centre([0.0; 3]), model.black);
        let back = model.inverse(&model.black, ScreenPosition::CENTRE).unwrap();
        assert_eq!(back.drive, [0.0; 3]);
        for law in &model.laws {
            assert_eq!(law.excitation(0.0), 0.0);
            assert!(law.excitation(1e-6).is_finite());
        }
    }
}

#[test]
fn a_log_law_that_turns_back_near_zero_is_caught_and_never_published() {
    // A lifted toe: 3 % of the light rises as v^0.2, the rest as v^2.4. An
    // unconstrained Cowan fit turns back near v = 0.04.
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("lifted-toe.csv");
    let mut text = String::from("dac,input_norm,R,G,B\n");
    for d in 0..256 {
        let v = d as f64 / 255.0;
        let e = 0.03 * v.powf(0.2) + 0.97 * v.powf(2.4);
        text += &format!("{d},{v},{e},{e},{e}\n");
    }
    std::fs::write(&table, text).unwrap();
    let config = format!(
        "[monitor]\npreset = \"lcd\"\ntransfer_csv = \"{}\"\n",
        table.display()
    );
    let (set, _) = simulate(&config, Path::new("."));
    let fit = fit_monitor(&set, &laws(&[LawKind::Cowan, LawKind::ThreeTerm])).unwrap();
    let cowan = fit
        .report
        .laws
        .iter()
        .find(|l| l.law == LawKind::Cowan)
        .unwrap();
    assert!(
        cowan
            .notes
            .iter()
            .filter(|n| n.contains("turned back"))
            .count()
            == 3,
        "{:?}",
        cowan.notes
    );
    for law in &fit.model.laws {
        law.monotonicity().unwrap();
    }
    // The inverse is monotone: darker XYZ never asks for more drive.
    let mut previous = -1.0;
    for k in 0..=200 {
        let e = k as f64 / 200.0;
        let d = fit.model.laws[1].drive(e);
        assert!(d >= previous, "drive falls at excitation {e}");
        previous = d;
    }
    assert_finite_profile(&fit);
}

#[test]
fn overload_at_full_drive_extrapolates_the_primary() {
    // Green at full drive (70 cd/m²) and white overload a 60 cd/m² instrument.
    let config = "[monitor]\npreset = \"crt\"\n[instrument.simulated]\noverload_limit = 60.0\n";
    let (set, truth) = simulate(config, Path::new("."));
    let overloaded = set
        .measurements
        .iter()
        .filter(|m| m.reading.status == ReadingStatus::Overload)
        .count();
    assert!(overloaded > 5);
    assert!(
        set.measurements
            .iter()
            .filter(|m| m.reading.status == ReadingStatus::Overload)
            .all(|m| m.reading.xyz.is_none())
    );
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    let green = &fit.report.primaries[1];
    assert!(!green.full_drive_measured);
    assert!(fit.report.primaries[0].full_drive_measured);
    let truth_y = truth.matrix[(1, 1)];
    assert!(
        (green.xyz.y - truth_y).abs() / truth_y < 0.03,
        "{} vs {truth_y}",
        green.xyz.y
    );
    assert_eq!(fit.report.counts.overload, overloaded);
    let held = fit.report.held_out.unwrap();
    assert!(held.mean < 1.0, "{held:?}");
    assert_finite_profile(&fit);
}

#[test]
fn a_non_monotone_ramp_is_pooled_and_reported() {
    let mut set = read_measurements(&fixture("journals/crt-default.jsonl")).unwrap();
    // Swap the readings of two neighbouring red levels: the brighter reads less.
    let mut red: Vec<usize> = (0..set.measurements.len())
        .filter(|i| {
            let m = &set.measurements[*i];
            m.role == Role::Ramp && m.drive[0] > 0.0
        })
        .collect();
    red.sort_by(|a, b| set.measurements[*a].drive[0].total_cmp(&set.measurements[*b].drive[0]));
    let (a, b) = (red[6], red[7]);
    let reading = set.measurements[a].reading.clone();
    set.measurements[a].reading = set.measurements[b].reading.clone();
    set.measurements[b].reading = reading;
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    let red_check = &fit.report.checks.monotonicity[0];
    assert_eq!(red_check.reversals_beyond_noise, 1);
    assert_eq!(
        fit.report.checks.monotonicity_verdict,
        chromacal_model::fit::checks::Verdict::Fails
    );
    let table = fit
        .report
        .laws
        .iter()
        .find(|l| l.law == LawKind::Table)
        .unwrap();
    assert!(
        table.notes.iter().any(|n| n.contains("pooled")),
        "{:?}",
        table.notes
    );
    assert_finite_profile(&fit);
}

#[test]
fn two_or_three_levels_per_channel_still_give_a_profile() {
    for (budget, levels, max_mean) in [(9, 2, 2.0), (12, 3, 0.5)] {
        let config = format!("[plan]\nstrategy = \"fixed\"\nbudget = {budget}\n");
        let (set, _) = simulate(&config, Path::new("."));
        let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
        assert!(fit.report.primaries.iter().all(|p| p.levels == levels));
        let held = fit.report.held_out.unwrap();
        assert!(held.mean < max_mean, "budget {budget}: {held:?}");
        assert!(!fit.report.law_rule.is_empty());
        assert_finite_profile(&fit);
    }
}

#[test]
fn near_collinear_primaries_are_refused_with_the_condition_number() {
    // Blue is almost exactly half red and half green.
    let dir = tempfile::tempdir().unwrap();
    let spd = common::shared_table("displays/spd/isetbio_lcd_dell_spd.csv");
    let mut text = String::from("wavelength_nm,R,G,B\n");
    for row in &spd {
        let blue = 0.5 * row[1] + 0.5 * row[2] + 0.0002 * row[3];
        text += &format!("{},{},{},{}\n", row[0], row[1], row[2], blue);
    }
    let primaries = dir.path().join("collinear.csv");
    std::fs::write(&primaries, text).unwrap();
    let config = format!(
        "[monitor]\npreset = \"lcd\"\nprimaries_csv = \"{}\"\n",
        primaries.display()
    );
    let (set, _) = simulate(&config, Path::new("."));
    match fit_monitor(&set, &FitOptions::default()) {
        Err(FitError::IllConditioned { condition, limit }) => {
            assert!(condition > limit);
            let message = FitError::IllConditioned { condition, limit }.to_string();
            assert!(message.contains("nearly collinear") && message.contains("condition number"));
        }
        other => panic!(
            "expected a refusal, got {:?}",
            other.map(|f| f.report.condition_number)
        ),
    }
    // Knowingly raised, the limit lets the profile through and the report says why.
    let options = FitOptions {
        max_condition_number: 1e9,
        ..FitOptions::default()
    };
    let fit = fit_monitor(&set, &options).unwrap();
    assert!(fit.report.condition_number > 1000.0);

    // The command keeps the journal and says what was wrong.
    let state = tempfile::tempdir().unwrap();
    let config_file = state.path().join("collinear.toml");
    std::fs::write(&config_file, &config).unwrap();
    let out = chromacal()
        .args([
            "calibrate",
            "--config",
            config_file.to_str().unwrap(),
            "--state-dir",
        ])
        .arg(state.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("nearly collinear"));
    let journal = std::fs::read_dir(state.path().join("runs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path()
        .join("journal.jsonl");
    // Every reading kept: the whole plan, beside the header.
    let (header, entries, _) = chromacal::journal::Journal::read(&journal).unwrap();
    assert_eq!(entries.len(), header.plan.patches.len());
    assert_eq!(
        std::fs::read_to_string(&journal).unwrap().lines().count(),
        entries.len() + 1
    );
}

#[test]
fn an_oled_from_a_ten_thousandth_to_a_thousand_candelas() {
    let monitor = isetbio_monitor(
        "isetbio_oled_sony",
        "white_luminance = 1000.0\nblack_luminance = 0.0001\nflare_luminance = 0.0\nfalloff = 0.02",
    );
    let (set, _) = simulate(&monitor, Path::new("."));
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    assert!(fit.report.counts.below_range > 0);
    assert!(
        fit.report
            .black
            .note
            .contains("below the instrument's range"),
        "{}",
        fit.report.black.note
    );
    assert!(fit.report.black.xyz.y < 0.003);
    let white = fit.model.white().y;
    assert!((white - 1000.0).abs() < 20.0, "{white}");
    let held = fit.report.held_out.unwrap();
    assert!(held.mean < 1.0, "{held:?}");
    assert_finite_profile(&fit);
}

#[test]
fn black_with_no_chromaticity_gives_finite_figures() {
    // No emitted black, no flare: X + Y + Z of black is noise around zero.
    let config = "[monitor]\npreset = \"crt\"\nblack_luminance = 0.0\nflare_luminance = 0.0\n[instrument.simulated]\nlow_light_limit = 0.0\n";
    let (set, _) = simulate(config, Path::new("."));
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    assert!(fit.report.black.xyz.norm() < 0.01);
    assert_finite_profile(&fit);
    let checks = &fit.report.checks;
    assert!(
        checks
            .primary_constancy
            .iter()
            .all(|c| c.max_delta_uv.is_finite())
    );
}

/// A grid read by an instrument that stayed at the centre while the patch moved (the
/// window sink without --prompt-positions did this): every grid reading is the dark
/// surround. Nothing of it is fitted, and the summary says why, once; a real screen's
/// darkest corner (half the centre's light) is still taken.
#[test]
fn a_grid_the_instrument_did_not_see_is_left_out_and_said() {
    let mut set = read_measurements(&fixture("journals/crt-default.jsonl")).unwrap();
    let grid = set
        .measurements
        .iter()
        .filter(|m| m.role == Role::Uniformity && m.reading.xyz.is_some())
        .count();
    assert!(grid > 8, "{grid}");
    let mut dimmed = set.clone();
    for m in set
        .measurements
        .iter_mut()
        .filter(|m| m.role == Role::Uniformity)
    {
        m.reading.xyz = m.reading.xyz.map(|xyz| xyz * 0.001);
    }
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    assert_eq!(fit.report.spatial.unseen, grid);
    assert_eq!(fit.report.spatial.positions, 0);
    assert!(matches!(
        fit.model.spatial,
        chromacal_model::SpatialMap::Uniform
    ));
    let summary = chromacal::report::fit_summary(&fit.report);
    assert!(
        summary.contains(&format!(
            "WARNING: {grid} uniformity-grid reading(s) under 20 % of the centre's light were left out"
        )) && summary.contains("--prompt-positions"),
        "{summary}"
    );
    // The report page says it in its uniformity section.
    let profile = profile_of(&fit);
    let page = chromacal::html_report::report_html(&chromacal::html_report::ReportInput {
        profile: &profile,
        readings: Some(&set),
        readings_note: None,
        history: None,
        device: None,
        checked: None,
        criteria: Default::default(),
        verified: None,
    })
    .unwrap();
    let section = &page[page.find("id=\"uniformity\"").unwrap()..];
    assert!(
        section.contains(&format!(
            "{grid} grid reading(s) under 20 % of the centre's light were left out"
        )),
        "{section}"
    );
    // Half the light, as a poor screen's corner: fitted, nothing said.
    for m in dimmed
        .measurements
        .iter_mut()
        .filter(|m| m.role == Role::Uniformity)
    {
        m.reading.xyz = m.reading.xyz.map(|xyz| xyz * 0.5);
    }
    let fit = fit_monitor(&dimmed, &FitOptions::default()).unwrap();
    assert_eq!(fit.report.spatial.unseen, 0);
    assert_eq!(fit.report.spatial.positions, 24);
    assert!(!chromacal::report::fit_summary(&fit.report).contains("WARNING: "));
}

#[test]
fn a_uniformity_grid_with_missing_cells() {
    let mut set = read_measurements(&fixture("journals/crt-default.jsonl")).unwrap();
    let full = fit_monitor(&set, &FitOptions::default()).unwrap();
    assert_eq!(full.report.spatial.positions, 24);
    // Drop ten cells and make two more unusable.
    let mut dropped = 0;
    set.measurements.retain(|m| {
        let drop = m.role == Role::Uniformity && dropped < 10;
        dropped += drop as usize;
        !drop
    });
    for m in set
        .measurements
        .iter_mut()
        .filter(|m| m.role == Role::Uniformity)
        .take(2)
    {
        m.reading.status = ReadingStatus::Overload;
        m.reading.xyz = None;
    }
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    assert_eq!(fit.report.spatial.positions, 12);
    assert!(!matches!(
        fit.model.spatial,
        chromacal_model::SpatialMap::Uniform
    ));
    // Four cells cannot carry a surface: the map falls back to uniform and says why.
    let mut kept = 0;
    set.measurements.retain(|m| {
        let keep = m.role != Role::Uniformity || m.reading.xyz.is_some() && kept < 4;
        kept += (m.role == Role::Uniformity && keep) as usize;
        keep
    });
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    assert_eq!(fit.report.spatial.positions, 4);
    assert!(matches!(
        fit.model.spatial,
        chromacal_model::SpatialMap::Uniform
    ));
    assert!(
        fit.report
            .spatial
            .candidates
            .iter()
            .any(|c| c.note.as_deref().is_some_and(|n| n.contains("too few")))
    );
}

#[test]
fn infinite_and_missing_values_in_imported_files_are_errors() {
    let text = std::fs::read_to_string(fixture("ti3/crt-default.ti3")).unwrap();
    // The row's fields past XYZ (the spectra of a spectral instrument) are zeros.
    let fields: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("NUMBER_OF_FIELDS "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let spectra = " 0".repeat(fields - 7);
    for bad in ["inf", "-inf", "NaN", "1e999", "x"] {
        let broken = text
            .replacen(
                "\nEND_DATA\n",
                &format!("\n99 0 0 0 1 {bad} 1{spectra}\nEND_DATA\n"),
                1,
            )
            .replace("NUMBER_OF_SETS 71", "NUMBER_OF_SETS 72");
        let err = chromacal_formats::cgats::ti3_from_text(&broken, "broken.ti3")
            .unwrap_err()
            .to_string();
        assert!(err.contains("XYZ_Y") && err.contains(bad), "{bad}: {err}");
    }
}

/// A fit of `set` on its own thread: its result, or `None` if it has not ended after a
/// minute (a hang; a real fit of these few readings takes milliseconds).
fn fit_that_ends(
    set: chromacal_model::measurement::MeasurementSet,
) -> Option<Result<chromacal_model::fit::FittedModel, FitError>> {
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(fit_monitor(&set, &FitOptions::default()));
    });
    receive
        .recv_timeout(std::time::Duration::from_secs(60))
        .ok()
}

#[test]
fn a_reading_out_of_all_proportion_ends_the_fit_with_a_result() {
    // One ramp reading a million times too bright (a unit slip in a journal): the log
    // laws' misfit overflows, and the line search once compared infinities for ever.
    let (mut set, _) = simulate("", Path::new("."));
    let ramp = set
        .measurements
        .iter_mut()
        .find(|m| m.role == Role::Ramp)
        .unwrap();
    let xyz = ramp.reading.xyz.unwrap();
    ramp.reading.xyz = Some(chromacal_color::Xyz::new(xyz.x * 1e6, 2e6, xyz.z * 1e6));
    let result = fit_that_ends(set).expect("the fit did not end");
    // Whatever it concludes, it says it in numbers or in words, never NaN.
    if let Ok(fit) = result {
        assert_finite_profile(&fit);
    }
}

#[test]
fn a_black_patch_relabelled_as_a_red_level_ends_the_fit() {
    // A real MacBook Pro set with its first black patch relabelled as red at 33.33 %
    // (an edit slip): the red ramp then turns back at its foot, and the fit once
    // searched for ever.
    let source = common::shared_text("measurements/macbookpro15_2014_colormunki_spectral_57.ti3");
    let black = "0.000000000 0.000000000 0.000000000";
    let at = source.find(black).expect("the set has a black patch");
    let edited = format!(
        "{}33.33000000 0.000000000 0.000000000{}",
        &source[..at],
        &source[at + black.len()..]
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("edited.ti3");
    std::fs::write(&path, edited).unwrap();
    let set = read_measurements(&path).unwrap();
    let result = fit_that_ends(set).expect("the fit did not end");
    if let Ok(fit) = result {
        assert_finite_profile(&fit);
    }
}

#[test]
fn a_uniformity_reading_of_minus_1e308_ends_the_fit() {
    // One grid position read as −1e308: its gain is −∞, and the SVD of the surface
    // fit iterated for ever on it.
    let (mut set, _) = simulate("", Path::new("."));
    let position = set
        .measurements
        .iter_mut()
        .find(|m| m.role == Role::Uniformity)
        .expect("the default plan measures a uniformity grid");
    let xyz = position.reading.xyz.unwrap();
    position.reading.xyz = Some(chromacal_color::Xyz::new(xyz.x, -1e308, xyz.z));
    let fit = fit_that_ends(set)
        .expect("the fit did not end")
        .expect("one absurd grid reading is left out, not fatal");
    assert_finite_profile(&fit);
}

#[test]
fn a_stop_check_ends_a_long_fit_early() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    // A 36-position uniformity grid makes the fit take seconds; a stop asked for
    // during it ends it within a fraction of that.
    let dir = tempfile::tempdir().unwrap();
    let (set, _) = simulate("[plan]\nuniformity_grid = 36\n", dir.path());
    let started = std::time::Instant::now();
    fit_monitor(&set, &FitOptions::default()).unwrap();
    let whole = started.elapsed();

    let stop = Arc::new(AtomicBool::new(false));
    let check: chromacal_model::fit::cancel::StopCheck = {
        let stop = stop.clone();
        Arc::new(move || stop.load(Ordering::SeqCst))
    };
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let result = chromacal_model::fit::cancel::with_stop(Some(check), || {
            fit_monitor(&set, &FitOptions::default())
        });
        let _ = send.send((result, std::time::Instant::now()));
    });
    std::thread::sleep(whole / 10);
    stop.store(true, Ordering::SeqCst);
    let asked = std::time::Instant::now();
    let (result, ended) = receive
        .recv_timeout(std::time::Duration::from_secs(60))
        .expect("the stopped fit did not end");
    assert!(
        matches!(result, Err(FitError::Stopped)),
        "{:?}",
        result.map(|_| "a whole fit")
    );
    let after = ended.saturating_duration_since(asked);
    assert!(
        after < whole / 4,
        "the fit ended {after:?} after the stop; a whole fit takes {whole:?}"
    );
}
