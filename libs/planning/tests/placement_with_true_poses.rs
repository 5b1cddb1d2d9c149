//! The push choice and the travel between pushes, checked in-process against the physics
//! library with the object's true pose (what the `oracle` planner sees): if these cannot
//! place an object, no estimator can make up for it.
//!
//! The gradient here is learned from ground truth (true contact points, true motions) with
//! the paper's protocol, so that the test isolates the planner: the estimator's own
//! learning from IR is tested in `agp-estimator`.

use agp_affordance::{AffordanceGradient, AffordanceLearner, LearnerConfig, PushOutcome};
use agp_physics::{Sim, SimConfig};
use agp_planning::{
    Goal, PushChoiceSettings, PushPlanner, TravelPhase, TravelRoutine, TravelSettings,
    approach_start, orbit_waypoints, symmetric_angle_error,
};
use agp_shared_types::Pose2;
use agp_world::{ObjectShape, Pose, Rng, RobotDescription, Scenario};
use glam::DVec2;

/// Push speed, m/s, approach and push alike.
const SPEED: f64 = 0.1;
/// Learned push duration after the first touch, s.
const PUSH_S: f64 = 0.5;
/// Gap (m) between the robot's shell and the object's farthest point at a push's start.
const START_GAP: f64 = 0.02;

fn start_radius(scenario: &Scenario, robot: &RobotDescription) -> f64 {
    scenario.object.shape.radius() + robot.body_radius + START_GAP
}

/// Distance along the ray from `origin` (object frame) to the object's border.
fn border_hit(shape: &ObjectShape, origin: DVec2, dir: DVec2) -> Option<f64> {
    match shape {
        ObjectShape::Polygon(p) => p.ray_cast(origin, dir, 1.0),
        ObjectShape::Circle { radius } => {
            let b = origin.dot(dir);
            let c = origin.length_squared() - radius * radius;
            let disc = b * b - c;
            (disc >= 0.0)
                .then(|| -b - disc.sqrt())
                .filter(|t| *t >= 0.0)
        }
    }
}

/// Drives straight at `SPEED` until the body touches the object (at most `max_s`), then
/// on for `push_s`, then lets the object come to rest. Whether it touched.
fn push(sim: &mut Sim, push_s: f64, max_s: f64) -> bool {
    let dt = sim.dt();
    let mut t = 0.0;
    while !sim.in_contact() && t < max_s {
        sim.step(SPEED, SPEED);
        t += dt;
    }
    if !sim.in_contact() {
        return false;
    }
    for _ in 0..(push_s / dt).round() as u64 {
        sim.step(SPEED, SPEED);
    }
    for _ in 0..(0.3 / dt).round() as u64 {
        sim.step(0.0, 0.0);
    }
    true
}

/// The paper's learning protocol on ground truth: alphas 0, +-15, 60 starts each.
fn learn_from_truth(scenario: &Scenario, robot: &RobotDescription) -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new(&scenario.name, &config).expect("learner");
    let mut sim = Sim::new(scenario, robot, SimConfig::default()).expect("sim");
    let home = Pose::new(0.0, 0.0, 0.0);
    let r = start_radius(scenario, robot);
    for &alpha in &config.alphas_deg {
        // S from the true border, one point every 2 mm.
        let border: Vec<DVec2> = match &scenario.object.shape {
            ObjectShape::Polygon(p) => p
                .edges()
                .flat_map(|(a, b)| {
                    let n = ((b - a).length() / 0.002).ceil() as usize;
                    (0..n).map(move |k| a.lerp(b, k as f64 / n as f64))
                })
                .collect(),
            ObjectShape::Circle { radius } => (0..360)
                .map(|k| *radius * DVec2::from_angle((k as f64).to_radians()))
                .collect(),
        };
        for p in border {
            learner.add_border_point(alpha, p).expect("border point");
        }
        for k in 0..60 {
            let phi = (6.0 * k as f64).to_radians();
            let s = r * DVec2::from_angle(phi);
            let heading = phi + std::f64::consts::PI + alpha.to_radians();
            let u = DVec2::from_angle(heading);
            let Some(t) = border_hit(&scenario.object.shape, s, u) else {
                continue;
            };
            sim.reset(home, Pose::new(s.x, s.y, heading));
            if push(&mut sim, PUSH_S, 2.0 * r / SPEED) {
                let outcome = PushOutcome::from_poses(home, sim.object_pose(), s + t * u, u);
                learner.add_push(alpha, &outcome).expect("push");
            }
        }
    }
    learner.into_gradient()
}

struct Episode {
    success: bool,
    pushes: u32,
    position_error_mm: f64,
    orientation_error_deg: f64,
}

/// Places the object at `goal` with true poses: plan, travel round, push, repeat.
fn place(scenario: &Scenario, ag: &AffordanceGradient, goal: Pose2, max_pushes: u32) -> Episode {
    let robot = RobotDescription::epuck();
    let order = scenario.object.shape.symmetry_order();
    let r = start_radius(scenario, &robot);
    let planner = PushPlanner::new(ag, PushChoiceSettings::new(order, r));
    let mut sim = Sim::new(scenario, &robot, SimConfig::default()).expect("sim");
    let dt = sim.dt();
    let (tol_m, tol_rad) = (scenario.task.tolerance_m, scenario.task.tolerance_rad);
    let target = Goal::Place { pose: goal };
    let errors = |sim: &Sim| {
        let o = sim.object_pose();
        (
            DVec2::new(o.x - goal.x, o.y - goal.y).length(),
            symmetric_angle_error(o.theta - goal.theta, order).abs(),
        )
    };
    let mut pushes = 0;
    loop {
        let (ep, eo) = errors(&sim);
        if (ep <= tol_m && eo <= tol_rad) || pushes == max_pushes {
            return Episode {
                success: ep <= tol_m && eo <= tol_rad,
                pushes,
                position_error_mm: ep * 1e3,
                orientation_error_deg: eo.to_degrees(),
            };
        }
        let object = sim.object_pose();
        let plan = planner.plan(object, &target).expect("a push");
        // Back off, then round the object to the push's start.
        for _ in 0..(0.15 / dt).round() as u64 {
            sim.step(-0.08, -0.08);
        }
        let centre = DVec2::new(object.x, object.y);
        let start = DVec2::new(plan.start.x, plan.start.y);
        let way = orbit_waypoints(sim.robot_pose().position(), centre, r, start, 0.2);
        let mut travel = TravelRoutine::new(
            TravelSettings::default(),
            robot.axle_length,
            robot.max_wheel_speed,
            way,
            plan.start.theta,
        );
        for _ in 0..(30.0 / dt) as u64 {
            let (left, right) = travel.update(sim.robot_pose());
            if travel.phase() == TravelPhase::Done {
                break;
            }
            sim.step(left, right);
        }
        assert_eq!(travel.phase(), TravelPhase::Done, "the travel got stuck");
        let moved = DVec2::new(sim.object_pose().x, sim.object_pose().y) - centre;
        assert!(
            moved.length() < 0.002,
            "travelling round the object moved it {:.1} mm",
            moved.length() * 1e3
        );
        push(&mut sim, plan.fraction * PUSH_S, 2.0 * r / SPEED);
        pushes += 1;
    }
}

#[test]
fn a_start_for_every_learned_contact_exists_on_the_learning_circle() {
    let scenario = Scenario::builtin("lshape").expect("built-in");
    let robot = RobotDescription::epuck();
    let ag = learn_from_truth(&scenario, &robot);
    let r = start_radius(&scenario, &robot);
    let planner = PushPlanner::new(&ag, PushChoiceSettings::new(1, r));
    assert!(planner.contacts().len() > 100);
    // The learned border lies on the true one within a cell or so.
    let ObjectShape::Polygon(p) = &scenario.object.shape else {
        unreachable!()
    };
    for c in planner.contacts() {
        assert!(p.border_distance(*c) < 0.003, "contact {c} off the border");
        for alpha in [0.0_f64, 15.0, -15.0] {
            // Every contact a push line of this alpha can reach has a start: the line
            // passes r sin(alpha) from the centroid, so nearer contacts have none.
            let reachable = c.length() > r * alpha.to_radians().sin().abs() + 1e-9;
            assert_eq!(
                approach_start(*c, alpha, r).is_some(),
                reachable,
                "contact {c}, alpha {alpha}"
            );
        }
    }
}

fn check_placement(name: &str) {
    let scenario = Scenario::builtin(name).expect("built-in");
    let ag = learn_from_truth(&scenario, &RobotDescription::epuck());
    // The scenario's own goal, then random goals as `agp bench place` draws them: 250 to
    // 500 mm away in any direction, any orientation.
    let g = scenario.task.goal;
    let mut goals = vec![g];
    let mut rng = Rng::new(scenario.task.seed);
    while goals.len() < 8 {
        let d = 0.25 + 0.25 * rng.uniform();
        let a = std::f64::consts::TAU * rng.uniform();
        let theta = std::f64::consts::TAU * rng.uniform() - std::f64::consts::PI;
        goals.push(Pose2::new(d * a.cos(), d * a.sin(), theta));
    }
    let mut failed = Vec::new();
    let mut pushes = Vec::new();
    for goal in &goals {
        let e = place(&scenario, &ag, *goal, scenario.task.max_pushes);
        println!(
            "{name} to ({:.0}, {:.0}) mm, {:.0} deg: {} after {} pushes, error {:.1} mm, {:.1} deg",
            goal.x * 1e3,
            goal.y * 1e3,
            goal.theta.to_degrees(),
            if e.success { "placed" } else { "NOT placed" },
            e.pushes,
            e.position_error_mm,
            e.orientation_error_deg
        );
        pushes.push(e.pushes);
        if !e.success {
            failed.push(*goal);
        }
    }
    pushes.sort_unstable();
    println!("{name}: median {} pushes", pushes[pushes.len() / 2]);
    assert!(
        failed.is_empty(),
        "{name}: {} of {} goals not reached: {failed:?}",
        failed.len(),
        goals.len()
    );
}

#[test]
fn with_true_poses_the_triangle_is_placed_at_every_goal_within_tolerance() {
    check_placement("triangle");
}

#[test]
fn with_true_poses_the_l_shape_is_placed_at_every_goal_within_tolerance() {
    check_placement("lshape");
}
