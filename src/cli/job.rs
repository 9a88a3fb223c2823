//! `chromacal job start|watch|cancel`: a running daemon's jobs, followed with a
//! progress bar.

use std::time::Duration;

use chromacal::daemon::api::StatusReply;
use chromacal::daemon::client::{Endpoint, follow_events_at};
use chromacal::daemon::events::{Event, JobKind, JobOutcome, JobStatus};
use clap::Subcommand;

use super::api::{ApiArgs, get, post, runtime};
use super::shared::{Failure, outln};
use super::status::describe_outcome;

/// Start, follow or cancel a daemon's job.
#[derive(clap::Args)]
pub struct JobArgs {
    #[command(subcommand)]
    command: JobCommand,
    #[command(flatten)]
    api: ApiArgs,
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

pub fn run(args: JobArgs) -> Result<(), Failure> {
    match args.command {
        JobCommand::Start { kind, watch } => job_start(&args.api, &kind, watch),
        JobCommand::Watch => job_watch(&args.api),
        JobCommand::Cancel => job_cancel(&args.api),
    }
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
                "verification of {}: mean {} {:.3} (threshold {})",
                record.profile_id,
                record.metric.name(),
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
