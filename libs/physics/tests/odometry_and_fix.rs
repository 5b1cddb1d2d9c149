//! The robot's own pose estimate (wheel odometry at 64 Hz) and the overhead camera's fix.

mod common;

use agp_world::{Localization, Pose};
use common::*;
use std::f64::consts::PI;

#[test]
fn noise_free_odometry_follows_the_true_pose_along_arcs() {
    // Object far away; wheels on an arc, then a turn on the spot, then straight. The
    // kinematic robot: its body moves exactly as its wheels turn (the finite-force robot
    // lags while it gets up to speed, which `finite_force.rs` measures as slip).
    let sc = quiet_kinematic("square");
    let mut s = placed(&sc, Pose::new(2.0, 2.0, 0.0), Pose::new(-0.25, 0.0, 0.3));
    let legs = [(0.05, 0.1), (-0.08, 0.08), (0.12, 0.12)];
    for (l, r) in legs {
        for _ in 0..640 {
            s.step(l, r);
        }
        // Every leg lasts a whole number of odometry periods (640 steps = 64 updates) at
        // constant wheel speeds, so the 64 Hz arcs compose into the true 640 Hz ones: both
        // sides agree to rounding (~1e-15 per step).
        let (o, t) = (s.sensors().odometry, s.robot_pose());
        assert!(
            (o.x - t.x).abs() < 1e-12 && (o.y - t.y).abs() < 1e-12,
            "{o:?} vs {t:?}"
        );
        assert!((o.theta - t.theta).abs() < 1e-12);
    }
}

#[test]
fn odometry_drifts_with_the_spread_the_wheel_noise_implies() {
    // Driving straight at v for 1 s, each of the n = 64 updates sees travel s = v / 64
    // per wheel; the heading error grows by s (e_r - e_l) / axle per update, so after n
    // updates its standard deviation is sqrt(2 n) * sigma * s / axle.
    let (v, sigma, axle) = (0.1, 0.005, 0.052);
    let mut sc = quiet("square");
    sc.robot.odometry_noise = sigma;
    let runs = 120;
    let mut sq = 0.0;
    for seed in 0..runs {
        let mut s = sim_with_seed(&sc, seed);
        s.reset(Pose::new(3.0, 3.0, 0.0), Pose::default());
        drive(&mut s, v, 1.0);
        sq += s.sensors().odometry.theta.powi(2);
    }
    let sd = (sq / runs as f64).sqrt();
    let expected = (2.0f64 * 64.0).sqrt() * sigma * (v / 64.0) / axle;
    // The deviation of 120 zero-mean draws has a relative standard error of
    // 1 / sqrt(2 * 120) = 6.5 %: 25 % is nearly four of them.
    assert!(
        (sd / expected - 1.0).abs() < 0.25,
        "heading drift {sd} rad, expected {expected}"
    );
}

#[test]
fn overhead_fixes_come_every_period_with_the_stated_noise() {
    let mut sc = quiet("square");
    let (noise_m, noise_rad) = (0.001, 0.5 * PI / 180.0);
    sc.robot.localization = Some(Localization {
        period_s: 0.05,
        noise_m,
        noise_rad,
    });
    let mut s = placed(&sc, Pose::new(2.0, 2.0, 0.0), Pose::new(0.1, -0.2, 1.0));
    assert_eq!(s.sensors().fix_seq, 0, "no fix before the first period");
    let fixes = 400;
    let (mut sx, mut st) = (0.0, 0.0);
    for k in 1..=fixes {
        // 0.05 s at 640 Hz = 32 steps per fix, on a robot turning on the spot.
        for _ in 0..32 {
            s.step(-0.05, 0.05);
        }
        let (f, t) = (s.sensors().fix, s.robot_pose());
        assert_eq!(s.sensors().fix_seq, k, "one fix per period");
        sx += (f.x - t.x).powi(2) + (f.y - t.y).powi(2);
        st += agp_shared_types::angle::wrap_angle(f.theta - t.theta).powi(2);
    }
    let sd_xy = (sx / (2.0 * fixes as f64)).sqrt();
    let sd_theta = (st / fixes as f64).sqrt();
    // 800 position draws (relative standard error of the deviation 2.5 %) and 400 angle
    // draws (3.5 %): 15 % is four or more of them.
    assert!(
        (sd_xy / noise_m - 1.0).abs() < 0.15,
        "position noise {sd_xy} m"
    );
    assert!(
        (sd_theta / noise_rad - 1.0).abs() < 0.15,
        "heading noise {sd_theta} rad"
    );
}

#[test]
fn a_scenario_without_the_fix_never_reports_one() {
    let mut s = sim(&quiet("square"));
    drive(&mut s, 0.05, 3.0);
    assert_eq!(s.sensors().fix_seq, 0);
}
