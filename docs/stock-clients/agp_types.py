"""ctypes mirrors of agp's shared-types payloads (shared-types/src/payloads.rs), for the stock
`iceoryx2` Python package (0.10.0). Type names and layouts must match the Rust
`#[type_name(...)]` and `#[repr(C)]` exactly, or iceoryx2 refuses to open the service."""
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
        return "agp::ObjectEstimate.v3"


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
assert ctypes.sizeof(ObjectEstimate) == 72 + 8 + 24 + 24 + 16 + 16 + 16 + 8 + 16 + 16 + 8 + 8 + 8 + 8 + 8 == 256
assert ctypes.sizeof(GridHeader) == 8 + 4 * 4 + 8 * 8 == 88
assert ctypes.sizeof(GradientGrid) == 88 + 4 * GRID_CELLS
for t in (IrFrame, MotorCommand, ObjectEstimate, GradientGrid):
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
