use agp_affordance::{
    AffordanceGradient, AffordanceLearner, Grid, LearnerBuildError, LearnerConfig, SampleAddError,
    ShapeMatcher, ShapeMatcherBuildError, ShapeMatcherConfig, learned_border_radius_m,
    symmetry_order_of,
};
use agp_shared_types::GRID_SIDE;
use agp_world::{Pose, RobotDescription};
use glam::DVec2;

use crate::{
    ContactEstimates, ContactEstimator, ContactMethod, IrView, LearnedShape, TrialFinishError,
    TrialOrderError, TrialPhase, TrialRecord, TrialRecorder,
};

/// How a [`LearningSession`] learns.
#[derive(Debug, Clone, PartialEq)]
pub struct LearningConfig {
    /// Alphas, grid and Gaussians of the gradients.
    pub learner: LearnerConfig,
    /// How circlings are matched to the learned shape. Its `symmetry_order` is not used:
    /// the matcher takes [`Self::symmetry_order`]'s, or the one learned from S.
    pub matcher: ShapeMatcherConfig,
    /// The object's rotational symmetry order (0 a disc, 1 none) for the matcher; `None`
    /// learns it from the S of the shape circling ([`symmetry_order_of`]), from IR alone.
    pub symmetry_order: Option<u32>,
    /// Which contact point the gradient is keyed by.
    pub contact_method: ContactMethod,
    /// Border points kept per buffer (a lap round a 100 mm object gives about a thousand).
    pub point_capacity: usize,
    /// A trial whose circling matches the learned shape with fewer inliers than this is
    /// rejected (0..1).
    pub min_inlier_fraction: f64,
    /// Whether the front sensors' border points seen during each approach (object at its
    /// known pose) are added to that alpha's S, as the paper's Algorithm 1 does. The
    /// matcher keeps the S of the first circling either way until
    /// [`LearningSession::rebuild_matcher`].
    pub approach_refines_shape: bool,
    /// A border point is added to an alpha's S only if no point added to it before lies
    /// closer than this (m); 0 adds every point, as the paper does. Readings pile up where
    /// the robot lingers (it pivots round every corner while circling, and each approach
    /// sees the same spot of a face for half a second), so without thinning the corners of
    /// S are several times the faces' height and the faces fall under the matcher's ridge
    /// threshold; with it, S has about the same height all round the border.
    pub border_spacing_m: f64,
}

impl LearningConfig {
    /// The defaults for an object of rotational symmetry `symmetry_order` (0 a disc, 1
    /// none), given rather than learned: see [`LearningConfig::default`].
    pub fn for_symmetry(symmetry_order: u32) -> Self {
        Self {
            symmetry_order: Some(symmetry_order),
            ..Self::default()
        }
    }

    /// Half the side of the gradients' grid, m: the farthest an object's border may reach
    /// from its centroid to be learned.
    pub fn grid_half_extent_m(&self) -> f64 {
        self.learner.cell_size_m * GRID_SIDE as f64 / 2.0
    }
}

impl Default for LearningConfig {
    /// The paper's alphas, the symmetry order learned from S, [`ContactMethod::HeadingLine`],
    /// 8192 points per buffer, trials under 60 % inliers rejected, approach points added to
    /// S, border points thinned to 1.5 mm apart.
    fn default() -> Self {
        Self {
            learner: LearnerConfig::default(),
            matcher: ShapeMatcherConfig::default(),
            symmetry_order: None,
            contact_method: ContactMethod::default(),
            point_capacity: 8192,
            min_inlier_fraction: 0.6,
            approach_refines_shape: true,
            border_spacing_m: 0.0015,
        }
    }
}

/// Why a [`LearningSession`] could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SessionBuildError {
    /// The learner's config was refused.
    #[error(transparent)]
    Learner(#[from] LearnerBuildError),
    /// A field of the session's config is out of range.
    #[error("learning config: `{field}` is {value}, {expected}")]
    BadConfig {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What it should be.
        expected: &'static str,
    },
}

/// Why the shape could not be learned from a circling.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeLearnError {
    /// No shape circling was under way.
    #[error(transparent)]
    Order(#[from] TrialOrderError),
    /// The circling gave fewer border points than the matcher needs.
    #[error("the circling gave {found} border points, at least {needed} needed")]
    TooFewPoints {
        /// Points collected.
        found: usize,
        /// Points needed.
        needed: usize,
    },
    /// A border point could not be learned.
    #[error(transparent)]
    Sample(#[from] SampleAddError),
    /// The learned S gives no border to match against.
    #[error(transparent)]
    Matcher(#[from] ShapeMatcherBuildError),
    /// The border seen while circling reaches beyond the gradients' grid: the object is too
    /// large to learn.
    #[error(
        "the border seen reaches {:.0} mm from the centroid, the gradient's grid only {:.0} mm: the object is too large to learn",
        reach_m * 1e3,
        grid_half_extent_m * 1e3
    )]
    TooLarge {
        /// Distance of the farthest border point seen from the centroid, m.
        reach_m: f64,
        /// Half the grid's side, m.
        grid_half_extent_m: f64,
    },
}

/// Why a trial could not start.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TrialStartError {
    /// The shape must be learned first (a circling at the known pose).
    #[error("no shape learned yet: circle the object at its known pose first")]
    NoShape,
    /// The alpha is not one the session learns.
    #[error("alpha {0} deg is not one of the learned alphas")]
    UnknownAlpha(f64),
}

/// Why a trial taught nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrialLearnError {
    /// The trial's estimate failed.
    #[error(transparent)]
    Finish(#[from] TrialFinishError),
    /// The push could not be learned.
    #[error(transparent)]
    Sample(#[from] SampleAddError),
}

/// The learning phase of one object (the paper's section III-B) on the estimator's side:
/// a circling at the known start pose gives the shape S, then each trial (reset to the
/// known pose, approach, push, circle) gives a contact point, the object's new pose from
/// the circling, and so one push of the gradient (Algorithms 1, 2 and 4). The harness
/// (the planner, or a test) drives the robot and tells the session when contact was
/// inferred and when the push ended; the session sees only IR frames and odometry.
pub struct LearningSession {
    config: LearningConfig,
    learner: AffordanceLearner,
    matcher: Option<ShapeMatcher>,
    /// The combined S the matcher was built on.
    shape: Option<Grid>,
    recorder: TrialRecorder,
    contact_estimator: ContactEstimator,
    /// Border points added to each alpha's S (object frame), for thinning; same order as
    /// the config's alphas.
    shape_points: Vec<Vec<DVec2>>,
    /// The symmetry order the matcher uses: the config's, or learned from the shape
    /// circling's S.
    symmetry_order: Option<u32>,
    /// Radius of the border learned by the shape circling ([`learned_border_radius_m`]).
    border_radius_m: Option<f64>,
    trials_learned: usize,
    trials_rejected: usize,
}

impl LearningSession {
    /// A session learning `object_name`, seen by `robot`. Allocates every buffer here.
    pub fn new(
        object_name: &str,
        robot: &RobotDescription,
        config: LearningConfig,
    ) -> Result<Self, SessionBuildError> {
        let f = config.min_inlier_fraction;
        if !(f.is_finite() && (0.0..=1.0).contains(&f)) {
            return Err(SessionBuildError::BadConfig {
                field: "min_inlier_fraction",
                value: f,
                expected: "expected in [0, 1]",
            });
        }
        let d = config.border_spacing_m;
        if !(d.is_finite() && d >= 0.0) {
            return Err(SessionBuildError::BadConfig {
                field: "border_spacing_m",
                value: d,
                expected: "expected a finite length >= 0",
            });
        }
        if config.point_capacity < agp_affordance::MIN_MATCH_POINTS {
            return Err(SessionBuildError::BadConfig {
                field: "point_capacity",
                value: config.point_capacity as f64,
                expected: "expected at least the matcher's minimum of points",
            });
        }
        Ok(Self {
            learner: AffordanceLearner::new(object_name, &config.learner)?,
            matcher: None,
            shape: None,
            recorder: TrialRecorder::new(robot, config.point_capacity),
            contact_estimator: ContactEstimator::new(robot),
            shape_points: config
                .learner
                .alphas_deg
                .iter()
                .map(|_| Vec::with_capacity(config.point_capacity))
                .collect(),
            trials_learned: 0,
            trials_rejected: 0,
            symmetry_order: config.symmetry_order,
            border_radius_m: None,
            config,
        })
    }

    /// The session's config.
    pub fn config(&self) -> &LearningConfig {
        &self.config
    }

    /// The recorder of the current trial (its phase, points and contact).
    pub fn recorder(&self) -> &TrialRecorder {
        &self.recorder
    }

    /// The object's rotational symmetry order the matcher uses (0 a disc, 1 none): the
    /// config's, or once the shape is learned the one learned from its S.
    pub fn symmetry_order(&self) -> Option<u32> {
        self.symmetry_order
    }

    /// How far the border learned by the shape circling reaches from the centroid, m
    /// ([`learned_border_radius_m`] of its S): where pushes start is set from it. `None`
    /// before the shape is learned.
    pub fn border_radius_m(&self) -> Option<f64> {
        self.border_radius_m
    }

    /// The matcher against the learned shape, once the shape is learned.
    pub fn matcher(&self) -> Option<&ShapeMatcher> {
        self.matcher.as_ref()
    }

    /// The matcher against the learned shape, mutable (to match circlings of one's own).
    pub fn matcher_mut(&mut self) -> Option<&mut ShapeMatcher> {
        self.matcher.as_mut()
    }

    /// The gradients learned so far.
    pub fn gradient(&self) -> &AffordanceGradient {
        self.learner.gradient()
    }

    /// The gradients learned, ending the session.
    pub fn into_gradient(self) -> AffordanceGradient {
        self.learner.into_gradient()
    }

    /// Trials whose push was learned.
    pub fn trials_learned(&self) -> usize {
        self.trials_learned
    }

    /// Trials that ended without a push learned (no match, a poor match, no contact).
    pub fn trials_rejected(&self) -> usize {
        self.trials_rejected
    }

    /// Starts the circling that learns the shape, the object resting at the known
    /// `object_pose` (odometry frame).
    pub fn begin_shape_circling(&mut self, object_pose: Pose) {
        self.recorder.begin_shape_circling(object_pose);
    }

    /// Takes one IR frame (allocates nothing).
    pub fn observe(&mut self, view: &IrView) {
        self.recorder.observe(view, self.matcher.as_mut());
    }

    /// Ends the shape circling: its border points, moved into the object's frame by the
    /// known pose, go into the S of every alpha; the symmetry order (unless the config
    /// gives it) and the border's radius are learned from the combined S, and the matcher
    /// is built on it. Returns the number of border points. Fails with
    /// [`ShapeLearnError::TooLarge`] when a border point seen lies beyond the grid.
    pub fn finish_shape_circling(&mut self) -> Result<usize, ShapeLearnError> {
        self.recorder.end_shape_circling()?;
        let points = self.recorder.circle_points();
        let needed = agp_affordance::MIN_MATCH_POINTS;
        if points.len() < needed {
            return Err(ShapeLearnError::TooFewPoints {
                found: points.len(),
                needed,
            });
        }
        let object = self.recorder.object_start();
        let to_obj = DVec2::from_angle(-object.theta);
        let recorder = &self.recorder;
        let points = || {
            recorder
                .circle_points()
                .iter()
                .map(|&p| to_obj.rotate(p - object.position()))
        };
        let reach_m = points().map(|p| p.length()).fold(0.0, f64::max);
        let grid_half_extent_m = self.config.grid_half_extent_m();
        if reach_m.is_nan() || reach_m >= grid_half_extent_m {
            return Err(ShapeLearnError::TooLarge {
                reach_m,
                grid_half_extent_m,
            });
        }
        for k in 0..self.config.learner.alphas_deg.len() {
            add_shape_points(
                &mut self.learner,
                &mut self.shape_points[k],
                self.config.learner.alphas_deg[k],
                self.config.border_spacing_m,
                points(),
            )?;
        }
        let n = self.recorder.circle_points().len();
        let shape = self.learner.gradient().combined_shape();
        let order = *self
            .symmetry_order
            .get_or_insert_with(|| symmetry_order_of(&shape));
        self.border_radius_m = learned_border_radius_m(&shape);
        self.build_matcher(shape, order)?;
        Ok(n)
    }

    /// Rebuilds the matcher on the combined S learned so far (after approaches refined it),
    /// with the symmetry order of the shape circling.
    pub fn rebuild_matcher(&mut self) -> Result<(), ShapeMatcherBuildError> {
        let shape = self.learner.gradient().combined_shape();
        let order = match self.symmetry_order {
            Some(k) => k,
            None => *self.symmetry_order.insert(symmetry_order_of(&shape)),
        };
        self.build_matcher(shape, order)
    }

    fn build_matcher(&mut self, shape: Grid, order: u32) -> Result<(), ShapeMatcherBuildError> {
        let config = ShapeMatcherConfig {
            symmetry_order: order,
            ..self.config.matcher.clone()
        };
        self.matcher = Some(ShapeMatcher::new(&shape, config)?);
        self.shape = Some(shape);
        Ok(())
    }

    /// Starts a trial at `alpha_deg`, the object put back at the known `object_pose`
    /// (odometry frame).
    pub fn begin_trial(
        &mut self,
        alpha_deg: f64,
        object_pose: Pose,
    ) -> Result<(), TrialStartError> {
        if self.matcher.is_none() {
            return Err(TrialStartError::NoShape);
        }
        if self.learner.gradient().push_count(alpha_deg).is_none() {
            return Err(TrialStartError::UnknownAlpha(alpha_deg));
        }
        self.recorder.begin_trial(alpha_deg, object_pose);
        Ok(())
    }

    /// Contact was inferred at frame `view`: the contact point by every method (object
    /// frame).
    pub fn infer_contact(&mut self, view: &IrView) -> Result<ContactEstimates, TrialOrderError> {
        match (&self.matcher, &self.shape) {
            (Some(m), Some(shape)) => self.recorder.infer_contact(
                view,
                LearnedShape {
                    border: m.border_points(),
                    shape,
                },
            ),
            _ => Err(TrialOrderError {
                call: "infer_contact",
                phase: self.recorder.phase(),
            }),
        }
    }

    /// The push ended at frame `view`; the circling starts.
    pub fn end_push(&mut self, view: &IrView) -> Result<(), TrialOrderError> {
        self.recorder.end_push(view)
    }

    /// Abandons the trial under way (e.g. the approach timed out); counted as rejected.
    pub fn abandon_trial(&mut self) {
        if self.recorder.phase() != TrialPhase::Idle {
            self.trials_rejected += 1;
        }
        self.recorder.abandon();
    }

    /// Ends the trial after its circling: estimates the object's new pose and learns the
    /// push (and, if configured, the approach's border points into that alpha's S).
    pub fn finish_trial(&mut self) -> Result<TrialRecord, TrialLearnError> {
        let Some(matcher) = self.matcher.as_mut() else {
            return Err(TrialFinishError::Order(TrialOrderError {
                call: "finish_trial",
                phase: self.recorder.phase(),
            })
            .into());
        };
        let record = match self.recorder.finish_trial(
            matcher,
            self.config.contact_method,
            self.config.min_inlier_fraction,
        ) {
            Ok(r) => r,
            Err(e) => {
                self.trials_rejected += 1;
                return Err(e.into());
            }
        };
        self.learner.add_push(record.alpha_deg, &record.outcome)?;
        if self.config.approach_refines_shape
            && let Some(k) = self
                .config
                .learner
                .alphas_deg
                .iter()
                .position(|&a| (a - record.alpha_deg).abs() < 1e-6)
        {
            add_shape_points(
                &mut self.learner,
                &mut self.shape_points[k],
                record.alpha_deg,
                self.config.border_spacing_m,
                self.recorder.approach_points().iter().copied(),
            )?;
        }
        self.trials_learned += 1;
        Ok(record)
    }

    /// The contact point by every method for a robot at frame `view` and the object at
    /// `object_pose` (odometry frame), against the learned shape: what a planner asks
    /// before predicting a push. `None` before the shape is learned.
    pub fn contact_estimates(&self, view: &IrView, object_pose: Pose) -> Option<ContactEstimates> {
        let (m, shape) = (self.matcher.as_ref()?, self.shape.as_ref()?);
        Some(self.contact_estimator.estimate(
            view.odometry,
            &view.ir_raw,
            object_pose,
            LearnedShape {
                border: m.border_points(),
                shape,
            },
        ))
    }
}

/// Adds `points` (object frame) to the S of alpha `alpha_deg`, each unless a point of
/// `added` (the points added to it before) lies closer than `spacing` (m).
fn add_shape_points(
    learner: &mut AffordanceLearner,
    added: &mut Vec<DVec2>,
    alpha_deg: f64,
    spacing: f64,
    points: impl Iterator<Item = DVec2>,
) -> Result<(), SampleAddError> {
    let spacing2 = spacing * spacing;
    for p in points {
        if spacing2 > 0.0 && added.iter().any(|q| q.distance_squared(p) < spacing2) {
            continue;
        }
        learner.add_border_point(alpha_deg, p)?;
        added.push(p);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds `s` a shape circling of a square of half side `h` (m) centred at the origin:
    /// 60 points per side, each read by IR1 from 20 mm.
    fn circle_square(s: &mut LearningSession, robot: &RobotDescription, h: f64) {
        s.begin_shape_circling(Pose::default());
        let mut k = 0;
        for side in 0..4 {
            for t in 0..60 {
                let u = -h + 2.0 * h * f64::from(t) / 60.0;
                let p = match side {
                    0 => DVec2::new(u, -h),
                    1 => DVec2::new(h, u),
                    2 => DVec2::new(-u, h),
                    _ => DVec2::new(-h, -u),
                };
                // A robot facing the point from 20 mm, reading it with its IR1.
                let sensor = &robot.ir_sensors[0];
                let dir = p.normalize();
                let heading = dir.to_angle() - sensor.angle_rad;
                let mount = DVec2::from_angle(heading).rotate(sensor.mount);
                let origin = p - DVec2::from_angle(heading + sensor.angle_rad) * 0.02 - mount;
                let mut raw = [0f32; 8];
                raw[0] = robot.response.reading(0.02) as f32;
                k += 1;
                s.observe(&IrView::new(k, raw, Pose::new(origin.x, origin.y, heading)));
            }
        }
    }

    #[test]
    fn a_trial_before_the_shape_or_at_an_unknown_alpha_is_refused() {
        let robot = RobotDescription::epuck();
        let mut s =
            LearningSession::new("square", &robot, LearningConfig::for_symmetry(4)).expect("valid");
        assert_eq!(
            s.begin_trial(0.0, Pose::default()),
            Err(TrialStartError::NoShape)
        );
        // A shape from points on a 60 mm square, seen from its known pose.
        circle_square(&mut s, &robot, 0.03);
        assert_eq!(s.finish_shape_circling(), Ok(240));
        let border = s.matcher().expect("built").border_points();
        assert!(border.len() > 100, "{} ridge points", border.len());
        // Distance of each ridge point to the square's border: on the faces within the
        // matching's precision; the ridge cuts the corners by a few millimetres.
        let mut d: Vec<f64> = border
            .iter()
            .map(|b| {
                let q = b.abs() - DVec2::splat(0.03);
                if q.x > 0.0 && q.y > 0.0 {
                    q.length()
                } else {
                    q.x.max(q.y).abs()
                }
            })
            .collect();
        d.sort_by(f64::total_cmp);
        assert!(d[d.len() / 2] < 3e-4, "median {} m", d[d.len() / 2]);
        assert!(d[d.len() - 1] < 4e-3, "worst {} m", d[d.len() - 1]);
        assert_eq!(
            s.begin_trial(7.0, Pose::default()),
            Err(TrialStartError::UnknownAlpha(7.0))
        );
        assert_eq!(s.begin_trial(15.0, Pose::default()), Ok(()));
    }

    #[test]
    fn a_config_out_of_range_is_refused() {
        let robot = RobotDescription::epuck();
        let bad = LearningConfig {
            min_inlier_fraction: 1.5,
            ..LearningConfig::for_symmetry(1)
        };
        assert!(matches!(
            LearningSession::new("l", &robot, bad),
            Err(SessionBuildError::BadConfig {
                field: "min_inlier_fraction",
                ..
            })
        ));
        let bad = LearningConfig {
            border_spacing_m: f64::NAN,
            ..LearningConfig::for_symmetry(1)
        };
        assert!(LearningSession::new("l", &robot, bad).is_err());
    }

    #[test]
    fn the_symmetry_and_the_border_radius_are_learned_from_the_shape_circling() {
        let robot = RobotDescription::epuck();
        let mut s =
            LearningSession::new("square", &robot, LearningConfig::default()).expect("valid");
        assert_eq!((s.symmetry_order(), s.border_radius_m()), (None, None));
        circle_square(&mut s, &robot, 0.03);
        assert_eq!(s.finish_shape_circling(), Ok(240));
        // A square is 4-fold symmetric; its corners lie 42.4 mm from the centre: the
        // farthest ridge point of S lies there within 2 mm (measured 43.8 mm: the Gaussians
        // of two faces add up just outside a corner).
        assert_eq!(s.symmetry_order(), Some(4));
        assert_eq!(s.matcher().expect("built").config().symmetry_order, 4);
        let r = s.border_radius_m().expect("a border");
        assert!(
            (r - 0.03 * 2f64.sqrt()).abs() <= 0.002,
            "border radius {r} m"
        );
    }

    #[test]
    fn a_border_seen_beyond_the_grid_is_refused_as_too_large() {
        let robot = RobotDescription::epuck();
        let mut s = LearningSession::new("huge", &robot, LearningConfig::default()).expect("valid");
        // A 300 mm square: its corners lie 212 mm out, the grid holds 128 mm.
        circle_square(&mut s, &robot, 0.15);
        match s.finish_shape_circling() {
            Err(ShapeLearnError::TooLarge {
                reach_m,
                grid_half_extent_m,
            }) => {
                assert!((reach_m - 0.15 * 2f64.sqrt()).abs() < 0.01, "{reach_m}");
                assert!((grid_half_extent_m - 0.128).abs() < 1e-9);
            }
            other => panic!("not refused as too large: {other:?}"),
        }
        assert!(s.matcher().is_none());
    }
}
