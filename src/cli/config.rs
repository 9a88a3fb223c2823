//! `chromacal config show`: the configuration in effect, and where it came from.

use std::path::PathBuf;

use chromacal::config::{check_config, config_search_paths, device_configs, load_config_searching};

use super::shared::{Failure, absolute_path, out};

/// Show the configuration chromacal would use: the file given, else the first of
/// $XDG_CONFIG_HOME/chromacal/config.toml (~/.config/chromacal/config.toml) and
/// /etc/chromacal/config.toml that exists, else the built-in config/default.toml.
#[derive(clap::Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    command: ConfigCommand,
}

#[derive(clap::Subcommand)]
enum ConfigCommand {
    /// Print the configuration in effect as TOML, every default filled in, after a
    /// comment saying which file it was read from (and which were looked for).
    Show {
        /// Configuration file [default: the first found, as above].
        #[arg(long)]
        config: Option<PathBuf>,
    },
}

pub fn run(args: ConfigArgs) -> Result<(), Failure> {
    match args.command {
        ConfigCommand::Show { config } => show(config),
    }
}

fn show(config: Option<PathBuf>) -> Result<(), Failure> {
    let search = config_search_paths();
    let loaded = load_config_searching(config.as_deref(), &search)?;
    let text = toml::to_string(&loaded.config)
        .map_err(|e| Failure::from(format!("cannot write the configuration as TOML: {e}")))?;
    let mut out = format!(
        "# The configuration in effect, read from {}.\n",
        loaded.origin
    );
    if config.is_none() {
        out += "# Looked for, in order:";
        for path in &search {
            out += &format!(
                " {}{};",
                path.display(),
                if path.is_file() { "" } else { " (absent)" }
            );
        }
        out += " then the built-in one.\n";
    }
    out += &format!(
        "# Relative paths are taken from {}.\n",
        absolute_path(&loaded.base_dir).display()
    );
    // The daemon's own checks, in its order: the whole config, then each device.
    let refused = check_config(&loaded.config)
        .err()
        .or_else(|| device_configs(&loaded).err());
    if let Some(why) = &refused {
        out += &format!("# It would be refused: {why}\n");
    }
    out!("{out}\n{text}")?;
    match refused {
        Some(why) => Err(Failure::from(format!(
            "this configuration would be refused: {why}"
        ))),
        None => Ok(()),
    }
}
