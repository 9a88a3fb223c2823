//! `bench sequential`: fixed plans against the sequential plan, held-out ΔE00 against
//! counted patches and instrument time on each virtual monitor, beside a fixed floor:
//! the instrument's repeatability on that monitor, measured on its own.
//!
//! The floor is what a perfect model would score. A held-out ΔE00 compares the
//! profile's prediction with one noisy reading of each verification patch; were the
//! prediction the truth, what is left is the ΔE00 between a reading and the truth.
//! So the floor is that, averaged over patches drawn as the runs draw their held-out
//! set and over readings with seeds of their own (not the runs': with the runs' seeds
//! the floor moved with them, and a plan passed with two seeds and failed with five).

use std::path::Path;

use std::fmt::Write as _;

use super::{BenchError, Tables};
use super::{Monitor, monitors, plan_config, run_seconds, simulate};
use crate::calibrate::session::rig_for;
use crate::report::table;
use chromacal_model::fit::fit_monitor;
use chromacal_model::fit::stats::{mean, standard_deviation};
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::plan::verification_drives;
use chromacal_sim::monitor::centre_patch;

/// Seeds of the floor's readings and patch sets, apart from the runs' (1 to 10): the
/// held-out set is drawn from seed mod 997, so these draw other patches as well as
/// other noise.
const FLOOR_SEEDS: std::ops::RangeInclusive<u64> = 500..=519;
/// Patches a seed of the floor reads: as many as the runs hold out.
const FLOOR_PATCHES: usize = 24;

/// A monitor's floor: its mean over seeds and the spread of the seeds' means.
#[derive(Debug, Clone, Copy)]
pub struct Floor {
    pub mean: f64,
    pub spread: f64,
}

/// The instrument's repeatability on the monitor `section` (the lines of a config's
/// `[monitor]` section) describes, on its own: the ΔE00 (against the true white) between each reading of
/// a held-out-like patch and what the monitor truly shows, over `FLOOR_SEEDS` ×
/// `FLOOR_PATCHES` readings with the default simulated instrument.
pub fn repeatability_floor(section: &str) -> Result<Floor, BenchError> {
    let monitor = Monitor {
        name: "floor".into(),
        section: section.to_string(),
    };
    let mut per_seed = Vec::new();
    for seed in FLOOR_SEEDS {
        let config = plan_config(&monitor, "strategy = \"fixed\"\nbudget = 16", seed)?;
        let rig = rig_for(&config, Path::new("."), None).map_err(|e| e.to_string())?;
        let mut instrument = rig.instrument;
        let truth = |drive| -> Result<_, BenchError> {
            let mut screen = rig
                .monitor
                .lock()
                .map_err(|_| "the virtual monitor's lock")?;
            screen.show(centre_patch(drive));
            let at = screen.patch_centre();
            Ok(screen.xyz_at(at).map_err(|e| e.to_string())?)
        };
        let white = truth([1.0; 3])?;
        let mut errors = Vec::new();
        for drive in verification_drives(FLOOR_PATCHES, seed) {
            rig.clock.advance(config.display.settle_s);
            let true_xyz = truth(drive)?;
            let reading = instrument.measure_now().map_err(|e| e.to_string())?;
            if let Some(xyz) = reading.xyz {
                errors.push(delta_e00_xyz(&true_xyz, &xyz, &white));
            }
        }
        if !errors.is_empty() {
            per_seed.push(mean(&errors));
        }
    }
    if per_seed.is_empty() {
        return Err(BenchError::from(
            "no reading for the repeatability floor: every patch was out of the instrument's range",
        ));
    }
    Ok(Floor {
        mean: mean(&per_seed),
        spread: standard_deviation(&per_seed),
    })
}

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
        "\nfixed against sequential plans: held-out ΔE00 on 24 verification patches (mean over {} seeds ± the seeds' standard deviation), counted patches and instrument seconds (all patches, settling included); ÷ floor: the mean over the monitor's fixed floor (the instrument's repeatability on it, measured on its own over {} seeds × {FLOOR_PATCHES} patches):",
        seeds.len(),
        FLOOR_SEEDS.count()
    )?;
    for monitor in monitors(data) {
        let floor = repeatability_floor(&monitor.section)
            .map_err(|e| BenchError::from(format!("{}: {e}", monitor.name)))?;
        let mut rows = Vec::new();
        for (name, plan) in &plans {
            let (mut means, mut p95s, mut counts) = (Vec::new(), Vec::new(), Vec::new());
            let mut seconds = Vec::new();
            for seed in seeds {
                let config = plan_config(&monitor, plan, *seed)?;
                let tag = format!("{}-{seed}", monitor.name.replace(' ', "_"));
                let set = simulate(&config, &dir, &tag)?;
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
            let held_out = mean(&means);
            rows.push(vec![
                name.clone(),
                format!("{:.1}", mean(&counts)),
                format!("{:.0}", mean(&seconds)),
                if means.len() == seeds.len() {
                    format!(
                        "{held_out:.3} ± {:.3} / {:.3}",
                        standard_deviation(&means),
                        mean(&p95s)
                    )
                } else {
                    format!("fails ({}/{})", seeds.len() - means.len(), seeds.len())
                },
                if means.len() == seeds.len() {
                    format!("{:.2}", held_out / floor.mean)
                } else {
                    "-".into()
                },
            ]);
        }
        writeln!(
            out.text,
            "\n{}: floor {:.3} ± {:.3}, 1.5 × that {:.3}",
            monitor.name,
            floor.mean,
            floor.spread,
            1.5 * floor.mean
        )?;
        write!(
            out.text,
            "{}",
            table(
                &[
                    "plan",
                    "counted patches",
                    "instrument s",
                    "held-out mean ± sd / p95",
                    "÷ floor"
                ],
                &rows
            )
        )?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
