//! Physics steps per second with the kinematic and with the finite-force robot, the robot
//! pushing each built-in object as `bench-physics` does (2 s pushes from the object's back,
//! a lateral offset changing per push, a slow sway of the heading):
//! `cargo run --release -p agp-physics --example step_cost [seconds per case] [drive]`.

use std::hint::black_box;
use std::time::Instant;

use agp_physics::{Sim, SimConfig};
use agp_world::{BUILTIN_NAMES, Pose, RobotDescription, RobotDrive, Scenario};

fn main() {
    let mut args = std::env::args().skip(1);
    let seconds: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(2.0);
    let only = args.next();
    let robot = RobotDescription::epuck();
    println!("object    drive          steps/s   x realtime");
    for name in BUILTIN_NAMES {
        for drive in [RobotDrive::Kinematic, RobotDrive::FiniteForce] {
            if only.as_deref().is_some_and(|o| o != drive.as_str()) {
                continue;
            }
            let Some(mut scenario) = Scenario::builtin(name) else {
                continue;
            };
            scenario.robot.drive = drive;
            let Ok(mut sim) = Sim::new(&scenario, &robot, SimConfig::default()) else {
                eprintln!("{name}: cannot build");
                continue;
            };
            let reach = scenario.object.shape.radius() + robot.body_radius + 0.005;
            let (mut steps, mut episode) = (0u64, 0u64);
            let start = Instant::now();
            while steps == 0 || start.elapsed().as_secs_f64() < seconds {
                let offset = 0.01 * ((episode % 5) as f64 - 2.0);
                sim.reset(Pose::default(), Pose::new(-reach, offset, 0.0));
                for k in 0..1280 {
                    let sway = 0.02 * (k as f64 * 0.01).sin();
                    sim.step(0.1 - sway, 0.1 + sway);
                    black_box(sim.in_contact());
                    black_box(sim.sensors());
                }
                steps += 1280;
                episode += 1;
            }
            let rate = steps as f64 / start.elapsed().as_secs_f64();
            println!(
                "{name:9} {:13} {rate:9.0} {:10.0}",
                drive.as_str(),
                rate / sim.config().step_hz
            );
        }
    }
}
