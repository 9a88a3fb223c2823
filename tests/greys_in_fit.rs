//! The greys shape the channels' curves: with each channel measured at two levels only
//! (half and full drive, as in the 57-patch ArgyllCMS sets) and a grey ramp, the fitted
//! curves follow the shape the greys show, not the power law two levels allow. On the
//! real 57-patch sets, that halves the error on every held-out mixture.

use chromacal::comparison::MAX_TRAIN;
use chromacal_color::Xyz;
use chromacal_formats::cgats::read_ti3;
use chromacal_model::fit::validate::{evaluate, ramps_and_greys_split};
use chromacal_model::fit::{FitOptions, fit_monitor};
use chromacal_model::measurement::{MeasurementSet, Role};
use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

mod common;

/// A transfer no two-level power law can follow: half a v^1.6 and half a v^3.2.
fn truth(v: f64) -> f64 {
    0.5 * v.powf(1.6) + 0.5 * v.powf(3.2)
}

fn primaries() -> Matrix3<f64> {
    Matrix3::new(41.0, 36.0, 18.0, 21.0, 72.0, 7.0, 2.0, 12.0, 95.0)
}

/// Black, each channel at 0.5 and 1, and greys at eighths, with 0.2 % noise.
fn two_level_set(with_greys: bool, seed: u64) -> MeasurementSet {
    let mut drives: Vec<[f64; 3]> = vec![[0.0; 3], [0.0; 3], [1.0; 3], [1.0; 3]];
    for c in 0..3 {
        for level in [0.5, 1.0] {
            let mut d = [0.0; 3];
            d[c] = level;
            drives.push(d);
        }
    }
    if with_greys {
        drives.extend((1..8).map(|k| [k as f64 / 8.0; 3]));
    }
    readings_of("two levels per channel", &drives, truth, seed)
}

/// A reading at each of `drives` of a display whose channels all follow `truth`
/// (black (0.2, 0.2, 0.3), `primaries()`), with 0.2 % noise.
fn readings_of(
    source: &str,
    drives: &[[f64; 3]],
    truth: impl Fn(f64) -> f64,
    seed: u64,
) -> MeasurementSet {
    let black = Xyz::new(0.2, 0.2, 0.3);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.002).unwrap();
    let measurements = drives
        .iter()
        .enumerate()
        .map(|(index, drive)| {
            let light = primaries() * Vector3::from_fn(|c, _| truth(drive[c]));
            let xyz = (black + light).map(|v| v * (1.0 + noise.sample(&mut rng)));
            common::xyz_measurement(index, *drive, xyz)
        })
        .collect();
    common::measurement_set(source, measurements)
}

/// Largest relative error of the fitted excitations at a quarter and three quarters.
fn worst_curve_error(set: &MeasurementSet) -> f64 {
    let fit = fit_monitor(set, &FitOptions::default()).unwrap();
    let mut worst: f64 = 0.0;
    for law in &fit.model.laws {
        for v in [0.25, 0.75] {
            worst = worst.max((law.excitation(v) / truth(v) - 1.0).abs());
        }
    }
    worst
}

#[test]
fn with_two_levels_per_channel_the_curves_follow_the_greys() {
    for seed in 1..=5 {
        let with = worst_curve_error(&two_level_set(true, seed));
        let without = worst_curve_error(&two_level_set(false, seed));
        eprintln!("seed {seed}: worst curve error with greys {with:.4}, without {without:.4}");
        assert!(with < 0.05, "seed {seed}: {with}");
        // Two levels alone allow only a power law, 20 % off at a quarter drive.
        assert!(without > 0.1, "seed {seed}: {without}");
    }
}

#[test]
fn the_57_patch_sets_predict_their_mixtures_from_the_greys() {
    for (name, bound) in [
        ("macbookpro15_2014_colormunki_spectral_57.ti3", 0.35),
        ("samsung_s24a350h_colormunki_spectral_57.ti3", 1.15),
    ] {
        let set = read_ti3(&common::shared_path(&format!("measurements/{name}"))).unwrap();
        let (train, test) = ramps_and_greys_split(&set, MAX_TRAIN);
        assert!(train.measurements.len() <= MAX_TRAIN);
        assert!(
            test.measurements
                .iter()
                .all(|m| Role::from_drive(m.drive) == Role::Mixture)
        );
        let fit = fit_monitor(&train, &FitOptions::default()).unwrap();
        let held = evaluate(
            &fit.model,
            test.measurements
                .iter()
                .filter_map(|m| Some((m, m.usable_xyz()?))),
        )
        .stats
        .unwrap();
        eprintln!("{name}: {held:?}, law {:?}", fit.report.chosen_law());
        assert_eq!(held.n, 36);
        assert!(held.mean < bound, "{name}: {held:?}");
    }
}

/// Noise-free readings of an exact power law 2.2 at these drives (ramps and greys).
fn power_law_set(drives: &[[f64; 3]]) -> MeasurementSet {
    let black = Xyz::new(0.2, 0.2, 0.3);
    let measurements = drives
        .iter()
        .enumerate()
        .map(|(index, drive)| {
            let light = primaries() * Vector3::from_fn(|c, _| drive[c].powf(2.2));
            common::xyz_measurement(index, *drive, black + light)
        })
        .collect();
    common::measurement_set("exact power law", measurements)
}

#[test]
fn grey_shares_keep_their_scale_when_a_fold_takes_an_unpinned_ramps_top_level() {
    // Full drive overloaded on every channel: each ramp normalises by its top level,
    // 0.9, which some fold leaves out. Cross-validating an exact law on exact data
    // must then still find no error at all.
    let mut drives = vec![[0.0; 3]];
    for c in 0..3 {
        for k in 1..=9 {
            let mut d = [0.0; 3];
            d[c] = k as f64 / 10.0;
            drives.push(d);
        }
    }
    drives.extend((1..=9).map(|k| [k as f64 / 10.0 - 0.05; 3]));
    let fit = fit_monitor(
        &power_law_set(&drives),
        &FitOptions {
            laws: vec![chromacal_model::LawKind::Power],
            ..FitOptions::default()
        },
    )
    .unwrap();
    let power = &fit.report.laws[0];
    let cv = power.cross_validation.as_ref().expect("cross-validated");
    assert!(cv.max < 1e-6, "{cv:?}");
}

/// Black, white, each channel and the grey at sixteenths, 0.2 % noise, every channel
/// following `truth`.
fn sixteenths_set(truth: impl Fn(f64) -> f64, seed: u64) -> MeasurementSet {
    let mut drives: Vec<[f64; 3]> = vec![[0.0; 3], [0.0; 3], [1.0; 3], [1.0; 3]];
    for k in 1..=16 {
        let level = k as f64 / 16.0;
        for c in 0..3 {
            let mut d = [0.0; 3];
            d[c] = level;
            drives.push(d);
        }
        if k < 16 {
            drives.push([level; 3]);
        }
    }
    readings_of("sixteenths", &drives, truth, seed)
}

fn cowan_only() -> FitOptions {
    FitOptions {
        laws: vec![chromacal_model::transfer::LawKind::Cowan],
        ..FitOptions::default()
    }
}

/// Issue 11: a law corrected at the measured levels. A curve with a slow 3 % wiggle no
/// two-parameter law follows gets the correction, and between the measured levels the
/// corrected curve is closer to the truth than the law alone could be.
#[test]
fn a_shape_the_law_misses_is_corrected_at_the_measured_levels() {
    let wiggle = |v: f64| v.powf(2.2) * (1.0 + 0.03 * (2.0 * std::f64::consts::PI * v).sin());
    for seed in 1..=3 {
        let fit = fit_monitor(&sixteenths_set(wiggle, seed), &cowan_only()).unwrap();
        let correction = fit.report.law_correction.clone().expect("tried");
        eprintln!("seed {seed}: {correction:?}");
        assert!(correction.kept, "seed {seed}: {correction:?}");
        let (alone, with) = (correction.law_cv.unwrap(), correction.corrected_cv.unwrap());
        assert!(with.mean < 0.7 * alone.mean, "{alone:?} {with:?}");
        // Between the measured levels, above the darkest (where 3 % is no light): the
        // law alone misses the wiggle by 1 to 2 %.
        for law in &fit.model.laws {
            let errors: Vec<f64> = (3..16)
                .map(|k| (k as f64 + 0.5) / 16.0)
                .map(|v| (law.excitation(v) / wiggle(v) - 1.0).abs())
                .collect();
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            let worst = errors.iter().copied().fold(0.0, f64::max);
            eprintln!("seed {seed}: curve error between levels mean {mean:.4}, worst {worst:.4}");
            assert!(mean < 0.004 && worst < 0.01, "seed {seed}: {errors:?}");
        }
    }
}

/// Issue 11: a display the law already follows is not corrected, at realistic noise
/// (0.2 %): false positives stay under 5 %.
#[test]
fn a_law_that_fits_gets_no_correction() {
    let kept = (1..=20)
        .filter(|seed| {
            let fit = fit_monitor(&sixteenths_set(|v| v.powf(2.2), *seed), &cowan_only()).unwrap();
            fit.report.law_correction.is_some_and(|c| c.kept)
        })
        .count();
    assert!(kept <= 1, "corrected in {kept} of 20 runs");
}

/// Issue 11: each primary is its full-drive reading. The TN panel's blue moves with
/// drive; a column taken along every level's axis missed its own full-drive reading by
/// 1.8 ΔE00 and made the held-out mixtures 85 % worse (1.05 against 0.57).
#[test]
fn the_tn_panel_s_primaries_are_its_full_drive_readings() {
    let set = read_ti3(&common::shared_path(
        "measurements/samsung_s24a350h_colormunki_spectral_57.ti3",
    ))
    .unwrap();
    let (train, test) = ramps_and_greys_split(&set, MAX_TRAIN);
    let fit = fit_monitor(&train, &FitOptions::default()).unwrap();
    let white = train.mean_white().unwrap();
    for m in &train.measurements {
        let single = m.drive.iter().filter(|d| **d > 0.0).count() == 1;
        if single && m.drive.contains(&1.0) {
            let measured = m.usable_xyz().unwrap();
            let predicted = fit.model.forward_centre(m.drive);
            let error =
                chromacal_model::fit::validate::delta_e00_xyz(&measured, &predicted, &white);
            assert!(error < 0.15, "{:?}: ΔE00 {error}", m.drive);
        }
    }
    let held = evaluate(
        &fit.model,
        test.measurements
            .iter()
            .filter_map(|m| Some((m, m.usable_xyz()?))),
    )
    .stats
    .unwrap();
    assert!(held.mean < 0.7, "{held:?}");
}
