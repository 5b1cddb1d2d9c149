//! Choosing the next push with an affordance gradient: the paper's `planBestPush`, done as
//! a search over contact point, alpha and push length with the AG's continuous prediction.
//!
//! The paper switches between three aims (the distance to the goal; the rotation when the
//! orientation is more than 30 deg off; a mix near the goal). Here one cost does all three:
//! the predicted distance to the goal plus the predicted orientation error weighted in
//! metres per radian, and the push that minimises it wins. Far from the goal the distance
//! dominates; near it, a push that turns the object towards its goal orientation wins as
//! soon as the turn is worth more than the distance it costs. Shorter pushes are part of
//! the search, which is what lets the object settle into a 10 mm tolerance.

use agp_affordance::{AffordanceGradient, Prediction, PushPredictor, approach_start};
use agp_shared_types::Pose2;
use agp_shared_types::angle;
use agp_shared_types::angle::wrap_angle;
use glam::DVec2;

/// What the planner is after.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Goal {
    /// The object's centroid at `pose`'s position and its orientation at `pose.theta`
    /// (compared modulo the object's symmetry).
    Place { pose: Pose2 },
    /// The centroid at `target`, orientation free (trajectory following feeds the point
    /// ahead on the path).
    Reach { target: DVec2 },
}

/// How the search runs.
#[derive(Debug, Clone, PartialEq)]
pub struct PushChoiceSettings {
    /// Contact points tried: rays from the centroid at even angles onto the learned S.
    pub contact_count: usize,
    /// Alphas tried: every learned alpha's range at this step, degrees.
    pub alpha_step_deg: f64,
    /// Push lengths tried, as fractions of the learned push duration. The prediction of a
    /// fraction `f` is the learned one scaled by `(f + fraction_offset) / (1 +
    /// fraction_offset)` (an approximation: the object turns during the push), so only
    /// fractions up to 1 are offered.
    pub push_fractions: Vec<f64>,
    /// A push moves the object farther than its duration alone says: the approach meets
    /// it a little before the IR infers contact, and it slides on when the robot stops.
    /// Measured with the learning protocol's push (0.5 s at 100 mm/s, contact inferred
    /// at 3 mm): about 9 mm plus 78 mm per second, so an offset of 0.23 of the push.
    pub fraction_offset: f64,
    /// Predictions with a lower confidence (about how many trials back them) are skipped.
    pub min_confidence: f64,
    /// Metres of distance one radian of orientation error is worth (1 mm per degree by
    /// default: the 10 mm / 10 deg tolerance of the benchmark weighs them equally).
    pub orientation_weight_m_per_rad: f64,
    /// Risk aversion: metres of cost per metre of the prediction's displacement spread
    /// (and per radian of its rotation spread times `spread_lever_m`). Where the learned
    /// effect changes sharply with the contact (corners, the L's ends) the smoothed
    /// prediction is unreliable, and without this the search picks those pushes for
    /// effects they do not have.
    pub spread_weight: f64,
    /// With [`Goal::Reach`] (orientation free), metres of cost per radian the push turns
    /// the object: a turning object's centroid runs along an arc, off the line between
    /// its ends, and turning pushes are the hardest to predict.
    pub reach_rotation_weight_m_per_rad: f64,
    /// Lever arm (m) turning a rotation spread into a displacement.
    pub spread_lever_m: f64,
    /// Rotational symmetry of the object (0: a disc, orientation ignored; 1: none).
    pub symmetry_order: u32,
    /// Radius (m) of the centroid-centred circle the robot starts each push from: the one
    /// the learning trials started from, so that an alpha means the same thing.
    pub start_radius_m: f64,
}

impl PushChoiceSettings {
    /// Defaults for an object of the given symmetry pushed from `start_radius_m`.
    pub fn new(symmetry_order: u32, start_radius_m: f64) -> Self {
        Self {
            contact_count: 120,
            alpha_step_deg: 2.5,
            push_fractions: vec![1.0, 0.5, 0.25],
            fraction_offset: 0.23,
            min_confidence: 0.5,
            orientation_weight_m_per_rad: 1e-3 * 180.0 / std::f64::consts::PI,
            spread_weight: 1.0,
            reach_rotation_weight_m_per_rad: 0.03,
            spread_lever_m: 0.03,
            symmetry_order,
            start_radius_m,
        }
    }
}

/// One chosen push.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushPlan {
    /// Where the robot's heading line meets the object, object frame, metres (the AG's key).
    pub contact_obj: DVec2,
    pub alpha_deg: f64,
    /// Fraction of the learned push duration.
    pub fraction: f64,
    /// The AG's prediction, scaled by `fraction`, in the object's frame before the push
    /// (along a path with its sideways part corrected, see [`PathFollowing::cross_gain`]).
    pub prediction: Prediction,
    /// The sideways part (across the push's heading) of the prediction scaled by
    /// `fraction` before any correction, object frame, m: `prediction.displacement` minus
    /// `(cross_gain - 1)` times this is what the estimator predicts from the push's aim
    /// point, alpha and scale alone. Zero for a full push and outside a path.
    pub uncorrected_cross: DVec2,
    /// The rotation of the prediction scaled by `fraction` before any correction (see
    /// [`PathFollowing::turn_gain`]), rad: what the estimator predicts.
    pub uncorrected_rotation_rad: f64,
    /// The object's predicted pose after the push, world frame.
    pub predicted: Pose2,
    /// Cost of the predicted pose plus the prediction's risk (see
    /// [`PushChoiceSettings::spread_weight`]); compare with [`PushPlanner::cost`] of the
    /// present one.
    pub cost: f64,
    /// Along a path ([`PushPlanner::plan_along`]): the predicted centroid track's mean
    /// distance to the path (offset as asked), m, sampled at a quarter, half, three
    /// quarters and the end of the push; 0 elsewhere.
    pub track_m: f64,
    /// Where the robot starts the push and the heading it drives at, world frame.
    pub start: Pose2,
}

/// Chooses pushes for one object from its affordance gradient (or, for the `model`
/// planner, from a table of predictions made otherwise: [`PushPlanner::from_predictions`]).
#[derive(Debug, Clone)]
pub struct PushPlanner<'a> {
    /// The gradient's predictor; `None` for a planner on a table of predictions.
    predictor: Option<PushPredictor<'a>>,
    settings: PushChoiceSettings,
    contacts: Vec<DVec2>,
    alphas: Vec<f64>,
    /// The predictor's prediction of every (contact, alpha) pair, contact-major: what the
    /// search reads. A prediction depends on the gradient alone, not on the object's pose
    /// or the goal, so it is made once here: the search itself then costs microseconds, not
    /// the tens of milliseconds of its 1,500 predictions (a realtime planner decides
    /// within a physics period).
    predictions: Vec<Option<Prediction>>,
    /// The heading (object frame, unit) of every (contact, alpha) pair's push from the
    /// start circle, in the order of `predictions`; `None` where no start sends it.
    headings: Vec<Option<DVec2>>,
    radius: f64,
}

/// The heading of the push from each (contact, alpha) pair's start, contact-major as the
/// predictions are; `None` where no start reaches the contact.
fn headings_of(contacts: &[DVec2], alphas: &[f64], start_radius_m: f64) -> Vec<Option<DVec2>> {
    contacts
        .iter()
        .flat_map(|&c| alphas.iter().map(move |&a| (c, a)))
        .map(|(c, a)| approach_start(c, a, start_radius_m).map(|(_, h)| DVec2::from_angle(h)))
        .collect()
}

impl<'a> PushPlanner<'a> {
    /// Precomputes the contact candidates, the alphas to try, the predictor for pushes
    /// from the start circle and its prediction of every candidate push (allocates; once
    /// per AG).
    pub fn new(ag: &'a AffordanceGradient, settings: PushChoiceSettings) -> Self {
        let contacts = ag.contact_candidates(settings.contact_count);
        let radius = contacts.iter().map(|c| c.length()).fold(0.0, f64::max);
        let learned: Vec<f64> = ag.alphas_deg().collect();
        let lo = learned.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = learned.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut alphas = Vec::new();
        if lo.is_finite() && hi.is_finite() {
            let step = settings.alpha_step_deg.max(0.1);
            let n = ((hi - lo) / step).round() as usize;
            for k in 0..=n {
                alphas.push((lo + k as f64 * step).min(hi));
            }
        }
        let predictor = PushPredictor::new(ag, settings.start_radius_m);
        let predictions = contacts
            .iter()
            .flat_map(|&c| alphas.iter().map(move |&a| (c, a)))
            .map(|(c, a)| predictor.predict(c, a))
            .collect();
        let headings = headings_of(&contacts, &alphas, settings.start_radius_m);
        Self {
            predictor: Some(predictor),
            settings,
            contacts,
            alphas,
            predictions,
            headings,
            radius,
        }
    }

    /// What the search predicts pushes with: pushes from the start circle, interpolated
    /// between learned alphas along each start (see [`PushPredictor`]); `None` for a
    /// planner on a table of predictions ([`PushPlanner::from_predictions`]).
    pub fn predictor(&self) -> Option<&PushPredictor<'a>> {
        self.predictor.as_ref()
    }

    /// The same search on predictions made otherwise (the `model` planner's): `predictions`
    /// holds the full-length prediction of every (contact, alpha) pair, contact-major, as
    /// [`PushPlanner::new`] makes them from a gradient.
    #[track_caller]
    pub fn from_predictions(
        contacts: Vec<DVec2>,
        alphas: Vec<f64>,
        predictions: Vec<Option<Prediction>>,
        settings: PushChoiceSettings,
    ) -> PushPlanner<'static> {
        assert_eq!(
            predictions.len(),
            contacts.len() * alphas.len(),
            "one prediction per (contact, alpha)"
        );
        let radius = contacts.iter().map(|c| c.length()).fold(0.0, f64::max);
        let headings = headings_of(&contacts, &alphas, settings.start_radius_m);
        PushPlanner {
            predictor: None,
            settings,
            contacts,
            alphas,
            predictions,
            headings,
            radius,
        }
    }

    /// The full-length prediction of the push at `contact` (object frame) and `alpha_deg`:
    /// the gradient's predictor's, or the table's entry for that exact pair.
    pub fn predict(&self, contact: DVec2, alpha_deg: f64) -> Option<Prediction> {
        if let Some(p) = &self.predictor {
            return p.predict(contact, alpha_deg);
        }
        let i = self.contacts.iter().position(|c| *c == contact)?;
        let j = self.alphas.iter().position(|a| *a == alpha_deg)?;
        self.predictions
            .get(i * self.alphas.len() + j)
            .copied()
            .flatten()
    }

    /// The same planner trying only these push lengths (fractions of the learned push):
    /// shares the predictions already made instead of making them again.
    pub fn with_push_fractions(&self, push_fractions: Vec<f64>) -> Self {
        Self {
            settings: PushChoiceSettings {
                push_fractions,
                ..self.settings.clone()
            },
            ..self.clone()
        }
    }

    pub fn settings(&self) -> &PushChoiceSettings {
        &self.settings
    }

    /// The farthest contact candidate from the centroid: the object's learned radius, m.
    pub fn object_radius(&self) -> f64 {
        self.radius
    }

    /// The contact candidates, object frame.
    pub fn contacts(&self) -> &[DVec2] {
        &self.contacts
    }

    /// How far `pose` is from `goal`: metres plus weighted orientation error.
    pub fn cost(&self, pose: Pose2, goal: &Goal) -> f64 {
        match goal {
            Goal::Place { pose: g } => {
                let d = DVec2::new(pose.x - g.x, pose.y - g.y).length();
                let e = symmetric_angle_error(pose.theta - g.theta, self.settings.symmetry_order);
                d + self.settings.orientation_weight_m_per_rad * e.abs()
            }
            Goal::Reach { target } => (DVec2::new(pose.x, pose.y) - *target).length(),
        }
    }

    /// One candidate push of `fraction` of the learned push, whose full-length prediction
    /// is `p`: the prediction scaled to that length (see
    /// [`PushChoiceSettings::fraction_offset`]), the object's predicted pose from
    /// `estimate`, and the push's cost: [`PushPlanner::cost`] of that pose plus the
    /// prediction's risk and, with [`Goal::Reach`], its turn.
    pub fn score(
        &self,
        p: &Prediction,
        fraction: f64,
        estimate: Pose2,
        goal: &Goal,
    ) -> (Prediction, Pose2, f64) {
        let s = &self.settings;
        let scale = (fraction + s.fraction_offset) / (1.0 + s.fraction_offset);
        let scaled = Prediction {
            displacement: p.displacement * scale,
            rotation_rad: p.rotation_rad * scale,
            ..*p
        };
        let predicted = scaled.apply_to(estimate);
        let risk = s.spread_weight
            * scale
            * (p.displacement_spread_m + s.spread_lever_m * p.rotation_spread_rad);
        let turn = match goal {
            Goal::Reach { .. } => s.reach_rotation_weight_m_per_rad * scaled.rotation_rad.abs(),
            Goal::Place { .. } => 0.0,
        };
        (scaled, predicted, self.cost(predicted, goal) + risk + turn)
    }

    /// The push whose predicted outcome is closest to `goal` from the object's estimated
    /// pose `estimate` (world frame); `None` if the AG predicts nothing anywhere.
    pub fn plan(&self, estimate: Pose2, goal: &Goal) -> Option<PushPlan> {
        let mut best: Option<PushPlan> = None;
        let predictions = self.predictions.chunks_exact(self.alphas.len().max(1));
        for (&c, row) in self.contacts.iter().zip(predictions) {
            for (&alpha, p) in self.alphas.iter().zip(row) {
                let Some(p) = *p else {
                    continue;
                };
                if p.confidence < self.settings.min_confidence {
                    continue;
                }
                for &f in &self.settings.push_fractions {
                    let (scaled, predicted, cost) = self.score(&p, f, estimate, goal);
                    if best.is_some_and(|b| b.cost <= cost) {
                        continue;
                    }
                    let Some((s, h)) = approach_start(c, alpha, self.settings.start_radius_m)
                    else {
                        continue;
                    };
                    let rot = DVec2::from_angle(estimate.theta);
                    let sw = DVec2::new(estimate.x, estimate.y) + rot.rotate(s);
                    best = Some(PushPlan {
                        contact_obj: c,
                        alpha_deg: alpha,
                        fraction: f,
                        prediction: scaled,
                        uncorrected_cross: DVec2::ZERO,
                        uncorrected_rotation_rad: scaled.rotation_rad,
                        predicted,
                        cost,
                        track_m: 0.0,
                        start: Pose2::new(sw.x, sw.y, wrap_angle(h + estimate.theta)),
                    });
                }
            }
        }
        best
    }
}

/// What a push along a path is after (see [`PushPlanner::plan_along`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathFollowing<'p> {
    /// The polyline to follow, world frame, m.
    pub path: &'p [DVec2],
    /// Push lengths tried, fractions of the learned push (as
    /// [`PushChoiceSettings::push_fractions`]; along a path shorter pushes keep closer).
    pub push_fractions: &'p [f64],
    /// How far along the path (m) one push should bring the centroid: pushes that advance
    /// less, or more, pay for the difference (see `progress_weight`). Near the path's end,
    /// what is left of it.
    pub advance_m: f64,
    /// Metres of cost per metre of the predicted centroid track's mean distance to the
    /// path over the push (the predicted end's distance counts once more on its own).
    pub track_weight: f64,
    /// Metres of cost per metre the push advances short of (or past) `advance_m`.
    pub progress_weight: f64,
    /// Keep the object's heading (its frame's x axis) to the path's tangent within this
    /// (rad): the predicted end's orientation is compared with the tangent where it ends,
    /// modulo the symmetry, and each radian beyond the tolerance costs `heading_weight`.
    pub heading_tolerance_rad: Option<f64>,
    /// Metres of cost per radian of heading beyond its tolerance.
    pub heading_weight_m_per_rad: f64,
    /// Keep the centroid this far (m) to the path's left (negative: its right) instead of
    /// on it: how the planner cancels a bias of the pushes it makes, which the circlings
    /// measure (see `EpisodeConfig::cross_track_gain`).
    pub offset_m: f64,
    /// The share of its predicted sideways motion (across the push's heading) that a push
    /// shorter than the learned one makes: the gradient learned full pushes, and a short
    /// push ends while the object is still mostly being pushed along the heading (the
    /// robot's speed ramp, the contact settling), so it carries the object sideways far
    /// less than its scaled prediction says. 1 predicts short pushes as before (the
    /// learned push scaled); full pushes are never corrected.
    pub cross_gain: f64,
    /// The same for the rotation: the share of its predicted rotation that a push shorter
    /// than the learned one makes.
    pub turn_gain: f64,
    /// Metres of cost per metre of a short push's sideways motion as the gradient predicts
    /// it (before `cross_gain`): the share a short push makes varies from push to push and
    /// seed to seed (a tenth to the whole of it), so a push that needs its sideways motion
    /// to keep to the path is a gamble; 0 trusts the corrected prediction.
    pub cross_doubt: f64,
}

/// The sideways part of `displacement` across the unit `heading`.
fn across(displacement: DVec2, heading: DVec2) -> DVec2 {
    displacement - displacement.dot(heading) * heading
}

/// The arc length (m) along `path` of the point of it closest to `p`, and the distance
/// (m) of `p` to it.
pub fn path_projection(path: &[DVec2], p: DVec2) -> (f64, f64) {
    let (s, d) = path_offset(path, p);
    (s, d.abs())
}

/// [`path_projection`] with the distance signed: positive on the path's left (of the
/// direction of the closest segment), negative on its right.
pub fn path_offset(path: &[DVec2], p: DVec2) -> (f64, f64) {
    let (mut best_d, mut best_s, mut best_side, mut s0) = (f64::INFINITY, 0.0, 1.0, 0.0);
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let ab = b - a;
        let len = ab.length();
        let t = if len > 1e-12 {
            ((p - a).dot(ab) / (len * len)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = (a + t * ab - p).length();
        if d < best_d {
            best_d = d;
            best_s = s0 + t * len;
            best_side = if ab.perp_dot(p - a) < 0.0 { -1.0 } else { 1.0 };
        }
        s0 += len;
    }
    if path.len() == 1 {
        return (0.0, (p - path[0]).length());
    }
    (best_s, best_side * best_d)
}

/// The direction (rad) of `path` at arc length `s` (its last segment's beyond the end).
pub fn path_direction_at(path: &[DVec2], s: f64) -> f64 {
    let mut left = s;
    let mut last = 0.0;
    for w in path.windows(2) {
        let d = w[1] - w[0];
        let len = d.length();
        if len <= 1e-12 {
            continue;
        }
        last = d.to_angle();
        if left <= len {
            return last;
        }
        left -= len;
    }
    last
}

impl PushPlanner<'_> {
    /// The push that carries the centroid along `follow.path`: every candidate push
    /// (contact, alpha, length) is scored on the AG's prediction by the predicted centroid
    /// track's distance to the path (its straight run from the estimate to the predicted
    /// end, sampled at four points), the end's distance once more, how far short of (or
    /// past) `advance_m` along the path it ends, the prediction's risk and turn (as
    /// [`PushPlanner::score`] weighs them) and, when the heading is asked for, the end
    /// heading's error beyond its tolerance. `None` if the AG predicts nothing anywhere.
    pub fn plan_along(&self, estimate: Pose2, follow: &PathFollowing<'_>) -> Option<PushPlan> {
        let (s0, _) = path_projection(follow.path, DVec2::new(estimate.x, estimate.y));
        let mut best: Option<PushPlan> = None;
        let width = self.alphas.len().max(1);
        let predictions = self.predictions.chunks_exact(width);
        let headings = self.headings.chunks_exact(width);
        for ((&c, row), heads) in self.contacts.iter().zip(predictions).zip(headings) {
            for ((&alpha, p), heading) in self.alphas.iter().zip(row).zip(heads) {
                let Some(p) = *p else {
                    continue;
                };
                if p.confidence < self.settings.min_confidence {
                    continue;
                }
                for &f in follow.push_fractions {
                    let scored = self.score_along(estimate, follow, s0, &p, *heading, f);
                    if best.is_some_and(|b| b.cost <= scored.cost) {
                        continue;
                    }
                    if let Some(plan) = self.plan_of(estimate, c, alpha, f, &p, scored) {
                        best = Some(plan);
                    }
                }
            }
        }
        best
    }

    /// The push through the centroid (alpha 0, or the learned alpha nearest it) heading
    /// most nearly along `toward` (world frame), `fraction` of the learned push long: the
    /// push the baseline planner makes, scored as [`PushPlanner::plan_along`] scores its
    /// candidates (the contact is the candidate whose ray from the centroid points most
    /// nearly against `toward`, within half the candidates' spacing). `None` if the AG
    /// predicts that push with too little confidence, or no start reaches it.
    pub fn plan_along_centroid_push(
        &self,
        estimate: Pose2,
        follow: &PathFollowing<'_>,
        toward: DVec2,
        fraction: f64,
    ) -> Option<PushPlan> {
        if toward.length_squared() <= 0.0 || self.alphas.is_empty() {
            return None;
        }
        // The push heads from the contact to the centroid: the contact is behind it.
        let back = DVec2::from_angle(-estimate.theta)
            .rotate(-toward)
            .normalize();
        let (i, _) = self
            .contacts
            .iter()
            .enumerate()
            .filter(|(_, c)| c.length_squared() > 0.0)
            .map(|(i, c)| (i, c.normalize().dot(back)))
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        let (j, _) = self
            .alphas
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
        let k = i * self.alphas.len() + j;
        let p = self.predictions.get(k).copied().flatten()?;
        if p.confidence < self.settings.min_confidence {
            return None;
        }
        let heading = self.headings.get(k).copied().flatten();
        let (s0, _) = path_projection(follow.path, DVec2::new(estimate.x, estimate.y));
        let scored = self.score_along(estimate, follow, s0, &p, heading, fraction);
        self.plan_of(
            estimate,
            self.contacts[i],
            self.alphas[j],
            fraction,
            &p,
            scored,
        )
    }

    /// The cost of one candidate push along `follow.path` (see [`PushPlanner::plan_along`])
    /// whose full-length prediction is `p`, its heading `heading` (object frame, unit),
    /// `f` of the learned push long, from `estimate` at arc length `s0` of the path.
    fn score_along(
        &self,
        estimate: Pose2,
        follow: &PathFollowing<'_>,
        s0: f64,
        p: &Prediction,
        heading: Option<DVec2>,
        f: f64,
    ) -> AlongScore {
        let s = &self.settings;
        let c0 = DVec2::new(estimate.x, estimate.y);
        let rot = DVec2::from_angle(estimate.theta);
        let scale = (f + s.fraction_offset) / (1.0 + s.fraction_offset);
        // The sideways part of a short push, corrected (see `cross_gain`).
        let cross = match heading {
            Some(u) if f < 1.0 => across(p.displacement * scale, u),
            _ => DVec2::ZERO,
        };
        let displacement = p.displacement * scale + (follow.cross_gain - 1.0) * cross;
        let moved = rot.rotate(displacement);
        let c1 = c0 + moved;
        let mut track = 0.0;
        for k in 1..=4 {
            let at = c0 + moved * (f64::from(k) / 4.0);
            track += (path_offset(follow.path, at).1 - follow.offset_m).abs();
        }
        let (s1, d1) = path_offset(follow.path, c1);
        let d1 = (d1 - follow.offset_m).abs();
        let turn = if f < 1.0 { follow.turn_gain } else { 1.0 };
        let rotation = p.rotation_rad * scale * turn;
        let risk = s.spread_weight
            * scale
            * (p.displacement_spread_m + s.spread_lever_m * p.rotation_spread_rad);
        let heading_cost = follow.heading_tolerance_rad.map_or(0.0, |tolerance| {
            let want = path_direction_at(follow.path, s1);
            let off =
                symmetric_angle_error(estimate.theta + rotation - want, s.symmetry_order).abs();
            follow.heading_weight_m_per_rad * (off - tolerance).max(0.0)
        });
        let cost = follow.track_weight * track / 4.0
            + d1
            + follow.cross_doubt * cross.length()
            + follow.progress_weight * (s1 - s0 - follow.advance_m).abs()
            + risk
            + s.reach_rotation_weight_m_per_rad * rotation.abs()
            + heading_cost;
        AlongScore {
            cost,
            track_m: track / 4.0,
            displacement,
            rotation,
            cross,
            uncorrected_rotation: p.rotation_rad * scale,
        }
    }

    /// The plan of a scored candidate push at `contact` (object frame) and `alpha`, `f`
    /// of the learned push long, whose full-length prediction is `p`; `None` if no start
    /// on the circle reaches the contact.
    fn plan_of(
        &self,
        estimate: Pose2,
        contact: DVec2,
        alpha: f64,
        f: f64,
        p: &Prediction,
        scored: AlongScore,
    ) -> Option<PushPlan> {
        let (start, h) = approach_start(contact, alpha, self.settings.start_radius_m)?;
        let rot = DVec2::from_angle(estimate.theta);
        let sw = DVec2::new(estimate.x, estimate.y) + rot.rotate(start);
        let scaled = Prediction {
            displacement: scored.displacement,
            rotation_rad: scored.rotation,
            ..*p
        };
        Some(PushPlan {
            contact_obj: contact,
            alpha_deg: alpha,
            fraction: f,
            prediction: scaled,
            uncorrected_cross: scored.cross,
            uncorrected_rotation_rad: scored.uncorrected_rotation,
            predicted: scaled.apply_to(estimate),
            cost: scored.cost,
            track_m: scored.track_m,
            start: Pose2::new(sw.x, sw.y, wrap_angle(h + estimate.theta)),
        })
    }
}

/// One candidate push along a path, scored (see [`PushPlanner::plan_along`]).
#[derive(Debug, Clone, Copy)]
struct AlongScore {
    cost: f64,
    /// The predicted track's mean distance to the path (offset by `offset_m`), m.
    track_m: f64,
    /// The predicted displacement (object frame, m) and rotation (rad), corrected.
    displacement: DVec2,
    rotation: f64,
    /// The sideways part before the correction (see [`PushPlan::uncorrected_cross`]).
    cross: DVec2,
    uncorrected_rotation: f64,
}

/// `angle` (radians) wrapped to the nearest equivalent under a symmetry of `order`
/// (0: every angle is equivalent, the error is 0; 1: none, wrap to (-pi, pi]).
pub fn symmetric_angle_error(angle: f64, order: u32) -> f64 {
    if order == 0 {
        return 0.0;
    }
    let period = std::f64::consts::TAU / f64::from(order);
    angle::wrap_to_half_period(angle, period)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_projects_on_the_closest_segment_at_its_arc_length() {
        let path = [DVec2::ZERO, DVec2::new(0.3, 0.0), DVec2::new(0.3, 0.2)];
        let (s, d) = path_projection(&path, DVec2::new(0.1, 0.02));
        assert!(
            (s - 0.1).abs() < 1e-12 && (d - 0.02).abs() < 1e-12,
            "{s} {d}"
        );
        // Signed: left of the first leg (heading +x) is +y, right of the second (+y) is +x.
        assert!((path_offset(&path, DVec2::new(0.1, 0.02)).1 - 0.02).abs() < 1e-12);
        assert!((path_offset(&path, DVec2::new(0.1, -0.02)).1 + 0.02).abs() < 1e-12);
        assert!((path_offset(&path, DVec2::new(0.33, 0.05)).1 + 0.03).abs() < 1e-12);
        // Beside the second leg: 0.3 along the first, 0.05 up the second.
        let (s, d) = path_projection(&path, DVec2::new(0.33, 0.05));
        assert!(
            (s - 0.35).abs() < 1e-12 && (d - 0.03).abs() < 1e-12,
            "{s} {d}"
        );
        // Before the start: the start, at its distance.
        let (s, d) = path_projection(&path, DVec2::new(-0.03, 0.04));
        assert!(s.abs() < 1e-12 && (d - 0.05).abs() < 1e-12, "{s} {d}");
    }

    /// A disc of radius 40 mm that every push (alphas 0 and +-15) moves 30 mm along the
    /// push's heading, without turning it: pushes are learned every 3 deg round it from
    /// the start circle of radius 100 mm.
    fn sliding_disc() -> AffordanceGradient {
        disc_moved_at(0.0)
    }

    /// The disc of [`sliding_disc`], each push carrying it 30 mm at `drift_rad` to the left
    /// of the push's heading.
    fn disc_moved_at(drift_rad: f64) -> AffordanceGradient {
        use agp_affordance::{AffordanceLearner, LearnerConfig, PushOutcome};
        let config = LearnerConfig::default();
        let mut learner = AffordanceLearner::new("disc", &config).expect("learner");
        for &alpha in &config.alphas_deg {
            for k in 0..360 {
                let p = 0.04 * DVec2::from_angle(f64::from(k).to_radians());
                learner.add_border_point(alpha, p).expect("border point");
            }
            for k in 0..120 {
                let phi = f64::from(3 * k).to_radians();
                let c = 0.04 * DVec2::from_angle(phi);
                let Some((_, heading)) = approach_start(c, alpha, 0.1) else {
                    continue;
                };
                let push = PushOutcome {
                    contact_point_obj: c,
                    displacement_obj: 0.03 * DVec2::from_angle(heading + drift_rad),
                    rotation_rad: 0.0,
                    heading_obj: DVec2::from_angle(heading),
                };
                learner.add_push(alpha, &push).expect("push");
            }
        }
        learner.into_gradient()
    }

    /// Following `path` with pushes of `push_fractions`, aiming `advance_m` on: the
    /// tests' weights (track 3, progress 0.5), no heading, no offset, half the sideways
    /// share, no doubt.
    fn along<'p>(
        path: &'p [DVec2],
        push_fractions: &'p [f64],
        advance_m: f64,
    ) -> PathFollowing<'p> {
        PathFollowing {
            path,
            push_fractions,
            advance_m,
            track_weight: 3.0,
            progress_weight: 0.5,
            heading_tolerance_rad: None,
            heading_weight_m_per_rad: 0.0,
            offset_m: 0.0,
            cross_gain: 0.5,
            turn_gain: 1.0,
            cross_doubt: 0.0,
        }
    }

    #[test]
    fn a_path_offset_moves_the_planned_track_by_the_offset() {
        let ag = sliding_disc();
        let planner = PushPlanner::new(&ag, PushChoiceSettings::new(0, 0.1));
        let path = [DVec2::ZERO, DVec2::new(0.6, 0.0)];
        // The disc sits 2 mm left of the path; a full push moves it 30 mm.
        let from = Pose2::new(0.0, 0.002, 0.0);
        let end = |offset_m: f64| {
            let follow = PathFollowing {
                offset_m,
                cross_gain: 1.0,
                ..along(&path, &[1.0], 0.03)
            };
            let plan = planner.plan_along(from, &follow).expect("a push");
            DVec2::new(plan.predicted.x, plan.predicted.y)
        };
        // On the path the push heads back to it; 3 mm to the right, past it by that much.
        let on = end(0.0);
        let right = end(-0.003);
        assert!(on.y.abs() < 0.001, "ends {:.2} mm off the path", on.y * 1e3);
        assert!(
            (right.y + 0.003).abs() < 0.001,
            "ends {:.2} mm off the path, 3 mm to its right asked",
            right.y * 1e3
        );
        assert!(on.x > 0.025 && right.x > 0.025, "{on} {right}");
    }

    /// The disc of [`sliding_disc`], but every push carries it 30 mm at 30 deg to the left
    /// of the push's heading.
    fn drifting_disc() -> AffordanceGradient {
        disc_moved_at(30f64.to_radians())
    }

    #[test]
    fn a_short_path_push_is_predicted_to_drift_sideways_by_the_cross_gains_share() {
        let ag = drifting_disc();
        let planner = PushPlanner::new(&ag, PushChoiceSettings::new(0, 0.1));
        let path = [DVec2::ZERO, DVec2::new(0.6, 0.0)];
        let plan = |cross_gain: f64, fraction: f64| {
            let fractions = [fraction];
            let follow = PathFollowing {
                cross_gain,
                ..along(&path, &fractions, 0.01)
            };
            planner
                .plan_along(Pose2::new(0.0, 0.0, 0.0), &follow)
                .expect("a push")
        };
        let k = planner.settings().fraction_offset;
        let scale = (0.25 + k) / (1.0 + k);
        for gain in [1.0, 0.5, 0.2] {
            let p = plan(gain, 0.25);
            let (_, h) = approach_start(p.contact_obj, p.alpha_deg, 0.1).expect("a start");
            let u = DVec2::from_angle(h);
            let d = p.prediction.displacement;
            // Along the heading, the learned 30 mm x cos 30 deg scaled; across it, the
            // learned 15 mm scaled and then the share asked (smoothing a uniform field
            // keeps it within a few per cent).
            let along = d.dot(u);
            let side = u.perp_dot(d);
            assert!(
                (along - scale * 0.03 * 30f64.to_radians().cos()).abs() < 0.03 * scale * 0.03,
                "gain {gain}: along {:.2} mm",
                along * 1e3
            );
            assert!(
                (side - gain * scale * 0.015).abs() < 0.05 * scale * 0.015,
                "gain {gain}: across {:.2} mm",
                side * 1e3
            );
            assert!(
                (u.perp_dot(p.uncorrected_cross) - scale * 0.015).abs() < 0.05 * scale * 0.015,
                "gain {gain}: uncorrected across {:.2} mm",
                u.perp_dot(p.uncorrected_cross) * 1e3
            );
        }
        // A full push is predicted as learned, whatever the share.
        let full = plan(0.2, 1.0);
        assert_eq!(full.uncorrected_cross, DVec2::ZERO);
        let (_, h) = approach_start(full.contact_obj, full.alpha_deg, 0.1).expect("a start");
        let side = DVec2::from_angle(h).perp_dot(full.prediction.displacement);
        assert!((side - 0.015).abs() < 0.05 * 0.015, "{:.2} mm", side * 1e3);
    }

    #[test]
    fn a_sideways_doubt_charges_each_short_push_its_sideways_motion_and_never_picks_more_of_it() {
        let ag = drifting_disc();
        let planner = PushPlanner::new(&ag, PushChoiceSettings::new(0, 0.1));
        let path = [DVec2::ZERO, DVec2::new(0.6, 0.0)];
        let plan = |cross_doubt: f64| {
            let follow = PathFollowing {
                cross_doubt,
                ..along(&path, &[0.375, 0.25], 0.04)
            };
            planner
                .plan_along(Pose2::new(0.0, 0.002, 0.0), &follow)
                .expect("a push")
        };
        let free = plan(0.0);
        for doubt in [0.5, 2.0, 10.0] {
            let p = plan(doubt);
            let (x0, x1) = (
                free.uncorrected_cross.length(),
                p.uncorrected_cross.length(),
            );
            // The best push with the charge costs at least the best without it plus its own
            // charge, and at most the free best's cost plus the free best's charge.
            assert!(p.cost - doubt * x1 >= free.cost - 1e-12, "doubt {doubt}");
            assert!(p.cost <= free.cost + doubt * x0 + 1e-12, "doubt {doubt}");
            // So it never carries the object sideways more than the free choice.
            assert!(x1 <= x0 + 1e-12, "doubt {doubt}: {x1} > {x0}");
        }
    }

    #[test]
    fn the_baseline_push_runs_through_the_centroid_at_the_target_and_is_scored_as_the_search_scores()
     {
        let ag = sliding_disc();
        let planner = PushPlanner::new(&ag, PushChoiceSettings::new(0, 0.1));
        let path = [DVec2::ZERO, DVec2::new(0.6, 0.0)];
        let follow = |fractions: &'static [f64]| along(&path, fractions, 0.03);
        // The disc 3 mm left of the path, turned 0.7 rad (the search works in its frame);
        // the target 40 mm on along the path.
        let from = Pose2::new(0.1, 0.003, 0.7);
        let toward = DVec2::new(0.04, -0.003);
        let base = planner
            .plan_along_centroid_push(from, &follow(&[0.8]), toward, 0.8)
            .expect("a centroid push");
        // Through the centroid, from behind it, within half the contacts' spacing (1.5 deg
        // for 120 of them) of the target's direction.
        assert_eq!(base.alpha_deg, 0.0);
        let off = wrap_angle(base.start.theta - toward.to_angle()).to_degrees();
        assert!(
            off.abs() <= 1.5 + 1e-9,
            "heading {off:.2} deg off the target's"
        );
        let back = DVec2::new(base.start.x - from.x, base.start.y - from.y);
        assert!(
            back.normalize().dot(-toward.normalize()) > 0.999,
            "starts at {back} from the centroid"
        );
        // The disc moves 30 mm along the heading for a full push: 0.8 of it is scaled by
        // the fraction offset, and the prediction is along the heading (no sideways part).
        let k = planner.settings().fraction_offset;
        let moved = DVec2::new(base.predicted.x - from.x, base.predicted.y - from.y);
        let want = 0.03 * (0.8 + k) / (1.0 + k);
        assert!(
            (moved.length() - want).abs() < 0.03 * want,
            "moved {:.2} mm, {:.2} mm expected",
            moved.length() * 1e3,
            want * 1e3
        );
        // Its track's mean distance to the path, at a quarter, half, three quarters and
        // the end of the straight run.
        let track: f64 = (1..=4)
            .map(|q| (from.y + moved.y * f64::from(q) / 4.0).abs())
            .sum::<f64>()
            / 4.0;
        assert!(
            (base.track_m - track).abs() < 1e-9,
            "{} against {track}",
            base.track_m
        );
        // The search over every push of that length finds none worse than it.
        let best = planner.plan_along(from, &follow(&[0.8])).expect("a push");
        assert!(
            best.cost <= base.cost + 1e-12,
            "{} > {}",
            best.cost,
            base.cost
        );
    }

    #[test]
    fn the_path_direction_is_its_segments_and_the_last_beyond_the_end() {
        let path = [DVec2::ZERO, DVec2::new(0.3, 0.0), DVec2::new(0.3, 0.2)];
        assert_eq!(path_direction_at(&path, 0.1), 0.0);
        let up = std::f64::consts::FRAC_PI_2;
        assert!((path_direction_at(&path, 0.4) - up).abs() < 1e-12);
        assert!((path_direction_at(&path, 2.0) - up).abs() < 1e-12);
    }

    #[test]
    fn orientation_errors_wrap_by_the_objects_symmetry() {
        let deg = f64::to_radians;
        assert!((symmetric_angle_error(deg(100.0), 3) - deg(-20.0)).abs() < 1e-12);
        assert!((symmetric_angle_error(deg(80.0), 4) - deg(-10.0)).abs() < 1e-12);
        assert!((symmetric_angle_error(deg(190.0), 1) - deg(-170.0)).abs() < 1e-12);
        assert_eq!(symmetric_angle_error(1.0, 0), 0.0);
    }
}
