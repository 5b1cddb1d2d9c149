//! The Rust side of the `agp` Python package's tests (python/tests): what its mirrors and
//! its affordance gradient are held to.
//!
//! - `agp-py-reference layout`: every payload the package mirrors, as JSON: its iceoryx2
//!   type name, size, alignment and every field's offset (`std::mem::offset_of!`). A
//!   field changed in Rust and not in the mirror fails the package's layout test.
//! - `agp-py-reference grids AG_FILE OUT`: the grid set the estimator publishes for that
//!   AG file (every kind of every alpha, `GradientGrid` after `GradientGrid`), raw.
//! - `agp-py-reference predict AG_FILE`: the predictions of the gradient rebuilt from that
//!   set, as the planner plans on it: for contact angles every 7.5 deg and alphas from
//!   the first learned to the last in 2.5 deg steps, the aim point ([`aim_point_at`]) and
//!   `AffordanceGradient::predict` there, in mm and degrees, as JSON.

use std::io::Write;

use agp_affordance::AffordanceGradient;
use agp_planning::aim_point_at;
use agp_shared_types::{
    ActiveEpoch, ControlRequest, ControlResponse, GRID_CELLS, Goal, GoalStatus, GradientGrid,
    GridHeader, GridKind, GroundTruth, IrFrame, LearnEvent, MotorCommand, ObjectEstimate, Pose2,
    ProcessStatus, PushChoice, PushRequest, StrangerStatus, Task, TimingHeader,
};
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use serde_json::{Map, Value, json};

/// One payload's entry: type name, size, alignment, field offsets.
macro_rules! layout {
    ($out:ident, $t:ident, [$($f:ident),* $(,)?]) => {{
        let mut fields = Map::new();
        $( fields.insert(stringify!($f).to_owned(), json!(std::mem::offset_of!($t, $f))); )*
        // SAFETY: `type_name` only returns the name the derive gave the type; the layout
        // promise it asks of its callers is what this program reports for checking.
        let name = unsafe { <$t as ZeroCopySend>::type_name() };
        $out.insert(
            stringify!($t).to_owned(),
            json!({
                "type_name": name,
                "size": std::mem::size_of::<$t>(),
                "align": std::mem::align_of::<$t>(),
                "fields": Value::Object(fields),
            }),
        );
    }};
}

fn layouts() -> Value {
    let mut out = Map::new();
    layout!(out, Pose2, [x, y, theta]);
    layout!(out, TimingHeader, [trace_id, stamps_ns]);
    // The Gymnasium environment's judge reads it (python/src/agp/envs), the only Python reader.
    layout!(
        out,
        GroundTruth,
        [step, sim_time_s, robot, object, contact, _pad]
    );
    layout!(
        out,
        IrFrame,
        [
            timing,
            cause,
            step,
            sim_time_s,
            ir_sample,
            ir_raw,
            odometry,
            fix_seq,
            fix,
            reset_seq,
            active_epoch
        ]
    );
    layout!(
        out,
        MotorCommand,
        [timing, step, epoch, left_mps, right_mps, token]
    );
    layout!(
        out,
        ObjectEstimate,
        [
            timing,
            step,
            robot,
            pose,
            sigma_xy,
            sigma_theta,
            centroid,
            centroid_sigma_m,
            object_radius_m,
            front_gap_m,
            contact_point,
            match_rms_m,
            match_inliers,
            match_seq,
            border_seen,
            grids_seq,
            estimator_start_ns,
            event_session,
            event_seq,
            valid,
            contact,
            learning,
            centroid_valid,
            symmetry_order,
            stalled
        ]
    );
    layout!(
        out,
        LearnEvent,
        [
            seq, session, kind, index, total, flag, step, alpha_deg, angle_rad, object, ir_sample,
            ir_raw, odometry, contact, scale
        ]
    );
    layout!(
        out,
        Task,
        [
            kind,
            path_len,
            goal,
            tolerance_m,
            tolerance_rad,
            path,
            max_pushes,
            _pad,
            seed,
            heading_tolerance_rad
        ]
    );
    layout!(out, Goal, [id, task]);
    layout!(
        out,
        GridHeader,
        [
            seq,
            kind,
            alpha_count,
            width,
            height,
            alpha_deg,
            cell_size_m,
            origin_x_m,
            origin_y_m,
            shape_scale,
            max_rotation_rad,
            pushes,
            border_points
        ]
    );
    layout!(out, GradientGrid, [header, cells]);
    layout!(out, ActiveEpoch, [epoch, seq]);
    layout!(
        out,
        ControlRequest,
        [
            kind, pid, epoch, value_ns, name, exec, args, args_set, _pad2, goal
        ]
    );
    layout!(
        out,
        ProcessStatus,
        [
            name, exec, pid, state, restarts, _pad, uptime_ms, epoch, rate_mhz, rate_topic
        ]
    );
    layout!(out, StrangerStatus, [pid, _pad, name]);
    layout!(
        out,
        GoalStatus,
        [
            id,
            state,
            kind,
            target,
            path_len,
            success,
            position_error_mm,
            orientation_error_deg,
            mean_path_error_mm,
            estimate_position_error_mm,
            estimate_orientation_error_deg,
            sim_time_s,
            end
        ]
    );
    layout!(
        out,
        ControlResponse,
        [
            kind,
            ok,
            supervisor_pid,
            process_count,
            uptime_ms,
            active_epoch,
            handover_ns,
            message,
            waiting,
            processes,
            paused,
            stranger_count,
            pause_left_ms,
            strangers,
            goal_id,
            goals_total,
            goal_count,
            goals
        ]
    );
    layout!(
        out,
        PushRequest,
        [
            seq,
            epoch,
            goal_id,
            object,
            sigma_xy,
            sigma_theta,
            goal,
            tolerance_m,
            tolerance_rad,
            robot,
            start_radius_m,
            sim_time_s,
            pushes,
            pushes_since_estimate,
            symmetry_order,
            full_only
        ]
    );
    layout!(
        out,
        PushChoice,
        [seq, epoch, kind, _pad, contact_deg, alpha_deg, length_mm]
    );
    Value::Object(out)
}

/// Every grid the estimator publishes for `ag` (seq 1).
fn published(ag: &AffordanceGradient) -> Vec<Box<GradientGrid>> {
    let mut grids = Vec::new();
    for alpha in ag.alphas_deg() {
        for kind in GridKind::ALL {
            let mut g = Box::new(GradientGrid {
                header: GridHeader::default(),
                cells: [0.0; GRID_CELLS],
            });
            if ag.write_component(alpha, kind, 1, &mut g).is_ok() {
                grids.push(g);
            }
        }
    }
    grids
}

fn load(path: &str) -> anyhow::Result<AffordanceGradient> {
    AffordanceGradient::load(path).map_err(|e| anyhow::anyhow!("cannot load {path}: {e}"))
}

fn predictions(ag: &AffordanceGradient) -> anyhow::Result<Value> {
    let grids = published(ag);
    let rebuilt = AffordanceGradient::from_grids(ag.object_name(), grids.iter().map(|g| &**g))
        .map_err(|e| anyhow::anyhow!("cannot rebuild the gradient from its grids: {e}"))?;
    let shape = rebuilt.combined_shape();
    let alphas: Vec<f64> = rebuilt.alphas_deg().collect();
    let (lo, hi) = (alphas[0], alphas[alphas.len() - 1]);
    let mut rows = Vec::new();
    for k in 0..48 {
        let contact_deg = 7.5 * f64::from(k);
        let aim = aim_point_at(&shape, contact_deg.to_radians());
        let mut alpha = lo;
        while alpha <= hi + 1e-9 {
            let p = aim.and_then(|c| rebuilt.predict(c, alpha));
            rows.push(json!({
                "contact_deg": contact_deg,
                "alpha_deg": alpha,
                "aim_mm": aim.map(|c| [c.x * 1e3, c.y * 1e3]),
                "prediction": p.map(|p| json!({
                    "dx_mm": p.displacement.x * 1e3,
                    "dy_mm": p.displacement.y * 1e3,
                    "dtheta_deg": p.rotation_rad.to_degrees(),
                    "spread_mm": p.displacement_spread_m * 1e3,
                    "rotation_spread_deg": p.rotation_spread_rad.to_degrees(),
                    "confidence": p.confidence,
                })),
            }));
            alpha += 2.5;
        }
    }
    Ok(json!({ "alphas_deg": alphas, "rows": rows }))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let words: Vec<&str> = args.iter().map(String::as_str).collect();
    match words[..] {
        ["layout"] => println!("{}", layouts()),
        ["grids", ag_file, out] => {
            let ag = load(ag_file)?;
            let mut f = std::fs::File::create(out)
                .map_err(|e| anyhow::anyhow!("cannot create {out}: {e}"))?;
            for g in published(&ag) {
                // SAFETY: GradientGrid is #[repr(C)] plain data (f64, u64, u32, f32 and no
                // padding the layout test does not pin); its bytes are what iceoryx2 sends.
                let bytes = unsafe {
                    std::slice::from_raw_parts(
                        (&*g as *const GradientGrid).cast::<u8>(),
                        std::mem::size_of::<GradientGrid>(),
                    )
                };
                f.write_all(bytes)
                    .map_err(|e| anyhow::anyhow!("cannot write {out}: {e}"))?;
            }
        }
        ["predict", ag_file] => println!("{}", predictions(&load(ag_file)?)?),
        _ => anyhow::bail!("usage: agp-py-reference layout | grids AG_FILE OUT | predict AG_FILE"),
    }
    Ok(())
}
