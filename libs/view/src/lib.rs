//! A live view of an agp instance, or of an MCAP recording of one, in Foxglove: a Foxglove
//! WebSocket server (the `foxglove` crate) publishing what the estimator believes as
//! Foxglove's well-known messages.
//!
//! - [`Viewer::start`] binds the server with the view's channels ([`topics`]);
//! - [`serve_instance`] subscribes to a running instance (a node of its own, reading the
//!   estimates, IR frames, grids, task and goal; never ground truth) and publishes the
//!   latest of each at [`ViewOptions::rate_hz`];
//! - [`serve_recording`] does the same from an MCAP recording, paced by its log times;
//! - [`FoxgloveTap`] writes the same scene into a recording, in Foxglove's protobuf
//!   schemas (`agp record`, `agp export`), so the field's own tools open it.
//!
//! What each topic shows: [`topics`] and the `scene` functions. The object's polygon is
//! ground truth and never reaches the view: the object is drawn as the border learned from
//! the AG layer's S ([`learned_border`]) placed at the estimated pose.

mod border;
mod live;
mod replay;
mod scene;
mod server;
mod state;
mod tap;

use std::path::PathBuf;
use std::time::Duration;

pub use border::{BORDER_MIN_S, BORDER_RAYS, learned_border};
pub use live::{NODE_NAME, serve_instance};
pub use replay::{MAX_RECORD_BYTES, open_recording, serve_recording};
pub use scene::{GOAL_FRAME, GRID_FIELDS, OBJECT_FRAME, ROBOT_FRAME, WORLD_FRAME};
pub use server::{Viewer, topics};
pub use state::{AgLayer, GoalView, ViewState};
pub use tap::{FOXGLOVE_METADATA, FoxgloveTap, SCENE_RATE_HZ, channels};

/// Foxglove's default WebSocket port.
pub const DEFAULT_PORT: u16 = agp_shared_types::DEFAULT_VIEW_PORT;

/// Slowest and fastest scene rate, publications per second.
pub const RATE_HZ_RANGE: (f64, f64) = (0.5, 200.0);

/// How the view serves.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewOptions {
    /// The address to listen on (`127.0.0.1`: this machine only).
    pub host: String,
    /// The port; 0 picks a free one ([`Viewer::port`] says which).
    pub port: u16,
    /// Scene publications per second (of wall time live, of log time in a replay), within
    /// [`RATE_HZ_RANGE`].
    pub rate_hz: f64,
    /// The alpha (degrees) whose AG layer is shown: the nearest learned one within 7.5.
    pub alpha_deg: f64,
    /// A replay's speed: log seconds per wall second.
    pub speed: f64,
    /// A replay starts over at its end instead of holding its last scene.
    pub loop_playback: bool,
    /// The name the server gives clients.
    pub server_name: String,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            host: "127.0.0.1".to_owned(),
            port: DEFAULT_PORT,
            rate_hz: 20.0,
            alpha_deg: 0.0,
            speed: 1.0,
            loop_playback: false,
            server_name: "agp".to_owned(),
        }
    }
}

impl ViewOptions {
    /// The time between two publications.
    pub fn period(&self) -> Duration {
        let hz = if self.rate_hz.is_finite() {
            self.rate_hz.clamp(RATE_HZ_RANGE.0, RATE_HZ_RANGE.1)
        } else {
            20.0
        };
        Duration::from_secs_f64(1.0 / hz)
    }
}

/// What a view did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ViewSummary {
    /// Estimates, IR frames and grids read.
    pub estimates: u64,
    pub frames: u64,
    pub grids: u64,
    /// Recorded messages of a shown topic whose bytes were not their payload's size.
    pub refused: u64,
    /// Scene publications.
    pub published: u64,
    /// It stopped on SIGTERM/SIGINT.
    pub stopped_by_signal: bool,
    /// Live: the instance's supervisor went away.
    pub instance_went_down: bool,
    /// Replay: the recording was played to its end.
    pub recording_ended: bool,
}

/// Why the view could not serve.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The WebSocket server could not listen.
    #[error("cannot listen on {host}:{port}: {reason}")]
    Bind {
        host: String,
        port: u16,
        reason: String,
    },
    /// No supervisor runs the instance.
    #[error("instance `{0}` is not up (no supervisor answers on it); start it with `agp up`")]
    NotUp(String),
    /// A node, topic or port of the instance could not be opened.
    #[error("cannot open {what}: {reason}")]
    Open { what: &'static str, reason: String },
    /// A subscriber failed to receive.
    #[error("cannot receive: {0}")]
    Receive(String),
    /// The recording could not be read.
    #[error("cannot read the recording {}: {reason}", path.display())]
    Recording { path: PathBuf, reason: String },
}
