use agp_shared_types::angle::wrap_angle;
use agp_world::Pose;

/// Moves a differential-drive robot by the given wheel travels (metres), both wheels
/// turning at constant speed over the interval: an exact arc of length
/// (left + right) / 2 turning by (right - left) / axle.
///
/// The chord of the arc points along the mean heading and is sinc(dtheta / 2) times the arc
/// length, so straight lines and turns on the spot are exact as well.
pub fn drive_arc(pose: Pose, left: f64, right: f64, axle: f64) -> Pose {
    let ds = (left + right) / 2.0;
    let dtheta = (right - left) / axle;
    let half = dtheta / 2.0;
    // sin(x)/x = 1 - x^2/6 to within 1e-20 below 1e-5 rad.
    let sinc = if half.abs() < 1e-5 {
        1.0 - half * half / 6.0
    } else {
        half.sin() / half
    };
    let chord = ds * sinc;
    let mid = pose.theta + half;
    Pose::new(
        pose.x + chord * mid.cos(),
        pose.y + chord * mid.sin(),
        wrap_angle(pose.theta + dtheta),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn a_quarter_circle_ends_where_geometry_says() {
        // Outer wheel on radius R + a/2, inner on R - a/2, a quarter turn.
        let (r, a) = (0.2, 0.052);
        let (l, rr) = ((r - a / 2.0) * PI / 2.0, (r + a / 2.0) * PI / 2.0);
        let p = drive_arc(Pose::new(0.0, 0.0, 0.0), l, rr, a);
        assert!((p.x - r).abs() < 1e-15 && (p.y - r).abs() < 1e-15, "{p:?}");
        assert!((p.theta - PI / 2.0).abs() < 1e-15);
    }

    #[test]
    fn equal_wheels_drive_straight_and_opposite_wheels_turn_on_the_spot() {
        let p = drive_arc(Pose::new(1.0, 2.0, 0.5), 0.1, 0.1, 0.052);
        assert!((p.x - (1.0 + 0.1 * 0.5f64.cos())).abs() < 1e-15);
        assert!((p.y - (2.0 + 0.1 * 0.5f64.sin())).abs() < 1e-15);
        let q = drive_arc(Pose::new(1.0, 2.0, 0.5), -0.01, 0.01, 0.052);
        assert_eq!((q.x, q.y), (1.0, 2.0));
        assert!((q.theta - (0.5 + 0.02 / 0.052)).abs() < 1e-15);
    }
}
