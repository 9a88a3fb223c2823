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

#[derive(Subcommand)]
enum ProfileCommand {
    /// Print the model in words and numbers.
    Show { profile: PathBuf },
    /// The current profile of a running daemon (TOML, or JSON).
    Current {
        #[command(flatten)]
        api: ApiArgs,
        #[arg(long)]
        json: bool,
        /// Any export format (the daemon exports it): icc4, icc2, ti3, psychopy, json, toml.
        #[arg(long, value_parser = ["icc4", "icc2", "ti3", "psychopy", "json", "toml"])]
        format: Option<String>,
        /// Write to this file instead of standard output.
        #[arg(short, long)]
        output: Option<PathBuf>,
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
        } => {
            current_profile(&api, json, format.as_deref(), output.as_deref()).map_err(Failure::from)
        }
    }
}
