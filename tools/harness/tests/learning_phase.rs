//! The learning phase against the physics, in-process: the acceptance of the learning
//! issue (benchmarks.md section 1). Two objects here, one symmetric and one not (the
//! triangle and the L); `examples/learn_report.rs` runs all four.
//!
//! Targets: median rotation error of unseen pushes <= 5 deg, median displacement error <=
//! 20 % of the true displacement, pose from one circling within 5 mm and 5 deg (medians).
//!
//! Both meet them on every seed of 1-10 (`agp bench learn --first-seed 1 --seeds 10`, push
//! sigma 2.5 mm, the shape circling started outside the grid as every learner does): the L
//! at 2.41-4.06 deg and 0.082-0.134 of the displacement, every unseen push predicted. The
//! L missed them on 6 of those seeds until the pushes that meet its border past the
//! centroid (across the notch) were kept apart from those that meet it first
//! (`agp_affordance::meets_past_centroid`); a push whose heading line meets no learned
//! border (the disc grazing a corner beside it) is keyed by where the body sweep says it
//! touched.

use agp_harness::learn_bench::{LearnBenchConfig, ObjectReport, format_report, run_object};
use agp_world::Scenario;

/// Whether `value` is a number no larger than `max` (a NaN median, from no sample, is not).
fn within(value: f64, max: f64) -> bool {
    value.is_finite() && value <= max
}

/// Every target the report misses, as sentences.
fn misses(r: &ObjectReport) -> Vec<String> {
    let mut out: Vec<String> = r
        .targets()
        .into_iter()
        .filter(|t| !t.met)
        .map(|t| format!("{}: measured {}", t.what, t.measured))
        .collect();
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

fn run_and_check(objects: &[&str], cfg: &LearnBenchConfig) {
    let mut failures = Vec::new();
    for name in objects {
        let scenario = Scenario::builtin(name).expect("a built-in scenario");
        let r = run_object(&scenario, cfg, &mut |_| {}).expect("the learning phase runs");
        println!("{}", format_report(&r));
        failures.extend(misses(&r).into_iter().map(|m| format!("{name}: {m}")));
    }
    assert!(
        failures.is_empty(),
        "targets missed:\n  {}",
        failures.join("\n  ")
    );
}

// One test per object and protocol, so the test harness's threads share the four learnings
// evenly (two objects in one test ran one after the other on one thread).

#[test]
fn the_papers_protocol_learns_the_triangles_gradients_within_the_targets() {
    // Alphas {0, +15, -15}, 60 trials each: benchmarks.md section 1 as written.
    run_and_check(&["triangle"], &LearnBenchConfig::default());
}

#[test]
fn the_papers_protocol_learns_the_ls_gradients_within_the_targets() {
    run_and_check(&["lshape"], &LearnBenchConfig::default());
}

/// The paper's protocol with four more alphas: the targets hold at a finer grid too.
fn every_5_degrees() -> LearnBenchConfig {
    LearnBenchConfig {
        alphas_deg: vec![0.0, 5.0, -5.0, 10.0, -10.0, 15.0, -15.0],
        ..LearnBenchConfig::default()
    }
}

#[test]
fn alphas_every_5_degrees_learn_the_triangles_gradients_within_the_targets() {
    run_and_check(&["triangle"], &every_5_degrees());
}

#[test]
fn alphas_every_5_degrees_learn_the_ls_gradients_within_the_targets() {
    run_and_check(&["lshape"], &every_5_degrees());
}
