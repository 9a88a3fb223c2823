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

pub fn run_completions(args: CompletionsArgs, mut command: clap::Command) -> Result<(), Failure> {
    // Made in memory, then written: `generate` panics when its writer fails, and a
    // reader that stops early (`| head`) is not a failure.
    let mut script = Vec::new();
    clap_complete::generate(args.shell, &mut command, "chromacal", &mut script);
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
