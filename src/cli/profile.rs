//! `chromacal profile show` (a profile in words and numbers) and `profile current` (a
//! running daemon's, in any export format).

use super::shared::out;
use std::path::PathBuf;

use clap::Subcommand;

use chromacal::profile::Profile;
use chromacal::report;

use super::api::ApiArgs;
use super::args::TargetArgs;
use super::history::current_profile;
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
        /// The curves' target (icc4, icc2, cal), as `export` takes it.
        #[command(flatten)]
        target: TargetArgs,
    },
}

pub fn run(args: ProfileArgs) -> Result<(), Failure> {
    match args.command {
        ProfileCommand::Show { profile } => {
            let profile = Profile::read(&profile)?;
            out!("{}", report::describe_profile(&profile))
        }
        ProfileCommand::Current {
            api,
            json,
            format,
            output,
            target,
        } => current_profile(
            &api,
            json,
            format.as_deref(),
            [
                ("white", target.white),
                ("tone", target.tone),
                ("luminance", target.luminance),
            ],
            output.as_deref(),
        ),
    }
}
