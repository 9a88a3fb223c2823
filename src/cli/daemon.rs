//! `chromacal daemon`, the service, and the commands that talk to a running one:
//! `status`, `job start|watch|cancel`, `history`, `rollback` (and `profile current`,
//! whose arguments are with `profile`).

use super::shared::{out, outln};
use std::path::PathBuf;
use std::time::Duration;

use bytes::Bytes;
use chromacal::daemon::api::{DevicesReply, StatusReply};
use chromacal::daemon::client::{Endpoint, Reply, follow_events_at, request};
use chromacal::daemon::default_socket;
use chromacal::daemon::events::{Event, JobKind, JobOutcome, JobStatus};
use chromacal::profile::store::default_state_dir;
use clap::Subcommand;

use super::shared::Failure;

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

/// Ask a running daemon how it is.
#[derive(clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    api: ApiArgs,
    /// Print the daemon's whole answer (GET /status) as JSON.
    #[arg(long)]
    json: bool,
}

/// Start, follow or cancel a daemon's job.
#[derive(clap::Args)]
pub struct JobArgs {
    #[command(subcommand)]
    command: JobCommand,
    #[command(flatten)]
    api: ApiArgs,
}

/// The daemon's profiles (made current, oldest first) and verifications.
#[derive(clap::Args)]
pub struct HistoryArgs {
    #[command(flatten)]
    api: ApiArgs,
    /// Print the daemon's whole answer (GET /history) as JSON.
    #[arg(long)]
    json: bool,
}

/// Make an earlier profile current again (default: the one before the current).
#[derive(clap::Args)]
pub struct RollbackArgs {
    /// The profile id to go back to.
    to: Option<String>,
    #[command(flatten)]
    api: ApiArgs,
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

#[derive(Subcommand)]
enum JobCommand {
    /// Start a job: calibrate, verify or uniformity.
    Start {
        /// calibrate (a whole calibration, published if it passes), verify (a few
        /// patches against the current profile's prediction) or uniformity (the grid
        /// alone: a new spatial map for the current profile).
        #[arg(value_parser = ["calibrate", "verify", "uniformity"])]
        kind: String,
        /// Follow it to its end with a progress bar.
        #[arg(long)]
        watch: bool,
    },
    /// Follow the running job to its end.
    Watch,
    /// Stop the running job after the reading under way (a cancelled calibration is
    /// not resumed).
    Cancel,
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

pub fn run_status(args: StatusArgs) -> Result<(), Failure> {
    status(&args.api, args.json)
}

pub fn run_job(args: JobArgs) -> Result<(), Failure> {
    match args.command {
        JobCommand::Start { kind, watch } => job_start(&args.api, &kind, watch),
        JobCommand::Watch => job_watch(&args.api),
        JobCommand::Cancel => job_cancel(&args.api),
    }
}

pub fn run_history(args: HistoryArgs) -> Result<(), Failure> {
    history(&args.api, args.json)
}

pub fn run_rollback(args: RollbackArgs) -> Result<(), Failure> {
    rollback(&args.api, args.to)
}

/// How to reach the daemon.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ApiArgs {
    /// The daemon's unix socket [default: as the daemon's: $RUNTIME_DIRECTORY/api.sock,
    /// else <state>/api.sock].
    #[arg(long, global = true)]
    socket: Option<PathBuf>,
    /// The daemon's state directory, to find its socket.
    #[arg(long, global = true)]
    state_dir: Option<PathBuf>,
    /// Talk TCP to this address instead (the daemon's `daemon.tcp`).
    #[arg(long, global = true, value_name = "ADDR")]
    tcp: Option<String>,
    /// The token file for TCP [default: <state>/api.token].
    #[arg(long, global = true)]
    token_file: Option<PathBuf>,
    /// The device of a daemon that runs several (`[[device]]`), by name.
    #[arg(long, global = true, value_name = "NAME")]
    device: Option<String>,
}

impl ApiArgs {
    /// A device's route: `/devices/NAME/…` with `--device`, else the route itself
    /// (which a daemon of one device answers).
    fn route(&self, path: &str) -> String {
        match &self.device {
            Some(name) => format!("/devices/{}{path}", query_value(name)),
            None => path.to_string(),
        }
    }

    fn endpoint(&self) -> Result<Endpoint, String> {
        let state = self.state_dir.clone().unwrap_or_else(default_state_dir);
        match &self.tcp {
            Some(address) => {
                let path = self
                    .token_file
                    .clone()
                    .unwrap_or_else(|| state.join("api.token"));
                let token = std::fs::read_to_string(&path)
                    .map_err(|e| format!("the API token {}: {e}", path.display()))?;
                Ok(Endpoint::Tcp {
                    address: address.clone(),
                    token: token.trim().to_string(),
                })
            }
            None => Ok(Endpoint::Unix(
                self.socket
                    .clone()
                    .unwrap_or_else(|| default_socket(&state)),
            )),
        }
    }
}

fn runtime() -> Result<tokio::runtime::Runtime, String> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| e.to_string())
}

/// A reply that must be 2xx, else its error as ours.
fn expect_ok(reply: Reply) -> Result<Reply, String> {
    if (200..300).contains(&reply.status) {
        Ok(reply)
    } else {
        Err(format!(
            "the daemon refused ({}): {}",
            reply.status,
            reply.error_message()
        ))
    }
}

async fn get(endpoint: &Endpoint, path: &str) -> Result<Reply, String> {
    expect_ok(
        request(endpoint, "GET", path, None)
            .await
            .map_err(|e| e.to_string())?,
    )
}

async fn post(endpoint: &Endpoint, path: &str, body: serde_json::Value) -> Result<Reply, String> {
    expect_ok(
        request(endpoint, "POST", path, Some(Bytes::from(body.to_string())))
            .await
            .map_err(|e| e.to_string())?,
    )
}

fn describe_job(job: &JobStatus) -> String {
    let mut out = format!(
        "{} ({}, started {} by {}): {}",
        job.id,
        job.kind.name(),
        job.started,
        job.origin,
        job.phase
    );
    if job.total > 0 {
        out += &format!(", {}/{} patches", job.done, job.total);
    }
    if let Some(eta) = job.eta_s {
        out += &format!(", about {} left", chromacal::report::duration(eta));
    }
    if let Some(last) = &job.last
        && let Some(de) = last.delta_e00
    {
        out += &format!(", last reading ΔE00 {de:.2} from the current profile");
    }
    out
}

fn describe_outcome(outcome: &JobOutcome) -> String {
    format!("{}: {}", outcome.result, outcome.message)
}

pub fn status(api: &ApiArgs, json: bool) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        // One device's status, or every device's.
        let (reply, statuses) = match &api.device {
            Some(_) => {
                let reply = get(&endpoint, &api.route("/status")).await?;
                let status: StatusReply = serde_json::from_slice(&reply.body)
                    .map_err(|e| format!("the daemon's status does not read: {e}"))?;
                (reply, vec![status])
            }
            None => {
                let reply = get(&endpoint, "/devices").await?;
                let devices: DevicesReply = serde_json::from_slice(&reply.body)
                    .map_err(|e| format!("the daemon's list of devices does not read: {e}"))?;
                let statuses: Vec<StatusReply> =
                    devices.devices.into_iter().map(|d| d.status).collect();
                match statuses.as_slice() {
                    // One device: its status, as `/status` gives it.
                    [one] => (
                        Reply {
                            status: reply.status,
                            body: serde_json::to_vec(one).map_err(|e| e.to_string())?.into(),
                        },
                        statuses,
                    ),
                    _ => (reply, statuses),
                }
            }
        };
        if json {
            outln!("{}", reply.text())?;
            return Ok(());
        }
        let Some(first) = statuses.first() else {
            return Err("the daemon has no devices".into());
        };
        outln!(
            "chromacal daemon {} (pid {}), up {}{}",
            first.version,
            first.pid,
            chromacal::report::duration(first.uptime_s),
            if first.shutting_down {
                ", shutting down"
            } else {
                ""
            }
        )?;
        for status in &statuses {
            print_device_status(status, statuses.len() > 1)?;
        }
        Ok(())
    })
}

/// One device's part of `chromacal status`; `named` puts its name first.
fn print_device_status(status: &StatusReply, named: bool) -> Result<(), Failure> {
    let indent = if named {
        outln!("device {}: state {}", status.device, status.state_dir)?;
        "    "
    } else {
        outln!("  state {}", status.state_dir)?;
        "  "
    };
    match &status.job {
        Some(job) => outln!("{indent}job: {}", describe_job(job))?,
        None => outln!("{indent}job: none running")?,
    }
    if let Some(last) = &status.last_job {
        outln!(
            "{indent}last job: {} {}",
            last.job.id,
            describe_outcome(&last.outcome)
        )?;
    }
    match &status.current_profile {
        Some(p) => outln!(
            "{indent}current profile: {} (made {}{}) at {}",
            p.id,
            p.created,
            p.held_out.map_or(String::new(), |h| format!(
                ", held-out mean ΔE00 {:.3}",
                h.mean
            )),
            p.path
        )?,
        None => outln!("{indent}current profile: none yet")?,
    }
    if let Some(next) = &status.next_verification {
        outln!("{indent}next verification: {next}")?;
    }
    for run in &status.unfinished_runs {
        outln!(
            "{indent}unfinished run: {} ({} readings{})",
            run.id,
            run.readings,
            if run.resumable() {
                String::new()
            } else {
                format!(
                    "; its fit failed {} times, so it is not resumed",
                    run.fit_failures
                )
            }
        )?;
    }
    Ok(())
}

/// Follow the events of job `id` (or of whatever job runs, if `None`) to its end,
/// with a progress bar. Events arrive through `events`.
async fn watch_job(
    mut events: tokio::sync::mpsc::UnboundedReceiver<Event>,
    mut id: Option<String>,
) -> Result<JobOutcome, Failure> {
    let progress = Progress::new();
    let ours = |job: &JobStatus, id: &mut Option<String>| match id {
        Some(id) => job.id == *id,
        None => {
            *id = Some(job.id.clone());
            true
        }
    };
    while let Some(event) = events.recv().await {
        match event {
            Event::JobStarted { job } | Event::Progress { job } if ours(&job, &mut id) => {
                let mut message = job.phase.clone();
                if let Some(last) = &job.last {
                    if let Some(y) = last.luminance {
                        message = format!("Y {y:.3} cd/m²");
                    }
                    if let Some(de) = last.delta_e00 {
                        message += &format!("  ΔE00 {de:.2}");
                    }
                }
                if let Some(eta) = job.eta_s {
                    message += &format!("  ETA {}", chromacal::report::duration(eta));
                }
                progress.job(&job, message)?;
            }
            Event::Warmup { job_id, step } if id.as_deref() == Some(job_id.as_str()) => {
                progress.message(format!(
                    "warming up: Y {:.3} cd/m², slope {}",
                    step.luminance,
                    step.slope_per_min
                        .map_or("…".into(), |s| format!("{:+.4} %/min", s * 100.0))
                ))?;
            }
            Event::Verification { record } => progress.line(format!(
                "verification of {}: mean ΔE00 {:.3} (threshold {})",
                record.profile_id,
                record.stats.map_or(f64::NAN, |s| s.mean),
                record.threshold
            ))?,
            Event::Published {
                profile_id, how, ..
            } => progress.line(format!("published {profile_id} ({how})"))?,
            Event::JobFinished { job, outcome } if ours(&job, &mut id) => {
                progress.finish();
                return Ok(outcome);
            }
            Event::ShuttingDown => {
                progress.finish();
                return Err(
                    "the daemon is shutting down; the job resumes when it starts again".into(),
                );
            }
            _ => {}
        }
    }
    progress.finish();
    Err("the daemon closed the event stream".into())
}

/// How `job watch` shows a job: a bar on a terminal; off one (a log, a pipe, CI), a
/// line a step on standard output, written as it comes, since a bar is not drawn there
/// and nothing would show until the job ended.
enum Progress {
    Bar(indicatif::ProgressBar),
    Lines,
}

impl Progress {
    fn new() -> Progress {
        use std::io::IsTerminal as _;
        if !std::io::stderr().is_terminal() {
            return Progress::Lines;
        }
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} {prefix} [{bar:40}] {pos}/{len}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        bar.enable_steady_tick(Duration::from_millis(200));
        Progress::Bar(bar)
    }

    /// The job's step and what its last reading said.
    fn job(&self, job: &JobStatus, message: String) -> Result<(), Failure> {
        match self {
            Progress::Bar(bar) => {
                bar.set_prefix(job.kind.name());
                bar.set_length(job.total as u64);
                bar.set_position(job.done as u64);
                bar.set_message(message);
                Ok(())
            }
            Progress::Lines => outln!("{} {}/{}  {message}", job.kind.name(), job.done, job.total),
        }
    }

    /// A passing state (warming up): the bar's message, or a line.
    fn message(&self, message: String) -> Result<(), Failure> {
        match self {
            Progress::Bar(bar) => {
                bar.set_message(message);
                Ok(())
            }
            Progress::Lines => outln!("{message}"),
        }
    }

    /// Something that happened (a verification, a profile published).
    fn line(&self, line: String) -> Result<(), Failure> {
        match self {
            Progress::Bar(bar) => {
                bar.println(line);
                Ok(())
            }
            Progress::Lines => outln!("{line}"),
        }
    }

    fn finish(&self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// Open the event stream, forwarding parsed events to a channel.
fn subscribe(api: &ApiArgs, endpoint: &Endpoint) -> tokio::sync::mpsc::UnboundedReceiver<Event> {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let endpoint = endpoint.clone();
    let path = api.route("/events");
    tokio::spawn(async move {
        let result = follow_events_at(&endpoint, &path, |_, data| {
            match serde_json::from_str::<Event>(data) {
                Ok(event) => tx.send(event).is_ok(),
                Err(_) => true, // an event this client does not know
            }
        })
        .await;
        match result {
            Ok(Some(refused)) => {
                eprintln!("chromacal: events refused: {}", refused.error_message())
            }
            Err(e) => eprintln!("chromacal: {e}"),
            Ok(None) => {}
        }
    });
    rx
}

fn finish(outcome: JobOutcome) -> Result<(), Failure> {
    outln!("{}", describe_outcome(&outcome))?;
    if outcome.result == "ok" {
        Ok(())
    } else {
        Err(format!("the job ended {}", outcome.result).into())
    }
}

pub fn job_start(api: &ApiArgs, kind: &str, watch: bool) -> Result<(), Failure> {
    let kind = JobKind::parse(kind)?;
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        // Subscribe first, so that no event of the new job is missed.
        let events = watch.then(|| subscribe(api, &endpoint));
        if events.is_some() {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let reply = post(
            &endpoint,
            &api.route("/jobs"),
            serde_json::json!({ "kind": kind.name() }),
        )
        .await?;
        let job: JobStatus = serde_json::from_slice(&reply.body)
            .map_err(|e| format!("the daemon's answer does not read: {e}"))?;
        match events {
            None => {
                outln!("started {}", job.id)?;
                Ok(())
            }
            Some(events) => finish(watch_job(events, Some(job.id)).await?),
        }
    })
}

pub fn job_watch(api: &ApiArgs) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        let events = subscribe(api, &endpoint);
        let status: StatusReply =
            serde_json::from_slice(&get(&endpoint, &api.route("/status")).await?.body)
                .map_err(|e| format!("the daemon's status does not read: {e}"))?;
        match status.job {
            Some(job) => finish(watch_job(events, Some(job.id)).await?),
            None => {
                match status.last_job {
                    Some(last) => outln!(
                        "no job is running; the last, {}, ended {}",
                        last.job.id,
                        describe_outcome(&last.outcome)
                    )?,
                    None => outln!("no job is running")?,
                }
                Ok(())
            }
        }
    })
}

pub fn job_cancel(api: &ApiArgs) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        let reply = post(&endpoint, &api.route("/jobs/cancel"), serde_json::json!({})).await?;
        let job: JobStatus = serde_json::from_slice(&reply.body)
            .map_err(|e| format!("the daemon's answer does not read: {e}"))?;
        outln!("cancelling {} after the reading under way", job.id)?;
        Ok(())
    })
}

pub fn history(api: &ApiArgs, json: bool) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        let reply = get(&endpoint, &api.route("/history")).await?;
        if json {
            outln!("{}", reply.text())?;
            return Ok(());
        }
        let value = reply.json()?;
        let current = value["current"].as_str().unwrap_or("");
        outln!("profiles made current, oldest first:")?;
        for p in value["profiles"].as_array().into_iter().flatten() {
            let id = p["id"].as_str().unwrap_or("?");
            outln!(
                "  {} {:<10} {}{}{}",
                p["at"].as_str().unwrap_or("?"),
                p["how"].as_str().unwrap_or("?"),
                id,
                p["held_out"]["mean"]
                    .as_f64()
                    .map_or(String::new(), |m| format!("  held-out mean ΔE00 {m:.3}")),
                if id == current { "  ← current" } else { "" }
            )?;
        }
        let verifications = value["verifications"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        outln!("verifications ({}):", verifications.len())?;
        for v in verifications {
            outln!(
                "  {} {}  mean ΔE00 {}  max {}{}",
                v["at"].as_str().unwrap_or("?"),
                v["profile_id"].as_str().unwrap_or("?"),
                v["stats"]["mean"]
                    .as_f64()
                    .map_or("-".into(), |m| format!("{m:.3}")),
                v["stats"]["max"]
                    .as_f64()
                    .map_or("-".into(), |m| format!("{m:.3}")),
                if v["escalated"].as_bool() == Some(true) {
                    "  → recalibrated"
                } else {
                    ""
                }
            )?;
        }
        Ok(())
    })
}

pub fn rollback(api: &ApiArgs, to: Option<String>) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        let body = match &to {
            Some(id) => serde_json::json!({ "to": id }),
            None => serde_json::json!({}),
        };
        let reply = post(&endpoint, &api.route("/rollback"), body).await?;
        let entry = reply.json()?;
        outln!(
            "current profile is now {}",
            entry["id"].as_str().unwrap_or("?")
        )?;
        Ok(())
    })
}

/// `text` percent-encoded for a query string (RFC 3986 §2.1): every byte but the
/// unreserved ones and the few a target is written with (`,`, `:`, `.`).
fn query_value(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'_' | b'.' | b'~' | b',' | b':' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}

pub fn current_profile(
    api: &ApiArgs,
    json: bool,
    format: Option<&str>,
    target: [(&str, Option<String>); 3],
    output: Option<&std::path::Path>,
) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    let format = format.unwrap_or(if json { "json" } else { "toml" });
    let mut query = api.route(&format!("/profile?format={}", query_value(format)));
    for (key, value) in target {
        if let Some(value) = value {
            query += &format!("&{key}={}", query_value(&value));
        }
    }
    runtime()?.block_on(async {
        let reply = get(&endpoint, &query).await?;
        match output {
            Some(path) => {
                std::fs::write(path, &reply.body)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                outln!(
                    "wrote {} ({format}, {} bytes)",
                    path.display(),
                    reply.body.len()
                )?;
            }
            None if matches!(format, "icc4" | "icc2") => {
                return Err(format!("{format} is binary: give -o FILE").into());
            }
            None => out!("{}", reply.text())?,
        }
        Ok(())
    })
}
