//! `chromacal bench law-rule`: does the rule that picks the transfer law ("the
//! simplest within one standard error of the best") give up held-out accuracy on
//! mixtures when the ramps hold many levels? Each rule against the other on virtual
//! monitors whose transfer is a real measured table (ISETBio's eight, and the shared
//! Dell U2713HM's grey ramp read off its 912-patch `.ti3`) and whose primaries are
//! real spectra, at a sparse and a dense fixed plan, over seeds, scored on 24 mixtures
//! held out of every fit.

use std::fmt::Write as _;

use super::{BenchError, Tables};
use std::path::{Path, PathBuf};

use crate::config::parse_config;
use crate::report::table;
use chromacal_formats::cgats::read_ti3;
use chromacal_model::fit::{FitOptions, LawRule, fit_monitor};
use chromacal_model::measurement::MeasurementSet;

/// ISETBio displays with both a spectrum and a transfer table in the shared data.
const ISETBIO: [&str; 8] = [
    "crt_dell",
    "crt_hp",
    "crt_newsome_lab",
    "lcd_apple",
    "lcd_dell",
    "lcd_example_srgb_like",
    "lcd_hp",
    "oled_sony",
];

/// Fixed-plan budgets: about 5, 12 and 45 ramp levels a channel.
const BUDGETS: [usize; 3] = [24, 48, 160];

/// A virtual monitor: its name and `[monitor]` section.
struct Virtual {
    name: String,
    section: String,
}

/// The Dell U2713HM's tone curve from its own grey ramp (57 steps; its single-channel
/// ramps have only 7): luminance over black, normalised at white, the same for the
/// three channels, written as an ISETBio-style table.
fn dell_transfer(data: &Path, dir: &Path) -> Result<Option<PathBuf>, String> {
    let path = data.join("measurements/dell_u2713hm_i1d3_912.ti3");
    if !path.is_file() {
        return Ok(None);
    }
    let set = read_ti3(&path).map_err(|e| e.to_string())?;
    let mut greys: Vec<(f64, f64)> = set
        .measurements
        .iter()
        .filter(|m| m.drive[0] == m.drive[1] && m.drive[1] == m.drive[2])
        .filter_map(|m| Some((m.drive[0], m.usable_xyz()?[1])))
        .collect();
    greys.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Each level the mean of its readings, black taken off.
    let mut levels: Vec<(f64, f64)> = Vec::new();
    for chunk in greys.chunk_by(|a, b| a.0 == b.0) {
        let y = chunk.iter().map(|g| g.1).sum::<f64>() / chunk.len() as f64;
        levels.push((chunk[0].0, y));
    }
    let (Some(black), true) = (levels.first().map(|l| l.1), levels.len() >= 16) else {
        return Ok(None);
    };
    let mut text = String::from("input_norm,R,G,B\n");
    for (level, y) in levels {
        let v = (y - black).max(0.0);
        text.push_str(&format!("{level},{v},{v},{v}\n"));
    }
    let out = dir.join("dell_u2713hm_gamma.csv");
    std::fs::write(&out, text).map_err(|e| e.to_string())?;
    Ok(Some(out))
}

fn monitors(data: &Path, dir: &Path) -> Result<Vec<Virtual>, String> {
    let section = |spd: &Path, gamma: &Path| {
        format!(
            "primaries_csv = \"{}\"\ntransfer_csv = \"{}\"\nblack_luminance = 0.1\nflare_luminance = 0.05\nfalloff = 0.05",
            spd.display(),
            gamma.display()
        )
    };
    // The presets' transfer is a law with noise: where simplicity should cost nothing.
    let mut list: Vec<Virtual> = ["crt", "lcd"]
        .iter()
        .map(|p| Virtual {
            name: format!("preset {p} (a law)"),
            section: format!("preset = \"{p}\""),
        })
        .collect();
    for stem in ISETBIO {
        let spd = data.join(format!("displays/spd/isetbio_{stem}_spd.csv"));
        let gamma = data.join(format!("displays/gamma/isetbio_{stem}_gamma.csv"));
        if spd.is_file() && gamma.is_file() {
            list.push(Virtual {
                name: format!("ISETBio {stem}"),
                section: section(&spd, &gamma),
            });
        }
    }
    let lcd = data.join("displays/spd/isetbio_lcd_dell_spd.csv");
    if let (Some(gamma), true) = (dell_transfer(data, dir)?, lcd.is_file()) {
        list.push(Virtual {
            name: "Dell U2713HM greys".into(),
            section: section(&lcd, &gamma),
        });
    }
    Ok(list)
}

fn simulate(
    monitor: &Virtual,
    budget: usize,
    seed: u64,
    dir: &Path,
) -> Result<MeasurementSet, String> {
    let text = format!(
        "[monitor]\n{}\n[instrument.simulated]\nseed = {seed}\n[plan]\nstrategy = \"fixed\"\nbudget = {budget}\nseed = {seed}\nverification = 24\nuniformity_grid = 1\n",
        monitor.section
    );
    let config = parse_config(&text, &monitor.name).map_err(|e| e.to_string())?;
    super::simulate(&config, dir, &format!("run-{budget}-{seed}"))
        .map_err(|e| format!("{}: {e}", monitor.name))
}

/// Print the table; `quick` takes two seeds instead of five.
pub(super) fn law_rule_table(out: &mut Tables, data: &Path, quick: bool) -> Result<(), BenchError> {
    let dir = std::env::temp_dir().join(format!("chromacal-bench-laws-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let seeds: Vec<u64> = if quick { vec![1, 2] } else { (1..=5).collect() };
    let rules = [
        ("simplest within noise", LawRule::SimplestWithinNoise),
        ("lowest error", LawRule::LowestError),
    ];
    writeln!(
        out.text,
        "law rule: held-out ΔE00 on 24 mixtures (mean over {} seeds; the laws chosen), fixed plans of {BUDGETS:?} patches:",
        seeds.len()
    )?;
    let mut rows = Vec::new();
    let mut totals = vec![[0.0; 2]; BUDGETS.len()];
    let monitors = monitors(data, &dir)?;
    for monitor in &monitors {
        let mut row = vec![monitor.name.clone()];
        for (b, budget) in BUDGETS.iter().enumerate() {
            let mut means = [0.0; 2];
            let mut chosen: [Vec<&str>; 2] = Default::default();
            for &seed in &seeds {
                let set = simulate(monitor, *budget, seed, &dir)?;
                for (r, (_, rule)) in rules.iter().enumerate() {
                    let options = FitOptions {
                        law_rule: *rule,
                        ..FitOptions::default()
                    };
                    let fit = fit_monitor(&set, &options)
                        .map_err(|e| format!("{}: {e}", monitor.name))?;
                    means[r] += fit.report.held_out.as_ref().map_or(f64::NAN, |h| h.mean);
                    chosen[r].extend(fit.report.chosen_law().map(|l| l.name()));
                }
            }
            for r in 0..rules.len() {
                means[r] /= seeds.len() as f64;
                totals[b][r] += means[r] / monitors.len() as f64;
                chosen[r].sort();
                chosen[r].dedup();
                row.push(format!("{:.3} ({})", means[r], chosen[r].join("+")));
            }
        }
        rows.push(row);
    }
    let mut total = vec!["mean over monitors".to_string()];
    for t in &totals {
        total.extend(t.iter().map(|m| format!("{m:.3}")));
    }
    rows.push(total);
    let headers: Vec<String> = std::iter::once("monitor".to_string())
        .chain(
            BUDGETS
                .iter()
                .flat_map(|b| rules.iter().map(move |(name, _)| format!("{b}: {name}"))),
        )
        .collect();
    let refs: Vec<&str> = headers.iter().map(String::as_str).collect();
    write!(out.text, "{}", table(&refs, &rows))?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
