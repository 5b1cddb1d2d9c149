//! `agp-bridge` (run as `agp bridge`): forwards chosen topics of a running instance to a
//! Zenoh session and back (agp-bridge's `run_bridge`), so the planner of one instance drives
//! the physics and estimator of another that shares no memory with it. A launch file's
//! `remote = { ... }` process runs it as a child of `agp up`, with the epoch and token of the
//! slot; `agp bridge ARGS` hands its arguments to this binary (exec, same pid).
//!
//! The link is Zenoh's TLS transport with mutual authentication (`--tls DIR`, a key folder
//! made by `agp bridge keygen DIR`), or plain TCP only when asked for with `--insecure`.
//!
//! A binary of its own so that `agp` links no Zenoh: the README's first command
//! (`cargo build --release`, the workspace's default members) builds no link, which took a
//! third of a cold build; `cargo build --release --workspace --bins` builds this too.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use agp_bridge::{BridgeConfig, BridgeEnd, Endpoint, Side, TlsKeys, parse_topics, run_bridge};
use agp_runtime::{Instance, WaitStrategy};
use agp_shared_types::{SessionKey, session_token_from_env};
use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;

/// Forward chosen topics of a running instance to a Zenoh session and back, so the planner
/// of one instance drives the physics and estimator of another that shares no memory with it
/// (another computer, or another instance on this one). One end listens, the other
/// connects; nothing is scouted. The link is mutual TLS with the keys of `agp bridge keygen
/// DIR`, or plain TCP with `--insecure`. A launch file's `remote = { ... }` process runs it
/// with the run.
///
/// Example: agp bridge keygen results/bridge-keys
///
/// Example: agp bridge --instance lab --side robot --listen tls/127.0.0.1:7447 --tls results/bridge-keys
///
/// Example: agp bridge --instance desk --side planner --connect tls/127.0.0.1:7447 --tls results/bridge-keys
#[derive(Debug, clap::Parser)]
#[command(name = "agp bridge", bin_name = "agp bridge", version)]
#[command(subcommand_negates_reqs = true)]
#[command(group(clap::ArgGroup::new("endpoint").required(true).args(["listen", "connect"])))]
#[command(group(clap::ArgGroup::new("security").required(true).args(["tls", "insecure"])))]
struct BridgeArgs {
    #[command(subcommand)]
    command: Option<BridgeCommand>,
    /// The instance whose topics are bridged (a supervisor must run it).
    #[arg(long, env = "AGP_INSTANCE", required = true)]
    instance: Option<String>,
    /// `robot`: this instance runs physics and the estimator (it sends frames, estimates,
    /// grids, learning reports and a live session's goal, and takes commands, resets, the
    /// planner's events, the task and the goals the planner ended); `planner`: this
    /// instance runs the planner (the other way round).
    #[arg(long, required = true)]
    side: Option<String>,
    /// Listen for the far end on this endpoint, e.g. `tls/127.0.0.1:7447` (with `--tls`)
    /// or `tcp/127.0.0.1:7447` (with `--insecure`).
    #[arg(long)]
    listen: Option<String>,
    /// Connect to the far end on this endpoint (retried until it answers).
    #[arg(long)]
    connect: Option<String>,
    /// The link's key folder (`agp bridge keygen DIR`): the link runs over TLS, and only a
    /// far end with a certificate of its CA joins it.
    #[arg(long, value_name = "DIR")]
    tls: Option<PathBuf>,
    /// Run the link over plain TCP: no authentication, no encryption; any host that reaches
    /// the port can join it and drive this instance.
    #[arg(long)]
    insecure: bool,
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
    /// Seconds the far end may be gone (a link cut, its bridge restarting) once it had
    /// joined, before this end gives up and exits 3 saying so; a far end that never joined
    /// is waited for as long as it takes.
    #[arg(long, env = "AGP_BRIDGE_FAR_TIMEOUT_S", default_value_t = agp_bridge::FAR_TIMEOUT.as_secs_f64(), value_parser = far_timeout_s)]
    far_timeout_s: f64,
    /// How the bridge's two threads wait for the next message (from this instance's topics,
    /// from the link): `block` (the default), `spin-then-block[:US]`, `yield` or `spin`, as
    /// `AGP_WAIT` names them; not `AGP_WAIT`'s own default. What wakes a bridge is the
    /// kernel (an iceoryx2 event's socket, Zenoh's receiving thread), and a bridge that
    /// polls takes the cores from the Zenoh threads and the pipeline it waits for (on 2
    /// loaded cores neither way was reliably faster: README, the bridge's profile).
    /// `agp profile` measures the link's floor waiting this way.
    #[arg(long, env = agp_bridge::BRIDGE_WAIT_ENV, default_value = "block", value_parser = bridge_wait)]
    wait: WaitStrategy,
}

/// `--wait`: a strategy as `AGP_WAIT` names it.
fn bridge_wait(s: &str) -> Result<WaitStrategy, String> {
    WaitStrategy::parse(s).ok_or_else(|| WaitStrategy::NOT_A_STRATEGY.to_owned())
}

/// Exit status of a bridge whose far end went away without a word.
const EXIT_FAR_GONE: u8 = 3;

/// `--far-timeout-s`: 0.1 s to a day.
fn far_timeout_s(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if (0.1..=86_400.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not between 0.1 and 86400 s"))
    }
}

/// `agp bridge`'s subcommands.
#[derive(Debug, clap::Subcommand)]
enum BridgeCommand {
    /// Make a key folder for a TLS link: a CA of its own, and a certificate and private key
    /// per side (robot, planner), valid for localhost, 127.0.0.1, ::1 and each `--host`.
    /// Private keys are written 0600, the folder 0700; nothing is overwritten. Copy the
    /// folder to both computers (or `ca.pem` and the side's two files), and give it to
    /// both ends (`--tls DIR`, or `tls = "DIR"` in the launch file's `remote`).
    ///
    /// Example: agp bridge keygen results/bridge-keys --host robot.lab --host 192.168.1.10
    Keygen {
        /// The folder to make (refused if it already holds keys).
        dir: PathBuf,
        /// Another name or address the far end connects by (repeatable).
        #[arg(long = "host", value_name = "NAME")]
        hosts: Vec<String>,
    },
    /// Measure the link's floor: a bare Zenoh ping-pong between this process and a copy of
    /// it over the loopback, on the transport a bridge uses (`--tls DIR`: mutual TLS;
    /// `--insecure`: plain TCP), with no iceoryx2 on either side. Prints the one-way
    /// latency (half a round trip) to set a bridged hop of `agp profile` against.
    ///
    /// Example: agp bridge floor --tls results/bridge-keys --seconds 3
    Floor {
        #[command(flatten)]
        security: Security,
        /// Seconds of timed round trips (after 200 untimed).
        #[arg(long, default_value_t = 3.0)]
        seconds: f64,
        /// Bytes per sample (a motor command is 64, a frame a few hundred).
        #[arg(long, default_value_t = 64)]
        size: usize,
        /// Print the figures as one JSON object instead (`agp profile` reads it): the
        /// locator, the round trips and every one-way figure in ns.
        #[arg(long)]
        json: bool,
    },
    /// The far end of `agp bridge floor` (run by it, not by hand).
    #[command(name = "floor-pong", hide = true)]
    FloorPong {
        #[arg(long)]
        listen: String,
        #[command(flatten)]
        security: Security,
    },
}

/// The link's security, as `--tls DIR` or `--insecure` give it.
#[derive(Debug, clap::Args)]
#[group(required = true, multiple = false)]
struct Security {
    /// The link's key folder (`agp bridge keygen DIR`).
    #[arg(long, value_name = "DIR")]
    tls: Option<PathBuf>,
    /// Plain TCP.
    #[arg(long)]
    insecure: bool,
}

impl Security {
    /// The keys of `side`, and the endpoint scheme that goes with them.
    fn keys(&self, side: Side) -> Result<(Option<TlsKeys>, &'static str)> {
        Ok(match &self.tls {
            Some(dir) => (Some(TlsKeys::load(dir, side)?), "tls"),
            None => (None, "tcp"),
        })
    }

    fn args(&self) -> Vec<String> {
        match &self.tls {
            Some(dir) => vec!["--tls".to_owned(), dir.display().to_string()],
            None => vec!["--insecure".to_owned()],
        }
    }
}

/// A bare Zenoh ping-pong between this process and a copy of it over the loopback, on the
/// transport a bridge with the key folder `tls` (mutual TLS) or none (plain TCP) uses, the
/// pong end answering in Zenoh's receive callback (as a bridge's receiving end republishes
/// there), the ping end waiting as `wait` says (a bridge's `AGP_BRIDGE_WAIT`), for `seconds` of timed round trips
/// of `size` bytes: the locator and the figures.
fn zenoh_floor(
    tls: Option<&Path>,
    wait: WaitStrategy,
    seconds: f64,
    size: usize,
) -> Result<(String, agp_bridge::FloorFigures)> {
    let security = Security {
        tls: tls.map(Path::to_owned),
        insecure: tls.is_none(),
    };
    let (keys, scheme) = security.keys(Side::Planner)?;
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .context("a free port on the loopback")?
        .port();
    let locator = format!("{scheme}/127.0.0.1:{port}");
    let exe = std::env::current_exe().context("the path of agp")?;
    let mut cmd = std::process::Command::new(exe);
    cmd.args(["floor-pong", "--listen", &locator])
        .args(security.args())
        .env(agp_bridge::BRIDGE_WAIT_ENV, wait.name())
        .stdin(std::process::Stdio::null());
    // It dies with this process, however it ends.
    let mut pong =
        agp_runtime::children::spawn_guarded(&mut cmd).context("start the floor's pong end")?;
    let figures = agp_bridge::floor_ping(
        &Endpoint::connect(&locator)?,
        keys.as_ref(),
        wait,
        seconds,
        size,
    );
    let _ = pong.kill();
    let _ = pong.wait();
    Ok((locator, figures?))
}

/// `agp bridge floor`.
fn floor(security: &Security, seconds: f64, size: usize, json: bool) -> Result<u8> {
    let (locator, f) = zenoh_floor(
        security.tls.as_deref(),
        bridge_wait_from_env()?,
        seconds,
        size,
    )?;
    if json {
        let doc = serde_json::json!({
            "locator": locator,
            "round_trips": f.round_trips,
            "one_way_ns": f.one_way_ns,
        });
        println!("{doc}");
        return Ok(0);
    }
    let us = |ns: u64| ns as f64 / 1e3;
    println!(
        "agp: Zenoh floor over {locator} ({}), {size} B samples, {} round trips: one way p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, max {:.1} us",
        if security.tls.is_some() {
            "mutual TLS"
        } else {
            "plain TCP"
        },
        f.round_trips,
        us(f.p50_ns),
        us(f.p90_ns),
        us(f.p99_ns),
        us(f.max_ns)
    );
    Ok(0)
}

/// How a bridge waits when neither `--wait` nor `AGP_BRIDGE_WAIT` says (`agp bridge floor`
/// and its far end wait so too).
fn bridge_wait_from_env() -> Result<WaitStrategy> {
    match std::env::var(agp_bridge::BRIDGE_WAIT_ENV) {
        Ok(v) => {
            bridge_wait(&v).map_err(|why| anyhow!("{}=`{v}`: {why}", agp_bridge::BRIDGE_WAIT_ENV))
        }
        Err(_) => Ok(WaitStrategy::Block),
    }
}

/// `agp bridge floor-pong`: the far end of `agp bridge floor`.
fn floor_pong(listen: &str, security: &Security) -> Result<u8> {
    agp_runtime::install_shutdown_handler();
    let (keys, _) = security.keys(Side::Robot)?;
    agp_bridge::floor_pong(
        &Endpoint::listen(listen)?,
        keys.as_ref(),
        agp_runtime::shutdown_requested,
    )?;
    Ok(0)
}

/// The warning a bridge on plain TCP starts with.
fn insecure_warning(locator: &str) -> String {
    format!(
        "agp: warning: the bridge runs on plain TCP (`{locator}`, insecure): no authentication, no encryption; any host that reaches it can join the link and drive this instance. Use TLS: `agp bridge keygen DIR`, then `--tls DIR` with a `tls/` endpoint"
    )
}

/// `agp bridge keygen DIR`.
fn keygen(dir: &Path, hosts: &[String]) -> Result<u8> {
    let written = agp_bridge::keygen(dir, hosts)?;
    println!(
        "agp: made the bridge's keys in {} (give both ends this folder: `--tls {}`, or `tls = \"DIR\"` in a launch file's `remote`, relative to that file):",
        dir.display(),
        dir.display()
    );
    for f in written {
        println!("  {}", f.display());
    }
    Ok(0)
}

fn run(args: &BridgeArgs) -> Result<u8> {
    match &args.command {
        Some(BridgeCommand::Keygen { dir, hosts }) => return keygen(dir, hosts),
        Some(BridgeCommand::Floor {
            security,
            seconds,
            size,
            json,
        }) => return floor(security, *seconds, *size, *json),
        Some(BridgeCommand::FloorPong { listen, security }) => {
            return floor_pong(listen, security);
        }
        None => {}
    }
    let (Some(instance_name), Some(side_name)) = (&args.instance, &args.side) else {
        bail!("give --instance and --side (or `agp bridge keygen DIR`)");
    };
    agp_runtime::install_shutdown_handler();
    let side = Side::parse(side_name)
        .ok_or_else(|| anyhow!("unknown side `{side_name}`; expected `robot` or `planner`"))?;
    let endpoint = match (&args.listen, &args.connect) {
        (Some(l), None) => Endpoint::listen(l)?,
        (None, Some(c)) => Endpoint::connect(c)?,
        _ => bail!("give one of --listen and --connect"),
    };
    let tls = match (&args.tls, args.insecure) {
        (Some(dir), false) => Some(TlsKeys::load(dir, side)?),
        (None, true) => None,
        _ => bail!("give one of --tls DIR and --insecure"),
    };
    if let Some(fault) = Endpoint::security_fault(endpoint.locator(), tls.is_some()) {
        bail!("{fault}");
    }
    if tls.is_none() {
        eprintln!("{}", insecure_warning(endpoint.locator()));
    }
    let topics = parse_topics(&args.topics)?;
    let instance = Instance::running(instance_name)?;
    let key = SessionKey::from_env().map_err(|e| anyhow!(e))?;
    let config = BridgeConfig {
        side,
        endpoint: endpoint.clone(),
        tls,
        topics,
        link: args.link.clone(),
        epoch: args.epoch,
        token: session_token_from_env(),
        key,
        node_name: format!("bridge-{}", side.name()),
        wait: args.wait,
        far_timeout: std::time::Duration::from_secs_f64(args.far_timeout_s),
        // `agp up` gives every child its clock; by hand, lockstep is the default clock.
        redeliver_command: std::env::var("AGP_CLOCK").as_deref().unwrap_or("lockstep")
            == "lockstep",
    };
    let names: Vec<&str> = config.topics.iter().map(|t| t.name).collect();
    let report = run_bridge(&instance, &config, || {
        println!(
            "agp: bridge of instance `{}` ({} side) {} {} ({}), link `{}`: {}",
            instance_name,
            side.name(),
            match endpoint {
                Endpoint::Listen(_) => "listening on",
                Endpoint::Connect(_) => "connecting to",
            },
            endpoint.locator(),
            if endpoint.is_tls() {
                "mutual TLS"
            } else {
                "plain TCP, insecure"
            },
            args.link,
            names.join(", ")
        );
    })
    .with_context(|| format!("bridge of instance `{}`", instance_name))?;
    let why = match report.end {
        BridgeEnd::FarEnded => "the far end stopped".to_owned(),
        BridgeEnd::Stopped => "stopped".to_owned(),
        BridgeEnd::InstanceDown => "the instance went down".to_owned(),
        BridgeEnd::FarGone(d) => format!(
            "the far end is gone: no peer on the link for {:.1} s, and it never said it stopped",
            d.as_secs_f64()
        ),
    };
    println!("agp: bridge of instance `{}` ended: {why}", instance_name);
    for (name, sent, received) in &report.topics {
        println!("  {name:<16} sent {sent:>9}  received {received:>9}");
    }
    if report.stale > 0 || report.refused > 0 {
        println!(
            "  commands and resets not forwarded: {} of an inactive epoch, {} without their token",
            report.stale, report.refused
        );
    }
    if report.far_lost > 0 {
        println!("  the far end was lost {} time(s)", report.far_lost);
    }
    if let BridgeEnd::FarGone(_) = report.end {
        eprintln!(
            "agp: error: bridge of instance `{instance_name}`: {why} (killed, or its computer or the link down)"
        );
        return Ok(EXIT_FAR_GONE);
    }
    Ok(0)
}

fn main() -> ExitCode {
    agp_runtime::quiet_iceoryx2();
    let args = BridgeArgs::parse();
    match run(&args) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("agp: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
