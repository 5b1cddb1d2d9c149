//! Runs the trajectory benchmark's paths in-process on the tuning seeds and prints each
//! planner's mean error per path: a development aid for tuning the trajectory planner.
//!
//! `cargo run -p agp-harness --example trajectory_probe -- AG_FILE FIRST_SEED SEEDS [PLANNERS]`
//! (PLANNERS: comma-separated, default `affordance,baseline`). Environment: `PATHS`
//! (comma-separated names), `AGP_TRACE`, and overrides of the episode config: `LOOK` (m),
//! `STEER` (deg, 0 off), `TRACK` (track weight), `ADV` (m), `PROG`, `FOLLOW` (0 off), `ROTW`,
//! `SPREAD`, `FRACS`, `HEAD` and `HEADW` (heading tolerance and weight, deg), `XTG` and
//! `XTL` (the cross-track integral's gain and leak), `XG` and `XR` (the share of their
//! predicted sideways motion short path pushes make, and how far each circling moves it),
//! `XT` (the share of their predicted rotation), `XD` (the cost per metre of a short path
//! push's predicted sideways motion), `XN` (the most pushes between circlings along a path),
//! `XC` (m: circle once the pushes since the last circling predicted this much sideways),
//! `XM` (m: the trust margin over the baseline's own push, `path_trust_margin_m`), `XCAP`
//! (1: the circlings never raise the sideways share above `XG`),
//! `AGDIR` (each seed's own AG, `AGDIR/seed-<S>/lshape.ag`, as `agp bench learn --seeds`
//! writes them, instead of AG_FILE for every seed).

use agp_affordance::AffordanceGradient;
use agp_harness::run_episode;
use agp_harness::side_by_side::side_by_side;
use agp_harness::task_goals::NamedPath;
use agp_planning::{EpisodeConfig, PlannerKind, Task};
use agp_world::{RobotDescription, Scenario};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let ag = AffordanceGradient::load(args.first().map_or("lshape.ag", String::as_str))?;
    let first: u64 = args.get(1).map_or(Ok(1), |s| s.parse())?;
    let n: u64 = args.get(2).map_or(Ok(10), |s| s.parse())?;
    let planners: Vec<PlannerKind> = args
        .get(3)
        .map_or("affordance,baseline", String::as_str)
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let scenario = Scenario::resolve("lshape")?;
    let robot = RobotDescription::epuck();
    let paths: Vec<NamedPath> = match std::env::var("PATHS") {
        Ok(v) => v
            .split(',')
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(anyhow::Error::msg)?,
        Err(_) => NamedPath::SET.to_vec(),
    };
    let mut config = EpisodeConfig::for_task(&scenario.task);
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    if let Some(v) = env("LOOK") {
        config.lookahead_m = v;
    }
    if let Some(v) = env("STEER") {
        config.steer_max_deg = v;
        config.steer_centroid_pushes = v > 0.0;
    }
    if let Some(v) = env("ROTW") {
        config.reach_rotation_weight_m_per_rad = v;
    }
    if let Some(v) = env("SPREAD") {
        config.spread_weight = v;
    }
    if let Some(v) = env("TRACK") {
        config.track_weight = v;
    }
    if let Some(v) = env("ADV") {
        config.advance_m = v;
    }
    let keep_heading_rad = env("HEAD").map(f64::to_radians);
    if let Some(v) = env("HEADW") {
        config.heading_weight_m_per_rad = v * 1e-3 * 180.0 / std::f64::consts::PI;
    }
    if let Some(v) = env("XTG") {
        config.cross_track_gain = v;
    }
    if let Some(v) = env("XTL") {
        config.cross_track_leak = v;
    }
    if let Some(v) = env("XG") {
        config.path_cross_gain = v;
    }
    if let Some(v) = env("XR") {
        config.path_cross_gain_rate = v;
    }
    if let Some(v) = env("XT") {
        config.path_turn_gain = v;
    }
    if let Some(v) = env("XD") {
        config.path_cross_doubt = v;
    }
    if let Some(v) = env("XN") {
        config.path_max_pushes_between_estimates = v as u32;
    }
    if let Some(v) = env("XC") {
        config.path_circle_after_cross_m = v;
    }
    if let Some(v) = env("XM") {
        config.path_trust_margin_m = Some(v);
    }
    if let Some(v) = env("XCAP") {
        config.path_cross_gain_capped = v > 0.0;
    }
    let ag_dir = std::env::var_os("AGDIR").map(std::path::PathBuf::from);
    let own_ags: Vec<(u64, AffordanceGradient)> = match &ag_dir {
        Some(dir) => (first..first + n)
            .map(|s| {
                let f = dir.join(format!("seed-{s}")).join("lshape.ag");
                Ok((s, AffordanceGradient::load(&f)?))
            })
            .collect::<anyhow::Result<_>>()?,
        None => Vec::new(),
    };
    if let Some(v) = env("PROG") {
        config.progress_weight = v;
    }
    if let Some(v) = env("FOLLOW") {
        config.follow_path = v > 0.0;
    }
    if let Ok(v) = std::env::var("FRACS") {
        config.path_push_fractions = v.split(',').filter_map(|x| x.parse().ok()).collect();
    }
    config.trace = std::env::var_os("AGP_TRACE").is_some();
    let work: Vec<(NamedPath, PlannerKind, u64)> = paths
        .iter()
        .flat_map(|&p| {
            let planners = &planners;
            (first..first + n).flat_map(move |s| planners.iter().map(move |&k| (p, k, s)))
        })
        .collect();
    let out = side_by_side(&work, |&(p, planner, seed)| {
        let path = p.points(&scenario);
        let cfg = EpisodeConfig {
            seed,
            ..config.clone()
        };
        let task = Task::Trajectory {
            path: path.clone(),
            keep_heading_rad,
        };
        let ag = own_ags
            .iter()
            .find(|(s, _)| *s == seed)
            .map_or(&ag, |(_, g)| g);
        let r = run_episode(&scenario, &robot, Some(ag), planner, &task, &cfg).ok()?;
        let e = r.evaluation?;
        let poses: Vec<_> = e.samples.iter().map(|s| s.pose).collect();
        let err = agp_harness::trajectory_error(&path, &poses)? * 1e3;
        Some((err, e.success, r.pushes))
    });
    for &p in &paths {
        let mut line = format!("{:<9}", p.name());
        for &k in &planners {
            let v: Vec<(f64, bool, u32)> = work
                .iter()
                .zip(&out)
                .filter(|((q, kk, _), _)| *q == p && *kk == k)
                .filter_map(|(_, o)| *o)
                .collect();
            let mean = v.iter().map(|x| x.0).sum::<f64>() / v.len().max(1) as f64;
            let ends = v.iter().filter(|x| x.1).count();
            let pushes = v.iter().map(|x| f64::from(x.2)).sum::<f64>() / v.len().max(1) as f64;
            let each: Vec<String> = v.iter().map(|x| format!("{:.2}", x.0)).collect();
            line += &format!(
                "  {k}: {mean:.2} mm ends {ends}/{} pushes {pushes:.0} [{}]",
                v.len(),
                each.join(" ")
            );
        }
        println!("{line}");
    }
    Ok(())
}
