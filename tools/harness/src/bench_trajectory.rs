//! `agp bench trajectory`: the paper's push along a path (benchmarks.md section 2) on a set
//! of paths (`task_goals::NamedPath`: a straight line, bends of 45 and 90 deg, an S-curve,
//! a circle arc), the affordance and the baseline planner on each path over the seeds, the
//! same seed for both, and beside them the `model` planner (a quasi-static pushing model
//! of the true object: it reads ground truth, and the tables say so).
//!
//! Every figure is built from one-seed documents: a run makes one per seed and merges them
//! with [`merge`], the function `agp bench merge` calls on the parts of a sharded run, so
//! the two cannot differ.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::bench_tasks::{
    EpisodePlan, judged, physics_label, physics_note, prefix_of, progress, resolve_ag, run_episodes,
};
use crate::seeds::{
    SeedArgs, SeedParts, Shard, Spread, finish_seed_doc, finite_or_null, mean_of, merge_parts,
    number_at, run_parts, seed_list, spread_at, write_json,
};
use crate::stop;
use crate::task_goals::{NamedPath, heading_share, path_length};
use crate::task_plot::{Overlay, Panel, plot_runs};
use crate::trajectory_error;
use agp_planning::{EpisodeConfig, EpisodeResult, PlannerKind, Task};
use agp_shared_types::{MAX_PATH_POINTS, Pose2};
use agp_world::{Scenario, TaskKind};
use anyhow::{Context, Result, bail};
use glam::DVec2;
use serde_json::{Map, Value, json};

/// The planners every trajectory run compares, in report order (`model` reads ground
/// truth: the classical method beside ours, see [`crate::bench_tasks::MODEL_NOTE`]).
const PLANNERS: [PlannerKind; 3] = [
    PlannerKind::Affordance,
    PlannerKind::Baseline,
    PlannerKind::Model,
];

/// The heading figure: the share of recorded points whose heading keeps to the path's
/// tangent within this, deg.
pub const HEADING_FIGURE_DEG: f64 = 15.0;

/// The options of `agp bench trajectory`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchTrajectoryArgs {
    /// Built-in scenario or a scenario file: the object pushed. The paths start at its
    /// object's start.
    #[arg(long, default_value = "lshape")]
    pub scenario: String,
    /// Paths to run, comma-separated: `straight` (600 mm along +x, through the centroid,
    /// the paper's line), `bend45` (300 mm, then 250 mm turned 45 deg left), `bend90` (300
    /// mm, then 250 mm turned 90 deg right), `s-curve` (500 mm on while moving 200 mm left),
    /// `arc` (radius 300 mm, 105 deg left), and `scenario` (the scenario's own `path_mm`,
    /// or its 600 mm line). Default: the five shapes, and `scenario` too when the scenario
    /// is a trajectory task (which always has its own `path_mm`).
    #[arg(long, value_delimiter = ',')]
    pub paths: Vec<NamedPath>,
    /// Affordance gradient file learned from IR (default: `results/learn/<object>.ag`,
    /// learned first with `agp bench learn` when missing).
    #[arg(long)]
    pub ag: Option<PathBuf>,
    /// Ask every path's task to keep the object's heading tangent to the path within this
    /// many degrees (the affordance planner weighs it in each push it chooses; the baseline
    /// cannot turn the object and ignores it). `heading_within_15_deg` reports how far
    /// each planner kept it. Default: the scenario's `keep_heading_deg`, else free.
    #[arg(long, value_name = "DEG", value_parser = heading_deg)]
    pub keep_heading: Option<f64>,
    #[command(flatten)]
    pub seeds: SeedArgs,
    /// Step the physics library in-process instead of running the pipeline's processes.
    #[arg(long)]
    pub in_process: bool,
    /// Also write the result as JSON to this file: per path and planner the mean error
    /// over the seeds with its spread, the ratio per path and overall, every episode in
    /// `per_seed`.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the first seed's runs of both planners, one row per path (the path, the
    /// object every few steps, as the paper's Fig. 6), to this SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

impl Default for BenchTrajectoryArgs {
    fn default() -> Self {
        Self {
            scenario: "lshape".into(),
            paths: Vec::new(),
            ag: None,
            keep_heading: None,
            seeds: SeedArgs::default(),
            in_process: false,
            json: None,
            plot: None,
        }
    }
}

/// A heading tolerance in degrees, in (0, 180].
fn heading_deg(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a number of degrees"))?;
    if v > 0.0 && v <= 180.0 {
        Ok(v)
    } else {
        Err(format!(
            "a heading tolerance is in (0, 180] degrees, got {v}"
        ))
    }
}

/// The paths `--paths` names, or the default set (see [`BenchTrajectoryArgs::paths`]),
/// each once, in the order given.
fn chosen_paths(args: &BenchTrajectoryArgs, scenario: &Scenario) -> Vec<NamedPath> {
    let mut chosen = if args.paths.is_empty() {
        let mut all = NamedPath::SET.to_vec();
        if scenario.task.kind == TaskKind::Trajectory {
            all.push(NamedPath::Scenario);
        }
        all
    } else {
        args.paths.clone()
    };
    let mut seen = Vec::new();
    chosen.retain(|p| {
        let new = !seen.contains(p);
        seen.push(*p);
        new
    });
    chosen
}

/// One episode as the JSON holds it.
fn episode_json(path: &[DVec2], r: &EpisodeResult) -> Value {
    let e = judged(r);
    let poses: Vec<Pose2> = e.samples.iter().map(|s| s.pose).collect();
    let error_mm = trajectory_error(path, &poses).map_or(f64::NAN, |v| v * 1e3);
    // The L has no symmetry; the heading is the orientation's, as the planner sees it.
    let heading = heading_share(path, &poses, 1, HEADING_FIGURE_DEG.to_radians());
    json!({
        "mean_error_mm": finite_or_null(error_mm),
        "points": e.samples.len(),
        "reached_end": r.success(),
        "end": r.end.name(),
        "final_distance_to_end_mm": e.position_error_mm,
        "heading_within_15_deg": heading.map_or(Value::Null, |h| json!(h)),
        "pushes": r.pushes,
        "circlings": r.circlings,
        "sim_time_s": r.sim_time_s,
        "wall_time_s": r.wall_time_s,
        "estimate": r.estimate_verdict,
    })
}

/// What must be alike in every seed of one run.
fn trajectory_signature(doc: &Value) -> Value {
    let paths: Map<String, Value> = doc["paths"]
        .as_object()
        .map(|m| {
            m.iter()
                .map(|(k, p)| {
                    let planners: Vec<String> = p["planners"]
                        .as_object()
                        .map(|q| q.keys().cloned().collect())
                        .unwrap_or_default();
                    (
                        k.clone(),
                        json!({"path_mm": p["path_mm"], "planners": planners}),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    json!({
        "scenario": doc["scenario"],
        "physics": doc["physics"],
        "keep_heading_deg": doc["keep_heading_deg"],
        "paths": paths,
    })
}

/// The trajectory document of `parts`: per path and planner the mean error over the seeds
/// with its spread and the ratio; per planner the mean over every path and seed and the
/// overall ratio; `seeds`, `per_seed` (and `shard`). Its `wall_time_s` is the longest
/// seed's; the caller sets the run's own.
fn assemble(parts: &SeedParts, shard: Option<Shard>) -> Value {
    let docs: Vec<&Value> = parts.docs().collect();
    let first = docs[0];
    let names: Vec<String> = first["paths"]
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    let planners: Vec<String> = first["planners"]
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    let mut paths = Map::new();
    for name in &names {
        let def = &first["paths"][name];
        let mut per_planner = Map::new();
        for p in &planners {
            let at = |key: &str| -> Vec<f64> {
                docs.iter()
                    .map(|d| number_at(d, &["paths", name, "planners", p, key]))
                    .collect()
            };
            let reached: Vec<f64> = docs
                .iter()
                .map(|d| {
                    if d["paths"][name]["planners"][p]["reached_end"] == true {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect();
            per_planner.insert(
                p.clone(),
                json!({
                    "mean_error_mm": finite_or_null(mean_of(&at("mean_error_mm"))),
                    "spread": spread_at(docs.iter().copied(), &["paths", name, "planners", p, "mean_error_mm"]),
                    "reached_end_rate": mean_of(&reached),
                    "heading_within_15_deg": finite_or_null(mean_of(&at("heading_within_15_deg"))),
                    "pushes": finite_or_null(mean_of(&at("pushes"))),
                }),
            );
        }
        let ratio = number_at(
            &Value::Object(per_planner.clone()),
            &["affordance", "mean_error_mm"],
        ) / number_at(
            &Value::Object(per_planner.clone()),
            &["baseline", "mean_error_mm"],
        );
        paths.insert(
            name.clone(),
            json!({
                "path_mm": def["path_mm"],
                "length_mm": def["length_mm"],
                "planners": per_planner,
                "ratio": finite_or_null(ratio),
            }),
        );
    }
    let mut overall = Map::new();
    for p in &planners {
        let per_seed: Vec<f64> = docs
            .iter()
            .map(|d| number_at(d, &["planners", p, "mean_error_mm"]))
            .collect();
        overall.insert(
            p.clone(),
            json!({
                "mean_error_mm": finite_or_null(mean_of(&per_seed)),
                "spread": spread_at(docs.iter().copied(), &["planners", p, "mean_error_mm"]),
            }),
        );
    }
    let overall_value = Value::Object(overall.clone());
    let ratio = number_at(&overall_value, &["affordance", "mean_error_mm"])
        / number_at(&overall_value, &["baseline", "mean_error_mm"]);
    let mut doc = Map::new();
    doc.insert("benchmark".into(), json!("trajectory"));
    doc.insert("scenario".into(), first["scenario"].clone());
    doc.insert("seed".into(), first["seed"].clone());
    doc.insert("physics".into(), first["physics"].clone());
    doc.insert("keep_heading_deg".into(), first["keep_heading_deg"].clone());
    doc.insert("planners".into(), overall_value);
    doc.insert("ratio".into(), finite_or_null(ratio));
    doc.insert("paths".into(), Value::Object(paths));
    finish_seed_doc(doc, parts, shard)
}

/// Merges trajectory documents of disjoint seed sets (whole runs, shards' parts, one-seed
/// documents) into the document one run over all their seeds writes, but for
/// `wall_time_s`: the longest part's.
pub fn merge(parts: &[Value]) -> Result<Value> {
    Ok(merge_parts(
        parts,
        "trajectory",
        trajectory_signature,
        assemble,
    )?)
}

/// The human table of a trajectory document: per path each planner's mean error, mean
/// (min-max) over the seeds, and the ratio; then the overall figures.
pub fn print_trajectory(doc: &Value, order: &[String], note: &str) {
    let lists = crate::seeds::SeedLists::of(doc);
    let own = &lists.own;
    println!(
        "trajectory `{}`: {}; {note}",
        doc["scenario"].as_str().unwrap_or("?"),
        lists.describe(),
    );
    println!(
        "mean distance of the centroid to the path per recorded point, mm{}; ends reached",
        if own.len() > 1 {
            ": mean (min-max) over the seeds"
        } else {
            ""
        }
    );
    let w = if own.len() > 1 { 20 } else { 10 };
    println!(
        "{:<10} {:>8} {:>w$} {:>6} {:>w$} {:>6} {:>6} {:>w$} {:>6}",
        "path", "length", "affordance", "ends", "baseline", "ends", "ratio", "model (GT)", "ends"
    );
    let cell = |p: &Value| -> String {
        serde_json::from_value::<Spread>(p["spread"].clone())
            .map_or_else(|_| "-".to_owned(), |s| s.show(2))
    };
    // The model's column, `-` in a document without it.
    let model_ends = |p: &Value| -> String {
        p.get("reached_end_rate")
            .and_then(Value::as_f64)
            .map_or_else(|| "-".to_owned(), |r| format!("{:.0}%", 100.0 * r))
    };
    for name in order {
        let path = &doc["paths"][name];
        let a = &path["planners"]["affordance"];
        let b = &path["planners"]["baseline"];
        let m = &path["planners"]["model"];
        println!(
            "{:<10} {:>5.0} mm {:>w$} {:>5.0}% {:>w$} {:>5.0}% {:>6.2} {:>w$} {:>6}",
            name,
            number_at(path, &["length_mm"]),
            cell(a),
            100.0 * number_at(a, &["reached_end_rate"]),
            cell(b),
            100.0 * number_at(b, &["reached_end_rate"]),
            number_at(path, &["ratio"]),
            cell(m),
            model_ends(m),
        );
    }
    println!(
        "{:<10} {:>8} {:>w$} {:>6} {:>w$} {:>6} {:>6.2} {:>w$}",
        "overall",
        "",
        cell(&doc["planners"]["affordance"]),
        "",
        cell(&doc["planners"]["baseline"]),
        "",
        number_at(doc, &["ratio"]),
        cell(&doc["planners"]["model"]),
    );
    println!("ratio affordance / baseline (paper, one straight line: 7.82 / 10.71 = 0.73)");
    if doc["planners"].get("model").is_some() {
        println!("(GT) {}", crate::bench_tasks::MODEL_NOTE);
    }
}

/// Runs `agp bench trajectory`: both planners on every chosen path over the seeds.
pub fn run_trajectory(args: &BenchTrajectoryArgs) -> Result<Value> {
    let wall = Instant::now();
    let scenario = Scenario::resolve(&args.scenario)
        .with_context(|| format!("cannot load scenario `{}`", args.scenario))?;
    let chosen = chosen_paths(args, &scenario);
    let paths = path_points(&chosen, &scenario)?;
    let ag = resolve_ag(args.ag.as_deref(), &args.scenario, &scenario, &PLANNERS)?;
    // From here on the episode loops poll the stop flag.
    let _checked = stop::checked();
    let note = physics_note(args.in_process);
    let all_seeds = args.seeds.all();
    let seeds = args.seeds.mine();
    let base = EpisodeConfig::for_task(&scenario.task);
    let keep_heading_rad = args
        .keep_heading
        .map(f64::to_radians)
        .or(scenario.task.keep_heading_rad);
    eprintln!(
        "bench trajectory: scenario `{}`, paths {}, seeds {}{}; {note}",
        scenario.name,
        chosen
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
            .join(", "),
        seed_list(&seeds),
        args.seeds.shard_note()
    );

    let work: Vec<(u64, PlannerKind)> = seeds
        .iter()
        .flat_map(|&seed| PLANNERS.iter().map(move |&p| (seed, p)))
        .collect();
    let bar = progress((paths.len() * work.len()) as u64);
    bar.set_prefix(prefix_of(&PLANNERS));
    let plan = EpisodePlan {
        benchmark: "trajectory",
        in_process: args.in_process,
        scenario_arg: &args.scenario,
        scenario: &scenario,
        ag: ag.as_deref(),
        several_seeds: seeds.len() > 1,
        online: false,
        bar: &bar,
    };
    let planned = paths.len() * work.len();
    let docs = SeedDocs {
        scenario: &scenario.name,
        seeds: &seeds,
        in_process: args.in_process,
        keep_heading_rad,
        paths: &paths,
    };
    // What finished, seeds of fewer paths included: the checkpoints and a stop's JSON.
    let partial_doc = |runs: &[(&[EpisodeResult], f64)]| -> Result<Value> {
        let parts = run_parts(
            &docs.of(runs),
            "trajectory",
            |_| Value::Null,
            all_seeds.clone(),
        )?;
        let mut doc = assemble(&parts, args.seeds.shard);
        doc["wall_time_s"] = json!(wall.elapsed().as_secs_f64());
        Ok(doc)
    };
    let runs = run_episodes(
        &plan,
        &work,
        |seed| {
            paths
                .iter()
                .map(|(name, points)| {
                    // Each path's episode draws the seed's noise afresh, the same for both
                    // planners.
                    let config = EpisodeConfig {
                        seed,
                        ..base.clone()
                    };
                    let task = Task::Trajectory {
                        path: points.clone(),
                        keep_heading_rad,
                    };
                    (format!("path `{name}`"), task, config)
                })
                .collect()
        },
        |runs, finished| {
            if let Ok(doc) = partial_doc(runs) {
                stop::checkpoint(doc, args.json.as_deref(), "trajectory", finished, planned);
            }
        },
    )?;
    bar.finish_and_clear();
    let runs: Vec<(&[EpisodeResult], f64)> = runs
        .iter()
        .map(|r| (r.results.as_slice(), r.wall_s))
        .collect();
    let finished: usize = runs.iter().map(|(r, _)| r.len()).sum();
    if stop::requested() {
        let doc = partial_doc(&runs)?;
        return Err(stop::write_partial(
            doc,
            args.json.as_deref(),
            "trajectory",
            finished,
            planned,
        ));
    }
    stop::end_checkpoints(args.json.as_deref(), "trajectory");
    let first_seed_runs: BTreeMap<PlannerKind, Vec<EpisodeResult>> = PLANNERS
        .iter()
        .zip(&runs)
        .map(|(&p, &(r, _))| (p, r.to_vec()))
        .collect();
    let parts = run_parts(
        &docs.of(&runs),
        "trajectory",
        trajectory_signature,
        all_seeds,
    )?;
    let mut doc = assemble(&parts, args.seeds.shard);
    let wall_time_s = wall.elapsed().as_secs_f64();
    doc["wall_time_s"] = json!(wall_time_s);
    let order: Vec<String> = chosen.iter().map(|p| p.name().to_owned()).collect();
    print_trajectory(&doc, &order, note);
    println!("wall time {wall_time_s:.1} s");
    if let Some(file) = &args.json {
        write_json(file, &doc)?;
        println!("JSON     {}", file.display());
    }
    if let Some(file) = &args.plot {
        plot_paths(file, &scenario, &paths, &first_seed_runs, seeds[0], note)?;
        println!("plot     {}", file.display());
    }
    Ok(doc)
}

/// The points of each chosen path on `scenario`; refuses a path of fewer than 2 or more
/// than `MAX_PATH_POINTS` points.
fn path_points(chosen: &[NamedPath], scenario: &Scenario) -> Result<Vec<(NamedPath, Vec<DVec2>)>> {
    let paths: Vec<(NamedPath, Vec<DVec2>)> =
        chosen.iter().map(|&p| (p, p.points(scenario))).collect();
    for (name, points) in &paths {
        if !(2..=MAX_PATH_POINTS).contains(&points.len()) {
            bail!(
                "path `{name}` has {} points; a trajectory takes 2 to {MAX_PATH_POINTS}",
                points.len()
            );
        }
    }
    Ok(paths)
}

/// What the one-seed documents of a trajectory run are made of, beside its episodes.
struct SeedDocs<'a> {
    scenario: &'a str,
    /// This run's own seeds, in order.
    seeds: &'a [u64],
    in_process: bool,
    keep_heading_rad: Option<f64>,
    paths: &'a [(NamedPath, Vec<DVec2>)],
}

impl SeedDocs<'_> {
    /// The one-seed documents of `runs` (the (seed, planner) pairs of the run in order,
    /// every planner of a seed in a row, each with the paths it finished).
    fn of(&self, runs: &[(&[EpisodeResult], f64)]) -> Vec<Value> {
        self.seeds
            .iter()
            .zip(runs.chunks(PLANNERS.len()))
            .map(|(&seed, pairs)| {
                let mut per_path: Vec<Map<String, Value>> = vec![Map::new(); self.paths.len()];
                let mut wall_s: f64 = 0.0;
                for (&planner, &(results, planner_wall_s)) in PLANNERS.iter().zip(pairs) {
                    wall_s = wall_s.max(planner_wall_s);
                    for ((slot, (_, points)), r) in per_path.iter_mut().zip(self.paths).zip(results)
                    {
                        slot.insert(planner.name().to_owned(), episode_json(points, r));
                    }
                }
                one_seed_doc(
                    self.scenario,
                    seed,
                    self.in_process,
                    self.keep_heading_rad,
                    self.paths,
                    per_path,
                    wall_s,
                )
            })
            .collect()
    }
}

/// The document of one seed: per path both planners' episodes and the ratio; per planner
/// the mean error over the paths.
fn one_seed_doc(
    scenario: &str,
    seed: u64,
    in_process: bool,
    keep_heading_rad: Option<f64>,
    paths: &[(NamedPath, Vec<DVec2>)],
    per_path: Vec<Map<String, Value>>,
    wall_s: f64,
) -> Value {
    let mut paths_json = Map::new();
    for ((name, points), planners) in paths.iter().zip(per_path) {
        let planners = Value::Object(planners);
        let ratio = number_at(&planners, &["affordance", "mean_error_mm"])
            / number_at(&planners, &["baseline", "mean_error_mm"]);
        paths_json.insert(
            name.name().to_owned(),
            json!({
                "path_mm": points.iter().map(|p| [p.x * 1e3, p.y * 1e3]).collect::<Vec<_>>(),
                "length_mm": path_length(points) * 1e3,
                "planners": planners,
                "ratio": finite_or_null(ratio),
            }),
        );
    }
    let paths_value = Value::Object(paths_json);
    let mut planners = Map::new();
    for planner in PLANNERS {
        let errors: Vec<f64> = paths
            .iter()
            .map(|(name, _)| {
                number_at(
                    &paths_value,
                    &[name.name(), "planners", planner.name(), "mean_error_mm"],
                )
            })
            .collect();
        planners.insert(
            planner.name().to_owned(),
            json!({ "mean_error_mm": finite_or_null(mean_of(&errors)) }),
        );
    }
    let planners = Value::Object(planners);
    let ratio = number_at(&planners, &["affordance", "mean_error_mm"])
        / number_at(&planners, &["baseline", "mean_error_mm"]);
    json!({
        "benchmark": "trajectory",
        "scenario": scenario,
        "seed": seed,
        "physics": physics_label(in_process),
        // To the micro-degree: what was asked, not its round trip through radians.
        "keep_heading_deg": keep_heading_rad.map(|h| (h.to_degrees() * 1e6).round() / 1e6),
        "planners": planners,
        "ratio": finite_or_null(ratio),
        "paths": paths_value,
        "wall_time_s": wall_s,
    })
}

/// One SVG with a row per path, each row both planners' runs of `seed` side by side.
fn plot_paths(
    file: &Path,
    scenario: &Scenario,
    paths: &[(NamedPath, Vec<DVec2>)],
    runs: &BTreeMap<PlannerKind, Vec<EpisodeResult>>,
    seed: u64,
    note: &str,
) -> Result<()> {
    let dir = tempfile::tempdir().context("cannot create a folder for the plot's rows")?;
    let mut rows = Vec::with_capacity(paths.len());
    for (k, (name, points)) in paths.iter().enumerate() {
        let panels: Vec<Panel> = runs
            .iter()
            .filter_map(|(planner, results)| {
                let r = results.get(k)?;
                let poses: Vec<Pose2> = judged(r).samples.iter().map(|s| s.pose).collect();
                let e = trajectory_error(points, &poses).map_or(f64::NAN, |v| v * 1e3);
                Some(Panel {
                    title: format!("{planner}: mean error {e:.2} mm per point"),
                    samples: &judged(r).samples,
                })
            })
            .collect();
        let row = dir.path().join(format!("row-{k}.svg"));
        let title = format!(
            "trajectory `{}`, path `{name}`, seed {seed}: path in red, object every few steps ({note})",
            scenario.name
        );
        plot_runs(
            &row,
            &title,
            &scenario.object.shape,
            &panels,
            Overlay::Path(points),
        )?;
        rows.push(
            std::fs::read_to_string(&row)
                .with_context(|| format!("cannot read the plot's row `{}`", row.display()))?,
        );
    }
    let svg = stack_rows(&rows)?;
    std::fs::write(file, svg).with_context(|| format!("cannot write `{}`", file.display()))
}

/// SVG documents stacked top to bottom into one.
fn stack_rows(rows: &[String]) -> Result<String> {
    let size = |svg: &str, key: &str| -> Option<f64> {
        let head = &svg[svg.find("<svg")?..];
        let head = &head[..head.find('>')?];
        let at = head.find(&format!(" {key}=\""))? + key.len() + 3;
        head[at..].split('"').next()?.parse().ok()
    };
    let mut body = String::new();
    let (mut width, mut y) = (0.0f64, 0.0f64);
    for row in rows {
        let (Some(w), Some(h)) = (size(row, "width"), size(row, "height")) else {
            bail!("cannot stack the plot's rows: a row without its size");
        };
        let start = row.find("<svg").unwrap_or(0);
        body.push_str(&format!(
            "<g transform=\"translate(0,{y})\">\n{}\n</g>\n",
            &row[start..]
        ));
        width = width.max(w);
        y += h;
    }
    Ok(format!(
        "<svg width=\"{width}\" height=\"{y}\" viewBox=\"0 0 {width} {y}\" xmlns=\"http://www.w3.org/2000/svg\">\n{body}</svg>\n"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-seed document as a run writes it, with made-up errors.
    fn doc_of(seed: u64, errors: &[(&str, f64, f64)]) -> Value {
        let scenario = Scenario::builtin("lshape").expect("built-in");
        let paths: Vec<(NamedPath, Vec<DVec2>)> = errors
            .iter()
            .map(|(n, _, _)| {
                let p: NamedPath = n.parse().expect("a path name");
                (p, p.points(&scenario))
            })
            .collect();
        let per_path = errors
            .iter()
            .map(|(_, a, b)| {
                let mut m = Map::new();
                m.insert(
                    "affordance".into(),
                    json!({"mean_error_mm": a, "reached_end": true}),
                );
                m.insert(
                    "baseline".into(),
                    json!({"mean_error_mm": b, "reached_end": false}),
                );
                m
            })
            .collect();
        one_seed_doc("lshape", seed, false, None, &paths, per_path, 1.0)
    }

    #[test]
    fn a_merge_of_one_seed_documents_is_the_run_over_their_union() {
        let a = doc_of(100, &[("straight", 1.0, 2.0), ("bend90", 3.0, 5.0)]);
        let b = doc_of(101, &[("straight", 2.0, 4.0), ("bend90", 5.0, 5.0)]);
        let c = doc_of(102, &[("straight", 3.0, 3.0), ("bend90", 1.0, 2.0)]);
        let whole = merge(&[a.clone(), b.clone(), c.clone()]).expect("merge");
        // Merged in any grouping, the same document.
        let ab = merge(&[b.clone(), a.clone()]).expect("merge");
        assert_eq!(merge(&[ab, c]).expect("merge"), whole);
        assert_eq!(whole["seeds"], json!([100, 101, 102]));
        assert_eq!(whole["seed"], json!(100));
        // straight: affordance 2, baseline 3; bend90: 3 and 4; overall 2.5 and 3.5.
        let at = |p: &[&str]| number_at(&whole, p);
        assert!(
            (at(&[
                "paths",
                "straight",
                "planners",
                "affordance",
                "mean_error_mm"
            ]) - 2.0)
                .abs()
                < 1e-12
        );
        assert!((at(&["paths", "bend90", "ratio"]) - 0.75).abs() < 1e-12);
        assert!((at(&["planners", "affordance", "mean_error_mm"]) - 2.5).abs() < 1e-12);
        assert!((at(&["ratio"]) - 2.5 / 3.5).abs() < 1e-12);
        assert_eq!(
            at(&[
                "paths",
                "bend90",
                "planners",
                "affordance",
                "reached_end_rate"
            ]),
            1.0
        );
        assert_eq!(
            at(&[
                "paths",
                "bend90",
                "planners",
                "baseline",
                "reached_end_rate"
            ]),
            0.0
        );
    }

    #[test]
    fn a_merge_refuses_a_seed_twice_and_a_part_of_other_paths() {
        let a = doc_of(100, &[("straight", 1.0, 2.0)]);
        assert!(merge(&[a.clone(), a.clone()]).is_err());
        let other = doc_of(101, &[("arc", 1.0, 2.0)]);
        assert!(merge(&[a, other]).is_err());
    }

    #[test]
    fn stacked_rows_keep_each_row_below_the_last() {
        let row = |w: u32, h: u32| {
            format!(
                "<?xml version=\"1.0\"?>\n<svg width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\"><rect/></svg>\n"
            )
        };
        let svg = stack_rows(&[row(100, 50), row(80, 30)]).expect("stacked");
        assert!(svg.starts_with("<svg width=\"100\" height=\"80\""), "{svg}");
        assert!(svg.contains("translate(0,50)"), "{svg}");
        assert!(!svg.contains("<?xml"), "{svg}");
    }
}
