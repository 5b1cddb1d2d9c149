use agp_shared_types::{IR_SENSOR_COUNT, IrFrame};
use agp_world::Pose;

/// What the estimator reads of one IR frame: the sample counter, the raw readings and the
/// robot's odometry pose. Everything else in a frame (time, the overhead fix, ground truth)
/// the learning phase does not use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IrView {
    /// Incremented at every IR sample; an unchanged value repeats the readings.
    pub ir_sample: u64,
    /// Raw readings of IR1..IR8 (0..4095, higher is closer).
    pub ir_raw: [f32; IR_SENSOR_COUNT],
    /// The robot's pose by odometry (metres, radians), the frame everything is estimated in.
    pub odometry: Pose,
}

impl IrView {
    /// A view from its parts.
    pub fn new(ir_sample: u64, ir_raw: [f32; IR_SENSOR_COUNT], odometry: Pose) -> Self {
        Self {
            ir_sample,
            ir_raw,
            odometry,
        }
    }
}

impl From<&IrFrame> for IrView {
    fn from(f: &IrFrame) -> Self {
        Self {
            ir_sample: f.ir_sample,
            ir_raw: f.ir_raw,
            odometry: f.odometry,
        }
    }
}
