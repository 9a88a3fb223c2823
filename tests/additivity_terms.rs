//! The terms for what additivity misses (channel interaction, chromaticity that moves
//! with drive) are kept only where the data show them: virtual monitors that are
//! additive by construction almost never get one, and monitors with each failure get
//! the term that models it and predict held-out mixtures better for it.

use std::path::Path;

use chromacal_model::ScreenPosition;
use chromacal_model::fit::terms::TermSet;
use chromacal_model::fit::{FitOptions, FittedModel, fit_monitor};

mod common;
use common::{isetbio_monitor, simulate};

/// The fit with and without terms of one seeded run of `monitor` (a `[monitor]`
/// section) with `failures`.
fn fits(monitor: &str, failures: &str, seed: u64) -> (FittedModel, FittedModel) {
    fits_with_plan(monitor, failures, seed, "")
}

/// `fits`, with `plan` added to the `[plan]` section.
fn fits_with_plan(
    monitor: &str,
    failures: &str,
    seed: u64,
    plan: &str,
) -> (FittedModel, FittedModel) {
    let config = format!(
        "{monitor}\n[monitor.failures]\n{failures}\n[instrument.simulated]\nseed = {seed}\n[plan]\nseed = {seed}\n{plan}\n"
    );
    let (set, _) = simulate(&config, Path::new("."));
    let with = fit_monitor(&set, &FitOptions::default()).unwrap();
    let plain = fit_monitor(
        &set,
        &FitOptions {
            additivity_terms: false,
            ..FitOptions::default()
        },
    )
    .unwrap();
    (with, plain)
}

fn kept(fit: &FittedModel) -> TermSet {
    let kept: Vec<TermSet> = fit
        .report
        .terms
        .iter()
        .filter(|t| t.kept)
        .map(|t| t.terms)
        .collect();
    assert_eq!(kept.len(), 1, "{:?}", fit.report.terms);
    kept[0]
}

fn held_out(fit: &FittedModel) -> f64 {
    fit.report.held_out.unwrap().mean
}

#[test]
fn additive_monitors_almost_never_get_a_term() {
    let monitors = [
        "[monitor]\npreset = \"crt\"".to_string(),
        "[monitor]\npreset = \"lcd\"".to_string(),
        isetbio_monitor("isetbio_lcd_dell", ""),
        isetbio_monitor("isetbio_oled_sony", ""),
    ];
    let seeds = 25;
    let mut runs = 0;
    let mut with_a_term = Vec::new();
    for monitor in &monitors {
        for seed in 1..=seeds {
            let (with, plain) = fits(monitor, "", seed);
            runs += 1;
            let set = kept(&with);
            if set != TermSet::None {
                with_a_term.push((monitor.lines().nth(1).unwrap_or("").to_string(), seed, set));
                // A term kept on an additive monitor must at least not cost accuracy.
                assert!(
                    held_out(&with) <= held_out(&plain) + 0.01,
                    "seed {seed}: {} against {}",
                    held_out(&with),
                    held_out(&plain)
                );
            } else {
                assert!(with.model.terms.is_empty());
                assert_eq!(with.model, plain.model);
            }
        }
    }
    eprintln!(
        "{} of {runs} additive runs kept a term: {with_a_term:?}",
        with_a_term.len()
    );
    assert!(
        (with_a_term.len() as f64) < 0.05 * runs as f64,
        "{} of {runs} additive runs kept a term: {with_a_term:?}",
        with_a_term.len()
    );
}

#[test]
fn channel_interaction_gets_its_term_and_predicts_better() {
    let (mut with_sum, mut plain_sum) = (0.0, 0.0);
    for seed in 1..=8 {
        let (with, plain) = fits(
            "[monitor]\npreset = \"crt\"",
            "channel_interaction = 0.06",
            seed,
        );
        assert!(
            matches!(kept(&with), TermSet::Interaction | TermSet::Both),
            "seed {seed}: {:?}",
            with.report.terms
        );
        // The virtual monitor's light drops by 0.06 times the mean channel output, so
        // each channel loses 0.02 per full channel beside it.
        let gamma = with.model.terms.interaction.unwrap();
        for g in gamma {
            assert!((g + 0.02).abs() < 0.006, "seed {seed}: γ = {gamma:?}");
        }
        with_sum += held_out(&with);
        plain_sum += held_out(&plain);
    }
    assert!(
        with_sum < 0.6 * plain_sum,
        "held-out mean {} with the term, {} without",
        with_sum / 8.0,
        plain_sum / 8.0
    );
}

#[test]
fn primaries_that_move_with_drive_get_the_shift_and_predict_better() {
    let (mut with_sum, mut plain_sum) = (0.0, 0.0);
    for seed in 1..=8 {
        let (with, plain) = fits(
            "[monitor]\npreset = \"crt\"",
            "primary_nonconstancy = 0.03",
            seed,
        );
        assert!(
            matches!(kept(&with), TermSet::ChromaticityShift | TermSet::Both),
            "seed {seed}: {:?}",
            with.report.terms
        );
        with_sum += held_out(&with);
        plain_sum += held_out(&plain);
    }
    assert!(
        with_sum < 0.4 * plain_sum,
        "held-out mean {} with the term, {} without",
        with_sum / 8.0,
        plain_sum / 8.0
    );
}

#[test]
fn a_model_with_terms_inverts_what_it_predicts_and_survives_its_file() {
    let (with, _) = fits(
        "[monitor]\npreset = \"crt\"",
        "primary_nonconstancy = 0.03\nchannel_interaction = 0.06",
        3,
    );
    let model = &with.model;
    assert!(!model.terms.is_empty());
    for drive in [
        [0.2, 0.5, 0.9],
        [0.5, 0.5, 0.5],
        [0.05, 0.0, 0.7],
        [1.0, 1.0, 1.0],
    ] {
        let xyz = model.forward_centre(drive);
        let back = model.inverse(&xyz, ScreenPosition::CENTRE).unwrap();
        let again = model.forward_centre(back.drive);
        assert!(
            (again - xyz).norm() < 1e-6 * xyz.norm(),
            "{drive:?}: {back:?}"
        );
    }
    let text = toml::to_string(model).unwrap();
    let read: chromacal_model::MonitorModel = toml::from_str(&text).unwrap();
    assert_eq!(&read, model);
}

/// Issue 27: a plasma-like panel, whose light drops with the mean output of the screen
/// (an automatic brightness limiter), built from a real measured table and real spectra
/// (ISETBio's Sony OLED): its greys read 5–8 % below the sum of their channels at mid
/// drive. What the greys and whites show is carried to the mixtures by the interaction
/// term, which is a light-dependent gain to first order, and the mixtures held out of
/// the fit gain from it.
#[test]
fn a_plasma_like_limiter_is_learnt_from_the_greys_and_carried_to_the_mixtures() {
    let monitor = isetbio_monitor("isetbio_oled_sony", "");
    let (mut with_sum, mut plain_sum) = (0.0, 0.0);
    for seed in 1..=6 {
        let (with, plain) = fits(&monitor, "channel_interaction = 0.35", seed);
        let deficit: Vec<(f64, f64)> = with
            .report
            .checks
            .additivity
            .iter()
            .map(|a| (a.drive, a.luminance_departure_percent))
            .collect();
        // The hard case as the issue states it: mid grey 5–8 % below the channel sum.
        let mid = deficit
            .iter()
            .min_by(|a, b| (a.0 - 0.5).abs().total_cmp(&(b.0 - 0.5).abs()))
            .unwrap();
        assert!((-8.0..=-5.0).contains(&mid.1), "seed {seed}: {deficit:?}");
        eprintln!(
            "seed {seed}: kept {:?}, held-out {:.3} with, {:.3} without; greys' departure from the channel sum (drive, %) {deficit:.3?}",
            kept(&with),
            held_out(&with),
            held_out(&plain)
        );
        assert!(
            matches!(kept(&with), TermSet::Interaction | TermSet::Both),
            "seed {seed}: {:?}",
            with.report.terms
        );
        with_sum += held_out(&with);
        plain_sum += held_out(&plain);
    }
    assert!(
        with_sum < 0.5 * plain_sum,
        "held-out mean {} with the term, {} without",
        with_sum / 6.0,
        plain_sum / 6.0
    );
}

/// Calibration curves solved at export go through the whole model: on a
/// plasma-like limiter (which dims a grey by up to a quarter below its channels' sum)
/// and on a CRT whose primaries move with drive, the colours the curves ask for are
/// the ones the kept terms predict, not the additive part's, at D65, 9300 K and D50.
/// Judged on the virtual monitor itself (its noise-free light through the curves), at
/// 16 bits so that the display's own code steps (one code of blue near the top moves
/// Z by 1 %, 0.7 ΔE00) do not decide.
#[test]
fn curves_solved_at_export_take_the_kept_terms_into_account() {
    use chromacal_model::target::{
        Target, ToneCurve, WhiteTarget, calibration_curves, white_error,
    };
    use chromacal_sim::monitor::centre_patch;
    let whites = [
        WhiteTarget::Chromaticity([0.3127, 0.3290]),
        WhiteTarget::Daylight(9300.0),
        WhiteTarget::Daylight(5003.0),
    ];
    // (monitor, failure, most white ΔE00, most tone error) through the whole model.
    // On the limiter the white lands 0.3–0.4 from D65, 1.0–1.6 from 9300 K and D50:
    // the term's shape against the limiter's, further from the native white.
    let cases = [
        (
            isetbio_monitor("isetbio_oled_sony", "bit_depth = 16"),
            "channel_interaction = 0.35",
            2.0,
            0.05,
        ),
        (
            "[monitor]\npreset = \"crt\"\nbit_depth = 16".to_string(),
            "primary_nonconstancy = 0.03",
            0.5,
            0.006,
        ),
    ];
    for (monitor, failure, most_white, most_tone) in cases {
        for seed in 1..=3 {
            let config_text = common::with_fixed_plan(&format!(
                "{monitor}\n[monitor.failures]\n{failure}\n[instrument.simulated]\nseed = {seed}\n[plan]\nseed = {seed}\n"
            ));
            let (set, _) = simulate(&config_text, Path::new("."));
            let fitted = fit_monitor(&set, &FitOptions::default()).unwrap();
            assert!(
                !fitted.model.terms.is_empty(),
                "{failure}, seed {seed}: no term kept"
            );
            let mut additive = fitted.model.clone();
            additive.terms = Default::default();
            let config = chromacal::config::parse_config(&config_text, "test config").unwrap();
            let rig =
                chromacal::calibrate::session::rig_for(&config, Path::new("."), None).unwrap();
            let mut screen = rig.monitor.lock().unwrap();
            // (white ΔE00 from the target, largest |Y / Y_target − 1| at k/8) on screen.
            let mut judge = |model: &chromacal_model::MonitorModel, white: WhiteTarget| {
                let target = Target {
                    white,
                    tone: ToneCurve::Power(2.2),
                    luminance: None,
                };
                let curves = calibration_curves(model, &target).unwrap();
                let mut shown = |x: f64| {
                    screen.show(centre_patch(curves.apply([x; 3])));
                    screen.clock().advance(10.0);
                    screen.xyz_at(screen.patch_centre()).unwrap()
                };
                let white = nalgebra::Vector3::from(curves.white);
                let white_de = white_error(&shown(1.0), &white);
                let black = shown(0.0).y;
                let tone = (1..=8)
                    .map(|k| {
                        let x = f64::from(k) / 8.0;
                        let want = black + (white.y - black) * x.powf(2.2);
                        (shown(x).y / want - 1.0).abs()
                    })
                    .fold(0.0, f64::max);
                (white_de, tone)
            };
            for white in whites {
                let (whole_white, whole_tone) = judge(&fitted.model, white);
                let (additive_white, additive_tone) = judge(&additive, white);
                eprintln!(
                    "{failure}, seed {seed}, {white:?}: on the screen, white ΔE00 {whole_white:.3} and tone within {:.2} % through the whole model's curves; {additive_white:.3} and {:.2} % through the additive part's",
                    100.0 * whole_tone,
                    100.0 * additive_tone
                );
                // On the limiter what is left is the term's shape against the limiter's
                // (3 % at 7/8): a gain linear in the other channels' light.
                assert!(
                    whole_white < most_white,
                    "{failure}, seed {seed}, {white:?}"
                );
                assert!(whole_tone < most_tone, "{failure}, seed {seed}, {white:?}");
                assert!(
                    whole_white < 0.7 * additive_white,
                    "{failure}, seed {seed}, {white:?}"
                );
                assert!(
                    whole_tone < 0.7 * additive_tone,
                    "{failure}, seed {seed}, {white:?}"
                );
            }
        }
    }
}

/// The simulated crosstalk raises a subpixel's drive by χ d (1 − d) times its
/// neighbours' mean drive (`channel_crosstalk`), as the voltage a lit neighbour's data
/// line couples in: the greys it lifts most are the dim ones, whose neighbours give
/// little light but much voltage. With greys at many levels (the 96-patch plan, as the
/// dense sets of real displays have them), cross-validation
/// keeps the crosstalk that follows the drives (λ) over the one that follows the light
/// (κ), and it takes most of what crosstalk costs off the held-out mixtures.
#[test]
fn crosstalk_through_the_drives_gets_the_drive_term_and_predicts_better() {
    let monitor = isetbio_monitor("isetbio_lcd_dell", "");
    let (mut with_sum, mut plain_sum, mut light_sum, mut drive_sum) = (0.0, 0.0, 0.0, 0.0);
    let seeds = 6;
    for seed in 1..=seeds {
        let (with, plain) =
            fits_with_plan(&monitor, "channel_crosstalk = 0.15", seed, "budget = 96");
        assert!(
            matches!(
                kept(&with),
                TermSet::DriveCrosstalk | TermSet::DriveCrosstalkAndShift
            ),
            "seed {seed}: {:?}",
            with.report.terms
        );
        let lambda = with.model.terms.drive_crosstalk.unwrap();
        assert!(
            lambda.iter().all(|l| *l > 0.02 && *l < 0.25),
            "seed {seed}: λ = {lambda:?}"
        );
        // What the crosstalk in light scored in the same cross-validation: worse.
        let score = |set: TermSet| with.report.term_score(set).unwrap();
        assert!(
            score(TermSet::DriveCrosstalk) < score(TermSet::Crosstalk),
            "seed {seed}: in drive {}, in light {}",
            score(TermSet::DriveCrosstalk),
            score(TermSet::Crosstalk)
        );
        light_sum += score(TermSet::Crosstalk);
        drive_sum += score(TermSet::DriveCrosstalk);
        with_sum += held_out(&with);
        plain_sum += held_out(&plain);
    }
    let n = seeds as f64;
    eprintln!(
        "held-out mean {:.3} with the term, {:.3} without; cross-validated: in drive {:.3}, in light {:.3}",
        with_sum / n,
        plain_sum / n,
        drive_sum / n,
        light_sum / n
    );
    assert!(
        with_sum < 0.6 * plain_sum,
        "held-out mean {} with the term, {} without",
        with_sum / n,
        plain_sum / n
    );
}

/// An LCD with both: its subpixels' drives coupled (crosstalk, largest at dim and mid
/// greys, none at white) and its light raised by what all channels give (the
/// interaction, largest at white), as the Dahua's greys sit 4–5 % above its channels
/// at mid drive and its white 1.1 %. The two shapes differ along the grey axis, so the
/// greys can tell them apart: the pair is kept where it beats the crosstalk in drive
/// alone beyond noise (2 of 6 seeds here, held-out 0.26 against 0.31–0.35 where the
/// crosstalk alone is kept), the interaction alone never (it cannot lift the dim greys).
#[test]
fn crosstalk_in_drive_with_an_interaction_gets_one_or_both_and_predicts_better() {
    let monitor = isetbio_monitor("isetbio_lcd_dell", "");
    let (mut with_sum, mut plain_sum, mut pairs) = (0.0, 0.0, 0);
    let seeds = 6;
    for seed in 1..=seeds {
        let (with, plain) = fits_with_plan(
            &monitor,
            "channel_crosstalk = 0.15\nchannel_interaction = -0.06",
            seed,
            "budget = 96",
        );
        let set = kept(&with);
        assert!(
            matches!(
                set,
                TermSet::DriveCrosstalk | TermSet::InteractionAndDriveCrosstalk
            ),
            "seed {seed}: {:?}",
            with.report.terms
        );
        if set == TermSet::InteractionAndDriveCrosstalk {
            pairs += 1;
            // The virtual white gains 0.06 times the mean channel output: each
            // channel 0.02 per full channel beside it.
            let gamma = with.model.terms.interaction.unwrap();
            assert!(
                gamma.iter().all(|g| (g - 0.02).abs() < 0.008),
                "seed {seed}: γ = {gamma:?}"
            );
        }
        with_sum += held_out(&with);
        plain_sum += held_out(&plain);
    }
    let n = seeds as f64;
    eprintln!(
        "the pair kept in {pairs} of {seeds}; held-out mean {:.3} with the terms, {:.3} without",
        with_sum / n,
        plain_sum / n
    );
    assert!(pairs >= 1, "the pair never kept");
    assert!(with_sum < 0.35 * plain_sum);
}
