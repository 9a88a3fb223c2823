//! `chromacal instruments`: list serial ports and identify the instruments on them.

use chromacal::instrument::scan::{PortFinding, candidate_ports, scan};

use super::shared::Failure;

/// List serial ports and identify the instruments on them.
#[derive(clap::Args)]
pub struct InstrumentsArgs {
    /// Also probe this port (pseudo-terminals are not listed by the system).
    #[arg(long)]
    port: Vec<String>,
    /// Print the ports and what answered on them as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: InstrumentsArgs) -> Result<(), Failure> {
    instruments(&args.port, args.json)
}

fn instruments(extra: &[String], json: bool) -> Result<(), Failure> {
    let ports = candidate_ports(extra);
    let findings = scan(&ports);
    if json {
        let rows: Vec<serde_json::Value> = findings
            .iter()
            .map(|(port, f)| match f {
                PortFinding::Found { kind, identity } => serde_json::json!({"port": port, "instrument": kind.name(), "identity": identity}),
                PortFinding::Silent => serde_json::json!({"port": port, "instrument": null}),
                PortFinding::Unopenable(why) => serde_json::json!({"port": port, "error": why}),
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    if findings.is_empty() {
        println!("no serial ports found (pseudo-terminals must be named with --port)");
    }
    for (port, finding) in findings {
        match finding {
            PortFinding::Found { kind, identity } => {
                println!("{port}: {identity}  (--instrument {kind}:{port})")
            }
            PortFinding::Silent => println!("{port}: no known instrument answered"),
            PortFinding::Unopenable(why) => println!("{port}: cannot open: {why}"),
        }
    }
    Ok(())
}
