//! The planner's logic, free of shared memory: contact inference from IR, the push, circling and travel routines, the push choice, the learning protocol against any [`LearnWorld`], and episodes of the benchmark tasks (Algorithm 5) against any [`World`]: the physics process over iceoryx2 or, with feature `sim`, the physics library in-process.

mod active_trial_chooser;
mod circle_routine;
mod episode;
mod estimate_log;
mod learning_protocol;
mod limit_surface;
mod push_choice;
mod push_model;
mod push_routine;
mod push_service;
mod travel;
mod world;

pub use active_trial_chooser::{ActiveSettings, ActiveTrialChooser, TrialChoice, run_active};
pub use agp_affordance::approach_start;
pub use circle_routine::{CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, Side};
pub use episode::{
    EpisodeConfig, EpisodeEnd, EpisodeResult, EpisodeRunError, Evaluation, PlannerKind,
    PlannerParseError, PoseSample, Task, distance_to_path, drive_episode, lookahead_point,
};
pub use estimate_log::{EstimateLog, EstimateVerdict};
pub use learning_protocol::{
    ALPHAS_DEG, Disruption, LearnFrame, LearnProtocol, LearnProtocolError, LearnProtocolSettings,
    LearnWorld, ProtocolStep, SHAPE_APPROACH_TIMEOUT_S, TrialRun, max_object_reach_m,
};
pub use limit_surface::{ContactMode, Footprint, GRAVITY_MPS2, LimitSurface, PointPush, Twist};
pub use push_choice::{
    Goal, PathFollowing, PushChoiceSettings, PushPlan, PushPlanner, path_direction_at, path_offset,
    path_projection, symmetric_angle_error,
};
pub use push_model::{PushModel, PushedObject, learned_push_travel_m};
pub use push_routine::{PushPhase, PushRoutine, PushSettings};
pub use push_service::{aim_point_at, learned_push_length_m};
pub use travel::{
    TravelPhase, TravelRoutine, TravelSettings, orbit_waypoints, orbit_waypoints_into,
};
pub use world::{ExternalPush, PushQuery, Senses, World, WorldStepError};
