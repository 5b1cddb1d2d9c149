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
