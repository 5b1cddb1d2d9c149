//! The pipeline's processes under faults and intruders (issue 14, items 8, 11 and 13):
//!
//! - a directory where the AG file should be stops the estimator at once, naming it, and a
//!   placement whose estimator waits to learn while its planner will not drive the learning
//!   fails at once, naming the missing AG file and how to learn it, instead of waiting;
//! - a planner killed with -9 during learning makes the estimator start over, so the AG file
//!   holds each trial of the protocol once; an estimator killed with -9 during learning is
//!   noticed by the planner from its first acknowledgement, and learning starts over at once;
//! - a process of the same user that joins the instance and sends motor commands and resets
//!   of the active epoch has none applied; physics names it, and the run completes.

use std::process::Command;
use std::time::Duration;

use agp_tests::{
    AgpUp, LaunchDir, bin_path, count_instance_files, status_entry, status_json,
    triangle_learning_launch,
};

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(120);

/// Trials per alpha of the learning runs: two, so a run is short and has six trials.
const TRIALS_PER_ALPHA: u32 = 2;

#[track_caller]
fn kill_9(pid: u64) {
    let pid = libc::pid_t::try_from(pid).expect("a pid");
    // SAFETY: plain kill(2) of a process the test's supervisor started.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGKILL) }, 0);
}

/// The pid of process `name` of instance `instance`, run from `dir`.
fn pid_of(dir: &std::path::Path, instance: &str, name: &str) -> u64 {
    let s = status_json(dir, instance, TIMEOUT);
    status_entry(&s, name)["pid"]
        .as_u64()
        .unwrap_or_else(|| panic!("no pid of `{name}`: {s}"))
}

/// `(learned, rejected, total)` of the estimator's last `learned` line.
#[track_caller]
fn learned_counts(stdout: &str) -> (u32, u32, u32) {
    let line = stdout
        .lines()
        .rfind(|l| l.contains("agp-estimator: learned `"))
        .unwrap_or_else(|| panic!("no `learned` line of the estimator:\n{stdout}"));
    let numbers: Vec<u32> = line
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|w| w.parse().ok())
        .collect();
    match numbers[..] {
        [learned, rejected, total, ..] => (learned, rejected, total),
        _ => panic!("cannot read the counts of `{line}`"),
    }
}

/// A learning launch of the triangle with `TRIALS_PER_ALPHA` trials per alpha, and `name`
/// (the planner or the estimator) restarted when it fails.
fn learning_launch(instance: &str, restarted: &str) -> String {
    let text = triangle_learning_launch(instance, TRIALS_PER_ALPHA, "");
    let needle = format!("name = \"{restarted}\"\n");
    text.replace(
        &needle,
        &format!(
            "{needle}restart = {{ policy = \"on-failure\", max_restarts = 2, backoff_ms = 10 }}\n"
        ),
    )
}

#[test]
fn a_directory_where_the_ag_file_should_be_stops_the_estimator_at_once_naming_it() {
    let name = "t-faults-agdir";
    let dir = tempfile::tempdir().expect("a temporary folder");
    let ag = dir.path().join("results").join("triangle.ag");
    std::fs::create_dir_all(&ag).expect("a directory in the AG file's place");
    let out = Command::new(bin_path("agp-estimator"))
        .args(["--instance", name, "--scenario", "triangle", "--reuse"])
        .arg("--results")
        .arg(dir.path().join("results"))
        .output()
        .expect("run agp-estimator");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "it exited 0: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    assert!(
        stderr.contains(&ag.display().to_string()) && stderr.contains("directory"),
        "{stderr}"
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn a_placement_with_no_ag_file_and_no_learn_if_missing_fails_naming_the_file() {
    let name = "t-faults-noag";
    let dir = LaunchDir::new(&format!(
        "instance = \"{name}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--reuse\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"place\", \"--planner\", \"affordance\"]\nends_run = true\n"
    ));
    let end = AgpUp::start(&dir.launch(), &[]).wait(TIMEOUT);
    assert!(!end.status.success(), "{}\n{}", end.stdout, end.stderr);
    let line = end
        .stderr
        .lines()
        .find(|l| l.contains("agp-planner: error:"))
        .unwrap_or_else(|| panic!("no planner error:\n{}", end.stderr));
    assert!(
        line.contains("results/triangle.ag")
            && line.contains("--learn-if-missing")
            && line.contains("agp bench learn"),
        "{line}"
    );
    // It said what it waited for before it gave up.
    assert!(end.stdout.contains("waiting up to"), "{}", end.stdout);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn killing_the_planner_during_learning_counts_no_trial_twice() {
    let name = "t-faults-kplanner";
    let dir = LaunchDir::new(&learning_launch(name, "planner"));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    // A trial's verdict is in: the estimator holds trials of this session.
    up.wait_for_lines("learning [", 1, TIMEOUT);
    kill_9(pid_of(dir.path(), name, "planner"));
    let end = up.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert!(
        end.stdout.contains("learning starts over"),
        "the estimator did not see the new session:\n{}",
        end.stdout
    );
    let (learned, rejected, total) = learned_counts(&end.stdout);
    assert_eq!(total, 3 * TRIALS_PER_ALPHA);
    assert_eq!(learned + rejected, total, "{}", end.stdout);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn killing_the_estimator_during_learning_starts_learning_over_without_a_timeout() {
    let name = "t-faults-kestim";
    // The planner is not restarted: a planner that waited out its 30 s timeout would fail
    // the run.
    let dir = LaunchDir::new(&learning_launch(name, "estimator"));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("learning [", 1, TIMEOUT);
    kill_9(pid_of(dir.path(), name, "estimator"));
    let end = up.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert!(
        end.stdout
            .contains("the estimator restarted: learning starts over"),
        "{}",
        end.stdout
    );
    assert!(
        !end.stderr.contains("did not acknowledge") && !end.stderr.contains("report from"),
        "the planner waited out a timeout:\n{}",
        end.stderr
    );
    let (learned, rejected, total) = learned_counts(&end.stdout);
    assert_eq!(total, 3 * TRIALS_PER_ALPHA);
    assert_eq!(learned + rejected, total, "{}", end.stdout);
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}

#[test]
fn a_stranger_process_cannot_drive_physics_and_the_run_completes() {
    let name = "t-faults-stranger";
    let dir = LaunchDir::new(&format!(
        "instance = \"{name}\"\nscenario = \"square\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-scripted-drive\"\n\
         args = [\"--pushes\", \"6\", \"--push-ms\", \"1500\"]\n\
         ends_run = true\n"
    ));
    let mut up = AgpUp::start(&dir.launch(), &[]);
    up.wait_for_lines("scripted drive:", 1, TIMEOUT);
    let stranger = Command::new(bin_path("agp-test-stranger"))
        .args(["--instance", name, "--commands", "300"])
        .env_remove("AGP_TOKEN")
        .env_remove("AGP_SESSION_KEY")
        .output()
        .expect("run the stranger");
    let said = String::from_utf8_lossy(&stranger.stdout);
    assert!(
        stranger.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&stranger.stderr)
    );
    let end = up.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert!(end.stdout.contains("scripted drive done"), "{}", end.stdout);
    // It did send, physics applied none of it, and named it.
    assert!(!said.contains("sent 0 commands"), "{said}");
    assert!(said.contains("; 0 applied"), "{said}");
    assert!(
        end.stderr
            .contains("refused a motor command from node `stranger`")
            || end.stderr.contains("refused a reset from node `stranger`"),
        "{}",
        end.stderr
    );
    assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
}
