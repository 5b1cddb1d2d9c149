//! The learning phase of benchmarks.md section 1, run in-process, and its evaluation
//! (feature `learn-bench`; `agp bench learn` is its command).
//!
//! The physics runs in this process: `agp_physics::Sim`, the rapier2d world as a library,
//! not the physics process over shared memory. The protocol is the planner's
//! ([`LearnProtocol`], the one `agp-planner --mode learn` drives over the pipeline), run
//! against an in-process world: the simulator, and the estimator's learner
//! ([`ProtocolLearner`]) fed every frame and every event as the estimator process would
//! be; it sees only IR frames and odometry. The evaluation alone reads the simulator's
//! ground truth: the world records it as the protocol's events pass.
//!
//! Per object: one circling for the shape, then the trials, each starting from the object
//! at its start pose: the paper's protocol makes `trials_per_alpha` per alpha, one every
//! `360 / trials_per_alpha` degrees round the object; the active one `active_trials` in
//! all, each where the gradient learned so far is least sure (`agp_planning::run_active`); then `eval_pushes` unseen pushes from random contact points with a
//! random alpha in [-15, 15] deg, predicted by the learned gradient and compared with what
//! the simulator did.

use agp_shared_types::angle;
use std::f64::consts::TAU;
use std::time::Instant;

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, LearnerBuildError, PushOutcome, PushPredictor,
    SampleAddError,
};
use agp_physics::{Sim, SimBuildError, SimConfig};
use agp_planning::{
    ActiveSettings, ActiveTrialChooser, CircleSettings, LearnFrame, LearnProtocol,
    LearnProtocolError, LearnProtocolSettings, LearnWorld, ProtocolStep, PushSettings,
    SHAPE_APPROACH_TIMEOUT_S, run_active,
};
use agp_shared_types::angle::wrap_angle;
use agp_shared_types::{LearnEvent, LearnEventKind, LearnReport, LearnReportKind};
use agp_world::{ObjectShape, Pose, Rng, RobotDescription, Scenario};
use glam::DVec2;

use agp_perception::{
    ContactEstimates, ContactMethod, IrView, LearnProblem, LearningConfig, ObjectTracker,
    ProtocolLearner, SessionBuildError, ShapeLearnError, TrackerConfig, TrialOrderError,
    TrialRecord, TrialStartError,
};

/// The paper's largest single-push rotations for the triangle, degrees, per alpha.
pub const PAPER_TRIANGLE_MAX_ROTATION_DEG: [(f64, f64); 3] =
    [(0.0, 39.51), (15.0, 59.06), (-15.0, 79.78)];

/// The unseen pushes benchmarks.md asks for, at least.
pub const MIN_EVAL_PUSHES: usize = 200;
/// Target: median rotation error of unseen pushes, degrees.
pub const TARGET_ROTATION_ERROR_DEG: f64 = 5.0;
/// Target: median displacement error as a fraction of the true displacement.
pub const TARGET_DISPLACEMENT_ERROR_RATIO: f64 = 0.20;
/// Target: median position error of the pose from one circling, mm.
pub const TARGET_POSE_POSITION_MM: f64 = 5.0;
/// Target: median orientation error of the pose from one circling, degrees.
pub const TARGET_POSE_ORIENTATION_DEG: f64 = 5.0;

/// Alphas of the paper's protocol (0, +15, -15 deg).
const ALPHAS_IN_PAPER: usize = 3;
/// Longest push this bench accepts, seconds.
const MAX_PUSH_DURATION_S: f64 = 10.0;
/// Stream of the evaluation's random pushes (the simulator's noise uses others).
const EVAL_RNG_STREAM: u64 = 99;

/// Where the learning trials are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TrialProtocol {
    /// The paper's: `trials_per_alpha` starts evenly round the object per alpha.
    #[default]
    Paper,
    /// Each next trial where the gradient learned so far is least sure
    /// ([`ActiveTrialChooser`]), `active_trials` in all.
    Active,
}

impl TrialProtocol {
    /// Its name on the command line and in the JSON: `paper`, `active`.
    pub fn name(self) -> &'static str {
        match self {
            TrialProtocol::Paper => "paper",
            TrialProtocol::Active => "active",
        }
    }
}

/// How the learning phase and its evaluation are run.
#[derive(Debug, Clone)]
pub struct LearnBenchConfig {
    /// Seed of the simulator's noise and of the evaluation's random pushes.
    pub seed: u64,
    /// Alphas of the trials, degrees.
    pub alphas_deg: Vec<f64>,
    /// Where the trials are made.
    pub protocol: TrialProtocol,
    /// Trials per alpha, evenly spread round the object (60: one every 6 deg), for the
    /// paper's protocol.
    pub trials_per_alpha: usize,
    /// Trials in all, for the active protocol.
    pub active_trials: usize,
    /// How the active protocol scores its candidates.
    pub active: ActiveSettings,
    /// Unseen pushes of the prediction check.
    pub eval_pushes: usize,
    /// Approach and push. The default pushes for 0.5 s at 100 mm/s (about 40 mm): the
    /// push duration is the one free parameter of the protocol, and 0.5 s gives the
    /// paper's largest A0 rotation of the triangle (39.51 deg) within a degree; 1 s gives
    /// 54 deg, the planner's default of 2 s 77 deg and up to 121 deg at alpha 15.
    pub push: PushSettings,
    /// The circling after each push (and the shape circling).
    pub circle: CircleSettings,
    /// Robot start: on a circle this far (m) outside the learned border's farthest point
    /// plus the robot's radius.
    pub start_margin_m: f64,
    /// After a push the robot backs off this long (s) at `backoff_speed` before circling.
    pub backoff_s: f64,
    /// Reverse speed of the back-off, m/s.
    pub backoff_speed: f64,
    /// The contact point the session's gradient is keyed by.
    pub contact_method: ContactMethod,
    /// Whether approach points refine S.
    pub approach_refines_shape: bool,
}

impl Default for LearnBenchConfig {
    /// The learning protocol's defaults ([`LearnProtocolSettings::default`]), seed 7,
    /// [`MIN_EVAL_PUSHES`] unseen pushes.
    fn default() -> Self {
        let p = LearnProtocolSettings::default();
        Self {
            seed: 7,
            alphas_deg: p.alphas_deg,
            protocol: TrialProtocol::Paper,
            trials_per_alpha: p.trials_per_alpha as usize,
            active_trials: p.trials_per_alpha as usize * ALPHAS_IN_PAPER / 2,
            active: ActiveSettings::default(),
            eval_pushes: MIN_EVAL_PUSHES,
            push: p.push,
            circle: p.circle,
            start_margin_m: p.start_margin_m,
            backoff_s: p.backoff_s,
            backoff_speed: p.backoff_speed,
            contact_method: ContactMethod::default(),
            approach_refines_shape: true,
        }
    }
}

impl LearnBenchConfig {
    /// Trials of the learning phase in all.
    pub fn total_trials(&self) -> usize {
        match self.protocol {
            TrialProtocol::Paper => self.alphas_deg.len() * self.trials_per_alpha,
            TrialProtocol::Active => self.active_trials,
        }
    }

    /// The protocol these settings run (the active protocol's trials per alpha: its trials
    /// in all over the alphas, rounded up, which only the events' `total` shows).
    pub fn protocol(&self) -> LearnProtocolSettings {
        let per_alpha = match self.protocol {
            TrialProtocol::Paper => self.trials_per_alpha,
            TrialProtocol::Active => self.active_trials.div_ceil(self.alphas_deg.len().max(1)),
        };
        LearnProtocolSettings {
            alphas_deg: self.alphas_deg.clone(),
            trials_per_alpha: u32::try_from(per_alpha).unwrap_or(u32::MAX),
            push: self.push,
            circle: self.circle,
            start_margin_m: self.start_margin_m,
            backoff_s: self.backoff_s,
            backoff_speed: self.backoff_speed,
            ..LearnProtocolSettings::default()
        }
    }

    /// Steps [`run_object`] reports progress in: the shape circling, every trial and every
    /// unseen push.
    pub fn progress_total(&self) -> usize {
        1 + self.total_trials() + self.eval_pushes
    }

    fn validate(&self) -> Result<(), LearnBenchError> {
        let bad = |field: &'static str, value: String, expected: &'static str| {
            Err(LearnBenchError::Config {
                field,
                value,
                expected,
            })
        };
        if self.alphas_deg.is_empty() {
            return bad("alphas_deg", "empty".into(), "at least one alpha");
        }
        if let Some(a) = self
            .alphas_deg
            .iter()
            .find(|a| !(a.is_finite() && a.abs() <= 45.0))
        {
            return bad("alphas_deg", format!("{a}"), "within [-45, 45] deg");
        }
        if self.total_trials() == 0 {
            return bad("trials", "0".into(), "at least 1");
        }
        if self.protocol == TrialProtocol::Active && self.active.starts_per_alpha == 0 {
            return bad("active.starts_per_alpha", "0".into(), "at least 1");
        }
        let d = self.push.push_duration;
        if !(d.is_finite() && d > 0.0 && d <= MAX_PUSH_DURATION_S) {
            return bad("push.push_duration", format!("{d} s"), "in (0, 10] s");
        }
        for (field, v) in [
            ("start_margin_m", self.start_margin_m),
            ("backoff_s", self.backoff_s),
            ("backoff_speed", self.backoff_speed),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("{v}"), "a finite number >= 0");
            }
        }
        Ok(())
    }
}

/// Why the learning bench could not run an object. Misses of the targets are not errors:
/// they are in the report ([`ObjectReport::targets`]).
#[derive(Debug, thiserror::Error)]
pub enum LearnBenchError {
    /// A field of [`LearnBenchConfig`] is out of range.
    #[error("learn bench config: `{field}` is {value}, expected {expected}")]
    Config {
        /// The field.
        field: &'static str,
        /// Its value.
        value: String,
        /// What it should be.
        expected: &'static str,
    },
    /// The object reaches beyond the gradient's grid, so its border cannot be learned.
    #[error(
        "`{object}` is too large to learn: it reaches {radius_mm:.0} mm from its centroid, the affordance gradient's grid only {max_mm:.0} mm"
    )]
    ObjectTooLarge {
        /// The scenario's name.
        object: String,
        /// Distance of the object's farthest point from its centroid, mm.
        radius_mm: f64,
        /// Half the grid's side, mm.
        max_mm: f64,
    },
    /// The simulator refused the scenario.
    #[error("cannot simulate `{object}`: {source}")]
    Sim {
        /// The scenario's name.
        object: String,
        /// The cause.
        source: SimBuildError,
    },
    /// The learning session refused its config (the alphas, or the object's symmetry).
    #[error("cannot learn `{object}`: {source}")]
    Session {
        /// The scenario's name.
        object: String,
        /// The cause.
        source: SessionBuildError,
    },
    /// A gradient for the evaluation's comparisons could not be built.
    #[error("cannot learn `{object}`: {source}")]
    Learner {
        /// The scenario's name.
        object: String,
        /// The cause.
        source: LearnerBuildError,
    },
    /// A stop signal arrived (`agp bench`, see `crate::stop`): the object's learning ended
    /// unfinished.
    #[error("`{object}`: stopped by a signal before it was learned")]
    Stopped {
        /// The scenario's name.
        object: String,
    },
    /// The robot, approaching for the shape circling, never saw the object.
    #[error(
        "`{object}`: the robot approached for {SHAPE_APPROACH_TIMEOUT_S} s and its IR never saw the object"
    )]
    ShapeApproach {
        /// The scenario's name.
        object: String,
    },
    /// The shape circling gave no shape to match poses against.
    #[error("`{object}`: the shape circling gave no usable shape: {source}")]
    Shape {
        /// The scenario's name.
        object: String,
        /// The cause.
        source: ShapeLearnError,
    },
    /// A trial could not start (an alpha the session does not know).
    #[error("`{object}`: cannot start a trial: {source}")]
    TrialStart {
        /// The scenario's name.
        object: String,
        /// The cause.
        source: TrialStartError,
    },
    /// The session saw a trial's events out of order.
    #[error("`{object}`: {source}")]
    TrialOrder {
        /// The scenario's name.
        object: String,
        /// The cause.
        source: TrialOrderError,
    },
    /// The protocol stopped otherwise (the learner answered no report, a shape without a
    /// border).
    #[error("`{object}`: the learning protocol stopped: {reason}")]
    Protocol {
        /// The scenario's name.
        object: String,
        /// Why.
        reason: String,
    },
}

/// What [`run_object`] is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LearnStage {
    /// Circling the object once for its shape.
    ShapeCircling,
    /// Learning trials.
    Trials,
    /// Unseen pushes of the prediction check.
    Evaluation,
}

/// Progress of [`run_object`]: `done` of `total` steps (the shape circling, each trial,
/// each unseen push; see [`LearnBenchConfig::progress_total`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LearnProgress {
    /// The stage under way.
    pub stage: LearnStage,
    /// Steps done.
    pub done: usize,
    /// Steps in all.
    pub total: usize,
}

/// Ground truth of one push, object frame before the push.
#[derive(Debug, Clone, Copy)]
struct PushTruth {
    /// Where the robot's disc first touched the object.
    touch_obj: Option<DVec2>,
    /// Where the robot's heading line met the object at that moment.
    aim_obj: Option<DVec2>,
    /// The robot's heading at that moment (unit).
    heading_obj: Option<DVec2>,
    /// Displacement of the centroid.
    displacement_obj: DVec2,
    /// Rotation, rad.
    rotation_rad: f64,
    /// The object's pose after the push (world frame).
    after: Pose,
}

/// One learning trial: what the estimator made of it, and the truth.
#[derive(Debug, Clone, Copy)]
struct TrialOutcome {
    alpha_deg: f64,
    record: Option<TrialRecord>,
    truth: PushTruth,
}

/// Median and 90th percentile of a sample.
#[derive(Debug, Clone, Copy, Default)]
pub struct Spread {
    /// Values.
    pub n: usize,
    /// Median (NaN without values).
    pub median: f64,
    /// 90th percentile (NaN without values).
    pub p90: f64,
}

impl Spread {
    /// The spread of `values` (sorted in place).
    pub fn of(values: &mut [f64]) -> Self {
        if values.is_empty() {
            return Self {
                n: 0,
                median: f64::NAN,
                p90: f64::NAN,
            };
        }
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
        Self {
            n: values.len(),
            median: at(0.5),
            p90: at(0.9),
        }
    }
}

/// How well a gradient predicts the unseen pushes.
#[derive(Debug, Clone, Copy, Default)]
pub struct PredictionStats {
    /// Pushes evaluated (contact made).
    pub pushes: usize,
    /// Pushes the gradient had no prediction for: no contact point to key it by, or no
    /// evidence within [`NEAREST_EVIDENCE_M`] of it.
    pub unpredicted: usize,
    /// Pushes predicted from the nearest point with evidence, the aim point having too
    /// little ([`PushPredictor::predict_push_nearest`]); counted in the errors.
    pub from_nearest: usize,
    /// Pushes whose heading line met no learned border (the robot's disc grazed the
    /// object beside it), keyed instead by where the body sweep says the disc touched
    /// first; predicted from the nearest evidence like the others, counted in the errors.
    pub keyed_by_touch: usize,
    /// |predicted - true displacement|, mm.
    pub displacement_error_mm: Spread,
    /// The same as a fraction of the true displacement.
    pub displacement_error_ratio: Spread,
    /// |predicted - true rotation|, deg (no values for a disc).
    pub rotation_error_deg: Spread,
    /// True displacement, mm.
    pub true_displacement_mm: Spread,
    /// True |rotation|, deg.
    pub true_rotation_abs_deg: Spread,
}

/// Everything measured on one object.
#[derive(Debug, Clone)]
pub struct ObjectReport {
    /// The scenario's name.
    pub name: String,
    /// Rotational symmetry of the object (0 for a disc, 1 for none).
    pub symmetry_order: u32,
    /// Alphas of the trials, degrees.
    pub alphas_deg: Vec<f64>,
    /// How long each push lasted, s.
    pub push_duration_s: f64,
    /// Border points of the shape circling.
    pub shape_points: usize,
    /// The symmetry order learned from the shape circling's S (what the matcher used).
    pub learned_symmetry_order: Option<u32>,
    /// Radius of the border learned by the shape circling, mm: the start circle's is this
    /// plus the robot's radius and the start margin.
    pub learned_border_radius_mm: f64,
    /// How far the object moved during the shape circling (it should not), mm.
    pub shape_circling_moved_object_mm: f64,
    /// Trials run.
    pub trials: usize,
    /// Trials learned into the gradient.
    pub learned: usize,
    /// Per alpha (degrees), the trials that pushed the object and circled it.
    pub pushed_by_alpha: Vec<(f64, usize)>,
    /// Trials whose push never touched the object.
    pub no_contact: usize,
    /// Trials the session refused (no pose match, say).
    pub rejected: usize,
    /// Circlings after a trial that did not close their lap.
    pub circle_timeouts: usize,
    /// (alpha, largest |rotation| in the learned AG, the true largest), degrees.
    pub max_rotation_deg: Vec<(f64, f64, f64)>,
    /// Pose from one circling: position error (mm).
    pub pose_position_mm: Spread,
    /// Orientation error modulo the symmetry (deg); `None` for a disc.
    pub pose_orientation_deg: Option<Spread>,
    /// Learned rotations whose symmetric branch was resolved wrongly (off by more than
    /// a quarter period from the truth).
    pub wrong_branch: usize,
    /// Error of the learned rotation against the true one, deg (orientation after the
    /// branch was resolved).
    pub learned_rotation_error_deg: Spread,
    /// Contact point errors (mm) per method: FrontIrMean and BodySweep against the true
    /// touch point, HeadingLine against the true aim point.
    pub contact_error_mm: Vec<(ContactMethod, Spread)>,
    /// Prediction of unseen pushes by the session's gradient.
    pub prediction: PredictionStats,
    /// Unseen pushes tried; those that touched nothing were tried again elsewhere.
    pub eval_attempts: usize,
    /// The same with gradients keyed by each method (learned from the same trials).
    pub prediction_by_method: Vec<(ContactMethod, PredictionStats)>,
    /// The same with a gradient learned from the truth (true aim points and effects of
    /// the same trials), queried at the true aim points: the representation's own limit.
    pub prediction_truth_learned: PredictionStats,
    /// Rotation error of the session's gradient for pushes whose alpha lies within
    /// 0-2.5, 2.5-5 and over 5 deg of the nearest learned alpha.
    pub rotation_error_by_alpha_gap_deg: [Spread; 3],
    /// The matcher's border (S of the first circling) against the true border.
    pub initial_shape: ShapeQuality,
    /// The border of the final combined S (what the AG file carries).
    pub final_shape: ShapeQuality,
    /// Simulated time of the shape circling and the trials, s.
    pub learning_sim_time_s: f64,
    /// Wall time of the same, s.
    pub learning_wall_s: f64,
    /// Simulated time of the unseen pushes, s.
    pub eval_sim_time_s: f64,
    /// Wall time of the same, s.
    pub eval_wall_s: f64,
    /// The learned gradient.
    pub gradient: AffordanceGradient,
}

/// One target of the learning issue, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetCheck {
    /// What is measured, with its limit: "median rotation error <= 5 deg".
    pub what: String,
    /// The measured value as text, with its unit.
    pub measured: String,
    /// Whether the target is met (a missing measurement is a miss).
    pub met: bool,
}

impl ObjectReport {
    /// The learning issue's targets on this object: at least 200 unseen pushes, each
    /// predicted; median rotation error <= 5 deg (not for a disc, whose orientation IR
    /// cannot see); median displacement error <= 0.2 of the true displacement; pose from
    /// one circling within 5 mm and 5 deg (medians; orientation modulo the symmetry, not
    /// for a disc).
    pub fn targets(&self) -> Vec<TargetCheck> {
        let p = &self.prediction;
        let mut out = vec![
            TargetCheck {
                what: format!("unseen pushes >= {MIN_EVAL_PUSHES}"),
                measured: format!("{}", p.pushes),
                met: p.pushes >= MIN_EVAL_PUSHES,
            },
            TargetCheck {
                what: "every unseen push predicted".into(),
                measured: format!("{} without a prediction", p.unpredicted),
                met: p.unpredicted == 0 && p.pushes > 0,
            },
        ];
        if self.symmetry_order != 0 {
            out.push(TargetCheck {
                what: format!("median rotation error <= {TARGET_ROTATION_ERROR_DEG} deg"),
                measured: format!("{:.2} deg", p.rotation_error_deg.median),
                met: within(p.rotation_error_deg.median, TARGET_ROTATION_ERROR_DEG),
            });
        }
        out.push(TargetCheck {
            what: format!(
                "median displacement error <= {TARGET_DISPLACEMENT_ERROR_RATIO} of the true displacement"
            ),
            // Four decimals: a miss by less than 0.0005 must not read as the limit itself.
            measured: format!("{:.4}", p.displacement_error_ratio.median),
            met: within(
                p.displacement_error_ratio.median,
                TARGET_DISPLACEMENT_ERROR_RATIO,
            ),
        });
        out.push(TargetCheck {
            what: format!("median pose position error <= {TARGET_POSE_POSITION_MM} mm"),
            measured: format!("{:.2} mm", self.pose_position_mm.median),
            met: within(self.pose_position_mm.median, TARGET_POSE_POSITION_MM),
        });
        if let Some(o) = &self.pose_orientation_deg {
            out.push(TargetCheck {
                what: format!("median pose orientation error <= {TARGET_POSE_ORIENTATION_DEG} deg"),
                measured: format!("{:.2} deg", o.median),
                met: within(o.median, TARGET_POSE_ORIENTATION_DEG),
            });
        }
        out
    }
}

/// Whether `value` is a number no larger than `max` (a NaN median, from no sample, is not).
fn within(value: f64, max: f64) -> bool {
    value.is_finite() && value <= max
}

/// A learned border (ridge points of S) against the true one.
#[derive(Debug, Clone, Copy, Default)]
pub struct ShapeQuality {
    /// Ridge points.
    pub points: usize,
    /// Distance of the ridge points to the true border, mm.
    pub error_mm: Spread,
    /// Fraction of the true border (sampled every mm) within 2 mm of a ridge point.
    pub coverage: f64,
}

fn shape_quality(shape: &ObjectShape, ridge: &[DVec2]) -> ShapeQuality {
    let mut err: Vec<f64> = ridge
        .iter()
        .map(|&p| (nearest_border_point(shape, p) - p).length() * 1e3)
        .collect();
    let border: Vec<DVec2> = match shape {
        ObjectShape::Circle { radius } => {
            let n = (TAU * radius / 0.001).ceil() as usize;
            (0..n)
                .map(|k| DVec2::from_angle(TAU * k as f64 / n as f64) * *radius)
                .collect()
        }
        ObjectShape::Polygon(poly) => poly
            .edges()
            .flat_map(|(a, b)| {
                let n = ((b - a).length() / 0.001).ceil() as usize;
                (0..n).map(move |k| a + (b - a) * (k as f64 / n as f64))
            })
            .collect(),
    };
    let covered = border
        .iter()
        .filter(|&&b| {
            ridge
                .iter()
                .any(|&p| p.distance_squared(b) <= 0.002 * 0.002)
        })
        .count();
    ShapeQuality {
        points: ridge.len(),
        error_mm: Spread::of(&mut err),
        coverage: covered as f64 / border.len().max(1) as f64,
    }
}

/// Point on the shape's border nearest to `p` (object frame).
fn nearest_border_point(shape: &ObjectShape, p: DVec2) -> DVec2 {
    match shape {
        ObjectShape::Circle { radius } => p.normalize_or(DVec2::X) * *radius,
        ObjectShape::Polygon(poly) => poly
            .edges()
            .map(|(a, b)| {
                let ab = b - a;
                let t = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
                a + ab * t
            })
            .min_by(|a, b| a.distance_squared(p).total_cmp(&b.distance_squared(p)))
            .unwrap_or(p),
    }
}

/// First crossing of the ray `origin + t dir` with the shape's border (object frame).
fn ray_hit(shape: &ObjectShape, origin: DVec2, dir: DVec2) -> Option<DVec2> {
    let t = match shape {
        ObjectShape::Polygon(poly) => poly.ray_cast(origin, dir, 1.0)?,
        ObjectShape::Circle { radius } => {
            let b = origin.dot(dir);
            let c = origin.length_squared() - radius * radius;
            let disc = b * b - c;
            if disc < 0.0 {
                return None;
            }
            let t = -b - disc.sqrt();
            if t < 0.0 {
                return None;
            }
            t
        }
    };
    Some(origin + dir * t)
}

fn view(sim: &Sim) -> IrView {
    let s = sim.sensors();
    IrView::new(s.ir_sample, s.ir_raw, s.odometry)
}

/// The protocol's world in this process: the simulator, and the estimator's learner fed
/// every frame and every event. It records the truth the evaluation needs as the events
/// pass: where the robot first touched the object in each push, the object's pose after
/// each trial's circling.
struct BenchWorld {
    name: String,
    sim: Sim,
    /// The estimator's perception: the front gap and its stall, as it publishes them.
    perception: ObjectTracker,
    learner: ProtocolLearner,
    /// The true shape, for the touch and aim points.
    shape: ObjectShape,
    object0: Pose,
    /// Reports not yet taken.
    reports: Vec<LearnReport>,
    sessions: u64,
    /// Between a push's start and its end: the first touch is recorded.
    watch_touch: bool,
    touch_obj: Option<DVec2>,
    aim_obj: Option<DVec2>,
    heading_obj: Option<DVec2>,
    /// The trial under way's alpha.
    trial_alpha: f64,
    trials: Vec<TrialOutcome>,
    no_contact: usize,
    circle_timeouts: usize,
    shape_points: usize,
    shape_circling_moved_object_mm: f64,
}

impl BenchWorld {
    /// A world of `sim` and `learner` before any push, the object at `object0`.
    fn new(
        name: &str,
        robot: &RobotDescription,
        sim: Sim,
        learner: ProtocolLearner,
        shape: ObjectShape,
        object0: Pose,
        cfg: &LearnBenchConfig,
    ) -> Self {
        BenchWorld {
            name: name.to_owned(),
            perception: ObjectTracker::new(robot, TrackerConfig::default()),
            sim,
            learner,
            shape,
            object0,
            reports: Vec::new(),
            sessions: 0,
            watch_touch: false,
            touch_obj: None,
            aim_obj: None,
            heading_obj: None,
            trial_alpha: f64::NAN,
            trials: Vec::with_capacity(cfg.total_trials()),
            no_contact: 0,
            circle_timeouts: 0,
            shape_points: 0,
            shape_circling_moved_object_mm: f64::NAN,
        }
    }

    /// The estimator's perception, fed the latest frame.
    fn perceive(&mut self) {
        let s = self.sim.sensors();
        self.perception
            .observe(s.ir_sample, &s.ir_raw, s.odometry, s.fix, s.fix_seq);
    }

    /// The gradient the learner's session holds so far.
    fn gradient(&self) -> Option<&AffordanceGradient> {
        self.learner.session().map(|s| s.gradient())
    }

    /// Starts watching for the first touch of a push.
    fn watch(&mut self) {
        self.watch_touch = true;
        self.touch_obj = None;
        self.aim_obj = None;
        self.heading_obj = None;
    }

    /// The bench's error for a problem of the learner that must not pass quietly.
    fn fatal(&self, problem: LearnProblem) -> Option<LearnBenchError> {
        let object = self.name.clone();
        match problem {
            LearnProblem::Shape { source, .. } => Some(LearnBenchError::Shape { object, source }),
            LearnProblem::TrialStart { source, .. } => {
                Some(LearnBenchError::TrialStart { object, source })
            }
            LearnProblem::Order { source, .. } => {
                Some(LearnBenchError::TrialOrder { object, source })
            }
            // A refused trial (no pose match, say) is counted in the report, not an error.
            LearnProblem::TrialRejected { .. } | LearnProblem::SessionRestarted { .. } => None,
        }
    }
}

impl LearnWorld for BenchWorld {
    type Error = LearnBenchError;

    fn frame(&self) -> LearnFrame {
        let s = self.sim.sensors();
        LearnFrame {
            step: self.sim.step_count(),
            sim_time_s: self.sim.sim_time(),
            ir_sample: s.ir_sample,
            ir_raw: s.ir_raw,
            odometry: s.odometry,
        }
    }

    fn front_gap(&self) -> Option<f64> {
        self.perception.front_gap()
    }

    fn stalled(&self) -> bool {
        self.perception.stalled()
    }

    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), LearnBenchError> {
        // A stop (`agp bench` got SIGINT, SIGTERM or SIGHUP) ends the learning here.
        if crate::stop::requested() {
            return Err(LearnBenchError::Stopped {
                object: self.name.clone(),
            });
        }
        self.sim.step(left_mps, right_mps);
        if self.watch_touch && self.touch_obj.is_none() && self.sim.in_contact() {
            let o = self.sim.object_pose();
            let rp = self.sim.robot_pose();
            let c = o.to_local(rp.position());
            self.touch_obj = Some(nearest_border_point(&self.shape, c));
            let d = DVec2::from_angle(rp.theta - o.theta);
            self.aim_obj = ray_hit(&self.shape, c, d);
            self.heading_obj = Some(d);
        }
        self.learner.observe(&view(&self.sim));
        self.perceive();
        Ok(())
    }

    fn reset(&mut self, object: Pose, robot: Pose) -> Result<(), LearnBenchError> {
        self.sim.reset(object, robot);
        // A new world, as the estimator sees it from the frame's reset count.
        self.perception.reset();
        self.learner.observe(&view(&self.sim));
        self.perceive();
        Ok(())
    }

    fn tell(&mut self, event: LearnEvent) -> Result<(), LearnBenchError> {
        let kind = LearnEventKind::from_u32(event.kind);
        match kind {
            Some(LearnEventKind::TrialBegin) => {
                self.trial_alpha = event.alpha_deg;
                self.watch();
            }
            Some(LearnEventKind::ShapeEnd) => {
                self.shape_circling_moved_object_mm =
                    (self.sim.object_pose().position() - self.object0.position()).length() * 1e3;
            }
            Some(LearnEventKind::PushEnd) => {
                self.watch_touch = false;
                if event.flag == 0 {
                    self.no_contact += 1;
                }
            }
            _ => {}
        }
        let reply = self
            .learner
            .handle(&event)
            .map_err(|source| LearnBenchError::Session {
                object: self.name.clone(),
                source,
            })?;
        if let Some(e) = reply.problem.and_then(|p| self.fatal(p)) {
            return Err(e);
        }
        if kind == Some(LearnEventKind::TrialEnd) && reply.report.is_some() {
            if event.flag == 0 {
                self.circle_timeouts += 1;
            }
            let after = self.sim.object_pose();
            self.trials.push(TrialOutcome {
                alpha_deg: self.trial_alpha,
                record: reply.record,
                truth: PushTruth {
                    touch_obj: self.touch_obj,
                    aim_obj: self.aim_obj,
                    heading_obj: self.heading_obj,
                    displacement_obj: self.object0.to_local(after.position()),
                    rotation_rad: wrap_angle(after.theta - self.object0.theta),
                    after,
                },
            });
        }
        if let Some(r) = reply.report {
            if r.kind == LearnReportKind::ShapeLearned as u32 {
                self.shape_points = r.value as usize;
            }
            self.reports.push(r);
        }
        if reply.finished {
            // Nothing to save in-process: the gradient stays in the learner.
            self.reports.push(self.learner.learned_report(0, true));
        }
        Ok(())
    }

    fn wait_report(&mut self, kinds: &[LearnReportKind]) -> Result<LearnReport, LearnBenchError> {
        let found = self
            .reports
            .iter()
            .position(|r| kinds.iter().any(|&k| k as u32 == r.kind));
        match found {
            Some(i) => {
                let r = self.reports[i];
                self.reports.drain(..=i);
                Ok(r)
            }
            None => Err(LearnBenchError::Protocol {
                object: self.name.clone(),
                reason: format!("the learner answered no {kinds:?} report"),
            }),
        }
    }

    fn new_session(&mut self) -> u64 {
        self.sessions += 1;
        self.sessions
    }
}

/// Checks, without running anything, what [`run_object`] checks before it starts: the
/// config, that the object fits the gradient's grid, that the simulator and the learning
/// session accept it. A command learning several objects calls this for each first, so
/// that a bad one fails before minutes of learning.
pub fn check_object(scenario: &Scenario, cfg: &LearnBenchConfig) -> Result<(), LearnBenchError> {
    setup(scenario, cfg).map(|_| ())
}

/// What a run starts from.
struct Setup {
    robot: RobotDescription,
    sim: Sim,
    learner: ProtocolLearner,
}

fn setup(scenario: &Scenario, cfg: &LearnBenchConfig) -> Result<Setup, LearnBenchError> {
    cfg.validate()?;
    let name = scenario.name.as_str();
    let robot = RobotDescription::epuck();
    let sim = Sim::new(
        scenario,
        &robot,
        SimConfig {
            seed: cfg.seed,
            ..SimConfig::default()
        },
    )
    .map_err(|source| LearnBenchError::Sim {
        object: name.to_owned(),
        source,
    })?;
    // The learner learns the object's symmetry and size from the shape circling; the
    // harness checks the true size first, so an object too large fails before minutes of
    // learning.
    let shape = &scenario.object.shape;
    let mut config = LearningConfig::default();
    config.learner.alphas_deg = cfg.alphas_deg.clone();
    config.contact_method = cfg.contact_method;
    config.approach_refines_shape = cfg.approach_refines_shape;
    let grid_half_extent = config.grid_half_extent_m();
    if shape.radius().is_nan() || shape.radius() >= grid_half_extent {
        return Err(LearnBenchError::ObjectTooLarge {
            object: name.to_owned(),
            radius_mm: shape.radius() * 1e3,
            max_mm: grid_half_extent * 1e3,
        });
    }
    let learner =
        ProtocolLearner::new(name, &robot, config).map_err(|source| LearnBenchError::Session {
            object: name.to_owned(),
            source,
        })?;
    Ok(Setup {
        robot,
        sim,
        learner,
    })
}

/// Runs the learning phase on `scenario`'s object and evaluates it against the simulator's
/// ground truth; `progress` hears after the shape circling, each trial and each unseen push.
///
/// The object starts every trial at the scenario's object start pose; the scenario's robot
/// start and task are not used (the protocol places the robot). Physics runs in-process.
pub fn run_object(
    scenario: &Scenario,
    cfg: &LearnBenchConfig,
    progress: &mut dyn FnMut(LearnProgress),
) -> Result<ObjectReport, LearnBenchError> {
    let Setup {
        robot,
        sim,
        learner,
    } = setup(scenario, cfg)?;
    let name = scenario.name.as_str();
    let shape = scenario.object.shape.clone();
    // The truth's symmetry, for scoring orientations; the learner learns its own.
    let order = shape.symmetry_order();
    let object0 = scenario.object.start;
    let total = cfg.progress_total();
    let mut done = 0;
    let mut tick = |stage: LearnStage| {
        done += 1;
        progress(LearnProgress { stage, done, total });
    };
    let mut world = BenchWorld::new(name, &robot, sim, learner, shape.clone(), object0, cfg);
    // The frame of the built world, as the estimator sees it.
    world.learner.observe(&view(&world.sim));

    let (protocol, learning) = learn(&mut world, cfg, &robot, object0, &mut tick)?;
    let session = learned_session(&world, name, &shape)?;
    let trials = &learning.trials;
    let pose = pose_errors(trials, order);
    let (by_method, truth_learned) = gradients_by_method(name, cfg, trials)?;
    let eval = evaluate(&mut world, &protocol, cfg, object0, &mut tick)?;

    let radius = protocol.start_radius_m();
    let predictor = PushPredictor::new(&session.gradient, radius);
    let prediction = predict_all(&predictor, &eval.samples, order, keyed(cfg.contact_method));
    let prediction_by_method = by_method
        .iter()
        .map(|(m, g)| {
            let p = PushPredictor::with_shape(g, predictor.shape().clone(), radius);
            (*m, predict_all(&p, &eval.samples, order, keyed(*m)))
        })
        .collect();
    let prediction_truth_learned = predict_all(
        &PushPredictor::with_shape(&truth_learned, predictor.shape().clone(), radius),
        &eval.samples,
        order,
        |e| e.true_aim.map(|(c, heading)| PushKey::at(c, heading)),
    );
    let rotation_error_by_alpha_gap_deg =
        rotation_error_by_alpha_gap(&predictor, &eval.samples, cfg, order);

    Ok(ObjectReport {
        name: name.to_owned(),
        symmetry_order: order,
        alphas_deg: cfg.alphas_deg.clone(),
        push_duration_s: cfg.push.push_duration,
        shape_points: learning.shape_points,
        learned_symmetry_order: session.symmetry_order,
        learned_border_radius_mm: session.border_radius_mm,
        shape_circling_moved_object_mm: learning.shape_circling_moved_object_mm,
        trials: cfg.total_trials(),
        learned: session.learned,
        pushed_by_alpha: cfg
            .alphas_deg
            .iter()
            .map(|&a| (a, trials.iter().filter(|t| t.alpha_deg == a).count()))
            .collect(),
        no_contact: learning.no_contact,
        rejected: session.rejected.saturating_sub(learning.no_contact),
        circle_timeouts: learning.circle_timeouts,
        max_rotation_deg: max_rotations(cfg, &session.gradient, trials),
        pose_position_mm: pose.position_mm,
        pose_orientation_deg: pose.orientation_deg,
        wrong_branch: pose.wrong_branch,
        learned_rotation_error_deg: pose.rotation_deg,
        contact_error_mm: contact_errors(trials),
        prediction,
        eval_attempts: eval.attempts,
        prediction_by_method,
        prediction_truth_learned,
        rotation_error_by_alpha_gap_deg,
        initial_shape: session.initial_shape,
        final_shape: session.final_shape,
        learning_sim_time_s: learning.sim_time_s,
        learning_wall_s: learning.wall_s,
        eval_sim_time_s: eval.sim_time_s,
        eval_wall_s: eval.wall_s,
        gradient: session.gradient,
    })
}

/// What the learning phase left: its trials and counts, and how long it took.
struct Learning {
    trials: Vec<TrialOutcome>,
    no_contact: usize,
    circle_timeouts: usize,
    shape_points: usize,
    shape_circling_moved_object_mm: f64,
    sim_time_s: f64,
    wall_s: f64,
}

/// (a) The shape, then (b) the trials: the planner's protocol, run against `world`.
/// Returns the protocol (its start circle is the learned border's) and what it left.
fn learn(
    world: &mut BenchWorld,
    cfg: &LearnBenchConfig,
    robot: &RobotDescription,
    object0: Pose,
    tick: &mut dyn FnMut(LearnStage),
) -> Result<(LearnProtocol, Learning), LearnBenchError> {
    let name = world.name.clone();
    let protocol_error = |e: LearnProtocolError<LearnBenchError>| match e {
        LearnProtocolError::World(e) => e,
        LearnProtocolError::ShapeApproach => LearnBenchError::ShapeApproach {
            object: name.clone(),
        },
        other => LearnBenchError::Protocol {
            object: name.clone(),
            reason: other.to_string(),
        },
    };
    let wall = Instant::now();
    let t_start = world.sim.sim_time();
    // The shape circling starts outside anything the grid can hold; everything after it
    // starts from the border learned.
    let mut protocol = LearnProtocol::new(cfg.protocol(), robot, object0);
    let mut progress = |step: ProtocolStep| match step {
        ProtocolStep::ShapeLearned { .. } => tick(LearnStage::ShapeCircling),
        ProtocolStep::Trial { .. } => tick(LearnStage::Trials),
        ProtocolStep::Again { .. } | ProtocolStep::Learned(_) => {}
    };
    let learned = match cfg.protocol {
        TrialProtocol::Paper => protocol.run(world, &mut progress),
        TrialProtocol::Active => {
            let mut chooser =
                ActiveTrialChooser::new(cfg.active.clone(), &cfg.alphas_deg, object0.theta);
            run_active(
                &mut protocol,
                &mut chooser,
                world,
                u32::try_from(cfg.active_trials).unwrap_or(u32::MAX),
                BenchWorld::gradient,
                &mut progress,
            )
        }
    };
    learned.map_err(protocol_error)?;
    let learning = Learning {
        trials: std::mem::take(&mut world.trials),
        no_contact: world.no_contact,
        circle_timeouts: world.circle_timeouts,
        shape_points: world.shape_points,
        shape_circling_moved_object_mm: world.shape_circling_moved_object_mm,
        sim_time_s: world.sim.sim_time() - t_start,
        wall_s: wall.elapsed().as_secs_f64(),
    };
    Ok((protocol, learning))
}

/// What the learner's session made of the trials.
struct SessionResults {
    learned: usize,
    rejected: usize,
    symmetry_order: Option<u32>,
    border_radius_mm: f64,
    /// The matcher's S (the first circling) against the true border.
    initial_shape: ShapeQuality,
    /// The final combined S (with the approaches' points), which the AG file carries.
    final_shape: ShapeQuality,
    gradient: AffordanceGradient,
}

/// The learner's session after the learning phase, its learned S scored against the true
/// `shape`.
fn learned_session(
    world: &BenchWorld,
    name: &str,
    shape: &ObjectShape,
) -> Result<SessionResults, LearnBenchError> {
    let Some(session) = world.learner.session() else {
        return Err(LearnBenchError::Protocol {
            object: name.to_owned(),
            reason: "the learner gave its session away".into(),
        });
    };
    let initial_shape = shape_quality(
        shape,
        session.matcher().map_or(&[][..], |m| m.border_points()),
    );
    let final_shape = match session.matcher().map(|m| {
        agp_affordance::ShapeMatcher::new(&session.gradient().combined_shape(), m.config().clone())
    }) {
        Some(Ok(m)) => shape_quality(shape, m.border_points()),
        _ => ShapeQuality::default(),
    };
    Ok(SessionResults {
        learned: session.trials_learned(),
        rejected: session.trials_rejected(),
        symmetry_order: session.symmetry_order(),
        border_radius_mm: session.border_radius_m().unwrap_or(f64::NAN) * 1e3,
        initial_shape,
        final_shape,
        gradient: session.gradient().clone(),
    })
}

/// (i) Largest rotation per alpha: (alpha, learned, true), degrees.
fn max_rotations(
    cfg: &LearnBenchConfig,
    gradient: &AffordanceGradient,
    trials: &[TrialOutcome],
) -> Vec<(f64, f64, f64)> {
    cfg.alphas_deg
        .iter()
        .map(|&a| {
            let learned = gradient.max_rotation_deg(a).unwrap_or(f64::NAN);
            let truth = trials
                .iter()
                .filter(|t| t.alpha_deg == a)
                .map(|t| t.truth.rotation_rad.abs().to_degrees())
                .fold(0.0, f64::max);
            (a, learned, truth)
        })
        .collect()
}

/// (iii) How far the pose from one circling, and the learned rotation, were from the truth.
struct PoseErrors {
    position_mm: Spread,
    /// None for a disc (no orientation).
    orientation_deg: Option<Spread>,
    /// Learned rotations more than a quarter of the symmetry period off.
    wrong_branch: usize,
    rotation_deg: Spread,
}

fn pose_errors(trials: &[TrialOutcome], order: u32) -> PoseErrors {
    let period = if order <= 1 {
        TAU
    } else {
        TAU / f64::from(order)
    };
    let (mut pos_err, mut ori_err, mut rot_err) = (Vec::new(), Vec::new(), Vec::new());
    let mut wrong_branch = 0;
    for t in trials {
        let Some(r) = &t.record else { continue };
        pos_err.push((r.object_after.position() - t.truth.after.position()).length() * 1e3);
        if order != 0 {
            ori_err.push(
                angle::distance(r.matched.orientation_rad, t.truth.after.theta, period)
                    .to_degrees(),
            );
            let e = wrap_angle(r.outcome.rotation_rad - t.truth.rotation_rad).abs();
            if order > 1 && e > period / 4.0 {
                wrong_branch += 1;
            }
            rot_err.push(e.to_degrees());
        }
    }
    PoseErrors {
        position_mm: Spread::of(&mut pos_err),
        orientation_deg: (order != 0).then(|| Spread::of(&mut ori_err)),
        wrong_branch,
        rotation_deg: Spread::of(&mut rot_err),
    }
}

/// Each method's contact estimates against the true touch (or aim) point, mm.
fn contact_errors(trials: &[TrialOutcome]) -> Vec<(ContactMethod, Spread)> {
    ContactMethod::ALL
        .iter()
        .map(|&m| {
            let mut e: Vec<f64> = trials
                .iter()
                .filter_map(|t| {
                    let est = t.record.as_ref()?.contact.get(m)?;
                    let truth = match m {
                        ContactMethod::HeadingLine => t.truth.aim_obj?,
                        _ => t.truth.touch_obj?,
                    };
                    Some((est - truth).length() * 1e3)
                })
                .collect();
            (m, Spread::of(&mut e))
        })
        .collect()
}

/// Gradients keyed by every method from the same trials, and one learned from the truth
/// (true aim points and effects): what the representation can do with them.
#[allow(clippy::type_complexity)]
fn gradients_by_method(
    name: &str,
    cfg: &LearnBenchConfig,
    trials: &[TrialOutcome],
) -> Result<(Vec<(ContactMethod, AffordanceGradient)>, AffordanceGradient), LearnBenchError> {
    let new_learner = || {
        let mut lc = LearningConfig::default().learner;
        lc.alphas_deg = cfg.alphas_deg.clone();
        AffordanceLearner::new(name, &lc).map_err(|source| LearnBenchError::Learner {
            object: name.to_owned(),
            source,
        })
    };
    // Every sample here has a known alpha and finite numbers (the session checked the
    // records; the truth comes from the simulator): one that does not is left out.
    let add = |learner: &mut AffordanceLearner, alpha: f64, outcome: &PushOutcome| {
        let _: Result<(), SampleAddError> = learner.add_push(alpha, outcome);
    };
    let mut by_method: Vec<(ContactMethod, AffordanceGradient)> = Vec::new();
    for &m in &ContactMethod::ALL {
        let mut learner = new_learner()?;
        for r in trials.iter().filter_map(|t| t.record.as_ref()) {
            if let Some(c) = r.contact.get(m) {
                let outcome = PushOutcome {
                    contact_point_obj: c,
                    ..r.outcome
                };
                add(&mut learner, r.alpha_deg, &outcome);
            }
        }
        by_method.push((m, learner.into_gradient()));
    }
    let truth_learned = {
        let mut learner = new_learner()?;
        for t in trials {
            if let (Some(c), Some(heading_obj)) = (t.truth.aim_obj, t.truth.heading_obj) {
                let outcome = PushOutcome {
                    contact_point_obj: c,
                    displacement_obj: t.truth.displacement_obj,
                    rotation_rad: t.truth.rotation_rad,
                    heading_obj,
                };
                add(&mut learner, t.alpha_deg, &outcome);
            }
        }
        learner.into_gradient()
    };
    Ok((by_method, truth_learned))
}

/// The unseen pushes of the evaluation, and how long they took.
struct Evaluation {
    samples: Vec<EvalPush>,
    /// Pushes tried, those that touched nothing included.
    attempts: usize,
    sim_time_s: f64,
    wall_s: f64,
}

/// (ii) Unseen pushes: random angle round the object, random alpha in [-15, 15]. A push
/// that touches nothing (or whose contact the estimator cannot place) is tried again
/// elsewhere, up to a bound, so an object the robot cannot push ends the run.
fn evaluate(
    world: &mut BenchWorld,
    protocol: &LearnProtocol,
    cfg: &LearnBenchConfig,
    object0: Pose,
    tick: &mut dyn FnMut(LearnStage),
) -> Result<Evaluation, LearnBenchError> {
    let wall = Instant::now();
    let t_eval = world.sim.sim_time();
    let mut rng = Rng::stream(cfg.seed, EVAL_RNG_STREAM);
    let mut samples: Vec<EvalPush> = Vec::with_capacity(cfg.eval_pushes);
    let max_attempts = cfg.eval_pushes.saturating_mul(4).saturating_add(20);
    let mut attempts = 0;
    while samples.len() < cfg.eval_pushes && attempts < max_attempts {
        attempts += 1;
        let phi = rng.range(0.0, TAU);
        let alpha = rng.range(-15.0, 15.0);
        // The protocol's approach and push, told to nobody: the learner is done.
        world.reset(object0, protocol.start_pose(phi, alpha))?;
        world.watch();
        let mut estimates = None;
        let contact = protocol.approach_and_push(world, |w| {
            estimates = w
                .learner
                .session()
                .and_then(|s| s.contact_estimates(&view(&w.sim), object0));
            Ok(())
        })?;
        world.watch_touch = false;
        if !contact {
            continue;
        }
        // Let the object come to rest.
        LearnProtocol::hold(world, 0.1, 0.0)?;
        let after = world.sim.object_pose();
        let Some(contact) = estimates else { continue };
        samples.push(EvalPush {
            contact,
            true_aim: world.aim_obj.zip(world.heading_obj),
            alpha_deg: alpha,
            displacement_obj: object0.to_local(after.position()),
            rotation_rad: wrap_angle(after.theta - object0.theta),
        });
        tick(LearnStage::Evaluation);
    }
    Ok(Evaluation {
        samples,
        attempts,
        sim_time_s: world.sim.sim_time() - t_eval,
        wall_s: wall.elapsed().as_secs_f64(),
    })
}

/// An unseen push's key by method `m`: the estimator's contact and the robot's heading as
/// it estimated it; a heading line that met no learned border (the disc grazed the object
/// beside it) gives way to the body sweep's touch point.
fn keyed(m: ContactMethod) -> impl Fn(&EvalPush) -> Option<PushKey> {
    move |e: &EvalPush| {
        let heading = DVec2::from_angle(e.contact.robot_obj.theta);
        match (e.contact.get(m), m) {
            (Some(c), _) => Some(PushKey::at(c, heading)),
            (None, ContactMethod::HeadingLine) => e.contact.body_sweep.map(|c| PushKey {
                by_touch: true,
                ..PushKey::at(c, heading)
            }),
            (None, _) => None,
        }
    }
}

/// Rotation error of the unseen pushes (keyed by the configured method), by how far each
/// push's alpha lies from the nearest learned alpha: under 2.5, under 5, 5 deg or more.
fn rotation_error_by_alpha_gap(
    predictor: &PushPredictor<'_>,
    samples: &[EvalPush],
    cfg: &LearnBenchConfig,
    order: u32,
) -> [Spread; 3] {
    let mut bins: [Vec<f64>; 3] = Default::default();
    if order != 0 {
        for e in samples {
            let Some(p) = keyed(cfg.contact_method)(e)
                .and_then(|k| predictor.predict_push(k.point, e.alpha_deg, k.heading))
            else {
                continue;
            };
            let d = cfg
                .alphas_deg
                .iter()
                .map(|a| (a - e.alpha_deg).abs())
                .fold(f64::INFINITY, f64::min);
            bins[((d / 2.5) as usize).min(2)].push(
                wrap_angle(p.rotation_rad - e.rotation_rad)
                    .abs()
                    .to_degrees(),
            );
        }
    }
    bins.map(|mut b| Spread::of(&mut b))
}

/// One unseen push of the evaluation.
#[derive(Debug, Clone, Copy)]
struct EvalPush {
    /// The estimator's contact estimates (object frame).
    contact: ContactEstimates,
    /// The true aim point and heading (object frame).
    true_aim: Option<(DVec2, DVec2)>,
    alpha_deg: f64,
    /// True effect, object frame.
    displacement_obj: DVec2,
    rotation_rad: f64,
}

/// How far from an unseen push's aim point the gradient's nearest evidence may lie for the
/// push to be predicted from it: two trials' spacing along the border (60 trials round
/// the object come about 5 mm apart).
pub const NEAREST_EVIDENCE_M: f64 = 0.01;

/// What an unseen push is predicted by.
#[derive(Debug, Clone, Copy)]
struct PushKey {
    /// Aim point (or touch point), object frame.
    point: DVec2,
    /// The robot's heading, object frame.
    heading: DVec2,
    /// Keyed by the touch point: the heading line met no learned border.
    by_touch: bool,
}

impl PushKey {
    fn at(point: DVec2, heading: DVec2) -> Self {
        Self {
            point,
            heading,
            by_touch: false,
        }
    }
}

/// How `g` predicts `samples`, queried as `key` says.
fn predict_all(
    g: &PushPredictor<'_>,
    samples: &[EvalPush],
    order: u32,
    key: impl Fn(&EvalPush) -> Option<PushKey>,
) -> PredictionStats {
    let mut stats = PredictionStats::default();
    let (mut de, mut dr, mut re, mut td, mut tr) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for e in samples {
        stats.pushes += 1;
        let Some((p, k)) = key(e).and_then(|k| {
            g.predict_push_nearest(k.point, e.alpha_deg, k.heading, NEAREST_EVIDENCE_M)
                .map(|p| (p, k))
        }) else {
            stats.unpredicted += 1;
            continue;
        };
        if k.by_touch {
            stats.keyed_by_touch += 1;
        }
        if p.confidence == 0.0 {
            stats.from_nearest += 1;
        }
        let err = (p.displacement - e.displacement_obj).length();
        de.push(err * 1e3);
        dr.push(err / e.displacement_obj.length().max(1e-6));
        td.push(e.displacement_obj.length() * 1e3);
        tr.push(e.rotation_rad.abs().to_degrees());
        if order != 0 {
            re.push(
                wrap_angle(p.rotation_rad - e.rotation_rad)
                    .abs()
                    .to_degrees(),
            );
        }
    }
    stats.displacement_error_mm = Spread::of(&mut de);
    stats.displacement_error_ratio = Spread::of(&mut dr);
    stats.rotation_error_deg = Spread::of(&mut re);
    stats.true_displacement_mm = Spread::of(&mut td);
    stats.true_rotation_abs_deg = Spread::of(&mut tr);
    stats
}

fn fmt_spread(s: &Spread, unit: &str) -> String {
    format!(
        "median {:7.2} {unit}  p90 {:7.2} {unit}  (n {})",
        s.median, s.p90, s.n
    )
}

/// The report of one object as text.
pub fn format_report(r: &ObjectReport) -> String {
    let mut out = String::new();
    let mut line = |s: String| {
        out.push_str(&s);
        out.push('\n');
    };
    line(format!(
        "== {} (symmetry order {}) ==",
        r.name, r.symmetry_order
    ));
    line(format!(
        "alphas {:?} deg, push {:.2} s; shape circling: {} border points (object moved {:.2} mm)",
        r.alphas_deg, r.push_duration_s, r.shape_points, r.shape_circling_moved_object_mm
    ));
    line(format!(
        "learned from the shape circling: symmetry order {}, border radius {:.1} mm",
        r.learned_symmetry_order
            .map_or("none".into(), |k| k.to_string()),
        r.learned_border_radius_mm
    ));
    for (what, q) in [
        ("S of the first circling", &r.initial_shape),
        ("final S (with approaches)", &r.final_shape),
    ] {
        line(format!(
            "{what}: {} ridge points, {} from the true border, {:.0} % of the border covered",
            q.points,
            fmt_spread(&q.error_mm, "mm"),
            q.coverage * 100.0
        ));
    }
    line(format!(
        "trials {}: learned {}, no contact {}, rejected {}, circlings not closed {}",
        r.trials, r.learned, r.no_contact, r.rejected, r.circle_timeouts
    ));
    line("(i) largest single-push rotation per alpha, deg:".into());
    for &(a, learned, truth) in &r.max_rotation_deg {
        let paper = PAPER_TRIANGLE_MAX_ROTATION_DEG
            .iter()
            .find(|p| p.0 == a)
            .map(|p| format!("{:6.2}", p.1))
            .unwrap_or_else(|| "   -  ".into());
        line(format!(
            "    A{:<4} learned (IR) {:6.2}   true {:6.2}   paper triangle {}",
            a, learned, truth, paper
        ));
    }
    let p = &r.prediction;
    line(format!(
        "(ii) {} unseen pushes (random angle, alpha in [-15, 15]), {} without a prediction, {} from the nearest evidence, {} keyed by the touch point:",
        p.pushes, p.unpredicted, p.from_nearest, p.keyed_by_touch
    ));
    line(format!(
        "    displacement error  {}",
        fmt_spread(&p.displacement_error_mm, "mm")
    ));
    line(format!(
        "    as a fraction       {}",
        fmt_spread(&p.displacement_error_ratio, "")
    ));
    if r.symmetry_order == 0 {
        line("    rotation error      n/a (a disc's orientation is not observable by IR)".into());
    } else {
        line(format!(
            "    rotation error      {}",
            fmt_spread(&p.rotation_error_deg, "deg")
        ));
    }
    line(format!(
        "    true displacement   {}   true |rotation| {}",
        fmt_spread(&p.true_displacement_mm, "mm"),
        fmt_spread(&p.true_rotation_abs_deg, "deg")
    ));
    line("    by contact method (gradient keyed by it, same trials):".into());
    for (m, s) in &r.prediction_by_method {
        line(format!(
            "      {:<14} disp {:6.2} mm ({:5.3})  rot {:6.2} deg  unpredicted {}",
            m.name(),
            s.displacement_error_mm.median,
            s.displacement_error_ratio.median,
            s.rotation_error_deg.median,
            s.unpredicted
        ));
    }
    let t = &r.prediction_truth_learned;
    line(format!(
        "      {:<14} disp {:6.2} mm ({:5.3})  rot {:6.2} deg  (gradient learned from the truth, at true aim points)",
        "truth-learned",
        t.displacement_error_mm.median,
        t.displacement_error_ratio.median,
        t.rotation_error_deg.median
    ));
    if r.symmetry_order != 0 {
        let b = &r.rotation_error_by_alpha_gap_deg;
        line(format!(
            "    rotation error by alpha's distance to the nearest learned alpha: 0-2.5 deg {:.2} (n {}), 2.5-5 deg {:.2} (n {}), >5 deg {:.2} (n {})",
            b[0].median, b[0].n, b[1].median, b[1].n, b[2].median, b[2].n
        ));
    }
    line("    contact point error vs truth (touch point; aim point for heading-line):".into());
    for (m, s) in &r.contact_error_mm {
        line(format!("      {:<14} {}", m.name(), fmt_spread(s, "mm")));
    }
    line("(iii) pose from one circling (after each trial):".into());
    line(format!(
        "    position    {}",
        fmt_spread(&r.pose_position_mm, "mm")
    ));
    match &r.pose_orientation_deg {
        Some(s) => line(format!(
            "    orientation {} (modulo {} deg)",
            fmt_spread(s, "deg"),
            if r.symmetry_order <= 1 {
                360.0
            } else {
                360.0 / f64::from(r.symmetry_order)
            }
        )),
        None => line("    orientation n/a (a disc)".into()),
    }
    if r.symmetry_order != 0 {
        line(format!(
            "    learned rotation error {}; symmetric branch wrong in {} trials",
            fmt_spread(&r.learned_rotation_error_deg, "deg"),
            r.wrong_branch
        ));
    }
    line(format!(
        "(iv) learning phase: {:.1} s simulated, {:.2} s wall; evaluation {:.1} s simulated, {:.2} s wall",
        r.learning_sim_time_s, r.learning_wall_s, r.eval_sim_time_s, r.eval_wall_s
    ));
    out
}
