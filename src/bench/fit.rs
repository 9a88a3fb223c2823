//! `bench fit-time` and `bench budget`: the fit's time per law against readings, the
//! whole fit's time on each real set, and held-out ΔE00 against the patch budget per
//! law on each virtual monitor.

use std::path::Path;
use std::time::Instant;

use std::fmt::Write as _;

use super::argyll::{RealSet, real_sets};
use super::{BenchError, Tables};
use super::{config_for, monitors, run_seconds, simulate, white_repeat_differences};
use crate::report::table;
use chromacal_model::fit::laws::fit_law;
use chromacal_model::fit::primaries::{ChannelRamp, RampPoint};
use chromacal_model::fit::stats::ErrorStats;
use chromacal_model::fit::{FitOptions, fit_monitor};
use chromacal_model::measurement::MeasurementSet;
use chromacal_model::transfer::{GainOffsetGamma, LawKind};

pub(super) fn bench(
    out: &mut Tables,
    quick: bool,
    data: &Path,
    fit_time: bool,
    budget: bool,
) -> Result<(), BenchError> {
    let repeats = if quick { 5 } else { 30 };
    let seeds: Vec<u64> = if quick {
        vec![1, 2]
    } else {
        vec![1, 2, 3, 4, 5]
    };

    // 1. Fit time per law against readings.
    if fit_time {
        fit_time_table(out, repeats)?;
        whole_fit_times(out, data, if quick { 3 } else { 11 })?;
    }
    if !budget {
        return Ok(());
    }
    budget_tables(out, data, &seeds)
}

/// Fit time per law against readings per channel.
fn fit_time_table(out: &mut Tables, repeats: usize) -> Result<(), BenchError> {
    writeln!(
        out.text,
        "fit time per channel, microseconds (median of {repeats}), against readings per channel:"
    )?;
    let sizes = [6usize, 12, 24, 48, 96];
    let mut rows = Vec::new();
    for kind in LawKind::ALL {
        let mut row = vec![kind.name().to_string()];
        for n in sizes {
            let ramp = synthetic_ramp(n);
            let mut times: Vec<f64> = (0..repeats)
                .map(|_| {
                    let t = Instant::now();
                    let _ = fit_law(kind, &ramp, 1.0 / 255.0);
                    t.elapsed().as_secs_f64() * 1e6
                })
                .collect();
            times.sort_by(|a, b| a.total_cmp(b));
            row.push(format!("{:.0}", times[times.len() / 2]));
        }
        rows.push(row);
    }
    let headers: Vec<String> = std::iter::once("law".to_string())
        .chain(sizes.iter().map(|n| format!("n={n}")))
        .collect();
    let header_refs: Vec<&str> = headers.iter().map(String::as_str).collect();
    write!(out.text, "{}", table(&header_refs, &rows))?;
    Ok(())
}

/// Time of the whole fit (black, drift, every law cross-validated, the additivity
/// terms, the spatial map, the checks) on each real measurement set as it is.
fn whole_fit_times(out: &mut Tables, data: &Path, repeats: usize) -> Result<(), BenchError> {
    let sets: Vec<(String, MeasurementSet)> = real_sets(data)
        .into_iter()
        .map(|(name, set)| match set {
            RealSet::One(set) | RealSet::Two(set, _) => (name, set),
        })
        .collect();
    if sets.is_empty() {
        return Ok(());
    }
    writeln!(
        out.text,
        "\nwhole fit on one core, every reading of each real set (median of {repeats}):"
    )?;
    let mut rows = Vec::new();
    for (name, set) in sets {
        let mut times: Vec<f64> = (0..repeats)
            .map(|_| {
                let t = Instant::now();
                let _ = fit_monitor(&set, &FitOptions::default());
                t.elapsed().as_secs_f64()
            })
            .collect();
        times.sort_by(|a, b| a.total_cmp(b));
        rows.push(vec![
            name,
            set.measurements.len().to_string(),
            crate::report::duration(times[times.len() / 2]),
        ]);
    }
    write!(
        out.text,
        "{}",
        table(&["display", "readings", "fit time"], &rows)
    )?;
    Ok(())
}

/// Held-out ΔE00 against budget, per law and for the law chosen, on each monitor.
fn budget_tables(out: &mut Tables, data: &Path, seeds: &[u64]) -> Result<(), BenchError> {
    let dir = std::env::temp_dir().join(format!("chromacal-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let budgets = [12usize, 24, 48, 96];
    let mut choices: Vec<(String, Vec<LawKind>)> = LawKind::ALL
        .iter()
        .map(|k| (k.name().to_string(), vec![*k]))
        .collect();
    choices.push(("chosen by CV".into(), LawKind::ALL.to_vec()));
    for monitor in monitors(data) {
        writeln!(
            out.text,
            "\n{}: held-out ΔE00 on 24 verification patches, mean / p95 (mean over {} seeds), and fit time, against counted patches:",
            monitor.name,
            seeds.len()
        )?;
        let mut rows: Vec<Vec<String>> = choices.iter().map(|c| vec![c.0.clone()]).collect();
        let mut chosen_names = Vec::new();
        let mut instrument_time = Vec::new();
        let mut repeat_differences = Vec::new();
        for budget in budgets {
            let mut sets = Vec::new();
            for seed in seeds {
                let config = config_for(&monitor, budget, *seed)?;
                let tag = format!("{}-{budget}-{seed}", monitor.name.replace(' ', "_"));
                let set = simulate(&config, &dir, &tag)?;
                sets.push(set);
            }
            instrument_time.push(run_seconds(&sets[0], 0.2));
            repeat_differences.extend(sets.iter().flat_map(white_repeat_differences));
            let mut picked = Vec::new();
            for (k, (_, laws)) in choices.iter().enumerate() {
                let options = FitOptions {
                    laws: laws.clone(),
                    ..FitOptions::default()
                };
                let mut means = Vec::new();
                let mut p95s = Vec::new();
                let mut micros = Vec::new();
                for set in &sets {
                    let t = Instant::now();
                    if let Ok(f) = fit_monitor(set, &options) {
                        micros.push(t.elapsed().as_secs_f64() * 1e3);
                        if let Some(s) = f.report.held_out {
                            means.push(s.mean);
                            p95s.push(s.p95);
                        }
                        if laws.len() > 1 {
                            picked.extend(f.report.chosen_law());
                        }
                    }
                }
                let cell = if means.len() == sets.len() {
                    let m = means.iter().sum::<f64>() / means.len() as f64;
                    let p = p95s.iter().sum::<f64>() / p95s.len() as f64;
                    let ms = micros.iter().sum::<f64>() / micros.len() as f64;
                    format!("{m:.3} / {p:.3}  {ms:.0} ms")
                } else {
                    format!("fails ({}/{})", sets.len() - means.len(), sets.len())
                };
                rows[k].push(cell);
            }
            picked.sort();
            picked.dedup();
            chosen_names.push(
                picked
                    .iter()
                    .map(|k| k.name())
                    .collect::<Vec<_>>()
                    .join("+"),
            );
        }
        let headers: Vec<String> = std::iter::once("law".to_string())
            .chain(budgets.iter().map(|b| format!("{b} patches")))
            .collect();
        let header_refs: Vec<&str> = headers.iter().map(String::as_str).collect();
        write!(out.text, "{}", table(&header_refs, &rows))?;
        writeln!(
            out.text,
            "  chosen: {}",
            budgets
                .iter()
                .zip(&chosen_names)
                .map(|(b, c)| format!("{b}: {c}"))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        if let Some(floor) = ErrorStats::of(&repeat_differences) {
            writeln!(
                out.text,
                "  the instrument's repeatability, the floor: ΔE00 between consecutive readings of the reference white, mean {:.3} / p95 {:.3} ({} pairs)",
                floor.mean, floor.p95, floor.n
            )?;
        }
        writeln!(
            out.text,
            "  instrument time per run (all patches incl. held-out and grid): {}",
            budgets
                .iter()
                .zip(&instrument_time)
                .map(|(b, t)| format!("{b}: {}", crate::report::duration(*t)))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// A synthetic ramp of `n` levels with 0.3 % noise, for timing the law fits alone.
fn synthetic_ramp(n: usize) -> ChannelRamp {
    let truth = GainOffsetGamma::from_cutoff(0.04, 2.4);
    let points = (1..=n)
        .map(|k| {
            let v = k as f64 / n as f64;
            let e = truth.excitation(v);
            let sigma = (1e-5f64.powi(2) + (0.003 * e).powi(2)).sqrt();
            let wiggle = ((k * 7919) % 13) as f64 / 6.0 - 1.0;
            RampPoint {
                index: k,
                drive: v,
                excitation: e + sigma * wiggle,
                sigma,
                xyz: Default::default(),
            }
        })
        .collect();
    ChannelRamp {
        channel: 0,
        direction: nalgebra::Vector3::new(0.8, 0.5, 0.3).normalize(),
        direction_se: Default::default(),
        normaliser: 50.0,
        normaliser_se: 0.05,
        pinned: true,
        points,
        grey_points: Vec::new(),
    }
}
