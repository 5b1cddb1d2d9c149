//! The `model` planner's predictions: the E-puck's round body pushing the object's true
//! footprint, quasi-statically, on its limit surface ([`crate::limit_surface`]). It reads
//! ground truth by design (the object's shape, mass and frictions, from the scenario, in
//! [`PushModel::from_scenario`] alone, and its pose before every push, as the `oracle`
//! does): it is the classical method beside the learned one, not a result of ours.
//!
//! A push of the planner's family (from the start circle, heading at the centroid turned by
//! alpha, through an aim point on the border) is integrated in small steps of the robot's
//! travel: the disc first touches the footprint where geometry says (the contact point is
//! the border's closest point to the disc's centre, the normal through that centre); at
//! each step the limit surface gives the object's twist for the robot's velocity at that
//! contact (sticking inside the motion cone, sliding on its edge outside), the object moves
//! by it, and the contact is found again. Predictions come out in the form the affordance
//! gradient's have ([`Prediction`]: displacement in the object's frame, rotation), with
//! confidence 1 and no spread, so that the same search ([`PushPlanner`]) chooses the pushes.

use agp_affordance::{Prediction, approach_start};
use agp_world::{RobotDescription, Scenario};
use glam::DVec2;

use crate::learning_protocol::ALPHAS_DEG;
use crate::limit_surface::{Footprint, LimitSurface};
use crate::{PushChoiceSettings, PushPlanner};

/// Step of the robot's travel in one integration step, m (0.5 mm: a push of 48 mm in 96
/// steps; halving it moves a prediction by under 0.1 mm and 0.1 deg).
const STEP_M: f64 = 0.0005;

/// Share of the commanded push speed at which the object moves while the robot pushes:
/// the push choice's length scaling was measured on the learning protocol's push (the
/// object moves about 9 mm plus 78 mm per second at 100 mm/s, see
/// [`PushChoiceSettings::fraction_offset`]), and the model's full push is that push.
const CONTACT_SPEED_SHARE: f64 = 0.78;

/// How far the robot travels in contact with the object during the learned push of
/// `push_speed_mps` for `push_duration_s`, m, with the push choice's `fraction_offset`: the
/// push the model predicts and the search scales (48 mm for 0.5 s at 100 mm/s).
pub fn learned_push_travel_m(
    push_speed_mps: f64,
    push_duration_s: f64,
    fraction_offset: f64,
) -> f64 {
    CONTACT_SPEED_SHARE * push_speed_mps * push_duration_s * (1.0 + fraction_offset)
}

/// What the model knows of the object: ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct PushedObject {
    /// Its footprint, centroid at the origin, in the frame its pose is given in.
    pub footprint: Footprint,
    pub mass_kg: f64,
    /// Coulomb coefficient with the floor.
    pub floor_friction: f64,
    /// Coulomb coefficient with the robot.
    pub contact_friction: f64,
    /// Its rotational symmetry (0: a disc, 1: none).
    pub symmetry_order: u32,
}

/// The quasi-static pushing model of one object and the E-puck's round body.
#[derive(Debug, Clone, PartialEq)]
pub struct PushModel {
    object: PushedObject,
    surface: LimitSurface,
    /// The robot's body radius, m.
    pusher_radius_m: f64,
}

impl PushModel {
    /// The model of `object` pushed by a disc of `pusher_radius_m`.
    pub fn new(object: PushedObject, pusher_radius_m: f64) -> Self {
        let surface = LimitSurface::uniform_pressure(
            &object.footprint,
            object.mass_kg,
            object.floor_friction,
        );
        Self {
            object,
            surface,
            pusher_radius_m,
        }
    }

    /// The model of `scenario`'s object pushed by `robot`: the one place the `model`
    /// planner reads the object's spec (ground truth), and what makes it a ground-truth
    /// reader (it says so in every report).
    pub fn from_scenario(scenario: &Scenario, robot: &RobotDescription) -> Self {
        let truth = &scenario.object;
        let footprint = match &truth.shape {
            agp_world::ObjectShape::Polygon(p) => Footprint::polygon(p),
            agp_world::ObjectShape::Circle { radius } => Footprint::Disc { radius: *radius },
        };
        Self::new(
            PushedObject {
                footprint,
                mass_kg: truth.mass,
                floor_friction: truth.floor_friction,
                contact_friction: truth.contact_friction,
                symmetry_order: truth.shape.symmetry_order(),
            },
            robot.body_radius,
        )
    }

    pub fn object(&self) -> &PushedObject {
        &self.object
    }

    pub fn surface(&self) -> &LimitSurface {
        &self.surface
    }

    /// The object's motion (object frame before the push) when the robot's centre starts
    /// at `start` (object frame, outside the object) and drives along `heading` (unit)
    /// until it touches the object, then `travel_m` farther; `None` if it passes by.
    pub fn push(&self, start: DVec2, heading: DVec2, travel_m: f64) -> Option<Prediction> {
        let fp = &self.object.footprint;
        let radius = self.pusher_radius_m;
        let touch = fp.first_touch(start, heading, radius)?;
        // The object's pose in the frame it had before the push, and the robot's centre.
        let (mut centre, mut theta) = (DVec2::ZERO, 0.0_f64);
        let mut robot = start + heading * touch;
        let mut left = travel_m.max(0.0);
        while left > 0.0 {
            let ds = left.min(STEP_M);
            left -= ds;
            let to_obj = DVec2::from_angle(-theta);
            let p = to_obj.rotate(robot - centre);
            let q = fp.closest_border_point(p);
            let d = (q - p).length();
            robot += heading * ds;
            if d > radius + 1e-6 || d < 1e-9 {
                // Out of touch (the object turned away): the robot drives on.
                continue;
            }
            let normal = (q - p) / d;
            let push = self.surface.point_push(
                q,
                normal,
                to_obj.rotate(heading),
                self.object.contact_friction,
            );
            let to_push = DVec2::from_angle(theta);
            centre += to_push.rotate(push.twist.v) * ds;
            theta += push.twist.omega * ds;
            // The step's error leaves the disc a hair inside the border: out along the
            // normal, as the rigid contact would.
            let to_obj = DVec2::from_angle(-theta);
            let p = to_obj.rotate(robot - centre);
            let q = fp.closest_border_point(p);
            let d = (q - p).length();
            if d < radius && d > 1e-9 {
                centre += DVec2::from_angle(theta).rotate((q - p) / d * (radius - d));
            }
        }
        Some(Prediction {
            displacement: centre,
            rotation_rad: theta,
            confidence: 1.0,
            displacement_spread_m: 0.0,
            rotation_spread_rad: 0.0,
        })
    }

    /// The push of the planner's family with aim point `aim` (object frame) and deviation
    /// `alpha_deg` from the circle of `start_radius_m` ([`approach_start`]), `travel_m` in
    /// contact; `None` when no start sends it through the aim point, or it misses.
    pub fn predict(
        &self,
        aim: DVec2,
        alpha_deg: f64,
        start_radius_m: f64,
        travel_m: f64,
    ) -> Option<Prediction> {
        let (start, heading) = approach_start(aim, alpha_deg, start_radius_m)?;
        self.push(start, DVec2::from_angle(heading), travel_m)
    }

    /// The aim points of `count` rays from the centroid at even angles: where each leaves
    /// the footprint for the last time.
    pub fn contact_candidates(&self, count: usize) -> Vec<DVec2> {
        (0..count)
            .filter_map(|k| {
                let u = DVec2::from_angle(std::f64::consts::TAU * k as f64 / count as f64);
                self.object.footprint.outermost_crossing(u)
            })
            .collect()
    }

    /// The push search of the affordance planner ([`PushPlanner`]) on this model's
    /// predictions: the contacts of `settings.contact_count` rays on the true border, the
    /// learned alphas' range every `settings.alpha_step_deg`, each push's full-length
    /// prediction of `travel_m` in contact (the search scales it for shorter pushes as it
    /// scales the gradient's). Allocates; once per episode.
    pub fn push_planner(
        &self,
        settings: PushChoiceSettings,
        travel_m: f64,
    ) -> PushPlanner<'static> {
        let contacts = self.contact_candidates(settings.contact_count);
        let lo = ALPHAS_DEG.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ALPHAS_DEG.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let step = settings.alpha_step_deg.max(0.1);
        let n = ((hi - lo) / step).round() as usize;
        let alphas: Vec<f64> = (0..=n).map(|k| (lo + k as f64 * step).min(hi)).collect();
        let predictions = contacts
            .iter()
            .flat_map(|&c| alphas.iter().map(move |&a| (c, a)))
            .map(|(c, a)| self.predict(c, a, settings.start_radius_m, travel_m))
            .collect();
        PushPlanner::from_predictions(contacts, alphas, predictions, settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agp_world::Polygon;

    /// The 60 mm square of the built-ins, 0.1 kg, floor 0.4, contact 0.3, pushed by the
    /// E-puck's 37 mm body.
    fn square_model(contact_friction: f64) -> PushModel {
        let polygon = Polygon::new(vec![
            DVec2::new(-0.03, -0.03),
            DVec2::new(0.03, -0.03),
            DVec2::new(0.03, 0.03),
            DVec2::new(-0.03, 0.03),
        ])
        .expect("a square");
        PushModel::new(
            PushedObject {
                footprint: Footprint::polygon(&polygon),
                mass_kg: 0.1,
                floor_friction: 0.4,
                contact_friction,
                symmetry_order: 4,
            },
            0.037,
        )
    }

    #[test]
    fn a_centred_push_on_the_square_carries_it_straight_as_far_as_the_robot_drives() {
        let m = square_model(0.3);
        let p = m
            .push(DVec2::new(-0.12, 0.0), DVec2::X, 0.048)
            .expect("a touch");
        assert!(
            (p.displacement - DVec2::new(0.048, 0.0)).length() < 1e-6,
            "{} mm",
            p.displacement * 1e3
        );
        assert!(p.rotation_rad.abs() < 1e-9, "{} rad", p.rotation_rad);
    }

    #[test]
    fn an_offset_push_turns_the_square_as_the_limit_surface_says_at_first() {
        let m = square_model(0.3);
        let c2 = m.surface().c_m().powi(2);
        // 10 mm above the centroid along +x: clockwise, at first at w / vx = -b / (c^2 +
        // a^2/4) (sticking); over a 2 mm push the ratio holds within 2 %.
        let b = 0.01;
        let p = m
            .push(DVec2::new(-0.12, b), DVec2::X, 0.002)
            .expect("a touch");
        let want = -b / (c2 + 0.03 * 0.03);
        let got = p.rotation_rad / p.displacement.x;
        assert!(got < 0.0, "turns counter-clockwise: {got}");
        assert!(
            (got - want).abs() < 0.02 * want.abs(),
            "{got} against {want}"
        );
        // Over a full push it keeps turning the same way, more for a larger offset.
        let turn = |b: f64| {
            m.push(DVec2::new(-0.12, b), DVec2::X, 0.048)
                .expect("a touch")
                .rotation_rad
        };
        assert!(turn(0.02) < turn(0.01) && turn(0.01) < 0.0);
        assert!(turn(-0.01) > 0.0);
    }

    #[test]
    fn a_frictionless_contact_slides_along_the_face_and_a_sticking_one_drags_the_square_round() {
        // The robot drives 20 deg off the left face's normal and meets it near its middle.
        let heading = DVec2::from_angle(20f64.to_radians());
        let start = DVec2::new(-0.12, -0.02);
        // mu_c = 0: the force is the face's normal, the square moves along it and the
        // robot's sideways motion slides past (it turns a little as the contact creeps up).
        let slippery = square_model(0.0)
            .push(start, heading, 0.005)
            .expect("a touch");
        assert!(
            slippery.displacement.y.abs() < 0.05 * slippery.displacement.x,
            "sideways {:.3} mm of {:.3} mm",
            slippery.displacement.y * 1e3,
            slippery.displacement.x * 1e3
        );
        // mu_c = 1 (tan 20 deg = 0.36, inside the cone): the contact sticks and is dragged
        // up the face, which turns the square clockwise, more than the slide does.
        let sticky = square_model(1.0)
            .push(start, heading, 0.005)
            .expect("a touch");
        assert!(
            sticky.rotation_rad < 0.0
                && sticky.rotation_rad.abs() > 2.0 * slippery.rotation_rad.abs(),
            "sticking {:.4} rad, sliding {:.4} rad",
            sticky.rotation_rad,
            slippery.rotation_rad
        );
    }

    #[test]
    fn the_models_planner_pushes_the_square_towards_a_goal_ahead() {
        let m = square_model(0.3);
        let settings = PushChoiceSettings::new(4, 0.03 * 2f64.sqrt() + 0.037 + 0.02);
        let planner = m.push_planner(settings, 0.048);
        assert_eq!(planner.contacts().len(), 120);
        let goal = crate::Goal::Place {
            pose: agp_shared_types::Pose2::new(0.2, 0.0, 0.0),
        };
        let plan = planner
            .plan(agp_shared_types::Pose2::new(0.0, 0.0, 0.0), &goal)
            .expect("a push");
        // The best push drives the square along +x, nearly straight.
        assert!(plan.predicted.x > 0.04, "{:?}", plan.predicted);
        assert!(plan.predicted.y.abs() < 0.005, "{:?}", plan.predicted);
    }
}
