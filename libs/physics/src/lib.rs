//! The physics of the world: rapier2d with the E-puck, one object, Coulomb floor friction over the footprint, and the robot's IR, odometry and overhead-fix senses.

mod convex_pieces;
mod drive;
pub mod finite_force;
mod floor_friction;
mod sensors;
mod sim;

pub use convex_pieces::convex_pieces;
pub use drive::drive_arc;
pub use floor_friction::{FloorFriction, FootprintCell, FrictionOutcome, G};
pub use sensors::{IR_COUNT, SensorState};
pub use sim::{CONTACT_DISTANCE, ContactImpulse, FloorModel, Sim, SimBuildError, SimConfig};
