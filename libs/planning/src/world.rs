//! What an episode drives: the robot's senses and wheels, one physics step at a time.
//!
//! The planner's logic sees the world only through [`World`]: the physics process over
//! iceoryx2 in the pipeline (the `agp-planner` binary's lockstep link), or the physics
//! library in-process (feature `sim`, for tests and examples). Ground truth is behind
//! [`World::object_truth`], which only the `oracle` and the evaluation call.

use agp_affordance::AffordanceGradient;
use agp_shared_types::{IR_SENSOR_COUNT, LearnEvent, ObjectEstimate, Pose2};
use agp_world::Pose;

/// One moment of the robot's senses: what a planner may read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Senses {
    /// Raw IR readings, IR1..IR8 (0..4095, higher is closer).
    pub ir_raw: [f32; IR_SENSOR_COUNT],
    /// Counts IR samples; unchanged readings repeat the last sample.
    pub ir_sample: u64,
    /// The robot's pose by odometry alone.
    pub odometry: Pose,
    /// The last overhead fix of the robot (meaningless while `fix_seq` is 0).
    pub fix: Pose,
    /// Counts overhead fixes; 0: none yet, or the fix is off.
    pub fix_seq: u64,
}

/// Why the world stopped answering in the middle of an episode.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorldStepError {
    /// The process was asked to stop (SIGTERM, Ctrl-C).
    #[error("shutdown requested")]
    Shutdown,
    /// Physics restarted: a new world from the scenario's start; the episode must start
    /// over from finding the object.
    #[error("physics restarted")]
    Restarted,
    /// The estimator restarted: what it perceived (the object's pose, its centroid) is
    /// gone; the episode must start over from finding the object, in the same world.
    #[error("the estimator restarted")]
    EstimatorRestarted,
    /// The link to physics failed (no frame in time, a port error).
    #[error("{0}")]
    Link(String),
}

/// The robot as an episode drives it: its senses and wheels, and the estimator that
/// perceives for it.
pub trait World {
    /// The latest senses (raw: the circling steers by the side IR).
    fn senses(&self) -> Senses;
    /// The estimator's estimate of the latest frame: the robot's pose, the front gap and
    /// contact, the object's pose and centroid and how far they may be off.
    fn perceived(&self) -> &ObjectEstimate;
    /// Tells the estimator what the planner does (a [`LearnEvent`] of a `Task*` kind),
    /// about the latest frame; it reads it before the next frame.
    fn tell(&mut self, event: LearnEvent) -> Result<(), WorldStepError>;
    /// Simulated time, s.
    fn sim_time(&self) -> f64;
    /// Physics steps since the world was built.
    fn step_count(&self) -> u64;
    /// Applies wheel speeds (m/s) for one physics step.
    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), WorldStepError>;
    /// The object's true pose now, where the world offers it: the `oracle`'s input and the
    /// evaluation's, nobody else's. `None` in the pipeline unless connected for the oracle.
    fn object_truth(&self) -> Option<Pose>;
    /// A newer gradient than the one the episode plans on, when the estimator learned on
    /// from the task's pushes and published it again (online learning); asked between
    /// two pushes, and the next pushes are planned on it. `None` (the default): the
    /// gradient the episode started with stays.
    fn newer_gradient(&mut self) -> Option<AffordanceGradient> {
        None
    }
    /// The push a push-level planner of another process chooses (`agp-planner --skills`),
    /// asked between two pushes; [`ExternalPush::Internal`] (the default): the episode's
    /// own planner chooses.
    fn external_push(&mut self, _query: &PushQuery) -> Result<ExternalPush, WorldStepError> {
        Ok(ExternalPush::Internal)
    }
}

/// What an episode tells a push-level planner of another process before each push.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushQuery {
    /// The object's estimated pose (world frame) and how far it may be off (m, rad).
    pub object: Pose2,
    pub error_m: f64,
    pub error_rad: f64,
    /// Place: the goal pose; trajectory: the point to head for (theta 0).
    pub goal: Pose2,
    pub tolerance_m: f64,
    pub tolerance_rad: f64,
    pub pushes: u32,
    pub pushes_since_estimate: u32,
    /// The object's rotational symmetry learned from S (0: a disc).
    pub symmetry_order: u32,
    /// The last pushes left the object where it was: a full push is wanted.
    pub full_only: bool,
    /// Radius of the circle pushes start from, round the centroid (m).
    pub start_radius_m: f64,
}

/// A push-level planner's answer to a [`PushQuery`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ExternalPush {
    /// No such planner: the episode chooses.
    Internal,
    /// Push at the aim point of `contact_deg` (object frame; see
    /// [`crate::aim_point_at`]), deviation `alpha_deg`, for `length_m` once in contact.
    Push {
        contact_deg: f64,
        alpha_deg: f64,
        length_m: f64,
    },
    /// The goal is reached.
    Done,
    /// No push helps.
    GiveUp,
}
