//! The rotational symmetry and the circumscribed radius of a learned shape gradient S.

use std::f64::consts::TAU;

use glam::DVec2;

use crate::{AIM_BORDER_THRESHOLD, Grid};

/// Largest symmetry order tested.
pub const MAX_SYMMETRY_ORDER: u32 = 12;

/// Least correlation ([`SymmetryEstimate::score`]) of S with itself turned by every
/// multiple of `2 pi / k` for S to count as k-fold symmetric.
///
/// The correlation is 1 for a perfect symmetry. Measured on the tests' polygon borders
/// (Gaussians of sigma 2 mm every millimetre, 2 mm cells): a true symmetry scores 0.99 drawn
/// cleanly, 0.71 to 0.97 with 1 to 2 mm of positional noise, a quarter of the border missing,
/// one half seen three times as often as the other, or the last two at once, and down to 0.62
/// for the pentagon (35 mm circumradius) with 2 mm of noise; a false order scores at most
/// -0.06 on those shapes (the minimum over the multiples of `2 pi / k` sees to that: the
/// hexagon turned by `2 pi / 7`, 51 deg, near its true 60, correlates fairly, but not at 103
/// and 154 deg). 0.5 leaves room below the true symmetries for evidence worse than the tests'.
///
/// Not the correlation with a small rotation that only blurs: turned by 3 deg the shapes
/// still correlate 0.84 to 0.95, which tells how wide the ridge is compared with the radius,
/// not how much gaps and uneven evidence take off a true symmetry, which is what decides.
/// Near-symmetries (a triangle of sides 80, 72, 72 mm scores 0.55 to 0.63 as 3-fold) are
/// [`SYMMETRY_SHIFT_TOLERANCE_M`]'s to reject.
pub const SYMMETRY_MATCH_THRESHOLD: f64 = 0.5;

/// Largest root mean square difference, metres, between the border's distance from the
/// origin in each direction and in the direction turned by a multiple of `2 pi / k`
/// ([`SymmetryEstimate::shift_m`]) for S to count as k-fold symmetric.
///
/// The correlation of ridges of sigma 2 mm tolerates borders a few millimetres apart; this
/// says how far apart in millimetres. Measured: a true symmetry 0.0 mm drawn cleanly, up to
/// up to 2.1 mm with 2 mm of positional noise (the rectangle of 80 x 40 mm, whose rays meet
/// the long sides obliquely and so magnify the noise); the triangle of sides 80, 72, 72 mm
/// turned by 120 deg 3.1 to 3.6 mm, the rectangle of 60 x 55 mm turned by 90 deg 2.9 to
/// 4.0 mm. A true symmetry that fails it reads as a lower order or 1, the safe side: the
/// matcher then searches all orientations, while a false order would fold distinct ones.
pub const SYMMETRY_SHIFT_TOLERANCE_M: f64 = 0.0025;

/// Largest root mean square spread, metres, of the border's distance from the origin over
/// the directions seen, for S to count as a disc (order 0).
///
/// Measured: a disc of 35 mm 0.01 mm drawn cleanly, 0.8 mm with 2 mm of positional noise,
/// up to 0.6 mm with a quarter missing; the regular hexagon of 40 mm circumradius (flats 5.4 mm
/// inside the corners) 1.4 mm and more, the pentagon of 35 mm 1.5 mm and more, the square
/// of 60 mm 3.4 mm. Regular polygons of 35 mm with 7 and 8 sides (flats 3.5 and 2.7 mm
/// inside the corners) spread 0.7 to 1.3 mm and read as discs or, with noise, as having no
/// symmetry: beyond 6 sides at this size, S does not resolve the corners. S off-centre by
/// `e` spreads by `e / sqrt 2`: the origin must be the centroid to within about 1 mm.
pub const DISC_RADIUS_RMS_M: f64 = 0.001;

/// Least fraction of the directions from the origin in which S has a border (a band of at
/// least [`AIM_BORDER_THRESHOLD`] of S's peak) for any order but 1 to be claimed.
pub const MIN_BORDER_COVERAGE: f64 = 0.5;

/// Least fraction of the directions with a border whose turned direction has one too, for
/// a rotation to be compared at all (below it, S counts as not symmetric under it).
pub const MIN_ROTATION_OVERLAP: f64 = 0.5;

/// Orders 2..=12.
const ORDERS: usize = (MAX_SYMMETRY_ORDER - 1) as usize;

/// Directions sampled around the origin (1 deg apart).
const DIRECTIONS: usize = 360;

/// Radial bins of the rotation-invariant profile, half a cell wide: enough for the corner
/// of a centred grid (`64 * sqrt 2 * 2 = 181` bins).
const RADIAL_BINS: usize = 192;

/// Distinct rotations tested: the reduced fractions `m / k` in (0, 1/2] with `k <= 12`
/// (a rotation's comparison is that of its inverse).
const ROTATIONS: usize = 23;

/// Ray steps per cell when walking S along a direction.
const RAY_STEPS_PER_CELL: f64 = 4.0;

/// What [`estimate_symmetry`] found in a learned shape S.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetryEstimate {
    /// The rotational symmetry order: 0 for a disc, 1 for none, else k in 2..=12.
    pub order: u32,
    /// `score_per_k[k - 2]` is [`SymmetryEstimate::score`]`(k)`, k in 2..=12.
    pub score_per_k: [f64; ORDERS],
    /// `shift_per_k_m[k - 2]` is [`SymmetryEstimate::shift_m`]`(k)`, k in 2..=12.
    pub shift_per_k_m: [f64; ORDERS],
    /// Root mean square spread of the border's distance from the origin over the directions
    /// seen, metres (compared with [`DISC_RADIUS_RMS_M`]); NaN when no border is seen.
    pub radius_rms_m: f64,
    /// Mean distance of the border from the origin over the directions seen, metres; NaN
    /// when no border is seen.
    pub mean_radius_m: f64,
    /// Fraction of the directions from the origin in which S has a border.
    pub coverage: f64,
}

impl SymmetryEstimate {
    /// How well S matches itself turned about the origin by every multiple of `2 pi / k`:
    /// the least, over those turns, normalised correlation in [-1, 1] of S's anisotropic
    /// part with its turned copy (see [`estimate_symmetry`]). NaN when a turn compares too
    /// little border ([`MIN_ROTATION_OVERLAP`]) or S has no anisotropic part (a perfect
    /// disc); `None` for `k` outside 2..=12.
    pub fn score(&self, k: u32) -> Option<f64> {
        order_index(k).map(|i| self.score_per_k[i])
    }

    /// How far the border moves when S is turned about the origin by a multiple of
    /// `2 pi / k`: the largest, over those turns, root mean square difference between the
    /// border's distance from the origin in a direction and in the turned direction, metres.
    /// NaN when a turn compares too little border; `None` for `k` outside 2..=12.
    pub fn shift_m(&self, k: u32) -> Option<f64> {
        order_index(k).map(|i| self.shift_per_k_m[i])
    }
}

fn order_index(k: u32) -> Option<usize> {
    (2..=MAX_SYMMETRY_ORDER)
        .contains(&k)
        .then_some((k - 2) as usize)
}

/// The rotational symmetry order of a learned shape S about its origin (the object
/// frame's, the centroid): 0 for a disc, k in 2..=12 for the largest k-fold symmetry found,
/// 1 for none or too little border seen to tell. See [`estimate_symmetry`].
pub fn symmetry_order_of(shape: &Grid) -> u32 {
    estimate_symmetry(shape).order
}

/// The rotational symmetry of a learned shape S (a peak of 1 or not: only ratios count)
/// about the object frame's origin, with the numbers behind it.
///
/// 1. The border in each of 360 directions from the origin: the outermost band of S of at
///    least [`AIM_BORDER_THRESHOLD`] of its peak on the ray (the lowest band a caller takes
///    for the border), located at its centroid. Seen in fewer than [`MIN_BORDER_COVERAGE`]
///    of the directions: order 1.
/// 2. The border's distance from the origin spreads by at most [`DISC_RADIUS_RMS_M`]:
///    order 0.
/// 3. Else the largest k in 2..=12 such that, for every turn by a multiple of `2 pi / k`,
///    the correlation reaches [`SYMMETRY_MATCH_THRESHOLD`] and the border moves by at most
///    [`SYMMETRY_SHIFT_TOLERANCE_M`]; else 1. Every divisor of an accepted k passes too.
///
/// The correlation compares S with `S(R^-1 x)` cell by cell, robust to how S is learned:
/// each direction is scaled by the inverse of S's largest value on its ray, so that a face
/// seen more often than another weighs the same; the mean over each circle about the origin
/// is subtracted, removing what every rotation matches (as it is, a pentagon turned by 60
/// deg correlates 0.82); and only directions where both S and the turned S have a border
/// count, so that a missing part of the border does not count against a symmetry.
///
/// The origin must be the object's centroid (the learner's frame): S off-centre by a couple
/// of millimetres blurs every symmetry. Compares the outer border only, so a shape whose
/// outline is symmetric but whose inner bands are not reads as symmetric. Allocates
/// nothing; 23 rotations of the 16k cells, once per gradient.
pub fn estimate_symmetry(shape: &Grid) -> SymmetryEstimate {
    let rays = border_rays(shape, AIM_BORDER_THRESHOLD);
    let seen_count = rays.iter().flatten().count();
    let coverage = seen_count as f64 / DIRECTIONS as f64;
    let (mean_radius_m, radius_rms_m) = radius_spread(&rays);
    // 1 / (largest S on the ray) where the ray has a border, else 0 (not compared).
    let gain: [f32; DIRECTIONS] = std::array::from_fn(|b| match rays[b] {
        Some(ray) if ray.peak > 0.0 => 1.0 / ray.peak,
        _ => 0.0,
    });

    let rotations = rotation_fractions();
    let angle: [f64; ROTATIONS] = std::array::from_fn(|n| {
        let (m, k) = rotations[n];
        TAU * f64::from(m) / f64::from(k)
    });
    let profile = radial_profile(shape, &gain);
    let correlation = rotation_correlations(shape, &gain, &profile, &angle);
    let shift: [f64; ROTATIONS] = std::array::from_fn(|n| ray_shift_rms(&rays, angle[n]));
    let overlap: [f64; ROTATIONS] = std::array::from_fn(|n| {
        let both = (0..DIRECTIONS)
            .filter(|&b| gain[b] > 0.0 && gain[direction_bin(bin_angle(b) - angle[n])] > 0.0)
            .count();
        both as f64 / seen_count.max(1) as f64
    });
    let comparable = |n: usize| overlap[n] >= MIN_ROTATION_OVERLAP;

    let mut score_per_k = [f64::NAN; ORDERS];
    let mut shift_per_k_m = [f64::NAN; ORDERS];
    for k in 2..=MAX_SYMMETRY_ORDER {
        let (mut score, mut moved) = (f64::INFINITY, 0.0_f64);
        for m in 1..=k / 2 {
            let g = gcd(m, k);
            let n = rotations
                .iter()
                .position(|&f| f == (m / g, k / g))
                .unwrap_or(0);
            let (c, s) = if comparable(n) {
                (correlation[n], shift[n])
            } else {
                (f64::NAN, f64::NAN)
            };
            score = nan_min(score, c);
            moved = nan_max(moved, s);
        }
        score_per_k[(k - 2) as usize] = score;
        shift_per_k_m[(k - 2) as usize] = moved;
    }

    let order = if seen_count == 0 || coverage < MIN_BORDER_COVERAGE {
        1
    } else if radius_rms_m <= DISC_RADIUS_RMS_M {
        0
    } else {
        (2..=MAX_SYMMETRY_ORDER)
            .rev()
            .find(|&k| {
                let i = (k - 2) as usize;
                score_per_k[i] >= SYMMETRY_MATCH_THRESHOLD
                    && shift_per_k_m[i] <= SYMMETRY_SHIFT_TOLERANCE_M
            })
            .unwrap_or(1)
    };
    SymmetryEstimate {
        order,
        score_per_k,
        shift_per_k_m,
        radius_rms_m,
        mean_radius_m,
        coverage,
    }
}

/// The circumscribed radius of the learned border, metres: the distance from the origin of
/// the farthest cell centre whose S is at least `threshold` (S with a peak of 1, as
/// [`crate::AffordanceGradient::combined_shape`] gives it). `None` when no cell reaches
/// `threshold`, or `threshold` is not positive (every cell would).
///
/// Take [`crate::CONTACT_BORDER_THRESHOLD`] (0.3) for the border where contacts are
/// planned, [`AIM_BORDER_THRESHOLD`] (0.15) for the widest band any caller counts as
/// border. Either way this is the outer edge of the learned band, not the border's centre
/// line: it exceeds the true circumradius by the band's half-width at the farthest corner,
/// give or take half a cell diagonal. The square of 60 mm (42.4 mm) drawn with sigma 2 mm on
/// 2 mm cells gives 43.8 to 43.9 mm, 45.5 mm at 0.3 with 2 mm of positional noise: an
/// upper bound, as a clearance wants. Allocates nothing.
pub fn shape_radius_m(shape: &Grid, threshold: f32) -> Option<f64> {
    if threshold.is_nan() || threshold <= 0.0 {
        return None;
    }
    let mut best: Option<f64> = None;
    for j in 0..Grid::SIDE {
        for i in 0..Grid::SIDE {
            if shape.get(i, j) >= threshold {
                let r = shape.cell_centre_m(i, j).length();
                best = Some(best.map_or(r, |b| b.max(r)));
            }
        }
    }
    best
}

/// The border met along one direction from the origin.
#[derive(Debug, Clone, Copy)]
struct Ray {
    /// Distance from the origin of the outermost band of S, metres.
    radius_m: f64,
    /// Largest S on the ray.
    peak: f32,
}

/// Angle of the centre of direction bin `b`, radians.
fn bin_angle(b: usize) -> f64 {
    (b as f64 + 0.5) * TAU / DIRECTIONS as f64
}

/// Direction bin of angle `phi`, radians (any range).
#[inline]
fn direction_bin(phi: f64) -> usize {
    let b = (phi.rem_euclid(TAU) * (DIRECTIONS as f64 / TAU)) as usize;
    b.min(DIRECTIONS - 1)
}

/// Distance from the origin to the grid's farthest corner, metres.
fn farthest_corner_m(shape: &Grid) -> f64 {
    let lo = shape.origin_m();
    let hi = lo + DVec2::splat(shape.extent_m());
    [lo, hi, DVec2::new(lo.x, hi.y), DVec2::new(hi.x, lo.y)]
        .iter()
        .map(|c| c.length())
        .fold(0.0, f64::max)
}

/// For each direction, the outermost band of S of at least `threshold` of S's peak on the
/// ray from the origin, located at its centroid, each sample weighted by its excess over
/// the level (as [`crate::AffordanceGradient::contact_candidates`] locates the border), and
/// the ray's largest S. `None` where the ray meets no band.
fn border_rays(shape: &Grid, threshold: f32) -> [Option<Ray>; DIRECTIONS] {
    let level = threshold * shape.max();
    let mut out = [None; DIRECTIONS];
    if level.is_nan() || level <= 0.0 {
        return out;
    }
    let reach = farthest_corner_m(shape);
    let step = shape.cell_size_m() / RAY_STEPS_PER_CELL;
    for (b, slot) in out.iter_mut().enumerate() {
        let u = DVec2::from_angle(bin_angle(b));
        let (mut weight, mut moment) = (0.0_f64, 0.0_f64);
        let mut peak = 0.0_f32;
        let mut band_passed = false;
        let mut r = reach;
        while r > 0.0 {
            let s = shape.sample(u * r);
            peak = peak.max(s);
            if !band_passed {
                if s >= level {
                    let e = f64::from(s - level);
                    weight += e;
                    moment += e * r;
                } else if weight > 0.0 {
                    band_passed = true;
                }
            }
            r -= step;
        }
        if weight > 0.0 {
            *slot = Some(Ray {
                radius_m: moment / weight,
                peak,
            });
        }
    }
    out
}

/// Mean and root mean square spread of the radii seen (NaN, NaN when none is).
fn radius_spread(rays: &[Option<Ray>; DIRECTIONS]) -> (f64, f64) {
    let (mut n, mut sum, mut sum_sq) = (0.0_f64, 0.0_f64, 0.0_f64);
    for r in rays.iter().flatten().map(|ray| ray.radius_m) {
        n += 1.0;
        sum += r;
        sum_sq += r * r;
    }
    if n == 0.0 {
        return (f64::NAN, f64::NAN);
    }
    let mean = sum / n;
    (mean, (sum_sq / n - mean * mean).max(0.0).sqrt())
}

/// Root mean square difference between the border's distance from the origin in each
/// direction and in the direction `theta` before it (interpolated between bins), over the
/// directions where both are seen; NaN when none is.
fn ray_shift_rms(rays: &[Option<Ray>; DIRECTIONS], theta: f64) -> f64 {
    let shift = theta * DIRECTIONS as f64 / TAU;
    let (mut n, mut sum) = (0.0_f64, 0.0_f64);
    for (b, ray) in rays.iter().enumerate() {
        let Some(ray) = ray else { continue };
        let c = b as f64 - shift;
        let t = c - c.floor();
        let i0 = (c.floor() as i64).rem_euclid(DIRECTIONS as i64) as usize;
        let i1 = (i0 + 1) % DIRECTIONS;
        let (Some(r0), Some(r1)) = (rays[i0], rays[i1]) else {
            continue;
        };
        let turned = r0.radius_m * (1.0 - t) + r1.radius_m * t;
        n += 1.0;
        sum += (ray.radius_m - turned).powi(2);
    }
    if n == 0.0 { f64::NAN } else { (sum / n).sqrt() }
}
/// Radial bin of distance `r` from the origin.
#[inline]
fn radial_bin(r: f64, cell: f64) -> usize {
    ((r / (0.5 * cell)) as usize).min(RADIAL_BINS - 1)
}

/// S scaled by its direction's gain, as compared (negative and NaN cells as 0).
#[inline]
fn scaled(s: f32, gain: f32) -> f64 {
    f64::from(gain * s.max(0.0))
}

/// Mean of the scaled S over the cells of each radial bin, in the directions seen.
fn radial_profile(shape: &Grid, gain: &[f32; DIRECTIONS]) -> [f64; RADIAL_BINS] {
    let cell = shape.cell_size_m();
    let mut sum = [0.0_f64; RADIAL_BINS];
    let mut count = [0.0_f64; RADIAL_BINS];
    for j in 0..Grid::SIDE {
        for i in 0..Grid::SIDE {
            let x = shape.cell_centre_m(i, j);
            let g = gain[direction_bin(x.y.atan2(x.x))];
            if g > 0.0 {
                let rb = radial_bin(x.length(), cell);
                sum[rb] += scaled(shape.get(i, j), g);
                count[rb] += 1.0;
            }
        }
    }
    std::array::from_fn(|k| {
        if count[k] > 0.0 {
            sum[k] / count[k]
        } else {
            0.0
        }
    })
}

fn gcd(mut a: u32, mut b: u32) -> u32 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// NaN if either is, else the smaller.
fn nan_min(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.min(b)
    }
}

/// NaN if either is, else the larger.
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// The reduced fractions `(m, k)` with `k` in 2..=12 and `m / k` in (0, 1/2].
fn rotation_fractions() -> [(u32, u32); ROTATIONS] {
    let mut out = [(0, 0); ROTATIONS];
    let mut n = 0;
    for k in 2..=MAX_SYMMETRY_ORDER {
        for m in 1..=k / 2 {
            if gcd(m, k) == 1 {
                out[n] = (m, k);
                n += 1;
            }
        }
    }
    debug_assert_eq!(n, ROTATIONS);
    out
}

/// For each rotation angle, the normalised correlation of the anisotropic part of the
/// scaled S (less its mean over each circle) with its turned copy, over the cells whose
/// direction and turned direction both have a border; NaN when nothing is anisotropic.
fn rotation_correlations(
    shape: &Grid,
    gain: &[f32; DIRECTIONS],
    profile: &[f64; RADIAL_BINS],
    angle: &[f64; ROTATIONS],
) -> [f64; ROTATIONS] {
    let cell = shape.cell_size_m();
    // (R S)(x) = S(R^-1 x).
    let inverse: [DVec2; ROTATIONS] = std::array::from_fn(|n| DVec2::from_angle(-angle[n]));
    let mut ab = [0.0_f64; ROTATIONS];
    let mut aa = [0.0_f64; ROTATIONS];
    let mut bb = [0.0_f64; ROTATIONS];
    for j in 0..Grid::SIDE {
        for i in 0..Grid::SIDE {
            let x = shape.cell_centre_m(i, j);
            let phi = x.y.atan2(x.x);
            let ga = gain[direction_bin(phi)];
            if ga <= 0.0 {
                continue;
            }
            let mean = profile[radial_bin(x.length(), cell)];
            let a = scaled(shape.get(i, j), ga) - mean;
            for n in 0..ROTATIONS {
                let gb = gain[direction_bin(phi - angle[n])];
                if gb <= 0.0 {
                    continue;
                }
                let b = scaled(shape.sample(inverse[n].rotate(x)), gb) - mean;
                ab[n] += a * b;
                aa[n] += a * a;
                bb[n] += b * b;
            }
        }
    }
    std::array::from_fn(|n| {
        let norm = (aa[n] * bb[n]).sqrt();
        if norm > 0.0 {
            (ab[n] / norm).clamp(-1.0, 1.0)
        } else {
            f64::NAN
        }
    })
}
