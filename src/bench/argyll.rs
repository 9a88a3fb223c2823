//! `bench argyll`: chromacal against ArgyllCMS's `colprof` on the real measurement
//! sets, both judged by one judge (`comparison`).

use std::path::Path;

use std::fmt::Write as _;

use super::{BenchError, Tables};
use crate::comparison::{MAX_TRAIN, RESCALINGS, compare_with_argyll, compare_with_argyll_across};
use crate::report::table;
use chromacal_formats::cgats::read_ti3;
use chromacal_model::fit::FitOptions;
use chromacal_model::measurement::MeasurementSet;

/// A real measurement set: one file split in two, or a set measured in two sessions
/// (training readings from the first, held-out mixtures from the second).
pub enum RealSet {
    One(MeasurementSet),
    Two(MeasurementSet, MeasurementSet),
}

/// The real measurement sets in `data` that have mixtures to hold out: the five
/// ArgyllCMS `.ti3` files, and the Psychtoolbox OLED's split (calibration, then
/// linearity check).
pub fn real_sets(data: &Path) -> Vec<(String, RealSet)> {
    let dir = data.join("measurements");
    let read = |name: &str| read_ti3(&dir.join(name)).ok();
    let mut sets = Vec::new();
    for (label, file) in [
        ("Dell U2713HM (IPS)", "dell_u2713hm_i1d3_912.ti3"),
        (
            "MacBook Pro 15 (IPS)",
            "macbookpro15_2014_colormunki_spectral_57.ti3",
        ),
        (
            "Samsung S24A350H (TN)",
            "samsung_s24a350h_colormunki_spectral_57.ti3",
        ),
        (
            "Dahua LM27-E331A (IPS, wide-gamut PFS backlight)",
            "dahua_lm27_e331a_spyderx_1140.ti3",
        ),
        (
            "Lenovo ThinkBook 14p Gen2 (LCD)",
            "lenovo_thinkbook14p_gen2_nv140drm_n62_i1d3_596.ti3",
        ),
    ] {
        if let Some(set) = read(file) {
            sets.push((label.to_string(), RealSet::One(set)));
        }
    }
    if let (Some(train), Some(test)) = (
        read("psychtoolbox/split/ptb_sony_pvm2541_oled_train.ti3"),
        read("psychtoolbox/split/ptb_sony_pvm2541_oled_test.ti3"),
    ) {
        sets.push((
            "Sony PVM-2541 (OLED)".to_string(),
            RealSet::Two(train, test),
        ));
    }
    sets
}

/// chromacal against ArgyllCMS's `colprof -qm -as` on every real set, one split, one
/// judge (`comparison`).
pub(super) fn against_argyll(
    out: &mut Tables,
    data: &Path,
    options: &FitOptions,
) -> Result<(), BenchError> {
    let sets = real_sets(data);
    if sets.is_empty() {
        writeln!(
            out.text,
            "\nno real measurement sets under {}",
            data.display()
        )?;
        return Ok(());
    }
    let (first, last) = (RESCALINGS.start(), RESCALINGS.end());
    writeln!(
        out.text,
        "\nreal displays: held-out ΔE00 mean (train: black, greys and single-channel ramps, at most {MAX_TRAIN}; test: every mixture), judged by ArgyllCMS profcheck -k on each tool's ICC profile; colprof -qm -as run on the rows as measured and rescaled by 1 + k·10⁻⁴, k = {first}…{last}:"
    )?;
    let work = std::env::temp_dir().join(format!("chromacal-argyll-{}", std::process::id()));
    let rescalings: Vec<i32> = RESCALINGS.collect();
    let mut rows = Vec::new();
    let (mut ratios, mut best_ratios) = (Vec::new(), Vec::new());
    for (k, (name, set)) in sets.iter().enumerate() {
        let dir = work.join(k.to_string());
        let compared = match set {
            RealSet::One(set) => compare_with_argyll(set, options, &rescalings, &dir),
            RealSet::Two(train, test) => {
                compare_with_argyll_across(train, test, options, &rescalings, &dir)
            }
        };
        // One display that cannot be compared leaves its row saying why, not the table.
        let c = match compared {
            Ok(c) => c,
            Err(e) => {
                rows.push(vec![name.clone(), format!("not compared: {e}")]);
                continue;
            }
        };
        ratios.extend(c.ratio());
        best_ratios.extend(c.ratio_to_best());
        let ratio = |r: Option<f64>| r.map_or("-".into(), |r| format!("{r:.2}"));
        rows.push(vec![
            name.clone(),
            format!("{} / {}", c.train, c.test),
            format!("{:.3}", c.chromacal.mean),
            format!("{:.3}", c.model_judged.mean),
            match &c.chromacal_icc {
                Ok(s) => format!("{:.3}", s.mean),
                Err(why) => format!("not judged: {why}"),
            },
            match (c.argyll_spread(), &c.argyll) {
                (Some(s), _) => format!("{:.3} / {:.3} / {:.3}", s.min, s.median, s.max),
                (None, Err(why)) => format!("not run: {why}"),
                (None, Ok(_)) => "-".into(),
            },
            ratio(c.ratio()),
            ratio(c.ratio_to_best()),
            c.fitted
                .report
                .chosen_law()
                .map_or("-".into(), |l| l.name().to_string()),
            crate::report::duration(c.fit_seconds),
        ]);
    }
    let _ = std::fs::remove_dir_all(&work);
    write!(
        out.text,
        "{}",
        table(
            &[
                "display",
                "train / test",
                "model (own check)",
                "model (judge's frame)",
                "chromacal ICC v2",
                "colprof min / median / max",
                "ratio",
                "to best",
                "law",
                "fit time"
            ],
            &rows
        )
    )?;
    let median = |v: Vec<f64>| chromacal_model::fit::stats::percentile(&v, 50.0);
    if !ratios.is_empty() {
        writeln!(
            out.text,
            "  median ratio chromacal ICC / colprof's median run: {:.2}; to colprof's best run: {:.2}",
            median(ratios),
            median(best_ratios)
        )?;
    }
    Ok(())
}
