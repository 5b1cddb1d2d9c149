//! `agp swap`: hot-swap a process of a running instance once, or (`--watch`) each time its
//! executable is rebuilt.

use std::path::PathBuf;

use agp_runtime::{InstanceLock, control_client};
use anyhow::{Context, Result};

use crate::{console, control, signals};

/// Hot-swap a process of a running instance, make before break.
#[derive(Debug, clap::Args)]
pub struct SwapArgs {
    /// The process of the launch file to swap.
    process: String,
    /// The new executable (default: the one running now).
    #[arg(long, conflicts_with = "watch")]
    exec: Option<PathBuf>,
    /// Swap in this executable now and each time it changes on disk, until Ctrl-C.
    #[arg(long, value_name = "PATH")]
    watch: Option<PathBuf>,
    /// Seconds the new process may take to become ready, and then to drive.
    #[arg(long, default_value_t = 10.0)]
    timeout_s: f64,
    #[command(flatten)]
    target: control::InstanceArg,
    /// Print JSON.
    #[arg(long)]
    json: bool,
    /// The new process's arguments (default: the ones running now).
    #[arg(last = true)]
    args: Option<Vec<String>>,
}

pub fn run(args: &SwapArgs) -> Result<u8> {
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0 && args.timeout_s <= 3600.0) {
        anyhow::bail!(
            "--timeout-s must be between 0 and 3600 seconds, got {}",
            args.timeout_s
        );
    }
    let name = args.target.name()?;
    if let Some(path) = &args.watch {
        return watch(args, &name, path);
    }
    let swapped = swap_once(args, &name, args.exec.as_deref())?;
    swapped.print(args.json)?;
    Ok(0)
}

/// A swap that went through.
struct Swapped {
    instance: String,
    process: String,
    pid: Option<u32>,
    epoch: u64,
    handover_us: f64,
    exec: Option<String>,
}

impl Swapped {
    fn print(&self, json: bool) -> Result<()> {
        if json {
            let v = serde_json::json!({
                "instance": self.instance,
                "process": self.process,
                "pid": self.pid,
                "epoch": self.epoch,
                "handover_us": self.handover_us,
                "exec": self.exec,
            });
            console::say(format_args!(
                "{}",
                serde_json::to_string(&v).context("cannot encode JSON")?
            ));
        } else {
            console::say(format_args!(
                "agp: swapped `{}` of instance `{}`: pid {}, epoch {}, handover {:.1} us (ready -> first command applied)",
                self.process,
                self.instance,
                self.pid.map_or("-".to_owned(), |p| p.to_string()),
                self.epoch,
                self.handover_us
            ));
        }
        Ok(())
    }
}

/// Asks the supervisor of `name` for one swap and waits for its end.
fn swap_once(args: &SwapArgs, name: &str, exec: Option<&std::path::Path>) -> Result<Swapped> {
    use agp_shared_types::{ControlKind, ControlRequest, read_str, write_str};
    let mut request = ControlRequest::new(ControlKind::SwapPlanner);
    if args.process.len() > request.name.len() {
        anyhow::bail!("no process is named `{}`", args.process);
    }
    write_str(&mut request.name, &args.process);
    if let Some(exec) = exec {
        let exec = std::fs::canonicalize(exec)
            .with_context(|| format!("--exec {}: no such file", exec.display()))?;
        let text = exec.to_string_lossy();
        if text.len() > request.exec.len() {
            anyhow::bail!(
                "--exec {text}: the path is longer than {} bytes",
                request.exec.len()
            );
        }
        write_str(&mut request.exec, &text);
    }
    if let Some(a) = &args.args
        && !request.set_args(a)
    {
        anyhow::bail!(
            "the arguments do not fit in {} bytes",
            agp_shared_types::SWAP_ARGS_LEN
        );
    }
    let timeout = std::time::Duration::from_secs_f64(args.timeout_s);
    request.value_ns = u64::try_from(timeout.as_nanos()).unwrap_or(u64::MAX);
    // The answer comes when the swap ends: ready, then driving, each within the timeout.
    let r = control_client::ask_with(
        name,
        request,
        timeout * 2 + std::time::Duration::from_secs(5),
    )?;
    if r.ok == 0 {
        anyhow::bail!(
            "swap of `{}` refused: {}",
            args.process,
            read_str(&r.message)
        );
    }
    let report = control::StatusReport::new(name, &r);
    let entry = report.processes.iter().find(|p| p.name == args.process);
    Ok(Swapped {
        instance: name.to_owned(),
        process: args.process.clone(),
        pid: entry.and_then(|p| p.pid),
        epoch: r.active_epoch,
        handover_us: r.handover_ns as f64 * 1e-3,
        exec: entry.map(|p| p.exec.clone()),
    })
}

/// What identifies one build of a file: a new build changes at least one.
fn file_stamp(path: &std::path::Path) -> Option<(std::time::SystemTime, u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    let m = std::fs::metadata(path).ok()?;
    Some((m.modified().ok()?, m.len(), m.ino()))
}

/// `agp swap PROCESS --watch PATH`: swaps PATH in now and after every change, until a stop
/// signal or the end of the instance. Each swap is printed (one JSON object per line with
/// `--json`); a refused one is reported and the watch goes on with the old process driving.
fn watch(args: &SwapArgs, name: &str, path: &std::path::Path) -> Result<u8> {
    use std::time::Duration;
    /// How often the file is looked at, and how long it must stay unchanged before a swap
    /// (a linker writes the file in several steps).
    const LOOK: Duration = Duration::from_millis(100);
    const SETTLE: Duration = Duration::from_millis(300);
    signals::install().context("cannot install the signal handlers")?;
    let instance = crate::control::instance_named(name)?;
    if file_stamp(path).is_none() {
        anyhow::bail!("--watch {}: no such file", path.display());
    }
    console::warn(format_args!(
        "agp: watching {} for `{}` of instance `{name}`: each new build is swapped in (Ctrl-C to stop)",
        path.display(),
        args.process
    ));
    let mut swapped_stamp = None;
    let mut swaps = 0u32;
    let mut refused = 0u32;
    loop {
        if let Some(s) = signals::first() {
            console::warn(format_args!(
                "agp: watch stopped by {}: {swaps} swaps, {refused} refused",
                signals::name(s)
            ));
            return Ok(0);
        }
        if !InstanceLock::is_held(&instance) {
            console::warn(format_args!(
                "agp: instance `{name}` is down: watch ends ({swaps} swaps, {refused} refused)"
            ));
            return Ok(0);
        }
        let stamp = file_stamp(path);
        if stamp.is_some() && stamp != swapped_stamp {
            std::thread::sleep(SETTLE);
            if file_stamp(path) != stamp {
                continue;
            }
            swapped_stamp = stamp;
            match swap_once(args, name, Some(path)) {
                Ok(s) => {
                    swaps += 1;
                    s.print(args.json)?;
                }
                Err(e) => {
                    refused += 1;
                    if args.json {
                        console::say(format_args!(
                            "{}",
                            serde_json::json!({"instance": name, "process": args.process, "refused": format!("{e:#}")})
                        ));
                    } else {
                        console::say(format_args!(
                            "agp: {e:#}; the running `{}` drives on",
                            args.process
                        ));
                    }
                }
            }
        }
        std::thread::sleep(LOOK);
    }
}
