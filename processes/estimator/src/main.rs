//! The estimator process: perceives the robot and the object from IR frames, learns the object's affordance gradients, and publishes both zero-copy.
//!
//! Perception, in every phase: for each IR frame it publishes an [`ObjectEstimate`] (the
//! robot's fused pose, the front gap and contact, and in a task the object's pose by
//! matching the circled border to the learned shape and tracking it through the pushes
//! the planner announces, see [`agp_perception::ObjectTracker`]); the planner acts on a
//! frame only once it has the frame's estimate.
//!
//! Learning:
//! It reads IR frames (readings and odometry: never ground truth) and the planner's
//! [`LearnEvent`]s, feeds an [`agp_perception::LearningSession`], reports each trial on the
//! learn reports topic and acknowledges every frame with an [`ObjectEstimate`] of the same
//! publish stamp (the planner in `learn` mode waits for it, so no frame is lost). When the
//! planner says learning is done it writes every grid (per alpha the paper's S, Px, Py, R+,
//! R- and the statistics a planner rebuilds the gradient from: every [`GridKind`]) straight
//! into loaned shared-memory samples, sends the `Learned` report and saves the AG file to
//! `$AGP_RESULTS/<object>.ag`. With `--load FILE` it publishes the grids of a saved file at
//! once instead of learning (a restarted estimator gets its gradients back).
//!
//! Order: the planner sends an event about a frame before the command that makes the next
//! frame, so draining the events before each frame hands them over in protocol order.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use agp_affordance::{AffordanceGradient, ContactPriorConfig};
use agp_perception::{
    IrView, LearnProblem, LearningConfig, ObjectTracker, OnlineLearningConfig, ProtocolLearner,
    TrackerConfig,
};
use agp_runtime::{
    AgpIpc, Instance, WaitOutcome, WaitStrategy, Waiter, alloc_count, install_shutdown_handler,
};
use agp_shared_types::{
    EstimatorLearning, GradientGrid, GridKind, IrFrame, LearnEvent, LearnEventKind, LearnReport,
    LearnReportKind, MAX_GRID_ALPHAS, ObjectEstimate, monotonic_ns, stage,
};
use agp_world::{RobotDescription, ScenarioBrief};
use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::Node;

/// Learns affordance gradients from IR frames and publishes them.
///
/// Every option can also come from the environment the supervisor sets (`AGP_INSTANCE`,
/// `AGP_SCENARIO`, `AGP_RESULTS`).
#[derive(Debug, Parser)]
#[command(name = "agp-estimator", version)]
struct Args {
    /// Instance name, shared with the other processes of the pipeline.
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    /// Built-in scenario or scenario file: which object is learned (its name: its shape and
    /// size are learned from the shape circling).
    #[arg(long, env = "AGP_SCENARIO", default_value = "triangle")]
    scenario: String,
    /// Folder the AG file is saved in, as `<object>.ag`.
    #[arg(long, env = "AGP_RESULTS", default_value = "results")]
    results: PathBuf,
    /// Publish the gradients of this AG file at once instead of learning.
    #[arg(long, conflicts_with = "reuse")]
    load: Option<PathBuf>,
    /// Publish the gradients saved in `<results>/<object>.ag` when that file exists, and
    /// learn (and save it) otherwise: what a run that learns once and then reuses wants. A
    /// restarted estimator gets its gradients back from the file.
    #[arg(long)]
    reuse: bool,
    /// Perceive only: neither learn nor serve gradients (for a planner that needs none,
    /// such as `baseline`). The estimates carry the robot, contact and the object's
    /// centroid; no pose without a gradient.
    #[arg(long, conflicts_with_all = ["load", "reuse"])]
    perceive_only: bool,
    /// Learn on from every push of a task whose effect a circling observes (weighted
    /// towards recent pushes, see `agp_perception::OnlineLearner`) and publish the grids
    /// again after each: the planner plans its next pushes on them. Off by default: the
    /// paper's tasks plan on the gradient of the learning phase, and every figure measured
    /// so far is of a frozen gradient.
    #[arg(long, env = "AGP_LEARN_ONLINE")]
    learn_online: bool,
    /// An object never pushed before: no AG file and no learning phase. The task's first
    /// circling gives the gradient, the prior that the contact geometry of that circling
    /// gives (`agp_affordance::contact_prior`: a push through the centroid translates the
    /// object along the push, an offset one turns it by its lever arm about the border's
    /// centroid), published as grids seq 1; the task's pushes learn on from it (needs
    /// `--learn-online`). Nothing is saved.
    #[arg(long, requires = "learn_online", conflicts_with_all = ["load", "reuse", "perceive_only"])]
    from_prior: bool,
    /// Exit with an error when neither a frame nor an event arrives for this long,
    /// seconds; 0 waits until SIGTERM.
    #[arg(long, default_value_t = 0)]
    idle_timeout_s: u64,
}

/// Counts heap allocations by region when `AGP_COUNT_ALLOCS=1` (see
/// [`agp_runtime::alloc_count`]): the estimator's per-frame loop allocates none.
#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

fn main() {
    agp_runtime::quiet_iceoryx2();
    alloc_count::enable_from_env();
    let result = run();
    alloc_count::report("agp-estimator", "learning", "frames");
    if let Err(e) = result {
        eprintln!("agp-estimator: error: {e:#}");
        std::process::exit(1);
    }
}

/// Longest single wait of the main loop: after it, late subscribers are connected (and get
/// the publishers' history, with a notification to wake them for it) and the idle limit is
/// checked. A new planner waits for that history while the ring is idle, once per episode
/// of a benchmark: the slice is its latency.
const WAIT_SLICE: Duration = Duration::from_millis(5);
/// While frames keep coming, late subscribers are connected at this period.
const FLOWING_UPDATE: Duration = Duration::from_millis(20);

fn run() -> Result<()> {
    let args = Args::parse();
    install_shutdown_handler();
    // The brief: the name, the robot, the task; nothing of the object.
    let scenario = ScenarioBrief::resolve(&args.scenario)?;
    let instance = Instance::new(&args.instance)
        .with_context(|| format!("bad instance name `{}`", args.instance))?;
    let saved = args.results.join(format!("{}.ag", scenario.name));
    let load = match (&args.load, args.reuse) {
        (Some(path), _) => Some(path.clone()),
        (None, true) if saved.is_file() => Some(saved.clone()),
        (None, true) => {
            println!(
                "agp-estimator: no AG file at {}: learning `{}` from the planner's trials",
                saved.display(),
                scenario.name
            );
            None
        }
        (None, false) => None,
    };
    let learns = load.is_none() && !args.perceive_only && !args.from_prior;
    if learns {
        // Learning ends by saving there: find out now, not after the whole protocol.
        check_ag_destination(&saved)?;
    }
    let mut estimator = Estimator::open(&instance, &scenario, !learns, &args)?;
    if args.from_prior {
        estimator
            .state
            .tracker
            .start_from_prior(&scenario.name, ContactPriorConfig::default());
        println!(
            "agp-estimator: `{}` was never pushed: its gradient will be the contact prior of the task's first circling, learned on from every push",
            scenario.name
        );
    }
    if let Some(path) = &load {
        let gradient = AffordanceGradient::load_for(path, &scenario.name)
            .with_context(|| format!("cannot load the AG file {}", path.display()))?;
        estimator.publish(&gradient)?;
        estimator.report(LearnReport {
            kind: LearnReportKind::Learned as u32,
            valid: 1,
            grids_seq: estimator.state.grids_seq,
            ..LearnReport::default()
        })?;
        println!(
            "agp-estimator: published the gradients of {} (grids seq {})",
            path.display(),
            estimator.state.grids_seq
        );
    }
    let idle = (args.idle_timeout_s > 0).then(|| Duration::from_secs(args.idle_timeout_s));
    let mut last_input = Instant::now();
    let mut last_update = Instant::now();
    loop {
        let outcome = {
            let waiter = &estimator.waiter;
            let state = &mut estimator.state;
            waiter.wait_for(WAIT_SLICE, || match state.poll() {
                Ok(true) => Some(Ok(())),
                Ok(false) => None,
                Err(e) => Some(Err(e)),
            })
        };
        match outcome {
            WaitOutcome::Ready(r) => {
                r?;
                last_input = Instant::now();
                // iceoryx2 hands a publisher's history (the grids) to a new subscriber
                // only in the publisher's `update_connections`: while frames keep coming
                // the wait never times out, and a planner swapped in beside a driving one
                // would never get its gradients.
                if last_update.elapsed() >= FLOWING_UPDATE {
                    last_update = Instant::now();
                    estimator.update_connections()?;
                }
            }
            WaitOutcome::Shutdown => return Ok(()),
            WaitOutcome::TimedOut => {
                estimator.update_connections()?;
                // History reaches a new subscriber without a notification of its own:
                // wake its reader now rather than at the end of its block slice.
                estimator.wake_readers();
                if let Some(limit) = idle
                    && last_input.elapsed() > limit
                {
                    bail!("no IR frame and no learn event for {limit:?}");
                }
            }
        }
        if let Some(gradient) = estimator.state.finished.take() {
            estimator.finish(&gradient)?;
        }
        if let Some(failed) = estimator.save_failed.take() {
            // The planner has the `Learned` report saying so; give it a moment to read it
            // before this process (and its publishers) goes.
            std::thread::sleep(Duration::from_millis(200));
            return Err(failed);
        }
    }
}

/// The ports and the learning state.
struct Estimator {
    _node: Node<AgpIpc>,
    waiter: Waiter,
    state: State,
    results: PathBuf,
    /// Set when the AG file could not be saved: the process ends with this error.
    save_failed: Option<anyhow::Error>,
}

/// What the main loop's poll works on.
struct State {
    frames: Subscriber<AgpIpc, IrFrame, ()>,
    events: Subscriber<AgpIpc, LearnEvent, ()>,
    estimates: Publisher<AgpIpc, ObjectEstimate, ()>,
    estimates_wake: Notifier<AgpIpc>,
    reports: Publisher<AgpIpc, LearnReport, ()>,
    reports_wake: Notifier<AgpIpc>,
    /// The learner of the planner's protocol (`None` with `--load` or `--perceive-only`).
    learner: Option<ProtocolLearner>,
    report_seq: u64,
    /// Set when the planner said learning is done: the gradient to publish and save.
    finished: Option<AffordanceGradient>,
    grids: Publisher<AgpIpc, GradientGrid, ()>,
    grids_wake: Notifier<AgpIpc>,
    /// The seq of the last set of grids published (0: none yet).
    grids_seq: u64,
    /// The tracker's gradient generation last published (online learning).
    published_generation: u64,
    /// The object's name, for what is said on stdout.
    object: String,
    /// When this estimator started (CLOCK_MONOTONIC, ns): carried by every estimate, so a
    /// planner sees a restarted estimator.
    start_ns: u64,
    /// Perception: the robot, contact, and the object in a task.
    tracker: ObjectTracker,
    /// The newest planner session whose task events the tracker takes (a planner swapped
    /// in supersedes the one it replaces).
    task_session: u64,
    /// The newest event taken in: its session and seq, carried by every estimate
    /// ([`ObjectEstimate::event_seq`]).
    event_session: u64,
    event_seq: u64,
    /// Step of the last frame observed (a smaller one: physics restarted).
    last_step: Option<u64>,
    /// Reset count of the last frame observed (another: the world was put back).
    last_reset: Option<u64>,
}

fn open_err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot open {what}: {e:?}")
}

impl Estimator {
    fn open(
        instance: &Instance,
        scenario: &ScenarioBrief,
        loading: bool,
        args: &Args,
    ) -> Result<Self> {
        let node = instance
            .node("estimator", false)
            .map_err(open_err("the estimator node"))?;
        let frames = instance
            .ir_frames(&node)
            .map_err(open_err("the IR frames"))?;
        let events = instance
            .learn_events(&node)
            .map_err(open_err("the learn events"))?;
        let estimates = instance
            .estimates(&node)
            .map_err(open_err("the estimates"))?;
        let reports = instance
            .learn_reports(&node)
            .map_err(open_err("the learn reports"))?;
        let grids = instance.grids(&node).map_err(open_err("the grids"))?;
        let learner = if loading {
            None
        } else {
            Some(learner(scenario)?)
        };
        let state = State {
            frames: frames
                .subscriber()
                .create()
                .map_err(open_err("the IR frame subscriber"))?,
            events: events
                .subscriber()
                .create()
                .map_err(open_err("the learn event subscriber"))?,
            estimates: estimates
                .data
                .publisher_builder()
                .create()
                .map_err(open_err("the estimate publisher"))?,
            estimates_wake: estimates
                .event
                .notifier_builder()
                .create()
                .map_err(open_err("the estimate notifier"))?,
            reports: reports
                .data
                .publisher_builder()
                .create()
                .map_err(open_err("the report publisher"))?,
            reports_wake: reports
                .event
                .notifier_builder()
                .create()
                .map_err(open_err("the report notifier"))?,
            learner,
            report_seq: 0,
            finished: None,
            grids: grids
                .data
                .publisher_builder()
                .create()
                .map_err(open_err("the grid publisher"))?,
            grids_wake: grids
                .event
                .notifier_builder()
                .create()
                .map_err(open_err("the grid notifier"))?,
            grids_seq: 0,
            published_generation: 0,
            object: scenario.name.clone(),
            start_ns: monotonic_ns(),
            tracker: ObjectTracker::new(
                &RobotDescription::epuck(),
                TrackerConfig {
                    online: OnlineLearningConfig {
                        enabled: args.learn_online,
                        ..OnlineLearningConfig::default()
                    },
                    ..TrackerConfig::default()
                },
            ),
            task_session: 0,
            event_session: 0,
            event_seq: 0,
            last_step: None,
            last_reset: None,
        };
        // Frames and learn events notify the same event service.
        let listener = frames
            .event
            .listener_builder()
            .create()
            .map_err(open_err("the IR frame listener"))?;
        Ok(Self {
            waiter: Waiter::new(listener, WaitStrategy::from_env()),
            state,
            results: args.results.clone(),
            save_failed: None,
            _node: node,
        })
    }

    fn report(&mut self, r: LearnReport) -> Result<()> {
        self.state.report(r)
    }

    /// Connects subscribers that came since the last send: a publisher hands its history
    /// (the latest estimate, the grids) to a new subscriber only then.
    fn update_connections(&self) -> Result<()> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.state
            .estimates
            .update_connections()
            .map_err(|e| anyhow!("cannot update the estimate connections: {e:?}"))?;
        self.state
            .reports
            .update_connections()
            .map_err(|e| anyhow!("cannot update the report connections: {e:?}"))?;
        self.state
            .grids
            .update_connections()
            .map_err(|e| anyhow!("cannot update the grid connections: {e:?}"))
    }

    /// Notifies every topic's event, with nothing new sent: a reader that just connected
    /// polls, and finds the history [`Self::update_connections`] handed it.
    fn wake_readers(&self) {
        // A notifier connects to listeners that came since its last notification here.
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let _ = self.state.estimates_wake.notify();
        let _ = self.state.reports_wake.notify();
        let _ = self.state.grids_wake.notify();
    }

    /// Publishes every grid of `gradient` (every [`GridKind`] of every alpha: one set), each
    /// written once straight into its loaned sample, and gives it to the tracker.
    fn publish(&mut self, gradient: &AffordanceGradient) -> Result<()> {
        let state = &mut self.state;
        state.grids_seq += 1;
        publish_grids(&state.grids, gradient, state.grids_seq)?;
        let _ = state.grids_wake.notify();
        if let Err(e) = state.tracker.set_gradient(gradient) {
            eprintln!(
                "agp-estimator: the gradient of `{}` cannot locate the object in a task: {e}",
                state.object
            );
        }
        state.published_generation = state.tracker.gradient_generation();
        Ok(())
    }

    /// Learning is done: publishes the grids, reports `Learned`, saves the AG file.
    fn finish(&mut self, gradient: &AffordanceGradient) -> Result<()> {
        self.publish(gradient)?;
        let path = self.results.join(format!("{}.ag", self.state.object));
        let saved = save(gradient, &path);
        let report = match &self.state.learner {
            Some(l) => l.learned_report(self.state.grids_seq, saved.is_ok()),
            None => LearnReport {
                kind: LearnReportKind::Learned as u32,
                valid: u32::from(saved.is_ok()),
                grids_seq: self.state.grids_seq,
                ..LearnReport::default()
            },
        };
        let (learned, rejected, total) = (
            report.trials_learned,
            report.trials_rejected,
            report.trials_total,
        );
        self.report(report)?;
        println!(
            "agp-estimator: learned `{}`: {learned} trials learned, {rejected} rejected of {total}; {} grids published (seq {}); AG file {}",
            self.state.object,
            gradient.alphas_deg().count() * GridKind::ALL.len(),
            self.state.grids_seq,
            if saved.is_ok() {
                path.display().to_string()
            } else {
                "not saved".into()
            }
        );
        for alpha in gradient.alphas_deg() {
            println!(
                "agp-estimator:   alpha {alpha:+.0} deg: {} pushes, largest rotation {}",
                gradient.push_count(alpha).unwrap_or(0),
                gradient
                    .max_rotation_deg(alpha)
                    .map_or("none".into(), |r| format!("{r:.2} deg"))
            );
        }
        self.save_failed = saved.err();
        Ok(())
    }
}

/// Writes every grid of `gradient` as set `seq`, each straight into its loaned sample.
fn publish_grids(
    grids: &Publisher<AgpIpc, GradientGrid, ()>,
    gradient: &AffordanceGradient,
    seq: u64,
) -> Result<()> {
    let alphas = gradient.alphas_deg().count();
    if alphas > MAX_GRID_ALPHAS {
        bail!(
            "the gradient has {alphas} alphas; the grids topic holds a set of at most {MAX_GRID_ALPHAS}"
        );
    }
    for alpha in gradient.alphas_deg() {
        for kind in GridKind::ALL {
            let sample = grids
                .loan_uninit()
                .map_err(|e| anyhow!("cannot loan a grid sample: {e:?}"))?;
            // SAFETY: the sample is shared memory mapped from a file: its bytes are
            // always initialised (zeros, or an older sample's), and every bit pattern
            // is a valid `GradientGrid` (integers and floats only, no padding), so
            // taking it as initialised reads nothing undefined. `write_component`
            // then overwrites the header and every cell.
            let mut sample = unsafe { sample.assume_init() };
            gradient
                .write_component(alpha, kind, seq, sample.payload_mut())
                .map_err(|e| anyhow!("cannot write a grid: {e}"))?;
            sample
                .send()
                .map_err(|e| anyhow!("cannot send a grid: {e:?}"))?;
        }
    }
    Ok(())
}

/// Fails when learning could not end by saving the AG file at `path`: a directory (or
/// anything but a regular file) in its place, or a results folder that cannot be created or
/// written. Learning takes minutes; this takes a moment.
fn check_ag_destination(path: &Path) -> Result<()> {
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
    {
        bail!(
            "the AG file {} is a directory or a special file, not a file: learning could not save there; move it away",
            path.display()
        );
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the results folder {}", dir.display()))?;
    let probe = dir.join(format!(".agp-estimator-probe-{}", std::process::id()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(anyhow!(
            "cannot write in the results folder {}: {e}; learning could not save the AG file {}",
            dir.display(),
            path.display()
        )),
    }
}

fn save(gradient: &AffordanceGradient, path: &Path) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the results folder {}", dir.display()))?;
    }
    gradient
        .save(path)
        .with_context(|| format!("cannot save the AG file {}", path.display()))
}

/// The learner of `scenario`'s object: its symmetry order and its size are learned from
/// the shape circling (an object too large for the gradient's grid fails there, see
/// [`agp_perception::ShapeLearnError::TooLarge`]); the scenario gives only its name.
fn learner(scenario: &ScenarioBrief) -> Result<ProtocolLearner> {
    let robot = RobotDescription::epuck();
    ProtocolLearner::new(&scenario.name, &robot, LearningConfig::default())
        .with_context(|| format!("cannot learn `{}`", scenario.name))
}

impl State {
    /// Handles what arrived: returns whether anything did. Each frame is preceded by the
    /// events sent before it, and acknowledged once observed. A frame allocates nothing
    /// (`tests/tests/pipeline_allocations.rs` counts).
    fn poll(&mut self) -> Result<bool> {
        let mut any = self.drain_events()?;
        self.republish_learned()?;
        loop {
            let frame = {
                let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
                match self.frames.receive() {
                    Ok(Some(f)) => *f,
                    Ok(None) => break,
                    Err(e) => bail!("cannot receive an IR frame: {e:?}"),
                }
            };
            any = true;
            let received = monotonic_ns();
            self.drain_events()?;
            {
                let _in_perception = alloc_count::enter(alloc_count::Region::Work);
                if self.last_step.is_some_and(|last| frame.step < last)
                    || self.last_reset.is_some_and(|r| r != frame.reset_seq)
                {
                    // Physics restarted, or the experimenter put the object and the robot
                    // back: a new world, nothing where it was.
                    self.tracker.reset();
                }
                self.last_step = Some(frame.step);
                self.last_reset = Some(frame.reset_seq);
                self.tracker.observe(
                    frame.ir_sample,
                    &frame.ir_raw,
                    frame.odometry,
                    frame.fix,
                    frame.fix_seq,
                );
            }
            if let Some(l) = &mut self.learner {
                let _in_learning = alloc_count::enter(alloc_count::Region::Work);
                l.observe(&IrView::from(&frame));
            }
            // Online learning: what the events before this frame taught goes out before
            // the frame's estimate, which carries its seq (as the in-process world's
            // estimate does): a planner that steps one frame after a circling plans the
            // next push on what that circling taught.
            self.republish_learned()?;
            self.acknowledge(&frame, received)?;
            alloc_count::message_done();
        }
        Ok(any)
    }

    /// Online learning: when the tracker learned a push (or built the prior) since the
    /// last publication, its gradient is published again as a new set (the next seq),
    /// before the estimate of the frame under way: that estimate and every later one carry
    /// the new seq, which tells the planner. Allocates nothing but what is said on stdout.
    fn republish_learned(&mut self) -> Result<()> {
        let generation = self.tracker.gradient_generation();
        if generation == self.published_generation {
            return Ok(());
        }
        let Some(gradient) = self.tracker.gradient() else {
            return Ok(());
        };
        self.grids_seq += 1;
        publish_grids(&self.grids, gradient, self.grids_seq)?;
        let _ = self.grids_wake.notify();
        let first = self.published_generation == 0;
        self.published_generation = generation;
        if first {
            println!(
                "agp-estimator: built the contact prior of `{}` from the first circling: grids seq {} published",
                self.object, self.grids_seq
            );
            return Ok(());
        }
        println!(
            "agp-estimator: learned a push online ({} since the gradient was given): grids seq {} published",
            self.tracker.pushes_learned(),
            self.grids_seq
        );
        Ok(())
    }

    fn drain_events(&mut self) -> Result<bool> {
        let mut any = false;
        loop {
            let event = {
                let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
                match self.events.receive() {
                    Ok(Some(e)) => *e,
                    Ok(None) => return Ok(any),
                    Err(e) => bail!("cannot receive a learn event: {e:?}"),
                }
            };
            any = true;
            let _in_learning = alloc_count::enter(alloc_count::Region::Work);
            self.handle(&event)?;
            (self.event_session, self.event_seq) = (event.session, event.seq);
        }
    }

    /// The frame's estimate: no pose during learning, the frame's trace and publish stamp.
    fn acknowledge(&mut self, frame: &IrFrame, received_ns: u64) -> Result<()> {
        let learning = match &self.learner {
            Some(l) if l.is_learning() && l.learn_session() == 0 => EstimatorLearning::Waiting,
            Some(l) if l.is_learning() => EstimatorLearning::UnderWay,
            _ => EstimatorLearning::No,
        };
        let mut e = ObjectEstimate {
            step: frame.step,
            grids_seq: self.grids_seq,
            learning: learning as u8,
            estimator_start_ns: self.start_ns,
            event_session: self.event_session,
            event_seq: self.event_seq,
            ..ObjectEstimate::default()
        };
        self.tracker.write_estimate(&mut e);
        e.timing.trace_id = frame.timing.trace_id;
        e.timing.stamps_ns[stage::FRAME_PUBLISHED] = frame.timing.stamps_ns[stage::FRAME_PUBLISHED];
        e.timing.stamps_ns[stage::ESTIMATOR_RECEIVED] = received_ns;
        e.timing.stamps_ns[stage::ESTIMATE_PUBLISHED] = monotonic_ns();
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let sample = self
            .estimates
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan an estimate: {e:?}"))?;
        sample
            .write_payload(e)
            .send()
            .map_err(|e| anyhow!("cannot send an estimate: {e:?}"))?;
        let _ = self.estimates_wake.notify();
        Ok(())
    }

    fn report(&mut self, mut r: LearnReport) -> Result<()> {
        self.report_seq += 1;
        r.seq = self.report_seq;
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let sample = self
            .reports
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan a report: {e:?}"))?;
        sample
            .write_payload(r)
            .send()
            .map_err(|e| anyhow!("cannot send a report: {e:?}"))?;
        let _ = self.reports_wake.notify();
        Ok(())
    }

    fn handle(&mut self, event: &LearnEvent) -> Result<()> {
        let Some(kind) = LearnEventKind::from_u32(event.kind) else {
            eprintln!("agp-estimator: unknown learn event kind {}", event.kind);
            return Ok(());
        };
        if matches!(
            kind,
            LearnEventKind::TaskCircleBegin
                | LearnEventKind::TaskCircleEnd
                | LearnEventKind::TaskPushBegin
                | LearnEventKind::TaskPushEnd
        ) {
            // A planner swapped in beside a running one sends with a newer session: from
            // its first event on, the old one's are stale.
            if event.session >= self.task_session {
                self.task_session = event.session;
                self.tracker.handle(event);
            }
            return Ok(());
        }
        // A step of the learning protocol: the learner's (nothing after learning, or with
        // the gradients from a file).
        let Some(learner) = &mut self.learner else {
            return Ok(());
        };
        let reply = learner.handle(event)?;
        match &reply.problem {
            // A planner that restarted: news, not a fault.
            Some(p @ LearnProblem::SessionRestarted { .. }) => println!("agp-estimator: {p}"),
            Some(p) => eprintln!("agp-estimator: {p}"),
            None => {}
        }
        if reply.finished {
            self.finished = learner.take_gradient();
        }
        if let Some(r) = reply.report {
            self.report(r)?;
        }
        Ok(())
    }
}
