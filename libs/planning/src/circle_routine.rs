use std::f64::consts::{FRAC_PI_2, TAU};

use agp_shared_types::angle::wrap_angle;
use agp_world::{BORDER_MAX_SIGMA, Pose, RobotDescription, ir_border_point, to_frame};
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
    /// Side-ray hits are traced over this much travel (m) to find the face's direction.
    pub trace_travel: f64,
    /// A trace shorter than this (m) means the side ray keeps hitting one spot while the
    /// robot moves: it is orbiting that spot, which may be a corner's tip or a point of a
    /// face that goes on unseen between the side ray and the 45 deg ray (the L's 30 mm
    /// end), so the orbit is widened to `orbit_curvature`.
    pub trace_min: f64,
    /// Sharpest curvature (1/m) of a turn towards the object while the side ray keeps
    /// hitting one spot. Must stay above the curvature of a round object's contour at the
    /// set gap (1 / 82 mm for the 35 mm disc).
    pub orbit_curvature: f64,
    /// How far (rad) the heading may turn towards the object past the traced face.
    pub face_margin: f64,
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
    /// distance (m), once the heading has turned a full turn less `close_heading`; past a
    /// full turn, at the closest return wherever it is.
    pub close_radius: f64,
    /// Slack on the full turn of heading for the lap to close, rad.
    pub close_heading: f64,
    /// Give up after this long, seconds of simulated time.
    pub timeout: f64,
    /// Largest standard deviation (m) of the distance a reading implies for it to give a
    /// border point; sets the border range through the response curve (1 mm: 40 mm from
    /// the E-puck's sensors, see [`agp_world::BORDER_MAX_SIGMA`]).
    pub max_sigma: f64,
    /// Border points the routine keeps (preallocated); later ones are dropped and counted.
    pub capacity: usize,
}

impl Default for CircleSettings {
    fn default() -> Self {
        Self {
            side: Side::Left,
            gap: 0.010,
            speed: 0.06,
            min_gap: 0.004,
            trace_travel: 0.012,
            trace_min: 0.003,
            orbit_curvature: 1.0 / 0.075,
            face_margin: 10f64.to_radians(),
            gap_gain: 60.0,
            max_correction: 50f64.to_radians(),
            heading_gain: 8.0,
            max_turn_rate: 3.0,
            stop_heading_error: 70f64.to_radians(),
            start_heading_error: 15f64.to_radians(),
            close_radius: 0.02,
            close_heading: 20f64.to_radians(),
            timeout: 40.0,
            max_sigma: BORDER_MAX_SIGMA,
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
    Turn {
        since: f64,
    },
    /// Following the contour; the lap started at `since`.
    Follow {
        since: f64,
    },
    Done {
        outcome: CircleOutcome,
        at: f64,
    },
}

/// The paper's TurnAroundObjCompShape as a state machine fed one IR frame per control
/// step: from a start near the object (facing it, e.g. after an approach), turn to put it
/// on one side, follow its contour once round, and collect the border points the IR
/// readings imply, in the odometry frame.
///
/// # The controller
/// Every reading within the border range (`max_sigma`, 1 mm by default: 40 mm from the
/// sensor, see [`agp_world::BORDER_MAX_SIGMA`]) gives a border point: mount + inverted
/// distance along the ray, moved by the odometry pose. Readings beyond it, up to the end
/// of the response curve (70 mm), are too noisy for the shape but are kept for steering.
/// The controller steers by the point nearest to the body centre of all points seen so
/// far: it keeps that point's gap to the shell at `gap`, heading along the tangent
/// (perpendicular to the centre-to-point line, object on the chosen side), corrected
/// towards the object when the gap grows and away when it shrinks. So:
/// - on a straight face the nearest point is the side sensor's (IR3 or IR6): this is the
///   wall follower holding the side reading at its set point;
/// - at an outer corner the side ray passes the tip and sees nothing, and the remembered
///   corner becomes the pivot the robot turns round;
/// - at an inner corner (the L's) the points the front sensors (±17, ±45 deg) put on the
///   face ahead become the nearest before the body gets there: the robot stops going
///   forward, turns away (in place: the body is a disc round the axle's centre, so turning
///   never touches) and runs along the new face.
///
/// Two guards cover what no ray sees between the ±45 and ±90 deg rays. While the side ray
/// hits a face, its hits over the last `trace_travel` of travel trace the face's
/// direction, and the heading may not turn towards the object more than `face_margin`
/// past it. When those hits stay on one spot while the robot moves, the robot is orbiting
/// that spot, which is a corner's tip or a point of a face going on unseen (the L's 30 mm
/// end): the orbit is widened to `orbit_curvature` at full speed, so the side ray slides
/// along whatever is there.
///
/// Commands are computed once per IR sample (`ir_sample` changes) and held in between.
#[derive(Debug, Clone)]
pub struct CircleRoutine {
    settings: CircleSettings,
    robot: RobotDescription,
    range: f64,
    points: Vec<DVec2>,
    /// Readings beyond the border range: for steering only.
    far: Vec<DVec2>,
    lap: Lap,
}

/// Where one circling stands: all of it starts over with [`CircleRoutine::restart`].
#[derive(Debug, Clone)]
struct Lap {
    phase: CirclePhase,
    started: f64,
    dropped: usize,
    last_sample: Option<u64>,
    command: (f64, f64),
    last_theta: f64,
    turned: f64,
    lap_start: DVec2,
    closest: f64,
    /// Odometry path length so far, m, and the position it was last measured at.
    travel: f64,
    last_pos: DVec2,
    /// The side ray's recent hits (odometry frame) with the travel they were seen at; a
    /// sample where the side ray sees nothing empties it.
    side_hits: [(DVec2, f64); SIDE_HITS],
    side_hit_count: usize,
    side_hit_next: usize,
}

impl Lap {
    fn new(now: f64) -> Self {
        Self {
            phase: CirclePhase::Turn { since: now },
            started: now,
            dropped: 0,
            last_sample: None,
            command: (0.0, 0.0),
            last_theta: 0.0,
            turned: 0.0,
            lap_start: DVec2::ZERO,
            closest: f64::INFINITY,
            travel: 0.0,
            last_pos: DVec2::ZERO,
            side_hits: [(DVec2::ZERO, 0.0); SIDE_HITS],
            side_hit_count: 0,
            side_hit_next: 0,
        }
    }
}

/// How much farther than its closest (m) the robot must be from the lap's start for the
/// lap to count as past it: above odometry's jitter between two samples.
const CLOSE_HYSTERESIS: f64 = 0.0005;

/// What the side ray's recent hits say about the surface beside the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
enum FaceTrace {
    /// The hits run along a face in this direction (rad, odometry frame).
    Along(f64),
    /// The hits stay on one spot while the robot moves round it.
    Orbiting,
}

/// Side-ray hits kept for tracing a face (over a second at the IR rate).
const SIDE_HITS: usize = 96;

impl CircleRoutine {
    /// A routine starting at time `now`. Allocates the point buffer here, never later.
    pub fn new(settings: CircleSettings, robot: &RobotDescription, now: f64) -> Self {
        Self {
            settings,
            robot: robot.clone(),
            range: robot.response.usable_range(settings.max_sigma),
            points: Vec::with_capacity(settings.capacity),
            far: Vec::with_capacity(settings.capacity),
            lap: Lap::new(now),
        }
    }

    /// Starts over at time `now`, as [`CircleRoutine::new`] would, keeping the robot and
    /// the point buffers: a planner that circles once a trial allocates nothing for it.
    pub fn restart(&mut self, now: f64) {
        self.points.clear();
        self.far.clear();
        self.lap = Lap::new(now);
    }

    pub fn phase(&self) -> CirclePhase {
        self.lap.phase
    }

    pub fn settings(&self) -> &CircleSettings {
        &self.settings
    }

    /// Border points collected so far, odometry frame, metres.
    pub fn border_points(&self) -> &[DVec2] {
        &self.points
    }

    /// Points (border or steering) that did not fit in their buffers.
    pub fn dropped_points(&self) -> usize {
        self.lap.dropped
    }

    /// Heading turned since the lap started, towards the object's side, rad.
    pub fn turned(&self) -> f64 {
        self.lap.turned
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
    pub fn update(
        &mut self,
        now: f64,
        ir_sample: u64,
        odometry: Pose,
        ir_raw: &[f32; 8],
    ) -> (f64, f64) {
        if let CirclePhase::Done { .. } = self.lap.phase {
            return (0.0, 0.0);
        }
        if now - self.lap.started > self.settings.timeout {
            return self.finish(CircleOutcome::Timeout, now);
        }
        if self.lap.last_sample == Some(ir_sample) {
            return self.lap.command;
        }
        let first = self.lap.last_sample.is_none();
        self.lap.last_sample = Some(ir_sample);
        if !first && let CirclePhase::Follow { .. } = self.lap.phase {
            self.lap.turned +=
                self.settings.side.sign() * wrap_angle(odometry.theta - self.lap.last_theta);
        }
        self.lap.last_theta = odometry.theta;
        if !first {
            self.lap.travel += (odometry.position() - self.lap.last_pos).length();
        }
        self.lap.last_pos = odometry.position();
        self.collect(odometry, ir_raw);
        let face = self.face_direction(odometry, ir_raw);

        let pos = odometry.position();
        let Some(nearest) = self.nearest(pos) else {
            // Nothing seen yet: look round in place for a turn, then give up.
            let search_time = TAU / self.settings.max_turn_rate;
            if now - self.lap.started > search_time {
                return self.finish(CircleOutcome::Lost, now);
            }
            return self.drive(
                0.0,
                -self.settings.side.sign() * self.settings.max_turn_rate,
            );
        };

        let s = &self.settings;
        let side = s.side.sign();
        let away = pos - nearest;
        let rho = away.length();
        let gap = rho - self.robot.body_radius;
        // Tangent with the object on `side`: the outward normal turned a quarter towards
        // the direction of travel.
        let normal = if rho > 1e-9 {
            away / rho
        } else {
            DVec2::from_angle(odometry.theta + side * -FRAC_PI_2)
        };
        let tangent = DVec2::from_angle(side * FRAC_PI_2).rotate(normal);
        let correction = (s.gap_gain * (gap - s.gap)).clamp(-s.max_correction, s.max_correction);
        let mut desired = tangent.to_angle() + side * correction;
        if let Some(FaceTrace::Along(face)) = face {
            let over = side * wrap_angle(desired - face) - s.face_margin;
            if over > 0.0 {
                desired -= side * over;
            }
        }
        let error = wrap_angle(desired - odometry.theta);
        let omega = (s.heading_gain * error).clamp(-s.max_turn_rate, s.max_turn_rate);

        match self.lap.phase {
            CirclePhase::Turn { .. } => {
                if error.abs() < s.start_heading_error {
                    self.lap.phase = CirclePhase::Follow { since: now };
                    self.lap.lap_start = pos;
                    self.lap.turned = 0.0;
                    self.lap.closest = f64::INFINITY;
                } else {
                    return self.drive(0.0, omega);
                }
            }
            CirclePhase::Follow { .. } => {
                if self.lap.turned >= TAU - s.close_heading {
                    // Close at the closest return to the lap's start: within `close_radius`
                    // once nearly a full turn is done, or wherever it is once the full
                    // turn is done (a start deep in an inner corner is off the path).
                    let d = (pos - self.lap.lap_start).length();
                    self.lap.closest = self.lap.closest.min(d);
                    let receding = d > self.lap.closest + CLOSE_HYSTERESIS;
                    let near = self.lap.closest <= s.close_radius;
                    if (receding && (near || self.lap.turned >= TAU))
                        || self.lap.turned >= TAU + FRAC_PI_2
                    {
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
        let (v, omega) =
            if face == Some(FaceTrace::Orbiting) && side * omega > v * s.orbit_curvature {
                // Widen the orbit at full speed, so the side ray slides along what it hits.
                let v = if gap < s.min_gap && closing {
                    0.0
                } else {
                    s.speed
                };
                let limit = v.max(0.25 * s.speed) * s.orbit_curvature;
                (v, side * (side * omega).min(limit))
            } else {
                (v, omega)
            };
        self.drive(v, omega)
    }

    fn finish(&mut self, outcome: CircleOutcome, now: f64) -> (f64, f64) {
        self.lap.phase = CirclePhase::Done { outcome, at: now };
        self.lap.command = (0.0, 0.0);
        self.lap.command
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
        self.lap.command = (l, r);
        self.lap.command
    }

    /// Readings within the border range become border points; farther ones (to the end
    /// of the curve) are too noisy for the shape but still steer: they show a face or a
    /// corner ahead before it comes within the border range.
    fn collect(&mut self, odometry: Pose, ir_raw: &[f32; 8]) {
        let max_range = self.robot.response.max_range();
        for (i, &raw) in ir_raw.iter().enumerate() {
            let Some(p) = ir_border_point(&self.robot, odometry, i, raw as f64, max_range) else {
                continue;
            };
            let sensor_distance = (p - to_frame(odometry, self.robot.ir_sensors[i].mount)).length();
            let buffer = if sensor_distance <= self.range {
                &mut self.points
            } else {
                &mut self.far
            };
            if buffer.len() < buffer.capacity() {
                buffer.push(p);
            } else {
                self.lap.dropped += 1;
            }
        }
    }

    /// Records this sample's side-ray hit and traces the face it is on, from the hit
    /// `trace_travel` of travel ago to this one. `None` when the side ray sees nothing now
    /// or has not traced long enough.
    fn face_direction(&mut self, odometry: Pose, ir_raw: &[f32; 8]) -> Option<FaceTrace> {
        let sensor = self.settings.side.sensor();
        let Some(hit) = ir_border_point(
            &self.robot,
            odometry,
            sensor,
            ir_raw[sensor] as f64,
            self.range,
        ) else {
            self.lap.side_hit_count = 0;
            return None;
        };
        self.lap.side_hits[self.lap.side_hit_next] = (hit, self.lap.travel);
        self.lap.side_hit_next = (self.lap.side_hit_next + 1) % SIDE_HITS;
        self.lap.side_hit_count = (self.lap.side_hit_count + 1).min(SIDE_HITS);
        let old = (1..self.lap.side_hit_count)
            .map(|k| self.lap.side_hits[(self.lap.side_hit_next + SIDE_HITS - 1 - k) % SIDE_HITS])
            .find(|&(_, t)| self.lap.travel - t >= self.settings.trace_travel)?;
        let trace = hit - old.0;
        let heading = DVec2::from_angle(odometry.theta);
        if trace.length() < self.settings.trace_min || trace.dot(heading) <= 0.0 {
            Some(FaceTrace::Orbiting)
        } else {
            Some(FaceTrace::Along(trace.to_angle()))
        }
    }

    fn nearest(&self, pos: DVec2) -> Option<DVec2> {
        self.points
            .iter()
            .chain(&self.far)
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
    fn a_side_ray_that_keeps_hitting_one_spot_widens_the_orbit_round_it() {
        let robot = RobotDescription::epuck();
        let mut r = routine();
        let s = *r.settings();
        // The robot runs a 50 mm circle counter-clockwise round a spot at the origin, IR3
        // looking straight at it: the readings never change while the robot moves on.
        let radius = 0.050;
        let mut raw = [0f32; 8];
        raw[2] = robot.response.reading(radius - 0.031) as f32;
        let step = s.speed / robot.ir_rate_hz;
        let mut last = (0.0, 0.0);
        for k in 0..40u64 {
            let phi = -FRAC_PI_2 + k as f64 * step / radius;
            let pose = Pose::new(radius * phi.cos(), radius * phi.sin(), phi + FRAC_PI_2);
            last = r.update(k as f64 / robot.ir_rate_hz, k, pose, &raw);
        }
        let (l, rr) = last;
        let v = 0.5 * (l + rr);
        let curvature = (rr - l) / robot.axle_length / v;
        // An orbit at 50 mm has curvature 20 /m; once 12 mm are traced the routine holds
        // to the widened orbit (13.3 /m) at full speed.
        assert!((v - s.speed).abs() < 1e-9, "speed {v}");
        assert!(
            curvature <= s.orbit_curvature + 1e-9,
            "curvature {curvature} /m"
        );
        assert!(
            curvature > 0.0,
            "still turning towards the object: {curvature} /m"
        );
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
        assert_eq!(
            r.update(12.0, 500, Pose::new(0.0, 0.0, 0.0), &raw),
            (0.0, 0.0)
        );
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
