"""ctypes mirrors of agp's payloads (shared-types/src/payloads.rs, control.rs, skills.rs) for
the stock `iceoryx2` package. Each carries the Rust `#[type_name(...)]`; layouts follow the
Rust `#[repr(C)]` structs field by field. python/tests/test_layout.py holds every mirror to
the Rust layout (size, alignment, every field's offset, type name) as
`agp-py-reference layout` prints it."""

from __future__ import annotations

import ctypes

IR_SENSOR_COUNT = 8
STAGE_COUNT = 8
GRID_SIDE = 128
GRID_CELLS = GRID_SIDE * GRID_SIDE
MAX_PATH_POINTS = 32
STATUS_NAME_LEN = 32
STATUS_PATH_LEN = 256
STATUS_TOPIC_LEN = 16
SWAP_ARGS_LEN = 1024
MAX_STATUS_PROCESSES = 16
MAX_STATUS_STRANGERS = 8
STATUS_NODE_NAME_LEN = 64
MAX_STATUS_GOALS = 16

c_u8, c_u32, c_u64, c_f32, c_f64 = ctypes.c_uint8, ctypes.c_uint32, ctypes.c_uint64, ctypes.c_float, ctypes.c_double


class Payload(ctypes.Structure):
    """A payload with its iceoryx2 type name (`TYPE_NAME`)."""

    TYPE_NAME = ""

    @classmethod
    def type_name(cls) -> str:
        return cls.TYPE_NAME


class Pose2(Payload):
    TYPE_NAME = "agp::Pose2.v1"
    _fields_ = [("x", c_f64), ("y", c_f64), ("theta", c_f64)]


class TimingHeader(Payload):
    TYPE_NAME = "agp::TimingHeader.v1"
    _fields_ = [("trace_id", c_u64), ("stamps_ns", c_u64 * STAGE_COUNT)]


class IrFrame(Payload):
    TYPE_NAME = "agp::IrFrame.v2"
    _fields_ = [
        ("timing", TimingHeader),
        ("cause", TimingHeader),
        ("step", c_u64),
        ("sim_time_s", c_f64),
        ("ir_sample", c_u64),
        ("ir_raw", c_f32 * IR_SENSOR_COUNT),
        ("odometry", Pose2),
        ("fix_seq", c_u64),
        ("fix", Pose2),
        ("reset_seq", c_u64),
        ("active_epoch", c_u64),
    ]


class MotorCommand(Payload):
    TYPE_NAME = "agp::MotorCommand.v2"
    _fields_ = [
        ("timing", TimingHeader),
        ("step", c_u64),
        ("epoch", c_u64),
        ("left_mps", c_f64),
        ("right_mps", c_f64),
        ("token", c_u64),
    ]


class ObjectEstimate(Payload):
    TYPE_NAME = "agp::ObjectEstimate.v4"
    _fields_ = [
        ("timing", TimingHeader),
        ("step", c_u64),
        ("robot", Pose2),
        ("pose", Pose2),
        ("sigma_xy", c_f64),
        ("sigma_theta", c_f64),
        ("centroid", c_f64 * 2),
        ("centroid_sigma_m", c_f64),
        ("object_radius_m", c_f64),
        ("front_gap_m", c_f64),
        ("contact_point", c_f64 * 2),
        ("match_rms_m", c_f64),
        ("match_inliers", c_f64),
        ("match_seq", c_u64),
        ("border_seen", c_f64),
        ("grids_seq", c_u64),
        ("estimator_start_ns", c_u64),
        ("event_session", c_u64),
        ("event_seq", c_u64),
        ("valid", c_u8),
        ("contact", c_u8),
        ("learning", c_u8),
        ("centroid_valid", c_u8),
        ("symmetry_order", c_u8),
        ("stalled", c_u8),
        ("_pad", c_u8 * 2),
    ]


class LearnEvent(Payload):
    TYPE_NAME = "agp::LearnEvent.v3"
    _fields_ = [
        ("seq", c_u64),
        ("session", c_u64),
        ("kind", c_u32),
        ("index", c_u32),
        ("total", c_u32),
        ("flag", c_u32),
        ("step", c_u64),
        ("alpha_deg", c_f64),
        ("angle_rad", c_f64),
        ("object", Pose2),
        ("ir_sample", c_u64),
        ("ir_raw", c_f32 * IR_SENSOR_COUNT),
        ("odometry", Pose2),
        ("contact", c_f64 * 2),
        ("scale", c_f64),
    ]


class Task(Payload):
    TYPE_NAME = "agp::Task.v2"
    _fields_ = [
        ("kind", c_u32),
        ("path_len", c_u32),
        ("goal", Pose2),
        ("tolerance_m", c_f64),
        ("tolerance_rad", c_f64),
        ("path", (c_f64 * 2) * MAX_PATH_POINTS),
        ("max_pushes", c_u32),
        ("_pad", c_u32),
        ("seed", c_u64),
        ("heading_tolerance_rad", c_f64),
    ]


class Goal(Payload):
    TYPE_NAME = "agp::Goal.v2"
    _fields_ = [("id", c_u64), ("task", Task)]


class GridHeader(Payload):
    TYPE_NAME = "agp::GridHeader.v2"
    _fields_ = [
        ("seq", c_u64),
        ("kind", c_u32),
        ("alpha_count", c_u32),
        ("width", c_u32),
        ("height", c_u32),
        ("alpha_deg", c_f64),
        ("cell_size_m", c_f64),
        ("origin_x_m", c_f64),
        ("origin_y_m", c_f64),
        ("shape_scale", c_f64),
        ("max_rotation_rad", c_f64),
        ("pushes", c_u64),
        ("border_points", c_u64),
    ]


class GradientGrid(Payload):
    TYPE_NAME = "agp::GradientGrid.v2"
    _fields_ = [("header", GridHeader), ("cells", c_f32 * GRID_CELLS)]


class ActiveEpoch(Payload):
    TYPE_NAME = "agp::ActiveEpoch.v1"
    _fields_ = [("epoch", c_u64), ("seq", c_u64)]


class ControlRequest(Payload):
    TYPE_NAME = "agp::ControlRequest.v2"
    _fields_ = [
        ("kind", c_u32),
        ("pid", c_u32),
        ("epoch", c_u64),
        ("value_ns", c_u64),
        ("name", c_u8 * STATUS_NAME_LEN),
        ("exec", c_u8 * STATUS_PATH_LEN),
        ("args", c_u8 * SWAP_ARGS_LEN),
        ("args_set", c_u32),
        ("_pad2", c_u32),
        ("goal", Goal),
    ]


class ProcessStatus(Payload):
    TYPE_NAME = "agp::ProcessStatus.v2"
    _fields_ = [
        ("name", c_u8 * STATUS_NAME_LEN),
        ("exec", c_u8 * STATUS_PATH_LEN),
        ("pid", c_u32),
        ("state", c_u32),
        ("restarts", c_u32),
        ("_pad", c_u32),
        ("uptime_ms", c_u64),
        ("epoch", c_u64),
        ("rate_mhz", c_u64),
        ("rate_topic", c_u8 * STATUS_TOPIC_LEN),
    ]


class StrangerStatus(Payload):
    TYPE_NAME = "agp::StrangerStatus.v1"
    _fields_ = [("pid", c_u32), ("_pad", c_u32), ("name", c_u8 * STATUS_NODE_NAME_LEN)]


class GoalStatus(Payload):
    TYPE_NAME = "agp::GoalStatus.v1"
    _fields_ = [
        ("id", c_u64),
        ("state", c_u32),
        ("kind", c_u32),
        ("target", Pose2),
        ("path_len", c_u32),
        ("success", c_u32),
        ("position_error_mm", c_f64),
        ("orientation_error_deg", c_f64),
        ("mean_path_error_mm", c_f64),
        ("estimate_position_error_mm", c_f64),
        ("estimate_orientation_error_deg", c_f64),
        ("sim_time_s", c_f64),
        ("end", c_u8 * STATUS_TOPIC_LEN),
    ]


class ControlResponse(Payload):
    TYPE_NAME = "agp::ControlResponse.v5"
    _fields_ = [
        ("kind", c_u32),
        ("ok", c_u32),
        ("supervisor_pid", c_u32),
        ("process_count", c_u32),
        ("uptime_ms", c_u64),
        ("active_epoch", c_u64),
        ("handover_ns", c_u64),
        ("message", c_u8 * STATUS_PATH_LEN),
        ("waiting", c_u8 * STATUS_NAME_LEN),
        ("processes", ProcessStatus * MAX_STATUS_PROCESSES),
        ("paused", c_u32),
        ("stranger_count", c_u32),
        ("pause_left_ms", c_u64),
        ("strangers", StrangerStatus * MAX_STATUS_STRANGERS),
        ("goal_id", c_u64),
        ("goals_total", c_u32),
        ("goal_count", c_u32),
        ("goals", GoalStatus * MAX_STATUS_GOALS),
    ]


class PushRequest(Payload):
    TYPE_NAME = "agp::PushRequest.v1"
    _fields_ = [
        ("seq", c_u64),
        ("epoch", c_u64),
        ("goal_id", c_u64),
        ("object", Pose2),
        ("sigma_xy", c_f64),
        ("sigma_theta", c_f64),
        ("goal", Pose2),
        ("tolerance_m", c_f64),
        ("tolerance_rad", c_f64),
        ("robot", Pose2),
        ("start_radius_m", c_f64),
        ("sim_time_s", c_f64),
        ("pushes", c_u32),
        ("pushes_since_estimate", c_u32),
        ("symmetry_order", c_u32),
        ("full_only", c_u32),
    ]


class PushChoice(Payload):
    TYPE_NAME = "agp::PushChoice.v1"
    _fields_ = [
        ("seq", c_u64),
        ("epoch", c_u64),
        ("kind", c_u32),
        ("_pad", c_u32),
        ("contact_deg", c_f64),
        ("alpha_deg", c_f64),
        ("length_mm", c_f64),
    ]


#: Every mirrored payload, by its Rust name (the layout test walks them).
MIRRORS: dict[str, type[Payload]] = {
    t.__name__: t
    for t in (
        Pose2,
        TimingHeader,
        IrFrame,
        MotorCommand,
        ObjectEstimate,
        LearnEvent,
        Task,
        Goal,
        GridHeader,
        GradientGrid,
        ActiveEpoch,
        ControlRequest,
        ProcessStatus,
        StrangerStatus,
        GoalStatus,
        ControlResponse,
        PushRequest,
        PushChoice,
    )
}

# `stage` (payloads.rs): indices of `TimingHeader.stamps_ns`.
FRAME_PUBLISHED = 0
ESTIMATOR_RECEIVED = 1
ESTIMATE_PUBLISHED = 2
PLANNER_RECEIVED = 3
COMMAND_PUBLISHED = 4
COMMAND_APPLIED = 5

# `LearnEventKind`: the kinds a task planner sends.
TASK_CIRCLE_BEGIN = 12
TASK_CIRCLE_END = 13
TASK_PUSH_BEGIN = 14
TASK_PUSH_END = 15

# `TaskKind`.
TASK_KIND_TRAJECTORY = 1
TASK_KIND_PLACE = 2

# `ControlKind`.
CONTROL_READY = 4
CONTROL_DRIVING = 5
CONTROL_GOAL_DONE = 9

# `PushChoiceKind`.
CHOICE_PUSH = 1
CHOICE_DONE = 2
CHOICE_GIVE_UP = 3

# `GridKind`: which component a grid holds.
GRID_SHAPE = 0
GRID_POSITION_X = 1
GRID_POSITION_Y = 2
GRID_PUSH_WEIGHT = 5
GRID_ROTATION = 6
GRID_DISPLACEMENT_SQ_MEAN = 7
GRID_ROTATION_SQ_MEAN = 8
GRIDS_PER_ALPHA = 17
