//! `chromacal runs`: the unfinished calibration runs of a state directory.

use std::path::PathBuf;

use chromacal::calibrate::session::{newest_resumable, unfinished_runs};
use chromacal::profile::store::default_state_dir;

use super::shared::{Failure, outln};

/// List the unfinished calibration runs of a state directory: the ones
/// `calibrate --resume [RUN]` can go on with.
#[derive(clap::Args)]
pub struct RunsArgs {
    /// Profile store and run journals (as for `calibrate`).
    #[arg(long)]
    state_dir: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: RunsArgs) -> Result<(), Failure> {
    let store = chromacal::profile::store::ProfileStore::new(
        &args.state_dir.unwrap_or_else(default_state_dir),
    );
    let runs = unfinished_runs(&store);
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&runs)?)?;
        return Ok(());
    }
    if runs.is_empty() {
        outln!("no unfinished runs in {}", store.runs_dir().display())?;
        return Ok(());
    }
    let newest = newest_resumable(&runs).map(|r| &r.id);
    outln!("{:<30} {:>9}  state", "run", "readings")?;
    for run in &runs {
        let state = if run.by_daemon {
            "a daemon's: `chromacal daemon` on this state directory resumes it when it starts"
                .to_string()
        } else if !run.resumable() {
            format!(
                "its fit failed {} times: resumed only by name",
                run.fit_failures
            )
        } else if Some(&run.id) == newest {
            "resumed by `calibrate --resume`".to_string()
        } else {
            "resume with `calibrate --resume <run>`".to_string()
        };
        outln!("{:<30} {:>9}  {state}", run.id, run.readings)?;
    }
    Ok(())
}
