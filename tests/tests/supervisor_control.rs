//! `agp status`, `agp down` and `agp up --detach`: the CLI talking to a running supervisor
//! through the instance's iceoryx2 control service. Every test has an instance of its own
//! and checks it leaves no file.

use std::time::Duration;

use agp_tests::{AgpUp, LaunchDir, count_instance_files, process_is_gone, run_agp};
use serde_json::Value;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(30);

fn launch(instance: &str) -> String {
    format!(
        "instance = \"{instance}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"alpha\"\nexec = \"agp-test-child\"\nargs = [\"--until-signal\"]\n\n\
         [[process]]\nname = \"beta\"\nexec = \"agp-test-child\"\nargs = [\"--until-signal\"]\n\
         restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n"
    )
}

#[track_caller]
fn status_json(dir: &std::path::Path, name: &str) -> Value {
    let run = run_agp(dir, &["status", "--instance", name, "--json"], TIMEOUT);
    assert!(run.status.success(), "agp status failed: {}", run.stderr);
    serde_json::from_str(&run.stdout).expect("agp status --json prints JSON")
}

/// The pid of process `name` in a status, if it runs.
fn pid_of(status: &Value, name: &str) -> Option<u32> {
    status["processes"]
        .as_array()?
        .iter()
        .find(|p| p["name"] == name)?["pid"]
        .as_u64()
        .and_then(|p| u32::try_from(p).ok())
}

#[test]
fn detach_returns_with_every_process_running_and_down_stops_them_and_cleans_up() {
    let name = "t-ctl-detach";
    let dir = LaunchDir::new(&launch(name));
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(
        up.status.success(),
        "agp up --detach failed: {}{}",
        up.stdout,
        up.stderr
    );

    // The launch file in the folder names the instance: no --instance needed.
    let run = run_agp(dir.path(), &["status", "--json"], TIMEOUT);
    assert!(run.status.success(), "agp status failed: {}", run.stderr);
    let status: Value = serde_json::from_str(&run.stdout).expect("JSON");
    assert_eq!(status["instance"], name);
    let supervisor = u32::try_from(status["supervisor_pid"].as_u64().expect("pid")).expect("pid");
    let mut children = Vec::new();
    for p in ["alpha", "beta"] {
        let entry = status["processes"]
            .as_array()
            .expect("processes")
            .iter()
            .find(|e| e["name"] == p)
            .unwrap_or_else(|| panic!("no `{p}` in {status}"));
        assert_eq!(entry["state"], "running", "{status}");
        let pid = pid_of(&status, p).expect("a running process has a pid");
        assert!(!process_is_gone(pid), "`{p}` (pid {pid}) is not alive");
        children.push(pid);
    }
    assert!(!process_is_gone(supervisor));

    let down = run_agp(dir.path(), &["down"], TIMEOUT);
    assert!(down.status.success(), "agp down failed: {}", down.stderr);
    assert!(down.stdout.contains("is down"), "{}", down.stdout);
    // `down` returns once the supervisor let go of the instance: all gone, nothing left.
    for pid in children {
        assert!(process_is_gone(pid), "child pid {pid} survived `agp down`");
    }
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
    let log = std::fs::read_to_string(dir.results().join(format!("agp-up-{name}.log")))
        .expect("the background supervisor's log");
    assert!(log.contains("stopped by `agp down`"), "{log}");
}

#[test]
fn down_ends_a_foreground_up_with_status_0() {
    let name = "t-ctl-down-fg";
    let dir = LaunchDir::new(&launch(name));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("started", 2, TIMEOUT);
    let down = run_agp(dir.path(), &["down", "--instance", name], TIMEOUT);
    assert!(down.status.success(), "agp down failed: {}", down.stderr);
    let end = up.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert!(
        end.stdout.contains("stopped by `agp down`"),
        "{}",
        end.stdout
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn a_child_killed_hard_shows_up_restarted_in_the_status() {
    let name = "t-ctl-restart";
    let dir = LaunchDir::new(&launch(name));
    let up = run_agp(dir.path(), &["up", "--detach"], TIMEOUT);
    assert!(up.status.success(), "{}{}", up.stdout, up.stderr);
    let before = status_json(dir.path(), name);
    let old = pid_of(&before, "beta").expect("beta runs");
    // SAFETY: plain kill(2) of a child of the test's supervisor.
    unsafe {
        libc::kill(old as libc::pid_t, libc::SIGKILL);
    }
    // Poll the status (the outcome, not the time it takes) until the restart shows.
    let deadline = std::time::Instant::now() + TIMEOUT;
    let after = loop {
        let s = status_json(dir.path(), name);
        let beta = s["processes"]
            .as_array()
            .and_then(|a| a.iter().find(|p| p["name"] == "beta").cloned())
            .expect("beta");
        if beta["restarts"] == 1 && beta["state"] == "running" {
            break s;
        }
        assert!(std::time::Instant::now() < deadline, "no restart seen: {s}");
        std::thread::sleep(Duration::from_millis(20));
    };
    let new = pid_of(&after, "beta").expect("beta runs again");
    assert_ne!(new, old);
    assert!(!process_is_gone(new));
    let down = run_agp(dir.path(), &["down"], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn status_and_down_of_an_instance_that_is_not_up_say_so_and_leave_nothing() {
    let name = "t-ctl-not-up";
    let dir = tempfile::tempdir().expect("temp dir");
    for cmd in ["status", "down"] {
        let run = run_agp(dir.path(), &[cmd, "--instance", name], TIMEOUT);
        assert!(!run.status.success(), "`agp {cmd}` of nothing succeeded");
        assert!(
            run.stderr.contains(&format!("instance `{name}` is not up")),
            "{}",
            run.stderr
        );
        assert_eq!(count_instance_files(name), 0);
    }
    // Without --instance and without a launch file there is nothing to address.
    let run = run_agp(dir.path(), &["status"], TIMEOUT);
    assert!(!run.status.success());
    assert!(run.stderr.contains("no --instance given"), "{}", run.stderr);
}

#[test]
fn two_instances_run_side_by_side_and_share_nothing() {
    let names = ["t-ctl-twin-a", "t-ctl-twin-b"];
    let dirs = names.map(|n| LaunchDir::new(&launch(n)));
    for d in &dirs {
        let up = run_agp(d.path(), &["up", "--detach"], TIMEOUT);
        assert!(up.status.success(), "{}{}", up.stdout, up.stderr);
    }
    let pids: Vec<Vec<u32>> = names
        .iter()
        .zip(&dirs)
        .map(|(n, d)| {
            let s = status_json(d.path(), n);
            assert_eq!(s["instance"], *n);
            ["alpha", "beta"]
                .iter()
                .map(|p| pid_of(&s, p).expect("running"))
                .collect()
        })
        .collect();
    assert!(
        pids[0].iter().all(|p| !pids[1].contains(p)),
        "the instances share a process: {pids:?}"
    );
    // Down one: the other runs on, untouched.
    let down = run_agp(dirs[0].path(), &["down"], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert_eq!(
        count_instance_files(names[0]),
        0,
        "files of `{}` remain",
        names[0]
    );
    assert!(
        count_instance_files(names[1]) > 0,
        "`{}` lost its files",
        names[1]
    );
    let s = status_json(dirs[1].path(), names[1]);
    for (p, pid) in ["alpha", "beta"].iter().zip(&pids[1]) {
        assert_eq!(pid_of(&s, p), Some(*pid), "{s}");
        assert!(!process_is_gone(*pid));
    }
    let down = run_agp(dirs[1].path(), &["down"], TIMEOUT);
    assert!(down.status.success(), "{}", down.stderr);
    assert_eq!(
        count_instance_files(names[1]),
        0,
        "files of `{}` remain",
        names[1]
    );
}
