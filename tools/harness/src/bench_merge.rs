//! `agp bench merge`: the partial JSONs of a run split with `--shard I/N` (or any documents
//! of one benchmark over disjoint seeds) merged into the JSON one run over all their seeds
//! writes. Each benchmark merges its own documents (`bench_learn::merge`,
//! `bench_tasks::merge`, `bench_trajectory::merge`, `bench_paper::merge`,
//! `bench_adapt::merge`); this module reads
//! the files, checks that they are parts of one run, and names the file at fault.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde_json::Value;

use crate::bench_tasks::{physics_note, print_place};
use crate::seeds::write_json;
use crate::seeds::{MergePartError, number_at, seed_list};
use crate::{bench_adapt, bench_learn, bench_paper, bench_tasks, bench_trajectory};

/// The options of `agp bench merge`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchMergeArgs {
    /// The parts: JSON files written by `agp bench <benchmark> --shard I/N --json FILE`
    /// (or by runs over disjoint seeds), of one benchmark and one run.
    #[arg(value_name = "PART.json", required = true)]
    pub parts: Vec<PathBuf>,
    /// Where to write the merged JSON: what one run over every seed writes.
    #[arg(long, value_name = "FILE")]
    pub json: PathBuf,
    /// Also draw each seed's figures per planner (the spread over the seeds) to this SVG.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Merge parts marked `"partial": true` too (a bench stopped by a signal, or its
    /// checkpoint): refused otherwise, since their figures cover fewer episodes. The merged
    /// JSON is then marked partial as well.
    #[arg(long)]
    pub allow_partial: bool,
}

/// Reads a part, a one-line error naming the file when it is not a JSON object.
fn read_part(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("`{}`: cannot read the part", path.display()))?;
    let v: Value = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("`{}`: not JSON ({e})", path.display()))?;
    if !v.is_object() {
        bail!(
            "`{}`: not a benchmark result (not a JSON object)",
            path.display()
        );
    }
    Ok(v)
}

/// Merges `parts` of `benchmark` by that benchmark's own merge.
pub fn merge_docs(benchmark: &str, parts: &[Value]) -> Result<Value> {
    match benchmark {
        "place" => bench_tasks::merge(parts),
        "learn" => bench_learn::merge(parts),
        "trajectory" => bench_trajectory::merge(parts),
        "paper" => bench_paper::merge(parts),
        "adapt" => bench_adapt::merge(parts),
        other => {
            bail!("`{other}` results cannot be merged (place, learn, trajectory, paper, adapt)")
        }
    }
}

/// Runs `agp bench merge`: reads every part, merges, writes `--json` (and `--plot`), prints
/// the merged table for a placement; a part of another run is refused in one line naming
/// its file.
pub fn run(args: &BenchMergeArgs) -> Result<Value> {
    for (i, p) in args.parts.iter().enumerate() {
        if args.parts[..i].contains(p) {
            bail!("`{}`: given twice", p.display());
        }
    }
    let parts: Vec<Value> = args
        .parts
        .iter()
        .map(|p| read_part(p))
        .collect::<Result<_>>()?;
    let partial: Vec<&PathBuf> = args
        .parts
        .iter()
        .zip(&parts)
        .filter(|(_, v)| v["partial"] == true)
        .map(|(p, _)| p)
        .collect();
    if let Some(p) = partial.first()
        && !args.allow_partial
    {
        bail!(
            "`{}`: a partial result ({}): it holds fewer episodes than its run; merge it with `--allow-partial`",
            p.display(),
            parts[args.parts.iter().position(|q| q == *p).unwrap_or(0)]["partial_reason"]
                .as_str()
                .unwrap_or("stopped before the end")
        );
    }
    let first = &args.parts[0];
    let benchmark = parts[0]["benchmark"]
        .as_str()
        .with_context(|| {
            format!(
                "`{}`: not a benchmark result (no `benchmark` field)",
                first.display()
            )
        })?
        .to_owned();
    let mut doc = merge_docs(&benchmark, &parts).map_err(|e| name_the_part(e, &args.parts))?;
    if !partial.is_empty() {
        doc["partial"] = serde_json::json!(true);
        doc["partial_reason"] = serde_json::json!(format!(
            "merged with --allow-partial from {} partial part(s)",
            partial.len()
        ));
    }
    let seeds: Vec<u64> = doc["seeds"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_u64).collect())
        .unwrap_or_default();
    if benchmark == "place" {
        print_place(&doc, physics_note(doc["physics"] == "in-process"));
    }
    if benchmark == "adapt" {
        bench_adapt::print_adapt(&doc);
    }
    println!(
        "merged {} parts of `{benchmark}`: seeds {}; wall time of the longest part {:.1} s",
        parts.len(),
        seed_list(&seeds),
        number_at(&doc, &["wall_time_s"])
    );
    write_json(&args.json, &doc)?;
    println!("JSON     {}", args.json.display());
    if let Some(plot) = &args.plot {
        plot_per_seed(plot, &benchmark, &doc)?;
        println!("plot     {}", plot.display());
    }
    Ok(doc)
}

/// A merge's refusal of a part, with the part's file in place of its index.
fn name_the_part(e: anyhow::Error, files: &[PathBuf]) -> anyhow::Error {
    match e.downcast_ref::<MergePartError>() {
        Some(MergePartError {
            part: Some(i),
            what,
        }) => {
            let mut what = what.clone();
            // "seed 102 is also in part 1": the other part by its file too.
            for (k, f) in files.iter().enumerate() {
                what = what.replace(
                    &format!("in part {}", k + 1),
                    &format!("in `{}`", f.display()),
                );
            }
            let file = files
                .get(*i)
                .map_or_else(|| "?".into(), |f| f.display().to_string());
            anyhow::anyhow!("`{file}`: {what}")
        }
        Some(MergePartError { part: None, what }) => anyhow::anyhow!(
            "{what} (parts: {})",
            files
                .iter()
                .map(|f| format!("`{}`", f.display()))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        None => e,
    }
}

/// The figures drawn per seed: (JSON path under a planner, label).
fn plotted_figures(benchmark: &str) -> &'static [(&'static str, &'static str)] {
    match benchmark {
        "place" => &[
            ("success_rate", "success rate"),
            ("median_position_error_mm", "median position error (mm)"),
        ],
        "trajectory" => &[("mean_error_mm", "mean error per point (mm)")],
        _ => &[],
    }
}

/// Each seed's figure per planner, one panel per figure, the mean over the seeds dashed.
fn plot_per_seed(path: &Path, benchmark: &str, doc: &Value) -> Result<()> {
    use plotters::prelude::*;
    let figures = plotted_figures(benchmark);
    if figures.is_empty() {
        bail!("--plot: no per-seed plot for `{benchmark}` results (place and trajectory have one)");
    }
    let per_seed: Vec<&Value> = doc["per_seed"]
        .as_array()
        .map(|a| a.iter().collect())
        .unwrap_or_default();
    let planners: Vec<String> = doc["planners"]
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    let seeds: Vec<f64> = per_seed.iter().map(|d| number_at(d, &["seed"])).collect();
    let (s0, s1) = (
        seeds.iter().copied().fold(f64::INFINITY, f64::min) - 0.5,
        seeds.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 0.5,
    );
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("cannot draw the plot: {e}");
    let mut svg = String::new();
    {
        let width = 560 * figures.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (width, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let areas = root.split_evenly((1, figures.len()));
        let colours = [
            RGBColor(30, 90, 200),
            RGBColor(200, 30, 30),
            RGBColor(40, 150, 60),
        ];
        for (area, (key, label)) in areas.iter().zip(figures) {
            let values: Vec<Vec<f64>> = planners
                .iter()
                .map(|p| {
                    per_seed
                        .iter()
                        .map(|d| number_at(d, &["planners", p, key]))
                        .collect()
                })
                .collect();
            let top = values
                .iter()
                .flatten()
                .copied()
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max)
                .max(1e-9)
                * 1.1;
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!("{label} per seed ({benchmark})"),
                    ("sans-serif", 14),
                )
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(50)
                .build_cartesian_2d(s0..s1, 0.0..top)
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("seed")
                .y_desc(*label)
                .draw()
                .map_err(|e| err(&e))?;
            for ((name, vals), colour) in planners.iter().zip(&values).zip(colours.iter().cycle()) {
                let points: Vec<(f64, f64)> = seeds
                    .iter()
                    .copied()
                    .zip(vals.iter().copied())
                    .filter(|(_, v)| v.is_finite())
                    .collect();
                let mean = number_at(&doc["planners"][name]["spread"], &[key, "mean"]);
                chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))
                    .map_err(|e| err(&e))?
                    .label(name.as_str())
                    .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
                if mean.is_finite() {
                    chart
                        .draw_series(DashedLineSeries::new(
                            [(s0, mean), (s1, mean)],
                            6,
                            4,
                            colour.stroke_width(1),
                        ))
                        .map_err(|e| err(&e))?;
                }
            }
            chart
                .configure_series_labels()
                .border_style(BLACK)
                .background_style(WHITE)
                .draw()
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    std::fs::write(path, svg).with_context(|| format!("cannot write `{}`", path.display()))
}
