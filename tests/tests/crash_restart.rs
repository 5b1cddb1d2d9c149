//! `kill -9` of each child of a lockstep run of real physics and a real planner: the
//! supervisor sees the death from the exit status, restarts the child per its policy, and
//! the run still completes. A restarted planner starts its script again against the world
//! physics kept; a restarted physics is a new world, which the planner notices from the
//! frames and answers by resetting it and repeating the push under way.
//!
//! The same during the placement task, with the estimator serving a learned AG file: a
//! restarted estimator publishes the gradients again, a restarted planner takes them and
//! finds the object where it is, a restarted physics puts the object back at its start and
//! the planner starts over; the run still ends with the object at the goal by ground truth.

use std::path::Path;
use std::time::{Duration, Instant};

use agp_tests::{
    AgpUp, LaunchDir, StepLog, assert_placed, count_instance_files, learned_ag, status_entry,
    status_json,
};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(90);

fn launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-scripted-drive\"\n\
         args = [\"--pushes\", \"24\", \"--push-ms\", \"2000\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\
         ends_run = true\n"
    )
}

/// The steps physics applied, in order (complete lines only).
fn steps(dir: &Path) -> Vec<u64> {
    let text = std::fs::read_to_string(dir.join("steps.log")).unwrap_or_default();
    let complete = text.rfind('\n').map_or("", |end| &text[..end]);
    complete
        .lines()
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect()
}

fn status(dir: &Path, name: &str) -> Value {
    status_json(dir, name, TIMEOUT)
}

#[track_caller]
fn process<'a>(status: &'a Value, name: &str) -> &'a Value {
    let entry = status_entry(status, name);
    assert!(!entry.is_null(), "process `{name}` is not listed: {status}");
    entry
}

/// Polls (the outcome, not the time it takes) until `ok`; returns when it held.
#[track_caller]
fn until(what: &str, mut ok: impl FnMut() -> bool) -> Instant {
    let deadline = Instant::now() + TIMEOUT;
    while !ok() {
        assert!(Instant::now() < deadline, "never: {what}");
        std::thread::sleep(Duration::from_millis(2));
    }
    Instant::now()
}

fn kill_9(pid: u64) {
    let pid = libc::pid_t::try_from(pid).expect("a pid");
    // SAFETY: plain kill(2) of a process the test's supervisor started.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
}

#[test]
fn each_child_killed_hard_is_restarted_and_the_run_completes() {
    let name = "t-crash-restart";
    let dir = LaunchDir::new(&launch(name));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 2, TIMEOUT);
    until("physics steps", || steps(dir.path()).len() > 300);

    // The planner: restarted, and the steps go on in the world physics kept.
    let s = status(dir.path(), name);
    let old = process(&s, "planner")["pid"].as_u64().expect("pid");
    let killed = Instant::now();
    kill_9(old);
    let running = until("the planner restarted", || {
        let s = status(dir.path(), name);
        let p = process(&s, "planner");
        p["restarts"] == 1 && p["state"] == "running" && p["pid"].as_u64() != Some(old)
    });
    // It prints its plan once it has physics's latest frame: from there it drives.
    up.wait_for_lines("scripted drive:", 2, TIMEOUT);
    let driving = Instant::now();
    let applied = steps(dir.path()).len();
    until("steps after the planner's restart", || {
        steps(dir.path()).len() > applied + 10
    });
    println!(
        "planner: restarted {:.1} ms after kill -9, connected and driving {:.1} ms after it",
        (running - killed).as_secs_f64() * 1e3,
        (driving - killed).as_secs_f64() * 1e3
    );
    // (Physics writes its step log through a buffer: the steps are complete up to the
    // last flush, which is all this needs.)
    let log = steps(dir.path());
    for w in log.windows(2) {
        assert_eq!(w[1], w[0] + 1, "a step was lost or applied twice");
    }

    // Physics: a new world, counting from step 0; the planner resets it and goes on.
    let s = status(dir.path(), name);
    let old = process(&s, "physics")["pid"].as_u64().expect("pid");
    let killed = Instant::now();
    kill_9(old);
    let running = until("physics restarted", || {
        let s = status(dir.path(), name);
        let p = process(&s, "physics");
        p["restarts"] == 1 && p["state"] == "running"
    });
    // The planner says so when the first frame of the new world reaches it.
    up.wait_for_lines("physics restarted: push", 1, TIMEOUT);
    let driving = Instant::now();
    println!(
        "physics: restarted {:.1} ms after kill -9, its new world reached the planner {:.1} ms after it",
        (running - killed).as_secs_f64() * 1e3,
        (driving - killed).as_secs_f64() * 1e3
    );

    let end = up.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert!(end.stdout.contains("scripted drive done"), "{}", end.stdout);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

/// Physics (logging every applied step), the estimator serving the learned AG file `ag`
/// and the affordance planner placing the triangle, each restarted if it fails.
fn place_launch(instance: &str, ag: &Path) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--load\", \"{}\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"place\", \"--planner\", \"affordance\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\
         ends_run = true\n",
        ag.display()
    )
}

/// Physics steps between one restart and the next kill: mid-run (a placement takes about
/// 90,000), the planner past its first circling (about 7,000) and pushing.
const STEPS_BETWEEN_KILLS: usize = 12_000;

/// Kills child `name` with SIGKILL and waits until `agp status` shows it restarted.
#[track_caller]
fn kill_and_see_restart(dir: &Path, instance: &str, name: &str) {
    let s = status(dir, instance);
    let old = process(&s, name);
    assert_eq!(old["state"], "running", "{s}");
    let old = old["pid"].as_u64().expect("pid");
    kill_9(old);
    until(&format!("{name} restarted"), || {
        let s = status(dir, instance);
        let p = process(&s, name);
        p["restarts"] == 1 && p["state"] == "running" && p["pid"].as_u64().is_some_and(|n| n != old)
    });
}

#[test]
fn each_child_killed_hard_during_a_placement_is_restarted_and_the_object_still_reaches_the_goal() {
    let started = Instant::now();
    let ag = learned_ag("triangle");
    let name = "t-crash-place";
    let dir = LaunchDir::new(&place_launch(name, &ag));
    let files_before = count_instance_files(name);
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 3, TIMEOUT);
    let run_started = Instant::now();
    up.wait_for_lines("affordance gradient of `triangle`", 1, TIMEOUT);
    let mut log = StepLog::new(dir.path().join("steps.log"));

    // The estimator, mid-run: restarted, it publishes the gradients of the file again.
    up.until("the estimator's kill", TIMEOUT, || {
        log.len() > STEPS_BETWEEN_KILLS
    });
    kill_and_see_restart(dir.path(), name, "estimator");
    up.wait_for_lines("agp-estimator: published the gradients", 2, TIMEOUT);
    let at = log.len();

    // The planner, after the estimator's restart: the restarted one takes the gradients
    // the new estimator published and drives on in the world physics kept.
    up.until("the planner's kill", TIMEOUT, || {
        log.len() > at + STEPS_BETWEEN_KILLS
    });
    kill_and_see_restart(dir.path(), name, "planner");
    up.wait_for_lines("affordance gradient of `triangle`", 2, TIMEOUT);
    up.wait_for_lines("planner `affordance`: place at", 2, TIMEOUT);
    let at = log.len();

    // Physics: a new world, the object back at its start; the planner starts over.
    up.until("physics's kill", TIMEOUT, || {
        log.len() > at + STEPS_BETWEEN_KILLS
    });
    kill_and_see_restart(dir.path(), name, "physics");
    up.wait_for_lines("physics restarted: the episode starts over", 1, TIMEOUT);

    let end = up.wait(TIMEOUT);
    let wall = run_started.elapsed();
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert!(
        end.stdout.contains("run over: `planner` finished it"),
        "{}",
        end.stdout
    );
    assert_eq!(
        count_instance_files(name),
        0,
        "files of `{name}` remain ({files_before} before the run)"
    );
    let (mm, deg) = assert_placed(&dir.results(), name, "triangle", &end.stdout);
    // The new world counts from step 0 and, stopped cleanly, logged every step it applied.
    // (The killed physics lost what its log buffer held, and may have left half a line that
    // the new one's first line completes: the new world starts where the steps went back,
    // at step 0, or 1 if its line 0 was joined to that half.)
    let log = log.poll();
    let new_world = (1..log.len())
        .rev()
        .find(|&i| log[i].0 < log[i - 1].0)
        .expect("the steps of a new world, counting from 0 again");
    let first = log[new_world].0;
    assert!(first <= 1, "the new world starts at step {first}");
    for (k, l) in log[new_world..].iter().enumerate() {
        assert_eq!(
            l.0,
            first + k as u64,
            "the new world's steps: a step was lost or applied twice"
        );
    }
    println!(
        "placement with each child killed once: {} steps logged, {} in the new world; final error {mm:.1} mm, {deg:.1} deg; run {:.1} s wall, test {:.1} s",
        log.len(),
        log.len() - new_world,
        wall.as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
}
