//! Hostile input files end to end: the real `agp` refuses a FIFO or `/dev/zero` as a
//! scenario without hanging, a scenario whose name is a path, and the AG file of another
//! object, each with one line naming the file.

use std::path::Path;
use std::time::Duration;

use agp_tests::{Finished, count_instance_files, run_agp};

/// A safety net: each refusal comes before anything runs.
const TIMEOUT: Duration = Duration::from_secs(60);

#[track_caller]
fn refused(dir: &Path, args: &[&str], words: &[&str]) -> Finished {
    let run = run_agp(dir, args, TIMEOUT);
    assert!(
        !run.status.success(),
        "`agp {}` was accepted: {}",
        args.join(" "),
        run.stdout
    );
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
    for w in words {
        assert!(
            run.stderr.contains(w),
            "`agp {}`: stderr does not say {w}: {}",
            args.join(" "),
            run.stderr
        );
    }
    assert_eq!(
        count_instance_files(&format!("probe-{}", run.pid)),
        0,
        "files left behind"
    );
    run
}

/// `agp probe push --scenario <scenario> --angle-deg 0` in `dir`, refused saying `words`.
#[track_caller]
fn probe_refused(dir: &Path, scenario: &str, words: &[&str]) -> Finished {
    refused(
        dir,
        &["probe", "push", "--scenario", scenario, "--angle-deg", "0"],
        words,
    )
}

fn make_fifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).expect("no NUL");
    // SAFETY: mkfifo(3) on a NUL-terminated path this test owns.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o600) };
    assert_eq!(rc, 0, "mkfifo: {}", std::io::Error::last_os_error());
}

#[test]
fn probe_push_with_a_fifo_as_its_scenario_is_refused_instead_of_hanging() {
    let dir = tempfile::tempdir().expect("temp dir");
    make_fifo(&dir.path().join("pipe.toml"));
    probe_refused(
        dir.path(),
        "pipe.toml",
        &["pipe.toml", "not a regular file but a FIFO"],
    );
}

#[test]
fn probe_push_with_a_link_to_dev_zero_as_its_scenario_is_refused_without_reading_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.toml")).expect("symlink");
    probe_refused(
        dir.path(),
        "zero.toml",
        &["zero.toml", "a character device"],
    );
}

#[test]
fn probe_push_with_a_scenario_whose_name_is_a_path_is_refused_with_its_line() {
    let dir = tempfile::tempdir().expect("temp dir");
    let square = agp_world::Scenario::builtin("square").expect("built-in");
    assert_eq!(square.name, "square");
    std::fs::write(
        dir.path().join("escape.toml"),
        "name = \"../../x/ESCAPED\"\n[object]\nshape = \"circle\"\nradius_mm = 35\n\
         mass_kg = 0.1\nfloor_friction = 0.4\ncontact_friction = 0.3\n",
    )
    .expect("write");
    let run = probe_refused(
        dir.path(),
        "escape.toml",
        &["escape.toml:1:", "not a plain name"],
    );
    assert_eq!(run.stderr.trim().lines().count(), 1, "{}", run.stderr);
    assert!(!dir.path().join("../x").exists());
}

/// The bytes of a valid AG file of one alpha, empty grids, learned on `object`
/// (the format of `AffordanceGradient::save`).
fn ag_file_of(object: &str) -> Vec<u8> {
    const SIDE: usize = 128;
    let mut out = Vec::new();
    out.extend_from_slice(b"AGPAG\0");
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&(SIDE as u32).to_le_bytes());
    out.extend_from_slice(&0.002f64.to_le_bytes());
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&0.0f64.to_le_bytes());
    out.extend_from_slice(&(object.len() as u32).to_le_bytes());
    out.extend_from_slice(object.as_bytes());
    out.resize(out.len() + 11 * SIDE * SIDE * 4 + 24, 0);
    let sum = out.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    });
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

#[test]
fn bench_place_with_the_ag_file_of_another_object_is_refused_naming_both() {
    let dir = tempfile::tempdir().expect("temp dir");
    std::fs::write(dir.path().join("tri.ag"), ag_file_of("triangle")).expect("write");
    refused(
        dir.path(),
        &[
            "bench",
            "place",
            "--in-process",
            "--scenario",
            "square",
            "--planners",
            "affordance",
            "--episodes",
            "1",
            "--ag",
            "tri.ag",
        ],
        &["tri.ag", "`triangle`", "not of `square`"],
    );
}
