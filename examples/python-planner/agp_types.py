"""ctypes mirrors of agp's shared-types payloads (shared-types/src/payloads.rs), for the stock
`iceoryx2` Python package (0.10.0). Type names and layouts must match the Rust
`#[type_name(...)]` and `#[repr(C)]` exactly, or iceoryx2 refuses to open the service.

The one home of these mirrors: `planner.py` beside it imports them, and so can any other
stock Python client (put this folder on `PYTHONPATH`)."""
import ctypes
import os

import iceoryx2 as iox2

IR_SENSOR_COUNT = 8
STAGE_COUNT = 8
GRID_SIDE = 128
GRID_CELLS = GRID_SIDE * GRID_SIDE


class Pose2(ctypes.Structure):
    _fields_ = [("x", ctypes.c_double), ("y", ctypes.c_double), ("theta", ctypes.c_double)]

    @staticmethod
    def type_name() -> str:
        return "agp::Pose2.v1"


class TimingHeader(ctypes.Structure):
    _fields_ = [("trace_id", ctypes.c_uint64), ("stamps_ns", ctypes.c_uint64 * STAGE_COUNT)]

    @staticmethod
    def type_name() -> str:
        return "agp::TimingHeader.v1"


class IrFrame(ctypes.Structure):
    _fields_ = [
        ("timing", TimingHeader),
        ("cause", TimingHeader),
        ("step", ctypes.c_uint64),
        ("sim_time_s", ctypes.c_double),
        ("ir_sample", ctypes.c_uint64),
        ("ir_raw", ctypes.c_float * IR_SENSOR_COUNT),
        ("odometry", Pose2),
        ("fix_seq", ctypes.c_uint64),
        ("fix", Pose2),
        ("reset_seq", ctypes.c_uint64),
        ("active_epoch", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "agp::IrFrame.v2"


class MotorCommand(ctypes.Structure):
    _fields_ = [
        ("timing", TimingHeader),
        ("step", ctypes.c_uint64),
        ("epoch", ctypes.c_uint64),
        ("left_mps", ctypes.c_double),
        ("right_mps", ctypes.c_double),
        ("token", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "agp::MotorCommand.v2"


class ObjectEstimate(ctypes.Structure):
    _fields_ = [
        ("timing", TimingHeader),
        ("step", ctypes.c_uint64),
        ("robot", Pose2),
        ("pose", Pose2),
        ("sigma_xy", ctypes.c_double),
        ("sigma_theta", ctypes.c_double),
        ("centroid", ctypes.c_double * 2),
        ("centroid_sigma_m", ctypes.c_double),
        ("object_radius_m", ctypes.c_double),
        ("front_gap_m", ctypes.c_double),
        ("contact_point", ctypes.c_double * 2),
        ("match_rms_m", ctypes.c_double),
        ("match_inliers", ctypes.c_double),
        ("match_seq", ctypes.c_uint64),
        ("border_seen", ctypes.c_double),
        ("grids_seq", ctypes.c_uint64),
        ("estimator_start_ns", ctypes.c_uint64),
        ("event_session", ctypes.c_uint64),
        ("event_seq", ctypes.c_uint64),
        ("valid", ctypes.c_uint8),
        ("contact", ctypes.c_uint8),
        ("learning", ctypes.c_uint8),
        ("centroid_valid", ctypes.c_uint8),
        ("symmetry_order", ctypes.c_uint8),
        ("stalled", ctypes.c_uint8),
        ("_pad", ctypes.c_uint8 * 2),
    ]

    @staticmethod
    def type_name() -> str:
        return "agp::ObjectEstimate.v4"


class LearnEvent(ctypes.Structure):
    """What the planner tells the estimator (`agp/learn_events`). A task planner sends the
    four `TASK_*` kinds below; the learning protocol's kinds are not mirrored here."""

    _fields_ = [
        ("seq", ctypes.c_uint64),
        ("session", ctypes.c_uint64),
        ("kind", ctypes.c_uint32),
        ("index", ctypes.c_uint32),
        ("total", ctypes.c_uint32),
        ("flag", ctypes.c_uint32),
        ("step", ctypes.c_uint64),
        ("alpha_deg", ctypes.c_double),
        ("angle_rad", ctypes.c_double),
        ("object", Pose2),
        ("ir_sample", ctypes.c_uint64),
        ("ir_raw", ctypes.c_float * IR_SENSOR_COUNT),
        ("odometry", Pose2),
        ("contact", ctypes.c_double * 2),
        ("scale", ctypes.c_double),
    ]

    @staticmethod
    def type_name() -> str:
        return "agp::LearnEvent.v3"


# `LearnEventKind` (payloads.rs): the kinds a task planner sends.
TASK_CIRCLE_BEGIN = 12
TASK_CIRCLE_END = 13
TASK_PUSH_BEGIN = 14
TASK_PUSH_END = 15

MAX_PATH_POINTS = 32
TASK_KIND_PLACE = 2


class Task(ctypes.Structure):
    """The task under way (`agp/task`, latched): the planner publishes it, the judge of
    `agp up` scores the run against it."""

    _fields_ = [
        ("kind", ctypes.c_uint32),
        ("path_len", ctypes.c_uint32),
        ("goal", Pose2),
        ("tolerance_m", ctypes.c_double),
        ("tolerance_rad", ctypes.c_double),
        ("path", (ctypes.c_double * 2) * MAX_PATH_POINTS),
        ("max_pushes", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("seed", ctypes.c_uint64),
        # Trajectory: the object's heading kept tangent to the path within this; 0: none.
        ("heading_tolerance_rad", ctypes.c_double),
    ]

    @staticmethod
    def type_name() -> str:
        return "agp::Task.v2"


# `stage` (payloads.rs): indices of `TimingHeader.stamps_ns`.
FRAME_PUBLISHED = 0
ESTIMATOR_RECEIVED = 1
ESTIMATE_PUBLISHED = 2
PLANNER_RECEIVED = 3
COMMAND_PUBLISHED = 4

# `GridKind` (payloads.rs): which component a grid holds.
GRID_SHAPE = 0
GRID_POSITION_X = 1
GRID_POSITION_Y = 2
GRID_PUSH_WEIGHT = 5
GRID_ROTATION = 6
GRID_DISPLACEMENT_SQ_MEAN = 7
GRID_ROTATION_SQ_MEAN = 8
# The same statistics of the pushes that meet the border past the centroid (payloads.rs,
# `GridKind`): a planner pushing from the start circle's nearest point never needs them.
GRID_PAST_PUSH_WEIGHT = 11
GRID_PAST_POSITION_X = 12
GRID_PAST_POSITION_Y = 13
GRID_PAST_ROTATION = 14
GRID_PAST_DISPLACEMENT_SQ_MEAN = 15
GRID_PAST_ROTATION_SQ_MEAN = 16
GRIDS_PER_ALPHA = 17


class GridHeader(ctypes.Structure):
    _fields_ = [
        ("seq", ctypes.c_uint64),
        ("kind", ctypes.c_uint32),
        ("alpha_count", ctypes.c_uint32),
        ("width", ctypes.c_uint32),
        ("height", ctypes.c_uint32),
        ("alpha_deg", ctypes.c_double),
        ("cell_size_m", ctypes.c_double),
        ("origin_x_m", ctypes.c_double),
        ("origin_y_m", ctypes.c_double),
        ("shape_scale", ctypes.c_double),
        ("max_rotation_rad", ctypes.c_double),
        ("pushes", ctypes.c_uint64),
        ("border_points", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "agp::GridHeader.v2"


class GradientGrid(ctypes.Structure):
    _fields_ = [("header", GridHeader), ("cells", ctypes.c_float * GRID_CELLS)]

    @staticmethod
    def type_name() -> str:
        return "agp::GradientGrid.v2"


# The sizes the Rust const asserts of shared-types/src/payloads.rs pin.
assert ctypes.sizeof(Pose2) == 24
assert ctypes.sizeof(TimingHeader) == 72
assert ctypes.sizeof(IrFrame) == 72 * 2 + 8 * 6 + 32 + 24 * 2 == 272
assert ctypes.sizeof(MotorCommand) == 72 + 40 == 112
assert ctypes.sizeof(ObjectEstimate) == 72 + 8 + 24 + 24 + 16 + 16 + 16 + 8 + 16 + 16 + 8 + 8 + 8 + 16 + 8 + 8 == 272
assert ctypes.sizeof(GridHeader) == 8 + 4 * 4 + 8 * 8 == 88
assert ctypes.sizeof(GradientGrid) == 88 + 4 * GRID_CELLS
assert ctypes.sizeof(LearnEvent) == 8 * 2 + 4 * 4 + 8 * 3 + 24 + 8 + 32 + 24 + 16 + 8 == 168
assert ctypes.sizeof(Task) == 8 + 24 + 16 + 16 * MAX_PATH_POINTS + 16 + 8
for t in (IrFrame, MotorCommand, ObjectEstimate, GradientGrid, LearnEvent, Task):
    assert ctypes.alignment(t) == 8


def instance_config(name: str) -> "iox2.config.Config":
    """The iceoryx2 config of agp instance `name`, as libs/runtime/src/instance.rs builds it:
    prefix `agp_<name>.`, root `<base>/<name>/` (base /tmp/agp or $AGP_IOX2_ROOT),
    creation timeout 2 s."""
    base = os.environ.get("AGP_IOX2_ROOT", "/tmp/agp")
    cfg = iox2.config.default()
    cfg.global_cfg.prefix = iox2.FileName.new(f"agp_{name}.")
    cfg.global_cfg.root_path = iox2.Path.new(os.path.join(base, name) + "/")
    cfg.global_cfg.creation_timeout = iox2.Duration.from_secs(2)
    return cfg
