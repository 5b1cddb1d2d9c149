//! The finite-force robot (a scenario's `[robot] drive = "finite-force"`), against closed
//! forms: its traction limit mu_wheel * m_robot * g, an object's floor friction
//! mu_floor * m_obj * g, constant-acceleration start-ups and Coulomb's cone at the contact.
//! None of the bounds below is a figure this code printed: each comes from the E-puck's
//! description and the scenario.

mod common;

use agp_physics::{G, Sim};
use agp_world::{Pose, RobotDescription, RobotDrive, Scenario};
use common::*;
use glam::DVec2;

/// Speed of every push, m/s (the probe's default).
const V: f64 = 0.1;
/// The pushes last 2 s (1280 steps at 640 Hz).
const PUSH_S: f64 = 2.0;
/// The built-ins' floor and contact friction.
const MU_FLOOR: f64 = 0.4;
const MU_CONTACT: f64 = 0.3;
/// The square's half side, m: its back face is at x = -HALF.
const HALF: f64 = 0.03;
/// The robot starts this far (m) behind the face it pushes.
const GAP: f64 = 0.001;

/// The square of the built-ins with the given mass and drive, noise-free.
fn square(drive: RobotDrive, mass: f64) -> Scenario {
    let mut s = quiet("square");
    assert_eq!(
        (s.object.floor_friction, s.object.contact_friction),
        (MU_FLOOR, MU_CONTACT)
    );
    s.robot.drive = drive;
    s.object.mass = mass;
    s
}

/// The robot `GAP` behind the square's back face at lateral offset `y`, heading +x.
fn behind(y: f64) -> Pose {
    let r = RobotDescription::epuck().body_radius;
    Pose::new(-(HALF + r + GAP), y, 0.0)
}

/// Pushes straight at `V` for `PUSH_S`, calling `each` after every step.
fn push(sim: &mut Sim, mut each: impl FnMut(&Sim)) {
    let steps = (PUSH_S / sim.dt()).round() as u64;
    for _ in 0..steps {
        sim.step(V, V);
        each(sim);
    }
}

/// The E-puck's traction: the most its two wheels pull together, N.
fn traction() -> f64 {
    let r = RobotDescription::epuck();
    r.wheel_friction * r.mass * G
}

#[test]
fn the_builtin_scenarios_drive_the_finite_force_robot() {
    let s = sim(&square(RobotDrive::Kinematic, 0.1));
    assert_eq!(s.drive(), RobotDrive::Kinematic);
    assert_eq!(s.wheel_force_limits(), None);
    let s = sim(&quiet("square"));
    assert_eq!(s.drive(), RobotDrive::FiniteForce);
    // mu m g / 2 per wheel; the motor (25 mN m / 20.5 mm = 1.22 N) does not bind.
    let (pull, grip) = s.wheel_force_limits().expect("finite force");
    assert!((pull - traction() / 2.0).abs() < 1e-12 && (grip - traction() / 2.0).abs() < 1e-12);
}

#[test]
fn alone_the_robot_ramps_up_within_its_traction_and_rolls_without_slip() {
    // Nothing in reach: the motor controller ramps the wheels up at `wheel_accel` (3 m/s^2),
    // below the mu_w g = 7.85 m/s^2 that traction allows, so the body follows the ramped
    // wheels: the slip is the solver's give only, under 5 % of the V^2 / (2 mu_w g) =
    // 0.64 mm a robot without a ramp slips, and the body is where the ramped travel puts it.
    let mut s = placed(
        &square(RobotDrive::FiniteForce, 0.1),
        Pose::new(5.0, 5.0, 0.0),
        Pose::default(),
    );
    push(&mut s, |_| {});
    let mu_w = RobotDescription::epuck().wheel_friction;
    let unramped = V * V / (2.0 * mu_w * G);
    let (l, r) = s.wheel_slip();
    eprintln!(
        "alone: slip {:.4}/{:.4} mm, unramped V^2 / (2 mu_w g) = {:.4} mm",
        l * 1e3,
        r * 1e3,
        unramped * 1e3
    );
    for slip in [l, r] {
        assert!(
            slip.abs() < 0.05 * unramped,
            "slip {:.4} mm, unramped {:.4} mm",
            slip * 1e3,
            unramped * 1e3
        );
    }
    let a = s.robot().wheel_accel;
    assert!(a < mu_w * G, "the ramp stays within traction");
    let ramped = V * PUSH_S - V * V / (2.0 * a);
    let p = s.robot_pose();
    // Within the slip bound above plus the ramp's discreteness, V dt = 0.16 mm.
    assert!(
        (p.x - ramped).abs() < 0.05 * unramped + V * s.dt(),
        "{p:?}, ramped travel {ramped} m"
    );
    // Straight, to the f32 state's rounding over 1280 steps.
    assert!(p.y.abs() < 1e-6 && p.theta.abs() < 1e-5, "{p:?}");
    // Turning on the spot, the wheels roll too: dtheta = (v_r - v_l) t / axle, less the
    // ramp-up's w^2 / (2 a) per wheel.
    let axle = RobotDescription::epuck().axle_length;
    let mut s = placed(
        &square(RobotDrive::FiniteForce, 0.1),
        Pose::new(5.0, 5.0, 0.0),
        Pose::default(),
    );
    let w = 0.05;
    for _ in 0..640 {
        s.step(-w, w);
    }
    let turned = s.robot_pose().theta;
    let commanded = 2.0 * (w * 1.0 - w * w / (2.0 * a)) / axle;
    assert!(
        (turned - commanded).abs() < 2.0 * w * s.dt() / axle + 1e-3,
        "turned {turned} rad, ramped command {commanded} rad"
    );
    // The centre stays put to within f32 rounding and the motors' frames turning by
    // omega dt / 2 = 1.5 mrad within a step, against 50 mm of wheel travel: 50 um.
    assert!(
        s.robot_pose().position().length() < 5e-5,
        "the centre moved to {:?}",
        s.robot_pose()
    );
}

#[test]
fn a_light_object_is_pushed_as_the_kinematic_robot_pushes_it() {
    // 0.1 kg at mu 0.4 takes mu m g = 0.39 N to slide, a third of the robot's 1.26 N of
    // traction: the robot keeps its speed once it has it.
    let mass = 0.1;
    let run = |drive| {
        let mut s = placed(&square(drive, mass), Pose::default(), behind(0.0));
        let mut forces = Vec::new();
        push(&mut s, |s| {
            if let Some(c) = s.contact_impulse() {
                forces.push(c.normal_impulse / s.dt());
            }
        });
        // The finite-force robot ramps down (at 3 m/s^2, slower than the object's floor
        // deceleration mu_f g = 3.9 m/s^2), so it stops with the object pressed against
        // it, both at rest to within the solver's rounding.
        for _ in 0..320 {
            s.step(0.0, 0.0);
        }
        let (v, w) = s.object_velocity();
        assert!(v.length() < 1e-4 && w.abs() < 1e-3, "at rest: {v:?} {w}");
        (s.object_pose(), s.wheel_slip(), forces)
    };
    let (kinematic, _, _) = run(RobotDrive::Kinematic);
    let (finite, slip, forces) = run(RobotDrive::FiniteForce);
    // The finite-force robot loses ground while it gets the object up to speed at the
    // contact, at worst at the acceleration of robot and object together with the object's
    // friction against it: a = (mu_w m_r g - mu_f m_o g) / (m_r + m_o), a slip of at most
    // V^2 / (2 a) = 1.51 mm. At the end the kinematic robot stops dead and the object
    // slides on by V^2 / (2 mu_f g) = 1.27 mm; the finite-force robot ramps down (3 m/s^2)
    // slower than the object decelerates (mu_f g = 3.9 m/s^2), so the object stops against
    // it, and its ramp-down travel makes up for its ramp-up. So the kinematic robot pushes
    // the object farther by the slide plus the slip, less the soft contact's give (0.3 mm).
    let m_r = RobotDescription::epuck().mass;
    let a = (traction() - MU_FLOOR * mass * G) / (m_r + mass);
    let lag = V * V / (2.0 * a);
    let slide = V * V / (2.0 * MU_FLOOR * G);
    let (dk, df) = (kinematic.x, finite.x);
    let ahead = dk - df;
    eprintln!(
        "light push: kinematic {:.3} mm, finite force {:.3} mm, difference {:.3} mm (slide {:.3} mm + slip); slip {:.3}/{:.3} mm (bound {:.3} mm)",
        dk * 1e3,
        df * 1e3,
        ahead * 1e3,
        slide * 1e3,
        slip.0 * 1e3,
        slip.1 * 1e3,
        lag * 1e3
    );
    assert!(dk > 0.19, "the kinematic robot pushed it {dk} m");
    let expected = slide + 0.5 * (slip.0 + slip.1);
    assert!(
        (ahead - expected).abs() < 3e-4,
        "finite force {df} m, kinematic {dk} m: {ahead} m apart, expected {expected} m"
    );
    assert!(slip.0 <= lag && slip.1 <= lag, "slip {slip:?}");
    assert!(
        finite.y.abs() < 1e-4 && finite.theta.abs() < 1e-3,
        "{finite:?}"
    );
    // Sliding at constant speed, the push is the object's floor friction mu_f m_o g.
    let steady = &forces[forces.len() / 2..];
    let want = MU_FLOOR * mass * G;
    for f in steady {
        assert!(
            (f - want).abs() < 0.01 * want,
            "push {f} N, mu m g = {want} N"
        );
    }
}

#[test]
fn a_heavy_object_stalls_the_robot_its_wheels_slip_and_odometry_counts_the_slip() {
    // 0.5 kg at mu 0.4 takes 1.96 N to slide; the robot's wheels pull 1.26 N at most.
    let mass = 0.5;
    let start = behind(0.0);
    let mut s = placed(
        &square(RobotDrive::FiniteForce, mass),
        Pose::default(),
        start,
    );
    let mut forces = Vec::new();
    push(&mut s, |s| {
        if let Some(c) = s.contact_impulse() {
            forces.push(c.normal_impulse / s.dt());
        }
    });
    let (object, robot, odometry, slip) = (
        s.object_pose(),
        s.robot_pose(),
        s.sensors().odometry,
        s.wheel_slip(),
    );
    let moved = object.position().length();
    let travelled = robot.x - start.x;
    eprintln!(
        "heavy push: object moved {:.3} mm, robot {:.3} mm, odometry {:.3} mm, slip {:.3}/{:.3} mm, push {:.4} N",
        moved * 1e3,
        travelled * 1e3,
        (odometry.x - start.x) * 1e3,
        slip.0 * 1e3,
        slip.1 * 1e3,
        forces.last().copied().unwrap_or(0.0)
    );
    assert!(moved < 0.005, "the object moved {moved} m");
    // The robot pushes with all its traction, and that is not enough.
    let steady = &forces[forces.len() / 2..];
    assert!(!steady.is_empty(), "the robot touches the object");
    for f in steady {
        assert!(
            (f - traction()).abs() < 0.01 * traction(),
            "push {f} N, traction mu_w m_r g = {} N",
            traction()
        );
        assert!(*f < MU_FLOOR * mass * G);
    }
    // The body crossed the gap and no more than the object moved, give or take the depth
    // to which rapier's soft contact sinks under the push: about F / (m_eff (2 pi 30 Hz)^2)
    // = 1.26 N / (0.121 kg x 35,500 /s^2) = 0.29 mm (rapier's default contact natural
    // frequency, 30 Hz; m_eff = m_r m_o / (m_r + m_o)). The steppers turned the whole
    // 200 mm, and odometry (noise-free here) counts them.
    let m_r = RobotDescription::epuck().mass;
    let sink = traction() / (m_r * mass / (m_r + mass) * (std::f64::consts::TAU * 30.0).powi(2));
    assert!(
        travelled < GAP + moved + 1.5 * sink,
        "the robot travelled {travelled} m (soft contact {sink} m)"
    );
    // The steppers ramp up at the robot file's rate, then turn at V: their travel is the
    // sum of the ramped speeds, V * PUSH_S less about V^2 / (2 a) = 1.7 mm.
    let dv = s.robot().wheel_accel * s.dt();
    let commanded: f64 = (1..=(PUSH_S / s.dt()).round() as u64)
        .map(|k| (k as f64 * dv).min(V) * s.dt())
        .sum();
    assert!((odometry.x - start.x - commanded).abs() < 1e-9);
    for w in [slip.0, slip.1] {
        assert!(w > commanded - GAP - moved - 1.5 * sink, "slip {w} m");
        // Slip is commanded minus ground travel, by definition: the body's travel.
        assert!((commanded - w - travelled).abs() < 1e-5, "slip {w} m");
    }
    // The odometry's error is the slip.
    let drift = odometry.x - robot.x;
    assert!(
        (drift - slip.0).abs() < 1e-5,
        "drift {drift} m, slip {} m",
        slip.0
    );
}

#[test]
fn an_offset_push_slides_the_object_along_the_robots_front_on_the_coulomb_cone() {
    // The robot pushes the square's back face 20 mm off its centroid. The square turns
    // and the contact slides along the robot's round front, where Coulomb's law puts the
    // contact force on the edge of its cone: tangential = mu_c x normal.
    let mut s = placed(
        &square(RobotDrive::FiniteForce, 0.1),
        Pose::default(),
        behind(0.02),
    );
    let (mut touching, mut sliding, mut worst_inside, mut worst_edge) = (0, 0, 0.0f64, 0.0f64);
    let mut lateral = Vec::new();
    push(&mut s, |s| {
        let Some(c) = s.contact_impulse() else {
            return;
        };
        touching += 1;
        let ratio = c.tangent_impulse / c.normal_impulse;
        worst_inside = worst_inside.max(ratio - MU_CONTACT);
        // Velocity of the object's material point at the contact relative to the robot's,
        // across the normal.
        let at = |(v, w): (DVec2, f64), centre: DVec2| v + (c.point - centre).perp() * w;
        let rel = at(s.object_velocity(), s.object_pose().position())
            - at(s.robot_velocity(), s.robot_pose().position());
        if rel.dot(c.normal.perp()).abs() > SLIDING {
            sliding += 1;
            worst_edge = worst_edge.max((ratio - MU_CONTACT).abs());
        }
        lateral.push(s.robot_pose().to_local(c.point).y);
    });
    eprintln!(
        "offset push: {touching} steps in contact, {sliding} sliding faster than {} mm/s; \
         tangential/normal at most mu + {worst_inside:.2e}; sliding, within {worst_edge:.2e} of mu; \
         contact moved {:.1} mm across the robot's front; object {:?}",
        SLIDING * 1e3,
        (lateral.last().unwrap_or(&0.0) - lateral.first().unwrap_or(&0.0)) * 1e3,
        s.object_pose()
    );
    // Inside the cone always (rapier clamps each point's friction; f32 sums).
    assert!(
        worst_inside <= 1e-4 * MU_CONTACT,
        "ratio passed mu by {worst_inside}"
    );
    // On its edge while sliding (0.1 %: f32 impulses summed over points).
    assert!(sliding > touching / 2, "{sliding} of {touching} steps slid");
    assert!(
        worst_edge <= 1e-3 * MU_CONTACT,
        "sliding ratio off mu by {worst_edge}"
    );
    // The contact started at the robot's front and slid sideways along it, to the right
    // (the square, pushed on its left half, turns clockwise away from it).
    let (first, last) = (lateral[0], lateral[lateral.len() - 1]);
    assert!(first.abs() < 1e-3, "first contact {first} m off the front");
    assert!(
        last < first - 0.01,
        "the contact slid from {first} to {last} m"
    );
    assert!(s.object_pose().theta < -0.5, "{:?}", s.object_pose());
}

/// Relative speed across the contact (m/s) above which it counts as sliding: above the
/// few mm/s of steps in which the contact sticks for part of the step and slides after.
const SLIDING: f64 = 0.01;

#[test]
fn the_finite_force_robot_is_deterministic_for_a_seed() {
    let run = || {
        let mut sc = square(RobotDrive::FiniteForce, 0.5);
        sc.robot.odometry_noise = 0.005;
        sc.robot.ir_noise_scale = 1.0;
        let mut s = sim_with_seed(&sc, 11);
        s.reset(Pose::default(), behind(0.01));
        let mut out = Vec::new();
        push(&mut s, |s| {
            out.push((
                s.robot_pose(),
                s.object_pose(),
                s.wheel_slip(),
                *s.sensors(),
            ))
        });
        out
    };
    let (a, b) = (run(), run());
    assert_eq!(a.len(), b.len());
    for (k, (x, y)) in a.iter().zip(&b).enumerate() {
        assert!(x == y, "step {k}: {x:?} vs {y:?}");
    }
}
