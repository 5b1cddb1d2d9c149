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

use agp_affordance::AffordanceGradient;
use agp_perception::{
    IrView, LearningConfig, LearningSession, ObjectTracker, TrackerConfig, TrialPhase,
};
use agp_runtime::{
    AgpIpc, Instance, WaitOutcome, WaitStrategy, Waiter, alloc_count, install_shutdown_handler,
};
use agp_shared_types::{
    EstimatorLearning, GRID_SIDE, GradientGrid, GridKind, IrFrame, LearnEvent, LearnEventKind,
    LearnReport, LearnReportKind, MAX_GRID_ALPHAS, ObjectEstimate, monotonic_ns, stage,
};
use agp_world::{RobotDescription, Scenario};
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
    /// Built-in scenario or scenario file: which object is learned (its name and symmetry).
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
    alloc_count::enable_from_env();
    let result = run();
    alloc_count::report("agp-estimator", "learning", "frames");
    if let Err(e) = result {
        eprintln!("agp-estimator: error: {e:#}");
        std::process::exit(1);
    }
}

/// Longest single wait of the main loop: after it, late subscribers are connected (and get
/// the publishers' history) and the idle limit is checked.
const WAIT_SLICE: Duration = Duration::from_millis(20);

fn run() -> Result<()> {
    let args = Args::parse();
    install_shutdown_handler();
    let scenario = Scenario::resolve(&args.scenario)?;
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
    if load.is_none() && !args.perceive_only {
        // Learning ends by saving there: find out now, not after the whole protocol.
        check_ag_destination(&saved)?;
    }
    let learns = load.is_none() && !args.perceive_only;
    let mut estimator = Estimator::open(&instance, &scenario, !learns, &args)?;
    if let Some(path) = &load {
        let gradient = AffordanceGradient::load_for(path, &scenario.name)
            .with_context(|| format!("cannot load the AG file {}", path.display()))?;
        estimator.publish(&gradient)?;
        estimator.report(LearnReport {
            kind: LearnReportKind::Learned as u32,
            valid: 1,
            grids_seq: estimator.grids_seq,
            ..LearnReport::default()
        })?;
        println!(
            "agp-estimator: published the gradients of {} (grids seq {})",
            path.display(),
            estimator.grids_seq
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
                if last_update.elapsed() >= WAIT_SLICE {
                    last_update = Instant::now();
                    estimator.update_connections()?;
                }
            }
            WaitOutcome::Shutdown => return Ok(()),
            WaitOutcome::TimedOut => {
                estimator.update_connections()?;
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
    grids: Publisher<AgpIpc, GradientGrid, ()>,
    grids_wake: Notifier<AgpIpc>,
    grids_seq: u64,
    results: PathBuf,
    object: String,
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
    /// The session under way (`None` once learning ended, or with `--load`).
    session: Option<LearningSession>,
    report_seq: u64,
    trials_total: u32,
    /// Set when the planner said learning is done: the gradient to publish and save.
    finished: Option<AffordanceGradient>,
    /// Trials learned and rejected when the session ended.
    final_counts: (u32, u32),
    grids_seq: u64,
    /// The planner's learning session the learning session holds (0: no event yet).
    learn_session: u64,
    /// When this estimator started (CLOCK_MONOTONIC, ns): carried by every estimate, so a
    /// planner sees a restarted estimator.
    start_ns: u64,
    /// The scenario learned, for a session started over.
    scenario: Scenario,
    /// Perception: the robot, contact, and the object in a task.
    tracker: ObjectTracker,
    /// The newest planner session whose task events the tracker takes (a planner swapped
    /// in supersedes the one it replaces).
    task_session: u64,
    /// Step of the last frame observed (a smaller one: physics restarted).
    last_step: Option<u64>,
}

fn open_err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot open {what}: {e:?}")
}

fn view(e: &LearnEvent) -> IrView {
    IrView::new(e.ir_sample, e.ir_raw, e.odometry)
}

impl Estimator {
    fn open(instance: &Instance, scenario: &Scenario, loading: bool, args: &Args) -> Result<Self> {
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
        let session = if loading {
            None
        } else {
            Some(session(scenario)?)
        };
        let state = State {
            frames: frames
                .data
                .subscriber_builder()
                .create()
                .map_err(open_err("the IR frame subscriber"))?,
            events: events
                .data
                .subscriber_builder()
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
            session,
            report_seq: 0,
            trials_total: 0,
            finished: None,
            final_counts: (0, 0),
            grids_seq: 0,
            learn_session: 0,
            start_ns: monotonic_ns(),
            scenario: scenario.clone(),
            tracker: ObjectTracker::new(&RobotDescription::epuck(), TrackerConfig::default()),
            task_session: 0,
            last_step: None,
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
            results: args.results.clone(),
            object: scenario.name.clone(),
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
        self.state
            .estimates
            .update_connections()
            .map_err(|e| anyhow!("cannot update the estimate connections: {e:?}"))?;
        self.state
            .reports
            .update_connections()
            .map_err(|e| anyhow!("cannot update the report connections: {e:?}"))?;
        self.grids
            .update_connections()
            .map_err(|e| anyhow!("cannot update the grid connections: {e:?}"))
    }

    /// Publishes every grid of `gradient` (every [`GridKind`] of every alpha: one set), each
    /// written once straight into its loaned sample.
    fn publish(&mut self, gradient: &AffordanceGradient) -> Result<()> {
        let alphas = gradient.alphas_deg().count();
        if alphas > MAX_GRID_ALPHAS {
            bail!(
                "the gradient has {alphas} alphas; the grids topic holds a set of at most {MAX_GRID_ALPHAS}"
            );
        }
        self.grids_seq += 1;
        let seq = self.grids_seq;
        for alpha in gradient.alphas_deg() {
            for kind in GridKind::ALL {
                let sample = self
                    .grids
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
        let _ = self.grids_wake.notify();
        self.state.grids_seq = seq;
        if let Err(e) = self.state.tracker.set_gradient(gradient) {
            eprintln!(
                "agp-estimator: the gradient of `{}` cannot locate the object in a task: {e}",
                self.object
            );
        }
        Ok(())
    }

    /// Learning is done: publishes the grids, reports `Learned`, saves the AG file.
    fn finish(&mut self, gradient: &AffordanceGradient) -> Result<()> {
        self.publish(gradient)?;
        let path = self.results.join(format!("{}.ag", self.object));
        let saved = save(gradient, &path);
        let (learned, rejected) = self.state.counts();
        self.report(LearnReport {
            kind: LearnReportKind::Learned as u32,
            trials_learned: learned,
            trials_rejected: rejected,
            trials_total: self.state.trials_total,
            valid: u32::from(saved.is_ok()),
            grids_seq: self.grids_seq,
            ..LearnReport::default()
        })?;
        println!(
            "agp-estimator: learned `{}`: {learned} trials learned, {rejected} rejected of {}; {} grids published (seq {}); AG file {}",
            self.object,
            self.state.trials_total,
            gradient.alphas_deg().count() * GridKind::ALL.len(),
            self.grids_seq,
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

/// The learning session of `scenario`'s object.
fn session(scenario: &Scenario) -> Result<LearningSession> {
    let robot = RobotDescription::epuck();
    let shape = &scenario.object.shape;
    let config = LearningConfig::for_symmetry(shape.symmetry_order());
    let half_extent = config.learner.cell_size_m * GRID_SIDE as f64 / 2.0;
    if shape.radius().is_nan() || shape.radius() >= half_extent {
        bail!(
            "`{}` is too large to learn: it reaches {:.0} mm from its centroid, the gradient's grid only {:.0} mm",
            scenario.name,
            shape.radius() * 1e3,
            half_extent * 1e3
        );
    }
    LearningSession::new(&scenario.name, &robot, config)
        .with_context(|| format!("cannot learn `{}`", scenario.name))
}

impl State {
    fn counts(&self) -> (u32, u32) {
        self.session.as_ref().map_or(self.final_counts, |s| {
            (s.trials_learned() as u32, s.trials_rejected() as u32)
        })
    }

    /// Handles what arrived: returns whether anything did. Each frame is preceded by the
    /// events sent before it, and acknowledged once observed. A frame allocates nothing
    /// (`tests/tests/pipeline_allocations.rs` counts).
    fn poll(&mut self) -> Result<bool> {
        let mut any = self.drain_events()?;
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
                if self.last_step.is_some_and(|last| frame.step < last) {
                    // Physics restarted: a new world, the object no longer where it was.
                    self.tracker.reset();
                }
                self.last_step = Some(frame.step);
                self.tracker.observe(
                    frame.ir_sample,
                    &frame.ir_raw,
                    frame.odometry,
                    frame.fix,
                    frame.fix_seq,
                );
            }
            if let Some(s) = &mut self.session {
                let _in_learning = alloc_count::enter(alloc_count::Region::Work);
                s.observe(&IrView::from(&frame));
            }
            self.acknowledge(&frame, received)?;
            alloc_count::message_done();
        }
        Ok(any)
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
        }
    }

    /// The frame's estimate: no pose during learning, the frame's trace and publish stamp.
    fn acknowledge(&mut self, frame: &IrFrame, received_ns: u64) -> Result<()> {
        let learning = match (&self.session, self.learn_session) {
            (None, _) => EstimatorLearning::No,
            (Some(_), 0) => EstimatorLearning::Waiting,
            (Some(_), _) => EstimatorLearning::UnderWay,
        };
        let mut e = ObjectEstimate {
            step: frame.step,
            grids_seq: self.grids_seq,
            learning: learning as u8,
            estimator_start_ns: self.start_ns,
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

    /// A trial report of `kind` for `event`, with the counts so far.
    fn trial_report(&self, kind: LearnReportKind, event: &LearnEvent) -> LearnReport {
        let (learned, rejected) = self.counts();
        LearnReport {
            kind: kind as u32,
            index: event.index,
            trials_learned: learned,
            trials_rejected: rejected,
            trials_total: self.trials_total,
            step: event.step,
            alpha_deg: event.alpha_deg,
            grids_seq: self.grids_seq,
            ..LearnReport::default()
        }
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
        if self.session.is_none() || kind as u32 > LearnEventKind::LearningDone as u32 {
            // Learning is over (or the gradients came from a file), or not a step of the
            // learning protocol.
            return Ok(());
        }
        if event.session != self.learn_session {
            if self.learn_session != 0 {
                // Another run of the protocol: its planner restarted. Everything learned
                // from the previous one (a half-done trial included) goes, so no trial is
                // counted twice.
                let (learned, rejected) = self.counts();
                println!(
                    "agp-estimator: a new learning session from the planner: the {} trial(s) of the previous one are dropped and learning starts over",
                    learned + rejected
                );
                self.session = Some(session(&self.scenario)?);
            }
            self.learn_session = event.session;
        }
        let Some(session) = &mut self.session else {
            return Ok(());
        };
        self.trials_total = self.trials_total.max(event.total);
        let v = view(event);
        let object = event.object;
        match kind {
            LearnEventKind::ShapeBegin => {
                session.begin_shape_circling(object);
                session.observe(&v);
            }
            LearnEventKind::ShapeEnd => {
                let r = session.finish_shape_circling();
                let mut report = self.trial_report(LearnReportKind::ShapeLearned, event);
                match r {
                    Ok(points) => report.value = points as f64,
                    Err(e) => {
                        eprintln!("agp-estimator: the shape circling gave no shape: {e}");
                        report.kind = LearnReportKind::ShapeFailed as u32;
                    }
                }
                self.report(report)?;
            }
            LearnEventKind::TrialBegin => {
                if let Err(e) = session.begin_trial(event.alpha_deg, object) {
                    eprintln!("agp-estimator: trial {} cannot start: {e}", event.index);
                    session.abandon_trial();
                    let r = self.trial_report(LearnReportKind::TrialRejected, event);
                    self.report(r)?;
                } else {
                    session.observe(&v);
                }
            }
            LearnEventKind::Contact => {
                if session.recorder().phase() == TrialPhase::Approach
                    && let Err(e) = session.infer_contact(&v)
                {
                    eprintln!("agp-estimator: trial {}: {e}", event.index);
                }
            }
            LearnEventKind::PushEnd => {
                if event.flag == 1 && session.recorder().phase() == TrialPhase::Push {
                    if let Err(e) = session.end_push(&v) {
                        eprintln!("agp-estimator: trial {}: {e}", event.index);
                    }
                } else if session.recorder().phase() != TrialPhase::Idle {
                    session.abandon_trial();
                    let r = self.trial_report(LearnReportKind::TrialRejected, event);
                    self.report(r)?;
                }
            }
            LearnEventKind::TrialEnd => {
                if session.recorder().phase() != TrialPhase::Circling {
                    return Ok(());
                }
                let result = session.finish_trial();
                let mut r = self.trial_report(LearnReportKind::TrialLearned, event);
                match result {
                    Ok(record) => {
                        r.contact_point = record.outcome.contact_point_obj.to_array();
                        r.displacement = record.outcome.displacement_obj.to_array();
                        r.rotation_rad = record.outcome.rotation_rad;
                        r.value = record.matched.inlier_fraction;
                    }
                    Err(e) => {
                        eprintln!("agp-estimator: trial {} rejected: {e}", event.index);
                        r.kind = LearnReportKind::TrialRejected as u32;
                    }
                }
                self.report(r)?;
            }
            LearnEventKind::LearningDone => {
                if let Some(s) = self.session.take() {
                    let (learned, rejected) = (s.trials_learned(), s.trials_rejected());
                    self.finished = Some(s.into_gradient());
                    self.final_counts = (learned as u32, rejected as u32);
                }
            }
            _ => {}
        }
        Ok(())
    }
}
