//! `chromacal profile show` (a profile in words and numbers) and `profile current` (a
//! running daemon's, in any export format).

use std::path::PathBuf;

use clap::Subcommand;

use chromacal::profile::Profile;
use chromacal::report;

use super::daemon::{ApiArgs, current_profile};
use super::shared::Failure;

/// Work with profiles.
#[derive(clap::Args)]
pub struct ProfileArgs {
    #[command(subcommand)]
    command: ProfileCommand,
}

// Parsed once per run: the size of its largest variant costs nothing worth boxing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum ProfileCommand {
    /// Print the model in words and numbers.
    Show {
        /// A chromacal profile (TOML), e.g. <state>/current.toml.
        profile: PathBuf,
    },
    /// The current profile of a running daemon (TOML, or JSON).
    Current {
        #[command(flatten)]
        api: ApiArgs,
        /// The profile as JSON (the same as --format json).
        #[arg(long)]
        json: bool,
        /// Any export format (the daemon exports it): icc4, icc2, ti3, cal, psychopy,
        /// json, toml.
        #[arg(long, ignore_case = true, value_parser = ["icc4", "icc2", "ti3", "cal", "psychopy", "json", "toml"])]
        format: Option<String>,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Calibration target white for the curves (icc4, icc2, cal), as `export`
        /// takes it: native, D50, D55, D65, D75, 6500K or x,y.
        #[arg(long)]
        white: Option<String>,
        /// Calibration target tone curve: gamma:G, srgb, bt1886 or lstar.
        #[arg(long)]
        tone: Option<String>,
        /// Calibration target white luminance in cd/m², or max.
        #[arg(long)]
        luminance: Option<String>,
    },
}

pub fn run(args: ProfileArgs) -> Result<(), Failure> {
    match args.command {
        ProfileCommand::Show { profile } => Profile::read(&profile)
            .map(|p| print!("{}", report::describe_profile(&p)))
            .map_err(Failure::from),
        ProfileCommand::Current {
            api,
            json,
            format,
            output,
            white,
            tone,
            luminance,
        } => current_profile(
            &api,
            json,
            format.as_deref(),
            [("white", white), ("tone", tone), ("luminance", luminance)],
            output.as_deref(),
        )
        .map_err(Failure::from),
    }
}
