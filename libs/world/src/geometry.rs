use glam::DVec2;

/// A simple polygon (convex or not), counter-clockwise, in its own frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    vertices: Vec<DVec2>,
}

/// Why a list of vertices is not a usable polygon.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolygonError {
    #[error("a polygon needs at least 3 vertices, got {0}")]
    TooFewVertices(usize),
    #[error("vertex {0} is not a finite number")]
    NotFinite(usize),
    #[error("the polygon has zero area")]
    ZeroArea,
    #[error("edges {0} and {1} cross: the polygon crosses itself")]
    SelfIntersecting(usize, usize),
}

impl Polygon {
    /// Checks the vertices and orients them counter-clockwise.
    pub fn new(mut vertices: Vec<DVec2>) -> Result<Self, PolygonError> {
        if vertices.len() < 3 {
            return Err(PolygonError::TooFewVertices(vertices.len()));
        }
        if let Some(i) = vertices.iter().position(|v| !v.is_finite()) {
            return Err(PolygonError::NotFinite(i + 1));
        }
        let n = vertices.len();
        for i in 0..n {
            for j in i + 1..n {
                // Adjacent edges share a vertex and never count as crossing.
                if j == i + 1 || (i == 0 && j == n - 1) {
                    continue;
                }
                let (a, b) = (vertices[i], vertices[(i + 1) % n]);
                let (c, d) = (vertices[j], vertices[(j + 1) % n]);
                if segments_intersect(a, b, c, d) {
                    return Err(PolygonError::SelfIntersecting(i + 1, j + 1));
                }
            }
        }
        let area = signed_area(&vertices);
        if area.abs() < 1e-12 {
            return Err(PolygonError::ZeroArea);
        }
        if area < 0.0 {
            vertices.reverse();
        }
        Ok(Self { vertices })
    }

    pub fn vertices(&self) -> &[DVec2] {
        &self.vertices
    }

    pub fn area(&self) -> f64 {
        signed_area(&self.vertices)
    }

    /// Centroid of the enclosed area.
    pub fn centroid(&self) -> DVec2 {
        let mut c = DVec2::ZERO;
        let n = self.vertices.len();
        for i in 0..n {
            let (p, q) = (self.vertices[i], self.vertices[(i + 1) % n]);
            c += (p + q) * p.perp_dot(q);
        }
        c / (6.0 * self.area())
    }

    /// The same polygon moved so its centroid is the origin.
    pub fn centred(&self) -> Self {
        let c = self.centroid();
        Self {
            vertices: self.vertices.iter().map(|v| *v - c).collect(),
        }
    }

    /// Polar moment of area about the centroid, divided by the area (m^2): times the mass
    /// it gives the moment of inertia of a uniform plate.
    pub fn inertia_per_mass(&self) -> f64 {
        let c = self.centroid();
        let n = self.vertices.len();
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..n {
            let (p, q) = (self.vertices[i] - c, self.vertices[(i + 1) % n] - c);
            let cross = p.perp_dot(q);
            num += cross * (p.dot(p) + p.dot(q) + q.dot(q));
            den += cross;
        }
        num / (6.0 * den)
    }

    pub fn contains(&self, p: DVec2) -> bool {
        let mut inside = false;
        let n = self.vertices.len();
        let mut j = n - 1;
        for i in 0..n {
            let (a, b) = (self.vertices[i], self.vertices[j]);
            if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
                inside = !inside;
            }
            j = i;
        }
        inside
    }

    /// Distance from `p` to the polygon's border.
    pub fn border_distance(&self, p: DVec2) -> f64 {
        self.edges()
            .map(|(a, b)| point_segment_distance(p, a, b))
            .fold(f64::INFINITY, f64::min)
    }

    /// Edges as (start, end) pairs.
    pub fn edges(&self) -> impl Iterator<Item = (DVec2, DVec2)> + '_ {
        let n = self.vertices.len();
        (0..n).map(move |i| (self.vertices[i], self.vertices[(i + 1) % n]))
    }

    /// Largest distance from the centroid to a vertex.
    pub fn radius(&self) -> f64 {
        let c = self.centroid();
        self.vertices
            .iter()
            .map(|v| (*v - c).length())
            .fold(0.0, f64::max)
    }

    /// Splits the polygon into triangles (ear clipping), for physics colliders and
    /// footprint sampling.
    pub fn triangulate(&self) -> Vec<[DVec2; 3]> {
        let mut idx: Vec<usize> = (0..self.vertices.len()).collect();
        let mut out = Vec::with_capacity(idx.len().saturating_sub(2));
        let v = &self.vertices;
        let mut guard = 0;
        while idx.len() > 3 && guard < 10_000 {
            guard += 1;
            let n = idx.len();
            let mut clipped = false;
            for k in 0..n {
                let (ia, ib, ic) = (idx[(k + n - 1) % n], idx[k], idx[(k + 1) % n]);
                let (a, b, c) = (v[ia], v[ib], v[ic]);
                if (b - a).perp_dot(c - b) <= 1e-15 {
                    continue; // reflex or flat corner: not an ear
                }
                let blocked = idx
                    .iter()
                    .filter(|&&m| m != ia && m != ib && m != ic)
                    .any(|&m| point_in_triangle(v[m], a, b, c));
                if blocked {
                    continue;
                }
                out.push([a, b, c]);
                idx.remove(k);
                clipped = true;
                break;
            }
            if !clipped {
                break;
            }
        }
        if idx.len() == 3 {
            out.push([v[idx[0]], v[idx[1]], v[idx[2]]]);
        }
        out
    }

    /// Distance along the ray `origin + t * dir` (dir a unit vector) to the first border
    /// crossing, if any, up to `max`.
    pub fn ray_cast(&self, origin: DVec2, dir: DVec2, max: f64) -> Option<f64> {
        self.edges()
            .filter_map(|(a, b)| ray_segment(origin, dir, a, b))
            .filter(|t| *t <= max)
            .fold(None, |best: Option<f64>, t| {
                Some(best.map_or(t, |b| b.min(t)))
            })
    }
}

/// Twice-signed area / 2: positive for counter-clockwise vertices.
pub fn signed_area(v: &[DVec2]) -> f64 {
    let n = v.len();
    (0..n).map(|i| v[i].perp_dot(v[(i + 1) % n])).sum::<f64>() / 2.0
}

pub fn point_segment_distance(p: DVec2, a: DVec2, b: DVec2) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - p).length()
}

fn point_in_triangle(p: DVec2, a: DVec2, b: DVec2, c: DVec2) -> bool {
    let d1 = (b - a).perp_dot(p - a);
    let d2 = (c - b).perp_dot(p - b);
    let d3 = (a - c).perp_dot(p - c);
    d1 >= 0.0 && d2 >= 0.0 && d3 >= 0.0
}

fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

fn on_segment(a: DVec2, b: DVec2, p: DVec2) -> bool {
    p.x >= a.x.min(b.x) - 1e-15
        && p.x <= a.x.max(b.x) + 1e-15
        && p.y >= a.y.min(b.y) - 1e-15
        && p.y <= a.y.max(b.y) + 1e-15
}

/// Whether the closed segments ab and cd share a point.
pub fn segments_intersect(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let (o1, o2, o3, o4) = (
        orient(a, b, c),
        orient(a, b, d),
        orient(c, d, a),
        orient(c, d, b),
    );
    if ((o1 > 0.0 && o2 < 0.0) || (o1 < 0.0 && o2 > 0.0))
        && ((o3 > 0.0 && o4 < 0.0) || (o3 < 0.0 && o4 > 0.0))
    {
        return true;
    }
    (o1 == 0.0 && on_segment(a, b, c))
        || (o2 == 0.0 && on_segment(a, b, d))
        || (o3 == 0.0 && on_segment(c, d, a))
        || (o4 == 0.0 && on_segment(c, d, b))
}

/// Parameter t >= 0 where the ray origin + t dir crosses segment ab.
pub fn ray_segment(origin: DVec2, dir: DVec2, a: DVec2, b: DVec2) -> Option<f64> {
    let e = b - a;
    let denom = dir.perp_dot(e);
    if denom.abs() < 1e-15 {
        return None;
    }
    let w = a - origin;
    let t = w.perp_dot(e) / denom;
    let u = w.perp_dot(dir) / denom;
    (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(side: f64) -> Polygon {
        let h = side / 2.0;
        Polygon::new(vec![
            DVec2::new(-h, -h),
            DVec2::new(h, -h),
            DVec2::new(h, h),
            DVec2::new(-h, h),
        ])
        .unwrap()
    }

    #[test]
    fn a_square_has_the_analytic_area_centroid_and_inertia() {
        let s = square(0.06);
        assert!((s.area() - 0.0036).abs() < 1e-15);
        assert!(s.centroid().length() < 1e-15);
        // Plate: (a^2 + b^2) / 12.
        assert!((s.inertia_per_mass() - 2.0 * 0.0036 / 12.0).abs() < 1e-15);
    }

    #[test]
    fn a_clockwise_polygon_is_turned_counter_clockwise() {
        let p = Polygon::new(vec![
            DVec2::ZERO,
            DVec2::new(0.0, 1.0),
            DVec2::new(1.0, 0.0),
        ])
        .unwrap();
        assert!(p.area() > 0.0);
    }

    #[test]
    fn a_bow_tie_is_refused_as_self_intersecting() {
        let e = Polygon::new(vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, 1.0),
        ])
        .unwrap_err();
        assert!(matches!(e, PolygonError::SelfIntersecting(..)));
    }

    #[test]
    fn collinear_points_are_refused_as_zero_area() {
        let e = Polygon::new(vec![
            DVec2::ZERO,
            DVec2::new(1.0, 0.0),
            DVec2::new(2.0, 0.0),
        ])
        .unwrap_err();
        assert!(matches!(
            e,
            PolygonError::ZeroArea | PolygonError::SelfIntersecting(..)
        ));
    }

    #[test]
    fn an_l_shape_triangulates_into_its_area() {
        let l = Polygon::new(
            [
                [0.0, 0.0],
                [3.0, 0.0],
                [3.0, 1.0],
                [1.0, 1.0],
                [1.0, 2.0],
                [0.0, 2.0],
            ]
            .iter()
            .map(|p| DVec2::new(p[0], p[1]))
            .collect(),
        )
        .unwrap();
        let tris = l.triangulate();
        assert_eq!(tris.len(), 4);
        let area: f64 = tris.iter().map(|t| signed_area(t)).sum();
        assert!((area - 4.0).abs() < 1e-12);
        assert!(l.contains(DVec2::new(0.5, 1.5)));
        assert!(!l.contains(DVec2::new(2.0, 1.5)));
    }

    #[test]
    fn a_ray_hits_the_nearest_edge() {
        let s = square(2.0);
        let t = s.ray_cast(DVec2::new(-5.0, 0.0), DVec2::X, 10.0).unwrap();
        assert!((t - 4.0).abs() < 1e-12);
        assert_eq!(s.ray_cast(DVec2::new(-5.0, 3.0), DVec2::X, 10.0), None);
    }
}
