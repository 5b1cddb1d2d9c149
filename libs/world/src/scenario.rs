use std::path::Path;

use glam::DVec2;
use serde::Deserialize;
use toml::Spanned;

pub use agp_shared_types::Pose2 as Pose;

use crate::bounded_read::{BoundedReadError, MAX_CONFIG_FILE_BYTES, read_regular_text};
use crate::geometry::{Polygon, PolygonError};
use crate::{RobotDescription, line_of};

/// Longest scenario `name`, characters. The name is a plain name (letters, digits, `-`,
/// `_`): it names the AG file in the results folder (`<name>.ag`), so it can never be a path.
pub const MAX_SCENARIO_NAME_LEN: usize = 64;
/// Most vertices a polygon may have: the convex decomposition and the physics's colliders
/// are built for objects of a few corners, not for a traced outline.
pub const MAX_POLYGON_VERTICES: usize = 64;
/// Half the side of the arena, mm: every coordinate of a scenario (vertices, starts, goal,
/// path) lies within +-this.
pub const ARENA_HALF_SIZE_MM: f64 = 5000.0;
/// Smallest and largest object: the distance from its centroid to its farthest border
/// point, mm.
pub const OBJECT_RADIUS_MM: (f64, f64) = (5.0, 1000.0);
/// Smallest object area, mm^2.
pub const MIN_OBJECT_AREA_MM2: f64 = 10.0;
/// Largest |angle| of a pose, degrees.
pub const MAX_POSE_ANGLE_DEG: f64 = 360.0;

/// The object's shape in its own frame, centred on its centroid.
#[derive(Debug, Clone, PartialEq)]
pub enum ObjectShape {
    Polygon(Polygon),
    Circle { radius: f64 },
}

impl ObjectShape {
    /// Largest distance from the centroid to the border.
    pub fn radius(&self) -> f64 {
        match self {
            Self::Polygon(p) => p.radius(),
            Self::Circle { radius } => *radius,
        }
    }

    /// Area of the footprint, m^2.
    pub fn area(&self) -> f64 {
        match self {
            Self::Polygon(p) => p.area(),
            Self::Circle { radius } => std::f64::consts::PI * radius * radius,
        }
    }

    /// Whether a point of the object frame is inside the shape.
    pub fn contains(&self, p: DVec2) -> bool {
        match self {
            Self::Polygon(poly) => poly.contains(p),
            Self::Circle { radius } => p.length() <= *radius,
        }
    }

    /// Rotational symmetry: the shape maps onto itself when turned by 360/order degrees.
    /// 0 for a circle (every angle), 1 for no symmetry.
    pub fn symmetry_order(&self) -> u32 {
        match self {
            Self::Circle { .. } => 0,
            Self::Polygon(p) => {
                // 1 % of the size: a file's vertices are rounded (a pentagon written to
                // 0.1 mm is off by up to 0.07 mm), and IR cannot tell apart poses that
                // differ by less than a millimetre anyway.
                let tol = 1e-2 * p.radius().max(1e-9);
                (2..=12u32)
                    .rev()
                    .find(|&k| {
                        let rot = DVec2::from_angle(std::f64::consts::TAU / k as f64);
                        p.vertices().iter().all(|v| {
                            let r = rot.rotate(*v);
                            p.vertices().iter().any(|w| (*w - r).length() < tol)
                        })
                    })
                    .unwrap_or(1)
            }
        }
    }
}

/// The object to push and where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectSpec {
    pub shape: ObjectShape,
    pub mass: f64,
    /// Coulomb coefficient between object and floor.
    pub floor_friction: f64,
    /// Coulomb coefficient between robot and object.
    pub contact_friction: f64,
    pub start: Pose,
}

/// The overhead camera's periodic fix of the robot's pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Localization {
    pub period_s: f64,
    pub noise_m: f64,
    pub noise_rad: f64,
}

/// How physics moves the robot (a scenario's `[robot] drive`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum RobotDrive {
    /// `"kinematic"`: the body follows the commanded wheel speeds exactly, with unbounded
    /// force; it never stalls and its wheels never slip. For comparison with the earlier
    /// figures and for the analytic tests of the push itself.
    Kinematic,
    /// `"finite-force"` (the default): a dynamic body driven by two stepper wheels, each
    /// pulling at most the smaller of its traction (`wheel_friction` times its share of the
    /// weight) and its motor's (`wheel_torque / wheel_radius`) of the robot file: a heavy
    /// object stalls it, its wheels slip and odometry, which counts commanded steps, drifts.
    #[default]
    FiniteForce,
}

impl RobotDrive {
    /// The name a scenario file gives it.
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Kinematic => "kinematic",
            Self::FiniteForce => "finite-force",
        }
    }
}

/// The robot's start and the noise of its senses.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotSetup {
    /// How physics moves the robot's body.
    pub drive: RobotDrive,
    pub start: Pose,
    /// Relative standard deviation of each wheel's travel per odometry update.
    pub odometry_noise: f64,
    /// `None` when the scenario turns the overhead fix off.
    pub localization: Option<Localization>,
    /// Multiplies the response table's noise.
    pub ir_noise_scale: f64,
}

/// What the run is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TaskKind {
    Learn,
    Trajectory,
    Place,
}

impl TaskKind {
    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Learn => "learn",
            Self::Trajectory => "trajectory",
            Self::Place => "place",
        }
    }
}

/// The task of a scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskSpec {
    pub kind: TaskKind,
    pub goal: Pose,
    pub tolerance_m: f64,
    pub tolerance_rad: f64,
    /// Polyline of a trajectory task, metres (world frame): the file's `path_mm`, else
    /// 600 mm along +x from the object's start (benchmarks.md section 2).
    pub path: Vec<DVec2>,
    /// A trajectory task's `keep_heading_deg`: the object's heading (its frame's x axis)
    /// kept tangent to the path within this (rad). `None`: the heading is free.
    pub keep_heading_rad: Option<f64>,
    pub max_pushes: u32,
    pub seed: u64,
}

/// A whole scenario: object, robot and task. The object's spec is ground truth: physics,
/// the judge, the probe and the `oracle` read it; the estimator and the planners get a
/// [`ScenarioBrief`].
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    pub name: String,
    /// Where it came from: a file path, or `built-in`.
    pub source: String,
    pub object: ObjectSpec,
    pub robot: RobotSetup,
    pub task: TaskSpec,
    /// Changes of the world at given simulated times (`[[world_change]]`), in order of
    /// time: ground truth, applied by physics alone.
    pub world_changes: Vec<WorldChange>,
}

/// A change of the world at a given simulated time (a scenario's `[[world_change]]`): the
/// floor's friction under the object, the object's mass, or both. Ground truth: physics
/// applies it, the judge may read it, the estimator and the planners never see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldChange {
    /// Simulated time since physics started, s.
    pub at_s: f64,
    /// The object-floor Coulomb coefficient from then on.
    pub floor_friction: Option<f64>,
    /// The object's mass from then on, kg.
    pub mass_kg: Option<f64>,
}

/// Most `[[world_change]]` entries a scenario may hold.
pub const MAX_WORLD_CHANGES: usize = 64;
/// Latest `at_s` of a world change, s (a day of simulated time).
pub const MAX_WORLD_CHANGE_AT_S: f64 = 86_400.0;

/// What the estimator and the planners may read of a scenario: its name (which AG file),
/// the robot's start and the noise of its senses, and the task. Nothing of the object: its
/// [`ObjectSpec`] is for physics, the judge, the probe and the `oracle` alone, and a process
/// that holds only a brief cannot reach it.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioBrief {
    pub name: String,
    /// Where it came from: a file path, or `built-in`.
    pub source: String,
    pub robot: RobotSetup,
    pub task: TaskSpec,
}

/// What the experimenter of the learning protocol (and of the scripted drive) knows: the
/// marked spot where they put the object back before each step, which fixes the frame the
/// gradient is learned in (as the paper's experimenter does by hand). Nothing else of the
/// object: the robot's first circling starts outside anything the gradients' grid can
/// hold, and every later start is set from the border learned by IR.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Experimenter {
    /// Where the object is put back (world frame).
    pub placement: Pose,
}

impl ScenarioBrief {
    /// The brief of a built-in scenario or a scenario file (see [`Scenario::resolve`]).
    pub fn resolve(name_or_file: &str) -> Result<Self, ScenarioLoadError> {
        Scenario::resolve(name_or_file).map(|s| s.brief())
    }
}

impl Scenario {
    /// What the estimator and the planners may read of it.
    pub fn brief(&self) -> ScenarioBrief {
        ScenarioBrief {
            name: self.name.clone(),
            source: self.source.clone(),
            robot: self.robot.clone(),
            task: self.task.clone(),
        }
    }

    /// What the experimenter of the learning protocol knows of it.
    pub fn experimenter(&self) -> Experimenter {
        Experimenter {
            placement: self.object.start,
        }
    }
}

/// Why a scenario could not be loaded. Every variant names the file; parse and validation
/// errors name the line.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioLoadError {
    #[error("cannot read scenario `{path}`: {reason}")]
    Read {
        path: String,
        /// Why (shown in the message, so not a `source` that would show it twice).
        reason: BoundedReadError,
    },
    #[error("{path}:{line}: {message}")]
    Invalid {
        path: String,
        line: usize,
        message: String,
    },
    #[error(
        "`{0}` is neither a built-in scenario ({builtins}) nor a file",
        builtins = BUILTIN_NAMES.join(", ")
    )]
    Unknown(String),
}

/// Names of the built-in scenarios.
pub const BUILTIN_NAMES: [&str; 4] = ["square", "triangle", "lshape", "circle"];

const BUILTINS: [(&str, &str); 4] = [
    ("square", include_str!("../scenarios/square.toml")),
    ("triangle", include_str!("../scenarios/triangle.toml")),
    ("lshape", include_str!("../scenarios/lshape.toml")),
    ("circle", include_str!("../scenarios/circle.toml")),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ScenarioFile {
    name: Spanned<String>,
    object: ObjectFile,
    #[serde(default)]
    robot: Option<RobotFile>,
    #[serde(default)]
    task: Option<TaskFile>,
    #[serde(default)]
    world_change: Vec<Spanned<WorldChangeFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldChangeFile {
    at_s: Spanned<f64>,
    #[serde(default)]
    floor_friction: Option<Spanned<f64>>,
    #[serde(default)]
    mass_kg: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectFile {
    shape: Spanned<String>,
    #[serde(default)]
    vertices_mm: Option<Spanned<Vec<[f64; 2]>>>,
    #[serde(default)]
    radius_mm: Option<Spanned<f64>>,
    mass_kg: Spanned<f64>,
    floor_friction: Spanned<f64>,
    contact_friction: Spanned<f64>,
    #[serde(default)]
    start: Option<Spanned<PoseFile>>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(deny_unknown_fields)]
struct PoseFile {
    x_mm: f64,
    y_mm: f64,
    theta_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotFile {
    #[serde(default)]
    drive: Option<Spanned<String>>,
    #[serde(default)]
    start: Option<Spanned<PoseFile>>,
    #[serde(default)]
    odometry_noise: Option<Spanned<f64>>,
    #[serde(default)]
    localization: Option<Spanned<toml::Value>>,
    #[serde(default)]
    ir_noise_scale: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LocalizationFile {
    period_s: f64,
    noise_mm: f64,
    noise_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ToleranceFile {
    mm: f64,
    deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TaskFile {
    kind: Spanned<String>,
    #[serde(default)]
    goal: Option<Spanned<PoseFile>>,
    #[serde(default)]
    tolerance: Option<Spanned<ToleranceFile>>,
    #[serde(default)]
    path_mm: Option<Spanned<Vec<[f64; 2]>>>,
    #[serde(default)]
    keep_heading_deg: Option<Spanned<f64>>,
    #[serde(default)]
    max_pushes: Option<Spanned<i64>>,
    #[serde(default)]
    seed: Option<Spanned<i64>>,
}

/// Defaults of the robot and task sections (benchmarks.md, robot-and-world.md).
const DEFAULT_ROBOT_START: Pose = Pose::new(-0.25, 0.0, 0.0);
const DEFAULT_ODOMETRY_NOISE: f64 = 0.005;
const DEFAULT_LOCALIZATION: Localization = Localization {
    period_s: 1.0,
    noise_m: 0.001,
    noise_rad: 0.5 * std::f64::consts::PI / 180.0,
};

impl Scenario {
    /// A built-in scenario by name.
    pub fn builtin(name: &str) -> Option<Scenario> {
        BUILTINS.iter().find(|(n, _)| *n == name).map(|(n, text)| {
            Self::parse(text, &format!("<built-in {n}>")).expect("built-in scenarios are valid")
        })
    }

    /// A built-in name, or else a path to a scenario file.
    pub fn resolve(name_or_file: &str) -> Result<Scenario, ScenarioLoadError> {
        if let Some(s) = Self::builtin(name_or_file) {
            return Ok(s);
        }
        let path = Path::new(name_or_file);
        if path.exists() {
            return Self::load(path);
        }
        Err(ScenarioLoadError::Unknown(name_or_file.to_owned()))
    }

    /// Loads and validates a scenario file whole. Refuses without blocking anything that is
    /// not a regular file (a FIFO, a link to `/dev/zero`) and any file larger than
    /// [`MAX_CONFIG_FILE_BYTES`].
    pub fn load(path: &Path) -> Result<Scenario, ScenarioLoadError> {
        let path = &crate::lexically_normal(path);
        let text = read_regular_text(path, MAX_CONFIG_FILE_BYTES).map_err(|reason| {
            ScenarioLoadError::Read {
                path: path.display().to_string(),
                reason,
            }
        })?;
        let mut s = Self::parse(&text, &path.display().to_string())?;
        s.source = path.display().to_string();
        Ok(s)
    }

    /// Parses and validates scenario text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Scenario, ScenarioLoadError> {
        let err = |span: std::ops::Range<usize>, message: String| ScenarioLoadError::Invalid {
            path: origin.to_owned(),
            line: line_of(text, span.start),
            message,
        };
        let file: ScenarioFile = toml::from_str(text).map_err(|e| {
            err(
                e.span().unwrap_or(0..0),
                e.message().trim_end().replace('\n', "; "),
            )
        })?;

        let name = file.name.get_ref().clone();
        if let Some(why) = bad_name(&name) {
            return Err(err(file.name.span(), why));
        }
        let object = object_spec(&file.object, &err)?;
        let robot = match &file.robot {
            None => RobotSetup {
                drive: RobotDrive::default(),
                start: DEFAULT_ROBOT_START,
                odometry_noise: DEFAULT_ODOMETRY_NOISE,
                localization: Some(DEFAULT_LOCALIZATION),
                ir_noise_scale: 1.0,
            },
            Some(r) => robot_setup(r, &err)?,
        };
        let mut task = match &file.task {
            None => TaskSpec {
                kind: TaskKind::Learn,
                goal: Pose::default(),
                tolerance_m: 0.01,
                tolerance_rad: 10f64.to_radians(),
                path: Vec::new(),
                keep_heading_rad: None,
                max_pushes: 150,
                seed: 7,
            },
            Some(t) => task(t, &err)?,
        };
        if task.path.is_empty() {
            // benchmarks.md section 2: the "predefined line on the floor" of a scenario
            // without `path_mm` is 600 mm straight along +x from the object's start. It is
            // fixed here, with the truth at hand, so the task reaches the planner in world
            // coordinates and nothing of the object with it.
            let s = object.start.position();
            task.path = vec![s, s + DVec2::new(0.6, 0.0)];
        }
        check_start_clearance(&file, &object, &robot, &err)?;
        let world_changes = world_changes(&file.world_change, &err)?;

        Ok(Scenario {
            name,
            source: "built-in".into(),
            object,
            robot,
            task,
            world_changes,
        })
    }
}

type ErrFn<'a> = dyn Fn(std::ops::Range<usize>, String) -> ScenarioLoadError + 'a;

/// The `[object]` table: its shape, its numbers within their bounds, its start.
fn object_spec(o: &ObjectFile, err: &ErrFn) -> Result<ObjectSpec, ScenarioLoadError> {
    let shape = match o.shape.get_ref().as_str() {
        "polygon" => {
            let Some(vs) = &o.vertices_mm else {
                return Err(err(o.shape.span(), "a polygon needs `vertices_mm`".into()));
            };
            if o.radius_mm.is_some() {
                return Err(err(o.shape.span(), "a polygon takes no `radius_mm`".into()));
            }
            ObjectShape::Polygon(polygon(vs, err)?)
        }
        "circle" => {
            let Some(r) = &o.radius_mm else {
                return Err(err(o.shape.span(), "a circle needs `radius_mm`".into()));
            };
            if o.vertices_mm.is_some() {
                return Err(err(
                    o.shape.span(),
                    "a circle takes no `vertices_mm`".into(),
                ));
            }
            let (lo, hi) = OBJECT_RADIUS_MM;
            positive_within(r, "radius_mm", lo, hi, "mm", err)?;
            ObjectShape::Circle {
                radius: *r.get_ref() * 1e-3,
            }
        }
        other => {
            return Err(err(
                o.shape.span(),
                format!("unknown shape `{other}`; expected `polygon` or `circle`"),
            ));
        }
    };
    positive_within(&o.mass_kg, "mass_kg", MASS_KG.0, MASS_KG.1, "kg", err)?;
    non_negative_within(&o.floor_friction, "floor_friction", MAX_FRICTION, "", err)?;
    non_negative_within(
        &o.contact_friction,
        "contact_friction",
        MAX_FRICTION,
        "",
        err,
    )?;
    Ok(ObjectSpec {
        shape,
        mass: *o.mass_kg.get_ref(),
        floor_friction: *o.floor_friction.get_ref(),
        contact_friction: *o.contact_friction.get_ref(),
        start: match &o.start {
            Some(p) => pose(p, "start", err)?,
            None => Pose::default(),
        },
    })
}

/// A polygon's `vertices_mm`: few enough, finite, inside the arena, a simple polygon (moved
/// to its centroid) of a size the simulator handles.
fn polygon(vs: &Spanned<Vec<[f64; 2]>>, err: &ErrFn) -> Result<Polygon, ScenarioLoadError> {
    let refuse = |msg: String| err(vs.span(), format!("`vertices_mm`: {msg}"));
    let count = vs.get_ref().len();
    if count > MAX_POLYGON_VERTICES {
        return Err(refuse(format!(
            "{count} vertices, at most {MAX_POLYGON_VERTICES} allowed"
        )));
    }
    for (i, v) in vs.get_ref().iter().enumerate() {
        if !(v[0].is_finite() && v[1].is_finite()) {
            return Err(refuse(format!("vertex {} is not a finite number", i + 1)));
        }
        if v[0].abs() > ARENA_HALF_SIZE_MM || v[1].abs() > ARENA_HALF_SIZE_MM {
            return Err(refuse(format!(
                "vertex {} ({}, {}) mm lies beyond the arena's +-{ARENA_HALF_SIZE_MM} mm",
                i + 1,
                v[0],
                v[1]
            )));
        }
    }
    let points = vs
        .get_ref()
        .iter()
        .map(|p| DVec2::new(p[0], p[1]) * 1e-3)
        .collect();
    let poly = Polygon::new(points).map_err(|e| {
        refuse(match e {
            PolygonError::NotFinite(i) => format!("vertex {i} is not a finite number"),
            other => other.to_string(),
        })
    })?;
    let poly = poly.centred();
    let radius_mm = poly.radius() * 1e3;
    let (lo, hi) = OBJECT_RADIUS_MM;
    if !(lo..=hi).contains(&radius_mm) {
        return Err(refuse(format!(
            "the object reaches {radius_mm:.1} mm from its centroid; it must reach from {lo} to {hi} mm"
        )));
    }
    let area_mm2 = poly.area() * 1e6;
    if area_mm2 < MIN_OBJECT_AREA_MM2 {
        return Err(refuse(format!(
            "the object's area is {area_mm2:.3} mm^2, at least {MIN_OBJECT_AREA_MM2} mm^2 needed"
        )));
    }
    Ok(poly)
}

/// The `[robot]` table, its keys left out taking their defaults.
fn robot_setup(r: &RobotFile, err: &ErrFn) -> Result<RobotSetup, ScenarioLoadError> {
    Ok(RobotSetup {
        drive: match &r.drive {
            None => RobotDrive::default(),
            Some(d) => match d.get_ref().as_str() {
                "kinematic" => RobotDrive::Kinematic,
                "finite-force" => RobotDrive::FiniteForce,
                other => {
                    return Err(err(
                        d.span(),
                        format!("`drive` is `{other}`; expected \"kinematic\" or \"finite-force\""),
                    ));
                }
            },
        },
        start: match &r.start {
            Some(p) => pose(p, "start", err)?,
            None => DEFAULT_ROBOT_START,
        },
        odometry_noise: match &r.odometry_noise {
            Some(v) => *non_negative_within(v, "odometry_noise", MAX_ODOMETRY_NOISE, "", err)?,
            None => DEFAULT_ODOMETRY_NOISE,
        },
        localization: match &r.localization {
            None => Some(DEFAULT_LOCALIZATION),
            Some(v) => localization(v, err)?,
        },
        ir_noise_scale: match &r.ir_noise_scale {
            Some(v) => *non_negative_within(v, "ir_noise_scale", MAX_IR_NOISE_SCALE, "", err)?,
            None => 1.0,
        },
    })
}

/// Refuses a robot that starts overlapping the object, naming the start that places it.
fn check_start_clearance(
    file: &ScenarioFile,
    object: &ObjectSpec,
    robot: &RobotSetup,
    err: &ErrFn,
) -> Result<(), ScenarioLoadError> {
    let clearance_mm = start_clearance_mm(object, robot);
    if clearance_mm < 0.0 {
        let o = &file.object;
        let at = match (file.robot.as_ref().and_then(|r| r.start.as_ref()), &o.start) {
            (Some(p), _) | (None, Some(p)) => p.span(),
            (None, None) => o.shape.span(),
        };
        return Err(err(
            at,
            format!(
                "the robot starts overlapping the object: clearance {clearance_mm:.1} mm between the robot's body and the object's border, at least 0 mm needed"
            ),
        ));
    }
    Ok(())
}

/// Bounds of the numbers of a scenario (the lower bounds of the ones that must be
/// positive keep the physics away from dividing by almost nothing).
const MASS_KG: (f64, f64) = (0.001, 10.0);
const MAX_FRICTION: f64 = 2.0;
const MAX_ODOMETRY_NOISE: f64 = 0.5;
const MAX_IR_NOISE_SCALE: f64 = 100.0;
const LOCALIZATION_PERIOD_S: (f64, f64) = (0.01, 3600.0);
const MAX_LOCALIZATION_NOISE_MM: f64 = 100.0;
const MAX_LOCALIZATION_NOISE_DEG: f64 = 45.0;
const MAX_TOLERANCE_MM: f64 = 1000.0;
const MAX_TOLERANCE_DEG: f64 = 180.0;
const MAX_PUSHES: i64 = 10_000;

/// Why `name` cannot be a scenario name, if it cannot.
fn bad_name(name: &str) -> Option<String> {
    if name.is_empty() {
        return Some("`name` is empty".into());
    }
    if name.chars().count() > MAX_SCENARIO_NAME_LEN {
        return Some(format!(
            "`name` is longer than {MAX_SCENARIO_NAME_LEN} characters"
        ));
    }
    if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Some(format!(
            "`name` {name:?} is not a plain name: use letters, digits, `-` and `_` (it names the AG file)"
        ));
    }
    None
}

/// Space between the robot's body and the object's border at their starts, mm (negative:
/// they overlap).
fn start_clearance_mm(object: &ObjectSpec, robot: &RobotSetup) -> f64 {
    let body_radius = RobotDescription::epuck().body_radius;
    let o = object.start;
    let p = o.to_local(robot.start.position());
    let to_border = match &object.shape {
        ObjectShape::Polygon(poly) if poly.contains(p) => -poly.border_distance(p),
        ObjectShape::Polygon(poly) => poly.border_distance(p),
        ObjectShape::Circle { radius } => p.length() - radius,
    };
    (to_border - body_radius) * 1e3
}

fn positive_within<'v>(
    v: &'v Spanned<f64>,
    key: &str,
    lo: f64,
    hi: f64,
    unit: &str,
    err: &ErrFn,
) -> Result<&'v f64, ScenarioLoadError> {
    let x = *v.get_ref();
    if x.is_finite() && x >= lo && x <= hi {
        Ok(v.get_ref())
    } else {
        Err(err(
            v.span(),
            format!(
                "`{key}` must be a positive number from {lo} to {hi}{}, got {x}",
                with_space(unit)
            ),
        ))
    }
}

fn non_negative_within<'v>(
    v: &'v Spanned<f64>,
    key: &str,
    hi: f64,
    unit: &str,
    err: &ErrFn,
) -> Result<&'v f64, ScenarioLoadError> {
    let x = *v.get_ref();
    if x.is_finite() && (0.0..=hi).contains(&x) {
        Ok(v.get_ref())
    } else {
        Err(err(
            v.span(),
            format!(
                "`{key}` must be a non-negative number of at most {hi}{}, got {x}",
                with_space(unit)
            ),
        ))
    }
}

fn with_space(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    }
}

/// Whether a point (mm) lies in the arena.
fn in_arena(x_mm: f64, y_mm: f64) -> bool {
    x_mm.abs() <= ARENA_HALF_SIZE_MM && y_mm.abs() <= ARENA_HALF_SIZE_MM
}

fn pose(p: &Spanned<PoseFile>, key: &str, err: &ErrFn) -> Result<Pose, ScenarioLoadError> {
    let v = p.get_ref();
    if ![v.x_mm, v.y_mm, v.theta_deg].iter().all(|x| x.is_finite()) {
        return Err(err(
            p.span(),
            format!("`{key}` holds a number that is not finite"),
        ));
    }
    if !in_arena(v.x_mm, v.y_mm) {
        return Err(err(
            p.span(),
            format!(
                "`{key}` ({}, {}) mm lies beyond the arena's +-{ARENA_HALF_SIZE_MM} mm",
                v.x_mm, v.y_mm
            ),
        ));
    }
    if v.theta_deg.abs() > MAX_POSE_ANGLE_DEG {
        return Err(err(
            p.span(),
            format!(
                "`{key}.theta_deg` is {}, beyond +-{MAX_POSE_ANGLE_DEG} deg",
                v.theta_deg
            ),
        ));
    }
    Ok(Pose::new(
        v.x_mm * 1e-3,
        v.y_mm * 1e-3,
        v.theta_deg.to_radians(),
    ))
}

fn localization(
    v: &Spanned<toml::Value>,
    err: &ErrFn,
) -> Result<Option<Localization>, ScenarioLoadError> {
    match v.get_ref() {
        toml::Value::String(s) if s == "off" => Ok(None),
        toml::Value::String(s) => Err(err(
            v.span(),
            format!(
                "`localization` is `{s}`; expected \"off\" or {{ period_s, noise_mm, noise_deg }}"
            ),
        )),
        other => {
            let l: LocalizationFile = other.clone().try_into().map_err(|e: toml::de::Error| {
                err(v.span(), format!("`localization`: {}", e.message()))
            })?;
            let (lo, hi) = LOCALIZATION_PERIOD_S;
            if !(l.period_s.is_finite() && (lo..=hi).contains(&l.period_s)) {
                return Err(err(
                    v.span(),
                    format!(
                        "`localization.period_s` must be positive, from {lo} to {hi} s, got {}",
                        l.period_s
                    ),
                ));
            }
            for (key, x, hi, unit) in [
                ("noise_mm", l.noise_mm, MAX_LOCALIZATION_NOISE_MM, "mm"),
                ("noise_deg", l.noise_deg, MAX_LOCALIZATION_NOISE_DEG, "deg"),
            ] {
                if !(x.is_finite() && (0.0..=hi).contains(&x)) {
                    return Err(err(
                        v.span(),
                        format!(
                            "`localization` noise must be non-negative and finite: `{key}` must be from 0 to {hi} {unit}, got {x}"
                        ),
                    ));
                }
            }
            Ok(Some(Localization {
                period_s: l.period_s,
                noise_m: l.noise_mm * 1e-3,
                noise_rad: l.noise_deg.to_radians(),
            }))
        }
    }
}

/// The `[[world_change]]` entries, checked: each at a finite time from 0 to
/// [`MAX_WORLD_CHANGE_AT_S`], in order of time, changing the floor friction and/or the
/// mass within the bounds of the `[object]` keys of the same names.
fn world_changes(
    entries: &[Spanned<WorldChangeFile>],
    err: &ErrFn,
) -> Result<Vec<WorldChange>, ScenarioLoadError> {
    if entries.len() > MAX_WORLD_CHANGES {
        return Err(err(
            entries[MAX_WORLD_CHANGES].span(),
            format!(
                "{} `[[world_change]]` entries, at most {MAX_WORLD_CHANGES} allowed",
                entries.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(entries.len());
    for entry in entries {
        let c = entry.get_ref();
        let at_s = *c.at_s.get_ref();
        if !(at_s.is_finite() && (0.0..=MAX_WORLD_CHANGE_AT_S).contains(&at_s)) {
            return Err(err(
                c.at_s.span(),
                format!(
                    "`world_change.at_s` must be a non-negative number of at most {MAX_WORLD_CHANGE_AT_S} s, got {at_s}"
                ),
            ));
        }
        if let Some(prev) = out.last().map(|p: &WorldChange| p.at_s)
            && at_s < prev
        {
            return Err(err(
                c.at_s.span(),
                format!(
                    "`world_change.at_s` is {at_s} s, before the previous change's {prev} s: list the changes in order of time"
                ),
            ));
        }
        if c.floor_friction.is_none() && c.mass_kg.is_none() {
            return Err(err(
                entry.span(),
                "a `[[world_change]]` changes nothing: give `floor_friction` and/or `mass_kg`"
                    .into(),
            ));
        }
        let floor_friction = match &c.floor_friction {
            Some(v) => Some(*non_negative_within(
                v,
                "world_change.floor_friction",
                MAX_FRICTION,
                "",
                err,
            )?),
            None => None,
        };
        let mass_kg = match &c.mass_kg {
            Some(v) => Some(*positive_within(
                v,
                "world_change.mass_kg",
                MASS_KG.0,
                MASS_KG.1,
                "kg",
                err,
            )?),
            None => None,
        };
        out.push(WorldChange {
            at_s,
            floor_friction,
            mass_kg,
        });
    }
    Ok(out)
}

fn task(t: &TaskFile, err: &ErrFn) -> Result<TaskSpec, ScenarioLoadError> {
    let kind = match t.kind.get_ref().as_str() {
        "learn" => TaskKind::Learn,
        "trajectory" => TaskKind::Trajectory,
        "place" => TaskKind::Place,
        other => {
            return Err(err(
                t.kind.span(),
                format!("unknown task kind `{other}`; expected `learn`, `trajectory` or `place`"),
            ));
        }
    };
    let goal = match &t.goal {
        Some(g) => pose(g, "goal", err)?,
        None if kind == TaskKind::Place => {
            return Err(err(t.kind.span(), "a `place` task needs a `goal`".into()));
        }
        None => Pose::default(),
    };
    let (tolerance_m, tolerance_rad) = match &t.tolerance {
        Some(tol) => {
            let v = tol.get_ref();
            if !(v.mm.is_finite()
                && v.mm > 0.0
                && v.mm <= MAX_TOLERANCE_MM
                && v.deg.is_finite()
                && v.deg > 0.0
                && v.deg <= MAX_TOLERANCE_DEG)
            {
                return Err(err(
                    tol.span(),
                    format!(
                        "`tolerance` must hold positive `mm` (at most {MAX_TOLERANCE_MM}) and `deg` (at most {MAX_TOLERANCE_DEG}), got {} mm and {} deg",
                        v.mm, v.deg
                    ),
                ));
            }
            (v.mm * 1e-3, v.deg.to_radians())
        }
        None => (0.01, 10f64.to_radians()),
    };
    let path = match &t.path_mm {
        Some(p) => {
            if p.get_ref().len() < 2 {
                return Err(err(p.span(), "`path_mm` needs at least 2 points".into()));
            }
            if p.get_ref().len() > 32 {
                return Err(err(p.span(), "`path_mm` holds more than 32 points".into()));
            }
            if p.get_ref().iter().flatten().any(|x| !x.is_finite()) {
                return Err(err(
                    p.span(),
                    "`path_mm` holds a number that is not finite".into(),
                ));
            }
            if let Some(k) = p.get_ref().iter().position(|q| !in_arena(q[0], q[1])) {
                return Err(err(
                    p.span(),
                    format!(
                        "`path_mm` point {} lies beyond the arena's +-{ARENA_HALF_SIZE_MM} mm",
                        k + 1
                    ),
                ));
            }
            p.get_ref()
                .iter()
                .map(|q| DVec2::new(q[0], q[1]) * 1e-3)
                .collect()
        }
        None if kind == TaskKind::Trajectory => {
            return Err(err(
                t.kind.span(),
                "a `trajectory` task needs `path_mm`".into(),
            ));
        }
        None => Vec::new(),
    };
    let keep_heading_rad = match &t.keep_heading_deg {
        Some(h) if kind != TaskKind::Trajectory => {
            return Err(err(
                h.span(),
                "`keep_heading_deg` belongs to a `trajectory` task".into(),
            ));
        }
        Some(h) if *h.get_ref() > 0.0 && *h.get_ref() <= 180.0 => Some(h.get_ref().to_radians()),
        Some(h) => {
            return Err(err(
                h.span(),
                format!(
                    "`keep_heading_deg` must be in (0, 180] degrees, got {}",
                    h.get_ref()
                ),
            ));
        }
        None => None,
    };
    let max_pushes = match &t.max_pushes {
        Some(m) if (1..=MAX_PUSHES).contains(m.get_ref()) => *m.get_ref() as u32,
        Some(m) => {
            return Err(err(
                m.span(),
                format!(
                    "`max_pushes` must be positive, at most {MAX_PUSHES}, got {}",
                    m.get_ref()
                ),
            ));
        }
        None => 150,
    };
    let seed = match &t.seed {
        Some(s) if *s.get_ref() >= 0 => *s.get_ref() as u64,
        Some(s) => {
            return Err(err(
                s.span(),
                format!("`seed` must be non-negative, got {}", s.get_ref()),
            ));
        }
        None => 7,
    };
    Ok(TaskSpec {
        kind,
        goal,
        tolerance_m,
        tolerance_rad,
        path,
        keep_heading_rad,
        max_pushes,
        seed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_builtin_loads_with_the_spec_figures() {
        for name in BUILTIN_NAMES {
            let s = Scenario::builtin(name).unwrap();
            assert_eq!(s.name, name);
            assert_eq!(s.object.mass, 0.1);
            assert_eq!(s.object.floor_friction, 0.4);
            assert_eq!(s.object.contact_friction, 0.3);
            assert_eq!(s.robot.odometry_noise, 0.005);
            assert!(s.robot.localization.is_some());
        }
        let tri = Scenario::builtin("triangle").unwrap();
        // Equilateral, 100 mm side: area sqrt(3)/4 * a^2.
        assert!((tri.object.shape.area() - 3f64.sqrt() / 4.0 * 0.01).abs() < 1e-12);
        assert_eq!(tri.object.shape.symmetry_order(), 3);
        let l = Scenario::builtin("lshape").unwrap();
        assert!((l.object.shape.area() - 4.0 * 0.03 * 0.03).abs() < 1e-12);
        assert_eq!(l.object.shape.symmetry_order(), 1);
        assert_eq!(
            Scenario::builtin("square")
                .unwrap()
                .object
                .shape
                .symmetry_order(),
            4
        );
        assert_eq!(
            Scenario::builtin("circle")
                .unwrap()
                .object
                .shape
                .symmetry_order(),
            0
        );
    }

    #[test]
    fn the_drive_is_finite_force_unless_the_scenario_asks_for_the_kinematic_robot() {
        for name in BUILTIN_NAMES {
            let s = Scenario::builtin(name).unwrap();
            assert_eq!(s.robot.drive, RobotDrive::FiniteForce);
        }
        let base = include_str!("../scenarios/triangle.toml");
        let text = base.replace("[robot]\n", "[robot]\ndrive = \"finite-force\"\n");
        let s = Scenario::parse(&text, "ff.toml").unwrap();
        assert_eq!(s.robot.drive, RobotDrive::FiniteForce);
        let text = base.replace("[robot]\n", "[robot]\ndrive = \"kinematic\"\n");
        assert_eq!(
            Scenario::parse(&text, "k.toml").unwrap().robot.drive,
            RobotDrive::Kinematic
        );
    }

    #[test]
    fn an_unknown_drive_is_refused_with_its_line() {
        let base = include_str!("../scenarios/triangle.toml");
        let text = base.replace("[robot]\n", "[robot]\ndrive = \"dynamic\"\n");
        let line = text.lines().position(|l| l.starts_with("drive")).unwrap() + 1;
        let msg = Scenario::parse(&text, "bad.toml").unwrap_err().to_string();
        assert_eq!(
            msg,
            format!(
                "bad.toml:{line}: `drive` is `dynamic`; expected \"kinematic\" or \"finite-force\""
            )
        );
    }

    #[test]
    fn polygons_are_centred_on_their_centroid() {
        let l = Scenario::builtin("lshape").unwrap();
        let ObjectShape::Polygon(p) = &l.object.shape else {
            panic!()
        };
        assert!(p.centroid().length() < 1e-12);
    }

    fn with_world_changes(extra: &str) -> String {
        format!("{}\n{extra}", include_str!("../scenarios/triangle.toml"))
    }

    #[test]
    fn world_changes_are_read_in_si_units_in_order_of_time() {
        let text = with_world_changes(
            "[[world_change]]\nat_s = 12.5\nfloor_friction = 0.25\n\n[[world_change]]\nat_s = 30\nmass_kg = 0.3\nfloor_friction = 0.1\n",
        );
        let s = Scenario::parse(&text, "w.toml").expect("valid");
        assert_eq!(
            s.world_changes,
            vec![
                WorldChange {
                    at_s: 12.5,
                    floor_friction: Some(0.25),
                    mass_kg: None
                },
                WorldChange {
                    at_s: 30.0,
                    floor_friction: Some(0.1),
                    mass_kg: Some(0.3)
                },
            ]
        );
        // None by default, and never in what the estimator and the planners get.
        assert!(
            Scenario::builtin("triangle")
                .unwrap()
                .world_changes
                .is_empty()
        );
    }

    #[test]
    fn a_bad_world_change_is_refused_with_its_file_line_and_reason() {
        let cases = [
            (
                "[[world_change]]\nat_s = -1\nmass_kg = 0.2\n",
                "at_s = -1",
                "`world_change.at_s` must be a non-negative number",
            ),
            (
                "[[world_change]]\nat_s = nan\nmass_kg = 0.2\n",
                "at_s = nan",
                "`world_change.at_s` must be a non-negative number",
            ),
            (
                "[[world_change]]\nat_s = 5\nfloor_friction = 2.5\n",
                "floor_friction = 2.5",
                "`world_change.floor_friction` must be a non-negative number of at most 2",
            ),
            (
                "[[world_change]]\nat_s = 5\nmass_kg = 0\n",
                "mass_kg = 0",
                "`world_change.mass_kg` must be a positive number from 0.001 to 10 kg",
            ),
            (
                "[[world_change]]\nat_s = 5\nfriction = 0.2\n",
                "friction = 0.2",
                "unknown field `friction`",
            ),
            (
                "[[world_change]]\nat_s = 5\nmass_kg = 0.2\n[[world_change]]\nat_s = 4\nmass_kg = 0.3\n",
                "at_s = 4",
                "before the previous change's 5 s",
            ),
            (
                "[[world_change]]\nat_s = 5\n",
                "[[world_change]]",
                "changes nothing",
            ),
        ];
        for (extra, at, reason) in cases {
            let text = with_world_changes(extra);
            let line = text.lines().position(|l| l == at).expect("the bad line") + 1;
            let msg = Scenario::parse(&text, "bad.toml").unwrap_err().to_string();
            assert!(
                msg.starts_with(&format!("bad.toml:{line}: ")) && msg.contains(reason),
                "{extra:?}: {msg}"
            );
        }
    }
}
