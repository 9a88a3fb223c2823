//! `chromacal bench`: speed against error, as tables.
//!
//! 1. Fit time of each law against the number of readings per channel.
//! 2. Held-out ΔE00 (the verification patches, never fitted on) against the patch
//!    budget, for each law forced and for the law chosen by cross-validation, on each
//!    simulated monitor: the two presets, and, when the shared reference data are
//!    there, virtual monitors whose primaries are real measured spectra and whose
//!    transfer is a real measured table (ISETBio CRT, LCD and OLED).
//!
//! Every simulated run uses realistic noise (0.2 % gain, 0.2 % per band, 0.0005 cd/m²
//! floor) and is repeated over seeds; the table gives the mean over seeds.

use super::shared::{out, outln};
use std::path::{Path, PathBuf};
use std::time::Instant;

use chromacal::calibrate::session::{block_on, measure_simulated};
use chromacal::cgats::read_ti3;
use chromacal::color::Xyz;
use chromacal::comparison::{
    MAX_TRAIN, RESCALINGS, compare_with_argyll, compare_with_argyll_across,
};
use chromacal::config::{Config, parse_config};
use chromacal::fit::laws::fit_law;
use chromacal::fit::primaries::{ChannelRamp, RampPoint};
use chromacal::fit::stats::ErrorStats;
use chromacal::fit::validate::delta_e00_xyz;
use chromacal::fit::{FitOptions, fit_monitor};
use chromacal::measurement::MeasurementSet;
use chromacal::measurement::Role;
use chromacal::model::transfer::{GainOffsetGamma, LawKind};
use chromacal::report::table;

use super::fit::LawArg;
use super::shared::{Failure, absolute_path};

/// A virtual monitor to measure, as a `[monitor]` config section.
struct Monitor {
    name: String,
    section: String,
}

fn monitors(data: &Path) -> Vec<Monitor> {
    let mut list = vec![
        Monitor {
            name: "preset crt".into(),
            section: "preset = \"crt\"".into(),
        },
        Monitor {
            name: "preset lcd".into(),
            section: "preset = \"lcd\"".into(),
        },
    ];
    for (name, stem, white, black, falloff) in [
        (
            "ISETBio CRT-Dell",
            "isetbio_crt_dell",
            "100.0",
            "0.02",
            "0.15",
        ),
        ("ISETBio LCD-Dell", "isetbio_lcd_dell", "", "0.0", "0.05"),
        (
            "ISETBio OLED-Sony",
            "isetbio_oled_sony",
            "",
            "0.0005",
            "0.02",
        ),
    ] {
        let spd = data.join(format!("displays/spd/{stem}_spd.csv"));
        let gamma = data.join(format!("displays/gamma/{stem}_gamma.csv"));
        if spd.is_file() && gamma.is_file() {
            let white = if white.is_empty() {
                String::new()
            } else {
                format!("white_luminance = {white}\n")
            };
            list.push(Monitor {
                name: name.into(),
                section: format!(
                    "primaries_csv = \"{}\"\ntransfer_csv = \"{}\"\n{white}black_luminance = {black}\nflare_luminance = 0.05\nfalloff = {falloff}",
                    spd.display(),
                    gamma.display()
                ),
            });
        }
    }
    list
}

fn config_for(monitor: &Monitor, budget: usize, seed: u64) -> Result<Config, String> {
    plan_config(
        monitor,
        &format!("strategy = \"fixed\"\nbudget = {budget}"),
        seed,
    )
}

/// The config of a run of `monitor` with `plan` (lines of its `[plan]` section), and
/// the benches' own held-out set and grid: 24 verification patches, a 5 × 5 grid.
fn plan_config(monitor: &Monitor, plan: &str, seed: u64) -> Result<Config, String> {
    let text = format!(
        "[monitor]\n{}\n[instrument.simulated]\nseed = {seed}\n[plan]\n{plan}\nseed = {seed}\nverification = 24\nuniformity_grid = 5\n",
        monitor.section
    );
    parse_config(&text, &monitor.name).map_err(|e| e.to_string())
}

/// Held-out ΔE00 against counted patches for fixed plans and for the sequential plan,
/// on each virtual monitor, beside the instrument's repeatability.
fn sequential_table(data: &Path, seeds: &[u64]) -> Result<(), Failure> {
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
    outln!(
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
                counts.push(chromacal::calibrate::sequential::counted(&set) as f64);
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
        outln!(
            "\n{}: the instrument's repeatability (consecutive reference whites) {floor:.3}, 1.5 × that {:.3}",
            monitor.name,
            1.5 * floor
        )?;
        out!(
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

/// Instrument time of a run: every reading's integration (held-out and grid patches
/// too) and the display's settling before it.
fn run_seconds(set: &MeasurementSet, settle_s: f64) -> f64 {
    set.measurements
        .iter()
        .map(|m| m.reading.integration_s + settle_s)
        .sum()
}

/// Measure a simulated run into a journal under `dir` and return its measurements.
pub(super) fn simulate(config: &Config, dir: &Path, tag: &str) -> Result<MeasurementSet, String> {
    let path = dir.join(format!("{tag}.jsonl"));
    let _ = std::fs::remove_file(&path);
    let journal = block_on(measure_simulated(config, "", Path::new("."), &path))
        .map_err(|e| e.to_string())?
        .map_err(|e| e.to_string())?;
    let set = journal.measurement_set();
    let _ = std::fs::remove_file(&path);
    Ok(set)
}

/// ΔE00 between consecutive readings of the reference white in one run (its own white
/// as reference): what the instrument's noise alone does to a reading, the floor no
/// fit can go below.
fn white_repeat_differences(set: &MeasurementSet) -> Vec<f64> {
    let whites: Vec<Xyz> = set
        .measurements
        .iter()
        .filter(|m| m.role == Role::Reference && m.drive == [1.0; 3])
        .filter_map(|m| m.usable_xyz())
        .collect();
    let Some(first) = whites.first() else {
        return Vec::new();
    };
    whites
        .windows(2)
        .map(|w| delta_e00_xyz(&w[0], &w[1], first))
        .collect()
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

/// Speed against error: fit time per law against readings, and held-out ΔE00
/// against patch budget, on simulated monitors (and on real measured displays when
/// ../shared/data is present).
#[derive(clap::Args)]
pub struct BenchArgs {
    /// Fewer repeats, for a quick look.
    #[arg(long)]
    quick: bool,
    /// Directory of the shared reference data [default: ../shared/data beside the
    /// project chromacal was built from, else beside the working directory].
    #[arg(long)]
    data: Option<PathBuf>,
    /// Candidate laws for the ArgyllCMS comparison (comma-separated) [default: all].
    #[arg(long, value_delimiter = ',', ignore_case = true)]
    laws: Option<Vec<LawArg>>,
    /// Only these tables (comma-separated): fit-time, budget, sequential, argyll,
    /// spectral, render, gamut, fleet, corrections, law-rule.
    #[arg(long, value_delimiter = ',', value_parser = TABLES, ignore_case = true)]
    only: Vec<String>,
    /// The same as --only, as words: `chromacal bench spectral`.
    #[arg(value_parser = TABLES, ignore_case = true)]
    tables: Vec<String>,
}

/// The tables `bench` prints.
const TABLES: [&str; 10] = [
    "fit-time",
    "budget",
    "sequential",
    "argyll",
    "spectral",
    "render",
    "gamut",
    "fleet",
    "corrections",
    "law-rule",
];

/// The shared reference data: `../shared/data` from the project chromacal was built
/// in, so that `bench` finds it from any working directory; else from the working
/// directory (a binary moved elsewhere); the first that exists.
fn shared_data() -> Result<PathBuf, Vec<PathBuf>> {
    let places = [
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
        absolute_path(Path::new("../shared/data")),
    ];
    places
        .iter()
        .find(|p| p.is_dir())
        .cloned()
        .ok_or_else(|| places.to_vec())
}

pub fn run(args: BenchArgs) -> Result<(), Failure> {
    // Said first, on standard error: the tables differ with and without the data, and
    // a table left out must not pass for one measured.
    let looked = match args.data {
        Some(data) => Ok(data).and_then(|d| if d.is_dir() { Ok(d) } else { Err(vec![d]) }),
        None => shared_data(),
    };
    let data = match looked {
        Ok(data) => {
            eprintln!(
                "chromacal: reference data (real displays, measured tables) from {}",
                std::fs::canonicalize(&data)
                    .unwrap_or_else(|_| absolute_path(&data))
                    .display()
            );
            data
        }
        Err(places) => {
            let places: Vec<String> = places
                .iter()
                .map(|p| absolute_path(p).display().to_string())
                .collect();
            eprintln!(
                "chromacal: no reference data at {}: the tables use the simulated presets only and leave out the real displays and measured tables (give --data DIR, the shared data's folder)",
                places.join(" nor at ")
            );
            places
                .first()
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from("../shared/data"))
        }
    };
    let only: Vec<&String> = args.only.iter().chain(&args.tables).collect();
    let wanted = |table: &str| only.is_empty() || only.iter().any(|o| *o == table);
    if wanted("fit-time") || wanted("budget") {
        bench(args.quick, &data, wanted("fit-time"), wanted("budget"))?;
    }
    if wanted("sequential") {
        let seeds: Vec<u64> = if args.quick {
            vec![1, 2]
        } else {
            (1..=5).collect()
        };
        sequential_table(&data, &seeds)?;
    }
    if wanted("argyll") {
        let mut options = FitOptions::default();
        if let Some(laws) = args.laws {
            options.laws = laws.into_iter().map(LawKind::from).collect();
        }
        against_argyll(&data, &options)?;
    }
    if wanted("spectral") {
        super::bench_spectral::spectral_tables(&data, args.quick)?;
    }
    if wanted("render") {
        super::bench_render::render_table(args.quick)?;
    }
    if wanted("gamut") {
        super::bench_gamut::gamut_bench_table(args.quick)?;
    }
    if wanted("fleet") {
        super::bench_fleet::fleet_table(args.quick)?;
    }
    if wanted("corrections") {
        super::bench_corrections::corrections_table(&data, args.quick)?;
    }
    if wanted("law-rule") {
        super::bench_laws::law_rule_table(&data, args.quick)?;
    }
    Ok(())
}

fn bench(quick: bool, data: &Path, fit_time: bool, budget: bool) -> Result<(), Failure> {
    let repeats = if quick { 5 } else { 30 };
    let seeds: Vec<u64> = if quick {
        vec![1, 2]
    } else {
        vec![1, 2, 3, 4, 5]
    };

    // 1. Fit time per law against readings.
    if fit_time {
        fit_time_table(repeats)?;
        whole_fit_times(data, if quick { 3 } else { 11 })?;
    }
    if !budget {
        return Ok(());
    }
    budget_tables(data, &seeds)
}

/// Fit time per law against readings per channel.
fn fit_time_table(repeats: usize) -> Result<(), Failure> {
    outln!(
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
    out!("{}", table(&header_refs, &rows))
}

/// Time of the whole fit (black, drift, every law cross-validated, the additivity
/// terms, the spatial map, the checks) on each real measurement set as it is.
fn whole_fit_times(data: &Path, repeats: usize) -> Result<(), Failure> {
    let sets: Vec<(String, MeasurementSet)> = real_sets(data)
        .into_iter()
        .map(|(name, set)| match set {
            RealSet::One(set) | RealSet::Two(set, _) => (name, set),
        })
        .collect();
    if sets.is_empty() {
        return Ok(());
    }
    outln!("\nwhole fit on one core, every reading of each real set (median of {repeats}):")?;
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
            chromacal::report::duration(times[times.len() / 2]),
        ]);
    }
    out!("{}", table(&["display", "readings", "fit time"], &rows))
}

/// Held-out ΔE00 against budget, per law and for the law chosen, on each monitor.
fn budget_tables(data: &Path, seeds: &[u64]) -> Result<(), Failure> {
    let dir = std::env::temp_dir().join(format!("chromacal-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let budgets = [12usize, 24, 48, 96];
    let mut choices: Vec<(String, Vec<LawKind>)> = LawKind::ALL
        .iter()
        .map(|k| (k.name().to_string(), vec![*k]))
        .collect();
    choices.push(("chosen by CV".into(), LawKind::ALL.to_vec()));
    for monitor in monitors(data) {
        outln!(
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
        out!("{}", table(&header_refs, &rows))?;
        outln!(
            "  chosen: {}",
            budgets
                .iter()
                .zip(&chosen_names)
                .map(|(b, c)| format!("{b}: {c}"))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        if let Some(floor) = ErrorStats::of(&repeat_differences) {
            outln!(
                "  the instrument's repeatability, the floor: ΔE00 between consecutive readings of the reference white, mean {:.3} / p95 {:.3} ({} pairs)",
                floor.mean,
                floor.p95,
                floor.n
            )?;
        }
        outln!(
            "  instrument time per run (all patches incl. held-out and grid): {}",
            budgets
                .iter()
                .zip(&instrument_time)
                .map(|(b, t)| format!("{b}: {}", chromacal::report::duration(*t)))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// A real measurement set: one file split in two, or a set measured in two sessions
/// (training readings from the first, held-out mixtures from the second).
pub enum RealSet {
    One(MeasurementSet),
    Two(MeasurementSet, MeasurementSet),
}

/// The real measurement sets in `data` that have mixtures to hold out: the three
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
fn against_argyll(data: &Path, options: &FitOptions) -> Result<(), Failure> {
    let sets = real_sets(data);
    if sets.is_empty() {
        outln!("\nno real measurement sets under {}", data.display())?;
        return Ok(());
    }
    let (first, last) = (RESCALINGS.start(), RESCALINGS.end());
    outln!(
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
            chromacal::report::duration(c.fit_seconds),
        ]);
    }
    let _ = std::fs::remove_dir_all(&work);
    out!(
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
    let median = |v: Vec<f64>| chromacal::fit::stats::percentile(&v, 50.0);
    if !ratios.is_empty() {
        outln!(
            "  median ratio chromacal ICC / colprof's median run: {:.2}; to colprof's best run: {:.2}",
            median(ratios),
            median(best_ratios)
        )?;
    }
    Ok(())
}
