//! SIGKILL at random points of runs, as a crash or a power cut would stop the daemon:
//! after each restart the run resumes with every reading taken before it kept as it
//! was, none taken twice, and the previous profile current until the new one passes.
//!
//! At least 20 kills in the suite; `scripts/test.sh --soak N` (or
//! `CHROMACAL_SOAK_KILLS=N cargo test --test daemon_kill`) for more.

use std::time::Duration;

use chromacal::journal::Journal;
use rand::{Rng, SeedableRng};

mod common;
use common::daemon::{TestDaemon, get, post, start_daemon, wait_idle};
use common::{assert_each_planned_patch_once, daemon_runs};

const CONFIG: &str = "[daemon]\nsimulated_time_scale = 0.004\n";

fn kills_wanted() -> usize {
    std::env::var("CHROMACAL_SOAK_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20)
}

/// The newest run's journal and whether it ended in a profile.
fn newest_run(daemon: &TestDaemon) -> Option<(std::path::PathBuf, bool)> {
    let journal = daemon_runs(&daemon.state).pop()?;
    let done = journal.with_file_name("profile").exists();
    Some((journal, done))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigkill_anywhere_loses_no_reading_and_keeps_the_previous_profile() {
    let seed: u64 = std::env::var("CHROMACAL_SOAK_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2026);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let dir = tempfile::tempdir().unwrap();

    // A first profile, made without interruption.
    let daemon = start_daemon(dir.path(), CONFIG);
    let api = daemon.endpoint();
    assert_eq!(
        post(&api, "/jobs", r#"{"kind": "calibrate"}"#).await.status,
        202
    );
    tokio::time::sleep(Duration::from_millis(50)).await;
    wait_idle(&api, Duration::from_secs(60)).await;
    drop(daemon);
    let current_id = |state: &std::path::Path| {
        chromacal::profile::Profile::read(&state.join("current.toml"))
            .unwrap()
            .id
    };
    let mut current = current_id(&dir.path().join("state"));

    let wanted = kills_wanted();
    let (mut kills, mut completed_runs) = (0, 0);
    // What each run's journal held after the last kill, to check nothing is lost.
    let mut kept: Option<(
        std::path::PathBuf,
        Vec<chromacal_model::measurement::Measurement>,
    )> = None;
    while kills < wanted {
        let mut daemon = start_daemon(dir.path(), CONFIG);
        let api = daemon.endpoint();
        // An unfinished run resumes by itself; otherwise start the next one.
        let status = get(&api, "/status").await.json().unwrap();
        if status["job"].is_null() && kept.is_none() {
            let reply = post(&api, "/jobs", r#"{"kind": "calibrate"}"#).await;
            assert!(matches!(reply.status, 202 | 409), "{}", reply.text());
        }
        tokio::time::sleep(Duration::from_millis(rng.random_range(20..300))).await;
        daemon.kill();
        kills += 1;

        let Some((journal, done)) = newest_run(&daemon) else {
            continue; // killed before the run began
        };
        let (header, entries, _) = Journal::read(&journal).unwrap();
        let mut indices: Vec<usize> = entries.iter().map(|m| m.index).collect();
        indices.sort();
        indices.dedup();
        assert_eq!(
            indices.len(),
            entries.len(),
            "kill {kills}: a reading was taken twice"
        );
        if let Some((path, before)) = &kept
            && *path == journal
        {
            assert!(
                entries.len() >= before.len(),
                "kill {kills}: readings were lost"
            );
            assert_eq!(
                &entries[..before.len()],
                &before[..],
                "kill {kills}: readings changed"
            );
        }
        let now_current = current_id(&daemon.state);
        let run_id = header.run_id.clone();
        if done {
            assert_each_planned_patch_once(&header, &entries);
            completed_runs += 1;
            current = now_current;
            kept = None;
        } else {
            // Killed between publishing and marking the run done, the current profile
            // may be this run's own (it passed); never anything else.
            assert!(
                now_current == current
                    || (now_current == run_id && entries.len() >= header.plan.patches.len()),
                "kill {kills}: the current profile is {now_current}, not {current} or a finished {run_id}"
            );
            kept = Some((journal, entries));
        }
    }
    // Let the last run finish, and check every run.
    let daemon = start_daemon(dir.path(), CONFIG);
    wait_idle(&daemon.endpoint(), Duration::from_secs(60)).await;
    for journal in daemon_runs(&daemon.state) {
        let (header, entries, recovery) = Journal::read(&journal).unwrap();
        assert!(recovery.dropped_tail.is_none());
        assert_each_planned_patch_once(&header, &entries);
    }
    eprintln!(
        "{kills} kills (seed {seed}), {completed_runs} runs completed between kills, {} runs in all",
        daemon_runs(&daemon.state).len()
    );
    assert!(kills >= 20.min(wanted));
}
