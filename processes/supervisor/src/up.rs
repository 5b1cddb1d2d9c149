//! `agp up`: its arguments and the checks before anything starts, then the run, which owns
//! one instance for its length: its lock, its iceoryx2 services, its processes, and the
//! removal of every file it leaves. `--detach` is in `detach.rs`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use agp_launch::{LaunchConfig, LaunchOptions, RECORDER_PROCESS};
use agp_runtime::{AgpIpc, Instance, InstanceLock, Topic, WaitStrategy};
use agp_shared_types::{
    GradientGrid, GroundTruth, IrFrame, MotorCommand, ObjectEstimate, Reset, Task,
};
use anyhow::{Context, Result, anyhow};
use iceoryx2::prelude::Node;

use agp_world::Scenario;

use crate::console::{Log, say, warn};
use crate::control_plane::ControlPlane;
use crate::detach;
use crate::run_end::{RunEnd, exit};
use crate::signals;
use crate::slot::{Slot, SlotState, alive_nodes, describe};
use agp_harness::evaluation::{self, RunJudge};
use agp_runtime::children::signal_group;
use agp_supervisor::{BRIDGE_CHECKS, CheckProcesses};

/// Start the processes of a launch file under one instance (see `agp up --help`).
#[derive(Debug, clap::Args)]
pub struct UpArgs {
    /// The launch file.
    #[arg(default_value = "launch.toml")]
    pub launch: PathBuf,
    /// Run under this instance name instead of the file's.
    #[arg(long)]
    pub instance: Option<String>,
    /// Return once every process is past start-up (running for 2 s, none restarted),
    /// leaving the supervisor in the background (its output goes to
    /// `agp-up-<instance>.log` in the results folder); stop it with `agp down`. A process
    /// that fails at start-up stops the run, and its error line is printed (exit 1).
    #[arg(long)]
    pub detach: bool,
}

/// `agp up`: validates the launch file whole (nothing starts on a bad one, exit 2), refuses
/// an instance another supervisor holds (exit 2), then runs it here or in the background.
pub fn start(args: &UpArgs) -> Result<u8> {
    // Every child inherits it: a value that names no strategy is refused here, not guessed.
    if let Err(why) = agp_runtime::WaitStrategy::from_env_checked() {
        warn(format_args!("agp: error: {why}"));
        warn(format_args!("agp: nothing was started"));
        return Ok(exit::INVALID);
    }
    let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
    let options = LaunchOptions {
        instance: args.instance.clone(),
        exe_dir: exe.parent().map(PathBuf::from).unwrap_or_default(),
        remote_checks: Some(BRIDGE_CHECKS),
    };
    let config = match LaunchConfig::load(&args.launch, &options)
        .and_then(|c| c.check_processes().map(|()| c))
    {
        Ok(c) => c,
        Err(e) => {
            for line in e.to_string().lines() {
                warn(format_args!("agp: error: {line}"));
            }
            warn(format_args!("agp: nothing was started"));
            return Ok(exit::INVALID);
        }
    };
    // An instance another supervisor holds is refused before anything starts, exit 2.
    match InstanceLock::acquire(&crate::control::instance_named(&config.instance)?) {
        Ok(lock) => drop(lock),
        Err(e @ agp_runtime::InstanceLockError::Held { .. }) => {
            warn(format_args!("agp: error: {e}"));
            warn(format_args!("agp: nothing was started"));
            return Ok(exit::INVALID);
        }
        Err(e) => return Err(e.into()),
    }
    if args.detach && std::env::var_os(detach::DETACHED_ENV).is_none() {
        return detach::detach(&args.launch, args.instance.as_deref(), &config);
    }
    up(&config)
}

/// How often the supervisor looks at its children and its signal flags.
const POLL: Duration = Duration::from_millis(10);

/// The same while a hot swap is under way.
const SWAP_POLL: Duration = Duration::from_micros(200);

/// How long leftover nodes of a previous run may take to die (their supervisor just died
/// and the kernel is killing them) before `up` refuses to clean their files.
const LEFTOVER_DEATH_WAIT: Duration = Duration::from_secs(3);

/// Whether the judge gave a verdict at the end of a run.
enum VerdictGiven {
    Some,
    None,
    Failed,
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
    say_what_runs(config);

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
    let mut errors = !remove_instance_files(&instance);
    drop(lock);

    let (verdict_given, task_failed, verdict_errors) = report_verdict(verdict, &scenario, config);
    errors |= verdict_errors;
    errors |= report_end(&end, &log, config, &verdict_given, session);
    let code = end.exit_code(errors, task_failed);
    if code == exit::TASK_FAILED {
        warn(format_args!(
            "agp: the task failed (exit status {})",
            exit::TASK_FAILED
        ));
    }
    Ok(code)
}

/// The run's first line: what runs, on which clock, and where the results go.
fn say_what_runs(config: &LaunchConfig) {
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
}

/// Removes every file of `instance` at the end of its run; false (each failure said on
/// stderr) when that failed or files remain.
fn remove_instance_files(instance: &Instance) -> bool {
    let mut ok = true;
    if let Err(e) = instance.remove_files() {
        warn(format_args!(
            "agp: error: cannot remove the files of instance `{}`: {e}",
            instance.name()
        ));
        ok = false;
    }
    let left = instance.files();
    if !left.is_empty() {
        warn(format_args!(
            "agp: error: {} file(s) of instance `{}` remain: {:?}",
            left.len(),
            instance.name(),
            left
        ));
        ok = false;
    }
    ok
}

/// Writes the judge's verdict (JSON and plot) and says it; what it was, whether the task
/// failed, and whether writing or judging failed.
fn report_verdict(
    verdict: Result<Option<evaluation::RunVerdict>>,
    scenario: &Scenario,
    config: &LaunchConfig,
) -> (VerdictGiven, bool, bool) {
    let mut errors = false;
    let mut task_failed = false;
    let verdict_given = match &verdict {
        Ok(Some(_)) => VerdictGiven::Some,
        Ok(None) => VerdictGiven::None,
        Err(_) => VerdictGiven::Failed,
    };
    match verdict {
        Ok(Some(v)) => {
            task_failed = !v.evaluation.success;
            match evaluation::report(&v, scenario, &config.instance, &config.results) {
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
    (verdict_given, task_failed, errors)
}

/// Says how the run ended; true when that end is an error this side must answer for (the
/// far planner ended the run before a task was published).
fn report_end(
    end: &RunEnd,
    log: &Log,
    config: &LaunchConfig,
    verdict_given: &VerdictGiven,
    session: bool,
) -> bool {
    let mut errors = false;
    match end {
        RunEnd::Finished { process } => {
            log.note(format_args!("run over: `{process}` finished it"));
            // The far end's planner ended this side's run without a task to judge: it
            // failed there (its supervisor printed why), and this run did nothing it was
            // asked, which must not read as success.
            if matches!(verdict_given, VerdictGiven::None) && !session && config.planner_is_remote()
            {
                warn(format_args!(
                    "agp: error: the planner's side ended the run before it published a task: nothing was judged (its supervisor's output says why)"
                ));
                errors = true;
            }
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
    errors
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
