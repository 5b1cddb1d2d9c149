//! Same seed, same world; and a reset puts everything where it is asked.

mod common;

use agp_physics::{SensorState, Sim};
use agp_world::Pose;
use common::*;
use glam::DVec2;

/// A few thousand steps of pushing the triangle with changing wheel speeds, recording
/// poses and senses at every step.
fn trajectory(seed: u64) -> Vec<(Pose, Pose, SensorState)> {
    let mut s = sim_with_seed(&builtin("triangle"), seed);
    s.reset(Pose::new(0.0, 0.0, 0.4), Pose::new(-0.1, 0.01, 0.0));
    (0..4000)
        .map(|k| {
            // Straight pushes with a slow sway: contact, turning and sliding.
            let sway = 0.03 * (k as f64 * 0.004).sin();
            s.step(0.1 - sway, 0.1 + sway);
            (s.robot_pose(), s.object_pose(), *s.sensors())
        })
        .collect()
}

fn bits(p: Pose) -> [u64; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()]
}

#[test]
fn the_same_seed_gives_bit_identical_trajectories() {
    let (a, b) = (trajectory(11), trajectory(11));
    let moved = a.last().unwrap().1.position().length();
    assert!(moved > 0.02, "the object was pushed ({moved} m)");
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!(bits(x.0), bits(y.0), "robot at step {k}");
        assert_eq!(bits(x.1), bits(y.1), "object at step {k}");
        let ir = |s: &SensorState| s.ir_raw.map(f32::to_bits);
        assert_eq!(ir(&x.2), ir(&y.2), "IR at step {k}");
        assert_eq!(
            bits(x.2.odometry),
            bits(y.2.odometry),
            "odometry at step {k}"
        );
        assert_eq!(
            (bits(x.2.fix), x.2.fix_seq),
            (bits(y.2.fix), y.2.fix_seq),
            "fix at step {k}"
        );
    }
}

#[test]
fn a_different_seed_gives_different_ir_noise() {
    let (a, b) = (trajectory(11), trajectory(12));
    // The noise does not move anything: the true poses are the same...
    assert_eq!(bits(a[3999].1), bits(b[3999].1));
    // ...but every reading in range differs.
    let mut compared = 0;
    for (x, y) in a.iter().zip(&b) {
        for k in 0..8 {
            if x.2.ir_raw[k] > 0.0 {
                assert_ne!(x.2.ir_raw[k], y.2.ir_raw[k]);
                compared += 1;
            }
        }
    }
    assert!(compared > 1000, "{compared} readings in range");
}

#[test]
fn reset_puts_object_and_robot_where_asked_and_odometry_at_the_robot() {
    let mut s = sim(&builtin("lshape"));
    // Push a while so there is motion, drift and contact to forget.
    s.reset(Pose::default(), Pose::new(-0.08, 0.0, 0.0));
    for _ in 0..1500 {
        s.step(0.128, 0.12);
    }
    assert!(s.object_velocity().0.length() > 0.0);
    let (object, robot) = (Pose::new(0.3, -0.2, 2.5), Pose::new(0.1, 0.15, -3.0));
    let sample = s.sensors().ir_sample;
    let steps = s.step_count();
    s.reset(object, robot);
    let o = s.object_pose();
    // The object's pose lives in rapier's f32: 0.3 m to within its rounding (3e-8 m).
    assert!(
        (o.x - object.x).abs() < 1e-7 && (o.y - object.y).abs() < 1e-7,
        "{o:?}"
    );
    assert!((o.theta - object.theta).abs() < 1e-6, "{o:?}");
    assert_eq!(
        s.robot_pose(),
        robot,
        "the robot's pose is kept in f64, exactly"
    );
    assert_eq!(s.sensors().odometry, robot);
    assert_eq!(s.object_velocity(), (DVec2::ZERO, 0.0));
    assert_eq!(
        s.sensors().ir_sample,
        sample + 1,
        "a fresh IR sample at once"
    );
    assert_eq!(s.step_count(), steps, "time goes on");
    assert!(!s.in_contact());
    // At rest it stays put.
    for _ in 0..100 {
        s.step(0.0, 0.0);
    }
    assert_eq!(s.object_pose(), o);
}

#[test]
fn wheel_speeds_are_clamped_to_the_robots_maximum() {
    let mut s: Sim = sim(&quiet_kinematic("square"));
    s.reset(Pose::new(2.0, 2.0, 0.0), Pose::default());
    s.step(5.0, f64::NAN);
    assert_eq!(s.wheel_speeds(), (0.128, 0.0));
    s.step(-5.0, -5.0);
    assert_eq!(s.wheel_speeds(), (-0.128, -0.128));
}

#[test]
fn the_finite_force_robots_wheels_ramp_to_the_clamped_command_at_the_stated_rate() {
    let mut s: Sim = sim(&quiet("square"));
    s.reset(Pose::new(2.0, 2.0, 0.0), Pose::default());
    let dv = s.robot().wheel_accel * s.dt();
    // 0.128 m/s at 3 m/s^2 and 640 Hz: 27.3 steps of 4.7 mm/s each.
    let steps = (0.128 / dv).ceil() as usize;
    for k in 1..=steps + 5 {
        s.step(5.0, f64::NAN);
        let (l, r) = s.wheel_speeds();
        let want = (k as f64 * dv).min(0.128);
        assert!((l - want).abs() < 1e-12 && r == 0.0, "step {k}: {l} {r}");
    }
    // A reversal ramps down through zero at the same rate.
    s.step(-5.0, -5.0);
    let (l, r) = s.wheel_speeds();
    assert!((l - (0.128 - dv)).abs() < 1e-12 && (r + dv).abs() < 1e-12);
}
