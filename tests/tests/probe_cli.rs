//! `agp probe push` end to end: the real `agp`, its own `agp-physics` over shared memory,
//! checked against what the mechanics must give and against bad input.

use std::time::Duration;

use agp_tests::{Finished, count_instance_files, run_agp};
use serde_json::Value;

/// A safety net: a probe of a few simulated seconds takes well under a second.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Runs a probe that must succeed, checks it left no file behind, returns its JSON.
#[track_caller]
fn probe(args: &[&str]) -> Value {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut all = vec!["probe", "push"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--json", "out.json"]);
    let run = run_agp(dir.path(), &all, TIMEOUT);
    assert!(
        run.status.success(),
        "`agp {}` failed: {}{}",
        all.join(" "),
        run.stdout,
        run.stderr
    );
    assert_clean(&run);
    let text = std::fs::read_to_string(dir.path().join("out.json")).expect("the JSON file");
    serde_json::from_str(&text).expect("valid JSON")
}

#[track_caller]
fn assert_clean(run: &Finished) {
    let name = format!("probe-{}", run.pid);
    assert_eq!(
        count_instance_files(&name),
        0,
        "the probe's instance `{name}` left files behind"
    );
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("`{key}` is not a number in {v}"))
}

#[test]
fn a_push_through_the_centroid_translates_the_square_by_speed_times_duration() {
    // The robot is kinematic (stepper wheels): once touching a face head-on through the
    // centroid it carries the square along at its own speed, with no torque. After the
    // push the robot stops dead and Coulomb friction stops the square within a fraction
    // of a millimetre (a 0.4 friction coefficient stops 0.1 m/s in 2.5 mm at most).
    for (angle, ex, ey) in [("0", -1.0, 0.0), ("90", 0.0, -1.0), ("180", 1.0, 0.0)] {
        let r = probe(&[
            "--scenario",
            "square",
            "--angle-deg",
            angle,
            "--alpha-deg",
            "0",
            "--duration-ms",
            "1500",
            "--speed-mm-s",
            "80",
        ]);
        assert_eq!(r["contact"], Value::Bool(true), "{r}");
        let expected = 80.0 * 1.5;
        let (dx, dy) = (num(&r, "dx_mm"), num(&r, "dy_mm"));
        assert!(
            (dx - ex * expected).abs() < 3.0 && (dy - ey * expected).abs() < 3.0,
            "from {angle} deg: moved ({dx:.1}, {dy:.1}) mm, expected ({:.1}, {:.1}) within 3 mm",
            ex * expected,
            ey * expected
        );
        let rot = num(&r, "rotation_deg");
        assert!(rot.abs() < 0.5, "from {angle} deg: turned {rot:.2} deg");
    }
}

#[test]
fn mirrored_pushes_on_the_triangles_axis_give_mirrored_motions() {
    // The triangle is mirror-symmetric about its object-frame y axis; a robot below it
    // (270 deg) driving 15 deg left or right of the centroid must produce mirror images:
    // rotations of opposite sign, dx of opposite sign, the same dy.
    let push = |alpha: &str| {
        probe(&[
            "--scenario",
            "triangle",
            "--angle-deg",
            "270",
            "--alpha-deg",
            alpha,
            "--duration-ms",
            "1000",
        ])
    };
    let (left, right) = (push("15"), push("-15"));
    for r in [&left, &right] {
        assert_eq!(r["contact"], Value::Bool(true), "{r}");
    }
    let (rl, rr) = (num(&left, "rotation_deg"), num(&right, "rotation_deg"));
    assert!(
        rl.abs() > 5.0,
        "an off-centre push must turn the triangle, turned {rl:.2} deg"
    );
    assert!(
        (rl + rr).abs() < 0.5,
        "rotations {rl:.2} and {rr:.2} deg are not mirror images"
    );
    let (xl, xr) = (num(&left, "dx_mm"), num(&right, "dx_mm"));
    let (yl, yr) = (num(&left, "dy_mm"), num(&right, "dy_mm"));
    assert!(
        (xl + xr).abs() < 1.0 && (yl - yr).abs() < 1.0,
        "displacements ({xl:.1}, {yl:.1}) and ({xr:.1}, {yr:.1}) mm are not mirror images"
    );
    // Alpha +15 from below heads up and to the left: the line of push passes left of
    // the centroid, and an upward force left of the centroid turns the body clockwise.
    assert!(
        rl < 0.0,
        "alpha +15 from below turned the triangle {rl:.2} deg"
    );
}

#[test]
fn a_drive_that_misses_the_object_reports_no_contact_and_no_motion() {
    // From 20 mm outside the square's corner circle, 70 deg off the centroid, the line of
    // drive passes the square's farthest point by more than the robot's radius.
    let r = probe(&[
        "--scenario",
        "square",
        "--angle-deg",
        "0",
        "--alpha-deg",
        "70",
    ]);
    assert_eq!(r["contact"], Value::Bool(false), "{r}");
    assert_eq!(num(&r, "dx_mm"), 0.0);
    assert_eq!(num(&r, "dy_mm"), 0.0);
    assert_eq!(num(&r, "rotation_deg"), 0.0);
}

#[track_caller]
fn refused(args: &[&str], dir: &std::path::Path, needle: &str) {
    let mut all = vec!["probe", "push"];
    all.extend_from_slice(args);
    let run = run_agp(dir, &all, TIMEOUT);
    assert!(
        !run.status.success(),
        "`agp {}` must fail, printed {}",
        all.join(" "),
        run.stdout
    );
    assert!(
        run.stderr.contains(needle),
        "`agp {}`: the error does not say `{needle}`: {}",
        all.join(" "),
        run.stderr
    );
    assert_clean(&run);
}

#[test]
fn bad_input_is_refused_with_a_message_that_names_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let base = ["--angle-deg", "0"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut v = base.to_vec();
        v.extend_from_slice(extra);
        v
    };
    refused(
        &with(&["--scenario", "hexagon"]),
        dir.path(),
        "`hexagon` is neither a built-in scenario",
    );
    std::fs::write(
        dir.path().join("bad.toml"),
        "name = \"bad\"\n[object]\nshape = \"circle\"\nradius_mm = -5\n",
    )
    .expect("write");
    refused(&with(&["--scenario", "bad.toml"]), dir.path(), "bad.toml:");
    refused(
        &with(&["--scenario", "square", "--alpha-deg", "95"]),
        dir.path(),
        "--alpha-deg 95",
    );
    refused(
        &with(&["--scenario", "square", "--speed-mm-s", "500"]),
        dir.path(),
        "--speed-mm-s 500",
    );
    refused(
        &with(&["--scenario", "square", "--duration-ms", "0"]),
        dir.path(),
        "--duration-ms 0",
    );
}
