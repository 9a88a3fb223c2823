//! `chromacal completions SHELL` and `chromacal man`: shell completion scripts
//! (`clap_complete`) and manual pages (`clap_mangen`), made from the same clap
//! definitions as `--help`, so they cannot drift from it.

use std::path::PathBuf;

use super::shared::{Failure, write_stdout};

/// Print a completion script for a shell, e.g.
/// `chromacal completions bash > ~/.local/share/bash-completion/completions/chromacal`.
#[derive(clap::Args)]
pub struct CompletionsArgs {
    /// The shell: bash, zsh, fish, elvish or powershell.
    #[arg(ignore_case = true)]
    shell: clap_complete::Shell,
}

/// Write the manual pages: chromacal(1) and one page a command (chromacal-calibrate(1),
/// …), for `man -l` or a man directory.
#[derive(clap::Args)]
pub struct ManArgs {
    /// The directory to write them to; without it, chromacal(1) goes to standard output.
    #[arg(short, long)]
    output: Option<PathBuf>,
}

pub fn run_completions(args: CompletionsArgs, command: clap::Command) -> Result<(), Failure> {
    // Made in memory, then written: `generate` panics when its writer fails, and a
    // reader that stops early (`| head`) is not a failure.
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut visible(&command), "chromacal", &mut script);
    write_stdout(&script)
}

pub fn run_man(args: ManArgs, command: clap::Command) -> Result<(), Failure> {
    match args.output {
        None => {
            let mut page = Vec::new();
            clap_mangen::Man::new(command).render(&mut page)?;
            write_stdout(&page)?;
        }
        Some(dir) => {
            std::fs::create_dir_all(&dir)
                .map_err(|e| Failure::from(format!("{}: {e}", dir.display())))?;
            clap_mangen::generate_to(command, &dir)
                .map_err(|e| Failure::from(format!("{}: {e}", dir.display())))?;
            eprintln!("chromacal: manual pages written to {}", dir.display());
        }
    }
    Ok(())
}

/// The command as a user sees it: what `--help` hides (the developer's tools, the
/// options only tests use) left out. `clap_mangen` leaves hidden parts out itself;
/// `clap_complete` would offer them. `command` must not be built yet (its `--help` and
/// `--version` are added when it is).
fn visible(command: &clap::Command) -> clap::Command {
    let mut shown = clap::Command::new(command.get_name().to_string());
    if let Some(about) = command.get_about() {
        shown = shown.about(about.clone());
    }
    if let Some(about) = command.get_long_about() {
        shown = shown.long_about(about.clone());
    }
    if let Some(version) = command.get_version() {
        shown = shown.version(version.to_string());
    }
    let kept: Vec<&clap::Arg> = command
        .get_arguments()
        .filter(|a| !a.is_hide_set())
        .collect();
    for arg in &kept {
        shown = shown.arg((*arg).clone());
    }
    // The groups the derive makes (one a struct of arguments) lose the hidden ones too.
    for group in command.get_groups() {
        let members = group
            .get_args()
            .filter(|id| kept.iter().any(|a| a.get_id() == *id));
        shown = shown.group(
            clap::ArgGroup::new(group.get_id().clone())
                .args(members.cloned())
                .multiple(group.clone().is_multiple())
                .required(group.is_required_set()),
        );
    }
    for sub in command.get_subcommands().filter(|s| !s.is_hide_set()) {
        shown = shown.subcommand(visible(sub));
    }
    shown
}
