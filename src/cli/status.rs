//! `chromacal status`: how a running daemon is, device by device.

use chromacal::daemon::api::{DevicesReply, StatusReply};
use chromacal::daemon::client::Reply;
use chromacal::daemon::events::{JobOutcome, JobStatus};

use super::api::{ApiArgs, get, runtime};
use super::shared::{Failure, outln};

/// Ask a running daemon how it is.
#[derive(clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    api: ApiArgs,
    /// Print the daemon's whole answer (GET /status) as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: StatusArgs) -> Result<(), Failure> {
    status(&args.api, args.json)
}

pub fn describe_job(job: &JobStatus) -> String {
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

pub fn describe_outcome(outcome: &JobOutcome) -> String {
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
                            headers: reply.headers.clone(),
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
