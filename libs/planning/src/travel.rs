//! Getting the robot to the start of its next push without touching the object: out to a
//! circle around the object, along it, then turning in place to the push heading.

use agp_shared_types::angle::wrap_angle;
use agp_world::Pose;
use glam::DVec2;

/// How the robot travels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TravelSettings {
    /// Forward speed, m/s.
    pub speed: f64,
    /// Fastest turn, rad/s.
    pub max_turn_rate: f64,
    /// Turn rate per radian of heading error, 1/s.
    pub heading_gain: f64,
    /// Above this heading error (rad) the robot turns in place before it goes on.
    pub turn_in_place: f64,
    /// An intermediate waypoint is passed within this distance, m.
    pub pass_radius: f64,
    /// The last waypoint is reached within this distance, m.
    pub arrive_radius: f64,
    /// The final heading is reached within this error, rad.
    pub heading_tolerance: f64,
    /// Angle between waypoints on the circle, rad.
    pub arc_step: f64,
}

impl Default for TravelSettings {
    fn default() -> Self {
        Self {
            speed: 0.1,
            max_turn_rate: 3.0,
            heading_gain: 8.0,
            turn_in_place: 0.3,
            pass_radius: 0.006,
            arrive_radius: 0.0015,
            heading_tolerance: 0.004,
            arc_step: 0.2,
        }
    }
}

/// Waypoints from `robot` to `target` that keep at least `radius` from `centre`: the
/// robot's radial projection onto the circle, then along the circle the shorter way round
/// to `target`'s angle, ending at `target` (which should lie on the circle).
pub fn orbit_waypoints(
    robot: DVec2,
    centre: DVec2,
    radius: f64,
    target: DVec2,
    arc_step: f64,
) -> Vec<DVec2> {
    let mut out = Vec::new();
    orbit_waypoints_into(&mut out, robot, centre, radius, target, arc_step);
    out
}

/// [`orbit_waypoints`] into `out` (cleared first), reusing its allocation.
pub fn orbit_waypoints_into(
    out: &mut Vec<DVec2>,
    robot: DVec2,
    centre: DVec2,
    radius: f64,
    target: DVec2,
    arc_step: f64,
) {
    let from = robot - centre;
    let a0 = if from.length() > 1e-9 {
        from.to_angle()
    } else {
        (target - centre).to_angle()
    };
    let a1 = (target - centre).to_angle();
    let turn = wrap_angle(a1 - a0);
    let n = (turn.abs() / arc_step.max(1e-3)).ceil() as usize;
    out.clear();
    out.reserve(n + 2);
    if from.length() < radius - 1e-4 || from.length() > radius + 1e-4 {
        out.push(centre + radius * DVec2::from_angle(a0));
    }
    for k in 1..n {
        out.push(centre + radius * DVec2::from_angle(a0 + turn * k as f64 / n as f64));
    }
    out.push(target);
}

/// Where a travel stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TravelPhase {
    /// Heading for waypoint `k`.
    Waypoint(usize),
    /// At the last waypoint, turning to the final heading.
    Turn,
    Done,
}

/// Follows waypoints, then turns to a heading; wheel speeds from the robot's pose.
#[derive(Debug, Clone)]
pub struct TravelRoutine {
    settings: TravelSettings,
    half_axle: f64,
    max_wheel: f64,
    waypoints: Vec<DVec2>,
    heading: f64,
    phase: TravelPhase,
}

impl TravelRoutine {
    /// A travel through `waypoints` ending with heading `heading` (rad), for a robot with
    /// this axle length and top wheel speed (m, m/s).
    pub fn new(
        settings: TravelSettings,
        axle_length: f64,
        max_wheel_speed: f64,
        waypoints: Vec<DVec2>,
        heading: f64,
    ) -> Self {
        let phase = if waypoints.is_empty() {
            TravelPhase::Turn
        } else {
            TravelPhase::Waypoint(0)
        };
        Self {
            settings,
            half_axle: 0.5 * axle_length,
            max_wheel: max_wheel_speed,
            waypoints,
            heading,
            phase,
        }
    }

    /// The waypoint buffer back, for the next travel to reuse.
    pub fn into_waypoints(self) -> Vec<DVec2> {
        self.waypoints
    }

    pub fn phase(&self) -> TravelPhase {
        self.phase
    }

    /// Wheel speeds (left, right), m/s, for the robot at `pose`; (0, 0) once done.
    pub fn update(&mut self, pose: Pose) -> (f64, f64) {
        loop {
            match self.phase {
                TravelPhase::Done => return (0.0, 0.0),
                TravelPhase::Turn => {
                    let e = wrap_angle(self.heading - pose.theta);
                    if e.abs() < self.settings.heading_tolerance {
                        self.phase = TravelPhase::Done;
                        continue;
                    }
                    return self.wheels(0.0, self.turn_rate(e));
                }
                TravelPhase::Waypoint(k) => {
                    let last = k + 1 == self.waypoints.len();
                    let to = self.waypoints[k] - pose.position();
                    let d = to.length();
                    let reach = if last {
                        self.settings.arrive_radius
                    } else {
                        self.settings.pass_radius
                    };
                    if d < reach {
                        self.phase = if last {
                            TravelPhase::Turn
                        } else {
                            TravelPhase::Waypoint(k + 1)
                        };
                        continue;
                    }
                    let e = wrap_angle(to.to_angle() - pose.theta);
                    if e.abs() > self.settings.turn_in_place {
                        return self.wheels(0.0, self.turn_rate(e));
                    }
                    // Slow down into the last waypoint so that the stop lands within reach.
                    let v = if last {
                        self.settings.speed.min(4.0 * d).max(0.01)
                    } else {
                        self.settings.speed
                    } * e.cos();
                    return self.wheels(v, self.turn_rate(e));
                }
            }
        }
    }

    fn turn_rate(&self, e: f64) -> f64 {
        let m = self.settings.max_turn_rate;
        (self.settings.heading_gain * e).clamp(-m, m)
    }

    /// Wheel speeds for forward speed `v` and turn rate `w`, scaled down together so that
    /// neither wheel exceeds the top speed (the path's curvature is kept).
    fn wheels(&self, v: f64, w: f64) -> (f64, f64) {
        let (l, r) = (v - w * self.half_axle, v + w * self.half_axle);
        let peak = l.abs().max(r.abs());
        if peak > self.max_wheel {
            let k = self.max_wheel / peak;
            (l * k, r * k)
        } else {
            (l, r)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_waypoints_stay_on_the_circle_and_go_the_short_way() {
        let c = DVec2::new(0.1, -0.2);
        let r = 0.09;
        let target = c + r * DVec2::from_angle(-2.5);
        let w = orbit_waypoints(c + DVec2::new(0.05, 0.0), c, r, target, 0.2);
        // First out to the circle along the robot's own ray.
        assert!((w[0] - (c + DVec2::new(r, 0.0))).length() < 1e-12);
        for p in &w {
            assert!(((*p - c).length() - r).abs() < 1e-9);
        }
        // From angle 0 to -2.5 rad the short way is clockwise: angles only decrease.
        let angles: Vec<f64> = w.iter().map(|p| (*p - c).to_angle()).collect();
        assert!(angles.windows(2).all(|a| a[1] < a[0]), "{angles:?}");
        assert_eq!(*w.last().expect("a waypoint"), target);
    }

    #[test]
    fn a_unicycle_following_the_routine_arrives_at_the_pose() {
        // Integrate the differential drive exactly as the physics does (arc per step).
        let mut pose = Pose::new(0.0, 0.0, 0.0);
        let axle = 0.052;
        let target = DVec2::new(-0.1, 0.08);
        let mut t = TravelRoutine::new(
            TravelSettings::default(),
            axle,
            0.128,
            orbit_waypoints(pose.position(), DVec2::new(-0.05, 0.0), 0.05, target, 0.2),
            1.0,
        );
        let dt = 1.0 / 640.0;
        for _ in 0..640 * 20 {
            let (l, r) = t.update(pose);
            if t.phase() == TravelPhase::Done {
                break;
            }
            let v = 0.5 * (l + r);
            let w = (r - l) / axle;
            let mid = pose.theta + 0.5 * w * dt;
            pose.x += v * dt * mid.cos();
            pose.y += v * dt * mid.sin();
            pose.theta = wrap_angle(pose.theta + w * dt);
        }
        assert_eq!(t.phase(), TravelPhase::Done);
        assert!((pose.position() - target).length() < 0.002, "{pose:?}");
        assert!(wrap_angle(pose.theta - 1.0).abs() < 0.01, "{pose:?}");
    }
}
