//! The math of `bench-math` agrees with its straightforward references on small inputs
//! (no timing is checked here), and the references themselves hold on analytic cases.

use agp_affordance::{
    AffordanceLearner, GaussianSmoother, Grid, LearnerConfig, MatchMethod, ShapeMatcher,
    ShapeMatcherConfig,
};
use agp_harness::math::{
    PaperReference, circling_points, learn_from_sim, orientation_disagreement, perimeter,
    polygon_of, push_cost_disagreement, random_goals, random_grid, reference_smooth,
    smoothing_disagreement, start_radius_m,
};
use agp_planning::{PushChoiceSettings, PushPlanner};
use agp_shared_types::Pose2;
use agp_shared_types::angle;
use agp_world::{Rng, RobotDescription, Scenario};
use glam::DVec2;

#[test]
fn the_reference_smoothing_of_an_impulse_is_the_kernels_outer_product() {
    let smoother = GaussianSmoother::new(1.5);
    let k = smoother.kernel();
    let r = smoother.radius();
    let mut src = Grid::default();
    src.set(60, 70, 1.0);
    let mut out = src.zeros_like();
    reference_smooth(k, &src, &mut out);
    for dy in 0..=2 * r {
        for dx in 0..=2 * r {
            let got = out.get(60 + dx - r, 70 + dy - r);
            let want = k[dx] * k[dy];
            assert!((got - want).abs() < 1e-7, "({dx}, {dy}): {got} vs {want}");
        }
    }
    assert!((out.sum() - 1.0).abs() < 1e-5, "mass {}", out.sum());
}

#[test]
fn our_smoothing_equals_the_direct_2d_convolution_within_1e_5() {
    for sigma in [1.0, 2.0] {
        let mut smoother = GaussianSmoother::new(sigma);
        let d = smoothing_disagreement(&mut smoother, &random_grid(5));
        assert!(d <= 1e-5, "sigma {sigma}: max difference {d:e}");
    }
}

/// An L of 30 mm squares, centred on its area centroid.
fn l_shape() -> Vec<DVec2> {
    let v = [
        DVec2::new(0.0, 0.0),
        DVec2::new(0.06, 0.0),
        DVec2::new(0.06, 0.03),
        DVec2::new(0.03, 0.03),
        DVec2::new(0.03, 0.09),
        DVec2::new(0.0, 0.09),
    ];
    // Area centroid: the 60 x 30 bar and the 30 x 60 column.
    let c = (DVec2::new(0.03, 0.015) * 1800.0 + DVec2::new(0.015, 0.06) * 1800.0) / 3600.0;
    v.iter().map(|p| *p - c).collect()
}

#[test]
fn the_paper_match_finds_the_orientation_of_the_brute_force_within_1_deg() {
    let polygon = l_shape();
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("l", &config).expect("valid config");
    let n = (perimeter(&polygon) / 0.002).round() as usize;
    let mut rng = Rng::new(3);
    for p in circling_points(
        &polygon,
        perimeter(&polygon) / n as f64,
        Pose2::default(),
        0.0,
        &mut rng,
    ) {
        learner.add_border_point(0.0, p).expect("a learned alpha");
    }
    let shape = learner.gradient().combined_shape();
    let match_config = ShapeMatcherConfig {
        method: MatchMethod::PaperOverlap,
        symmetry_order: 1,
        paper_step_deg: 1.0,
        ..ShapeMatcherConfig::default()
    };
    let mut matcher = ShapeMatcher::new(&shape, match_config.clone()).expect("a border");
    let mut reference = PaperReference::new(&shape, &match_config);
    let mut truths = Vec::new();
    let sets: Vec<_> = (0..4)
        .map(|_| {
            let pose = Pose2::new(
                rng.range(-0.3, 0.3),
                rng.range(-0.3, 0.3),
                rng.range(0.0, std::f64::consts::TAU),
            );
            truths.push(pose.theta);
            circling_points(&polygon, 0.001, pose, 0.0005, &mut rng)
        })
        .collect();
    let d = orientation_disagreement(&mut matcher, &mut reference, &sets).expect("enough points");
    assert!(
        d.to_degrees() <= 1.0,
        "ours and the brute force differ by {:.2} deg",
        d.to_degrees()
    );
    // The brute force itself finds the true orientation (the paper's method ties over a
    // few degrees: 5 deg allowed, as in agp-affordance's tests).
    for (points, truth) in sets.iter().zip(truths) {
        let found = reference.orientation_rad(points);
        let e = angle::distance(found, truth, std::f64::consts::TAU).to_degrees();
        assert!(e <= 5.0, "brute force off by {e:.1} deg");
    }
}

#[test]
fn our_push_search_chooses_a_push_of_the_reference_searchs_cost() {
    let scenario = Scenario::builtin("lshape").expect("built-in");
    let ag = learn_from_sim(&scenario, 12).expect("a gradient");
    assert!(polygon_of(&scenario).is_ok());
    let robot = RobotDescription::epuck();
    let settings = PushChoiceSettings {
        contact_count: 36,
        alpha_step_deg: 5.0,
        ..PushChoiceSettings::new(1, start_radius_m(&scenario, &robot))
    };
    let planner = PushPlanner::new(&ag, settings);
    let goals = random_goals(4, 1);
    let d = push_cost_disagreement(&planner, Pose2::new(0.1, -0.05, 0.3), &goals);
    assert!(d <= 1e-9, "costs differ by {d:e} m");
    assert!(
        goals
            .iter()
            .all(|g| planner.plan(Pose2::default(), g).is_some()),
        "the search found no push"
    );
}

#[test]
fn a_planner_given_other_push_lengths_plans_as_one_built_with_them() {
    let scenario = Scenario::builtin("triangle").expect("built-in");
    let ag = learn_from_sim(&scenario, 12).expect("a gradient");
    let robot = RobotDescription::epuck();
    let settings = PushChoiceSettings {
        contact_count: 36,
        alpha_step_deg: 5.0,
        ..PushChoiceSettings::new(3, start_radius_m(&scenario, &robot))
    };
    let shared = PushPlanner::new(&ag, settings.clone()).with_push_fractions(vec![1.0]);
    let built = PushPlanner::new(
        &ag,
        PushChoiceSettings {
            push_fractions: vec![1.0],
            ..settings
        },
    );
    let estimate = Pose2::new(0.1, -0.05, 0.3);
    for goal in random_goals(4, 2) {
        assert_eq!(shared.plan(estimate, &goal), built.plan(estimate, &goal));
    }
}
