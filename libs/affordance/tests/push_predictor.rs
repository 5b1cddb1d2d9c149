//! The push predictor: pushes of the learning protocol's family (start on a circle, heading
//! at the centroid turned by alpha), interpolated between learned alphas along each start.

use agp_shared_types::angle;
use std::f64::consts::{PI, TAU};

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, Grid, LearnerConfig, PushOutcome, PushPredictor,
    approach_start, meets_past_centroid,
};
use glam::DVec2;

/// The round object's radius and the start circle's, metres.
const R: f64 = 0.04;
const START: f64 = 0.1;

/// Where the push from start angle `phi` at `alpha_deg` first meets the disc: its aim point.
fn aim(phi: f64, alpha_deg: f64) -> Option<DVec2> {
    let s = DVec2::from_angle(phi) * START;
    let d = DVec2::from_angle(phi + PI + alpha_deg.to_radians());
    let b = s.dot(d);
    let disc = b * b - (s.length_squared() - R * R);
    (disc >= 0.0).then(|| s + d * (-b - disc.sqrt()))
}

/// The analytic "physics" of the synthetic trials: the effect depends on where the push
/// starts (sharply: three turns of the rotation per lap) and linearly on alpha, as the
/// probe shows for real pushes from one start.
fn model(phi: f64, alpha_deg: f64) -> (DVec2, f64) {
    let displacement = DVec2::from_angle(phi + PI + 0.01 * alpha_deg) * 0.03;
    let rotation = 0.4 * (3.0 * phi).sin() - 0.03 * alpha_deg;
    (displacement, rotation)
}

/// 240 trials per alpha round the circle, keyed by aim point; the disc's border as S.
fn learned() -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("disc", &config).expect("a valid config");
    for &alpha in &config.alphas_deg {
        for k in 0..240 {
            let phi = TAU * k as f64 / 240.0;
            let (displacement_obj, rotation_rad) = model(phi, alpha);
            let push = PushOutcome {
                contact_point_obj: aim(phi, alpha).expect("every start meets the disc"),
                displacement_obj,
                rotation_rad,
                heading_obj: DVec2::from_angle(phi + PI + alpha.to_radians()),
            };
            learner.add_push(alpha, &push).expect("a learned alpha");
            learner
                .add_border_point(alpha, DVec2::from_angle(phi) * R)
                .expect("a learned alpha");
        }
    }
    learner.into_gradient()
}

#[test]
fn at_a_learned_alpha_the_predictor_answers_as_the_gradient_does() {
    let ag = learned();
    let predictor = PushPredictor::new(&ag, START);
    for alpha in [0.0, 15.0, -15.0] {
        for k in 0..24 {
            let c = DVec2::from_angle(TAU * k as f64 / 24.0) * R;
            assert_eq!(predictor.predict(c, alpha), ag.predict(c, alpha));
        }
    }
}

#[test]
fn between_learned_alphas_the_predictor_follows_the_pushes_of_one_start() {
    // The learned layers smooth the model along the border (push sigma 2.5 mm, about 3.6
    // deg of the disc): the three-per-lap rotation loses about 1 - exp(-(3 * 0.0625)^2 / 2)
    // = 1.7 % of its 23 deg amplitude, 0.4 deg, at a learned alpha as between them. The
    // predictor adds little to that; interpolating at a fixed aim point mixes pushes that
    // started 20 deg apart, where the rotation differs by up to 24 deg.
    let ag = learned();
    let predictor = PushPredictor::new(&ag, START);
    let (mut ours, mut per_contact) = (Vec::new(), Vec::new());
    for alpha in [-10.0, -7.5, -2.5, 4.0, 7.5, 11.0] {
        for k in 0..72 {
            let phi = TAU * (k as f64 + 0.5) / 72.0;
            let c = aim(phi, alpha).expect("the disc is in the way");
            let (_, truth) = model(phi, alpha);
            let p = predictor.predict(c, alpha).expect("learned all round");
            let q = ag.predict(c, alpha).expect("learned all round");
            ours.push(
                angle::wrap_to_half_period_floor(p.rotation_rad - truth, TAU)
                    .abs()
                    .to_degrees(),
            );
            per_contact.push(
                angle::wrap_to_half_period_floor(q.rotation_rad - truth, TAU)
                    .abs()
                    .to_degrees(),
            );
        }
    }
    let worst = ours.iter().copied().fold(0.0, f64::max);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    eprintln!(
        "rotation error: along the start mean {:.2} worst {worst:.2} deg; per contact mean {:.2} deg",
        mean(&ours),
        mean(&per_contact)
    );
    assert!(worst < 2.5, "the predictor is off by up to {worst:.2} deg");
    assert!(
        mean(&per_contact) > 2.5 * mean(&ours),
        "per contact {:.2} deg, along the start {:.2} deg on average",
        mean(&per_contact),
        mean(&ours)
    );
}

#[test]
fn a_straight_push_starts_on_the_contacts_own_ray() {
    let c = DVec2::new(0.03, 0.04);
    let (s, h) = approach_start(c, 0.0, 0.1).expect("a start");
    assert!((s - c.normalize() * 0.1).length() < 1e-9, "{s}");
    assert!(
        angle::wrap_to_half_period_floor(h - (-c).to_angle(), TAU).abs() < 1e-9,
        "heading {h} is not towards the centroid"
    );
}

#[test]
fn an_alpha_push_starts_where_its_line_meets_the_contact_at_that_alpha() {
    for alpha in [-15.0_f64, -7.5, 5.0, 15.0] {
        for c in [
            DVec2::new(-0.05, 0.0),
            DVec2::new(0.02, -0.04),
            DVec2::new(0.0, 0.057),
        ] {
            let r = 0.1;
            let (s, h) = approach_start(c, alpha, r).expect("a start");
            assert!((s.length() - r).abs() < 1e-9);
            let u = DVec2::from_angle(h);
            // The heading line passes through the contact, ahead of the robot...
            assert!(u.perp_dot(c - s).abs() < 1e-7, "alpha {alpha}, c {c}");
            assert!(u.dot(c - s) > 0.0);
            // ...and makes the angle alpha with the direction to the centroid.
            let dev = angle::wrap_to_half_period_floor(h - (-s).to_angle(), TAU).to_degrees();
            assert!((dev - alpha).abs() < 1e-6, "deviation {dev} vs {alpha}");
        }
    }
}

#[test]
fn a_contact_outside_the_start_circle_has_no_start() {
    assert!(approach_start(DVec2::new(0.2, 0.0), 0.0, 0.1).is_none());
}

/// The two pushes at alpha `alpha_deg` whose heading lines pass through `c` from the start
/// circle of radius `START`: (start, unit heading) of the one that meets `c` before its
/// line passes closest to the centroid, then of the one that meets it past.
fn both_pushes_through(c: DVec2, alpha_deg: f64) -> [(DVec2, DVec2); 2] {
    let q = START * alpha_deg.to_radians().sin() / c.length();
    let gamma = c.to_angle();
    let mut pushes = [gamma - q.asin(), gamma - PI + q.asin()].map(|h| {
        let u = DVec2::from_angle(h);
        let cu = c.dot(u);
        let t = cu + (cu * cu - c.length_squared() + START * START).sqrt();
        (c - t * u, u)
    });
    pushes.sort_by(|a, b| c.dot(a.1).total_cmp(&c.dot(b.1)));
    pushes
}

#[test]
fn two_pushes_through_one_aim_point_at_one_alpha_are_told_apart_by_their_heading() {
    let c = DVec2::new(0.0, 0.04);
    let alpha = 15.0;
    let [near, past] = both_pushes_through(c, alpha);
    // Both are pushes of the protocol: from the start circle, heading at the centroid
    // turned by +15 deg, through c; one meets c before the closest approach, one past it.
    for (s, u) in [near, past] {
        assert!((s.length() - START).abs() < 1e-9);
        let alpha_of = (-s).angle_to(u).to_degrees();
        assert!((alpha_of - alpha).abs() < 1e-6, "alpha {alpha_of}");
        assert!((s + u * (c - s).length() - c).length() < 1e-9);
    }
    assert!(!meets_past_centroid(c, near.1) && meets_past_centroid(c, past.1));
    // 2 acos(25.9 mm / 40 mm) = 99 deg apart: two different pushes.
    assert!(near.1.angle_to(past.1).abs().to_degrees() > 50.0);

    // One learned push of each, with different effects.
    let mut learner = AffordanceLearner::new("l", &LearnerConfig::default()).expect("valid");
    let effects = [
        (DVec2::new(0.01, -0.03), -0.5),
        (DVec2::new(-0.02, 0.0), 0.3),
    ];
    for ((_, u), (d, r)) in [near, past].into_iter().zip(effects) {
        let push = PushOutcome {
            contact_point_obj: c,
            displacement_obj: d,
            rotation_rad: r,
            heading_obj: u,
        };
        learner.add_push(alpha, &push).expect("a learned alpha");
    }
    let ag = learner.into_gradient();
    let shape = Grid::centred(ag.cell_size_m());
    let predictor = PushPredictor::with_shape(&ag, shape, START);
    // Each heading gets its own push's effect, not their mean.
    for ((_, u), (d, r)) in [near, past].into_iter().zip(effects) {
        let p = predictor.predict_push(c, alpha, u).expect("learned there");
        assert!((p.displacement - d).length() < 1e-6, "{p:?}");
        assert!((p.rotation_rad - r).abs() < 1e-6);
        assert!(p.rotation_spread_rad < 1e-3);
    }
    // A planner's push (from the nearer start) is the one that meets c first.
    let p = predictor.predict(c, alpha).expect("learned there");
    assert!((p.rotation_rad - effects[0].1).abs() < 1e-6);
    let (start, heading) = approach_start(c, alpha, START).expect("reachable");
    assert!(start.distance(near.0) < 1e-9);
    assert!(DVec2::from_angle(heading).distance(near.1) < 1e-9);
}
