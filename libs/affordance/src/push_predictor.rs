use std::borrow::Cow;

use glam::DVec2;

use crate::affordance_gradient::ALPHA_EPS_DEG;
use crate::{AIM_BORDER_THRESHOLD, AffordanceGradient, Grid, Prediction, meets_past_centroid};

/// Predicts pushes of the learning protocol's family from an [`AffordanceGradient`]: pushes
/// that start on the centroid-centred circle of radius `start_radius_m` (where the learning
/// trials started) heading at the centroid turned by alpha, keyed by their aim point (where
/// the heading line meets the object's border) as the learned gradient is.
///
/// # Between learned alphas
/// [`AffordanceGradient::predict`] interpolates between two learned alphas at the same aim
/// point. Those two pushes start far apart on the circle and meet the object along lines
/// that cross at the aim point: near a corner one of them can land on another face. The
/// effect of a push changes smoothly with alpha when the push keeps its start instead
/// (the robot turns on the spot), so this predictor interpolates along that family: for a
/// push at aim point `c` and alpha `a` between learned `a0 < a < a1`, it finds the start
/// `s` on the circle ([`approach_start`]), the aim points `c0`, `c1` of the pushes from `s`
/// at `a0` and `a1` (where their heading lines cross the learned border, as the estimator
/// locates aim points), and blends the gradient's predictions there. At a learned alpha it
/// answers exactly as [`AffordanceGradient::predict`] does; where a neighbour's line misses
/// the learned border it falls back to that too.
///
/// # Before or past the centroid
/// At alpha != 0 two starts on the circle send a push through the same aim point: one
/// meets the border before its heading line passes closest to the centroid, the other past
/// it ([`meets_past_centroid`]), and the gradient keeps their effects apart.
/// [`PushPredictor::predict`] answers for the first (the nearer start, a planner's push);
/// [`PushPredictor::predict_push`] for the push its heading names; between alphas, each
/// neighbouring alpha's push from the same start is read from its own branch.
#[derive(Debug, Clone)]
pub struct PushPredictor<'a> {
    ag: &'a AffordanceGradient,
    /// S over all alphas, normalised: where aim points are located (owned, or borrowed
    /// from a caller that keeps it, see [`PushPredictor::borrowing`]).
    shape: Cow<'a, Grid>,
    start_radius_m: f64,
}

impl<'a> PushPredictor<'a> {
    /// A predictor for pushes starting at `start_radius_m` from the centroid. Allocates the
    /// combined shape once: build it once per gradient, not per push.
    pub fn new(ag: &'a AffordanceGradient, start_radius_m: f64) -> Self {
        Self {
            ag,
            shape: Cow::Owned(ag.combined_shape()),
            start_radius_m,
        }
    }

    /// A predictor that locates aim points on `shape`, borrowed: `ag.combined_shape()` kept
    /// by the caller (or another normalised S in the gradient's frame, as for
    /// [`PushPredictor::with_shape`]). Allocates nothing: a caller that keeps the gradient
    /// and its shape can build one per push.
    pub fn borrowing(ag: &'a AffordanceGradient, shape: &'a Grid, start_radius_m: f64) -> Self {
        Self {
            ag,
            shape: Cow::Borrowed(shape),
            start_radius_m,
        }
    }

    /// A predictor that locates aim points on `shape` (a normalised S in the gradient's
    /// frame) instead of the gradient's own S: for a gradient learned without border points.
    pub fn with_shape(ag: &'a AffordanceGradient, shape: Grid, start_radius_m: f64) -> Self {
        Self {
            ag,
            shape: Cow::Owned(shape),
            start_radius_m,
        }
    }

    /// The gradient predicted from.
    pub fn gradient(&self) -> &'a AffordanceGradient {
        self.ag
    }

    /// Radius of the start circle, m.
    pub fn start_radius_m(&self) -> f64 {
        self.start_radius_m
    }

    /// The combined shape gradient S that aim points are located on.
    pub fn shape(&self) -> &Grid {
        &self.shape
    }

    /// The effect of the push with aim point `contact_point_obj` (object frame) and deviation
    /// `alpha_deg` that starts from the start circle's nearest point (the push a planner
    /// makes, [`approach_start`]); `None` as for [`AffordanceGradient::predict`]. Allocates
    /// nothing.
    pub fn predict(&self, contact_point_obj: DVec2, alpha_deg: f64) -> Option<Prediction> {
        if !contact_point_obj.is_finite() || !alpha_deg.is_finite() {
            return None;
        }
        match approach_start(contact_point_obj, alpha_deg, self.start_radius_m) {
            Some((start, heading)) => self.predict_from(
                contact_point_obj,
                alpha_deg,
                start,
                DVec2::from_angle(heading),
            ),
            None => self.ag.predict(contact_point_obj, alpha_deg),
        }
    }

    /// The effect of the push with aim point `contact_point_obj` and deviation `alpha_deg`
    /// that heads along `heading_obj` (object frame, any length): the push that started
    /// where its heading line enters the start circle, which meets the border before the
    /// centroid or past it ([`meets_past_centroid`]) as its heading says. What a push
    /// whose start is not the planner's choice (the learning benchmark's unseen pushes, a
    /// random angle round the object) needs. `None` as for [`PushPredictor::predict`], or
    /// when the heading is zero or the aim point is outside the start circle. Allocates
    /// nothing.
    pub fn predict_push(
        &self,
        contact_point_obj: DVec2,
        alpha_deg: f64,
        heading_obj: DVec2,
    ) -> Option<Prediction> {
        let c = contact_point_obj;
        let u = heading_obj.try_normalize()?;
        if !c.is_finite() || !alpha_deg.is_finite() {
            return None;
        }
        // |c - t u| = radius with t > 0: where the line enters the circle behind c.
        let cu = c.dot(u);
        let disc = cu * cu - c.length_squared() + self.start_radius_m * self.start_radius_m;
        if disc < 0.0 {
            return None;
        }
        let t = cu + disc.sqrt();
        if t <= 0.0 {
            return None;
        }
        self.predict_from(c, alpha_deg, c - t * u, u)
    }

    /// The push from `start` (on the start circle) heading along the unit `u` through aim
    /// point `c` at deviation `alpha_deg` (see the type's documentation).
    fn predict_from(&self, c: DVec2, alpha_deg: f64, start: DVec2, u: DVec2) -> Option<Prediction> {
        let ag = self.ag;
        let (first, last) = (ag.layers.first()?, ag.layers.last()?);
        if alpha_deg < first.alpha_deg - ALPHA_EPS_DEG || alpha_deg > last.alpha_deg + ALPHA_EPS_DEG
        {
            return None;
        }
        let past = meets_past_centroid(c, u);
        if let Some(k) = ag.layer_index(alpha_deg) {
            return ag.layers[k].predict(c, past);
        }
        let hi = ag.layers.iter().position(|l| l.alpha_deg > alpha_deg)?;
        let (a, b) = (&ag.layers[hi - 1], &ag.layers[hi]);
        let to_centroid = (-start).to_angle();
        let aim = |alpha: f64| {
            let dir = DVec2::from_angle(to_centroid + alpha.to_radians());
            border_crossing(&self.shape, start, dir, AIM_BORDER_THRESHOLD).map(|p| (p, dir))
        };
        let (Some((ca, da)), Some((cb, db))) = (aim(a.alpha_deg), aim(b.alpha_deg)) else {
            return ag.predict_branch(c, alpha_deg, past);
        };
        let t = (alpha_deg - a.alpha_deg) / (b.alpha_deg - a.alpha_deg);
        AffordanceGradient::blend(
            a.predict(ca, meets_past_centroid(ca, da)),
            b.predict(cb, meets_past_centroid(cb, db)),
            t,
        )
    }

    /// [`PushPredictor::predict_push`], or where the gradient has too little evidence at the
    /// aim point (no trial's aim point within about 3 sigma), the prediction at the nearest
    /// point within `max_distance_m` that has it (searched in 1 mm rings, 16 directions
    /// each, the heading kept), with confidence 0: a planner that skips unconfident
    /// predictions never picks the push, but a user asking what it would do gets the
    /// nearest learned effect. `None` only when nothing within `max_distance_m` has
    /// evidence. Allocates nothing.
    pub fn predict_push_nearest(
        &self,
        contact_point_obj: DVec2,
        alpha_deg: f64,
        heading_obj: DVec2,
        max_distance_m: f64,
    ) -> Option<Prediction> {
        let predict = |c| self.predict_push(c, alpha_deg, heading_obj);
        if let Some(p) = predict(contact_point_obj) {
            return Some(p);
        }
        let rings = (max_distance_m / NEAREST_RING_STEP_M).floor() as u32;
        (1..=rings)
            .flat_map(|r| {
                (0..NEAREST_DIRECTIONS).map(move |k| {
                    let angle =
                        std::f64::consts::TAU * f64::from(k) / f64::from(NEAREST_DIRECTIONS);
                    contact_point_obj
                        + DVec2::from_angle(angle) * (f64::from(r) * NEAREST_RING_STEP_M)
                })
            })
            .find_map(predict)
            .map(|p| Prediction {
                confidence: 0.0,
                ..p
            })
    }
}

/// Ring spacing of [`PushPredictor::predict_push_nearest`]'s search, m.
const NEAREST_RING_STEP_M: f64 = 0.001;
/// Directions per ring of [`PushPredictor::predict_push_nearest`]'s search.
const NEAREST_DIRECTIONS: u32 = 16;

/// The first crossing of the line from `origin` along the unit vector `dir` with the border
/// that `shape` (normalised S) marks: the centre of the first band of samples at or above
/// `threshold` along the line, each weighted by its excess over the threshold. `None` when
/// the line meets no band. This is how an aim point is located.
pub fn border_crossing(shape: &Grid, origin: DVec2, dir: DVec2, threshold: f32) -> Option<DVec2> {
    let step = 0.25 * shape.cell_size_m();
    // Far enough to cross the whole grid from anywhere near it.
    let end = origin.length() + shape.extent_m();
    let mut t = 0.0;
    while t < end && shape.sample(origin + dir * t) < threshold {
        t += step;
    }
    let (mut weight, mut moment) = (0.0_f64, 0.0_f64);
    while t < end {
        let s = shape.sample(origin + dir * t);
        if s < threshold {
            break;
        }
        let w = f64::from(s - threshold);
        weight += w;
        moment += w * t;
        t += step;
    }
    (weight > 0.0).then(|| origin + dir * (moment / weight))
}

/// Where on the centroid-centred circle of radius `radius` a push with deviation
/// `alpha_deg` must start so that the robot's heading line goes through `contact_obj`:
/// the start position and heading, object frame. The heading is the direction to the
/// centroid turned by alpha (counter-clockwise positive), as in the learning trials.
///
/// Of the starts whose line passes through the contact ahead of the robot, the one
/// nearest to the contact (the contact is then on the near side of the object). `None`
/// if no start reaches the contact (it is outside the circle, or alpha is too large for
/// a contact that close to the centroid's line).
pub fn approach_start(contact_obj: DVec2, alpha_deg: f64, radius: f64) -> Option<(DVec2, f64)> {
    if !(contact_obj.is_finite() && alpha_deg.is_finite() && radius > contact_obj.length()) {
        return None;
    }
    let alpha = alpha_deg.to_radians();
    // With u the heading and s the start, u = rot(alpha)(-s / |s|) gives
    // u x s = radius sin(alpha), and c = s + t u on the line gives u x c = u x s; with
    // gamma the angle of c that is |c| sin(gamma - h) = radius sin(alpha).
    let q = radius * alpha.sin() / contact_obj.length();
    if !(-1.0..=1.0).contains(&q) {
        return None;
    }
    let gamma = contact_obj.to_angle();
    let mut best: Option<(f64, DVec2, DVec2)> = None;
    for h in [gamma - q.asin(), gamma - std::f64::consts::PI + q.asin()] {
        let u = DVec2::from_angle(h);
        // |c - t u| = radius with t > 0: the positive root (|c| < radius).
        let cu = contact_obj.dot(u);
        let t = cu + (cu * cu - contact_obj.length_squared() + radius * radius).sqrt();
        let s = contact_obj - t * u;
        // The deviation is alpha, not pi - alpha: the robot heads towards the centroid.
        if t > 0.0 && u.dot(-s) > 0.0 && best.is_none_or(|b| t < b.0) {
            best = Some((t, s, u));
        }
    }
    // The heading as the angle of its unit vector: in (-pi, pi].
    best.map(|(_, s, u)| (s, u.to_angle()))
}
