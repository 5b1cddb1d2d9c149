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

mod bridge;
mod endpoint;
mod floor;
mod ports;
mod route;
pub mod tls;
pub mod trace;
pub mod wire;

pub use bridge::{
    BRIDGE_WAIT_ENV, BridgeConfig, BridgeEnd, BridgeError, BridgeReport, FAR_TIMEOUT, run_bridge,
};
pub use endpoint::{Endpoint, EndpointParseError};
pub use floor::{FloorError, FloorFigures, floor_ping, floor_pong};
pub use ports::Restamp;
pub use route::{
    BRIDGED_TOPICS, BridgedTopic, Latch, Side, TopicListParseError, all_topics, bridged_topic,
    parse_topics,
};
pub use tls::{TlsError, TlsKeys, keygen};
pub use trace::TRACE_ENV;
