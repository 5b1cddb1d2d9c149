//! Runs a few episodes and prints each: a development aid for the episode runner.
//!
//! `cargo run --release -p agp-harness --example episode_probe -- OBJECT PLANNER N [AG_FILE]`
//! (without an AG file, one is learned from ground truth first). PLANNER `trajectory`
//! runs the affordance and baseline planners along the default path on N seeds and
//! splits the error before and after x = 270 mm (where a bend of a custom path may be).
//!
//! Environment: `AGP_TRACE` (every estimate and push on stderr), `AGP_ONLY=K` (place
//! episode K only), `AGP_SEED`, and overrides of the episode config: `SPREAD`, `ROTW`,
//! `ASTEP`, `STEER` (deg, 0 off), `LOOK` (m), `MARGIN`, `FRACS` (comma-separated).

#[path = "../tests/common/mod.rs"]
mod common;

use agp_affordance::AffordanceGradient;
use agp_harness::{place_goals, run_episode};
use agp_planning::{EpisodeConfig, PlannerKind, Task};
use agp_world::{RobotDescription, Scenario};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let name = args.first().map_or("triangle", String::as_str);
    let which = args.get(1).map_or("affordance", String::as_str);
    let n: usize = args.get(2).map_or(Ok(4), |s| s.parse())?;
    let scenario = Scenario::resolve(name)?;
    let robot = RobotDescription::epuck();
    let t = std::time::Instant::now();
    let ag = match args.get(3) {
        Some(f) => AffordanceGradient::load(f)?,
        None => common::learn_from_truth(&scenario, &robot),
    };
    eprintln!("AG ready in {:.1} s", t.elapsed().as_secs_f64());
    let mut config = EpisodeConfig::for_task(&scenario.task);
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    if let Some(v) = env("SPREAD") {
        config.spread_weight = v;
    }
    if let Some(v) = env("ROTW") {
        config.reach_rotation_weight_m_per_rad = v;
    }
    if let Some(v) = env("ASTEP") {
        config.alpha_step_deg = v;
    }
    if let Some(v) = env("STEER") {
        config.steer_max_deg = v;
        config.steer_centroid_pushes = v > 0.0;
    }
    if let Some(v) = env("AGP_SEED") {
        config.seed = v as u64;
    }
    if let Some(v) = env("LOOK") {
        config.lookahead_m = v;
    }
    if let Some(v) = env("MARGIN") {
        config.stop_margin = v;
    }
    if let Ok(v) = std::env::var("FRACS") {
        config.push_fractions = v.split(',').filter_map(|x| x.parse().ok()).collect();
    }
    if which == "trajectory" {
        let path = scenario.task.path.clone();
        let mut sums = [0.0, 0.0];
        for seed in 0..n as u64 {
            for (i, planner) in [PlannerKind::Affordance, PlannerKind::Baseline]
                .into_iter()
                .enumerate()
            {
                let cfg = EpisodeConfig {
                    trace: std::env::var_os("AGP_TRACE").is_some(),
                    seed: config.seed + seed,
                    ..config.clone()
                };
                let task = Task::Trajectory {
                    path: path.clone(),
                    keep_heading_rad: None,
                };
                let r = run_episode(&scenario, &robot, Some(&ag), planner, &task, &cfg)?;
                let judged = r
                    .evaluation
                    .clone()
                    .expect("in-process episodes are judged");
                let poses: Vec<_> = judged.samples.iter().map(|s| s.pose).collect();
                let e = agp_harness::trajectory_error(&path, &poses).unwrap_or(f64::NAN);
                let straight: Vec<_> = poses.iter().copied().filter(|p| p.x < 0.27).collect();
                let bend: Vec<_> = poses.iter().copied().filter(|p| p.x >= 0.27).collect();
                println!(
                    "  straight {:.2} mm ({} points), bend {:.2} mm ({} points)",
                    agp_harness::trajectory_error(&path, &straight).unwrap_or(f64::NAN) * 1e3,
                    straight.len(),
                    agp_harness::trajectory_error(&path, &bend).unwrap_or(f64::NAN) * 1e3,
                    bend.len()
                );
                println!(
                    "{planner}: {} {} pushes {} circlings {}, mean error {:.2} mm over {} points, end error {:.1} mm, sim {:.0} s",
                    if judged.success { "OK" } else { "FAIL" },
                    r.end.name(),
                    r.pushes,
                    r.circlings,
                    e * 1e3,
                    poses.len(),
                    judged.position_error_mm,
                    r.sim_time_s
                );
                sums[i] += e * 1e3 / n as f64;
            }
        }
        println!(
            "mean over {n} seeds: affordance {:.2} mm, baseline {:.2} mm, ratio {:.2}",
            sums[0],
            sums[1],
            sums[0] / sums[1]
        );
        return Ok(());
    }
    let planner: PlannerKind = which.parse()?;
    let only: Option<usize> = std::env::var("AGP_ONLY").ok().and_then(|s| s.parse().ok());
    for (k, goal) in place_goals(&scenario, n, config.seed)
        .into_iter()
        .enumerate()
    {
        if only.is_some_and(|o| o != k) {
            continue;
        }
        let cfg = EpisodeConfig {
            seed: config.seed + k as u64,
            trace: std::env::var_os("AGP_TRACE").is_some(),
            ..config.clone()
        };
        let r = run_episode(
            &scenario,
            &robot,
            Some(&ag),
            planner,
            &Task::Place { goal },
            &cfg,
        )?;
        let e = r
            .evaluation
            .clone()
            .expect("in-process episodes are judged");
        println!(
            "{k}: goal ({:.0}, {:.0}) {:.0} deg: {} {} pushes {} circlings {}, err {:.1} mm {:.1} deg, sim {:.0} s wall {:.1} s",
            goal.x * 1e3,
            goal.y * 1e3,
            goal.theta.to_degrees(),
            if e.success { "OK" } else { "FAIL" },
            r.end.name(),
            r.pushes,
            r.circlings,
            e.position_error_mm,
            e.orientation_error_deg,
            r.sim_time_s,
            r.wall_time_s
        );
    }
    Ok(())
}
