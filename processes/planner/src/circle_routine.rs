use std::f64::consts::{FRAC_PI_2, TAU};

use agp_world::{Pose, RobotDescription, border_range, ir_border_point, wrap_angle};
use glam::DVec2;

/// Which side of the robot the object is kept on while circling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Object on the left (IR3 at +90 deg): the robot goes round it counter-clockwise.
    Left,
    /// Object on the right (IR6 at -90 deg): clockwise.
    Right,
}

impl Side {
    /// +1 for left, -1 for right: the sign of a turn towards the object.
    fn sign(self) -> f64 {
        match self {
            Self::Left => 1.0,
            Self::Right => -1.0,
        }
    }

    /// Index of the side sensor (IR3 or IR6).
    pub fn sensor(self) -> usize {
        match self {
            Self::Left => 2,
            Self::Right => 5,
        }
    }
}

/// How the robot circles an object.
#[derive(Debug, Clone, Copy)]
pub struct CircleSettings {
    pub side: Side,
    /// Gap (m) kept between the robot's shell and the object: the side sensor's set point
    /// on a straight face (see [`CircleRoutine::side_setpoint_raw`]).
    pub gap: f64,
    /// Forward speed of the body centre while following, m/s.
    pub speed: f64,
    /// Below this gap (m) the robot no longer moves forward while its heading points closer
    /// to the nearest border point: it only turns, which never touches.
    pub min_gap: f64,
    /// Heading correction towards the object per metre of gap error, rad/m.
    pub gap_gain: f64,
    /// Largest heading correction the gap error may ask for, rad.
    pub max_correction: f64,
    /// Turn rate per radian of heading error, 1/s.
    pub heading_gain: f64,
    /// Fastest turn, rad/s.
    pub max_turn_rate: f64,
    /// Heading error (rad) at and above which the robot stops going forward and only turns;
    /// below it the forward speed falls linearly with the error.
    pub stop_heading_error: f64,
    /// The start turn (in place) ends when the heading error falls below this, rad.
    pub start_heading_error: f64,
    /// The lap closes at the closest return to the lap's start position within this
    /// distance (m), once the heading has turned a full turn less `close_heading`.
    pub close_radius: f64,
    /// Slack on the full turn of heading for the lap to close, rad.
    pub close_heading: f64,
    /// Give up after this long, seconds of simulated time.
    pub timeout: f64,
    /// Border points the routine keeps (preallocated); later ones are dropped and counted.
    pub capacity: usize,
}

impl Default for CircleSettings {
    fn default() -> Self {
        Self {
            side: Side::Left,
            gap: 0.010,
            min_gap: 0.004,
            speed: 0.06,
            gap_gain: 60.0,
            max_correction: 50f64.to_radians(),
            heading_gain: 8.0,
            max_turn_rate: 3.0,
            stop_heading_error: 70f64.to_radians(),
            start_heading_error: 15f64.to_radians(),
            close_radius: 0.02,
            close_heading: 20f64.to_radians(),
            timeout: 40.0,
            capacity: 8192,
        }
    }
}

/// How a circling ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CircleOutcome {
    /// One lap closed: odometry back near the lap's start after a full turn of heading.
    Closed,
    /// The timeout passed first.
    Timeout,
    /// Nothing was seen at the start: no object to circle.
    Lost,
}

/// Where a circling stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CirclePhase {
    /// Turning in place to put the object on the chosen side.
    Turn { since: f64 },
    /// Following the contour; the lap started at `since`.
    Follow { since: f64 },
    Done { outcome: CircleOutcome, at: f64 },
}

/// The paper's TurnAroundObjCompShape as a state machine fed one IR frame per control
/// step: from a start near the object (facing it, e.g. after an approach), turn to put it
/// on one side, follow its contour once round, and collect the border points the IR
/// readings imply, in the odometry frame.
///
/// # The controller
/// Every reading within the usable range ([`agp_world::border_range`], 40 mm) gives a
/// border point (mount + inverted distance along the ray, moved by the odometry pose);
/// the points are kept for the lap. The controller steers by the point nearest to the
/// body centre, of all points seen so far: it keeps that point's gap to the shell at
/// `gap`, heading along the tangent (perpendicular to the centre-to-point line, object on
/// the chosen side) corrected towards the object when the gap grows and away when it
/// shrinks. On a straight face the nearest point is the side sensor's (IR3 or IR6), so
/// this is the wall follower that holds the side reading at its set point; at an outer
/// corner the side ray loses the face and the remembered corner becomes the pivot the
/// robot turns round; at an inner corner (the L's) the points the front sensors (±17,
/// ±45 deg) put on the face ahead become the nearest before the body gets there, and
/// the robot stops going forward and turns away until it runs along the new face. The
/// body is a disc round the wheel axle's centre, so turning in place never touches.
///
/// Commands are computed once per IR sample (`ir_sample` changes) and held in between.
#[derive(Debug, Clone)]
pub struct CircleRoutine {
    settings: CircleSettings,
    robot: RobotDescription,
    range: f64,
    phase: CirclePhase,
    started: f64,
    points: Vec<DVec2>,
    dropped: usize,
    last_sample: Option<u64>,
    command: (f64, f64),
    last_theta: f64,
    turned: f64,
    lap_start: DVec2,
    closest: f64,
}

impl CircleRoutine {
    /// A routine starting at time `now`. Allocates the point buffer here, never later.
    pub fn new(settings: CircleSettings, robot: &RobotDescription, now: f64) -> Self {
        Self {
            settings,
            robot: robot.clone(),
            range: border_range(robot),
            phase: CirclePhase::Turn { since: now },
            started: now,
            points: Vec::with_capacity(settings.capacity),
            dropped: 0,
            last_sample: None,
            command: (0.0, 0.0),
            last_theta: 0.0,
            turned: 0.0,
            lap_start: DVec2::ZERO,
            closest: f64::INFINITY,
        }
    }

    pub fn phase(&self) -> CirclePhase {
        self.phase
    }

    pub fn settings(&self) -> &CircleSettings {
        &self.settings
    }

    /// Border points collected so far, odometry frame, metres.
    pub fn border_points(&self) -> &[DVec2] {
        &self.points
    }

    /// Points that did not fit in the buffer.
    pub fn dropped_points(&self) -> usize {
        self.dropped
    }

    /// Heading turned since the lap started, towards the object's side, rad.
    pub fn turned(&self) -> f64 {
        self.turned
    }

    /// Largest distance (m) from a sensor at which a reading gives a border point.
    pub fn border_range(&self) -> f64 {
        self.range
    }

    /// The side sensor's reading at the set gap, on a face parallel to the heading: the
    /// wall follower's set point in raw units.
    pub fn side_setpoint_raw(&self) -> f64 {
        let s = &self.robot.ir_sensors[self.settings.side.sensor()];
        // Length of the ray inside the body: from the mount to the shell.
        let (m, d) = (s.mount, s.direction());
        let md = m.dot(d);
        let r = self.robot.body_radius;
        let inner = -md + (md * md - m.length_squared() + r * r).max(0.0).sqrt();
        self.robot.response.reading(inner + self.settings.gap)
    }

    /// Wheel speeds (left, right, m/s) for this step, given the frame's time, its IR
    /// sample count, the odometry pose and the raw IR readings.
    pub fn update(&mut self, now: f64, ir_sample: u64, odometry: Pose, ir_raw: &[f32; 8]) -> (f64, f64) {
        if let CirclePhase::Done { .. } = self.phase {
            return (0.0, 0.0);
        }
        if now - self.started > self.settings.timeout {
            return self.finish(CircleOutcome::Timeout, now);
        }
        if self.last_sample == Some(ir_sample) {
            return self.command;
        }
        let first = self.last_sample.is_none();
        self.last_sample = Some(ir_sample);
        if !first && let CirclePhase::Follow { .. } = self.phase {
            self.turned += self.settings.side.sign() * wrap_angle(odometry.theta - self.last_theta);
        }
        self.last_theta = odometry.theta;
        self.collect(odometry, ir_raw);

        let pos = odometry.position();
        let Some(nearest) = self.nearest(pos) else {
            // Nothing seen yet: look round in place for a turn, then give up.
            let search_time = TAU / self.settings.max_turn_rate;
            if now - self.started > search_time {
                return self.finish(CircleOutcome::Lost, now);
            }
            return self.drive(0.0, -self.settings.side.sign() * self.settings.max_turn_rate);
        };

        let s = &self.settings;
        let side = s.side.sign();
        let away = pos - nearest;
        let rho = away.length();
        let gap = rho - self.robot.body_radius;
        // Tangent with the object on `side`: the outward normal turned a quarter towards
        // the direction of travel.
        let normal = if rho > 1e-9 { away / rho } else { DVec2::from_angle(odometry.theta + side * -FRAC_PI_2) };
        let tangent = DVec2::from_angle(side * FRAC_PI_2).rotate(normal);
        let correction = (s.gap_gain * (gap - s.gap)).clamp(-s.max_correction, s.max_correction);
        let desired = tangent.to_angle() + side * correction;
        let error = wrap_angle(desired - odometry.theta);
        let omega = (s.heading_gain * error).clamp(-s.max_turn_rate, s.max_turn_rate);

        match self.phase {
            CirclePhase::Turn { .. } => {
                if error.abs() < s.start_heading_error {
                    self.phase = CirclePhase::Follow { since: now };
                    self.lap_start = pos;
                    self.turned = 0.0;
                    self.closest = f64::INFINITY;
                } else {
                    return self.drive(0.0, omega);
                }
            }
            CirclePhase::Follow { .. } => {
                if self.turned >= TAU - s.close_heading {
                    let d = (pos - self.lap_start).length();
                    if d <= s.close_radius {
                        if d > self.closest {
                            return self.finish(CircleOutcome::Closed, now);
                        }
                        self.closest = d;
                    } else if self.closest.is_finite() || self.turned >= TAU + FRAC_PI_2 {
                        // Left the closing circle again, or far past a full turn.
                        return self.finish(CircleOutcome::Closed, now);
                    }
                }
            }
            CirclePhase::Done { .. } => return (0.0, 0.0),
        }
        let s = &self.settings;
        let closing = DVec2::from_angle(odometry.theta).dot(normal) < 0.0;
        let v = if gap < s.min_gap && closing {
            0.0
        } else {
            s.speed * (1.0 - error.abs() / s.stop_heading_error).clamp(0.0, 1.0)
        };
        self.drive(v, omega)
    }

    fn finish(&mut self, outcome: CircleOutcome, now: f64) -> (f64, f64) {
        self.phase = CirclePhase::Done { outcome, at: now };
        self.command = (0.0, 0.0);
        self.command
    }

    /// Wheel speeds for body speed `v` and turn rate `omega`, both scaled down together
    /// (keeping the curvature) when a wheel would pass its maximum.
    fn drive(&mut self, v: f64, omega: f64) -> (f64, f64) {
        let half = 0.5 * self.robot.axle_length;
        let (mut l, mut r) = (v - omega * half, v + omega * half);
        let m = l.abs().max(r.abs());
        if m > self.robot.max_wheel_speed {
            let k = self.robot.max_wheel_speed / m;
            l *= k;
            r *= k;
        }
        self.command = (l, r);
        self.command
    }

    fn collect(&mut self, odometry: Pose, ir_raw: &[f32; 8]) {
        for (i, &raw) in ir_raw.iter().enumerate() {
            if let Some(p) = ir_border_point(&self.robot, odometry, i, raw as f64, self.range) {
                if self.points.len() < self.points.capacity() {
                    self.points.push(p);
                } else {
                    self.dropped += 1;
                }
            }
        }
    }

    fn nearest(&self, pos: DVec2) -> Option<DVec2> {
        self.points
            .iter()
            .copied()
            .min_by(|a, b| a.distance_squared(pos).total_cmp(&b.distance_squared(pos)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn routine() -> CircleRoutine {
        CircleRoutine::new(CircleSettings::default(), &RobotDescription::epuck(), 0.0)
    }

    #[test]
    fn facing_a_wall_the_robot_first_turns_in_place_away_from_its_side() {
        let robot = RobotDescription::epuck();
        let mut r = routine();
        // A wall 10 mm ahead of the shell: x = 47 mm, seen by the two +-17 deg sensors.
        let mut raw = [0f32; 8];
        for i in [0, 7] {
            let s = &robot.ir_sensors[i];
            let t = (0.047 - s.mount.x) / s.direction().x;
            raw[i] = robot.response.reading(t) as f32;
        }
        let (l, rr) = r.update(0.0, 1, Pose::new(0.0, 0.0, 0.0), &raw);
        // Object kept on the left: turn right (clockwise) in place.
        assert!(l > 0.0 && rr < 0.0 && (l + rr).abs() < 1e-12, "{l} {rr}");
        assert!(matches!(r.phase(), CirclePhase::Turn { .. }));
        assert_eq!(r.border_points().len(), 2);
        for p in r.border_points() {
            assert!((p.x - 0.047).abs() < 1e-4, "{p}");
        }
    }

    #[test]
    fn a_held_frame_repeats_the_command_and_adds_no_points() {
        let robot = RobotDescription::epuck();
        let mut r = routine();
        let mut raw = [0f32; 8];
        raw[2] = robot.response.reading(0.016) as f32;
        let first = r.update(0.0, 5, Pose::new(0.0, 0.0, 0.0), &raw);
        let n = r.border_points().len();
        let again = r.update(0.01, 5, Pose::new(0.0, 0.0, 0.0), &raw);
        assert_eq!(first, again);
        assert_eq!(r.border_points().len(), n);
    }

    #[test]
    fn running_beside_a_wall_at_the_set_gap_goes_straight_ahead() {
        let robot = RobotDescription::epuck();
        let mut r = routine();
        // A wall on the left at the set gap from the shell, parallel to the heading.
        let wall_y = robot.body_radius + r.settings().gap;
        let mut raw = [0f32; 8];
        for (i, s) in robot.ir_sensors.iter().enumerate() {
            let d = s.direction();
            if d.y > 1e-9 {
                raw[i] = robot.response.reading((wall_y - s.mount.y) / d.y) as f32;
            }
        }
        assert!((raw[2] as f64 - r.side_setpoint_raw()).abs() < 0.01);
        let (l, rr) = r.update(0.0, 1, Pose::new(0.0, 0.0, 0.0), &raw);
        assert!(matches!(r.phase(), CirclePhase::Follow { .. }));
        assert!((l - rr).abs() < 1e-3 && l > 0.05, "{l} {rr}");
        // Farther from the wall: turn towards it (left); nearer: away from it.
        let shift = |dy: f64| {
            let mut r = routine();
            let pose = Pose::new(0.0, dy, 0.0);
            let mut raw = [0f32; 8];
            for (i, s) in robot.ir_sensors.iter().enumerate() {
                let d = s.direction();
                if d.y > 1e-9 {
                    raw[i] = robot.response.reading((wall_y - dy - s.mount.y) / d.y) as f32;
                }
            }
            r.update(0.0, 1, pose, &raw)
        };
        let (l, rr) = shift(-0.004);
        assert!(rr > l, "too far: turn left, got {l} {rr}");
        let (l, rr) = shift(0.004);
        assert!(rr < l, "too near: turn right, got {l} {rr}");
    }

    #[test]
    fn the_routine_stops_at_its_timeout() {
        let robot = RobotDescription::epuck();
        let settings = CircleSettings {
            timeout: 1.0,
            ..CircleSettings::default()
        };
        let mut r = CircleRoutine::new(settings, &robot, 10.0);
        let mut raw = [0f32; 8];
        raw[2] = robot.response.reading(0.016) as f32;
        let mut k = 0;
        while k < 200 && !matches!(r.phase(), CirclePhase::Done { .. }) {
            r.update(10.0 + k as f64 / 64.0, k, Pose::new(0.0, 0.0, 0.0), &raw);
            k += 1;
        }
        let CirclePhase::Done { outcome, at } = r.phase() else {
            panic!("still running: {:?}", r.phase());
        };
        assert_eq!(outcome, CircleOutcome::Timeout);
        assert!((at - 11.0).abs() <= 1.0 / 64.0 + 1e-12, "stopped at {at}");
        assert_eq!(r.update(12.0, 500, Pose::new(0.0, 0.0, 0.0), &raw), (0.0, 0.0));
    }

    #[test]
    fn with_nothing_in_sight_the_routine_looks_round_then_gives_up() {
        let mut r = routine();
        let mut t = 0.0;
        let mut k = 0;
        while !matches!(r.phase(), CirclePhase::Done { .. }) && t < 10.0 {
            r.update(t, k, Pose::new(0.0, 0.0, 0.0), &[0.0; 8]);
            k += 1;
            t += 1.0 / 64.0;
        }
        assert!(matches!(
            r.phase(),
            CirclePhase::Done {
                outcome: CircleOutcome::Lost,
                ..
            }
        ));
        assert!(t < 3.0, "gave up after {t} s");
    }
}
