//! `agp probe push`: one push on a scenario, measured against ground truth.
//!
//! The probe starts its own lockstep `agp-physics` under a private instance
//! (`probe-<pid>`), drives it directly, and removes every file of that instance when it
//! is done, whatever happened.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use agp_runtime::{DriveError, Instance, LockstepDriver, TruthAccess, install_shutdown_handler};
use agp_shared_types::Pose2;
use agp_shared_types::angle::wrap_angle;
use agp_world::{RobotDescription, Scenario};
use anyhow::{Context, Result, anyhow, bail};
use serde::Serialize;

use agp_runtime::children::{GuardedChild, sibling_executable};

/// Gap (m) between the robot's shell and the object's farthest point at the start.
const START_GAP: f64 = 0.02;
/// How long the object is left to come to rest after the push (s of simulated time).
const SETTLE_S: f64 = 0.5;
/// Physics steps per simulated second: the pipeline's default.
const RATE_HZ: f64 = agp_shared_types::DEFAULT_RATE_HZ;
/// How long to wait for physics to answer before giving up (a safety net, not a check).
const PHYSICS_TIMEOUT: Duration = Duration::from_secs(30);

/// The options of `agp probe push` (its help is on the subcommand in `main.rs`).
#[derive(Debug, Clone, clap::Args)]
pub struct ProbeArgs {
    /// Built-in scenario (square, triangle, lshape, circle) or a scenario file.
    #[arg(long)]
    pub scenario: String,
    /// Where the robot starts, as an angle around the object in the object's frame
    /// (degrees; 0 = the object's +x side).
    #[arg(long, allow_negative_numbers = true)]
    pub angle_deg: f64,
    /// Direction of the drive, relative to the line to the object's centroid (degrees,
    /// counter-clockwise positive; strictly between -90 and 90).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.0)]
    pub alpha_deg: f64,
    /// How long the push lasts once the robot touches the object (milliseconds).
    #[arg(long, default_value_t = 2000)]
    pub duration_ms: u64,
    /// Robot speed, approach and push (millimetres per second; at most the E-puck's 128).
    #[arg(long, default_value_t = 100.0)]
    pub speed_mm_s: f64,
    /// Seed of the sensor noise (default: the scenario's). Ground truth does not depend
    /// on it.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Also write the result as JSON to this file (`-` for standard output).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What one push did to the object, world frame.
#[derive(Debug, Clone, Serialize)]
pub struct ProbeResult {
    pub scenario: String,
    pub angle_deg: f64,
    pub alpha_deg: f64,
    pub duration_ms: u64,
    pub speed_mm_s: f64,
    /// Whether the robot's body touched the object at all.
    pub contact: bool,
    /// Distance the robot drove before the first touch (mm), if it touched.
    pub approach_mm: Option<f64>,
    pub dx_mm: f64,
    pub dy_mm: f64,
    /// Counter-clockwise positive, in (-180, 180].
    pub rotation_deg: f64,
    /// How physics moved the robot: `kinematic` or `finite-force` (the scenario's
    /// `[robot] drive`).
    pub drive: String,
    /// Slip of the [left, right] wheel over the whole probe (mm): the travel the steppers
    /// were commanded, which odometry counts, minus the ground travel of the wheel's
    /// contact point along the robot's heading (from the true poses). 0 for the kinematic
    /// robot; for the finite-force robot, what a stalled push adds to the odometry's drift.
    pub wheel_slip_mm: [f64; 2],
}

/// Runs the probe; `Ok(None)` when it was interrupted (Ctrl-C) before it finished.
pub fn run(args: &ProbeArgs) -> Result<Option<ProbeResult>> {
    let robot = RobotDescription::epuck();
    check_args(args, &robot)?;
    let scenario = Scenario::resolve(&args.scenario)?;
    install_shutdown_handler();

    let name = format!("probe-{}", std::process::id());
    let instance = Instance::new(&name).map_err(|e| anyhow!("instance `{name}`: {e}"))?;
    // A probe of the same pid that died hard may have left files: they are ours.
    instance
        .remove_files()
        .context("cannot clear the probe's instance files")?;
    let mut physics = PhysicsChild::start(&name, &args.scenario, args.seed)?;
    let outcome = drive(&instance, &scenario, &robot, args);
    let stopped = physics.stop();
    let removed = instance.remove_files();
    let result = outcome?;
    stopped?;
    removed.with_context(|| format!("cannot remove the files of instance `{name}`"))?;
    if let Some(r) = &result {
        report(r, args.json.as_deref())?;
    }
    Ok(result)
}

fn check_args(args: &ProbeArgs, robot: &RobotDescription) -> Result<()> {
    for (flag, v) in [
        ("--angle-deg", args.angle_deg),
        ("--alpha-deg", args.alpha_deg),
    ] {
        if !v.is_finite() {
            bail!("{flag} must be a finite number of degrees, got {v}");
        }
    }
    if args.alpha_deg.abs() >= 90.0 {
        bail!(
            "--alpha-deg {} drives away from the object; use a value strictly between -90 and 90",
            args.alpha_deg
        );
    }
    let max = robot.max_wheel_speed * 1e3;
    if !(args.speed_mm_s > 0.0 && args.speed_mm_s <= max) {
        bail!(
            "--speed-mm-s {} is out of range; the E-puck drives at more than 0 and at most {max} mm/s",
            args.speed_mm_s
        );
    }
    if args.duration_ms == 0 || args.duration_ms > 600_000 {
        bail!(
            "--duration-ms {} is out of range; use 1 to 600000 ms",
            args.duration_ms
        );
    }
    Ok(())
}

/// Puts the robot on its start pose, drives to contact, pushes, settles.
fn drive(
    instance: &Instance,
    scenario: &Scenario,
    robot: &RobotDescription,
    args: &ProbeArgs,
) -> Result<Option<ProbeResult>> {
    let mut driver = match LockstepDriver::connect(
        instance,
        "probe",
        0,
        TruthAccess::GroundTruth,
        PHYSICS_TIMEOUT,
    ) {
        Ok(d) => d,
        Err(DriveError::Shutdown) => return Ok(None),
        Err(e) => return Err(e).context("cannot reach the probe's physics"),
    };
    let obj = scenario.object.start;
    let radius = scenario.object.shape.radius() + robot.body_radius + START_GAP;
    let side = obj.theta + args.angle_deg.to_radians();
    let (x, y) = (obj.x + radius * side.cos(), obj.y + radius * side.sin());
    let heading = wrap_angle(side + std::f64::consts::PI + args.alpha_deg.to_radians());
    let object_start = obj;
    let dt = 1.0 / RATE_HZ;
    let v = args.speed_mm_s * 1e-3;

    let mut slip = [0.0f64; 2];
    let half_axle = robot.axle_length / 2.0;
    macro_rules! step {
        ($l:expr, $r:expr) => {
            let before = driver.truth().robot;
            match driver.step($l, $r) {
                Ok(_) => {}
                Err(DriveError::Shutdown) => return Ok(None),
                Err(e) => return Err(e).context("physics stopped answering"),
            }
            let ground = wheel_ground_travel(before, driver.truth().robot, half_axle);
            slip[0] += $l * dt - ground[0];
            slip[1] += $r * dt - ground[1];
        };
    }

    match driver.reset(object_start, Pose2::new(x, y, heading)) {
        Ok(_) => {}
        Err(DriveError::Shutdown) => return Ok(None),
        Err(e) => return Err(e).context("physics refused the start poses"),
    }
    // Past twice the start radius the robot has crossed the object's whole extent.
    let approach_steps = (2.0 * radius / v / dt).ceil() as u64;
    let mut travelled_steps = 0u64;
    let mut contact = driver.truth().contact == 1;
    while !contact && travelled_steps < approach_steps {
        step!(v, v);
        travelled_steps += 1;
        contact = driver.truth().contact == 1;
    }
    let approach_mm = contact.then_some(travelled_steps as f64 * dt * v * 1e3);
    if contact {
        let push_steps = (args.duration_ms as f64 * 1e-3 / dt).round() as u64;
        for _ in 0..push_steps {
            step!(v, v);
        }
    }
    let settle_steps = (SETTLE_S / dt).round() as u64;
    for _ in 0..settle_steps {
        step!(0.0, 0.0);
    }
    let end = driver.truth().object;
    Ok(Some(ProbeResult {
        scenario: scenario.name.clone(),
        angle_deg: args.angle_deg,
        alpha_deg: args.alpha_deg,
        duration_ms: args.duration_ms,
        speed_mm_s: args.speed_mm_s,
        contact,
        approach_mm,
        dx_mm: (end.x - obj.x) * 1e3,
        dy_mm: (end.y - obj.y) * 1e3,
        rotation_deg: wrap_angle(end.theta - obj.theta).to_degrees(),
        drive: scenario.robot.drive.as_str().to_owned(),
        wheel_slip_mm: slip.map(|s| s * 1e3),
    }))
}

/// Ground travel of the [left, right] wheel's contact point (at +-`half_axle` across the
/// heading) from pose `a` to `b`, along the mean heading, m.
fn wheel_ground_travel(a: Pose2, b: Pose2, half_axle: f64) -> [f64; 2] {
    let mid = a.theta + wrap_angle(b.theta - a.theta) / 2.0;
    let (c, s) = (mid.cos(), mid.sin());
    [half_axle, -half_axle].map(|y| {
        let p = |q: Pose2| (q.x - y * q.theta.sin(), q.y + y * q.theta.cos());
        let (pa, pb) = (p(a), p(b));
        (pb.0 - pa.0) * c + (pb.1 - pa.1) * s
    })
}

fn report(r: &ProbeResult, json: Option<&Path>) -> Result<()> {
    let text = serde_json::to_string_pretty(r).context("cannot encode the result as JSON")?;
    if json == Some(Path::new("-")) {
        println!("{text}");
        return Ok(());
    }
    println!(
        "push on `{}` from {} deg, alpha {} deg, {} mm/s for {} ms",
        r.scenario, r.angle_deg, r.alpha_deg, r.speed_mm_s, r.duration_ms
    );
    match r.approach_mm {
        Some(a) => println!("  contact     yes, after {a:.1} mm of approach"),
        None => println!("  contact     no: the robot drove past the object"),
    }
    println!(
        "  moved       dx {:+.1} mm, dy {:+.1} mm ({:.1} mm, world frame)",
        r.dx_mm,
        r.dy_mm,
        r.dx_mm.hypot(r.dy_mm)
    );
    println!(
        "  rotated     {:+.1} deg (counter-clockwise positive)",
        r.rotation_deg
    );
    println!(
        "  wheel slip  left {:.1} mm, right {:.1} mm ({} robot)",
        r.wheel_slip_mm[0], r.wheel_slip_mm[1], r.drive
    );
    if let Some(path) = json {
        write_atomically(path, text.as_bytes())?;
        println!("  written     {}", path.display());
    }
    Ok(())
}

/// Writes through a temporary file next to `path` and renames it: a crash or a full disk
/// never leaves a half-written result in place of a good one.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile_in(dir, path)?;
    let write = tmp
        .1
        .write_all(bytes)
        .and_then(|()| tmp.1.write_all(b"\n"))
        .and_then(|()| tmp.1.sync_all());
    if let Err(e) = write {
        let _ = std::fs::remove_file(&tmp.0);
        return Err(e).with_context(|| format!("cannot write {}", tmp.0.display()));
    }
    std::fs::rename(&tmp.0, path).with_context(|| {
        let _ = std::fs::remove_file(&tmp.0);
        format!("cannot write {}", path.display())
    })
}

fn tempfile_in(dir: &Path, path: &Path) -> Result<(PathBuf, std::fs::File)> {
    let file_name = path
        .file_name()
        .ok_or_else(|| anyhow!("--json {}: not a file name", path.display()))?;
    let tmp = dir.join(format!(
        ".{}.{}.tmp",
        file_name.to_string_lossy(),
        std::process::id()
    ));
    let f = std::fs::File::create(&tmp)
        .with_context(|| format!("cannot create {} (for --json)", tmp.display()))?;
    Ok((tmp, f))
}

/// The probe's own lockstep physics process.
struct PhysicsChild(GuardedChild);

impl PhysicsChild {
    fn start(instance: &str, scenario: &str, seed: Option<u64>) -> Result<Self> {
        let exe = sibling_executable("agp-physics")?;
        let mut cmd = Command::new(&exe);
        cmd.args(["--instance", instance, "--scenario", scenario])
            .args(["--clock", "lockstep", "--idle-timeout-s", "30"])
            .args(["--rate-hz", &RATE_HZ.to_string()])
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        if let Some(seed) = seed {
            cmd.args(["--seed", &seed.to_string()]);
        }
        Ok(Self(GuardedChild::spawn("agp-physics", &mut cmd)?))
    }

    /// SIGTERM, a grace period, then SIGKILL; always reaped.
    fn stop(&mut self) -> Result<()> {
        self.0.stop(Duration::from_secs(5)).map(|_| ())
    }
}

/// Exit status of an interrupted probe (128 + SIGINT, as shells report it).
pub const INTERRUPTED: u8 = 130;
