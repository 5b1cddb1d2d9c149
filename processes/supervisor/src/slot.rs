//! One `[[process]]` of a run and what became of it: started, restarted per its policy
//! after its backoff, or done; how a child is spawned with its context, its token or the
//! run's key; and the instance's live nodes.

use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Instant;

use agp_launch::{ExitDecision, LaunchConfig, ProcessConfig};
use agp_runtime::children::spawn_guarded;
use agp_runtime::control_client::is_client_node;
use agp_runtime::{AgpIpc, Instance};
use iceoryx2::node::{NodeState, NodeView};
use iceoryx2::prelude::{CallbackProgression, Node};

use crate::console::Log;
use crate::run_end::RunEnd;
use crate::signals;

pub(crate) enum SlotState {
    Running(Child),
    /// Waiting for its backoff before restart number `nth`.
    Pending {
        at: Instant,
        nth: u32,
    },
    Done,
}

/// One `[[process]]` of the launch file and what became of it.
pub(crate) struct Slot<'a> {
    pub(crate) process: &'a ProcessConfig,
    pub(crate) state: SlotState,
    pub(crate) restarts: u32,
    /// When it was last started.
    pub(crate) started: Option<Instant>,
    /// The planner epoch it runs at (`AGP_EPOCH`): 0 unless swapped in.
    pub(crate) epoch: u64,
    /// Executable and arguments a hot swap put in place of the launch file's.
    pub(crate) exec_override: Option<(PathBuf, Vec<String>)>,
}

impl Slot<'_> {
    /// The executable and arguments it runs with.
    pub(crate) fn command(&self) -> (PathBuf, Vec<String>) {
        match &self.exec_override {
            Some((exec, args)) => (exec.clone(), args.clone()),
            None => (self.process.exec.clone(), self.process.args.clone()),
        }
    }
}

impl Slot<'_> {
    /// Spawns the process; `nth` is the restart number, if this is a restart.
    pub(crate) fn start(
        &mut self,
        config: &LaunchConfig,
        log: &Log,
        nth: Option<u32>,
        epoch: u64,
    ) -> Result<(), RunEnd> {
        let (exec, args) = self.command();
        match spawn_process(config, self.process, &exec, &args, epoch) {
            Ok(child) => {
                let pid = child.id();
                match nth {
                    None => log.event(&self.process.name, format_args!("started, pid {pid}")),
                    Some(n) => log.event(
                        &self.process.name,
                        format_args!(
                            "restarted ({n} of {}), pid {pid}",
                            self.process.restart.max_restarts
                        ),
                    ),
                }
                self.state = SlotState::Running(child);
                self.started = Some(Instant::now());
                self.epoch = epoch;
                Ok(())
            }
            Err(e) => {
                self.state = SlotState::Done;
                Err(RunEnd::Failed {
                    process: self.process.name.clone(),
                    why: format!("could not be started from {}: {e}", exec.display()),
                })
            }
        }
    }

    /// Reaps an exit, or starts a pending restart whose time came.
    pub(crate) fn poll(
        &mut self,
        config: &LaunchConfig,
        node: &Node<AgpIpc>,
        log: &Log,
        now: Instant,
        active_epoch: u64,
    ) -> Option<RunEnd> {
        let process = self.process;
        let name = &process.name;
        match &mut self.state {
            SlotState::Running(child) => {
                let status = match child.try_wait() {
                    Ok(None) => return None,
                    Ok(Some(status)) => status,
                    Err(e) => {
                        return Some(RunEnd::Failed {
                            process: name.clone(),
                            why: format!("could not be watched: {e}"),
                        });
                    }
                };
                self.state = SlotState::Done;
                log.event(name, format_args!("{}", describe(status)));
                // Its ports die with it: free their slots before anyone restarts.
                node.try_cleanup_dead_nodes();
                if process.ends_run && status.success() {
                    return Some(RunEnd::Finished {
                        process: name.clone(),
                    });
                }
                match process.restart.decide(status.success(), self.restarts) {
                    ExitDecision::Done => None,
                    ExitDecision::Restart { nth, delay } => {
                        self.state = SlotState::Pending {
                            at: now + delay,
                            nth,
                        };
                        None
                    }
                    ExitDecision::FailRun => {
                        let r = &process.restart;
                        let why = if self.restarts > 0 {
                            format!(
                                "{} after {} restart(s) (policy `{}`, max_restarts {})",
                                describe(status),
                                self.restarts,
                                r.policy.as_str(),
                                r.max_restarts
                            )
                        } else {
                            format!("{} (policy `{}`)", describe(status), r.policy.as_str())
                        };
                        Some(RunEnd::Failed {
                            process: name.clone(),
                            why,
                        })
                    }
                }
            }
            SlotState::Pending { at, nth } if now >= *at => {
                let nth = *nth;
                self.restarts = nth;
                // A restart drives at once: it gets the active epoch (if it is the planner
                // that drives, the one it had).
                self.start(config, log, Some(nth), active_epoch.max(self.epoch))
                    .err()
            }
            SlotState::Pending { .. } | SlotState::Done => None,
        }
    }
}

/// Starts one process with its context in the environment, in a process group of its own
/// (a Ctrl-C at the terminal reaches only the supervisor, which then stops it), killed by
/// the kernel if the supervisor dies.
pub(crate) fn spawn_process(
    config: &LaunchConfig,
    process: &ProcessConfig,
    exec: &std::path::Path,
    args: &[String],
    epoch: u64,
) -> std::io::Result<Child> {
    let mut cmd = Command::new(exec);
    cmd.args(args)
        .envs(&process.env)
        .envs(config.context_env(process))
        .env("AGP_EPOCH", epoch.to_string())
        .stdin(Stdio::null());
    // The run's secret goes to physics alone, and to the planner side of a bridge, which
    // forwards only commands that carry this run's tokens; every other child gets its
    // epoch's token, so physics applies commands of the processes this supervisor started
    // only.
    let key = run_session_key()?;
    let planner_side_bridge = agp_launch::bridge_side(exec, args) == Some("planner");
    if exec.file_name().is_some_and(|n| n == "agp-physics") || planner_side_bridge {
        cmd.env(agp_shared_types::SESSION_KEY_ENV, key.to_hex())
            .env_remove(agp_shared_types::SESSION_TOKEN_ENV);
    } else {
        cmd.env(
            agp_shared_types::SESSION_TOKEN_ENV,
            key.token(epoch).to_string(),
        )
        .env_remove(agp_shared_types::SESSION_KEY_ENV);
    }
    spawn_guarded(&mut cmd)
}

/// The secret of this run of the supervisor, made at its first child.
fn run_session_key() -> std::io::Result<agp_shared_types::SessionKey> {
    static KEY: std::sync::OnceLock<agp_shared_types::SessionKey> = std::sync::OnceLock::new();
    if let Some(k) = KEY.get() {
        return Ok(*k);
    }
    let key = agp_shared_types::SessionKey::random()?;
    Ok(*KEY.get_or_init(|| key))
}

/// How a process ended, for status lines.
pub(crate) fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exited with status {code}"),
        (None, Some(sig)) => format!("was killed by {}", signals::name(sig)),
        (None, None) => format!("ended ({status})"),
    }
}

/// The live iceoryx2 nodes of `instance`, as `name (pid N)`.
pub(crate) fn alive_nodes(instance: &Instance, with_clients: bool) -> Vec<String> {
    let mut alive = Vec::new();
    let listed = Node::<AgpIpc>::list(instance.config(), |state| {
        if let NodeState::Alive(view) = state {
            match view.details() {
                // A client of the dead supervisor (`agp status` polling it) holds nothing
                // the run needs, and gives up its request once it sees the supervisor gone.
                Some(d)
                    if !with_clients
                        && is_client_node(
                            d.name().as_str(),
                            u32::try_from(d.process_id().value()).unwrap_or(0),
                        ) => {}
                Some(d) => alive.push(format!("node `{}` (pid {})", d.name(), d.process_id())),
                None => alive.push("a node".to_owned()),
            }
        }
        CallbackProgression::Continue
    });
    // A half-removed leftover can fail to list; then nothing in it is alive to protect.
    if listed.is_err() {
        alive.clear();
    }
    alive
}
