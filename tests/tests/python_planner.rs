//! The Python planners of `examples/python-planner/`, on the `agp` Python package (python/)
//! over the stock `iceoryx2` package: `agp up` runs physics and the estimator of agp and a
//! planner script, and the judge's verdicts are read from the results JSON or `agp status`.
//! In lockstep, so the outcome does not depend on the machine's load.
//!
//! - the push-level planner (`push_planner.py`: Algorithm 5's push choice on the gradient,
//!   in Python; agp's skills travel, push and circle) places the triangle from the
//!   shipped launch.toml;
//! - in a live session it pursues a goal with the Rust planner swapped for it and back
//!   mid-goal: every physics step applied once, the goal reached;
//! - the wheel-level planner (`wheel_planner.py`) serves two goals one after another, each
//!   end reported and judged, with a swap mid-goal: every physics step applied once.
//!
//! The interpreter is `AGP_PYTHON`, by default `.venv-ci/bin/python` as `tools/setup.sh`
//! makes it (with the `agp` package installed from python/). Without it the tests fail and
//! name the set-up command.

use std::path::{Path, PathBuf};
use std::time::Duration;

use agp_runtime::Instance;
use agp_tests::{
    AgpUp, DownOnPanic, LaunchDir, StepLog, assert_every_step_applied_once, assert_placed,
    count_instance_files, learned_ag, run_agp, status_json,
};
use serde_json::Value;

/// Safety net of each run; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(300);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository")
        .to_path_buf()
}

fn example(file: &str) -> PathBuf {
    repo().join("examples/python-planner").join(file)
}

/// An executable in `dir` that runs `python` with its arguments: `agp swap` resolves the
/// executable it is given (a venv's `bin/python` is a symlink to the base interpreter,
/// which lacks the venv's packages), a script does not move.
fn python_wrapper(dir: &Path, python: &Path) -> String {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join("python-venv");
    std::fs::write(
        &path,
        format!("#!/bin/sh\nexec \"{}\" \"$@\"\n", python.display()),
    )
    .expect("write the wrapper");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))
        .expect("make the wrapper executable");
    path.display().to_string()
}

/// The example's launch.toml as shipped, but for where things are: its planner run by
/// `python` (the shipped file runs `./push_planner.py` by its shebang) and its results in
/// the test's own folder.
fn shipped_launch(python: &Path) -> String {
    let shipped = std::fs::read_to_string(example("launch.toml")).expect("the example's launch");
    let (mut planner_lines, mut results_lines) = (0, 0);
    let text: Vec<String> = shipped
        .lines()
        .map(|line| {
            if line.starts_with("exec = \"./push_planner.py\"") {
                planner_lines += 1;
                format!(
                    "exec = \"{}\"\nargs = [\"{}\"]",
                    python.display(),
                    example("push_planner.py").display()
                )
            } else if line.starts_with("results = ") {
                results_lines += 1;
                "results = \"results\"".to_owned()
            } else {
                line.to_owned()
            }
        })
        .collect();
    assert_eq!(
        (planner_lines, results_lines),
        (1, 1),
        "the example's launch.toml changed: one `exec = \"./push_planner.py\"` and one `results` line expected"
    );
    text.join("\n") + "\n"
}

/// A live session in lockstep: physics logging every applied step, the estimator serving
/// `ag`, the planner `planner_exec` with `planner_args`.
fn live_launch(instance: &str, ag: &Path, planner_exec: &str, planner_args: &[String]) -> String {
    let args: Vec<String> = planner_args.iter().map(|a| format!("\"{a}\"")).collect();
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--load\", \"{}\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"{planner_exec}\"\nargs = [{}]\n",
        ag.display(),
        args.join(", ")
    )
}

fn goals(status: &Value) -> Vec<Value> {
    status["goals"].as_array().cloned().unwrap_or_default()
}

/// Polls `agp status` until `n` goals are done; returns them.
#[track_caller]
fn wait_goals_done(dir: &Path, name: &str, n: usize) -> Vec<Value> {
    let deadline = std::time::Instant::now() + TIMEOUT;
    loop {
        let g = goals(&status_json(dir, name, TIMEOUT));
        if g.iter().filter(|g| g["state"] == "done").count() >= n {
            return g;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "fewer than {n} goals done: {g:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// `agp swap planner` with a new executable and arguments; panics unless it succeeded.
#[track_caller]
fn swap(dir: &Path, name: &str, exec: &str, args: &[String]) {
    let mut words = vec![
        "swap".to_owned(),
        "planner".into(),
        "--instance".into(),
        name.into(),
        "--exec".into(),
        exec.into(),
        "--".into(),
    ];
    words.extend_from_slice(args);
    let w: Vec<&str> = words.iter().map(String::as_str).collect();
    let run = run_agp(dir, &w, TIMEOUT);
    run.assert_success("`agp swap planner`");
}

/// The `agp` package's interpreter and an executable wrapper of it (`python_wrapper`),
/// in a folder of its own kept as long as this.
struct Python {
    wrapper: String,
    _dir: tempfile::TempDir,
}

impl Python {
    /// Fails naming the set-up command when there is no interpreter with the package.
    fn new() -> Self {
        let python = agp_tests::python_with(&["agp", "iceoryx2", "numpy"]);
        let dir = tempfile::tempdir().expect("a folder");
        let wrapper = python_wrapper(dir.path(), &python);
        Self { wrapper, _dir: dir }
    }
}

/// A session under `agp up` of a launch file in a folder of its own, past its start-up
/// (three processes started), brought down if the test panics; physics's step log
/// `steps.log` read as it grows.
struct Live {
    up: AgpUp,
    _guard: DownOnPanic,
    dir: LaunchDir,
    log: StepLog,
    name: &'static str,
}

impl Live {
    fn start(name: &'static str, launch: &str) -> Self {
        let dir = LaunchDir::new(launch);
        let guard = DownOnPanic::new(dir.path(), name);
        let mut up = AgpUp::start(&dir.launch(), &[]);
        up.wait_for_lines("started", 3, TIMEOUT);
        let log = StepLog::new(dir.path().join("steps.log"));
        Self {
            up,
            _guard: guard,
            dir,
            log,
            name,
        }
    }

    /// `agp goal --place X Y THETA` (mm, mm, deg); panics unless it was queued.
    #[track_caller]
    fn goal(&self, place: [&str; 3]) {
        let mut words = vec!["goal", "--instance", self.name, "--place"];
        words.extend_from_slice(&place);
        run_agp(self.dir.path(), &words, TIMEOUT).assert_success("`agp goal`");
    }

    /// `agp swap planner` to `exec` with `args`; panics unless it succeeded.
    #[track_caller]
    fn swap(&self, exec: &str, args: &[String]) {
        swap(self.dir.path(), self.name, exec, args);
    }

    /// Polls `agp status` until `n` goals are done; returns them.
    #[track_caller]
    fn goals_done(&self, n: usize) -> Vec<Value> {
        wait_goals_done(self.dir.path(), self.name, n)
    }

    /// `agp status`'s pid of process `process`.
    #[track_caller]
    fn pid_of(&self, process: &str) -> u32 {
        agp_tests::status_entry(&status_json(self.dir.path(), self.name, TIMEOUT), process)["pid"]
            .as_u64()
            .and_then(|p| u32::try_from(p).ok())
            .unwrap_or_else(|| panic!("{process} runs"))
    }

    /// `agp down`; panics unless the supervisor exits 0 leaving no file of the instance.
    /// Returns the step log as read to the end.
    #[track_caller]
    fn down(self) -> Vec<(u64, u64)> {
        let Self {
            up,
            _guard,
            dir,
            mut log,
            name,
        } = self;
        run_agp(dir.path(), &["down", "--instance", name], TIMEOUT).assert_success("`agp down`");
        let end = up.wait(TIMEOUT);
        assert!(end.status.success(), "{}\n{}", end.stdout, end.stderr);
        assert_eq!(
            count_instance_files(name),
            0,
            "files of `{name}` remain: {:?}",
            Instance::new(name).expect("a valid name").files()
        );
        log.poll().to_vec()
    }
}

#[test]
fn the_push_level_python_planner_places_the_triangle_from_the_shipped_launch_file() {
    let name = "t-py-push-place";
    let python = agp_tests::python_with(&["agp", "iceoryx2", "numpy"]);
    let dir = LaunchDir::new(&shipped_launch(&python));
    std::fs::create_dir_all(dir.results()).expect("the results folder");
    std::fs::copy(learned_ag("triangle"), dir.results().join("triangle.ag"))
        .expect("the triangle's AG file into the results folder");
    let launch = dir.launch();
    let launch = launch.to_str().expect("a UTF-8 path");
    let run = run_agp(dir.path(), &["up", launch, "--instance", name], TIMEOUT);
    run.assert_success("`agp up`");
    assert!(
        run.stdout.contains("push_planner.py: gradient with alphas"),
        "{}",
        run.stdout
    );
    let (mm, deg) = assert_placed(&dir.results(), name, "triangle", &run.stdout);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
    let done = run
        .stdout
        .lines()
        .find(|l| l.contains("done after"))
        .unwrap_or_default();
    println!("{done}\njudged: {mm:.1} mm, {deg:.1} deg");
}

#[test]
fn a_live_goal_is_reached_with_the_rust_planner_swapped_for_the_python_one_and_back_mid_goal() {
    let name = "t-py-push-swap";
    let python = Python::new();
    let ag = learned_ag("triangle");
    let rust_args: Vec<String> = ["--mode", "serve", "--planner", "affordance"]
        .map(String::from)
        .to_vec();
    let py_args = vec![
        example("push_planner.py").display().to_string(),
        "--serve".to_owned(),
    ];
    let mut live = Live::start(name, &live_launch(name, &ag, "agp-planner", &rust_args));
    live.goal(["300", "150", "90"]);
    // Mid-goal: the Rust planner has found the object and pushed (a circling is about
    // 7,000 steps); the Python one takes over, and after a push or two the Rust one again.
    let Live { up, log, .. } = &mut live;
    up.until("the Rust planner's first 12,000 steps", TIMEOUT, || {
        log.len() >= 12_000
    });
    live.swap(&python.wrapper, &py_args);
    let Live { up, log, .. } = &mut live;
    up.until("the Python planner's 15,000 steps", TIMEOUT, || {
        log.poll().iter().filter(|l| l.1 == 1).count() >= 15_000
    });
    let rust = agp_tests::bin_path("agp-planner");
    live.swap(&rust.display().to_string(), &rust_args);
    let done = live.goals_done(1);
    let g = &done[0];
    let log = &live.down();
    assert_every_step_applied_once(log);
    let epochs: std::collections::BTreeSet<u64> = log.iter().map(|l| l.1).collect();
    assert_eq!(
        epochs,
        [0, 1, 2].into_iter().collect(),
        "Rust, Python and Rust again drove"
    );
    assert_eq!(g["success"], true, "the goal was not reached: {g}");
    println!(
        "goal 1 ({}): {} steps, Python drove {}; final error {} mm, {} deg",
        g["end"],
        log.len(),
        log.iter().filter(|l| l.1 == 1).count(),
        g["position_error_mm"],
        g["orientation_error_deg"]
    );
}

#[test]
fn the_wheel_level_python_planner_serves_two_goals_and_hands_over_mid_goal_without_losing_a_step() {
    let name = "t-py-wheels-serve";
    let python = Python::new();
    let args = vec![
        example("wheel_planner.py").display().to_string(),
        "--serve".to_owned(),
    ];
    let launch = live_launch(name, &learned_ag("triangle"), &python.wrapper, &args);
    let mut live = Live::start(name, &launch);
    live.goal(["300", "150", "90"]);
    live.goal(["200", "0", "0"]);
    // Mid-goal 1 (the nudge takes about 1,800 steps): the same planner again, hot.
    let Live { up, log, .. } = &mut live;
    let before = log.len();
    up.until("goal 1 under way", TIMEOUT, || log.len() >= before + 600);
    live.swap(&python.wrapper, &args);
    let done = live.goals_done(2);
    let log = &live.down();
    assert_every_step_applied_once(log);
    assert!(
        log.iter().any(|l| l.1 == 1),
        "the swapped-in planner never drove"
    );
    for g in &done {
        assert_eq!(g["state"], "done", "{g}");
        assert_eq!(g["end"], "done", "the planner's word for its end: {g}");
    }
    println!(
        "{} steps, epochs 0 and 1; goals: {}",
        log.len(),
        done.iter()
            .map(|g| format!("{} {} ({} s)", g["id"], g["end"], g["sim_time_s"]))
            .collect::<Vec<_>>()
            .join(", ")
    );
}

#[test]
fn the_wheel_level_python_planner_carries_on_after_a_physics_restart() {
    let name = "t-py-wheels-restart";
    let python = Python::new();
    let args = [
        format!("\"{}\"", example("wheel_planner.py").display()),
        "\"--serve\"".to_owned(),
    ];
    let text = format!(
        "instance = \"{name}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--load\", \"{}\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"{}\"\nargs = [{}]\n",
        learned_ag("triangle").display(),
        python.wrapper,
        args.join(", ")
    );
    let mut live = Live::start(name, &text);
    live.goal(["300", "150", "90"]);
    live.goals_done(1);
    // Physics dies (SIGKILL); the supervisor starts it again, a new world from the
    // scenario's start. The planner goes on driving it: the next goal is served.
    let pid = i32::try_from(live.pid_of("physics")).expect("a pid");
    // SAFETY: kill(2) of a child of the supervisor this test started, by its pid.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
    live.up.wait_for_lines("physics: restarted", 1, TIMEOUT);
    live.goal(["200", "0", "0"]);
    let done = live.goals_done(2);
    live.down();
    assert_eq!(done[1]["end"], "done", "{:?}", done);
}

/// The children of process `pid` (`/proc/<pid>/task/<pid>/children`).
fn children(pid: u32) -> Vec<u32> {
    std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children"))
        .unwrap_or_default()
        .split_whitespace()
        .filter_map(|p| p.parse().ok())
        .collect()
}

#[test]
fn the_skills_executor_never_outlives_the_python_planner_that_started_it() {
    let name = "t-py-push-orphan";
    let python = Python::new();
    let args = vec![
        example("push_planner.py").display().to_string(),
        "--serve".to_owned(),
    ];
    let launch = live_launch(name, &learned_ag("triangle"), &python.wrapper, &args);
    let mut live = Live::start(name, &launch);
    live.up.wait_for_lines("serving the goals", 1, TIMEOUT);
    let planner = live.pid_of("planner");
    // The wrapper execs the interpreter: the planner's pid is Python's, its child the
    // executor `agp-planner --skills`.
    let executor = children(planner);
    assert_eq!(
        executor.len(),
        1,
        "the Python planner's children: {executor:?}"
    );
    let executor = executor[0];
    let pid = i32::try_from(planner).expect("a pid");
    // SAFETY: kill(2) of the planner the supervisor this test started runs, by its pid.
    let killed = unsafe { libc::kill(pid, libc::SIGKILL) };
    assert_eq!(killed, 0, "kill -9 the Python planner");
    // The executor ends on its parent's death (SIGTERM by PR_SET_PDEATHSIG), whether or
    // not the supervisor is still up.
    let deadline = std::time::Instant::now() + TIMEOUT;
    while !agp_tests::process_is_gone(executor) {
        assert!(
            std::time::Instant::now() < deadline,
            "the executor (pid {executor}) outlived the Python planner"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    // The supervisor may already be ending the run its planner left: down if it is not.
    let _ = run_agp(live.dir.path(), &["down", "--instance", name], TIMEOUT);
    let end = live.up.wait(TIMEOUT);
    assert!(
        agp_tests::process_is_gone(executor),
        "the executor outlived the run: {}",
        end.stdout
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}
