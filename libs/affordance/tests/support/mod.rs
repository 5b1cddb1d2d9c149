//! Shared by the integration tests: a deterministic RNG and minimal polygon geometry.
#![allow(dead_code)]

use agp_affordance::Grid;
use glam::DVec2;

/// SplitMix64: deterministic, good enough for test noise.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Area centroid of a simple polygon.
pub fn centroid(v: &[DVec2]) -> DVec2 {
    let (mut a, mut c) = (0.0, DVec2::ZERO);
    for k in 0..v.len() {
        let (p, q) = (v[k], v[(k + 1) % v.len()]);
        let cross = p.perp_dot(q);
        a += cross;
        c += (p + q) * cross;
    }
    c / (3.0 * a)
}

/// `v` moved so that its area centroid is the origin.
pub fn centred(v: &[DVec2]) -> Vec<DVec2> {
    let c = centroid(v);
    v.iter().map(|p| *p - c).collect()
}

/// Equilateral triangle of side `side` metres, centred.
pub fn triangle(side: f64) -> Vec<DVec2> {
    centred(&[
        DVec2::ZERO,
        DVec2::new(side, 0.0),
        DVec2::new(side / 2.0, side * 3f64.sqrt() / 2.0),
    ])
}

/// Square of side `side` metres, centred.
pub fn square(side: f64) -> Vec<DVec2> {
    centred(&[
        DVec2::ZERO,
        DVec2::new(side, 0.0),
        DVec2::new(side, side),
        DVec2::new(0.0, side),
    ])
}

/// L tetromino of four square cells of side `cell` metres (three stacked, one beside the
/// bottom one), centred.
pub fn l_tetromino(cell: f64) -> Vec<DVec2> {
    centred(&[
        DVec2::ZERO,
        DVec2::new(2.0 * cell, 0.0),
        DVec2::new(2.0 * cell, cell),
        DVec2::new(cell, cell),
        DVec2::new(cell, 3.0 * cell),
        DVec2::new(0.0, 3.0 * cell),
    ])
}

pub fn perimeter(v: &[DVec2]) -> f64 {
    (0..v.len())
        .map(|k| v[k].distance(v[(k + 1) % v.len()]))
        .sum()
}

/// The border point at arc length `s` (wrapped) from the first vertex.
pub fn border_at(v: &[DVec2], s: f64) -> DVec2 {
    let mut s = s.rem_euclid(perimeter(v));
    for k in 0..v.len() {
        let (p, q) = (v[k], v[(k + 1) % v.len()]);
        let len = p.distance(q);
        if s <= len {
            return p + (q - p) * (s / len);
        }
        s -= len;
    }
    v[0]
}

/// Border points every `spacing` metres of arc, with their arc fraction in [0, 1).
pub fn sample_border(v: &[DVec2], spacing: f64) -> Vec<(DVec2, f64)> {
    let l = perimeter(v);
    let n = (l / spacing).round() as usize;
    (0..n)
        .map(|k| {
            let s = l * k as f64 / n as f64;
            (border_at(v, s), s / l)
        })
        .collect()
}

/// The S a careful learner would build of polygon `v`: Gaussians of `sigma_m` every
/// millimetre of border, normalised to [0, 1].
pub fn learned_shape(v: &[DVec2], sigma_m: f64) -> Grid {
    let mut s = Grid::default();
    for (p, _) in sample_border(v, 0.001) {
        s.add_gaussian(p, sigma_m, 1.0);
    }
    let max = s.max();
    s.scale(1.0 / max);
    s
}

/// `p` (object frame) placed at pose (`position`, `theta`).
pub fn place(p: DVec2, position: DVec2, theta: f64) -> DVec2 {
    position + DVec2::from_angle(theta).rotate(p)
}
