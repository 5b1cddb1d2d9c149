//! The Ray sweep of `tools/sweep/` (`ray_sweep.py`, the stock `ray` package from PyPI)
//! against one process: `tools/sweep/test_ray_sweep.sh` starts a local single-node Ray
//! cluster, runs `agp bench place` over the pipeline in 4 shards as Ray tasks, merges them
//! with `agp bench merge`, runs the same 8 seeds in one `agp` process, compares the two
//! JSONs field by field (wall times aside), stops the cluster and checks /dev/shm.
//!
//! Runs when the virtual environment `.ci/run` makes has Ray (`.venv-ci/bin/ray`, with
//! `ray==2.60.0`; or `AGP_RAY_VENV`); without it the test says so and passes.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use agp_tests::{bin_path, learned_ag};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository")
        .to_path_buf()
}

#[test]
fn a_sweep_of_four_shards_on_ray_merges_into_what_one_process_writes() {
    let venv = std::env::var_os("AGP_RAY_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv-ci"));
    // A test that cannot run fails, naming the set-up line; it never skips in silence.
    assert!(
        venv.join("bin/ray").is_file(),
        "no Ray at {}: run `tools/setup.sh` (the README's test command does)",
        venv.join("bin/ray").display(),
    );
    let ag = learned_ag("triangle");
    let out = Command::new("bash")
        .arg(repo().join("tools/sweep/test_ray_sweep.sh"))
        .env("AGP", bin_path("agp"))
        .env("AGP_RAY_VENV", &venv)
        .env("AGP_AG", &ag)
        .env("SEEDS", "8")
        .env("SHARDS", "4")
        .stdin(Stdio::null())
        .output()
        .expect("run tools/sweep/test_ray_sweep.sh");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("identical: every figure and every per-seed list"),
        "{stdout}"
    );
    assert!(
        stdout.contains("merged 4 parts of `place`: seeds 200-207"),
        "{stdout}"
    );
}
