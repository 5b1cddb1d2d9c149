mod support;

use agp_affordance::{DEFAULT_CELL_SIZE_M, Grid, GridPayloadReadError};
use agp_shared_types::{GRID_CELLS, GRID_SIDE, GradientGrid, GridHeader, GridKind};
use glam::DVec2;
use support::Rng;

fn empty_payload() -> Box<GradientGrid> {
    Box::new(GradientGrid {
        header: GridHeader::default(),
        cells: [0.0; GRID_CELLS],
    })
}

#[test]
fn a_centred_grid_has_the_centroid_at_its_middle() {
    let g = Grid::default();
    assert_eq!(g.cell_size_m(), DEFAULT_CELL_SIZE_M);
    assert_eq!(g.origin_m(), DVec2::splat(-0.128));
    assert!((g.extent_m() - 0.256).abs() < 1e-12);
    // The centroid is the corner shared by the four middle cells.
    let c = g.to_cell_coords(DVec2::ZERO);
    assert_eq!(c, DVec2::splat(GRID_SIDE as f64 / 2.0 - 0.5));
}

#[test]
fn cell_centres_map_back_to_their_cells() {
    let g = Grid::centred(0.003);
    for (i, j) in [(0, 0), (127, 0), (0, 127), (64, 63), (127, 127), (5, 99)] {
        let p = g.cell_centre_m(i, j);
        assert_eq!(g.cell_at(p), Some((i, j)));
        let c = g.to_cell_coords(p);
        assert!((c - DVec2::new(i as f64, j as f64)).length() < 1e-9);
        assert!((g.from_cell_coords(c) - p).length() < 1e-12);
    }
    assert_eq!(g.cell_at(DVec2::new(0.2, 0.0)), None);
    assert_eq!(g.cell_at(DVec2::new(0.0, -0.193)), None);
}

#[test]
fn bilinear_sample_reproduces_a_linear_field_exactly() {
    let mut g = Grid::default();
    let f = |p: DVec2| 0.5 + 3.0 * p.x - 7.0 * p.y;
    for j in 0..GRID_SIDE {
        for i in 0..GRID_SIDE {
            g.set(i, j, f(g.cell_centre_m(i, j)) as f32);
        }
    }
    let mut rng = Rng::new(1);
    for _ in 0..1000 {
        // Between the first and last cell centres, where all four neighbours exist.
        let p = DVec2::new(rng.range(-0.126, 0.126), rng.range(-0.126, 0.126));
        assert!((f64::from(g.sample(p)) - f(p)).abs() < 1e-5, "at {p}");
    }
    // Off the grid, everything is zero.
    assert_eq!(g.sample(DVec2::new(0.3, 0.0)), 0.0);
}

#[test]
fn a_gaussian_touches_only_cells_within_three_sigma() {
    let mut g = Grid::default();
    let (p, sigma, w) = (DVec2::new(0.0123, -0.0311), 0.005, 2.5_f32);
    g.add_gaussian(p, sigma, w);
    let mut touched = 0;
    for j in 0..GRID_SIDE {
        for i in 0..GRID_SIDE {
            let d = g.cell_centre_m(i, j).distance(p);
            let v = g.get(i, j);
            if d > 3.0 * sigma {
                assert_eq!(v, 0.0, "cell ({i}, {j}) at {d} m");
            } else {
                touched += 1;
                let expected = f64::from(w) * (-d * d / (2.0 * sigma * sigma)).exp();
                assert!((f64::from(v) - expected).abs() < 1e-6);
            }
        }
    }
    // About pi (3 sigma / cell)^2 = pi * 7.5^2 = 177 cells.
    assert!((150..=200).contains(&touched), "{touched} cells touched");
}

#[test]
fn a_gaussian_off_the_grid_adds_nothing() {
    let mut g = Grid::default();
    g.add_gaussian(DVec2::new(1.0, 1.0), 0.005, 1.0);
    g.add_gaussian(DVec2::new(f64::NAN, 0.0), 0.005, 1.0);
    assert_eq!(g.sum(), 0.0);
}

#[test]
fn a_grid_written_into_a_payload_reads_back_the_same() {
    let mut g = Grid::centred(0.0025);
    let mut rng = Rng::new(2);
    g.cells_mut()
        .iter_mut()
        .for_each(|c| *c = rng.uniform() as f32);
    let mut payload = empty_payload();
    g.write_into(GridKind::RotationNeg, -15.0, 42, &mut payload);
    let h = payload.header;
    assert_eq!(h.seq, 42);
    assert_eq!(GridKind::from_u32(h.kind), Some(GridKind::RotationNeg));
    assert_eq!(h.alpha_deg, -15.0);
    assert_eq!((h.width, h.height), (GRID_SIDE as u32, GRID_SIDE as u32));
    let back = Grid::from_payload(&payload).expect("a valid payload");
    assert_eq!(back.cells(), g.cells());
    assert!((back.cell_size_m() - 0.0025).abs() < 1e-9);
    assert_eq!(back.origin_m(), g.origin_m());
}

#[test]
fn a_payload_of_another_size_kind_or_geometry_is_refused() {
    let g = Grid::default();
    let mut payload = empty_payload();
    g.write_into(GridKind::Shape, 0.0, 1, &mut payload);
    payload.header.width = 64;
    assert!(matches!(
        Grid::from_payload(&payload),
        Err(GridPayloadReadError::WrongSize { width: 64, .. })
    ));
    g.write_into(GridKind::Shape, 0.0, 1, &mut payload);
    // The first number past the kinds.
    let unknown = GridKind::ALL.len() as u32;
    payload.header.kind = unknown;
    assert_eq!(
        Grid::from_payload(&payload),
        Err(GridPayloadReadError::UnknownKind(unknown))
    );
    g.write_into(GridKind::Shape, 0.0, 1, &mut payload);
    payload.header.cell_size_m = 0.0;
    assert!(matches!(
        Grid::from_payload(&payload),
        Err(GridPayloadReadError::BadCellSize(_))
    ));
    g.write_into(GridKind::Shape, 0.0, 1, &mut payload);
    payload.header.origin_x_m = f64::INFINITY;
    assert!(matches!(
        Grid::from_payload(&payload),
        Err(GridPayloadReadError::BadOrigin(..))
    ));
}
