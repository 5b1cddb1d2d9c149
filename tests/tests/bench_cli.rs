//! `agp bench place`, `trajectory` and `paper` as a user runs them: the real binary in a
//! temporary folder, over the real pipeline; the JSON fields scripts rely on
//! (benchmarks.md, "What a benchmark run writes"), the plots, the private instance left
//! clean, and bad input refused before anything runs.

use std::path::Path;
use std::time::Duration;

use agp_tests::{count_instance_files, learned_ag, run_agp};
use serde_json::Value;

/// Safety net of every run; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(900);

fn json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: not JSON: {e}", path.display()))
}

fn num(v: &Value, key: &str) -> f64 {
    v.get(key)
        .and_then(Value::as_f64)
        .unwrap_or_else(|| panic!("no number `{key}` in {v}"))
}

#[track_caller]
fn assert_svg(path: &Path) {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("no plot at {}: {e}", path.display()));
    assert!(text.starts_with("<svg"), "{} is not an SVG", path.display());
}

#[test]
fn bench_place_writes_every_planners_figures_over_the_pipeline_and_leaves_no_file() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let ag = learned_ag("triangle");
    let ag = ag.to_str().expect("a UTF-8 path");
    let run = run_agp(
        dir.path(),
        &[
            "bench",
            "place",
            "--scenario",
            "triangle",
            "--episodes",
            "2",
            "--seed",
            "3",
            "--ag",
            ag,
            "--json",
            "place.json",
            "--plot",
            "place.svg",
        ],
        TIMEOUT,
    );
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    let v = json(&dir.path().join("place.json"));
    assert_eq!(v["benchmark"], "place");
    assert_eq!(v["scenario"], "triangle");
    assert_eq!(v["seed"], 3);
    assert_eq!(v["physics"], "pipeline");
    assert!(num(&v, "wall_time_s") > 0.0);
    for planner in ["affordance", "baseline", "oracle"] {
        let p = &v["planners"][planner];
        assert_eq!(p["episodes"], 2, "{planner}: {p}");
        let rate = num(p, "success_rate");
        assert!((0.0..=1.0).contains(&rate), "{planner}: {rate}");
        for key in [
            "median_position_error_mm",
            "median_orientation_error_deg",
            "median_pushes",
            "sim_time_s",
        ] {
            assert!(num(p, key) >= 0.0, "{planner}: {key} in {p}");
        }
        assert_eq!(p["reads_ground_truth"], planner == "oracle");
        // The episodes' goals lie 250 to 500 mm from the start, as the benchmark asks.
        for r in p["runs"].as_array().expect("runs") {
            let d = num(r, "goal_x_mm").hypot(num(r, "goal_y_mm"));
            assert!((250.0..=500.0).contains(&d), "{planner}: goal {d} mm away");
        }
    }
    assert!(
        run.stdout.contains("oracle (GT)"),
        "the oracle is labelled: {}",
        run.stdout
    );
    assert_svg(&dir.path().join("place.svg"));
    assert_eq!(bench_files_left(run.pid), 0);
}

/// `agp bench trajectory` of the L at seed 7 with the test AG, JSON to `t.json`, and `more`.
fn bench_trajectory_of_seed_7(dir: &std::path::Path, more: &[&str]) -> agp_tests::Finished {
    let ag = learned_ag("lshape");
    let ag = ag.to_str().expect("a UTF-8 path");
    let mut args = vec![
        "bench",
        "trajectory",
        "--scenario",
        "lshape",
        "--ag",
        ag,
        "--seed",
        "7",
        "--json",
        "t.json",
    ];
    args.extend_from_slice(more);
    run_agp(dir, &args, TIMEOUT)
}

#[test]
fn a_trajectory_that_asks_to_keep_the_heading_hands_it_to_the_planner_process() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let run =
        bench_trajectory_of_seed_7(dir.path(), &["--paths", "straight", "--keep-heading", "15"]);
    // Each episode's planner process takes the heading with its path (it refuses an
    // argument it does not know, and the run would fail).
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    let v = json(&dir.path().join("t.json"));
    assert_eq!(v["keep_heading_deg"], 15.0, "{v}");
    let a = &v["per_seed"][0]["paths"]["straight"]["planners"]["affordance"];
    assert_eq!(a["reached_end"], true, "{a}");
    // Along a straight line through the centroid the heading never needs to turn.
    assert!(num(a, "heading_within_15_deg") > 0.9, "{a}");
}

#[test]
fn bench_trajectory_compares_both_planners_on_each_path_of_one_seed() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let run = bench_trajectory_of_seed_7(
        dir.path(),
        &["--paths", "straight,bend90", "--plot", "t.svg"],
    );
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    let v = json(&dir.path().join("t.json"));
    assert_eq!(v["benchmark"], "trajectory");
    assert_eq!(v["physics"], "pipeline");
    assert_eq!(v["seed"], 7);
    assert_eq!(v["seeds"], serde_json::json!([7]));
    assert_eq!(
        v["keep_heading_deg"],
        serde_json::Value::Null,
        "no heading asked"
    );
    let a = num(&v["planners"]["affordance"], "mean_error_mm");
    let b = num(&v["planners"]["baseline"], "mean_error_mm");
    assert!(a > 0.0 && b > 0.0, "{v}");
    assert!((num(&v, "ratio") - a / b).abs() < 1e-9, "{v}");
    let paths = v["paths"].as_object().expect("paths");
    assert_eq!(
        paths.keys().map(String::as_str).collect::<Vec<_>>(),
        ["bend90", "straight"]
    );
    // The bend's second leg runs 250 mm towards -y: the path handed to the planner
    // process is the benchmark's, not the scenario's line.
    let corner_end = &v["paths"]["bend90"]["path_mm"][2];
    let xy = |i: usize| corner_end[i].as_f64().expect("a number");
    assert!(
        (xy(0) - 300.0).abs() < 1e-6 && (xy(1) + 250.0).abs() < 1e-6,
        "{v}"
    );
    let episode = &v["per_seed"][0]["paths"]["bend90"]["planners"];
    for planner in ["affordance", "baseline"] {
        // The object is recorded while it is pushed: many points along 550 mm.
        assert!(num(&episode[planner], "points") > 20.0, "{planner}: {v}");
        // Both ended near the bent path's end, which only following the bend reaches.
        assert!(
            num(&episode[planner], "final_distance_to_end_mm") < 30.0,
            "{planner}: {v}"
        );
    }
    assert!(run.stdout.contains("bend90"), "{}", run.stdout);
    assert!(run.stdout.contains("overall"), "{}", run.stdout);
    assert!(
        run.stdout
            .contains("paper, one straight line: 7.82 / 10.71"),
        "{}",
        run.stdout
    );
    assert_svg(&dir.path().join("t.svg"));
    assert_eq!(bench_files_left(run.pid), 0);
}

#[test]
fn bad_bench_input_is_refused_before_anything_runs() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    // A user's scenario file (the pentagon of benchmarks.md) with two vertices only.
    let pentagon =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../libs/world/scenarios/pentagon.toml");
    let text = std::fs::read_to_string(&pentagon).expect("the pentagon scenario");
    let bad: String = text
        .lines()
        .map(|l| {
            if l.starts_with("vertices_mm") {
                "vertices_mm = [[0, 0], [10, 0]]".to_owned()
            } else {
                l.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(dir.path().join("bad.toml"), bad).expect("write a bad scenario");
    let cases: [(&[&str], &str); 4] = [
        (
            &[
                "bench",
                "place",
                "--scenario",
                "triangle",
                "--episodes",
                "0",
            ],
            "--episodes",
        ),
        (
            &[
                "bench",
                "place",
                "--scenario",
                "triangle",
                "--planners",
                "magic",
            ],
            "unknown planner `magic`",
        ),
        (
            &[
                "bench",
                "place",
                "--scenario",
                "bad.toml",
                "--episodes",
                "1",
            ],
            "bad.toml:7: `vertices_mm`: a polygon needs at least 3 vertices",
        ),
        (
            &[
                "bench",
                "trajectory",
                "--scenario",
                "lshape",
                "--ag",
                "missing.ag",
            ],
            "missing.ag",
        ),
    ];
    for (args, expected) in cases {
        let run = run_agp(dir.path(), args, TIMEOUT);
        assert!(!run.status.success(), "{args:?} succeeded");
        assert!(
            run.stderr.contains(expected),
            "{args:?}: expected `{expected}` in:\n{}",
            run.stderr
        );
        assert_eq!(bench_files_left(run.pid), 0);
    }
    // Nothing was learned or written for the refused runs.
    assert!(!dir.path().join("results").exists());
}

#[test]
fn a_scenario_file_of_the_users_own_is_learned_and_placed_with_no_code_change() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let pentagon =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../libs/world/scenarios/pentagon.toml");
    let pentagon = pentagon.to_str().expect("a UTF-8 path");
    // No AG file yet: the bench learns the pentagon first with the paper's protocol.
    let run = run_agp(
        dir.path(),
        &[
            "bench",
            "place",
            "--scenario",
            pentagon,
            "--episodes",
            "1",
            "--planners",
            "affordance",
            "--json",
            "p.json",
        ],
        TIMEOUT,
    );
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    assert!(
        dir.path().join("results/learn/my-pentagon.ag").is_file(),
        "the learned gradient is kept for the next run"
    );
    let v = json(&dir.path().join("p.json"));
    assert_eq!(v["scenario"], "my-pentagon");
    let p = &v["planners"]["affordance"];
    assert_eq!(num(p, "success_rate"), 1.0, "{p}");
    assert!(num(p, "median_position_error_mm") <= 10.0, "{p}");
    assert!(num(p, "median_orientation_error_deg") <= 10.0, "{p}");
    assert_eq!(bench_files_left(run.pid), 0);
}

/// Files left by the private pipelines of a bench run (`bench-<pid>-<first three letters of the
/// planner>`, one per planner, run side by side), and any other file of `/dev/shm` that names the run's pid.
fn bench_files_left(pid: u32) -> usize {
    let named = format!("bench-{pid}-");
    let in_shm = std::fs::read_dir("/dev/shm")
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().contains(&named))
                .count()
        })
        .unwrap_or(0);
    ["aff", "bas", "ora"]
        .iter()
        .map(|planner| count_instance_files(&format!("bench-{pid}-{planner}")))
        .sum::<usize>()
        + in_shm
}
