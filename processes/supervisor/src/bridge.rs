//! `agp bridge`: forwards chosen topics of a running instance to a Zenoh session and back
//! (agp-bridge's `run_bridge`), so the planner of one instance drives the physics and
//! estimator of another that shares no memory with it. A launch file's `remote = { ... }`
//! process runs it as a child of `agp up`, with the epoch and token of the slot.

use agp_bridge::{BridgeConfig, BridgeEnd, Endpoint, Side, parse_topics, run_bridge};
use agp_runtime::WaitStrategy;
use agp_shared_types::{SessionKey, session_token_from_env};
use anyhow::{Context, Result, anyhow, bail};

/// `agp bridge`.
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("endpoint").required(true).args(["listen", "connect"])))]
pub(crate) struct BridgeArgs {
    /// The instance whose topics are bridged (a supervisor must run it).
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    /// `robot`: this instance runs physics and the estimator (it sends frames, estimates,
    /// grids, learning reports and a live session's goal, and takes commands, resets, the
    /// planner's events, the task and the goals the planner ended); `planner`: this
    /// instance runs the planner (the other way round).
    #[arg(long)]
    side: String,
    /// Listen for the far end on this TCP endpoint, e.g. `tcp/127.0.0.1:7447`.
    #[arg(long)]
    listen: Option<String>,
    /// Connect to the far end on this TCP endpoint (retried until it answers).
    #[arg(long)]
    connect: Option<String>,
    /// The topics carried, comma-separated (both ends must name the same): grids,
    /// ir_frames, estimates, learn_reports, goal, learn_events, task, resets,
    /// motor_commands, goal_ends, or `all`.
    #[arg(long, default_value = "all")]
    topics: String,
    /// The Zenoh key prefix both ends share; two links on one Zenoh network keep apart
    /// by it.
    #[arg(long, default_value = "agp")]
    link: String,
    /// The epoch the robot side's forwarded commands carry (`agp up` sets it).
    #[arg(long, env = "AGP_EPOCH", default_value_t = 0)]
    epoch: u64,
}

pub(crate) fn run(args: &BridgeArgs) -> Result<u8> {
    agp_runtime::install_shutdown_handler();
    let side = Side::parse(&args.side).ok_or_else(|| {
        anyhow!(
            "unknown side `{}`; expected `robot` or `planner`",
            args.side
        )
    })?;
    let endpoint = match (&args.listen, &args.connect) {
        (Some(l), None) => Endpoint::listen(l)?,
        (None, Some(c)) => Endpoint::connect(c)?,
        _ => bail!("give one of --listen and --connect"),
    };
    let topics = parse_topics(&args.topics)?;
    let instance = crate::control::running_instance(&args.instance)?;
    let key = SessionKey::from_env().map_err(|e| anyhow!(e))?;
    let config = BridgeConfig {
        side,
        endpoint: endpoint.clone(),
        topics,
        link: args.link.clone(),
        epoch: args.epoch,
        token: session_token_from_env(),
        key,
        node_name: format!("bridge-{}", side.name()),
        wait: WaitStrategy::from_env(),
    };
    let names: Vec<&str> = config.topics.iter().map(|t| t.name).collect();
    let report = run_bridge(&instance, &config, || {
        println!(
            "agp: bridge of instance `{}` ({} side) {} {}, link `{}`: {}",
            args.instance,
            side.name(),
            match endpoint {
                Endpoint::Listen(_) => "listening on",
                Endpoint::Connect(_) => "connecting to",
            },
            endpoint.locator(),
            args.link,
            names.join(", ")
        );
    })
    .with_context(|| format!("bridge of instance `{}`", args.instance))?;
    let why = match report.end {
        BridgeEnd::FarEnded => "the far end stopped",
        BridgeEnd::Stopped => "stopped",
        BridgeEnd::InstanceDown => "the instance went down",
    };
    println!("agp: bridge of instance `{}` ended: {why}", args.instance);
    for (name, sent, received) in &report.topics {
        println!("  {name:<16} sent {sent:>9}  received {received:>9}");
    }
    if report.stale > 0 || report.refused > 0 {
        println!(
            "  commands and resets not forwarded: {} of an inactive epoch, {} without their token",
            report.stale, report.refused
        );
    }
    Ok(0)
}
