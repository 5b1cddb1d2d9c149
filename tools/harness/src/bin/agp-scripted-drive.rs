//! A scripted drive straight against physics, in the place of a planner: push the object
//! from a few sides, inferring contact from the IR readings with the estimator's own
//! perception code (`agp-perception`'s `ObjectTracker`, run here since no estimator runs),
//! and report what the robot sensed. A test and demonstration tool of the harness: the
//! planner process decides and perceives nothing itself (ARCHITECTURE.md).
//!
//! It runs as the `planner` process of a lockstep launch file, and takes a hot swap as a
//! planner does (`AGP_EPOCH`: tell the supervisor it is ready, wait for its epoch, report
//! its first applied command). The run ends when the script does.
//!
//! ```toml
//! [[process]]
//! name = "planner"
//! exec = "agp-scripted-drive"
//! args = ["--pushes", "4", "--push-ms", "2000"]
//! ends_run = true
//! ```

use std::time::Duration;

use agp_perception::{ObjectTracker, TrackerConfig};
use agp_planning::{PushPhase, PushRoutine, PushSettings};
use agp_runtime::{
    DriveError, Instance, LockstepDriver, SwapIn, TruthAccess, install_shutdown_handler,
};
use agp_shared_types::angle::wrap_angle;
use agp_shared_types::{Pose2, stage};
use agp_world::{RobotDescription, Scenario};
use anyhow::{Context, Result, bail};
use clap::Parser;

/// Pushes the object from sides evenly spread around it, over the pipeline.
///
/// Every option can also come from the environment the supervisor sets (`AGP_INSTANCE`,
/// `AGP_SCENARIO`, `AGP_CLOCK`, `AGP_EPOCH`).
#[derive(Debug, Parser)]
#[command(name = "agp-scripted-drive", version)]
struct Args {
    /// Instance name, shared with the other processes of the pipeline.
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    /// Built-in scenario or scenario file (the same physics runs).
    #[arg(long, env = "AGP_SCENARIO", default_value = "triangle")]
    scenario: String,
    /// Clock mode of the pipeline: the script resets the world between pushes and times
    /// them by steps, so it needs `lockstep`.
    #[arg(long, env = "AGP_CLOCK", default_value = "lockstep")]
    clock: String,
    /// Number of pushes, from sides evenly spread around the object.
    #[arg(long, default_value_t = 4)]
    pushes: u32,
    /// Push duration after contact, milliseconds.
    #[arg(long, default_value_t = 2000)]
    push_ms: u64,
    /// The epoch this drive runs at. 0: from the start. Set by the supervisor for a hot
    /// swap.
    #[arg(long, env = "AGP_EPOCH", default_value_t = 0)]
    epoch: u64,
}

/// Safety net of the waits on other processes.
const TIMEOUT: Duration = Duration::from_secs(30);

fn main() {
    agp_runtime::quiet_iceoryx2();
    if let Err(e) = run() {
        eprintln!("agp-scripted-drive: error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args = Args::parse();
    if args.clock != "lockstep" {
        bail!(
            "the scripted drive needs the lockstep clock, not `{}`",
            args.clock
        );
    }
    install_shutdown_handler();
    let full = Scenario::resolve(&args.scenario)?;
    // The drive reads the scenario's name and the experimenter's placement of the object,
    // nothing else of it.
    let (name, placement) = (full.name.clone(), full.experimenter().placement);
    drop(full);
    let instance = Instance::new(&args.instance)
        .with_context(|| format!("bad instance name `{}`", args.instance))?;
    script(&instance, &name, placement, &args)
}

fn script(instance: &Instance, scenario: &str, obj: Pose2, args: &Args) -> Result<()> {
    let robot = RobotDescription::epuck();
    // Without an estimator the scripted drive perceives for itself, with its code.
    let mut perception = ObjectTracker::new(&robot, TrackerConfig::default());
    let mut driver = match LockstepDriver::connect(
        instance,
        "planner",
        args.epoch,
        TruthAccess::SensesOnly,
        TIMEOUT,
    ) {
        Ok(d) => d,
        Err(DriveError::Shutdown) => return Ok(()),
        Err(e) => return Err(e).context("cannot reach physics"),
    };
    let mut swap_in = match SwapIn::start(instance, &mut driver, TIMEOUT) {
        Ok(s) => s,
        Err(_) if agp_runtime::shutdown_requested() => return Ok(()),
        Err(e) => return Err(e.into()),
    };
    let settings = PushSettings {
        push_duration: args.push_ms as f64 * 1e-3,
        ..PushSettings::default()
    };
    // Nothing tells how far the object reaches: start outside anything the grid holds.
    let radius = agp_planning::max_object_reach_m() + robot.body_radius + 0.03;
    println!(
        "scripted drive: {} pushes of `{scenario}`, {} ms each",
        args.pushes, args.push_ms
    );
    let mut k = 0;
    while k < args.pushes {
        let side = obj.theta + std::f64::consts::TAU * k as f64 / args.pushes.max(1) as f64;
        let (x, y) = (obj.x + radius * side.cos(), obj.y + radius * side.sin());
        let heading = wrap_angle(side + std::f64::consts::PI);
        // The learning phase puts the object back before each trial; so does the script.
        let push = (|| -> Result<(), DriveError> {
            let frame = *driver.reset(obj, Pose2::new(x, y, heading))?;
            let start_odo = frame.odometry;
            let mut routine = PushRoutine::new(settings, frame.sim_time_s);
            perception.reset();
            let mut peak = 0f32;
            loop {
                let f = *driver.frame();
                peak = peak.max(f.ir_raw[0].max(f.ir_raw[7]));
                if let PushPhase::Done { contact } = routine.phase() {
                    let odo = f.odometry;
                    println!(
                        "  push {}/{} from {:>5.1} deg: {}, front IR peak {:>6.0}, robot travelled {:>5.1} mm by odometry",
                        k + 1,
                        args.pushes,
                        side.to_degrees(),
                        if contact {
                            "contact inferred from IR"
                        } else {
                            "no contact"
                        },
                        peak,
                        (odo.x - start_odo.x).hypot(odo.y - start_odo.y) * 1e3
                    );
                    return Ok(());
                }
                perception.observe(f.ir_sample, &f.ir_raw, f.odometry, f.fix, f.fix_seq);
                let (l, r) = routine.step(
                    perception.front_gap(),
                    perception.stalled(),
                    f.sim_time_s,
                    f.ir_sample,
                );
                let next = driver.step(l, r)?;
                if let Some(s) = swap_in.take() {
                    let applied = next.timing.stamps_ns[stage::COMMAND_APPLIED];
                    s.driving(applied, TIMEOUT)
                        .map_err(|e| DriveError::Port(format!("{e:#}")))?;
                }
            }
        })();
        match push {
            Ok(()) => k += 1,
            Err(DriveError::PhysicsRestarted) => {
                // A new world: this push again, from its reset.
                println!("  physics restarted: push {} again", k + 1);
            }
            Err(DriveError::Shutdown) => return Ok(()),
            Err(e) => return Err(e.into()),
        }
    }
    println!("scripted drive done");
    Ok(())
}
