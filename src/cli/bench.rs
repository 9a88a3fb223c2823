//! `chromacal bench`: speed against error, as tables (`chromacal::bench` makes them;
//! this prints them). A developer's tool: hidden from the user's `--help`.

use std::path::PathBuf;

use chromacal::bench::{BenchOptions, RunError, TABLES, Tables, shared_data};

use super::fit::LawArg;
use super::shared::{Failure, absolute_path, write_stdout};

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
    let options = BenchOptions {
        quick: args.quick,
        data,
        only: args.only.into_iter().chain(args.tables).collect(),
        laws: args
            .laws
            .map(|laws| laws.into_iter().map(Into::into).collect()),
    };
    let print = |tables: Tables| {
        for note in &tables.notes {
            eprintln!("{note}");
        }
        write_stdout(tables.text.as_bytes())
    };
    chromacal::bench::run(&options, print).map_err(|e| match e {
        RunError::Bench(e) => Failure::from(e),
        RunError::Emit(failure) => failure,
    })
}
