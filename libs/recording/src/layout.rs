//! The schema of every recorded channel: a text that documents the payload's `#[repr(C)]`
//! layout (each field's offset, size and type, little-endian), built from the types
//! themselves with `offset_of!`, so it cannot drift from the code.

use core::mem::{align_of, offset_of, size_of};

use agp_shared_types::{
    ActiveEpoch, Goal, GoalEnd, GradientGrid, IrFrame, LearnEvent, LearnReport, MotorCommand,
    ObjectEstimate, Reset, Task,
};

/// One field of a payload: its dotted path, byte offset, size in bytes and element type
/// (`u64`, `f64`, `f32[8]`, `f64[32][2]`, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    pub name: &'static str,
    pub offset: usize,
    pub size: usize,
    pub ty: &'static str,
}

/// The layout of one payload type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Layout {
    /// The iceoryx2 type name (`agp::IrFrame.v2`).
    pub type_name: &'static str,
    pub size: usize,
    pub align: usize,
    /// Every byte of the payload belongs to exactly one field (padding is an explicit
    /// `_pad` field in every agp payload); a unit test holds it.
    pub fields: Vec<Field>,
}

fn field_size<T, F>(_: fn(&T) -> &F) -> usize {
    size_of::<F>()
}

/// The iceoryx2 type name of `T` (its `#[type_name]` attribute).
pub fn type_name_of<T: iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>() -> &'static str
{
    // SAFETY: `type_name` is unsafe for its implementers (who promise one layout per
    // name); calling it only reads the name.
    unsafe { <T as iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>::type_name() }
}

macro_rules! layout {
    ($ty:ty { $($($field:ident).+ : $kind:literal),* $(,)? }) => {
        Layout {
            type_name: type_name_of::<$ty>(),
            size: size_of::<$ty>(),
            align: align_of::<$ty>(),
            fields: vec![$(Field {
                name: concat!($(stringify!($field), "."),+),
                offset: offset_of!($ty, $($field).+),
                size: field_size(|v: &$ty| &v.$($field).+),
                ty: $kind,
            }),*],
        }
    };
}

macro_rules! timing {
    ($ty:ty, $h:ident) => {
        layout!($ty { $h.trace_id: "u64", $h.stamps_ns: "u64[8]" })
    };
}

macro_rules! pose {
    ($ty:ty, $($p:ident).+) => {
        layout!($ty { $($p).+.x: "f64", $($p).+.y: "f64", $($p).+.theta: "f64" })
    };
}

/// Joins the field lists of several partial layouts of one type, in offset order.
fn join(parts: Vec<Layout>) -> Layout {
    let mut all = parts.into_iter();
    let mut first = all.next().expect("at least one part");
    for p in all {
        first.fields.extend(p.fields);
    }
    first.fields.sort_by_key(|f| f.offset);
    for f in &mut first.fields {
        // `concat!` leaves a trailing dot.
        f.name = f.name.strip_suffix('.').unwrap_or(f.name);
    }
    first
}

pub(crate) fn ir_frame() -> Layout {
    join(vec![
        timing!(IrFrame, timing),
        timing!(IrFrame, cause),
        layout!(IrFrame {
            step: "u64",
            sim_time_s: "f64",
            ir_sample: "u64",
            ir_raw: "f32[8]",
            fix_seq: "u64",
            reset_seq: "u64",
            active_epoch: "u64",
        }),
        pose!(IrFrame, odometry),
        pose!(IrFrame, fix),
    ])
}

pub(crate) fn motor_command() -> Layout {
    join(vec![
        timing!(MotorCommand, timing),
        layout!(MotorCommand {
            step: "u64",
            epoch: "u64",
            left_mps: "f64",
            right_mps: "f64",
            token: "u64",
        }),
    ])
}

pub(crate) fn reset() -> Layout {
    join(vec![
        layout!(Reset {
            seq: "u64",
            epoch: "u64",
            token: "u64",
            seed: "u64"
        }),
        pose!(Reset, object),
        pose!(Reset, robot),
    ])
}

pub(crate) fn object_estimate() -> Layout {
    join(vec![
        timing!(ObjectEstimate, timing),
        layout!(ObjectEstimate {
            step: "u64",
            sigma_xy: "f64",
            sigma_theta: "f64",
            centroid: "f64[2]",
            centroid_sigma_m: "f64",
            object_radius_m: "f64",
            front_gap_m: "f64",
            contact_point: "f64[2]",
            match_rms_m: "f64",
            match_inliers: "f64",
            match_seq: "u64",
            border_seen: "f64",
            grids_seq: "u64",
            estimator_start_ns: "u64",
            event_session: "u64",
            event_seq: "u64",
            valid: "u8",
            contact: "u8",
            learning: "u8",
            centroid_valid: "u8",
            symmetry_order: "u8",
            stalled: "u8",
            _pad: "u8[2]",
        }),
        pose!(ObjectEstimate, robot),
        pose!(ObjectEstimate, pose),
    ])
}

pub(crate) fn gradient_grid() -> Layout {
    join(vec![layout!(GradientGrid {
        header.seq: "u64",
        header.kind: "u32",
        header.alpha_count: "u32",
        header.width: "u32",
        header.height: "u32",
        header.alpha_deg: "f64",
        header.cell_size_m: "f64",
        header.origin_x_m: "f64",
        header.origin_y_m: "f64",
        header.shape_scale: "f64",
        header.max_rotation_rad: "f64",
        header.pushes: "u64",
        header.border_points: "u64",
        cells: "f32[16384]",
    })])
}

pub(crate) fn task() -> Layout {
    join(vec![
        layout!(Task {
            kind: "u32",
            path_len: "u32",
            tolerance_m: "f64",
            tolerance_rad: "f64",
            path: "f64[32][2]",
            max_pushes: "u32",
            _pad: "u32",
            seed: "u64",
            heading_tolerance_rad: "f64",
        }),
        pose!(Task, goal),
    ])
}

pub(crate) fn goal() -> Layout {
    join(vec![
        layout!(Goal {
            id: "u64",
            task.kind: "u32",
            task.path_len: "u32",
            task.tolerance_m: "f64",
            task.tolerance_rad: "f64",
            task.path: "f64[32][2]",
            task.max_pushes: "u32",
            task._pad: "u32",
            task.seed: "u64",
            task.heading_tolerance_rad: "f64",
        }),
        pose!(Goal, task.goal),
    ])
}

pub(crate) fn active_epoch() -> Layout {
    join(vec![layout!(ActiveEpoch {
        epoch: "u64",
        seq: "u64"
    })])
}

pub(crate) fn learn_event() -> Layout {
    join(vec![
        layout!(LearnEvent {
            seq: "u64",
            session: "u64",
            kind: "u32",
            index: "u32",
            total: "u32",
            flag: "u32",
            step: "u64",
            alpha_deg: "f64",
            angle_rad: "f64",
            ir_sample: "u64",
            ir_raw: "f32[8]",
            contact: "f64[2]",
            scale: "f64",
        }),
        pose!(LearnEvent, object),
        pose!(LearnEvent, odometry),
    ])
}

pub(crate) fn learn_report() -> Layout {
    join(vec![layout!(LearnReport {
        seq: "u64",
        kind: "u32",
        index: "u32",
        trials_learned: "u32",
        trials_rejected: "u32",
        trials_total: "u32",
        valid: "u32",
        step: "u64",
        push_end_step: "u64",
        alpha_deg: "f64",
        contact_point: "f64[2]",
        displacement: "f64[2]",
        rotation_rad: "f64",
        grids_seq: "u64",
        value: "f64",
        border_radius_m: "f64",
    })])
}

pub(crate) fn goal_end() -> Layout {
    join(vec![layout!(GoalEnd {
        id: "u64",
        sim_time_ns: "u64",
        end: "u8[32]",
    })])
}

impl Layout {
    /// The schema text stored in the MCAP file: a header saying how to read the bytes, then
    /// one line per field, `offset size type name`.
    pub fn schema_text(&self) -> String {
        let mut s = format!(
            "# {name}: the raw bytes of a #[repr(C)] struct, little-endian, {size} bytes, aligned to {align}.\n\
             # Integers are unsigned (uN), floats IEEE 754 (f32, f64); tN[k] is k consecutive tN,\n\
             # tN[k][m] is k rows of m. Units are SI (m, s, rad) unless the name says otherwise.\n\
             # The fields cover every byte; `_pad` fields are zero.\n\
             # offset size type name\n",
            name = self.type_name,
            size = self.size,
            align = self.align
        );
        for f in &self.fields {
            s.push_str(&format!("{} {} {} {}\n", f.offset, f.size, f.ty, f.name));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all() -> Vec<Layout> {
        vec![
            ir_frame(),
            motor_command(),
            reset(),
            object_estimate(),
            gradient_grid(),
            task(),
            goal(),
            active_epoch(),
            learn_event(),
            learn_report(),
            goal_end(),
        ]
    }

    /// Bytes of one element of a type written `u64`, `f32[8]`, `f64[32][2]`.
    fn type_bytes(ty: &str) -> usize {
        let base = ty.split('[').next().unwrap_or(ty);
        let elem = match base {
            "u8" => 1,
            "u32" | "f32" => 4,
            "u64" | "f64" => 8,
            other => panic!("unknown type `{other}`"),
        };
        ty.split('[')
            .skip(1)
            .map(|d| d.trim_end_matches(']').parse::<usize>().expect("a count"))
            .product::<usize>()
            * elem
    }

    #[test]
    fn every_layout_covers_each_byte_of_its_payload_once_in_offset_order() {
        for l in all() {
            let mut end = 0;
            for f in &l.fields {
                assert_eq!(
                    f.offset, end,
                    "{}: `{}` leaves a gap or overlaps",
                    l.type_name, f.name
                );
                assert_eq!(
                    f.size,
                    type_bytes(f.ty),
                    "{}: `{}` is not a {}",
                    l.type_name,
                    f.name,
                    f.ty
                );
                end = f.offset + f.size;
            }
            assert_eq!(
                end, l.size,
                "{}: the fields end before the payload",
                l.type_name
            );
        }
    }

    #[test]
    fn the_schema_text_names_the_type_and_every_field_with_its_offset() {
        let text = ir_frame().schema_text();
        assert!(text.starts_with("# agp::IrFrame.v2:"), "{text}");
        assert!(text.contains("\n0 8 u64 timing.trace_id\n"), "{text}");
        let step = offset_of!(IrFrame, step);
        assert!(text.contains(&format!("\n{step} 8 u64 step\n")), "{text}");
        assert!(!text.contains("trace_id."), "no trailing dot: {text}");
    }
}
