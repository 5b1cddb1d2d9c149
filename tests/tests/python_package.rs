//! The `agp` Python package (python/) against Rust: its pytest suite, run with the venv's
//! interpreter as the README's test command sets it up (`tools/setup.sh`: `.venv-ci/` with
//! the pinned packages and this package installed from python/). The suite holds every
//! payload mirror to the Rust layout `agp-py-reference layout` prints, and the package's
//! affordance gradient to the Rust prediction on the same learned AG file within 1e-6.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use agp_tests::{bin_path, learned_ag};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository")
        .to_path_buf()
}

/// `.venv-ci/bin/python` (or `AGP_PYTHON`) with the `agp` package, numpy, pytest and
/// iceoryx2; panics in one line naming the set-up command when it is not there.
#[track_caller]
pub fn python_with_agp() -> PathBuf {
    let python = std::env::var_os("AGP_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv-ci/bin/python"));
    let ok = Command::new(&python)
        .args(["-c", "import agp, iceoryx2, numpy, pytest"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "no Python with the `agp` package (and iceoryx2, numpy, pytest) at {}: run `tools/setup.sh` at the repository's root (it makes .venv-ci and installs ./python), or set AGP_PYTHON to such an interpreter",
        python.display()
    );
    python
}

#[test]
fn the_python_package_passes_its_tests_against_the_rust_layouts_and_predictions() {
    let python = python_with_agp();
    let reference = bin_path("agp-py-reference");
    let ag = learned_ag("triangle");
    let out = Command::new(&python)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "python/tests",
        ])
        .current_dir(repo())
        .env("AGP_PY_REFERENCE", &reference)
        .env("AGP_TEST_AG", &ag)
        .stdin(Stdio::null())
        .output()
        .expect("run pytest");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "pytest python/tests failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    let summary = stdout.lines().last().unwrap_or_default();
    assert!(
        summary.contains("passed") && !summary.contains("failed"),
        "pytest's summary: {summary}"
    );
    println!("pytest python/tests: {summary}");
}
