//! `agp profile`: latency of each hop and stage of a running instance, and the floor.
//!
//! The profiler attaches to a running instance with one more IR frame subscriber. Every
//! frame carries, besides its own timing, the whole timing of the motor command that
//! produced it (`IrFrame::cause`): the frame that command answered was published, the
//! planner received it, published the command, physics received and applied it. So one
//! frame is one complete control step, and the profiler needs no other topic.
//!
//! A step goes physics -> planner -> physics, or, while the estimator is in the lockstep
//! loop (the learning phase: the planner acts on a frame once it has the estimator's
//! estimate of it), physics -> estimator -> planner -> physics: then the command carries the
//! estimator's stamps and PLANNER_RECEIVED is the estimate's receipt. Each step is measured
//! along its own route; a hop or stage no sampled step passed is left out of the report.
//!
//! It samples instead of following every frame: about every millisecond it wakes, takes
//! what its subscriber's buffer holds (the latest few frames; older ones were overwritten)
//! and sleeps again. It never spins, so on two cores it leaves the pipeline its cores, and
//! the figures are those of the pipeline as it runs without a profiler, less the cost of
//! delivering each frame to one more subscriber.
//!
//! After the sampling, it measures the floor: a bare iceoryx2 ping-pong between `agp` and
//! a copy of itself (`agp profile-floor-pong`), waiting as the pipeline waits (the
//! supervisor reports its `AGP_WAIT`; the profiler's own is not used) and notifying after
//! every send as the pipeline does. While the floor runs, the instance's processes are
//! paused, so the floor has the machine as the pipeline had it: on two cores a running
//! pipeline would otherwise compete with the floor it is compared to. A lockstep pipeline
//! loses nothing by the pause. `--no-pause` keeps the pipeline running instead.
//!
//! The pause is a lease the profiler takes from the instance's supervisor
//! ([`ControlKind::Pause`]) with a deadline a few seconds past the floor's expected end,
//! renewed if the floor runs longer and released at its end: the supervisor stops and
//! continues its processes, so a profiler that dies, even by SIGKILL, leaves the pipeline
//! paused at most until the deadline. The pong side dies with the profiler
//! (`PR_SET_PDEATHSIG`), and the next `agp profile` removes the files of a floor whose
//! profiler died.
//!
//! An instance with a bridge (an `agp bridge` among its processes: its planner, or its
//! physics and estimator, run in another instance) gets a second floor after the first: the
//! link's, a bare Zenoh ping-pong between `agp` and a copy of itself (`agp bridge
//! floor-pong`) on the bridge's own transport (mutual TLS with the bridge's key folder, or
//! plain TCP), read from the bridge's command line: the pong end answers in Zenoh's
//! receive callback, where a bridge's receiving end republishes, and the ping end waits for
//! each answer as a bridge's sending end waits for its next message (`agp bridge --wait`,
//! `block` by default); the pipeline is paused meanwhile as for the first. The two hops that cross the link
//! (estimator->planner, planner->physics) are each given as a ratio to it: what the bridge
//! costs beyond Zenoh's own.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use agp_runtime::control_client::ControlClient;
use agp_runtime::{
    AgpIpc, Instance, InstanceLock, WaitOutcome, WaitStrategy, Waiter, control_client,
    install_shutdown_handler, shutdown_requested,
};
use agp_shared_types::{
    ControlKind, ControlRequest, IrFrame, TimingHeader, monotonic_ns, read_str, stage,
};
use anyhow::{Context, Result, anyhow, bail};
use hdrhistogram::Histogram;
use iceoryx2::node::NodeState;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use crate::control;

/// The hidden subcommand `agp profile` re-executes `agp` with for the floor's pong side.
pub const FLOOR_PONG_SUBCOMMAND: &str = "profile-floor-pong";

/// Measure where the time of a control step goes on a running instance: each hop and
/// stage, end to end, and the floor (a bare iceoryx2 hop waiting the same way).
#[derive(Debug, clap::Args)]
pub struct ProfileArgs {
    #[command(flatten)]
    pub target: control::InstanceArg,
    /// How long to sample the pipeline, seconds.
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
    /// How long to run the floor after the sampling, seconds.
    #[arg(long, default_value_t = 1.0)]
    pub floor_seconds: f64,
    /// Also write the figures as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Also plot the latency histograms (each hop, end to end, the floor) as SVG here.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Keep the pipeline running while the floor runs (by default its supervisor pauses its
    /// processes for that second, under a lease that ends by itself a few seconds after the
    /// floor should have, so the floor does not compete with them for the cores).
    #[arg(long)]
    pub no_pause: bool,
}

/// The pong side of the floor (run by `agp profile`, not by hand).
#[derive(Debug, clap::Args)]
pub struct FloorPongArgs {
    /// The floor's private instance.
    #[arg(long)]
    pub instance: String,
}

/// How often the profiler looks at its subscriber.
const POLL_PERIOD: Duration = Duration::from_millis(1);

/// Round trips of the floor before it records.
const FLOOR_WARMUP: u64 = 200;

/// The longest wait for one message of the floor, or for its pong side to come up.
const FLOOR_TIMEOUT: Duration = Duration::from_secs(10);

/// How far past the floor's expected end the pause lease lasts, and how long a renewal
/// extends it.
const LEASE_MARGIN: Duration = Duration::from_secs(3);

/// A lease with less than this left is renewed.
const LEASE_RENEW_BEFORE: Duration = Duration::from_secs(2);

/// The instance name of the floor of the profiler with process id `pid`.
fn floor_instance_name(pid: u32) -> String {
    format!("pfloor-{pid}")
}

/// A span between two stamps of a control step.
#[derive(Debug, Clone, Copy)]
enum Stamp {
    /// A stamp of the frame's own timing.
    Frame(usize),
    /// A stamp of the frame's cause (the command that produced it).
    Cause(usize),
}

impl Stamp {
    fn of(self, f: &IrFrame) -> u64 {
        match self {
            Self::Frame(i) => f.timing.stamps_ns[i],
            Self::Cause(i) => f.cause.stamps_ns[i],
        }
    }
}

/// Which control steps a row measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// Every step.
    Any,
    /// Steps through the estimator: physics -> estimator -> planner -> physics.
    Estimator,
    /// Steps straight from physics to the planner.
    Direct,
}

impl Route {
    /// The route of the step that made `f`: through the estimator if its command carries
    /// the estimator's receipt.
    fn of(f: &IrFrame) -> Self {
        if f.cause.stamps_ns[stage::ESTIMATOR_RECEIVED] != 0 {
            Self::Estimator
        } else {
            Self::Direct
        }
    }

    fn takes(self, f: &IrFrame) -> bool {
        self == Self::Any || self == Self::of(f)
    }

    fn path(self) -> &'static str {
        match self {
            Self::Any => "any",
            Self::Estimator => "physics -> estimator -> planner -> physics",
            Self::Direct => "physics -> planner -> physics",
        }
    }
}

/// What one row reads of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Span {
    /// The step that made the frame did not pass this span.
    OffRoute,
    /// A stamp is missing or the two are out of order.
    Missing,
    Ns(u64),
}

/// Which table a row belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Group {
    Hop,
    Stage,
    EndToEnd,
}

/// One measured span.
struct Row {
    name: &'static str,
    group: Group,
    route: Route,
    from: Stamp,
    to: Stamp,
    histogram: Histogram<u64>,
    /// Frames whose stamps for this span were missing or out of order.
    missing: u64,
}

impl Row {
    fn span(&self, f: &IrFrame) -> Span {
        if !self.route.takes(f) {
            return Span::OffRoute;
        }
        let (a, b) = (self.from.of(f), self.to.of(f));
        if a == 0 || b == 0 || b < a {
            Span::Missing
        } else {
            Span::Ns(b - a)
        }
    }
}

fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 60_000_000_000, 3)
        .expect("constant bounds 1 ns..60 s at 3 digits are valid")
}

fn rows() -> Vec<Row> {
    use Stamp::{Cause, Frame};
    use stage::*;
    let row = |name, group, route, from, to| Row {
        name,
        group,
        route,
        from,
        to,
        histogram: histogram(),
        missing: 0,
    };
    vec![
        row(
            "physics->estimator",
            Group::Hop,
            Route::Estimator,
            Cause(FRAME_PUBLISHED),
            Cause(ESTIMATOR_RECEIVED),
        ),
        row(
            "estimator->planner",
            Group::Hop,
            Route::Estimator,
            Cause(ESTIMATE_PUBLISHED),
            Cause(PLANNER_RECEIVED),
        ),
        row(
            "physics->planner",
            Group::Hop,
            Route::Direct,
            Cause(FRAME_PUBLISHED),
            Cause(PLANNER_RECEIVED),
        ),
        row(
            "planner->physics",
            Group::Hop,
            Route::Any,
            Cause(COMMAND_PUBLISHED),
            Cause(COMMAND_RECEIVED),
        ),
        row(
            "estimator",
            Group::Stage,
            Route::Estimator,
            Cause(ESTIMATOR_RECEIVED),
            Cause(ESTIMATE_PUBLISHED),
        ),
        row(
            "planner",
            Group::Stage,
            Route::Any,
            Cause(PLANNER_RECEIVED),
            Cause(COMMAND_PUBLISHED),
        ),
        row(
            "physics.step",
            Group::Stage,
            Route::Any,
            Cause(COMMAND_RECEIVED),
            Cause(COMMAND_APPLIED),
        ),
        row(
            "physics.publish",
            Group::Stage,
            Route::Any,
            Cause(COMMAND_APPLIED),
            Frame(FRAME_PUBLISHED),
        ),
        row(
            "end_to_end",
            Group::EndToEnd,
            Route::Any,
            Cause(FRAME_PUBLISHED),
            Cause(COMMAND_APPLIED),
        ),
    ]
}

/// The figures of one row.
#[derive(Debug, Clone)]
struct Figures {
    name: String,
    samples: u64,
    p50_ns: u64,
    p90_ns: u64,
    p99_ns: u64,
    p999_ns: u64,
    max_ns: u64,
}

impl Figures {
    fn new(name: &str, h: &Histogram<u64>) -> Self {
        Self {
            name: name.to_owned(),
            samples: h.len(),
            p50_ns: h.value_at_quantile(0.50),
            p90_ns: h.value_at_quantile(0.90),
            p99_ns: h.value_at_quantile(0.99),
            p999_ns: h.value_at_quantile(0.999),
            max_ns: h.max(),
        }
    }

    fn ratio(&self, floor: &Figures) -> Option<f64> {
        (floor.p50_ns > 0 && self.samples > 0).then(|| self.p50_ns as f64 / floor.p50_ns as f64)
    }

    fn to_json(&self, floor: &Figures) -> serde_json::Value {
        serde_json::json!({
            "name": self.name,
            "samples": self.samples,
            "p50_ns": self.p50_ns,
            "p90_ns": self.p90_ns,
            "p99_ns": self.p99_ns,
            "p999_ns": self.p999_ns,
            "max_ns": self.max_ns,
            "ratio_to_floor_p50": self.ratio(floor),
        })
    }
}

/// What the sampling saw.
struct Sampling {
    rows: Vec<Row>,
    /// Frames taken from the subscriber.
    frames: u64,
    /// Frames with no cause (the first frame, a reset's frame).
    uncaused: u64,
    /// Control steps sampled through the estimator and straight to the planner.
    via_estimator: u64,
    direct: u64,
    /// Wake-ups of the profiler.
    polls: u64,
    /// Physics steps between the first and the last frame taken, and the time between
    /// their publications (summed over runs of physics, if it restarted).
    steps: u64,
    span_ns: u64,
    elapsed: Duration,
    /// The instance went down while it was sampled (its supervisor let go of it).
    ended_early: bool,
}

impl Sampling {
    fn steps_per_s(&self) -> Option<f64> {
        (self.span_ns > 0).then(|| self.steps as f64 / (self.span_ns as f64 * 1e-9))
    }
}

/// The trace base of a frame: one per run of physics.
fn run_of(f: &IrFrame) -> u64 {
    f.timing.trace_id.wrapping_sub(f.step)
}

fn sample_pipeline(instance: &Instance, seconds: f64) -> Result<Sampling> {
    let node = instance
        .node(&format!("agp-profile-{}", std::process::id()), false)
        .map_err(|e| anyhow!("cannot create an iceoryx2 node: {e:?}"))?;
    let frames = instance
        .ir_frames(&node)
        .context("cannot open the IR frames")?;
    let subscriber = frames
        .subscriber()
        .create()
        .map_err(|e| anyhow!("cannot subscribe to the IR frames: {e:?}"))?;
    let mut s = Sampling {
        rows: rows(),
        frames: 0,
        uncaused: 0,
        via_estimator: 0,
        direct: 0,
        polls: 0,
        steps: 0,
        span_ns: 0,
        elapsed: Duration::ZERO,
        ended_early: false,
    };
    let mut last: Option<IrFrame> = None;
    let duration = Duration::from_secs_f64(seconds);
    let start = Instant::now();
    let mut next_check = start;
    while start.elapsed() < duration && !shutdown_requested() {
        s.polls += 1;
        if Instant::now() >= next_check {
            // An instance that goes down ends the sampling: what came so far is kept.
            if !InstanceLock::is_held(instance) {
                s.ended_early = true;
                break;
            }
            next_check = Instant::now() + Duration::from_millis(100);
        }
        while let Some(sample) = subscriber
            .receive()
            .map_err(|e| anyhow!("cannot receive an IR frame: {e:?}"))?
        {
            let f = *sample.payload();
            drop(sample);
            s.frames += 1;
            if let Some(prev) = &last
                && run_of(prev) == run_of(&f)
                && f.step >= prev.step
            {
                let (a, b) = (
                    prev.timing.stamps_ns[stage::FRAME_PUBLISHED],
                    f.timing.stamps_ns[stage::FRAME_PUBLISHED],
                );
                if b > a {
                    s.steps += f.step - prev.step;
                    s.span_ns += b - a;
                }
            }
            last = Some(f);
            if f.cause.trace_id == 0 {
                s.uncaused += 1;
                continue;
            }
            match Route::of(&f) {
                Route::Estimator => s.via_estimator += 1,
                _ => s.direct += 1,
            }
            for row in &mut s.rows {
                match row.span(&f) {
                    Span::OffRoute => {}
                    Span::Missing => row.missing += 1,
                    Span::Ns(ns) => row.histogram.saturating_record(ns),
                }
            }
        }
        std::thread::sleep(POLL_PERIOD);
    }
    s.elapsed = start.elapsed();
    Ok(s)
}

/// The floor's message: a sequence number (`trace_id`) and the ping's send stamp
/// (`stamps_ns[0]`), in the pipeline's own timing header.
type FloorMessage = TimingHeader;

const FLOOR_READY: u64 = u64::MAX - 1;
const FLOOR_STOP: u64 = u64::MAX;

type FloorTopic = publish_subscribe::PortFactory<AgpIpc, FloorMessage, ()>;
type FloorEvents = event::PortFactory<AgpIpc>;

/// One side's ports of the floor.
struct FloorPorts {
    publisher: Publisher<AgpIpc, FloorMessage, ()>,
    subscriber: Subscriber<AgpIpc, FloorMessage, ()>,
    notifier: Notifier<AgpIpc>,
    waiter: Waiter,
    _services: (FloorTopic, FloorTopic, FloorEvents, FloorEvents),
}

impl FloorPorts {
    fn open(node: &Node<AgpIpc>, ping_side: bool, waiting: WaitStrategy) -> Result<Self> {
        let topic =
            |name: &str| -> Result<publish_subscribe::PortFactory<AgpIpc, FloorMessage, ()>> {
                let service: ServiceName = name
                    .try_into()
                    .map_err(|e| anyhow!("bad service name `{name}`: {e:?}"))?;
                node.service_builder(&service)
                    .publish_subscribe::<FloorMessage>()
                    .history_size(0)
                    .subscriber_max_buffer_size(4)
                    .max_publishers(2)
                    .max_subscribers(2)
                    .open_or_create()
                    .map_err(|e| anyhow!("cannot open `{name}`: {e:?}"))
            };
        let events = |name: &str| -> Result<FloorEvents> {
            let service: ServiceName = name
                .try_into()
                .map_err(|e| anyhow!("bad service name `{name}`: {e:?}"))?;
            node.service_builder(&service)
                .event()
                .event_id_max_value(agp_runtime::EVENT_ID_MAX_VALUE)
                .max_notifiers(2)
                .max_listeners(2)
                .open_or_create()
                .map_err(|e| anyhow!("cannot open `{name}`: {e:?}"))
        };
        let ping = topic("floor/ping")?;
        let pong = topic("floor/pong")?;
        let ping_ev = events("floor/ping.ev")?;
        let pong_ev = events("floor/pong.ev")?;
        let (out, inp, out_ev, in_ev) = if ping_side {
            (&ping, &pong, &ping_ev, &pong_ev)
        } else {
            (&pong, &ping, &pong_ev, &ping_ev)
        };
        let listener: Listener<AgpIpc> = in_ev
            .listener_builder()
            .create()
            .map_err(|e| anyhow!("cannot create the floor's listener: {e:?}"))?;
        Ok(Self {
            publisher: out
                .publisher_builder()
                .create()
                .map_err(|e| anyhow!("cannot create the floor's publisher: {e:?}"))?,
            subscriber: inp
                .subscriber_builder()
                .create()
                .map_err(|e| anyhow!("cannot create the floor's subscriber: {e:?}"))?,
            notifier: out_ev
                .notifier_builder()
                .create()
                .map_err(|e| anyhow!("cannot create the floor's notifier: {e:?}"))?,
            waiter: Waiter::new(listener, waiting),
            _services: (ping, pong, ping_ev, pong_ev),
        })
    }

    /// Sends one message and notifies, as every pipeline publisher does.
    fn send(&self, seq: u64, stamp_ns: u64) -> Result<()> {
        let mut m = FloorMessage {
            trace_id: seq,
            ..FloorMessage::default()
        };
        m.stamps_ns[0] = stamp_ns;
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| anyhow!("floor: cannot loan a sample: {e:?}"))?;
        sample
            .write_payload(m)
            .send()
            .map_err(|e| anyhow!("floor: cannot send: {e:?}"))?;
        let _ = self.notifier.notify();
        Ok(())
    }

    /// The next message: `(seq, stamp_ns)`.
    fn next(&self) -> Result<(u64, u64)> {
        let subscriber = &self.subscriber;
        match self.waiter.wait_for(FLOOR_TIMEOUT, || {
            subscriber
                .receive()
                .ok()
                .flatten()
                .map(|s| (s.payload().trace_id, s.payload().stamps_ns[0]))
        }) {
            WaitOutcome::Ready(m) => Ok(m),
            WaitOutcome::TimedOut => bail!("floor: no answer within {FLOOR_TIMEOUT:?}"),
            WaitOutcome::Shutdown => bail!("floor: interrupted"),
        }
    }
}

/// The floor's result.
struct Floor {
    histogram: Histogram<u64>,
    round_trips: u64,
    /// How many processes of the pipeline were paused while it ran (`None`: not paused).
    paused: Option<u32>,
}

/// The pipeline of an instance paused by its supervisor under a lease this process holds,
/// until the lease's deadline or [`PauseLease::release`] (also on drop).
struct PauseLease {
    client: ControlClient,
    _node: Node<AgpIpc>,
    /// The deadline as this side counts it (the supervisor's is no later).
    deadline: Instant,
    /// How many processes the supervisor paused.
    processes: u32,
    released: bool,
}

impl PauseLease {
    /// Asks the supervisor of `instance` to pause its processes for `len`.
    fn take(instance: &Instance, len: Duration) -> Result<Self> {
        let node = instance
            .node(&format!("agp-cli-{}", std::process::id()), false)
            .map_err(|e| anyhow!("cannot create an iceoryx2 node: {e:?}"))?;
        let client = ControlClient::open(instance, &node, FLOOR_TIMEOUT)?;
        let mut lease = Self {
            client,
            _node: node,
            deadline: Instant::now(),
            processes: 0,
            released: false,
        };
        lease.processes = lease.ask_pause(len)?;
        Ok(lease)
    }

    /// Asks for (or renews) the pause for `len` from now; the processes paused.
    fn ask_pause(&mut self, len: Duration) -> Result<u32> {
        let mut request = ControlRequest::new(ControlKind::Pause);
        request.pid = std::process::id();
        request.value_ns = u64::try_from(len.as_nanos()).unwrap_or(u64::MAX);
        let asked = Instant::now();
        let r = self.client.ask(&request, FLOOR_TIMEOUT)?;
        if r.ok == 0 {
            bail!("the supervisor refused the pause: {}", read_str(&r.message));
        }
        self.deadline = asked + len.min(agp_shared_types::MAX_PAUSE_LEASE);
        Ok(r.paused)
    }

    /// Renews the lease if little of it is left.
    fn renew_if_due(&mut self) -> Result<()> {
        if self.deadline.saturating_duration_since(Instant::now()) < LEASE_RENEW_BEFORE {
            self.ask_pause(LEASE_MARGIN)?;
        }
        Ok(())
    }

    /// Gives the lease back: the processes run again.
    fn release(&mut self) -> Result<()> {
        if self.released {
            return Ok(());
        }
        self.released = true;
        let mut request = ControlRequest::new(ControlKind::Resume);
        request.pid = std::process::id();
        let r = self.client.ask(&request, FLOOR_TIMEOUT)?;
        if r.ok == 0 {
            bail!(
                "the supervisor refused the resume: {}",
                read_str(&r.message)
            );
        }
        Ok(())
    }
}

impl Drop for PauseLease {
    fn drop(&mut self) {
        // On an error or Ctrl-C: the deadline would resume the pipeline, but sooner is
        // better.
        let _ = self.release();
    }
}

/// Removes the files of the floors whose profiler died (killed before it could): an
/// instance `pfloor-<pid>` whose process `pid` is gone and which has no live node.
fn clean_dead_floors() {
    let Ok(probe) = Instance::new(&floor_instance_name(0)) else {
        return;
    };
    let Some(base) = probe.root_dir().parent() else {
        return;
    };
    let Ok(entries) = std::fs::read_dir(base) else {
        return;
    };
    for entry in entries.filter_map(Result::ok) {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name
            .strip_prefix("pfloor-")
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if name != floor_instance_name(pid) || pid == std::process::id() || process_exists(pid) {
            continue;
        }
        let Ok(instance) = Instance::new(&name) else {
            continue;
        };
        let mut alive = false;
        let listed = Node::<AgpIpc>::list(instance.config(), |state| {
            alive |= matches!(state, NodeState::Alive(_));
            CallbackProgression::Continue
        });
        if listed.is_ok() && !alive {
            let _ = instance.remove_files();
        }
    }
}

/// Whether process `pid` exists.
fn process_exists(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill(2) with signal 0 only checks that the process exists.
    let rc = unsafe { libc::kill(pid, 0) };
    rc == 0 || std::io::Error::last_os_error().raw_os_error() != Some(libc::ESRCH)
}

/// How the processes of instance `name` wait, as its supervisor reports it: the floor must
/// wait the same way. An `AGP_WAIT` of the caller's that differs is said and not used.
fn pipeline_waiting(name: &str) -> Result<WaitStrategy> {
    let r = control_client::ask(name, agp_shared_types::ControlKind::Status)?;
    let reported = control::StatusReport::new(name, &r).waiting;
    let Some(waiting) = WaitStrategy::parse(&reported) else {
        bail!(
            "the processes of instance `{name}` wait in different ways (`{reported}`: launch.toml sets `AGP_WAIT` for some of them): the floor needs one way to compare with; give them all the same"
        );
    };
    if let Ok(Some(own)) = WaitStrategy::from_env_checked()
        && own != waiting
    {
        eprintln!(
            "agp profile: the floor waits as instance `{name}` does, `{}`; AGP_WAIT=`{}` here is not used",
            waiting.name(),
            own.name()
        );
    }
    Ok(waiting)
}

/// The ping side: starts the pong side, both waiting by `waiting`, measures for `seconds`
/// (with the pipeline of `pause` paused meanwhile, if given), stops it, removes the floor's
/// files.
fn run_floor(seconds: f64, waiting: WaitStrategy, pause: Option<&Instance>) -> Result<Floor> {
    let name = floor_instance_name(std::process::id());
    let instance =
        Instance::new(&name).map_err(|e| anyhow!("bad floor instance name `{name}`: {e}"))?;
    let _ = instance.remove_files();
    let result = (|| {
        let node = instance
            .node("floor-ping", false)
            .map_err(|e| anyhow!("cannot create the floor's node: {e:?}"))?;
        let ports = FloorPorts::open(&node, true, waiting)?;
        let exe = std::env::current_exe().context("cannot find the running `agp` executable")?;
        let mut cmd = Command::new(exe);
        cmd.args([FLOOR_PONG_SUBCOMMAND, "--instance", &name])
            .env(WaitStrategy::ENV, waiting.name())
            .stdin(Stdio::null());
        // It dies with the profiler, however the profiler ends.
        let child = agp_runtime::children::spawn_guarded(&mut cmd)
            .context("cannot start the floor's pong side")?;
        let mut child = KillOnDrop(child);
        let floor = ping(&ports, seconds, pause);
        // Stop the pong side however the ping ended; it also times out on its own.
        let _ = ports.send(FLOOR_STOP, 0);
        let deadline = Instant::now() + Duration::from_secs(5);
        while child.0.try_wait().ok().flatten().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        drop(child);
        drop(ports);
        drop(node);
        floor
    })();
    let _ = instance.remove_files();
    result
}

/// Kills and reaps the child if it is still running when dropped.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if self.0.try_wait().ok().flatten().is_none() {
            let _ = self.0.kill();
        }
        let _ = self.0.wait();
    }
}

fn ping(ports: &FloorPorts, seconds: f64, pause: Option<&Instance>) -> Result<Floor> {
    while ports.next()?.0 != FLOOR_READY {}
    let duration = Duration::from_secs_f64(seconds);
    let mut lease = match pause {
        Some(instance) => Some(
            PauseLease::take(instance, duration + LEASE_MARGIN)
                .context("cannot pause the pipeline for the floor")?,
        ),
        None => None,
    };
    let mut h = histogram();
    let start = Instant::now();
    let mut seq = 0u64;
    while seq < FLOOR_WARMUP || start.elapsed() < duration {
        if shutdown_requested() {
            bail!("floor: interrupted");
        }
        if let Some(lease) = &mut lease {
            lease.renew_if_due()?;
        }
        ports.send(seq, monotonic_ns())?;
        let rtt = loop {
            let (s, stamp) = ports.next()?;
            if s == seq {
                break monotonic_ns().saturating_sub(stamp);
            }
        };
        if seq >= FLOOR_WARMUP {
            h.saturating_record(rtt / 2);
        }
        seq += 1;
    }
    let paused = match &mut lease {
        Some(lease) => {
            lease
                .release()
                .context("cannot resume the pipeline after the floor")?;
            Some(lease.processes)
        }
        None => None,
    };
    Ok(Floor {
        round_trips: h.len(),
        histogram: h,
        paused,
    })
}

/// `agp profile-floor-pong`: echoes the floor's pings until told to stop.
pub fn run_floor_pong(args: &FloorPongArgs) -> Result<u8> {
    install_shutdown_handler();
    let instance = crate::control::instance_named(&args.instance)?;
    let node = instance
        .node("floor-pong", false)
        .map_err(|e| anyhow!("cannot create the floor's node: {e:?}"))?;
    let ports = FloorPorts::open(&node, false, WaitStrategy::from_env())?;
    ports.send(FLOOR_READY, monotonic_ns())?;
    loop {
        let (seq, stamp) = ports.next()?;
        if seq == FLOOR_STOP {
            return Ok(0);
        }
        if seq == FLOOR_READY {
            continue;
        }
        ports.send(seq, stamp)?;
    }
}

/// The machine's 1, 5 and 15 minute load averages.
fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = text.split_whitespace().map(|v| v.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

/// `agp profile`.
pub fn run(args: &ProfileArgs) -> Result<u8> {
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 3600.0) {
        bail!("--seconds must be between 0 and 3600, got {}", args.seconds);
    }
    if !(args.floor_seconds.is_finite() && args.floor_seconds > 0.0 && args.floor_seconds <= 600.0)
    {
        bail!(
            "--floor-seconds must be between 0 and 600, got {}",
            args.floor_seconds
        );
    }
    let name = args.target.name()?;
    let instance = crate::control::instance_named(&name)?;
    if !InstanceLock::is_held(&instance) {
        bail!("instance `{name}` is not up (no supervisor holds it): start it with `agp up`");
    }
    install_shutdown_handler();
    clean_dead_floors();
    let waiting = pipeline_waiting(&name)?;
    let sampling = sample_pipeline(&instance, args.seconds)?;
    if shutdown_requested() {
        bail!("interrupted");
    }
    let ended_early = sampling.ended_early;
    if ended_early {
        crate::console::warn(format_args!(
            "agp: error: instance `{name}` went down {:.1} s into the {:.1} s profile; what was sampled until then follows (the floor runs alone: no pipeline is left to pause)",
            sampling.elapsed.as_secs_f64(),
            args.seconds
        ));
    }
    if sampling.frames == 0 {
        bail!(
            "no IR frame of instance `{name}` arrived in {:.1} s: is physics running?",
            sampling.elapsed.as_secs_f64()
        );
    }
    if sampling.frames == sampling.uncaused {
        bail!(
            "no control step of instance `{name}` was sampled in {:.1} s ({} frames, none made by a motor command): is a planner driving physics?",
            sampling.elapsed.as_secs_f64(),
            sampling.frames
        );
    }
    let floor = run_floor(
        args.floor_seconds,
        waiting,
        (!args.no_pause && !ended_early).then_some(&instance),
    )
    .context("the floor failed")?;
    let link_floor = link_floor(
        &name,
        args.floor_seconds,
        (!args.no_pause && !ended_early).then_some(&instance),
    );
    let paused = floor.paused.map(|n| n as usize);
    let load = load_average();
    let report = Report {
        instance: name,
        waiting: waiting.name(),
        sampling,
        floor_figures: Figures::new("floor", &floor.histogram),
        floor,
        floor_seconds: args.floor_seconds,
        paused,
        load,
        link_floor,
    };
    report.print();
    if let Some(path) = &args.json {
        let text =
            serde_json::to_string_pretty(&report.to_json()).context("cannot encode the JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    if let Some(path) = &args.plot {
        report.plot(path)?;
    }
    Ok(u8::from(ended_early))
}

struct Report {
    instance: String,
    waiting: String,
    sampling: Sampling,
    floor: Floor,
    floor_figures: Figures,
    floor_seconds: f64,
    /// How many processes were paused while the floor ran (`None`: `--no-pause`).
    paused: Option<usize>,
    load: Option<[f64; 3]>,
    /// The Zenoh floor of the instance's bridge, if it has one.
    link_floor: Option<LinkFloor>,
}

impl Report {
    /// The figures of the rows of `group` some sampled step passed.
    fn figures(&self, group: Group) -> Vec<Figures> {
        self.sampling
            .rows
            .iter()
            .filter(|r| r.group == group && !r.histogram.is_empty())
            .map(|r| Figures::new(r.name, &r.histogram))
            .collect()
    }

    fn caused(&self) -> u64 {
        self.sampling.frames - self.sampling.uncaused
    }

    fn print(&self) {
        let s = &self.sampling;
        let load = self.load.map_or("unknown".to_owned(), |l| {
            format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2])
        });
        println!(
            "agp profile: instance `{}`, waiting `{}`, load average {load} (1, 5, 15 min), {} cores",
            self.instance,
            self.waiting,
            std::thread::available_parallelism().map_or(0, |n| n.get())
        );
        println!(
            "  sampled {} control steps ({} frames taken, {} without a cause) in {:.1} s: {} wake-ups about every {} ms, each taking what the subscriber's buffer held (no spinning)",
            self.caused(),
            s.frames,
            s.uncaused,
            s.elapsed.as_secs_f64(),
            s.polls,
            POLL_PERIOD.as_millis()
        );
        match s.steps_per_s() {
            Some(r) => println!(
                "  physics stepped {r:.0} steps/s (so about {:.1} % of the steps were sampled)",
                100.0 * self.caused() as f64 / (r * s.elapsed.as_secs_f64()).max(1.0)
            ),
            None => println!("  physics steps/s: unknown (fewer than two frames of one run)"),
        }
        for (route, n) in [
            (Route::Estimator, s.via_estimator),
            (Route::Direct, s.direct),
        ] {
            if n > 0 {
                println!("  {n} sampled steps went {}", route.path());
            }
        }
        println!(
            "  floor: bare iceoryx2 ping-pong between two `agp` processes, same waiting, one-way = round trip / 2, {} round trips over {:.1} s after the sampling, {}",
            self.floor.round_trips,
            self.floor_seconds,
            self.floor_when()
        );
        let hops: Vec<Figures> = self.figures(Group::Hop);
        println!(
            "  hops of the sampled run: {}",
            hops.iter()
                .map(|f| f.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
        println!(
            "\n  {:<6} {:<18} {:>8} {:>9} {:>9} {:>9} {:>9} {:>10} {:>9}",
            "", "name", "samples", "p50 us", "p90 us", "p99 us", "p99.9 us", "max us", "p50/floor"
        );
        let us = |ns: u64| ns as f64 * 1e-3;
        let line = |kind: &str, f: &Figures| {
            println!(
                "  {:<6} {:<18} {:>8} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>10.2} {:>9}",
                kind,
                f.name,
                f.samples,
                us(f.p50_ns),
                us(f.p90_ns),
                us(f.p99_ns),
                us(f.p999_ns),
                us(f.max_ns),
                f.ratio(&self.floor_figures)
                    .map_or("-".to_owned(), |r| format!("{r:.1}x"))
            );
        };
        for f in &hops {
            line("hop", f);
        }
        for f in self.figures(Group::Stage) {
            line("stage", &f);
        }
        for f in self.figures(Group::EndToEnd) {
            line("e2e", &f);
        }
        line("floor", &self.floor_figures);
        if let Some(link) = &self.link_floor {
            link.print(&hops, line);
        }
        for r in &s.rows {
            if r.missing > 0 {
                println!(
                    "  note: {} sampled steps had no usable stamps for `{}`",
                    r.missing, r.name
                );
            }
        }
    }

    fn floor_when(&self) -> String {
        match self.paused {
            Some(n) => format!("the pipeline's {n} processes paused meanwhile"),
            None => "the pipeline running beside it".to_owned(),
        }
    }

    fn to_json(&self) -> serde_json::Value {
        let s = &self.sampling;
        let floor = &self.floor_figures;
        let list = |g| {
            self.figures(g)
                .iter()
                .map(|f| f.to_json(floor))
                .collect::<Vec<_>>()
        };
        let end_to_end = self
            .figures(Group::EndToEnd)
            .first()
            .map(|f| f.to_json(floor))
            .unwrap_or(serde_json::Value::Null);
        let routes: Vec<serde_json::Value> = [
            (Route::Estimator, s.via_estimator),
            (Route::Direct, s.direct),
        ]
        .iter()
        .filter(|(_, n)| *n > 0)
        .map(|(r, n)| serde_json::json!({ "path": r.path(), "samples": n }))
        .collect();
        serde_json::json!({
            "instance": self.instance,
            "waiting": self.waiting,
            "hops": list(Group::Hop),
            "stages": list(Group::Stage),
            "end_to_end": end_to_end,
            "floor": floor.to_json(floor),
            "link_floor": self.link_floor.as_ref().map(|l| l.to_json(&self.figures(Group::Hop))),
            "samples": self.caused(),
            "routes": routes,
            "sampling": {
                "method": format!(
                    "every ~{} ms, the frames the subscriber's buffer held (no spinning)",
                    POLL_PERIOD.as_millis()
                ),
                "seconds": s.elapsed.as_secs_f64(),
                "instance_went_down": s.ended_early,
                "wake_ups": s.polls,
                "frames": s.frames,
                "frames_without_cause": s.uncaused,
            },
            "steps_per_s": s.steps_per_s(),
            "load_average": self.load,
            "floor_run": {
                "round_trips": self.floor.round_trips,
                "seconds": self.floor_seconds,
                "when": format!("after the sampling, {}", self.floor_when()),
                "paused_processes": self.paused,
                "one_way": "round trip / 2",
            },
        })
    }

    /// Latency histograms of each hop, end to end, the floor and the link floor, log-scaled x.
    fn plot(&self, path: &Path) -> Result<()> {
        let mut series: Vec<(String, &Histogram<u64>)> = self
            .sampling
            .rows
            .iter()
            .filter(|r| r.group != Group::Stage && !r.histogram.is_empty())
            .map(|r| (r.name.to_owned(), &r.histogram))
            .collect();
        if !self.floor.histogram.is_empty() {
            series.push(("floor".to_owned(), &self.floor.histogram));
        }
        if let Some(link) = self.link_floor.as_ref().filter(|l| !l.histogram.is_empty()) {
            series.push((format!("link floor ({})", link.transport), &link.histogram));
        }
        let svg = plot_svg(&series, &self.instance, &self.waiting)?;
        std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))
    }
}

/// Buckets per decade of the plot.
const PLOT_BUCKETS_PER_DECADE: f64 = 20.0;

/// The hops a bridge carries, whichever side of it the profiled instance is: the estimate
/// to the planner and its command back (physics and the estimator run on one side).
const BRIDGED_HOPS: [&str; 2] = ["estimator->planner", "planner->physics"];

/// The floor of a bridge's link: a bare Zenoh ping-pong on its transport.
struct LinkFloor {
    /// `mutual TLS` or `plain TCP`.
    transport: &'static str,
    figures: Figures,
    histogram: Histogram<u64>,
}

impl LinkFloor {
    fn ratio(&self, hops: &[Figures], name: &str) -> Option<f64> {
        hops.iter()
            .find(|h| h.name == name)
            .and_then(|h| h.ratio(&self.figures))
    }

    /// What the profile says of the link: how its floor was measured, and each bridged hop
    /// sampled, its p50 and its ratio to the floor's.
    fn lines(&self, hops: &[Figures]) -> [String; 2] {
        let us = |ns: u64| ns as f64 * 1e-3;
        let against: Vec<String> = BRIDGED_HOPS
            .iter()
            .filter_map(|n| {
                let hop = hops.iter().find(|h| h.name == *n)?;
                let r = self.ratio(hops, n)?;
                Some(format!("{n} {:.2} us = {r:.2}x", us(hop.p50_ns)))
            })
            .collect();
        [
            format!(
                "  link floor ({}): bare Zenoh ping-pong between two `agp` processes over the bridge's transport on the loopback, answered in Zenoh's callback and waited for as the bridge does, one-way = round trip / 2, {} round trips after the iceoryx2 floor: p50 {:.2} us, p99 {:.2} us",
                self.transport,
                self.figures.samples,
                us(self.figures.p50_ns),
                us(self.figures.p99_ns)
            ),
            format!(
                "  the bridged hops against it (p50, {}): {}",
                self.transport,
                if against.is_empty() {
                    "none sampled".to_owned()
                } else {
                    against.join(", ")
                }
            ),
        ]
    }

    fn print(&self, hops: &[Figures], line: impl Fn(&str, &Figures)) {
        line("floor", &self.figures);
        for l in self.lines(hops) {
            println!("{l}");
        }
    }

    fn to_json(&self, hops: &[Figures]) -> serde_json::Value {
        let mut v = self.figures.to_json(&self.figures);
        v["transport"] = serde_json::json!(self.transport);
        v["hops_ratio_to_link_floor_p50"] = BRIDGED_HOPS
            .iter()
            .map(|n| ((*n).to_owned(), serde_json::json!(self.ratio(hops, n))))
            .collect::<serde_json::Map<_, _>>()
            .into();
        v
    }
}

/// The Zenoh floor of instance `name`'s bridge, if one of its processes is an `agp bridge`
/// (its transport, keys and waiting read from its command line and environment), answered
/// in Zenoh's callback and waited for as the bridge does, measured for `seconds` with the pipeline of `pause` paused
/// meanwhile. A floor that cannot be measured is said, and the
/// profile goes on without it.
fn link_floor(name: &str, seconds: f64, pause: Option<&Instance>) -> Option<LinkFloor> {
    let r = control_client::ask(name, agp_shared_types::ControlKind::Status).ok()?;
    let bridge = control::StatusReport::new(name, &r)
        .processes
        .iter()
        .filter_map(|p| p.pid)
        .find_map(crate::bridge_process::bridge_of_process)?;
    let measured = (|| -> Result<(String, crate::bridge_process::FloorFigures)> {
        let mut lease = pause
            .map(|i| PauseLease::take(i, Duration::from_secs_f64(seconds) + LEASE_MARGIN))
            .transpose()
            .context("cannot pause the pipeline for the link floor")?;
        // The lease outlasts the floor by LEASE_MARGIN; it is given back right after.
        let floor =
            crate::bridge_process::zenoh_floor(bridge.tls.as_deref(), bridge.wait, seconds, 64);
        if let Some(lease) = &mut lease {
            lease.release()?;
        }
        floor
    })();
    match measured {
        Ok((locator, f)) => {
            let mut h = histogram();
            for ns in &f.one_way_ns {
                h.saturating_record(*ns);
            }
            let transport = if locator.starts_with("tls/") {
                "mutual TLS"
            } else {
                "plain TCP"
            };
            Some(LinkFloor {
                transport,
                figures: Figures::new("link_floor", &h),
                histogram: h,
            })
        }
        Err(e) => {
            eprintln!("agp profile: the link floor of instance `{name}`'s bridge failed: {e:#}");
            None
        }
    }
}

/// One series of the plot: `(latency us at the bucket's geometric centre, share of the
/// series' samples in the bucket)`.
fn buckets(h: &Histogram<u64>, lo_ns: f64, hi_ns: f64) -> Vec<(f64, f64)> {
    let step = 10f64.powf(1.0 / PLOT_BUCKETS_PER_DECADE);
    let total = h.len().max(1) as f64;
    let mut out = Vec::new();
    let mut a = lo_ns;
    while a < hi_ns {
        let b = a * step;
        let count = h.count_between(a.ceil() as u64, (b.ceil() as u64).saturating_sub(1));
        out.push(((a * b).sqrt() * 1e-3, count as f64 / total));
        a = b;
    }
    out
}

fn draw_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("cannot draw the plot: {e:?}")
}

fn plot_svg(series: &[(String, &Histogram<u64>)], instance: &str, waiting: &str) -> Result<String> {
    use plotters::prelude::*;
    const FONT: &str = "sans-serif";
    let min_ns = series
        .iter()
        .map(|(_, h)| h.min())
        .min()
        .unwrap_or(100)
        .max(10) as f64;
    let max_ns = series
        .iter()
        .map(|(_, h)| h.max())
        .max()
        .unwrap_or(1000)
        .max(100) as f64;
    let lo = 10f64.powf(min_ns.log10().floor());
    let hi = 10f64.powf((max_ns * 1.01).log10().ceil());
    let data: Vec<(String, Vec<(f64, f64)>)> = series
        .iter()
        .map(|(n, h)| (n.clone(), buckets(h, lo, hi)))
        .collect();
    let top = data
        .iter()
        .flat_map(|(_, d)| d.iter().map(|p| p.1))
        .fold(0.0f64, f64::max)
        .max(1e-3)
        * 1.1;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_error)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("latency of instance `{instance}` (waiting `{waiting}`)"),
                (FONT, 18),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((lo * 1e-3..hi * 1e-3).log_scale(), 0.0..top)
            .map_err(draw_error)?;
        chart
            .configure_mesh()
            .x_desc("latency, us (log scale)")
            .y_desc("share of samples per bucket")
            .label_style((FONT, 11))
            .x_label_formatter(&|v| format!("{v}"))
            .draw()
            .map_err(draw_error)?;
        let palette = [
            RGBColor(31, 119, 180),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
            RGBColor(80, 80, 80),
            RGBColor(214, 39, 40),
            RGBColor(148, 103, 189),
            RGBColor(140, 86, 75),
        ];
        for (k, (name, d)) in data.iter().enumerate() {
            let colour = palette[k % palette.len()];
            chart
                .draw_series(LineSeries::new(d.iter().copied(), colour.stroke_width(2)))
                .map_err(draw_error)?
                .label(name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 12))
            .draw()
            .map_err(draw_error)?;
        root.present().map_err(draw_error)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_reads_the_quantiles_of_a_uniform_histogram_within_its_precision() {
        // 1..=1000 us, one each: p50 = 500 us, p99 = 990 us, max = 1000 us, within the
        // histogram's 3 significant digits (0.1 %).
        let mut h = histogram();
        for us in 1..=1000u64 {
            h.record(us * 1000).expect("in bounds");
        }
        let f = Figures::new("x", &h);
        let close = |got: u64, want: u64| (got as f64 - want as f64).abs() <= want as f64 * 1e-3;
        assert!(close(f.p50_ns, 500_000), "p50 {}", f.p50_ns);
        assert!(close(f.p90_ns, 900_000), "p90 {}", f.p90_ns);
        assert!(close(f.p99_ns, 990_000), "p99 {}", f.p99_ns);
        assert!(close(f.p999_ns, 999_000), "p99.9 {}", f.p999_ns);
        assert!(close(f.max_ns, 1_000_000), "max {}", f.max_ns);
    }

    /// The spans of the rows `f`'s step passed, by row name.
    fn spans(f: &IrFrame) -> Vec<(&'static str, u64)> {
        rows()
            .iter()
            .filter_map(|r| match r.span(f) {
                Span::Ns(ns) => Some((r.name, ns)),
                Span::OffRoute => None,
                Span::Missing => panic!("`{}` has no usable stamps", r.name),
            })
            .collect()
    }

    #[test]
    fn the_spans_of_a_frame_are_read_from_its_cause_and_its_own_stamps() {
        let mut f = IrFrame::default();
        f.cause.trace_id = 9;
        for (i, t) in [
            (stage::FRAME_PUBLISHED, 100),
            (stage::PLANNER_RECEIVED, 130),
            (stage::COMMAND_PUBLISHED, 150),
            (stage::COMMAND_RECEIVED, 190),
            (stage::COMMAND_APPLIED, 260),
        ] {
            f.cause.stamps_ns[i] = t;
        }
        f.timing.stamps_ns[stage::FRAME_PUBLISHED] = 275;
        assert_eq!(
            spans(&f),
            [
                ("physics->planner", 30),
                ("planner->physics", 40),
                ("planner", 20),
                ("physics.step", 70),
                ("physics.publish", 15),
                ("end_to_end", 160),
            ]
        );
    }

    #[test]
    fn a_step_through_the_estimator_is_measured_hop_by_hop_along_its_route() {
        let mut f = IrFrame::default();
        f.cause.trace_id = 9;
        for (i, t) in [
            (stage::FRAME_PUBLISHED, 100),
            (stage::ESTIMATOR_RECEIVED, 112),
            (stage::ESTIMATE_PUBLISHED, 120),
            (stage::PLANNER_RECEIVED, 135),
            (stage::COMMAND_PUBLISHED, 150),
            (stage::COMMAND_RECEIVED, 190),
            (stage::COMMAND_APPLIED, 260),
        ] {
            f.cause.stamps_ns[i] = t;
        }
        f.timing.stamps_ns[stage::FRAME_PUBLISHED] = 275;
        assert_eq!(Route::of(&f), Route::Estimator);
        // No physics->planner: PLANNER_RECEIVED is the estimate's receipt, not the frame's.
        assert_eq!(
            spans(&f),
            [
                ("physics->estimator", 12),
                ("estimator->planner", 15),
                ("planner->physics", 40),
                ("estimator", 8),
                ("planner", 15),
                ("physics.step", 70),
                ("physics.publish", 15),
                ("end_to_end", 160),
            ]
        );
    }

    #[test]
    fn a_route_no_sampled_step_took_leaves_no_row_in_the_report() {
        let mut sampling = Sampling {
            rows: rows(),
            frames: 1,
            uncaused: 0,
            via_estimator: 0,
            direct: 1,
            polls: 1,
            steps: 0,
            span_ns: 0,
            elapsed: Duration::from_secs(1),
            ended_early: false,
        };
        for r in &mut sampling.rows {
            if r.route != Route::Estimator {
                r.histogram.record(1_000).expect("in bounds");
            }
        }
        let mut floor = histogram();
        floor.record(500).expect("in bounds");
        let report = Report {
            instance: "t".to_owned(),
            waiting: "block".to_owned(),
            sampling,
            floor_figures: Figures::new("floor", &floor),
            floor: Floor {
                histogram: floor,
                round_trips: 1,
                paused: None,
            },
            floor_seconds: 1.0,
            paused: None,
            load: None,
            link_floor: None,
        };
        let v = report.to_json();
        let names = |k: &str| -> Vec<String> {
            v[k].as_array()
                .expect("a list")
                .iter()
                .map(|r| r["name"].as_str().expect("a name").to_owned())
                .collect()
        };
        assert_eq!(names("hops"), ["physics->planner", "planner->physics"]);
        assert_eq!(
            names("stages"),
            ["planner", "physics.step", "physics.publish"]
        );
        assert_eq!(v["end_to_end"]["name"], "end_to_end");
    }

    #[test]
    fn the_link_floor_says_its_transport_and_sets_each_bridged_hop_against_its_p50() {
        // Figures as a histogram would give them (its quantiles are read to 3 digits).
        let figures = |name: &str, ns: u64| Figures {
            name: name.to_owned(),
            samples: 100,
            p50_ns: ns,
            p90_ns: ns,
            p99_ns: ns,
            p999_ns: ns,
            max_ns: ns,
        };
        let floor = figures("link_floor", 20_000);
        let histogram = histogram();
        let hops = [
            figures("physics->estimator", 2_000),
            figures("estimator->planner", 30_000),
            figures("planner->physics", 25_000),
        ];
        for transport in ["mutual TLS", "plain TCP"] {
            let link = LinkFloor {
                transport,
                figures: floor.clone(),
                histogram: histogram.clone(),
            };
            let [how, against] = link.lines(&hops);
            assert!(how.contains(&format!("link floor ({transport})")), "{how}");
            assert!(how.contains("p50 20.00 us"), "{how}");
            assert_eq!(
                against,
                format!(
                    "  the bridged hops against it (p50, {transport}): estimator->planner 30.00 us = 1.50x, planner->physics 25.00 us = 1.25x"
                )
            );
            let json = link.to_json(&hops);
            assert_eq!(json["transport"], transport);
            assert_eq!(
                json["hops_ratio_to_link_floor_p50"]["estimator->planner"],
                1.5
            );
        }
        // No bridged hop sampled: said so, not a ratio of nothing.
        let link = LinkFloor {
            transport: "plain TCP",
            figures: floor,
            histogram,
        };
        assert!(link.lines(&hops[..1])[1].ends_with("none sampled"));
    }

    #[test]
    fn the_plot_buckets_of_a_histogram_hold_all_its_samples() {
        let mut h = histogram();
        for ns in [150u64, 900, 1_000, 5_000, 80_000] {
            h.record(ns).expect("in bounds");
        }
        let share: f64 = buckets(&h, 100.0, 1e6).iter().map(|b| b.1).sum();
        assert!((share - 1.0).abs() < 1e-9, "share {share}");
    }

    #[test]
    fn a_plot_of_two_series_is_an_svg_naming_both() {
        let mut a = histogram();
        let mut b = histogram();
        for ns in 1_000..2_000u64 {
            a.record(ns).expect("in bounds");
            b.record(ns * 3).expect("in bounds");
        }
        let svg = plot_svg(
            &[("hop".to_owned(), &a), ("floor".to_owned(), &b)],
            "t",
            "block",
        )
        .expect("a plot");
        assert!(svg.starts_with("<svg"));
        assert!(svg.contains("hop") && svg.contains("floor"));
    }
}
