//! The CLI's side of the control service: `agp status`, `agp down` and the wait of
//! `agp up --detach`; the requests themselves go through `agp_runtime::control_client`.

use std::path::Path;
use std::time::{Duration, Instant};

use agp_launch::{LaunchConfig, LaunchOptions};
use agp_runtime::{Instance, InstanceLock, control_client};
use agp_shared_types::{ControlKind, ControlResponse, ProcessState, read_str};
use anyhow::{Context, Result, anyhow, bail};
use serde::Serialize;

use crate::goals::GoalReport;

/// How long the children of a dead supervisor may take to die before `agp down` names
/// them and refuses to clean.
const DEAD_CHILDREN_WAIT: Duration = Duration::from_secs(3);

/// Which instance a client command addresses (`agp status`, `down`, `swap`, `goal`,
/// `profile`).
#[derive(Debug, clap::Args)]
pub struct InstanceArg {
    /// The instance (default: the one of LAUNCH).
    #[arg(long)]
    pub instance: Option<String>,
    /// The launch file that names the instance when `--instance` does not.
    #[arg(long, default_value = "launch.toml")]
    pub launch: std::path::PathBuf,
}

/// The instance named `name`, or one line saying why the name is refused.
pub fn instance_named(name: &str) -> Result<Instance> {
    Instance::new(name).map_err(|e| anyhow!("bad instance name `{name}`: {e}"))
}

impl InstanceArg {
    /// `--instance`, else the launch file's.
    pub fn name(&self) -> Result<String> {
        let launch = self.launch.as_path();
        if let Some(name) = self.instance.as_deref() {
            Instance::validate_name(name)
                .map_err(|e| anyhow!("bad instance name `{name}`: {e}"))?;
            return Ok(name.to_owned());
        }
        if !launch.is_file() {
            bail!(
                "no --instance given and no launch file {} to take it from",
                launch.display()
            );
        }
        let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
        let options = LaunchOptions {
            instance: None,
            exe_dir: exe.parent().map(Path::to_path_buf).unwrap_or_default(),
            remote_checks: Some(agp_supervisor::BRIDGE_CHECKS),
        };
        let config = LaunchConfig::load(launch, &options).map_err(|e| anyhow!("{e}"))?;
        Ok(config.instance)
    }
}

/// One process of `agp status --json`.
#[derive(Debug, Serialize)]
pub struct ProcessReport {
    pub name: String,
    pub state: &'static str,
    pub pid: Option<u32>,
    pub restarts: u32,
    pub uptime_s: f64,
    pub exec: String,
    /// The planner epoch it runs at (0 unless swapped in).
    pub epoch: u64,
    /// Messages per second it publishes on `rate_topic` (physics: IR frames; the
    /// driving planner: motor commands), over the last second.
    pub rate_per_s: Option<f64>,
    pub rate_topic: Option<String>,
}

/// A live node of the instance its supervisor did not start (`agp status --json`).
#[derive(Debug, Serialize)]
pub struct StrangerReport {
    /// The node's name (empty if it has none).
    pub node: String,
    /// The process the node declares (0: unknown).
    pub pid: u32,
}

/// `agp status --json`.
#[derive(Debug, Serialize)]
pub struct StatusReport {
    pub instance: String,
    pub supervisor_pid: u32,
    pub uptime_s: f64,
    /// The epoch of the planner that drives.
    pub active_epoch: u64,
    /// How the processes wait for messages (`AGP_WAIT`), or `mixed`.
    pub waiting: String,
    pub processes: Vec<ProcessReport>,
    /// Processes paused now by `agp profile`'s pause lease, and the seconds it has left.
    pub paused: u32,
    pub pause_left_s: f64,
    /// Live nodes of the instance that are neither the supervisor's, nor its processes',
    /// nor a client's: processes that joined the instance on their own.
    pub strangers: Vec<StrangerReport>,
    /// Goals queued to a live session so far (`agp goal`), and the latest of them, oldest
    /// first, each with the judge's verdict once done.
    pub goals_total: u32,
    pub goals: Vec<GoalReport>,
}

impl StatusReport {
    pub fn new(instance: &str, r: &ControlResponse) -> Self {
        let count = (r.process_count as usize).min(r.processes.len());
        Self {
            instance: instance.to_owned(),
            supervisor_pid: r.supervisor_pid,
            uptime_s: r.uptime_ms as f64 * 1e-3,
            active_epoch: r.active_epoch,
            waiting: read_str(&r.waiting),
            processes: r.processes[..count]
                .iter()
                .map(|p| ProcessReport {
                    name: read_str(&p.name),
                    state: ProcessState::from_u32(p.state).map_or("unknown", ProcessState::as_str),
                    pid: (p.pid != 0).then_some(p.pid),
                    restarts: p.restarts,
                    uptime_s: p.uptime_ms as f64 * 1e-3,
                    exec: read_str(&p.exec),
                    epoch: p.epoch,
                    rate_per_s: (p.rate_topic[0] != 0).then_some(p.rate_mhz as f64 * 1e-3),
                    rate_topic: (p.rate_topic[0] != 0).then(|| read_str(&p.rate_topic)),
                })
                .collect(),
            paused: r.paused,
            pause_left_s: r.pause_left_ms as f64 * 1e-3,
            strangers: r.strangers[..(r.stranger_count as usize).min(r.strangers.len())]
                .iter()
                .map(|s| StrangerReport {
                    node: read_str(&s.name),
                    pid: s.pid,
                })
                .collect(),
            goals_total: r.goals_total,
            goals: r.goals[..(r.goal_count as usize).min(r.goals.len())]
                .iter()
                .map(GoalReport::new)
                .collect(),
        }
    }

    /// Whether every process is running.
    pub fn all_running(&self) -> bool {
        self.processes.iter().all(|p| p.state == "running")
    }

    pub fn print(&self) {
        println!(
            "instance `{}`: supervisor pid {}, up {:.1} s, active planner epoch {}, waiting `{}`",
            self.instance, self.supervisor_pid, self.uptime_s, self.active_epoch, self.waiting
        );
        let width = self
            .processes
            .iter()
            .map(|p| p.name.len())
            .max()
            .unwrap_or(0)
            .max("process".len());
        println!(
            "  {:<width$}  {:<8}  {:>8}  {:>8}  {:>9}  {:>5}  {:>24}  exec",
            "process", "state", "pid", "restarts", "uptime", "epoch", "publishes"
        );
        for p in &self.processes {
            let rate = match (&p.rate_topic, p.rate_per_s) {
                (Some(topic), Some(r)) => format!("{r:.0}/s {topic}"),
                _ => "-".to_owned(),
            };
            println!(
                "  {:<width$}  {:<8}  {:>8}  {:>8}  {:>7.1} s  {:>5}  {:>24}  {}",
                p.name,
                p.state,
                p.pid.map_or("-".to_owned(), |pid| pid.to_string()),
                p.restarts,
                p.uptime_s,
                p.epoch,
                rate,
                p.exec
            );
        }
        if self.paused > 0 {
            println!(
                "  paused: {} process(es) by `agp profile` for {:.1} s more",
                self.paused, self.pause_left_s
            );
        }
        if self.goals_total > 0 {
            let shown = self.goals.len();
            println!(
                "  goals: {} queued so far{}",
                self.goals_total,
                if (shown as u32) < self.goals_total {
                    format!(", the latest {shown}:")
                } else {
                    ":".to_owned()
                }
            );
            for g in &self.goals {
                println!("    {}", g.line());
            }
        }
        for s in &self.strangers {
            println!(
                "  stranger: node `{}` of pid {} joined the instance; the supervisor did not start it",
                s.node,
                if s.pid == 0 {
                    "?".to_owned()
                } else {
                    s.pid.to_string()
                }
            );
        }
    }
}

/// What `agp down` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DownOutcome {
    /// The supervisor stopped its processes and removed the instance's files.
    Stopped,
    /// No supervisor held the instance (it died, `kill -9`), and nothing of it was alive:
    /// `removed` leftover files went.
    Cleaned { removed: usize },
}

/// `agp down`: asks the supervisor to stop, then waits until it has let go of the instance
/// (every process stopped, every file removed). With no supervisor but files left (its
/// supervisor died), removes them, unless a process of the instance still lives: then it
/// names them and refuses.
pub fn down(name: &str, timeout: Duration) -> Result<DownOutcome> {
    let instance = instance_named(name)?;
    if !InstanceLock::is_held(&instance) && !instance.files().is_empty() {
        return clean_dead(&instance);
    }
    let r = control_client::ask(name, ControlKind::Down)?;
    if r.ok == 0 {
        bail!("the supervisor of instance `{name}` refused to stop");
    }
    let deadline = Instant::now() + timeout;
    while InstanceLock::is_held(&instance) {
        if Instant::now() >= deadline {
            bail!(
                "the supervisor of instance `{name}` (pid {}) is still stopping after {timeout:?}",
                r.supervisor_pid
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(DownOutcome::Stopped)
}

/// Removes the files of an instance whose supervisor is gone, holding its lock meanwhile
/// so no `agp up` starts on them, once no node of the instance is alive.
fn clean_dead(instance: &Instance) -> Result<DownOutcome> {
    let name = instance.name();
    let lock = InstanceLock::acquire(instance)?;
    // Children of a supervisor killed a moment ago are still being killed by the kernel.
    let deadline = Instant::now() + DEAD_CHILDREN_WAIT;
    let mut alive = crate::slot::alive_nodes(instance, false);
    while !alive.is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
        alive = crate::slot::alive_nodes(instance, false);
    }
    if !alive.is_empty() {
        bail!(
            "instance `{name}` has no supervisor but live processes: {}; stop them first, then run `agp down` again",
            alive.join(", ")
        );
    }
    let removed = instance
        .remove_files()
        .with_context(|| format!("cannot remove the leftovers of instance `{name}`"))?;
    drop(lock);
    Ok(DownOutcome::Cleaned { removed })
}

/// `agp down --stale`: removes the instances of benchmarks that died without cleaning
/// (`bench-<pid>-*` of this user, pid gone: `agp bench`'s pipelines and `bench-faults`'
/// runs) and says how many.
pub fn down_stale() -> Result<u8> {
    let swept = agp_harness::stop::sweep_stale()?;
    match swept.line() {
        Some(line) => println!("agp: {line}"),
        None => println!("agp: no leftover instance of a dead benchmark"),
    }
    Ok(0)
}
