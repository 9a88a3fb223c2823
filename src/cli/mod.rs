//! The command line, one file a command: each holds its clap arguments beside the code
//! that runs it, and ends in `run(args) -> Result<(), Failure>`. `main.rs` only parses
//! and dispatches; what the commands share is in `shared`.

pub mod adjust;
pub mod api;
pub mod args;
pub mod bench;
pub mod calibrate;
pub mod check;
pub mod completions;
pub mod config;
pub mod correction;
pub mod daemon;
pub mod displays;
pub mod emulate;
pub mod export;
pub mod fit;
pub mod history;
pub mod instruments;
pub mod job;
pub mod lut;
pub mod lut3d;
mod lut_wayland;
pub mod measure;
pub mod profile;
pub mod render;
pub mod report;
pub mod runs;
pub mod shared;
pub mod spectrum;
pub mod status;
pub mod verify;

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every argument of every command, positionals included, says what it is in
    /// `--help`.
    #[test]
    fn every_argument_has_help() {
        fn walk(command: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in command.get_arguments() {
                let id = arg.get_id().as_str();
                if matches!(id, "help" | "version") {
                    continue;
                }
                if arg.get_help().is_none() && arg.get_long_help().is_none() {
                    missing.push(format!("{path} {id}"));
                }
            }
            for sub in command.get_subcommands() {
                if sub.get_name() != "help" {
                    walk(sub, &format!("{path} {}", sub.get_name()), missing);
                }
            }
        }
        let mut missing = Vec::new();
        walk(&crate::Cli::command(), "chromacal", &mut missing);
        assert!(missing.is_empty(), "arguments without help: {missing:#?}");
        crate::Cli::command().debug_assert();
    }
}
