//! Quasi-static pushing with an ellipsoidal limit surface: the classical model a
//! roboticist reaches for (Goyal, Ruina and Papadopoulos 1991, "Planar sliding with dry
//! friction"; Lynch, Lee and Cutkosky 1992, "Manipulation and active sensing by pushing
//! using tactile feedback"). Pure math: no world, no robot.
//!
//! An object of mass m sliding on the floor with Coulomb friction mu under uniform pressure
//! over its footprint A resists any planar motion with a wrench on its *limit surface*.
//! Its extremes are the pure force f_max = mu m g (translation) and the pure moment
//! m_max = mu m g (1/A) integral over A of |r| dA (rotation about the centroid, r from the
//! centroid). The ellipsoid approximation
//!
//! ```text
//! H(f, m) = (fx^2 + fy^2) / f_max^2 + m^2 / m_max^2 = 1
//! ```
//!
//! makes the object's twist normal to it: (vx, vy, w) ~ (fx, fy, m / c^2) with
//! c = m_max / f_max, the footprint's mean distance to its centroid. A point pusher at
//! r = (x, y) (object frame, from the centroid) with contact normal n (into the object) and
//! contact friction mu_c pushes with a force inside its friction cone. The cone's two edges
//! map to two contact-point velocities, the *motion cone*. A pusher velocity v_p inside it
//! sticks, and the object's twist is Lynch's closed form
//!
//! ```text
//! vx = ((c^2 + x^2) v_px + x y v_py) / (c^2 + x^2 + y^2)
//! vy = (x y v_px + (c^2 + y^2) v_py) / (c^2 + x^2 + y^2)
//! w  = (x vy - y vx) / c^2
//! ```
//!
//! Outside it the contact slides: the force lies on the cone's edge nearer to v_p and the
//! object moves with that edge's twist, scaled so that the contact point's normal velocity
//! matches the pusher's.

use agp_world::Polygon;
use glam::DVec2;

/// Standard gravity, m/s^2.
pub const GRAVITY_MPS2: f64 = 9.81;

/// Subdivisions per triangle side when the mean distance over a polygon is integrated:
/// `n^2` small triangles per triangle of the footprint, each weighted at its centroid
/// (second order: 64 gives the square's closed form to 1e-5 of it).
const INTEGRATION_SUBDIVISIONS: usize = 64;

/// An object's footprint on the floor, in its own frame with the centroid at the origin.
#[derive(Debug, Clone, PartialEq)]
pub enum Footprint {
    /// A simple polygon (convex or not), counter-clockwise, centred on its centroid.
    Polygon(Polygon),
    /// A disc of this radius, m.
    Disc { radius: f64 },
}

impl Footprint {
    /// The footprint of `polygon`, moved so that its centroid is the origin.
    pub fn polygon(polygon: &Polygon) -> Self {
        Self::Polygon(polygon.centred())
    }

    /// Largest distance from the centroid to the border, m.
    pub fn radius(&self) -> f64 {
        match self {
            Self::Polygon(p) => p.radius(),
            Self::Disc { radius } => *radius,
        }
    }

    /// The mean distance of the footprint's points to its centroid, m: for a polygon
    /// integrated numerically over its triangles (ear clipping, each split into
    /// [`INTEGRATION_SUBDIVISIONS`]^2 triangles weighted at their centroids); for a disc its
    /// closed form 2 r / 3.
    pub fn mean_distance_to_centroid(&self) -> f64 {
        match self {
            Self::Disc { radius } => 2.0 * radius / 3.0,
            Self::Polygon(p) => {
                let n = INTEGRATION_SUBDIVISIONS;
                let (mut moment, mut area) = (0.0, 0.0);
                for [a, b, c] in p.triangulate() {
                    let (u, v) = ((b - a) / n as f64, (c - a) / n as f64);
                    let small = 0.5 * u.perp_dot(v).abs();
                    for i in 0..n {
                        for j in 0..n - i {
                            let o = a + u * i as f64 + v * j as f64;
                            // The upright small triangle (o, o + u, o + v), and the one
                            // pointing down beside it (o + u, o + u + v, o + v).
                            moment += small * (o + (u + v) / 3.0).length();
                            area += small;
                            if i + j + 1 < n {
                                moment += small * (o + (u + v) * (2.0 / 3.0)).length();
                                area += small;
                            }
                        }
                    }
                }
                if area > 0.0 { moment / area } else { 0.0 }
            }
        }
    }

    /// The point of the border closest to `p` (object frame).
    pub fn closest_border_point(&self, p: DVec2) -> DVec2 {
        match self {
            Self::Disc { radius } => {
                let d = p.length();
                if d > 1e-12 {
                    p * (radius / d)
                } else {
                    DVec2::new(*radius, 0.0)
                }
            }
            Self::Polygon(poly) => {
                let mut best = (f64::INFINITY, DVec2::ZERO);
                for (a, b) in poly.edges() {
                    let ab = b - a;
                    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-300)).clamp(0.0, 1.0);
                    let q = a + ab * t;
                    let d = (p - q).length_squared();
                    if d < best.0 {
                        best = (d, q);
                    }
                }
                best.1
            }
        }
    }

    /// Where the ray from the centroid along the unit vector `dir` leaves the footprint
    /// for the last time: the outermost border point in that direction (the aim point a
    /// ray from outside meets first).
    pub fn outermost_crossing(&self, dir: DVec2) -> Option<DVec2> {
        match self {
            Self::Disc { radius } => Some(dir * *radius),
            Self::Polygon(poly) => poly
                .edges()
                .filter_map(|(a, b)| agp_world::ray_segment(DVec2::ZERO, dir, a, b))
                .fold(None, |best: Option<f64>, t| {
                    Some(best.map_or(t, |b| b.max(t)))
                })
                .map(|t| dir * t),
        }
    }

    /// How far a disc of radius `radius` whose centre starts at `start` (outside the
    /// footprint grown by `radius`) travels along the unit vector `dir` before it first
    /// touches the footprint; `None` if it passes by.
    pub fn first_touch(&self, start: DVec2, dir: DVec2, radius: f64) -> Option<f64> {
        match self {
            Self::Disc { radius: r } => ray_circle(start, dir, DVec2::ZERO, r + radius),
            Self::Polygon(poly) => {
                let mut best: Option<f64> = None;
                let mut take = |t: Option<f64>| {
                    if let Some(t) = t {
                        best = Some(best.map_or(t, |b| b.min(t)));
                    }
                };
                for (a, b) in poly.edges() {
                    // The edge moved out by the radius (counter-clockwise: the outward
                    // normal is the edge turned clockwise), met from outside.
                    let e = b - a;
                    let out = DVec2::new(e.y, -e.x).normalize_or_zero();
                    if dir.dot(out) < 0.0 {
                        take(agp_world::ray_segment(
                            start,
                            dir,
                            a + out * radius,
                            b + out * radius,
                        ));
                    }
                    take(ray_circle(start, dir, a, radius));
                }
                best
            }
        }
    }
}

/// The first t >= 0 at which `origin + t dir` (unit `dir`) is on the circle of `radius`
/// round `centre`, from outside; `None` if the ray misses it.
fn ray_circle(origin: DVec2, dir: DVec2, centre: DVec2, radius: f64) -> Option<f64> {
    let o = origin - centre;
    let b = o.dot(dir);
    let disc = b * b - (o.length_squared() - radius * radius);
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t >= 0.0).then_some(t)
}

/// A rigid body's planar velocity: its centroid's (object frame) and its angular velocity
/// (counter-clockwise positive), per unit of the pusher's speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Twist {
    pub v: DVec2,
    pub omega: f64,
}

impl Twist {
    /// The velocity of the body's point `r` (object frame, from the centroid).
    pub fn at(&self, r: DVec2) -> DVec2 {
        self.v + self.omega * r.perp()
    }
}

/// How the pusher's contact behaves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactMode {
    /// The pusher's velocity is inside the motion cone: the contact point moves with it.
    Sticking,
    /// Outside the cone: the contact slides, the force on a cone edge.
    Sliding,
    /// The pusher moves away from the object (or along its border): no force, no motion.
    Separating,
}

/// The object's motion under a point push.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointPush {
    pub twist: Twist,
    pub mode: ContactMode,
    /// Direction of the pusher's force on the object (unit, object frame; zero when
    /// separating).
    pub force_dir: DVec2,
}

/// An ellipsoidal limit surface of uniform pressure (see the module's doc).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimitSurface {
    /// Largest friction force, N: mu m g.
    pub f_max_n: f64,
    /// Largest friction moment about the centroid, N m: mu m g times the footprint's mean
    /// distance to its centroid.
    pub m_max_nm: f64,
}

impl LimitSurface {
    /// The limit surface of `footprint` of mass `mass_kg` on a floor of Coulomb
    /// coefficient `floor_friction`, the pressure uniform over the footprint.
    pub fn uniform_pressure(footprint: &Footprint, mass_kg: f64, floor_friction: f64) -> Self {
        let f_max_n = floor_friction * mass_kg * GRAVITY_MPS2;
        Self {
            f_max_n,
            m_max_nm: f_max_n * footprint.mean_distance_to_centroid(),
        }
    }

    /// c = m_max / f_max, m: the lever that turns a moment into a force on the surface.
    pub fn c_m(&self) -> f64 {
        if self.f_max_n > 0.0 {
            self.m_max_nm / self.f_max_n
        } else {
            0.0
        }
    }

    /// The twist (up to scale) of a wrench: the ellipsoid's normal, (fx, fy, m / c^2).
    pub fn twist_of_wrench(&self, force: DVec2, moment: f64) -> Twist {
        let c = self.c_m();
        Twist {
            v: force,
            omega: moment / (c * c).max(1e-300),
        }
    }

    /// The twist (up to scale) of a force applied at `r` (object frame, from the centroid).
    pub fn twist_of_force_at(&self, r: DVec2, force: DVec2) -> Twist {
        self.twist_of_wrench(force, r.perp_dot(force))
    }

    /// The object's twist when a point pusher at `r` (object frame, from the centroid),
    /// touching along the unit normal `normal` (pointing into the object), moves at
    /// `pusher_velocity` with contact friction `contact_friction`: sticking (Lynch's
    /// closed form) inside the motion cone, sliding on the cone's nearer edge outside it.
    pub fn point_push(
        &self,
        r: DVec2,
        normal: DVec2,
        pusher_velocity: DVec2,
        contact_friction: f64,
    ) -> PointPush {
        let separating = PointPush {
            twist: Twist {
                v: DVec2::ZERO,
                omega: 0.0,
            },
            mode: ContactMode::Separating,
            force_dir: DVec2::ZERO,
        };
        let vn = pusher_velocity.dot(normal);
        if vn <= 0.0 {
            return separating;
        }
        // The friction cone's edges: the normal turned by +-atan(mu_c).
        let half = contact_friction.max(0.0).atan();
        let left = DVec2::from_angle(half).rotate(normal);
        let right = DVec2::from_angle(-half).rotate(normal);
        let (tl, tr) = (
            self.twist_of_force_at(r, left),
            self.twist_of_force_at(r, right),
        );
        let (vl, vr) = (tl.at(r), tr.at(r));
        // Inside the motion cone spanned by vl and vr (vl counter-clockwise of vr).
        let inside = vr.perp_dot(pusher_velocity) >= 0.0 && pusher_velocity.perp_dot(vl) >= 0.0;
        if inside {
            let c2 = self.c_m().powi(2);
            let (x, y) = (r.x, r.y);
            let (px, py) = (pusher_velocity.x, pusher_velocity.y);
            let d = c2 + x * x + y * y;
            let vx = ((c2 + x * x) * px + x * y * py) / d;
            let vy = (x * y * px + (c2 + y * y) * py) / d;
            let omega = (x * vy - y * vx) / c2.max(1e-300);
            // The force is the wrench whose twist this is: (fx, fy) = (vx, vy).
            return PointPush {
                twist: Twist {
                    v: DVec2::new(vx, vy),
                    omega,
                },
                mode: ContactMode::Sticking,
                force_dir: DVec2::new(vx, vy).normalize_or_zero(),
            };
        }
        // Outside: the edge on the pusher's side; scaled so the contact point's normal
        // velocity is the pusher's.
        let (t, v, f) = if normal.perp_dot(pusher_velocity) > 0.0 {
            (tl, vl, left)
        } else {
            (tr, vr, right)
        };
        let k = vn / v.dot(normal).max(1e-300);
        PointPush {
            twist: Twist {
                v: t.v * k,
                omega: t.omega * k,
            },
            mode: ContactMode::Sliding,
            force_dir: f,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square of side `a` (m), centred.
    fn square(a: f64) -> Footprint {
        let h = 0.5 * a;
        Footprint::polygon(
            &Polygon::new(vec![
                DVec2::new(-h, -h),
                DVec2::new(h, -h),
                DVec2::new(h, h),
                DVec2::new(-h, h),
            ])
            .expect("a square"),
        )
    }

    #[test]
    fn the_mean_distance_over_a_square_is_its_closed_form() {
        // Mean distance from the centre of a square of side a:
        // a (sqrt 2 + ln(1 + sqrt 2)) / 6 = 0.382598 a.
        let a = 0.06;
        let exact = a * (2f64.sqrt() + (1.0 + 2f64.sqrt()).ln()) / 6.0;
        let got = square(a).mean_distance_to_centroid();
        assert!(
            (got - exact).abs() < 1e-4 * exact,
            "{:.6} mm against {:.6} mm",
            got * 1e3,
            exact * 1e3
        );
    }

    #[test]
    fn the_limit_surface_of_uniform_pressure_scales_with_weight_and_friction() {
        let s = LimitSurface::uniform_pressure(&square(0.06), 0.1, 0.4);
        assert!((s.f_max_n - 0.4 * 0.1 * 9.81).abs() < 1e-12);
        let c = 0.06 * (2f64.sqrt() + (1.0 + 2f64.sqrt()).ln()) / 6.0;
        assert!((s.m_max_nm - s.f_max_n * c).abs() < 1e-4 * s.m_max_nm);
        assert!((s.c_m() - c).abs() < 1e-4 * c);
    }

    #[test]
    fn a_centred_push_on_a_square_translates_it_along_the_push() {
        let s = LimitSurface::uniform_pressure(&square(0.06), 0.1, 0.4);
        // The left face's middle, pushed along +x.
        let p = s.point_push(DVec2::new(-0.03, 0.0), DVec2::X, DVec2::X, 0.3);
        assert_eq!(p.mode, ContactMode::Sticking);
        assert!(p.twist.omega.abs() < 1e-12, "turns at {}", p.twist.omega);
        assert!(
            (p.twist.v - DVec2::X).length() < 1e-12,
            "moves at {}",
            p.twist.v
        );
    }

    #[test]
    fn an_offset_push_turns_the_square_away_from_the_pushed_side_by_lynchs_ratio() {
        let a = 0.06;
        let s = LimitSurface::uniform_pressure(&square(a), 0.1, 0.4);
        let c2 = s.c_m().powi(2);
        // Offsets within the motion cone of a push along the normal (mu_c = 0.3).
        for b in [0.005, 0.01, -0.01] {
            let r = DVec2::new(-0.5 * a, b);
            let p = s.point_push(r, DVec2::X, DVec2::X, 0.3);
            assert_eq!(p.mode, ContactMode::Sticking, "offset {b}");
            // Pushed along +x above the centroid it turns clockwise, below it
            // counter-clockwise.
            assert_eq!(p.twist.omega.signum(), -b.signum(), "offset {b}");
            // Sticking on the face x = -a/2 at offset b along +x: w / vx = -b / (c^2 + a^2/4).
            let want = -b / (c2 + 0.25 * a * a);
            let got = p.twist.omega / p.twist.v.x;
            assert!(
                (got - want).abs() < 1e-9 * want.abs(),
                "offset {b}: {got} against {want}"
            );
            // The contact point moves with the pusher: it sticks.
            assert!((p.twist.at(r) - DVec2::X).length() < 1e-12);
        }
        // Farther out the normal push leaves the motion cone: the contact slides along
        // the face, the force on the friction cone's edge, and the square still turns
        // clockwise.
        let b = 0.025;
        let r = DVec2::new(-0.5 * a, b);
        let p = s.point_push(r, DVec2::X, DVec2::X, 0.3);
        assert_eq!(p.mode, ContactMode::Sliding);
        assert!(p.twist.omega < 0.0);
        assert!((p.force_dir.y.abs() / p.force_dir.x - 0.3).abs() < 1e-12);
        let moved = p.twist.at(r);
        assert!((moved.x - 1.0).abs() < 1e-12, "{moved}");
        assert!(moved.y.abs() > 1e-3, "{moved}");
    }

    #[test]
    fn a_push_outside_the_motion_cone_slides_on_the_friction_cones_edge() {
        let a = 0.06;
        let s = LimitSurface::uniform_pressure(&square(a), 0.1, 0.4);
        let mu = 0.3;
        let r = DVec2::new(-0.5 * a, 0.0);
        // 40 deg off the normal: tan 40 deg = 0.84, far beyond mu.
        let v = DVec2::from_angle(40f64.to_radians());
        let p = s.point_push(r, DVec2::X, v, mu);
        assert_eq!(p.mode, ContactMode::Sliding);
        // The force is on the cone's edge on the pusher's side: tangential / normal = mu.
        assert!(p.force_dir.y > 0.0);
        assert!((p.force_dir.y / p.force_dir.x - mu).abs() < 1e-12);
        // The contact point keeps up with the pusher along the normal and lags behind it
        // along the face: it slides, against the friction on the object.
        let moved = p.twist.at(r);
        assert!((moved.x - v.x).abs() < 1e-12, "{moved} against {v}");
        assert!(moved.y < v.y - 1e-3, "{moved} against {v}");
        // A push just inside the cone sticks.
        let v = DVec2::from_angle(2f64.to_radians());
        assert_eq!(s.point_push(r, DVec2::X, v, mu).mode, ContactMode::Sticking);
        // Pulling away touches nothing.
        let p = s.point_push(r, DVec2::X, -DVec2::X, mu);
        assert_eq!(p.mode, ContactMode::Separating);
        assert_eq!(p.twist.v, DVec2::ZERO);
    }

    #[test]
    fn a_disc_pusher_first_touches_a_face_and_a_corner_where_geometry_says() {
        let sq = square(0.06);
        // Head-on at the left face from 100 mm: 100 - 30 - 37 mm.
        let t = sq
            .first_touch(DVec2::new(-0.1, 0.01), DVec2::X, 0.037)
            .expect("a touch");
        assert!((t - 0.033).abs() < 1e-12, "{t}");
        // Past the corner (-30, 30) mm, 40 mm above the face's line: the disc's edge
        // touches the corner when its centre is 37 mm from it.
        let y = 0.03 + 0.02;
        let t = sq
            .first_touch(DVec2::new(-0.1, y), DVec2::X, 0.037)
            .expect("a touch");
        let dx = (0.037f64.powi(2) - 0.02f64.powi(2)).sqrt();
        assert!((t - (0.1 - 0.03 - dx)).abs() < 1e-12, "{t}");
        // Far above: it passes by.
        assert!(
            sq.first_touch(DVec2::new(-0.1, 0.08), DVec2::X, 0.037)
                .is_none()
        );
        // A disc object: centre distance r + R.
        let disc = Footprint::Disc { radius: 0.035 };
        let t = disc
            .first_touch(DVec2::new(-0.1, 0.0), DVec2::X, 0.037)
            .expect("a touch");
        assert!((t - 0.028).abs() < 1e-12, "{t}");
        assert!((disc.mean_distance_to_centroid() - 0.035 * 2.0 / 3.0).abs() < 1e-15);
    }
}
