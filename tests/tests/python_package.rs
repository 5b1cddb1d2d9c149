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

#[test]
fn the_python_package_passes_its_tests_against_the_rust_layouts_and_predictions() {
    let python = agp_tests::python_with(&["agp", "iceoryx2", "numpy", "pytest"]);
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
