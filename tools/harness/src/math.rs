//! The math at speed beside straightforward references: Gaussian smoothing, the paper's
//! orientation match (Algorithm 3) and the push search, each with a reference
//! implementation written for obviousness, the inputs to run them on, and the checks that
//! ours and the reference agree.

use agp_shared_types::angle;
use std::f64::consts::TAU;
use std::time::Instant;

use agp_affordance::{
    AffordanceGradient, AffordanceLearner, GaussianSmoother, Grid, LearnerConfig, Prediction,
    PushOutcome, PushPredictor, ShapeMatcher, ShapeMatcherConfig,
};
use agp_physics::{Sim, SimConfig};
use agp_planning::{Goal, PushChoiceSettings, PushPlan, PushPlanner, approach_start};
use agp_shared_types::{GRID_SIDE, Pose2};
use agp_world::{ObjectShape, Pose, Rng, RobotDescription, Scenario};
use anyhow::{Context, Result, bail};
use glam::DVec2;

/// Per-call times of one measured case, microseconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    /// Calls timed (after the warm-up).
    pub calls: usize,
    /// Median time of a call, us.
    pub median_us: f64,
    /// 90th percentile, us.
    pub p90_us: f64,
    /// Slowest call, us.
    pub max_us: f64,
    /// Heap allocations per timed call, by the counter given to [`measure`].
    pub allocations_per_call: f64,
}

/// Times `calls` calls of `f`, each on its own, after `warmup` untimed calls.
/// `allocations` reads a running count of heap allocations (`|| 0` when none is kept); the
/// buffer of times is allocated before the first timed call.
pub fn measure(
    warmup: usize,
    calls: usize,
    allocations: impl Fn() -> u64,
    mut f: impl FnMut(),
) -> Timing {
    assert!(calls > 0, "at least one timed call");
    for _ in 0..warmup {
        f();
    }
    let mut times = vec![0.0_f64; calls];
    let before = allocations();
    for t in times.iter_mut() {
        let start = Instant::now();
        f();
        *t = start.elapsed().as_secs_f64() * 1e6;
    }
    let allocated = allocations() - before;
    times.sort_unstable_by(f64::total_cmp);
    let at = |q: f64| times[((calls - 1) as f64 * q).round() as usize];
    Timing {
        calls,
        median_us: at(0.5),
        p90_us: at(0.9),
        max_us: times[calls - 1],
        allocations_per_call: allocated as f64 / calls as f64,
    }
}

// ---------------------------------------------------------------------------------------
// Smoothing

/// A grid of uniform random values in [0, 1) (cells of [`agp_affordance::DEFAULT_CELL_SIZE_M`]).
pub fn random_grid(seed: u64) -> Grid {
    let mut rng = Rng::new(seed);
    let mut g = Grid::default();
    g.cells_mut()
        .iter_mut()
        .for_each(|c| *c = rng.uniform() as f32);
    g
}

/// The reference smoothing: the direct 2-D convolution of `src` with the outer product of
/// the 1-D `kernel` (odd length, centre in the middle), cells off the grid counting zero,
/// accumulated in f64.
pub fn reference_smooth(kernel: &[f32], src: &Grid, dst: &mut Grid) {
    assert!(kernel.len() % 2 == 1, "a kernel of odd length");
    let n = GRID_SIDE as isize;
    let r = (kernel.len() / 2) as isize;
    for j in 0..n {
        for i in 0..n {
            let mut acc = 0.0_f64;
            for dy in -r..=r {
                for dx in -r..=r {
                    let (x, y) = (i + dx, j + dy);
                    if (0..n).contains(&x) && (0..n).contains(&y) {
                        let w = f64::from(kernel[(dx + r) as usize])
                            * f64::from(kernel[(dy + r) as usize]);
                        acc += w * f64::from(src.get(x as usize, y as usize));
                    }
                }
            }
            dst.set(i as usize, j as usize, acc as f32);
        }
    }
}

/// Largest absolute difference between two grids' cells.
pub fn max_abs_diff(a: &Grid, b: &Grid) -> f32 {
    a.cells()
        .iter()
        .zip(b.cells())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Smooths `src` with `smoother` and with [`reference_smooth`] (same kernel): the largest
/// absolute difference of the two results.
pub fn smoothing_disagreement(smoother: &mut GaussianSmoother, src: &Grid) -> f32 {
    let mut ours = src.zeros_like();
    let mut reference = src.zeros_like();
    smoother.smooth(src, &mut ours);
    reference_smooth(smoother.kernel(), src, &mut reference);
    max_abs_diff(&ours, &reference)
}

// ---------------------------------------------------------------------------------------
// Orientation match (Algorithm 3)

/// The paper's Algorithm 3 done by brute force: for each trial rotation, every point is
/// rotated about the points' centroid onto the learned border's centroid and looked up in
/// the grid; the score is the number of distinct cells hit where S is above the threshold.
/// Ties are broken as [`agp_affordance::MatchMethod::PaperOverlap`] documents: the middle
/// of the longest circular run of best-scoring rotations.
pub struct PaperReference {
    shape: Grid,
    mask: Vec<bool>,
    border_centroid: DVec2,
    steps: usize,
    /// Cells already counted at the present rotation.
    hit: Vec<bool>,
    scores: Vec<u32>,
}

impl PaperReference {
    /// Reads the learned `shape` with `config`'s paper threshold and step.
    pub fn new(shape: &Grid, config: &ShapeMatcherConfig) -> Self {
        let min = config.paper_threshold * shape.max();
        let mask: Vec<bool> = shape.cells().iter().map(|&c| c > min).collect();
        let (mut count, mut sum) = (0usize, DVec2::ZERO);
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                if mask[Grid::index(i, j)] {
                    count += 1;
                    sum += shape.cell_centre_m(i, j);
                }
            }
        }
        let steps = (360.0 / config.paper_step_deg).round().max(1.0) as usize;
        Self {
            shape: shape.clone(),
            mask,
            border_centroid: sum / count.max(1) as f64,
            steps,
            hit: vec![false; GRID_SIDE * GRID_SIDE],
            scores: vec![0; steps],
        }
    }

    /// The orientation (radians, in [0, 2 pi)) of the best rotation.
    pub fn orientation_rad(&mut self, points: &[DVec2]) -> f64 {
        let centroid = points.iter().sum::<DVec2>() / points.len() as f64;
        for k in 0..self.steps {
            let theta = k as f64 * TAU / self.steps as f64;
            let (s, c) = theta.sin_cos();
            self.hit.fill(false);
            let mut score = 0;
            for &p in points {
                let d = p - centroid;
                // R(-theta) d
                let q = DVec2::new(c * d.x + s * d.y, -s * d.x + c * d.y) + self.border_centroid;
                if let Some((i, j)) = self.shape.cell_at(q) {
                    let cell = Grid::index(i, j);
                    if self.mask[cell] && !self.hit[cell] {
                        self.hit[cell] = true;
                        score += 1;
                    }
                }
            }
            self.scores[k] = score;
        }
        let n = self.steps;
        let best = self.scores.iter().copied().max().unwrap_or(0);
        let is_best = |k: usize| self.scores[k % n] == best;
        let (mut best_start, mut best_len) = (0, 0);
        for start in 0..n {
            // A run starts where the previous rotation is not a best one.
            if !is_best(start) || (n > 1 && is_best(start + n - 1)) {
                continue;
            }
            let len = (0..n).take_while(|&d| is_best(start + d)).count();
            if len > best_len {
                (best_start, best_len) = (start, len);
            }
        }
        if best_len == 0 {
            // Every rotation ties.
            return 0.0;
        }
        angle::wrap_positive(
            (best_start as f64 + (best_len - 1) as f64 / 2.0) * TAU / n as f64,
            TAU,
        )
    }
}

/// The largest orientation difference (radians, modulo the matcher's symmetry) between
/// `matcher` and `reference` over `point_sets`.
pub fn orientation_disagreement(
    matcher: &mut ShapeMatcher,
    reference: &mut PaperReference,
    point_sets: &[Vec<DVec2>],
) -> Result<f64> {
    let period = matcher.symmetry_period_rad();
    let mut worst = 0.0_f64;
    for points in point_sets {
        let ours = matcher
            .match_points(points)
            .context("the matcher refused the points")?
            .best
            .orientation_rad;
        let theirs = reference.orientation_rad(points);
        worst = worst.max(angle::distance(ours, theirs, period));
    }
    Ok(worst)
}

/// Border points of `polygon` (object frame) every `spacing_m` of arc, placed at `pose`
/// (world = position + R(theta) object), each coordinate with Gaussian noise of `noise_m`:
/// what a circling measures all around the object.
pub fn circling_points(
    polygon: &[DVec2],
    spacing_m: f64,
    pose: Pose2,
    noise_m: f64,
    rng: &mut Rng,
) -> Vec<DVec2> {
    let rot = DVec2::from_angle(pose.theta);
    let at = DVec2::new(pose.x, pose.y);
    border_samples(polygon, spacing_m)
        .map(|p| {
            let noise = DVec2::new(rng.gaussian(), rng.gaussian()) * noise_m;
            at + rot.rotate(p) + noise
        })
        .collect()
}

/// Perimeter of a closed polygon.
pub fn perimeter(polygon: &[DVec2]) -> f64 {
    (0..polygon.len())
        .map(|k| polygon[k].distance(polygon[(k + 1) % polygon.len()]))
        .sum()
}

/// Points along the edges of `polygon`, about `spacing_m` apart (each edge split evenly).
fn border_samples(polygon: &[DVec2], spacing_m: f64) -> impl Iterator<Item = DVec2> + '_ {
    (0..polygon.len()).flat_map(move |k| {
        let (a, b) = (polygon[k], polygon[(k + 1) % polygon.len()]);
        let n = ((b - a).length() / spacing_m).round().max(1.0) as usize;
        (0..n).map(move |s| a.lerp(b, s as f64 / n as f64))
    })
}

// ---------------------------------------------------------------------------------------
// Push search

/// The push the reference search chose and what it costs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePush {
    /// Contact point, object frame, metres.
    pub contact_obj: DVec2,
    /// Deviation of the push from the centroid, degrees.
    pub alpha_deg: f64,
    /// Fraction of the learned push duration.
    pub fraction: f64,
    /// Cost of the push (see [`PushPlanner::score`]).
    pub cost: f64,
}

/// The push search written plainly: the contact candidates and the alphas are built anew
/// from the AG (no precomputation), and every (contact, alpha, fraction) is evaluated in
/// full with [`AffordanceGradient::predict`] and [`approach_start`], no early exit; `cost`
/// prices a full-length prediction at a push fraction. The first candidate of least cost
/// wins, as in [`PushPlanner::plan`].
pub fn reference_plan(
    predictor: &PushPredictor<'_>,
    settings: &PushChoiceSettings,
    cost: impl Fn(&Prediction, f64) -> f64,
) -> Option<ReferencePush> {
    reference_plan_over(
        predictor,
        &predictor
            .gradient()
            .contact_candidates(settings.contact_count),
        settings,
        cost,
    )
}

/// [`reference_plan`] with the contact candidates given (only the alphas built per call).
pub fn reference_plan_over(
    predictor: &PushPredictor<'_>,
    contacts: &[DVec2],
    settings: &PushChoiceSettings,
    cost: impl Fn(&Prediction, f64) -> f64,
) -> Option<ReferencePush> {
    let learned: Vec<f64> = predictor.gradient().alphas_deg().collect();
    let lo = learned.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = learned.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let step = settings.alpha_step_deg.max(0.1);
    let n = ((hi - lo) / step).round() as usize;
    let mut best: Option<ReferencePush> = None;
    for &c in contacts {
        for k in 0..=n {
            let alpha = (lo + k as f64 * step).min(hi);
            let Some(p) = predictor.predict(c, alpha) else {
                continue;
            };
            for &f in &settings.push_fractions {
                let reachable = approach_start(c, alpha, settings.start_radius_m).is_some();
                let c_after = cost(&p, f);
                let eligible = p.confidence >= settings.min_confidence && reachable;
                if eligible && best.is_none_or(|b| c_after < b.cost) {
                    best = Some(ReferencePush {
                        contact_obj: c,
                        alpha_deg: alpha,
                        fraction: f,
                        cost: c_after,
                    });
                }
            }
        }
    }
    best
}

/// How far apart the costs of the pushes ours and the reference chose are, over `goals`
/// from `estimate`: the largest `|ours - reference|`, metres (infinite when only one of
/// the two finds a push, or the planner has no gradient to predict with).
pub fn push_cost_disagreement(planner: &PushPlanner<'_>, estimate: Pose2, goals: &[Goal]) -> f64 {
    let Some(predictor) = planner.predictor() else {
        return f64::INFINITY;
    };
    let mut worst = 0.0_f64;
    for goal in goals {
        let ours: Option<PushPlan> = planner.plan(estimate, goal);
        let theirs = reference_plan(predictor, planner.settings(), |p, f| {
            planner.score(p, f, estimate, goal).2
        });
        let d = match (ours, theirs) {
            (Some(a), Some(b)) => (a.cost - b.cost).abs(),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        };
        worst = worst.max(d);
    }
    worst
}

// ---------------------------------------------------------------------------------------
// Inputs

/// Push speed while learning, m/s.
const LEARN_SPEED_MPS: f64 = 0.1;
/// Learned push duration after the first touch, s.
const LEARN_PUSH_S: f64 = 0.5;
/// Gap between the robot's shell and the object's farthest point at a push's start, m.
const LEARN_START_GAP_M: f64 = 0.02;

/// Radius (m) of the circle the learning pushes start from for `scenario`'s object.
pub fn start_radius_m(scenario: &Scenario, robot: &RobotDescription) -> f64 {
    scenario.object.shape.radius() + robot.body_radius + LEARN_START_GAP_M
}

/// The vertices of a built-in scenario's polygonal object (object frame).
pub fn polygon_of(scenario: &Scenario) -> Result<Vec<DVec2>> {
    match &scenario.object.shape {
        ObjectShape::Polygon(p) => Ok(p.vertices().to_vec()),
        ObjectShape::Circle { .. } => bail!("scenario `{}` has a disc", scenario.name),
    }
}

/// Learns an AG of `scenario`'s polygonal object the way the paper's protocol does, on
/// ground truth and in-process against [`Sim`]: S from the true border (a point every
/// 2 mm), and `starts_per_alpha` pushes per alpha from evenly spread starts on the start
/// circle, each outcome read from the true poses.
pub fn learn_from_sim(scenario: &Scenario, starts_per_alpha: usize) -> Result<AffordanceGradient> {
    let robot = RobotDescription::epuck();
    let polygon = polygon_of(scenario)?;
    let ObjectShape::Polygon(shape) = &scenario.object.shape else {
        bail!("scenario `{}` has a disc", scenario.name);
    };
    let config = LearnerConfig::default();
    let mut learner =
        AffordanceLearner::new(&scenario.name, &config).context("cannot build the learner")?;
    let mut sim = Sim::new(scenario, &robot, SimConfig::default())
        .with_context(|| format!("cannot build the world of scenario `{}`", scenario.name))?;
    let r = start_radius_m(scenario, &robot);
    let home = Pose::new(0.0, 0.0, 0.0);
    let dt = sim.dt();
    for &alpha in &config.alphas_deg {
        for p in border_samples(&polygon, 0.002) {
            learner
                .add_border_point(alpha, p)
                .context("cannot learn a border point")?;
        }
        for k in 0..starts_per_alpha {
            let phi = TAU * k as f64 / starts_per_alpha as f64;
            let s = r * DVec2::from_angle(phi);
            let heading = phi + std::f64::consts::PI + alpha.to_radians();
            let u = DVec2::from_angle(heading);
            let Some(t) = shape.ray_cast(s, u, 1.0) else {
                continue;
            };
            sim.reset(home, Pose::new(s.x, s.y, heading));
            let mut waited = 0.0;
            while !sim.in_contact() && waited < 2.0 * r / LEARN_SPEED_MPS {
                sim.step(LEARN_SPEED_MPS, LEARN_SPEED_MPS);
                waited += dt;
            }
            if !sim.in_contact() {
                continue;
            }
            for _ in 0..(LEARN_PUSH_S / dt).round() as u64 {
                sim.step(LEARN_SPEED_MPS, LEARN_SPEED_MPS);
            }
            for _ in 0..(0.3 / dt).round() as u64 {
                sim.step(0.0, 0.0);
            }
            let o = sim.object_pose();
            let outcome = PushOutcome::from_poses(home, o, s + t * u, u);
            learner
                .add_push(alpha, &outcome)
                .context("cannot learn a push")?;
        }
    }
    Ok(learner.into_gradient())
}

/// Goals 250 to 500 mm away in any direction, any orientation, as `agp bench place` draws
/// them.
pub fn random_goals(count: usize, seed: u64) -> Vec<Goal> {
    let mut rng = Rng::new(seed);
    (0..count)
        .map(|_| {
            let d = 0.25 + 0.25 * rng.uniform();
            let a = TAU * rng.uniform();
            let theta = TAU * rng.uniform() - std::f64::consts::PI;
            Goal::Place {
                pose: Pose2::new(d * a.cos(), d * a.sin(), theta),
            }
        })
        .collect()
}
