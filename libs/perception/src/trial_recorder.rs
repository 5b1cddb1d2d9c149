use agp_affordance::{MatchedPose, PushOutcome, ShapeMatchError, ShapeMatcher};
use agp_shared_types::angle;
use agp_shared_types::angle::wrap_angle;
use agp_world::{Pose, RobotDescription, border_range, ir_border_point, ir_point_robot, to_frame};
use glam::DVec2;

use crate::{ContactEstimates, ContactEstimator, ContactMethod, IrView, LearnedShape};

/// Most IR samples whose border points the push tracker matches together (125 ms).
const TRACK_WINDOW: usize = 8;
/// The tracker takes samples, newest first, until it holds this many points, and matches
/// only then: fewer points (a corner pointing at the robot, seen by one or two rays) leave
/// the orientation loose.
const TRACK_POINTS: usize = 12;
/// A tracker update that turns the object by more than this fraction of the symmetry
/// period (at most [`TRACK_MAX_TURN`]) is refused: it may have jumped to a symmetric match.
const TRACK_MAX_TURN_PERIOD: f64 = 1.0 / 3.0;
/// Largest turn of one tracker update, rad (45 deg).
const TRACK_MAX_TURN: f64 = std::f64::consts::FRAC_PI_4;
/// A tracker update that moves the object by more than this (m) is refused.
const TRACK_MAX_SHIFT: f64 = 0.03;
/// A tracker update with fewer inliers than this fraction is refused.
const TRACK_MIN_INLIERS: f64 = 0.6;

/// Where a learning trial stands, as the estimator sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrialPhase {
    /// Nothing under way.
    Idle,
    /// Circling the object at a known pose to learn its shape: border points collected.
    ShapeCircling,
    /// The robot approaches the object at its known start pose: the front sensors' border
    /// points are collected (the paper's Algorithm 1).
    Approach,
    /// Contact was inferred and the robot pushes: the object moves; what the sensors see
    /// of it tracks its orientation relative to the robot (see
    /// [`TrialRecorder::finish_trial`]).
    Push,
    /// After the push the robot circles the object: border points collected for the pose.
    Circling,
}

/// A call that does not fit the trial's phase (a programming error of the caller).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("`{call}` is not allowed while the trial is in phase {phase:?}")]
pub struct TrialOrderError {
    /// The method called.
    pub call: &'static str,
    /// The phase the trial was in.
    pub phase: TrialPhase,
}

/// Why a trial gave no usable push.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrialFinishError {
    /// The call came in the wrong phase.
    #[error(transparent)]
    Order(#[from] TrialOrderError),
    /// The circling's border points could not be matched to the learned shape.
    #[error("the circling could not be matched to the learned shape: {0}")]
    Match(#[from] ShapeMatchError),
    /// The match leaves too many points off the learned border to be trusted.
    #[error(
        "only {:.0} % of the circling's points lie on the learned border (rms {:.2} mm)",
        inlier_fraction * 100.0,
        rms_error_m * 1e3
    )]
    PoorMatch {
        /// Fraction of the points within the matcher's inlier distance.
        inlier_fraction: f64,
        /// Their root mean square distance to the border, metres.
        rms_error_m: f64,
    },
    /// The configured contact method found no contact point.
    #[error("no contact point by method `{}`", method.name())]
    NoContact {
        /// The method.
        method: ContactMethod,
    },
}

/// What one learning trial measured, all from IR and odometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialRecord {
    /// The push direction's deviation from the centroid, degrees.
    pub alpha_deg: f64,
    /// The object's known pose before the push, odometry frame.
    pub object_before: Pose,
    /// The object's pose after the push estimated from the circling, odometry frame, its
    /// orientation resolved among the symmetric matches (see
    /// [`TrialRecorder::finish_trial`]).
    pub object_after: Pose,
    /// The contact point by every method, object frame.
    pub contact: ContactEstimates,
    /// The push's effect with the contact point of the configured method: what the
    /// gradient learns.
    pub outcome: PushOutcome,
    /// The best match of the circling's points to the learned shape, as the matcher gave
    /// it (orientation modulo the symmetry).
    pub matched: MatchedPose,
    /// The best distinct other match, if any.
    pub runner_up: Option<MatchedPose>,
    /// Border points the circling collected.
    pub circle_points: usize,
    /// Border points the front sensors saw during the approach (object frame).
    pub approach_points: usize,
    /// The object's orientation at the end of the push by tracking during the push,
    /// odometry frame, rad (continuous: not reduced modulo the symmetry).
    pub tracked_orientation_rad: f64,
    /// Tracker updates accepted during the push.
    pub track_updates: usize,
}

/// The object's pose relative to the robot during a push, followed by matching what the
/// sensors see of it to the learned shape sample by sample: each match is absolute (no
/// drift), and continuity keeps the orientation on the right one of the symmetric
/// matches. Fixed-size buffers: allocates nothing.
#[derive(Debug, Clone)]
struct PushTracker {
    /// Border points of the last samples, robot frame, `None` where a sensor saw nothing.
    window: [[Option<DVec2>; 8]; TRACK_WINDOW],
    next: usize,
    scratch: [DVec2; 8 * TRACK_WINDOW],
    /// The object's centroid and orientation in the robot frame (continuous).
    position: DVec2,
    orientation: f64,
    updates: usize,
}

impl PushTracker {
    fn new() -> Self {
        Self {
            window: [[None; 8]; TRACK_WINDOW],
            next: 0,
            scratch: [DVec2::ZERO; 8 * TRACK_WINDOW],
            position: DVec2::ZERO,
            orientation: 0.0,
            updates: 0,
        }
    }

    /// Starts from the object's pose in the frame of the robot at `robot` (both odometry).
    fn start(&mut self, robot: Pose, object: Pose) {
        let rel = ContactEstimator::robot_in_object_frame(object, robot);
        self.window = [[None; 8]; TRACK_WINDOW];
        self.next = 0;
        self.position = rel.position();
        self.orientation = rel.theta;
        self.updates = 0;
    }

    fn update(
        &mut self,
        robot: &RobotDescription,
        range: f64,
        view: &IrView,
        matcher: &mut ShapeMatcher,
    ) {
        let slot = &mut self.window[self.next];
        for (i, p) in slot.iter_mut().enumerate() {
            *p = ir_point_robot(robot, i, f64::from(view.ir_raw[i]), range);
        }
        // Newest samples first, until enough points: a face seen by four sensors needs
        // three samples, a corner pointing at the robot (one or two rays on it) more.
        let mut n = 0;
        for age in 0..TRACK_WINDOW {
            let k = (self.next + TRACK_WINDOW - age) % TRACK_WINDOW;
            for p in self.window[k].iter().flatten() {
                self.scratch[n] = *p;
                n += 1;
            }
            if n >= TRACK_POINTS {
                break;
            }
        }
        self.next = (self.next + 1) % TRACK_WINDOW;
        if n < TRACK_POINTS {
            return;
        }
        let Ok(m) = matcher.refine(&self.scratch[..n], self.position, self.orientation) else {
            return;
        };
        let period = matcher.symmetry_period_rad();
        // The matcher reports the orientation modulo the symmetry: the representative
        // nearest the last one.
        let turn = angle::wrap_to_half_period_floor(m.orientation_rad - self.orientation, period);
        if m.inlier_fraction < TRACK_MIN_INLIERS
            || turn.abs() > TRACK_MAX_TURN.min(TRACK_MAX_TURN_PERIOD * period)
            || m.position.distance(self.position) > TRACK_MAX_SHIFT
        {
            return;
        }
        self.orientation += turn;
        self.position = m.position;
        self.updates += 1;
    }
}

/// The estimator's side of one learning trial, fed one IR frame per control step.
///
/// The learning phase puts the object back at a known pose (in the odometry frame: right
/// after a reset, odometry starts at the robot's placed pose) before each trial, so
/// whatever the IR sees before the push is known in the object's frame. A trial:
/// [`begin_trial`](Self::begin_trial) (approach: the front sensors' border points are kept
/// in the object frame), [`infer_contact`](Self::infer_contact) when the planner infers
/// contact (the contact point by every [`ContactMethod`]), [`end_push`](Self::end_push)
/// when the push is over (the circling's border points are collected from here, odometry
/// frame), and [`finish_trial`](Self::finish_trial): the object's new pose by matching the
/// circling to the learned shape, and the push's [`PushOutcome`].
///
/// The shape itself comes from a circling at the known pose:
/// [`begin_shape_circling`](Self::begin_shape_circling), then
/// [`circle_points`](Self::circle_points).
///
/// Buffers are allocated in [`TrialRecorder::new`]; [`observe`](Self::observe) allocates
/// nothing (points past the capacity are dropped and counted).
#[derive(Debug, Clone)]
pub struct TrialRecorder {
    robot: RobotDescription,
    range: f64,
    front: [usize; 4],
    contact_estimator: ContactEstimator,
    phase: TrialPhase,
    last_sample: Option<u64>,
    alpha_deg: f64,
    object_start: Pose,
    approach_points: Vec<DVec2>,
    circle_points: Vec<DVec2>,
    dropped: usize,
    contact: Option<ContactEstimates>,
    push_end: Option<Pose>,
    tracker: PushTracker,
}

impl TrialRecorder {
    /// A recorder for `robot` keeping up to `capacity` border points per buffer (a lap of
    /// an E-puck round a 100 mm object gives about a thousand).
    pub fn new(robot: &RobotDescription, capacity: usize) -> Self {
        Self {
            robot: robot.clone(),
            range: border_range(robot),
            front: robot.front_sensors(),
            contact_estimator: ContactEstimator::new(robot),
            phase: TrialPhase::Idle,
            last_sample: None,
            alpha_deg: 0.0,
            object_start: Pose::default(),
            approach_points: Vec::with_capacity(capacity),
            circle_points: Vec::with_capacity(capacity),
            dropped: 0,
            contact: None,
            push_end: None,
            tracker: PushTracker::new(),
        }
    }

    /// Where the trial stands.
    pub fn phase(&self) -> TrialPhase {
        self.phase
    }

    /// The current trial's alpha, degrees.
    pub fn alpha_deg(&self) -> f64 {
        self.alpha_deg
    }

    /// The object's known pose at the start of the current trial or shape circling,
    /// odometry frame.
    pub fn object_start(&self) -> Pose {
        self.object_start
    }

    /// Border points of the current (or last) circling, odometry frame, metres.
    pub fn circle_points(&self) -> &[DVec2] {
        &self.circle_points
    }

    /// Border points the front sensors saw during the current (or last) approach, object
    /// frame, metres.
    pub fn approach_points(&self) -> &[DVec2] {
        &self.approach_points
    }

    /// Points dropped because a buffer was full, since the last trial began.
    pub fn dropped_points(&self) -> usize {
        self.dropped
    }

    /// The contact estimates of the current trial, once inferred.
    pub fn contact(&self) -> Option<&ContactEstimates> {
        self.contact.as_ref()
    }

    /// Starts a circling of the object resting at the known `object_pose` (odometry frame),
    /// to learn its shape. Allowed in any phase (it abandons a trial under way).
    pub fn begin_shape_circling(&mut self, object_pose: Pose) {
        self.reset(TrialPhase::ShapeCircling, 0.0, object_pose);
    }

    /// Starts a trial at `alpha_deg` with the object resting at the known `object_pose`
    /// (odometry frame). Allowed in any phase (it abandons a trial under way).
    pub fn begin_trial(&mut self, alpha_deg: f64, object_pose: Pose) {
        self.reset(TrialPhase::Approach, alpha_deg, object_pose);
    }

    /// Abandons whatever is under way (e.g. the approach found nothing).
    pub fn abandon(&mut self) {
        self.phase = TrialPhase::Idle;
    }

    fn reset(&mut self, phase: TrialPhase, alpha_deg: f64, object_pose: Pose) {
        self.phase = phase;
        self.alpha_deg = alpha_deg;
        self.object_start = object_pose;
        self.last_sample = None;
        self.approach_points.clear();
        self.circle_points.clear();
        self.dropped = 0;
        self.contact = None;
        self.push_end = None;
    }

    /// Takes one frame: on a fresh IR sample, collects the border points the phase wants;
    /// during the push, tracks the object against `matcher` (the learned shape; without
    /// it, nothing is tracked). Allocates nothing.
    pub fn observe(&mut self, view: &IrView, matcher: Option<&mut ShapeMatcher>) {
        if self.last_sample == Some(view.ir_sample) {
            return;
        }
        self.last_sample = Some(view.ir_sample);
        match self.phase {
            TrialPhase::ShapeCircling | TrialPhase::Circling => {
                for i in 0..view.ir_raw.len() {
                    let raw = f64::from(view.ir_raw[i]);
                    if let Some(p) = ir_border_point(&self.robot, view.odometry, i, raw, self.range)
                    {
                        push_bounded(&mut self.circle_points, &mut self.dropped, p);
                    }
                }
            }
            TrialPhase::Approach => {
                let robot_obj =
                    ContactEstimator::robot_in_object_frame(view.odometry, self.object_start);
                for &i in &self.front {
                    let raw = f64::from(view.ir_raw[i]);
                    if let Some(p) = ir_border_point(&self.robot, robot_obj, i, raw, self.range) {
                        push_bounded(&mut self.approach_points, &mut self.dropped, p);
                    }
                }
            }
            TrialPhase::Push => {
                if let Some(m) = matcher {
                    self.tracker.update(&self.robot, self.range, view, m);
                }
            }
            TrialPhase::Idle => {}
        }
    }

    /// Contact was inferred (by the planner, from IR) at frame `view`: estimates the
    /// contact point by every method against the learned shape, and moves on to the push.
    pub fn infer_contact(
        &mut self,
        view: &IrView,
        learned: LearnedShape<'_>,
    ) -> Result<ContactEstimates, TrialOrderError> {
        self.expect(TrialPhase::Approach, "infer_contact")?;
        self.observe(view, None);
        let e = self.contact_estimator.estimate(
            view.odometry,
            &view.ir_raw,
            self.object_start,
            learned,
        );
        self.contact = Some(e);
        self.tracker.start(view.odometry, self.object_start);
        self.phase = TrialPhase::Push;
        // The contact frame's sample is the push's first.
        self.last_sample = None;
        Ok(e)
    }

    /// The push is over at frame `view` (the robot stopped): the circling starts.
    pub fn end_push(&mut self, view: &IrView) -> Result<(), TrialOrderError> {
        self.expect(TrialPhase::Push, "end_push")?;
        self.push_end = Some(view.odometry);
        self.phase = TrialPhase::Circling;
        self.last_sample = None;
        self.circle_points.clear();
        Ok(())
    }

    /// Ends the shape circling: its points are in [`circle_points`](Self::circle_points).
    pub fn end_shape_circling(&mut self) -> Result<(), TrialOrderError> {
        self.expect(TrialPhase::ShapeCircling, "end_shape_circling")?;
        self.phase = TrialPhase::Idle;
        Ok(())
    }

    /// Ends the trial: matches the circling's points to the learned shape, resolves the
    /// orientation among the symmetric matches, and returns the push's effect with the
    /// contact point of `method`. The recorder goes idle whatever the result.
    ///
    /// # Symmetric objects
    /// A circling tells the orientation of a square only modulo 90 deg (a triangle: 120
    /// deg), while a push may turn it further. During the push the recorder tracks the
    /// object's pose relative to the robot by matching what the sensors see to the
    /// learned shape each sample, starting from the known pose; of the circling's
    /// symmetric orientations the one nearest the tracked one is kept. (Without any
    /// accepted tracker update, the nearest to the start: the smallest rotation.)
    pub fn finish_trial(
        &mut self,
        matcher: &mut ShapeMatcher,
        method: ContactMethod,
        min_inlier_fraction: f64,
    ) -> Result<TrialRecord, TrialFinishError> {
        self.expect(TrialPhase::Circling, "finish_trial")?;
        self.phase = TrialPhase::Idle;
        let (Some(contact), Some(push_end)) = (self.contact, self.push_end) else {
            return Err(TrialOrderError {
                call: "finish_trial",
                phase: TrialPhase::Circling,
            }
            .into());
        };
        let contact_obj = contact
            .get(method)
            .ok_or(TrialFinishError::NoContact { method })?;
        let m = matcher.match_points(&self.circle_points)?;
        if m.best.inlier_fraction < min_inlier_fraction {
            return Err(TrialFinishError::PoorMatch {
                inlier_fraction: m.best.inlier_fraction,
                rms_error_m: m.best.rms_error_m,
            });
        }
        let before = self.object_start;
        let tracked = push_end.theta + self.tracker.orientation;
        let theta = match matcher.config().symmetry_order {
            // A disc: the orientation cannot be seen; report none.
            0 => before.theta,
            1 => m.best.orientation_rad,
            _ => {
                let period = matcher.symmetry_period_rad();
                tracked + angle::wrap_to_half_period_floor(m.best.orientation_rad - tracked, period)
            }
        };
        let after = Pose::new(m.best.position.x, m.best.position.y, theta);
        let to_obj = DVec2::from_angle(-before.theta);
        let outcome = PushOutcome {
            contact_point_obj: contact_obj,
            displacement_obj: to_obj.rotate(after.position() - before.position()),
            rotation_rad: wrap_angle(after.theta - before.theta),
            heading_obj: DVec2::from_angle(contact.robot_obj.theta),
        };
        Ok(TrialRecord {
            alpha_deg: self.alpha_deg,
            object_before: before,
            object_after: after,
            contact,
            outcome,
            matched: m.best,
            runner_up: m.runner_up,
            circle_points: self.circle_points.len(),
            approach_points: self.approach_points.len(),
            tracked_orientation_rad: tracked,
            track_updates: self.tracker.updates,
        })
    }

    /// The object's pose by the push tracker, odometry frame, for a robot at `robot`
    /// (continuous orientation); the known start pose before any update.
    pub fn tracked_object(&self, robot: Pose) -> Pose {
        let p = to_frame(robot, self.tracker.position);
        Pose::new(p.x, p.y, robot.theta + self.tracker.orientation)
    }

    fn expect(&self, phase: TrialPhase, call: &'static str) -> Result<(), TrialOrderError> {
        if self.phase == phase {
            Ok(())
        } else {
            Err(TrialOrderError {
                call,
                phase: self.phase,
            })
        }
    }
}

fn push_bounded(buf: &mut Vec<DVec2>, dropped: &mut usize, p: DVec2) {
    if buf.len() < buf.capacity() {
        buf.push(p);
    } else {
        *dropped += 1;
    }
}

#[cfg(test)]
mod tests {

    use super::*;

    #[test]
    fn calls_out_of_order_are_refused_and_change_nothing() {
        let robot = RobotDescription::epuck();
        let mut r = TrialRecorder::new(&robot, 16);
        let view = IrView::new(1, [0.0; 8], Pose::default());
        let e = r.end_push(&view).unwrap_err();
        assert_eq!(e.phase, TrialPhase::Idle);
        assert_eq!(r.phase(), TrialPhase::Idle);
        r.begin_trial(15.0, Pose::default());
        assert!(r.end_push(&view).is_err());
        assert_eq!(r.phase(), TrialPhase::Approach);
    }

    #[test]
    fn approach_points_land_in_the_object_frame_and_a_full_buffer_drops_points() {
        let robot = RobotDescription::epuck();
        let mut r = TrialRecorder::new(&robot, 6);
        // Object at (1, 1) turned 90 deg; a wall of it 5 mm ahead of the robot's shell.
        let object = Pose::new(1.0, 1.0, std::f64::consts::FRAC_PI_2);
        r.begin_trial(0.0, object);
        let wall = robot.body_radius + 0.005;
        let mut raw = [0f32; 8];
        for i in robot.front_sensors() {
            let s = &robot.ir_sensors[i];
            raw[i] = robot.response.reading((wall - s.mount.x) / s.direction().x) as f32;
        }
        // Robot 0.1 m below the object's centre, facing it (+y in the odometry frame).
        let odo = Pose::new(1.0, 0.9, std::f64::consts::FRAC_PI_2);
        r.observe(&IrView::new(1, raw, odo), None);
        r.observe(&IrView::new(1, raw, odo), None);
        assert_eq!(
            r.approach_points().len(),
            4,
            "a repeated frame adds nothing"
        );
        for p in r.approach_points() {
            // The robot sits at object-frame (-0.1, 0) facing +x: the wall is at x = -0.1
            // + wall.
            assert!((p.x - (-0.1 + wall)).abs() < 2e-5, "{p}");
        }
        r.observe(&IrView::new(2, raw, odo), None);
        assert_eq!(r.approach_points().len(), 6);
        assert_eq!(r.dropped_points(), 2);
    }
}
