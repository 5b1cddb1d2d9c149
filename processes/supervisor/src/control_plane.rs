//! The supervisor's side of the control service: answers `agp status` and `agp down`, and
//! runs hot swaps make-before-break (pipeline.md, "Hot-swapping the planner"):
//!
//! 1. `agp swap NAME` arrives: the new process starts with the next epoch in `AGP_EPOCH`;
//! 2. it opens its ports, takes the latest state from history and sends `Ready`;
//! 3. the supervisor publishes the new active epoch (one sample; physics applies motor
//!    commands and resets of the active epoch only, so the two never both drive);
//! 4. the new process sends `Driving` once its first command was applied; only then is the
//!    old one stopped (SIGTERM, grace, SIGKILL) and the swap answered.
//!
//! A new process that exits or misses its deadline before step 4 is killed, the old epoch
//! is published again, and the old process, which never stopped, drives on.
//!
//! It also holds the pause lease of `agp profile` ([`PauseLease`]): the pipeline's
//! processes stay stopped until the lease's deadline, its release, the death of its holder
//! or the end of the run, whichever comes first, so a profiler killed with SIGKILL cannot
//! leave them stopped. And a status reply names the strangers: live nodes of the instance
//! that are not the supervisor's, its processes' (or their descendants') or a client's.

use std::path::PathBuf;
use std::process::Child;
use std::time::{Duration, Instant};

use agp_runtime::control_client::is_client_node;
use agp_runtime::{AgpIpc, ControlService, Instance, Topic};
use agp_shared_types::{
    ActiveEpoch, ControlKind, ControlRequest, ControlResponse, MAX_PAUSE_LEASE,
    MAX_STATUS_PROCESSES, MAX_STATUS_STRANGERS, ProcessState, read_str, write_str,
};
use anyhow::{Result, anyhow};
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::node::{NodeState, NodeView};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::{CallbackProgression, Node};

use agp_harness::evaluation::RunJudge;
use agp_launch::LaunchConfig;
use agp_supervisor::check_goal;
use agp_world::TaskSpec;

use crate::goals::GoalBook;

use crate::console::Log;
use crate::rates::MessageRates;
use crate::run_end::RunEnd;
use crate::slot::{Slot, SlotState, describe, spawn_process};
use agp_runtime::children::signal_group;

/// How long a swapped-in process may take to become ready, and then to drive, unless the
/// request says otherwise.
const DEFAULT_SWAP_TIMEOUT: Duration = Duration::from_secs(10);

type Request = ActiveRequest<AgpIpc, ControlRequest, (), ControlResponse, ()>;

enum SwapPhase {
    /// Started; waiting for its `Ready`.
    Starting,
    /// Its epoch is active; waiting for its `Driving`.
    Flipped,
}

/// A hot swap under way.
struct Swap {
    /// The `agp swap` request, answered when the swap ends.
    request: Request,
    slot: usize,
    child: Child,
    epoch: u64,
    exec: PathBuf,
    args: Vec<String>,
    phase: SwapPhase,
    deadline: Instant,
    timeout: Duration,
}

/// A swapped-out process on its way out.
struct Retiring {
    name: String,
    child: Child,
    kill_at: Instant,
    killed: bool,
}

/// A pause of the pipeline granted to one holder until a deadline.
#[derive(Debug)]
pub(crate) struct PauseLease {
    /// The holder's process id.
    pub(crate) holder: u32,
    pub(crate) deadline: Instant,
    /// The process groups (or lone processes, negative: groups) stopped for it.
    pub(crate) stopped: Vec<libc::pid_t>,
}

impl PauseLease {
    /// The deadline a request for `len` from `now` gets: at most [`MAX_PAUSE_LEASE`].
    pub(crate) fn deadline_for(now: Instant, len: Duration) -> Instant {
        now + len.min(MAX_PAUSE_LEASE)
    }

    /// Whether the lease is over at `now`: its deadline passed, or `holder_alive` says its
    /// holder died.
    pub(crate) fn is_over(&self, now: Instant, holder_alive: bool) -> bool {
        now >= self.deadline || !holder_alive
    }
}

/// Whether process `pid` exists (a zombie counts as gone only once reaped; a profiler's
/// parent reaps it at once).
fn process_alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill(2) with signal 0 only checks that the process exists.
    let rc = unsafe { libc::kill(pid, 0) };
    rc == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
}

/// Sends `signal` to every target of `targets` (negative: a process group).
fn signal_all(targets: &[libc::pid_t], signal: libc::c_int) {
    for &t in targets {
        // SAFETY: kill(2) of a process (group) this supervisor started.
        unsafe { libc::kill(t, signal) };
    }
}

/// The control service, the active epoch and the swaps of one run.
pub(crate) struct ControlPlane {
    server: Server<AgpIpc, ControlRequest, (), ControlResponse, ()>,
    _service: ControlService,
    epochs: Publisher<AgpIpc, ActiveEpoch, ()>,
    physics_inbox: Notifier<AgpIpc>,
    _epoch_topic: Topic<ActiveEpoch>,
    active_epoch: u64,
    next_epoch: u64,
    seq: u64,
    swap: Option<Swap>,
    retiring: Vec<Retiring>,
    /// How the instance's processes wait, for status replies.
    waiting: String,
    /// `None` when the streams could not be opened (then `agp status` shows no rates).
    rates: Option<MessageRates>,
    /// The pause `agp profile` holds, if any.
    pause: Option<PauseLease>,
    instance: Instance,
    /// The goals of a live session.
    pub(crate) goals: GoalBook,
}

fn err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot create the {what}: {e:?}")
}

impl ControlPlane {
    /// Creates the control service and publishes epoch 0 (the launch file's processes).
    /// `waiting` is how the instance's processes wait ([`LaunchConfig::waiting`]), which
    /// every status reply carries.
    pub(crate) fn open(
        instance: &Instance,
        node: &Node<AgpIpc>,
        log: &Log,
        waiting: &str,
        task: &TaskSpec,
        robot_is_remote: bool,
    ) -> Result<Self> {
        let service = instance.create_control(node)?;
        let goals = GoalBook::open(instance, node, task, robot_is_remote)?;
        let server = service
            .server_builder()
            .create()
            .map_err(err("control server"))?;
        let topic = instance.active_epoch(node)?;
        let epochs = topic
            .data
            .publisher_builder()
            .create()
            .map_err(err("active epoch publisher"))?;
        let physics_inbox = topic
            .event
            .notifier_builder()
            .create()
            .map_err(err("physics inbox notifier"))?;
        let mut plane = Self {
            server,
            _service: service,
            epochs,
            physics_inbox,
            _epoch_topic: topic,
            active_epoch: 0,
            next_epoch: 1,
            seq: 0,
            swap: None,
            retiring: Vec::new(),
            waiting: waiting.to_owned(),
            pause: None,
            instance: instance.clone(),
            goals,
            rates: match MessageRates::open(instance, node) {
                Ok(r) => Some(r),
                Err(e) => {
                    log.note(format_args!(
                        "`agp status` will show no message rates: {e:#}"
                    ));
                    None
                }
            },
        };
        plane.publish_epoch(0)?;
        Ok(plane)
    }

    /// Whether a hot swap is under way.
    pub(crate) fn swapping(&self) -> bool {
        self.swap.is_some()
    }

    /// The epoch whose commands physics applies.
    pub(crate) fn active_epoch(&self) -> u64 {
        self.active_epoch
    }

    fn publish_epoch(&mut self, epoch: u64) -> Result<()> {
        self.seq += 1;
        let sample = self
            .epochs
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan an active epoch sample: {e:?}"))?;
        sample
            .write_payload(ActiveEpoch {
                epoch,
                seq: self.seq,
            })
            .send()
            .map_err(|e| anyhow!("cannot publish the active epoch: {e:?}"))?;
        let _ = self.physics_inbox.notify();
        self.active_epoch = epoch;
        Ok(())
    }

    /// Answers every pending request; `Some` when one ends the run.
    pub(crate) fn serve(
        &mut self,
        config: &LaunchConfig,
        slots: &mut [Slot<'_>],
        judge: &RunJudge,
        log: &Log,
    ) -> Option<RunEnd> {
        let mut end = None;
        self.goals.update_connections();
        self.goals.take_relayed(judge, log);
        loop {
            let request = match self.server.receive() {
                Ok(Some(r)) => r,
                Ok(None) => return end,
                Err(e) => {
                    log.note(format_args!("control service: cannot receive: {e:?}"));
                    return end;
                }
            };
            let payload = *request.payload();
            match ControlKind::from_u32(payload.kind) {
                Some(ControlKind::Status) => {
                    self.answer(&request, slots, log, Ok(0));
                }
                Some(ControlKind::Down) => {
                    log.note(format_args!("`agp down` received"));
                    end = Some(RunEnd::Down);
                    self.answer(&request, slots, log, Ok(0));
                }
                Some(ControlKind::SwapPlanner) => {
                    if let Err(why) = self.start_swap(config, request, &payload, slots, log) {
                        // `start_swap` hands the request back only when it refused.
                        let (request, why) = *why;
                        self.answer(&request, slots, log, Err(why));
                    }
                }
                Some(ControlKind::Ready) => {
                    let result = self.on_ready(payload.epoch, log);
                    self.answer(&request, slots, log, result.map(|()| 0));
                }
                Some(ControlKind::Driving) => {
                    let result = self.on_driving(payload.epoch, payload.value_ns, slots, log);
                    self.answer(&request, slots, log, result.map(|()| 0));
                }
                Some(ControlKind::Pause) => {
                    let result = self.on_pause(payload.pid, payload.value_ns, slots, log);
                    self.answer(&request, slots, log, result.map(|()| 0));
                }
                Some(ControlKind::Resume) => {
                    let result = self.on_resume(payload.pid, log);
                    self.answer(&request, slots, log, result.map(|()| 0));
                }
                Some(ControlKind::Goal) => {
                    let result = check_goal(&payload.goal)
                        .and_then(|()| self.goals.queue(payload.goal, log));
                    self.answer(&request, slots, log, result);
                }
                Some(ControlKind::GoalDone) => {
                    let end = read_str(&payload.name);
                    let sim_time_s = payload.value_ns as f64 * 1e-9;
                    let result = self
                        .goals
                        .done(payload.goal.id, &end, sim_time_s, judge, log)
                        .map(|()| payload.goal.id);
                    self.answer(&request, slots, log, result);
                }
                None => {
                    let why = format!("unknown request kind {}", payload.kind);
                    self.answer(&request, slots, log, Err(why));
                }
            }
        }
    }

    fn answer(
        &self,
        request: &Request,
        slots: &[Slot<'_>],
        log: &Log,
        result: Result<u64, String>,
    ) {
        let mut response = ControlResponse {
            kind: request.payload().kind,
            ok: u32::from(result.is_ok()),
            supervisor_pid: std::process::id(),
            uptime_ms: u64::try_from(log.start.elapsed().as_millis()).unwrap_or(u64::MAX),
            active_epoch: self.active_epoch,
            ..ControlResponse::default()
        };
        match ControlKind::from_u32(request.payload().kind) {
            Some(ControlKind::Goal | ControlKind::GoalDone) => {
                response.goal_id = *result.as_ref().unwrap_or(&0);
            }
            _ => response.handover_ns = *result.as_ref().unwrap_or(&0),
        }
        self.goals.fill(&mut response);
        if let Err(why) = &result {
            write_str(&mut response.message, why);
        }
        write_str(&mut response.waiting, &self.waiting);
        fill_status(slots, self.rates.as_ref(), &mut response);
        if let Some(p) = &self.pause {
            response.paused = u32::try_from(p.stopped.len()).unwrap_or(u32::MAX);
            response.pause_left_ms = u64::try_from(
                p.deadline
                    .saturating_duration_since(Instant::now())
                    .as_millis(),
            )
            .unwrap_or(u64::MAX);
        }
        if ControlKind::from_u32(request.payload().kind) == Some(ControlKind::Status) {
            let ours = self.pids(slots);
            let found = strangers(&self.instance, &ours);
            response.stranger_count =
                u32::try_from(found.len().min(MAX_STATUS_STRANGERS)).unwrap_or(0);
            for ((name, pid), out) in found.iter().zip(response.strangers.iter_mut()) {
                out.pid = *pid;
                write_str(&mut out.name, name);
            }
        }
        if let Err(e) = request.send_copy(response) {
            log.note(format_args!("control service: cannot answer: {e:?}"));
        }
    }

    #[allow(clippy::result_large_err)]
    fn start_swap(
        &mut self,
        config: &LaunchConfig,
        request: Request,
        payload: &ControlRequest,
        slots: &[Slot<'_>],
        log: &Log,
    ) -> Result<(), Box<(Request, String)>> {
        let name = read_str(&payload.name);
        let refuse = |request, why: String| Err(Box::new((request, why)));
        if self.swap.is_some() {
            return refuse(request, "a swap is already under way".to_owned());
        }
        let Some(index) = slots.iter().position(|s| s.process.name == name) else {
            return refuse(request, format!("no process is named `{name}`"));
        };
        let slot = &slots[index];
        if !matches!(slot.state, SlotState::Running(_)) {
            return refuse(request, format!("`{name}` is not running"));
        }
        let (cur_exec, cur_args) = slot.command();
        let exec_text = read_str(&payload.exec);
        let exec = if exec_text.is_empty() {
            cur_exec
        } else {
            PathBuf::from(exec_text)
        };
        let args = payload.get_args().unwrap_or(cur_args);
        let epoch = self.next_epoch;
        self.next_epoch += 1;
        let child = match spawn_process(config, slot.process, &exec, &args, epoch) {
            Ok(c) => c,
            Err(e) => {
                return refuse(request, format!("cannot start {}: {e}", exec.display()));
            }
        };
        log.event(
            &name,
            format_args!(
                "swap: started {} as pid {} (epoch {epoch}); the old one drives until it is ready",
                exec.display(),
                child.id()
            ),
        );
        let timeout = if payload.value_ns > 0 {
            Duration::from_nanos(payload.value_ns)
        } else {
            DEFAULT_SWAP_TIMEOUT
        };
        self.swap = Some(Swap {
            request,
            slot: index,
            child,
            epoch,
            exec,
            args,
            phase: SwapPhase::Starting,
            deadline: Instant::now() + timeout,
            timeout,
        });
        Ok(())
    }

    fn on_ready(&mut self, epoch: u64, log: &Log) -> Result<(), String> {
        let Some(swap) = &mut self.swap else {
            return Err(format!("no swap waits for epoch {epoch}"));
        };
        if swap.epoch != epoch || !matches!(swap.phase, SwapPhase::Starting) {
            return Err(format!("no swap waits for epoch {epoch} to be ready"));
        }
        swap.phase = SwapPhase::Flipped;
        swap.deadline = Instant::now() + swap.timeout;
        self.publish_epoch(epoch).map_err(|e| format!("{e:#}"))?;
        log.note(format_args!("swap: epoch {epoch} ready, now active"));
        Ok(())
    }

    fn on_driving(
        &mut self,
        epoch: u64,
        handover_ns: u64,
        slots: &mut [Slot<'_>],
        log: &Log,
    ) -> Result<(), String> {
        match &self.swap {
            Some(s) if s.epoch == epoch && matches!(s.phase, SwapPhase::Flipped) => {}
            _ => return Err(format!("no swap waits for epoch {epoch} to drive")),
        }
        let Some(swap) = self.swap.take() else {
            return Err("no swap".to_owned());
        };
        let slot = &mut slots[swap.slot];
        let name = slot.process.name.clone();
        let new_pid = swap.child.id();
        let old = std::mem::replace(&mut slot.state, SlotState::Running(swap.child));
        slot.started = Some(Instant::now());
        slot.epoch = epoch;
        slot.exec_override = Some((swap.exec, swap.args));
        if let SlotState::Running(old) = old {
            signal_group(&old, libc::SIGTERM);
            log.event(
                &name,
                format_args!(
                    "swap: pid {new_pid} drives (handover {:.1} us); stopping old pid {}",
                    handover_ns as f64 * 1e-3,
                    old.id()
                ),
            );
            self.retiring.push(Retiring {
                name: name.clone(),
                child: old,
                kill_at: Instant::now() + slot.process.stop_grace,
                killed: false,
            });
        }
        let request = swap.request;
        self.answer(&request, slots, log, Ok(handover_ns));
        Ok(())
    }

    /// The processes this supervisor started and runs now: the launch file's, a swap's new
    /// one, the retiring ones.
    fn pids(&self, slots: &[Slot<'_>]) -> Vec<u32> {
        let mut pids: Vec<u32> = slots
            .iter()
            .filter_map(|s| match &s.state {
                SlotState::Running(child) => Some(child.id()),
                _ => None,
            })
            .collect();
        pids.extend(self.swap.as_ref().map(|s| s.child.id()));
        pids.extend(self.retiring.iter().map(|r| r.child.id()));
        pids
    }

    /// Grants (or renews, for its holder) the pause lease: stops every running process's
    /// group until `len_ns` from now.
    fn on_pause(
        &mut self,
        holder: u32,
        len_ns: u64,
        slots: &[Slot<'_>],
        log: &Log,
    ) -> Result<(), String> {
        if holder == 0 || len_ns == 0 {
            return Err("a pause needs its holder's pid and a length".to_owned());
        }
        let now = Instant::now();
        let deadline = PauseLease::deadline_for(now, Duration::from_nanos(len_ns));
        if let Some(p) = &mut self.pause {
            if p.holder != holder {
                return Err(format!(
                    "the pipeline is already paused by pid {} for {:.1} s more",
                    p.holder,
                    p.deadline.saturating_duration_since(now).as_secs_f64()
                ));
            }
            p.deadline = deadline;
            return Ok(());
        }
        let mut stopped = Vec::new();
        for slot in slots {
            let SlotState::Running(child) = &slot.state else {
                continue;
            };
            let Ok(pid) = libc::pid_t::try_from(child.id()) else {
                continue;
            };
            // Each child leads a process group of its own: stop the group, or the process
            // alone if it leads none.
            for target in [-pid, pid] {
                // SAFETY: kill(2) of a child of ours, not reaped yet.
                if unsafe { libc::kill(target, libc::SIGSTOP) } == 0 {
                    stopped.push(target);
                    break;
                }
            }
        }
        log.note(format_args!(
            "paused {} process{} for pid {holder} (lease of {:.1} s)",
            stopped.len(),
            if stopped.len() == 1 { "" } else { "es" },
            deadline.saturating_duration_since(now).as_secs_f64()
        ));
        self.pause = Some(PauseLease {
            holder,
            deadline,
            stopped,
        });
        Ok(())
    }

    /// Releases the pause lease of `holder`.
    fn on_resume(&mut self, holder: u32, log: &Log) -> Result<(), String> {
        match &self.pause {
            Some(p) if p.holder == holder => {
                self.resume(log, "released");
                Ok(())
            }
            Some(p) => Err(format!(
                "the pause is held by pid {}, not {holder}",
                p.holder
            )),
            None => Ok(()),
        }
    }

    /// Continues what the pause lease stopped, and ends the lease.
    fn resume(&mut self, log: &Log, why: &str) {
        if let Some(p) = self.pause.take() {
            signal_all(&p.stopped, libc::SIGCONT);
            log.note(format_args!(
                "resumed {} process{}: the pause lease of pid {} {why}",
                p.stopped.len(),
                if p.stopped.len() == 1 { "" } else { "es" },
                p.holder
            ));
        }
    }

    /// Watches the swap under way, the retiring processes and the pause lease.
    pub(crate) fn poll(&mut self, slots: &[Slot<'_>], log: &Log) {
        if let Some(p) = &self.pause {
            let alive = process_alive(p.holder);
            if p.is_over(Instant::now(), alive) {
                self.resume(
                    log,
                    if alive {
                        "expired"
                    } else {
                        "ended: its holder is gone"
                    },
                );
            }
        }
        // A restarted physics subscribes anew: hand it the latched epoch now, not at the
        // next swap.
        let _ = self.epochs.update_connections();
        if let Some(rates) = &mut self.rates {
            rates.poll(self.active_epoch);
        }
        let now = Instant::now();
        if let Some(swap) = &mut self.swap {
            let exited = match swap.child.try_wait() {
                Ok(Some(status)) => Some(describe(status)),
                Ok(None) => None,
                Err(e) => Some(format!("could not be watched: {e}")),
            };
            let why = match (exited, now >= swap.deadline) {
                (Some(how), _) => Some(format!("the new process {how} before it drove")),
                (None, true) => Some(format!(
                    "the new process did not {} within {:?}",
                    match swap.phase {
                        SwapPhase::Starting => "become ready",
                        SwapPhase::Flipped => "drive",
                    },
                    swap.timeout
                )),
                (None, false) => None,
            };
            if let Some(why) = why {
                self.abort_swap(why, slots, log);
            }
        }
        self.retiring.retain_mut(|r| match r.child.try_wait() {
            Ok(Some(status)) => {
                log.event(
                    &r.name,
                    format_args!("swap: old pid {} {}", r.child.id(), describe(status)),
                );
                false
            }
            Ok(None) => {
                if !r.killed && now >= r.kill_at {
                    signal_group(&r.child, libc::SIGKILL);
                    r.killed = true;
                }
                true
            }
            Err(_) => false,
        });
    }

    /// Kills the swap's new process, gives the drive back to the old one, answers.
    fn abort_swap(&mut self, why: String, slots: &[Slot<'_>], log: &Log) {
        let Some(mut swap) = self.swap.take() else {
            return;
        };
        signal_group(&swap.child, libc::SIGKILL);
        let _ = swap.child.wait();
        let old_epoch = slots[swap.slot].epoch;
        if self.active_epoch != old_epoch
            && let Err(e) = self.publish_epoch(old_epoch)
        {
            log.note(format_args!("swap: cannot give the drive back: {e:#}"));
        }
        log.event(
            &slots[swap.slot].process.name,
            format_args!("swap refused: {why}; the old process drives on"),
        );
        self.answer(&swap.request, slots, log, Err(why));
    }

    /// Stops what the swaps left running and ends a pause (at the end of the run: a stopped
    /// process could not act on its SIGTERM).
    pub(crate) fn shutdown(&mut self, slots: &[Slot<'_>], log: &Log) {
        self.resume(log, "ended with the run");
        if self.swap.is_some() {
            self.abort_swap("the run is ending".to_owned(), slots, log);
        }
        for r in &mut self.retiring {
            signal_group(&r.child, libc::SIGKILL);
            let _ = r.child.wait();
        }
        self.retiring.clear();
    }
}

/// The stream a process publishes that `agp status` shows the rate of, known by the
/// process's name or executable: physics's IR frames, the planner's motor commands.
fn rate_of(slot: &Slot<'_>, rates: &MessageRates) -> Option<(&'static str, f64)> {
    let exec = slot.command().0;
    let stem = exec.file_stem().map(|s| s.to_string_lossy().into_owned());
    let is =
        |what: &str| slot.process.name == what || stem.as_deref() == Some(&format!("agp-{what}"));
    if is("physics") {
        Some(("ir_frames", rates.frames_per_s()))
    } else if is("planner") {
        Some(("motor_commands", rates.commands_per_s()))
    } else {
        None
    }
}

/// The live nodes of `instance` that are strangers, as `(name, pid)`: not of this
/// supervisor, not of a process in `ours` or in one of their process groups (each child
/// leads one: its own children are in it), not of a client (`agp status`, `agp down`,
/// `agp swap`, `agp profile`: node `agp-cli-<pid>` or `agp-profile-<pid>` of an `agp`
/// executable with that pid). The pid is the one the node declares.
fn strangers(instance: &Instance, ours: &[u32]) -> Vec<(String, u32)> {
    let me = std::process::id();
    let mut found = Vec::new();
    let _ = Node::<AgpIpc>::list(instance.config(), |state| {
        if let NodeState::Alive(view) = state {
            match view.details() {
                Some(d) => {
                    let name = d.name().as_str().to_owned();
                    let pid = u32::try_from(d.process_id().value()).unwrap_or(0);
                    if pid != me && !belongs_to(pid, ours) && !is_client_node(&name, pid) {
                        found.push((name, pid));
                    }
                }
                None => found.push((String::new(), 0)),
            }
        }
        CallbackProgression::Continue
    });
    found.sort_by_key(|s| s.1);
    found
}

/// Whether `pid` is one of `ours` or in the process group one of them leads.
fn belongs_to(pid: u32, ours: &[u32]) -> bool {
    if ours.contains(&pid) {
        return true;
    }
    let Ok(p) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: getpgid(2) reads the process group of a pid; no memory is involved.
    let group = unsafe { libc::getpgid(p) };
    group > 0 && u32::try_from(group).is_ok_and(|g| ours.contains(&g))
}

/// Each process's state into a status reply.
fn fill_status(slots: &[Slot<'_>], rates: Option<&MessageRates>, out: &mut ControlResponse) {
    let now = Instant::now();
    out.process_count = u32::try_from(slots.len().min(MAX_STATUS_PROCESSES)).unwrap_or(0);
    for (slot, p) in slots.iter().zip(out.processes.iter_mut()) {
        write_str(&mut p.name, &slot.process.name);
        write_str(&mut p.exec, &slot.command().0.to_string_lossy());
        p.restarts = slot.restarts;
        p.epoch = slot.epoch;
        p.uptime_ms = slot.started.map_or(0, |t| {
            u64::try_from((now - t).as_millis()).unwrap_or(u64::MAX)
        });
        let (state, pid) = match &slot.state {
            SlotState::Running(child) => (ProcessState::Running, child.id()),
            SlotState::Pending { .. } => (ProcessState::Pending, 0),
            SlotState::Done if slot.started.is_none() => (ProcessState::Pending, 0),
            SlotState::Done => (ProcessState::Exited, 0),
        };
        p.state = state as u32;
        p.pid = pid;
        if let Some((topic, rate)) = rates.and_then(|r| rate_of(slot, r))
            && state == ProcessState::Running
        {
            write_str(&mut p.rate_topic, topic);
            p.rate_mhz = (rate * 1e3).round() as u64;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pause_lease_whose_holder_stops_renewing_ends_at_its_deadline() {
        let now = Instant::now();
        let lease = PauseLease {
            holder: 42,
            deadline: PauseLease::deadline_for(now, Duration::from_secs(3)),
            stopped: Vec::new(),
        };
        assert!(!lease.is_over(now + Duration::from_secs(2), true));
        assert!(lease.is_over(now + Duration::from_secs(3), true));
        assert!(lease.is_over(now, false), "a dead holder ends it at once");
    }

    #[test]
    fn no_pause_lease_outlasts_the_longest_one_granted() {
        let now = Instant::now();
        assert_eq!(
            PauseLease::deadline_for(now, Duration::from_secs(86_400)),
            now + MAX_PAUSE_LEASE
        );
    }

    #[test]
    fn the_supervisor_itself_and_the_processes_of_a_childs_group_are_no_strangers() {
        // This test process leads no group of its own, but its pid is `ours`.
        let me = std::process::id();
        assert!(belongs_to(me, &[me]));
        // SAFETY: getpgid(0): the caller's own process group.
        let group = u32::try_from(unsafe { libc::getpgid(0) }).expect("a group");
        assert!(belongs_to(me, &[group]), "a member of a listed group");
        assert!(!belongs_to(me, &[]));
    }

    #[test]
    fn a_node_named_like_a_client_is_a_stranger_unless_an_agp_with_that_pid_made_it() {
        let me = std::process::id();
        // The test executable is not `agp`.
        assert!(!is_client_node(&format!("agp-cli-{me}"), me));
        assert!(!is_client_node("agp-cli-1", me));
        assert!(!is_client_node("intruder", me));
    }
}
