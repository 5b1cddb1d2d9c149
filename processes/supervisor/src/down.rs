//! `agp down`: stop a running instance and remove its files, or (`--stale`) the leftovers of
//! benchmarks that died.

use anyhow::Result;

use crate::control;

/// Stop a running instance: every process, then every file of it.
#[derive(Debug, clap::Args)]
pub struct DownArgs {
    #[command(flatten)]
    target: control::InstanceArg,
    /// Give up waiting for the stop after this many seconds.
    #[arg(long, default_value_t = 60)]
    timeout_s: u64,
    /// Instead, remove the leftovers of benchmarks that died without cleaning (`kill -9`):
    /// every instance `bench-<pid>-*` of this user whose pid no process runs any more (what
    /// every `agp bench` does when it starts), the fault campaign's (`bench-faults`) too.
    #[arg(long, conflicts_with = "instance")]
    stale: bool,
}

pub fn run(args: &DownArgs) -> Result<u8> {
    if args.stale {
        return control::down_stale();
    }
    let name = args.target.name()?;
    match control::down(&name, std::time::Duration::from_secs(args.timeout_s))? {
        control::DownOutcome::Stopped => println!("agp: instance `{name}` is down"),
        control::DownOutcome::Cleaned { removed } => println!(
            "agp: instance `{name}` had no supervisor (it died); removed {removed} leftover file(s): it is down"
        ),
    }
    Ok(0)
}
