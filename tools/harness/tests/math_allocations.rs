//! The hot paths `bench-math` times allocate nothing once built: smoothing, the paper's
//! orientation match and the push search. One test in this binary, so that no other test
//! thread allocates while it counts.

use agp_affordance::{GaussianSmoother, MatchMethod, ShapeMatcher, ShapeMatcherConfig};
use agp_harness::math::{
    circling_points, learn_from_sim, perimeter, polygon_of, random_goals, random_grid,
    start_radius_m,
};
use agp_planning::{PushChoiceSettings, PushPlanner};
use agp_runtime::alloc_count;
use agp_shared_types::Pose2;
use agp_world::{Rng, RobotDescription, Scenario};

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

/// Allocations `f` makes, on any thread of the process.
fn allocations_of(mut f: impl FnMut()) -> u64 {
    alloc_count::enable();
    let before = alloc_count::process_allocations();
    f();
    alloc_count::process_allocations() - before
}

#[test]
fn smoothing_matching_and_the_push_search_allocate_nothing_once_built() {
    let mut smoother = GaussianSmoother::new(2.0);
    let src = random_grid(1);
    let mut dst = src.zeros_like();
    let n = allocations_of(|| {
        for _ in 0..3 {
            smoother.smooth(&src, &mut dst);
        }
    });
    assert_eq!(n, 0, "smoothing allocated {n} times");

    let scenario = Scenario::builtin("lshape").expect("built-in");
    let ag = learn_from_sim(&scenario, 8).expect("a gradient");
    let polygon = polygon_of(&scenario).expect("a polygon");
    let config = ShapeMatcherConfig {
        method: MatchMethod::PaperOverlap,
        paper_step_deg: 1.0,
        ..ShapeMatcherConfig::default()
    };
    let mut matcher = ShapeMatcher::new(&ag.combined_shape(), config).expect("a border");
    let mut rng = Rng::new(2);
    let points = circling_points(
        &polygon,
        perimeter(&polygon) / 300.0,
        Pose2::new(0.2, -0.1, 1.0),
        0.001,
        &mut rng,
    );
    let n = allocations_of(|| {
        for _ in 0..3 {
            assert!(matcher.match_points(&points).is_ok());
        }
    });
    assert_eq!(n, 0, "the orientation match allocated {n} times");

    let robot = RobotDescription::epuck();
    let planner = PushPlanner::new(
        &ag,
        PushChoiceSettings::new(1, start_radius_m(&scenario, &robot)),
    );
    let goals = random_goals(3, 4);
    let n = allocations_of(|| {
        for goal in &goals {
            assert!(planner.plan(Pose2::default(), goal).is_some());
        }
    });
    assert_eq!(n, 0, "the push search allocated {n} times");
}
