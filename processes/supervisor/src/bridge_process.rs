//! `agp bridge ARGS`: runs the bridge binary `agp-bridge` beside `agp` with ARGS, in this
//! process (exec: the same pid, so a supervisor that started `agp bridge` watches and
//! signals the bridge itself). The bridge is a binary of its own so that `agp` links no
//! Zenoh (processes/bridge). `agp profile` finds a running bridge here and measures its
//! link's floor with `agp-bridge floor --json`.

use std::ffi::OsString;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use agp_runtime::WaitStrategy;
use anyhow::{Context, Result, anyhow, bail};

/// `agp bridge`: every argument goes to `agp-bridge` (`agp bridge --help` shows its own).
#[derive(Debug, clap::Args)]
#[command(disable_help_flag = true, disable_version_flag = true)]
pub(crate) struct BridgeArgs {
    /// The bridge's arguments (`agp bridge --help` lists them).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, num_args = 0..)]
    args: Vec<OsString>,
}

/// `agp-bridge` beside this `agp`, or why it cannot run.
fn bridge_exe() -> Result<PathBuf> {
    let agp = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let exe = agp_supervisor::bridge_binary(&agp);
    if !exe.is_file() {
        bail!("{}", agp_supervisor::build_the_bridge_hint(&agp));
    }
    Ok(exe)
}

/// `agp bridge ARGS`: becomes `agp-bridge ARGS`; returns only if that cannot start.
pub(crate) fn run(args: &BridgeArgs) -> Result<u8> {
    let exe = bridge_exe()?;
    let e = Command::new(&exe).args(&args.args).exec();
    Err(anyhow!("cannot run {}: {e}", exe.display()))
}

/// A running bridge, as its command line and environment show it.
pub(crate) struct RunningBridge {
    /// The key folder of its link (`None`: plain TCP).
    pub tls: Option<PathBuf>,
    /// How its threads wait (`--wait`, else `AGP_BRIDGE_WAIT`, else `block`).
    pub wait: WaitStrategy,
}

/// The bridge of a running process `pid`, if it is one: `agp-bridge`, which `agp bridge`
/// becomes by exec before it does anything (an `agp bridge` that could not exec has exited
/// saying why).
pub(crate) fn bridge_of_process(pid: u32) -> Option<RunningBridge> {
    let words = |file: &str| -> Option<Vec<String>> {
        let bytes = std::fs::read(format!("/proc/{pid}/{file}")).ok()?;
        Some(
            bytes
                .split(|b| *b == 0)
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect(),
        )
    };
    let args = words("cmdline")?;
    let is_bridge = args
        .first()
        .is_some_and(|a| Path::new(a).file_name().is_some_and(|n| n == "agp-bridge"));
    if !is_bridge {
        return None;
    }
    let after = |flag: &str| args.windows(2).find(|w| w[0] == flag).map(|w| w[1].clone());
    let env_wait = || {
        words("environ")?.into_iter().find_map(|kv| {
            kv.strip_prefix(agp_bridge::BRIDGE_WAIT_ENV)
                .and_then(|v| v.strip_prefix('='))
                .map(str::to_owned)
        })
    };
    let wait = after("--wait")
        .or_else(env_wait)
        .and_then(|w| WaitStrategy::parse(&w))
        .unwrap_or(WaitStrategy::Block);
    Some(RunningBridge {
        tls: after("--tls").map(PathBuf::from),
        wait,
    })
}

/// The figures of a link's floor (`agp-bridge floor --json`): one-way latency, ns.
pub(crate) struct FloorFigures {
    /// Every timed one-way figure.
    pub one_way_ns: Vec<u64>,
}

/// A bare Zenoh ping-pong between two `agp-bridge` processes over the loopback, on the
/// transport of a bridge with the key folder `tls` (mutual TLS) or none (plain TCP), both
/// ends waiting as `wait` says, for `seconds` of timed round trips of `size` bytes
/// (`agp-bridge floor`): the locator and the figures.
pub(crate) fn zenoh_floor(
    tls: Option<&Path>,
    wait: WaitStrategy,
    seconds: f64,
    size: usize,
) -> Result<(String, FloorFigures)> {
    let exe = bridge_exe()?;
    let mut cmd = Command::new(&exe);
    cmd.args(["floor", "--json", "--seconds", &seconds.to_string()])
        .args(["--size", &size.to_string()])
        .env(agp_bridge::BRIDGE_WAIT_ENV, wait.name())
        .stdin(Stdio::null())
        .stderr(Stdio::piped());
    match tls {
        Some(dir) => cmd.arg("--tls").arg(dir),
        None => cmd.arg("--insecure"),
    };
    let out = cmd
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    if !out.status.success() {
        let why = String::from_utf8_lossy(&out.stderr);
        let line = why.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
        bail!("`agp-bridge floor` ended with {}: {line}", out.status);
    }
    let doc: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("`agp-bridge floor --json` printed no JSON")?;
    let locator = doc["locator"]
        .as_str()
        .ok_or_else(|| anyhow!("`agp-bridge floor --json`: no locator"))?
        .to_owned();
    let one_way_ns = doc["one_way_ns"]
        .as_array()
        .ok_or_else(|| anyhow!("`agp-bridge floor --json`: no one_way_ns"))?
        .iter()
        .filter_map(serde_json::Value::as_u64)
        .collect();
    Ok((locator, FloorFigures { one_way_ns }))
}
