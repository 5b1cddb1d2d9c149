use std::f64::consts::{PI, TAU};

use agp_world::{ObjectShape, Polygon};
use glam::DVec2;

/// Standard gravity, m/s^2: the normal load of an object on the floor is m * G.
pub const G: f64 = 9.81;

/// One cell of the footprint: where its load acts and how much of it there is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FootprintCell {
    /// Centroid of the cell's area, in the object frame (origin at the object's centroid), m.
    pub centre: DVec2,
    /// Share of the normal load carried by the cell, N.
    pub load: f64,
}

/// Coulomb friction between an object and the floor, distributed over the object's
/// footprint (robot-and-world.md, "Floor friction").
///
/// The footprint is cut into cells of about equal size, each carrying the normal load of
/// its own area (uniform pressure). Cells are exact pieces of the shape (grid squares
/// clipped by the polygon; ring sectors of a disc), so their load-weighted centroid is the
/// object's centroid and a push through the centroid meets no spurious torque.
#[derive(Debug, Clone)]
pub struct FloorFriction {
    cells: Vec<FootprintCell>,
    mu: f64,
}

/// What [`FloorFriction::apply`] did to the object's velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrictionOutcome {
    /// The object was already at rest.
    AtRest,
    /// Friction slowed the object by one step's worth of its wrench.
    Slowed,
    /// Friction would have drained the object's kinetic energy within the step: the
    /// object is stopped (sticking) instead of being pushed backwards.
    Stopped,
}

impl FloorFriction {
    /// Cuts `shape` into about `cells` cells carrying `mass * G` in total.
    ///
    /// `cells` must be at least 1 (checked by the caller).
    pub fn new(shape: &ObjectShape, mass: f64, mu: f64, cells: usize) -> Self {
        let cells = cells.max(1);
        let raw = match shape {
            ObjectShape::Polygon(p) => polygon_cells(p, cells),
            ObjectShape::Circle { radius } => disc_cells(*radius, cells),
        };
        let total: f64 = raw.iter().map(|(_, a)| a).sum();
        let cells = raw
            .into_iter()
            .map(|(centre, area)| FootprintCell {
                centre,
                load: mass * G * area / total,
            })
            .collect();
        Self { cells, mu }
    }

    /// The object's mass changed to `mass` (kg) and the floor's coefficient to `mu`: each
    /// cell's load is rescaled (the footprint is the same). Allocates nothing.
    pub fn set_mass_and_mu(&mut self, mass: f64, mu: f64) {
        let total: f64 = self.cells.iter().map(|c| c.load).sum();
        if total > 0.0 {
            let k = mass * G / total;
            for c in &mut self.cells {
                c.load *= k;
            }
        }
        self.mu = mu;
    }

    /// The footprint's cells, in the object frame.
    pub fn cells(&self) -> &[FootprintCell] {
        &self.cells
    }

    /// Coulomb coefficient between the object and the floor.
    pub fn mu(&self) -> f64 {
        self.mu
    }

    /// Largest friction torque about the centroid, N m: the footprint turning on the spot,
    /// every cell resisting with mu * load at its distance from the centroid.
    pub fn max_torque(&self) -> f64 {
        self.cells
            .iter()
            .map(|c| self.mu * c.load * c.centre.length())
            .sum()
    }

    /// Largest friction force, N: mu times the whole load.
    pub fn max_force(&self) -> f64 {
        self.mu * self.cells.iter().map(|c| c.load).sum::<f64>()
    }

    /// Friction force (world frame, N) and torque (N m) on an object moving with linear
    /// velocity `v` (world frame, at the centroid) and angular velocity `omega`, heading
    /// `theta`. Each cell resists its own sliding velocity `v + omega x r` with `mu * load`.
    pub fn wrench(&self, v: DVec2, omega: f64, theta: f64) -> (DVec2, f64) {
        let rot = DVec2::from_angle(theta);
        // Work in the object frame: one rotation instead of one per cell.
        let vb = DVec2::new(rot.x * v.x + rot.y * v.y, rot.x * v.y - rot.y * v.x);
        let mut force = DVec2::ZERO;
        let mut torque = 0.0;
        for c in &self.cells {
            let vc = vb + omega * c.centre.perp();
            let speed = vc.length();
            if speed > 1e-12 {
                let f = vc * (-self.mu * c.load / speed);
                force += f;
                torque += c.centre.perp_dot(f);
            }
        }
        (rot.rotate(force), torque)
    }

    /// Applies one step `dt` of floor friction to the velocity of a body of `mass` and
    /// moment of inertia `inertia` (about the centroid), in place.
    ///
    /// Clamp: Coulomb friction only dissipates, at the rate P = F.v + tau.omega < 0, and for
    /// a sliding object |P| grows in proportion to the speed, so the kinetic energy
    /// K = (m v^2 + I omega^2) / 2 reaches zero after T = 2K / |P|. When T <= dt the object
    /// comes to rest within this step: it is stopped (sticking) rather than overshooting
    /// into a reversed motion. Otherwise the full wrench is applied, which keeps
    /// (twist . M . new twist) > 0: no reversal either.
    pub fn apply(
        &self,
        v: &mut DVec2,
        omega: &mut f64,
        theta: f64,
        mass: f64,
        inertia: f64,
        dt: f64,
    ) -> FrictionOutcome {
        if *v == DVec2::ZERO && *omega == 0.0 {
            return FrictionOutcome::AtRest;
        }
        let (force, torque) = self.wrench(*v, *omega, theta);
        let dissipation = -(force.dot(*v) + torque * *omega);
        let twice_kinetic = mass * v.length_squared() + inertia * *omega * *omega;
        // No dissipation means no cell slides measurably (all below 1e-12 m/s): at rest.
        if dissipation <= 0.0 || twice_kinetic <= dissipation * dt {
            *v = DVec2::ZERO;
            *omega = 0.0;
            return FrictionOutcome::Stopped;
        }
        *v += force * (dt / mass);
        *omega += torque * (dt / inertia);
        FrictionOutcome::Slowed
    }
}

/// Grid squares of side sqrt(area / cells), aligned on lines through the centroid, each
/// clipped by the polygon: (centroid, area) of every non-empty piece.
fn polygon_cells(poly: &Polygon, cells: usize) -> Vec<(DVec2, f64)> {
    let h = (poly.area() / cells as f64).sqrt();
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for v in poly.vertices() {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    let (i0, i1) = ((lo.x / h).floor() as i64, (hi.x / h).ceil() as i64);
    let (j0, j1) = ((lo.y / h).floor() as i64, (hi.y / h).ceil() as i64);
    let min_area = poly.area() * 1e-9;
    let mut out = Vec::new();
    let mut scratch = (Vec::new(), Vec::new());
    for i in i0..i1 {
        for j in j0..j1 {
            let (x0, y0) = (i as f64 * h, j as f64 * h);
            let piece = clip_to_box(poly.vertices(), x0, y0, x0 + h, y0 + h, &mut scratch);
            let (centroid, area) = area_centroid(piece);
            if area > min_area {
                out.push((centroid, area));
            }
        }
    }
    out
}

/// Sutherland-Hodgman clip of a (possibly non-convex) polygon by an axis-aligned box.
/// With a non-convex subject the result may hold zero-width bridges along the box, which
/// add nothing to its area and first moments, the only things used here.
fn clip_to_box<'a>(
    subject: &[DVec2],
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    scratch: &'a mut (Vec<DVec2>, Vec<DVec2>),
) -> &'a [DVec2] {
    let (a, b) = scratch;
    a.clear();
    a.extend_from_slice(subject);
    // Each half-plane as (signed distance of a point inside >= 0).
    let planes: [&dyn Fn(DVec2) -> f64; 4] =
        [&|p| p.x - x0, &|p| x1 - p.x, &|p| p.y - y0, &|p| y1 - p.y];
    for inside in planes {
        b.clear();
        let n = a.len();
        for k in 0..n {
            let (p, q) = (a[k], a[(k + 1) % n]);
            let (dp, dq) = (inside(p), inside(q));
            if dp >= 0.0 {
                b.push(p);
            }
            if (dp >= 0.0) != (dq >= 0.0) {
                b.push(p + (q - p) * (dp / (dp - dq)));
            }
        }
        std::mem::swap(a, b);
        if a.is_empty() {
            break;
        }
    }
    a
}

/// (centroid, area) of a polygon by the shoelace formulas; area 0 for fewer than 3 points.
fn area_centroid(v: &[DVec2]) -> (DVec2, f64) {
    if v.len() < 3 {
        return (DVec2::ZERO, 0.0);
    }
    let (mut a2, mut c) = (0.0, DVec2::ZERO);
    for k in 0..v.len() {
        let (p, q) = (v[k], v[(k + 1) % v.len()]);
        let cross = p.perp_dot(q);
        a2 += cross;
        c += (p + q) * cross;
    }
    if a2.abs() < 1e-300 {
        return (DVec2::ZERO, 0.0);
    }
    (c / (3.0 * a2), a2 / 2.0)
}

/// Rings of equal width, each cut into sectors about as long as the ring is wide (about
/// `cells` in all): exact (centroid, area) of every ring sector. Sector borders start at
/// angle 0, so the cells are mirror-symmetric about the x axis.
fn disc_cells(radius: f64, cells: usize) -> Vec<(DVec2, f64)> {
    let rings = ((cells as f64 / PI).sqrt().round() as usize).max(1);
    let mut out = Vec::new();
    for k in 0..rings {
        let (r0, r1) = (
            radius * k as f64 / rings as f64,
            radius * (k + 1) as f64 / rings as f64,
        );
        let sectors = ((TAU * (k as f64 + 0.5)).round() as usize).max(3);
        let span = TAU / sectors as f64;
        let area = span / 2.0 * (r1 * r1 - r0 * r0);
        // Centroid of an annular sector: (2/3) (r1^3 - r0^3) / (r1^2 - r0^2) * sinc(span/2).
        let half = span / 2.0;
        let rho = 2.0 / 3.0 * (r1.powi(3) - r0.powi(3)) / (r1 * r1 - r0 * r0) * half.sin() / half;
        for s in 0..sectors {
            let mid = span * (s as f64 + 0.5);
            out.push((DVec2::from_angle(mid) * rho, area));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(side: f64) -> ObjectShape {
        let h = side / 2.0;
        ObjectShape::Polygon(
            Polygon::new(vec![
                DVec2::new(-h, -h),
                DVec2::new(h, -h),
                DVec2::new(h, h),
                DVec2::new(-h, h),
            ])
            .unwrap(),
        )
    }

    #[test]
    fn cells_carry_the_whole_load_centred_on_the_centroid() {
        for shape in [square(0.06), ObjectShape::Circle { radius: 0.035 }] {
            let f = FloorFriction::new(&shape, 0.1, 0.4, 64);
            let load: f64 = f.cells().iter().map(|c| c.load).sum();
            let moment: DVec2 = f.cells().iter().map(|c| c.centre * c.load).sum();
            // Sums of ~64 terms of size ~0.015 N: rounding stays below 1e-15 N.
            assert!((load - 0.1 * G).abs() < 1e-12, "load {load}");
            assert!(moment.length() < 1e-15, "first moment {moment}");
            assert!(
                (40..=100).contains(&f.cells().len()),
                "{} cells",
                f.cells().len()
            );
        }
    }

    #[test]
    fn a_sliding_object_feels_mu_m_g_against_its_motion() {
        let f = FloorFriction::new(&square(0.06), 0.1, 0.4, 64);
        let (force, torque) = f.wrench(DVec2::new(0.0, 0.2), 0.0, 0.3);
        // Every cell slides the same way: the sum is exact up to rounding.
        assert!((force - DVec2::new(0.0, -0.4 * 0.1 * G)).length() < 1e-12);
        assert!(torque.abs() < 1e-15);
    }

    #[test]
    fn the_clamp_stops_an_object_instead_of_reversing_it() {
        let f = FloorFriction::new(&square(0.06), 0.1, 0.4, 64);
        let mut v = DVec2::new(1e-3, 0.0);
        let mut w = 0.0;
        // mu g dt = 3.9 m/s^2 / 640 Hz = 6.1 mm/s > 1 mm/s: this step stops it.
        let out = f.apply(&mut v, &mut w, 0.0, 0.1, 6e-5, 1.0 / 640.0);
        assert_eq!(out, FrictionOutcome::Stopped);
        assert_eq!((v, w), (DVec2::ZERO, 0.0));
    }
}
