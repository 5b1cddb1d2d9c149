mod support;

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, LearnerBuildError, LearnerConfig, PushOutcome,
    SampleAddError,
};
use agp_shared_types::{GRID_CELLS, GradientGrid, GridHeader, GridKind, Pose2};
use glam::DVec2;

/// Radius of the round object of the synthetic trials, metres.
const RADIUS_M: f64 = 0.04;

/// The analytic "physics" the synthetic trials sample: a push at contact angle `phi` on the
/// circle with deviation `alpha_deg` moves the centroid by about 20 mm away from the
/// contact, turned by half of alpha, and rotates it by a smooth function of both.
fn model(phi: f64, alpha_deg: f64) -> (DVec2, f64) {
    let a = alpha_deg.to_radians();
    let displacement = DVec2::from_angle(phi + PI + 0.5 * a) * (0.02 + 0.004 * phi.cos());
    let rotation = 0.3 * phi.sin() + 0.8 * a;
    (displacement, rotation)
}

fn contact(phi: f64) -> DVec2 {
    DVec2::from_angle(phi) * RADIUS_M
}

/// 60 trials per alpha, one every 6 degrees, as in the paper; the border seen all round.
fn learned() -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("disc", &config).expect("a valid config");
    for &alpha in &config.alphas_deg {
        for k in 0..60 {
            let phi = TAU * k as f64 / 60.0;
            let (displacement_obj, rotation_rad) = model(phi, alpha);
            let push = PushOutcome {
                contact_point_obj: contact(phi),
                displacement_obj,
                rotation_rad,
                heading_obj: -contact(phi),
            };
            learner.add_push(alpha, &push).expect("a learned alpha");
            for s in 0..4 {
                let border = contact(phi + TAU * s as f64 / 240.0);
                learner
                    .add_border_point(alpha, border)
                    .expect("a learned alpha");
            }
        }
    }
    learner.into_gradient()
}

#[test]
fn predictions_between_trials_match_the_analytic_model() {
    // Tolerances: the Gaussian-weighted mean (push sigma 2.5 mm, trials 4.2 mm apart on the
    // circle) smooths the model along the border with a bias of about sigma^2 / 2 * f'':
    // 0.04 mm for the displacement (|f''| = 20 mm / R^2), 0.04 deg for the rotation. In alpha
    // the model's displacement turns along an arc that the linear interpolation cuts by
    // 20 mm * (1 - cos 3.75 deg) = 0.04 mm; its rotation is linear in alpha.
    let ag = learned();
    let mut worst = (0.0_f64, 0.0_f64);
    for alpha in [0.0, 15.0, -15.0, 7.5, -4.0, 11.0] {
        for k in 0..60 {
            let phi = TAU * (k as f64 + 0.5) / 60.0;
            let p = ag
                .predict(contact(phi), alpha)
                .expect("trials on both sides");
            let (d, r) = model(phi, alpha);
            let (ed, er) = (p.displacement.distance(d), (p.rotation_rad - r).abs());
            assert!(
                ed < 0.0005,
                "alpha {alpha} phi {phi}: displacement off by {ed} m"
            );
            assert!(
                er < 0.5_f64.to_radians(),
                "alpha {alpha} phi {phi}: rotation off by {er} rad"
            );
            assert!(p.confidence > 0.6 && p.confidence <= 1.0);
            worst = (worst.0.max(ed), worst.1.max(er));
        }
    }
    eprintln!(
        "worst: {:.3} mm, {:.3} deg",
        worst.0 * 1e3,
        worst.1.to_degrees()
    );
}

#[test]
fn a_prediction_at_7_5_deg_lies_between_those_at_0_and_15() {
    let ag = learned();
    for k in 0..36 {
        let c = contact(TAU * (k as f64 + 0.3) / 36.0);
        let (p0, p15, p) = (
            ag.predict(c, 0.0).expect("learned"),
            ag.predict(c, 15.0).expect("learned"),
            ag.predict(c, 7.5).expect("between learned alphas"),
        );
        let between = |x: f64, a: f64, b: f64| x >= a.min(b) - 1e-12 && x <= a.max(b) + 1e-12;
        assert!(between(
            p.displacement.x,
            p0.displacement.x,
            p15.displacement.x
        ));
        assert!(between(
            p.displacement.y,
            p0.displacement.y,
            p15.displacement.y
        ));
        assert!(between(p.rotation_rad, p0.rotation_rad, p15.rotation_rad));
        // Halfway, in fact.
        assert!((p.rotation_rad - 0.5 * (p0.rotation_rad + p15.rotation_rad)).abs() < 1e-9);
    }
}

#[test]
fn no_prediction_far_from_every_trial_or_outside_the_learned_alphas() {
    let ag = learned();
    assert!(
        ag.predict(DVec2::ZERO, 0.0).is_none(),
        "the centroid is 8 sigma from any contact"
    );
    assert!(ag.predict(contact(1.0), 20.0).is_none());
    assert!(ag.predict(contact(1.0), -15.5).is_none());
    assert!(ag.predict(DVec2::new(f64::NAN, 0.0), 0.0).is_none());
    assert!(ag.predict(contact(1.0), -15.0).is_some());
}

#[test]
fn with_data_on_one_side_only_the_confidence_falls_with_the_alpha_distance() {
    let mut learner = AffordanceLearner::new("disc", &LearnerConfig::default()).expect("valid");
    let (d, r) = model(0.0, 0.0);
    let push = PushOutcome {
        contact_point_obj: contact(0.0),
        displacement_obj: d,
        rotation_rad: r,
        heading_obj: -contact(0.0),
    };
    learner.add_push(0.0, &push).expect("learned alpha");
    let ag = learner.into_gradient();
    let at0 = ag.predict(contact(0.0), 0.0).expect("on the trial");
    let at12 = ag.predict(contact(0.0), 12.0).expect("A0 still answers");
    // The contact (40, 0) mm lies 1 mm from the four nearest cell centres in x and in y,
    // so the interpolated weight there is exp(-2 mm^2 / (2 sigma^2)).
    let sigma_mm = LearnerConfig::default().push_sigma_m * 1e3;
    let w = (-2.0_f64 / (2.0 * sigma_mm * sigma_mm)).exp();
    assert!(
        (at0.confidence - (1.0 - (-w).exp())).abs() < 1e-6,
        "{at0:?}"
    );
    assert!((at12.confidence - at0.confidence * 0.2).abs() < 1e-9);
    assert_eq!(at12.displacement, at0.displacement);
}

#[test]
fn r_plus_and_r_minus_keep_each_sign_apart() {
    let ag = learned();
    for alpha in [0.0, 15.0, -15.0] {
        let plus = ag.component(alpha, GridKind::RotationPos).expect("learned");
        let minus = ag.component(alpha, GridKind::RotationNeg).expect("learned");
        assert!(plus.cells().iter().all(|&c| c >= 0.0));
        assert!(minus.cells().iter().all(|&c| c <= 0.0));
        assert!(plus.max() > 0.0);
        // At the contact phi = 90 deg the model turns counter-clockwise at every alpha,
        // at -90 deg clockwise: each shows in its own grid, the other one is empty there.
        for phi in [PI / 2.0, -PI / 2.0] {
            let c = contact(phi);
            let expected = model(phi, alpha).1;
            let (shown, other) = if expected >= 0.0 {
                (&plus, &minus)
            } else {
                (&minus, &plus)
            };
            assert!(
                (f64::from(shown.sample(c)) - expected).abs() < 0.01,
                "alpha {alpha}"
            );
            assert_eq!(other.sample(c), 0.0);
        }
    }
}

#[test]
fn the_largest_rotation_is_that_of_the_strongest_single_push() {
    let ag = learned();
    for alpha in [0.0, 15.0, -15.0] {
        let expected = (0..60)
            .map(|k| model(TAU * k as f64 / 60.0, alpha).1.abs())
            .fold(0.0, f64::max)
            .to_degrees();
        let got = ag
            .max_rotation_deg(alpha)
            .expect("learned alpha with pushes");
        assert!(
            (got - expected).abs() < 1e-9,
            "alpha {alpha}: {got} vs {expected}"
        );
        assert_eq!(ag.push_count(alpha), Some(60));
        assert_eq!(ag.border_point_count(alpha), Some(240));
    }
    assert_eq!(ag.max_rotation_deg(5.0), None);
}

#[test]
fn the_shape_is_normalised_and_contact_candidates_lie_on_the_border() {
    let ag = learned();
    let s = ag.component(0.0, GridKind::Shape).expect("learned");
    assert!((s.max() - 1.0).abs() < 1e-6);
    assert!(s.cells().iter().all(|&c| (0.0..=1.0).contains(&c)));
    let combined = ag.combined_shape();
    assert!((combined.max() - 1.0).abs() < 1e-6);
    let candidates = ag.contact_candidates(72);
    assert_eq!(candidates.len(), 72);
    for (k, c) in candidates.iter().enumerate() {
        // On the circle, in angle order. The ridge of a ring blurred by sigma lies
        // sigma^2 / (2 R) = 0.08 mm inside it.
        assert!(
            (c.length() - RADIUS_M).abs() < 0.0002,
            "candidate {k} at {}",
            c.length()
        );
        let expected = TAU * k as f64 / 72.0;
        assert!(DVec2::from_angle(expected).dot(c.normalize()) > 0.9999);
    }
}

#[test]
fn write_component_fills_a_payload_with_the_grid_of_means() {
    let ag = learned();
    let mut payload = Box::new(GradientGrid {
        header: GridHeader::default(),
        cells: [0.0; GRID_CELLS],
    });
    for kind in GridKind::ALL {
        ag.write_component(-15.0, kind, 7, &mut payload)
            .expect("learned alpha");
        assert_eq!(payload.header.kind, kind as u32);
        assert_eq!(payload.header.alpha_deg, -15.0);
        assert_eq!(payload.header.seq, 7);
        let grid = ag.component(-15.0, kind).expect("learned alpha");
        assert_eq!(&payload.cells[..], grid.cells());
    }
    assert!(
        ag.write_component(3.0, GridKind::Shape, 1, &mut payload)
            .is_err()
    );
    // Means, not sums: the x displacement on the trial at phi = 0 is about -24 mm.
    let px = ag.component(0.0, GridKind::PositionX).expect("learned");
    assert!((f64::from(px.sample(contact(0.0))) + 0.024).abs() < 0.0005);
}

#[test]
fn the_motion_alone_is_in_the_objects_frame_before_the_push_and_wrapped() {
    // Facing +y, the object moves 0.1 m along +y (its own +x) and turns 30 deg.
    let (d, r) = PushOutcome::motion(
        Pose2::new(1.0, 2.0, FRAC_PI_2),
        Pose2::new(1.0, 2.1, FRAC_PI_2 + 30f64.to_radians()),
    );
    assert!(d.distance(DVec2::new(0.1, 0.0)) < 1e-12, "{d}");
    assert!((r - 30f64.to_radians()).abs() < 1e-12);
    // Turned 350 deg counter-clockwise is turned 10 deg clockwise.
    let (d, r) = PushOutcome::motion(
        Pose2::new(0.0, 0.0, 0.0),
        Pose2::new(0.0, 0.0, 350f64.to_radians()),
    );
    assert_eq!(d, DVec2::ZERO);
    assert!((r + 10f64.to_radians()).abs() < 1e-12, "{r}");
}

#[test]
fn a_push_outcome_from_poses_applied_to_the_start_pose_gives_the_end_pose() {
    let before = Pose2::new(0.3, -0.2, 2.5);
    let after = Pose2::new(0.31, -0.185, 2.5 + 0.4 - TAU);
    let contact_world = DVec2::new(0.27, -0.21);
    // The robot heads at the centroid.
    let heading_world = DVec2::new(before.x, before.y) - contact_world;
    let push = PushOutcome::from_poses(before, after, contact_world, heading_world);
    assert!((push.rotation_rad - 0.4).abs() < 1e-12);
    // Back to the world: the contact point, the heading and the end pose.
    let to_world = DVec2::from_angle(before.theta);
    let c = DVec2::new(before.x, before.y) + to_world.rotate(push.contact_point_obj);
    assert!(c.distance(contact_world) < 1e-12);
    assert!(to_world.rotate(push.heading_obj).distance(heading_world) < 1e-12);
    assert!(!push.meets_past_centroid());
    let mut learner = AffordanceLearner::new("box", &LearnerConfig::default()).expect("valid");
    learner.add_push(0.0, &push).expect("learned alpha");
    let p = learner
        .gradient()
        .predict(push.contact_point_obj, 0.0)
        .expect("on the trial");
    let end = p.apply_to(before);
    assert!((end.x - after.x).abs() < 1e-6 && (end.y - after.y).abs() < 1e-6);
    assert!((end.theta - (before.theta + 0.4)).abs() < 1e-6);
}

#[test]
fn the_learner_refuses_unknown_alphas_non_finite_samples_and_bad_configs() {
    let mut learner = AffordanceLearner::new("box", &LearnerConfig::default()).expect("valid");
    assert_eq!(
        learner.add_border_point(10.0, DVec2::ZERO),
        Err(SampleAddError::UnknownAlpha(10.0))
    );
    assert_eq!(
        learner.add_border_point(0.0, DVec2::new(f64::INFINITY, 0.0)),
        Err(SampleAddError::NonFinite)
    );
    let push = PushOutcome {
        contact_point_obj: DVec2::ZERO,
        displacement_obj: DVec2::ZERO,
        rotation_rad: f64::NAN,
        heading_obj: DVec2::X,
    };
    assert_eq!(learner.add_push(0.0, &push), Err(SampleAddError::NonFinite));
    let config = |alphas: Vec<f64>, sigma: f64| LearnerConfig {
        alphas_deg: alphas,
        push_sigma_m: sigma,
        ..LearnerConfig::default()
    };
    assert_eq!(
        AffordanceLearner::new("x", &config(vec![], 0.005)).err(),
        Some(LearnerBuildError::NoAlphas)
    );
    assert_eq!(
        AffordanceLearner::new("x", &config(vec![0.0, 15.0, 0.0], 0.005)).err(),
        Some(LearnerBuildError::DuplicateAlpha(0.0))
    );
    assert!(matches!(
        AffordanceLearner::new("x", &config(vec![0.0], -1.0)),
        Err(LearnerBuildError::BadLength {
            field: "push_sigma_m",
            ..
        })
    ));
    let ag = learned();
    assert_eq!(
        AffordanceLearner::resume(ag.clone(), &config(vec![0.0], 0.005)).err(),
        Some(LearnerBuildError::GradientMismatch)
    );
    let mut resumed =
        AffordanceLearner::resume(ag, &config(vec![15.0, -15.0, 0.0], 0.005)).expect("same alphas");
    resumed
        .add_border_point(15.0, DVec2::new(0.04, 0.0))
        .expect("learned alpha");
    assert_eq!(resumed.gradient().border_point_count(15.0), Some(241));
}
