//! The learner's two updates for online learning, against closed forms: a uniform gain
//! scales every prediction by itself, and a push learned with forgetting f on top of one
//! earlier push at the same point predicts their weighted mean (f * old + new) / (f + 1).

use agp_affordance::{AffordanceLearner, LearnerConfig, PushOutcome};
use glam::DVec2;

fn push(contact: DVec2, d: DVec2, rot: f64) -> PushOutcome {
    PushOutcome {
        contact_point_obj: contact,
        displacement_obj: d,
        rotation_rad: rot,
        heading_obj: -contact,
    }
}

#[test]
fn a_uniform_gain_scales_every_prediction_and_its_spread_by_itself() {
    let mut l = AffordanceLearner::new("t", &LearnerConfig::default()).expect("valid");
    let (a, b) = (DVec2::new(-0.03, 0.0), DVec2::new(0.0, 0.03));
    l.add_push(0.0, &push(a, DVec2::new(0.04, 0.0), 0.2))
        .unwrap();
    l.add_push(0.0, &push(a, DVec2::new(0.02, 0.0), 0.1))
        .unwrap();
    l.add_push(0.0, &push(b, DVec2::new(0.0, -0.03), -0.3))
        .unwrap();
    let before = [a, b].map(|p| l.gradient().predict(p, 0.0).expect("data"));
    l.scale_motion(0.5, 2.0);
    let after = [a, b].map(|p| l.gradient().predict(p, 0.0).expect("data"));
    for (x, y) in before.iter().zip(&after) {
        // f32 cells: relative 1e-5.
        assert!((y.displacement - x.displacement * 0.5).length() < 1e-5 * x.displacement.length());
        assert!((y.rotation_rad - x.rotation_rad * 2.0).abs() < 1e-5 * x.rotation_rad.abs());
        assert!((y.displacement_spread_m - 0.5 * x.displacement_spread_m).abs() < 1e-5);
        assert!(
            (y.confidence - x.confidence).abs() < 1e-9,
            "the weights stay"
        );
    }
}

#[test]
fn a_push_learned_with_forgetting_outweighs_the_evidence_before_it_at_its_contact_point() {
    let mut l = AffordanceLearner::new("t", &LearnerConfig::default()).expect("valid");
    // A cell centre: the Gaussian's peak (1) falls on it exactly.
    let cell = LearnerConfig::default().cell_size_m;
    let p = DVec2::new(-0.03 + cell / 2.0, cell / 2.0);
    let (old, new) = (DVec2::new(0.04, 0.0), DVec2::new(0.02, 0.0));
    l.add_push(0.0, &push(p, old, 0.0)).unwrap();
    let f = 0.5;
    l.add_recent_push(0.0, &push(p, new, 0.0), f).unwrap();
    let got = l.gradient().predict(p, 0.0).expect("data").displacement.x;
    // At the contact point the old push counts f, the new one 1.
    let expected = (f * old.x + new.x) / (f + 1.0);
    assert!(
        (got - expected).abs() < 1e-6,
        "{got} m, expected {expected} m"
    );
    // Forgetting 1 is plain learning: the mean of the two.
    let mut plain = AffordanceLearner::new("t", &LearnerConfig::default()).expect("valid");
    plain.add_push(0.0, &push(p, old, 0.0)).unwrap();
    plain.add_recent_push(0.0, &push(p, new, 0.0), 1.0).unwrap();
    let mean = plain
        .gradient()
        .predict(p, 0.0)
        .expect("data")
        .displacement
        .x;
    assert!((mean - 0.03).abs() < 1e-6, "{mean}");
}
