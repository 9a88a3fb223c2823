//! `chromacal history`, `chromacal rollback` and `chromacal profile current`: a
//! running daemon's profiles.

use super::api::{ApiArgs, get_if_running, post, query_value, runtime};
use super::shared::{Failure, out, outln};
use chromacal::profile::store::ProfileStore;

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

pub fn run(args: HistoryArgs) -> Result<(), Failure> {
    history(&args.api, args.json)
}

pub fn run_rollback(args: RollbackArgs) -> Result<(), Failure> {
    rollback(&args.api, args.to)
}

pub fn history(api: &ApiArgs, json: bool) -> Result<(), Failure> {
    let endpoint = api.endpoint()?;
    runtime()?.block_on(async {
        let value = match get_if_running(&endpoint, &api.route("/history")).await? {
            Some(reply) => reply.json()?,
            None => history_on_disk(api, &endpoint)?,
        };
        if json {
            outln!("{}", serde_json::to_string_pretty(&value)?)?;
            return Ok(());
        }
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
            // Records before HDR verifications had no metric: ΔE00.
            let metric = v["metric"]
                .as_str()
                .and_then(|m| m.parse::<chromacal::verify::Metric>().ok())
                .unwrap_or_default()
                .name();
            outln!(
                "  {} {}  mean {metric} {}  max {}{}",
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

/// The current profile as TOML or JSON, read from the state directory when no daemon
/// runs; other formats are `chromacal export`'s.
fn current_on_disk(
    api: &ApiArgs,
    endpoint: &chromacal::daemon::client::Endpoint,
    format: &str,
) -> Result<chromacal::daemon::client::Reply, Failure> {
    let no_daemon = format!("no daemon answers at {endpoint}");
    let root = api.store_on_disk().ok_or_else(|| no_daemon.clone())?;
    let path = ProfileStore::new(&root).current_path();
    let profile =
        chromacal::profile::Profile::read(&path).map_err(|e| format!("{no_daemon}, and {e}"))?;
    let body = match format {
        "toml" => toml::to_string(&profile).map_err(|e| e.to_string())?,
        "json" => serde_json::to_string_pretty(&profile)?,
        other => {
            return Err(format!(
                "{no_daemon}: for {other}, `chromacal export {} --format {other} -o FILE` writes it from the file",
                path.display()
            )
            .into());
        }
    };
    eprintln!("chromacal: {no_daemon}; read {}", path.display());
    Ok(chromacal::daemon::client::Reply {
        status: 200,
        body: body.into(),
        headers: Vec::new(),
    })
}

/// What `GET /history` answers, read from the state directory when no daemon
/// runs (its files are there: `history.json`, `verifications.jsonl`).
fn history_on_disk(
    api: &ApiArgs,
    endpoint: &chromacal::daemon::client::Endpoint,
) -> Result<serde_json::Value, Failure> {
    let no_daemon = || format!("no daemon answers at {endpoint}");
    let root = api.store_on_disk().ok_or_else(no_daemon)?;
    if !root.join("history.json").exists() {
        return Err(format!(
            "{}, and {} has no history.json",
            no_daemon(),
            root.display()
        )
        .into());
    }
    let store = ProfileStore::new(&root);
    let (history, verifications) = (
        store.history().map_err(|e| e.to_string())?,
        store.verifications().map_err(|e| e.to_string())?,
    );
    eprintln!("chromacal: {}; read from {}", no_daemon(), root.display());
    Ok(serde_json::json!({
        "current": history.current,
        "profiles": history.entries,
        "verifications": verifications,
    }))
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
        let reply = match get_if_running(&endpoint, &query).await? {
            Some(reply) => reply,
            None => current_on_disk(api, &endpoint, format)?,
        };
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
