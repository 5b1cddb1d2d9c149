//! Forwarding an agp instance's topics to a Zenoh session and back, so the planner of one instance drives the physics and estimator of another that shares no memory with it.
//!
//! Each payload crosses as its `#[repr(C)]` bytes, its iceoryx2 type name and size checked
//! at the far end ([`wire`]); frames, estimates and grids go from the robot side to the
//! planner side, commands, resets, the planner's events and the task back ([`BRIDGED_TOPICS`]).
//! The latched state (the latest frame, estimate and task, the latest whole grid set) is
//! sent once to a far end that joins, then only what is published: a grid set crosses once.
//!
//! The link runs over Zenoh's TLS transport with mutual authentication ([`tls`]: a CA of
//! the link's own, a certificate per side), or over plain TCP when asked for explicitly.

#[cfg(feature = "link")]
mod bridge;
mod endpoint;
#[cfg(feature = "link")]
mod floor;
#[cfg(feature = "link")]
mod keygen;
#[cfg(feature = "link")]
mod ports;
mod route;
pub mod tls;
#[cfg(feature = "link")]
pub mod trace;
pub mod wire;

#[cfg(feature = "link")]
pub use bridge::{BridgeConfig, BridgeEnd, BridgeError, BridgeReport, FAR_TIMEOUT, run_bridge};
pub use endpoint::{Endpoint, EndpointParseError};
#[cfg(feature = "link")]
pub use floor::{FloorError, FloorFigures, floor_ping, floor_pong};
#[cfg(feature = "link")]
pub use keygen::keygen;
#[cfg(feature = "link")]
pub use ports::Restamp;
pub use route::{
    BRIDGED_TOPICS, BridgedTopic, Latch, Side, TopicListParseError, all_topics, bridged_topic,
    parse_topics,
};
pub use tls::{TlsError, TlsKeys};
#[cfg(feature = "link")]
pub use trace::TRACE_ENV;

/// The environment variable that says how a bridge's threads wait (`BridgeConfig::wait`,
/// `agp bridge --wait`), named as `AGP_WAIT` names a strategy; `block` when unset. Not
/// `AGP_WAIT` itself: a bridge is woken by the kernel (an iceoryx2 event's socket, Zenoh's
/// receiving thread), and one that polls takes the cores from the threads it waits for.
pub const BRIDGE_WAIT_ENV: &str = "AGP_BRIDGE_WAIT";
