//! Scenario files written to do harm: a name that is a path, absurd sizes and numbers, a
//! robot inside the object, a FIFO or `/dev/zero` in place of a file. Each is refused with
//! the file, the line and the limit; random mutations of a good file never panic.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use agp_world::{MAX_CONFIG_FILE_BYTES, Scenario, ScenarioLoadError};
use proptest::prelude::*;

const GOOD: &str = r#"name = "my-pentagon"

[object]
shape = "polygon"
vertices_mm = [[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]
mass_kg = 0.1
floor_friction = 0.4
contact_friction = 0.3
start = { x_mm = 0, y_mm = 0, theta_deg = 0 }

[robot]
start = { x_mm = -250, y_mm = 0, theta_deg = 0 }
odometry_noise = 0.005
localization = { period_s = 1.0, noise_mm = 1.0, noise_deg = 0.5 }
ir_noise_scale = 1.0

[task]
kind = "trajectory"
goal = { x_mm = 300, y_mm = 150, theta_deg = 90 }
tolerance = { mm = 10, deg = 10 }
path_mm = [[0, 0], [600, 0]]
max_pushes = 150
seed = 7
"#;

const ORIGIN: &str = "hostile.toml";

#[test]
fn a_trajectory_task_may_ask_to_keep_the_heading_and_a_placement_may_not() {
    let kept = Scenario::parse(
        &GOOD.replace("seed = 7", "seed = 7\nkeep_heading_deg = 15"),
        ORIGIN,
    )
    .expect("a trajectory keeping its heading");
    let h = kept.task.keep_heading_rad.expect("the heading asked");
    assert!((h - 15f64.to_radians()).abs() < 1e-15);
    let free = Scenario::parse(GOOD, ORIGIN).expect("the good file");
    assert_eq!(free.task.keep_heading_rad, None);
    let (line, msg) = refused(
        "kind = \"trajectory\"\n",
        "kind = \"place\"\nkeep_heading_deg = 15\n",
    );
    assert_eq!(line, 19, "{msg}");
    assert!(msg.contains("belongs to a `trajectory` task"), "{msg}");
}

/// Parses GOOD with `from` replaced by `to`; the refusal's line and message.
#[track_caller]
fn refused(from: &str, to: &str) -> (usize, String) {
    assert!(GOOD.contains(from), "test setup: `{from}` not in the file");
    match Scenario::parse(&GOOD.replacen(from, to, 1), ORIGIN) {
        Ok(_) => panic!("`{to}` was accepted"),
        Err(e @ ScenarioLoadError::Invalid { .. }) => {
            let shown = e.to_string();
            let ScenarioLoadError::Invalid {
                path,
                line,
                message,
            } = e
            else {
                unreachable!()
            };
            assert_eq!(path, ORIGIN);
            assert!(shown.starts_with(&format!("{ORIGIN}:{line}: ")), "{shown}");
            (line, message)
        }
        Err(other) => panic!("unexpected error kind: {other}"),
    }
}

/// Runs `f` on a thread; panics if it has not returned within 20 s (a safety net: the
/// tests assert what comes back, not how fast).
fn without_hanging<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(20))
        .expect("the load blocked (or read without end)")
}

fn make_fifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).expect("no NUL");
    // SAFETY: mkfifo(3) on a NUL-terminated path this test owns.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o600) };
    assert_eq!(rc, 0, "mkfifo: {}", std::io::Error::last_os_error());
}

#[test]
fn the_file_these_tests_mutate_is_valid() {
    let s = Scenario::parse(GOOD, ORIGIN).expect("valid");
    assert_eq!(s.name, "my-pentagon");
}

#[test]
fn a_scenario_name_that_is_a_path_is_refused_with_its_line() {
    for bad in [
        "../../x/ESCAPED",
        "/etc/passwd",
        "a/b",
        "..",
        "with space",
        "tab\\there",
        "",
    ] {
        let (line, msg) = refused("name = \"my-pentagon\"", &format!("name = \"{bad}\""));
        assert_eq!(line, 1, "{bad}: {msg}");
        assert!(msg.contains("`name`"), "{bad}: {msg}");
    }
    let long = "n".repeat(agp_world::MAX_SCENARIO_NAME_LEN + 1);
    let (line, msg) = refused("name = \"my-pentagon\"", &format!("name = \"{long}\""));
    assert_eq!(line, 1);
    assert!(msg.contains("longer than 64"), "{msg}");
    let ok = "n".repeat(agp_world::MAX_SCENARIO_NAME_LEN);
    let s = Scenario::parse(&GOOD.replace("my-pentagon", &ok), ORIGIN).expect("64 is fine");
    assert_eq!(s.name, ok);
}

#[test]
fn a_polygon_of_ten_thousand_vertices_is_refused_naming_the_limit() {
    let ring: Vec<String> = (0..10_000)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 10_000.0;
            format!("[{:.4}, {:.4}]", 50.0 * a.cos(), 50.0 * a.sin())
        })
        .collect();
    let (line, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        &format!("[{}]", ring.join(", ")),
    );
    assert_eq!(line, 5);
    assert!(
        msg.contains("10000 vertices") && msg.contains("at most 64"),
        "{msg}"
    );
}

#[test]
fn a_polygon_of_a_billion_millimetres_is_refused_naming_the_arena() {
    let (line, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [1e9, 0], [1e9, 1e9], [0, 1e9]]",
    );
    assert_eq!(line, 5);
    assert!(msg.contains("vertex 2") && msg.contains("5000 mm"), "{msg}");
}

#[test]
fn an_object_too_small_or_too_large_is_refused_naming_the_size_limit() {
    let (line, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [4000, 0], [4000, 4000], [0, 4000]]",
    );
    assert_eq!(line, 5);
    assert!(msg.contains("from 5 to 1000 mm"), "{msg}");
    let (_, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [1, 0], [1, 1], [0, 1]]",
    );
    assert!(msg.contains("from 5 to 1000 mm"), "{msg}");
    let (_, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [100, 0], [100, 0.01], [0, 0.01]]",
    );
    assert!(msg.contains("area") && msg.contains("10 mm^2"), "{msg}");
}

#[test]
fn a_robot_that_starts_inside_or_over_the_object_is_refused_with_the_clearance() {
    // Inside: the robot's centre on the object's centroid.
    let (line, msg) = refused(
        "start = { x_mm = -250, y_mm = 0, theta_deg = 0 }",
        "start = { x_mm = 0, y_mm = 0, theta_deg = 0 }",
    );
    assert_eq!(line, 12);
    assert!(
        msg.contains("overlapping") && msg.contains("clearance -"),
        "{msg}"
    );
    // Overlapping: the body (37 mm radius) reaches 7 mm into the pentagon's vertex at
    // x = 50 mm... from x = 80 mm.
    let (_, msg) = refused(
        "start = { x_mm = -250, y_mm = 0, theta_deg = 0 }",
        "start = { x_mm = 80, y_mm = 0, theta_deg = 0 }",
    );
    assert!(msg.contains("clearance -7.0 mm"), "{msg}");
    // Clear by a millimetre: accepted.
    Scenario::parse(
        &GOOD.replace(
            "start = { x_mm = -250, y_mm = 0, theta_deg = 0 }",
            "start = { x_mm = 88, y_mm = 0, theta_deg = 0 }",
        ),
        ORIGIN,
    )
    .expect("a robot 1 mm clear is fine");
}

#[test]
fn every_numeric_field_beyond_its_bounds_is_refused_naming_the_field_and_limit() {
    let cases: &[(&str, &str, usize, &[&str])] = &[
        ("mass_kg = 0.1", "mass_kg = 1e300", 6, &["mass_kg", "10 kg"]),
        (
            "mass_kg = 0.1",
            "mass_kg = 1e-300",
            6,
            &["mass_kg", "0.001"],
        ),
        (
            "floor_friction = 0.4",
            "floor_friction = 1e9",
            7,
            &["floor_friction", "at most 2"],
        ),
        (
            "contact_friction = 0.3",
            "contact_friction = -1",
            8,
            &["contact_friction"],
        ),
        (
            "start = { x_mm = 0, y_mm = 0, theta_deg = 0 }",
            "start = { x_mm = 0, y_mm = 9000, theta_deg = 0 }",
            9,
            &["`start`", "5000 mm"],
        ),
        (
            "start = { x_mm = 0, y_mm = 0, theta_deg = 0 }",
            "start = { x_mm = 0, y_mm = 0, theta_deg = 1e12 }",
            9,
            &["theta_deg", "360 deg"],
        ),
        (
            "odometry_noise = 0.005",
            "odometry_noise = 7",
            13,
            &["odometry_noise", "0.5"],
        ),
        (
            "ir_noise_scale = 1.0",
            "ir_noise_scale = 1e6",
            15,
            &["ir_noise_scale", "100"],
        ),
        (
            "period_s = 1.0",
            "period_s = 1e-9",
            14,
            &["period_s", "0.01 to 3600 s"],
        ),
        (
            "noise_mm = 1.0",
            "noise_mm = 1e5",
            14,
            &["noise_mm", "100 mm"],
        ),
        (
            "noise_deg = 0.5",
            "noise_deg = 720",
            14,
            &["noise_deg", "45 deg"],
        ),
        (
            "goal = { x_mm = 300, y_mm = 150, theta_deg = 90 }",
            "goal = { x_mm = -1e7, y_mm = 150, theta_deg = 90 }",
            19,
            &["`goal`", "5000 mm"],
        ),
        (
            "tolerance = { mm = 10, deg = 10 }",
            "tolerance = { mm = 1e9, deg = 10 }",
            20,
            &["tolerance", "1000"],
        ),
        (
            "tolerance = { mm = 10, deg = 10 }",
            "tolerance = { mm = 10, deg = 400 }",
            20,
            &["tolerance", "180"],
        ),
        (
            "[[0, 0], [600, 0]]",
            "[[0, 0], [6000, 0]]",
            21,
            &["path_mm", "point 2", "5000 mm"],
        ),
        (
            "max_pushes = 150",
            "max_pushes = 4000000000",
            22,
            &["max_pushes", "10000"],
        ),
        ("seed = 7", "seed = -7", 23, &["seed"]),
        (
            "seed = 7",
            "seed = 7\nkeep_heading_deg = 0",
            24,
            &["keep_heading_deg", "(0, 180]"],
        ),
        (
            "seed = 7",
            "seed = 7\nkeep_heading_deg = 270",
            24,
            &["keep_heading_deg", "270"],
        ),
    ];
    for &(from, to, want_line, words) in cases {
        let (line, msg) = refused(from, to);
        assert_eq!(line, want_line, "{to}: {msg}");
        for w in words {
            assert!(msg.contains(w), "{to}: `{msg}` does not say {w}");
        }
    }
    let circle = GOOD
        .replace("shape = \"polygon\"", "shape = \"circle\"")
        .replace(
            "vertices_mm = [[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
            "radius_mm = 1e9",
        );
    let e = Scenario::parse(&circle, ORIGIN).expect_err("a circle of 1e9 mm");
    assert!(
        e.to_string().starts_with("hostile.toml:5: `radius_mm`")
            && e.to_string().contains("1000 mm"),
        "{e}"
    );
}

#[test]
fn a_fifo_as_a_scenario_is_refused_without_blocking() {
    let dir = tempfile::tempdir().expect("temp dir");
    let fifo = dir.path().join("scenario.toml");
    make_fifo(&fifo);
    let shown = {
        let fifo = fifo.clone();
        without_hanging(move || Scenario::resolve(fifo.to_str().expect("UTF-8")))
    }
    .expect_err("a FIFO is no scenario")
    .to_string();
    assert!(
        shown.contains(&fifo.display().to_string())
            && shown.contains("not a regular file but a FIFO"),
        "{shown}"
    );
}

#[test]
fn a_link_to_dev_zero_as_a_scenario_is_refused_without_reading() {
    let dir = tempfile::tempdir().expect("temp dir");
    let link = dir.path().join("zero.toml");
    std::os::unix::fs::symlink("/dev/zero", &link).expect("symlink");
    let shown = without_hanging(move || Scenario::load(&link))
        .expect_err("/dev/zero is no scenario")
        .to_string();
    assert!(
        shown.contains("zero.toml") && shown.contains("a character device"),
        "{shown}"
    );
}

#[test]
fn a_scenario_larger_than_a_mebibyte_is_refused_naming_the_limit() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path: PathBuf = dir.path().join("big.toml");
    let mut text = GOOD.to_owned();
    text.push_str(&"# padding\n".repeat((MAX_CONFIG_FILE_BYTES / 10) as usize + 1));
    std::fs::write(&path, text).expect("write");
    let shown = Scenario::load(&path).expect_err("too large").to_string();
    assert!(
        shown.contains("big.toml") && shown.contains("1048576 bytes"),
        "{shown}"
    );
}

/// One edit of a scenario's text.
#[derive(Debug, Clone)]
enum Edit {
    DeleteLine(usize),
    ReplaceValue(usize, String),
    InsertLine(usize, String),
    Truncate(usize),
}

fn hostile_value() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("1e300".to_owned()),
        Just("-1e300".to_owned()),
        Just("nan".to_owned()),
        Just("-inf".to_owned()),
        Just("0".to_owned()),
        Just("-0.0".to_owned()),
        Just("9223372036854775807".to_owned()),
        Just("-9223372036854775808".to_owned()),
        Just("\"../../x/ESCAPED\"".to_owned()),
        Just("\"\"".to_owned()),
        Just("[]".to_owned()),
        Just("{}".to_owned()),
        Just("[[0, 0], [1e9, 0], [0, 1e9]]".to_owned()),
        Just("{ x_mm = 0, y_mm = 0, theta_deg = 0 }".to_owned()),
        Just("\"off\"".to_owned()),
        any::<f64>().prop_map(|x| format!("{x:?}")),
        any::<i64>().prop_map(|x| x.to_string()),
        "[ -~]{0,12}",
        "\\PC{0,6}",
    ]
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (0..30usize).prop_map(Edit::DeleteLine),
        (0..30usize, hostile_value()).prop_map(|(k, v)| Edit::ReplaceValue(k, v)),
        (0..30usize, "[ -~]{0,20}").prop_map(|(k, v)| Edit::InsertLine(k, v)),
        (0..GOOD.len()).prop_map(Edit::Truncate),
    ]
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let mut cut = None;
    for e in edits {
        let n = lines.len().max(1);
        match e {
            Edit::DeleteLine(k) if !lines.is_empty() => {
                lines.remove(k % n);
            }
            Edit::ReplaceValue(k, v) if !lines.is_empty() => {
                let line = &mut lines[k % n];
                if let Some(eq) = line.find('=') {
                    line.truncate(eq + 1);
                    line.push(' ');
                    line.push_str(v);
                }
            }
            Edit::InsertLine(k, v) => lines.insert(k % (lines.len() + 1), v.clone()),
            Edit::Truncate(at) => cut = Some(*at),
            _ => {}
        }
    }
    let mut out = lines.join("\n");
    if let Some(at) = cut {
        let mut at = at.min(out.len());
        while !out.is_char_boundary(at) {
            at -= 1;
        }
        out.truncate(at);
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn a_mutated_scenario_never_panics_and_every_refusal_names_the_file_and_line(
        edits in proptest::collection::vec(edit(), 1..4)
    ) {
        let text = apply(GOOD, &edits);
        match Scenario::parse(&text, ORIGIN) {
            Ok(s) => {
                // What is accepted is within the limits.
                prop_assert!(s.name.len() <= agp_world::MAX_SCENARIO_NAME_LEN);
                prop_assert!(s.object.shape.radius() <= 1.0);
                prop_assert!(s.object.mass.is_finite() && s.object.mass > 0.0);
            }
            Err(ScenarioLoadError::Invalid { path, line, message }) => {
                prop_assert_eq!(path, ORIGIN);
                prop_assert!(line >= 1 && line <= text.lines().count().max(1) + 1, "line {} of {}", line, text);
                prop_assert!(!message.is_empty());
                prop_assert!(!message.contains('\n'), "{}", message);
            }
            Err(other) => prop_assert!(false, "unexpected error kind: {}", other),
        }
    }
}
