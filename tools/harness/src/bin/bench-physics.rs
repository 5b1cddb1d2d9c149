//! Physics steps per second: the robot pushing each built-in object (IR sampled at 64 Hz,
//! odometry, overhead fix: the whole step), and with no object in reach.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

use agp_physics::{Sim, SimConfig};
use agp_runtime::alloc_count;
use agp_world::{BUILTIN_NAMES, Pose, RobotDescription, Scenario};
use anyhow::{Context, Result, bail};
use clap::Parser;

/// Counts allocations, to report how many a step makes in a release build (none: the
/// simulator preallocates and rapier is patched, see vendor/rapier2d/PATCHES.md).
#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

/// Measures physics steps per second for each built-in object while the robot pushes it.
#[derive(Debug, Parser)]
#[command(name = "bench-physics", version)]
struct Args {
    /// Wall-clock seconds to measure each case.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Physics steps per second of simulated time.
    #[arg(long, default_value_t = 640.0)]
    step_hz: f64,
    /// Also write the figures as one JSON object to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Steps of one pushing episode: 2 s of simulated time at 640 Hz.
const EPISODE_STEPS: u64 = 1280;

struct Figures {
    steps: u64,
    wall_s: f64,
    contact_steps: u64,
    allocations: u64,
}

impl Figures {
    fn steps_per_s(&self) -> f64 {
        self.steps as f64 / self.wall_s
    }
}

/// Runs pushing episodes for `seconds`: each resets the object at the origin and the robot
/// 5 mm behind it with a lateral offset that changes from episode to episode, then pushes
/// at 0.1 m/s with a slow sway of the heading, so the object slides and turns.
/// `in_reach = false` parks the object 10 m away: the robot drives alone.
fn run(scenario: &Scenario, config: SimConfig, seconds: f64, in_reach: bool) -> Result<Figures> {
    let robot = RobotDescription::epuck();
    let mut sim = Sim::new(scenario, &robot, config)
        .with_context(|| format!("cannot build the world of scenario `{}`", scenario.name))?;
    let reach = scenario.object.shape.radius() + robot.body_radius + 0.005;
    let mut f = Figures {
        steps: 0,
        wall_s: 0.0,
        contact_steps: 0,
        allocations: 0,
    };
    let mut episode = 0u64;
    let start = Instant::now();
    let allocations = alloc_count::process_allocations();
    while f.steps == 0 || start.elapsed().as_secs_f64() < seconds {
        let offset = 0.01 * ((episode % 5) as f64 - 2.0);
        let object = if in_reach {
            Pose::default()
        } else {
            Pose::new(10.0, 10.0, 0.0)
        };
        sim.reset(object, Pose::new(-reach, offset, 0.0));
        for k in 0..EPISODE_STEPS {
            let sway = 0.02 * (k as f64 * 0.01).sin();
            sim.step(0.1 - sway, 0.1 + sway);
            f.contact_steps += u64::from(black_box(sim.in_contact()));
            black_box(sim.sensors());
        }
        f.steps += EPISODE_STEPS;
        episode += 1;
    }
    f.wall_s = start.elapsed().as_secs_f64();
    f.allocations = alloc_count::process_allocations() - allocations;
    Ok(f)
}

fn main() {
    alloc_count::enable();
    if let Err(e) = run_all() {
        eprintln!("bench-physics: error: {e:#}");
        std::process::exit(1);
    }
}

fn run_all() -> Result<()> {
    let args = Args::parse();
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        bail!("--seconds must be positive, got {}", args.seconds);
    }
    let config = SimConfig {
        step_hz: args.step_hz,
        ..SimConfig::default()
    };
    let wall = Instant::now();
    println!(
        "physics steps per second at {} Hz, {} s per case, pushing episodes of {} steps",
        args.step_hz, args.seconds, EPISODE_STEPS
    );
    println!(
        "{:<12} {:>12} {:>10} {:>12} {:>14}",
        "case", "steps/s", "x realtime", "in contact", "allocs/step"
    );
    let mut cases = serde_json::Map::new();
    let mut report = |name: &str, f: &Figures| {
        let contact = f.contact_steps as f64 / f.steps as f64;
        let allocs = f.allocations as f64 / f.steps as f64;
        println!(
            "{:<12} {:>12.0} {:>10.0} {:>11.0}% {:>14.2}",
            name,
            f.steps_per_s(),
            f.steps_per_s() / args.step_hz,
            100.0 * contact,
            allocs
        );
        cases.insert(
            name.to_owned(),
            serde_json::json!({
                "steps": f.steps,
                "wall_time_s": f.wall_s,
                "steps_per_s": f.steps_per_s(),
                "contact_fraction": contact,
                "allocations_per_step": allocs,
            }),
        );
    };
    for name in BUILTIN_NAMES {
        let scenario =
            Scenario::builtin(name).with_context(|| format!("no built-in scenario `{name}`"))?;
        let f = run(&scenario, config, args.seconds, true)?;
        report(name, &f);
    }
    let scenario = Scenario::builtin("square").context("no built-in scenario `square`")?;
    let f = run(&scenario, config, args.seconds, false)?;
    report("no-object", &f);

    if let Some(path) = &args.json {
        let doc = serde_json::json!({
            "benchmark": "physics",
            "step_hz": args.step_hz,
            "seconds_per_case": args.seconds,
            "cases": cases,
            "wall_time_s": wall.elapsed().as_secs_f64(),
        });
        let text = serde_json::to_string_pretty(&doc).context("cannot encode the figures")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write `{}`", path.display()))?;
    }
    Ok(())
}
