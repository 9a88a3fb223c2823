//! The `chromacal` command: parses the command line and hands each command to its file
//! under `cli/`, where its arguments and its code are.

use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};

mod cli;

use cli::{
    adjust, bench, calibrate, check, completions, config, correction, daemon, displays, emulate,
    export, fit, history, instruments, job, lut, lut3d, measure, profile, render, report, runs,
    spectrum, status, verify,
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
    Adjust(adjust::AdjustArgs),
    Runs(runs::RunsArgs),
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
    Verify(verify::VerifyArgs),
    Export(export::ExportArgs),
    Profile(profile::ProfileArgs),
    Daemon(daemon::DaemonArgs),
    Status(status::StatusArgs),
    Job(job::JobArgs),
    History(history::HistoryArgs),
    Rollback(history::RollbackArgs),
    // A developer's tool: hidden from the user's --help, its man page and completions.
    #[command(hide = true)]
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
        Command::Adjust(args) => adjust::run(args),
        Command::Runs(args) => runs::run(args),
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
        Command::Verify(args) => verify::run(args),
        Command::Export(args) => export::run(args),
        Command::Profile(args) => profile::run(args),
        Command::Daemon(args) => daemon::run(args),
        Command::Status(args) => status::run(args),
        Command::Job(args) => job::run(args),
        Command::History(args) => history::run(args),
        Command::Rollback(args) => history::run_rollback(args),
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
