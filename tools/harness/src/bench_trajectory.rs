//! `agp bench trajectory`: the paper's push along a path (benchmarks.md section 2), the
//! affordance and the baseline planner on the same seed.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::bench_tasks::{
    Overlay, Panel, Runner, judged, physics_label, physics_note, plot_runs, prefix_of, progress,
    resolve_ag, write_json,
};
use crate::side_by_side::side_by_side;
use crate::trajectory_error;
use agp_planning::{EpisodeConfig, EstimateVerdict, PlannerKind, Task};
use agp_shared_types::Pose2;
use agp_world::Scenario;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::PathBuf;

/// The options of `agp bench trajectory`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchTrajectoryArgs {
    /// Built-in scenario or a scenario file; its `path_mm` if it has one, else 300 mm
    /// along +x then 200 mm at 45 deg.
    #[arg(long, default_value = "lshape")]
    pub scenario: String,
    /// Affordance gradient file learned from IR (default: `results/learn/<object>.ag`,
    /// learned first with `agp bench learn` when missing).
    #[arg(long)]
    pub ag: Option<PathBuf>,
    /// Seed of the sensor noise (default: the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Step the physics library in-process instead of running the pipeline's processes.
    #[arg(long)]
    pub in_process: bool,
    /// Also write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw both runs (path, object every few steps, as the paper's Fig. 6) to this
    /// SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

#[derive(Debug, Serialize)]
struct TrajectoryPlannerJson {
    mean_error_mm: f64,
    points: usize,
    reached_end: bool,
    final_distance_to_end_mm: f64,
    pushes: u32,
    circlings: u32,
    sim_time_s: f64,
    wall_time_s: f64,
    /// The estimator's estimates of the episode, judged.
    estimate: Option<EstimateVerdict>,
}

#[derive(Debug, Serialize)]
struct TrajectoryJson {
    benchmark: &'static str,
    scenario: String,
    seed: u64,
    physics: &'static str,
    path_mm: Vec<[f64; 2]>,
    planners: BTreeMap<String, TrajectoryPlannerJson>,
    /// Affordance over baseline.
    ratio: f64,
    wall_time_s: f64,
}

/// Runs `agp bench trajectory`: the affordance and the baseline planner on the same
/// seed.
pub fn run_trajectory(args: &BenchTrajectoryArgs) -> Result<serde_json::Value> {
    let wall = Instant::now();
    let scenario = Scenario::resolve(&args.scenario)
        .with_context(|| format!("cannot load scenario `{}`", args.scenario))?;
    let planners = [PlannerKind::Affordance, PlannerKind::Baseline];
    let ag = resolve_ag(args.ag.as_deref(), &args.scenario, &scenario, &planners)?;
    let note = physics_note(args.in_process);
    let seed = args.seed.unwrap_or(scenario.task.seed);
    let path = scenario.task.path.clone();
    let config = EpisodeConfig {
        seed,
        ..EpisodeConfig::for_task(&scenario.task)
    };
    eprintln!(
        "bench trajectory: scenario `{}`, seed {seed}; {note}",
        scenario.name
    );
    let bar = progress(planners.len() as u64);
    bar.set_prefix(prefix_of(&planners));
    let task = Task::Trajectory { path: path.clone() };
    let runs = side_by_side(&planners, |&planner| {
        let mut runner = Runner::start(
            args.in_process,
            &args.scenario,
            &scenario,
            ag.as_deref(),
            planner,
            seed,
        )?;
        let r = runner
            .episode(planner, &task, &config)
            .with_context(|| format!("planner `{planner}`"));
        // Stopped and cleaned up whatever happened: a failed episode leaves no file.
        let finished = runner.finish();
        let r = r?;
        finished?;
        bar.inc(1);
        Ok(r)
    })
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    bar.finish_and_clear();
    let wall_time_s = wall.elapsed().as_secs_f64();

    let errors: Vec<f64> = runs
        .iter()
        .map(|r| {
            let poses: Vec<Pose2> = judged(r).samples.iter().map(|s| s.pose).collect();
            trajectory_error(&path, &poses).unwrap_or(f64::NAN) * 1e3
        })
        .collect();
    let ratio = errors[0] / errors[1];
    println!(
        "trajectory `{}`: seed {seed}, path {} mm; {note}",
        scenario.name,
        path.iter()
            .map(|p| format!("({:.0}, {:.0})", p.x * 1e3, p.y * 1e3))
            .collect::<Vec<_>>()
            .join(" -> ")
    );
    println!(
        "{:<12} {:>14} {:>8} {:>10} {:>8} {:>10} {:>8} {:>8}",
        "planner", "mean err mm", "points", "end", "pushes", "circlings", "sim s", "wall s"
    );
    let mut json_planners = BTreeMap::new();
    for ((planner, r), e) in planners.iter().zip(&runs).zip(&errors) {
        println!(
            "{:<12} {:>14.2} {:>8} {:>10} {:>8} {:>10} {:>8.0} {:>8.1}",
            planner.name(),
            e,
            judged(r).samples.len(),
            if r.success() { "reached" } else { r.end.name() },
            r.pushes,
            r.circlings,
            r.sim_time_s,
            r.wall_time_s
        );
        json_planners.insert(
            planner.name().to_owned(),
            TrajectoryPlannerJson {
                mean_error_mm: *e,
                points: judged(r).samples.len(),
                reached_end: r.success(),
                final_distance_to_end_mm: judged(r).position_error_mm,
                pushes: r.pushes,
                circlings: r.circlings,
                sim_time_s: r.sim_time_s,
                wall_time_s: r.wall_time_s,
                estimate: r.estimate_verdict,
            },
        );
    }
    println!("ratio affordance / baseline {ratio:.2} (paper 7.82 / 10.71 = 0.73)");
    println!("wall time {wall_time_s:.1} s");
    let doc = serde_json::to_value(TrajectoryJson {
        benchmark: "trajectory",
        scenario: scenario.name.clone(),
        seed,
        physics: physics_label(args.in_process),
        path_mm: path.iter().map(|p| [p.x * 1e3, p.y * 1e3]).collect(),
        planners: json_planners,
        ratio,
        wall_time_s,
    })
    .context("cannot encode the result")?;
    if let Some(file) = &args.json {
        write_json(file, &doc)?;
        println!("JSON     {}", file.display());
    }
    if let Some(file) = &args.plot {
        let panels: Vec<Panel> = planners
            .iter()
            .zip(&runs)
            .zip(&errors)
            .map(|((planner, r), e)| Panel {
                title: format!("{planner}: mean error {e:.2} mm per point"),
                samples: &judged(r).samples,
            })
            .collect();
        let title = format!(
            "trajectory `{}`: path in red, object every few steps ({note})",
            scenario.name
        );
        plot_runs(
            file,
            &title,
            &scenario.object.shape,
            &panels,
            Overlay::Path(&path),
        )?;
        println!("plot     {}", file.display());
    }
    Ok(doc)
}
