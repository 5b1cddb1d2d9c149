//! `agp up` with real child processes over real shared memory: how a run ends, how children
//! are stopped, restarted and cleaned up, and how a bad launch file is refused before
//! anything starts. Every test has an instance of its own and checks it leaves no file.

use std::time::{Duration, Instant};

use agp_runtime::Instance;
use agp_tests::{
    AgpUp, LaunchDir, assert_instance_clean as assert_clean, child_launch as launch,
    count_instance_files, pid_in, process_is_gone, run_agp, test_child as child,
};

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(30);

#[test]
fn up_ends_when_an_ends_run_child_exits_0_and_leaves_no_file() {
    let name = "t-up-ends-run";
    let dir = LaunchDir::new(&launch(
        name,
        &[
            child("server", r#""--until-signal""#, ""),
            child(
                "job",
                r#""--exit-after-ms", "300", "--status", "0""#,
                "ends_run = true",
            ),
        ]
        .concat(),
    ));
    let run = AgpUp::start(&dir.launch(), &[]).wait(TIMEOUT);
    run.assert_exit(0);
    run.assert_stdout_says(&[
        "job: exited with status 0",
        "server: stopped",
        "run over: `job` finished it",
    ]);
    assert_clean(name, &run);
}

#[test]
fn up_stops_every_child_on_sigint_exits_non_zero_and_leaves_no_file() {
    let name = "t-up-sigint";
    let dir = LaunchDir::new(&launch(
        name,
        &[
            child("first", r#""--until-signal""#, ""),
            child("second", r#""--until-signal""#, ""),
        ]
        .concat(),
    ));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines(": ready, pid", 2, TIMEOUT);
    assert!(
        count_instance_files(name) > 0,
        "the children hold shared memory"
    );
    up.signal(libc::SIGINT);
    let run = up.wait(TIMEOUT);
    run.assert_exit(130);
    run.assert_stdout_says(&[
        "first: stopped: exited with status 0",
        "second: stopped: exited with status 0",
    ]);
    assert_clean(name, &run);
}

#[test]
fn a_child_ignoring_sigterm_is_killed_after_the_grace_period() {
    let name = "t-up-sigkill";
    let dir = LaunchDir::new(&launch(
        name,
        &child("stubborn", r#""--ignore-sigterm""#, "stop_grace_ms = 500"),
    ));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines(": ready, pid", 1, TIMEOUT);
    let asked = Instant::now();
    up.signal(libc::SIGINT);
    let run = up.wait(TIMEOUT);
    assert!(
        asked.elapsed() >= Duration::from_millis(500),
        "SIGKILL must wait for the grace period"
    );
    assert_ne!(run.status.code(), Some(0));
    run.assert_stdout_says(&[
        "stubborn: still running 0.5 s after SIGTERM: SIGKILL",
        "stubborn: stopped: was killed by SIGKILL",
    ]);
    assert_clean(name, &run);
}

#[test]
fn an_on_failure_child_that_crashes_is_restarted_up_to_max_restarts_then_the_run_fails() {
    let name = "t-up-restart";
    let dir = LaunchDir::new(&launch(
        name,
        &[
            child("steady", r#""--until-signal""#, ""),
            child(
                "crasher",
                r#""--exit-after-ms", "20", "--status", "3""#,
                r#"restart = { policy = "on-failure", max_restarts = 4, backoff_ms = 20 }"#,
            ),
        ]
        .concat(),
    ));
    let run = AgpUp::start(&dir.launch(), &[]).wait(TIMEOUT);
    run.assert_exit(1);
    let count = |needle: &str| run.stdout_lines_with(needle);
    assert_eq!(count("crasher: started"), 1, "{}", run.stdout);
    assert_eq!(count("crasher: restarted ("), 4, "{}", run.stdout);
    assert_eq!(count("crasher: exited with status 3"), 5, "{}", run.stdout);
    // Five crashed publishers on a topic that takes four: only possible if each dead one
    // was cleaned before the next started.
    assert_eq!(count("crasher: ready"), 5, "{}", run.stdout);
    run.assert_stderr_says(&["process `crasher` exited with status 3 after 4 restart(s)"]);
    run.assert_stdout_says(&["steady: stopped"]);
    let starts = std::fs::read_to_string(dir.results().join("crasher.log")).expect("record");
    assert_eq!(starts.lines().count(), 5);
    assert_clean(name, &run);
}

#[test]
fn children_of_a_killed_supervisor_die_and_the_next_up_cleans_their_files() {
    let name = "t-up-killed-sup";
    let dir = LaunchDir::new(&launch(
        name,
        &[
            child("first", r#""--until-signal""#, ""),
            child("second", r#""--ignore-sigterm""#, ""),
        ]
        .concat(),
    ));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    let started = up.wait_for_lines(": started, pid", 2, TIMEOUT);
    up.wait_for_lines(": ready, pid", 2, TIMEOUT);
    let pids: Vec<u32> = started.iter().filter_map(|l| pid_in(l)).collect();
    assert_eq!(pids.len(), 2);
    up.signal(libc::SIGKILL);
    let killed = up.wait(TIMEOUT);
    assert_eq!(killed.status.code(), None, "killed by a signal");

    let deadline = Instant::now() + TIMEOUT;
    while !pids.iter().all(|&p| process_is_gone(p)) {
        assert!(
            Instant::now() < deadline,
            "children outlived their supervisor: {pids:?}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(count_instance_files(name) > 0, "a killed run leaves files");

    let dir2 = LaunchDir::new(&launch(
        name,
        &child(
            "job",
            r#""--exit-after-ms", "0", "--status", "0""#,
            "ends_run = true",
        ),
    ));
    let run = AgpUp::start(&dir2.launch(), &[]).wait(TIMEOUT);
    run.assert_exit(0);
    run.assert_stdout_says(&["leftover file(s) of instance"]);
    assert_clean(name, &run);
}

#[test]
fn every_child_gets_its_context_in_the_environment() {
    let name = "t-up-env";
    let text = format!(
        "instance = \"not-this-one\"\nscenario = \"circle\"\nresults = \"out\"\n\n[clock]\nmode = \"realtime\"\nrate_hz = 320\n\n{}",
        child(
            "job",
            r#""--exit-after-ms", "0", "--status", "0""#,
            "ends_run = true\nenv = { AGP_TEST_MARK = \"hello\" }",
        )
    );
    let dir = LaunchDir::new(&text);
    let run = AgpUp::start(&dir.launch(), &["--instance", name]).wait(TIMEOUT);
    run.assert_exit(0);
    let results = dir.path().join("out");
    let record = std::fs::read_to_string(results.join("job.log")).expect("the child's record");
    for expected in [
        format!("AGP_INSTANCE={name} "),
        "AGP_SCENARIO=circle ".to_owned(),
        "AGP_CLOCK=realtime ".to_owned(),
        "AGP_RATE_HZ=320 ".to_owned(),
        format!("AGP_RESULTS={} ", results.display()),
        "AGP_PROCESS=job ".to_owned(),
        "AGP_TEST_MARK=hello ".to_owned(),
        "args=--exit-after-ms,0,--status,0".to_owned(),
    ] {
        assert!(
            record.contains(&expected),
            "`{expected}` missing from {record}"
        );
    }
    assert_clean(name, &run);
    assert_eq!(count_instance_files("not-this-one"), 0);
}

#[test]
fn a_second_up_of_a_live_instance_is_refused() {
    let name = "t-up-second";
    let dir = LaunchDir::new(&launch(name, &child("server", r#""--until-signal""#, "")));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines(": ready, pid", 1, TIMEOUT);

    let dir2 = LaunchDir::new(&launch(name, &child("intruder", r#""--until-signal""#, "")));
    let second = run_agp(dir2.path(), &["up"], TIMEOUT);
    // Exit 2, as README, RELIABILITY and `agp up --help` say: nothing was started.
    second.assert_exit(2);
    second.assert_stderr_says(&[&format!(
        "instance `{name}` is already up under supervisor pid {}",
        up.pid()
    )]);
    assert!(!second.stdout.contains("started"), "{}", second.stdout);
    assert!(
        !dir2.results().exists(),
        "the refused run created its results folder"
    );

    up.signal(libc::SIGTERM);
    let run = up.wait(TIMEOUT);
    run.assert_exit(143);
    assert_clean(name, &run);
}

/// Runs `agp up` on a bad launch file and checks it is refused (exit 2), naming the file and
/// `line` (when the fault has one), saying `reason`, and starting nothing.
#[track_caller]
fn assert_refused(name: &str, text: &str, line: Option<usize>, reason: &str) {
    let dir = LaunchDir::new(text);
    let run = run_agp(dir.path(), &["up"], TIMEOUT);
    // Exit 2, a bad launch file (README, `agp up --help`), not a crash.
    run.assert_exit(2);
    let place = match line {
        Some(l) => format!("launch.toml:{l}: "),
        None => "launch.toml: ".to_owned(),
    };
    run.assert_stderr_says(&[&place, reason, "nothing was started"]);
    assert!(!run.stdout.contains("started"), "{}", run.stdout);
    assert!(
        !dir.results().exists(),
        "a refused run created its results folder"
    );
    if Instance::validate_name(name).is_ok() {
        assert_clean(name, &run);
    }
}

const OK_CHILD: &str = r#""--exit-after-ms", "0""#;

#[test]
fn a_launch_file_with_an_unknown_key_is_refused_before_anything_starts() {
    let name = "t-bad-key";
    let text = launch(name, &child("job", OK_CHILD, "restrat = 3"));
    assert_refused(name, &text, Some(11), "unknown field `restrat`");
}

#[test]
fn a_launch_file_with_a_missing_executable_is_refused_before_anything_starts() {
    let name = "t-bad-exec";
    let text = launch(name, &child("job", OK_CHILD, "")).replace("agp-test-child", "agp-nothing");
    assert_refused(name, &text, Some(9), "no executable `agp-nothing`");
}

#[test]
fn a_launch_file_with_an_unknown_policy_is_refused_before_anything_starts() {
    let name = "t-bad-policy";
    let text = launch(
        name,
        &child("job", OK_CHILD, r#"restart = { policy = "sometimes" }"#),
    );
    assert_refused(
        name,
        &text,
        Some(11),
        "unknown policy `sometimes`; expected `never`, `on-failure` or `always`",
    );
}

#[test]
fn a_launch_file_with_a_negative_rate_is_refused_before_anything_starts() {
    let name = "t-bad-rate";
    let text = launch(name, &child("job", OK_CHILD, ""))
        .replace("mode = \"lockstep\"", "mode = \"lockstep\"\nrate_hz = -640");
    assert_refused(name, &text, Some(6), "`rate_hz` must be a positive number");
}

#[test]
fn a_launch_file_with_an_unknown_clock_mode_is_refused_before_anything_starts() {
    let name = "t-bad-clock";
    let text = launch(name, &child("job", OK_CHILD, "")).replace("\"lockstep\"", "\"sometimes\"");
    assert_refused(name, &text, Some(5), "unknown clock mode `sometimes`");
}

#[test]
fn a_launch_file_with_a_bad_instance_name_is_refused_before_anything_starts() {
    let text = launch("Not Valid", &child("job", OK_CHILD, ""));
    assert_refused("Not Valid", &text, Some(1), "bad instance name `Not Valid`");
}

#[test]
fn a_launch_file_with_a_duplicate_process_name_is_refused_before_anything_starts() {
    let name = "t-bad-dup";
    let text = launch(
        name,
        &[child("job", OK_CHILD, ""), child("job", OK_CHILD, "")].concat(),
    );
    assert_refused(
        name,
        &text,
        Some(13),
        "duplicate process name `job` (first at line 8)",
    );
}

#[test]
fn a_launch_file_without_process_is_refused_before_anything_starts() {
    let name = "t-bad-noproc";
    assert_refused(name, &launch(name, ""), None, "no `[[process]]` entry");
}

#[test]
fn a_launch_file_with_an_unknown_scenario_is_refused_before_anything_starts() {
    let name = "t-bad-scenario";
    let text =
        launch(name, &child("job", OK_CHILD, "")).replace("\"triangle\"", "\"hexagon.toml\"");
    assert_refused(
        name,
        &text,
        Some(2),
        "scenario `hexagon.toml` is neither a built-in",
    );
}

#[test]
fn a_launch_file_that_is_not_toml_is_refused_before_anything_starts() {
    let name = "t-bad-syntax";
    let text = launch(name, &child("job", OK_CHILD, "ends_run = yes"));
    assert_refused(name, &text, Some(11), "");
}

#[test]
fn a_launch_file_with_a_bad_waiting_strategy_is_refused_before_anything_starts() {
    let name = "t-bad-wait";
    let text = launch(
        name,
        &child("job", OK_CHILD, "env = { AGP_WAIT = \"fast\" }"),
    );
    assert_refused(name, &text, Some(11), "not a waiting strategy");
}

#[test]
fn a_bad_waiting_strategy_in_the_environment_is_refused_before_anything_starts() {
    let name = "t-bad-wait-env";
    let dir = LaunchDir::new(&launch(name, &child("job", OK_CHILD, "")));
    let run = std::process::Command::new(agp_tests::bin_path("agp"))
        .arg("up")
        .current_dir(dir.path())
        .env("AGP_WAIT", "spin-then-block:soon")
        .output()
        .expect("run agp up");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("AGP_WAIT=`spin-then-block:soon` is not a waiting strategy"),
        "{stderr}"
    );
    assert!(stderr.contains("nothing was started"), "{stderr}");
    assert!(
        !dir.results().exists(),
        "a refused run created its results folder"
    );
    assert_eq!(count_instance_files(name), 0);
}

#[test]
fn a_realtime_launch_file_whose_planner_learns_is_refused_before_anything_starts() {
    let name = "t-bad-rt-learn";
    // The planner's line: the `name` of its `[[process]]` entry.
    let text = format!(
        "instance = \"{name}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"realtime\"\n\n[[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n[[process]]\nname = \"planner\"\nexec = \"agp-planner\"\nargs = [\"--mode\", \"place\", \"--learn-if-missing\"]\nends_run = true\n"
    );
    assert_refused(
        name,
        &text,
        Some(12),
        "process `planner`: `--learn-if-missing` may run the learning phase, which needs the lockstep clock",
    );
}
