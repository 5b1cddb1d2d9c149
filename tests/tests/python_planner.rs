//! The Python planner of `examples/python-planner/` (the stock `iceoryx2` package from PyPI,
//! no binding of ours) places the triangle: `agp up` runs the example's launch file, its
//! physics and estimator agp's, its planner `planner.py`, and the judge's verdict is read
//! from the results JSON. In lockstep, so the outcome does not depend on the machine's load.
//!
//! The interpreter is `AGP_PYTHON`, by default the virtual environment `.ci/run` creates at
//! the repository's root (`.venv-ci/bin/python`, with `iceoryx2==0.10.0`). Without it the
//! test fails and says how to make it.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use agp_runtime::Instance;
use agp_tests::{LaunchDir, assert_placed, count_instance_files, learned_ag, run_agp};

/// Safety net of the run; the checks never depend on it (about 5 s on an idle machine,
/// debug build).
const TIMEOUT: Duration = Duration::from_secs(300);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository")
        .to_path_buf()
}

/// The Python interpreter with `iceoryx2` installed: `AGP_PYTHON`, else `.venv-ci/bin/python`.
/// Panics in one line saying how to make it when it is missing or lacks the package.
#[track_caller]
fn python() -> PathBuf {
    let python = std::env::var_os("AGP_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv-ci/bin/python"));
    let ok = Command::new(&python)
        .args(["-c", "import iceoryx2"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "no Python with the `iceoryx2` package at {}: create it with `python3 -m venv .venv-ci && .venv-ci/bin/pip install iceoryx2==0.10.0` at the repository's root (as .ci/run does), or set AGP_PYTHON to such an interpreter",
        python.display()
    );
    python
}

/// The example's launch file as shipped, but for where things are: its planner run by
/// `python` (the shipped file runs `planner.py` by its shebang) and its results in the test's
/// own folder.
fn launch_text(python: &Path) -> String {
    let dir = repo().join("examples/python-planner");
    let shipped =
        std::fs::read_to_string(dir.join("launch.toml")).expect("the example's launch.toml");
    let mut planner_lines = 0;
    let mut results_lines = 0;
    let text: Vec<String> = shipped
        .lines()
        .map(|line| {
            if line.starts_with("exec = \"./planner.py\"") {
                planner_lines += 1;
                format!(
                    "exec = \"{}\"\nargs = [\"{}\"]",
                    python.display(),
                    dir.join("planner.py").display()
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
        "the example's launch.toml changed: one `exec = \"./planner.py\"` and one `results` line expected"
    );
    text.join("\n") + "\n"
}

#[test]
fn the_python_planner_on_stock_iceoryx2_places_the_triangle() {
    let name = "t-python-planner";
    let python = python();
    let dir = LaunchDir::new(&launch_text(&python));
    std::fs::create_dir_all(dir.results()).expect("the results folder");
    std::fs::copy(learned_ag("triangle"), dir.results().join("triangle.ag"))
        .expect("the triangle's AG file into the results folder");

    let start = Instant::now();
    let launch = dir.launch();
    let run = run_agp(
        dir.path(),
        &[
            "up",
            launch.to_str().expect("a UTF-8 path"),
            "--instance",
            name,
        ],
        TIMEOUT,
    );
    let wall = start.elapsed();
    run.assert_success("`agp up`");
    let done = run
        .stdout
        .lines()
        .find(|l| l.starts_with("planner.py: done after"))
        .unwrap_or_else(|| {
            panic!(
                "the Python planner did not say it was done:\n{}",
                run.stdout
            )
        });
    let (mm, deg) = assert_placed(&dir.results(), name, "triangle", &run.stdout);
    assert_eq!(
        count_instance_files(name),
        0,
        "files of `{name}` remain: {:?}",
        Instance::new(name).expect("a valid name").files()
    );
    println!("{done}\njudged: {mm:.1} mm, {deg:.1} deg; agp up took {wall:.1?}");
}
