//! `chromacal daemon`: the service, and `daemon reload`, which asks a running one to
//! reread its config. The commands that talk to a running daemon are in `status`,
//! `job` and `history`; how they reach it, in `api`.

use std::path::PathBuf;

use chromacal::profile::store::default_state_dir;
use clap::Subcommand;

use super::api::{ApiArgs, post, runtime};
use super::shared::{Failure, outln};

/// Run as a service: hold the instruments and displays, run one job at a time on each,
/// verify on a schedule and recalibrate when the screen moved, and answer the
/// control API (HTTP on a unix socket, mode 0600; optionally loopback TCP with a
/// token): GET /status, POST /jobs {"kind": …}, POST /jobs/cancel, GET /events
/// (server-sent events), GET /profile[?format=toml|json|icc4|icc2|ti3|cal|psychopy],
/// GET /history, GET /report (HTML), POST /rollback; with several devices
/// ([[device]] in the config) each under /devices/NAME/…; GET /devices, GET /metrics
/// (Prometheus), GET / (the fleet page; over TCP a browser logs in at /login), POST
/// /reload.
/// Stops on SIGTERM after the reading under way; an interrupted calibration
/// resumes at the next start. SIGHUP (or `chromacal daemon reload`) rereads the
/// config.
#[derive(clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct DaemonArgs {
    #[command(subcommand)]
    command: Option<DaemonCommand>,
    /// Configuration file (TOML) [default: $XDG_CONFIG_HOME/chromacal/config.toml, else
    /// /etc/chromacal/config.toml, else the built-in config/default.toml; see
    /// `chromacal config show`].
    #[arg(long)]
    config: Option<PathBuf>,
    /// Profile store, journals, history [default: as for calibrate].
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// The API's unix socket [default: $RUNTIME_DIRECTORY/api.sock, else <state>/api.sock].
    #[arg(long)]
    socket: Option<PathBuf>,
    /// Also serve the API on this loopback TCP address (token in <state>/api.token).
    #[arg(long, value_name = "ADDR")]
    tcp: Option<String>,
    /// Real seconds per simulated second for the simulated monitor and instrument
    /// (`daemon.simulated_time_scale`; 0.01 runs a 5-minute calibration in 3 s).
    #[arg(long, value_name = "S", value_parser = super::shared::positive_number)]
    time_scale: Option<f64>,
}

#[derive(Subcommand)]
enum DaemonCommand {
    /// Make the running daemon reread its config, as SIGHUP does: devices added
    /// start, devices removed or changed leave after their running job (a changed one
    /// then starts on its new config), the others are not touched. A config that does
    /// not load is refused and the daemon runs on with the one it had (exit 1).
    Reload {
        #[command(flatten)]
        api: ApiArgs,
    },
}

fn daemon(options: chromacal::daemon::DaemonOptions) -> Result<(), Failure> {
    let loaded = options.load_config().map_err(Failure::from)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let result = runtime.block_on(chromacal::daemon::run(loaded, options));
    // The daemon has stopped its job and left its devices; connections still open
    // (event streams) are simply dropped.
    runtime.shutdown_timeout(std::time::Duration::from_millis(200));
    result.map_err(|e| Failure::from(e.to_string()))
}

pub fn run(args: DaemonArgs) -> Result<(), Failure> {
    if let Some(DaemonCommand::Reload { api }) = &args.command {
        return reload(api);
    }
    daemon(chromacal::daemon::DaemonOptions {
        config: args.config,
        state_dir: args.state_dir.unwrap_or_else(default_state_dir),
        socket: args.socket,
        tcp: args.tcp,
        time_scale: args.time_scale,
    })
}

/// `chromacal daemon reload`: `POST /reload`, and what it changed.
fn reload(api: &ApiArgs) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        let reply = post(&endpoint, "/reload", serde_json::json!({})).await?;
        let value = reply.json()?;
        let list = |key: &str| {
            let names: Vec<&str> = value[key]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|n| n.as_str())
                .collect();
            match names.is_empty() {
                true => "none".to_string(),
                false => names.join(", "),
            }
        };
        outln!(
            "config reloaded: added {}; removed {}; changed {}",
            list("added"),
            list("removed"),
            list("changed")
        )?;
        if value["restart_needed"]
            .as_array()
            .is_some_and(|a| !a.is_empty())
        {
            outln!(
                "changes to {} take effect at the next restart",
                list("restart_needed")
            )?;
        }
        Ok(())
    })
}
