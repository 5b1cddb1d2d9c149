use agp_shared_types::angle;
use std::f64::consts::TAU;

use agp_shared_types::{GRID_CELLS, GRID_SIDE};
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::svd::{ComputeSvdVectors, svd, svd_scratch};
use faer::{Mat, Par};
use glam::DVec2;

use crate::Grid;
use crate::simd::Simd;

/// Smallest coarse rotation step, degrees (at most 60 coarse trials).
const MIN_COARSE_STEP_DEG: f64 = 6.0;

/// Words of a one-bit-per-cell mask of a grid.
const MASK_WORDS: usize = GRID_CELLS.div_ceil(64);
const _: () = assert!(MASK_WORDS.is_power_of_two() && MASK_WORDS * 64 == GRID_CELLS);
/// A point off the grid in the paper's method.
const OFF_GRID: u32 = u32::MAX;
/// Points of one match the paper's method holds room for from the start: a circling
/// gives a few hundred to a few thousand.
const PAPER_POINTS_RESERVED: usize = 4096;

/// Least number of points [`ShapeMatcher::match_points`] accepts.
pub const MIN_MATCH_POINTS: usize = 8;

/// Two poses closer than this in orientation (modulo the symmetry) are the same optimum.
const DISTINCT_ANGLE_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Two poses closer than this in position are the same optimum.
const DISTINCT_POSITION_M: f64 = 0.005;
/// The coarse and fine searches use at most about this many points (every k-th).
const SEARCH_POINTS: usize = 64;
/// Translation-only steps after each trial rotation of the coarse search.
const COARSE_TRANSLATION_STEPS: usize = 5;
/// At each coarse rotation, translations are first tried on a square grid of this
/// half-width around the centroid guess (a partial border moves the points' centroid away
/// from the border's by up to the object's size), metres.
const TRANSLATION_SEARCH_M: f64 = 0.04;
/// Step of that grid, metres.
const TRANSLATION_SEARCH_STEP_M: f64 = 0.01;
/// Points used to score the translation grid (every k-th point).
const TRANSLATION_SEARCH_POINTS: usize = 24;
/// Translation-only steps after each trial rotation of the fine search.
const FINE_TRANSLATION_STEPS: usize = 2;
/// How many of the candidates, best first after the fine search, ICP refines.
const ICP_CANDIDATES: usize = 3;
/// ICP stops when an iteration moves the pose by less than this (radians, plus metres
/// divided by the inlier distance).
const ICP_CONVERGED: f64 = 1e-5;
/// During the rotation search and the first ICP steps, correspondences are kept up to this
/// multiple of the inlier distance (the initial guess may be far off).
const WIDE_INLIER_FACTOR: f64 = 2.5;

/// How [`ShapeMatcher`] finds the pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MatchMethod {
    /// Coarse-to-fine rotation search scoring the points on the distance transform of the
    /// learned border (a truncated chamfer score), then point-to-shape ICP whose every
    /// rigid fit is a 2 x 2 SVD. At each coarse rotation the translation is searched on a
    /// 10 mm grid of +-40 mm around the centroid guess, then refined by closest-point
    /// steps: a partial border moves the points' centroid far from the border's. The
    /// distinct optima (modulo the symmetry) are refined at the fine step, and the best
    /// three by ICP. Works with partial borders. The default.
    #[default]
    ChamferIcp,
    /// The paper's Algorithm 3: the points' centroid as the object's, and the best of the
    /// trial rotations (every `paper_step_deg`) by the number of cells where both the points
    /// and the learned S are non-zero. The points' centroid is matched to the centroid of
    /// the learned border (not the object's centroid) so that shapes whose border and area
    /// centroids differ (the L) are not off by that difference. Counting cells is coarse: a
    /// range of rotations ties, and the middle of the longest tied run wins. Needs the
    /// whole border: gaps move the points' centroid.
    PaperOverlap,
}

/// How a [`ShapeMatcher`] reads the learned shape and searches.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeMatcherConfig {
    /// Which algorithm.
    pub method: MatchMethod,
    /// Rotational symmetry of the object: 1 none, 2, 3 (triangle), 4 (square) ..., 0 for a
    /// circle (continuous: orientation is reported as 0). Orientations are reported modulo
    /// `360 / symmetry_order` degrees.
    pub symmetry_order: u32,
    /// Fraction of S's largest value above which a ridge of S is the learned border.
    pub border_threshold: f32,
    /// Rotation step of the coarse search, degrees, 6 to 90.
    pub coarse_step_deg: f64,
    /// Rotation step of the fine search around each coarse candidate, degrees.
    pub fine_step_deg: f64,
    /// How many distinct coarse optima the fine search refines (ICP then refines the best
    /// three).
    pub candidates: usize,
    /// Points farther than this from the learned border are outliers: they count this
    /// distance in the score and are left out of the rigid fits, metres.
    pub inlier_distance_m: f64,
    /// Largest number of ICP iterations per candidate.
    pub icp_iterations: usize,
    /// Rotation step of [`MatchMethod::PaperOverlap`], degrees.
    pub paper_step_deg: f64,
    /// Fraction of S's largest value above which a cell of S counts as non-zero in
    /// [`MatchMethod::PaperOverlap`] (and in the centroid of the learned border). Read
    /// literally (any positive cell), the Gaussians' tails make a band so wide that many
    /// rotations tie; 0.3 keeps a band about 3 sigma wide.
    pub paper_threshold: f32,
}

impl Default for ShapeMatcherConfig {
    /// Chamfer + ICP, no symmetry, ridge above 0.3, 10 deg coarse and 1 deg fine steps, 8
    /// candidates, 10 mm inlier distance, 30 ICP iterations; paper: 1 deg, threshold 0.3.
    fn default() -> Self {
        Self {
            method: MatchMethod::ChamferIcp,
            symmetry_order: 1,
            border_threshold: 0.3,
            coarse_step_deg: 10.0,
            fine_step_deg: 1.0,
            candidates: 8,
            inlier_distance_m: 0.01,
            icp_iterations: 30,
            paper_step_deg: 1.0,
            paper_threshold: 0.3,
        }
    }
}

/// Why a [`ShapeMatcher`] could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeMatcherBuildError {
    /// The learned S has no border (all zeros, or fewer than three ridge cells).
    #[error("the learned shape gradient has no border to match against")]
    EmptyShape,
    /// A config field is out of range.
    #[error("shape matcher config: `{field}` is {value}, {expected}")]
    BadConfig {
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
        /// What it should be.
        expected: &'static str,
    },
}

/// Why a set of points could not be matched.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeMatchError {
    /// Too few points to say anything.
    #[error("{found} border points, at least {MIN_MATCH_POINTS} needed")]
    TooFewPoints {
        /// How many were given.
        found: usize,
    },
    /// A point is not finite.
    #[error("border point {index} is not finite")]
    NonFinitePoint {
        /// Its index.
        index: usize,
    },
    /// The starting pose given to [`ShapeMatcher::refine`] is not finite.
    #[error("the starting pose is not finite")]
    NonFiniteStart,
}

/// A pose of the object found by matching, in the points' frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MatchedPose {
    /// The object's centroid, metres.
    pub position: DVec2,
    /// The object's orientation, radians, in `[0, 2 pi / symmetry_order)` (0 for a circle).
    pub orientation_rad: f64,
    /// Root mean square distance of the inlier points to the learned border, metres.
    pub rms_error_m: f64,
    /// Fraction of the points within the inlier distance of the learned border.
    pub inlier_fraction: f64,
}

/// The result of [`ShapeMatcher::match_points`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeMatch {
    /// The best pose.
    pub best: MatchedPose,
    /// The best pose distinct from `best` (by more than 5 deg modulo the symmetry, or 5 mm),
    /// if the search found one: when its error is close to `best`'s, the points do not tell
    /// the two apart (an undeclared symmetry, or too partial a border).
    pub runner_up: Option<MatchedPose>,
}

/// A trial pose: world point = position + R(theta) * object point.
#[derive(Debug, Clone, Copy)]
struct Trial {
    theta: f64,
    t: DVec2,
    score: f64,
}

/// Finds an object's pose from border points measured around it, against a learned S
/// (the paper's Algorithm 3 and the better default, see [`MatchMethod`]).
///
/// Everything that depends only on S (the border's ridge points to sub-cell precision, the
/// distance transform and nearest-border-point map, the non-zero mask, SVD workspace) is
/// computed once in [`ShapeMatcher::new`]; a match allocates nothing.
pub struct ShapeMatcher {
    config: ShapeMatcherConfig,
    geometry: Grid,
    /// 1 / cell size, per metre.
    inv_cell: f64,
    /// Subtracted from `q * inv_cell` to give cell coordinates (cell centres at integers).
    cell_offset: DVec2,
    /// Ridge points of S, object frame, metres.
    border: Vec<DVec2>,
    /// Centroid of the learned border: mean of the cells of S above the paper's threshold.
    border_centroid: DVec2,
    /// Distance from each cell centre to the nearest border point, metres.
    distance: Vec<f32>,
    /// Index in `border` of the nearest border point to each cell centre.
    nearest: Vec<u32>,
    /// Cells where S is non-zero (paper's method), one bit per cell in [`Grid::index`]
    /// order.
    mask: Vec<u64>,
    /// Cells hit by the points at one trial rotation (paper's method), same layout, so
    /// that each cell counts once.
    hit: Vec<u64>,
    /// The points about their centroid (paper's method), x and y apart.
    rel_x: Vec<f64>,
    rel_y: Vec<f64>,
    /// The cell of each point at one trial rotation, or [`OFF_GRID`].
    cells: Vec<u32>,
    /// The vector build of the paper's method's inner loop.
    simd: Simd,
    /// Scratch of the searches.
    trials: Vec<Trial>,
    refined: Vec<Trial>,
    /// 2 x 2 SVD workspace.
    cross: Mat<f64>,
    u: Mat<f64>,
    v: Mat<f64>,
    s: Diag<f64>,
    svd_mem: MemBuffer,
}

impl ShapeMatcher {
    /// Prepares matching against the learned shape gradient `shape` (object frame).
    pub fn new(shape: &Grid, config: ShapeMatcherConfig) -> Result<Self, ShapeMatcherBuildError> {
        validate(&config)?;
        let max = shape.max();
        if max <= 0.0 {
            return Err(ShapeMatcherBuildError::EmptyShape);
        }
        let border = ridge_points(shape, config.border_threshold * max);
        if border.len() < 3 {
            return Err(ShapeMatcherBuildError::EmptyShape);
        }
        let mut distance = vec![0.0_f32; GRID_CELLS];
        let mut nearest = vec![0_u32; GRID_CELLS];
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                let c = shape.cell_centre_m(i, j);
                let (k, d2) = border
                    .iter()
                    .enumerate()
                    .map(|(k, b)| (k, b.distance_squared(c)))
                    .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
                distance[Grid::index(i, j)] = d2.sqrt() as f32;
                nearest[Grid::index(i, j)] = k as u32;
            }
        }
        let paper_min = config.paper_threshold * max;
        let mut mask = vec![0_u64; MASK_WORDS];
        for (c, _) in shape
            .cells()
            .iter()
            .enumerate()
            .filter(|&(_, &v)| v > paper_min)
        {
            mask[c / 64] |= 1 << (c % 64);
        }
        // The paper's computeCentroid: the mean of the cells above the threshold. Unlike
        // the ridge points, whose density depends on the edges' directions, the band of
        // cells has the same width along every edge, so its mean is the border's.
        let (mut count, mut sum) = (0usize, DVec2::ZERO);
        for j in 0..GRID_SIDE {
            for i in 0..GRID_SIDE {
                let c = Grid::index(i, j);
                if mask[c / 64] & (1 << (c % 64)) != 0 {
                    count += 1;
                    sum += shape.cell_centre_m(i, j);
                }
            }
        }
        let border_centroid = sum / count.max(1) as f64;
        let coarse = (360.0 / config.coarse_step_deg).ceil() as usize + 1;
        let paper = (360.0 / config.paper_step_deg).ceil() as usize + 1;
        let svd_req = svd_scratch::<f64>(
            2,
            2,
            ComputeSvdVectors::Full,
            ComputeSvdVectors::Full,
            Par::Seq,
            Default::default(),
        );
        Ok(Self {
            inv_cell: 1.0 / shape.cell_size_m(),
            cell_offset: shape.origin_m() / shape.cell_size_m() + 0.5,
            geometry: shape.zeros_like(),
            border,
            border_centroid,
            distance,
            nearest,
            mask,
            hit: vec![0; MASK_WORDS],
            rel_x: Vec::with_capacity(PAPER_POINTS_RESERVED),
            rel_y: Vec::with_capacity(PAPER_POINTS_RESERVED),
            cells: Vec::with_capacity(PAPER_POINTS_RESERVED),
            simd: Simd::detect(),
            trials: Vec::with_capacity(coarse.max(paper)),
            refined: Vec::with_capacity(config.candidates),
            cross: Mat::zeros(2, 2),
            u: Mat::zeros(2, 2),
            v: Mat::zeros(2, 2),
            s: Diag::zeros(2),
            svd_mem: MemBuffer::new(svd_req),
            config,
        })
    }

    /// The config the matcher was built with.
    pub fn config(&self) -> &ShapeMatcherConfig {
        &self.config
    }

    /// The learned border the matcher uses: ridge points of S (object frame, metres).
    pub fn border_points(&self) -> &[DVec2] {
        &self.border
    }

    /// The period of the orientation, radians: `2 pi / symmetry_order` (`2 pi` for none
    /// and for a circle).
    pub fn symmetry_period_rad(&self) -> f64 {
        match self.config.symmetry_order {
            0 | 1 => TAU,
            n => TAU / f64::from(n),
        }
    }

    /// Finds the object's pose from border points measured around it (any frame, metres),
    /// with the configured method.
    pub fn match_points(&mut self, points: &[DVec2]) -> Result<ShapeMatch, ShapeMatchError> {
        check_points(points)?;
        match self.config.method {
            MatchMethod::ChamferIcp => Ok(self.match_chamfer(points)),
            MatchMethod::PaperOverlap => Ok(self.match_paper(points)),
        }
    }

    /// Refines a pose known roughly (within about 15 deg and 15 mm) by ICP alone: cheaper
    /// than a full match, e.g. to correct a prediction with the border seen after a push.
    pub fn refine(
        &mut self,
        points: &[DVec2],
        position: DVec2,
        orientation_rad: f64,
    ) -> Result<MatchedPose, ShapeMatchError> {
        check_points(points)?;
        if !position.is_finite() || !orientation_rad.is_finite() {
            return Err(ShapeMatchError::NonFiniteStart);
        }
        let trial = self.icp(
            points,
            Trial {
                theta: orientation_rad,
                t: position,
                score: 0.0,
            },
        );
        Ok(self.pose_of(points, trial))
    }

    fn match_chamfer(&mut self, points: &[DVec2]) -> ShapeMatch {
        let centroid = points.iter().sum::<DVec2>() / points.len() as f64;
        let wide = WIDE_INLIER_FACTOR * self.config.inlier_distance_m;
        if self.config.symmetry_order == 0 {
            let mut t = centroid - self.border_centroid;
            for _ in 0..self.config.icp_iterations {
                let before = t;
                t = self.translation_step(points, 1, 0.0, t, wide);
                if before.distance(t) < 1e-7 {
                    break;
                }
            }
            let trial = Trial {
                theta: 0.0,
                t,
                score: 0.0,
            };
            return ShapeMatch {
                best: self.pose_of(points, trial),
                runner_up: None,
            };
        }
        // Coarse: every coarse step over the full turn, translation refined at each. The
        // searches use a subsample of the points; ICP uses them all.
        let stride = points.len().div_ceil(SEARCH_POINTS).max(1);
        self.trials.clear();
        let coarse = self.config.coarse_step_deg.to_radians();
        let n = (TAU / coarse).round().max(1.0) as usize;
        for k in 0..n {
            let theta = k as f64 * TAU / n as f64;
            let guess = centroid - DVec2::from_angle(theta).rotate(self.border_centroid);
            let mut t = self.translation_search(points, theta, guess, wide);
            for _ in 0..COARSE_TRANSLATION_STEPS {
                t = self.translation_step(points, stride, theta, t, wide);
            }
            let score = self.score(points, stride, theta, t);
            self.trials.push(Trial { theta, t, score });
        }
        // The best local minima, one per orientation class modulo the symmetry.
        self.refined.clear();
        let period = self.symmetry_period_rad();
        let m = self.trials.len();
        let minima: u64 = (0..m)
            .filter(|&k| {
                let s = self.trials[k].score;
                s <= self.trials[(k + m - 1) % m].score && s <= self.trials[(k + 1) % m].score
            })
            .fold(0, |bits, k| bits | (1 << k));
        // Only the minima matter from here: mark the others and sort by score.
        for (k, trial) in self.trials.iter_mut().enumerate() {
            if minima & (1 << k) == 0 {
                trial.score = f64::INFINITY;
            }
        }
        self.trials.sort_by(|a, b| a.score.total_cmp(&b.score));
        for k in 0..m {
            let trial = self.trials[k];
            if self.refined.len() == self.config.candidates || trial.score == f64::INFINITY {
                break;
            }
            let seen = self
                .refined
                .iter()
                .any(|r| angle::distance(r.theta, trial.theta, period) < 1.5 * coarse);
            if !seen {
                self.refined.push(trial);
            }
        }
        // Fine: every fine step around each candidate; then ICP on the best few.
        let fine = self.config.fine_step_deg.to_radians();
        let half = (0.5 * coarse / fine).ceil() as i64;
        for c in 0..self.refined.len() {
            let start = self.refined[c];
            let mut best = start;
            for s in -half..=half {
                if s == 0 {
                    continue;
                }
                let theta = start.theta + s as f64 * fine;
                let mut t = start.t;
                for _ in 0..FINE_TRANSLATION_STEPS {
                    t = self.translation_step(points, stride, theta, t, wide);
                }
                let score = self.score(points, stride, theta, t);
                if score < best.score {
                    best = Trial { theta, t, score };
                }
            }
            self.refined[c] = best;
        }
        self.refined.sort_by(|a, b| a.score.total_cmp(&b.score));
        self.refined.truncate(ICP_CANDIDATES);
        for c in 0..self.refined.len() {
            self.refined[c] = self.icp(points, self.refined[c]);
        }
        self.refined.sort_by(|a, b| a.score.total_cmp(&b.score));
        let best = self.refined[0];
        let runner_up = self.refined[1..]
            .iter()
            .find(|r| {
                angle::distance(r.theta, best.theta, period) > DISTINCT_ANGLE_RAD
                    || r.t.distance(best.t) > DISTINCT_POSITION_M
            })
            .copied();
        ShapeMatch {
            best: self.pose_of(points, best),
            runner_up: runner_up.map(|r| self.pose_of(points, r)),
        }
    }

    fn match_paper(&mut self, points: &[DVec2]) -> ShapeMatch {
        let centroid = points.iter().sum::<DVec2>() / points.len() as f64;
        let step = self.config.paper_step_deg.to_radians();
        let n = (TAU / step).round().max(1.0) as usize;
        self.trials.clear();
        // Cell coordinates (cell (i, j) spans [i, i + 1) x [j, j + 1)) of a point q of the
        // object frame: q * inv_cell - origin / cell. A point p maps to
        // q = R(-theta) (p - centroid) + border_centroid, so to the cell coordinates
        // (R(-theta) inv_cell) (p - centroid) + centre, with no division per point.
        let centre = (self.border_centroid - self.geometry.origin_m()) * self.inv_cell;
        // The points about their centroid, in columns (the rotation loop below then runs
        // over plain arrays, which the compiler vectorises). The scratch grows only when a
        // larger point set than any before arrives.
        self.rel_x.clear();
        self.rel_y.clear();
        self.rel_x.extend(points.iter().map(|p| p.x - centroid.x));
        self.rel_y.extend(points.iter().map(|p| p.y - centroid.y));
        self.cells.resize(points.len(), OFF_GRID);
        for k in 0..n {
            let theta = k as f64 * TAU / n as f64;
            let to_cells = DVec2::from_angle(-theta) * self.inv_cell;
            // Pass 1, no branch: the cell of every point, or OFF_GRID.
            let rotation = CellRotation { to_cells, centre };
            cells_at(
                self.simd,
                rotation,
                &self.rel_x,
                &self.rel_y,
                &mut self.cells,
            );
            // Pass 2: each cell of the mask counts once. The points of a circling come in
            // order along the border, several to a cell: a repeat of the previous point's
            // cell is skipped without touching memory.
            let count = count_mask_cells(&self.cells, &self.mask, &mut self.hit);
            let t = centroid - DVec2::from_angle(theta).rotate(self.border_centroid);
            self.trials.push(Trial {
                theta,
                t,
                score: -(count as f64),
            });
        }
        let period = if self.config.symmetry_order == 0 {
            TAU
        } else {
            self.symmetry_period_rad()
        };
        let best = self.plateau_centre(centroid);
        let runner_up = self
            .trials
            .iter()
            .filter(|r| angle::distance(r.theta, best.theta, period) > DISTINCT_ANGLE_RAD)
            .copied()
            .min_by(|a, b| a.score.total_cmp(&b.score));
        ShapeMatch {
            best: self.pose_of(points, best),
            runner_up: runner_up.map(|r| self.pose_of(points, r)),
        }
    }

    /// The trial at the middle of the longest run (circular) of trials sharing the best
    /// score: counting cells is coarse, and a whole range of rotations ties.
    fn plateau_centre(&self, centroid: DVec2) -> Trial {
        let n = self.trials.len();
        let best_score = self
            .trials
            .iter()
            .map(|t| t.score)
            .fold(f64::INFINITY, f64::min);
        let is_best = |k: usize| self.trials[k % n].score == best_score;
        let (mut best_start, mut best_len) = (0, 0);
        for start in 0..n {
            if !is_best(start) || (is_best(start + n - 1) && n > 1) {
                continue;
            }
            let len = (0..n).take_while(|&d| is_best(start + d)).count();
            if len > best_len {
                (best_start, best_len) = (start, len);
            }
        }
        if best_len == 0 {
            // Every trial ties (a circle): any rotation will do.
            return self.trials.first().copied().unwrap_or(Trial {
                theta: 0.0,
                t: centroid - self.border_centroid,
                score: 0.0,
            });
        }
        let step = TAU / n as f64;
        let theta = (best_start as f64 + (best_len - 1) as f64 / 2.0) * step;
        Trial {
            theta,
            t: centroid - DVec2::from_angle(theta).rotate(self.border_centroid),
            score: best_score,
        }
    }

    /// Point-to-shape ICP from `start`: correspondences are the nearest learned border
    /// points, each rigid fit a 2 x 2 SVD (Kabsch); the inlier distance shrinks from wide
    /// to the configured one.
    fn icp(&mut self, points: &[DVec2], start: Trial) -> Trial {
        let mut theta = start.theta;
        let mut t = start.t;
        let tau = self.config.inlier_distance_m;
        let mut gate = WIDE_INLIER_FACTOR * tau;
        for _ in 0..self.config.icp_iterations {
            let Some((new_theta, new_t)) = self.rigid_fit(points, theta, t, gate) else {
                break;
            };
            let moved = (new_theta - theta).abs() + new_t.distance(t) / tau;
            theta = new_theta;
            t = new_t;
            gate = (gate * 0.8).max(tau);
            if moved < ICP_CONVERGED && gate == tau {
                break;
            }
        }
        Trial {
            theta,
            t,
            score: self.score(points, 1, theta, t),
        }
    }

    /// One ICP step: the rigid transform best mapping the nearest border points of the
    /// inliers onto the points. `None` when fewer than three inliers or the SVD fails.
    fn rigid_fit(
        &mut self,
        points: &[DVec2],
        theta: f64,
        t: DVec2,
        gate: f64,
    ) -> Option<(f64, DVec2)> {
        let to_obj = DVec2::from_angle(-theta);
        let gate2 = gate * gate;
        let (mut n, mut sum_m, mut sum_p) = (0usize, DVec2::ZERO, DVec2::ZERO);
        let mut h = [[0.0_f64; 2]; 2];
        // One pass: sums and raw cross products; centred below (coordinates are metres
        // around the robot, so the cancellation loses nothing that matters in f64).
        for &p in points {
            let q = to_obj.rotate(p - t);
            let m = self.nearest_border(q);
            if m.distance_squared(q) <= gate2 {
                n += 1;
                sum_m += m;
                sum_p += p;
                h[0][0] += m.x * p.x;
                h[0][1] += m.x * p.y;
                h[1][0] += m.y * p.x;
                h[1][1] += m.y * p.y;
            }
        }
        if n < 3 {
            return None;
        }
        let (mean_m, mean_p) = (sum_m / n as f64, sum_p / n as f64);
        let nf = n as f64;
        h[0][0] -= nf * mean_m.x * mean_p.x;
        h[0][1] -= nf * mean_m.x * mean_p.y;
        h[1][0] -= nf * mean_m.y * mean_p.x;
        h[1][1] -= nf * mean_m.y * mean_p.y;
        for (r, row) in h.iter().enumerate() {
            for (c, &x) in row.iter().enumerate() {
                self.cross[(r, c)] = x;
            }
        }
        let stack = MemStack::new(&mut self.svd_mem);
        svd(
            self.cross.as_ref(),
            self.s.as_mut(),
            Some(self.u.as_mut()),
            Some(self.v.as_mut()),
            Par::Seq,
            stack,
            Default::default(),
        )
        .ok()?;
        // H = U S V^T, R = V diag(1, det(V U^T)) U^T.
        let (u, v) = (&self.u, &self.v);
        let det_u = u[(0, 0)] * u[(1, 1)] - u[(0, 1)] * u[(1, 0)];
        let det_v = v[(0, 0)] * v[(1, 1)] - v[(0, 1)] * v[(1, 0)];
        let d = (det_u * det_v).signum();
        let r = |i: usize, j: usize| v[(i, 0)] * u[(j, 0)] + d * v[(i, 1)] * u[(j, 1)];
        let (r00, r10) = (r(0, 0), r(1, 0));
        let new_theta = r10.atan2(r00);
        if !new_theta.is_finite() {
            return None;
        }
        let new_t = mean_p - DVec2::from_angle(new_theta).rotate(mean_m);
        Some((new_theta, new_t))
    }

    /// The best translation at rotation `theta` on a grid around `guess`, scored on a
    /// subsample of the points by the cell-resolution distance transform truncated at
    /// `gate` (points off the grid count `gate`).
    fn translation_search(&self, points: &[DVec2], theta: f64, guess: DVec2, gate: f64) -> DVec2 {
        let to_obj = DVec2::from_angle(-theta);
        let inv_cell = self.inv_cell;
        // Object-frame cell coordinates of the rotated points, before the translation.
        let stride = points.len().div_ceil(TRANSLATION_SEARCH_POINTS).max(1);
        let mut rotated = [DVec2::ZERO; TRANSLATION_SEARCH_POINTS];
        let mut n = 0;
        for (slot, &p) in rotated.iter_mut().zip(points.iter().step_by(stride)) {
            *slot = to_obj.rotate(p) * inv_cell - self.cell_offset + 0.5;
            n += 1;
        }
        let rotated = &rotated[..n];
        let half = (TRANSLATION_SEARCH_M / TRANSLATION_SEARCH_STEP_M).round() as i32;
        let gate2 = (gate * gate) as f32;
        let side = GRID_SIDE as f64;
        let (mut best, mut best_score) = (guess, f32::INFINITY);
        for iy in -half..=half {
            for ix in -half..=half {
                let t =
                    guess + DVec2::new(f64::from(ix), f64::from(iy)) * TRANSLATION_SEARCH_STEP_M;
                let shift = to_obj.rotate(t) * inv_cell;
                let mut score = 0.0_f32;
                for &r in rotated {
                    // Cell coordinates shifted by +0.5, so truncation rounds to the nearest.
                    let c = r - shift;
                    score += if c.x >= 0.0 && c.y >= 0.0 && c.x < side && c.y < side {
                        let d = self.distance[Grid::index(c.x as usize, c.y as usize)];
                        (d * d).min(gate2)
                    } else {
                        gate2
                    };
                }
                if score < best_score {
                    (best, best_score) = (t, score);
                }
            }
        }
        best
    }

    /// One translation-only step at rotation `theta`: shifts by the mean offset from the
    /// points (every `stride`-th) to their nearest border points (those within `gate`).
    fn translation_step(
        &self,
        points: &[DVec2],
        stride: usize,
        theta: f64,
        t: DVec2,
        gate: f64,
    ) -> DVec2 {
        let to_obj = DVec2::from_angle(-theta);
        let gate2 = gate * gate;
        let (mut n, mut sum) = (0usize, DVec2::ZERO);
        for &p in points.iter().step_by(stride) {
            let q = to_obj.rotate(p - t);
            let r = self.nearest_border(q) - q;
            if r.length_squared() <= gate2 {
                n += 1;
                sum += r;
            }
        }
        if n == 0 {
            return t;
        }
        t - DVec2::from_angle(theta).rotate(sum / n as f64)
    }

    /// Mean over the points (every `stride`-th) of the squared distance to the learned
    /// border, truncated at the inlier distance.
    fn score(&self, points: &[DVec2], stride: usize, theta: f64, t: DVec2) -> f64 {
        let to_obj = DVec2::from_angle(-theta);
        let tau = self.config.inlier_distance_m;
        let tau2 = tau * tau;
        let (mut n, mut sum) = (0usize, 0.0);
        for &p in points.iter().step_by(stride) {
            let d = self.border_distance(to_obj.rotate(p - t));
            n += 1;
            sum += (d * d).min(tau2);
        }
        sum / n.max(1) as f64
    }

    fn pose_of(&self, points: &[DVec2], trial: Trial) -> MatchedPose {
        let to_obj = DVec2::from_angle(-trial.theta);
        let tau = self.config.inlier_distance_m;
        let (mut n, mut sum2) = (0usize, 0.0);
        for &p in points {
            let d = self.border_distance(to_obj.rotate(p - trial.t));
            if d <= tau {
                n += 1;
                sum2 += d * d;
            }
        }
        let orientation_rad = if self.config.symmetry_order == 0 {
            0.0
        } else {
            angle::wrap_positive(trial.theta, self.symmetry_period_rad())
        };
        MatchedPose {
            position: trial.t,
            orientation_rad,
            rms_error_m: if n > 0 { (sum2 / n as f64).sqrt() } else { tau },
            inlier_fraction: n as f64 / points.len() as f64,
        }
    }

    /// Distance (metres) from `q` (object frame) to the learned border: bilinear on the
    /// distance transform, plus the distance to the grid for points off it.
    fn border_distance(&self, q: DVec2) -> f64 {
        let max = (GRID_SIDE - 1) as f64;
        let c = q * self.inv_cell - self.cell_offset;
        let cc = c.clamp(DVec2::ZERO, DVec2::splat(max));
        let outside = if cc == c {
            0.0
        } else {
            (c - cc).length() / self.inv_cell
        };
        let (i0, j0) = (cc.x as usize, cc.y as usize);
        let (i1, j1) = ((i0 + 1).min(GRID_SIDE - 1), (j0 + 1).min(GRID_SIDE - 1));
        let (fx, fy) = ((cc.x - i0 as f64) as f32, (cc.y - j0 as f64) as f32);
        let d = |i: usize, j: usize| self.distance[Grid::index(i, j)];
        let inside = (1.0 - fy) * ((1.0 - fx) * d(i0, j0) + fx * d(i1, j0))
            + fy * ((1.0 - fx) * d(i0, j1) + fx * d(i1, j1));
        f64::from(inside) + outside
    }

    /// The learned border point nearest to `q`'s cell (the nearest cell on the grid for
    /// points off it).
    #[inline]
    fn nearest_border(&self, q: DVec2) -> DVec2 {
        let max = (GRID_SIDE - 1) as f64;
        // Clamped to [0, max] then truncated after + 0.5: rounds to the nearest cell.
        let c = (q * self.inv_cell - self.cell_offset).clamp(DVec2::ZERO, DVec2::splat(max)) + 0.5;
        self.border[self.nearest[Grid::index(c.x as usize, c.y as usize)] as usize]
    }
}

/// How many distinct cells of `cells` (cell indices, or [`OFF_GRID`]) are set in `mask`;
/// `hit` is scratch of the mask's size.
fn count_mask_cells(cells: &[u32], mask: &[u64], hit: &mut [u64]) -> u64 {
    let mask: &[u64; MASK_WORDS] = mask.try_into().expect("a mask of every cell");
    let hit: &mut [u64; MASK_WORDS] = hit.try_into().expect("a hit set of every cell");
    hit.fill(0);
    let mut count = 0_u64;
    let mut previous = OFF_GRID;
    for &cell in cells {
        // The points of a circling come in order along the border, several to a cell: a
        // repeat of the previous point's cell is skipped without touching memory.
        if cell == previous || cell == OFF_GRID {
            continue;
        }
        previous = cell;
        // Cell indices are below GRID_CELLS, so the word is below MASK_WORDS (a power of
        // two): the mask only lets the compiler see it.
        let (word, bit) = ((cell as usize / 64) & (MASK_WORDS - 1), cell % 64);
        // Counts the cell if it is in the mask and not yet hit; no branch.
        count += ((mask[word] & !hit[word]) >> bit) & 1;
        hit[word] |= 1 << bit;
    }
    count
}

/// Maps points about their centroid to cell coordinates at one trial rotation:
/// `to_cells.rotate(p) + centre`.
#[derive(Clone, Copy)]
struct CellRotation {
    to_cells: DVec2,
    centre: DVec2,
}

/// The index of the cell of each point (`rel_x[k]`, `rel_y[k]`) at `rotation`, or
/// [`OFF_GRID`]: no branch, so that it vectorises.
#[inline(always)]
fn cells_body(rotation: CellRotation, rel_x: &[f64], rel_y: &[f64], cells: &mut [u32]) {
    let CellRotation { to_cells, centre } = rotation;
    let side = GRID_SIDE as f64;
    for ((cell, &x), &y) in cells.iter_mut().zip(rel_x).zip(rel_y) {
        let cx = to_cells.x * x - to_cells.y * y + centre.x;
        let cy = to_cells.y * x + to_cells.x * y + centre.y;
        let inside = (cx >= 0.0) & (cy >= 0.0) & (cx < side) & (cy < side);
        // Clamped first so that the truncation is a plain conversion; for a point on the
        // grid the clamp changes nothing.
        // SAFETY: the points and the rotation are finite (checked on entry), so the
        // clamped values are finite and in [0, side - 1], which fits an i32.
        let (i, j) = unsafe {
            (
                cx.clamp(0.0, side - 1.0).to_int_unchecked::<i32>(),
                cy.clamp(0.0, side - 1.0).to_int_unchecked::<i32>(),
            )
        };
        let index = (j * GRID_SIDE as i32 + i) as u32;
        *cell = if inside { index } else { OFF_GRID };
    }
}

/// [`cells_body`] in the vector build `simd`, which must be one this CPU runs
/// ([`Simd::detect`] or narrower).
fn cells_at(simd: Simd, rotation: CellRotation, rel_x: &[f64], rel_y: &[f64], cells: &mut [u32]) {
    match simd {
        // SAFETY: the callers pass the matcher's `simd` (from `Simd::detect`) or one of
        // `Simd::runnable` (the tests): `Avx512` only where this CPU reported AVX-512F and
        // FMA, the features `cells_avx512` is compiled for.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { cells_avx512(rotation, rel_x, rel_y, cells) },
        // SAFETY: likewise `Avx2` only where this CPU reported FMA and AVX2 (or AVX-512F,
        // which includes it), the features `cells_avx2` is compiled for.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { cells_avx2(rotation, rel_x, rel_y, cells) },
        _ => cells_body(rotation, rel_x, rel_y, cells),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn cells_avx2(rotation: CellRotation, rel_x: &[f64], rel_y: &[f64], cells: &mut [u32]) {
    cells_body(rotation, rel_x, rel_y, cells);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn cells_avx512(rotation: CellRotation, rel_x: &[f64], rel_y: &[f64], cells: &mut [u32]) {
    cells_body(rotation, rel_x, rel_y, cells);
}

fn check_points(points: &[DVec2]) -> Result<(), ShapeMatchError> {
    if points.len() < MIN_MATCH_POINTS {
        return Err(ShapeMatchError::TooFewPoints {
            found: points.len(),
        });
    }
    if let Some(index) = points.iter().position(|p| !p.is_finite()) {
        return Err(ShapeMatchError::NonFinitePoint { index });
    }
    Ok(())
}

fn validate(c: &ShapeMatcherConfig) -> Result<(), ShapeMatcherBuildError> {
    let bad = |field: &'static str, value: f64, expected: &'static str| {
        Err(ShapeMatcherBuildError::BadConfig {
            field,
            value,
            expected,
        })
    };
    let fraction = |v: f32| v.is_finite() && v > 0.0 && v < 1.0;
    if !fraction(c.border_threshold) {
        return bad(
            "border_threshold",
            c.border_threshold.into(),
            "expected in (0, 1)",
        );
    }
    if !fraction(c.paper_threshold) {
        return bad(
            "paper_threshold",
            c.paper_threshold.into(),
            "expected in (0, 1)",
        );
    }
    if !(c.coarse_step_deg.is_finite() && (MIN_COARSE_STEP_DEG..=90.0).contains(&c.coarse_step_deg))
    {
        return bad(
            "coarse_step_deg",
            c.coarse_step_deg,
            "expected in [6, 90] deg",
        );
    }
    for (field, v) in [
        ("fine_step_deg", c.fine_step_deg),
        ("paper_step_deg", c.paper_step_deg),
    ] {
        if !(v.is_finite() && (0.01..=90.0).contains(&v)) {
            return bad(field, v, "expected in [0.01, 90] deg");
        }
    }
    if c.fine_step_deg > c.coarse_step_deg {
        return bad(
            "fine_step_deg",
            c.fine_step_deg,
            "expected at most coarse_step_deg",
        );
    }
    if !(c.inlier_distance_m.is_finite() && c.inlier_distance_m > 0.0) {
        return bad(
            "inlier_distance_m",
            c.inlier_distance_m,
            "expected a positive length",
        );
    }
    if c.candidates == 0 {
        return bad("candidates", 0.0, "expected at least 1");
    }
    if c.symmetry_order > 360 {
        return bad(
            "symmetry_order",
            c.symmetry_order.into(),
            "expected at most 360",
        );
    }
    Ok(())
}

/// The radius of the learned border of `shape` (a normalised or unnormalised S): the
/// farthest ridge point above the default matcher's threshold (0.3 of S's largest value)
/// from the object frame's origin, m. What the shape matcher's border reaches, learned from
/// IR alone: where pushes start is set from it. `None` for an S without a border.
pub fn learned_border_radius_m(shape: &Grid) -> Option<f64> {
    let max = shape.max();
    if max <= 0.0 {
        return None;
    }
    let threshold = ShapeMatcherConfig::default().border_threshold * max;
    let r = ridge_points(shape, threshold)
        .iter()
        .map(|p| p.length())
        .fold(0.0, f64::max);
    (r > 0.0).then_some(r)
}

/// The ridge of `s` above `threshold`: cells that are a maximum of `s` along the direction
/// of its strongest negative curvature (the Hessian's eigenvector), moved to the peak of
/// the parabola through that direction's three samples (object frame, metres).
fn ridge_points(s: &Grid, threshold: f32) -> Vec<DVec2> {
    let mut out = Vec::new();
    let v = |i: usize, j: usize| f64::from(s.get(i, j));
    for j in 1..GRID_SIDE - 1 {
        for i in 1..GRID_SIDE - 1 {
            let f0 = v(i, j);
            if f0 < f64::from(threshold) {
                continue;
            }
            let a = v(i + 1, j) - 2.0 * f0 + v(i - 1, j);
            let c = v(i, j + 1) - 2.0 * f0 + v(i, j - 1);
            let b = 0.25 * (v(i + 1, j + 1) - v(i + 1, j - 1) - v(i - 1, j + 1) + v(i - 1, j - 1));
            let mean = 0.5 * (a + c);
            let root = (0.25 * (a - c) * (a - c) + b * b).sqrt();
            let lambda = mean - root;
            if lambda >= 0.0 {
                continue;
            }
            let e1 = DVec2::new(b, lambda - a);
            let e2 = DVec2::new(lambda - c, b);
            let e = if e1.length_squared() >= e2.length_squared() {
                e1
            } else {
                e2
            };
            let n = if e.length_squared() > 1e-24 {
                e.normalize()
            } else {
                DVec2::X
            };
            let centre = DVec2::new(i as f64, j as f64);
            let at = |c: DVec2| f64::from(s.sample(s.from_cell_coords(c)));
            let (fm, fp) = (at(centre - n), at(centre + n));
            if f0 > fm && f0 >= fp {
                let denom = fm - 2.0 * f0 + fp;
                let delta = if denom < 0.0 {
                    (0.5 * (fm - fp) / denom).clamp(-0.5, 0.5)
                } else {
                    0.0
                };
                out.push(s.from_cell_coords(centre + delta * n));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every vector build of the paper's method's cell loop this CPU runs gives the
    /// baseline build's cells, on and off the grid.
    #[test]
    fn every_vector_build_finds_the_baseline_cells() {
        let n = 1001;
        let rel_x: Vec<f64> = (0..n).map(|k| (k as f64 * 0.37).sin() * 0.4).collect();
        let rel_y: Vec<f64> = (0..n).map(|k| (k as f64 * 0.23).cos() * 0.4).collect();
        let rotation = CellRotation {
            to_cells: DVec2::from_angle(-0.7) * 320.0,
            centre: DVec2::splat(64.3),
        };
        let mut baseline = vec![0; n];
        cells_body(rotation, &rel_x, &rel_y, &mut baseline);
        let off = baseline.iter().filter(|&&c| c == OFF_GRID).count();
        assert!(
            off > 0 && off < n,
            "some points on the grid and some off it"
        );
        for &simd in Simd::runnable() {
            let mut cells = vec![0; n];
            cells_at(simd, rotation, &rel_x, &rel_y, &mut cells);
            assert_eq!(cells, baseline, "{simd:?}");
        }
    }
}
