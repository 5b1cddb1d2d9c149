//! The Foxglove WebSocket server and its channels: publishes a [`ViewState`] as the scene.

use std::sync::Arc;

use agp_world::RobotDescription;
use foxglove::messages::{FrameTransforms, Grid, RawImage, SceneUpdate};
use foxglove::websocket::Capability;
use foxglove::{Channel, Context, WebSocketServer, WebSocketServerHandle};
use glam::DVec2;

use crate::border::learned_border;
use crate::scene;
use crate::state::ViewState;
use crate::{ViewError, ViewOptions};

/// The topics the view publishes, with what each shows (README, "Live view").
pub mod topics {
    /// `SceneUpdate`: the robot's body and heading at the estimator's fused pose.
    pub const ROBOT: &str = "/robot";
    /// `SceneUpdate`: the eight IR rays, as long as the readings say.
    pub const IR: &str = "/ir";
    /// `SceneUpdate`: the object as the estimator believes it: the learned border at the
    /// estimated pose, the bounds on position and heading, the contact point, the centroid.
    pub const ESTIMATE: &str = "/estimate";
    /// `SceneUpdate`: the goal under way.
    pub const GOAL: &str = "/goal";
    /// `FrameTransforms`: `world` -> `robot`, `object`, `goal`.
    pub const TF: &str = "/tf";
    /// `Grid`: the AG layer in the `object` frame.
    pub const AG_GRID: &str = "/ag/grid";
    /// `RawImage`: the AG layer as a picture.
    pub const AG_IMAGE: &str = "/ag/image";
    /// Every topic.
    pub const ALL: [&str; 7] = [ROBOT, IR, ESTIMATE, GOAL, TF, AG_GRID, AG_IMAGE];
}

/// The AG layer is sent again this often (wall time) for clients that connected after it
/// changed.
const LAYER_RESEND: std::time::Duration = std::time::Duration::from_secs(1);

/// A running Foxglove WebSocket server with the view's channels.
pub struct Viewer {
    _context: Arc<Context>,
    handle: Option<WebSocketServerHandle>,
    robot_channel: Channel<SceneUpdate>,
    ir_channel: Channel<SceneUpdate>,
    estimate_channel: Channel<SceneUpdate>,
    goal_channel: Channel<SceneUpdate>,
    tf_channel: Channel<FrameTransforms>,
    grid_channel: Channel<Grid>,
    image_channel: Channel<RawImage>,
    robot: RobotDescription,
    /// The layer version the border was read from, and the border.
    border: (u64, Option<Vec<DVec2>>),
    /// The layer version last sent to a client and when.
    layer_sent: Option<(u64, std::time::Instant)>,
    published: u64,
}

impl Viewer {
    /// Binds the server on `options.host:options.port` (port 0: any free port) with the
    /// view's channels. With `time`, the server tells clients the time of the data (a
    /// recording's log time), so Foxglove's clock follows the replay.
    pub fn start(options: &ViewOptions, time: bool) -> Result<Self, ViewError> {
        let context = Context::new();
        let channel = |topic: &str| context.channel_builder(topic).build();
        let robot_channel = channel(topics::ROBOT);
        let ir_channel = channel(topics::IR);
        let estimate_channel = channel(topics::ESTIMATE);
        let goal_channel = channel(topics::GOAL);
        let tf_channel = context.channel_builder(topics::TF).build();
        let grid_channel = context.channel_builder(topics::AG_GRID).build();
        let image_channel = context.channel_builder(topics::AG_IMAGE).build();
        let mut server = WebSocketServer::new()
            .name(options.server_name.clone())
            .bind(options.host.clone(), options.port)
            .context(&context);
        if time {
            server = server.capabilities([Capability::Time]);
        }
        let handle = server.start_blocking().map_err(|e| ViewError::Bind {
            host: options.host.clone(),
            port: options.port,
            reason: e.to_string(),
        })?;
        Ok(Self {
            _context: context,
            handle: Some(handle),
            robot_channel,
            ir_channel,
            estimate_channel,
            goal_channel,
            tf_channel,
            grid_channel,
            image_channel,
            robot: RobotDescription::epuck(),
            border: (0, None),
            layer_sent: None,
            published: 0,
        })
    }

    /// The port the server listens on.
    pub fn port(&self) -> u16 {
        self.handle.as_ref().map_or(0, WebSocketServerHandle::port)
    }

    /// How many clients are connected.
    pub fn clients(&self) -> usize {
        self.handle
            .as_ref()
            .map_or(0, WebSocketServerHandle::client_count)
    }

    /// How many times the scene was published.
    pub fn published(&self) -> u64 {
        self.published
    }

    /// Tells clients the data's time (ns since the epoch).
    pub fn broadcast_time(&self, ns: u64) {
        if let Some(h) = &self.handle {
            h.broadcast_time(ns);
        }
    }

    /// Publishes `state` stamped `ts` (ns since the epoch) on every channel a client
    /// subscribed to; builds nothing for a channel no one reads.
    pub fn publish(&mut self, state: &ViewState, ts: u64) {
        self.published += 1;
        if self.border.0 != state.layer_version {
            self.border = (
                state.layer_version,
                state.layer.as_ref().and_then(learned_border),
            );
        }
        let border = self.border.1.as_deref();
        if let Some(e) = &state.estimate {
            if self.robot_channel.has_sinks() {
                self.robot_channel
                    .log_with_time(&scene::robot_scene(&self.robot, e, ts), ts);
            }
            if self.estimate_channel.has_sinks() {
                self.estimate_channel
                    .log_with_time(&scene::estimate_scene(e, border, ts), ts);
            }
            if let Some(f) = &state.frame
                && self.ir_channel.has_sinks()
            {
                self.ir_channel
                    .log_with_time(&scene::ir_scene(&self.robot, &e.robot, &f.ir_raw, ts), ts);
            }
        }
        if self.goal_channel.has_sinks() {
            self.goal_channel
                .log_with_time(&scene::goal_scene(state.goal.as_ref(), border, ts), ts);
        }
        if self.tf_channel.has_sinks() {
            self.tf_channel.log_with_time(
                &scene::transforms(state.estimate.as_ref(), state.goal.as_ref(), ts),
                ts,
            );
        }
        if let Some(layer) = &state.layer {
            let due = self
                .layer_sent
                .is_none_or(|(v, at)| v != state.layer_version || at.elapsed() >= LAYER_RESEND);
            let grid = self.grid_channel.has_sinks();
            let image = self.image_channel.has_sinks();
            if due && (grid || image) {
                if grid {
                    self.grid_channel
                        .log_with_time(&scene::ag_grid(layer, ts), ts);
                }
                if image {
                    self.image_channel
                        .log_with_time(&scene::ag_image(layer, ts), ts);
                }
                self.layer_sent = Some((state.layer_version, std::time::Instant::now()));
            }
        }
    }

    /// Stops the server, closing every client's connection.
    pub fn stop(mut self) {
        if let Some(h) = self.handle.take() {
            h.stop().wait_blocking();
        }
    }
}
