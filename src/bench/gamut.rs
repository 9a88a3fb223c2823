//! `chromacal bench gamut`: the gamut mappings on the scenes that need them
//! (`crf::gamut_bench`), as a table.

use std::fmt::Write as _;

use super::{BenchError, Tables};

use crate::report::table;
use chromacal_crf::gamut_bench::gamut_table;

/// Print the table for the simulated default display.
pub(super) fn gamut_bench_table(out: &mut Tables, quick: bool) -> Result<(), BenchError> {
    let profile = super::render::default_profile()?;
    let rows = gamut_table(&profile.model, if quick { 3 } else { 9 }).map_err(|e| e.to_string())?;
    writeln!(
        out.text,
        "Gamut mapping on the simulated default display (centre of the screen; scenes carried to its white by Bradford): ΔE00 between the colour asked for and what the mapping made of it; hue turned over the colours moved; time per colour, median of the rounds\n"
    )?;
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.scene.clone(),
                r.mapping.clone(),
                format!("{:.2} / {:.2}", r.mean_delta_e00, r.max_delta_e00),
                format!("{:.2}", r.mean_hue_turn),
                format!("{:.0} %", r.moved * 100.0),
                format!("{:.1}", r.microseconds),
            ]
        })
        .collect();
    writeln!(
        out.text,
        "{}",
        table(
            &[
                "scene",
                "mapping",
                "ΔE00 mean / max",
                "hue turned (°)",
                "moved",
                "µs / colour"
            ],
            &cells
        )
    )?;
    Ok(())
}
