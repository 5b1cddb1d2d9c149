//! Synthetic gradients for the plot tests.

use std::f64::consts::{PI, TAU};

use agp_affordance::{AffordanceGradient, AffordanceLearner, LearnerConfig, PushOutcome};
use glam::DVec2;

/// Radius of the round object of the synthetic trials, metres.
pub const RADIUS_M: f64 = 0.04;

/// A push at contact angle `phi` with deviation `alpha_deg` moves the centroid about 20 mm
/// away from the contact and turns it by a smooth function of both (as in the affordance
/// crate's tests).
fn model(phi: f64, alpha_deg: f64) -> (DVec2, f64) {
    let a = alpha_deg.to_radians();
    let displacement = DVec2::from_angle(phi + PI + 0.5 * a) * (0.02 + 0.004 * phi.cos());
    let rotation = 0.3 * phi.sin() + 0.8 * a;
    (displacement, rotation)
}

/// `trials` pushes per alpha (0, +15, -15) evenly round a disc of [`RADIUS_M`], the border
/// seen all round.
pub fn learned_disc(trials: usize) -> AffordanceGradient {
    learned_disc_of_radius(trials, RADIUS_M)
}

/// As [`learned_disc`], with a disc of `radius_m`.
pub fn learned_disc_of_radius(trials: usize, radius_m: f64) -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("disc", &config).expect("a valid config");
    for &alpha in &config.alphas_deg {
        for k in 0..trials {
            let phi = TAU * k as f64 / trials as f64;
            let (displacement_obj, rotation_rad) = model(phi, alpha);
            let push = PushOutcome {
                contact_point_obj: DVec2::from_angle(phi) * radius_m,
                displacement_obj,
                rotation_rad,
                heading_obj: -DVec2::from_angle(phi),
            };
            learner.add_push(alpha, &push).expect("a learned alpha");
            for s in 0..4 {
                let border = DVec2::from_angle(phi + TAU * s as f64 / (4 * trials) as f64);
                learner
                    .add_border_point(alpha, border * radius_m)
                    .expect("a learned alpha");
            }
        }
    }
    learner.into_gradient()
}
