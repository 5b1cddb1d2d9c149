//! No two files of one crate import each other, directly or round a circle
//! (`tools/module_cycles.py` reads every crate's `src/`): a reader can take the files of a
//! crate in an order where each needs only those before it.

use std::path::Path;
use std::process::Command;

#[test]
fn no_file_of_a_crate_imports_another_that_imports_it_back() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository");
    let out = Command::new("python3")
        .arg(repo.join("tools/module_cycles.py"))
        .arg(repo)
        .output()
        .expect("python3 runs tools/module_cycles.py (install Python 3.11 or later)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "import circles between files of one crate:\n{stdout}{stderr}"
    );
    assert!(stdout.starts_with("no import circle:"), "{stdout}");
}
