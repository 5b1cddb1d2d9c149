//! A live session (`agp-planner --mode serve`) given goals with `agp goal`: they are
//! pursued one after the other, judged by ground truth as each ends, and listed with their
//! verdicts by `agp status --json` and in `<results>/<instance>-goals.json` after `agp
//! down`. The session runs on the lockstep clock here (outcomes, not timing, are checked;
//! launch-live.toml runs the same on the realtime clock).

use std::path::Path;
use std::time::Duration;

use agp_tests::{
    AgpUp, LaunchDir, count_instance_files, learned_ag, run_agp, status_json, triangle_ring_launch,
};
use agp_world::Scenario;
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(240);

/// The triangle's ring with the planner serving goals.
fn launch(instance: &str, ag: &Path) -> String {
    triangle_ring_launch(
        instance,
        ag,
        "",
        r#""--mode", "serve", "--planner", "affordance""#,
        false,
    )
}

/// The goals listed by a status reply.
fn goals(status: &Value) -> Vec<Value> {
    status["goals"].as_array().cloned().unwrap_or_default()
}

#[test]
fn three_goals_queued_to_a_session_are_reached_one_after_the_other_and_judged() {
    let name = "t-live-goals";
    let ag = learned_ag("triangle");
    let dir = LaunchDir::new(&launch(name, &ag));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("serving the goals", 1, TIMEOUT);

    // A bad goal is refused in one line, and queues nothing.
    let bad = run_agp(
        dir.path(),
        &["goal", "--instance", name, "--path", "0,0", "1;2"],
        TIMEOUT,
    );
    assert_ne!(bad.status.code(), Some(0));
    assert_eq!(
        bad.stderr.trim(),
        "agp: error: `1;2` is not a point: expected X,Y in millimetres, e.g. 100,-50"
    );

    for goal in [
        &["--place", "300", "150", "90"][..],
        &["--place", "200", "-50", "0"][..],
        &["--path", "200,-50", "350,-50"][..],
    ] {
        let mut args = vec!["goal", "--instance", name];
        args.extend_from_slice(goal);
        let run = run_agp(dir.path(), &args, TIMEOUT);
        assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
        assert!(run.stdout.contains("queued on"), "{}", run.stdout);
    }
    let queued = status_json(dir.path(), name, TIMEOUT);
    assert_eq!(queued["goals_total"], 3, "{queued}");

    let mut last = Value::Null;
    up.until("every goal judged", TIMEOUT, || {
        last = status_json(dir.path(), name, TIMEOUT);
        goals(&last).iter().all(|g| g["state"] == "done")
    });
    let task = Scenario::builtin("triangle").expect("built-in").task;
    let done = goals(&last);
    assert_eq!(
        done.iter().map(|g| g["id"].as_u64()).collect::<Vec<_>>(),
        [Some(1), Some(2), Some(3)]
    );
    for g in &done {
        assert_eq!(g["success"], true, "goal not reached: {g}");
        let mm = g["position_error_mm"].as_f64().expect("a position error");
        assert!(mm <= task.tolerance_m * 1e3, "{g}");
        assert!(g["estimate_position_error_mm"].as_f64().is_some(), "{g}");
    }
    for g in &done[..2] {
        assert_eq!(g["task"], "place");
        let deg = g["orientation_error_deg"]
            .as_f64()
            .expect("an orientation error");
        assert!(deg <= task.tolerance_rad.to_degrees(), "{g}");
    }
    assert_eq!(done[2]["task"], "trajectory");
    assert!(
        done[2]["mean_path_error_mm"].as_f64().is_some(),
        "{}",
        done[2]
    );
    // One after the other: each started where the one before left the object, so each
    // took simulated time of its own.
    assert!(done.iter().all(|g| g["sim_time_s"].as_f64() > Some(0.0)));

    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    let run = up.wait(TIMEOUT);
    assert_eq!(run.status.code(), Some(0), "{}\n{}", run.stdout, run.stderr);
    let file: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.results().join(format!("{name}-goals.json")))
            .expect("the session's goals file"),
    )
    .expect("JSON");
    assert_eq!(file["goals"], Value::Array(done), "{file}");
    assert_eq!(count_instance_files(name), 0);
}
