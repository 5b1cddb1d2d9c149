//! `tools/setup.sh`, which the README's test command runs before building, installs what the
//! tests need once: by the time the tests run it has run, so running it again installs
//! nothing and says each part is up to date.

use std::path::Path;
use std::process::Command;

#[test]
fn a_second_run_of_the_setup_installs_nothing() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the repository");
    let out = Command::new("bash")
        .arg(repo.join("tools/setup.sh"))
        .output()
        .expect("bash runs tools/setup.sh");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "tools/setup.sh failed (the README's test command runs it first):\n{stdout}{stderr}"
    );
    assert!(
        !stdout.contains("installing"),
        "a second run installed something:\n{stdout}"
    );
    for part in [
        "Python packages up to date",
        "npm packages up to date",
        "chromium present",
    ] {
        assert!(stdout.contains(part), "`{part}` missing:\n{stdout}");
    }
}
