mod support;

use std::f64::consts::{PI, TAU};

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, GradientFromGridsError, Grid, GridSetAssembler,
    LearnerConfig, Prediction, PushOutcome, PushPredictor,
};
use agp_shared_types::{
    GRID_CELLS, GRIDS_PER_ALPHA, GradientGrid, GridHeader, GridKind, MAX_GRID_ALPHAS,
};
use glam::DVec2;
use support::Rng;

/// Radius of the round object of the synthetic trials, metres.
const RADIUS_M: f64 = 0.04;

fn contact(phi: f64) -> DVec2 {
    DVec2::from_angle(phi) * RADIUS_M
}

/// Two noisy trials every 6 degrees at each of the paper's alphas, the border seen all
/// round: the centroid moves about 20 mm away from the contact (3 mm noise), the object
/// turns by a smooth function of the contact that changes sign twice round the disc (0.05
/// rad noise), so both R+ and R- are learned, and the spreads are not zero.
fn learned() -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("disc", &config).expect("a valid config");
    let mut rng = Rng::new(7);
    for &alpha in &config.alphas_deg {
        let a = f64::to_radians(alpha);
        for k in 0..120 {
            let phi = TAU * (k / 2) as f64 / 60.0 + rng.range(-0.02, 0.02);
            let noise = DVec2::new(rng.normal(), rng.normal()) * 0.003;
            let push = PushOutcome {
                contact_point_obj: contact(phi),
                displacement_obj: DVec2::from_angle(phi + PI + 0.5 * a) * 0.02 + noise,
                rotation_rad: 0.3 * phi.sin() + 0.8 * a + 0.05 * rng.normal(),
                // A third of the pushes at +-15 deg filed as meeting the border past the
                // centroid (impossible on a disc, but what the grids carry all the same).
                heading_obj: if alpha != 0.0 && k % 3 == 0 {
                    contact(phi)
                } else {
                    -contact(phi)
                },
            };
            learner.add_push(alpha, &push).expect("a learned alpha");
            for s in 0..2 {
                let border = contact(phi + TAU * s as f64 / 240.0);
                learner
                    .add_border_point(alpha, border)
                    .expect("a learned alpha");
            }
        }
    }
    learner.into_gradient()
}

fn empty_grid() -> Box<GradientGrid> {
    Box::new(GradientGrid {
        header: GridHeader::default(),
        cells: [0.0; GRID_CELLS],
    })
}

/// Every grid of `ag` as the estimator publishes them: alpha by alpha, every kind.
fn published(ag: &AffordanceGradient, seq: u64) -> Vec<Box<GradientGrid>> {
    let mut grids = Vec::new();
    for alpha in ag.alphas_deg() {
        for kind in GridKind::ALL {
            let mut g = empty_grid();
            ag.write_component(alpha, kind, seq, &mut g)
                .expect("a learned alpha");
            grids.push(g);
        }
    }
    grids
}

fn rebuilt(grids: &[Box<GradientGrid>]) -> Result<AffordanceGradient, GradientFromGridsError> {
    AffordanceGradient::from_grids("disc", grids.iter().map(|g| &**g))
}

/// `|a - b|` relative to `|a|`, or to `floor` when `|a|` is smaller: a value passing
/// through zero (the signed rotation between the two senses) is compared at the scale of
/// the quantity, not of its rounding.
fn relative(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / a.abs().max(floor)
}

/// The largest relative difference between two predictions, over every field.
///
/// A spread is `sqrt(E[x^2] - E[x]^2)`, both moments about the mean's size: f32 rounds them
/// relative to that, so a spread much smaller than its mean carries a rounding error
/// relative to the root mean square `sqrt(E[x^2])`, not to itself (here, where the rotation
/// spread is 15 times smaller than the rotation, the difference reaches 4e-5 of the spread
/// and 3e-6 of the root mean square). Spreads are compared at that scale; a signed rotation
/// passing through zero at the scale of 1 mrad.
fn prediction_difference(a: &Prediction, b: &Prediction) -> f64 {
    let rms = |spread: f64, mean: f64| spread.hypot(mean);
    [
        a.displacement.distance(b.displacement) / a.displacement.length().max(1e-3),
        relative(a.rotation_rad, b.rotation_rad, 1e-3),
        relative(a.confidence, b.confidence, 1e-3),
        relative(
            a.displacement_spread_m,
            b.displacement_spread_m,
            rms(a.displacement_spread_m, a.displacement.length()),
        ),
        relative(
            a.rotation_spread_rad,
            b.rotation_spread_rad,
            rms(a.rotation_spread_rad, a.rotation_rad).max(1e-3),
        ),
    ]
    .into_iter()
    .fold(0.0, f64::max)
}

#[test]
fn a_gradient_rebuilt_from_its_grids_predicts_as_the_original() {
    let original = learned();
    let grids = published(&original, 4);
    assert_eq!(grids.len(), 3 * GRIDS_PER_ALPHA);
    let copy = rebuilt(&grids).expect("a complete set");

    assert_eq!(copy.object_name(), "disc");
    assert_eq!(copy.cell_size_m(), original.cell_size_m());
    assert_eq!(
        copy.alphas_deg().collect::<Vec<_>>(),
        original.alphas_deg().collect::<Vec<_>>()
    );
    for alpha in original.alphas_deg() {
        assert_eq!(copy.push_count(alpha), original.push_count(alpha));
        assert_eq!(
            copy.border_point_count(alpha),
            original.border_point_count(alpha)
        );
        assert_eq!(
            copy.max_rotation_deg(alpha),
            original.max_rotation_deg(alpha)
        );
    }

    // Tolerance: every weighted sum comes back as fl(fl(sum / weight) * weight), within
    // one f32 ulp (1.2e-7) of the original; a prediction divides interpolated sums, and a
    // spread takes the difference of two moments (see `prediction_difference`).
    let mut rng = Rng::new(11);
    let (mut compared, mut worst) = (0, 0.0_f64);
    let shape = original.combined_shape();
    let past_of_original = PushPredictor::with_shape(&original, shape.clone(), 0.1);
    let past_of_copy = PushPredictor::with_shape(&copy, shape, 0.1);
    for alpha in [-15.0, -10.0, -4.0, 0.0, 3.0, 7.5, 15.0] {
        for k in 0..360 {
            let phi = TAU * (k as f64 + rng.uniform()) / 360.0;
            let p = contact(phi) * rng.range(0.9, 1.1);
            // The pushes that meet the border first, and (heading away from the centroid)
            // those past it.
            for (a, b) in [
                (original.predict(p, alpha), copy.predict(p, alpha)),
                (
                    past_of_original.predict_push(p, alpha, p),
                    past_of_copy.predict_push(p, alpha, p),
                ),
            ] {
                assert_eq!(a.is_some(), b.is_some(), "alpha {alpha} at {p}");
                if let (Some(a), Some(b)) = (a, b) {
                    let d = prediction_difference(&a, &b);
                    assert!(d < 1e-5, "alpha {alpha} at {p}: {a:?} against {b:?}");
                    worst = worst.max(d);
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 3000, "only {compared} predictions compared");
    eprintln!("{compared} predictions, worst relative difference {worst:.2e}");

    let (a, b) = (original.combined_shape(), copy.combined_shape());
    assert!(a.same_geometry(&b));
    let shape_error = a
        .cells()
        .iter()
        .zip(b.cells())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0_f32, f32::max);
    assert!(shape_error < 1e-6, "combined S differs by {shape_error}");
    assert!(a.max() > 0.99, "the combined S is normalised");
}

#[test]
fn each_grid_carries_its_set_and_its_layer_in_the_header() {
    let ag = learned();
    for g in published(&ag, 9) {
        let h = g.header;
        assert_eq!((h.seq, h.alpha_count), (9, 3));
        assert_eq!(h.pushes, ag.push_count(h.alpha_deg).expect("learned"));
        assert_eq!(
            h.border_points,
            ag.border_point_count(h.alpha_deg).expect("learned")
        );
        assert_eq!(
            Some(h.max_rotation_rad.to_degrees()),
            ag.max_rotation_deg(h.alpha_deg)
        );
        assert!(h.shape_scale > 1.0, "S's scale {}", h.shape_scale);
        assert_eq!(h.cell_size_m, ag.cell_size_m());
    }
}

#[test]
fn the_grids_rebuild_the_same_gradient_in_any_order() {
    let original = learned();
    let mut grids = published(&original, 1);
    let in_order = rebuilt(&grids).expect("a complete set");
    let mut rng = Rng::new(3);
    for k in (1..grids.len()).rev() {
        grids.swap(k, rng.next_u64() as usize % (k + 1));
    }
    assert_eq!(rebuilt(&grids).expect("a complete set"), in_order);
}

#[test]
fn a_set_missing_a_grid_or_a_whole_alpha_is_refused() {
    let ag = learned();
    let mut grids = published(&ag, 1);
    let at = grids
        .iter()
        .position(|g| {
            g.header.kind == GridKind::RotationSqMean as u32 && g.header.alpha_deg == 15.0
        })
        .expect("published");
    let dropped = grids.remove(at);
    assert_eq!(
        rebuilt(&grids),
        Err(GradientFromGridsError::MissingKind {
            kind: GridKind::RotationSqMean,
            alpha_deg: 15.0
        })
    );
    grids.insert(at, dropped);
    grids.retain(|g| g.header.alpha_deg != -15.0);
    assert_eq!(
        rebuilt(&grids),
        Err(GradientFromGridsError::MissingAlphas {
            found: 2,
            expected: 3
        })
    );
    assert_eq!(rebuilt(&[]), Err(GradientFromGridsError::Empty));
}

#[test]
fn a_set_sent_again_while_under_way_is_taken_from_its_start() {
    // A bridge whose far end comes back resends the latest set: the planner's assembler
    // then holds part of that set already, and must take the resent one whole.
    let ag = learned();
    let grids = published(&ag, 1);
    let mut set = GridSetAssembler::new();
    for g in &grids[..grids.len() / 2] {
        set.add_or_start_over(g).expect("the first half");
    }
    for g in &grids {
        set.add_or_start_over(g).expect("the set again, whole");
    }
    assert!(set.is_complete());
    assert_eq!(set.finish("disc"), rebuilt(&grids));
    // The plain `add` still refuses the duplicate: a set holds each grid once.
    let mut strict = GridSetAssembler::new();
    strict.add(&grids[0]).expect("first");
    assert!(matches!(
        strict.add(&grids[0]),
        Err(GradientFromGridsError::Duplicate { .. })
    ));
}

#[test]
fn a_duplicated_grid_is_refused() {
    let ag = learned();
    let mut grids = published(&ag, 1);
    let mut again = empty_grid();
    ag.write_component(0.0, GridKind::PositionY, 1, &mut again)
        .expect("learned");
    grids.insert(5, again);
    assert_eq!(
        rebuilt(&grids),
        Err(GradientFromGridsError::Duplicate {
            kind: GridKind::PositionY,
            alpha_deg: 0.0
        })
    );
}

#[test]
fn grids_of_two_publications_are_refused() {
    let ag = learned();
    let mut grids = published(&ag, 1);
    grids[20].header.seq = 2;
    assert_eq!(
        rebuilt(&grids),
        Err(GradientFromGridsError::MixedSeq {
            expected: 1,
            found: 2
        })
    );
}

#[test]
fn a_lone_grid_a_set_too_large_or_a_bad_header_is_refused() {
    let ag = learned();
    let mut lone = empty_grid();
    Grid::default().write_into(GridKind::Shape, 0.0, 1, &mut lone);
    assert!(matches!(
        rebuilt(&[lone]),
        Err(GradientFromGridsError::NotInSet { .. })
    ));

    let mut grids = published(&ag, 1);
    grids[0].header.alpha_count = MAX_GRID_ALPHAS as u32 + 1;
    assert_eq!(
        rebuilt(&grids),
        Err(GradientFromGridsError::TooManyAlphas {
            alpha_count: MAX_GRID_ALPHAS as u32 + 1
        })
    );

    let mut grids = published(&ag, 1);
    grids[3].header.kind = 99;
    assert!(matches!(
        rebuilt(&grids),
        Err(GradientFromGridsError::BadHeader(_))
    ));

    let mut grids = published(&ag, 1);
    grids[7].header.pushes += 1;
    assert!(matches!(
        rebuilt(&grids),
        Err(GradientFromGridsError::LayerMismatch { .. })
    ));
}

#[test]
fn the_assembler_says_what_it_holds_and_starts_over_when_cleared() {
    let ag = learned();
    let grids = published(&ag, 5);
    let mut set = GridSetAssembler::new();
    assert_eq!((set.seq(), set.expected_grid_count()), (None, None));
    for g in &grids[..GRIDS_PER_ALPHA + 1] {
        set.add(g).expect("a grid of the set");
    }
    assert_eq!(set.seq(), Some(5));
    assert_eq!(set.grid_count(), GRIDS_PER_ALPHA + 1);
    assert_eq!(set.expected_grid_count(), Some(3 * GRIDS_PER_ALPHA));
    assert!(!set.is_complete());
    assert!(set.finish("disc").is_err(), "incomplete");
    // A grid refused leaves the set as it was.
    assert!(set.add(&grids[0]).is_err());
    assert_eq!(set.grid_count(), GRIDS_PER_ALPHA + 1);

    set.clear();
    assert_eq!(set.seq(), None);
    for g in &grids {
        set.add(g).expect("a grid of the set");
    }
    assert!(set.is_complete());
    let gradient = set.finish("disc").expect("a complete set");
    assert_eq!(set.seq(), None, "finishing empties the assembler");
    assert_eq!(Ok(gradient), rebuilt(&grids));
}
