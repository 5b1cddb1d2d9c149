//! One-way latency of a bare iceoryx2 hop between two processes, per waiting strategy.
//!
//! The binary re-executes itself as the pong process (`--role pong`, hidden), ping-pongs a
//! sequence number and a CLOCK_MONOTONIC stamp over two pub-sub services, and reports half
//! of each round trip. Each (payload, strategy) run gets a fresh child and services of its
//! own; the whole invocation uses the instance `hop-<pid>`, whose files are removed on
//! every way out.
//!
//! ```text
//! cargo run --release -p agp-harness --bin bench-hop -- --round-trips 20000 --json hop.json
//! ```

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use agp_harness::hop::{
    HOP_GRID_BYTES, HopError, HopGrid, HopPayload, HopPorts, HopSmall, Side, Strategy, Summary,
    WaitConfig, format_table, new_histogram, ping_loop, pong_loop, service_stem,
};
use agp_runtime::{Instance, install_shutdown_handler};
use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};
use iceoryx2::prelude::ipc;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Role {
    Ping,
    Pong,
}

/// One-way latency of a bare iceoryx2 hop between two processes (round trip / 2).
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Measured round trips per strategy.
    #[arg(long, default_value_t = 20_000, value_parser = clap::value_parser!(u64).range(1..))]
    round_trips: u64,

    /// Unmeasured round trips before them.
    #[arg(long, default_value_t = 2_000)]
    warmup: u64,

    /// Waiting strategies to run, one after another: spin, yield, waitset, spin-then-block,
    /// listener (Listener::timed_wait without a WaitSet).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "spin,yield,waitset,spin-then-block"
    )]
    strategy: Vec<Strategy>,

    /// Payload sizes in bytes: 16 (sequence number + stamp) and/or 65536 (a gradient grid).
    #[arg(long, value_delimiter = ',', default_value = "16", value_parser = parse_payload_bytes)]
    payload_bytes: Vec<usize>,

    /// How long spin-then-block spins before it blocks, microseconds.
    #[arg(long, default_value_t = 20)]
    spin_budget_us: u64,

    /// Deadline attached to the listener: longest single block, and how often the peer's
    /// liveness is checked, milliseconds.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    deadline_ms: u64,

    /// Give up when no sample arrives for this long, seconds.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    stall_timeout_s: u64,

    /// Also write the figures as a JSON array to this file.
    #[arg(long)]
    json: Option<PathBuf>,

    #[arg(long, value_enum, default_value = "ping", hide = true)]
    role: Role,

    /// Instance name of the run (pong role).
    #[arg(long, hide = true)]
    instance: Option<String>,

    /// Pid of the ping process (pong role).
    #[arg(long, hide = true)]
    parent_pid: Option<u32>,
}

fn parse_payload_bytes(s: &str) -> Result<usize, String> {
    let n: usize = s.parse().map_err(|e| format!("`{s}`: {e}"))?;
    if n == std::mem::size_of::<HopSmall>() || n == HOP_GRID_BYTES {
        Ok(n)
    } else {
        Err(format!(
            "{n} bytes: only {} and {HOP_GRID_BYTES} are supported",
            std::mem::size_of::<HopSmall>()
        ))
    }
}

impl Args {
    fn wait_config(&self, strategy: Strategy) -> WaitConfig {
        WaitConfig {
            strategy,
            spin_budget: Duration::from_micros(self.spin_budget_us),
            deadline: Duration::from_millis(self.deadline_ms),
            stall_timeout: Duration::from_secs(self.stall_timeout_s),
        }
    }
}

fn main() -> Result<()> {
    let args = Args::parse();
    install_shutdown_handler();
    match args.role {
        Role::Ping => ping_main(&args),
        Role::Pong => pong_main(&args),
    }
}

/// Removes the instance's files when dropped, so every way out (error, panic) cleans up.
/// Declared before anything that opens the instance, so it is dropped after all of it.
struct RemoveOnDrop<'a> {
    instance: &'a Instance,
    done: bool,
}

impl RemoveOnDrop<'_> {
    fn remove_now(&mut self) -> std::io::Result<usize> {
        self.done = true;
        self.instance.remove_files()
    }
}

impl Drop for RemoveOnDrop<'_> {
    fn drop(&mut self) {
        if !self.done
            && let Err(e) = self.instance.remove_files()
        {
            eprintln!(
                "bench-hop: cannot remove the files of instance {}: {e}",
                self.instance.name()
            );
        }
    }
}

fn ping_main(args: &Args) -> Result<()> {
    let name = format!("hop-{}", std::process::id());
    let instance = Instance::new(&name).with_context(|| format!("instance name `{name}`"))?;
    let mut cleanup = RemoveOnDrop {
        instance: &instance,
        done: false,
    };
    // Leftovers of an earlier run that had our pid.
    cleanup
        .remove_now()
        .with_context(|| format!("remove stale files of instance {name}"))?;
    cleanup.done = false;

    let result = run_all(&instance, args);

    // Every node and port of both processes is gone here: run_one drops its ports and
    // waits for (or kills) its child before returning.
    let removed = cleanup
        .remove_now()
        .with_context(|| format!("remove the files of instance {name}"))?;
    let left = instance.files();
    if left.is_empty() {
        eprintln!("bench-hop: instance {name}: removed {removed} entries, none left");
    } else {
        eprintln!("bench-hop: instance {name}: files left behind: {left:?}");
    }

    let rows = result?;
    print!("{}", format_table(&rows));
    if let Some(path) = &args.json {
        let json = serde_json::Value::Array(rows.iter().map(Summary::to_json).collect());
        let text = serde_json::to_string_pretty(&json).context("serialise the figures")?;
        std::fs::write(path, text + "\n").with_context(|| format!("write {}", path.display()))?;
        eprintln!("bench-hop: wrote {}", path.display());
    }
    Ok(())
}

fn run_all(instance: &Instance, args: &Args) -> Result<Vec<Summary>> {
    let mut rows = Vec::new();
    for &bytes in &args.payload_bytes {
        for &strategy in &args.strategy {
            let config = args.wait_config(strategy);
            eprintln!(
                "bench-hop: {strategy}, {bytes} B: {} + {} round trips",
                args.warmup, args.round_trips
            );
            let started = Instant::now();
            let summary = if bytes == HOP_GRID_BYTES {
                run_one::<HopGrid>(instance, args, &config)
            } else {
                run_one::<HopSmall>(instance, args, &config)
            }
            .with_context(|| format!("run {strategy} with {bytes} B payloads"))?;
            eprintln!(
                "bench-hop: {strategy}, {bytes} B: done in {:.2} s",
                started.elapsed().as_secs_f64()
            );
            rows.push(summary);
        }
    }
    Ok(rows)
}

/// One ping-pong run against a fresh child.
fn run_one<P: HopPayload>(
    instance: &Instance,
    args: &Args,
    config: &WaitConfig,
) -> Result<Summary> {
    let node = instance
        .node_of::<ipc::Service>("hop-ping", false)
        .map_err(|e| anyhow::anyhow!("{e:?}"))
        .context("create the ping node")?;
    let ports = HopPorts::<P>::open(&node, &service_stem::<P>(config.strategy), Side::Ping)
        .context("open the ping side's ports")?;
    let mut child = PongChild::spawn(instance, args, config, std::mem::size_of::<P>())?;
    let mut histogram = new_histogram();
    {
        let mut liveness = || child.check_alive();
        ping_loop(
            &ports,
            config,
            args.warmup,
            args.round_trips,
            &mut histogram,
            &mut liveness,
        )
        .context("ping-pong")?;
    }
    child.finish(Duration::from_secs(5))?;
    Ok(Summary::from_histogram(
        config,
        std::mem::size_of::<P>(),
        &histogram,
    ))
}

/// The pong process. Dropping it without [`PongChild::finish`] asks it to stop (SIGTERM),
/// then kills it after a grace period, and always reaps it.
struct PongChild {
    child: Child,
    reaped: bool,
}

impl PongChild {
    fn spawn(instance: &Instance, args: &Args, config: &WaitConfig, bytes: usize) -> Result<Self> {
        let exe = std::env::current_exe().context("find this executable")?;
        let child = Command::new(&exe)
            .arg("--role=pong")
            .arg(format!("--instance={}", instance.name()))
            .arg(format!("--strategy={}", config.strategy.name()))
            .arg(format!("--payload-bytes={bytes}"))
            .arg(format!("--spin-budget-us={}", args.spin_budget_us))
            .arg(format!("--deadline-ms={}", args.deadline_ms))
            .arg(format!("--stall-timeout-s={}", args.stall_timeout_s))
            .arg(format!("--parent-pid={}", std::process::id()))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .with_context(|| format!("start {} as the pong process", exe.display()))?;
        Ok(Self {
            child,
            reaped: false,
        })
    }

    fn check_alive(&mut self) -> Result<(), HopError> {
        match self.child.try_wait() {
            Ok(None) => Ok(()),
            Ok(Some(_)) | Err(_) => Err(HopError::PeerGone),
        }
    }

    /// Waits up to `grace` for the child to exit on its own; it must exit with success.
    fn finish(mut self, grace: Duration) -> Result<()> {
        let status = self.wait_for(grace).context("wait for the pong process")?;
        match status {
            Some(s) if s.success() => Ok(()),
            Some(s) => bail!("the pong process failed: {s}"),
            None => bail!("the pong process did not stop within {grace:?}"),
        }
    }

    fn wait_for(&mut self, grace: Duration) -> std::io::Result<Option<std::process::ExitStatus>> {
        let start = Instant::now();
        loop {
            if let Some(s) = self.child.try_wait()? {
                self.reaped = true;
                return Ok(Some(s));
            }
            if start.elapsed() >= grace {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

impl Drop for PongChild {
    fn drop(&mut self) {
        if self.reaped {
            return;
        }
        if let Ok(pid) = libc::pid_t::try_from(self.child.id())
            && matches!(self.child.try_wait(), Ok(None))
        {
            // SAFETY: plain kill(2) on our own, not yet reaped child.
            unsafe { libc::kill(pid, libc::SIGTERM) };
        }
        if !matches!(self.wait_for(Duration::from_secs(2)), Ok(Some(_))) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn pong_main(args: &Args) -> Result<()> {
    let parent_pid = args.parent_pid.context("--role pong needs --parent-pid")?;
    // Die with the parent. SIGTERM sets the shutdown flag, so the loop ends and the ports
    // are dropped; if the parent is gone, we also remove the instance's files below.
    // SAFETY: prctl(PR_SET_PDEATHSIG) only sets a property of this process.
    unsafe { libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) };
    let parent_alive = || std::os::unix::process::parent_id() == parent_pid;
    if !parent_alive() {
        bail!("the ping process {parent_pid} is gone before the pong process started");
    }
    let name = args
        .instance
        .as_deref()
        .context("--role pong needs --instance")?;
    let instance = Instance::new(name).with_context(|| format!("instance name `{name}`"))?;
    let (Some(&strategy), Some(&bytes)) = (args.strategy.first(), args.payload_bytes.first())
    else {
        bail!("--role pong needs one --strategy and one --payload-bytes");
    };
    let config = args.wait_config(strategy);
    let mut liveness = || {
        if parent_alive() {
            Ok(())
        } else {
            Err(HopError::PeerGone)
        }
    };
    let result = if bytes == HOP_GRID_BYTES {
        pong_run::<HopGrid, _>(&instance, &config, &mut liveness)
    } else {
        pong_run::<HopSmall, _>(&instance, &config, &mut liveness)
    };
    if !parent_alive() {
        // Nobody else will clean up; our ports are dropped by now.
        let removed = instance.remove_files();
        bail!(
            "the ping process {parent_pid} died; removed the files of instance {name}: {removed:?}"
        );
    }
    result
}

fn pong_run<P: HopPayload, F: FnMut() -> Result<(), HopError>>(
    instance: &Instance,
    config: &WaitConfig,
    liveness: &mut F,
) -> Result<()> {
    let node = instance
        .node_of::<ipc::Service>("hop-pong", false)
        .map_err(|e| anyhow::anyhow!("{e:?}"))
        .context("create the pong node")?;
    let ports = HopPorts::<P>::open(&node, &service_stem::<P>(config.strategy), Side::Pong)
        .context("open the pong side's ports")?;
    pong_loop(&ports, config, liveness).context("echo pings")?;
    Ok(())
}
