//! `kill -9` of each child of a lockstep run of real physics and a real planner: the
//! supervisor sees the death from the exit status, restarts the child per its policy, and
//! the run still completes. A restarted planner starts its script again against the world
//! physics kept; a restarted physics is a new world, which the planner notices from the
//! frames and answers by resetting it and repeating the push under way.

use std::path::Path;
use std::time::{Duration, Instant};

use agp_tests::{AgpUp, LaunchDir, count_instance_files, run_agp};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(90);

fn launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"script\", \"--pushes\", \"24\", \"--push-ms\", \"2000\"]\n\
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
    let run = run_agp(dir, &["status", "--instance", name, "--json"], TIMEOUT);
    assert!(run.status.success(), "{}", run.stderr);
    serde_json::from_str(&run.stdout).expect("JSON")
}

fn process<'a>(status: &'a Value, name: &str) -> &'a Value {
    status["processes"]
        .as_array()
        .and_then(|a| a.iter().find(|p| p["name"] == name))
        .expect("the process is listed")
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
