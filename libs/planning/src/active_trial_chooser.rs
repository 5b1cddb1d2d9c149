//! Active learning (issue 33, item 1): each next trial of the learning phase where the
//! gradient learned so far is least sure, instead of the paper's fixed circle of 60 starts
//! per alpha.
//!
//! A trial of the protocol is a start on the start circle and an alpha; its aim point is
//! where its heading line meets the learned border (as the estimator keys it), and it meets
//! the border before its line passes the centroid or past it (the gradient keeps the two
//! apart). [`ActiveTrialChooser::choose`] scores every candidate start (a fine circle per
//! alpha) by how sure the gradient is at its aim point, and takes the least sure:
//!
//! ```text
//! score = coverage * (1 + spread_weight * v)
//! ```
//!
//! - Where the gradient has evidence, what its grids hold there: the push weight `w`
//!   (about the number of trials within one push sigma: the count) gives
//!   `coverage = 1 / (w + prior_weight)`, and the weighted spread of the effects learned
//!   there gives `v = (rotation spread / 5 deg)^2 + (displacement spread / (0.2
//!   |displacement|))^2`, the references being the learning targets.
//! - Where it has none (no trial's Gaussian reaches the aim point), `coverage = (1 + d /
//!   reach) / prior_weight`, above any point with evidence, `d` the distance to the
//!   nearest aim point of an earlier trial of the same alpha and branch: the farthest
//!   first, so the first trials spread evenly along the border. Its `v` is how much the
//!   nearest candidates with evidence on either side round the circle disagree, a quarter
//!   of the squared difference of their predictions in the same units (the error of
//!   interpolating between them, at the gap's middle): a gap between pushes that turn the
//!   object opposite ways (a corner) is filled before one between pushes that agree.
//!
//! A candidate is tried once: a trial that taught nothing (no contact, refused) is not
//! repeated at the same start. Ties go to the candidate farthest round the circle from
//! every tried start of its alpha.
//!
//! [`run_active`] drives the protocol's trials with it over any [`LearnWorld`] that can
//! show the gradient learned so far (in-process: the learner's session).

use std::f64::consts::{PI, TAU};

use agp_affordance::{
    AIM_BORDER_THRESHOLD, AffordanceGradient, Grid, PushPredictor, border_crossing,
    meets_past_centroid,
};
use agp_shared_types::{LearnEvent, LearnEventKind, LearnReport, LearnReportKind};
use glam::DVec2;

use crate::{LearnProtocol, LearnProtocolError, LearnWorld, ProtocolStep};

/// The rotation error the learning targets allow, rad (5 deg): the spread of the rotations
/// learned at a point is measured in it.
const ROTATION_REFERENCE_RAD: f64 = 5.0 * PI / 180.0;
/// The displacement error the learning targets allow, as a fraction of the displacement.
const DISPLACEMENT_REFERENCE_RATIO: f64 = 0.2;
/// The least displacement the fraction is taken of, m (a push that barely moves the object
/// is not measured against a vanishing reference).
const MIN_REFERENCE_DISPLACEMENT_M: f64 = 0.005;
/// The largest count read back from a prediction's confidence (`1 - exp(-w)`).
const MAX_COUNT: f64 = 30.0;
/// The distance to the nearest earlier trial of a layer and branch that has none, m.
const NO_TRIAL_DISTANCE_M: f64 = 1.0;

/// How [`ActiveTrialChooser`] scores candidates.
#[derive(Debug, Clone, PartialEq)]
pub struct ActiveSettings {
    /// Candidate starts per alpha, evenly round the start circle (180: every 2 deg).
    pub starts_per_alpha: usize,
    /// Weight of the spread in the score: 0 chooses by the count alone (farthest first,
    /// then least known).
    pub spread_weight: f64,
    /// Pseudo-count of the prior: a point of no evidence scores at least
    /// `1 / prior_weight`.
    pub prior_weight: f64,
    /// How far from an earlier trial's aim point (m) a point without evidence counts one
    /// more prior: `coverage = (1 + d / reach) / prior_weight`.
    pub reach_m: f64,
}

impl Default for ActiveSettings {
    /// 180 starts per alpha, spread weight 0.25, prior weight 0.5, reach 8 mm (about where
    /// a trial's Gaussian of 2.5 mm stops giving evidence); run on seeds 1-10 (every
    /// target met on 40 of 40 at 90 trials), not swept: see README, The learning benchmark.
    fn default() -> Self {
        Self {
            starts_per_alpha: 180,
            spread_weight: 0.25,
            prior_weight: 0.5,
            reach_m: 0.008,
        }
    }
}

/// The trial chosen: its alpha and start, and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialChoice {
    /// Alpha, degrees.
    pub alpha_deg: f64,
    /// Start angle round the object, rad, world frame (as [`LearnProtocol::trial`] takes).
    pub phi_rad: f64,
    /// The aim point on the learned border, object frame, m.
    pub aim_obj: DVec2,
    /// The gradient's count at the aim point (0: no evidence).
    pub count: f64,
    /// The normalised spread `v` at the aim point.
    pub spread: f64,
    /// The score.
    pub score: f64,
}

/// One candidate start of one alpha, as [`ActiveTrialChooser::choose`] reads the gradient.
#[derive(Debug, Clone, Copy, Default)]
struct Candidate {
    /// Its heading line meets the learned border.
    valid: bool,
    /// The aim point, object frame.
    aim: DVec2,
    /// It meets the border past the centroid.
    past: bool,
    /// The gradient has evidence there.
    known: bool,
    /// The count there.
    count: f64,
    /// The normalised spread there.
    spread: f64,
    /// The predicted rotation, rad.
    rotation: f64,
    /// The predicted displacement, m.
    displacement: DVec2,
}

impl Candidate {
    /// A quarter of the squared difference of two predictions, in the targets' units.
    fn disagreement(&self, other: &Candidate) -> f64 {
        let d_ref = DISPLACEMENT_REFERENCE_RATIO
            * (0.5 * (self.displacement.length() + other.displacement.length()))
                .max(MIN_REFERENCE_DISPLACEMENT_M);
        let r = (self.rotation - other.rotation) / ROTATION_REFERENCE_RAD;
        let d = (self.displacement - other.displacement).length() / d_ref;
        0.25 * (r * r + d * d)
    }
}

/// Chooses each next learning trial where the gradient is least sure (see the module).
/// Allocates its tables once; [`Self::choose`] allocates nothing.
#[derive(Debug, Clone)]
pub struct ActiveTrialChooser {
    settings: ActiveSettings,
    alphas_deg: Vec<f64>,
    /// The object's orientation in the world when placed (the learned frame's).
    placement_theta: f64,
    /// Per candidate (alpha-major): tried already.
    tried: Vec<bool>,
    /// The chosen trials' (alpha index, aim point, past the centroid).
    aims: Vec<(usize, DVec2, bool)>,
    /// Scratch: per start of one alpha, the distance (in starts) to the nearest tried one.
    gap: Vec<usize>,
    /// Scratch: the candidates of one alpha.
    candidates: Vec<Candidate>,
}

impl ActiveTrialChooser {
    /// A chooser over `alphas_deg`, for an object placed at orientation `placement_theta`
    /// (rad, world frame). `starts_per_alpha` of at least 1 (asserted).
    #[track_caller]
    pub fn new(settings: ActiveSettings, alphas_deg: &[f64], placement_theta: f64) -> Self {
        assert!(
            settings.starts_per_alpha >= 1,
            "at least one start per alpha"
        );
        let n = settings.starts_per_alpha;
        Self {
            tried: vec![false; n * alphas_deg.len()],
            aims: Vec::with_capacity(n * alphas_deg.len()),
            gap: vec![0; n],
            candidates: vec![Candidate::default(); n],
            alphas_deg: alphas_deg.to_vec(),
            placement_theta,
            settings,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &ActiveSettings {
        &self.settings
    }

    /// Start angle (rad, world frame) of candidate `k`.
    fn phi(&self, k: usize) -> f64 {
        TAU * k as f64 / self.settings.starts_per_alpha as f64
    }

    /// Marks the trial at (`alpha_deg`, `phi_rad`) as tried (its nearest candidate), with
    /// its aim point and heading (object frame) when known.
    pub fn mark_tried(&mut self, alpha_deg: f64, phi_rad: f64, aim: Option<(DVec2, DVec2)>) {
        let n = self.settings.starts_per_alpha;
        let Some(a) = self
            .alphas_deg
            .iter()
            .position(|&x| (x - alpha_deg).abs() < 1e-9)
        else {
            return;
        };
        let k = (phi_rad.rem_euclid(TAU) / TAU * n as f64).round() as usize % n;
        self.tried[a * n + k] = true;
        if let Some((c, heading)) = aim
            && self.aims.len() < self.aims.capacity()
        {
            self.aims.push((a, c, meets_past_centroid(c, heading)));
        }
    }

    /// Fills `gap` with each start's distance (in starts, round the circle) to the nearest
    /// tried start of alpha `a`; `n` where none was tried.
    fn fill_gaps(&mut self, a: usize) {
        let n = self.settings.starts_per_alpha;
        let tried = &self.tried[a * n..(a + 1) * n];
        self.gap.fill(n);
        // Two sweeps each way round the circle (the second wraps).
        let mut last: Option<usize> = None;
        for i in 0..2 * n {
            let k = i % n;
            if tried[k] {
                last = Some(i);
            }
            if let Some(l) = last {
                self.gap[k] = self.gap[k].min(i - l);
            }
        }
        last = None;
        for i in (0..2 * n).rev() {
            let k = i % n;
            if tried[k] {
                last = Some(i);
            }
            if let Some(l) = last {
                self.gap[k] = self.gap[k].min(l - i);
            }
        }
    }

    /// Reads the gradient at every candidate of alpha `a` into `candidates`.
    fn read_candidates(&mut self, a: usize, predictor: &PushPredictor<'_>, start_radius_m: f64) {
        let alpha_deg = self.alphas_deg[a];
        for k in 0..self.settings.starts_per_alpha {
            let phi_obj = self.phi(k) - self.placement_theta;
            let start = DVec2::from_angle(phi_obj) * start_radius_m;
            let u = DVec2::from_angle(phi_obj + PI + alpha_deg.to_radians());
            let mut cand = Candidate::default();
            if let Some(c) = border_crossing(predictor.shape(), start, u, AIM_BORDER_THRESHOLD) {
                cand.valid = true;
                cand.aim = c;
                cand.past = meets_past_centroid(c, u);
                if let Some(p) = predictor.predict_push(c, alpha_deg, u) {
                    let d_ref = DISPLACEMENT_REFERENCE_RATIO
                        * p.displacement.length().max(MIN_REFERENCE_DISPLACEMENT_M);
                    cand.known = true;
                    cand.count = (-(1.0 - p.confidence).max(1e-300).ln()).min(MAX_COUNT);
                    cand.spread = (p.rotation_spread_rad / ROTATION_REFERENCE_RAD).powi(2)
                        + (p.displacement_spread_m / d_ref).powi(2);
                    cand.rotation = p.rotation_rad;
                    cand.displacement = p.displacement;
                }
            }
            self.candidates[k] = cand;
        }
    }

    /// The nearest candidate with evidence of the same branch as candidate `k`, walking
    /// round the circle by `step` (+1 or n - 1); `None` when there is none.
    fn known_neighbour(&self, k: usize, step: usize) -> Option<&Candidate> {
        let n = self.settings.starts_per_alpha;
        let past = self.candidates[k].past;
        let mut i = (k + step) % n;
        while i != k {
            let c = &self.candidates[i];
            if c.valid && c.known && c.past == past {
                return Some(c);
            }
            i = (i + step) % n;
        }
        None
    }

    /// The count-and-spread score of candidate `k` of alpha `a` (see the module); `None`
    /// for a candidate tried or whose line meets no border.
    fn score(&self, a: usize, k: usize) -> Option<(f64, f64)> {
        let n = self.settings.starts_per_alpha;
        let c = &self.candidates[k];
        if self.tried[a * n + k] || !c.valid {
            return None;
        }
        let s = &self.settings;
        let (coverage, spread) = if c.known {
            (1.0 / (c.count + s.prior_weight), c.spread)
        } else {
            let d = self
                .aims
                .iter()
                .filter(|(ta, _, past)| *ta == a && *past == c.past)
                .map(|(_, aim, _)| aim.distance(c.aim))
                .fold(NO_TRIAL_DISTANCE_M, f64::min);
            let spread = match (self.known_neighbour(k, 1), self.known_neighbour(k, n - 1)) {
                (Some(l), Some(r)) => l.disagreement(r),
                _ => 0.0,
            };
            ((1.0 + d / s.reach_m) / s.prior_weight, spread)
        };
        Some((coverage * (1.0 + s.spread_weight * spread), spread))
    }

    /// Whether the chosen trial meets the border past the centroid (its heading from its
    /// start, object frame).
    fn candidates_past(&self, k: usize, choice: TrialChoice) -> bool {
        let phi_obj = self.phi(k) - self.placement_theta;
        let u = DVec2::from_angle(phi_obj + PI + choice.alpha_deg.to_radians());
        meets_past_centroid(choice.aim_obj, u)
    }

    /// The next trial: the untried candidate of highest score on `ag` (its S `shape`, the
    /// normalised combined shape, locates aim points) for a start circle of radius
    /// `start_radius_m`; `None` when every candidate was tried or meets no border. Marks it
    /// tried, with its aim point. Allocates nothing.
    pub fn choose(
        &mut self,
        ag: &AffordanceGradient,
        shape: &Grid,
        start_radius_m: f64,
    ) -> Option<TrialChoice> {
        let n = self.settings.starts_per_alpha;
        let predictor = PushPredictor::borrowing(ag, shape, start_radius_m);
        // (choice, its gap, its candidate index)
        let mut best: Option<(TrialChoice, usize, usize)> = None;
        for a in 0..self.alphas_deg.len() {
            self.fill_gaps(a);
            self.read_candidates(a, &predictor, start_radius_m);
            for k in 0..n {
                let Some((score, spread)) = self.score(a, k) else {
                    continue;
                };
                let gap = self.gap[k];
                let better = match &best {
                    None => true,
                    Some((b, bgap, _)) => score > b.score || (score == b.score && gap > *bgap),
                };
                if better {
                    let c = &self.candidates[k];
                    best = Some((
                        TrialChoice {
                            alpha_deg: self.alphas_deg[a],
                            phi_rad: self.phi(k),
                            aim_obj: c.aim,
                            count: if c.known { c.count } else { 0.0 },
                            spread,
                            score,
                        },
                        gap,
                        a * n + k,
                    ));
                }
            }
        }
        let (choice, _, index) = best?;
        self.tried[index] = true;
        if self.aims.len() < self.aims.capacity() {
            let past = self.candidates_past(index % n, choice);
            self.aims.push((index / n, choice.aim_obj, past));
        }
        Some(choice)
    }
}

/// Runs the learning protocol with `trials` trials chosen by `chooser` on the gradient
/// learned so far (`gradient` shows it from the world; `None` ends the trials early): the
/// shape circling as [`LearnProtocol::run`] does, then each trial where the chooser says,
/// each answered by the learner before the next is chosen, then `LearningDone`. Returns
/// the learner's `Learned` report. The events carry session 0 (a fresh learner's): this
/// run does not start over after a restart, as [`LearnProtocol::run`] does. The combined
/// shape is built once per trial (one grid); the choice itself allocates nothing.
pub fn run_active<W, G>(
    protocol: &mut LearnProtocol,
    chooser: &mut ActiveTrialChooser,
    world: &mut W,
    trials: u32,
    gradient: G,
    progress: &mut dyn FnMut(ProtocolStep),
) -> Result<LearnReport, LearnProtocolError<W::Error>>
where
    W: LearnWorld,
    G: Fn(&W) -> Option<&AffordanceGradient>,
{
    let world_err = LearnProtocolError::World;
    let lap_closed = protocol.shape(world)?;
    protocol.take_shape(world, lap_closed, progress)?;
    let radius = protocol.start_radius_m();
    for index in 0..trials {
        let choice = match gradient(world) {
            Some(ag) => {
                let shape = ag.combined_shape();
                chooser.choose(ag, &shape, radius)
            }
            None => None,
        };
        let Some(choice) = choice else { break };
        let run = protocol
            .trial(world, index, choice.alpha_deg, choice.phi_rad)
            .map_err(world_err)?;
        let report = world
            .wait_report(&[
                LearnReportKind::TrialLearned,
                LearnReportKind::TrialRejected,
            ])
            .map_err(world_err)?;
        progress(ProtocolStep::Trial {
            done: index + 1,
            total: trials,
            alpha_deg: choice.alpha_deg,
            phi_rad: choice.phi_rad,
            run,
            report,
        });
    }
    let f = world.frame();
    let done = LearnEvent {
        kind: LearnEventKind::LearningDone as u32,
        total: trials,
        step: f.step,
        ir_sample: f.ir_sample,
        ir_raw: f.ir_raw,
        odometry: f.odometry,
        ..LearnEvent::default()
    };
    world.tell(done).map_err(world_err)?;
    let learned = world
        .wait_report(&[LearnReportKind::Learned])
        .map_err(world_err)?;
    progress(ProtocolStep::Learned(learned));
    Ok(learned)
}

#[cfg(test)]
mod tests {
    use super::*;
    use agp_affordance::{AffordanceLearner, LearnerConfig, PushOutcome};

    /// Radius of the disc of the analytic cases, m.
    const DISC_M: f64 = 0.03;
    /// Their start circle's radius, m.
    const START_M: f64 = 0.087;

    /// A disc's gradient at alpha 0: its border, and a push at each of `pushes` (angle of
    /// the aim point round the disc, deg; rotation, rad), each aimed at the centroid.
    fn disc_gradient(pushes: &[(f64, f64)]) -> AffordanceGradient {
        let config = LearnerConfig {
            alphas_deg: vec![0.0],
            ..LearnerConfig::default()
        };
        let mut learner = AffordanceLearner::new("disc", &config).expect("a valid config");
        for k in 0..360 {
            let p = DVec2::from_angle(f64::from(k).to_radians()) * DISC_M;
            learner
                .add_border_point(0.0, p)
                .expect("alpha 0 is learned");
        }
        for &(deg, rotation_rad) in pushes {
            let c = DVec2::from_angle(deg.to_radians()) * DISC_M;
            let push = PushOutcome {
                contact_point_obj: c,
                displacement_obj: -c.normalize() * 0.03,
                rotation_rad,
                heading_obj: -c,
            };
            learner.add_push(0.0, &push).expect("a finite push");
        }
        learner.into_gradient()
    }

    /// The aim point and heading of the trial at alpha 0 from `deg` round the disc.
    fn aim_of(deg: f64) -> (DVec2, DVec2) {
        let c = DVec2::from_angle(deg.to_radians()) * DISC_M;
        (c, -c)
    }

    fn chooser(tried_deg: &[f64]) -> ActiveTrialChooser {
        let mut c = ActiveTrialChooser::new(ActiveSettings::default(), &[0.0], 0.0);
        for &deg in tried_deg {
            c.mark_tried(0.0, deg.to_radians(), Some(aim_of(deg)));
        }
        c
    }

    #[test]
    fn the_next_trial_goes_to_the_middle_of_the_largest_arc_without_evidence() {
        // Trials every 5 deg round the disc but for the arc from 90 to 180 deg: a start at
        // alpha 0 aims at the disc's point of its own angle, so the least known start is
        // the arc's middle, 135 deg (within one candidate, 2 deg).
        let done: Vec<f64> = (0..72)
            .map(|k| 5.0 * f64::from(k))
            .filter(|d| !(90.0 < *d && *d < 180.0))
            .collect();
        let pushes: Vec<(f64, f64)> = done.iter().map(|&d| (d, 0.1)).collect();
        let ag = disc_gradient(&pushes);
        let shape = ag.combined_shape();
        let choice = chooser(&done)
            .choose(&ag, &shape, START_M)
            .expect("a candidate");
        let deg = choice.phi_rad.to_degrees();
        assert!((deg - 135.0).abs() <= 2.0 + 1e-9, "chose {deg} deg");
        assert_eq!(choice.count, 0.0, "no evidence there");
        // Its aim point is the disc's border at that angle, within a cell (2 mm).
        let expected = DVec2::from_angle(choice.phi_rad) * DISC_M;
        assert!(
            (choice.aim_obj - expected).length() < 0.002,
            "{:?}",
            choice.aim_obj
        );
    }

    #[test]
    fn where_every_start_is_known_the_next_trial_goes_where_the_learned_turns_disagree() {
        // Trials every 5 deg all round, each turning the disc by 0.1 rad, but for those
        // from 200 to 240 deg, which turn it by +-0.3 rad in turn: the count is alike
        // everywhere, the spread high only there.
        let done: Vec<f64> = (0..72).map(|k| 5.0 * f64::from(k)).collect();
        let pushes: Vec<(f64, f64)> = done
            .iter()
            .enumerate()
            .map(|(k, &d)| {
                let rot = if (200.0..=240.0).contains(&d) {
                    if k % 2 == 0 { 0.3 } else { -0.3 }
                } else {
                    0.1
                };
                (d, rot)
            })
            .collect();
        let ag = disc_gradient(&pushes);
        let shape = ag.combined_shape();
        let choice = chooser(&done)
            .choose(&ag, &shape, START_M)
            .expect("a candidate");
        let deg = choice.phi_rad.to_degrees();
        assert!((200.0..=240.0).contains(&deg), "chose {deg} deg");
        assert!(choice.count > 0.5, "known there: count {}", choice.count);
        // Rotations of +-0.3 rad spread about 0.3 rad (17 deg) round their mean: v, in
        // units of the 5 deg target, is over 4 (a spread of 10 deg) at least.
        assert!(choice.spread > 4.0, "spread {}", choice.spread);
    }

    #[test]
    fn a_start_is_never_chosen_twice() {
        let ag = disc_gradient(&[]);
        let shape = ag.combined_shape();
        let mut c = ActiveTrialChooser::new(
            ActiveSettings {
                starts_per_alpha: 8,
                ..ActiveSettings::default()
            },
            &[0.0],
            0.0,
        );
        let mut seen: Vec<f64> = Vec::new();
        while let Some(choice) = c.choose(&ag, &shape, START_M) {
            assert!(
                !seen.iter().any(|&p| (p - choice.phi_rad).abs() < 1e-9),
                "{} twice",
                choice.phi_rad
            );
            seen.push(choice.phi_rad);
        }
        assert_eq!(seen.len(), 8);
        // Farthest first on an empty gradient: 0, then the opposite side, then between.
        assert!((seen[1] - std::f64::consts::PI).abs() < 1e-9, "{seen:?}");
    }
}
