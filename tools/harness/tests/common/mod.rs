//! An affordance gradient learned from ground truth with the paper's protocol, for tests
//! that isolate the planner from the estimator (the estimator's learning from IR is tested
//! in `agp-estimator`).

use agp_affordance::{AffordanceGradient, AffordanceLearner, LearnerConfig, PushOutcome};
use agp_perception::{ApproachContact, ContactSense};
use agp_physics::{Sim, SimConfig};
use agp_planning::{PushPhase, PushRoutine, PushSettings};
use agp_world::{ObjectShape, Pose, RobotDescription, Scenario};
use glam::DVec2;

/// Learned push duration after the IR-inferred contact, s (the learning protocol's).
pub const PUSH_S: f64 = 0.5;
/// Gap (m) between the robot's shell and the object's farthest point at a push's start.
pub const START_GAP: f64 = 0.02;

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

/// The paper's learning protocol with true poses and true aim points: alphas 0 and +-15,
/// 60 starts each, S from the true border; each push is the episodes' own (approach until
/// the IR infers contact, then `PUSH_S` at 100 mm/s), so the AG predicts what they do.
pub fn learn_from_truth(scenario: &Scenario, robot: &RobotDescription) -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new(&scenario.name, &config).expect("learner");
    let mut sim = Sim::new(scenario, robot, SimConfig::default()).expect("sim");
    let sense = ContactSense::new(robot);
    let settings = PushSettings {
        push_duration: PUSH_S,
        ..PushSettings::default()
    };
    let home = Pose::new(0.0, 0.0, 0.0);
    let r = scenario.object.shape.radius() + robot.body_radius + START_GAP;
    for &alpha in &config.alphas_deg {
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
            let mut routine = PushRoutine::new(settings, sim.sim_time());
            let mut approach = ApproachContact::new();
            let touched = loop {
                let st = *sim.sensors();
                let gap = sense.front_gap(&st.ir_raw);
                approach.observe(st.ir_sample, gap, st.odometry);
                let (left, right) =
                    routine.step(gap, approach.stalled(), sim.sim_time(), st.ir_sample);
                if let PushPhase::Done { contact } = routine.phase() {
                    break contact;
                }
                sim.step(left, right);
            };
            for _ in 0..(0.2 / sim.dt()).round() as u64 {
                sim.step(0.0, 0.0);
            }
            if touched {
                let outcome = PushOutcome::from_poses(home, sim.object_pose(), s + t * u, u);
                learner.add_push(alpha, &outcome).expect("push");
            }
        }
    }
    learner.into_gradient()
}
