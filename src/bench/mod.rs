//! Speed against error, as tables: what `chromacal bench` prints. Each table is made
//! here and returned as text ([`Tables`]); the command only prints it.
//!
//! 1. Fit time of each law against the number of readings per channel (`fit-time`).
//! 2. Held-out ΔE00 (the verification patches, never fitted on) against the patch
//!    budget, for each law forced and for the law chosen by cross-validation, on each
//!    simulated monitor: the two presets, and, when the shared reference data are
//!    there, virtual monitors whose primaries are real measured spectra and whose
//!    transfer is a real measured table (ISETBio CRT, LCD and OLED) (`budget`).
//! 3. Fixed against sequential plans (`sequential`), chromacal against ArgyllCMS on
//!    real measurement sets (`argyll`), the survey's spectral methods (`spectral`),
//!    the colour reproduction function's speed (`render`), the gamut mappings
//!    (`gamut`), a fleet on one daemon (`fleet`), colorimeter corrections
//!    (`corrections`) and the law rule (`law-rule`), each in its own file.
//!
//! Every simulated run uses realistic noise (0.2 % gain, 0.2 % per band, 0.0005 cd/m²
//! floor) and is repeated over seeds; the table gives the mean over seeds.

mod argyll;
mod corrections;
mod fit;
mod fleet;
mod gamut;
mod laws;
mod render;
mod sequential;
mod spectral;

pub use sequential::{Floor, repeatability_floor};

use std::path::{Path, PathBuf};

use crate::calibrate::session::{block_on, measure_simulated};
use crate::config::{Config, parse_config};
use crate::journal::absolute_path;
use chromacal_color::Xyz;
use chromacal_model::fit::FitOptions;
use chromacal_model::fit::validate::delta_e00_xyz;
use chromacal_model::measurement::MeasurementSet;
use chromacal_model::measurement::Role;
use chromacal_model::transfer::LawKind;

/// What a table produced: its text (for standard output) and notes for the user on
/// what it left out and why (for standard error).
#[derive(Debug, Default)]
pub struct Tables {
    pub text: String,
    pub notes: Vec<String>,
}

/// Why a table could not be made.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BenchError(String);

impl From<String> for BenchError {
    fn from(message: String) -> Self {
        BenchError(message)
    }
}

impl From<&str> for BenchError {
    fn from(message: &str) -> Self {
        BenchError(message.to_string())
    }
}

impl From<std::fmt::Error> for BenchError {
    fn from(e: std::fmt::Error) -> Self {
        BenchError(e.to_string())
    }
}

/// The tables `bench` makes, in the order it makes them.
pub const TABLES: [&str; 10] = [
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

/// What to make.
#[derive(Debug, Clone, Default)]
pub struct BenchOptions {
    /// Fewer repeats, for a quick look.
    pub quick: bool,
    /// The shared reference data (real displays, measured tables); the tables that
    /// need it leave those rows out where it is missing.
    pub data: PathBuf,
    /// Only these of [`TABLES`]; all when empty.
    pub only: Vec<String>,
    /// Candidate laws for the ArgyllCMS comparison; all when `None`.
    pub laws: Option<Vec<LawKind>>,
}

/// The shared reference data: `../shared/data` from the project chromacal was built
/// in, so that `bench` finds it from any working directory; else from the working
/// directory (a binary moved elsewhere); the first that exists, or every place looked.
pub fn shared_data() -> Result<PathBuf, Vec<PathBuf>> {
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

/// Make the tables `options` asks for, handing each to `emit` as soon as it is made
/// (a bench runs for minutes: the first tables are printed while the rest are made).
pub fn run<E>(
    options: &BenchOptions,
    mut emit: impl FnMut(Tables) -> Result<(), E>,
) -> Result<(), RunError<E>> {
    let wanted = |table: &str| options.only.is_empty() || options.only.iter().any(|o| o == table);
    let data = options.data.as_path();
    let quick = options.quick;
    let mut table = |make: &dyn Fn(&mut Tables) -> Result<(), BenchError>| {
        let mut out = Tables::default();
        make(&mut out).map_err(RunError::Bench)?;
        emit(out).map_err(RunError::Emit)
    };
    if wanted("fit-time") || wanted("budget") {
        table(&|out| fit::bench(out, quick, data, wanted("fit-time"), wanted("budget")))?;
    }
    if wanted("sequential") {
        let seeds: Vec<u64> = if quick {
            vec![1, 2]
        } else {
            (1..=10).collect()
        };
        table(&|out| sequential::sequential_table(out, data, &seeds))?;
    }
    if wanted("argyll") {
        let mut fit = FitOptions::default();
        if let Some(laws) = &options.laws {
            fit.laws = laws.clone();
        }
        table(&|out| argyll::against_argyll(out, data, &fit))?;
    }
    if wanted("spectral") {
        table(&|out| spectral::spectral_tables(out, data, quick))?;
    }
    if wanted("render") {
        table(&|out| render::render_table(out, quick))?;
    }
    if wanted("gamut") {
        table(&|out| gamut::gamut_bench_table(out, quick))?;
    }
    if wanted("fleet") {
        table(&|out| fleet::fleet_table(out, quick))?;
    }
    if wanted("corrections") {
        table(&|out| corrections::corrections_table(out, data, quick))?;
    }
    if wanted("law-rule") {
        table(&|out| laws::law_rule_table(out, data, quick))?;
    }
    Ok(())
}

/// Why [`run`] stopped: a table could not be made, or the one made could not be
/// handed on (standard output closed).
#[derive(Debug)]
pub enum RunError<E> {
    Bench(BenchError),
    Emit(E),
}

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

/// Instrument time of a run: every reading's integration (held-out and grid patches
/// too) and the display's settling before it.
fn run_seconds(set: &MeasurementSet, settle_s: f64) -> f64 {
    set.measurements
        .iter()
        .map(|m| m.reading.integration_s + settle_s)
        .sum()
}

/// Measure a simulated run into a journal under `dir` and return its measurements.
fn simulate(config: &Config, dir: &Path, tag: &str) -> Result<MeasurementSet, String> {
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
