mod support;

use std::process::Command;

fn ag_plot() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ag-plot"))
}

#[test]
fn the_cli_plots_a_saved_gradient() {
    let dir = tempfile::tempdir().expect("a temp dir");
    let ag_path = dir.path().join("disc.ag");
    support::learned_disc(12)
        .save(&ag_path)
        .expect("the AG file is written");
    let out = dir.path().join("disc.svg");
    let run = ag_plot()
        .arg(&ag_path)
        .arg(&out)
        .output()
        .expect("ag-plot runs");
    assert!(
        run.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("3 alphas"), "stdout: {stdout}");
    let svg = std::fs::read_to_string(&out).expect("the SVG is written");
    assert!(svg.contains("<svg") && svg.contains("affordance gradient of `disc`"));
}

#[test]
fn the_cli_refuses_a_file_that_is_not_an_ag_file() {
    let dir = tempfile::tempdir().expect("a temp dir");
    let bad = dir.path().join("bad.ag");
    std::fs::write(&bad, b"definitely not a gradient").expect("a bad file");
    let out = dir.path().join("bad.svg");
    let run = ag_plot()
        .arg(&bad)
        .arg(&out)
        .output()
        .expect("ag-plot runs");
    assert!(!run.status.success(), "a bad file fails");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("bad.ag"), "stderr names the file: {stderr}");
    assert!(
        stderr.contains("not an AG file"),
        "stderr says why: {stderr}"
    );
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn the_cli_refuses_a_missing_file_and_missing_arguments() {
    let dir = tempfile::tempdir().expect("a temp dir");
    let run = ag_plot()
        .arg(dir.path().join("missing.ag"))
        .arg(dir.path().join("out.svg"))
        .output()
        .expect("ag-plot runs");
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("missing.ag"));

    let run = ag_plot().output().expect("ag-plot runs");
    assert!(!run.status.success(), "no arguments is a usage error");
}
