//! `--mode learn`: the learning phase of benchmarks.md section 1 over the real pipeline.
//!
//! The protocol is [`agp_planning::LearnProtocol`], the one the in-process learning bench
//! runs too; this module is its world over the pipeline ([`PipelineWorld`]: lockstep
//! physics through [`LockstepDriver`], the estimator as the learner, told each step with a
//! [`LearnEvent`] carrying the frame it refers to and answering on the learn reports
//! topic) and the command line's progress bar. It never reads ground truth.
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

use std::time::Duration;

use agp_planning::{
    Disruption, LearnFrame, LearnProtocol, LearnProtocolError, LearnProtocolSettings, LearnWorld,
    ProtocolStep, TrialRun,
};
use agp_runtime::{DriveError, Instance, LockstepDriver, TruthAccess};

use crate::ring::{EstimatorLink, EstimatorRestarted, Ring};
use agp_shared_types::{LearnEvent, LearnReport, LearnReportKind, monotonic_ns};
use agp_world::{Experimenter, Pose, RobotDescription, ScenarioBrief};
use anyhow::{Context, Result, anyhow, bail};

/// How the learning phase is driven over the pipeline: the protocol's settings and the
/// waits on the other processes.
#[derive(Debug, Clone)]
pub struct LearnSettings {
    /// The protocol (trials, alphas, push, circling, back-off, start margin).
    pub protocol: LearnProtocolSettings,
    /// Safety net of every wait on another process.
    pub timeout: Duration,
    /// How long the estimator may take to publish the gradients after the last trial.
    pub learned_timeout: Duration,
}

impl LearnSettings {
    /// The protocol's defaults with `trials_per_alpha` trials per alpha and a push of
    /// `push_ms` milliseconds.
    pub fn new(trials_per_alpha: u32, push_ms: u64, timeout: Duration) -> Self {
        Self {
            protocol: LearnProtocolSettings::new(trials_per_alpha, push_ms as f64 * 1e-3),
            timeout,
            learned_timeout: Duration::from_secs(120),
        }
    }
}

/// The protocol's world over the pipeline: physics through the lockstep driver, each frame
/// acknowledged by the estimator (the learner) before it is acted on; its reports from the
/// learn reports topic.
struct PipelineWorld {
    ring: Ring,
    timeout: Duration,
    learned_timeout: Duration,
}

impl LearnWorld for PipelineWorld {
    type Error = anyhow::Error;

    fn frame(&self) -> LearnFrame {
        let f = self.ring.frame();
        LearnFrame {
            step: f.step,
            sim_time_s: f.sim_time_s,
            ir_sample: f.ir_sample,
            ir_raw: f.ir_raw,
            odometry: f.odometry,
        }
    }

    fn front_gap(&self) -> Option<f64> {
        self.ring.estimate().front_gap()
    }

    fn stalled(&self) -> bool {
        self.ring.estimate().stalled == 1
    }

    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<()> {
        self.ring.step(left_mps, right_mps).map(drop)
    }

    fn reset(&mut self, object: Pose, robot: Pose) -> Result<()> {
        self.ring.reset(object, robot).map(drop)
    }

    fn tell(&mut self, event: LearnEvent) -> Result<()> {
        self.ring.send(event)
    }

    fn wait_report(&mut self, kinds: &[LearnReportKind]) -> Result<LearnReport> {
        let timeout = if kinds.contains(&LearnReportKind::Learned) {
            self.learned_timeout
        } else {
            self.timeout
        };
        self.ring.link.wait_report(kinds, timeout)
    }

    fn new_session(&mut self) -> u64 {
        new_session()
    }

    fn disruption(&self, e: &anyhow::Error) -> Option<Disruption> {
        if matches!(e.downcast_ref(), Some(DriveError::PhysicsRestarted)) {
            Some(Disruption::WorldRestarted)
        } else if e.downcast_ref::<EstimatorRestarted>().is_some() {
            Some(Disruption::LearnerRestarted)
        } else {
            None
        }
    }
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
    scenario: &ScenarioBrief,
    experimenter: Experimenter,
    epoch: u64,
    settings: &LearnSettings,
) -> Result<()> {
    if settings.protocol.trials_per_alpha == 0 {
        bail!("`--trials-per-alpha` must be at least 1");
    }
    if epoch != 0 {
        // A swapped-in learner would start the protocol again from scratch, and the
        // estimator's session cannot tell its events from the old planner's.
        bail!("the learning phase cannot be hot-swapped in (epoch {epoch})");
    }
    let robot = RobotDescription::epuck();
    let driver = match LockstepDriver::connect(
        instance,
        "planner",
        epoch,
        TruthAccess::SensesOnly,
        settings.timeout,
    ) {
        Ok(d) => d,
        Err(DriveError::Shutdown) => return Ok(()),
        Err(e) => return Err(e).context("cannot reach physics"),
    };
    let link = EstimatorLink::open(instance, settings.timeout)?;
    let ring = Ring::new(driver, link).context("waiting for the estimator")?;
    let mut world = PipelineWorld {
        ring,
        timeout: settings.timeout,
        learned_timeout: settings.learned_timeout,
    };
    // Where the experimenter puts the object back: an input of the protocol, the
    // experimenter's (`Experimenter`). The object's shape and symmetry are learned from
    // the circling, the trials' start circle from the learned border.
    let mut protocol =
        LearnProtocol::new(settings.protocol.clone(), &robot, experimenter.placement);
    match learn(&mut world, &mut protocol, scenario) {
        Err(e) if shutdown(&e) => Ok(()),
        other => other,
    }
}

fn learn(
    world: &mut PipelineWorld,
    protocol: &mut LearnProtocol,
    scenario: &ScenarioBrief,
) -> Result<()> {
    let settings = protocol.settings().clone();
    let wall = std::time::Instant::now();
    println!(
        "learning `{}`: {} trials per alpha at alphas {:?} deg, push {} ms",
        scenario.name,
        settings.trials_per_alpha,
        settings.alphas_deg,
        (settings.push.push_duration * 1e3).round()
    );
    let total = settings.total_trials();
    let mut progress = Progress::new(total);
    let r = protocol.run(world, &mut |step| match step {
        ProtocolStep::ShapeLearned { lap_closed, report } => println!(
            "shape circling: lap {}, {} border points, learned border {:.1} mm from the centroid",
            if lap_closed { "closed" } else { "not closed" },
            report.value,
            report.border_radius_m * 1e3
        ),
        ProtocolStep::Trial {
            done,
            total,
            alpha_deg,
            phi_rad,
            run,
            report: r,
        } => {
            let learned = r.kind == LearnReportKind::TrialLearned as u32;
            if !learned || !matches!(run, TrialRun::Pushed { lap_closed: true }) {
                let line = format!(
                    "trial {done}/{total} alpha {alpha_deg:+.0} deg from {:.0} deg: {}; estimator: {}",
                    phi_rad.to_degrees(),
                    match run {
                        TrialRun::NoContact => "no contact",
                        TrialRun::Pushed { lap_closed: true } => "pushed, lap closed",
                        TrialRun::Pushed { lap_closed: false } => "pushed, lap not closed",
                    },
                    if learned { "learned" } else { "rejected" }
                );
                progress.note(&line);
            }
            progress.show(done, r.trials_learned, r.trials_rejected);
        }
        ProtocolStep::Again {
            why: Disruption::WorldRestarted,
            trial,
        } => match trial {
            Some(i) => progress.note(&format!("  physics restarted: trial {} again", i + 1)),
            None => progress.note("  physics restarted: the shape circling again"),
        },
        ProtocolStep::Again {
            why: Disruption::LearnerRestarted,
            ..
        } => {
            progress.note("  the estimator restarted: learning starts over");
            progress = Progress::new(total);
        }
        ProtocolStep::Learned(_) => progress.finish(),
    });
    let r = match r {
        Ok(r) => r,
        Err(LearnProtocolError::World(e)) => return Err(e),
        Err(e @ LearnProtocolError::ShapeFailed { .. }) => {
            return Err(anyhow!("{e}")).context("the estimator could not learn the shape");
        }
        Err(e) => return Err(anyhow!("{e}")),
    };
    println!(
        "learned: {} trials learned, {} rejected of {}; grids seq {}; sim {:.1} s, wall {:.1} s; AG file {}",
        r.trials_learned,
        r.trials_rejected,
        r.trials_total,
        r.grids_seq,
        world.ring.frame().sim_time_s,
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
