//! Every payload that crosses a process boundary, and the one place that builds an instance's iceoryx2 config and names its services.
//!
//! Payloads are `#[repr(C)]`, fixed-size and self-contained (no pointers), so iceoryx2 can
//! place them in shared memory and every process reads them in place. Each carries a
//! version in its iceoryx2 type name (`agp::IrFrame.v1`): iceoryx2 compares name, size and
//! alignment when a port connects, and only the version notices a changed layout that
//! keeps the other two. Change a payload, bump its version.
//!
//! Units: SI inside (metres, seconds, radians), as in the rest of the code.

pub mod alloc_count;
mod control;
mod driver;
mod instance;
mod owner_only_storage;
mod payloads;
mod service;
mod wait;

pub use control::{
    ActiveEpoch, ControlAskError, ControlClient, ControlKind, ControlOpenError, ControlRequest,
    ControlResponse, ControlService, MAX_PAUSE_LEASE, MAX_STATUS_PROCESSES, MAX_STATUS_STRANGERS,
    ProcessState, ProcessStatus, STATUS_NODE_NAME_LEN, SWAP_ARGS_LEN, StrangerStatus, read_str,
    write_str,
};
pub use driver::{DriveError, LockstepDriver};
pub use instance::{
    Instance, InstanceDirError, InstanceNameError, MAX_INSTANCE_NAME_LEN, OpenError, ROOT_ENV,
    ServiceNames, Topic, instance_files_in,
};
pub use payloads::*;
pub use service::{AgpIpc, EVENT_ID_MAX_VALUE, PooledGuard, PooledRc};
pub use wait::{
    WaitOutcome, WaitStrategy, Waiter, install_shutdown_handler, request_shutdown,
    shutdown_requested,
};

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
