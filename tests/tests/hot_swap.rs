//! `agp swap planner` on a lockstep run of real physics and real planners: make before
//! break, proven by physics's step log (every step applied exactly once, epochs in order),
//! and a bad replacement never stops the robot.

use std::path::Path;
use std::time::Duration;

use agp_tests::{AgpUp, LaunchDir, bin_path, count_instance_files, process_is_gone, run_agp};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Physics (logging every applied step) and the scripted planner, pushing for long enough
/// that the run is still going when the test is done with it.
fn launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"script\", \"--pushes\", \"100000\", \"--push-ms\", \"200\"]\n\
         ends_run = true\n"
    )
}

/// `(step, epoch)` of every applied command, in order (complete lines only: physics may
/// be writing the next one).
fn step_log(dir: &Path) -> Vec<(u64, u64)> {
    let text = std::fs::read_to_string(dir.join("steps.log")).unwrap_or_default();
    let complete = text.rfind('\n').map_or("", |end| &text[..end]);
    complete
        .lines()
        .map(|l| {
            let mut it = l
                .split_whitespace()
                .map(|v| v.parse::<u64>().expect("a number"));
            (it.next().expect("step"), it.next().expect("epoch"))
        })
        .collect()
}

/// Every step from the first to the last was applied exactly once, and the epochs never
/// went back.
#[track_caller]
fn assert_every_step_applied_once(log: &[(u64, u64)]) {
    assert!(log.len() > 100, "only {} steps were applied", log.len());
    for (k, w) in log.windows(2).enumerate() {
        assert_eq!(
            w[1].0,
            w[0].0 + 1,
            "line {}: step {} follows step {}: a step was lost or applied twice",
            k + 2,
            w[1].0,
            w[0].0
        );
        assert!(w[1].1 >= w[0].1, "line {}: the epoch went back", k + 2);
    }
}

/// Polls `agp status` (the outcome, not the time it takes) until `ok` holds for it.
#[track_caller]
fn status_until(dir: &Path, name: &str, ok: impl Fn(&Value) -> bool) -> Value {
    let deadline = std::time::Instant::now() + TIMEOUT;
    loop {
        let run = run_agp(dir, &["status", "--instance", name, "--json"], TIMEOUT);
        assert!(run.status.success(), "{}", run.stderr);
        let v: Value = serde_json::from_str(&run.stdout).expect("JSON");
        if ok(&v) {
            return v;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "status never as expected: {v}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The status entry of process `name`.
fn entry<'a>(status: &'a Value, name: &str) -> &'a Value {
    status["processes"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p["name"] == name))
        .unwrap_or(&Value::Null)
}

/// Puts a copy of `from` at `to` the way a build does: a new file renamed into place.
fn install(from: &Path, to: &Path) {
    let tmp = to.with_extension("tmp");
    std::fs::copy(from, &tmp).expect("copy the executable");
    std::fs::rename(&tmp, to).expect("rename it into place");
}

#[track_caller]
fn swap(dir: &Path, name: &str, extra: &[&str]) -> agp_tests::Finished {
    let mut args = vec!["swap", "planner", "--instance", name, "--json"];
    args.extend_from_slice(extra);
    run_agp(dir, &args, TIMEOUT)
}

fn planner_pid(dir: &Path, name: &str) -> u32 {
    let run = run_agp(dir, &["status", "--instance", name, "--json"], TIMEOUT);
    assert!(run.status.success(), "{}", run.stderr);
    let v: Value = serde_json::from_str(&run.stdout).expect("JSON");
    v["processes"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p["name"] == "planner"))
        .and_then(|p| p["pid"].as_u64())
        .and_then(|p| u32::try_from(p).ok())
        .expect("the planner runs")
}

#[test]
fn twenty_swaps_in_lockstep_lose_no_step_and_apply_none_twice() {
    let name = "t-swap-twenty";
    let dir = LaunchDir::new(&launch(name));
    // Physics runs in the launch folder (the supervisor's working folder): its step log
    // goes there.
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(up.status.success(), "{}{}", up.stdout, up.stderr);

    let mut handovers = Vec::new();
    let mut pids = vec![planner_pid(dir.path(), name)];
    for k in 1..=20u64 {
        // The swap's own deadline is a safety net too: the check is the step log.
        let run = swap(dir.path(), name, &["--timeout-s", "30"]);
        assert!(run.status.success(), "swap {k} failed: {}", run.stderr);
        let v: Value = serde_json::from_str(&run.stdout).expect("JSON");
        assert_eq!(v["epoch"], k, "{v}");
        handovers.push(v["handover_us"].as_f64().expect("handover"));
        let pid = u32::try_from(v["pid"].as_u64().expect("pid")).expect("pid");
        assert!(!pids.contains(&pid), "swap {k} did not start a new planner");
        pids.push(pid);
    }
    // The status shows who drives, at which epoch, and the streams' rates (lockstep: one
    // command per frame).
    let status = status_until(dir.path(), name, |s| {
        entry(s, "planner")["rate_per_s"].as_f64() > Some(0.0)
            && entry(s, "physics")["rate_per_s"].as_f64() > Some(0.0)
    });
    assert_eq!(status["active_epoch"], 20, "{status}");
    assert_eq!(entry(&status, "planner")["epoch"], 20, "{status}");
    assert_eq!(entry(&status, "planner")["rate_topic"], "motor_commands");
    assert_eq!(entry(&status, "physics")["rate_topic"], "ir_frames");
    println!(
        "status: physics {} IR frames/s, planner {} motor commands/s",
        entry(&status, "physics")["rate_per_s"],
        entry(&status, "planner")["rate_per_s"]
    );
    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    for pid in &pids {
        assert!(process_is_gone(*pid), "planner pid {pid} survived");
    }
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");

    let log = step_log(dir.path());
    assert_every_step_applied_once(&log);
    let epochs: std::collections::BTreeSet<u64> = log.iter().map(|l| l.1).collect();
    assert_eq!(
        epochs,
        (0..=20).collect(),
        "every planner, the first and the 20 swapped in, drove"
    );
    handovers.sort_by(f64::total_cmp);
    println!(
        "handover (ready -> first command applied) over 20 swaps: p50 {:.0} us, max {:.0} us",
        handovers[handovers.len() / 2],
        handovers[handovers.len() - 1]
    );
}

#[test]
fn a_replacement_that_dies_or_never_gets_ready_is_killed_and_the_old_planner_drives_on() {
    let name = "t-swap-bad";
    let dir = LaunchDir::new(&launch(name));
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(up.status.success(), "{}{}", up.stdout, up.stderr);
    let before = planner_pid(dir.path(), name);
    let child = bin_path("agp-test-child");
    let child = child.to_str().expect("a UTF-8 path");

    let dies = swap(
        dir.path(),
        name,
        &[
            "--exec",
            child,
            "--",
            "--exit-after-ms",
            "0",
            "--status",
            "3",
        ],
    );
    assert!(!dies.status.success());
    assert!(
        dies.stderr
            .contains("the new process exited with status 3 before it drove"),
        "{}",
        dies.stderr
    );
    let mute = swap(
        dir.path(),
        name,
        &["--timeout-s", "1", "--exec", child, "--", "--until-signal"],
    );
    assert!(!mute.status.success());
    assert!(
        mute.stderr
            .contains("the new process did not become ready within 1s"),
        "{}",
        mute.stderr
    );
    // The old planner still drives: the same pid, and the steps go on at epoch 0.
    assert_eq!(planner_pid(dir.path(), name), before);
    let log_dir = dir.path().to_path_buf();
    let steps_then = step_log(&log_dir).len();
    let deadline = std::time::Instant::now() + TIMEOUT;
    while step_log(&log_dir).len() < steps_then + 100 {
        assert!(
            std::time::Instant::now() < deadline,
            "physics stopped stepping"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert!(step_log(&log_dir).iter().all(|l| l.1 == 0));
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn watch_swaps_in_each_new_build_and_rolls_back_one_that_dies() {
    let name = "t-swap-watch";
    let dir = LaunchDir::new(&launch(name));
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(up.status.success(), "{}{}", up.stdout, up.stderr);
    let build = dir.path().join("my-planner");
    install(&bin_path("agp-planner"), &build);
    let build_arg = build.to_str().expect("a UTF-8 path");
    let mut watch = AgpUp::spawn(
        dir.path(),
        &[
            "swap",
            "planner",
            "--instance",
            name,
            "--watch",
            build_arg,
            "--json",
            "--timeout-s",
            "30",
        ],
    );
    // The build there now is swapped in at once, and the next one when it lands.
    watch.wait_for_lines("\"epoch\":1,", 1, TIMEOUT);
    install(&bin_path("agp-planner"), &build);
    watch.wait_for_lines("\"epoch\":2,", 1, TIMEOUT);
    let driving = entry(&status_until(dir.path(), name, |_| true), "planner")["pid"].clone();

    // A broken build (here an executable that refuses the planner's arguments and exits):
    // refused, and the planner of epoch 2 drives on.
    install(&bin_path("agp-test-child"), &build);
    let refused = watch.wait_for_lines("refused", 1, TIMEOUT);
    assert!(refused[0].contains("before it drove"), "{}", refused[0]);
    let status = status_until(dir.path(), name, |_| true);
    assert_eq!(status["active_epoch"], 2, "{status}");
    assert_eq!(entry(&status, "planner")["pid"], driving, "{status}");

    // The fixed build goes in (epoch 3 went to the refused one).
    install(&bin_path("agp-planner"), &build);
    watch.wait_for_lines("\"epoch\":4,", 1, TIMEOUT);
    watch.signal(libc::SIGINT);
    let end = watch.wait(TIMEOUT);
    assert!(end.status.success(), "{}\n{}", end.stdout, end.stderr);
    assert!(end.stderr.contains("3 swaps, 1 refused"), "{}", end.stderr);

    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
    let log = step_log(dir.path());
    assert_every_step_applied_once(&log);
    let epochs: std::collections::BTreeSet<u64> = log.iter().map(|l| l.1).collect();
    assert!(!epochs.contains(&3), "the refused build drove");
}
