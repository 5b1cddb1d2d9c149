//! `agp status`: each process of a running instance, its goals, as a table or JSON.

use agp_runtime::control_client;
use anyhow::{Context, Result};

use crate::control;

/// Show each process of a running instance: state, pid, restarts, uptime.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    target: control::InstanceArg,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: &StatusArgs) -> Result<u8> {
    let name = args.target.name()?;
    let r = control_client::ask(&name, agp_shared_types::ControlKind::Status)?;
    let report = control::StatusReport::new(&name, &r);
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report).context("cannot encode the status")?
        );
    } else {
        report.print();
    }
    Ok(0)
}
