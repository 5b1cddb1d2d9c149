//! The benchmark tasks over many episodes (benchmarks.md sections 2 and 3): `place`
//! (random goals) and `trajectory` (the L along a polyline), with their summaries.

use agp_shared_types::Pose2;
use agp_world::{Rng, Scenario};
use glam::DVec2;

use agp_planning::{EpisodeResult, distance_to_path};

/// `count` place goals drawn from `seed`: 250 to 500 mm from the object's start in any
/// direction, any orientation (benchmarks.md, "Built-in scenarios").
pub fn place_goals(scenario: &Scenario, count: usize, seed: u64) -> Vec<Pose2> {
    let start = scenario.object.start;
    let mut rng = Rng::new(seed);
    (0..count)
        .map(|_| {
            let d = rng.range(0.25, 0.5);
            let a = std::f64::consts::TAU * rng.uniform();
            let theta = std::f64::consts::TAU * rng.uniform() - std::f64::consts::PI;
            Pose2::new(start.x + d * a.cos(), start.y + d * a.sin(), theta)
        })
        .collect()
}

/// A path of the trajectory benchmark, by name: its points relative to the object's start
/// (the robot approaches along +x, so every path leaves the start along +x).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NamedPath {
    /// 600 mm straight along +x, through the L's centroid: the paper's line.
    Straight,
    /// 300 mm along +x, then 250 mm turned 45 deg to the left.
    Bend45,
    /// 300 mm along +x, then 250 mm turned 90 deg to the right.
    Bend90,
    /// A lane change: 500 mm along +x while the path moves 200 mm to the left on half a
    /// cosine (leaves and ends along +x, 32 deg at its steepest, radius 250 mm at least).
    SCurve,
    /// A circle of radius 300 mm turning 105 deg to the left (550 mm).
    Arc,
    /// The scenario's own `path_mm` (or its 600 mm default line), in world coordinates.
    Scenario,
}

impl NamedPath {
    /// The five paths every run takes unless `--paths` says otherwise.
    pub const SET: [Self; 5] = [
        Self::Straight,
        Self::Bend45,
        Self::Bend90,
        Self::SCurve,
        Self::Arc,
    ];

    /// The name on the command line and in the JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::Straight => "straight",
            Self::Bend45 => "bend45",
            Self::Bend90 => "bend90",
            Self::SCurve => "s-curve",
            Self::Arc => "arc",
            Self::Scenario => "scenario",
        }
    }

    /// The path, world frame, m: the set's shapes start at the object's start;
    /// [`NamedPath::Scenario`] is the scenario's path as it stands.
    pub fn points(self, scenario: &Scenario) -> Vec<DVec2> {
        let start = scenario.object.start.position();
        let mm = |x: f64, y: f64| start + DVec2::new(x, y) * 1e-3;
        match self {
            Self::Straight => vec![mm(0.0, 0.0), mm(600.0, 0.0)],
            Self::Bend45 => {
                let d = 250.0 * std::f64::consts::FRAC_1_SQRT_2;
                vec![mm(0.0, 0.0), mm(300.0, 0.0), mm(300.0 + d, d)]
            }
            Self::Bend90 => vec![mm(0.0, 0.0), mm(300.0, 0.0), mm(300.0, -250.0)],
            Self::SCurve => {
                const SEGMENTS: u32 = 24;
                (0..=SEGMENTS)
                    .map(|k| {
                        let u = f64::from(k) / f64::from(SEGMENTS);
                        mm(500.0 * u, 100.0 * (1.0 - (std::f64::consts::PI * u).cos()))
                    })
                    .collect()
            }
            Self::Arc => {
                const SEGMENTS: u32 = 21;
                const RADIUS_MM: f64 = 300.0;
                let turn = 105f64.to_radians();
                (0..=SEGMENTS)
                    .map(|k| {
                        let a = turn * f64::from(k) / f64::from(SEGMENTS);
                        mm(RADIUS_MM * a.sin(), RADIUS_MM * (1.0 - a.cos()))
                    })
                    .collect()
            }
            Self::Scenario => scenario.task.path.clone(),
        }
    }
}

impl std::fmt::Display for NamedPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for NamedPath {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::SET
            .into_iter()
            .chain([Self::Scenario])
            .find(|p| p.name() == s.trim())
            .ok_or_else(|| {
                format!(
                    "unknown path `{s}` (paths: straight, bend45, bend90, s-curve, arc, scenario)"
                )
            })
    }
}

/// The length of the polyline `path`, m.
pub fn path_length(path: &[DVec2]) -> f64 {
    path.windows(2).map(|w| (w[1] - w[0]).length()).sum()
}

/// The direction (rad) of the path's segment closest to `p`.
pub fn path_tangent(path: &[DVec2], p: DVec2) -> Option<f64> {
    path.windows(2)
        .filter(|w| (w[1] - w[0]).length() > 1e-12)
        .map(|w| {
            (
                agp_world::point_segment_distance(p, w[0], w[1]),
                w[1] - w[0],
            )
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, d)| d.to_angle())
}

/// The share of `samples` whose heading (the object's frame's x axis, as the planner
/// keeps it) lies within `tolerance` (rad) of the tangent of the path's closest segment,
/// modulo the object's symmetry of `order`. `None` without samples.
pub fn heading_share(path: &[DVec2], samples: &[Pose2], order: u32, tolerance: f64) -> Option<f64> {
    if samples.is_empty() {
        return None;
    }
    let within = samples
        .iter()
        .filter(|s| {
            path_tangent(path, DVec2::new(s.x, s.y)).is_some_and(|t| {
                agp_planning::symmetric_angle_error(s.theta - t, order).abs() <= tolerance
            })
        })
        .count();
    Some(within as f64 / samples.len() as f64)
}

/// The paper's trajectory error: for every recorded centroid position, the distance to
/// the closest point of the path; the mean over the points, m. `None` without points.
pub fn trajectory_error(path: &[DVec2], samples: &[Pose2]) -> Option<f64> {
    if samples.is_empty() {
        return None;
    }
    let sum: f64 = samples
        .iter()
        .map(|p| distance_to_path(path, DVec2::new(p.x, p.y)))
        .sum();
    Some(sum / samples.len() as f64)
}

/// The median of `values` (the mean of the middle two for an even count); NaN if empty.
pub fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| !x.is_nan()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// One planner's episodes, summarised as the benchmark reports them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannerSummary {
    pub episodes: usize,
    /// Fraction of episodes that succeeded.
    pub success_rate: f64,
    pub median_position_error_mm: f64,
    pub median_orientation_error_deg: f64,
    pub median_pushes: f64,
    /// Simulated time of all episodes, s.
    pub sim_time_s: f64,
    /// Wall time of all episodes, s.
    pub wall_time_s: f64,
}

impl PlannerSummary {
    /// The summary of `results` (all from one planner); an episode without an evaluation
    /// counts as a failure with no errors to report.
    pub fn of(results: &[EpisodeResult]) -> Self {
        let n = results.len();
        let pick = |f: fn(&EpisodeResult) -> f64| results.iter().map(f).collect::<Vec<_>>();
        Self {
            episodes: n,
            success_rate: if n == 0 {
                0.0
            } else {
                results.iter().filter(|r| r.success()).count() as f64 / n as f64
            },
            median_position_error_mm: median(&pick(|r| {
                r.evaluation
                    .as_ref()
                    .map_or(f64::NAN, |e| e.position_error_mm)
            })),
            median_orientation_error_deg: median(&pick(|r| {
                r.evaluation
                    .as_ref()
                    .map_or(f64::NAN, |e| e.orientation_error_deg)
            })),
            median_pushes: median(&pick(|r| f64::from(r.pushes))),
            sim_time_s: results.iter().map(|r| r.sim_time_s).sum(),
            wall_time_s: results.iter().map(|r| r.wall_time_s).sum(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn place_goals_lie_250_to_500_mm_from_the_start() {
        let scenario = Scenario::builtin("triangle").expect("built-in");
        let goals = place_goals(&scenario, 200, 3);
        assert_eq!(goals.len(), 200);
        for g in &goals {
            let d = DVec2::new(g.x, g.y).length();
            assert!((0.25..=0.5).contains(&d), "{g:?}");
            assert!(g.theta.abs() <= std::f64::consts::PI);
        }
        assert_eq!(
            place_goals(&scenario, 200, 3),
            goals,
            "same seed, same goals"
        );
        assert_ne!(place_goals(&scenario, 200, 4), goals);
    }

    #[test]
    fn every_named_path_leaves_the_objects_start_along_x_and_runs_500_to_600_mm() {
        let mut scenario = Scenario::builtin("lshape").expect("built-in");
        scenario.object.start = Pose2::new(0.1, -0.05, 0.0);
        let start = DVec2::new(0.1, -0.05);
        for p in NamedPath::SET {
            let points = p.points(&scenario);
            assert!(
                (2..=32).contains(&points.len()),
                "{p}: {} points",
                points.len()
            );
            assert!((points[0] - start).length() < 1e-12, "{p}");
            let first = (points[1] - points[0]).to_angle().to_degrees();
            assert!(first.abs() < 5.0, "{p}: leaves at {first} deg");
            let len = path_length(&points);
            assert!((0.5..=0.6 + 1e-9).contains(&len), "{p}: {len} m");
            assert_eq!(p.name().parse::<NamedPath>(), Ok(p));
        }
        // The bends turn by their names' angles, the arc by 105 deg.
        let turn = |p: NamedPath| {
            let q = p.points(&scenario);
            let n = q.len();
            (q[n - 1] - q[n - 2]).to_angle().to_degrees()
        };
        assert!((turn(NamedPath::Bend45) - 45.0).abs() < 1e-9);
        assert!((turn(NamedPath::Bend90) + 90.0).abs() < 1e-9);
        assert!(turn(NamedPath::SCurve).abs() < 10.0);
        assert!((turn(NamedPath::Arc) - 105.0).abs() < 5.0);
        assert_eq!(NamedPath::Scenario.points(&scenario), scenario.task.path);
        assert!("zigzag".parse::<NamedPath>().is_err());
    }

    #[test]
    fn the_heading_share_counts_points_within_the_tolerance_of_the_tangent() {
        let path = [DVec2::ZERO, DVec2::new(0.3, 0.0), DVec2::new(0.3, 0.3)];
        let deg = f64::to_radians;
        let samples = [
            Pose2::new(0.1, 0.0, deg(10.0)),
            Pose2::new(0.2, 0.0, deg(-20.0)),
            Pose2::new(0.31, 0.2, deg(80.0)),
            Pose2::new(0.31, 0.25, deg(0.0)),
        ];
        let share = heading_share(&path, &samples, 1, deg(15.0)).expect("samples");
        assert!((share - 0.5).abs() < 1e-12, "{share}");
        assert_eq!(heading_share(&path, &[], 1, deg(15.0)), None);
    }

    #[test]
    fn the_trajectory_error_is_the_mean_distance_to_the_path() {
        let path = [DVec2::ZERO, DVec2::new(1.0, 0.0)];
        let samples = [
            Pose2::new(0.1, 0.01, 0.0),
            Pose2::new(0.5, -0.03, 1.0),
            Pose2::new(0.9, 0.0, 2.0),
        ];
        let e = trajectory_error(&path, &samples).expect("points");
        assert!((e - 0.04 / 3.0).abs() < 1e-12);
        assert_eq!(trajectory_error(&path, &[]), None);
    }

    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&[5.0, 1.0, 3.0]), 3.0);
        assert!(median(&[]).is_nan());
    }
}
