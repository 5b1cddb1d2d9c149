//! From IR readings to geometry: the border point a reading implies, and the paper's mean
//! IR vector. Everything goes through the robot description's calibrated response curve.

use glam::DVec2;

use crate::robot::RobotDescription;
use crate::scenario::Pose;

/// Largest standard deviation (one sigma, metres) of the distance a reading implies for the
/// reading to count as a border point: 1 mm.
///
/// With the E-puck's table (robot-and-world.md) the distance error (reading noise divided
/// by the curve's slope) stays under 0.6 mm up to 40 mm from the sensor; just beyond 40 mm
/// the slope flattens to 3.8 raw/mm and the error jumps to 1.2 mm, and past 50 mm to 3 mm.
/// So [`border_range`] is **40 mm** from the sensor (a 2 mm bound would give 50 mm, a
/// 0.5 mm bound only 15 mm because of the 4 % noise at 15 mm). The paper's own 0.75
/// threshold maps to about 30 grid units of its curve; 40 mm is this table's equivalent.
pub const BORDER_MAX_SIGMA: f64 = 1e-3;

/// Distance from a sensor (metres) up to which its reading places a border point within
/// [`BORDER_MAX_SIGMA`]: the curve's usable range (40 mm for the E-puck). Computed from the
/// table, so a different calibration gives its own range. Not for a hot loop: compute it
/// once and pass it to [`ir_border_point`].
pub fn border_range(robot: &RobotDescription) -> f64 {
    robot.response.usable_range(BORDER_MAX_SIGMA)
}

/// Where the ray of sensor `sensor` meets the object, in the robot frame (x forward, y
/// left, metres): mount + inverted distance * ray direction. `None` when the index is not
/// a sensor, the reading is 0 (or not a number), or the inverted distance is beyond
/// `max_range` (use [`border_range`]).
pub fn ir_point_robot(
    robot: &RobotDescription,
    sensor: usize,
    raw: f64,
    max_range: f64,
) -> Option<DVec2> {
    let s = robot.ir_sensors.get(sensor)?;
    if raw.is_nan() || raw <= 0.0 {
        return None;
    }
    let d = robot.response.distance(raw)?;
    if d > max_range {
        return None;
    }
    Some(s.mount + s.direction() * d)
}

/// The point on the object's border that sensor `sensor`'s reading `raw` implies, in the
/// frame of `pose` (the robot's pose in that frame, e.g. odometry): pose * (mount +
/// inverted distance * ray direction). `None` as for [`ir_point_robot`].
pub fn ir_border_point(
    robot: &RobotDescription,
    pose: Pose,
    sensor: usize,
    raw: f64,
    max_range: f64,
) -> Option<DVec2> {
    ir_point_robot(robot, sensor, raw, max_range).map(|p| to_frame(pose, p))
}

/// A point of the robot frame expressed in the frame `pose` lives in.
pub fn to_frame(pose: Pose, p_robot: DVec2) -> DVec2 {
    pose.to_world(p_robot)
}

/// The paper's mean IR vector (Algorithm 2, line 1): the sum over the sensors of their ray
/// directions weighted by their normalised readings (raw / the curve's largest reading, so
/// 0..1 with 1 the closest an object can be sensed), rotated by the robot's `heading`
/// (radians) into the frame the heading is given in. Zero when nothing is seen. Readings
/// beyond the robot's sensors are ignored; non-finite or negative readings count as 0.
pub fn mean_ir_vector(robot: &RobotDescription, heading: f64, ir_raw: &[f32]) -> DVec2 {
    let max = robot.response.max_reading();
    let sum = robot
        .ir_sensors
        .iter()
        .zip(ir_raw)
        .map(|(s, &raw)| {
            let w = if raw.is_finite() {
                (raw as f64 / max).clamp(0.0, 1.0)
            } else {
                0.0
            };
            s.direction() * w
        })
        .fold(DVec2::ZERO, |a, b| a + b);
    DVec2::from_angle(heading).rotate(sum)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance along a ray from `o` (unit direction `d`) to the line x = `wall_x`.
    fn ray_to_wall(o: DVec2, d: DVec2, wall_x: f64) -> Option<f64> {
        if d.x.abs() < 1e-12 {
            return None;
        }
        let t = (wall_x - o.x) / d.x;
        (t >= 0.0).then_some(t)
    }

    #[test]
    fn the_border_range_of_the_epuck_is_40_mm_for_a_1_mm_sigma() {
        let robot = RobotDescription::epuck();
        let range = border_range(&robot);
        assert!((range - 0.040).abs() < 1e-4, "usable range {range}");
        assert!(robot.response.distance_sigma(range) <= BORDER_MAX_SIGMA);
        assert!(robot.response.distance_sigma(range + 0.0005) > BORDER_MAX_SIGMA);
    }

    #[test]
    fn a_wall_at_a_known_distance_gives_points_on_the_wall() {
        let robot = RobotDescription::epuck();
        let range = border_range(&robot);
        let wall_x = 0.55;
        let mut seen = 0;
        // Several poses facing the wall at various angles and distances.
        for (k, heading_deg) in [-70.0f64, -30.0, 0.0, 20.0, 65.0, 110.0, 170.0, -120.0]
            .iter()
            .enumerate()
        {
            let pose = Pose::new(
                0.52 - 0.003 * k as f64,
                0.2 + 0.01 * k as f64,
                heading_deg.to_radians(),
            );
            let rot = DVec2::from_angle(pose.theta);
            for (i, s) in robot.ir_sensors.iter().enumerate() {
                let o = pose.position() + rot.rotate(s.mount);
                let dir = rot.rotate(s.direction());
                let raw = match ray_to_wall(o, dir, wall_x) {
                    Some(t) => robot.response.reading(t),
                    None => 0.0,
                };
                let p = ir_border_point(&robot, pose, i, raw, range);
                match ray_to_wall(o, dir, wall_x) {
                    Some(t) if t > 0.0 && t <= range => {
                        let p = p.expect("a wall within range gives a point");
                        // The curve is piecewise linear both ways: inversion is exact.
                        assert!(
                            (p.x - wall_x).abs() < 1e-9,
                            "sensor {i} heading {heading_deg}: {p}"
                        );
                        let expected = o + dir * t;
                        assert!(
                            (p - expected).length() < 1e-9,
                            "sensor {i}: {p} vs {expected}"
                        );
                        seen += 1;
                    }
                    Some(t) if t > range => {
                        assert_eq!(p, None, "sensor {i} at {t} m is beyond the usable range")
                    }
                    _ => assert_eq!(p, None),
                }
            }
        }
        assert!(seen >= 10, "only {seen} readings hit the wall within range");
    }

    #[test]
    fn a_zero_reading_or_a_bad_index_gives_no_point() {
        let robot = RobotDescription::epuck();
        let range = border_range(&robot);
        let pose = Pose::new(0.1, -0.2, 0.3);
        assert_eq!(ir_border_point(&robot, pose, 0, 0.0, range), None);
        assert_eq!(ir_border_point(&robot, pose, 0, f64::NAN, range), None);
        assert_eq!(ir_border_point(&robot, pose, 8, 1000.0, range), None);
        // 60 mm is a valid reading but too noisy for a border point.
        assert_eq!(
            ir_border_point(&robot, pose, 2, robot.response.reading(0.060), range),
            None
        );
        assert!(ir_border_point(&robot, pose, 2, robot.response.reading(0.060), 0.07).is_some());
    }

    #[test]
    fn the_side_sensor_sees_a_point_straight_beside_the_robot() {
        let robot = RobotDescription::epuck();
        let range = border_range(&robot);
        // Heading +y: IR3 (+90 deg) looks towards -x. A reading of 20 mm from the mount at
        // (0, 31 mm) puts the point 51 mm to the robot's left.
        let pose = Pose::new(1.0, 2.0, std::f64::consts::FRAC_PI_2);
        let p = ir_border_point(&robot, pose, 2, robot.response.reading(0.020), range)
            .expect("in range");
        assert!((p - DVec2::new(1.0 - 0.051, 2.0)).length() < 1e-9, "{p}");
    }

    #[test]
    fn the_mean_ir_vector_points_at_what_the_robot_sees() {
        let robot = RobotDescription::epuck();
        let c = &robot.response;
        // A symmetric obstacle ahead: the vector points along the heading, in any frame.
        let mut raw = [0f32; 8];
        raw[0] = c.reading(0.010) as f32;
        raw[7] = c.reading(0.010) as f32;
        raw[1] = c.reading(0.030) as f32;
        raw[6] = c.reading(0.030) as f32;
        for heading in [0.0, 1.0, -2.5] {
            let v = mean_ir_vector(&robot, heading, &raw);
            let along = DVec2::from_angle(heading);
            assert!(v.perp_dot(along).abs() < 1e-6, "heading {heading}: {v}");
            let w = 2.0
                * (raw[0] as f64 * 17f64.to_radians().cos()
                    + raw[1] as f64 * 45f64.to_radians().cos())
                / c.max_reading();
            assert!((v.dot(along) - w).abs() < 1e-6);
        }
        // Only the left side sensor sees something: the vector points to the robot's left.
        let mut raw = [0f32; 8];
        raw[2] = c.max_reading() as f32;
        let v = mean_ir_vector(&robot, 0.5, &raw);
        assert!((v - DVec2::from_angle(0.5 + std::f64::consts::FRAC_PI_2)).length() < 1e-9);
        assert_eq!(mean_ir_vector(&robot, 0.5, &[0.0; 8]), DVec2::ZERO);
    }
}
