//! The push-level service: a planner process of its own (the `agp` Python package's
//! `PushPlanner`) chooses each push; `agp-planner --skills` carries it out with the
//! planning library's skills (travel to the contact point, the push, the circling that
//! re-estimates the object). The executor asks on [`PUSH_REQUESTS`], the chooser answers
//! on [`PUSH_CHOICES`]; both carry the planner's epoch, so during a hot swap each executor
//! hears only its own chooser.

use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

use crate::Pose2;

/// The executor's questions (latched: a chooser that comes late reads the one pending).
pub const PUSH_REQUESTS: &str = "agp/push_requests";
/// The chooser's answers.
pub const PUSH_CHOICES: &str = "agp/push_choices";

/// "Which push next?", asked between two pushes of an episode.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::PushRequest.v1")]
pub struct PushRequest {
    /// 1, 2, ... per executor run; the answer names it.
    pub seq: u64,
    /// The asking planner's epoch (`AGP_EPOCH`).
    pub epoch: u64,
    /// The live session's goal under way (0: the scenario's task).
    pub goal_id: u64,
    /// The object's estimated pose, world frame (m, rad).
    pub object: Pose2,
    /// How far the estimate may be off (m, rad; infinite: unknown).
    pub sigma_xy: f64,
    pub sigma_theta: f64,
    /// The goal pose (m, rad) and its tolerance.
    pub goal: Pose2,
    pub tolerance_m: f64,
    pub tolerance_rad: f64,
    /// The robot's pose by the estimator (m, rad).
    pub robot: Pose2,
    /// Radius of the circle pushes start from, round the centroid (m).
    pub start_radius_m: f64,
    /// Simulated time (s).
    pub sim_time_s: f64,
    /// Pushes made in this episode so far, and since the last circling.
    pub pushes: u32,
    pub pushes_since_estimate: u32,
    /// The object's rotational symmetry learned from S (0: a disc).
    pub symmetry_order: u32,
    /// 1: the last pushes left the object where it was; a full-length push is wanted.
    pub full_only: u32,
}

/// What a [`PushChoice`] says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PushChoiceKind {
    /// Make the push `contact_deg`, `alpha_deg`, `length_mm`.
    Push = 1,
    /// The goal is reached: the episode ends, done.
    Done = 2,
    /// No push helps: the episode ends, lost.
    GiveUp = 3,
}

impl PushChoiceKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Push, Self::Done, Self::GiveUp]
            .into_iter()
            .find(|k| *k as u32 == v)
    }
}

/// The chooser's answer to one [`PushRequest`].
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::PushChoice.v1")]
pub struct PushChoice {
    /// The request answered.
    pub seq: u64,
    /// The answering planner's epoch (the request's).
    pub epoch: u64,
    /// A [`PushChoiceKind`] as u32.
    pub kind: u32,
    pub _pad: u32,
    /// Where the push aims: the ray from the centroid at this angle (object frame, deg)
    /// meets the learned border (S above 0.3).
    pub contact_deg: f64,
    /// The push's deviation from the centroid's direction (deg), as the gradient's alphas.
    pub alpha_deg: f64,
    /// How far the robot pushes once in contact (mm; the learned push is 50 mm).
    pub length_mm: f64,
}

const _: () = {
    use core::mem::{align_of, size_of};
    assert!(size_of::<PushRequest>() == 24 + 24 + 16 + 24 + 16 + 24 + 16 + 16);
    assert!(align_of::<PushRequest>() == 8);
    assert!(size_of::<PushChoice>() == 48 && align_of::<PushChoice>() == 8);
};
