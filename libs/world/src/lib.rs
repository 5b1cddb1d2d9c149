//! The world both physics and estimator know: the robot's description, scenarios and polygon geometry.

mod bounded_read;
mod geometry;
mod ir_geometry;
mod rng;
mod robot;
mod scenario;

pub use bounded_read::{
    BoundedReadError, MAX_CONFIG_FILE_BYTES, lexically_normal, read_regular_file, read_regular_text,
};
pub use geometry::{
    Polygon, PolygonError, point_segment_distance, ray_segment, segments_intersect, signed_area,
};
pub use ir_geometry::{
    BORDER_MAX_SIGMA, border_range, ir_border_point, ir_point_robot, mean_ir_vector, to_frame,
};
pub use rng::Rng;
pub use robot::{
    IrSensor, ResponseCurve, RobotDescription, RobotLoadError, WHEEL_FRICTION_RANGE,
    WHEEL_TORQUE_MNM_RANGE,
};
pub use scenario::{
    ARENA_HALF_SIZE_MM, BUILTIN_NAMES, Experimenter, Localization, MAX_POLYGON_VERTICES,
    MAX_POSE_ANGLE_DEG, MAX_SCENARIO_NAME_LEN, MAX_WORLD_CHANGE_AT_S, MAX_WORLD_CHANGES,
    MIN_OBJECT_AREA_MM2, OBJECT_RADIUS_MM, ObjectShape, ObjectSpec, Pose, RobotDrive, RobotSetup,
    Scenario, ScenarioBrief, ScenarioLoadError, TaskKind, TaskSpec, WorldChange,
};

/// 1-based line number of byte offset `offset` in `text`.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    // Bytes, not a str slice: an offset inside a character must not panic.
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}
