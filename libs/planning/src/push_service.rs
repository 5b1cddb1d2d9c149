//! What a push chosen by another process means: the push-level service of
//! `agp-planner --mode skills` takes a push as (contact angle, alpha, length), the words of
//! the `agp` Python package's `PushPlanner`, and makes it a push of the planning library's
//! family (from the start circle, at an aim point of the learned border).

use agp_affordance::{CONTACT_BORDER_THRESHOLD, Grid};
use glam::DVec2;

/// The aim point (object frame, m) of contact angle `angle_rad`: on the ray from the
/// centroid at that angle, walking in from the grid's edge, the centroid of the first band
/// of `shape` (the combined S, normalised) above [`CONTACT_BORDER_THRESHOLD`], as
/// `AffordanceGradient::contact_candidates` locates each of its rays'. `None` when the ray
/// meets no border.
pub fn aim_point_at(shape: &Grid, angle_rad: f64) -> Option<DVec2> {
    if !angle_rad.is_finite() {
        return None;
    }
    let u = DVec2::from_angle(angle_rad);
    let step = 0.25 * shape.cell_size_m();
    let mut r = 0.5 * shape.extent_m() - shape.cell_size_m();
    let mut s = shape.sample(u * r);
    while r > 0.0 && s < CONTACT_BORDER_THRESHOLD {
        r -= step;
        s = shape.sample(u * r);
    }
    let (mut weight, mut moment) = (0.0_f64, 0.0_f64);
    while r > 0.0 && s >= CONTACT_BORDER_THRESHOLD {
        let w = f64::from(s - CONTACT_BORDER_THRESHOLD);
        weight += w;
        moment += w * r;
        r -= step;
        s = shape.sample(u * r);
    }
    (weight > 0.0).then(|| u * (moment / weight))
}

/// The length (m) of the learned push: the push routine's speed for its duration.
pub fn learned_push_length_m(push_speed_mps: f64, push_duration_s: f64) -> f64 {
    push_speed_mps * push_duration_s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_through_a_ring_of_border_aims_at_the_ring() {
        // S = 1 on the cells 30 mm (+-1 cell) from the centre, 0 elsewhere.
        let mut g = Grid::centred(0.002);
        for j in 0..Grid::SIDE {
            for i in 0..Grid::SIDE {
                let p = g.cell_centre_m(i, j);
                if (p.length() - 0.03).abs() <= 0.001 {
                    g.cells_mut()[Grid::index(i, j)] = 1.0;
                }
            }
        }
        for deg in [0.0_f64, 37.0, 90.0, 200.0] {
            let p = aim_point_at(&g, deg.to_radians()).expect("the ray meets the ring");
            assert!((p.length() - 0.03).abs() < 1.5e-3, "{deg} deg: {p}");
            assert!(
                (p.to_angle() - deg.to_radians()).sin().abs() < 1e-9,
                "{deg} deg: {p}"
            );
        }
    }
}
