//! The floor-friction checks of robot-and-world.md, against the quasi-static pushing model
//! (Mason, Lynch) and against closed-form sliding. The pusher is the kinematic robot, which
//! moves exactly as commanded, so that the closed forms hold; the finite-force robot's own
//! checks are in `finite_force.rs`.

mod common;

use agp_physics::{FloorModel, Sim, SimBuildError, SimConfig};
use agp_world::{Pose, RobotDescription};
use common::*;
use glam::DVec2;
use std::f64::consts::FRAC_PI_2;

/// Rotation (rad) a push may leave where the physics allows none. The pushes below are
/// mirror-symmetric (or, for the L, balanced: a translating plate feels its floor friction
/// at the centroid), so rotation can only come from rounding in rapier's f32 state
/// (~1e-7 per step); 1e-4 rad stays far below the tens of degrees an offset push gives.
const NO_ROTATION: f64 = 1e-4;

/// Pushes the object, starting at rest at the origin, with the robot driving straight at
/// `speed` from `robot` for `seconds`, then stops the robot and lets the object settle.
fn push(name: &str, robot: Pose, speed: f64, seconds: f64) -> Sim {
    let mut s = placed(&quiet_kinematic(name), Pose::default(), robot);
    drive(&mut s, speed, seconds);
    assert!(settle(&mut s, 1.0), "the {name} came to rest");
    s
}

#[test]
fn a_push_through_the_centroid_moves_the_object_straight() {
    // Robot 100 mm behind the centroid on the x axis, pushing +x for 250 mm: more than
    // 150 mm of pushing after contact.
    for name in ["square", "circle", "lshape"] {
        let o = push(name, Pose::new(-0.1, 0.0, 0.0), 0.1, 2.5).object_pose();
        assert!(o.x > 0.15, "the {name} was pushed ({} m)", o.x);
        assert!(
            o.theta.abs() < NO_ROTATION,
            "the {name} turned by {} rad",
            o.theta
        );
        // Sideways drift allowed: the same rounding, times the push length (0.25 m).
        assert!(
            o.y.abs() < NO_ROTATION * 0.25,
            "the {name} drifted {} m sideways",
            o.y
        );
    }
    // The triangle pushed square onto its bottom edge, along its axis of symmetry.
    let o = push("triangle", Pose::new(0.0, -0.1, FRAC_PI_2), 0.1, 2.5).object_pose();
    assert!(o.y > 0.15);
    assert!(
        o.theta.abs() < NO_ROTATION && o.x.abs() < NO_ROTATION * 0.25,
        "{o:?}"
    );
}

#[test]
fn an_offset_push_turns_the_object_towards_the_side_not_pushed_more_for_a_larger_offset() {
    // The square's back face spans y = -30..30 mm. Pushing it at y = +d (its left half)
    // with a +x force gives a moment -d F about the centroid: the object turns clockwise
    // (theta < 0), towards its right side, the side not pushed. About 100 mm of pushing.
    let turn = |offset_m: f64| {
        push("square", Pose::new(-0.1, offset_m, 0.0), 0.1, 1.33)
            .object_pose()
            .theta
    };
    let (t10, t20) = (turn(0.010), turn(0.020));
    // "Turned" means clearly beyond rounding: at least a degree.
    assert!(t10 < -1f64.to_radians(), "10 mm offset turned {t10} rad");
    assert!(
        t20 < t10 - 1f64.to_radians(),
        "20 mm offset turned {t20} rad, 10 mm {t10} rad"
    );
    // The mirrored push turns the other way by the same angle (the setup is symmetric).
    let m10 = turn(-0.010);
    assert!((m10 + t10).abs() < NO_ROTATION, "mirror {m10} vs {t10}");
}

#[test]
fn once_the_robot_stops_the_object_stops_within_a_few_millimetres() {
    let v = 0.128; // the robot's top speed
    let mut s = placed(
        &quiet_kinematic("square"),
        Pose::default(),
        Pose::new(-0.1, 0.0, 0.0),
    );
    drive(&mut s, v, 1.5);
    let at_stop = s.object_pose();
    let dt = s.dt();
    let mut steps = 0;
    while s.object_velocity() != (DVec2::ZERO, 0.0) {
        s.step(0.0, 0.0);
        steps += 1;
        assert!(steps < 1000, "the object still moves after 1000 steps");
    }
    let slide = s.object_pose().x - at_stop.x;
    // The object left the robot at speed v and slides v^2 / (2 mu g) = 2.09 mm, less
    // v dt / 2 = 0.1 mm: semi-implicit Euler moves with the speed after each step's
    // deceleration (an arithmetic series). 1 % covers the last, partial step.
    let expected = v * v / (2.0 * MU_G) - v * dt / 2.0;
    assert!(
        (slide - expected).abs() < 0.01 * expected,
        "slide {slide} m, expected {expected} m"
    );
    // It stops after v / (mu g) = 33 ms, to within a step.
    let t_stop = v / MU_G;
    assert!(
        (steps as f64 * dt - t_stop).abs() <= 2.0 * dt,
        "{steps} steps to stop"
    );

    // A turning object (offset push) stops within a few millimetres too.
    let mut s = placed(
        &quiet_kinematic("square"),
        Pose::default(),
        Pose::new(-0.1, 0.015, 0.0),
    );
    drive(&mut s, v, 1.5);
    let at_stop = s.object_pose();
    assert!(settle(&mut s, 0.5), "the turning object rests within 0.5 s");
    let moved = (s.object_pose().position() - at_stop.position()).length();
    assert!(
        moved < 0.005,
        "the turning object slid {moved} m after the stop"
    );
}

#[test]
fn a_disc_and_a_square_of_equal_mass_slide_the_same_distance_under_the_same_push() {
    // Both 0.1 kg; each starts with its back 20 mm ahead of the robot's front (radius
    // 37 mm) and is pushed at 0.1 m/s for 2 s, then left to slide.
    let moved = |name: &str, half_depth: f64| {
        let robot = Pose::new(-(half_depth + 0.020 + 0.037), 0.0, 0.0);
        push(name, robot, 0.1, 2.0).object_pose().x
    };
    let (square, disc) = (moved("square", 0.030), moved("circle", 0.035));
    // Same robot travel and gap, and the same post-stop slide: a translating plate feels
    // mu m g whatever its shape. Only the contact solver's slop (0.05 mm) differs between
    // a flat face and a round one.
    assert!(
        (square - disc).abs() < 1e-4,
        "square {square} m, disc {disc} m"
    );
    assert!(
        (square - 0.18).abs() < 0.003,
        "moved {square} m: 200 mm of robot travel less the 20 mm gap, plus the slide"
    );
}

#[test]
fn a_kicked_object_slides_v0_squared_over_2_mu_g_and_never_reverses() {
    let (v0, dir) = (0.5, DVec2::new(0.6, 0.8));
    for name in ["square", "triangle", "lshape", "circle"] {
        // Robot far away (0.7 m), object turned 0.3 rad: friction must not care.
        let mut s = placed(
            &quiet_kinematic(name),
            Pose::new(0.0, 0.0, 0.3),
            Pose::new(-0.5, 0.5, 0.0),
        );
        s.set_object_velocity(dir * v0, 0.0);
        let mut progress = 0.0;
        for _ in 0..640 {
            s.step(0.0, 0.0);
            let (v, w) = s.object_velocity();
            assert!(v.dot(dir) >= 0.0, "the {name} reversed");
            // Pure translation: the friction of a uniform plate acts at its centroid, so
            // any spin is the rounding of a sum of ~64 torques of ~1e-4 N m (~1e-18).
            assert!(w.abs() < 1e-9, "the {name} started turning ({w} rad/s)");
            let p = s.object_pose().position().dot(dir);
            assert!(p >= progress, "the {name} moved backwards");
            progress = p;
        }
        assert_eq!(
            s.object_velocity(),
            (DVec2::ZERO, 0.0),
            "the {name} rests after 1 s"
        );
        let d = s.object_pose().position().length();
        // Analytic 31.9 mm; semi-implicit Euler slides v0 dt / 2 = 0.4 mm (1.2 %) less.
        let analytic = v0 * v0 / (2.0 * MU_G);
        assert!(
            (d / analytic - 1.0).abs() < 0.02,
            "the {name} slid {d} m, analytic {analytic} m"
        );
        assert!(
            (s.object_pose().theta - 0.3).abs() < 1e-6,
            "the {name} kept its heading"
        );
    }
}

#[test]
fn a_spinning_disc_stops_after_the_analytic_angle() {
    // Uniform disc: friction torque (2/3) mu m g R, inertia m R^2 / 2, so it decelerates
    // at alpha = 4 mu g / (3 R) and turns w0^2 / (2 alpha) before stopping.
    let (w0, r) = (30.0, 0.035);
    let mut s = placed(
        &quiet_kinematic("circle"),
        Pose::default(),
        Pose::new(-0.5, 0.5, 0.0),
    );
    s.set_object_velocity(DVec2::ZERO, w0);
    assert!(settle(&mut s, 1.0));
    let expected = w0 * w0 / (2.0 * 4.0 * MU_G / (3.0 * r));
    // Ring-sector cells carry their load at their centroids, 0.55 % inside the ring's mean
    // radius (sinc of half the sector angle), and semi-implicit Euler turns
    // alpha dt / w0 = 0.8 % less: 3 % holds both.
    let turned = s.object_pose().theta;
    assert!(
        (turned / expected - 1.0).abs() < 0.03,
        "turned {turned} rad, expected {expected}"
    );
    assert!(
        s.object_pose().position().length() < 1e-9,
        "a spinning disc stays in place"
    );
}

#[test]
fn a_damping_floor_slows_an_object_exponentially() {
    let config = SimConfig {
        floor: FloorModel::Damping {
            linear: 2.0,
            angular: 2.0,
        },
        ..SimConfig::default()
    };
    let mut s = Sim::new(
        &quiet_kinematic("square"),
        &RobotDescription::epuck(),
        config,
    )
    .unwrap();
    s.reset(Pose::default(), Pose::new(-0.5, 0.5, 0.0));
    s.set_object_velocity(DVec2::new(0.2, 0.0), 0.0);
    drive(&mut s, 0.0, 1.0);
    // Velocity damping c: v(t) = v0 exp(-c t) = 0.2 exp(-2) = 27 mm/s after 1 s; rapier's
    // implicit factor 1 / (1 + c dt) per step differs by c^2 dt t / 2 = 0.3 %.
    let v = s.object_velocity().0.x;
    let expected = 0.2 * (-2.0f64).exp();
    assert!(
        (v / expected - 1.0).abs() < 0.01,
        "v {v}, expected {expected}"
    );
}

#[test]
fn a_bad_configuration_is_refused() {
    let robot = RobotDescription::epuck();
    let sc = builtin("square");
    let with = |config: SimConfig| Sim::new(&sc, &robot, config).err();
    assert!(matches!(
        with(SimConfig {
            step_hz: f64::NAN,
            ..SimConfig::default()
        }),
        Some(SimBuildError::StepRate { .. })
    ));
    assert!(matches!(
        with(SimConfig {
            step_hz: 10.0,
            ..SimConfig::default()
        }),
        Some(SimBuildError::StepRate { .. })
    ));
    assert_eq!(
        with(SimConfig {
            floor: FloorModel::Coulomb { cells: 0 },
            ..SimConfig::default()
        }),
        Some(SimBuildError::FootprintCells(0))
    );
    assert!(matches!(
        with(SimConfig {
            floor: FloorModel::Damping {
                linear: -1.0,
                angular: 0.0
            },
            ..SimConfig::default()
        }),
        Some(SimBuildError::Damping { .. })
    ));
}
