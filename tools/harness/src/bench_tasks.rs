//! `agp bench place` and `agp bench trajectory`: the paper's two tasks (benchmarks.md
//! sections 2 and 3) over many episodes, each planner on the same goals and seeds.
//!
//! Episodes run over the real pipeline by default ([`PipelineBench`]: lockstep
//! `agp-physics`, `agp-estimator` serving the AG file, an `agp-planner` process per
//! episode, ground truth read by the benchmark only); `--in-process` steps the physics
//! library directly instead (the same planner logic and simulator, no transport), and every
//! output says which.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::{PlannerSummary, place_goals, run_episode};
use agp_affordance::AffordanceGradient;
use agp_planning::{
    EpisodeConfig, EpisodeResult, EstimateVerdict, Evaluation, PlannerKind, PoseSample, Task,
};
use agp_shared_types::Pose2;
use agp_world::{ObjectShape, RobotDescription, Scenario};
use anyhow::{Context, Result, bail};

use crate::bench_learn;
use crate::pipeline_bench::PipelineBench;
use crate::side_by_side::side_by_side;
use glam::DVec2;
use indicatif::{ProgressBar, ProgressStyle};
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;

/// What every bench output says about where the physics ran.
const PIPELINE_NOTE: &str =
    "over the pipeline (agp-physics, agp-estimator, one agp-planner per episode, iceoryx2)";
const IN_PROCESS_NOTE: &str = "physics in-process (agp_physics library, no iceoryx2)";
const ORACLE_NOTE: &str = "`oracle` reads the object's true pose (ground truth): an upper bound";

/// The options of `agp bench place`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchPlaceArgs {
    /// Built-in scenario (triangle, lshape, square, circle) or a scenario file.
    #[arg(long, default_value = "triangle")]
    pub scenario: String,
    /// Episodes per planner: random goals 250 to 500 mm from the start, any orientation.
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// Seed of the goals and of the sensor noise (default: the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Planners to run, comma-separated: affordance, baseline, oracle.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "affordance,baseline,oracle"
    )]
    pub planners: Vec<PlannerKind>,
    /// Affordance gradient file learned from IR (default: `results/learn/<object>.ag`,
    /// learned first with `agp bench learn` when missing).
    #[arg(long)]
    pub ag: Option<PathBuf>,
    /// Step the physics library in-process instead of running the pipeline's processes
    /// (the same planner logic and simulator; faster, no transport).
    #[arg(long)]
    pub in_process: bool,
    /// Also write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the first episode of each planner (object every few steps, goal
    /// outline, as the paper's Fig. 7) to this SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

#[derive(Debug, Serialize)]
struct PlaceEpisodeJson {
    goal_x_mm: f64,
    goal_y_mm: f64,
    goal_theta_deg: f64,
    success: bool,
    end: &'static str,
    position_error_mm: f64,
    orientation_error_deg: f64,
    pushes: u32,
    circlings: u32,
    sim_time_s: f64,
    wall_time_s: f64,
    /// The estimator's estimates of the episode, judged.
    estimate: Option<EstimateVerdict>,
}

#[derive(Debug, Serialize)]
struct PlacePlannerJson {
    episodes: usize,
    success_rate: f64,
    median_position_error_mm: f64,
    median_orientation_error_deg: f64,
    median_pushes: f64,
    sim_time_s: f64,
    wall_time_s: f64,
    reads_ground_truth: bool,
    runs: Vec<PlaceEpisodeJson>,
}

#[derive(Debug, Serialize)]
struct PlaceJson {
    benchmark: &'static str,
    scenario: String,
    seed: u64,
    physics: &'static str,
    tolerance_mm: f64,
    tolerance_deg: f64,
    planners: BTreeMap<String, PlacePlannerJson>,
    wall_time_s: f64,
}

/// The AG file the affordance and oracle planners use: `path`, or the learning
/// benchmark's file for the object, learned first (and said so) when it is missing.
/// `None` when no planner of `needed_by` needs one.
pub fn resolve_ag(
    path: Option<&Path>,
    scenario_arg: &str,
    scenario: &Scenario,
    needed_by: &[PlannerKind],
) -> Result<Option<PathBuf>> {
    if !needed_by.iter().any(|k| k.needs_gradient()) {
        return Ok(None);
    }
    if let Some(path) = path {
        if !path.is_file() {
            bail!("--ag {}: no such file", path.display());
        }
        return Ok(Some(path.to_owned()));
    }
    let out = PathBuf::from(bench_learn::DEFAULT_OUT);
    let learned = bench_learn::ag_path(&out, scenario);
    if !learned.is_file() {
        eprintln!(
            "no affordance gradient of `{}` at {}: learning it first (agp bench learn --scenario {scenario_arg})",
            scenario.name,
            learned.display()
        );
        bench_learn::run(&bench_learn::BenchLearnArgs::for_scenarios(
            &[scenario_arg],
            out,
        ))?;
    }
    Ok(Some(learned))
}

/// Where episodes run.
#[expect(
    clippy::large_enum_variant,
    reason = "one per benchmark run; boxing buys nothing"
)]
pub(crate) enum Runner<'a> {
    InProcess {
        scenario: &'a Scenario,
        robot: RobotDescription,
        ag: Option<AffordanceGradient>,
    },
    Pipeline(PipelineBench),
}

impl<'a> Runner<'a> {
    /// A runner for `planner`'s episodes: each planner gets a fresh physics seeded with
    /// `seed`, so its results do not depend on which planners ran before it.
    pub(crate) fn start(
        in_process: bool,
        scenario_arg: &str,
        scenario: &'a Scenario,
        ag: Option<&Path>,
        planner: PlannerKind,
        seed: u64,
    ) -> Result<Self> {
        let ag = ag.filter(|_| planner.needs_gradient());
        if in_process {
            let ag = ag
                .map(|p| {
                    AffordanceGradient::load_for(p, &scenario.name).with_context(|| {
                        format!("cannot load the affordance gradient `{}`", p.display())
                    })
                })
                .transpose()?;
            Ok(Self::InProcess {
                scenario,
                robot: RobotDescription::epuck(),
                ag,
            })
        } else {
            Ok(Self::Pipeline(PipelineBench::start(
                scenario_arg,
                ag,
                seed,
                // Instance names are short (iceoryx2's socket paths): three letters tell
                // the planners apart.
                planner.name().get(..3).unwrap_or(planner.name()),
            )?))
        }
    }

    pub(crate) fn episode(
        &mut self,
        planner: PlannerKind,
        task: &Task,
        config: &EpisodeConfig,
    ) -> Result<EpisodeResult> {
        match self {
            Self::InProcess {
                scenario,
                robot,
                ag,
            } => Ok(run_episode(
                scenario,
                robot,
                ag.as_ref(),
                planner,
                task,
                config,
            )?),
            Self::Pipeline(bench) => bench.episode(planner, task, config),
        }
    }

    pub(crate) fn finish(self) -> Result<()> {
        match self {
            Self::InProcess { .. } => Ok(()),
            Self::Pipeline(bench) => {
                if bench.truth_gaps > 0 {
                    eprintln!(
                        "note: the evaluation missed {} ground-truth samples (its buffer overflowed); the recorded paths have gaps there",
                        bench.truth_gaps
                    );
                }
                bench.stop()
            }
        }
    }
}

/// The progress bar's label for planners that run side by side.
pub(crate) fn prefix_of(planners: &[PlannerKind]) -> String {
    planners
        .iter()
        .map(|p| p.name())
        .collect::<Vec<_>>()
        .join("+")
}

/// The evaluation of an episode both runners judged.
pub(crate) fn judged(r: &EpisodeResult) -> &Evaluation {
    r.evaluation
        .as_ref()
        .expect("both runners judge every episode against ground truth")
}

/// The JSON's `physics` field.
pub(crate) fn physics_label(in_process: bool) -> &'static str {
    if in_process { "in-process" } else { "pipeline" }
}

pub(crate) fn physics_note(in_process: bool) -> &'static str {
    if in_process {
        IN_PROCESS_NOTE
    } else {
        PIPELINE_NOTE
    }
}

pub(crate) fn progress(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    if let Ok(style) =
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} episodes {elapsed}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

pub(crate) fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value).context("cannot serialise the result")?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write `{}`", path.display()))
}

/// Runs `agp bench place`.
pub fn run_place(args: &BenchPlaceArgs) -> Result<serde_json::Value> {
    let wall = Instant::now();
    if args.episodes == 0 {
        bail!("`--episodes` must be at least 1");
    }
    if args.planners.is_empty() {
        bail!("`--planners` names no planner");
    }
    let scenario = Scenario::resolve(&args.scenario)
        .with_context(|| format!("cannot load scenario `{}`", args.scenario))?;
    let ag = resolve_ag(
        args.ag.as_deref(),
        &args.scenario,
        &scenario,
        &args.planners,
    )?;
    let note = physics_note(args.in_process);
    let seed = args.seed.unwrap_or(scenario.task.seed);
    let mut planners = args.planners.clone();
    planners.sort();
    planners.dedup();
    let base = EpisodeConfig::for_task(&scenario.task);
    let goals = place_goals(&scenario, args.episodes, seed);

    eprintln!(
        "bench place: scenario `{}`, {} episodes per planner, seed {seed}; {note}",
        scenario.name, args.episodes
    );
    if planners.contains(&PlannerKind::Oracle) {
        eprintln!("{ORACLE_NOTE}");
    }
    let bar = progress((goals.len() * planners.len()) as u64);
    bar.set_prefix(prefix_of(&planners));
    let runs = side_by_side(&planners, |&planner| {
        let mut runner = Runner::start(
            args.in_process,
            &args.scenario,
            &scenario,
            ag.as_deref(),
            planner,
            seed,
        )?;
        let mut runs = Vec::with_capacity(goals.len());
        let episodes = (|| -> Result<()> {
            for (k, goal) in goals.iter().enumerate() {
                let config = EpisodeConfig {
                    seed: seed.wrapping_add(k as u64),
                    ..base.clone()
                };
                let r = runner
                    .episode(planner, &Task::Place { goal: *goal }, &config)
                    .with_context(|| format!("planner `{planner}`, episode {k}"))?;
                runs.push(r);
                bar.inc(1);
            }
            Ok(())
        })();
        // Stopped and cleaned up whatever happened: a failed episode leaves no file.
        let finished = runner.finish();
        episodes?;
        finished?;
        Ok(runs)
    })
    .into_iter()
    .collect::<Result<Vec<_>>>()?;
    let results: BTreeMap<PlannerKind, Vec<EpisodeResult>> =
        planners.iter().copied().zip(runs).collect();
    bar.finish_and_clear();
    let wall_time_s = wall.elapsed().as_secs_f64();

    println!(
        "place `{}`: {} episodes per planner, seed {seed}, tolerance {:.0} mm / {:.0} deg; {note}",
        scenario.name,
        args.episodes,
        base.tolerance_m * 1e3,
        base.tolerance_rad.to_degrees()
    );
    println!(
        "{:<12} {:>8} {:>8} {:>12} {:>12} {:>8} {:>10} {:>8}",
        "planner", "episodes", "success", "pos err mm", "ori err deg", "pushes", "sim s", "wall s"
    );
    let mut json_planners = BTreeMap::new();
    for (planner, runs) in &results {
        let s = PlannerSummary::of(runs);
        let label = if planner.reads_ground_truth() {
            format!("{planner} (GT)")
        } else {
            planner.name().to_owned()
        };
        println!(
            "{:<12} {:>8} {:>7.0}% {:>12.1} {:>12.1} {:>8.1} {:>10.0} {:>8.1}",
            label,
            s.episodes,
            100.0 * s.success_rate,
            s.median_position_error_mm,
            s.median_orientation_error_deg,
            s.median_pushes,
            s.sim_time_s,
            s.wall_time_s
        );
        json_planners.insert(
            planner.name().to_owned(),
            PlacePlannerJson {
                episodes: s.episodes,
                success_rate: s.success_rate,
                median_position_error_mm: s.median_position_error_mm,
                median_orientation_error_deg: s.median_orientation_error_deg,
                median_pushes: s.median_pushes,
                sim_time_s: s.sim_time_s,
                wall_time_s: s.wall_time_s,
                reads_ground_truth: planner.reads_ground_truth(),
                runs: runs
                    .iter()
                    .zip(&goals)
                    .map(|(r, g)| PlaceEpisodeJson {
                        goal_x_mm: g.x * 1e3,
                        goal_y_mm: g.y * 1e3,
                        goal_theta_deg: g.theta.to_degrees(),
                        success: r.success(),
                        end: r.end.name(),
                        position_error_mm: judged(r).position_error_mm,
                        orientation_error_deg: judged(r).orientation_error_deg,
                        pushes: r.pushes,
                        circlings: r.circlings,
                        sim_time_s: r.sim_time_s,
                        wall_time_s: r.wall_time_s,
                        estimate: r.estimate_verdict,
                    })
                    .collect(),
            },
        );
    }
    if results.contains_key(&PlannerKind::Oracle) {
        println!("(GT) {ORACLE_NOTE}");
    }
    println!("wall time {wall_time_s:.1} s");
    let doc = serde_json::to_value(PlaceJson {
        benchmark: "place",
        scenario: scenario.name.clone(),
        seed,
        physics: physics_label(args.in_process),
        tolerance_mm: base.tolerance_m * 1e3,
        tolerance_deg: base.tolerance_rad.to_degrees(),
        planners: json_planners,
        wall_time_s,
    })
    .context("cannot encode the result")?;
    if let Some(path) = &args.json {
        write_json(path, &doc)?;
        println!("JSON     {}", path.display());
    }
    if let Some(path) = &args.plot {
        let panels: Vec<Panel> = results
            .iter()
            .filter_map(|(planner, runs)| {
                let r = runs.first()?;
                Some(Panel {
                    title: format!(
                        "{}{}: {} in {} pushes, {:.1} mm / {:.1} deg",
                        planner,
                        if planner.reads_ground_truth() {
                            " (ground truth)"
                        } else {
                            ""
                        },
                        if r.success() { "placed" } else { "not placed" },
                        r.pushes,
                        judged(r).position_error_mm,
                        judged(r).orientation_error_deg
                    ),
                    samples: &judged(r).samples,
                })
            })
            .collect();
        let goal = goals[0];
        let title = format!(
            "place `{}`: first episode per planner, goal outline in red ({note})",
            scenario.name
        );
        plot_runs(
            path,
            &title,
            &scenario.object.shape,
            &panels,
            Overlay::Goal(goal),
        )?;
        println!("plot     {}", path.display());
    }
    Ok(doc)
}

/// One panel of a plot: a run's recorded poses.
pub(crate) struct Panel<'a> {
    pub title: String,
    pub samples: &'a [PoseSample],
}

/// What is drawn under every panel in red.
pub(crate) enum Overlay<'a> {
    Goal(Pose2),
    Path(&'a [DVec2]),
}

/// The object's outline at `pose`, mm, closed.
fn outline_mm(shape: &ObjectShape, pose: Pose2) -> Vec<(f64, f64)> {
    let rot = DVec2::from_angle(pose.theta);
    let c = DVec2::new(pose.x, pose.y);
    let local: Vec<DVec2> = match shape {
        ObjectShape::Polygon(p) => p.vertices().to_vec(),
        ObjectShape::Circle { radius } => (0..36)
            .map(|k| *radius * DVec2::from_angle(f64::from(k) * std::f64::consts::TAU / 36.0))
            .collect(),
    };
    let mut out: Vec<(f64, f64)> = local
        .iter()
        .map(|v| {
            let w = c + rot.rotate(*v);
            (w.x * 1e3, w.y * 1e3)
        })
        .collect();
    if let Some(&first) = out.first() {
        out.push(first);
    }
    out
}

fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("cannot draw the plot: {e}")
}

/// Draws the panels side by side: under each the overlay in red, the centroid's path in
/// blue and the object's outline every few recorded poses (at most about 40 per panel).
pub(crate) fn plot_runs(
    path: &Path,
    title: &str,
    shape: &ObjectShape,
    panels: &[Panel<'_>],
    overlay: Overlay<'_>,
) -> Result<()> {
    const PANEL_PX: u32 = 560;
    if panels.is_empty() {
        bail!("nothing to plot");
    }
    // One square view for all panels: every pose, the overlay, and a margin.
    let mut xs: Vec<f64> = Vec::new();
    let mut ys: Vec<f64> = Vec::new();
    for p in panels {
        for s in p.samples {
            xs.push(s.pose.x * 1e3);
            ys.push(s.pose.y * 1e3);
        }
    }
    match &overlay {
        Overlay::Goal(g) => {
            xs.push(g.x * 1e3);
            ys.push(g.y * 1e3);
        }
        Overlay::Path(points) => {
            for p in *points {
                xs.push(p.x * 1e3);
                ys.push(p.y * 1e3);
            }
        }
    }
    let margin = shape.radius() * 1e3 + 20.0;
    let fold = |v: &[f64], f: fn(f64, f64) -> f64, init: f64| v.iter().copied().fold(init, f);
    let (x0, x1) = (
        fold(&xs, f64::min, f64::INFINITY),
        fold(&xs, f64::max, f64::NEG_INFINITY),
    );
    let (y0, y1) = (
        fold(&ys, f64::min, f64::INFINITY),
        fold(&ys, f64::max, f64::NEG_INFINITY),
    );
    let half = 0.5 * (x1 - x0).max(y1 - y0) + margin;
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let x_range = (cx - half)..(cx + half);
    let y_range = (cy - half)..(cy + half);

    let width = PANEL_PX * panels.len() as u32;
    let height = PANEL_PX + 40;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error)?;
        let (head, body) = root.split_vertically(40);
        head.draw(&Text::new(
            title.to_owned(),
            (10, 12),
            ("sans-serif", 15).into_font(),
        ))
        .map_err(plot_error)?;
        let areas: Vec<DrawingArea<SVGBackend<'_>, Shift>> = body.split_evenly((1, panels.len()));
        for (area, panel) in areas.iter().zip(panels) {
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, ("sans-serif", 13))
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(45)
                .build_cartesian_2d(x_range.clone(), y_range.clone())
                .map_err(plot_error)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x (mm)")
                .y_desc("y (mm)")
                .label_style(("sans-serif", 11))
                .draw()
                .map_err(plot_error)?;
            let red = RGBColor(200, 30, 30);
            match &overlay {
                Overlay::Goal(g) => {
                    chart
                        .draw_series(std::iter::once(PathElement::new(
                            outline_mm(shape, *g),
                            red.stroke_width(2),
                        )))
                        .map_err(plot_error)?;
                }
                Overlay::Path(points) => {
                    let line: Vec<(f64, f64)> =
                        points.iter().map(|p| (p.x * 1e3, p.y * 1e3)).collect();
                    chart
                        .draw_series(std::iter::once(PathElement::new(line, red.stroke_width(2))))
                        .map_err(plot_error)?;
                }
            }
            let every = panel.samples.len().div_ceil(40).max(1);
            let grey = RGBColor(90, 90, 90);
            chart
                .draw_series(
                    panel
                        .samples
                        .iter()
                        .step_by(every)
                        .chain(panel.samples.last())
                        .map(|s| PathElement::new(outline_mm(shape, s.pose), grey.stroke_width(1))),
                )
                .map_err(plot_error)?;
            let centroid: Vec<(f64, f64)> = panel
                .samples
                .iter()
                .map(|s| (s.pose.x * 1e3, s.pose.y * 1e3))
                .collect();
            chart
                .draw_series(std::iter::once(PathElement::new(
                    centroid,
                    BLUE.stroke_width(1),
                )))
                .map_err(plot_error)?;
        }
        root.present().map_err(plot_error)?;
    }
    std::fs::write(path, svg).with_context(|| format!("cannot write `{}`", path.display()))
}
