mod support;

use agp_affordance::{GaussianSmoother, Grid, SmoothingMethod};
use agp_shared_types::GRID_SIDE;
use support::Rng;

/// The sampled Gaussian the smoother should apply along one axis: taps within
/// ceil(3 sigma), normalised to sum 1.
fn analytic_kernel(sigma: f64) -> (Vec<f64>, usize) {
    let r = (3.0 * sigma).ceil() as usize;
    let taps: Vec<f64> = (0..=2 * r)
        .map(|t| {
            let d = t as f64 - r as f64;
            (-d * d / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let total: f64 = taps.iter().sum();
    (taps.iter().map(|t| t / total).collect(), r)
}

fn random_grid(seed: u64) -> Grid {
    let mut rng = Rng::new(seed);
    let mut g = Grid::default();
    g.cells_mut()
        .iter_mut()
        .for_each(|c| *c = rng.range(-1.0, 1.0) as f32);
    g
}

fn max_abs_diff(a: &Grid, b: &Grid) -> f32 {
    a.cells()
        .iter()
        .zip(b.cells())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn max_abs(a: &Grid) -> f32 {
    a.cells().iter().map(|x| x.abs()).fold(0.0, f32::max)
}

#[test]
fn the_three_methods_agree_on_random_grids() {
    for (seed, sigma) in [(1, 2.0), (2, 1.3), (3, 3.7), (4, 0.6)] {
        let src = random_grid(seed);
        let mut smoother = GaussianSmoother::new(sigma);
        let mut reference = Grid::default();
        smoother.smooth_with(SmoothingMethod::Direct2d, &src, &mut reference);
        let scale = max_abs(&reference);
        for method in [SmoothingMethod::Separable, SmoothingMethod::FaerMatmul] {
            let mut out = Grid::default();
            smoother.smooth_with(method, &src, &mut out);
            let diff = max_abs_diff(&out, &reference);
            assert!(
                diff <= 1e-4 * scale,
                "{method:?} sigma {sigma}: differs by {diff} (scale {scale})"
            );
        }
    }
}

#[test]
fn smoothing_an_impulse_gives_the_sampled_gaussian() {
    let sigma = 2.0;
    let (k, r) = analytic_kernel(sigma);
    for method in [
        SmoothingMethod::Separable,
        SmoothingMethod::FaerMatmul,
        SmoothingMethod::Direct2d,
    ] {
        let mut src = Grid::default();
        let (ci, cj) = (70, 40);
        src.set(ci, cj, 1.0);
        let mut out = Grid::default();
        GaussianSmoother::new(sigma).smooth_with(method, &src, &mut out);
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                let (dx, dy) = (i as isize - ci as isize, j as isize - cj as isize);
                let expected = if dx.unsigned_abs() <= r && dy.unsigned_abs() <= r {
                    k[(dx + r as isize) as usize] * k[(dy + r as isize) as usize]
                } else {
                    0.0
                };
                let got = f64::from(out.get(i, j));
                assert!(
                    (got - expected).abs() < 1e-6,
                    "{method:?} at ({i}, {j}): {got} vs {expected}"
                );
            }
        }
        // Away from the borders the sum is preserved.
        assert!(
            (out.sum() - 1.0).abs() < 1e-5,
            "{method:?}: sum {}",
            out.sum()
        );
    }
}

#[test]
fn an_impulse_next_to_the_border_loses_the_mass_beyond_it() {
    let sigma = 2.0;
    let (k, r) = analytic_kernel(sigma);
    let mut src = Grid::default();
    src.set(1, 64, 1.0);
    let mut out = Grid::default();
    GaussianSmoother::new(sigma).smooth(&src, &mut out);
    // Along x, the taps landing left of cell 0 (offsets -r ..= -2) are lost.
    let kept: f64 = k[r - 1..].iter().sum();
    assert!(
        (out.sum() - kept).abs() < 1e-5,
        "sum {} vs {kept}",
        out.sum()
    );
}

#[test]
fn smoothing_in_place_equals_smoothing_into_another_grid() {
    let src = random_grid(9);
    for method in [
        SmoothingMethod::Separable,
        SmoothingMethod::FaerMatmul,
        SmoothingMethod::Direct2d,
    ] {
        let mut smoother = GaussianSmoother::new(2.0).with_method(method);
        let mut out = Grid::default();
        smoother.smooth(&src, &mut out);
        let mut in_place = src.clone();
        smoother.smooth_in_place(&mut in_place);
        assert!(max_abs_diff(&out, &in_place) <= 1e-6, "{method:?}");
    }
}

#[test]
fn the_default_method_is_the_separable_loop() {
    let s = GaussianSmoother::from_sigma_m(0.004, 0.002);
    assert_eq!(s.method(), SmoothingMethod::Separable);
    assert_eq!(s.sigma_cells(), 2.0);
    assert_eq!(s.radius(), 6);
    assert_eq!(s.kernel().len(), 13);
    let total: f32 = s.kernel().iter().sum();
    assert!((total - 1.0).abs() < 1e-6);
}
