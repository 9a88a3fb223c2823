//! `chromacal history`, `chromacal rollback` and `chromacal profile current`: a
//! running daemon's profiles.

use super::api::{ApiArgs, get, post, query_value, runtime};
use super::shared::{Failure, out, outln};

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
