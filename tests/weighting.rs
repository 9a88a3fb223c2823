//! The weighting of every fit: each reading counts by its real noise, the inverse of
//! σ(Y)² = floor² + (relative · Y)², with `relative` and `floor` measured from the
//! run's own repeats (the reference white and the blacks).

use chromacal::measurement_file::read_measurements;
use chromacal_color::Xyz;
use chromacal_model::fit::laws::fit_law;
use chromacal_model::fit::primaries::{ChannelRamp, RampPoint};
use chromacal_model::fit::{FitOptions, fit_monitor};
use chromacal_model::transfer::LawKind;
use nalgebra::Vector3;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

mod common;

const RELATIVE: f64 = 0.003;
const FLOOR: f64 = 2e-4; // in excitation units: 0.02 cd/m² on a 100 cd/m² primary
const GAMMA: f64 = 2.4;

fn ramp(rng: &mut rand_chacha::ChaCha8Rng, weighted: bool) -> ChannelRamp {
    let unit = Normal::new(0.0, 1.0).unwrap();
    let points = (1..=16)
        .map(|k| {
            let v = k as f64 / 16.0;
            let e = v.powf(GAMMA);
            let sigma = (FLOOR * FLOOR + (RELATIVE * e).powi(2)).sqrt();
            RampPoint {
                index: k,
                drive: v,
                excitation: e + sigma * unit.sample(rng),
                // Unweighted: every reading claims the same noise.
                sigma: if weighted { sigma } else { RELATIVE },
                xyz: Xyz::zeros(),
            }
        })
        .collect();
    ChannelRamp {
        channel: 0,
        direction: Vector3::new(0.6, 0.7, 0.4).normalize(),
        direction_se: Vector3::zeros(),
        normaliser: 100.0,
        normaliser_se: 1e-9,
        pinned: true,
        points,
        grey_points: Vec::new(),
    }
}

/// Weighting by the real noise gives gammas closer to the truth than equal weights,
/// and standard errors that match the real scatter.
#[test]
fn weighting_by_real_noise_beats_equal_weights_and_its_errors_are_honest() {
    let trials = 300;
    let mut weighted_errors = Vec::new();
    let mut plain_errors = Vec::new();
    let mut z = Vec::new();
    for seed in 0..trials {
        // The same noise draws for both fits.
        let mut a = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut b = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let weighted = fit_law(LawKind::Power, &ramp(&mut a, true), 1.0 / 255.0).unwrap();
        let plain = fit_law(LawKind::Power, &ramp(&mut b, false), 1.0 / 255.0).unwrap();
        let g = &weighted.parameters[0];
        weighted_errors.push(g.value - GAMMA);
        plain_errors.push(plain.parameters[0].value - GAMMA);
        z.push((g.value - GAMMA) / g.standard_error.unwrap());
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    eprintln!(
        "gamma rms error: weighted {:.5}, equal weights {:.5}; rms z {:.2}",
        rms(&weighted_errors),
        rms(&plain_errors),
        rms(&z)
    );
    assert!(rms(&weighted_errors) < 0.7 * rms(&plain_errors));
    assert!((0.8..1.25).contains(&rms(&z)), "rms z {}", rms(&z));
}

/// On a whole simulated run the noise model found from the repeats is the simulated
/// instrument's.
#[test]
fn the_noise_model_found_is_the_simulated_instruments() {
    let set = read_measurements(&common::fixture("journals/crt-default.jsonl")).unwrap();
    let fit = fit_monitor(&set, &FitOptions::default()).unwrap();
    let noise = &fit.report.noise;
    // Simulated: 0.2 % common gain (plus 0.2 % per band, mostly averaged away), and a
    // 0.0005 cd/m² floor.
    assert!((0.0012..0.0045).contains(&noise.relative), "{noise:?}");
    assert!((0.0001..0.0025).contains(&noise.floor), "{noise:?}");
}
