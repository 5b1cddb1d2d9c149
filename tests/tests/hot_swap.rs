//! `agp swap planner` on a lockstep run of real physics and real planners: make before
//! break, proven by physics's step log (every step applied exactly once, epochs in order),
//! and a bad replacement never stops the robot. With the scripted planner, and during the
//! placement task, whose swapped-in planners find the object again and push it on to the
//! goal, judged by ground truth at the end.

use std::path::Path;
use std::time::{Duration, Instant};

use agp_tests::{
    AgpUp, DownOnPanic, LaunchDir, StepLog, assert_every_step_applied_once, assert_placed,
    bin_path, count_instance_files, learned_ag, process_is_gone, run_agp, status_entry,
    status_json,
};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Physics (logging every applied step) and the scripted planner, pushing for long enough
/// that the run is still going when the test is done with it.
fn launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-scripted-drive\"\n\
         args = [\"--pushes\", \"100000\", \"--push-ms\", \"200\"]\n\
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

/// Polls `agp status` (the outcome, not the time it takes) until `ok` holds for it.
#[track_caller]
fn status_until(dir: &Path, name: &str, ok: impl Fn(&Value) -> bool) -> Value {
    let deadline = std::time::Instant::now() + TIMEOUT;
    loop {
        let v = status_json(dir, name, TIMEOUT);
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

/// Checks the JSON of swap `k` (`swap_stdout`): epoch `k`, by a planner not seen before;
/// records its handover time (us) and pid.
#[track_caller]
fn record_swap(k: u64, swap_stdout: &str, handovers: &mut Vec<f64>, pids: &mut Vec<u32>) {
    let v: Value = serde_json::from_str(swap_stdout).expect("JSON");
    assert_eq!(v["epoch"], k, "{v}");
    handovers.push(v["handover_us"].as_f64().expect("handover"));
    let pid = u32::try_from(v["pid"].as_u64().expect("pid")).expect("pid");
    assert!(!pids.contains(&pid), "swap {k} did not start a new planner");
    pids.push(pid);
}

fn planner_pid(dir: &Path, name: &str) -> u32 {
    status_entry(&status_json(dir, name, TIMEOUT), "planner")["pid"]
        .as_u64()
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
    let _down = DownOnPanic::new(dir.path(), name);

    let mut handovers = Vec::new();
    let mut pids = vec![planner_pid(dir.path(), name)];
    // The first planner drives before the first swap: on a loaded machine it may still be
    // starting, and a swap then takes over before epoch 0 applied a step.
    let deadline = Instant::now() + TIMEOUT;
    while step_log(dir.path()).is_empty() {
        assert!(Instant::now() < deadline, "the first planner never drove");
        std::thread::sleep(Duration::from_millis(5));
    }
    for k in 1..=20u64 {
        // The swap's own deadline is a safety net too: the check is the step log.
        let run = swap(dir.path(), name, &["--timeout-s", "30"]);
        assert!(run.status.success(), "swap {k} failed: {}", run.stderr);
        record_swap(k, &run.stdout, &mut handovers, &mut pids);
    }
    // The status shows who drives, at which epoch, and the streams' rates (lockstep: one
    // command per frame).
    let status = status_until(dir.path(), name, |s| {
        status_entry(s, "planner")["rate_per_s"].as_f64() > Some(0.0)
            && status_entry(s, "physics")["rate_per_s"].as_f64() > Some(0.0)
    });
    assert_eq!(status["active_epoch"], 20, "{status}");
    assert_eq!(status_entry(&status, "planner")["epoch"], 20, "{status}");
    assert_eq!(
        status_entry(&status, "planner")["rate_topic"],
        "motor_commands"
    );
    assert_eq!(status_entry(&status, "physics")["rate_topic"], "ir_frames");
    println!(
        "status: physics {} IR frames/s, planner {} motor commands/s",
        status_entry(&status, "physics")["rate_per_s"],
        status_entry(&status, "planner")["rate_per_s"]
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
    let _down = DownOnPanic::new(dir.path(), name);
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
    let _down = DownOnPanic::new(dir.path(), name);
    let build = dir.path().join("my-planner");
    install(&bin_path("agp-scripted-drive"), &build);
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
    install(&bin_path("agp-scripted-drive"), &build);
    watch.wait_for_lines("\"epoch\":2,", 1, TIMEOUT);
    let driving = status_entry(&status_until(dir.path(), name, |_| true), "planner")["pid"].clone();

    // A broken build (here an executable that refuses the planner's arguments and exits):
    // refused, and the planner of epoch 2 drives on.
    install(&bin_path("agp-test-child"), &build);
    let refused = watch.wait_for_lines("refused", 1, TIMEOUT);
    assert!(refused[0].contains("before it drove"), "{}", refused[0]);
    let status = status_until(dir.path(), name, |_| true);
    assert_eq!(status["active_epoch"], 2, "{status}");
    assert_eq!(status_entry(&status, "planner")["pid"], driving, "{status}");

    // The fixed build goes in (epoch 3 went to the refused one).
    install(&bin_path("agp-scripted-drive"), &build);
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

/// Physics (logging every applied step), the estimator serving the learned AG file `ag` and
/// the affordance planner placing the triangle at [`FAR_GOAL`]; the run ends when the
/// planner's estimate says the object is there.
fn place_launch(instance: &str, ag: &Path) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--load\", \"{}\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"place\", \"--planner\", \"affordance\", \"--goal\", \"{FAR_GOAL}\"]\n\
         ends_run = true\n",
        ag.display()
    )
}

/// The placement's goal, `X_MM,Y_MM,THETA_DEG`: 3.58 m from the triangle's start, about
/// 85 pushes and 630,000 steps for one planner alone. Not the scenario's goal, 335 mm away
/// (9 pushes): a swapped-in planner given time to find the object and push moves it on by
/// a push or more, so with the scenario's goal the object is placed, and the run over,
/// after 6 to 10 swaps (measured), before the 20th. The old planner drives on while its
/// successor starts (50 to 500 ms here), on a loaded machine up to 130,000 steps: with a goal
/// 1.34 m away the object was placed after 16 to 19 swaps when the other tests of this file
/// ran beside, and 2.68 m left little margin.
const FAR_GOAL: &str = "3200,1600,90";

/// Physics steps each planner drives, from its first applied command to the request for
/// its successor: a turn to face the object (up to 3,000 steps), a circling to find its
/// pose (about 7,000), then the travel round the object and a push. It drives on while its
/// successor starts, a few thousand steps more.
const STEPS_PER_PLANNER: usize = 10_000;

/// Safety net of the placement run (about 800,000 steps; tens of seconds).
const PLACE_TIMEOUT: Duration = Duration::from_secs(300);

#[test]
fn twenty_swaps_during_a_placement_keep_every_step_and_the_object_still_reaches_the_goal() {
    let started = Instant::now();
    let ag = learned_ag("triangle");
    let name = "t-swap-place";
    let dir = LaunchDir::new(&place_launch(name, &ag));
    let files_before = count_instance_files(name);
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 3, TIMEOUT);
    let run_started = Instant::now();
    let mut log = StepLog::new(dir.path().join("steps.log"));

    let mut pids = Vec::new();
    let mut handovers = Vec::new();
    // The first step of the planner that drives.
    let mut from = 0;
    for k in 1..=20u64 {
        let ask_at = from + STEPS_PER_PLANNER;
        up.until(&format!("swap {k} at step {ask_at}"), PLACE_TIMEOUT, || {
            log.len() >= ask_at
        });
        let run = swap(dir.path(), name, &["--timeout-s", "30"]);
        if !run.status.success() {
            let end = up.wait(PLACE_TIMEOUT);
            panic!(
                "swap {k} failed: {}{}\nthe run ({}):\n{}\n{}",
                run.stdout, run.stderr, end.status, end.stdout, end.stderr
            );
        }
        record_swap(k, &run.stdout, &mut handovers, &mut pids);
        up.until(&format!("planner {k}'s first step"), TIMEOUT, || {
            log.poll().iter().any(|l| l.1 == k)
        });
        from = log.poll().iter().position(|l| l.1 == k).expect("its step");
    }
    let end = up.wait(PLACE_TIMEOUT);
    let wall = run_started.elapsed();
    assert_eq!(
        end.status.code(),
        Some(0),
        "the run failed:\n{}\n{}",
        end.stdout,
        end.stderr
    );
    assert!(
        end.stdout.contains("run over: `planner` finished it"),
        "{}",
        end.stdout
    );
    for pid in &pids {
        assert!(process_is_gone(*pid), "planner pid {pid} survived");
    }
    assert_eq!(
        count_instance_files(name),
        0,
        "files of `{name}` remain ({files_before} before the run)"
    );

    // The verdict, by ground truth, against the scenario's tolerance.
    let (mm, deg) = assert_placed(&dir.results(), name, "triangle", &end.stdout);

    // Every step once, the epochs in order, each of the 21 planners drove.
    let log = log.poll();
    assert_eq!(
        log.first().map(|l| l.0),
        Some(0),
        "the log starts at step 0"
    );
    assert_every_step_applied_once(log);
    let changes = log.windows(2).filter(|w| w[1].1 != w[0].1).count();
    assert!(
        changes >= 20,
        "only {changes} epoch changes in the step log"
    );
    let epochs: std::collections::BTreeSet<u64> = log.iter().map(|l| l.1).collect();
    assert_eq!(epochs, (0..=20).collect(), "every planner drove");

    let driven: Vec<usize> = (0..20u64)
        .map(|e| log.iter().filter(|l| l.1 == e).count())
        .collect();
    handovers.sort_by(f64::total_cmp);
    println!(
        "placement at ({FAR_GOAL}) with 20 swaps: {} steps, planners 0-19 drove {} to {} steps each \
         ({driven:?}), the last {}; final error {mm:.1} mm, {deg:.1} deg; run {:.1} s wall, test {:.1} s; \
         handover p50 {:.0} us, max {:.0} us",
        log.len(),
        driven.iter().min().expect("planners"),
        driven.iter().max().expect("planners"),
        log.len() - from,
        wall.as_secs_f64(),
        started.elapsed().as_secs_f64(),
        handovers[handovers.len() / 2],
        handovers[handovers.len() - 1]
    );
}
