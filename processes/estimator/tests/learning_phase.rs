//! The learning phase against the physics, in-process: the acceptance of the learning
//! issue (benchmarks.md section 1). Two objects here, one symmetric and one not (the
//! triangle and the L); `examples/learn_report.rs` runs all four.
//!
//! Targets: median rotation error of unseen pushes <= 5 deg, median displacement error <=
//! 20 % of the true displacement, pose from one circling within 5 mm and 5 deg (medians).

#[path = "harness/mod.rs"]
mod harness;

use harness::{HarnessConfig, ObjectReport, format_report, run_object};

/// Median rotation error of unseen pushes, degrees.
const MAX_ROTATION_ERROR_DEG: f64 = 5.0;
/// Median displacement error as a fraction of the true displacement.
const MAX_DISPLACEMENT_ERROR_RATIO: f64 = 0.20;
/// Median position error of the pose from one circling, mm.
const MAX_POSE_POSITION_MM: f64 = 5.0;
/// Median orientation error of the pose from one circling, degrees.
const MAX_POSE_ORIENTATION_DEG: f64 = 5.0;

/// Whether `value` is a number no larger than `max` (a NaN median, from no sample, is not).
fn within(value: f64, max: f64) -> bool {
    value.is_finite() && value <= max
}

/// Every target the report misses, as sentences.
fn misses(r: &ObjectReport) -> Vec<String> {
    let mut out = Vec::new();
    let p = &r.prediction;
    if p.pushes < 200 {
        out.push(format!("only {} unseen pushes", p.pushes));
    }
    if p.unpredicted > 0 {
        out.push(format!("{} unseen pushes got no prediction", p.unpredicted));
    }
    if r.symmetry_order != 0 && !within(p.rotation_error_deg.median, MAX_ROTATION_ERROR_DEG) {
        out.push(format!(
            "median rotation error {:.2} deg > {MAX_ROTATION_ERROR_DEG}",
            p.rotation_error_deg.median
        ));
    }
    if !within(
        p.displacement_error_ratio.median,
        MAX_DISPLACEMENT_ERROR_RATIO,
    ) {
        out.push(format!(
            "median displacement error {:.3} of the true displacement > {MAX_DISPLACEMENT_ERROR_RATIO}",
            p.displacement_error_ratio.median
        ));
    }
    if !within(r.pose_position_mm.median, MAX_POSE_POSITION_MM) {
        out.push(format!(
            "median pose position error {:.2} mm > {MAX_POSE_POSITION_MM}",
            r.pose_position_mm.median
        ));
    }
    if let Some(o) = &r.pose_orientation_deg
        && !within(o.median, MAX_POSE_ORIENTATION_DEG)
    {
        out.push(format!(
            "median pose orientation error {:.2} deg > {MAX_POSE_ORIENTATION_DEG}",
            o.median
        ));
    }
    if r.shape_circling_moved_object_mm > 1.0 {
        out.push(format!(
            "the shape circling moved the object by {:.1} mm (it must not touch it)",
            r.shape_circling_moved_object_mm
        ));
    }
    // The learned largest rotations are the true ones within the pose's accuracy.
    if r.symmetry_order != 0 {
        for &(alpha, learned, truth) in &r.max_rotation_deg {
            if !within((learned - truth).abs(), 3.0) {
                out.push(format!(
                    "A{alpha}: learned largest rotation {learned:.2} deg, true {truth:.2}"
                ));
            }
        }
    }
    if r.learned * 10 < r.trials * 9 {
        out.push(format!("only {} of {} trials learned", r.learned, r.trials));
    }
    out
}

fn run_and_check(objects: &[&str], cfg: &HarnessConfig) {
    let mut failures = Vec::new();
    for name in objects {
        let r = run_object(name, cfg);
        println!("{}", format_report(&r));
        failures.extend(misses(&r).into_iter().map(|m| format!("{name}: {m}")));
    }
    assert!(
        failures.is_empty(),
        "targets missed:\n  {}",
        failures.join("\n  ")
    );
}

#[test]
#[ignore = "issue 3 open: the 3-alpha protocol misses the rotation (8.1-8.3 deg > 5) and displacement (0.21-0.25 > 0.2) targets; run with --ignored"]
fn the_papers_protocol_learns_gradients_that_predict_unseen_pushes_within_the_targets() {
    // Alphas {0, +15, -15}, 60 trials each: benchmarks.md section 1 as written.
    run_and_check(&["triangle", "lshape"], &HarnessConfig::default());
}

#[test]
#[ignore = "issue 3 open: the L's median displacement error is 0.211 > 0.2; run with --ignored"]
fn alphas_every_5_degrees_learn_gradients_that_predict_unseen_pushes_within_the_targets() {
    // The same protocol with four more alphas: predictions at an alpha between two
    // learned ones interpolate linearly, and 15 deg apart that is what misses the target.
    let cfg = HarnessConfig {
        alphas_deg: vec![0.0, 5.0, -5.0, 10.0, -10.0, 15.0, -15.0],
        ..HarnessConfig::default()
    };
    run_and_check(&["triangle", "lshape"], &cfg);
}
