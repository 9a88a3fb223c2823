//! `chromacal instruments`: list serial ports and identify the instruments on them, and
//! the instruments ArgyllCMS sees.

use super::shared::outln;
use chromacal_instruments::argyll::driver::list_ports;
use chromacal_instruments::argyll::transport::spotread_program;
use chromacal_instruments::scan::{PortFinding, scan};
use chromacal_instruments::serial::candidate_ports;

use super::shared::Failure;

/// Seconds ArgyllCMS's port scan may take in the listing.
const ARGYLL_SCAN_S: u64 = 15;

/// List serial ports and identify the instruments on them.
#[derive(clap::Args)]
pub struct InstrumentsArgs {
    /// Also probe this port (pseudo-terminals are not listed by the system).
    #[arg(long)]
    port: Vec<String>,
    /// Print the ports and what answered on them as JSON.
    #[arg(long)]
    json: bool,
    /// Do not ask ArgyllCMS which instruments it sees.
    #[arg(long)]
    no_argyll: bool,
}

pub fn run(args: InstrumentsArgs) -> Result<(), Failure> {
    instruments(&args.port, args.json, !args.no_argyll)
}

fn instruments(extra: &[String], json: bool, argyll: bool) -> Result<(), Failure> {
    let ports = candidate_ports(extra);
    let findings = scan(&ports);
    // ArgyllCMS is optional: without it the list says so and carries on.
    // After the serial scan, not beside it: both would probe the same ports. Bounded,
    // so that a port Argyll's scan hangs on costs seconds, not a minute.
    let argyll_ports = argyll.then(|| {
        list_ports(
            &spotread_program(),
            std::time::Duration::from_secs(ARGYLL_SCAN_S),
            extra,
        )
        .map_err(|e| format!("{e} (--no-argyll skips it)"))
    });
    if json {
        let mut rows: Vec<serde_json::Value> = findings
            .iter()
            .map(|(port, f)| match f {
                PortFinding::Found { kind, identity } => serde_json::json!({"port": port, "instrument": kind.name(), "identity": identity}),
                PortFinding::Silent => serde_json::json!({"port": port, "instrument": null}),
                PortFinding::Unopenable(why) => serde_json::json!({"port": port, "error": why}),
            })
            .collect();
        match &argyll_ports {
            Some(Ok(ports)) => rows.extend(ports.iter().map(|p| {
                serde_json::json!({"port": p.path, "instrument": format!("argyll:{}", p.number), "identity": p.instrument})
            })),
            Some(Err(why)) => rows.push(serde_json::json!({"instrument": "argyll", "error": why})),
            None => {}
        }
        outln!("{}", serde_json::to_string_pretty(&rows)?)?;
        return Ok(());
    }
    if findings.is_empty() {
        outln!("no serial ports found (pseudo-terminals must be named with --port)")?;
    }
    for (port, finding) in findings {
        match finding {
            PortFinding::Found { kind, identity } => {
                outln!("{port}: {identity}  (--instrument {kind}:{port})")?
            }
            PortFinding::Silent => outln!("{port}: no known instrument answered")?,
            PortFinding::Unopenable(why) => outln!("{port}: cannot open: {why}")?,
        }
    }
    match argyll_ports {
        Some(Ok(ports)) if ports.is_empty() => outln!("ArgyllCMS sees no instrument")?,
        Some(Ok(ports)) => {
            for p in ports {
                outln!(
                    "{}: {}  (--instrument argyll:{}, through ArgyllCMS)",
                    p.path,
                    p.instrument.as_deref().unwrap_or("not identified"),
                    p.number
                )?;
            }
        }
        Some(Err(why)) => outln!("ArgyllCMS: {why}")?,
        None => {}
    }
    Ok(())
}
