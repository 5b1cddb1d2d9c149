//! Online learning: the gradient goes on learning from the pushes of a task, each push's
//! effect observed between two circlings, weighted towards recent pushes.
//!
//! A push of a task is learned when its effect is known: the object's pose matched to S
//! by the circling before it and by the circling after it, with no other push between
//! (the pushes of a run of several between two circlings are not told apart, and are not
//! learned). The push's key is the one the planner announced (aim point and alpha, in the
//! object frame of the pose it was planned from, which is the first circling's), and its
//! effect is divided by the announced share of a learned push (`scale`), so that it is a
//! learned push's effect, as in the learning phase.
//!
//! Two updates per learned push, in this order:
//! 1. a uniform gain: the push's observed displacement along the predicted one, over the
//!    predicted one's length (and the same for the rotation when the prediction turns the
//!    object by at least [`OnlineLearningConfig::min_rotation_rad`]), clamped to
//!    [1/3, 3], raised to [`OnlineLearningConfig::gain_step`], scales every push learned
//!    so far ([`AffordanceLearner::scale_motion`]). A change of the floor or of the
//!    object's mass changes every push's effect alike; a local update alone would correct
//!    the gradient only round the few contact points a task pushes at, and a placement
//!    pushes at a new one almost every time;
//! 2. the push itself, as the learning phase learns a trial, after the evidence already
//!    round its contact point was multiplied by [`OnlineLearningConfig::forgetting`]
//!    ([`AffordanceLearner::add_recent_push`]); only a push at a learned alpha (0, +-15
//!    deg): the grids hold those alone, and the planner's pushes between them (it tries
//!    alphas every 2.5 deg) teach the gain only.

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, Grid, LearnerBuildError, LearnerConfig, Prediction,
    PushOutcome, PushPredictor, approach_start,
};
use agp_shared_types::{Pose2, angle};
use glam::DVec2;

/// How the tracker learns from a task's pushes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineLearningConfig {
    /// Learn at all; `false` freezes the gradient (the paper's tasks).
    pub enabled: bool,
    /// What the evidence already at a push's contact point counts for once the push is
    /// learned, in (0, 1] (0.5: the new push weighs about as much as the learning phase's
    /// trials round it, one to two, together; a second push there outweighs them).
    pub forgetting: f64,
    /// Exponent of each push's observed/predicted ratio in the uniform gain, in (0, 1]
    /// (0.4: an error of the whole gradient shrinks to 0.6^n of itself in n learned
    /// pushes, to 8 % in 5; the noise of one push's ratio reaches the gain as
    /// sqrt(0.4 / 1.6) = 0.5 of itself).
    pub gain_step: f64,
    /// Pushes announced to make less than this share of a learned push are not learned
    /// (0.99: full pushes only). A shorter push's effect, divided by the planner's share
    /// (its model `(f + 0.23) / 1.23` of a push of fraction `f`), teaches the gradient that
    /// model's error: with 0.3 (quarter pushes learned) the updating gradient's full-push
    /// predictions grew to 60 to 90 mm against 30 to 50 mm true (`agp bench adapt`,
    /// triangle, friction 0.4 to 0.25).
    pub min_scale: f64,
    /// The rotation gain learns only from pushes predicted to turn the object by at least
    /// this, rad (3 deg): below, the ratio is noise.
    pub min_rotation_rad: f64,
    /// The displacement gain learns only from pushes predicted to move the object by at
    /// least this, m (3 mm).
    pub min_displacement_m: f64,
    /// Standard deviation of a push's Gaussian, m: the learning phase's
    /// ([`LearnerConfig::default`]).
    pub push_sigma_m: f64,
}

impl Default for OnlineLearningConfig {
    /// Off: a task's gradient stays the learned one unless asked (the paper's tasks, and
    /// every figure measured before online learning, keep their meaning).
    fn default() -> Self {
        Self {
            enabled: false,
            forgetting: 0.7,
            gain_step: 0.25,
            min_scale: 0.99,
            min_rotation_rad: 10f64.to_radians(),
            min_displacement_m: 0.003,
            push_sigma_m: LearnerConfig::default().push_sigma_m,
        }
    }
}

impl OnlineLearningConfig {
    /// The defaults, learning.
    pub fn updating() -> Self {
        Self {
            enabled: true,
            ..Self::default()
        }
    }
}

/// A push learned online: what was predicted, what was observed (a learned push's worth,
/// object frame before the push) and the gains applied.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnedPush {
    /// Aim point (object frame, m) and alpha (deg) the push was keyed by.
    pub contact_obj: DVec2,
    /// Alpha, degrees.
    pub alpha_deg: f64,
    /// The gradient's prediction before the push was learned (a learned push's worth).
    pub predicted: Prediction,
    /// The observed displacement (m) and rotation (rad), divided by the push's share.
    pub observed: PushOutcome,
    /// The uniform gains applied to the displacement and the rotation.
    pub gains: (f64, f64),
    /// Whether the push was also learned at its contact point: only at a learned alpha
    /// (the grids hold those alone).
    pub local: bool,
}

/// The push under way that may be learned: where it started and what was announced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PendingPush {
    /// The object's pose matched by the circling before the push.
    pub before: Pose2,
    pub contact_obj: DVec2,
    pub alpha_deg: f64,
    pub scale: f64,
}

/// One update of an [`OnlineLearner`], kept so that it can be made again on a rebuilt
/// prior ([`OnlineLearner::rebased`]): the uniform gains, then the push learned at its
/// contact point (alpha, outcome), if it was.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Update {
    gains: (f64, f64),
    local: Option<(f64, PushOutcome)>,
}

/// Updates kept for [`OnlineLearner::rebased`] without allocating: more than a task's
/// pushes (150).
const HISTORY_CAPACITY: usize = 256;

/// Learns a gradient on from observed pushes (see the module's documentation).
pub struct OnlineLearner {
    config: OnlineLearningConfig,
    learner: AffordanceLearner,
    pushes_learned: u64,
    /// Every update so far, in order.
    history: Vec<Update>,
}

impl OnlineLearner {
    /// Goes on learning `ag` (a copy).
    pub fn new(
        ag: &AffordanceGradient,
        config: OnlineLearningConfig,
    ) -> Result<Self, LearnerBuildError> {
        let learner_config = LearnerConfig {
            alphas_deg: ag.alphas_deg().collect(),
            cell_size_m: ag.cell_size_m(),
            push_sigma_m: config.push_sigma_m,
            ..LearnerConfig::default()
        };
        Ok(Self {
            config,
            learner: AffordanceLearner::resume(ag.clone(), &learner_config)?,
            pushes_learned: 0,
            history: Vec::with_capacity(HISTORY_CAPACITY),
        })
    }

    /// The same learning made again on `base` (a prior rebuilt from more of the object's
    /// border, its frame's origin at `shift` of this one's, the axes alike): every update
    /// in order, each push's contact point moved into the new frame and its displacement
    /// made the new origin's (`d + (R(rotation) - I) shift`). The gains are the ones
    /// learned, not measured again against the new prior. Allocates.
    pub fn rebased(
        &self,
        base: &AffordanceGradient,
        shift: DVec2,
    ) -> Result<Self, LearnerBuildError> {
        let mut rebased = Self::new(base, self.config)?;
        for u in &self.history {
            rebased.learner.scale_motion(u.gains.0, u.gains.1);
            if let Some((alpha, push)) = u.local {
                let moved = PushOutcome {
                    contact_point_obj: push.contact_point_obj - shift,
                    displacement_obj: push.displacement_obj
                        + (DVec2::from_angle(push.rotation_rad).rotate(shift) - shift),
                    ..push
                };
                // It was learned once; the frames differ by millimetres.
                let _ = rebased
                    .learner
                    .add_recent_push(alpha, &moved, self.config.forgetting);
            }
            rebased.history.push(*u);
        }
        rebased.pushes_learned = self.pushes_learned;
        Ok(rebased)
    }

    /// The gradient as learned so far.
    pub fn gradient(&self) -> &AffordanceGradient {
        self.learner.gradient()
    }

    /// The config it learns with.
    pub fn config(&self) -> &OnlineLearningConfig {
        &self.config
    }

    /// Pushes learned so far.
    pub fn pushes_learned(&self) -> u64 {
        self.pushes_learned
    }

    /// Learns `push`, whose object came to rest at `after` (matched by a circling, same
    /// frame as `push.before`); `shape` (the gradient's combined S, which online learning
    /// never changes) and `start_radius_m` (the learning trials' start circle) are the
    /// predictor's, and `period_rad` the orientation's symmetry period (infinite for no
    /// symmetry, 0 for a disc: its rotation is not observed and not learned). `None` when
    /// the push is not learned (disabled, too short a push, nothing predicted there, a
    /// sample out of range). Allocates nothing (past 256 pushes learned, the history it
    /// keeps for [`OnlineLearner::rebased`] grows).
    pub(crate) fn learn(
        &mut self,
        push: PendingPush,
        after: Pose2,
        shape: &Grid,
        start_radius_m: f64,
        period_rad: f64,
    ) -> Option<LearnedPush> {
        let c = self.config;
        if !(c.enabled && push.scale.is_finite() && push.scale >= c.min_scale) {
            return None;
        }
        let predicted = PushPredictor::borrowing(self.learner.gradient(), shape, start_radius_m)
            .predict(push.contact_obj, push.alpha_deg)?;
        let (raw_displacement, raw_rotation) = PushOutcome::motion(push.before, after);
        let displacement = raw_displacement / push.scale;
        // Out of any push's reach: a bad match, not a push.
        if !displacement.is_finite() || displacement.length() > 0.2 {
            return None;
        }
        // The rotation nearest the predicted one among those the symmetry allows.
        let expected = predicted.rotation_rad * push.scale;
        let rotation_rad = if period_rad == 0.0 {
            predicted.rotation_rad
        } else if period_rad.is_finite() {
            (expected + angle::wrap_to_half_period(raw_rotation - expected, period_rad))
                / push.scale
        } else {
            raw_rotation / push.scale
        };
        // The planner's push: from the start circle's nearest point, as predicted.
        let heading_obj = approach_start(push.contact_obj, push.alpha_deg, start_radius_m)
            .map_or(-push.contact_obj, |(_, h)| DVec2::from_angle(h));
        let observed = PushOutcome {
            contact_point_obj: push.contact_obj,
            displacement_obj: displacement,
            rotation_rad,
            heading_obj,
        };
        let ratio = |o: f64, p: f64| (o / p).clamp(1.0 / 3.0, 3.0).powf(c.gain_step);
        let p = predicted.displacement;
        let gain_d = if p.length() >= c.min_displacement_m {
            ratio(displacement.dot(p), p.length_squared())
        } else {
            1.0
        };
        let gain_r = if predicted.rotation_rad.abs() >= c.min_rotation_rad && period_rad != 0.0 {
            ratio(rotation_rad, predicted.rotation_rad)
        } else {
            1.0
        };
        self.learner.scale_motion(gain_d, gain_r);
        // The grids hold the learned alphas only; a push between them (the planner tries
        // alphas every few degrees) teaches the gain alone.
        let local = self.learner.gradient().push_count(push.alpha_deg).is_some()
            && self
                .learner
                .add_recent_push(push.alpha_deg, &observed, c.forgetting)
                .is_ok();
        self.pushes_learned += 1;
        self.history.push(Update {
            gains: (gain_d, gain_r),
            local: local.then_some((push.alpha_deg, observed)),
        });
        Some(LearnedPush {
            contact_obj: push.contact_obj,
            alpha_deg: push.alpha_deg,
            predicted,
            observed,
            gains: (gain_d, gain_r),
            local,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agp_affordance::{ContactPriorConfig, contact_prior};

    /// Border points of a square of half side `h` round `centre`, 40 per side.
    fn square(h: f64, centre: DVec2) -> Vec<DVec2> {
        (0..160)
            .map(|k| {
                let u = -h + 2.0 * h * f64::from(k % 40) / 40.0;
                centre
                    + match k / 40 {
                        0 => DVec2::new(u, -h),
                        1 => DVec2::new(h, u),
                        2 => DVec2::new(-u, h),
                        _ => DVec2::new(-h, -u),
                    }
            })
            .collect()
    }

    #[test]
    fn a_rebased_learner_learns_the_same_pushes_again_in_the_new_frame() {
        let config = ContactPriorConfig {
            trials_per_alpha: 12,
            ..ContactPriorConfig::default()
        };
        let prior = contact_prior("box", &square(0.03, DVec2::ZERO), &config).expect("a prior");
        let mut learner =
            OnlineLearner::new(&prior, OnlineLearningConfig::updating()).expect("a learner");
        let shape = prior.combined_shape();
        let start_radius = 0.03 * 2f64.sqrt() + 0.057;
        // A push at the -x face, alpha 0, observed to move the object 30 mm and turn it
        // 10 deg.
        let push = PendingPush {
            before: Pose2::new(0.0, 0.0, 0.0),
            contact_obj: DVec2::new(-0.03, 0.01),
            alpha_deg: 0.0,
            scale: 1.0,
        };
        let after = Pose2::new(0.03, 0.0, 10f64.to_radians());
        let learned = learner
            .learn(push, after, &shape, start_radius, f64::INFINITY)
            .expect("learned");
        assert!(learned.local);
        // Again on the same prior, the frame unmoved: the same gradient.
        let again = learner.rebased(&prior, DVec2::ZERO).expect("rebased");
        assert_eq!(again.gradient(), learner.gradient());
        assert_eq!(again.pushes_learned(), 1);
        // On a base of S alone, its origin 2 mm off the old one's: the push alone predicts
        // at its contact point moved into the new frame, the displacement the new
        // origin's.
        let mut s_only = AffordanceLearner::new(
            "box",
            &LearnerConfig {
                alphas_deg: prior.alphas_deg().collect(),
                ..LearnerConfig::default()
            },
        )
        .expect("a learner");
        for alpha in prior.alphas_deg().collect::<Vec<_>>() {
            for p in square(0.03, DVec2::ZERO) {
                s_only.add_border_point(alpha, p).expect("a border point");
            }
        }
        let shift = DVec2::new(0.002, -0.001);
        let moved = learner.rebased(s_only.gradient(), shift).expect("rebased");
        let p = moved
            .gradient()
            .predict(push.contact_obj - shift, 0.0)
            .expect("a prediction");
        let turn = 10f64.to_radians();
        let expected = DVec2::new(0.03, 0.0) + (DVec2::from_angle(turn).rotate(shift) - shift);
        assert!(
            (p.displacement - expected).length() < 1e-6,
            "{p:?} vs {expected}"
        );
        assert!((p.rotation_rad - turn).abs() < 1e-6, "{p:?}");
    }
}
