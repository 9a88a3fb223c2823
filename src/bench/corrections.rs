//! `chromacal bench corrections`: each emulated colorimeter's held-out ΔE00 before and
//! after a correction made against the emulated PR-670, on virtual monitors made of
//! ISETBio's measured CRT, LCD and OLED spectra (from the shared data), beside the
//! colorimeter's repeatability, and what a run costs.

use std::fmt::Write as _;

use super::{BenchError, Tables};
use std::path::Path;
use std::time::Instant;

use crate::calibrate::correction::{correction_patches, emulated_correction};
use crate::calibrate::session::block_on;
use crate::config::parse_config;
use crate::report::table;
use chromacal_instruments::devices::DeviceKind;

/// Print the table; `quick` takes one seed instead of three.
pub(super) fn corrections_table(
    out: &mut Tables,
    data: &Path,
    quick: bool,
) -> Result<(), BenchError> {
    let seeds: Vec<u64> = if quick { vec![1] } else { vec![1, 2, 3] };
    let patches = correction_patches().len();
    writeln!(
        out.text,
        "colorimeter corrections made against an emulated PR-670 ({patches} patches read by both, 6 held out; mean over {} seed(s)):",
        seeds.len()
    )?;
    let mut rows = Vec::new();
    for (name, stem) in [
        ("CRT (ISETBio Dell)", "isetbio_crt_dell"),
        ("LCD (ISETBio Dell)", "isetbio_lcd_dell"),
        ("OLED (ISETBio Sony)", "isetbio_oled_sony"),
    ] {
        let spd = data.join(format!("displays/spd/{stem}_spd.csv"));
        let gamma = data.join(format!("displays/gamma/{stem}_gamma.csv"));
        if !spd.is_file() || !gamma.is_file() {
            writeln!(
                out.text,
                "  ({name}: {} is missing; skipped)",
                spd.display()
            )?;
            continue;
        }
        let text = format!(
            "[monitor]\nprimaries_csv = \"{}\"\ntransfer_csv = \"{}\"\n",
            spd.display(),
            gamma.display()
        );
        let config = parse_config(&text, name).map_err(|e| e.to_string())?;
        let spec = config
            .monitor
            .resolve(Path::new("."))
            .map_err(|e| e.to_string())?;
        for kind in [DeviceKind::K10a, DeviceKind::Cs100a, DeviceKind::ColorCal2] {
            let (mut u, mut c, mut r, mut seconds) = (0.0, 0.0, 0.0, 0.0);
            for &seed in &seeds {
                let started = Instant::now();
                let fit = block_on(emulated_correction(spec.clone(), kind, seed))
                    .map_err(|e| e.to_string())?
                    .map_err(|e| format!("{name}, {kind}: {e}"))?;
                seconds += started.elapsed().as_secs_f64();
                u += fit.held_out_uncorrected.mean;
                c += fit.held_out_corrected.mean;
                r += fit.colorimeter_repeatability.mean;
            }
            let n = seeds.len() as f64;
            rows.push(vec![
                name.to_string(),
                kind.to_string(),
                format!("{:.3}", u / n),
                format!("{:.3}", c / n),
                format!("{:.3}", r / n),
                format!("{:.2}", c / r.max(1e-12)),
                format!("{:.0}", 1000.0 * seconds / n),
            ]);
        }
    }
    writeln!(
        out.text,
        "{}",
        table(
            &[
                "display",
                "colorimeter",
                "uncorrected",
                "corrected",
                "repeatability",
                "corrected / repeat.",
                "ms a run",
            ],
            &rows,
        )
    )?;
    Ok(())
}
