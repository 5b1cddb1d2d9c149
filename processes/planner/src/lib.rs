//! The planner's logic, free of shared memory: contact inference from IR and the push routine.

mod circle_routine;
mod contact_sense;
mod push_routine;

pub use circle_routine::{CircleOutcome, CirclePhase, CircleRoutine, CircleSettings, Side};
pub use contact_sense::ContactSense;
pub use push_routine::{PushPhase, PushRoutine, PushSettings};
