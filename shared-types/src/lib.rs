//! Every payload that crosses a process boundary, and the names of an instance's iceoryx2 services.
//!
//! Payloads are `#[repr(C)]`, fixed-size and self-contained (no pointers), so iceoryx2 can
//! place them in shared memory and every process reads them in place. Each carries a
//! version in its iceoryx2 type name (`agp::IrFrame.v1`): iceoryx2 compares name, size and
//! alignment when a port connects, and only the version notices a changed layout that
//! keeps the other two. Change a payload, bump its version.
//!
//! This crate holds data and names only (and the pose and angle math every crate shares,
//! the rule for an instance's name and the names of the waiting strategies, so a launch
//! file is checked without iceoryx2): opening the services, waiting and driving are
//! `agp_runtime`'s. Its one dependency on iceoryx2 is the `ZeroCopySend` derive.
//!
//! Units: SI inside (metres, seconds, radians), as in the rest of the code.
//!
//! `Pose2`, the one pose type of the workspace, carries its frame transforms; [`angle`]
//! holds every angle wrapping. Both use `glam`, a plain math crate.

pub mod angle;
mod control;
mod instance_name;
mod payloads;
mod service_names;
mod skills;
mod wait_strategy;

pub use control::{
    ActiveEpoch, ControlKind, ControlRequest, ControlResponse, GoalState, GoalStatus,
    MAX_PAUSE_LEASE, MAX_STATUS_GOALS, MAX_STATUS_PROCESSES, MAX_STATUS_STRANGERS, ProcessState,
    ProcessStatus, STATUS_NODE_NAME_LEN, SWAP_ARGS_LEN, StrangerStatus, read_str, write_str,
};
pub use instance_name::{
    InstanceNameError, MAX_INSTANCE_NAME_LEN, ROOT_ENV, validate_instance_name,
};
pub use payloads::*;
pub use service_names::ServiceNames;
pub use skills::{PUSH_CHOICES, PUSH_REQUESTS, PushChoice, PushChoiceKind, PushRequest};
pub use wait_strategy::WaitStrategy;

/// CLOCK_MONOTONIC in nanoseconds: system-wide on Linux, so stamps from different
/// processes compare.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Default physics rate, in steps per second: launch.toml's `[clock] rate_hz` when absent,
/// and the probe's.
pub const DEFAULT_RATE_HZ: f64 = 640.0;

/// The live view's WebSocket port unless told otherwise (Foxglove's default): `agp view`'s
/// and a launch file's `view = true`.
pub const DEFAULT_VIEW_PORT: u16 = 8765;
