//! The topics a recording holds, and the payloads read back from raw bytes.

use core::mem::size_of;

use agp_shared_types::{
    ActiveEpoch, Goal, GoalEnd, GradientGrid, GridHeader, IrFrame, LearnEvent, LearnReport,
    MotorCommand, ObjectEstimate, Pose2, Reset, ServiceNames, Task, TimingHeader,
};

use crate::layout::{self, Layout};

/// One recorded topic: its iceoryx2 service name (the MCAP channel's topic), its payload's
/// iceoryx2 type name (the schema's name) and size.
#[derive(Debug, Clone, Copy)]
pub struct TopicSpec {
    pub service: &'static str,
    pub type_name: &'static str,
    pub size: usize,
    layout: fn() -> Layout,
}

impl TopicSpec {
    /// The payload's layout (the schema).
    pub fn layout(&self) -> Layout {
        (self.layout)()
    }
}

/// Every topic of an instance a recording holds, in channel order. Ground truth
/// (`agp/ground_truth`) is not one of them: only the judge, the probe and the oracle read
/// it. The control service (request-response) is not a topic.
pub fn recorded_topics() -> [TopicSpec; TOPIC_COUNT] {
    fn spec(service: &'static str, layout: fn() -> Layout) -> TopicSpec {
        let l = layout();
        TopicSpec {
            service,
            type_name: l.type_name,
            size: l.size,
            layout,
        }
    }
    [
        spec(ServiceNames::IR_FRAMES, layout::ir_frame),
        spec(ServiceNames::MOTOR_COMMANDS, layout::motor_command),
        spec(ServiceNames::RESETS, layout::reset),
        spec(ServiceNames::ESTIMATES, layout::object_estimate),
        spec(ServiceNames::GRIDS, layout::gradient_grid),
        spec(ServiceNames::TASK, layout::task),
        spec(ServiceNames::GOAL, layout::goal),
        spec(ServiceNames::ACTIVE_EPOCH, layout::active_epoch),
        spec(ServiceNames::LEARN_EVENTS, layout::learn_event),
        spec(ServiceNames::LEARN_REPORTS, layout::learn_report),
        spec(ServiceNames::GOAL_ENDS, layout::goal_end),
    ]
}

/// How many topics a recording holds.
pub const TOPIC_COUNT: usize = 11;

/// A payload any bit pattern of whose size is a valid value: `#[repr(C)]`, made of
/// integers, floats and arrays of them only (no `bool`, enum, reference or pointer), with
/// its padding spelled out as `_pad` fields. Every agp payload a recording holds is one.
///
/// # Safety
///
/// An implementer promises the above: [`payload_from_bytes`] reads any bytes as `Self`.
pub unsafe trait Plain: Copy {}

// Each payload below is #[repr(C)] of u8/u32/u64/f32/f64 fields and arrays of them, with
// explicit padding; layout.rs's test checks that every byte belongs to a field.
// SAFETY: `IrFrame` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for IrFrame {}
// SAFETY: `MotorCommand` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for MotorCommand {}
// SAFETY: `Reset` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for Reset {}
// SAFETY: `ObjectEstimate` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for ObjectEstimate {}
// SAFETY: `GridHeader` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for GridHeader {}
// SAFETY: `Task` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for Task {}
// SAFETY: `Goal` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for Goal {}
// SAFETY: `GoalEnd` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for GoalEnd {}
// SAFETY: `ActiveEpoch` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for ActiveEpoch {}
// SAFETY: `LearnEvent` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for LearnEvent {}
// SAFETY: `LearnReport` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for LearnReport {}
// SAFETY: `TimingHeader` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for TimingHeader {}
// SAFETY: `Pose2` is such a payload (see above): any bytes of its size are a valid value.
unsafe impl Plain for Pose2 {}

/// The payload a message's data holds: `None` unless `bytes` is exactly `size_of::<T>()`
/// long. The bytes need no alignment (they are copied).
pub fn payload_from_bytes<T: Plain>(bytes: &[u8]) -> Option<T> {
    if bytes.len() != size_of::<T>() {
        return None;
    }
    // SAFETY: the length is checked, `read_unaligned` needs no alignment, and `T: Plain`
    // makes any bytes a valid `T`.
    Some(unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<T>()) })
}

/// A gradient grid (64 KiB, not `Copy`) from a message's data, on the heap: `None` unless
/// `bytes` is exactly `size_of::<GradientGrid>()` long.
pub fn grid_from_bytes(bytes: &[u8]) -> Option<Box<GradientGrid>> {
    if bytes.len() != size_of::<GradientGrid>() {
        return None;
    }
    let layout = std::alloc::Layout::new::<GradientGrid>();
    // SAFETY: the layout is a grid's (not zero-sized); the bytes, whose length is checked,
    // are written whole over the allocation before it becomes a `Box` (a header of
    // integers and floats and an array of f32: any bytes are a valid grid).
    unsafe {
        let ptr = std::alloc::alloc(layout).cast::<GradientGrid>();
        if ptr.is_null() {
            std::alloc::handle_alloc_error(layout);
        }
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), ptr.cast::<u8>(), bytes.len());
        Some(Box::from_raw(ptr))
    }
}

/// The bytes of a payload as iceoryx2 holds them.
pub(crate) fn bytes_of<T>(value: &T) -> &[u8] {
    // SAFETY: every recorded payload is #[repr(C)] with no implicit padding (layout.rs's
    // test), so each of its bytes is initialised.
    unsafe { std::slice::from_raw_parts((value as *const T).cast::<u8>(), size_of::<T>()) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_survives_its_bytes_even_unaligned() {
        let mut frame = IrFrame {
            step: 42,
            sim_time_s: 0.065625,
            ir_raw: [1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 4095.0],
            ..IrFrame::default()
        };
        frame.odometry.theta = -1.25;
        let mut buf = vec![0u8; size_of::<IrFrame>() + 1];
        buf[1..].copy_from_slice(bytes_of(&frame));
        let back: IrFrame = payload_from_bytes(&buf[1..]).expect("the right length");
        assert_eq!(back, frame);
    }

    #[test]
    fn bytes_of_the_wrong_length_give_nothing() {
        let frame = IrFrame::default();
        let bytes = bytes_of(&frame);
        assert!(payload_from_bytes::<IrFrame>(&bytes[1..]).is_none());
        assert!(payload_from_bytes::<MotorCommand>(bytes).is_none());
        assert!(grid_from_bytes(bytes).is_none());
    }

    #[test]
    fn a_grid_survives_its_bytes() {
        let zeros = vec![0u8; size_of::<GradientGrid>()];
        let mut grid = grid_from_bytes(&zeros).expect("the right length");
        grid.header.seq = 3;
        grid.cells[129] = 0.25;
        let back = grid_from_bytes(bytes_of(&*grid)).expect("the right length");
        assert_eq!(back.header, grid.header);
        assert_eq!(back.cells[129].to_bits(), 0.25f32.to_bits());
    }

    #[test]
    fn every_topic_has_a_distinct_service_and_a_versioned_type_name() {
        let topics = recorded_topics();
        let mut names: Vec<_> = topics.iter().map(|t| t.service).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), TOPIC_COUNT);
        assert!(!names.contains(&ServiceNames::GROUND_TRUTH));
        for t in &topics {
            assert!(t.type_name.starts_with("agp::"), "{}", t.type_name);
            assert!(t.type_name.contains(".v"), "{}", t.type_name);
            assert_eq!(t.layout().size, t.size);
        }
        assert_eq!(topics[0].type_name, "agp::IrFrame.v2");
    }
}
