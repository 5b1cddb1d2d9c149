//! Every payload that crosses a process boundary, and the one place that builds an instance's iceoryx2 config and names its services.
//!
//! Payloads are `#[repr(C)]`, fixed-size and self-contained (no pointers), so iceoryx2 can
//! place them in shared memory and every process reads them in place. Each carries a
//! version in its iceoryx2 type name (`agp::IrFrame.v1`): iceoryx2 compares name, size and
//! alignment when a port connects, and only the version notices a changed layout that
//! keeps the other two. Change a payload, bump its version.
//!
//! Units: SI inside (metres, seconds, radians), as in the rest of the code.

mod instance;
mod payloads;

pub use instance::{
    Instance, InstanceNameError, MAX_INSTANCE_NAME_LEN, ServiceNames, instance_files_in,
};
pub use payloads::*;
