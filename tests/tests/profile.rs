//! `agp profile` on a running lockstep instance of real physics and the scripted planner,
//! and of a learning run with the estimator in the loop: every promised figure is there and
//! ordered, the floor ran, and nothing is left behind.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use agp_runtime::{Instance, LockstepDriver, TruthAccess};
use agp_shared_types::{Pose2, stage};
use agp_tests::{
    AgpUp, LaunchDir, bin_path, count_instance_files, learned_ag, run_agp, triangle_ring_launch,
};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(120);

/// Physics and the scripted planner, pushing for longer than the test runs, both waiting
/// by `yield` (set in the launch file: the profiler must take it from the instance, not
/// from its own environment).
fn launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nenv = {{ AGP_WAIT = \"yield\" }}\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-scripted-drive\"\nenv = {{ AGP_WAIT = \"yield\" }}\n\
         args = [\"--pushes\", \"100000\", \"--push-ms\", \"200\"]\n\
         ends_run = true\n"
    )
}

/// The learning phase over physics, the estimator and the planner, with more trials than
/// the test lasts.
fn learn_launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"learn\", \"--trials-per-alpha\", \"60\"]\n\
         ends_run = true\n"
    )
}

/// Stops the instance if a failed assertion left it up.
struct Down<'a> {
    dir: &'a Path,
    name: &'a str,
}

impl Drop for Down<'_> {
    fn drop(&mut self) {
        if count_instance_files(self.name) > 0 {
            let _ = run_agp(self.dir, &["down", "--instance", self.name], TIMEOUT);
        }
    }
}

/// The state letter of process `pid` in /proc (`R`, `S`, `T` for stopped...).
fn process_state(pid: u64) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(')')?
        .1
        .split_whitespace()
        .next()?
        .chars()
        .next()
}

const FIGURES: [&str; 5] = ["p50_ns", "p90_ns", "p99_ns", "p999_ns", "max_ns"];

/// A row holds every figure, as a number, in order, and its ratio to the floor.
#[track_caller]
fn assert_row(row: &Value, what: &str) -> u64 {
    let name = row["name"]
        .as_str()
        .unwrap_or_else(|| panic!("{what}: no name in {row}"));
    let values: Vec<u64> = FIGURES
        .iter()
        .map(|k| {
            row[k]
                .as_u64()
                .unwrap_or_else(|| panic!("{what} `{name}`: no `{k}` in {row}"))
        })
        .collect();
    assert!(
        values.windows(2).all(|w| w[0] <= w[1]),
        "{what} `{name}`: p50 <= p90 <= p99 <= p999 <= max does not hold: {values:?}"
    );
    assert!(values[0] > 0, "{what} `{name}`: p50 is 0: {row}");
    assert!(
        row["ratio_to_floor_p50"].as_f64().is_some_and(|r| r > 0.0),
        "{what} `{name}`: no ratio to the floor in {row}"
    );
    values[0]
}

/// Runs `agp profile <extra...> --seconds 1` in `dir`, writing `out.json` and `out.svg`
/// there, and returns the JSON and the pid `agp profile` ran as (its floor's private
/// instance is `pfloor-<pid>`); panics if it fails.
#[track_caller]
fn profile_json(dir: &Path, extra: &[&str]) -> (Value, u32) {
    let mut args = vec!["profile"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--seconds", "1", "--json", "out.json", "--plot", "out.svg"]);
    let profile = run_agp(dir, &args, TIMEOUT);
    assert!(
        profile.status.success(),
        "agp profile failed: {}{}",
        profile.stdout,
        profile.stderr
    );
    let text = std::fs::read_to_string(dir.join("out.json")).expect("out.json written");
    (
        serde_json::from_str(&text).expect("out.json is JSON"),
        profile.pid,
    )
}

#[test]
fn profile_of_a_lockstep_run_reports_every_hop_stage_and_the_floor_in_order_and_leaves_no_file() {
    let name = "t-profile";
    let dir = LaunchDir::new(&launch(name));
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(up.status.success(), "{}{}", up.stdout, up.stderr);
    let guard = Down {
        dir: dir.path(),
        name,
    };

    let (v, profile_pid) = profile_json(dir.path(), &[]);

    let hops = v["hops"].as_array().expect("`hops` is a list");
    let hop_names: Vec<&str> = hops.iter().filter_map(|h| h["name"].as_str()).collect();
    assert_eq!(hop_names, ["physics->planner", "planner->physics"]);
    let hop_p50: Vec<u64> = hops.iter().map(|h| assert_row(h, "hop")).collect();
    let stages = v["stages"].as_array().expect("`stages` is a list");
    let stage_names: Vec<&str> = stages.iter().filter_map(|h| h["name"].as_str()).collect();
    assert_eq!(stage_names, ["planner", "physics.step", "physics.publish"]);
    for s in stages {
        assert_row(s, "stage");
    }
    let end_to_end = assert_row(&v["end_to_end"], "end_to_end");
    assert_row(&v["floor"], "floor");
    for (name, p50) in hop_names.iter().zip(&hop_p50) {
        assert!(
            end_to_end >= *p50,
            "end to end p50 {end_to_end} ns is below hop `{name}`'s p50 {p50} ns"
        );
    }
    // The launch file's, reported by the supervisor; this process has no AGP_WAIT of its
    // own to offer (or one that the profiler says it does not use).
    assert_eq!(v["waiting"].as_str(), Some("yield"), "{v}");
    let status = run_agp(dir.path(), &["status", "--json"], TIMEOUT);
    let status: Value = serde_json::from_str(&status.stdout).expect("status --json is JSON");
    assert_eq!(status["waiting"].as_str(), Some("yield"), "{status}");
    assert!(
        v["samples"].as_u64().is_some_and(|n| n > 0),
        "no sample in {v}"
    );
    assert!(
        v["floor_run"]["round_trips"]
            .as_u64()
            .is_some_and(|n| n > 0),
        "the floor made no round trip: {v}"
    );
    let svg = std::fs::read_to_string(dir.path().join("out.svg")).expect("out.svg written");
    assert!(svg.starts_with("<svg"), "out.svg is no SVG");
    for series in [
        "physics-&gt;planner",
        "planner-&gt;physics",
        "end_to_end",
        "floor",
    ] {
        assert!(svg.contains(series), "the plot has no series `{series}`");
    }
    // The floor's private instance is gone with it.
    assert_eq!(count_instance_files(&format!("pfloor-{profile_pid}")), 0);
    // The pipeline, paused while the floor ran, runs again: no process is left stopped.
    let status = run_agp(
        dir.path(),
        &["status", "--instance", name, "--json"],
        TIMEOUT,
    );
    assert!(status.status.success(), "{}", status.stderr);
    let status: Value = serde_json::from_str(&status.stdout).expect("status JSON");
    for p in status["processes"].as_array().expect("processes") {
        let pid = p["pid"].as_u64().expect("a running process has a pid");
        assert_ne!(
            process_state(pid),
            Some('T'),
            "process `{}` is still stopped after the profile",
            p["name"]
        );
    }

    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    drop(guard);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` are left");
}

/// Profiles the running instance `name` and checks that every step went through the three
/// processes: the estimator's hops and stages, no physics->planner hop; then stops it.
fn assert_three_process_ring(dir: &Path, name: &str, up: AgpUp) {
    let guard = Down { dir, name };
    let (v, profile_pid) = profile_json(dir, &["--instance", name]);

    // The estimator's hops, and no physics->planner: the planner acts on the estimate.
    let hops = v["hops"].as_array().expect("`hops` is a list");
    let hop_names: Vec<&str> = hops.iter().filter_map(|h| h["name"].as_str()).collect();
    assert_eq!(
        hop_names,
        [
            "physics->estimator",
            "estimator->planner",
            "planner->physics"
        ]
    );
    for row in hops {
        assert!(
            row["samples"].as_u64().is_some_and(|n| n > 0),
            "hop without samples: {row}"
        );
    }
    let hop_p50: Vec<u64> = hops.iter().map(|h| assert_row(h, "hop")).collect();
    let stages = v["stages"].as_array().expect("`stages` is a list");
    let stage_names: Vec<&str> = stages.iter().filter_map(|h| h["name"].as_str()).collect();
    assert_eq!(
        stage_names,
        ["estimator", "planner", "physics.step", "physics.publish"]
    );
    for s in stages {
        assert_row(s, "stage");
    }
    let end_to_end = assert_row(&v["end_to_end"], "end_to_end");
    assert_row(&v["floor"], "floor");
    for (hop, p50) in hop_names.iter().zip(&hop_p50) {
        assert!(
            end_to_end >= *p50,
            "end to end p50 {end_to_end} ns is below hop `{hop}`'s p50 {p50} ns"
        );
    }
    assert!(
        v["waiting"].as_str().is_some_and(|w| !w.is_empty()),
        "no waiting strategy in {v}"
    );
    let svg = std::fs::read_to_string(dir.join("out.svg")).expect("out.svg written");
    for series in [
        "physics-&gt;estimator",
        "estimator-&gt;planner",
        "planner-&gt;physics",
    ] {
        assert!(svg.contains(series), "the plot has no series `{series}`");
    }
    assert!(
        !svg.contains("physics-&gt;planner"),
        "the plot has a series no step passed"
    );
    assert_eq!(count_instance_files(&format!("pfloor-{profile_pid}")), 0);

    // Stop the run before its end; the supervisor then removes the instance.
    let down = run_agp(dir, &["down", "--instance", name], TIMEOUT);
    let run = up.wait(TIMEOUT);
    assert!(
        down.status.success(),
        "agp down: {}{}\nrun: {}{}",
        down.stdout,
        down.stderr,
        run.stdout,
        run.stderr
    );
    drop(guard);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` are left");
}

#[test]
fn profile_of_a_learning_run_reports_the_hops_through_the_estimator_and_leaves_no_file() {
    let name = "t-profile-learn";
    let dir = LaunchDir::new(&learn_launch(name));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    // The planner says so once the estimator acknowledged the first frame: from then on
    // every step goes through the three processes.
    up.wait_for_lines("learning `triangle`", 1, TIMEOUT);
    assert_three_process_ring(dir.path(), name, up);
}

/// The placement task with the estimator serving a learned AG file, towards a goal far
/// enough (800 mm and a half turn away) that the run outlasts the profile.
fn place_launch(instance: &str, ag: &Path) -> String {
    triangle_ring_launch(
        instance,
        ag,
        "",
        r#""--mode", "place", "--goal=600,600,180""#,
        true,
    )
}

#[test]
fn profile_of_a_placement_reports_the_hops_through_the_estimator_and_leaves_no_file() {
    let ag = learned_ag("triangle");
    let name = "t-profile-place";
    let dir = LaunchDir::new(&place_launch(name, &ag));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    // The planner has the gradient and the estimator's first estimate: every step from now
    // on goes physics -> estimator -> planner -> physics.
    up.wait_for_lines("planner `affordance`: place at", 1, TIMEOUT);
    assert_three_process_ring(dir.path(), name, up);
}

#[test]
fn an_instance_that_goes_down_while_profiled_ends_the_profile_in_one_line_and_keeps_what_was_sampled()
 {
    let name = "t-profile-ends";
    let dir = LaunchDir::new(&launch(name));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("scripted drive:", 1, TIMEOUT);
    let json = dir.path().join("ended.json");
    let profiler = Command::new(bin_path("agp"))
        .args(["profile", "--instance", name, "--seconds", "600", "--json"])
        .arg(&json)
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start agp profile");
    // Down once the profiler samples (its node is on the instance), not after a delay.
    let instance = Instance::new(name).expect("name");
    let profiling = || {
        let mut found = false;
        let _ = iceoryx2::prelude::Node::<agp_runtime::AgpIpc>::list(instance.config(), |state| {
            if let iceoryx2::node::NodeState::Alive(view) = &state {
                use iceoryx2::node::NodeView;
                found |= view
                    .details()
                    .as_ref()
                    .is_some_and(|d| d.name().as_str().starts_with("agp-profile-"));
            }
            iceoryx2::prelude::CallbackProgression::Continue
        });
        found
    };
    up.until("the profiler samples", TIMEOUT, profiling);
    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    let out = profiler.wait_with_output().expect("agp profile ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "one line, no iceoryx2 dump: {stderr}");
    assert!(
        lines[0].starts_with(&format!("agp: error: instance `{name}` went down ")),
        "{stderr}"
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the JSON is written"))
            .expect("JSON");
    assert_eq!(report["sampling"]["instance_went_down"], true, "{report}");
    assert!(report["samples"].as_u64() > Some(0), "{report}");
    let _ = up.wait(TIMEOUT);
    assert_eq!(count_instance_files(name), 0);
}

#[test]
fn profile_refuses_an_instance_that_is_not_up() {
    let name = "t-profile-none";
    let dir = LaunchDir::new(&launch(name));
    let run = run_agp(
        dir.path(),
        &["profile", "--instance", name, "--seconds", "1"],
        TIMEOUT,
    );
    assert!(
        !run.status.success(),
        "profile of a stopped instance succeeded"
    );
    assert!(
        run.stderr.contains("is not up"),
        "unexpected error: {}",
        run.stderr
    );
    assert_eq!(count_instance_files(name), 0);
}

#[test]
fn a_frame_carries_the_whole_timing_of_the_command_that_made_it() {
    let instance = Instance::new(&format!("t-cause-{}", std::process::id())).expect("name");
    instance.remove_files().expect("clean start");
    let mut child = Command::new(bin_path("agp-physics"))
        .env("AGP_INSTANCE", instance.name())
        .env("AGP_SCENARIO", "square")
        .env("AGP_CLOCK", "lockstep")
        .args(["--idle-timeout-s", "60"])
        .spawn()
        .expect("start agp-physics");
    let checked = std::panic::catch_unwind(|| {
        let mut driver = LockstepDriver::connect(
            &instance,
            "test",
            0,
            TruthAccess::SensesOnly,
            Duration::from_secs(30),
        )
        .expect("physics answers");
        let reset = *driver
            .reset(Pose2::new(0.0, 0.0, 0.0), Pose2::new(-0.12, 0.0, 0.0))
            .expect("reset");
        assert_eq!(reset.cause.trace_id, 0, "a reset's frame has no cause");
        for _ in 0..50 {
            let answered = *driver.frame();
            let next = *driver.step(0.05, 0.05).expect("a step");
            let c = &next.cause;
            assert_eq!(c.trace_id, answered.timing.trace_id, "the cause's trace");
            assert_eq!(
                c.stamps_ns[stage::FRAME_PUBLISHED],
                answered.timing.stamps_ns[stage::FRAME_PUBLISHED]
            );
            // Every stage the control step passed, in causal order, then this frame's own
            // publication.
            let chain = [
                c.stamps_ns[stage::FRAME_PUBLISHED],
                c.stamps_ns[stage::PLANNER_RECEIVED],
                c.stamps_ns[stage::COMMAND_PUBLISHED],
                c.stamps_ns[stage::COMMAND_RECEIVED],
                c.stamps_ns[stage::COMMAND_APPLIED],
                next.timing.stamps_ns[stage::FRAME_PUBLISHED],
            ];
            assert!(chain[0] > 0, "no stamp: {chain:?}");
            assert!(
                chain.windows(2).all(|w| w[0] <= w[1]),
                "stamps out of causal order: {chain:?}"
            );
            // The frame's own timing keeps meaning what it meant: the command's receive
            // and application.
            assert_eq!(
                next.timing.stamps_ns[stage::COMMAND_APPLIED],
                c.stamps_ns[stage::COMMAND_APPLIED]
            );
            assert_eq!(
                next.timing.stamps_ns[stage::COMMAND_RECEIVED],
                c.stamps_ns[stage::COMMAND_RECEIVED]
            );
        }
    });
    // SAFETY: kill(2) of our own child, not yet reaped.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let deadline = Instant::now() + Duration::from_secs(20);
    while child.try_wait().expect("wait").is_none() {
        assert!(Instant::now() < deadline, "physics ignored SIGTERM");
        std::thread::sleep(Duration::from_millis(10));
    }
    instance
        .remove_files()
        .expect("remove the instance's files");
    if let Err(panic) = checked {
        std::panic::resume_unwind(panic);
    }
}
