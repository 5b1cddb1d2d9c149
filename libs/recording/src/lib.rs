//! Recording an agp instance in MCAP, reading recordings back, and the plan of a lockstep
//! replay.
//!
//! # The file
//!
//! - One MCAP channel per iceoryx2 topic of the instance ([`recorded_topics`]): the
//!   channel's topic is the service name (`agp/ir_frames`, ...), its message encoding
//!   [`MESSAGE_ENCODING`], its metadata `agp.type_name` and `agp.size`. Ground truth is
//!   not recorded.
//! - One schema per payload type: named by the payload's iceoryx2 type name
//!   (`agp::IrFrame.v2`), encoding [`SCHEMA_ENCODING`], data a text that lists every field
//!   (`offset size type name`, little-endian; [`Layout::schema_text`]).
//! - Message data: the payload's raw `#[repr(C)]` bytes, as iceoryx2 held them; read them
//!   with [`payload_from_bytes`] (or [`grid_from_bytes`] for the 64 KiB grids). `log_time`:
//!   Unix ns when the recorder took the message; `publish_time`: the payload's own publish
//!   stamp (moved from CLOCK_MONOTONIC to Unix time) where it has one, else the log time.
//! - Channels a [`Tap`] adds beside these, from the recorded messages (`agp record` adds
//!   the scene in Foxglove's protobuf schemas: agp-view's `FoxgloveTap`).
//! - Metadata [`RUN_METADATA`] ([`RunInfo`]: version, instance, scenario, clock, seed,
//!   launch file) and, once the recorder finished, [`RECORDING_METADATA`] (per topic
//!   `received`, `written`, `dropped`, `lost`).
//!
//! # Recording without slowing the ring
//!
//! [`Recorder`] is a subscriber of its own (its own node), drained on one thread and
//! written on another through a bounded queue; see the `recorder` module for what it drops
//! and how it counts it.

mod layout;
mod reader;
mod recorder;
mod replay;
mod tap;
mod topics;

use std::collections::BTreeMap;

pub use layout::{Field, Layout, type_name_of};
pub use mcap;
pub use reader::{ChannelInfo, MAX_RECORDING_BYTES, ReadError, Recording};
pub use recorder::{RecordError, RecordStats, Recorder, RecorderOptions, TopicStats};
pub use replay::{ReplayAction, ReplayError, ReplayScript, same_sensing};
pub use tap::{McapFile, Tap};
pub use topics::{
    Plain, TOPIC_COUNT, TopicSpec, grid_from_bytes, payload_from_bytes, recorded_topics,
};

/// Every message's encoding: the payload's raw `#[repr(C)]` bytes.
pub const MESSAGE_ENCODING: &str = "agp-repr-c";

/// Every schema's encoding: a text documenting the layout ([`Layout::schema_text`]).
pub const SCHEMA_ENCODING: &str = "agp-repr-c-layout";

/// Name of the metadata record describing the run ([`RunInfo`]).
pub const RUN_METADATA: &str = "agp.run";

/// Name of the metadata record the recorder writes at its end: per topic
/// `<topic>.received`, `.written`, `.dropped`, `.lost`.
pub const RECORDING_METADATA: &str = "agp.recording";

/// What a recording says of the run it recorded (the [`RUN_METADATA`] record), what a
/// replay needs: the scenario (a built-in name, or a file with its text), the clock and
/// rate, physics's seed, the instance, the launch file and agp's version.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunInfo {
    pub agp_version: String,
    pub instance: String,
    /// A built-in name or the scenario file's path, as the run named it.
    pub scenario: String,
    /// The scenario file's text, when it is a file.
    pub scenario_toml: Option<String>,
    /// `lockstep` or `realtime`; empty when unknown.
    pub clock: String,
    pub rate_hz: Option<f64>,
    /// Physics's noise seed (its `--seed`, else the scenario's).
    pub seed: Option<u64>,
    pub launch_file: Option<String>,
    pub launch_toml: Option<String>,
    /// Unix time the recording started, ns.
    pub started_unix_ns: u64,
}

impl RunInfo {
    /// The metadata record's map.
    pub fn to_metadata(&self) -> BTreeMap<String, String> {
        let mut m = BTreeMap::new();
        m.insert("agp_version".into(), self.agp_version.clone());
        m.insert("instance".into(), self.instance.clone());
        m.insert("scenario".into(), self.scenario.clone());
        m.insert("clock".into(), self.clock.clone());
        m.insert("started_unix_ns".into(), self.started_unix_ns.to_string());
        if let Some(t) = &self.scenario_toml {
            m.insert("scenario_toml".into(), t.clone());
        }
        if let Some(r) = self.rate_hz {
            m.insert("rate_hz".into(), r.to_string());
        }
        if let Some(s) = self.seed {
            m.insert("seed".into(), s.to_string());
        }
        if let Some(f) = &self.launch_file {
            m.insert("launch_file".into(), f.clone());
        }
        if let Some(t) = &self.launch_toml {
            m.insert("launch_toml".into(), t.clone());
        }
        m
    }

    /// Reads it back; missing or unreadable entries stay empty.
    pub fn from_metadata(m: &BTreeMap<String, String>) -> Self {
        let get = |k: &str| m.get(k).cloned();
        Self {
            agp_version: get("agp_version").unwrap_or_default(),
            instance: get("instance").unwrap_or_default(),
            scenario: get("scenario").unwrap_or_default(),
            scenario_toml: get("scenario_toml"),
            clock: get("clock").unwrap_or_default(),
            rate_hz: get("rate_hz").and_then(|v| v.parse().ok()),
            seed: get("seed").and_then(|v| v.parse().ok()),
            launch_file: get("launch_file"),
            launch_toml: get("launch_toml"),
            started_unix_ns: get("started_unix_ns")
                .and_then(|v| v.parse().ok())
                .unwrap_or(0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_info_survives_its_metadata_map() {
        let info = RunInfo {
            agp_version: "0.1.0".into(),
            instance: "default".into(),
            scenario: "/x/my.toml".into(),
            scenario_toml: Some("[object]\n".into()),
            clock: "lockstep".into(),
            rate_hz: Some(640.0),
            seed: Some(7),
            launch_file: Some("launch.toml".into()),
            launch_toml: Some("instance = \"default\"\n".into()),
            started_unix_ns: 123,
        };
        assert_eq!(RunInfo::from_metadata(&info.to_metadata()), info);
    }
}
