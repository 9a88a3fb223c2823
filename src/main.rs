//! The `chromacal` command: parses the command line and hands each command to its file
//! under `cli/`, where its arguments and its code are.

use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};

mod cli;

use cli::{
    bench, calibrate, check, completions, config, correction, daemon, displays, emulate, export,
    fit, instruments, lut, lut3d, measure, profile, render, report, spectrum,
};

#[derive(Parser)]
#[command(
    name = "chromacal",
    version,
    about = "Monitor calibration: measure, fit a physical model, test its assumptions, publish a profile",
    after_help = cli::shared::EXIT_CODES
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// More on stderr: -v says what is done, -vv debug, -vvv trace. CHROMACAL_LOG or
    /// RUST_LOG (a tracing filter such as `chromacal=debug`), when set, decide instead.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Only errors on stderr (no warnings).
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
}

/// Every command; the doc comment of each one's arguments is its help.
#[derive(Subcommand)]
enum Command {
    Calibrate(calibrate::CalibrateArgs),
    Runs(calibrate::RunsArgs),
    Fit(fit::FitArgs),
    Check(check::CheckArgs),
    Spectrum(spectrum::SpectrumArgs),
    Render(render::RenderArgs),
    Report(report::ReportArgs),
    Emulate(emulate::EmulateArgs),
    Measure(measure::MeasureArgs),
    Correction(correction::CorrectionArgs),
    Instruments(instruments::InstrumentsArgs),
    Displays(displays::DisplaysArgs),
    Lut(lut::LutArgs),
    Lut3d(lut3d::Lut3dArgs),
    Export(export::ExportArgs),
    Profile(profile::ProfileArgs),
    Daemon(daemon::DaemonArgs),
    Status(daemon::StatusArgs),
    Job(daemon::JobArgs),
    History(daemon::HistoryArgs),
    Rollback(daemon::RollbackArgs),
    Bench(bench::BenchArgs),
    Config(config::ConfigArgs),
    Completions(completions::CompletionsArgs),
    Man(completions::ManArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    cli::shared::init_logging(
        matches!(cli.command, Command::Daemon(_)),
        cli.verbose,
        cli.quiet,
    );
    let result = match cli.command {
        Command::Calibrate(args) => calibrate::run(args),
        Command::Runs(args) => calibrate::run_runs(args),
        Command::Fit(args) => fit::run(args),
        Command::Check(args) => check::run(args),
        Command::Spectrum(args) => spectrum::run(args),
        Command::Render(args) => render::run(args),
        Command::Report(args) => report::run(args),
        Command::Emulate(args) => emulate::run(args),
        Command::Measure(args) => measure::run(args),
        Command::Correction(args) => correction::run(args),
        Command::Instruments(args) => instruments::run(args),
        Command::Displays(args) => displays::run(args),
        Command::Lut(args) => lut::run(args),
        Command::Lut3d(args) => lut3d::run(args),
        Command::Export(args) => export::run(args),
        Command::Profile(args) => profile::run(args),
        Command::Daemon(args) => daemon::run(args),
        Command::Status(args) => daemon::run_status(args),
        Command::Job(args) => daemon::run_job(args),
        Command::History(args) => daemon::run_history(args),
        Command::Rollback(args) => daemon::run_rollback(args),
        Command::Bench(args) => bench::run(args),
        Command::Config(args) => config::run(args),
        Command::Completions(args) => completions::run_completions(args, Cli::command()),
        Command::Man(args) => completions::run_man(args, Cli::command()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) if f.is_output_closed() => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("chromacal: {}", f.message);
            ExitCode::from(f.code)
        }
    }
}
