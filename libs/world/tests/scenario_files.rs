//! Scenario files as a user writes them: the good ones load, each kind of bad one is refused
//! with the file, the line and what is wrong.

use std::path::PathBuf;

use agp_world::{ObjectShape, Scenario, ScenarioLoadError, TaskKind};

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
kind = "place"
goal = { x_mm = 300, y_mm = 150, theta_deg = 90 }
tolerance = { mm = 10, deg = 10 }
max_pushes = 150
seed = 7
"#;

fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("my.toml");
    std::fs::write(&path, text).expect("write scenario");
    (dir, path)
}

/// Loads `text` with `from` replaced by `to` and returns the error's line and message.
fn refused(from: &str, to: &str) -> (usize, String) {
    assert!(
        GOOD.contains(from),
        "test setup: `{from}` not in the good file"
    );
    let (_dir, path) = write(&GOOD.replacen(from, to, 1));
    match Scenario::load(&path) {
        Ok(_) => panic!("`{to}` was accepted"),
        Err(ScenarioLoadError::Invalid {
            path: p,
            line,
            message,
        }) => {
            assert_eq!(p, path.display().to_string(), "the error names the file");
            let shown = Scenario::load(&path).unwrap_err().to_string();
            assert!(
                shown.starts_with(&format!("{}:{line}: ", path.display())),
                "{shown}"
            );
            (line, message)
        }
        Err(other) => panic!("unexpected error kind: {other}"),
    }
}

#[test]
fn the_pentagon_of_the_spec_loads_as_a_user_would_write_it() {
    let (_dir, path) = write(GOOD);
    let s = Scenario::load(&path).expect("valid scenario");
    assert_eq!(s.name, "my-pentagon");
    assert_eq!(s.task.kind, TaskKind::Place);
    assert!(
        (s.task.goal.x - 0.3).abs() < 1e-12
            && (s.task.goal.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12
    );
    let ObjectShape::Polygon(p) = &s.object.shape else {
        panic!("a polygon")
    };
    assert_eq!(p.vertices().len(), 5);
    assert!(p.centroid().length() < 1e-12, "moved to its centroid");
}

#[test]
fn the_shipped_pentagon_example_loads() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/pentagon.toml");
    let s = Scenario::resolve(path.to_str().unwrap()).expect("shipped example loads");
    assert_eq!(s.name, "my-pentagon");
}

#[test]
fn a_polygon_that_crosses_itself_is_refused() {
    let (line, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [50, 50], [50, 0], [0, 50]]",
    );
    assert_eq!(line, 5);
    assert!(msg.contains("crosses itself"), "{msg}");
}

#[test]
fn a_polygon_of_two_vertices_is_refused() {
    let (line, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [50, 50]]",
    );
    assert_eq!(line, 5);
    assert!(msg.contains("at least 3 vertices"), "{msg}");
}

#[test]
fn a_polygon_of_zero_area_is_refused() {
    let (line, msg) = refused(
        "[[50, 0], [15.5, 47.6], [-40.5, 29.4], [-40.5, -29.4], [15.5, -47.6]]",
        "[[0, 0], [10, 0], [20, 0], [30, 0]]",
    );
    assert_eq!(line, 5);
    assert!(
        msg.contains("zero area") || msg.contains("crosses itself"),
        "{msg}"
    );
}

#[test]
fn a_negative_mass_is_refused() {
    let (line, msg) = refused("mass_kg = 0.1", "mass_kg = -0.1");
    assert_eq!(line, 6);
    assert!(msg.contains("mass_kg") && msg.contains("positive"), "{msg}");
}

#[test]
fn a_negative_friction_is_refused() {
    let (line, msg) = refused("floor_friction = 0.4", "floor_friction = -0.4");
    assert_eq!(line, 7);
    assert!(msg.contains("floor_friction"), "{msg}");
}

#[test]
fn a_number_that_is_not_finite_is_refused() {
    let (line, msg) = refused("contact_friction = 0.3", "contact_friction = nan");
    assert_eq!(line, 8);
    assert!(msg.contains("contact_friction"), "{msg}");
    let (line, msg) = refused("[15.5, -47.6]]", "[15.5, inf]]");
    assert_eq!(line, 5);
    assert!(msg.contains("not a finite number"), "{msg}");
}

#[test]
fn an_unknown_key_is_refused_with_its_name() {
    let (line, msg) = refused("mass_kg = 0.1", "mass_kg = 0.1\ncolour = \"red\"");
    assert_eq!(line, 7);
    assert!(msg.contains("colour"), "{msg}");
}

#[test]
fn an_unknown_shape_and_task_kind_are_refused() {
    let (line, msg) = refused("shape = \"polygon\"", "shape = \"blob\"");
    assert_eq!(line, 4);
    assert!(msg.contains("blob"), "{msg}");
    let (line, msg) = refused("kind = \"place\"", "kind = \"juggle\"");
    assert_eq!(line, 18);
    assert!(msg.contains("juggle"), "{msg}");
}

#[test]
fn a_bad_localization_is_refused() {
    let (line, msg) = refused(
        "localization = { period_s = 1.0, noise_mm = 1.0, noise_deg = 0.5 }",
        "localization = \"sometimes\"",
    );
    assert_eq!(line, 14);
    assert!(msg.contains("sometimes"), "{msg}");
    let (_dir, path) = write(&GOOD.replace(
        "localization = { period_s = 1.0, noise_mm = 1.0, noise_deg = 0.5 }",
        "localization = \"off\"",
    ));
    assert_eq!(Scenario::load(&path).unwrap().robot.localization, None);
}

#[test]
fn a_toml_syntax_error_names_its_line() {
    let (line, _msg) = refused("max_pushes = 150", "max_pushes = = 150");
    assert_eq!(line, 21);
}

#[test]
fn a_missing_file_and_an_unknown_name_are_told_apart() {
    let e = Scenario::load(std::path::Path::new("no/such/scenario.toml")).unwrap_err();
    assert!(e.to_string().contains("no/such/scenario.toml"), "{e}");
    let e = Scenario::resolve("hexagon").unwrap_err();
    assert!(
        e.to_string().contains("`hexagon`") && e.to_string().contains("triangle"),
        "{e}"
    );
}

#[test]
fn a_regular_polygon_written_to_a_tenth_of_a_millimetre_keeps_its_symmetry() {
    // The example file's pentagon: vertices rounded to 0.1 mm (up to 0.07 mm off).
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/pentagon.toml");
    let pentagon = Scenario::load(&file).expect("the example loads");
    assert_eq!(pentagon.object.shape.symmetry_order(), 5);
    // A 60 x 40 mm rectangle turns onto itself by half a turn only; a quadrilateral 3 mm off
    // a square (more than IR tells apart) has no symmetry.
    let shape = |mm: &[[f64; 2]]| {
        let v = mm
            .iter()
            .map(|p| glam::DVec2::new(p[0], p[1]) * 1e-3)
            .collect();
        ObjectShape::Polygon(agp_world::Polygon::new(v).expect("a polygon").centred())
    };
    let rect = shape(&[[30.0, 20.0], [-30.0, 20.0], [-30.0, -20.0], [30.0, -20.0]]);
    assert_eq!(rect.symmetry_order(), 2);
    let skew = shape(&[[33.0, 30.0], [-30.0, 30.0], [-30.0, -30.0], [30.0, -30.0]]);
    assert_eq!(skew.symmetry_order(), 1);
}
