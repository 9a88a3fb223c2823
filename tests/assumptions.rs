//! Each switchable failure of the virtual monitor is caught by the check of the
//! assumption it breaks, and an ideal monitor passes them all.

use std::path::Path;

use chromacal_model::fit::checks::Verdict;
use chromacal_model::fit::{FitOptions, fit_monitor};

mod common;
use common::simulate;

fn with_failure(failure: &str) -> chromacal_model::fit::FittedModel {
    let config = format!("[monitor]\npreset = \"crt\"\n[monitor.failures]\n{failure}\n");
    let (set, _) = simulate(&config, Path::new("."));
    fit_monitor(&set, &FitOptions::default()).unwrap()
}

#[test]
fn an_ideal_monitor_passes_every_check() {
    let fit = with_failure("");
    let c = &fit.report.checks;
    for (name, verdict) in [
        ("constancy", c.primary_constancy_verdict),
        ("additivity", c.additivity_verdict),
        ("spatial independence", c.spatial_independence_verdict),
        ("temporal", c.temporal_stability_verdict),
        ("monotonicity", c.monotonicity_verdict),
    ] {
        assert_eq!(verdict, Verdict::WithinNoise, "{name}");
    }
}

#[test]
fn primary_non_constancy_is_caught() {
    let fit = with_failure("primary_nonconstancy = 0.05");
    let c = &fit.report.checks;
    assert_eq!(
        c.primary_constancy_verdict,
        Verdict::Fails,
        "{:?}",
        c.primary_constancy
    );
    assert!(c.primary_constancy.iter().all(|p| p.max_delta_uv > 0.004));
    // Spectra show it too: one shape no longer explains the ramp.
    let ideal = with_failure("");
    for (bad, good) in c
        .primary_constancy
        .iter()
        .zip(&ideal.report.checks.primary_constancy)
    {
        assert!(bad.spectral_first_component.unwrap() < good.spectral_first_component.unwrap());
    }
    assert_eq!(c.additivity_verdict, Verdict::WithinNoise);
}

#[test]
fn channel_interaction_is_caught_with_its_size() {
    let alpha = 0.06;
    let fit = with_failure(&format!("channel_interaction = {alpha}"));
    let c = &fit.report.checks;
    assert_ne!(
        c.additivity_verdict,
        Verdict::WithinNoise,
        "{:?}",
        c.additivity
    );
    // White loses α of its light, each primary alone α/3.
    let expected = ((1.0 - alpha) / (1.0 - alpha / 3.0) - 1.0) * 100.0;
    let white = c.additivity.iter().find(|a| a.drive == 1.0).unwrap();
    assert!(
        (white.luminance_departure_percent - expected).abs() < 0.5,
        "{white:?} vs {expected}"
    );
    assert_eq!(c.spatial_independence_verdict, Verdict::WithinNoise);
}

#[test]
fn surround_dependence_is_caught() {
    let fit = with_failure("surround_dependence = 0.1");
    let s = fit.report.checks.spatial_independence.clone().unwrap();
    assert!(s.luminance_change_percent < -5.0, "{s:?}");
    assert_ne!(s.verdict, Verdict::WithinNoise);
}

#[test]
fn warm_up_is_measured_and_correcting_it_lowers_the_error() {
    let config = "[monitor]\npreset = \"crt\"\n[monitor.failures]\nwarmup_amplitude = 0.06\nwarmup_time_constant_s = 150.0\n";
    let (set, _) = simulate(config, Path::new("."));
    let corrected = fit_monitor(&set, &FitOptions::default()).unwrap();
    let drift = &corrected.report.checks.temporal_stability;
    assert!(drift.corrected && drift.degree.unwrap() >= 1, "{drift:?}");
    assert!(drift.amplitude_percent > 2.0, "{drift:?}");
    assert_ne!(
        corrected.report.checks.temporal_stability_verdict,
        Verdict::WithinNoise
    );
    let uncorrected = fit_monitor(
        &set,
        &FitOptions {
            correct_drift: false,
            ..FitOptions::default()
        },
    )
    .unwrap();
    let (a, b) = (
        corrected.report.held_out.unwrap(),
        uncorrected.report.held_out.unwrap(),
    );
    eprintln!("warm-up: corrected {a:?}, uncorrected {b:?}");
    assert!(a.mean < b.mean, "correction must help: {a:?} vs {b:?}");
}
