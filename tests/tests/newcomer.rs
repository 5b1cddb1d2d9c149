//! What a newcomer met on a fresh clone (issue 34), each held by a test against the real
//! `agp`: the bridge example run as the README gives it, a detached run whose planner fails
//! at start-up, and the exit status of an instance already up.
//!
//! Not here: the robot side of a bridge whose far planner failed before a task exits 1
//! (`up.rs`, `report_end`), held by `bridge_faults.rs`. A test of it here hung once in five
//! under load: a planner side that stopped before its bridge's sending half saw the far end's
//! hello sent no `bye`. A bridge now always says `bye`, and a far end gone for its far
//! timeout ends the other side.

use std::path::{Path, PathBuf};
use std::time::Duration;

use agp_tests::{AgpUp, DownOnPanic, LaunchDir, count_instance_files, learned_ag, run_agp};

/// Safety net of each run; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(240);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository")
        .to_path_buf()
}

/// A copy of the repository's layout that the bridge example needs, in a temporary folder:
/// `examples/bridge/*.toml` as shipped and `results/triangle.ag` where the first `agp up`
/// puts it.
fn bridge_example_tree() -> tempfile::TempDir {
    let tree = tempfile::tempdir().expect("a temporary folder");
    let bridge = tree.path().join("examples/bridge");
    std::fs::create_dir_all(&bridge).expect("mkdir examples/bridge");
    for side in ["robot.toml", "planner.toml"] {
        std::fs::copy(repo().join("examples/bridge").join(side), bridge.join(side))
            .expect("copy the example's launch file");
    }
    std::fs::create_dir_all(tree.path().join("results")).expect("mkdir results");
    std::fs::copy(
        learned_ag("triangle"),
        tree.path().join("results/triangle.ag"),
    )
    .expect("copy the learned AG");
    tree
}

/// `agp bridge keygen results/bridge-keys` from the root of `tree`, as the README gives it
/// before the two halves.
fn keygen(tree: &Path) {
    run_agp(
        tree,
        &["bridge", "keygen", "results/bridge-keys"],
        Duration::from_secs(60),
    )
    .assert_success("agp bridge keygen");
}

/// `agp up examples/bridge/<side>.toml` from the root of `tree`, as the README gives it.
fn up_side(tree: &Path, side: &str) -> AgpUp {
    AgpUp::spawn(tree, &["up", &format!("examples/bridge/{side}.toml")])
}

#[test]
fn the_bridge_example_places_the_triangle_as_the_readme_gives_it() {
    let tree = bridge_example_tree();
    keygen(tree.path());
    let robot = up_side(tree.path(), "robot");
    let planner = up_side(tree.path(), "planner");
    let end_planner = planner.wait(TIMEOUT);
    let end_robot = robot.wait(TIMEOUT);
    let all = format!(
        "robot:\n{}\n{}\nplanner:\n{}\n{}",
        end_robot.stdout, end_robot.stderr, end_planner.stdout, end_planner.stderr
    );
    assert_eq!(end_planner.status.code(), Some(0), "{all}");
    assert_eq!(end_robot.status.code(), Some(0), "{all}");
    assert!(
        end_robot.stdout.contains("`triangle` placed"),
        "the judge's verdict: {all}"
    );
    assert!(
        tree.path()
            .join("results/bridge_robot-place.json")
            .is_file(),
        "the verdict's JSON goes to the repository's results/: {all}"
    );
    assert!(
        !tree.path().join("examples/bridge/results").exists(),
        "nothing is written beside the example's launch files: {all}"
    );
    for name in ["bridge_robot", "bridge_planner"] {
        assert_eq!(count_instance_files(name), 0, "files of `{name}` remain");
    }
}

/// `launch-live.toml` as shipped but for its instance's name, in a folder with no AG file.
fn live_launch_without_ag(name: &str) -> LaunchDir {
    let shipped =
        std::fs::read_to_string(repo().join("launch-live.toml")).expect("read launch-live.toml");
    let text = shipped.replacen("instance = \"live\"", &format!("instance = \"{name}\""), 1);
    assert_ne!(text, shipped, "launch-live.toml names its instance `live`");
    LaunchDir::new(&text)
}

#[test]
fn a_detached_run_whose_planner_fails_at_start_up_exits_1_with_the_planners_error_line() {
    let name = format!("t-dfail-{}", std::process::id() % 100_000);
    let dir = live_launch_without_ag(&name);
    let _down = DownOnPanic::new(dir.path(), &name);
    let run = run_agp(dir.path(), &["up", "launch.toml", "--detach"], TIMEOUT);
    let all = format!("stdout:\n{}\nstderr:\n{}", run.stdout, run.stderr);
    assert_eq!(run.status.code(), Some(1), "{all}");
    assert!(
        run.stderr.contains("no AG file"),
        "the planner's own error line reaches the terminal: {all}"
    );
    assert!(
        run.stderr.contains("failed at start-up"),
        "it says the run did not start: {all}"
    );
    assert!(
        !run.stdout.contains("runs in the background"),
        "it never says the run is up: {all}"
    );
    // The run was stopped: its supervisor and files are gone.
    let status = run_agp(
        dir.path(),
        &["status", "--instance", &name],
        Duration::from_secs(30),
    );
    assert_ne!(status.status.code(), Some(0), "{}", status.stdout);
    assert_eq!(count_instance_files(&name), 0, "files of `{name}` remain");
}

#[test]
fn up_on_an_instance_already_up_exits_2_as_the_readme_and_help_say() {
    let name = format!("t-upup-{}", std::process::id() % 100_000);
    let ag = learned_ag("triangle");
    let text = agp_tests::triangle_ring_launch(&name, &ag, "", "\"--mode\", \"serve\"", false);
    let dir = LaunchDir::new(&text);
    let mut first = AgpUp::start(&dir.launch(), &[]);
    first.wait_for_lines("agp: instance", 1, TIMEOUT);
    // Its supervisor answers: the instance is up, not starting.
    first.until("its supervisor answers `agp status`", TIMEOUT, || {
        run_agp(
            dir.path(),
            &["status", "--instance", &name],
            Duration::from_secs(30),
        )
        .status
        .success()
    });
    let second = run_agp(dir.path(), &["up", "launch.toml"], TIMEOUT);
    let all = format!("stdout:\n{}\nstderr:\n{}", second.stdout, second.stderr);
    assert_eq!(second.status.code(), Some(2), "{all}");
    assert!(second.stderr.contains("is already up"), "{all}");
    assert!(second.stderr.contains("nothing was started"), "{all}");
    // The first run is untouched by the second: it still answers, and stops clean.
    let down = run_agp(
        dir.path(),
        &["down", "--instance", &name],
        Duration::from_secs(60),
    );
    down.assert_success("agp down");
    let end = first.wait(TIMEOUT);
    assert_eq!(end.status.code(), Some(0), "{}\n{}", end.stdout, end.stderr);
    assert_eq!(count_instance_files(&name), 0, "files of `{name}` remain");

    // README and --help say the same.
    let readme = std::fs::read_to_string(repo().join("README.md")).expect("README");
    let readme = readme.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        readme.contains("2 on a bad launch file or an instance already up"),
        "the README's exit statuses"
    );
    let help = run_agp(dir.path(), &["up", "--help"], Duration::from_secs(30));
    assert!(
        help.stdout.contains("or the instance is already up"),
        "{}",
        help.stdout
    );
}
