//! The planner's logic, free of shared memory: contact inference from IR, the push, circling and travel routines, the push choice, and episodes of the benchmark tasks against the in-process physics.

mod bench_tasks;
mod circle_routine;
mod contact_sense;
mod episode;
mod push_choice;
mod push_routine;
mod robot_localizer;
mod travel;

pub use agp_affordance::approach_start;
pub use bench_tasks::{PlannerSummary, median, place_goals, trajectory_error, trajectory_path};
pub use circle_routine::{CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, Side};
pub use contact_sense::ContactSense;
pub use episode::{
    EpisodeConfig, EpisodeEnd, EpisodeResult, EpisodeRunError, PlannerKind, PlannerParseError,
    PoseSample, Task, border_centroid, distance_to_path, lookahead_point, run_episode,
};
pub use push_choice::{Goal, PushChoiceSettings, PushPlan, PushPlanner, symmetric_angle_error};
pub use push_routine::{PushPhase, PushRoutine, PushSettings};
pub use robot_localizer::RobotLocalizer;
pub use travel::{TravelPhase, TravelRoutine, TravelSettings, orbit_waypoints};
