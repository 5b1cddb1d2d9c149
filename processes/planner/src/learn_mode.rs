//! `--mode learn`: the learning phase of benchmarks.md section 1 over the real pipeline.
//!
//! The planner drives lockstep physics through [`LockstepDriver`] with the protocol of the
//! in-process learning bench (`agp_perception::run_object`): one circling of the object at
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

use agp_planning::{
    CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, PushPhase, PushRoutine, PushSettings,
};
use agp_runtime::{DriveError, Instance, LockstepDriver};

use crate::ring::{EstimatorLink, EstimatorRestarted, Ring};
use agp_shared_types::angle::wrap_angle;
use agp_shared_types::{IrFrame, LearnEvent, LearnEventKind, LearnReportKind, Pose2, monotonic_ns};
use agp_world::{RobotDescription, Scenario};
use anyhow::{Context, Result, bail};
use glam::DVec2;

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

/// The protocol's driver: physics through the lockstep driver, each frame acknowledged by
/// the estimator before it is acted on.
struct Learner<'a> {
    ring: Ring,
    /// One routine for every circling, restarted each time: its buffers are allocated once.
    circling: CircleRoutine,
    /// The IR sampling period, s.
    ir_period_s: f64,
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
        let mut f = self.ring.frame();
        self.circling.restart(f.sim_time_s);
        loop {
            let (l, r) = self
                .circling
                .update(f.sim_time_s, f.ir_sample, f.odometry, &f.ir_raw);
            if let CirclePhase::Done { outcome, .. } = self.circling.phase() {
                return Ok((f, outcome == CircleOutcome::Closed));
            }
            f = self.ring.step(l, r)?;
        }
    }

    /// The shape circling: approach from the left, then one lap at the known pose.
    fn shape(&mut self) -> Result<bool> {
        let start = start_pose(self.object0, self.radius, PI, 0.0);
        let mut f = self.ring.reset(self.object0, start)?;
        let begin = self.event(LearnEventKind::ShapeBegin);
        self.ring.link.send(begin, &f)?;
        let t0 = f.sim_time_s;
        // Stop 2 mm before the circling's gap: the robot coasts about that far past the
        // reading that ends the approach.
        let gap = self.settings.circle.gap + 0.002;
        loop {
            if self.ring.estimate().front_gap().is_some_and(|g| g <= gap) {
                break;
            }
            if f.sim_time_s - t0 >= SHAPE_APPROACH_TIMEOUT_S {
                bail!(
                    "the shape circling's approach met no object within {SHAPE_APPROACH_TIMEOUT_S} s"
                );
            }
            f = self.ring.step(SHAPE_APPROACH_SPEED, SHAPE_APPROACH_SPEED)?;
        }
        let (f, closed) = self.circle()?;
        let mut end = self.event(LearnEventKind::ShapeEnd);
        end.flag = u32::from(closed);
        self.ring.link.send(end, &f)?;
        Ok(closed)
    }

    /// One trial at `alpha_deg` from angle `phi` (rad) round the object.
    fn trial(&mut self, index: u32, alpha_deg: f64, phi: f64) -> Result<TrialRun> {
        let start = start_pose(self.object0, self.radius, phi, alpha_deg.to_radians());
        let mut f = self.ring.reset(self.object0, start)?;
        let mut ev = self.event(LearnEventKind::TrialBegin);
        ev.index = index;
        ev.alpha_deg = alpha_deg;
        ev.angle_rad = phi;
        self.ring.link.send(ev, &f)?;
        let mut routine = PushRoutine::new(self.settings.push, f.sim_time_s);
        loop {
            let before = routine.phase();
            let (l, r) = routine.update(
                self.ring.estimate().front_gap(),
                self.ir_period_s,
                f.sim_time_s,
                f.ir_sample,
            );
            let after = routine.phase();
            if matches!(before, PushPhase::Approach { .. })
                && matches!(after, PushPhase::Push { .. })
            {
                ev.kind = LearnEventKind::Contact as u32;
                self.ring.link.send(ev, &f)?;
            }
            if let PushPhase::Done { contact } = after {
                ev.kind = LearnEventKind::PushEnd as u32;
                ev.flag = u32::from(contact);
                self.ring.link.send(ev, &f)?;
                if !contact {
                    return Ok(TrialRun::NoContact);
                }
                break;
            }
            f = self.ring.step(l, r)?;
        }
        let t0 = f.sim_time_s;
        let v = -self.settings.backoff_speed;
        while f.sim_time_s - t0 < self.settings.backoff_s {
            f = self.ring.step(v, v)?;
        }
        let (f, lap_closed) = self.circle()?;
        ev.kind = LearnEventKind::TrialEnd as u32;
        ev.flag = u32::from(lap_closed);
        self.ring.link.send(ev, &f)?;
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
    let ring = Ring::new(driver, link).context("waiting for the estimator")?;
    let mut learner = Learner {
        ring,
        ir_period_s: 1.0 / robot.ir_rate_hz,
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
    let shape = learner.ring.link.wait_report(
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
            let r = learner.ring.link.wait_report(
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
    let f = learner.ring.frame();
    let done = learner.event(LearnEventKind::LearningDone);
    learner.ring.link.send(done, &f)?;
    let r = learner
        .ring
        .link
        .wait_report(&[LearnReportKind::Learned], settings.learned_timeout)?;
    println!(
        "learned: {} trials learned, {} rejected of {}; grids seq {}; sim {:.1} s, wall {:.1} s; AG file {}",
        r.trials_learned,
        r.trials_rejected,
        r.trials_total,
        r.grids_seq,
        learner.ring.frame().sim_time_s,
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
