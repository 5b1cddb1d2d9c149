//! The supervisor under faults (issue 14): a closed stdout, every catchable stop signal, a
//! task the judge says failed, a result it cannot write, a process that joins the instance
//! on its own, and `agp profile` stopped or killed while the pipeline is paused for its
//! floor. Every test has an instance of its own and checks it leaves no file.

use std::io::{BufRead, BufReader};
use std::os::unix::process::ExitStatusExt;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use agp_runtime::Instance;
use agp_shared_types::{GroundTruth, MAX_PATH_POINTS, Pose2, Task, TaskKind};
use agp_tests::{
    AgpUp, DownOnPanic, Finished, LaunchDir, bin_path, count_instance_files, run_agp, status_json,
};

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(60);

/// A launch file of instance `instance` running `processes` (TOML `[[process]]` entries).
fn launch(instance: &str, processes: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n{processes}"
    )
}

/// A `[[process]]` running `agp-test-child` until SIGTERM.
fn server(name: &str) -> String {
    format!(
        "[[process]]\nname = \"{name}\"\nexec = \"agp-test-child\"\nargs = [\"--until-signal\"]\n\n"
    )
}

#[track_caller]
fn assert_no_file(name: &str, run: &Finished) {
    assert_eq!(
        count_instance_files(name),
        0,
        "files of `{name}` remain: {:?}\nstdout:\n{}\nstderr:\n{}",
        Instance::new(name).expect("valid name").files(),
        run.stdout,
        run.stderr
    );
}

#[test]
fn a_closed_stdout_stops_agp_up_cleanly_instead_of_panicking_and_leaves_no_file() {
    let name = "t-fault-epipe";
    let dir = LaunchDir::new(&launch(name, &[server("first"), server("second")].concat()));
    let mut child = Command::new(bin_path("agp"))
        .args(["up", dir.launch().to_str().expect("UTF-8")])
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start agp up");
    // `agp up | head -1`: one line read, then the reader is gone.
    let mut out = BufReader::new(child.stdout.take().expect("piped stdout"));
    let mut first = String::new();
    out.read_line(&mut first).expect("the first line");
    drop(out);
    let run = finish(child);
    // The children share the closed stdout: what they do about it is theirs. The
    // supervisor's main thread (its thread id is its pid) must not panic.
    assert!(
        !run.stderr.contains(&format!("({}) panicked", run.pid)),
        "{}",
        run.stderr
    );
    assert_eq!(
        run.status.code(),
        Some(128 + libc::SIGPIPE),
        "a closed stdout stops the run as SIGPIPE would; stderr:\n{}",
        run.stderr
    );
    assert_no_file(name, &run);
}

/// Waits for `child` (an `agp` whose stdout is taken or closed) and collects its stderr.
fn finish(mut child: Child) -> Finished {
    let pid = child.id();
    let deadline = Instant::now() + TIMEOUT;
    let status = loop {
        if let Some(s) = child.try_wait().expect("watch agp") {
            break s;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("agp did not exit within {TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut stderr);
    }
    Finished {
        pid,
        status,
        stdout: String::new(),
        stderr,
    }
}

#[test]
fn sigquit_sigusr1_sigusr2_and_sigpipe_stop_agp_up_cleanly_and_leave_no_file() {
    for (signal, name) in [
        (libc::SIGQUIT, "t-fault-sigquit"),
        (libc::SIGUSR1, "t-fault-sigusr1"),
        (libc::SIGUSR2, "t-fault-sigusr2"),
        (libc::SIGPIPE, "t-fault-sigpipe"),
    ] {
        let dir = LaunchDir::new(&launch(name, &server("server")));
        let mut up = AgpUp::start(&dir.launch(), &[]);
        up.wait_for_lines(": ready, pid", 1, TIMEOUT);
        assert!(
            count_instance_files(name) > 0,
            "the child holds shared memory"
        );
        up.signal(signal);
        let run = up.wait(TIMEOUT);
        assert_eq!(
            run.status.code(),
            Some(128 + signal),
            "signal {signal}: stdout:\n{}\nstderr:\n{}",
            run.stdout,
            run.stderr
        );
        assert!(
            run.stdout.contains("server: stopped: exited with status 0"),
            "signal {signal}: {}",
            run.stdout
        );
        assert_no_file(name, &run);
    }
}

/// A placement task with `goal`, as the planner publishes it.
fn place_task(goal: Pose2) -> Task {
    Task {
        kind: TaskKind::Place as u32,
        path_len: 0,
        goal,
        tolerance_m: 0.01,
        tolerance_rad: 10f64.to_radians(),
        path: [[0.0; 2]; MAX_PATH_POINTS],
        max_pushes: 1,
        _pad: 0,
        seed: 7,
        heading_tolerance_rad: 0.0,
    }
}

/// Set in the environment of the stand-in planner of [`run_judged`].
const STAND_IN_ENV: &str = "AGP_FAULT_STAND_IN";

/// The stand-in planner of [`run_judged`]: this test binary, started by `agp up` with
/// [`STAND_IN_ENV`] set, runs only this test. It plays the planner and physics to the
/// judge: publishes a placement task whose goal is 300 mm from where the object lies, and
/// the object's ground truth, says so, and keeps them published until it is stopped. In a
/// normal test run it does nothing.
#[test]
fn stand_in_planner_publishes_a_task_and_ground_truth_only_under_agp_up() {
    if std::env::var_os(STAND_IN_ENV).is_none() {
        return;
    }
    let name = std::env::var("AGP_INSTANCE").expect("AGP_INSTANCE from agp up");
    let instance = Instance::new(&name).expect("valid name");
    let node = instance.node("test-planner", false).expect("a node");
    let task = instance.task(&node).expect("the task topic");
    let tasks = task.data.publisher_builder().create().expect("a publisher");
    tasks
        .send_copy(place_task(Pose2::new(0.3, 0.0, 0.0)))
        .expect("publish the task");
    let truth = instance
        .ground_truth(&node)
        .expect("the ground truth topic");
    let truths = truth
        .data
        .publisher_builder()
        .create()
        .expect("a publisher");
    for step in 0..3 {
        truths
            .send_copy(GroundTruth {
                step,
                sim_time_s: step as f64 * 0.01,
                ..GroundTruth::default()
            })
            .expect("publish ground truth");
    }
    println!("test-planner: published");
    // Until `agp up` stops it, after the judge has judged.
    loop {
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// Runs `agp up` with the stand-in planner above and a process that ends the run once the
/// file `go` of its folder exists, written once the task is published. `prepare` runs on
/// the folder first.
fn run_judged(name: &str, prepare: impl FnOnce(&LaunchDir)) -> Finished {
    let dir = LaunchDir::new("");
    let go = dir.path().join("go");
    let me = std::env::current_exe().expect("the test executable");
    let stand_in = format!(
        "[[process]]\nname = \"planner\"\nexec = \"{}\"\n\
         args = [\"--exact\", \"stand_in_planner_publishes_a_task_and_ground_truth_only_under_agp_up\", \"--nocapture\"]\n\
         env = {{ {STAND_IN_ENV} = \"1\" }}\n\n",
        me.display()
    );
    let waiter = format!(
        "[[process]]\nname = \"task\"\nexec = \"/bin/sh\"\nargs = [\"-c\", \"while [ ! -e {} ]; do sleep 0.02; done\"]\nends_run = true\n",
        go.display()
    );
    std::fs::write(dir.launch(), launch(name, &[stand_in, waiter].concat()))
        .expect("write launch.toml");
    prepare(&dir);
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("test-planner: published", 1, TIMEOUT);
    std::fs::write(&go, "").expect("write go");
    let run = up.wait(TIMEOUT);
    assert_no_file(name, &run);
    run
}

#[test]
fn agp_up_exits_3_not_0_when_the_judge_says_not_placed() {
    let name = "t-fault-not-placed";
    let run = run_judged(name, |_| {});
    assert!(
        run.stdout.contains("NOT placed"),
        "{}\n{}",
        run.stdout,
        run.stderr
    );
    assert_eq!(
        run.status.code(),
        Some(3),
        "stdout:\n{}\nstderr:\n{}",
        run.stdout,
        run.stderr
    );
}

#[test]
fn agp_up_exits_1_when_the_result_cannot_be_written() {
    let name = "t-fault-unwritable";
    // A folder where the verdict's JSON should go: no write can replace it (not even
    // root's, as a read-only folder could).
    let run = run_judged(name, |dir| {
        std::fs::create_dir_all(dir.results().join(format!("{name}-place.json")))
            .expect("a folder in the way");
    });
    assert!(
        run.stderr.contains("cannot write the result"),
        "{}",
        run.stderr
    );
    assert_eq!(
        run.status.code(),
        Some(1),
        "stdout:\n{}\nstderr:\n{}",
        run.stdout,
        run.stderr
    );
}

#[test]
fn agp_status_names_a_process_that_joined_the_instance_on_its_own() {
    let name = "t-fault-stranger";
    let dir = LaunchDir::new(&launch(name, &[server("first"), server("second")].concat()));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines(": ready, pid", 2, TIMEOUT);
    let instance = Instance::new(name).expect("valid name");
    let me = std::process::id();
    let status = {
        let _intruder = instance.node("intruder", false).expect("a node");
        status_json(dir.path(), name, TIMEOUT)
    };
    let strangers = status["strangers"].as_array().expect("a `strangers` list");
    assert_eq!(
        strangers.len(),
        1,
        "only the intruder: not the supervisor, its children or `agp status`: {status:#}"
    );
    assert_eq!(strangers[0]["node"], "intruder", "{status:#}");
    assert_eq!(strangers[0]["pid"], me, "{status:#}");
    let text = run_agp(dir.path(), &["status", "--instance", name], TIMEOUT);
    assert!(
        !text.stdout.contains("stranger:"),
        "the intruder left: {}",
        text.stdout
    );
    up.signal(libc::SIGTERM);
    let run = up.wait(TIMEOUT);
    assert_eq!(run.status.code(), Some(143), "{}", run.stderr);
    assert_no_file(name, &run);
}

/// Physics and the scripted planner in lockstep, pushing for longer than the test runs.
fn pipeline(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-scripted-drive\"\n\
         args = [\"--pushes\", \"100000\", \"--push-ms\", \"200\"]\n\
         ends_run = true\n"
    )
}

/// The state letter of process `pid` in /proc (`T`: stopped).
fn process_state(pid: u64) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    stat.rsplit_once(')')?
        .1
        .split_whitespace()
        .next()?
        .chars()
        .next()
}

/// Waits (at most `TIMEOUT`, a safety net) until `ok` holds; panics naming `what`.
#[track_caller]
fn until(what: &str, mut ok: impl FnMut() -> bool) {
    let deadline = Instant::now() + TIMEOUT;
    while !ok() {
        assert!(Instant::now() < deadline, "{what} did not come");
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn agp_profile_stopped_then_killed_during_the_floor_leaves_the_pipeline_running_and_no_floor_file()
{
    let name = "t-fault-profile";
    let dir = LaunchDir::new(&pipeline(name));
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(up.status.success(), "{}{}", up.stdout, up.stderr);
    let _down = DownOnPanic::new(dir.path(), name);
    let status = status_json(dir.path(), name, TIMEOUT);
    let pids: Vec<u64> = status["processes"]
        .as_array()
        .expect("processes")
        .iter()
        .map(|p| p["pid"].as_u64().expect("running"))
        .collect();
    let stopped = || pids.iter().all(|p| process_state(*p) == Some('T'));
    let running = || {
        pids.iter()
            .all(|p| process_state(*p).is_some_and(|s| s != 'T'))
    };

    let mut profile = Command::new(bin_path("agp"))
        .args(["profile", "--instance", name, "--seconds", "0.3"])
        .args(["--floor-seconds", "5"])
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start agp profile");
    let profiler = libc::pid_t::try_from(profile.id()).expect("pid fits");
    until("the pause of the pipeline for the floor", stopped);
    // The profiler stops renewing (stopped, it is still alive): its lease runs out at its
    // deadline (the floor's 5 s and a margin) and the supervisor resumes the pipeline.
    // SAFETY: kill(2) of our own child, not reaped yet.
    assert_eq!(unsafe { libc::kill(profiler, libc::SIGSTOP) }, 0);
    until(
        "the pipeline running again at the lease's deadline",
        running,
    );
    // SAFETY: as above.
    assert_eq!(unsafe { libc::kill(profiler, libc::SIGKILL) }, 0);
    let _ = profile.wait();
    let floor = format!("pfloor-{profiler}");
    let status = status_json(dir.path(), name, TIMEOUT);
    assert_eq!(status["paused"], 0, "{status:#}");

    // The next profile removes the dead profiler's floor files, and runs to its end.
    let next = run_agp(
        dir.path(),
        &[
            "profile",
            "--instance",
            name,
            "--seconds",
            "0.3",
            "--floor-seconds",
            "0.2",
        ],
        TIMEOUT,
    );
    assert!(next.status.success(), "{}{}", next.stdout, next.stderr);
    assert_eq!(
        count_instance_files(&floor),
        0,
        "the dead floor's files remain"
    );
    assert!(running(), "the pipeline runs after the second profile");

    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert_eq!(count_instance_files(name), 0);
}

/// Found by the fault campaign (`bench-faults`, seed 100): `agp status` polling a
/// supervisor that was then killed with -9 kept its node alive, waiting for an answer that
/// would never come, and the next `agp up` of the instance refused to start ("live
/// processes not started by a supervisor: node `agp-cli-…`"), leaving the dead one's files.
#[test]
fn up_after_a_supervisor_killed_with_9_is_not_refused_for_a_status_client_still_asking_it() {
    let name = "t-fault-client";
    let dir = LaunchDir::new(&launch(name, &server("server")));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines(": ready, pid", 1, TIMEOUT);
    // A supervisor that cannot answer, then dies while a client waits for its answer.
    up.signal(libc::SIGSTOP);
    let status = Command::new(bin_path("agp"))
        .args(["status", "--instance", name])
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start agp status");
    let deadline = Instant::now() + TIMEOUT;
    while !client_node_alive(name, status.id()) {
        assert!(Instant::now() < deadline, "agp status made no node");
        std::thread::sleep(Duration::from_millis(5));
    }
    up.signal(libc::SIGKILL);
    let dead = up.wait(TIMEOUT);
    assert_eq!(dead.status.signal(), Some(libc::SIGKILL));

    // The client gives up on the dead supervisor instead of waiting out its timeout (if
    // the kill came before its request was out, it finds no supervisor at all: on a loaded
    // machine either happens, and either is an answer)...
    let asked = finish(status);
    assert!(!asked.status.success(), "{}", asked.stderr);
    assert!(
        asked
            .stderr
            .contains("the supervisor died before it answered")
            || asked.stderr.contains("no supervisor answers on instance"),
        "{}",
        asked.stderr
    );
    // ...and a new `agp up` of the instance cleans what the dead one left and runs.
    let mut again = AgpUp::start(&dir.launch(), &[]);
    again.wait_for_lines(": ready, pid", 1, TIMEOUT);
    let stopped = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(stopped.status.success(), "{}", stopped.stderr);
    let run = again.wait(TIMEOUT);
    assert!(run.status.success(), "{}\n{}", run.stdout, run.stderr);
    assert!(
        !run.stderr.contains("not started by a supervisor"),
        "{}",
        run.stderr
    );
    assert_no_file(name, &run);
}

/// Whether process `pid` has a live iceoryx2 node in instance `name`.
fn client_node_alive(name: &str, pid: u32) -> bool {
    use agp_runtime::AgpIpc;
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::{CallbackProgression, Node, NodeState};
    let instance = Instance::new(name).expect("valid name");
    let mut found = false;
    let _ = Node::<AgpIpc>::list(instance.config(), |state| {
        if let NodeState::Alive(view) = state
            && view
                .details()
                .as_ref()
                .is_some_and(|d| i64::from(d.process_id().value()) == i64::from(pid))
        {
            found = true;
        }
        CallbackProgression::Continue
    });
    found
}
