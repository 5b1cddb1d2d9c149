//! The view's state as Foxglove's well-known messages: pure functions, no IPC, no server.
//!
//! Everything is drawn in the `world` frame from what the estimator believes (the robot's
//! fused pose, the object's pose and its error bounds), never from ground truth. The object's
//! outline is the border learned from S ([`crate::border::learned_border`]), placed at the
//! estimated pose; the AG layer's grid and image sit in the `object` frame, which
//! `/tf` places at the estimated pose while it is valid.

use agp_shared_types::{GRID_CELLS, GRID_SIDE, ObjectEstimate, Pose2, TaskKind};
use agp_world::RobotDescription;
use foxglove::bytes::Bytes;
use foxglove::messages::{
    ArrowPrimitive, Color, CylinderPrimitive, FrameTransform, FrameTransforms, Grid, LinePrimitive,
    Log, PackedElementField, Point3, PointCloud, Pose, PoseInFrame, Quaternion, RawImage,
    SceneEntity, SceneEntityDeletion, SceneUpdate, SpherePrimitive, TextPrimitive, Timestamp,
    TriangleListPrimitive, Vector2, Vector3, line_primitive, log, packed_element_field,
    scene_entity_deletion,
};
use glam::DVec2;

use crate::state::{AgLayer, GoalView};

/// The fixed frame everything is drawn in.
pub const WORLD_FRAME: &str = "world";
/// The robot's frame at its estimated pose.
pub const ROBOT_FRAME: &str = "robot";
/// The object's frame at its estimated pose (the AG grids' frame).
pub const OBJECT_FRAME: &str = "object";
/// The goal pose of a placement.
pub const GOAL_FRAME: &str = "goal";

/// Height of the robot's body drawn, m (the E-puck's shell is about 5 cm tall).
const ROBOT_HEIGHT_M: f64 = 0.05;
/// A bound larger than this (m) is drawn as "lost", not as a circle.
const MAX_DRAWN_SIGMA_M: f64 = 1.0;

/// The foxglove timestamp of `ns` nanoseconds since the epoch.
pub fn timestamp(ns: u64) -> Timestamp {
    let sec = u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new_checked(sec, (ns % 1_000_000_000) as u32).unwrap_or(Timestamp::MAX)
}

fn quat(theta: f64) -> Quaternion {
    let h = 0.5 * theta;
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: h.sin(),
        w: h.cos(),
    }
}

fn pose_at(p: DVec2, z: f64, theta: f64) -> Pose {
    Pose {
        position: Some(Vector3 { x: p.x, y: p.y, z }),
        orientation: Some(quat(theta)),
    }
}

fn identity() -> Pose {
    pose_at(DVec2::ZERO, 0.0, 0.0)
}

/// A sphere of `diameter` metres at `p`, height `z`.
fn dot(p: DVec2, z: f64, diameter: f64, color: Color) -> SpherePrimitive {
    SpherePrimitive {
        pose: Some(pose_at(p, z, 0.0)),
        size: Some(Vector3 {
            x: diameter,
            y: diameter,
            z: diameter,
        }),
        color: Some(color),
    }
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

fn pt(p: DVec2, z: f64) -> Point3 {
    Point3 { x: p.x, y: p.y, z }
}

fn circle(center: DVec2, radius: f64, z: f64) -> Vec<Point3> {
    (0..48)
        .map(|k| {
            let a = std::f64::consts::TAU * f64::from(k) / 48.0;
            pt(center + radius * DVec2::from_angle(a), z)
        })
        .collect()
}

fn line(
    kind: line_primitive::Type,
    points: Vec<Point3>,
    thickness: f64,
    color: Color,
) -> LinePrimitive {
    LinePrimitive {
        r#type: kind as i32,
        pose: Some(identity()),
        thickness,
        scale_invariant: false,
        points,
        color: Some(color),
        ..LinePrimitive::default()
    }
}

fn text(at: DVec2, z: f64, s: String, color: Color) -> TextPrimitive {
    TextPrimitive {
        pose: Some(pose_at(at, z, 0.0)),
        billboard: true,
        font_size: 12.0,
        scale_invariant: true,
        color: Some(color),
        text: s,
    }
}

fn entity(id: &str, ts: u64) -> SceneEntity {
    SceneEntity {
        timestamp: Some(timestamp(ts)),
        frame_id: WORLD_FRAME.to_owned(),
        id: id.to_owned(),
        ..SceneEntity::default()
    }
}

/// A scene update that replaces everything its topic showed before with `entities`.
fn update(entities: Vec<SceneEntity>, ts: u64) -> SceneUpdate {
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(timestamp(ts)),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}

fn mm(v: f64) -> f64 {
    v * 1000.0
}

/// `/robot`: the robot's body (a cylinder) and heading at the estimator's fused pose, red
/// while the estimator senses contact.
pub fn robot_scene(robot: &RobotDescription, e: &ObjectEstimate, ts: u64) -> SceneUpdate {
    let p = e.robot.position();
    let body = if e.contact == 1 {
        rgba(0.95, 0.35, 0.2, 0.9)
    } else {
        rgba(0.3, 0.5, 0.85, 0.9)
    };
    let r = robot.body_radius;
    let mut ent = entity("robot", ts);
    ent.cylinders.push(CylinderPrimitive {
        pose: Some(pose_at(p, 0.5 * ROBOT_HEIGHT_M, e.robot.theta)),
        size: Some(Vector3 {
            x: 2.0 * r,
            y: 2.0 * r,
            z: ROBOT_HEIGHT_M,
        }),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: Some(body),
    });
    ent.arrows.push(ArrowPrimitive {
        pose: Some(pose_at(p, ROBOT_HEIGHT_M + 0.002, e.robot.theta)),
        shaft_length: 0.8 * r,
        shaft_diameter: 0.006,
        head_length: 0.4 * r,
        head_diameter: 0.016,
        color: Some(rgba(1.0, 1.0, 1.0, 1.0)),
    });
    ent.texts.push(text(
        p,
        ROBOT_HEIGHT_M + 0.03,
        format!(
            "robot (estimate) ({:.1}, {:.1}) mm, {:.1} deg; step {}",
            mm(e.robot.x),
            mm(e.robot.y),
            e.robot.theta.to_degrees(),
            e.step
        ),
        rgba(1.0, 1.0, 1.0, 1.0),
    ));
    ent.metadata.push(kv("step", e.step.to_string()));
    ent.metadata.push(kv("pose_mm_deg", pose_text(&e.robot)));
    update(vec![ent], ts)
}

/// A pose as `x y theta`: millimetres and degrees.
fn pose_text(p: &Pose2) -> String {
    format!("{:.3} {:.3} {:.3}", mm(p.x), mm(p.y), p.theta.to_degrees())
}

fn kv(key: &str, value: String) -> foxglove::messages::KeyValuePair {
    foxglove::messages::KeyValuePair {
        key: key.to_owned(),
        value,
    }
}

/// `/ir`: each IR sensor's ray from its mount at the robot's estimated pose, as long as
/// the distance its raw reading implies (the response curve inverted), red when it sees
/// something and faint grey to the sensor's range when it sees nothing.
pub fn ir_scene(
    robot: &RobotDescription,
    robot_pose: &Pose2,
    ir_raw: &[f32],
    ts: u64,
) -> SceneUpdate {
    let mut points = Vec::with_capacity(2 * ir_raw.len());
    let mut colors = Vec::with_capacity(2 * ir_raw.len());
    let z = 0.02;
    for (sensor, &raw) in robot.ir_sensors.iter().zip(ir_raw) {
        let from = robot_pose.to_world(sensor.mount);
        let (len, color) = match robot.response.distance(f64::from(raw)) {
            Some(d) => (d, rgba(1.0, 0.2, 0.2, 1.0)),
            None => (robot.response.max_range(), rgba(0.7, 0.7, 0.7, 0.35)),
        };
        let to = robot_pose.to_world(sensor.mount + len * sensor.direction());
        points.push(pt(from, z));
        points.push(pt(to, z));
        colors.push(color);
        colors.push(color);
    }
    let mut ent = entity("ir_rays", ts);
    let mut l = line(
        line_primitive::Type::LineList,
        points,
        0.0015,
        rgba(1.0, 0.2, 0.2, 1.0),
    );
    l.colors = colors;
    ent.lines.push(l);
    ent.metadata.push(kv(
        "ir_raw",
        ir_raw
            .iter()
            .map(|r| format!("{r:.0}"))
            .collect::<Vec<_>>()
            .join(" "),
    ));
    update(vec![ent], ts)
}

/// The learned border placed at `pose`, as a closed line and a translucent fill.
fn outline(
    border: &[DVec2],
    pose: &Pose2,
    z: f64,
    line_color: Color,
    fill: Option<Color>,
) -> (LinePrimitive, Option<TriangleListPrimitive>) {
    let world: Vec<DVec2> = border.iter().map(|b| pose.to_world(*b)).collect();
    let l = line(
        line_primitive::Type::LineLoop,
        world.iter().map(|p| pt(*p, z)).collect(),
        0.002,
        line_color,
    );
    let t = fill.map(|color| {
        let c = pose.position();
        let mut points = Vec::with_capacity(3 * world.len());
        for k in 0..world.len() {
            points.push(pt(c, z - 0.001));
            points.push(pt(world[k], z - 0.001));
            points.push(pt(world[(k + 1) % world.len()], z - 0.001));
        }
        TriangleListPrimitive {
            pose: Some(identity()),
            points,
            color: Some(color),
            ..TriangleListPrimitive::default()
        }
    });
    (l, t)
}

/// `/estimate`: what the estimator believes of the object. With a valid pose: the learned
/// border at the estimated pose (line and fill), its heading, and its uncertainty: a circle
/// of radius `sigma_xy` round the estimated position and two rays at the heading
/// +-`sigma_theta` (a text says "lost" when a bound is infinite); the contact point while
/// the robot touches it. With a valid centroid track: the centroid and its bound. Nothing
/// while the estimator has neither.
pub fn estimate_scene(e: &ObjectEstimate, border: Option<&[DVec2]>, ts: u64) -> SceneUpdate {
    let mut entities = Vec::new();
    let z = 0.004;
    if e.valid == 1 {
        let pose = e.pose;
        let c = pose.position();
        let mut ent = entity("object_estimate", ts);
        match border {
            Some(b) => {
                let (l, t) = outline(
                    b,
                    &pose,
                    z,
                    rgba(0.2, 0.9, 0.4, 1.0),
                    Some(rgba(0.2, 0.9, 0.4, 0.25)),
                );
                ent.lines.push(l);
                ent.triangles.extend(t);
            }
            None => ent.lines.push(line(
                line_primitive::Type::LineLoop,
                circle(c, e.object_radius_m.max(0.01), z),
                0.002,
                rgba(0.2, 0.9, 0.4, 1.0),
            )),
        }
        ent.arrows.push(ArrowPrimitive {
            pose: Some(pose_at(c, z + 0.002, pose.theta)),
            shaft_length: 0.03,
            shaft_diameter: 0.004,
            head_length: 0.012,
            head_diameter: 0.01,
            color: Some(rgba(0.2, 0.9, 0.4, 1.0)),
        });
        let finite = e.sigma_xy.is_finite() && e.sigma_theta.is_finite();
        if e.sigma_xy.is_finite() && e.sigma_xy > 0.0 && e.sigma_xy <= MAX_DRAWN_SIGMA_M {
            ent.lines.push(line(
                line_primitive::Type::LineLoop,
                circle(c, e.sigma_xy, z + 0.001),
                0.0015,
                rgba(1.0, 0.85, 0.1, 0.9),
            ));
        }
        if e.sigma_theta.is_finite() && e.sigma_theta > 0.0 {
            let reach = 0.05;
            let s = e.sigma_theta.min(std::f64::consts::PI);
            let points = vec![
                pt(c, z + 0.001),
                pt(c + reach * DVec2::from_angle(pose.theta - s), z + 0.001),
                pt(c, z + 0.001),
                pt(c + reach * DVec2::from_angle(pose.theta + s), z + 0.001),
            ];
            ent.lines.push(line(
                line_primitive::Type::LineList,
                points,
                0.0015,
                rgba(1.0, 0.85, 0.1, 0.9),
            ));
        }
        if e.contact == 1 {
            let cp = pose.to_world(DVec2::new(e.contact_point[0], e.contact_point[1]));
            ent.spheres
                .push(dot(cp, z, 0.008, rgba(1.0, 0.3, 0.1, 1.0)));
        }
        let bound = if finite {
            format!(
                "+- {:.1} mm, +- {:.1} deg",
                mm(e.sigma_xy),
                e.sigma_theta.to_degrees()
            )
        } else {
            "bound lost (a push went otherwise than predicted)".to_owned()
        };
        ent.texts.push(text(
            c,
            0.06,
            format!(
                "object (estimate) ({:.1}, {:.1}) mm, {:.1} deg {bound}; match {}",
                mm(pose.x),
                mm(pose.y),
                pose.theta.to_degrees(),
                e.match_seq
            ),
            rgba(0.6, 1.0, 0.7, 1.0),
        ));
        ent.metadata.push(kv("pose_mm_deg", pose_text(&pose)));
        ent.metadata
            .push(kv("sigma_xy_mm", format!("{:.3}", mm(e.sigma_xy))));
        ent.metadata.push(kv(
            "sigma_theta_deg",
            format!("{:.3}", e.sigma_theta.to_degrees()),
        ));
        entities.push(ent);
    }
    if e.centroid_valid == 1 {
        let c = DVec2::new(e.centroid[0], e.centroid[1]);
        let mut ent = entity("centroid_track", ts);
        ent.spheres.push(dot(c, z, 0.006, rgba(0.8, 0.5, 1.0, 1.0)));
        if e.centroid_sigma_m.is_finite()
            && e.centroid_sigma_m > 0.0
            && e.centroid_sigma_m <= MAX_DRAWN_SIGMA_M
        {
            ent.lines.push(line(
                line_primitive::Type::LineLoop,
                circle(c, e.centroid_sigma_m, z),
                0.001,
                rgba(0.8, 0.5, 1.0, 0.8),
            ));
        }
        entities.push(ent);
    }
    update(entities, ts)
}

/// `/goal`: a placement's goal pose (arrow, the tolerance circle, and the learned border
/// placed there when there is one) or a trajectory's path.
pub fn goal_scene(goal: Option<&GoalView>, border: Option<&[DVec2]>, ts: u64) -> SceneUpdate {
    let Some(g) = goal else {
        return update(Vec::new(), ts);
    };
    let t = &g.task;
    let mut ent = entity("goal", ts);
    let z = 0.001;
    let label = if g.id == 0 {
        "goal".to_owned()
    } else {
        format!("goal {}", g.id)
    };
    let color = rgba(0.3, 0.8, 1.0, 0.9);
    if t.kind == TaskKind::Trajectory as u32 {
        let n = (t.path_len as usize).min(t.path.len());
        let path: Vec<DVec2> = t.path[..n].iter().map(|p| DVec2::new(p[0], p[1])).collect();
        if let Some(end) = path.last() {
            ent.lines.push(line(
                line_primitive::Type::LineStrip,
                path.iter().map(|p| pt(*p, z)).collect(),
                0.003,
                color,
            ));
            ent.texts.push(text(
                *end,
                0.05,
                format!(
                    "{label}: push along {n} points to ({:.0}, {:.0}) mm",
                    mm(end.x),
                    mm(end.y)
                ),
                color,
            ));
        }
    } else {
        let p = t.goal.position();
        ent.arrows.push(ArrowPrimitive {
            pose: Some(pose_at(p, z, t.goal.theta)),
            shaft_length: 0.03,
            shaft_diameter: 0.004,
            head_length: 0.012,
            head_diameter: 0.01,
            color: Some(color),
        });
        if t.tolerance_m.is_finite() && t.tolerance_m > 0.0 {
            ent.lines.push(line(
                line_primitive::Type::LineLoop,
                circle(p, t.tolerance_m, z),
                0.001,
                color,
            ));
        }
        if let Some(b) = border {
            ent.lines
                .push(outline(b, &t.goal, z, rgba(0.3, 0.8, 1.0, 0.6), None).0);
        }
        ent.texts.push(text(
            p,
            0.05,
            format!(
                "{label}: place at ({:.0}, {:.0}) mm, {:.0} deg",
                mm(t.goal.x),
                mm(t.goal.y),
                t.goal.theta.to_degrees()
            ),
            color,
        ));
    }
    update(vec![ent], ts)
}

fn transform(child: &str, p: &Pose2, ts: u64) -> FrameTransform {
    FrameTransform {
        timestamp: Some(timestamp(ts)),
        parent_frame_id: WORLD_FRAME.to_owned(),
        child_frame_id: child.to_owned(),
        translation: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        rotation: Some(quat(p.theta)),
    }
}

/// `/tf`: `world` -> `robot` at the estimated robot pose, `world` -> `object` at the
/// estimated object pose while it is valid, `world` -> `goal` at a placement's goal.
pub fn transforms(e: Option<&ObjectEstimate>, goal: Option<&GoalView>, ts: u64) -> FrameTransforms {
    let mut transforms = Vec::new();
    if let Some(e) = e {
        transforms.push(transform(ROBOT_FRAME, &e.robot, ts));
        if e.valid == 1 {
            transforms.push(transform(OBJECT_FRAME, &e.pose, ts));
        }
    }
    if let Some(g) = goal
        && g.task.kind == TaskKind::Place as u32
    {
        transforms.push(transform(GOAL_FRAME, &g.task.goal, ts));
    }
    FrameTransforms { transforms }
}

/// `/robot/pose`, `/estimate/pose`: a pose in the `world` frame, as Foxglove's
/// `PoseInFrame` (Rerun draws it as a transform).
pub fn pose_in_world(p: &Pose2, ts: u64) -> PoseInFrame {
    PoseInFrame {
        timestamp: Some(timestamp(ts)),
        frame_id: WORLD_FRAME.to_owned(),
        pose: Some(pose_at(p.position(), 0.0, p.theta)),
    }
}

/// Bytes of one point of the point clouds: x, y, z (f32), red, green, blue, alpha (u8).
const POINT_STRIDE: usize = 16;

/// Appends a point of colour `rgba` (0-255) to a point cloud's data.
fn push_point(data: &mut Vec<u8>, p: DVec2, z: f64, rgba: [u8; 4]) {
    for v in [p.x as f32, p.y as f32, z as f32] {
        data.extend_from_slice(&v.to_le_bytes());
    }
    data.extend_from_slice(&rgba);
}

/// A point cloud in the `world` frame of points packed by [`push_point`].
fn point_cloud(data: Vec<u8>, ts: u64) -> PointCloud {
    use packed_element_field::NumericType;
    let field = |name: &str, offset: u32, ty: NumericType| PackedElementField {
        name: name.to_owned(),
        offset,
        r#type: ty as i32,
    };
    PointCloud {
        timestamp: Some(timestamp(ts)),
        frame_id: WORLD_FRAME.to_owned(),
        pose: Some(identity()),
        point_stride: POINT_STRIDE as u32,
        fields: vec![
            field("x", 0, NumericType::Float32),
            field("y", 4, NumericType::Float32),
            field("z", 8, NumericType::Float32),
            field("red", 12, NumericType::Uint8),
            field("green", 13, NumericType::Uint8),
            field("blue", 14, NumericType::Uint8),
            field("alpha", 15, NumericType::Uint8),
        ],
        data: Bytes::from(data),
    }
}

/// The object's colour in the point clouds (the `/estimate` scene's green).
pub const OBJECT_RGBA: [u8; 4] = [51, 230, 102, 255];
/// The robot's colour in the point clouds (the `/robot` scene's blue, out of contact).
pub const ROBOT_RGBA: [u8; 4] = [77, 128, 217, 255];
/// An IR ray that sees something, in the point clouds (the `/ir` scene's red).
pub const IR_HIT_RGBA: [u8; 4] = [255, 51, 51, 255];
/// An IR ray that sees nothing, in the point clouds.
pub const IR_MISS_RGBA: [u8; 4] = [178, 178, 178, 120];

/// Points every this far (m) along the rays of a filled point cloud.
const FILL_STEP_M: f64 = 0.002;

/// `/estimate/points`: the object as the estimator believes it, as points a viewer without
/// scene entities draws (Rerun): the learned border at the estimated pose, filled by
/// points along the rays from the estimated position to it (a disc of the object's radius
/// without a border). Empty while the estimate is not valid.
pub fn estimate_points(e: &ObjectEstimate, border: Option<&[DVec2]>, ts: u64) -> PointCloud {
    let mut data = Vec::new();
    if e.valid == 1 {
        let pose = e.pose;
        let ring;
        let rim: &[DVec2] = match border {
            Some(b) => b,
            None => {
                let r = e.object_radius_m.clamp(0.01, 0.5);
                ring = (0..90)
                    .map(|k| r * DVec2::from_angle(std::f64::consts::TAU * f64::from(k) / 90.0))
                    .collect::<Vec<_>>();
                &ring
            }
        };
        for b in rim {
            let n = (b.length() / FILL_STEP_M).ceil().max(1.0) as usize;
            for k in 1..=n {
                let local = *b * (k as f64 / n as f64);
                push_point(&mut data, pose.to_world(local), 0.004, OBJECT_RGBA);
            }
        }
    }
    point_cloud(data, ts)
}

/// `/robot/points`: the robot's body as a filled disc of points at its estimated pose.
pub fn robot_points(robot: &RobotDescription, e: &ObjectEstimate, ts: u64) -> PointCloud {
    let mut data = Vec::new();
    let r = robot.body_radius;
    let rings = (r / FILL_STEP_M).ceil().max(1.0) as usize;
    for j in 1..=rings {
        let radius = r * j as f64 / rings as f64;
        let n = (std::f64::consts::TAU * radius / FILL_STEP_M)
            .ceil()
            .max(6.0) as usize;
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let local = radius * DVec2::from_angle(a);
            push_point(&mut data, e.robot.to_world(local), 0.05, ROBOT_RGBA);
        }
    }
    point_cloud(data, ts)
}

/// `/ir/points`: each IR ray of [`ir_scene`] as points every 2 mm from its mount, red when
/// it sees something, faint grey when not.
pub fn ir_points(
    robot: &RobotDescription,
    robot_pose: &Pose2,
    ir_raw: &[f32],
    ts: u64,
) -> PointCloud {
    let mut data = Vec::new();
    for (sensor, &raw) in robot.ir_sensors.iter().zip(ir_raw) {
        let (len, color) = match robot.response.distance(f64::from(raw)) {
            Some(d) => (d, IR_HIT_RGBA),
            None => (robot.response.max_range(), IR_MISS_RGBA),
        };
        let n = (len / FILL_STEP_M).ceil().max(1.0) as usize;
        for k in 0..=n {
            let local = sensor.mount + (len * k as f64 / n as f64) * sensor.direction();
            push_point(&mut data, robot_pose.to_world(local), 0.02, color);
        }
    }
    point_cloud(data, ts)
}

/// `/log`: one line of what a process said on the ring, from `name` (`planner`,
/// `estimator`, `supervisor`, `physics`).
pub fn log_line(name: &str, message: String, ts: u64) -> Log {
    Log {
        timestamp: Some(timestamp(ts)),
        level: log::Level::Info as i32,
        message,
        name: name.to_owned(),
        file: String::new(),
        line: 0,
    }
}

/// The fields of each cell of `/ag/grid`, in order, all f32.
pub const GRID_FIELDS: [&str; 5] = [
    "shape",
    "push_x_m",
    "push_y_m",
    "rotation_rad",
    "push_weight",
];

/// `/ag/grid`: the AG layer in the `object` frame, one cell per grid cell with the fields
/// of [`GRID_FIELDS`] (the 3D panel colours it by the one you pick).
pub fn ag_grid(layer: &AgLayer, ts: u64) -> Grid {
    let h = &layer.header;
    let stride = 4 * GRID_FIELDS.len();
    let mut data = Vec::with_capacity(GRID_CELLS * stride);
    for k in 0..GRID_CELLS {
        for v in [
            layer.shape[k],
            layer.push_x_m[k],
            layer.push_y_m[k],
            layer.rotation_rad[k],
            layer.push_weight[k],
        ] {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    Grid {
        timestamp: Some(timestamp(ts)),
        frame_id: OBJECT_FRAME.to_owned(),
        pose: Some(pose_at(DVec2::new(h.origin_x_m, h.origin_y_m), 0.0, 0.0)),
        column_count: GRID_SIDE as u32,
        cell_size: Some(Vector2 {
            x: h.cell_size_m,
            y: h.cell_size_m,
        }),
        row_stride: (GRID_SIDE * stride) as u32,
        cell_stride: stride as u32,
        fields: GRID_FIELDS
            .iter()
            .enumerate()
            .map(|(k, name)| PackedElementField {
                name: (*name).to_owned(),
                offset: (4 * k) as u32,
                r#type: packed_element_field::NumericType::Float32 as i32,
            })
            .collect(),
        data: Bytes::from(data),
    }
}

/// `/ag/image`: the AG layer as a 128 x 128 `rgb8` picture, +y up (the object frame as the
/// paper's Fig. 2 draws it): S in grey, tinted red where a push from the cell turns the
/// object counter-clockwise and blue where clockwise, the tint growing with the rotation
/// (full at the layer's largest).
pub fn ag_image(layer: &AgLayer, ts: u64) -> RawImage {
    let max_rot = layer
        .rotation_rad
        .iter()
        .zip(&layer.push_weight)
        .filter(|(_, w)| **w > 1e-3)
        .map(|(r, _)| r.abs())
        .fold(0.0f32, f32::max);
    let mut data = Vec::with_capacity(GRID_CELLS * 3);
    for row in 0..GRID_SIDE {
        let j = GRID_SIDE - 1 - row;
        for i in 0..GRID_SIDE {
            let k = j * GRID_SIDE + i;
            let grey = (layer.shape[k].clamp(0.0, 1.0) * 200.0) as u8;
            let mut px = [grey; 3];
            if max_rot > 0.0 && layer.push_weight[k] > 1e-3 {
                let t = (layer.rotation_rad[k].abs() / max_rot).clamp(0.0, 1.0);
                let tint = (55.0 + 200.0 * t) as u8;
                let c = if layer.rotation_rad[k] > 0.0 { 0 } else { 2 };
                px[c] = px[c].max(tint);
            }
            data.extend_from_slice(&px);
        }
    }
    RawImage {
        timestamp: Some(timestamp(ts)),
        frame_id: OBJECT_FRAME.to_owned(),
        width: GRID_SIDE as u32,
        height: GRID_SIDE as u32,
        encoding: "rgb8".to_owned(),
        step: (GRID_SIDE * 3) as u32,
        data: Bytes::from(data),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_turn_is_the_quaternion_about_z_of_half_its_angle() {
        let q = quat(std::f64::consts::FRAC_PI_2);
        let h = std::f64::consts::FRAC_PI_4;
        assert!((q.z - h.sin()).abs() < 1e-12 && (q.w - h.cos()).abs() < 1e-12);
        assert_eq!((q.x, q.y), (0.0, 0.0));
    }

    #[test]
    fn the_robot_is_drawn_at_the_estimated_pose_with_its_bodys_diameter() {
        let robot = RobotDescription::epuck();
        let e = ObjectEstimate {
            robot: Pose2::new(-0.2, 0.1, 0.5),
            ..ObjectEstimate::default()
        };
        let s = robot_scene(&robot, &e, 1_000_000_123);
        let c = &s.entities[0].cylinders[0];
        let p = c.pose.and_then(|p| p.position).expect("a position");
        assert_eq!((p.x, p.y), (-0.2, 0.1));
        let size = c.size.expect("a size");
        assert!((size.x - 2.0 * robot.body_radius).abs() < 1e-12);
        let ts = s.entities[0].timestamp.expect("a timestamp");
        assert_eq!((ts.sec(), ts.nsec()), (1, 123));
    }

    #[test]
    fn an_ir_ray_that_sees_nothing_reaches_the_sensors_range_and_one_that_sees_stops_short() {
        let robot = RobotDescription::epuck();
        let pose = Pose2::new(0.0, 0.0, 0.0);
        let mut raw = [0.0f32; 8];
        // Reading the curve at 1 cm gives the distance back.
        raw[0] = robot.response.reading(0.01) as f32;
        let s = ir_scene(&robot, &pose, &raw, 0);
        let pts = &s.entities[0].lines[0].points;
        let len = |k: usize| {
            let (a, b) = (&pts[2 * k], &pts[2 * k + 1]);
            ((b.x - a.x).powi(2) + (b.y - a.y).powi(2)).sqrt()
        };
        assert!((len(0) - 0.01).abs() < 1e-4, "{}", len(0));
        assert!(
            (len(1) - robot.response.max_range()).abs() < 1e-9,
            "{}",
            len(1)
        );
    }

    #[test]
    fn an_invalid_estimate_draws_no_object_and_an_infinite_bound_draws_no_circle() {
        let e = ObjectEstimate::default();
        assert!(estimate_scene(&e, None, 0).entities.is_empty());
        let e = ObjectEstimate {
            valid: 1,
            pose: Pose2::new(0.3, 0.15, 1.0),
            sigma_xy: f64::INFINITY,
            sigma_theta: f64::INFINITY,
            ..ObjectEstimate::default()
        };
        let s = estimate_scene(&e, None, 0);
        assert_eq!(s.entities.len(), 1);
        // The outline circle and nothing for the bounds.
        assert_eq!(s.entities[0].lines.len(), 1);
        assert!(s.entities[0].texts[0].text.contains("bound lost"));
    }

    #[test]
    fn the_image_puts_the_grids_last_row_on_top() {
        let mut layer = AgLayer {
            header: agp_shared_types::GridHeader::default(),
            shape: vec![0.0; GRID_CELLS],
            push_x_m: vec![0.0; GRID_CELLS],
            push_y_m: vec![0.0; GRID_CELLS],
            rotation_rad: vec![0.0; GRID_CELLS],
            push_weight: vec![0.0; GRID_CELLS],
        };
        // Cell (0, 127): top left of a y-up picture.
        layer.shape[(GRID_SIDE - 1) * GRID_SIDE] = 1.0;
        let img = ag_image(&layer, 0);
        assert_eq!(img.data.len(), GRID_CELLS * 3);
        assert_eq!(&img.data[..3], &[200, 200, 200]);
        assert_eq!(img.data[3 * GRID_SIDE * (GRID_SIDE - 1)], 0);
    }
}
