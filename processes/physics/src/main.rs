//! The physics process: simulates the robot, its IR sensors and the object, and talks to
//! the rest of the pipeline only through the instance's iceoryx2 services.

use std::time::{Duration, Instant};

use agp_physics::{Sim, SimConfig};
use agp_runtime::{
    AgpIpc, Instance, WaitOutcome, WaitStrategy, Waiter, alloc_count, install_shutdown_handler,
    shutdown_requested,
};
use agp_shared_types::{
    ActiveEpoch, GroundTruth, IrFrame, MotorCommand, ObjectEstimate, Reset, SessionKey,
    TimingHeader, monotonic_ns, stage,
};
use agp_world::{RobotDescription, Scenario};
use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};
use iceoryx2::identifiers::{UniqueNodeId, UniquePublisherId};
use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::{CallbackProgression, Node, NodeState, PortFactory};

mod watchdog;
use watchdog::WatchdogAccount;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Clock {
    /// Advance one step only when the command for that step has arrived (reproducible).
    Lockstep,
    /// Step at a fixed rate on the wall clock; stop the wheels when commands go stale.
    Realtime,
}

/// Simulates the E-puck, its eight IR sensors and one object, and publishes IR frames and
/// ground truth over iceoryx2.
///
/// Every option can also come from the environment the supervisor sets (`AGP_INSTANCE`,
/// `AGP_SCENARIO`, `AGP_CLOCK`, `AGP_RATE_HZ`).
#[derive(Debug, Parser)]
#[command(name = "agp-physics", version)]
struct Args {
    /// Instance name: selects the iceoryx2 prefix and root folder shared with the others.
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    /// Built-in scenario (square, triangle, lshape, circle) or a scenario file.
    #[arg(long, env = "AGP_SCENARIO", default_value = "triangle")]
    scenario: String,
    /// Clock mode.
    #[arg(long, env = "AGP_CLOCK", value_enum, default_value = "lockstep")]
    clock: Clock,
    /// Physics steps per second of simulated time (also the realtime tick rate).
    #[arg(long, env = "AGP_RATE_HZ", default_value_t = 640.0)]
    rate_hz: f64,
    /// Seed of the IR, odometry and overhead-fix noise (default: the scenario's).
    #[arg(long, env = "AGP_SEED")]
    seed: Option<u64>,
    /// Realtime: stop the wheels when no command arrived for this long (ms), counted in
    /// ticks of the realtime clock; a command answering a frame older than this is refused.
    #[arg(long, default_value_t = 250)]
    watchdog_ms: u64,
    /// Lockstep: give up when no command arrives for this long (s); 0 waits forever.
    #[arg(long, default_value_t = 0)]
    idle_timeout_s: u64,
    /// Lockstep: append `STEP EPOCH` for every applied motor command to this file (the
    /// proof that a hot swap lost and repeated no step).
    #[arg(long)]
    step_log: Option<std::path::PathBuf>,
    /// Lockstep: apply each motor command for this many steps (1 to 64), without a command
    /// round trip per step. Of the hold's frames, those the robot senses at (a new IR
    /// sample or overhead fix, 64 Hz) and the last are published, each once the estimator
    /// has estimated the frame published two before, so it takes in every one, in order. A
    /// command answers every N-th step's frame. Needs an estimator on the instance.
    #[arg(long, default_value_t = 1)]
    hold_steps: u32,
}

/// Counts heap allocations by region when `AGP_COUNT_ALLOCS=1` (see
/// [`agp_runtime::alloc_count`]): physics's steady-state lockstep loop allocates none.
#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

fn main() {
    agp_runtime::quiet_iceoryx2();
    alloc_count::enable_from_env();
    if let Err(e) = run() {
        eprintln!("agp-physics: error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args = Args::parse();
    if !(args.rate_hz.is_finite() && args.rate_hz >= 64.0 && args.rate_hz <= 100_000.0) {
        bail!(
            "--rate-hz must be between 64 and 100000, got {}",
            args.rate_hz
        );
    }
    if !(1..=MAX_HOLD_STEPS).contains(&args.hold_steps) {
        bail!(
            "--hold-steps must be between 1 and {MAX_HOLD_STEPS}, got {}",
            args.hold_steps
        );
    }
    if args.hold_steps > 1 && args.clock != Clock::Lockstep {
        bail!("--hold-steps needs the lockstep clock");
    }
    install_shutdown_handler();
    let key = SessionKey::from_env().map_err(|e| anyhow::anyhow!(e))?;
    let scenario = Scenario::resolve(&args.scenario)?;
    let robot = RobotDescription::epuck();
    let config = SimConfig {
        step_hz: args.rate_hz,
        seed: args.seed.unwrap_or(scenario.task.seed),
        ..SimConfig::default()
    };
    let sim = Sim::new(&scenario, &robot, config)
        .with_context(|| format!("cannot build the world of scenario `{}`", scenario.name))?;

    let instance = Instance::new(&args.instance)
        .with_context(|| format!("bad instance name `{}`", args.instance))?;
    let node = instance
        .node("physics", false)
        .map_err(|e| anyhow::anyhow!("cannot create the iceoryx2 node: {e:?}"))?;
    let (ports, inbox) = Ports::open(&instance, &node)?;
    let waiter = Waiter::new(inbox, WaitStrategy::from_env());
    let hold = if args.hold_steps > 1 {
        Some(Hold::open(&instance, &node, args.hold_steps)?)
    } else {
        None
    };
    let step_log = match &args.step_log {
        Some(path) => Some(StepLog::open(path)?),
        None => None,
    };

    let mut runner = Runner {
        sim,
        gate: Gate::new(key, &instance),
        ports,
        reset_seq: 0,
        active_epoch: 0,
        trace_base: monotonic_ns(),
        rate_hz: args.rate_hz,
        step_log,
        hold,
        recent_frames: [0; HOLD_WINDOW as usize],
    };
    let result = match args.clock {
        Clock::Lockstep => runner.lockstep(&waiter, args.idle_timeout_s),
        Clock::Realtime => runner.realtime(&waiter, Duration::from_millis(args.watchdog_ms)),
    };
    runner.gate.summary();
    result
}

struct Ports {
    frames: Publisher<AgpIpc, IrFrame, ()>,
    frames_ev: Notifier<AgpIpc>,
    truth: Publisher<AgpIpc, GroundTruth, ()>,
    truth_ev: Notifier<AgpIpc>,
    commands: Subscriber<AgpIpc, MotorCommand, ()>,
    resets: Subscriber<AgpIpc, Reset, ()>,
    epochs: Subscriber<AgpIpc, ActiveEpoch, ()>,
    /// The services of commands and resets, to name the node of a stranger's publisher.
    commands_service:
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<AgpIpc, MotorCommand, ()>,
    resets_service:
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<AgpIpc, Reset, ()>,
}

fn port_err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow::anyhow!("cannot create the {what}: {e:?}")
}

impl Ports {
    /// Opens every port physics uses, and the listener of its inbox.
    fn open(
        instance: &Instance,
        node: &iceoryx2::prelude::Node<AgpIpc>,
    ) -> Result<(Self, Listener<AgpIpc>)> {
        let frames = instance.ir_frames(node)?;
        let truth = instance.ground_truth(node)?;
        let commands = instance.motor_commands(node)?;
        let resets = instance.resets(node)?;
        let epochs = instance.active_epoch(node)?;
        let inbox = commands
            .event
            .listener_builder()
            .create()
            .map_err(port_err("physics inbox listener"))?;
        let ports = Self {
            frames: frames
                .data
                .publisher_builder()
                .create()
                .map_err(port_err("IR frame publisher"))?,
            frames_ev: frames
                .event
                .notifier_builder()
                .create()
                .map_err(port_err("IR frame notifier"))?,
            truth: truth
                .data
                .publisher_builder()
                .create()
                .map_err(port_err("ground truth publisher"))?,
            truth_ev: truth
                .event
                .notifier_builder()
                .create()
                .map_err(port_err("ground truth notifier"))?,
            commands: commands
                .subscriber()
                .create()
                .map_err(port_err("motor command subscriber"))?,
            resets: resets
                .subscriber()
                .create()
                .map_err(port_err("reset subscriber"))?,
            epochs: epochs
                .subscriber()
                .create()
                .map_err(port_err("active epoch subscriber"))?,
            commands_service: commands.data,
            resets_service: resets.data,
        };
        Ok((ports, inbox))
    }
}

/// Most strangers named one by one on stderr; later ones are only counted.
const MAX_STRANGERS: usize = 16;

/// Which commands physics applies: with the run's [`SessionKey`] (the supervisor hands it
/// to physics alone), only those carrying the token of their epoch, that is from processes
/// the supervisor started; without one (physics run by hand, the probe's and benchmarks'
/// private pipelines), every command. Each stranger's publisher is named once on stderr.
struct Gate {
    key: Option<SessionKey>,
    /// The token of the last epoch asked about.
    cached: (u64, u64),
    dropped: u64,
    /// Publishers seen sending without the token (at most [`MAX_STRANGERS`], room kept).
    strangers: Vec<(UniquePublisherId, &'static str)>,
    /// How many of `strangers` are not yet named on stderr.
    unnamed: usize,
    config: iceoryx2::config::Config,
}

impl Gate {
    fn new(key: Option<SessionKey>, instance: &Instance) -> Self {
        Self {
            cached: (0, key.map_or(0, |k| k.token(0))),
            key,
            dropped: 0,
            strangers: Vec::with_capacity(MAX_STRANGERS),
            unnamed: 0,
            config: instance.config().clone(),
        }
    }

    /// Whether a command or reset (`what`) of `epoch` carrying `token`, sent by
    /// `publisher`, may be applied. Allocates nothing.
    fn admits(
        &mut self,
        epoch: u64,
        token: u64,
        publisher: UniquePublisherId,
        what: &'static str,
    ) -> bool {
        let Some(key) = &self.key else {
            return true;
        };
        if self.cached.0 != epoch {
            self.cached = (epoch, key.token(epoch));
        }
        if token == self.cached.1 {
            return true;
        }
        self.dropped += 1;
        if self.strangers.len() < MAX_STRANGERS
            && !self.strangers.iter().any(|(p, _)| *p == publisher)
        {
            self.strangers.push((publisher, what));
            self.unnamed += 1;
        }
        false
    }

    /// Names on stderr each stranger not named yet: its node, process and executable.
    fn name_strangers(&mut self, ports: &Ports) {
        if self.unnamed == 0 {
            return;
        }
        let first = self.strangers.len() - self.unnamed;
        self.unnamed = 0;
        for &(publisher, what) in &self.strangers[first..] {
            let mut node_id = None;
            let find =
                |d: &iceoryx2::service::dynamic_config::publish_subscribe::PublisherDetails| {
                    if d.publisher_id == publisher {
                        node_id = Some(d.node_id);
                        CallbackProgression::Stop
                    } else {
                        CallbackProgression::Continue
                    }
                };
            if what == "reset" {
                ports.resets_service.dynamic_config().list_publishers(find);
            } else {
                ports
                    .commands_service
                    .dynamic_config()
                    .list_publishers(find);
            }
            eprintln!(
                "agp-physics: refused a {what} from {}: not a process this instance's supervisor started (no token of its epoch); its commands and resets are dropped",
                node_id.map_or_else(
                    || "a publisher that has gone".to_owned(),
                    |id| self.describe(id)
                )
            );
        }
    }

    /// `node `NAME` of pid N (`EXECUTABLE`)`, or the node id when it cannot be listed.
    fn describe(&self, id: UniqueNodeId) -> String {
        let mut found = None;
        let _ = Node::<AgpIpc>::list(&self.config, |state| {
            if let NodeState::Alive(view) = &state
                && *view.id() == id
            {
                found = view.details().as_ref().map(|d| {
                    format!(
                        "node `{}` of pid {} (`{}`)",
                        d.name(),
                        d.process_id(),
                        d.executable()
                    )
                });
                return CallbackProgression::Stop;
            }
            CallbackProgression::Continue
        });
        found.unwrap_or_else(|| format!("node {id}"))
    }

    /// At exit: how many commands and resets were refused, if any.
    fn summary(&self) {
        if self.dropped > 0 {
            eprintln!(
                "agp-physics: refused {} motor command(s) and reset(s) of {} process(es) the supervisor did not start",
                self.dropped,
                self.strangers.len()
            );
        }
    }
}

/// A motor command that arrived before its epoch became active.
#[derive(Debug, Clone, Copy)]
struct Ahead {
    step: u64,
    epoch: u64,
    wheels: (f64, f64),
    /// The command's timing, COMMAND_RECEIVED stamped.
    timing: TimingHeader,
}

/// A command's timing with physics's receive stamped.
fn received(c: &MotorCommand) -> TimingHeader {
    let mut t = c.timing;
    t.stamps_ns[stage::COMMAND_RECEIVED] = monotonic_ns();
    t
}

/// The latest active epoch the supervisor published, or `current` when none is pending.
fn latest_epoch(epochs: &Subscriber<AgpIpc, ActiveEpoch, ()>, current: u64) -> u64 {
    let mut epoch = current;
    while let Ok(Some(e)) = epochs.receive() {
        epoch = e.epoch;
    }
    epoch
}

struct Runner {
    sim: Sim,
    gate: Gate,
    ports: Ports,
    reset_seq: u64,
    active_epoch: u64,
    trace_base: u64,
    rate_hz: f64,
    step_log: Option<StepLog>,
    /// `--hold-steps` above 1: each command held for that many steps, paced by the estimator.
    hold: Option<Hold>,
    /// The steps of the last [`HOLD_WINDOW`] frames published, oldest first: a hold
    /// publishes a frame once the estimate of the oldest is in.
    recent_frames: [u64; HOLD_WINDOW as usize],
}

/// The longest hold `--hold-steps` takes.
const MAX_HOLD_STEPS: u32 = 64;

/// How many frames may be published and not yet estimated during a hold: fewer than the
/// estimator's frame buffer (4, `Qos::stream`), so it loses none.
const HOLD_WINDOW: u64 = 3;

/// A hold of each command for `steps` steps (`--hold-steps`): physics steps on while the
/// estimator keeps up, read from the step of its newest estimate.
struct Hold {
    steps: u32,
    estimates: Subscriber<AgpIpc, ObjectEstimate, ()>,
    waiter: Waiter,
    /// The step of the newest estimate seen (its frame's).
    estimated: Option<u64>,
}

impl Hold {
    fn open(instance: &Instance, node: &Node<AgpIpc>, steps: u32) -> Result<Self> {
        let topic = instance.estimates(node)?;
        let estimates = topic
            .subscriber()
            .create()
            .map_err(port_err("estimate subscriber"))?;
        let listener = topic
            .event
            .listener_builder()
            .create()
            .map_err(port_err("estimate listener"))?;
        Ok(Self {
            steps,
            estimates,
            waiter: Waiter::new(listener, WaitStrategy::from_env()),
            estimated: None,
        })
    }

    /// Until the estimate of frame `need` or a later one is in. With `need` the oldest of
    /// the last [`HOLD_WINDOW`] frames published, at most `HOLD_WINDOW - 1` frames then
    /// wait for the estimator besides the one about to be published.
    fn pace(&mut self, need: u64) -> Result<()> {
        let deadline = Instant::now() + HOLD_TIMEOUT;
        loop {
            let estimates = &self.estimates;
            let estimated = &mut self.estimated;
            let outcome = {
                let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
                self.waiter.wait_for(Duration::from_millis(5), || {
                    while let Ok(Some(e)) = estimates.receive() {
                        *estimated = Some(estimated.map_or(e.step, |s| s.max(e.step)));
                    }
                    estimated.is_some_and(|s| s >= need).then_some(())
                })
            };
            match outcome {
                WaitOutcome::Ready(()) => return Ok(()),
                // The caller sees the request and stops stepping.
                WaitOutcome::Shutdown => return Ok(()),
                WaitOutcome::TimedOut if Instant::now() > deadline => bail!(
                    "no estimate of step {need} within {HOLD_TIMEOUT:?} during a held command: \
                     is agp-estimator running on this instance?"
                ),
                WaitOutcome::TimedOut => {}
            }
        }
    }
}

/// What the robot has sensed so far: its IR samples and overhead fixes.
fn sensed(s: &agp_physics::SensorState) -> (u64, u64) {
    (s.ir_sample, s.fix_seq)
}

/// Safety net of a held command's wait for the estimator.
const HOLD_TIMEOUT: Duration = Duration::from_secs(60);

impl Runner {
    /// Publishes the frame and ground truth of the current step. `cause` is the timing of
    /// the command that produced the step, COMMAND_RECEIVED and COMMAND_APPLIED stamped
    /// (zeros when none did: the first frame, a reset); `applied_ns` is when the step was
    /// taken (in realtime also without a command).
    fn publish(&mut self, applied_ns: u64, cause: TimingHeader) -> Result<()> {
        let s = self.sim.sensors();
        let step = self.sim.step_count();
        self.recent_frames.rotate_left(1);
        self.recent_frames[HOLD_WINDOW as usize - 1] = step;
        let mut frame = IrFrame {
            step,
            sim_time_s: self.sim.sim_time(),
            ir_sample: s.ir_sample,
            ir_raw: s.ir_raw,
            odometry: s.odometry,
            fix_seq: s.fix_seq,
            fix: s.fix,
            reset_seq: self.reset_seq,
            active_epoch: self.active_epoch,
            cause,
            ..IrFrame::default()
        };
        frame.timing.trace_id = self.trace_base.wrapping_add(step);
        frame.timing.stamps_ns[stage::COMMAND_RECEIVED] = cause.stamps_ns[stage::COMMAND_RECEIVED];
        frame.timing.stamps_ns[stage::COMMAND_APPLIED] = applied_ns;
        let truth = GroundTruth {
            step,
            sim_time_s: self.sim.sim_time(),
            robot: (self.sim.robot_pose()),
            object: (self.sim.object_pose()),
            contact: self.sim.in_contact() as u8,
            _pad: [0; 7],
        };
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        // Ground truth first: a reader woken by the frame then finds the truth of that step.
        let sample = self
            .ports
            .truth
            .loan_uninit()
            .map_err(|e| anyhow::anyhow!("cannot loan a ground truth sample: {e:?}"))?;
        sample
            .write_payload(truth)
            .send()
            .map_err(|e| anyhow::anyhow!("cannot send ground truth: {e:?}"))?;
        let _ = self.ports.truth_ev.notify();
        frame.timing.stamps_ns[stage::FRAME_PUBLISHED] = monotonic_ns();
        let sample = self
            .ports
            .frames
            .loan_uninit()
            .map_err(|e| anyhow::anyhow!("cannot loan an IR frame sample: {e:?}"))?;
        sample
            .write_payload(frame)
            .send()
            .map_err(|e| anyhow::anyhow!("cannot send an IR frame: {e:?}"))?;
        let _ = self.ports.frames_ev.notify();
        Ok(())
    }

    /// Applies the last pending reset, if any. Returns whether one was applied.
    fn apply_resets(&mut self) -> Result<bool> {
        let mut last = None;
        while let Some(r) = {
            let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
            self.ports.resets.receive()
        }
        .map_err(|e| anyhow::anyhow!("cannot receive a reset: {e:?}"))?
        {
            if !self
                .gate
                .admits(r.epoch, r.token, r.header().publisher_id(), "reset")
            {
                continue;
            }
            if r.epoch > self.active_epoch {
                // A planner sends nothing before it saw its epoch active, so the epoch's
                // sample is already here: read it before judging the reset.
                self.active_epoch = latest_epoch(&self.ports.epochs, self.active_epoch);
            }
            // A reset of a planner that does not drive (one being swapped in or out) is
            // dropped, as its motor commands are.
            if r.epoch == self.active_epoch {
                last = Some(*r);
            }
        }
        self.gate.name_strangers(&self.ports);
        if let Some(r) = last {
            let _in_simulation = alloc_count::enter(alloc_count::Region::Work);
            if r.seed != 0 {
                self.sim.reseed(r.seed);
            }
            self.sim.reset(r.object, r.robot);
            self.reset_seq = r.seq;
            return Ok(true);
        }
        Ok(false)
    }

    fn lockstep(&mut self, waiter: &Waiter, idle_timeout_s: u64) -> Result<()> {
        let result = self.lockstep_loop(waiter, idle_timeout_s);
        alloc_count::report("agp-physics", "simulation", "steps");
        result
    }

    fn lockstep_loop(&mut self, waiter: &Waiter, idle_timeout_s: u64) -> Result<()> {
        let idle_limit = (idle_timeout_s > 0).then(|| Duration::from_secs(idle_timeout_s));
        // A subscriber that connects while physics waits gets the latest frame from history
        // only when the publisher updates its connections: do so at this period while idle,
        // and wake the readers for it (a new planner waits for that frame once per episode
        // of a benchmark: the period is its latency).
        let slice = Duration::from_millis(5);
        let mut idle_since = Instant::now();
        // A command of a newer epoch than the active one, for the step it names: kept until
        // its epoch becomes active (a hot swap's flip), or dropped when the step passes.
        let mut ahead: Option<Ahead> = None;
        self.publish(0, TimingHeader::default())?;
        loop {
            let step = self.sim.step_count();
            let mut epoch = self.active_epoch;
            let mut reset = false;
            let outcome = {
                let commands = &self.ports.commands;
                let resets = &self.ports.resets;
                let epochs = &self.ports.epochs;
                let gate = &mut self.gate;
                let ahead = &mut ahead;
                // Every call in the wait is iceoryx2's (polls and the block); the closure
                // itself only compares and copies.
                let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
                waiter.wait_for(slice, || {
                    epoch = latest_epoch(epochs, epoch);
                    if resets.has_samples().unwrap_or(false) {
                        return Some(None);
                    }
                    while let Ok(Some(c)) = commands.receive() {
                        if !gate.admits(
                            c.epoch,
                            c.token,
                            c.header().publisher_id(),
                            "motor command",
                        ) {
                            continue;
                        }
                        if c.step != step {
                            // A command of another step: stale. Dropped.
                            continue;
                        }
                        if c.epoch > epoch {
                            // Its planner saw its epoch active before sending: the epoch's
                            // sample may have arrived since the read above.
                            epoch = latest_epoch(epochs, epoch);
                        }
                        if c.epoch == epoch {
                            return Some(Some((c.left_mps, c.right_mps, received(&c))));
                        }
                        if c.epoch > epoch {
                            *ahead = Some(Ahead {
                                step,
                                epoch: c.epoch,
                                wheels: (c.left_mps, c.right_mps),
                                timing: received(&c),
                            });
                        }
                        // Otherwise a command of a retired planner: dropped.
                    }
                    match *ahead {
                        Some(a) if a.step == step && a.epoch == epoch => {
                            *ahead = None;
                            Some(Some((a.wheels.0, a.wheels.1, a.timing)))
                        }
                        _ => None,
                    }
                })
            };
            self.active_epoch = epoch;
            self.gate.name_strangers(&self.ports);
            match outcome {
                WaitOutcome::Shutdown => return Ok(()),
                WaitOutcome::TimedOut => {
                    if idle_limit.is_some_and(|limit| idle_since.elapsed() > limit) {
                        bail!("no motor command for step {step} within {idle_timeout_s} s");
                    }
                    let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
                    self.update_connections()?;
                    let _ = self.ports.frames_ev.notify();
                    continue;
                }
                WaitOutcome::Ready(None) => {
                    idle_since = Instant::now();
                    reset = self.apply_resets()?;
                }
                WaitOutcome::Ready(Some((l, r, cause))) => {
                    idle_since = Instant::now();
                    self.apply_command(l, r, cause)?;
                    alloc_count::message_done();
                }
            }
            if reset {
                // The same step again, with the world as the reset put it.
                self.publish(0, TimingHeader::default())?;
            }
        }
    }

    /// Applies a command: one step and its frame; with `--hold-steps N`, [`Self::held_steps`].
    fn apply_command(&mut self, l: f64, r: f64, mut cause: TimingHeader) -> Result<()> {
        if let Some(mut hold) = self.hold.take() {
            let result = self.held_steps(&mut hold, l, r, cause);
            self.hold = Some(hold);
            return result;
        }
        if let Some(log) = &mut self.step_log {
            log.record(self.sim.step_count(), self.active_epoch)?;
        }
        {
            let _in_simulation = alloc_count::enter(alloc_count::Region::Work);
            self.sim.step(l, r);
        }
        let applied = monotonic_ns();
        cause.stamps_ns[stage::COMMAND_APPLIED] = applied;
        self.publish(applied, cause)
    }

    /// With `--hold-steps N`: the command for N steps. Of their frames only those the robot
    /// senses at are published (a new IR sample or overhead fix: the robot's 64 Hz, where
    /// physics steps at 640) and the hold's last, which the next command answers; each
    /// once the estimator has kept up. A frame between two samples repeats the sensing of
    /// the one before, which the estimator takes in once (`ObjectTracker::observe`), so
    /// the estimates of the frames published are those of publishing every frame. The
    /// first frame published carries the command's timing (applied at the hold's first
    /// step), the others none of their own.
    fn held_steps(&mut self, hold: &mut Hold, l: f64, r: f64, cause: TimingHeader) -> Result<()> {
        let mut cause = Some(cause);
        let mut first_applied = 0;
        for k in 1..=hold.steps {
            if k > 1 && shutdown_requested() {
                return Ok(());
            }
            if let Some(log) = &mut self.step_log {
                log.record(self.sim.step_count(), self.active_epoch)?;
            }
            let before = sensed(self.sim.sensors());
            {
                let _in_simulation = alloc_count::enter(alloc_count::Region::Work);
                self.sim.step(l, r);
            }
            let applied = monotonic_ns();
            if k == 1 {
                first_applied = applied;
            }
            if k < hold.steps && before == sensed(self.sim.sensors()) {
                continue;
            }
            hold.pace(self.recent_frames[0])?;
            if shutdown_requested() {
                return Ok(());
            }
            match cause.take() {
                Some(mut c) => {
                    c.stamps_ns[stage::COMMAND_APPLIED] = first_applied;
                    self.publish(first_applied, c)?;
                }
                None => self.publish(applied, TimingHeader::default())?,
            }
        }
        Ok(())
    }

    /// Hands history to subscribers that connected since the last send.
    fn update_connections(&self) -> Result<()> {
        self.ports
            .frames
            .update_connections()
            .map_err(|e| anyhow::anyhow!("cannot update IR frame connections: {e:?}"))?;
        self.ports
            .truth
            .update_connections()
            .map_err(|e| anyhow::anyhow!("cannot update ground truth connections: {e:?}"))?;
        Ok(())
    }

    fn realtime(&mut self, waiter: &Waiter, watchdog: Duration) -> Result<()> {
        let period = Duration::from_secs_f64(1.0 / self.rate_hz);
        let mut wheels = (0.0, 0.0);
        let mut next = Instant::now();
        let mut ticks = TickAccount::default();
        // The watchdog and a command's age count ticks of this clock (watchdog.rs).
        let mut dog = WatchdogAccount::new(watchdog, self.rate_hz);
        self.publish(0, TimingHeader::default())?;
        while !shutdown_requested() {
            if self.apply_resets()? {
                wheels = (0.0, 0.0);
                dog.reset();
            }
            let epoch_before = self.active_epoch;
            self.active_epoch = latest_epoch(&self.ports.epochs, self.active_epoch);
            let mut cause = TimingHeader::default();
            // The step of the newest frame a command of this tick answers.
            let mut answered = None;
            let step = self.sim.step_count();
            while let Some(c) = self
                .ports
                .commands
                .receive()
                .map_err(|e| anyhow::anyhow!("cannot receive a command: {e:?}"))?
            {
                if !self
                    .gate
                    .admits(c.epoch, c.token, c.header().publisher_id(), "motor command")
                {
                    continue;
                }
                if c.epoch > self.active_epoch {
                    self.active_epoch = latest_epoch(&self.ports.epochs, self.active_epoch);
                }
                // A command held on its way longer than the watchdog (its frame older than
                // that) would drive the robot on what it sensed long ago: refused, counted.
                if c.epoch == self.active_epoch && dog.admits(step, c.step) {
                    wheels = (c.left_mps, c.right_mps);
                    cause = received(&c);
                    answered = Some(c.step);
                }
            }
            if answered.is_some()
                && let Some(stop) = dog.command(
                    monotonic_ns(),
                    step,
                    cause.stamps_ns[stage::FRAME_PUBLISHED],
                )
            {
                println!("agp-physics: {stop}");
            }
            self.gate.name_strangers(&self.ports);
            if self.active_epoch != epoch_before {
                ticks.flip();
            }
            if let Some(gap) = ticks.tick(self.sim.step_count(), answered) {
                println!(
                    "agp-physics: handover to epoch {}: {gap} tick(s) without a command",
                    self.active_epoch
                );
            }
            if dog.expired(step) {
                // Stale commands: stop, as the robot's firmware would.
                if let Some(stop) = dog.fire(monotonic_ns(), step, wheels) {
                    println!("agp-physics: {}", stop.fired_line());
                }
                wheels = (0.0, 0.0);
            }
            self.sim.step(wheels.0, wheels.1);
            let applied = monotonic_ns();
            dog.stepped(applied, self.sim.robot_pose());
            if cause.trace_id != 0 {
                cause.stamps_ns[stage::COMMAND_APPLIED] = applied;
            }
            self.publish(applied, cause)?;
            next += period;
            let now = Instant::now();
            if next > now {
                // Sleep on the inbox so the loop also wakes for shutdown; commands are read
                // at the next tick.
                let _ = waiter.wait_for(next - now, || None::<()>);
            } else if now - next > period * 100 {
                // Far behind (the machine stalled): do not try to catch up in a burst.
                next = now;
            }
        }
        if let Some(stop) = dog.current() {
            println!("agp-physics: {stop}");
        }
        println!("agp-physics: {ticks}; {dog}");
        Ok(())
    }
}

/// How the commands kept up with the realtime clock, tick by tick, from the first command
/// of a planner on: a tick is on time when a command answering the newest frame (the one
/// the tick before published) arrived in it, late when the newest command that arrived
/// answers an older frame, and missing when none arrived (the wheels keep the last speeds until the
/// watchdog stops them).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
struct TickAccount {
    /// Ticks since the first command.
    ticks: u64,
    on_time: u64,
    late: u64,
    missing: u64,
    /// The longest run of ticks in a row without a command.
    longest_gap: u64,
    gap: u64,
    /// Hot swaps: how many flipped the active epoch, the most ticks any of them went
    /// without a command between the flip and the new planner's first, and the count for
    /// the flip under way.
    handovers: u64,
    longest_handover: u64,
    since_flip: Option<u64>,
}

impl TickAccount {
    /// Books the tick that steps the world from frame `step`, where `answered` is the
    /// step of the frame the newest command received in it answers.
    /// Returns the ticks the handover under way went without a command, when it ended in
    /// this tick.
    fn tick(&mut self, step: u64, answered: Option<u64>) -> Option<u64> {
        let mut ended = None;
        if let Some(n) = self.since_flip {
            if answered.is_some() {
                ended = Some(n);
                self.handovers += 1;
                self.longest_handover = self.longest_handover.max(n);
                self.since_flip = None;
            } else {
                self.since_flip = Some(n + 1);
            }
        }
        match answered {
            None if self.ticks == 0 => return ended,
            None => {
                self.missing += 1;
                self.gap += 1;
                self.longest_gap = self.longest_gap.max(self.gap);
            }
            Some(a) => {
                self.gap = 0;
                if a >= step {
                    self.on_time += 1;
                } else {
                    self.late += 1;
                }
            }
        }
        self.ticks += 1;
        ended
    }
}

impl TickAccount {
    /// The active epoch changed in this tick (a hot swap's flip): only commands of the new
    /// planner count from now on.
    fn flip(&mut self) {
        self.since_flip = Some(0);
    }
}

impl std::fmt::Display for TickAccount {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "realtime: {} ticks since the first command: {} on time, {} late, {} missing (longest run without a command: {} ticks)",
            self.ticks, self.on_time, self.late, self.missing, self.longest_gap
        )?;
        if self.handovers > 0 || self.since_flip.is_some() {
            write!(
                f,
                "; {} hot swap handovers, at most {} tick(s) without a command at one{}",
                self.handovers,
                self.longest_handover,
                if self.since_flip.is_some() {
                    " (one more flipped and never drove)"
                } else {
                    ""
                }
            )?;
        }
        Ok(())
    }
}

/// `--step-log`: one line `STEP EPOCH` per applied command, written in whole lines (a
/// buffer of complete lines goes out in one write), so a physics killed with SIGKILL leaves
/// no torn line for its restarted successor to append to: only its last unwritten lines
/// are lost. Allocates nothing per step.
struct StepLog {
    file: std::fs::File,
    lines: Vec<u8>,
}

impl StepLog {
    /// Bytes of complete lines kept before they are written.
    const FLUSH_AT: usize = 4096;

    fn open(path: &std::path::Path) -> Result<Self> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("cannot open the step log {}", path.display()))?;
        Ok(Self {
            file,
            lines: Vec::with_capacity(Self::FLUSH_AT + 64),
        })
    }

    fn record(&mut self, step: u64, epoch: u64) -> Result<()> {
        use std::io::Write;
        writeln!(self.lines, "{step} {epoch}").context("cannot format the step log")?;
        if self.lines.len() >= Self::FLUSH_AT {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        use std::io::Write;
        self.file
            .write_all(&self.lines)
            .context("cannot write the step log")?;
        self.lines.clear();
        Ok(())
    }
}

impl Drop for StepLog {
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            eprintln!("agp-physics: {e:#}");
        }
    }
}

#[cfg(test)]
mod tick_tests {
    use super::TickAccount;

    #[test]
    fn ticks_before_the_first_command_are_not_booked() {
        let mut t = TickAccount::default();
        t.tick(0, None);
        t.tick(1, None);
        assert_eq!(t, TickAccount::default());
    }

    #[test]
    fn a_command_answering_an_older_frame_is_late_and_a_tick_without_one_is_missing() {
        let mut t = TickAccount::default();
        t.tick(10, Some(10)); // answers the newest frame: on time
        t.tick(11, None); // nothing came
        t.tick(12, None);
        t.tick(13, Some(11)); // answers a frame two ticks old
        t.tick(14, Some(14));
        assert_eq!((t.ticks, t.on_time, t.late, t.missing), (5, 2, 1, 2));
        assert_eq!(t.longest_gap, 2);
    }

    #[test]
    fn a_handover_counts_the_ticks_from_the_flip_to_the_new_planners_first_command() {
        let mut t = TickAccount::default();
        t.tick(1, Some(1));
        t.flip();
        t.tick(2, None); // the old planner's commands no longer count
        t.tick(3, Some(3));
        t.flip();
        t.tick(4, Some(4)); // the new planner answered within the tick of the flip
        assert_eq!((t.handovers, t.longest_handover), (2, 1));
        assert!(
            t.to_string()
                .contains("2 hot swap handovers, at most 1 tick(s)")
        );
    }
}
