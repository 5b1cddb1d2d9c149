//! The prior of an object never pushed: an affordance gradient built from its circled border alone, by the quasi-static mechanics of a point push.
//!
//! What it knows of the object is what one circling saw: border points in the object's
//! frame (the border's centroid at the origin, the axes those of the frame the points were
//! gathered in). From them:
//! - S, as the learning phase learns it from its shape circling (a unit Gaussian per border
//!   point, points thinned to [`ContactPriorConfig::border_spacing_m`] apart);
//! - the support: the border as a ring (the points' mean per angle bin round the
//!   centroid), its area taken as the footprint, pressed on the floor evenly;
//! - each push of the learning protocol's family (from the start circle, heading at the
//!   centroid turned by alpha, aim point where the heading line meets S), its effect by
//!   the quasi-static model of a point push on a body sliding on a floor with an
//!   ellipsoidal limit surface (Lynch, Maekawa and Tanie 1992; Goyal, Ruina and
//!   Papadopoulos 1991): the object's twist `(V, omega)` is along the load `(f, m)` scaled by
//!   the limit surface, `V ~ f`, `omega ~ m / c^2`, with `c` the mean distance of the
//!   footprint from its centroid (`m_max / f_max` under even pressure). If the robot's
//!   front sticks at the contact `r`, its velocity `v` there is `V + omega z x r`, so
//!   `V = M^-1 v` with `M = I + (z x r)(r x .) / c^2`, and `omega = (r x V) / c^2`: a push
//!   whose line passes through the centroid translates the object along the push, an
//!   offset one turns it by the lever arm `r x v` about the centroid, away from the
//!   contact. When the sticking force leaves the contact's friction cone (around the
//!   border's inward normal there, half-angle `atan(mu)`), the contact slides and the force
//!   lies on the cone's edge, the robot's speed along the normal setting its size. The
//!   effect of a push is that twist at first contact times the robot's travel
//!   ([`ContactPriorConfig::push_travel_m`]), its turn at most a quarter turn.
//!
//! Nothing of the object is assumed but what the circling saw and two figures of the
//! robot's own push (its travel after contact, the learning protocol's) and a nominal
//! robot-object friction: no mass, no floor friction (even pressure makes the motion
//! independent of both), no polygon. The online learner then corrects it push by push.

use agp_shared_types::angle;
use glam::DVec2;

use crate::{
    AIM_BORDER_THRESHOLD, AffordanceGradient, AffordanceLearner, LearnerBuildError, LearnerConfig,
    PushOutcome, SampleAddError, border_crossing, learned_border_radius_m,
};

/// How a [`contact_prior`] is built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPriorConfig {
    /// Distance from the robot's centre to the farthest border point of S where each
    /// prior push starts, m: the robot's body radius plus the start gap, as the tracker
    /// and the planner set the start circle from S (37 + 20 mm).
    pub start_clearance_m: f64,
    /// How far the robot travels after contact in a full push, m: the learning protocol's
    /// push, 0.5 s at 100 mm/s (50 mm).
    pub push_travel_m: f64,
    /// Robot-object friction coefficient assumed at the contact (0.3: plastic on plastic;
    /// a nominal figure, not the scenario's).
    pub contact_friction: f64,
    /// Prior pushes per alpha, evenly round the start circle (60: the learning phase's
    /// count, so a task's push weighs against the prior as against learned trials).
    pub trials_per_alpha: u32,
    /// Border points of the circling closer than this to one already added are skipped, m
    /// (1.5 mm, the learning phase's spacing).
    pub border_spacing_m: f64,
    /// Integration steps over the push's travel (1: the twist at first contact times the
    /// travel). Finer steps, with the contact held fixed on the object, turn an offset
    /// push faster and faster (a point push's instability: the lever arm grows as the
    /// object turns), which the robot's round front, sliding along the face, does not
    /// follow; one step keeps the prior's turn at the lever arm's.
    pub substeps: u32,
    /// The limit surface's length `c` as a multiple of the footprint's mean distance from
    /// its centroid (1: even pressure, a point contact that sticks where it touches).
    pub limit_surface_scale: f64,
    /// Later circlings of the task whose border points refine the prior (S and the
    /// footprint built again from every circling's points, the frame's origin moved to
    /// their centroid; `agp_perception`'s tracker does it): 0 never (the default). The
    /// refined pose holds to a lap's tolerance (tested in the tracker's tests; the 7 mm
    /// seen before was the robot's pose after a reset, not the refinement), but on the
    /// tuning seeds 1-10 (`agp bench online --in-process`, 2 episodes a seed) 8 placed the
    /// pentagon 17 of 20 in a median 17.5 pushes, the trapezoid 20 of 20 in 16, the house
    /// 17 of 20 in 14.5, where 0 placed them 20, 20 and 19 of 20 in 18, 14.5 and 13.5: no
    /// better, so it stays 0.
    pub refine_circlings: u32,
}

impl Default for ContactPriorConfig {
    fn default() -> Self {
        Self {
            start_clearance_m: 0.037 + 0.02,
            push_travel_m: 0.05,
            contact_friction: 0.3,
            trials_per_alpha: 60,
            border_spacing_m: 0.0015,
            substeps: 1,
            limit_surface_scale: 1.0,
            refine_circlings: 0,
        }
    }
}

/// Why no [`contact_prior`] could be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ContactPriorBuildError {
    /// Too few border points, or a ring of zero area.
    #[error("the circled border ({points} points) encloses no footprint")]
    NoFootprint {
        /// Border points given.
        points: usize,
    },
    /// A border point lies beyond the gradient's grid.
    #[error(
        "the border seen reaches {:.0} mm from its centroid, the gradient's grid only {:.0} mm",
        .reach_m * 1e3,
        .half_extent_m * 1e3
    )]
    TooLarge {
        /// Farthest border point from the centroid, m.
        reach_m: f64,
        /// Half the grid's side, m.
        half_extent_m: f64,
    },
    /// A figure of the config is out of range.
    #[error("contact prior config: `{0}` out of range")]
    Config(&'static str),
    /// The learner refused the config.
    #[error(transparent)]
    Learner(#[from] LearnerBuildError),
    /// A sample was refused (a non-finite number).
    #[error(transparent)]
    Sample(#[from] SampleAddError),
}

/// The largest turn one prior push makes, rad (90 deg).
const MAX_PRIOR_TURN_RAD: f64 = std::f64::consts::FRAC_PI_2;

/// Angle bins of the support's ring (3 deg each).
const RING_BINS: usize = 120;

/// The footprint of an object seen by one circling, and how a point push moves it.
#[derive(Debug, Clone, PartialEq)]
pub struct PushMechanics {
    /// The border as a counter-clockwise ring round the centroid (object frame, m).
    ring: Vec<DVec2>,
    /// The limit surface's length `c` (m): the mean distance of the footprint from the
    /// origin.
    c: f64,
}

/// A circled border as a ring: the points binned by their angle round `centre` (`BINS`
/// equal bins over the turn), the mean of each bin that holds one, counter-clockwise.
/// Allocates the ring.
pub fn angle_ring<const BINS: usize>(
    points: impl IntoIterator<Item = DVec2>,
    centre: DVec2,
) -> Vec<DVec2> {
    let mut sums = [(DVec2::ZERO, 0usize); BINS];
    for p in points {
        let a = angle::wrap_positive((p - centre).to_angle(), std::f64::consts::TAU);
        let k = ((a / std::f64::consts::TAU * BINS as f64) as usize).min(BINS - 1);
        sums[k].0 += p;
        sums[k].1 += 1;
    }
    sums.iter()
        .filter(|(_, n)| *n > 0)
        .map(|(s, n)| *s / *n as f64)
        .collect()
}

impl PushMechanics {
    /// The footprint enclosed by `border_obj` (object frame, the centroid at the origin).
    /// `None` for fewer than three angle bins with a point, or a zero area.
    pub fn from_border(border_obj: &[DVec2]) -> Option<Self> {
        let finite = border_obj.iter().copied().filter(|p| p.is_finite());
        let ring = angle_ring::<RING_BINS>(finite, DVec2::ZERO);
        if ring.len() < 3 {
            return None;
        }
        // Mean distance from the origin over the area: the ring's triangles from the
        // origin, each integrated on a small barycentric lattice.
        const N: usize = 12;
        let (mut area, mut moment) = (0.0, 0.0);
        for k in 0..ring.len() {
            let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
            let tri = 0.5 * a.perp_dot(b);
            let mut mean = 0.0;
            let mut count = 0usize;
            for i in 0..N {
                for j in 0..N - i {
                    // Centres of the lattice's small triangles (one orientation of two:
                    // enough for a mean).
                    let (u, v) = (
                        (i as f64 + 1.0 / 3.0) / N as f64,
                        (j as f64 + 1.0 / 3.0) / N as f64,
                    );
                    mean += (a * u + b * v).length();
                    count += 1;
                }
            }
            area += tri;
            moment += tri * mean / count as f64;
        }
        if area.abs() < 1e-8 {
            return None;
        }
        let c = moment / area;
        (c.is_finite() && c > 0.0).then_some(Self { ring, c })
    }

    /// The limit surface's length `c`, m (see the module's documentation).
    pub fn limit_surface_length_m(&self) -> f64 {
        self.c
    }

    /// The border's inward unit normal at the ring's segment nearest to `p`.
    pub fn inward_normal(&self, p: DVec2) -> DVec2 {
        let n = self.ring.len();
        let mut best = (f64::INFINITY, DVec2::ZERO);
        for k in 0..n {
            let (a, b) = (self.ring[k], self.ring[(k + 1) % n]);
            let t = b - a;
            let s = ((p - a).dot(t) / t.length_squared().max(1e-18)).clamp(0.0, 1.0);
            let d = (a + t * s - p).length_squared();
            if d < best.0 {
                // Counter-clockwise ring: the inside is on the left.
                best = (d, t.perp().normalize_or_zero());
            }
        }
        best.1
    }

    /// The object's twist per unit of the robot's travel when the robot pushes at
    /// `contact` (object frame) along the unit `dir` (object frame), contact friction
    /// `mu`: the centroid's velocity and the turn rate. Zero when the robot moves away
    /// from the border there.
    pub fn twist(&self, contact: DVec2, dir: DVec2, mu: f64) -> (DVec2, f64) {
        let c2 = self.c * self.c;
        let r = contact;
        let mut n = self.inward_normal(r);
        if n == DVec2::ZERO {
            n = dir;
        }
        let push_in = dir.dot(n);
        if push_in <= 1e-9 {
            return (DVec2::ZERO, 0.0);
        }
        // Sticking: V = M^-1 v.
        let det = c2 + r.length_squared();
        let v = DVec2::new(
            (c2 + r.x * r.x) * dir.x + r.x * r.y * dir.y,
            r.x * r.y * dir.x + (c2 + r.y * r.y) * dir.y,
        ) / det;
        // The force is along V: inside the cone, the contact sticks.
        let half = mu.max(0.0).atan();
        let off = v.to_angle() - n.to_angle();
        let off = angle::wrap_angle(off);
        if off.abs() <= half {
            return (v, r.perp_dot(v) / c2);
        }
        let f = DVec2::from_angle(n.to_angle() + half.copysign(off));
        // Sliding: the force on the cone's edge; its size such that the contact point
        // moves into the border as fast as the robot does.
        let w = r.perp_dot(f) / c2;
        let contact_velocity = f + r.perp() * w;
        let along = contact_velocity.dot(n);
        if along <= 1e-12 {
            return (DVec2::ZERO, 0.0);
        }
        let k = push_in / along;
        (f * k, w * k)
    }

    /// The effect of a push at `contact` along `heading` (object frame) over `travel_m` of
    /// the robot's travel: the displacement (object frame before the push) and the
    /// rotation, integrated in `substeps` steps with the contact fixed on the object.
    pub fn push(
        &self,
        contact: DVec2,
        heading: DVec2,
        travel_m: f64,
        mu: f64,
        substeps: u32,
    ) -> (DVec2, f64) {
        let Some(u) = heading.try_normalize() else {
            return (DVec2::ZERO, 0.0);
        };
        let steps = substeps.max(1);
        let ds = travel_m / f64::from(steps);
        let (mut moved, mut theta) = (DVec2::ZERO, 0.0);
        for _ in 0..steps {
            let rot = DVec2::from_angle(theta);
            // The robot keeps its heading; in the turned object's frame it turns back.
            let dir = DVec2::from_angle(-theta).rotate(u);
            let (v, w) = self.twist(contact, dir, mu);
            moved += rot.rotate(v) * ds;
            theta += w * ds;
        }
        // Past a quarter turn the model's fixed contact is fiction: the robot would have
        // slid off the face.
        (moved, theta.clamp(-MAX_PRIOR_TURN_RAD, MAX_PRIOR_TURN_RAD))
    }
}

/// The prior gradient of `object_name` from the border points `border_obj` one circling
/// saw (object frame: their centroid at the origin), see the module's documentation: the
/// learning phase's alphas and cell size, S from the points, and per alpha
/// [`ContactPriorConfig::trials_per_alpha`] pushes of the protocol's family, each learned
/// as a trial with the effect [`PushMechanics::push`] gives. Allocates.
pub fn contact_prior(
    object_name: &str,
    border_obj: &[DVec2],
    config: &ContactPriorConfig,
) -> Result<AffordanceGradient, ContactPriorBuildError> {
    let ok = |v: f64| v.is_finite() && v >= 0.0;
    for (field, good) in [
        ("start_clearance_m", ok(config.start_clearance_m)),
        (
            "push_travel_m",
            ok(config.push_travel_m) && config.push_travel_m <= 1.0,
        ),
        ("contact_friction", ok(config.contact_friction)),
        (
            "trials_per_alpha",
            (1..=3600).contains(&config.trials_per_alpha),
        ),
        ("border_spacing_m", ok(config.border_spacing_m)),
        ("substeps", (1..=1000).contains(&config.substeps)),
        (
            "limit_surface_scale",
            config.limit_surface_scale.is_finite() && config.limit_surface_scale > 0.0,
        ),
    ] {
        if !good {
            return Err(ContactPriorBuildError::Config(field));
        }
    }
    let learner_config = LearnerConfig::default();
    let mut learner = AffordanceLearner::new(object_name, &learner_config)?;
    let half_extent_m = 0.5 * crate::Grid::centred(learner_config.cell_size_m).extent_m();
    let reach_m = border_obj.iter().map(|p| p.length()).fold(0.0, f64::max);
    if reach_m.is_nan() || reach_m >= half_extent_m {
        return Err(ContactPriorBuildError::TooLarge {
            reach_m,
            half_extent_m,
        });
    }
    let mut mechanics =
        PushMechanics::from_border(border_obj).ok_or(ContactPriorBuildError::NoFootprint {
            points: border_obj.len(),
        })?;
    mechanics.c *= config.limit_surface_scale;
    // S: the circling's points, thinned, in every alpha's S.
    let spacing2 = config.border_spacing_m * config.border_spacing_m;
    let mut added: Vec<DVec2> = Vec::with_capacity(border_obj.len());
    for p in border_obj.iter().filter(|p| p.is_finite()) {
        if spacing2 > 0.0 && added.iter().any(|q| q.distance_squared(*p) < spacing2) {
            continue;
        }
        added.push(*p);
    }
    for &alpha in &learner_config.alphas_deg {
        for p in &added {
            learner.add_border_point(alpha, *p)?;
        }
    }
    let shape = learner.gradient().combined_shape();
    let radius = learned_border_radius_m(&shape).ok_or(ContactPriorBuildError::NoFootprint {
        points: border_obj.len(),
    })?;
    let start_radius = radius + config.start_clearance_m;
    for &alpha in &learner_config.alphas_deg {
        for k in 0..config.trials_per_alpha {
            let phi = std::f64::consts::TAU * f64::from(k) / f64::from(config.trials_per_alpha);
            let start = DVec2::from_angle(phi) * start_radius;
            let heading = DVec2::from_angle(phi + std::f64::consts::PI + alpha.to_radians());
            let Some(contact) = border_crossing(&shape, start, heading, AIM_BORDER_THRESHOLD)
            else {
                continue;
            };
            let (displacement, rotation) = mechanics.push(
                contact,
                heading,
                config.push_travel_m,
                config.contact_friction,
                config.substeps,
            );
            learner.add_push(
                alpha,
                &PushOutcome {
                    contact_point_obj: contact,
                    displacement_obj: displacement,
                    rotation_rad: rotation,
                    heading_obj: heading,
                },
            )?;
        }
    }
    Ok(learner.into_gradient())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Border points of a square of half side `h` centred at the origin, `n` per side.
    fn square(h: f64, n: usize) -> Vec<DVec2> {
        let mut out = Vec::new();
        for side in 0..4 {
            for k in 0..n {
                let u = -h + 2.0 * h * (k as f64 + 0.5) / n as f64;
                out.push(match side {
                    0 => DVec2::new(u, -h),
                    1 => DVec2::new(h, u),
                    2 => DVec2::new(-u, h),
                    _ => DVec2::new(-h, -u),
                });
            }
        }
        out
    }

    #[test]
    fn the_limit_surface_length_of_a_square_is_its_mean_distance_from_the_centre() {
        // A square of side 2h: mean |r| = h (sqrt(2) + asinh(1)) / 3 = 0.7652 h.
        let m = PushMechanics::from_border(&square(0.03, 60)).expect("a footprint");
        let expected = 0.03 * (2f64.sqrt() + 1f64.asinh()) / 3.0;
        let got = m.limit_surface_length_m();
        assert!(
            (got - expected).abs() < 0.01 * expected,
            "{got} vs {expected}"
        );
    }

    #[test]
    fn a_push_through_the_centroid_translates_the_object_along_the_push() {
        let m = PushMechanics::from_border(&square(0.03, 60)).expect("a footprint");
        let (d, r) = m.push(DVec2::new(-0.03, 0.0), DVec2::X, 0.05, 0.3, 20);
        assert!((d - DVec2::new(0.05, 0.0)).length() < 1e-6, "{d}");
        assert!(r.abs() < 1e-9, "{r}");
    }

    #[test]
    fn an_offset_push_turns_the_object_away_from_the_contact_by_the_lever_arm() {
        let m = PushMechanics::from_border(&square(0.03, 60)).expect("a footprint");
        let c = m.limit_surface_length_m();
        // The -x face pushed along +x 15 mm above the centre: r x v = -15 mm, clockwise.
        let r = DVec2::new(-0.03, 0.015);
        let (v, w) = m.twist(r, DVec2::X, 10.0);
        // Sticking (a wide cone): omega = (r x V) / c^2 with V = M^-1 x.
        let det = c * c + r.length_squared();
        let v_expected = DVec2::new(c * c + r.x * r.x, r.x * r.y) / det;
        assert!((v - v_expected).length() < 1e-9, "{v} vs {v_expected}");
        assert!((w - r.perp_dot(v_expected) / (c * c)).abs() < 1e-9);
        assert!(
            w < 0.0,
            "turns clockwise, away from the contact above the centre"
        );
        // The default push is the twist at first contact times the travel.
        let (d, turn) = m.push(r, DVec2::X, 0.05, 10.0, 1);
        assert!((d - v * 0.05).length() < 1e-12 && (turn - w * 0.05).abs() < 1e-12);
    }

    #[test]
    fn a_push_outside_the_friction_cone_slides_with_the_force_on_the_cone_edge() {
        let m = PushMechanics::from_border(&square(0.03, 60)).expect("a footprint");
        // 5 mm from the corner: sticking would need the force 28 deg off the normal.
        let r = DVec2::new(-0.03, 0.025);
        let (v, w) = m.twist(r, DVec2::X, 0.1);
        // The force, and so V, on the cone's edge at atan(0.1) from the inward normal +x.
        assert!((v.to_angle().abs() - 0.1f64.atan()).abs() < 1e-9, "{v}");
        // omega = (r x V) / c^2, and the contact point moves into the face as fast as the
        // robot does.
        let c = m.limit_surface_length_m();
        assert!((w - r.perp_dot(v) / (c * c)).abs() < 1e-9);
        assert!(((v + r.perp() * w).x - 1.0).abs() < 1e-9);
    }

    #[test]
    fn the_prior_of_a_square_predicts_a_centred_push_straight_and_offset_ones_turning() {
        let ag = contact_prior("box", &square(0.03, 80), &ContactPriorConfig::default())
            .expect("a prior");
        let p = ag
            .predict(DVec2::new(-0.03, 0.0), 0.0)
            .expect("a prediction");
        assert!(p.displacement.x > 0.04, "{p:?}");
        assert!(p.displacement.y.abs() < 0.005, "{p:?}");
        assert!(p.rotation_rad.abs() < 3f64.to_radians(), "{p:?}");
        let above = ag
            .predict(DVec2::new(-0.03, 0.02), 0.0)
            .expect("a prediction");
        let below = ag
            .predict(DVec2::new(-0.03, -0.02), 0.0)
            .expect("a prediction");
        assert!(above.rotation_rad < -5f64.to_radians(), "{above:?}");
        assert!(below.rotation_rad > 5f64.to_radians(), "{below:?}");
    }

    #[test]
    fn a_border_beyond_the_grid_or_without_area_is_refused() {
        let far = square(0.2, 20);
        assert!(matches!(
            contact_prior("big", &far, &ContactPriorConfig::default()),
            Err(ContactPriorBuildError::TooLarge { .. })
        ));
        let line: Vec<DVec2> = (0..5).map(|k| DVec2::new(0.001 * k as f64, 0.0)).collect();
        assert!(matches!(
            contact_prior("line", &line, &ContactPriorConfig::default()),
            Err(ContactPriorBuildError::NoFootprint { .. })
        ));
    }
}
