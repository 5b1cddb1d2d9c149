//! `agp up`: owns one instance for the length of a run: its lock, its iceoryx2 services, its
//! processes, and the removal of every file it leaves.

use std::io::Write;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use agp_runtime::control_client::is_client_node;
use agp_runtime::{AgpIpc, Instance, InstanceLock, Topic, WaitStrategy};
use agp_shared_types::{
    GradientGrid, GroundTruth, IrFrame, MotorCommand, ObjectEstimate, Reset, Task,
};
use agp_supervisor::{ExitDecision, LaunchConfig, ProcessConfig, RECORDER_PROCESS};
use anyhow::{Context, Result, anyhow};
use iceoryx2::node::{NodeState, NodeView};
use iceoryx2::prelude::{CallbackProgression, Node};

use agp_world::Scenario;

use crate::control_plane::ControlPlane;
use crate::signals;
use agp_harness::evaluation::{self, RunJudge};
use agp_runtime::children::{signal_group, spawn_guarded};

/// How often the supervisor looks at its children and its signal flags.
const POLL: Duration = Duration::from_millis(10);

/// The same while a hot swap is under way.
const SWAP_POLL: Duration = Duration::from_micros(200);

/// How long leftover nodes of a previous run may take to die (their supervisor just died
/// and the kernel is killing them) before `up` refuses to clean their files.
const LEFTOVER_DEATH_WAIT: Duration = Duration::from_secs(3);

/// The exit statuses of `agp up` (its `--help` lists them).
pub(crate) mod exit {
    /// The run ended as asked (its `ends_run` process finished, or `agp down`), and its
    /// task, if it had one, succeeded.
    pub(crate) const OK: u8 = 0;
    /// The run ended in error: a process failed past its restart policy or could not be
    /// started, every process exited with none marked `ends_run`, the verdict could not be
    /// judged or written, or files of the instance remain; or nothing could start (the
    /// instance is held, its leftovers cannot be removed).
    pub(crate) const ERROR: u8 = 1;
    /// The launch file or the environment is invalid: nothing was started.
    pub(crate) const INVALID: u8 = 2;
    /// The run ended by itself and the judge says the task failed (`NOT placed`, the
    /// path's end not reached).
    pub(crate) const TASK_FAILED: u8 = 3;
    /// Stopped by signal N (SIGINT, SIGTERM, ...): 128 + N, as a shell reports it.
    pub(crate) const SIGNAL_BASE: u8 = 128;
}

/// Why a run ended.
#[derive(Debug)]
pub(crate) enum RunEnd {
    /// A process marked `ends_run` exited with status 0.
    Finished { process: String },
    /// The supervisor got a stop signal.
    Signal(i32),
    /// A process failed past its restart policy, or could not be started.
    Failed { process: String, why: String },
    /// Nothing runs any more and nothing ended the run.
    AllExited,
    /// `agp down` asked for it.
    Down,
}

impl RunEnd {
    /// The exit status of `agp up` for a run that ended so: `errors` when something went
    /// wrong after the run (the verdict or the cleaning), `task_failed` when the judge said
    /// the task failed. A stop signal says how the run ended whatever the rest; an error
    /// outranks a verdict; a run stopped by `agp down` has no verdict to answer for.
    pub(crate) fn exit_code(&self, errors: bool, task_failed: bool) -> u8 {
        match self {
            Self::Signal(s) => {
                u8::try_from(i32::from(exit::SIGNAL_BASE) + s).unwrap_or(exit::ERROR)
            }
            Self::Failed { .. } | Self::AllExited => exit::ERROR,
            Self::Finished { .. } | Self::Down if errors => exit::ERROR,
            Self::Finished { .. } if task_failed => exit::TASK_FAILED,
            Self::Finished { .. } | Self::Down => exit::OK,
        }
    }
}

/// Writes one line to stdout. A stdout nobody reads any more (`agp up | head -1`) is no
/// reason to stop supervising: the write's error is dropped (the SIGPIPE it raised stops
/// the run cleanly, see [`signals::STOP_SIGNALS`]), never a panic.
pub(crate) fn say(line: std::fmt::Arguments<'_>) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// Writes one line to stderr; a closed stderr is ignored as [`say`] ignores a closed
/// stdout.
pub(crate) fn warn(line: std::fmt::Arguments<'_>) {
    let _ = writeln!(std::io::stderr().lock(), "{line}");
}

/// Prints one status line per event, stamped with the time since `up` started.
pub(crate) struct Log {
    pub(crate) start: Instant,
}

impl Log {
    pub(crate) fn event(&self, process: &str, what: std::fmt::Arguments<'_>) {
        say(format_args!(
            "[{:8.3} s] {process}: {what}",
            self.start.elapsed().as_secs_f64()
        ));
    }

    pub(crate) fn note(&self, what: std::fmt::Arguments<'_>) {
        say(format_args!(
            "[{:8.3} s] {what}",
            self.start.elapsed().as_secs_f64()
        ));
    }
}

/// The instance's services, created by the supervisor before any child so they outlive
/// every child (a restarted child finds them, and its dead predecessor's ports are cleaned).
struct Services {
    _ir_frames: Topic<IrFrame>,
    _ground_truth: Topic<GroundTruth>,
    _motor_commands: Topic<MotorCommand>,
    _resets: Topic<Reset>,
    _estimates: Topic<ObjectEstimate>,
    _grids: Topic<GradientGrid>,
    _task: Topic<Task>,
}

impl Services {
    fn open(instance: &Instance, node: &Node<AgpIpc>) -> Result<Self> {
        Ok(Self {
            _ir_frames: instance.ir_frames(node).context("ir_frames")?,
            _ground_truth: instance.ground_truth(node).context("ground_truth")?,
            _motor_commands: instance.motor_commands(node).context("motor_commands")?,
            _resets: instance.resets(node).context("resets")?,
            _estimates: instance.estimates(node).context("estimates")?,
            _grids: instance.grids(node).context("grids")?,
            _task: instance.task(node).context("task")?,
        })
    }
}

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

/// Runs `config` until it ends; returns the exit status of `agp up`. Errors are for what
/// happens before any child starts (lock, leftovers, services).
pub fn up(config: &LaunchConfig) -> Result<u8> {
    signals::install().context("cannot install the signal handlers")?;
    let scenario = Scenario::resolve(&config.scenario.env_value().to_string_lossy())
        .with_context(|| format!("cannot load the scenario {}", config.scenario))?;
    let log = Log {
        start: Instant::now(),
    };
    let instance = crate::control::instance_named(&config.instance)?;
    let mut lock = InstanceLock::acquire(&instance)?;

    clean_leftovers(&instance, &log)?;
    std::fs::create_dir_all(&config.results).with_context(|| {
        format!(
            "cannot create the results folder {}",
            config.results.display()
        )
    })?;
    say(format_args!(
        "agp: instance `{}`: {} process{}, scenario {}, {} at {} Hz, results in {}",
        config.instance,
        config.processes.len(),
        if config.processes.len() == 1 {
            ""
        } else {
            "es"
        },
        config.scenario,
        config.clock.mode.as_str(),
        config.clock.rate_hz,
        config.results.display()
    ));

    let node = instance
        .node("agp", false)
        .map_err(|e| anyhow!("cannot create the supervisor's iceoryx2 node: {e:?}"))?;
    let services = match Services::open(&instance, &node) {
        Ok(s) => s,
        Err(e) => {
            drop(node);
            let _ = instance.remove_files();
            return Err(e.context(format!(
                "cannot create the services of instance `{}`",
                config.instance
            )));
        }
    };

    let waiting = config.waiting(WaitStrategy::from_env_checked().ok().flatten());
    let mut control = match ControlPlane::open(
        &instance,
        &node,
        &log,
        &waiting,
        &scenario.task,
        config.robot_is_remote(),
    ) {
        Ok(c) => c,
        Err(e) => {
            drop(services);
            drop(node);
            let _ = instance.remove_files();
            return Err(e.context(format!(
                "cannot create the control service of instance `{}`",
                config.instance
            )));
        }
    };
    // It answers from now on: clients (`agp status`, `agp down`, ...) may make their nodes.
    if let Err(e) = lock.announce() {
        warn(format_args!(
            "agp: cannot write the pid into the lock of instance `{}` ({e}): `agp status` and `agp down` will say it is starting",
            config.instance
        ));
    }

    let mut slots: Vec<Slot<'_>> = config
        .processes
        .iter()
        .map(|process| Slot {
            process,
            state: SlotState::Done,
            restarts: 0,
            started: None,
            epoch: 0,
            exec_override: None,
        })
        .collect();
    // The judge reads ground truth and the task the planner publishes; it judges the
    // run once it is over (a run with no task, the scripted drive, gets no verdict).
    let judge = RunJudge::spawn(&instance, scenario.clone());
    let end = run(config, &mut slots, &node, &mut control, &judge, &log);
    control.shutdown(&slots, &log);
    let mut verdict = judge.finish();
    // A live session judged each goal as it ended: its record is the goals' JSON, not one
    // verdict of whatever was under way at the end.
    let session = control.goals.any();
    if session {
        verdict = Ok(None);
        match control.goals.write_json(&config.results, &config.instance) {
            Ok(path) => say(format_args!(
                "agp: goals of the session: {}",
                path.display()
            )),
            Err(e) => warn(format_args!("agp: error: {e:#}")),
        }
    }

    stop_all(&mut slots, &log);
    node.try_cleanup_dead_nodes();
    drop(control);
    drop(services);
    drop(node);
    let mut errors = false;
    if let Err(e) = instance.remove_files() {
        warn(format_args!(
            "agp: error: cannot remove the files of instance `{}`: {e}",
            config.instance
        ));
        errors = true;
    }
    let left = instance.files();
    if !left.is_empty() {
        warn(format_args!(
            "agp: error: {} file(s) of instance `{}` remain: {:?}",
            left.len(),
            config.instance,
            left
        ));
        errors = true;
    }
    drop(lock);

    let mut task_failed = false;
    match verdict {
        Ok(Some(v)) => {
            task_failed = !v.evaluation.success;
            match evaluation::report(&v, &scenario, &config.instance, &config.results) {
                Ok((json, plot)) => {
                    say(format_args!(
                        "agp: plot {}, JSON {}",
                        plot.display(),
                        json.display()
                    ));
                }
                Err(e) => {
                    warn(format_args!("agp: error: cannot write the result: {e:#}"));
                    errors = true;
                }
            }
            if v.gaps > 0 {
                warn(format_args!(
                    "agp: note: the judge missed {} ground-truth samples; the plotted path has gaps",
                    v.gaps
                ));
            }
        }
        Ok(None) => {}
        Err(e) => {
            warn(format_args!("agp: error: the judge failed: {e:#}"));
            errors = true;
        }
    }
    match &end {
        RunEnd::Finished { process } => {
            log.note(format_args!("run over: `{process}` finished it"));
        }
        RunEnd::Signal(s) => {
            log.note(format_args!("stopped by {}", signals::name(*s)));
        }
        RunEnd::Failed { process, why } => {
            warn(format_args!("agp: error: process `{process}` {why}"));
        }
        RunEnd::AllExited => {
            warn(format_args!(
                "agp: error: every process exited and none is marked `ends_run`"
            ));
        }
        RunEnd::Down => {
            log.note(format_args!("stopped by `agp down`"));
        }
    }
    let code = end.exit_code(errors, task_failed);
    if code == exit::TASK_FAILED {
        warn(format_args!(
            "agp: the task failed (exit status {})",
            exit::TASK_FAILED
        ));
    }
    Ok(code)
}

/// Removes what a previous run of this instance left, once no node of it is alive. The
/// caller holds the instance lock, so no supervisor owns these files. The instance's folders
/// are checked first (ours, not links, 0700): a root folder planted by another user is
/// refused, not listed or removed. Only this instance's files go: the prefix ends where the
/// name does, so instance `pc` never touches those of `pc_x`.
fn clean_leftovers(instance: &Instance, log: &Log) -> Result<()> {
    if instance.root_dir().symlink_metadata().is_ok() {
        instance.prepare_dirs()?;
    }
    let deadline = Instant::now() + LEFTOVER_DEATH_WAIT;
    loop {
        if alive_nodes(instance, true).is_empty() {
            break;
        }
        if Instant::now() >= deadline {
            // A client of the dead supervisor still waiting holds nothing the run needs.
            let alive = alive_nodes(instance, false);
            if alive.is_empty() {
                break;
            }
            anyhow::bail!(
                "instance `{}` has live processes not started by a supervisor ({}); stop them or pick another name with `--instance`",
                instance.name(),
                alive.join(", ")
            );
        }
        std::thread::sleep(POLL);
    }
    let removed = instance.remove_files().with_context(|| {
        format!(
            "cannot remove the leftovers of instance `{}`",
            instance.name()
        )
    })?;
    if removed > 0 {
        log.note(format_args!(
            "removed {removed} leftover file(s) of instance `{}` (its last supervisor died)",
            instance.name()
        ));
    }
    Ok(())
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

/// Starts the processes in order, then watches them until the run ends.
fn run(
    config: &LaunchConfig,
    slots: &mut [Slot<'_>],
    node: &Node<AgpIpc>,
    control: &mut ControlPlane,
    judge: &RunJudge,
    log: &Log,
) -> RunEnd {
    for slot in slots.iter_mut() {
        if let Some(s) = signals::first() {
            return RunEnd::Signal(s);
        }
        let recording = config
            .record
            .as_deref()
            .filter(|_| slot.process.name == RECORDER_PROCESS);
        let before = recording.and_then(file_stamp);
        if let Err(end) = slot.start(config, log, None, 0) {
            return end;
        }
        if let Some(path) = recording
            && let Some(end) = await_recorder(slot, path, before, log)
        {
            return end;
        }
    }
    loop {
        if let Some(s) = signals::first() {
            return RunEnd::Signal(s);
        }
        let now = Instant::now();
        for slot in slots.iter_mut() {
            if let Some(end) = slot.poll(config, node, log, now, control.active_epoch()) {
                return end;
            }
        }
        if slots.iter().all(|s| matches!(s.state, SlotState::Done)) {
            return RunEnd::AllExited;
        }
        if let Some(end) = control.serve(config, slots, judge, log) {
            return end;
        }
        control.poll(slots, log);
        // A swap's handover waits on this loop: look more often while one is under way.
        std::thread::sleep(if control.swapping() { SWAP_POLL } else { POLL });
    }
}

/// How long the processes after the recorder wait for it to be subscribed.
const RECORDER_READY: Duration = Duration::from_secs(10);

/// When `path` was last written, if it exists.
fn file_stamp(path: &Path) -> Option<std::time::SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// Waits until the recorder has created its file (it does once every subscriber is in
/// place), so the processes started after it publish nothing it misses. A recorder that
/// exits first is the watch loop's to report; one that takes longer than
/// [`RECORDER_READY`] is said, and the run goes on.
fn await_recorder(
    slot: &mut Slot<'_>,
    path: &Path,
    before: Option<std::time::SystemTime>,
    log: &Log,
) -> Option<RunEnd> {
    let start = Instant::now();
    loop {
        if let Some(s) = signals::first() {
            return Some(RunEnd::Signal(s));
        }
        if file_stamp(path).is_some_and(|now| Some(now) != before) {
            return None;
        }
        let SlotState::Running(child) = &mut slot.state else {
            return None;
        };
        if !matches!(child.try_wait(), Ok(None)) {
            return None;
        }
        if start.elapsed() > RECORDER_READY {
            log.event(
                RECORDER_PROCESS,
                format_args!(
                    "not subscribed after {RECORDER_READY:?}: the run starts without waiting for it"
                ),
            );
            return None;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

impl Slot<'_> {
    /// Spawns the process; `nth` is the restart number, if this is a restart.
    fn start(
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
    fn poll(
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
    let planner_side_bridge = exec.file_name().is_some_and(|n| n == "agp")
        && args
            .windows(2)
            .any(|w| w[0] == "--side" && w[1] == "planner");
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

/// SIGTERM to every running process, SIGKILL to those still alive after their grace period
/// (at once after a second stop signal), and every one reaped.
fn stop_all(slots: &mut [Slot<'_>], log: &Log) {
    struct Stopping {
        index: usize,
        deadline: Instant,
        killed: bool,
    }
    let signals_before = signals::count();
    let now = Instant::now();
    let mut stopping = Vec::new();
    for (index, slot) in slots.iter_mut().enumerate().rev() {
        match &slot.state {
            SlotState::Running(child) => {
                signal_group(child, libc::SIGTERM);
                stopping.push(Stopping {
                    index,
                    deadline: now + slot.process.stop_grace,
                    killed: false,
                });
            }
            SlotState::Pending { .. } => slot.state = SlotState::Done,
            SlotState::Done => {}
        }
    }
    if stopping.is_empty() {
        return;
    }
    log.note(format_args!(
        "stopping {} process{} (SIGTERM)",
        stopping.len(),
        if stopping.len() == 1 { "" } else { "es" }
    ));
    while !stopping.is_empty() {
        let now = Instant::now();
        let hurry = signals::count() > signals_before;
        stopping.retain_mut(|s| {
            let slot = &mut slots[s.index];
            let SlotState::Running(child) = &mut slot.state else {
                return false;
            };
            match child.try_wait() {
                Ok(Some(status)) => {
                    log.event(
                        &slot.process.name,
                        format_args!("stopped: {}", describe(status)),
                    );
                    slot.state = SlotState::Done;
                    return false;
                }
                Ok(None) => {}
                Err(e) => {
                    log.event(&slot.process.name, format_args!("cannot be watched: {e}"));
                    slot.state = SlotState::Done;
                    return false;
                }
            }
            if !s.killed && (hurry || now >= s.deadline) {
                signal_group(child, libc::SIGKILL);
                s.killed = true;
                if hurry {
                    log.event(
                        &slot.process.name,
                        format_args!("SIGKILL (second stop signal)"),
                    );
                } else {
                    log.event(
                        &slot.process.name,
                        format_args!(
                            "still running {:.1} s after SIGTERM: SIGKILL",
                            slot.process.stop_grace.as_secs_f64()
                        ),
                    );
                }
            }
            true
        });
        if !stopping.is_empty() {
            std::thread::sleep(POLL);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_finished_run_whose_task_failed_exits_non_zero_and_an_error_outranks_it() {
        let finished = RunEnd::Finished {
            process: "planner".to_owned(),
        };
        assert_eq!(finished.exit_code(false, false), exit::OK);
        assert_eq!(finished.exit_code(false, true), exit::TASK_FAILED);
        assert_eq!(finished.exit_code(true, true), exit::ERROR);
        assert_eq!(RunEnd::Down.exit_code(true, false), exit::ERROR);
        assert_eq!(RunEnd::Down.exit_code(false, true), exit::OK);
        let failed = RunEnd::Failed {
            process: "physics".to_owned(),
            why: "crashed".to_owned(),
        };
        assert_eq!(failed.exit_code(false, false), exit::ERROR);
        assert_eq!(RunEnd::AllExited.exit_code(false, false), exit::ERROR);
        assert_eq!(RunEnd::Signal(libc::SIGTERM).exit_code(true, true), 143);
        assert_eq!(RunEnd::Signal(libc::SIGPIPE).exit_code(false, false), 141);
        let codes = [exit::OK, exit::ERROR, exit::INVALID, exit::TASK_FAILED];
        assert!(codes.iter().all(|c| *c < exit::SIGNAL_BASE));
        let mut distinct = codes.to_vec();
        distinct.dedup();
        assert_eq!(distinct.len(), codes.len(), "distinct exit statuses");
    }
}
