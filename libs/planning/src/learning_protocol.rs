//! The learning phase's protocol (the paper's section III-B, benchmarks.md section 1), the
//! planner's side, written once and driven over any [`LearnWorld`]: the physics process
//! and the estimator over iceoryx2 (`agp-planner --mode learn`), or the physics library
//! and the learner in-process (the learning bench).
//!
//! One circling of the object at its start pose for the shape; then per alpha
//! `trials_per_alpha` trials evenly spread round the object, each: object put back at its
//! start, robot placed on a circle round it facing the centroid turned by alpha, approach
//! until contact is inferred from IR, push a fixed time at a fixed speed, back off, circle
//! the object. Each step is told to the learner with a [`LearnEvent`] about the frame it
//! happened at, and the learner's [`LearnReport`]s are waited for: the shape's (its
//! learned border sets the start circle's radius), each trial's verdict before the next
//! trial, and `Learned` at the end. The protocol never reads ground truth: it steers by
//! the frames' IR and odometry and the estimator's front gap.

use std::f64::consts::{PI, TAU};

use agp_affordance::LearnerConfig;
use agp_shared_types::angle::wrap_angle;
use agp_shared_types::{
    GRID_SIDE, IR_SENSOR_COUNT, LearnEvent, LearnEventKind, LearnReport, LearnReportKind,
};
use agp_world::{Pose, RobotDescription};
use glam::DVec2;

use crate::{
    CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, PushPhase, PushRoutine, PushSettings,
};

/// The alphas of the protocol, degrees, in the order they are run.
pub const ALPHAS_DEG: [f64; 3] = [0.0, 15.0, -15.0];

/// The shape circling's approach gives up after this long, seconds of simulated time.
pub const SHAPE_APPROACH_TIMEOUT_S: f64 = 5.0;
/// Speed of the shape circling's approach, m/s.
const SHAPE_APPROACH_SPEED: f64 = 0.08;

/// The latest frame, as the protocol reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnFrame {
    /// Physics step of the frame.
    pub step: u64,
    /// Simulated time, s.
    pub sim_time_s: f64,
    /// Counts IR samples; unchanged readings repeat the last sample.
    pub ir_sample: u64,
    /// Raw IR readings, IR1..IR8.
    pub ir_raw: [f32; IR_SENSOR_COUNT],
    /// The robot's pose by odometry.
    pub odometry: Pose,
}

/// Something that made a world's call fail but lets the protocol go on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Disruption {
    /// The world restarted (physics): the shape circling or the trial under way runs again
    /// from its reset.
    WorldRestarted,
    /// The learner restarted and lost what it learned: the protocol starts over, in a new
    /// session.
    LearnerRestarted,
}

/// What the protocol drives: the robot's frames and wheels, the experimenter's hands (who
/// puts the object and the robot back), and the learner it tells each step and hears from.
pub trait LearnWorld {
    /// Why a call failed.
    type Error;
    /// The latest frame.
    fn frame(&self) -> LearnFrame;
    /// The estimator's front gap at the latest frame (m, `None`: nothing ahead).
    fn front_gap(&self) -> Option<f64>;
    /// Whether the estimator sees the front gap stalled at the latest frame (stopped
    /// shrinking while the robot drove forward: `ObjectEstimate::stalled`).
    fn stalled(&self) -> bool;
    /// Applies wheel speeds (m/s) for one physics step; the next frame is the latest.
    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), Self::Error>;
    /// Puts the object and the robot at these poses (the experimenter puts the object back
    /// at its start and the robot at a start pose); the reset world's frame is the latest.
    fn reset(&mut self, object: Pose, robot: Pose) -> Result<(), Self::Error>;
    /// Tells the learner `event`, stamped with the latest frame (its step, IR and
    /// odometry): the learner has seen that frame and takes the event before the next.
    fn tell(&mut self, event: LearnEvent) -> Result<(), Self::Error>;
    /// The learner's next report of one of `kinds`: waited for over a pipeline (a
    /// `Learned` report may take long), at hand in-process. Reports of other kinds that
    /// arrived meanwhile are dropped.
    fn wait_report(&mut self, kinds: &[LearnReportKind]) -> Result<LearnReport, Self::Error>;
    /// A new protocol run's session id ([`LearnEvent::session`]): unique per run, not 0.
    fn new_session(&mut self) -> u64;
    /// Whether `error` is a [`Disruption`] the protocol rides out; `None` ends it.
    fn disruption(&self, error: &Self::Error) -> Option<Disruption> {
        let _ = error;
        None
    }
}

/// How the protocol runs: the in-process bench's defaults, which the pipeline shares.
#[derive(Debug, Clone)]
pub struct LearnProtocolSettings {
    /// Alphas of the trials, degrees, in the order they are run.
    pub alphas_deg: Vec<f64>,
    /// Trials per alpha, evenly spread round the object.
    pub trials_per_alpha: u32,
    /// Approach and push. The default pushes for 0.5 s at 100 mm/s (about 40 mm): the push
    /// duration is the one free parameter of the protocol, and 0.5 s gives the paper's
    /// largest A0 rotation of the triangle (39.51 deg) within a degree.
    pub push: PushSettings,
    /// The circlings.
    pub circle: CircleSettings,
    /// Robot start: this far (m) outside the learned border's farthest point plus the
    /// robot's radius.
    pub start_margin_m: f64,
    /// Back-off after the push, seconds, at `backoff_speed` m/s.
    pub backoff_s: f64,
    /// Reverse speed of the back-off, m/s.
    pub backoff_speed: f64,
    /// Where the robot starts for the shape circling: this far (m) from the object's
    /// centroid, plus the robot's radius and `start_margin_m`. `None` (the default, and
    /// what every agp learner uses) starts outside anything the gradients' grid can hold
    /// ([`max_object_reach_m`], 128 mm): before the shape circling nothing learned tells
    /// how far the object reaches. Over seeds 1-10 on the four built-in objects it learned
    /// as well as a start at the object's true circumscribed radius (14 against 13 of the
    /// learning benchmark's targets missed, in 40 object runs).
    pub shape_start_reach_m: Option<f64>,
}

/// The farthest any object the gradients can hold reaches from its centroid, m: half the
/// grid's side (128 mm). Where the robot starts before anything tells how far an object
/// reaches (the shape circling, the scripted drive).
pub fn max_object_reach_m() -> f64 {
    LearnerConfig::default().cell_size_m * GRID_SIDE as f64 / 2.0
}

impl Default for LearnProtocolSettings {
    /// The paper's alphas, 60 trials per alpha, a 0.5 s push.
    fn default() -> Self {
        Self {
            alphas_deg: ALPHAS_DEG.to_vec(),
            trials_per_alpha: 60,
            push: PushSettings {
                push_duration: 0.5,
                ..PushSettings::default()
            },
            circle: CircleSettings::default(),
            start_margin_m: 0.02,
            backoff_s: 0.15,
            backoff_speed: 0.08,
            shape_start_reach_m: None,
        }
    }
}

impl LearnProtocolSettings {
    /// The defaults with `trials_per_alpha` trials per alpha and a push of `push_s` seconds.
    pub fn new(trials_per_alpha: u32, push_s: f64) -> Self {
        let mut s = Self {
            trials_per_alpha,
            ..Self::default()
        };
        s.push.push_duration = push_s;
        s
    }

    /// Trials of the whole protocol.
    pub fn total_trials(&self) -> u32 {
        self.trials_per_alpha
            .saturating_mul(self.alphas_deg.len() as u32)
    }
}

/// How one trial went, as the planner saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrialRun {
    /// The approach met nothing (or lost it): no push.
    NoContact,
    /// Pushed, backed off and circled; whether the circling closed its lap.
    Pushed {
        /// The circling closed its lap (else it timed out).
        lap_closed: bool,
    },
}

/// What the protocol did, for a progress display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProtocolStep {
    /// The shape circling ended and the learner answered (`ShapeLearned`).
    ShapeLearned {
        /// The circling closed its lap.
        lap_closed: bool,
        /// The learner's report: `value` border points, `border_radius_m`.
        report: LearnReport,
    },
    /// A trial ended and the learner gave its verdict.
    Trial {
        /// Trials done, this one included.
        done: u32,
        /// Trials in all.
        total: u32,
        /// The trial's alpha, deg.
        alpha_deg: f64,
        /// Where the robot started round the object, rad.
        phi_rad: f64,
        /// How it went, as the planner saw it.
        run: TrialRun,
        /// The learner's verdict (`TrialLearned` or `TrialRejected`) and counts.
        report: LearnReport,
    },
    /// A step runs again (the world restarted) or the protocol starts over (the learner
    /// restarted).
    Again {
        /// What happened.
        why: Disruption,
        /// The trial run again (its index), `None` for the shape circling or a start over.
        trial: Option<u32>,
    },
    /// The learner reported the gradients learned.
    Learned(LearnReport),
}

/// Why the protocol stopped.
#[derive(Debug, thiserror::Error)]
pub enum LearnProtocolError<E> {
    /// The world failed (not a disruption it rides out).
    #[error("{0}")]
    World(E),
    /// The settings cannot run.
    #[error("learning protocol settings: {0}")]
    Settings(&'static str),
    /// The shape circling's approach met nothing.
    #[error("the shape circling's approach met no object within {SHAPE_APPROACH_TIMEOUT_S} s")]
    ShapeApproach,
    /// The learner could not learn the shape from the circling; `too_large_m`: the border it
    /// saw reaches that far, beyond the gradient's grid.
    #[error("the learner could not learn the shape from the circling{}", match too_large_m {
        Some(r) => format!(": the object is too large, its border reaches {:.0} mm from its centroid", r * 1e3),
        None => String::new(),
    })]
    ShapeFailed {
        /// How far the border seen reaches (m) when that is why.
        too_large_m: Option<f64>,
    },
    /// The learner learned a shape without a border to start pushes from.
    #[error("the learned shape has no border (radius {0} m)")]
    NoBorder(f64),
}

/// The protocol over one object: its settings, the robot, the object's start pose (where
/// the experimenter puts it back) and, once the shape is learned, the start circle.
pub struct LearnProtocol {
    settings: LearnProtocolSettings,
    robot: RobotDescription,
    placement: Pose,
    /// One routine for every circling, restarted each time: its buffers are allocated once.
    circling: CircleRoutine,
    /// Radius of the trials' start circle, from the learned border (NaN before).
    start_radius_m: f64,
    session: u64,
}

impl LearnProtocol {
    /// The protocol learning the object the experimenter puts back at `placement` (world
    /// frame, which fixes the learned frame), seen and driven as `robot`.
    pub fn new(settings: LearnProtocolSettings, robot: &RobotDescription, placement: Pose) -> Self {
        Self {
            circling: CircleRoutine::new(settings.circle, robot, 0.0),
            settings,
            robot: robot.clone(),
            placement,
            start_radius_m: f64::NAN,
            session: 0,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &LearnProtocolSettings {
        &self.settings
    }

    /// Radius of the trials' start circle round the centroid (m): the learned border's
    /// radius plus the robot's and the start margin. NaN before the shape is learned.
    pub fn start_radius_m(&self) -> f64 {
        self.start_radius_m
    }

    /// Sets the start circle from a learned border's radius (m), as [`Self::shape`]'s
    /// report does.
    pub fn set_border_radius(&mut self, border_radius_m: f64) {
        self.start_radius_m =
            border_radius_m + self.robot.body_radius + self.settings.start_margin_m;
    }

    /// The robot on the start circle of radius `r` at angle `phi` (rad, from the centroid),
    /// facing the centroid turned by `alpha` (rad).
    pub fn start_pose_at(&self, r: f64, phi: f64, alpha: f64) -> Pose {
        let c = self.placement.position() + DVec2::from_angle(phi) * r;
        Pose::new(c.x, c.y, wrap_angle(phi + PI + alpha))
    }

    /// The robot on the trials' start circle at angle `phi`, facing the centroid turned by
    /// `alpha_deg`.
    pub fn start_pose(&self, phi: f64, alpha_deg: f64) -> Pose {
        self.start_pose_at(self.start_radius_m, phi, alpha_deg.to_radians())
    }

    fn event(&self, kind: LearnEventKind) -> LearnEvent {
        LearnEvent {
            kind: kind as u32,
            session: self.session,
            total: self.settings.total_trials(),
            object: self.placement,
            ..LearnEvent::default()
        }
    }

    /// Tells `world` `event` about its latest frame.
    fn tell<W: LearnWorld>(world: &mut W, mut event: LearnEvent) -> Result<(), W::Error> {
        let f = world.frame();
        event.step = f.step;
        event.ir_sample = f.ir_sample;
        event.ir_raw = f.ir_raw;
        event.odometry = f.odometry;
        world.tell(event)
    }

    /// Circles the object until the routine ends; returns whether the lap closed.
    pub fn circle<W: LearnWorld>(&mut self, world: &mut W) -> Result<bool, W::Error> {
        let mut f = world.frame();
        self.circling.restart(f.sim_time_s);
        loop {
            let (l, r) = self
                .circling
                .update(f.sim_time_s, f.ir_sample, f.odometry, &f.ir_raw);
            if let CirclePhase::Done { outcome, .. } = self.circling.phase() {
                return Ok(outcome == CircleOutcome::Closed);
            }
            world.step(l, r)?;
            f = world.frame();
        }
    }

    /// Approach until contact is inferred from the front gap, then push: the push
    /// routine from the latest frame. `at_contact` hears the frame at which contact was
    /// inferred (before the push's first command). Returns the routine's verdict: whether
    /// the push was made in contact.
    pub fn approach_and_push<W: LearnWorld>(
        &self,
        world: &mut W,
        mut at_contact: impl FnMut(&mut W) -> Result<(), W::Error>,
    ) -> Result<bool, W::Error> {
        let mut f = world.frame();
        let mut routine = PushRoutine::new(self.settings.push, f.sim_time_s);
        loop {
            let before = routine.phase();
            let (l, r) = routine.step(
                world.front_gap(),
                world.stalled(),
                f.sim_time_s,
                f.ir_sample,
            );
            let after = routine.phase();
            if matches!(before, PushPhase::Approach { .. })
                && matches!(after, PushPhase::Push { .. })
            {
                at_contact(world)?;
            }
            if let PushPhase::Done { contact } = after {
                return Ok(contact);
            }
            world.step(l, r)?;
            f = world.frame();
        }
    }

    /// Drives at `speed` (m/s, both wheels) for `seconds` of simulated time.
    pub fn hold<W: LearnWorld>(world: &mut W, seconds: f64, speed: f64) -> Result<(), W::Error> {
        let t0 = world.frame().sim_time_s;
        while world.frame().sim_time_s - t0 < seconds {
            world.step(speed, speed)?;
        }
        Ok(())
    }

    /// The shape circling: object at its start pose, robot to its left
    /// ([`LearnProtocolSettings::shape_start_reach_m`]); approach until the circling's gap,
    /// one lap; tells
    /// `ShapeBegin` and `ShapeEnd` (`flag`: lap closed). Returns whether the lap closed.
    pub fn shape<W: LearnWorld>(
        &mut self,
        world: &mut W,
    ) -> Result<bool, LearnProtocolError<W::Error>> {
        let reach = self
            .settings
            .shape_start_reach_m
            .unwrap_or_else(max_object_reach_m);
        let r = reach + self.robot.body_radius + self.settings.start_margin_m;
        let start = self.start_pose_at(r, PI, 0.0);
        world
            .reset(self.placement, start)
            .map_err(LearnProtocolError::World)?;
        Self::tell(world, self.event(LearnEventKind::ShapeBegin))
            .map_err(LearnProtocolError::World)?;
        let t0 = world.frame().sim_time_s;
        // Stop 2 mm before the circling's gap: the robot coasts about that far past the
        // reading that ends the approach (one IR sample at 80 mm/s).
        let gap = self.settings.circle.gap + 0.002;
        loop {
            if world.front_gap().is_some_and(|g| g <= gap) {
                break;
            }
            if world.frame().sim_time_s - t0 >= SHAPE_APPROACH_TIMEOUT_S {
                return Err(LearnProtocolError::ShapeApproach);
            }
            world
                .step(SHAPE_APPROACH_SPEED, SHAPE_APPROACH_SPEED)
                .map_err(LearnProtocolError::World)?;
        }
        let closed = self.circle(world).map_err(LearnProtocolError::World)?;
        let mut end = self.event(LearnEventKind::ShapeEnd);
        end.flag = u32::from(closed);
        Self::tell(world, end).map_err(LearnProtocolError::World)?;
        Ok(closed)
    }

    /// Trial `index` at `alpha_deg` from angle `phi` (rad) round the object: reset, approach
    /// and push, back off, circle; tells `TrialBegin`, `Contact`, `PushEnd` (`flag`:
    /// contact) and, after a push, `TrialEnd` (`flag`: lap closed). Needs the start circle
    /// ([`Self::shape`] or [`Self::set_border_radius`]).
    pub fn trial<W: LearnWorld>(
        &mut self,
        world: &mut W,
        index: u32,
        alpha_deg: f64,
        phi: f64,
    ) -> Result<TrialRun, W::Error> {
        world.reset(self.placement, self.start_pose(phi, alpha_deg))?;
        let mut ev = self.event(LearnEventKind::TrialBegin);
        ev.index = index;
        ev.alpha_deg = alpha_deg;
        ev.angle_rad = phi;
        Self::tell(world, ev)?;
        let contact = self.approach_and_push(world, |w| {
            ev.kind = LearnEventKind::Contact as u32;
            Self::tell(w, ev)
        })?;
        ev.kind = LearnEventKind::PushEnd as u32;
        ev.flag = u32::from(contact);
        Self::tell(world, ev)?;
        if !contact {
            return Ok(TrialRun::NoContact);
        }
        Self::hold(world, self.settings.backoff_s, -self.settings.backoff_speed)?;
        let lap_closed = self.circle(world)?;
        ev.kind = LearnEventKind::TrialEnd as u32;
        ev.flag = u32::from(lap_closed);
        Self::tell(world, ev)?;
        Ok(TrialRun::Pushed { lap_closed })
    }

    /// After the shape circling ([`Self::shape`], whose lap closed or not): waits for the
    /// learner's verdict on the shape, takes its border radius (the start circle follows
    /// from it) and says `ShapeLearned`. A shape the learner refused, or a border that is
    /// not a positive radius, is the error.
    pub(crate) fn take_shape<W: LearnWorld>(
        &mut self,
        world: &mut W,
        lap_closed: bool,
        progress: &mut dyn FnMut(ProtocolStep),
    ) -> Result<(), LearnProtocolError<W::Error>> {
        let report = world
            .wait_report(&[LearnReportKind::ShapeLearned, LearnReportKind::ShapeFailed])
            .map_err(LearnProtocolError::World)?;
        if report.kind != LearnReportKind::ShapeLearned as u32 {
            return Err(LearnProtocolError::ShapeFailed {
                too_large_m: (report.border_radius_m > 0.0).then_some(report.border_radius_m),
            });
        }
        let border = report.border_radius_m;
        if !(border.is_finite() && border > 0.0) {
            return Err(LearnProtocolError::NoBorder(border));
        }
        self.set_border_radius(border);
        progress(ProtocolStep::ShapeLearned { lap_closed, report });
        Ok(())
    }

    /// The whole protocol: the shape circling, every trial (each answered by the learner
    /// before the next), `LearningDone`; returns the learner's `Learned` report (whether
    /// it saved the gradients is its `valid`). A restarted world runs the step under way
    /// again; a restarted learner starts the protocol over in a new session. `progress`
    /// hears each step.
    pub fn run<W: LearnWorld>(
        &mut self,
        world: &mut W,
        progress: &mut dyn FnMut(ProtocolStep),
    ) -> Result<LearnReport, LearnProtocolError<W::Error>> {
        if self.settings.trials_per_alpha == 0 {
            return Err(LearnProtocolError::Settings(
                "at least one trial per alpha is needed",
            ));
        }
        if self.settings.alphas_deg.is_empty() {
            return Err(LearnProtocolError::Settings("at least one alpha is needed"));
        }
        loop {
            // Each run of the protocol is a session of its own: a learner that still
            // holds trials of an earlier one (this planner restarted) drops them.
            self.session = world.new_session();
            match self.run_once(world, progress) {
                Err(LearnProtocolError::World(e))
                    if world.disruption(&e) == Some(Disruption::LearnerRestarted) =>
                {
                    progress(ProtocolStep::Again {
                        why: Disruption::LearnerRestarted,
                        trial: None,
                    });
                }
                other => return other,
            }
        }
    }

    fn restarted<W: LearnWorld>(world: &W, e: &LearnProtocolError<W::Error>) -> bool {
        matches!(e, LearnProtocolError::World(e) if world.disruption(e) == Some(Disruption::WorldRestarted))
    }

    /// One run of the protocol, from the shape circling to the `Learned` report.
    fn run_once<W: LearnWorld>(
        &mut self,
        world: &mut W,
        progress: &mut dyn FnMut(ProtocolStep),
    ) -> Result<LearnReport, LearnProtocolError<W::Error>> {
        let world_err = LearnProtocolError::World;
        let lap_closed = loop {
            match self.shape(world) {
                Ok(c) => break c,
                Err(e) if Self::restarted(world, &e) => progress(ProtocolStep::Again {
                    why: Disruption::WorldRestarted,
                    trial: None,
                }),
                Err(e) => return Err(e),
            }
        };
        self.take_shape(world, lap_closed, progress)?;
        let n = self.settings.trials_per_alpha;
        let total = self.settings.total_trials();
        let mut index = 0;
        for a in 0..self.settings.alphas_deg.len() {
            let alpha = self.settings.alphas_deg[a];
            for k in 0..n {
                let phi = TAU * f64::from(k) / f64::from(n);
                let run = loop {
                    match self.trial(world, index, alpha, phi) {
                        Ok(r) => break r,
                        Err(e) if world.disruption(&e) == Some(Disruption::WorldRestarted) => {
                            progress(ProtocolStep::Again {
                                why: Disruption::WorldRestarted,
                                trial: Some(index),
                            })
                        }
                        Err(e) => return Err(world_err(e)),
                    }
                };
                index += 1;
                // One report per trial: its verdict before the next trial starts.
                let report = world
                    .wait_report(&[
                        LearnReportKind::TrialLearned,
                        LearnReportKind::TrialRejected,
                    ])
                    .map_err(world_err)?;
                progress(ProtocolStep::Trial {
                    done: index,
                    total,
                    alpha_deg: alpha,
                    phi_rad: phi,
                    run,
                    report,
                });
            }
        }
        Self::tell(world, self.event(LearnEventKind::LearningDone)).map_err(world_err)?;
        let learned = world
            .wait_report(&[LearnReportKind::Learned])
            .map_err(world_err)?;
        progress(ProtocolStep::Learned(learned));
        Ok(learned)
    }
}
