//! What the robot knows of the object from its own senses, frame by frame: its fused pose,
//! the front gap and contact, the border its IR sees while it circles, the object's pose
//! matched to S after a circling and carried on through each push by the gradient's
//! prediction, and the gradient-free centroid track. The planner sees only what this
//! writes into an [`ObjectEstimate`].
//!
//! ```text
//! observe(frame)        robot pose (odometry pulled to the fixes), front gap, contact,
//!                       contact point; while circling: border points (world frame)
//! TaskCircleBegin       forget the gathered border, gather from this frame on
//! TaskCircleEnd         pose <- match_pose(S, border) (sigma 0); centroid <- the border's
//! TaskPushBegin         the contact pose, the announced plan (aim point, alpha, scale)
//! TaskPushEnd           pose <- prediction applied, touch-corrected; sigma grows;
//!                       centroid += the robot's travel since contact
//! ```

use agp_affordance::{
    AffordanceGradient, ContactPriorBuildError, ContactPriorConfig, Grid, MIN_MATCH_POINTS,
    MatchedPose, Prediction, PushPredictor, ShapeMatcher, ShapeMatcherBuildError,
    ShapeMatcherConfig, symmetry_order_of,
};
use agp_shared_types::{LearnEvent, LearnEventKind, ObjectEstimate, Pose2, angle};
use agp_world::{BORDER_MAX_SIGMA, Pose, RobotDescription, ir_border_point};
use glam::DVec2;

use crate::online_learner::PendingPush;
use crate::{ApproachContact, LearnedPush, OnlineLearner, OnlineLearningConfig};
use crate::{ContactSense, RobotLocalizer};

/// Sectors of [`ObjectEstimate::border_seen`]: 10 degrees each round the estimated centre.
pub const BORDER_SECTORS: u32 = 36;

/// How an [`ObjectTracker`] fuses and tracks. The defaults are the planner's episode's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerConfig {
    /// How far each overhead fix pulls the robot's pose estimate, in (0, 1] (0.3).
    pub fix_gain: f64,
    /// Each push adds to the pose's error bound this share of its predicted motion
    /// (displacement and rotation) plus the prediction's spread plus the floors below; the
    /// centroid's bound grows by this share of the robot's travel plus the floor (0.15).
    pub error_growth: f64,
    /// Added to the position error bound at each push, m (1 mm).
    pub error_floor_m: f64,
    /// Added to the orientation error bound at each push, rad (1 deg).
    pub error_floor_rad: f64,
    /// Correct each prediction so that the object's learned border touches the robot's
    /// body where the robot stopped pushing (true).
    pub contact_correction: bool,
    /// Gap (m) between the robot's shell and the object's farthest learned point at a
    /// push's start, as in the learning trials: sets the start radius (20 mm).
    pub start_gap_m: f64,
    /// Front gap (m) at or under which the object counts as in contact, and under which a
    /// push counts as having ended against the object (10 mm).
    pub contact_gap_m: f64,
    /// Largest standard deviation (m) of a reading's inverted distance for it to give a
    /// border point ([`BORDER_MAX_SIGMA`]: 40 mm from the E-puck's sensors).
    pub max_sigma: f64,
    /// Border points one circling can gather (8192); more are dropped and counted.
    pub capacity: usize,
    /// The object's rotational symmetry for the matcher (0 disc, 1 none, k: k-fold);
    /// `None` learns it from the gradient's S ([`symmetry_order_of`]).
    pub symmetry_order: Option<u32>,
    /// Whether and how the gradient goes on learning from a task's pushes (off by
    /// default: see [`OnlineLearningConfig`]).
    pub online: OnlineLearningConfig,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            fix_gain: 0.3,
            error_growth: 0.15,
            error_floor_m: 0.001,
            error_floor_rad: 1f64.to_radians(),
            contact_correction: true,
            start_gap_m: 0.02,
            contact_gap_m: 0.01,
            max_sigma: BORDER_MAX_SIGMA,
            capacity: 8192,
            symmetry_order: None,
            online: OnlineLearningConfig::default(),
        }
    }
}

impl TrackerConfig {
    /// Checks every field: `Err` names the first out of range.
    pub fn validate(&self) -> Result<(), TrackerError> {
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        let checks = [
            (
                "fix_gain",
                self.fix_gain > 0.0 && self.fix_gain <= 1.0,
                "in (0, 1]",
            ),
            ("error_growth", nonneg(self.error_growth), "finite and >= 0"),
            (
                "error_floor_m",
                nonneg(self.error_floor_m),
                "finite and >= 0",
            ),
            (
                "error_floor_rad",
                nonneg(self.error_floor_rad),
                "finite and >= 0",
            ),
            ("start_gap_m", nonneg(self.start_gap_m), "finite and >= 0"),
            (
                "contact_gap_m",
                nonneg(self.contact_gap_m),
                "finite and >= 0",
            ),
            (
                "max_sigma",
                self.max_sigma.is_finite() && self.max_sigma > 0.0,
                "finite and > 0",
            ),
            ("capacity", self.capacity > 0, "at least 1"),
            (
                "symmetry_order",
                self.symmetry_order.is_none_or(|k| k < 255),
                "under 255",
            ),
        ];
        match checks.into_iter().find(|(_, ok, _)| !ok) {
            Some((field, _, expected)) => Err(TrackerError::Config { field, expected }),
            None => Ok(()),
        }
    }
}

/// Why an [`ObjectTracker`] could not be built or given a gradient.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackerError {
    /// A [`TrackerConfig`] field is out of range.
    #[error("tracker config: `{field}` must be {expected}")]
    Config {
        /// The field.
        field: &'static str,
        /// What it should be.
        expected: &'static str,
    },
    /// The gradient's S gives no matcher (no border).
    #[error(transparent)]
    Matcher(#[from] ShapeMatcherBuildError),
    /// The gradient cannot be learned on (its alphas or cell size).
    #[error(transparent)]
    Learner(#[from] agp_affordance::LearnerBuildError),
}

/// What the tracker keeps of a gradient: an owned copy (in its online learner, which
/// leaves it as it is unless online learning is on), its combined S, the matcher on it.
struct GradientState {
    learner: OnlineLearner,
    /// `ag.combined_shape()`, kept so that a push's predictor borrows it.
    shape: Grid,
    matcher: ShapeMatcher,
    start_radius_m: f64,
    symmetry_order: u32,
}

impl GradientState {
    fn ag(&self) -> &AffordanceGradient {
        self.learner.gradient()
    }
}

/// A push under way: the robot's pose when contact was made and what was announced.
#[derive(Debug, Clone, Copy)]
struct PushStart {
    contact: Pose,
    /// Aim point (object frame), alpha (deg), scale: a push planned on the gradient.
    plan: Option<(DVec2, f64, f64)>,
}

/// The estimator's perception: from IR frames, odometry, overhead fixes and the planner's
/// task events to every perception field of an [`ObjectEstimate`].
///
/// Two tracks of the object run side by side:
/// - the pose track (needs a gradient, [`ObjectTracker::set_gradient`]): after a circling
///   the gathered border matched to S (error bound 0); after each push announced with its
///   plan, the gradient's prediction of it applied, moved along the robot's heading so that
///   the learned border touches the robot where it stopped, the error bound grown
///   ([`TrackerConfig::error_growth`]); a push that ended without the object just ahead,
///   or whose prediction needed more than 15 mm of correction, makes the bound infinite;
/// - the centroid track (the baseline's): after a circling the centroid of the gathered
///   border (its radius from the first circling), moved after each push by the robot's
///   travel from contact to end; no orientation.
///
/// [`ObjectTracker::observe`] allocates nothing; a circling's end (the match) may.
pub struct ObjectTracker {
    config: TrackerConfig,
    robot: RobotDescription,
    sense: ContactSense,
    localizer: RobotLocalizer,
    /// Largest sensor distance (m) of a border point.
    border_range: f64,
    gradient: Option<Box<GradientState>>,

    // The latest frame.
    robot_pose: Pose,
    last_sample: Option<u64>,
    last_raw: [f32; 8],
    front_gap: Option<f64>,
    approach: ApproachContact,

    // The border.
    circling: bool,
    points: Vec<DVec2>,
    dropped: usize,
    /// Bit k: sector k round the centre got a border point.
    sectors: u64,

    // The pose track.
    pose: Pose2,
    sigma_xy: f64,
    sigma_theta: f64,
    valid: bool,
    match_rms_m: f64,
    match_inliers: f64,
    match_seq: u64,

    // The centroid track.
    centroid: DVec2,
    centroid_sigma_m: f64,
    centroid_valid: bool,
    object_radius_m: Option<f64>,

    push: Option<PushStart>,

    // Online learning.
    /// Pushes since the last circling that matched.
    pushes_since_match: u32,
    /// The push under way, or ended, that is learned if a circling matches right after.
    pending: Option<PendingPush>,
    /// Counts the gradient's versions: 1 once given, +1 per push learned.
    generation: u64,
    /// The latest push learned.
    last_learned: Option<LearnedPush>,
    /// An object never pushed: the object's name and the prior to build from the first
    /// circling, while no gradient is given ([`ObjectTracker::start_from_prior`]).
    prior: Option<(String, ContactPriorConfig)>,
    /// Why the last circling gave no prior, if it did not.
    prior_error: Option<ContactPriorBuildError>,
    /// Once the prior is built: the border seen so far, which later circlings refine.
    refinement: Option<PriorRefinement>,
}

/// An object never pushed, its prior built: what rebuilds it from later circlings
/// ([`ObjectTracker::refine_prior`]).
struct PriorRefinement {
    name: String,
    config: ContactPriorConfig,
    /// Border points of every circling so far, object frame (each circling's thinned).
    border: Vec<DVec2>,
    /// Later circlings that refined the prior.
    circlings: u32,
}

impl ObjectTracker {
    /// A tracker for `robot` with no gradient (the centroid track only until
    /// [`ObjectTracker::set_gradient`]).
    ///
    /// # Panics
    /// If `config` is invalid ([`TrackerConfig::validate`]); [`ObjectTracker::try_new`]
    /// returns the error instead.
    #[track_caller]
    pub fn new(robot: &RobotDescription, config: TrackerConfig) -> Self {
        match Self::try_new(robot, config) {
            Ok(t) => t,
            Err(e) => panic!("{e}"),
        }
    }

    /// A tracker for `robot` with no gradient; `Err` if `config` is out of range.
    pub fn try_new(robot: &RobotDescription, config: TrackerConfig) -> Result<Self, TrackerError> {
        config.validate()?;
        Ok(Self {
            robot: robot.clone(),
            sense: ContactSense::new(robot),
            localizer: RobotLocalizer::new(config.fix_gain),
            border_range: robot.response.usable_range(config.max_sigma),
            gradient: None,
            robot_pose: Pose::default(),
            last_sample: None,
            last_raw: [0.0; 8],
            front_gap: None,
            approach: ApproachContact::new(),
            circling: false,
            points: Vec::with_capacity(config.capacity),
            dropped: 0,
            sectors: 0,
            pose: Pose2::default(),
            sigma_xy: f64::INFINITY,
            sigma_theta: f64::INFINITY,
            valid: false,
            match_rms_m: 0.0,
            match_inliers: 0.0,
            match_seq: 0,
            centroid: DVec2::ZERO,
            centroid_sigma_m: f64::INFINITY,
            centroid_valid: false,
            object_radius_m: None,
            push: None,
            pushes_since_match: 0,
            pending: None,
            generation: 0,
            last_learned: None,
            prior: None,
            prior_error: None,
            refinement: None,
            config,
        })
    }

    /// Takes `ag` (an owned copy): builds the matcher on its combined S, learns the
    /// symmetry order unless the config gives one, and sets the start radius (farthest
    /// learned border point + body radius + start gap). The tracks are kept. Allocates.
    pub fn set_gradient(&mut self, ag: &AffordanceGradient) -> Result<(), TrackerError> {
        let state = self.gradient_state(OnlineLearner::new(ag, self.config.online)?)?;
        self.generation += 1;
        self.pending = None;
        self.refinement = None;
        self.gradient = Some(Box::new(state));
        Ok(())
    }

    /// What the tracker keeps of the gradient `learner` learns on: its combined S, the
    /// matcher on it (the symmetry order learned from S unless the config gives one), the
    /// start radius (farthest learned border point + body radius + start gap). Allocates.
    fn gradient_state(&self, learner: OnlineLearner) -> Result<GradientState, TrackerError> {
        let shape = learner.gradient().combined_shape();
        let order = self
            .config
            .symmetry_order
            .unwrap_or_else(|| symmetry_order_of(&shape));
        let matcher = ShapeMatcher::new(
            &shape,
            ShapeMatcherConfig {
                symmetry_order: order,
                ..ShapeMatcherConfig::default()
            },
        )?;
        let radius = matcher
            .border_points()
            .iter()
            .map(|p| p.length())
            .fold(0.0, f64::max);
        Ok(GradientState {
            learner,
            shape,
            matcher,
            start_radius_m: radius + self.robot.body_radius + self.config.start_gap_m,
            symmetry_order: order,
        })
    }

    /// An object never pushed (no learning phase, no AG file): the first circling that
    /// closes, or gathers enough points, gives the gradient, the prior
    /// [`agp_affordance::contact_prior`] builds from its border points alone (their
    /// centroid the object frame's origin, the axes the world's), which
    /// [`ObjectTracker::set_gradient`] then takes, and the circling is matched to its S
    /// (so the object's pose is the border's centroid, orientation 0, or a turn the S's
    /// symmetry allows). With online learning on, the task's pushes learn on from there.
    /// The prior's start clearance is the tracker's (body radius plus start gap). Does
    /// nothing once a gradient is given.
    pub fn start_from_prior(&mut self, object_name: &str, config: ContactPriorConfig) {
        let config = ContactPriorConfig {
            start_clearance_m: self.robot.body_radius + self.config.start_gap_m,
            ..config
        };
        self.prior = Some((object_name.to_owned(), config));
    }

    /// Why the latest circling gave no prior ([`ObjectTracker::start_from_prior`]), if it
    /// gave none.
    pub fn prior_error(&self) -> Option<&ContactPriorBuildError> {
        self.prior_error.as_ref()
    }

    /// Builds the prior from the circling's points, if one is asked for and no gradient is
    /// given. Allocates.
    fn take_prior(&mut self) {
        if self.gradient.is_some() {
            return;
        }
        let Some((name, config)) = self.prior.clone() else {
            return;
        };
        let Some(c) = border_centroid(&self.points) else {
            return;
        };
        let mut border = Vec::with_capacity(self.points.len());
        thin_into(
            &mut border,
            self.points.iter().map(|p| *p - c),
            config.border_spacing_m,
        );
        match agp_affordance::contact_prior(&name, &border, &config) {
            Ok(ag) => match self.set_gradient(&ag) {
                Ok(()) => {
                    self.prior_error = None;
                    self.refinement = Some(PriorRefinement {
                        name,
                        config,
                        border,
                        circlings: 0,
                    });
                }
                Err(_) => {
                    self.prior_error = Some(ContactPriorBuildError::NoFootprint {
                        points: border.len(),
                    });
                }
            },
            Err(e) => self.prior_error = Some(e),
        }
    }

    /// An object never pushed, at a later circling matched at `self.pose`: the circling's
    /// border points join those seen before (object frame), and S and the prior are built
    /// again from them all, the frame's origin moved to their centroid; what the task's
    /// pushes taught is learned again on the new prior ([`OnlineLearner::rebased`]) and
    /// the pose moved with the origin. Up to [`ContactPriorConfig::refine_circlings`]
    /// circlings. Allocates.
    fn refine_prior(&mut self) {
        let Some(r) = self.refinement.as_mut() else {
            return;
        };
        if r.circlings >= r.config.refine_circlings {
            return;
        }
        let pose = self.pose;
        let seen = r.border.len();
        thin_into(
            &mut r.border,
            self.points.iter().map(|p| pose.to_local(*p)),
            r.config.border_spacing_m,
        );
        let (name, config) = (r.name.clone(), r.config);
        let moved = border_centroid(&r.border)
            .map(|c| (c, r.border.iter().map(|p| *p - c).collect::<Vec<DVec2>>()));
        // Each circling's points are thinned among themselves only: the circlings'
        // points near each other are what averages S.
        let config = ContactPriorConfig {
            border_spacing_m: 0.0,
            ..config
        };
        let rebuilt = moved.and_then(|(c, border)| {
            let base = agp_affordance::contact_prior(&name, &border, &config).ok()?;
            let learner = self.gradient.as_ref()?.learner.rebased(&base, c).ok()?;
            let state = self.gradient_state(learner).ok()?;
            Some((c, border, state))
        });
        let Some(r) = self.refinement.as_mut() else {
            return;
        };
        let Some((c, border, state)) = rebuilt else {
            r.border.truncate(seen);
            return;
        };
        r.border = border;
        r.circlings += 1;
        let origin = pose.to_world(c);
        self.pose = Pose2::new(origin.x, origin.y, pose.theta);
        self.gradient = Some(Box::new(state));
        self.generation += 1;
    }

    /// The gradient taken by [`ObjectTracker::set_gradient`], if any, as learned on since
    /// (online learning).
    pub fn gradient(&self) -> Option<&AffordanceGradient> {
        self.gradient.as_ref().map(|g| g.ag())
    }

    /// The gradient's version: 0 without one, 1 once given by
    /// [`ObjectTracker::set_gradient`] (each call counts on), and one more for each push
    /// learned online. A publisher republishes the gradient when it advances.
    pub fn gradient_generation(&self) -> u64 {
        self.generation
    }

    /// The latest push learned online, if any.
    pub fn last_learned(&self) -> Option<&LearnedPush> {
        self.last_learned.as_ref()
    }

    /// Pushes learned online since the gradient was given.
    pub fn pushes_learned(&self) -> u64 {
        self.gradient
            .as_ref()
            .map_or(0, |g| g.learner.pushes_learned())
    }

    /// The matcher's symmetry order (0 disc, 1 none, k: k-fold); `None` without a gradient.
    pub fn symmetry_order(&self) -> Option<u32> {
        self.gradient.as_ref().map(|g| g.symmetry_order)
    }

    /// Radius (m) of the circle round the centroid the learning trials started on;
    /// `None` without a gradient.
    pub fn start_radius_m(&self) -> Option<f64> {
        self.gradient.as_ref().map(|g| g.start_radius_m)
    }

    /// The config the tracker runs with.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// The robot's fused pose at the latest frame (world frame).
    pub fn robot_pose(&self) -> Pose {
        self.robot_pose
    }

    /// The front gap at the latest frame, m; `None` when the front sensors see nothing.
    pub fn front_gap(&self) -> Option<f64> {
        self.front_gap
    }

    /// Whether the front gap has stalled at the latest frame ([`ApproachContact`]).
    pub fn stalled(&self) -> bool {
        self.approach.stalled()
    }

    /// The border points gathered by the current or last circling (world frame, m).
    pub fn border_points(&self) -> &[DVec2] {
        &self.points
    }

    /// Border points of the current or last circling that did not fit in the buffer.
    pub fn dropped_points(&self) -> usize {
        self.dropped
    }

    /// Whether a circling is under way (between its begin and end events).
    pub fn circling(&self) -> bool {
        self.circling
    }

    /// One frame: the robot's pose (odometry pulled towards the fix when `fix_seq` is new),
    /// the front gap; at a new `ir_sample`, the border points the readings give (gathered
    /// while circling, and marked in the sectors round the estimated centre). Allocates
    /// nothing.
    pub fn observe(
        &mut self,
        ir_sample: u64,
        ir_raw: &[f32; 8],
        odometry: Pose2,
        fix: Pose2,
        fix_seq: u64,
    ) {
        self.robot_pose = self.localizer.update(odometry, fix, fix_seq);
        self.front_gap = self.sense.front_gap(ir_raw);
        // Travel by odometry: smooth, where the fused pose jumps at each fix.
        self.approach.observe(ir_sample, self.front_gap, odometry);
        self.last_raw = *ir_raw;
        if self.last_sample != Some(ir_sample) {
            self.last_sample = Some(ir_sample);
            self.absorb_frame();
        }
    }

    /// The latest frame's border points: into the circling's buffer, and into the sectors.
    fn absorb_frame(&mut self) {
        let centre = self.centre();
        for i in 0..self.last_raw.len() {
            let Some(p) = ir_border_point(
                &self.robot,
                self.robot_pose,
                i,
                f64::from(self.last_raw[i]),
                self.border_range,
            ) else {
                continue;
            };
            if self.circling {
                if self.points.len() < self.points.capacity() {
                    self.points.push(p);
                } else {
                    self.dropped += 1;
                }
            }
            if let Some(c) = centre {
                self.sectors |= 1u64 << sector(p, c);
            }
        }
    }

    /// The estimated centre: the pose's position if valid, else the centroid if valid.
    fn centre(&self) -> Option<DVec2> {
        if self.valid {
            Some(self.pose.position())
        } else {
            self.centroid_valid.then_some(self.centroid)
        }
    }

    /// A task event (the four `Task*` kinds); every other kind is ignored. Events refer to
    /// the latest observed frame (the sender sends them before the command that makes the
    /// next one). A circling's end runs the match and may allocate; the rest does not.
    pub fn handle(&mut self, event: &LearnEvent) {
        match LearnEventKind::from_u32(event.kind) {
            Some(LearnEventKind::TaskCircleBegin) => self.begin_circling(),
            Some(LearnEventKind::TaskCircleEnd) => self.end_circling(event.flag == 1),
            Some(LearnEventKind::TaskPushBegin) => {
                // Learnable when it starts from a pose a circling just matched.
                self.pending = (event.flag == 1
                    && self.pushes_since_match == 0
                    && self.valid
                    && self.sigma_xy == 0.0)
                    .then(|| PendingPush {
                        before: self.pose,
                        contact_obj: DVec2::new(event.contact[0], event.contact[1]),
                        alpha_deg: event.alpha_deg,
                        scale: event.scale,
                    });
                self.push = Some(PushStart {
                    contact: self.robot_pose,
                    plan: (event.flag == 1).then(|| {
                        (
                            DVec2::new(event.contact[0], event.contact[1]),
                            event.alpha_deg,
                            event.scale,
                        )
                    }),
                });
            }
            Some(LearnEventKind::TaskPushEnd) => {
                if let Some(start) = self.push.take() {
                    self.pushes_since_match += 1;
                    self.end_push(start);
                }
            }
            _ => {}
        }
    }

    fn begin_circling(&mut self) {
        self.circling = true;
        self.points.clear();
        self.dropped = 0;
        self.sectors = 0;
        // The frame the circling starts at is the routine's first sample.
        if self.last_sample.is_some() {
            self.absorb_frame();
        }
    }

    /// The circling's match and centroid, as the planner's `estimate` takes them: only
    /// when its lap closed or it gathered enough points anyway.
    fn end_circling(&mut self, closed: bool) {
        self.circling = false;
        if !(closed || self.points.len() >= 4 * MIN_MATCH_POINTS) {
            return;
        }
        let built_now = self.gradient.is_none();
        self.take_prior();
        let mut refine = false;
        if let Some(g) = self.gradient.as_mut() {
            let guess = self.valid.then_some(self.pose);
            if let Some(m) = match_pose(&mut g.matcher, &self.points, guess) {
                let matched = Pose2::new(m.position.x, m.position.y, m.orientation_rad);
                // Online learning: the one push since the last match, its effect observed.
                if let Some(push) = self.pending.take()
                    && self.pushes_since_match == 1
                {
                    let period = match g.symmetry_order {
                        0 => 0.0,
                        1 => f64::INFINITY,
                        k => std::f64::consts::TAU / f64::from(k),
                    };
                    let GradientState {
                        learner,
                        shape,
                        start_radius_m,
                        ..
                    } = &mut **g;
                    if let Some(l) = learner.learn(push, matched, shape, *start_radius_m, period) {
                        self.last_learned = Some(l);
                        self.generation += 1;
                    }
                }
                self.pushes_since_match = 0;
                self.pose = matched;
                self.sigma_xy = 0.0;
                self.sigma_theta = 0.0;
                self.valid = true;
                self.match_seq += 1;
                self.match_rms_m = m.rms_error_m;
                self.match_inliers = m.inlier_fraction;
                refine = !built_now;
            }
        }
        if refine {
            self.refine_prior();
        }
        if let Some(c) = border_centroid(&self.points) {
            let r = self
                .points
                .iter()
                .map(|p| (*p - c).length())
                .fold(0.0, f64::max);
            self.centroid = c;
            self.centroid_sigma_m = 0.0;
            self.centroid_valid = true;
            self.object_radius_m.get_or_insert(r);
        }
        // The sectors round the new centre.
        self.sectors = 0;
        if let Some(c) = self.centre() {
            for p in &self.points {
                self.sectors |= 1u64 << sector(*p, c);
            }
        }
    }

    /// updateEstimate: both tracks carried on by the push that started at `start` and
    /// ended (the object at rest) at the latest frame.
    fn end_push(&mut self, start: PushStart) {
        let c = self.config;
        let end = self.robot_pose;
        let ended_in_contact = self.front_gap.is_some_and(|g| g <= c.contact_gap_m);
        if self.valid {
            let prediction = match (start.plan, self.gradient.as_deref()) {
                (Some((aim, alpha_deg, scale)), Some(g)) => {
                    PushPredictor::borrowing(g.ag(), &g.shape, g.start_radius_m)
                        .predict(aim, alpha_deg)
                        .map(|p| Prediction {
                            displacement: p.displacement * scale,
                            rotation_rad: p.rotation_rad * scale,
                            ..p
                        })
                        .map(|p| (p, g))
                }
                _ => None,
            };
            match prediction {
                Some((p, g)) => {
                    let predicted = p.apply_to(self.pose);
                    let corrected = if c.contact_correction {
                        touch_correction(g.matcher.border_points(), predicted, end, &self.robot)
                    } else {
                        Some(predicted)
                    };
                    let surprised = corrected.is_none() || !ended_in_contact;
                    self.pose = corrected.unwrap_or(predicted);
                    self.sigma_xy = if surprised { f64::INFINITY } else { 0.0 }
                        + self.sigma_xy
                        + c.error_growth * p.displacement.length()
                        + p.displacement_spread_m
                        + c.error_floor_m;
                    self.sigma_theta = self.sigma_theta
                        + c.error_growth * p.rotation_rad.abs()
                        + p.rotation_spread_rad
                        + c.error_floor_rad;
                }
                None => {
                    // Nothing predicted (no plan announced, no gradient, no data there):
                    // the object went who knows where.
                    self.sigma_xy = f64::INFINITY;
                    self.sigma_theta = f64::INFINITY;
                }
            }
        }
        if self.centroid_valid {
            let moved = end.position() - start.contact.position();
            self.centroid += moved;
            self.centroid_sigma_m = if ended_in_contact { 0.0 } else { f64::INFINITY }
                + self.centroid_sigma_m
                + c.error_growth * moved.length()
                + c.error_floor_m;
        }
    }

    /// Fills every perception field of `out`: `robot`, `pose`, `sigma_xy`, `sigma_theta`,
    /// `valid`, `centroid`, `centroid_sigma_m`, `centroid_valid`, `object_radius_m` (0
    /// before a circling), `front_gap_m` (-1 when nothing is seen), `contact`,
    /// `contact_point` (object frame when `contact` and `valid`, else 0), `match_rms_m`,
    /// `match_inliers`, `match_seq`, `border_seen`, `symmetry_order` (255 without a
    /// gradient). Error bounds are infinite while their track is not valid. Leaves
    /// `timing`, `step`, `grids_seq`, `learning`, `estimator_start_ns` and `_pad` alone.
    pub fn write_estimate(&self, out: &mut ObjectEstimate) {
        out.robot = self.robot_pose;
        out.pose = self.pose;
        out.sigma_xy = if self.valid {
            self.sigma_xy
        } else {
            f64::INFINITY
        };
        out.sigma_theta = if self.valid {
            self.sigma_theta
        } else {
            f64::INFINITY
        };
        out.valid = u8::from(self.valid);
        out.centroid = self.centroid.to_array();
        out.centroid_sigma_m = if self.centroid_valid {
            self.centroid_sigma_m
        } else {
            f64::INFINITY
        };
        out.centroid_valid = u8::from(self.centroid_valid);
        out.object_radius_m = self.object_radius_m.unwrap_or(0.0);
        out.front_gap_m = self.front_gap.unwrap_or(-1.0);
        let contact = self
            .front_gap
            .is_some_and(|g| g <= self.config.contact_gap_m);
        out.contact = u8::from(contact);
        out.stalled = u8::from(self.approach.stalled());
        out.contact_point = match self.front_gap {
            Some(gap) if contact && self.valid => {
                let ahead = self.robot_pose.position()
                    + DVec2::from_angle(self.robot_pose.theta) * (self.robot.body_radius + gap);
                self.pose.to_local(ahead).to_array()
            }
            _ => [0.0; 2],
        };
        out.match_rms_m = self.match_rms_m;
        out.match_inliers = self.match_inliers;
        out.match_seq = self.match_seq;
        out.border_seen = self.border_seen();
        out.symmetry_order = self
            .symmetry_order()
            .map_or(255, |k| u8::try_from(k.min(254)).unwrap_or(254));
    }

    /// Share of the [`BORDER_SECTORS`] sectors round the estimated centre (the pose's
    /// position if valid, else the centroid) that hold a border point seen since the last
    /// circling began (the circling's points are re-sorted round the new centre when it
    /// ends); 0 without a centre.
    pub fn border_seen(&self) -> f64 {
        if self.centre().is_none() {
            return 0.0;
        }
        f64::from(self.sectors.count_ones()) / f64::from(BORDER_SECTORS)
    }

    /// The physics restarted: forgets the object (both tracks, the gathered border, a push
    /// under way, the radius) and the robot's fix offset (the odometry restarts at the
    /// true pose). Keeps the gradient and `match_seq` (it counts on).
    pub fn reset(&mut self) {
        self.localizer = RobotLocalizer::new(self.config.fix_gain);
        self.robot_pose = Pose::default();
        self.last_sample = None;
        self.last_raw = [0.0; 8];
        self.front_gap = None;
        self.approach.reset();
        self.circling = false;
        self.points.clear();
        self.dropped = 0;
        self.sectors = 0;
        self.pose = Pose2::default();
        self.sigma_xy = f64::INFINITY;
        self.sigma_theta = f64::INFINITY;
        self.valid = false;
        self.match_rms_m = 0.0;
        self.match_inliers = 0.0;
        self.centroid = DVec2::ZERO;
        self.centroid_sigma_m = f64::INFINITY;
        self.centroid_valid = false;
        self.object_radius_m = None;
        self.push = None;
        self.pushes_since_match = 0;
        self.pending = None;
    }
}

/// Sector (0..[`BORDER_SECTORS`]) of `p` round `centre`.
fn sector(p: DVec2, centre: DVec2) -> u32 {
    let a = angle::wrap_positive((p - centre).to_angle(), std::f64::consts::TAU);
    ((a / std::f64::consts::TAU * f64::from(BORDER_SECTORS)) as u32).min(BORDER_SECTORS - 1)
}

/// The pose from circled border points: ShapeMatcher against S. When the runner-up fits
/// about as well and is nearer to `guess`, the runner-up (the points do not tell them
/// apart; the last estimate does). `None` when too few points fit the learned border.
fn match_pose(
    matcher: &mut ShapeMatcher,
    points: &[DVec2],
    guess: Option<Pose2>,
) -> Option<MatchedPose> {
    let m = matcher.match_points(points).ok()?;
    let period = matcher.symmetry_period_rad();
    let mut best = m.best;
    if let (Some(g), Some(r)) = (guess, m.runner_up) {
        let off = |p: &MatchedPose| {
            (p.position - DVec2::new(g.x, g.y)).length()
                + 0.05 * angle::distance(p.orientation_rad - g.theta, 0.0, period)
        };
        if r.rms_error_m <= 1.3 * best.rms_error_m && off(&r) + 0.01 < off(&best) {
            best = r;
        }
    }
    (best.inlier_fraction >= 0.6).then_some(best)
}

/// Moves the predicted `pose` along the robot's heading so that the object's learned
/// border (object frame) touches the robot's body where the robot stopped (`robot_pose`,
/// its own estimate): the push ends in contact. `None` when the correction would exceed
/// 15 mm: the push did not go as predicted.
fn touch_correction(
    border: &[DVec2],
    pose: Pose2,
    robot_pose: Pose,
    robot: &RobotDescription,
) -> Option<Pose2> {
    let u = DVec2::from_angle(robot_pose.theta);
    let rot = DVec2::from_angle(pose.theta);
    let mut centre = DVec2::new(pose.x, pose.y);
    let mut total = 0.0;
    for _ in 0..3 {
        let nearest = border
            .iter()
            .map(|b| (centre + rot.rotate(*b) - robot_pose.position()).length())
            .fold(f64::INFINITY, f64::min);
        if !nearest.is_finite() {
            return None;
        }
        let shift = nearest - robot.body_radius;
        centre -= shift * u;
        total += shift;
    }
    (total.abs() <= 0.015).then(|| Pose2::new(centre.x, centre.y, pose.theta))
}

/// Appends the points of `points` to `out`, each unless one appended from `points` before
/// lies closer than `spacing` (m; 0 keeps every point).
fn thin_into(out: &mut Vec<DVec2>, points: impl Iterator<Item = DVec2>, spacing: f64) {
    let from = out.len();
    let spacing2 = spacing * spacing;
    for p in points.filter(|p| p.is_finite()) {
        if spacing2 > 0.0 && out[from..].iter().any(|q| q.distance_squared(p) < spacing2) {
            continue;
        }
        out.push(p);
    }
}

/// The centroid of the area a circled border encloses: the points binned by angle round
/// their mean (2 deg bins, the mean of each), the bins' means as a polygon. Good for
/// shapes star-shaped from their centroid; off by a few mm on the L's inner corner.
/// `None` for fewer than [`MIN_MATCH_POINTS`] points or a degenerate ring. Allocates.
pub fn border_centroid(points: &[DVec2]) -> Option<DVec2> {
    const BINS: usize = 180;
    if points.len() < MIN_MATCH_POINTS {
        return None;
    }
    let mean = points.iter().sum::<DVec2>() / points.len() as f64;
    let ring = agp_affordance::angle_ring::<BINS>(points.iter().copied(), mean);
    if ring.len() < 3 {
        return None;
    }
    let (mut area, mut c) = (0.0, DVec2::ZERO);
    for k in 0..ring.len() {
        let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
        let cross = a.perp_dot(b);
        area += cross;
        c += (a + b) * cross;
    }
    (area.abs() > 1e-9).then(|| c / (3.0 * area))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_border_centroid_of_a_square_ring_is_its_centre() {
        let c = DVec2::new(0.2, -0.1);
        let points: Vec<DVec2> = (0..400)
            .map(|k| {
                let s = k as f64 / 100.0;
                let (side, t) = (s.floor() as usize, s.fract() - 0.5);
                let q = match side {
                    0 => DVec2::new(0.03, 0.06 * t),
                    1 => DVec2::new(-0.06 * t, 0.03),
                    2 => DVec2::new(-0.03, -0.06 * t),
                    _ => DVec2::new(0.06 * t, -0.03),
                };
                c + q
            })
            .collect();
        let got = border_centroid(&points).expect("a centroid");
        assert!((got - c).length() < 1e-4, "{got}");
    }

    #[test]
    fn a_predicted_pose_is_moved_along_the_push_until_its_border_touches_the_robot() {
        let robot = RobotDescription::epuck();
        // A square of 60 mm, its -x face 10 mm ahead of the robot's shell.
        let border: Vec<DVec2> = (0..60)
            .map(|k| DVec2::new(-0.03, -0.03 + k as f64 * 0.001))
            .collect();
        let robot_pose = Pose::new(0.0, 0.0, 0.0);
        let pose = Pose2::new(robot.body_radius + 0.01 + 0.03, 0.0, 0.0);
        let got = touch_correction(&border, pose, robot_pose, &robot).expect("trusted");
        assert!((got.x - (robot.body_radius + 0.03)).abs() < 1e-6, "{got:?}");
        // 20 mm off is not trusted.
        let far = Pose2::new(robot.body_radius + 0.02 + 0.03, 0.0, 0.0);
        assert_eq!(touch_correction(&border, far, robot_pose, &robot), None);
    }

    #[test]
    fn points_fall_in_the_sector_of_their_angle_round_the_centre() {
        let c = DVec2::new(0.1, 0.1);
        assert_eq!(sector(c + DVec2::new(0.01, 0.0001), c), 0);
        assert_eq!(sector(c + DVec2::new(0.0, 0.01), c), 9);
        assert_eq!(sector(c + DVec2::new(0.01, -0.0001), c), 35);
    }

    #[test]
    fn an_invalid_config_is_refused_by_name() {
        let robot = RobotDescription::epuck();
        let bad = TrackerConfig {
            fix_gain: 0.0,
            ..TrackerConfig::default()
        };
        assert!(matches!(
            ObjectTracker::try_new(&robot, bad),
            Err(TrackerError::Config {
                field: "fix_gain",
                ..
            })
        ));
        assert!(TrackerConfig::default().validate().is_ok());
    }
}
