//! The README's commands, run as a newcomer runs them (issue 34): `tools/readme_commands.py`
//! cuts every ```sh block of README.md and of the examples' READMEs into commands and runs
//! each in a fresh clone after the first `agp up` (its AG file put in place), against the
//! binaries of this build: the quick ones as written, the long ones (benchmarks, a 10 s
//! recording) with the smallest arguments that exercise them, the ones that serve until
//! Ctrl-C or need a second computer with their arguments checked (`--help` appended: clap
//! reads them all first). The script says which is which and why; a README command it has
//! no rule for fails the test. Then `git status` in the clone must be clean.

use std::path::Path;
use std::process::Command;

use agp_tests::{bin_path, learned_ag, python_with};

#[test]
fn every_readme_command_exits_as_the_readme_says_in_a_fresh_clone_and_leaves_it_clean() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository");
    let agp = bin_path("agp");
    let bin = agp.parent().expect("agp sits in target/<profile>");
    let python = python_with(&["mcap", "mcap_protobuf"]);
    let out = Command::new("python3")
        .arg(repo.join("tools/readme_commands.py"))
        .arg("--bin")
        .arg(bin)
        .arg("--ag")
        .arg(learned_ag("triangle"))
        .arg("--python")
        .arg(&python)
        .output()
        .expect("python3 runs tools/readme_commands.py (install Python 3.11 or later)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "README commands that did not exit as the README says:\n{stdout}{stderr}"
    );
    assert!(
        stdout.contains("every command exited as the README says; git status clean"),
        "{stdout}"
    );
}
