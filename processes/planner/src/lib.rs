//! The planner's logic, free of shared memory: contact inference from IR and the push routine.

mod contact_sense;
mod push_routine;

pub use contact_sense::ContactSense;
pub use push_routine::{PushPhase, PushRoutine, PushSettings};
