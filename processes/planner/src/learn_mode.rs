//! `--mode learn`: the learning phase of benchmarks.md section 1 over the real pipeline.
//!
//! The planner drives lockstep physics through [`LockstepDriver`] with the protocol of the
//! in-process learning bench (`agp_estimator::run_object`): one circling of the object at
//! its start pose for the shape, then per alpha `trials_per_alpha` trials evenly spread
//! round the object, each: object put back, robot placed on a circle round it facing the
//! centroid turned by alpha, approach until contact is inferred from IR, push a fixed time
//! at a fixed speed, back off, circle the object. It tells the estimator each step of the
//! protocol with a [`LearnEvent`] carrying the frame it refers to, and never reads ground
//! truth.
//!
//! Pacing: physics waits for the planner only, so an estimator that fell behind would lose
//! IR frames (the topic keeps 4). The planner therefore waits, before it acts on a frame,
//! for the estimator's [`ObjectEstimate`] of that frame (matched by the frame's publish
//! stamp, unique per published frame even across resets). So the estimator has seen every
//! frame before the planner sends an event about it or the command that makes the next
//! frame, and draining events before each frame gives it the protocol in order.
//!
//! Waiting: after a command or a reset the planner waits on the estimates' event service
//! only, never on the frames': the estimator acknowledges a frame only after physics
//! published it, so once the acknowledgement of a frame newer than the latest is in, the
//! new frame is in the planner's subscriber too and is taken without waiting. Each physics
//! step thus wakes (or keeps spinning) one process, the estimator, not two competing for
//! the cores physics needs.

use std::f64::consts::{PI, TAU};
use std::time::Duration;

use agp_planner::{
    CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, ContactSense, PushPhase,
    PushRoutine, PushSettings,
};
use agp_runtime::{
    AgpIpc, DriveError, Instance, LockstepDriver, WaitOutcome, WaitStrategy, Waiter, alloc_count,
};
use agp_shared_types::angle::wrap_angle;
use agp_shared_types::{
    IrFrame, LearnEvent, LearnEventKind, LearnReport, LearnReportKind, ObjectEstimate, Pose2,
    monotonic_ns, stage,
};
use agp_world::{RobotDescription, Scenario};
use anyhow::{Context, Result, anyhow, bail};
use glam::DVec2;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

/// The alphas of the protocol, degrees, in the order they are run.
pub const ALPHAS_DEG: [f64; 3] = [0.0, 15.0, -15.0];

/// How the learning phase is driven: the in-process bench's defaults.
#[derive(Debug, Clone)]
pub struct LearnSettings {
    /// Trials per alpha, evenly spread round the object.
    pub trials_per_alpha: u32,
    /// Approach and push (0.5 s at the routine's push speed).
    pub push: PushSettings,
    /// The circlings.
    pub circle: CircleSettings,
    /// Robot start: this far (m) outside the object's farthest point plus the body radius.
    pub start_margin_m: f64,
    /// Back-off after the push, seconds, at `backoff_speed` m/s.
    pub backoff_s: f64,
    pub backoff_speed: f64,
    /// Safety net of every wait on another process.
    pub timeout: Duration,
    /// How long the estimator may take to publish the gradients after the last trial.
    pub learned_timeout: Duration,
}

impl LearnSettings {
    /// The in-process learning bench's protocol with `trials_per_alpha` trials per alpha
    /// and a push of `push_ms` milliseconds.
    pub fn new(trials_per_alpha: u32, push_ms: u64, timeout: Duration) -> Self {
        Self {
            trials_per_alpha,
            push: PushSettings {
                push_duration: push_ms as f64 * 1e-3,
                ..PushSettings::default()
            },
            circle: CircleSettings::default(),
            start_margin_m: 0.02,
            backoff_s: 0.15,
            backoff_speed: 0.08,
            timeout,
            learned_timeout: Duration::from_secs(120),
        }
    }
}

/// The shape circling's approach gives up after this long, seconds of simulated time.
const SHAPE_APPROACH_TIMEOUT_S: f64 = 5.0;
/// Speed of the shape circling's approach, m/s.
const SHAPE_APPROACH_SPEED: f64 = 0.08;

/// The planner's ports to the estimator: events out, acknowledgements and reports in.
struct EstimatorLink {
    _node: Node<AgpIpc>,
    events: Publisher<AgpIpc, LearnEvent, ()>,
    wake: Notifier<AgpIpc>,
    estimates: Subscriber<AgpIpc, ObjectEstimate, ()>,
    estimates_waiter: Waiter,
    reports: Subscriber<AgpIpc, LearnReport, ()>,
    reports_waiter: Waiter,
    seq: u64,
    /// Publish stamp of the newest frame the estimator acknowledged.
    acked_stamp: u64,
    /// The estimate of that frame and when it was received (CLOCK_MONOTONIC), until the
    /// command answering the frame took its stamps.
    latest: Option<(ObjectEstimate, u64)>,
    /// The latest trial counts the estimator reported.
    learned: u32,
    rejected: u32,
    timeout: Duration,
    /// Start time of the estimator that acknowledges (from its estimates; 0: none seen).
    estimator_start_ns: u64,
    /// Set when an estimate came from an estimator started after that one.
    estimator_restarted: bool,
}

/// The estimator restarted: it lost what it learned, so the protocol starts over (a new
/// session) rather than waiting for acknowledgements or reports it will never send.
#[derive(Debug)]
struct EstimatorRestarted;

impl std::fmt::Display for EstimatorRestarted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("the estimator restarted")
    }
}

impl std::error::Error for EstimatorRestarted {}

/// How long a wait for a report lasts before it looks again for a restarted estimator.
const REPORT_WAIT_SLICE: Duration = Duration::from_millis(20);

/// What [`take_estimates`] keeps track of.
#[derive(Debug, Clone, Copy)]
struct Acks {
    /// Publish stamp of the newest frame acknowledged.
    stamp: u64,
    /// That frame's estimate and its receipt, until taken.
    latest: Option<(ObjectEstimate, u64)>,
    /// The acknowledging estimator's start time, and whether a later one appeared.
    estimator_start_ns: u64,
    restarted: bool,
}

fn open_err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot open {what}: {e:?}")
}

impl EstimatorLink {
    fn open(instance: &Instance, timeout: Duration) -> Result<Self> {
        let node = instance
            .node("planner-learn", false)
            .map_err(open_err("the learn node"))?;
        let events = instance
            .learn_events(&node)
            .map_err(open_err("the learn events"))?;
        let estimates = instance
            .estimates(&node)
            .map_err(open_err("the estimates"))?;
        let reports = instance
            .learn_reports(&node)
            .map_err(open_err("the learn reports"))?;
        let strategy = WaitStrategy::from_env();
        Ok(Self {
            events: events
                .data
                .publisher_builder()
                .create()
                .map_err(open_err("the learn event publisher"))?,
            wake: events
                .event
                .notifier_builder()
                .create()
                .map_err(open_err("the learn event notifier"))?,
            estimates: estimates
                .data
                .subscriber_builder()
                .create()
                .map_err(open_err("the estimate subscriber"))?,
            estimates_waiter: Waiter::new(
                estimates
                    .event
                    .listener_builder()
                    .create()
                    .map_err(open_err("the estimate listener"))?,
                strategy,
            ),
            reports: reports
                .data
                .subscriber_builder()
                .create()
                .map_err(open_err("the report subscriber"))?,
            reports_waiter: Waiter::new(
                reports
                    .event
                    .listener_builder()
                    .create()
                    .map_err(open_err("the report listener"))?,
                WaitStrategy::Block,
            ),
            seq: 0,
            acked_stamp: 0,
            latest: None,
            learned: 0,
            rejected: 0,
            timeout,
            estimator_start_ns: 0,
            estimator_restarted: false,
            _node: node,
        })
    }

    /// Waits until the estimator has seen `frame` (or a later one). Returns the estimator's
    /// estimate of `frame` itself and when it was received (CLOCK_MONOTONIC), once: the
    /// command answering `frame` carries its stamps.
    fn ack(&mut self, frame: &IrFrame) -> Result<Option<(ObjectEstimate, u64)>> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let stamp = frame.timing.stamps_ns[stage::FRAME_PUBLISHED];
        if self.acked_stamp < stamp {
            let estimates = &self.estimates;
            let mut acks = self.acks();
            let outcome = self.estimates_waiter.wait_for(self.timeout, || {
                take_estimates(estimates, &mut acks);
                (acks.stamp >= stamp || acks.restarted).then_some(())
            });
            self.set_acks(acks);
            self.check_estimator()?;
            match outcome {
                WaitOutcome::Ready(()) => {}
                WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
                WaitOutcome::TimedOut => return Err(self.no_ack(frame.step)),
            }
        }
        Ok(self
            .latest
            .take_if(|(e, _)| e.timing.stamps_ns[stage::FRAME_PUBLISHED] == stamp))
    }

    fn acks(&self) -> Acks {
        Acks {
            stamp: self.acked_stamp,
            latest: self.latest,
            estimator_start_ns: self.estimator_start_ns,
            restarted: self.estimator_restarted,
        }
    }

    fn set_acks(&mut self, a: Acks) {
        self.acked_stamp = a.stamp;
        self.latest = a.latest;
        self.estimator_start_ns = a.estimator_start_ns;
        self.estimator_restarted = a.restarted;
    }

    /// [`EstimatorRestarted`] once when an estimate showed a restarted estimator.
    fn check_estimator(&mut self) -> Result<()> {
        if std::mem::take(&mut self.estimator_restarted) {
            return Err(EstimatorRestarted.into());
        }
        Ok(())
    }

    fn no_ack(&self, step: u64) -> anyhow::Error {
        anyhow!(
            "the estimator did not acknowledge the frame of step {step} within {:?}: is `agp-estimator` running on this instance?",
            self.timeout
        )
    }

    /// Sends one event about `frame`.
    fn send(&mut self, mut event: LearnEvent, frame: &IrFrame) -> Result<()> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.seq += 1;
        event.seq = self.seq;
        event.step = frame.step;
        event.ir_sample = frame.ir_sample;
        event.ir_raw = frame.ir_raw;
        event.odometry = frame.odometry;
        let sample = self
            .events
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan a learn event: {e:?}"))?;
        sample
            .write_payload(event)
            .send()
            .map_err(|e| anyhow!("cannot send a learn event: {e:?}"))?;
        let _ = self.wake.notify();
        Ok(())
    }

    /// Takes the reports that arrived; returns the first of `wanted` kind among them. Called
    /// by [`Self::wait_report`] alone, whose region it shares.
    fn drain_reports(&mut self, wanted: Option<LearnReportKind>) -> Option<LearnReport> {
        let mut found = None;
        while let Ok(Some(r)) = self.reports.receive() {
            let kind = LearnReportKind::from_u32(r.kind);
            if matches!(
                kind,
                Some(
                    LearnReportKind::TrialLearned
                        | LearnReportKind::TrialRejected
                        | LearnReportKind::Learned
                )
            ) {
                self.learned = r.trials_learned;
                self.rejected = r.trials_rejected;
            }
            if found.is_none() && kind.is_some() && kind == wanted {
                found = Some(*r);
            }
        }
        found
    }

    /// Waits up to `timeout` for a report of one of `kinds`. Ends with
    /// [`EstimatorRestarted`] when a restarted estimator acknowledges a frame meanwhile (it
    /// would never send the report).
    fn wait_report(&mut self, kinds: &[LearnReportKind], timeout: Duration) -> Result<LearnReport> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        let start = std::time::Instant::now();
        loop {
            let mut acks = self.acks();
            take_estimates(&self.estimates, &mut acks);
            self.set_acks(acks);
            self.check_estimator()?;
            let mut found = None;
            for &k in kinds {
                if found.is_none() {
                    found = self.drain_reports(Some(k));
                }
            }
            if let Some(r) = found {
                return Ok(r);
            }
            let left = timeout.saturating_sub(start.elapsed());
            if left.is_zero() {
                bail!("no {kinds:?} report from the estimator within {timeout:?}");
            }
            let reports = &self.reports;
            match self
                .reports_waiter
                .wait_for(left.min(REPORT_WAIT_SLICE), || {
                    reports.has_samples().unwrap_or(false).then_some(())
                }) {
                WaitOutcome::Ready(()) | WaitOutcome::TimedOut => {}
                WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
            }
        }
    }
}

/// Takes the estimates that arrived: raises the acknowledged stamp to the newest one and
/// keeps that frame's estimate, with its receipt. An estimate of an estimator started
/// later than the one known marks a restart; one of an estimator started earlier (left in
/// the queue by one that died) is ignored.
fn take_estimates(estimates: &Subscriber<AgpIpc, ObjectEstimate, ()>, acks: &mut Acks) {
    while let Ok(Some(e)) = estimates.receive() {
        if e.estimator_start_ns < acks.estimator_start_ns {
            continue;
        }
        if e.estimator_start_ns > acks.estimator_start_ns {
            acks.restarted |= acks.estimator_start_ns != 0;
            acks.estimator_start_ns = e.estimator_start_ns;
        }
        let published = e.timing.stamps_ns[stage::FRAME_PUBLISHED];
        if published > acks.stamp {
            acks.stamp = published;
            acks.latest = Some((*e, monotonic_ns()));
        }
    }
}

/// The protocol's driver: physics through the lockstep driver, each frame acknowledged by
/// the estimator before it is acted on.
struct Learner<'a> {
    driver: LockstepDriver,
    link: EstimatorLink,
    /// One routine for every circling, restarted each time: its buffers are allocated once.
    circling: CircleRoutine,
    sense: ContactSense,
    settings: &'a LearnSettings,
    object0: Pose2,
    radius: f64,
    total: u32,
    /// The run of the protocol under way ([`LearnEvent::session`]).
    session: u64,
}

/// How one trial went, as the planner saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TrialRun {
    NoContact,
    Pushed { lap_closed: bool },
}

/// The robot on a circle of radius `r` round `object` at angle `phi` (from the centroid),
/// facing the centroid turned by `alpha` (rad).
fn start_pose(object: Pose2, r: f64, phi: f64, alpha: f64) -> Pose2 {
    let c = DVec2::new(object.x, object.y) + DVec2::from_angle(phi) * r;
    Pose2::new(c.x, c.y, wrap_angle(phi + PI + alpha))
}

impl Learner<'_> {
    fn frame(&self) -> IrFrame {
        *self.driver.frame()
    }

    fn step(&mut self, l: f64, r: f64) -> Result<IrFrame> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.driver.send(l, r)?;
        let next = self.driver.frame().step + 1;
        self.next_frame(next)
    }

    fn reset(&mut self, robot: Pose2) -> Result<IrFrame> {
        let _in_iceoryx2 = alloc_count::enter(alloc_count::Region::Iceoryx2);
        self.driver.send_reset(self.object0, robot)?;
        let same = self.driver.frame().step;
        self.next_frame(same)
    }

    /// The frame the command or reset just sent makes (of step `step`), once the estimator
    /// acknowledged it. Waits on the estimates alone. The frames are polled on each turn of
    /// the wait (the frame usually comes first, and a restarted physics shows there) but
    /// waited on only in the rare case of an acknowledgement that reached this planner
    /// before the frame did (physics preempted between its subscribers' deliveries).
    fn next_frame(&mut self, step: u64) -> Result<IrFrame> {
        let before = self.driver.frame().timing.stamps_ns[stage::FRAME_PUBLISHED];
        let driver = &mut self.driver;
        let link = &mut self.link;
        let estimates = &link.estimates;
        let mut acks = link.acks();
        let mut taken = None;
        let outcome = link.estimates_waiter.wait_for(link.timeout, || {
            take_estimates(estimates, &mut acks);
            if acks.restarted {
                return Some(Ok(()));
            }
            if taken.is_none() {
                match driver.take_frame() {
                    Ok(Some(f)) => taken = Some(f.timing.stamps_ns[stage::FRAME_PUBLISHED]),
                    Ok(None) => {}
                    Err(e) => return Some(Err(e)),
                }
            }
            // Acknowledged: the frame taken, or (not yet taken) one newer than `before`.
            (acks.stamp >= taken.unwrap_or(before + 1)).then_some(Ok(()))
        });
        link.set_acks(acks);
        link.check_estimator()?;
        match outcome {
            WaitOutcome::Ready(Ok(())) => {}
            WaitOutcome::Ready(Err(e)) => return Err(e.into()),
            WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
            WaitOutcome::TimedOut if taken.is_some() => return Err(link.no_ack(step)),
            WaitOutcome::TimedOut => {
                return Err(DriveError::NoFrame {
                    step,
                    timeout: link.timeout,
                }
                .into());
            }
        }
        let f = match taken {
            Some(_) => *driver.frame(),
            None => *driver.await_frame()?,
        };
        self.ack(&f)?;
        Ok(f)
    }

    /// Waits for the estimator's acknowledgement of `f`, the driver's latest frame; the
    /// command answering it then carries the estimator's stamps and the estimate's receipt.
    fn ack(&mut self, f: &IrFrame) -> Result<()> {
        if let Some((estimate, received_ns)) = self.link.ack(f)? {
            self.driver.note_estimate(&estimate, received_ns);
        }
        Ok(())
    }

    fn event(&self, kind: LearnEventKind) -> LearnEvent {
        LearnEvent {
            kind: kind as u32,
            session: self.session,
            total: self.total,
            object: self.object0,
            ..LearnEvent::default()
        }
    }

    /// Circles the object until the routine ends; returns the last frame and whether the
    /// lap closed.
    fn circle(&mut self) -> Result<(IrFrame, bool)> {
        let mut f = self.frame();
        self.circling.restart(f.sim_time_s);
        loop {
            let (l, r) = self
                .circling
                .update(f.sim_time_s, f.ir_sample, f.odometry, &f.ir_raw);
            if let CirclePhase::Done { outcome, .. } = self.circling.phase() {
                return Ok((f, outcome == CircleOutcome::Closed));
            }
            f = self.step(l, r)?;
        }
    }

    /// The shape circling: approach from the left, then one lap at the known pose.
    fn shape(&mut self) -> Result<bool> {
        let start = start_pose(self.object0, self.radius, PI, 0.0);
        let mut f = self.reset(start)?;
        let begin = self.event(LearnEventKind::ShapeBegin);
        self.link.send(begin, &f)?;
        let t0 = f.sim_time_s;
        // Stop 2 mm before the circling's gap: the robot coasts about that far past the
        // reading that ends the approach.
        let gap = self.settings.circle.gap + 0.002;
        loop {
            if self.sense.front_gap(&f.ir_raw).is_some_and(|g| g <= gap) {
                break;
            }
            if f.sim_time_s - t0 >= SHAPE_APPROACH_TIMEOUT_S {
                bail!(
                    "the shape circling's approach met no object within {SHAPE_APPROACH_TIMEOUT_S} s"
                );
            }
            f = self.step(SHAPE_APPROACH_SPEED, SHAPE_APPROACH_SPEED)?;
        }
        let (f, closed) = self.circle()?;
        let mut end = self.event(LearnEventKind::ShapeEnd);
        end.flag = u32::from(closed);
        self.link.send(end, &f)?;
        Ok(closed)
    }

    /// One trial at `alpha_deg` from angle `phi` (rad) round the object.
    fn trial(&mut self, index: u32, alpha_deg: f64, phi: f64) -> Result<TrialRun> {
        let start = start_pose(self.object0, self.radius, phi, alpha_deg.to_radians());
        let mut f = self.reset(start)?;
        let mut ev = self.event(LearnEventKind::TrialBegin);
        ev.index = index;
        ev.alpha_deg = alpha_deg;
        ev.angle_rad = phi;
        self.link.send(ev, &f)?;
        let mut routine = PushRoutine::new(self.settings.push, f.sim_time_s);
        loop {
            let before = routine.phase();
            let (l, r) = routine.update(&self.sense, f.sim_time_s, f.ir_sample, &f.ir_raw);
            let after = routine.phase();
            if matches!(before, PushPhase::Approach { .. })
                && matches!(after, PushPhase::Push { .. })
            {
                ev.kind = LearnEventKind::Contact as u32;
                self.link.send(ev, &f)?;
            }
            if let PushPhase::Done { contact } = after {
                ev.kind = LearnEventKind::PushEnd as u32;
                ev.flag = u32::from(contact);
                self.link.send(ev, &f)?;
                if !contact {
                    return Ok(TrialRun::NoContact);
                }
                break;
            }
            f = self.step(l, r)?;
        }
        let t0 = f.sim_time_s;
        let v = -self.settings.backoff_speed;
        while f.sim_time_s - t0 < self.settings.backoff_s {
            f = self.step(v, v)?;
        }
        let (f, lap_closed) = self.circle()?;
        ev.kind = LearnEventKind::TrialEnd as u32;
        ev.flag = u32::from(lap_closed);
        self.link.send(ev, &f)?;
        Ok(TrialRun::Pushed { lap_closed })
    }
}

/// Whether `e` means physics restarted (the step under way is run again from its reset).
fn restarted(e: &anyhow::Error) -> bool {
    matches!(e.downcast_ref(), Some(DriveError::PhysicsRestarted))
}

/// Whether `e` means the estimator restarted (the protocol starts over).
fn estimator_restarted(e: &anyhow::Error) -> bool {
    e.downcast_ref::<EstimatorRestarted>().is_some()
}

/// A new session id: unique per run of the protocol, never 0.
fn new_session() -> u64 {
    (monotonic_ns() ^ (u64::from(std::process::id()) << 40)).max(1)
}

/// Whether `e` means a shutdown was asked for (the planner stops quietly).
fn shutdown(e: &anyhow::Error) -> bool {
    matches!(e.downcast_ref(), Some(DriveError::Shutdown))
}

/// Runs the learning phase of `scenario`'s object; returns when the estimator reported the
/// gradients learned (or on shutdown).
pub fn run(
    instance: &Instance,
    scenario: &Scenario,
    epoch: u64,
    settings: &LearnSettings,
) -> Result<()> {
    if settings.trials_per_alpha == 0 {
        bail!("`--trials-per-alpha` must be at least 1");
    }
    if epoch != 0 {
        // A swapped-in learner would start the protocol again from scratch, and the
        // estimator's session cannot tell its events from the old planner's.
        bail!("the learning phase cannot be hot-swapped in (epoch {epoch})");
    }
    let robot = RobotDescription::epuck();
    let driver = match LockstepDriver::connect(instance, "planner", epoch, false, settings.timeout)
    {
        Ok(d) => d,
        Err(DriveError::Shutdown) => return Ok(()),
        Err(e) => return Err(e).context("cannot reach physics"),
    };
    let link = EstimatorLink::open(instance, settings.timeout)?;
    let o = scenario.object.start;
    let total = settings.trials_per_alpha * ALPHAS_DEG.len() as u32;
    let mut learner = Learner {
        driver,
        link,
        sense: ContactSense::new(&robot),
        radius: scenario.object.shape.radius() + robot.body_radius + settings.start_margin_m,
        circling: CircleRoutine::new(settings.circle, &robot, 0.0),
        settings,
        object0: o,
        total,
        session: 0,
    };
    match learn(&mut learner, scenario) {
        Err(e) if shutdown(&e) => Ok(()),
        other => other,
    }
}

fn learn(learner: &mut Learner<'_>, scenario: &Scenario) -> Result<()> {
    let settings = learner.settings;
    let wall = std::time::Instant::now();
    let first = learner.frame();
    learner.ack(&first).context("waiting for the estimator")?;
    println!(
        "learning `{}`: {} trials per alpha at alphas {:?} deg, push {} ms",
        scenario.name,
        settings.trials_per_alpha,
        ALPHAS_DEG,
        (settings.push.push_duration * 1e3).round()
    );
    loop {
        // Each run of the protocol is a session of its own: an estimator that still holds
        // trials of an earlier one (this planner restarted) drops them.
        learner.session = new_session();
        match protocol(learner, wall) {
            Err(e) if estimator_restarted(&e) => {
                println!("  the estimator restarted: learning starts over");
            }
            other => return other,
        }
    }
}

/// One run of the protocol, from the shape circling to the estimator's `Learned` report.
fn protocol(learner: &mut Learner<'_>, wall: std::time::Instant) -> Result<()> {
    let settings = learner.settings;
    let closed = loop {
        match learner.shape() {
            Ok(c) => break c,
            Err(e) if restarted(&e) => println!("  physics restarted: the shape circling again"),
            Err(e) => return Err(e),
        }
    };
    let shape = learner.link.wait_report(
        &[LearnReportKind::ShapeLearned, LearnReportKind::ShapeFailed],
        settings.timeout,
    )?;
    if shape.kind == LearnReportKind::ShapeFailed as u32 {
        bail!("the estimator could not learn the shape from the circling");
    }
    println!(
        "shape circling: lap {}, {} border points",
        if closed { "closed" } else { "not closed" },
        shape.value
    );
    let n = settings.trials_per_alpha;
    let mut index = 0;
    let mut progress = Progress::new(learner.total);
    for alpha in ALPHAS_DEG {
        for k in 0..n {
            let phi = TAU * f64::from(k) / f64::from(n);
            let run = loop {
                match learner.trial(index, alpha, phi) {
                    Ok(r) => break r,
                    Err(e) if restarted(&e) => {
                        println!("  physics restarted: trial {} again", index + 1)
                    }
                    Err(e) => return Err(e),
                }
            };
            index += 1;
            // One report per trial: its verdict before the next trial starts.
            let r = learner.link.wait_report(
                &[
                    LearnReportKind::TrialLearned,
                    LearnReportKind::TrialRejected,
                ],
                settings.timeout,
            )?;
            if r.kind != LearnReportKind::TrialLearned as u32
                || !matches!(run, TrialRun::Pushed { lap_closed: true })
            {
                let line = format!(
                    "trial {index}/{} alpha {alpha:+.0} deg from {:.0} deg: {}; estimator: {}",
                    learner.total,
                    phi.to_degrees(),
                    match run {
                        TrialRun::NoContact => "no contact",
                        TrialRun::Pushed { lap_closed: true } => "pushed, lap closed",
                        TrialRun::Pushed { lap_closed: false } => "pushed, lap not closed",
                    },
                    if r.kind == LearnReportKind::TrialLearned as u32 {
                        "learned"
                    } else {
                        "rejected"
                    }
                );
                progress.note(&line);
            }
            progress.show(index, r.trials_learned, r.trials_rejected);
        }
    }
    progress.finish();
    let f = learner.frame();
    let done = learner.event(LearnEventKind::LearningDone);
    learner.link.send(done, &f)?;
    let r = learner
        .link
        .wait_report(&[LearnReportKind::Learned], settings.learned_timeout)?;
    println!(
        "learned: {} trials learned, {} rejected of {}; grids seq {}; sim {:.1} s, wall {:.1} s; AG file {}",
        r.trials_learned,
        r.trials_rejected,
        r.trials_total,
        r.grids_seq,
        learner.frame().sim_time_s,
        wall.elapsed().as_secs_f64(),
        if r.valid == 1 { "saved" } else { "NOT saved" }
    );
    if r.valid != 1 {
        bail!("the estimator could not save the AG file");
    }
    Ok(())
}

/// The learning phase's progress bar: trials done, learned and rejected, time spent and
/// about how much is left. Redrawn in place on a terminal; every tenth of the way (one line
/// each) when the output goes to a file or a supervisor.
struct Progress {
    total: u32,
    start: std::time::Instant,
    tty: bool,
    shown: u32,
    /// The bar's text, rewritten in place for each redraw.
    line: String,
}

impl Progress {
    fn new(total: u32) -> Self {
        use std::io::IsTerminal;
        Self {
            total: total.max(1),
            start: std::time::Instant::now(),
            tty: std::io::stdout().is_terminal(),
            shown: 0,
            line: String::with_capacity(160),
        }
    }

    /// Writes the bar into `self.line`, reusing its buffer.
    fn render(&mut self, done: u32, learned: u32, rejected: u32) {
        use std::fmt::Write;
        const WIDTH: u32 = 30;
        let filled = WIDTH * done / self.total;
        let elapsed = self.start.elapsed().as_secs_f64();
        let left = if done > 0 {
            elapsed / f64::from(done) * f64::from(self.total - done.min(self.total))
        } else {
            f64::NAN
        };
        self.line.clear();
        self.line.push_str("learning [");
        self.line
            .extend((0..WIDTH).map(|k| if k < filled { '#' } else { '.' }));
        let _ = write!(
            self.line,
            "] {done}/{} trials, {learned} learned, {rejected} rejected, {elapsed:.1} s, about {left:.0} s left",
            self.total
        );
    }

    fn show(&mut self, done: u32, learned: u32, rejected: u32) {
        use std::io::Write;
        let due = done * 10 / self.total > self.shown * 10 / self.total || done == self.total;
        self.shown = done;
        if !self.tty && !due {
            return;
        }
        self.render(done, learned, rejected);
        if self.tty {
            print!("\r{}", self.line);
            let _ = std::io::stdout().flush();
        } else {
            println!("{}", self.line);
        }
    }

    /// A line of its own above the bar.
    fn note(&self, line: &str) {
        if self.tty {
            print!("\r\x1b[2K");
        }
        println!("{line}");
    }

    fn finish(&self) {
        if self.tty {
            println!();
        }
    }
}
