//! The planner's logic, free of shared memory: contact inference from IR and the push routine.

mod circle_routine;
mod contact_sense;
mod push_choice;
mod push_routine;
mod travel;

pub use circle_routine::{CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, Side};
pub use contact_sense::ContactSense;
pub use push_choice::{
    Goal, PushChoiceSettings, PushPlan, PushPlanner, approach_start, symmetric_angle_error,
};
pub use push_routine::{PushPhase, PushRoutine, PushSettings};
pub use travel::{TravelPhase, TravelRoutine, TravelSettings, orbit_waypoints};
