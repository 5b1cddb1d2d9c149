//! The iceoryx2 runtime every agp process shares: the service type, an instance's config and services, waiting, the lockstep driver, the control client, a hot swap's swapped-in side and the allocation counter.
//!
//! Payloads and service names are `agp_shared_types`'s; this crate opens the services under
//! those names, with one quality of service per topic, for every process of an instance.

pub mod alloc_count;
pub mod children;
pub mod control_client;
mod driver;
mod instance;
mod instance_lock;
mod owner_only_storage;
mod service;
mod swap_in;
mod wait;

pub use driver::{DriveError, LockstepDriver, TruthAccess};

/// Keeps iceoryx2's own log off the terminal: its warnings come as Debug dumps of its
/// internals (a profiler that outlives its instance printed screens of them), while every
/// failure that matters reaches the caller as an error, which agp reports in one line.
/// `IOX2_LOG_LEVEL` (`trace` ... `fatal`) turns them back on for debugging. Every agp
/// binary calls it first thing.
pub fn quiet_iceoryx2() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Fatal);
}
pub use instance::{
    ControlOpenError, ControlService, Instance, InstanceDirError, InstanceNameError,
    MAX_INSTANCE_NAME_LEN, OpenError, ROOT_ENV, RunningInstanceError, TAP_DEPTH, Topic,
    instance_files_in,
};
pub use instance_lock::{InstanceLock, InstanceLockError};
pub use service::{AgpIpc, EVENT_ID_MAX_VALUE, PooledGuard, PooledRc};
pub use swap_in::{SwapIn, SwapInError};
pub use wait::{
    WaitOutcome, WaitStrategy, Waiter, install_shutdown_handler, request_shutdown,
    shutdown_requested,
};
