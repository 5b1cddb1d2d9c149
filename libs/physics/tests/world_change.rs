//! A scenario's `[[world_change]]`s, applied by physics at their simulated time, against
//! closed forms: a sliding object decelerates at mu g, before the change with the old
//! floor friction and after it with the new; an object made heavier than the robot's
//! traction can move stalls it.

mod common;

use agp_physics::G;
use agp_world::{Pose, RobotDescription, RobotDrive, WorldChange};
use common::*;
use glam::DVec2;

#[test]
fn a_sliding_object_decelerates_at_mu_g_before_and_at_the_new_mu_g_after_a_friction_change() {
    let mut scenario = quiet_kinematic("circle");
    assert_eq!(scenario.object.floor_friction, 0.4);
    // The change at 50 ms: step 32 at 640 Hz.
    scenario.world_changes = vec![WorldChange {
        at_s: 0.05,
        floor_friction: Some(0.25),
        mass_kg: None,
    }];
    let mut s = placed(&scenario, Pose::default(), Pose::new(-0.5, 0.5, 0.0));
    let dir = DVec2::new(0.6, 0.8);
    s.set_object_velocity(dir * 0.5, 0.0);
    let mut speeds = Vec::new();
    for _ in 0..96 {
        s.step(0.0, 0.0);
        speeds.push((s.sim_time(), s.object_velocity().0.dot(dir)));
    }
    let decel = |from: usize, to: usize| {
        let ((t0, v0), (t1, v1)) = (speeds[from], speeds[to]);
        (v0 - v1) / (t1 - t0)
    };
    // Coulomb friction on a translating plate: exactly mu g per second, whatever the
    // footprint (each cell mu * its load); 0.5 % covers the f32 velocities of rapier.
    for (what, got, mu) in [
        ("before", decel(2, 30), 0.4),
        ("after", decel(34, 95), 0.25),
    ] {
        assert!(
            (got / (mu * G) - 1.0).abs() < 5e-3,
            "{what} the change: {got} m/s^2, expected {} m/s^2",
            mu * G
        );
    }
    assert_eq!(s.world_changes_applied(), 1);
    assert_eq!(s.scenario().object.floor_friction, 0.25);
    let floor = s.floor_friction().expect("the Coulomb floor");
    assert!((floor.max_force() - 0.25 * 0.1 * G).abs() < 1e-12);
}

#[test]
fn an_object_made_heavier_than_the_robots_traction_can_move_stalls_the_finite_force_robot() {
    let robot = RobotDescription::epuck();
    let traction = robot.wheel_friction * robot.mass * G;
    let mut scenario = quiet("square");
    scenario.robot.drive = RobotDrive::FiniteForce;
    // 0.5 kg on the floor at 0.4: 1.96 N to slide it, more than the wheels' pull.
    let heavy = 0.5;
    assert!(0.4 * heavy * G > traction && 0.4 * 0.1 * G < traction);
    scenario.world_changes = vec![WorldChange {
        at_s: 1.0,
        floor_friction: None,
        mass_kg: Some(heavy),
    }];
    // The square's back face 1 mm ahead of the robot.
    let start = Pose::new(-(0.03 + robot.body_radius + 0.001), 0.0, 0.0);
    let mut s = placed(&scenario, Pose::default(), start);
    // Before the change (0.1 kg) a 0.5 s push at 100 mm/s moves it.
    drive(&mut s, 0.1, 0.5);
    settle(&mut s, 0.5);
    let light_moved = s.object_pose().x;
    assert!(light_moved > 0.03, "the light square moved {light_moved} m");
    // Wait past the change, then push again for 1 s: the heavy square stays.
    while s.sim_time() < 1.0 {
        s.step(0.0, 0.0);
    }
    let before = s.object_pose().position();
    let robot_before = s.robot_pose().position();
    drive(&mut s, 0.1, 1.0);
    let moved = (s.object_pose().position() - before).length();
    assert_eq!(s.world_changes_applied(), 1);
    assert_eq!(s.scenario().object.mass, heavy);
    assert!(moved < 1e-3, "the heavy square moved {moved} m");
    // The robot closed the gap left by the object's slide and then stalled against it.
    let robot_moved = (s.robot_pose().position() - robot_before).length();
    assert!(robot_moved < 0.03, "the robot went on {robot_moved} m");
}
