//! Times Gaussian smoothing (three methods) and shape matching (two methods), and checks
//! matching accuracy over many random poses. Prints medians; asserts nothing.
//!
//! As measured (this crate at opt-level 3 without debug assertions, dependencies as the
//! dev profile builds them, no release build of the workspace):
//!
//! ```text
//! cargo run -p agp-affordance --example measure \
//!   --config 'profile.dev.package.agp-affordance.opt-level=3' \
//!   --config 'profile.dev.package.agp-affordance.debug-assertions=false' \
//!   --config 'profile.dev.package.agp-affordance.overflow-checks=false'
//! ```

#[path = "../tests/support/mod.rs"]
mod support;

use agp_shared_types::angle;
use std::hint::black_box;
use std::time::Instant;

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, GaussianSmoother, Grid, LearnerConfig, MatchMethod,
    PushOutcome, ShapeMatcher, ShapeMatcherConfig, SmoothingMethod,
};
use glam::DVec2;
use support::{Rng, l_tetromino, learned_shape, place, sample_border, square, triangle};

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn time_us(runs: usize, mut f: impl FnMut()) -> (f64, f64) {
    for _ in 0..runs.div_ceil(10) {
        f();
    }
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    (percentile(&mut t, 0.5), percentile(&mut t, 0.9))
}

fn disc_gradient() -> AffordanceGradient {
    let config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new("disc", &config).expect("valid config");
    for &alpha in &config.alphas_deg {
        for k in 0..60 {
            let phi = std::f64::consts::TAU * k as f64 / 60.0;
            let c = DVec2::from_angle(phi) * 0.04;
            let push = PushOutcome {
                contact_point_obj: c,
                displacement_obj: -c * 0.5,
                rotation_rad: 0.3 * phi.sin() + alpha.to_radians(),
                heading_obj: -c,
            };
            learner.add_push(alpha, &push).expect("learned alpha");
        }
    }
    learner.into_gradient()
}

fn main() {
    println!("smoothing 128 x 128, sigma 2 cells (radius 6):");
    let mut rng = Rng::new(1);
    let mut src = Grid::default();
    src.cells_mut()
        .iter_mut()
        .for_each(|c| *c = rng.uniform() as f32);
    let mut dst = Grid::default();
    let mut smoother = GaussianSmoother::new(2.0);
    for (method, runs) in [
        (SmoothingMethod::Separable, 5000),
        (SmoothingMethod::FaerMatmul, 2000),
        (SmoothingMethod::Direct2d, 50),
    ] {
        let (median, p90) = time_us(runs, || {
            smoother.smooth_with(method, black_box(&src), &mut dst);
            black_box(&dst);
        });
        println!("  {method:<12?} median {median:8.1} us   p90 {p90:8.1} us   ({runs} runs)");
    }

    println!(
        "prediction (60 pushes per alpha on a 40 mm disc, random contact on it, random alpha):"
    );
    let ag = disc_gradient();
    let mut rng = Rng::new(3);
    let queries: Vec<(DVec2, f64)> = (0..1000)
        .map(|_| {
            (
                DVec2::from_angle(rng.range(0.0, 6.3)) * 0.04,
                rng.range(-15.0, 15.0),
            )
        })
        .collect();
    let (median, p90) = time_us(2000, || {
        for &(c, a) in &queries {
            black_box(ag.predict(black_box(c), a));
        }
    });
    let per_call = |us: f64| us * 1e3 / queries.len() as f64;
    println!(
        "  predict      median {:8.1} ns   p90 {:8.1} ns   (per call, 2000 x 1000 calls)",
        per_call(median),
        per_call(p90)
    );

    println!(
        "shape matching (1 mm noise, points every 3 mm (dense: 1 mm), 200 random poses per row):"
    );
    let shapes = [
        ("triangle", triangle(0.1), 3),
        ("lshape", l_tetromino(0.03), 1),
        ("square", square(0.06), 4),
    ];
    for method in [MatchMethod::ChamferIcp, MatchMethod::PaperOverlap] {
        for (name, v, order) in &shapes {
            let config = ShapeMatcherConfig {
                method,
                symmetry_order: *order,
                ..ShapeMatcherConfig::default()
            };
            let built = Instant::now();
            let mut m = ShapeMatcher::new(&learned_shape(v, 0.0025), config).expect("a border");
            let build_ms = built.elapsed().as_secs_f64() * 1e3;
            let period = m.symmetry_period_rad();
            for coverage in ["full", "arc60", "patchy60", "dense"] {
                let mut rng = Rng::new(7);
                let (mut times, mut dp, mut da) = (Vec::new(), Vec::new(), Vec::new());
                let mut ok = 0;
                let mut npts = 0;
                let cases = 200;
                for _ in 0..cases {
                    let position = DVec2::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5));
                    let theta = rng.range(0.0, std::f64::consts::TAU);
                    let phase = rng.uniform();
                    let spacing = if coverage == "dense" { 0.001 } else { 0.003 };
                    let points: Vec<DVec2> = sample_border(v, spacing)
                        .into_iter()
                        .filter(|&(_, s)| match coverage {
                            "full" | "dense" => true,
                            "arc60" => (s - phase).rem_euclid(1.0) < 0.6,
                            _ => ((s + phase) * 5.0).fract() < 0.6,
                        })
                        .map(|(p, _)| place(p, position, theta))
                        .collect::<Vec<_>>()
                        .into_iter()
                        .map(|p| p + DVec2::new(rng.normal(), rng.normal()) * 0.001)
                        .collect();
                    npts = points.len();
                    let s = Instant::now();
                    let found = m.match_points(&points).expect("enough points").best;
                    times.push(s.elapsed().as_secs_f64() * 1e6);
                    let e = (
                        found.position.distance(position),
                        angle::distance(found.orientation_rad, theta, period),
                    );
                    if e.0 <= 0.003 && e.1 <= 3f64.to_radians() {
                        ok += 1;
                    }
                    dp.push(e.0 * 1e3);
                    da.push(e.1.to_degrees());
                }
                println!(
                    "  {method:<12?} {name:<8} {coverage:<8} ({npts:3} pts): median {:7.1} us p90 {:7.1} us | within 3 mm & 3 deg {ok:3}/{cases} | median err {:.2} mm {:.2} deg | build {build_ms:.1} ms",
                    percentile(&mut times, 0.5),
                    percentile(&mut times, 0.9),
                    percentile(&mut dp, 0.5),
                    percentile(&mut da, 0.5),
                );
            }
        }
    }
}
