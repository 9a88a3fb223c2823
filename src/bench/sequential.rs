//! `bench sequential`: fixed plans against the sequential plan, held-out ΔE00 against
//! counted patches and instrument time on each virtual monitor, beside the
//! instrument's repeatability.

use std::path::Path;

use std::fmt::Write as _;

use super::{BenchError, Tables};
use super::{monitors, plan_config, run_seconds, simulate, white_repeat_differences};
use crate::report::table;
use chromacal_model::fit::fit_monitor;
use chromacal_model::fit::stats::ErrorStats;

/// Held-out ΔE00 against counted patches for fixed plans and for the sequential plan,
/// on each virtual monitor, beside the instrument's repeatability.
pub(super) fn sequential_table(
    out: &mut Tables,
    data: &Path,
    seeds: &[u64],
) -> Result<(), BenchError> {
    let dir = std::env::temp_dir().join(format!("chromacal-sequential-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let plans: Vec<(String, String)> = [16usize, 24, 32, 48]
        .iter()
        .map(|b| {
            (
                format!("fixed, {b}"),
                format!("strategy = \"fixed\"\nbudget = {b}"),
            )
        })
        .chain([32usize, 48].iter().map(|b| {
            (
                format!("sequential, seed 16, up to {b}"),
                format!(
                    "strategy = \"sequential\"\nseed_budget = 16\nbudget = {b}\ntarget_de00 = 0.0"
                ),
            )
        }))
        .chain(std::iter::once((
            "sequential to estimate 0.2, up to 64".to_string(),
            "strategy = \"sequential\"\nseed_budget = 16\nbudget = 64\ntarget_de00 = 0.2"
                .to_string(),
        )))
        .collect();
    writeln!(
        out.text,
        "\nfixed against sequential plans: held-out ΔE00 on 24 verification patches (mean over {} seeds), counted patches and instrument seconds (all patches, settling included):",
        seeds.len()
    )?;
    for monitor in monitors(data) {
        let mut rows = Vec::new();
        let mut floor = Vec::new();
        for (name, plan) in &plans {
            let (mut means, mut p95s, mut counts) = (Vec::new(), Vec::new(), Vec::new());
            let mut seconds = Vec::new();
            for seed in seeds {
                let config = plan_config(&monitor, plan, *seed)?;
                let tag = format!("{}-{seed}", monitor.name.replace(' ', "_"));
                let set = simulate(&config, &dir, &tag)?;
                floor.extend(white_repeat_differences(&set));
                counts.push(crate::calibrate::sequential::counted(&set) as f64);
                seconds.push(run_seconds(&set, config.display.settle_s));
                if let Some(s) = fit_monitor(&set, &config.fit)
                    .ok()
                    .and_then(|f| f.report.held_out)
                {
                    means.push(s.mean);
                    p95s.push(s.p95);
                }
            }
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
            rows.push(vec![
                name.clone(),
                format!("{:.1}", mean(&counts)),
                format!("{:.0}", mean(&seconds)),
                if means.len() == seeds.len() {
                    format!("{:.3} / {:.3}", mean(&means), mean(&p95s))
                } else {
                    format!("fails ({}/{})", seeds.len() - means.len(), seeds.len())
                },
            ]);
        }
        let floor = ErrorStats::of(&floor).map_or(f64::NAN, |f| f.mean);
        writeln!(
            out.text,
            "\n{}: the instrument's repeatability (consecutive reference whites) {floor:.3}, 1.5 × that {:.3}",
            monitor.name,
            1.5 * floor
        )?;
        write!(
            out.text,
            "{}",
            table(
                &[
                    "plan",
                    "counted patches",
                    "instrument s",
                    "held-out mean / p95"
                ],
                &rows
            )
        )?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
