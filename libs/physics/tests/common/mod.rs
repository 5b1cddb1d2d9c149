//! Helpers shared by the physics tests: scenarios, placements and pushes.
#![allow(dead_code)] // each test file uses its own subset

use agp_physics::{Sim, SimConfig};
use agp_world::{ObjectShape, Polygon, Pose, RobotDescription, Scenario};
use glam::DVec2;

/// Floor friction and gravity of the built-in scenarios: mu * g, m/s^2.
pub const MU_G: f64 = 0.4 * agp_physics::G;

/// A built-in scenario by name.
pub fn builtin(name: &str) -> Scenario {
    Scenario::builtin(name).expect("a built-in scenario")
}

/// A built-in scenario with noise-free IR and odometry and no overhead fix.
pub fn quiet(name: &str) -> Scenario {
    let mut s = builtin(name);
    s.robot.ir_noise_scale = 0.0;
    s.robot.odometry_noise = 0.0;
    s.robot.localization = None;
    s
}

/// [`quiet`] with the kinematic robot, which moves exactly as commanded: the closed forms
/// of the floor model assume a pusher that neither yields nor lags.
pub fn quiet_kinematic(name: &str) -> Scenario {
    let mut s = quiet(name);
    s.robot.drive = agp_world::RobotDrive::Kinematic;
    s
}

/// An axis-aligned rectangle object, w x h metres, centred on its centroid.
pub fn rectangle(w: f64, h: f64) -> ObjectShape {
    let (a, b) = (w / 2.0, h / 2.0);
    ObjectShape::Polygon(
        Polygon::new(vec![
            DVec2::new(-a, -b),
            DVec2::new(a, -b),
            DVec2::new(a, b),
            DVec2::new(-a, b),
        ])
        .expect("a rectangle is a valid polygon"),
    )
}

/// A simulation of `scenario` with the E-puck and the default configuration but `seed`.
pub fn sim_with_seed(scenario: &Scenario, seed: u64) -> Sim {
    let config = SimConfig {
        seed,
        ..SimConfig::default()
    };
    Sim::new(scenario, &RobotDescription::epuck(), config).expect("the scenario builds")
}

/// A simulation of `scenario` with the E-puck and the default configuration.
pub fn sim(scenario: &Scenario) -> Sim {
    sim_with_seed(scenario, 7)
}

/// A simulation with the object at rest at `object` and the robot at `robot`.
pub fn placed(scenario: &Scenario, object: Pose, robot: Pose) -> Sim {
    let mut s = sim(scenario);
    s.reset(object, robot);
    s
}

/// Drives both wheels at `speed` for `seconds`.
pub fn drive(sim: &mut Sim, speed: f64, seconds: f64) {
    let steps = (seconds / sim.dt()).round() as u64;
    for _ in 0..steps {
        sim.step(speed, speed);
    }
}

/// Steps with the wheels stopped until the object rests, at most `seconds`; returns
/// whether it came to rest.
pub fn settle(sim: &mut Sim, seconds: f64) -> bool {
    let steps = (seconds / sim.dt()).round() as u64;
    for _ in 0..steps {
        sim.step(0.0, 0.0);
        let (v, w) = sim.object_velocity();
        if v == DVec2::ZERO && w == 0.0 {
            return true;
        }
    }
    false
}
