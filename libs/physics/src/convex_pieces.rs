use agp_world::{Polygon, signed_area};
use glam::DVec2;

/// Relative tolerance of the convexity tests: a corner turning less than this (times the
/// squared size of the polygon) is taken as straight.
const FLAT: f64 = 1e-12;

/// Splits a simple polygon into convex pieces (counter-clockwise vertex lists) covering
/// it exactly: the polygon itself when it is convex, otherwise its ear-clipping
/// triangulation with neighbouring pieces merged while the union stays convex
/// (Hertel-Mehlhorn). Returns `None` when the triangulation does not cover the area.
pub fn convex_pieces(poly: &Polygon) -> Option<Vec<Vec<DVec2>>> {
    let scale = poly.radius().max(1e-300).powi(2);
    if is_convex(poly.vertices(), scale) {
        return Some(vec![poly.vertices().to_vec()]);
    }
    let tris = poly.triangulate();
    let covered: f64 = tris.iter().map(|t| signed_area(t)).sum();
    if (covered - poly.area()).abs() > 1e-9 * poly.area() {
        return None;
    }
    let mut pieces: Vec<Vec<DVec2>> = tris.iter().map(|t| t.to_vec()).collect();
    'merge: loop {
        for i in 0..pieces.len() {
            for j in i + 1..pieces.len() {
                if let Some(m) = merge(&pieces[i], &pieces[j])
                    && is_convex(&m, scale)
                {
                    pieces[i] = m;
                    pieces.swap_remove(j);
                    continue 'merge;
                }
            }
        }
        break;
    }
    Some(pieces)
}

/// Whether every corner of a counter-clockwise polygon turns left (or goes straight).
fn is_convex(v: &[DVec2], scale: f64) -> bool {
    let n = v.len();
    (0..n).all(|k| {
        let (a, b, c) = (v[k], v[(k + 1) % n], v[(k + 2) % n]);
        (b - a).perp_dot(c - b) >= -FLAT * scale
    })
}

/// The union of two counter-clockwise polygons sharing an edge (a, b) in `p` and (b, a) in
/// `q`, counter-clockwise, or `None` when they share no edge.
fn merge(p: &[DVec2], q: &[DVec2]) -> Option<Vec<DVec2>> {
    let (np, nq) = (p.len(), q.len());
    for k in 0..np {
        let (a, b) = (p[k], p[(k + 1) % np]);
        for l in 0..nq {
            if q[l] == b && q[(l + 1) % nq] == a {
                // p from b round to a, then q's vertices strictly between a and b.
                let mut out = Vec::with_capacity(np + nq - 2);
                out.extend((0..np).map(|s| p[(k + 1 + s) % np]));
                out.extend((0..nq - 2).map(|s| q[(l + 2 + s) % nq]));
                return Some(out);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poly(pts: &[[f64; 2]]) -> Polygon {
        Polygon::new(pts.iter().map(|p| DVec2::new(p[0], p[1])).collect()).unwrap()
    }

    #[test]
    fn a_convex_polygon_stays_one_piece() {
        let p = poly(&[[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]);
        assert_eq!(convex_pieces(&p).unwrap().len(), 1);
    }

    #[test]
    fn an_l_shape_becomes_a_few_convex_pieces_of_its_area() {
        let l = poly(&[
            [0.0, 0.0],
            [3.0, 0.0],
            [3.0, 1.0],
            [2.0, 1.0],
            [2.0, 2.0],
            [0.0, 2.0],
        ]);
        let pieces = convex_pieces(&l).unwrap();
        assert!(
            pieces.len() >= 2 && pieces.len() <= 3,
            "{} pieces",
            pieces.len()
        );
        let area: f64 = pieces.iter().map(|p| signed_area(p)).sum();
        assert!((area - l.area()).abs() < 1e-12);
        assert!(pieces.iter().all(|p| is_convex(p, 4.0)));
    }
}
