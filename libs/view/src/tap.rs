//! The scene in a recording: [`FoxgloveTap`], an `agp_recording::Tap` that writes, beside a
//! recording's raw channels, what `agp view` shows, as Foxglove's protobuf schemas (message
//! encoding `protobuf`, the schema's `FileDescriptorSet` as schema data), so that
//! Foxglove, Lichtblick, Rerun and the `mcap` decoders open the file without agp.
//!
//! It keeps a [`ViewState`] from the recorded messages, as the live view does from the
//! ring, and writes the scene from the same `scene` functions, at [`SCENE_RATE_HZ`] of log
//! time; the AG layer once per set; one `foxglove.Log` line per event the processes sent
//! each other. It runs on the recorder's writing thread (or in `agp export`), never on
//! the ring.

use std::collections::BTreeMap;

use agp_recording::{McapFile, grid_from_bytes, payload_from_bytes};
use agp_shared_types::{
    ActiveEpoch, Goal, GoalEnd, IrFrame, LearnEvent, LearnEventKind, LearnReport, LearnReportKind,
    ObjectEstimate, Reset, ServiceNames, Task, TaskKind,
};
use agp_world::RobotDescription;
use foxglove::Encode;
use foxglove::messages::{
    FrameTransforms, Grid, Log, PointCloud, PoseInFrame, RawImage, SceneUpdate,
};
use glam::DVec2;
use mcap::McapError;

use crate::border::learned_border;
use crate::scene;
use crate::state::ViewState;

/// Scene messages per second of log time.
pub const SCENE_RATE_HZ: u64 = 25;

/// Name of the metadata record the tap writes at the end: messages per Foxglove topic.
pub const FOXGLOVE_METADATA: &str = "agp.foxglove";

/// The Foxglove channels of a recording: topic and schema name.
pub mod channels {
    /// `foxglove.FrameTransforms`: `world` -> `robot`, `object`, `goal` (as the view's `/tf`).
    pub const TF: (&str, &str) = ("/tf", "foxglove.FrameTransforms");
    /// `foxglove.SceneUpdate`: the robot's body and heading (the view's `/robot`).
    pub const ROBOT: (&str, &str) = ("/robot", "foxglove.SceneUpdate");
    /// `foxglove.SceneUpdate`: the IR rays (the view's `/ir`).
    pub const IR: (&str, &str) = ("/ir", "foxglove.SceneUpdate");
    /// `foxglove.SceneUpdate`: the learned border at the estimated pose and its bounds.
    pub const ESTIMATE: (&str, &str) = ("/estimate", "foxglove.SceneUpdate");
    /// `foxglove.SceneUpdate`: the goal under way.
    pub const GOAL: (&str, &str) = ("/goal", "foxglove.SceneUpdate");
    /// `foxglove.PoseInFrame`: the robot's estimated pose in `world`.
    pub const ROBOT_POSE: (&str, &str) = ("/robot/pose", "foxglove.PoseInFrame");
    /// `foxglove.PoseInFrame`: the object's estimated pose in `world`, while valid.
    pub const ESTIMATE_POSE: (&str, &str) = ("/estimate/pose", "foxglove.PoseInFrame");
    /// `foxglove.PointCloud`: the robot's body as points (for viewers without scenes).
    pub const ROBOT_POINTS: (&str, &str) = ("/robot/points", "foxglove.PointCloud");
    /// `foxglove.PointCloud`: the IR rays as points.
    pub const IR_POINTS: (&str, &str) = ("/ir/points", "foxglove.PointCloud");
    /// `foxglove.PointCloud`: the object as believed, the learned border filled.
    pub const ESTIMATE_POINTS: (&str, &str) = ("/estimate/points", "foxglove.PointCloud");
    /// `foxglove.Grid`: the AG layer in the `object` frame (the view's `/ag/grid`).
    pub const AG_GRID: (&str, &str) = ("/ag/grid", "foxglove.Grid");
    /// `foxglove.RawImage`: the AG layer as a picture (the view's `/ag/image`).
    pub const AG_IMAGE: (&str, &str) = ("/ag/image", "foxglove.RawImage");
    /// `foxglove.Log`: what the processes told each other (learning steps, reports, resets,
    /// tasks, goals and their ends, the active epoch).
    pub const LOG: (&str, &str) = ("/log", "foxglove.Log");
    /// Every channel, in the order their ids are given.
    pub const ALL: [(&str, &str); 13] = [
        TF,
        ROBOT,
        IR,
        ESTIMATE,
        GOAL,
        ROBOT_POSE,
        ESTIMATE_POSE,
        ROBOT_POINTS,
        IR_POINTS,
        ESTIMATE_POINTS,
        AG_GRID,
        AG_IMAGE,
        LOG,
    ];
}

/// Index of each channel in [`channels::ALL`].
#[derive(Debug, Clone, Copy)]
enum Ch {
    Tf,
    Robot,
    Ir,
    Estimate,
    Goal,
    RobotPose,
    EstimatePose,
    RobotPoints,
    IrPoints,
    EstimatePoints,
    AgGrid,
    AgImage,
    Log,
}

const CHANNELS: usize = channels::ALL.len();

/// Writes the scene of a recording in Foxglove's schemas (see the module's text).
pub struct FoxgloveTap {
    robot: RobotDescription,
    state: ViewState,
    /// The layer version the border was read from, and the border.
    border: (u64, Option<Vec<DVec2>>),
    /// The layer version last written.
    layer_written: u64,
    period_ns: u64,
    next_scene: u64,
    /// The newest log time seen, and whether the state changed since the last scene.
    last_time: u64,
    dirty: bool,
    ids: [u16; CHANNELS],
    sequence: [u32; CHANNELS],
    written: [u64; CHANNELS],
    /// Recorded messages of a shown topic whose bytes were not their payload's size.
    refused: u64,
    buf: Vec<u8>,
}

impl Default for FoxgloveTap {
    fn default() -> Self {
        Self::new(0.0)
    }
}

impl FoxgloveTap {
    /// A tap drawing the AG layer of `alpha_deg` (the nearest learned alpha).
    pub fn new(alpha_deg: f64) -> Self {
        Self {
            robot: RobotDescription::epuck(),
            state: ViewState::new(alpha_deg),
            border: (0, None),
            layer_written: 0,
            period_ns: 1_000_000_000 / SCENE_RATE_HZ,
            next_scene: 0,
            last_time: 0,
            dirty: false,
            ids: [0; CHANNELS],
            sequence: [0; CHANNELS],
            written: [0; CHANNELS],
            refused: 0,
            buf: Vec::with_capacity(64 << 10),
        }
    }

    /// Messages written per Foxglove topic so far.
    pub fn counts(&self) -> BTreeMap<&'static str, u64> {
        channels::ALL
            .iter()
            .zip(self.written)
            .map(|((topic, _), n)| (*topic, n))
            .collect()
    }

    /// Recorded messages it could not read (their size was not their payload's).
    pub fn refused(&self) -> u64 {
        self.refused
    }

    fn write<M: Encode>(
        &mut self,
        out: &mut McapFile,
        ch: Ch,
        msg: &M,
        t: u64,
    ) -> Result<(), McapError> {
        self.buf.clear();
        // A Vec grows as needed: encoding into one does not fail.
        if msg.encode(&mut self.buf).is_err() {
            return Ok(());
        }
        let k = ch as usize;
        let header = mcap::records::MessageHeader {
            channel_id: self.ids[k],
            sequence: self.sequence[k],
            log_time: t,
            publish_time: t,
        };
        out.write_to_known_channel(&header, &self.buf)?;
        self.sequence[k] = self.sequence[k].wrapping_add(1);
        self.written[k] += 1;
        Ok(())
    }

    fn log(
        &mut self,
        out: &mut McapFile,
        name: &str,
        text: String,
        t: u64,
    ) -> Result<(), McapError> {
        let line: Log = scene::log_line(name, text, t);
        self.write(out, Ch::Log, &line, t)
    }

    /// The scene at log time `t`, on every scene channel.
    fn scene(&mut self, out: &mut McapFile, t: u64) -> Result<(), McapError> {
        if self.border.0 != self.state.layer_version {
            self.border = (
                self.state.layer_version,
                self.state.layer.as_ref().and_then(learned_border),
            );
        }
        let border = self.border.1.take();
        let b = border.as_deref();
        let state = std::mem::take(&mut self.state);
        let r = self.scene_of(out, &state, b, t);
        self.state = state;
        self.border.1 = border;
        self.dirty = false;
        r
    }

    fn scene_of(
        &mut self,
        out: &mut McapFile,
        state: &ViewState,
        border: Option<&[DVec2]>,
        t: u64,
    ) -> Result<(), McapError> {
        let tf: FrameTransforms =
            scene::transforms(state.estimate.as_ref(), state.goal.as_ref(), t);
        // None yet: nothing to write (Rerun refuses a FrameTransforms without any).
        if !tf.transforms.is_empty() {
            self.write(out, Ch::Tf, &tf, t)?;
        }
        if let Some(e) = &state.estimate {
            let robot: SceneUpdate = scene::robot_scene(&self.robot, e, t);
            self.write(out, Ch::Robot, &robot, t)?;
            let estimate: SceneUpdate = scene::estimate_scene(e, border, t);
            self.write(out, Ch::Estimate, &estimate, t)?;
            let pose: PoseInFrame = scene::pose_in_world(&e.robot, t);
            self.write(out, Ch::RobotPose, &pose, t)?;
            if e.valid == 1 {
                let pose: PoseInFrame = scene::pose_in_world(&e.pose, t);
                self.write(out, Ch::EstimatePose, &pose, t)?;
            }
            let points: PointCloud = scene::robot_points(&self.robot, e, t);
            self.write(out, Ch::RobotPoints, &points, t)?;
            let points: PointCloud = scene::estimate_points(e, border, t);
            self.write(out, Ch::EstimatePoints, &points, t)?;
            if let Some(f) = &state.frame {
                let ir: SceneUpdate = scene::ir_scene(&self.robot, &e.robot, &f.ir_raw, t);
                self.write(out, Ch::Ir, &ir, t)?;
                let points: PointCloud = scene::ir_points(&self.robot, &e.robot, &f.ir_raw, t);
                self.write(out, Ch::IrPoints, &points, t)?;
            }
        }
        let goal: SceneUpdate = scene::goal_scene(state.goal.as_ref(), border, t);
        self.write(out, Ch::Goal, &goal, t)
    }

    /// The AG layer, when a new one was gathered.
    fn layer(&mut self, out: &mut McapFile, t: u64) -> Result<(), McapError> {
        if self.state.layer_version == self.layer_written {
            return Ok(());
        }
        self.layer_written = self.state.layer_version;
        let Some(layer) = self.state.layer.take() else {
            return Ok(());
        };
        let grid: Grid = scene::ag_grid(&layer, t);
        let image: RawImage = scene::ag_image(&layer, t);
        self.state.layer = Some(layer);
        self.write(out, Ch::AgGrid, &grid, t)?;
        self.write(out, Ch::AgImage, &image, t)
    }
}

fn refused<T>(v: Option<T>, refused: &mut u64) -> Option<T> {
    if v.is_none() {
        *refused += 1;
    }
    v
}

impl agp_recording::Tap for FoxgloveTap {
    fn begin(&mut self, out: &mut McapFile) -> Result<(), McapError> {
        let mut schemas: BTreeMap<&str, u16> = BTreeMap::new();
        let schema_of = |name: &str| match name {
            "foxglove.FrameTransforms" => FrameTransforms::get_schema(),
            "foxglove.SceneUpdate" => SceneUpdate::get_schema(),
            "foxglove.PoseInFrame" => PoseInFrame::get_schema(),
            "foxglove.PointCloud" => PointCloud::get_schema(),
            "foxglove.Grid" => Grid::get_schema(),
            "foxglove.RawImage" => RawImage::get_schema(),
            _ => Log::get_schema(),
        };
        let meta = BTreeMap::from([("agp.source".to_owned(), "agp-view scene".to_owned())]);
        for (k, (topic, name)) in channels::ALL.iter().enumerate() {
            let id = match schemas.get(name) {
                Some(id) => *id,
                None => {
                    let Some(s) = schema_of(name) else {
                        continue;
                    };
                    let id = out.add_schema(&s.name, &s.encoding, &s.data)?;
                    schemas.insert(name, id);
                    id
                }
            };
            self.ids[k] = out.add_channel(id, topic, "protobuf", &meta)?;
        }
        Ok(())
    }

    fn message(
        &mut self,
        out: &mut McapFile,
        service: &str,
        data: &[u8],
        t: u64,
    ) -> Result<(), McapError> {
        self.last_time = self.last_time.max(t);
        let r = &mut self.refused;
        match service {
            ServiceNames::ESTIMATES => {
                if let Some(e) = refused(payload_from_bytes::<ObjectEstimate>(data), r) {
                    self.state.on_estimate(&e);
                    self.dirty = true;
                }
            }
            ServiceNames::IR_FRAMES => {
                if let Some(f) = refused(payload_from_bytes::<IrFrame>(data), r) {
                    self.state.on_frame(&f);
                    self.dirty = true;
                }
            }
            ServiceNames::GRIDS => {
                if let Some(g) = refused(grid_from_bytes(data), r) {
                    self.state.on_grid(&g);
                    self.layer(out, t)?;
                }
            }
            ServiceNames::TASK => {
                if let Some(task) = refused(payload_from_bytes::<Task>(data), r) {
                    self.state.on_task(&task);
                    self.dirty = true;
                    self.log(out, "supervisor", format!("task: {}", task_text(&task)), t)?;
                }
            }
            ServiceNames::GOAL => {
                if let Some(g) = refused(payload_from_bytes::<Goal>(data), r) {
                    self.state.on_goal(&g);
                    self.dirty = true;
                    // Goal 0 is none: the supervisor's word that no goal is under way.
                    let text = if g.id == 0 {
                        "no goal".to_owned()
                    } else {
                        format!("goal {}: {}", g.id, task_text(&g.task))
                    };
                    self.log(out, "supervisor", text, t)?;
                }
            }
            ServiceNames::GOAL_ENDS => {
                if let Some(g) = refused(payload_from_bytes::<GoalEnd>(data), r) {
                    let end = String::from_utf8_lossy(&g.end);
                    let text = format!(
                        "goal {} ended: {} after {:.1} s",
                        g.id,
                        end.trim_end_matches('\0'),
                        g.sim_time_ns as f64 * 1e-9
                    );
                    self.log(out, "planner", text, t)?;
                }
            }
            ServiceNames::LEARN_EVENTS => {
                if let Some(e) = refused(payload_from_bytes::<LearnEvent>(data), r) {
                    let kind = LearnEventKind::from_u32(e.kind)
                        .map_or_else(|| format!("kind {}", e.kind), |k| format!("{k:?}"));
                    let text = format!(
                        "step {}: {kind} {}/{} (alpha {:.0} deg)",
                        e.step, e.index, e.total, e.alpha_deg
                    );
                    self.log(out, "planner", text, t)?;
                }
            }
            ServiceNames::LEARN_REPORTS => {
                if let Some(e) = refused(payload_from_bytes::<LearnReport>(data), r) {
                    let kind = LearnReportKind::from_u32(e.kind)
                        .map_or_else(|| format!("kind {}", e.kind), |k| format!("{k:?}"));
                    let text = format!(
                        "step {}: {kind} {} ({} learned, {} rejected of {})",
                        e.step, e.index, e.trials_learned, e.trials_rejected, e.trials_total
                    );
                    self.log(out, "estimator", text, t)?;
                }
            }
            ServiceNames::RESETS => {
                if let Some(e) = refused(payload_from_bytes::<Reset>(data), r) {
                    let text = format!(
                        "reset {}: object at ({:.1}, {:.1}) mm, robot at ({:.1}, {:.1}) mm",
                        e.seq,
                        e.object.x * 1e3,
                        e.object.y * 1e3,
                        e.robot.x * 1e3,
                        e.robot.y * 1e3
                    );
                    self.log(out, "planner", text, t)?;
                }
            }
            ServiceNames::ACTIVE_EPOCH => {
                if let Some(e) = refused(payload_from_bytes::<ActiveEpoch>(data), r) {
                    let text = format!("the planner of epoch {} drives", e.epoch);
                    self.log(out, "supervisor", text, t)?;
                }
            }
            _ => {}
        }
        if self.dirty && t >= self.next_scene {
            self.scene(out, t)?;
            self.next_scene = t.saturating_add(self.period_ns);
        }
        Ok(())
    }

    fn end(&mut self, out: &mut McapFile) -> Result<(), McapError> {
        // The last state, when it changed since the last scene.
        if self.dirty {
            self.scene(out, self.last_time)?;
        }
        let mut counts: BTreeMap<String, String> = self
            .counts()
            .into_iter()
            .map(|(topic, n)| (topic.to_owned(), n.to_string()))
            .collect();
        counts.insert("refused".to_owned(), self.refused.to_string());
        counts.insert("scene_rate_hz".to_owned(), SCENE_RATE_HZ.to_string());
        out.write_metadata(&mcap::records::Metadata {
            name: FOXGLOVE_METADATA.into(),
            metadata: counts,
        })
    }
}

/// A task in a few words: `place at (x, y) mm, theta deg`, `trajectory of n points`, ...
fn task_text(t: &Task) -> String {
    if t.kind == TaskKind::Place as u32 {
        format!(
            "place at ({:.0}, {:.0}) mm, {:.0} deg",
            t.goal.x * 1e3,
            t.goal.y * 1e3,
            t.goal.theta.to_degrees()
        )
    } else if t.kind == TaskKind::Trajectory as u32 {
        format!("push along a path of {} points", t.path_len)
    } else if t.kind == TaskKind::Learn as u32 {
        "learn".to_owned()
    } else {
        format!("kind {}", t.kind)
    }
}
