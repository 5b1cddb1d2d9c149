//! `--shard I/N` and `agp bench merge` as a user runs them: the real binary in a temporary
//! folder. The shards of a run, merged, write the JSON one process over every seed writes,
//! field by field but for wall times, for the placement (in-process and over the pipeline)
//! and the learning benchmark; parts of different runs are refused in one line naming the
//! file.

use std::path::Path;
use std::time::Duration;

use agp_tests::{learned_ag, run_agp};
use serde_json::Value;

/// Safety net of every run; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(900);

fn json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: not JSON: {e}", path.display()))
}

/// `doc` without its wall times (`wall_time_s`, at any depth), the one field a merge may
/// change, and, over the pipeline, without each episode's `estimate` (the count of the
/// estimator's estimates the judge's reader saw depends on timing).
fn figures(doc: &Value, drop_estimates: bool) -> Value {
    match doc {
        Value::Object(m) => Value::Object(
            m.iter()
                .filter(|(k, _)| {
                    k.as_str() != "wall_time_s" && !(drop_estimates && k.as_str() == "estimate")
                })
                .map(|(k, v)| (k.clone(), figures(v, drop_estimates)))
                .collect(),
        ),
        Value::Array(a) => Value::Array(a.iter().map(|v| figures(v, drop_estimates)).collect()),
        v => v.clone(),
    }
}

#[track_caller]
fn run_ok(dir: &Path, args: &[&str]) -> String {
    let run = run_agp(dir, args, TIMEOUT);
    assert!(
        run.status.success(),
        "agp {}\n{}\n{}",
        args.join(" "),
        run.stdout,
        run.stderr
    );
    run.stdout
}

/// Runs `bench` over `seeds` seeds in one process and in `shards` shards, merges the
/// shards, and checks the two JSONs agree but for wall times.
fn shards_merge_into_one_run(
    dir: &Path,
    bench: &[&str],
    seeds: u64,
    shards: u64,
    over_pipeline: bool,
) {
    let seeds = seeds.to_string();
    let mut one: Vec<&str> = bench.to_vec();
    one.extend(["--seeds", &seeds, "--json", "one.json"]);
    run_ok(dir, &one);
    let mut parts = Vec::new();
    for i in 1..=shards {
        let shard = format!("{i}/{shards}");
        let part = format!("part-{i}.json");
        let mut args: Vec<&str> = bench.to_vec();
        args.extend(["--seeds", &seeds, "--shard", &shard, "--json", &part]);
        run_ok(dir, &args);
        let v = json(&dir.join(&part));
        assert_eq!(v["shard"], shard.as_str(), "{part}");
        assert_eq!(
            v["seeds"].as_array().map(Vec::len),
            Some(seeds.parse().expect("a count")),
            "{part}: `seeds` lists every seed of the run"
        );
        parts.push(part);
    }
    let mut merge: Vec<&str> = vec!["bench", "merge"];
    merge.extend(parts.iter().map(String::as_str));
    merge.extend(["--json", "merged.json"]);
    run_ok(dir, &merge);
    let one = json(&dir.join("one.json"));
    let merged = json(&dir.join("merged.json"));
    assert!(merged.get("shard").is_none(), "a merged run is no shard");
    let per_seed: Vec<&Value> = merged["per_seed"]
        .as_array()
        .expect("per_seed")
        .iter()
        .map(|d| &d["seed"])
        .collect();
    let seeds: Vec<&Value> = merged["seeds"].as_array().expect("seeds").iter().collect();
    assert_eq!(per_seed, seeds, "one per_seed entry per seed, in order");
    assert_eq!(
        merged["seed"], one["seeds"][0],
        "`seed` is the first seed run"
    );
    assert_eq!(
        figures(&merged, over_pipeline),
        figures(&one, over_pipeline),
        "the merged shards differ from one run"
    );
}

#[test]
fn placement_shards_merge_into_what_one_in_process_run_writes() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let ag = learned_ag("triangle");
    let ag = ag.to_str().expect("a UTF-8 path");
    let bench = [
        "bench",
        "place",
        "--in-process",
        "--scenario",
        "triangle",
        "--planners",
        "affordance,baseline",
        "--episodes",
        "1",
        "--ag",
        ag,
    ];
    shards_merge_into_one_run(dir.path(), &bench, 4, 3, false);
    // Aggregated over every episode of every seed, with each figure's spread over seeds.
    let merged = json(&dir.path().join("merged.json"));
    let p = &merged["planners"]["affordance"];
    assert_eq!(p["episodes"], 4);
    let rate = p["success_rate"].as_f64().expect("success_rate");
    let spread = &p["spread"]["success_rate"];
    assert_eq!(spread["n"], 4);
    assert!(
        (spread["mean"].as_f64().expect("mean") - rate).abs() < 1e-12,
        "one episode per seed: the mean over seeds is the rate over episodes: {p}"
    );
}

#[test]
fn placement_shards_over_the_pipeline_merge_into_what_one_run_writes() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let bench = [
        "bench",
        "place",
        "--scenario",
        "triangle",
        "--planners",
        "baseline",
        "--episodes",
        "1",
    ];
    shards_merge_into_one_run(dir.path(), &bench, 2, 2, true);
}

#[test]
fn learning_shards_merge_into_what_one_run_writes() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let bench = [
        "bench",
        "learn",
        "--scenario",
        "triangle",
        "--trials",
        "12",
        "--eval",
        "4",
        "--out",
        "learned",
    ];
    shards_merge_into_one_run(dir.path(), &bench, 2, 2, false);
    // Each seed learned its own gradient, in a folder of its own.
    for seed in [200, 201] {
        assert!(
            dir.path()
                .join(format!("learned/seed-{seed}/triangle.ag"))
                .is_file(),
            "seed {seed}"
        );
    }
}

#[test]
fn parts_of_different_runs_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let ag = learned_ag("triangle");
    let ag = ag.to_str().expect("a UTF-8 path");
    let place = |shard: &str, seeds: &str, planners: &str, json: &str| {
        run_ok(
            dir.path(),
            &[
                "bench",
                "place",
                "--in-process",
                "--scenario",
                "triangle",
                "--planners",
                planners,
                "--episodes",
                "1",
                "--ag",
                ag,
                "--seeds",
                seeds,
                "--shard",
                shard,
                "--json",
                json,
            ],
        );
    };
    place("1/2", "2", "baseline", "a.json");
    place("2/2", "2", "baseline", "b.json");
    place("2/2", "4", "baseline", "other-run.json");
    place("2/2", "2", "affordance", "other-planner.json");
    std::fs::write(dir.path().join("broken.json"), "{").expect("write");
    let learn = r#"{"benchmark": "learn", "seed": 201, "objects": {}}"#;
    std::fs::write(dir.path().join("learn.json"), learn).expect("write");
    let cases: [(&[&str], &str); 6] = [
        (
            &["a.json"],
            "seed 201 of the run (seeds 200, 201) is in no part",
        ),
        (&["a.json", "a.json"], "`a.json`: given twice"),
        (
            &["a.json", "other-run.json"],
            "`other-run.json`: a part of another run",
        ),
        (
            &["a.json", "other-planner.json"],
            "`other-planner.json`: seed 201 is of another run",
        ),
        (&["a.json", "broken.json"], "`broken.json`: not JSON"),
        (
            &["a.json", "learn.json"],
            "`learn.json`: a `learn` result, not `place`",
        ),
    ];
    for (parts, expected) in cases {
        let mut args = vec!["bench", "merge"];
        args.extend(parts);
        args.extend(["--json", "merged.json"]);
        let run = run_agp(dir.path(), &args, TIMEOUT);
        assert!(!run.status.success(), "{parts:?} merged");
        assert!(
            run.stderr.contains(expected),
            "{parts:?}: expected `{expected}` in:\n{}",
            run.stderr
        );
        assert_eq!(
            run.stderr.trim().lines().count(),
            1,
            "one line: {}",
            run.stderr
        );
        assert!(!dir.path().join("merged.json").exists());
    }
    // The right parts merge.
    run_ok(
        dir.path(),
        &[
            "bench",
            "merge",
            "b.json",
            "a.json",
            "--json",
            "merged.json",
        ],
    );
    assert_eq!(
        json(&dir.path().join("merged.json"))["seeds"],
        serde_json::json!([200, 201])
    );
}
