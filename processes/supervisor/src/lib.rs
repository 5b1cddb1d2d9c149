//! The supervisor's logic beside its CLI: a live session's goals, and the checks of a launch file's plan (`agp_launch`) that need the bridge or run a process.

mod goal_spec;
mod launch_checks;

pub use goal_spec::{GoalSpec, GoalSpecError, check_goal};
pub use launch_checks::{BRIDGE_CHECKS, CheckProcesses, bridge_binary, build_the_bridge_hint};
