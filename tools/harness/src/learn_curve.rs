//! `agp bench learn --curve N,..`: the learning curve of both protocols (issue 33, item 1):
//! at each trial count, a learning run of the paper's protocol and one of the active one
//! over every seed and object, and the error of the unseen pushes against the trials, as a
//! table, a JSON document and an SVG plot (mean over the seeds with its min-max bar, the
//! learning targets dashed).
//!
//! Each point is a run of its own (`bench_learn::learn`, its JSON and AG files in
//! `<out>/curve/<protocol>-<trials>/`): the paper's protocol at 30
//! trials is 10 starts per alpha, not the first 30 trials of its 180 (those are all at
//! alpha 0).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use plotters::prelude::*;
use serde_json::{Map, Value, json};

use crate::bench_learn::{BenchLearnArgs, ProtocolArg, learn};
use crate::learn_bench::{TARGET_DISPLACEMENT_ERROR_RATIO, TARGET_ROTATION_ERROR_DEG};
use crate::seeds::{Spread, number_at, seed_list};

/// The protocols of a curve, in the order run and drawn.
const PROTOCOLS: [(ProtocolArg, &str); 2] = [
    (ProtocolArg::Paper, "paper"),
    (ProtocolArg::Active, "active"),
];

/// The figures of a curve point per object: (key in the curve's JSON, path in the learning
/// document's `spread`, label of the plot's row, the target).
const FIGURES: [(&str, [&str; 2], &str, f64); 2] = [
    (
        "rotation_error_deg",
        ["prediction", "median_rotation_error_deg"],
        "median rotation error (deg)",
        TARGET_ROTATION_ERROR_DEG,
    ),
    (
        "displacement_error_ratio",
        ["prediction", "median_displacement_error_ratio"],
        "median displacement error / displacement",
        TARGET_DISPLACEMENT_ERROR_RATIO,
    ),
];

/// Where the curve's plot goes unless `--plot` says.
pub fn default_plot(out: &Path) -> PathBuf {
    out.join("learning-curve.svg")
}

/// Runs the learning curve `args.curve` asks for; writes its JSON (`--json`) and plot.
pub fn run_curve(args: &BenchLearnArgs) -> Result<Value> {
    let wall = Instant::now();
    if args.seeds.shard.is_some() {
        bail!("--curve runs every seed itself: it takes no --shard");
    }
    let mut counts = args.curve.clone();
    counts.sort_unstable();
    counts.dedup();
    if counts.first() == Some(&0) {
        bail!("--curve: a trial count of 0");
    }
    let alphas = args.alphas.len().max(1);
    if let Some(n) = counts.iter().find(|&&n| n % alphas != 0) {
        bail!(
            "--curve {n}: the paper's protocol makes as many trials at each of the {alphas} alphas, so every count is a multiple of {alphas}"
        );
    }
    let seeds = args.seeds.all();
    println!(
        "agp bench learn --curve: both protocols at {} trials, seeds {}",
        counts
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", "),
        seed_list(&seeds)
    );
    // The largest count first, the active protocol before the paper's: a run stopped
    // early has the points that matter most (each point's JSON is written as it ends).
    let mut points: Vec<(usize, &str, Value)> = Vec::with_capacity(2 * counts.len());
    for &n in counts.iter().rev() {
        for (protocol, name) in PROTOCOLS.iter().rev().copied() {
            println!("\n== {name} protocol, {n} trials ==");
            // Each point's own run writes its learning JSON and AG files in a folder of
            // its own.
            let out = args.out.join("curve").join(format!("{name}-{n}"));
            std::fs::create_dir_all(&out)
                .with_context(|| format!("--out: cannot create the folder {}", out.display()))?;
            let run = BenchLearnArgs {
                protocol,
                trials: n,
                curve: Vec::new(),
                plot: None,
                json: Some(out.join("learn.json")),
                out,
                ..args.clone()
            };
            let doc = learn(&run).with_context(|| format!("the {name} protocol at {n} trials"))?;
            points.push((n, name, point(n, &doc)));
        }
    }
    let mut curve = Map::new();
    for (_, name) in PROTOCOLS {
        let mut mine: Vec<&(usize, &str, Value)> = points.iter().filter(|p| p.1 == name).collect();
        mine.sort_by_key(|p| p.0);
        curve.insert(
            name.to_owned(),
            Value::Array(mine.into_iter().map(|p| p.2.clone()).collect()),
        );
    }
    let doc = json!({
        "benchmark": "learn-curve",
        "seeds": seeds,
        "alphas_deg": args.alphas,
        "eval_pushes": args.eval,
        "trials": counts,
        "curve": curve,
        "wall_time_s": wall.elapsed().as_secs_f64(),
    });
    println!("{}", table(&doc));
    let plot = args.plot.clone().unwrap_or_else(|| default_plot(&args.out));
    plot_curve(&doc, &plot)?;
    println!("plot     {}", plot.display());
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&doc).context("cannot encode the JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("JSON     {}", path.display());
    }
    Ok(doc)
}

/// One point of the curve from a learning run's document: per object each figure's
/// spread over the seeds, and on how many seeds the object met every target.
fn point(trials: usize, doc: &Value) -> Value {
    let per_seed: Vec<&Value> = doc["per_seed"]
        .as_array()
        .map(|a| a.iter().collect())
        .unwrap_or_else(|| vec![doc]);
    let mut objects = Map::new();
    if let Some(names) = doc["objects"].as_object() {
        for (name, o) in names {
            let mut p = Map::new();
            for (key, path, _, _) in FIGURES {
                p.insert(key.to_owned(), o["spread"][path[0]][path[1]].clone());
            }
            let prefix = format!("{name}: ");
            let met = per_seed
                .iter()
                .filter(|d| {
                    !d["targets_missed"].as_array().is_some_and(|m| {
                        m.iter()
                            .filter_map(Value::as_str)
                            .any(|t| t.starts_with(&prefix))
                    })
                })
                .count();
            p.insert("seeds_meeting_every_target".into(), json!(met));
            p.insert("seeds".into(), json!(per_seed.len()));
            objects.insert(name.clone(), Value::Object(p));
        }
    }
    json!({ "trials": trials, "objects": objects })
}

/// The spread at `path` of a curve point, if any.
fn spread(v: &Value) -> Option<Spread> {
    serde_json::from_value::<Spread>(v.clone()).ok()
}

/// The curve as a table: per object and trial count, both protocols' figures.
fn table(doc: &Value) -> String {
    let mut out = String::from(
        "\nlearning curve: mean (min-max) over the seeds; seeds meeting every target\n",
    );
    let paper = doc["curve"]["paper"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let active = doc["curve"]["active"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let names: Vec<String> = paper
        .first()
        .and_then(|p| p["objects"].as_object())
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    let show = |v: &Value, d: usize| spread(v).map_or_else(|| "-".to_owned(), |s| s.show(d));
    for name in &names {
        out.push_str(&format!(
            "== {name} ==\n  {:>6}  {:<22} {:<22} {:>5}   {:<22} {:<22} {:>5}\n",
            "trials",
            "paper rotation deg",
            "paper ratio",
            "met",
            "active rotation deg",
            "active ratio",
            "met"
        ));
        for (p, a) in paper.iter().zip(&active) {
            let (po, ao) = (&p["objects"][name], &a["objects"][name]);
            let met = |o: &Value| {
                format!(
                    "{}/{}",
                    number_at(o, &["seeds_meeting_every_target"]),
                    number_at(o, &["seeds"])
                )
            };
            out.push_str(&format!(
                "  {:>6}  {:<22} {:<22} {:>5}   {:<22} {:<22} {:>5}\n",
                number_at(p, &["trials"]),
                show(&po["rotation_error_deg"], 2),
                show(&po["displacement_error_ratio"], 3),
                met(po),
                show(&ao["rotation_error_deg"], 2),
                show(&ao["displacement_error_ratio"], 3),
                met(ao)
            ));
        }
    }
    out
}

/// Draws the curve: one column per object, a row per figure; each protocol's mean over the
/// seeds as a line, its min-max as a bar at each count, the target dashed.
pub fn plot_curve(doc: &Value, path: &Path) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("cannot draw the learning curve: {e}");
    let names: Vec<String> = doc["curve"]["paper"][0]["objects"]
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    if names.is_empty() {
        bail!("no object in the learning curve to plot");
    }
    let counts: Vec<f64> = doc["trials"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default();
    let x_max = counts.iter().copied().fold(1.0, f64::max) * 1.05;
    let colours = [RGBColor(30, 90, 200), RGBColor(200, 30, 30)];
    let mut svg = String::new();
    {
        let (w, h) = (320 * names.len() as u32, 2 * 300 + 30);
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let (title, body) = root.split_vertically(30);
        title
            .titled(
                &format!(
                    "learning curve: unseen pushes' error against trials, seeds {} (paper blue, active red; mean, min-max bars, target dashed)",
                    doc["seeds"]
                        .as_array()
                        .map(|s| s.iter().map(ToString::to_string).collect::<Vec<_>>().join(","))
                        .unwrap_or_default()
                ),
                ("sans-serif", 14),
            )
            .map_err(|e| err(&e))?;
        let rows = body.split_evenly((FIGURES.len(), names.len()));
        for (r, (key, _, label, target)) in FIGURES.iter().enumerate() {
            for (c, name) in names.iter().enumerate() {
                let area = &rows[r * names.len() + c];
                // (protocol, per count: (trials, mean, min, max)).
                let series: Vec<Vec<(f64, f64, f64, f64)>> = PROTOCOLS
                    .iter()
                    .map(|(_, p)| {
                        doc["curve"][*p]
                            .as_array()
                            .map(|pts| {
                                pts.iter()
                                    .filter_map(|pt| {
                                        let s = spread(&pt["objects"][name][*key])?;
                                        Some((number_at(pt, &["trials"]), s.mean, s.min, s.max))
                                    })
                                    .collect()
                            })
                            .unwrap_or_default()
                    })
                    .collect();
                let top = series.iter().flatten().map(|s| s.3).fold(*target, f64::max) * 1.15;
                let mut chart = ChartBuilder::on(area)
                    .caption(name.as_str(), ("sans-serif", 13))
                    .margin(8)
                    .x_label_area_size(28)
                    .y_label_area_size(44)
                    .build_cartesian_2d(0.0..x_max, 0.0..top)
                    .map_err(|e| err(&e))?;
                chart
                    .configure_mesh()
                    .disable_mesh()
                    .x_desc("trials")
                    .y_desc(*label)
                    .draw()
                    .map_err(|e| err(&e))?;
                // The target, dashed.
                let dashes = (0..40).map(|k| {
                    let x0 = x_max * f64::from(k) / 40.0;
                    PathElement::new(
                        vec![(x0, *target), (x0 + x_max / 80.0, *target)],
                        BLACK.mix(0.6),
                    )
                });
                chart.draw_series(dashes).map_err(|e| err(&e))?;
                if series.iter().all(Vec::is_empty) {
                    chart
                        .draw_series(std::iter::once(Text::new(
                            "n/a (a disc)",
                            (x_max * 0.3, top * 0.5),
                            ("sans-serif", 13),
                        )))
                        .map_err(|e| err(&e))?;
                }
                for (s, colour) in series.iter().zip(colours) {
                    chart
                        .draw_series(LineSeries::new(
                            s.iter().map(|p| (p.0, p.1)),
                            colour.stroke_width(2),
                        ))
                        .map_err(|e| err(&e))?;
                    chart
                        .draw_series(s.iter().map(|p| {
                            PathElement::new(vec![(p.0, p.2), (p.0, p.3)], colour.stroke_width(2))
                        }))
                        .map_err(|e| err(&e))?;
                }
            }
        }
        root.present().map_err(|e| err(&e))?;
    }
    std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}
