//! The IR proximity sensors: readings against the response table, what hides what, and
//! the 64 Hz sampling clock.

mod common;

use agp_physics::Sim;
use agp_world::{ObjectShape, Polygon, Pose, Scenario};
use common::*;
use glam::DVec2;

/// The response table of robot-and-world.md at its rows in range of the test rig:
/// (distance mm, raw, noise as a fraction of the reading).
const TABLE: [(f64, f64, f64); 7] = [
    (10.0, 1465.73, 0.007),
    (15.0, 601.46, 0.0406),
    (20.0, 383.84, 0.01472),
    (30.0, 234.93, 0.0241),
    (40.0, 158.03, 0.0287),
    (50.0, 120.0, 0.04225),
    (60.0, 104.09, 0.03065),
];

/// IR1 and IR8: rays at +-17 degrees from mounts (30, +-10) mm.
const IR1: usize = 0;
const IR8: usize = 7;

/// A 300 mm square wall, noise as in `noise_scale`, no odometry noise or fix.
fn wall(noise_scale: f64) -> Scenario {
    let mut s = quiet("square");
    s.object.shape = rectangle(0.3, 0.3);
    s.robot.ir_noise_scale = noise_scale;
    s
}

/// The robot at the origin facing +x, the wall's face at x = `face` (m).
fn facing_wall(scenario: &Scenario, face: f64) -> Sim {
    placed(scenario, Pose::new(face + 0.15, 0.0, 0.0), Pose::default())
}

/// Face position putting IR1's (and IR8's) ray `d` metres long: the ray leaves x = 30 mm
/// at 17 degrees, so it meets the plane x = face after (face - 0.030) / cos 17.
fn face_for(d: f64) -> f64 {
    0.030 + d * 17f64.to_radians().cos()
}

/// Steps until `n` new IR samples have come, handing each to `f`.
fn samples(sim: &mut Sim, n: usize, mut f: impl FnMut(&[f32; 8])) {
    let mut last = sim.sensors().ir_sample;
    let mut got = 0;
    while got < n {
        sim.step(0.0, 0.0);
        let s = sim.sensors();
        if s.ir_sample != last {
            last = s.ir_sample;
            got += 1;
            f(&s.ir_raw);
        }
    }
}

#[test]
fn a_reading_against_distance_follows_the_response_table_within_its_noise() {
    let scenario = wall(1.0);
    let n = 300;
    for (d_mm, raw, frac) in TABLE {
        let mut sim = facing_wall(&scenario, face_for(d_mm * 1e-3));
        let mut readings = Vec::with_capacity(2 * n);
        samples(&mut sim, n, |ir| {
            readings.extend([ir[IR1] as f64, ir[IR8] as f64])
        });
        let count = readings.len() as f64;
        let mean = readings.iter().sum::<f64>() / count;
        let sd = (readings.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (count - 1.0)).sqrt();
        let sigma = raw * frac;
        // The mean of 600 Gaussian readings lies within 4 standard errors of the table
        // (a 6e-5 chance to fail by bad luck), and the f32 geometry moves the distance by
        // ~1e-7 m, under 0.04 raw units on the steepest slope here.
        let se = sigma / count.sqrt();
        assert!(
            (mean - raw).abs() < 4.0 * se + 0.04,
            "{d_mm} mm: mean {mean}, table {raw} (se {se})"
        );
        // The sample deviation of 600 readings has a relative standard error of
        // 1 / sqrt(2 * 600) = 2.9 %: 15 % is five of them.
        assert!(
            (sd / sigma - 1.0).abs() < 0.15,
            "{d_mm} mm: spread {sd}, table {sigma}"
        );
    }
}

#[test]
fn the_robot_body_does_not_hide_the_object_from_its_own_sensors() {
    // The mounts sit inside the 37 mm body. With the wall touching the body's front
    // (face at x = 37 mm), IR1's ray runs (37 - 30) / cos 17 = 7.3 mm inside the body to
    // the wall and must read the table there, not the body's own edge.
    let scenario = wall(0.0);
    let sim = facing_wall(&scenario, 0.037);
    let d = (0.037 - 0.030) / 17f64.to_radians().cos();
    // Table between 5 mm (2133.33) and 10 mm (1465.73), linear.
    let expected = 2133.33 + (d * 1e3 - 5.0) / 5.0 * (1465.73 - 2133.33);
    for k in [IR1, IR8] {
        let r = sim.sensors().ir_raw[k] as f64;
        // f32 geometry: ~1e-7 m on a slope of 0.13 raw / um: 0.02 raw; f32 reading 1e-4.
        assert!(
            (r - expected).abs() < 0.1,
            "IR{}: {r}, table {expected}",
            k + 1
        );
    }
}

#[test]
fn sensors_facing_away_from_the_object_read_zero() {
    // Noise on: a sensor with nothing in range must still read exactly 0.
    let scenario = wall(1.0);
    let mut sim = facing_wall(&scenario, face_for(0.020));
    samples(&mut sim, 50, |ir| {
        // IR3..IR6 look sideways and backwards (+-90, +-150 degrees).
        for (k, r) in ir.iter().enumerate().take(6).skip(2) {
            assert_eq!(*r, 0.0, "IR{} read {r}", k + 1);
        }
        assert!(ir[IR1] > 0.0 && ir[IR8] > 0.0);
    });
    // Beyond the table's 70 mm the front sensors read 0 too.
    let mut far = facing_wall(&scenario, face_for(0.0705));
    samples(&mut far, 50, |ir| assert_eq!(ir, &[0.0; 8]));
}

#[test]
fn a_ray_into_the_l_notch_reads_the_nearest_face_not_the_far_one() {
    // With one object in the world, occlusion is the non-convex object hiding itself.
    // The L (file frame, mm): cells 0..90 x 0..30 and 60..90 x 30..60, centroid
    // (52.5, 22.5). A ray straight down (-y) at x = 20.8 mm crosses the notch (empty above
    // y = 30) and meets the top of the bottom row at y = 30, 30 mm before its bottom face
    // at y = 0. Robot at (20, 80) heading -107 degrees points IR1 (ray at +17) straight
    // down; its body clears the L (44.7 mm to the corner (60, 60) > 37 mm).
    let scenario = {
        let mut s = quiet("lshape");
        s.robot.ir_noise_scale = 0.0;
        s
    };
    let centroid = DVec2::new(0.0525, 0.0225);
    let robot_file = DVec2::new(0.020, 0.080);
    let heading = (-107f64).to_radians();
    let robot = (robot_file - centroid).extend(heading);
    let sim = placed(
        &scenario,
        Pose::default(),
        Pose::new(robot.x, robot.y, robot.z),
    );
    let mount = robot_file + DVec2::from_angle(heading).rotate(DVec2::new(0.030, 0.010));
    let (near, far) = (mount.y - 0.030, mount.y);
    assert!(
        near < 0.07 && far < 0.07,
        "both faces in range: the test discriminates"
    );
    let curve = &sim.robot().response;
    let r = sim.sensors().ir_raw[IR1] as f64;
    // Same f32 geometry bound as above.
    assert!(
        (r - curve.reading(near)).abs() < 0.1,
        "IR1 {r}: near face {}, far face {}",
        curve.reading(near),
        curve.reading(far)
    );
    assert!(!sim.in_contact());
}

#[test]
fn ir_is_sampled_at_64_hz_and_held_between_samples() {
    let scenario = wall(1.0);
    let mut sim = facing_wall(&scenario, face_for(0.020));
    let first = sim.sensors().ir_sample;
    let mut held = *sim.sensors();
    for step in 1..=640u64 {
        sim.step(0.0, 0.0);
        let s = *sim.sensors();
        // 640 Hz steps, 64 Hz samples: one sample every 10 steps exactly.
        assert_eq!(s.ir_sample, first + step / 10, "step {step}");
        if step % 10 != 0 {
            assert_eq!(s.ir_raw, held.ir_raw, "readings held between samples");
        } else {
            assert_ne!(s.ir_raw, held.ir_raw, "new noise at a new sample");
        }
        held = s;
    }
}

#[test]
fn a_non_convex_object_gets_a_collider_of_convex_pieces() {
    let l = sim(&builtin("lshape"));
    assert!(
        (2..=3).contains(&l.object_pieces()),
        "{} pieces",
        l.object_pieces()
    );
    let mut pentagon = builtin("square");
    pentagon.object.shape = ObjectShape::Polygon(
        Polygon::new(
            [
                [50.0, 0.0],
                [15.5, 47.6],
                [-40.5, 29.4],
                [-40.5, -29.4],
                [15.5, -47.6],
            ]
            .iter()
            .map(|p| DVec2::new(p[0], p[1]) * 1e-3)
            .collect(),
        )
        .unwrap()
        .centred(),
    );
    assert_eq!(sim(&pentagon).object_pieces(), 1);
}
