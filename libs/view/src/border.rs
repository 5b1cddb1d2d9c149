//! The learned border of the object, read off the AG layer's S: the view never knows the
//! object's polygon (ground truth), only what the estimator learned by circling it.

use glam::DVec2;

use crate::state::AgLayer;

/// Rays cast from the object frame's origin (the learned centroid): one every 4 degrees.
pub const BORDER_RAYS: usize = 90;

/// An S value below this (of S's maximum, 1) is no border.
pub const BORDER_MIN_S: f32 = 0.3;

/// The learned border as a closed polygon in the object frame (m), counter-clockwise: on
/// each of [`BORDER_RAYS`] rays from the origin, the point where S peaks, if it reaches
/// [`BORDER_MIN_S`]. S is a ridge along the border the robot circled, so its crest is the
/// border; an object whose border a ray from the centroid crosses twice (deeply concave)
/// shows its outer crossing's crest only where that one is the higher. `None` with fewer
/// than three border points.
pub fn learned_border(layer: &AgLayer) -> Option<Vec<DVec2>> {
    let h = &layer.header;
    let cell = h.cell_size_m;
    if cell.is_nan() || cell <= 0.0 {
        return None;
    }
    // Far enough to leave the grid from the origin whichever way.
    let corners = [
        DVec2::new(h.origin_x_m, h.origin_y_m),
        DVec2::new(h.origin_x_m + cell * h.width as f64, h.origin_y_m),
        DVec2::new(h.origin_x_m, h.origin_y_m + cell * h.height as f64),
        DVec2::new(
            h.origin_x_m + cell * h.width as f64,
            h.origin_y_m + cell * h.height as f64,
        ),
    ];
    let reach = corners.iter().map(|c| c.length()).fold(0.0, f64::max);
    let step = 0.25 * cell;
    let steps = (reach / step).ceil() as usize;
    let mut points = Vec::with_capacity(BORDER_RAYS);
    for k in 0..BORDER_RAYS {
        let dir = DVec2::from_angle(std::f64::consts::TAU * k as f64 / BORDER_RAYS as f64);
        let (mut best, mut at) = (0.0_f32, 0.0_f64);
        for n in 0..=steps {
            let t = n as f64 * step;
            let s = layer.shape_at(dir * t);
            if s > best {
                best = s;
                at = t;
            }
        }
        if best >= BORDER_MIN_S {
            // The cell's value stands for its centre: the crest is read to within a cell.
            points.push(dir * at);
        }
    }
    (points.len() >= 3).then_some(points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use agp_shared_types::{GRID_CELLS, GRID_SIDE, GridHeader};

    /// A layer whose S is a ring of radius `r` round the origin, 2 cells wide.
    fn ring(r: f64) -> AgLayer {
        let cell = 0.002;
        let origin = -(GRID_SIDE as f64) * cell / 2.0;
        let mut shape = vec![0.0f32; GRID_CELLS];
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                let c = DVec2::new(
                    origin + (i as f64 + 0.5) * cell,
                    origin + (j as f64 + 0.5) * cell,
                );
                let d = (c.length() - r) / cell;
                shape[j * GRID_SIDE + i] = (-d * d).exp() as f32;
            }
        }
        AgLayer {
            header: GridHeader {
                width: GRID_SIDE as u32,
                height: GRID_SIDE as u32,
                cell_size_m: cell,
                origin_x_m: origin,
                origin_y_m: origin,
                ..GridHeader::default()
            },
            shape,
            push_x_m: vec![0.0; GRID_CELLS],
            push_y_m: vec![0.0; GRID_CELLS],
            rotation_rad: vec![0.0; GRID_CELLS],
            push_weight: vec![0.0; GRID_CELLS],
        }
    }

    #[test]
    fn the_border_of_a_ring_of_s_is_the_ring_within_one_cell() {
        let r = 0.05;
        let layer = ring(r);
        let border = learned_border(&layer).expect("a border");
        assert_eq!(border.len(), BORDER_RAYS);
        for p in &border {
            // A cell is 2 mm: the crest is found within one cell's diagonal.
            assert!((p.length() - r).abs() < 0.002 * 1.5, "{p}");
        }
    }

    #[test]
    fn an_empty_s_has_no_border() {
        let mut layer = ring(0.05);
        layer.shape.iter_mut().for_each(|s| *s = 0.0);
        assert_eq!(learned_border(&layer), None);
    }
}
