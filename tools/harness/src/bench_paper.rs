//! `agp bench paper`: the paper's three benchmarks on its objects (benchmarks.md), each
//! run as its own `agp bench` command would, then our figures beside the paper's.

use std::path::PathBuf;
use std::time::Instant;

use agp_planning::PlannerKind;
use anyhow::{Context, Result};
use serde_json::{Value, json};

use crate::bench_learn::{self, BenchLearnArgs};
use crate::bench_tasks::{self, BenchPlaceArgs};
use crate::bench_trajectory::{self, BenchTrajectoryArgs};

/// The paper's figures (Sanchez-Fibla, Duff, Verschure; benchmarks.md).
const PAPER_MAX_ROTATION_DEG: [(&str, f64); 3] = [("0", 39.51), ("15", 59.06), ("-15", 79.78)];
const PAPER_TRAJECTORY_AFFORDANCE: f64 = 7.82;
const PAPER_TRAJECTORY_BASELINE: f64 = 10.71;
/// The objects the paper learns, pushes along a line and places.
const LEARN_OBJECTS: [&str; 4] = ["triangle", "square", "lshape", "circle"];
const TRAJECTORY_OBJECT: &str = "lshape";
const PLACE_OBJECTS: [&str; 2] = ["triangle", "lshape"];
/// The project's targets beside the paper's (issue 4).
const TARGET_TRAJECTORY_RATIO: f64 = 0.6;
const TARGET_PLACE_SUCCESS: f64 = 0.9;

/// The options of `agp bench paper`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchPaperArgs {
    /// Placement episodes per planner and object (random goals 250 to 500 mm away).
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// Seed of every benchmark (noise, unseen pushes, goals).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Folder for everything the benchmarks write: `learn/` (AG files and gradient plots),
    /// `trajectory.{json,svg}`, `place-<object>.{json,svg}`.
    #[arg(long, default_value = "results/paper")]
    pub out: PathBuf,
    /// Also write all the figures as one JSON object to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Step the physics library in-process for the trajectory and placement benchmarks
    /// instead of running the pipeline's processes.
    #[arg(long)]
    pub in_process: bool,
}

/// Runs the three benchmarks and prints the comparison.
pub fn run(args: &BenchPaperArgs) -> Result<Value> {
    let wall = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("--out: cannot create the folder {}", args.out.display()))?;
    let learn_dir = args.out.join("learn");

    println!("== 1/3 learning phase ==");
    let learn = bench_learn::learn(&BenchLearnArgs {
        seed: args.seed,
        json: Some(args.out.join("learn.json")),
        ..BenchLearnArgs::for_scenarios(&LEARN_OBJECTS, learn_dir.clone())
    })?;
    let ag = |object: &str| Some(learn_dir.join(format!("{object}.ag")));

    println!("\n== 2/3 push along a trajectory ==");
    let trajectory = bench_trajectory::run_trajectory(&BenchTrajectoryArgs {
        scenario: TRAJECTORY_OBJECT.into(),
        ag: ag(TRAJECTORY_OBJECT),
        seed: Some(args.seed),
        in_process: args.in_process,
        json: Some(args.out.join("trajectory.json")),
        plot: Some(args.out.join("trajectory.svg")),
    })?;

    println!("\n== 3/3 position and orientation ==");
    let mut place = serde_json::Map::new();
    for object in PLACE_OBJECTS {
        let doc = bench_tasks::run_place(&BenchPlaceArgs {
            scenario: object.into(),
            episodes: args.episodes,
            seed: Some(args.seed),
            planners: PlannerKind::ALL.to_vec(),
            ag: ag(object),
            in_process: args.in_process,
            json: Some(args.out.join(format!("place-{object}.json"))),
            plot: Some(args.out.join(format!("place-{object}.svg"))),
        })?;
        place.insert(object.into(), doc);
        println!();
    }
    let wall_time_s = wall.elapsed().as_secs_f64();
    let doc = json!({
        "benchmark": "paper",
        "seed": args.seed,
        "physics": if args.in_process { "in-process" } else { "pipeline" },
        "learn": learn,
        "trajectory": trajectory,
        "place": place,
        "paper": {
            "max_rotation_deg": PAPER_MAX_ROTATION_DEG.iter().map(|(k, v)| ((*k).to_owned(), json!(v))).collect::<serde_json::Map<_, _>>(),
            "trajectory": {
                "affordance": PAPER_TRAJECTORY_AFFORDANCE,
                "baseline": PAPER_TRAJECTORY_BASELINE,
                "ratio": PAPER_TRAJECTORY_AFFORDANCE / PAPER_TRAJECTORY_BASELINE,
            },
        },
        "wall_time_s": wall_time_s,
    });
    print_comparison(&doc, args);
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&doc).context("cannot encode the JSON")?;
        std::fs::write(path, text + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("JSON     {}", path.display());
    }
    Ok(doc)
}

fn num(v: &Value, path: &[&str]) -> f64 {
    path.iter()
        .try_fold(v, |v, k| v.get(*k))
        .and_then(Value::as_f64)
        .unwrap_or(f64::NAN)
}

fn met(ok: bool) -> &'static str {
    if ok { "met   " } else { "MISSED" }
}

fn print_comparison(doc: &Value, args: &BenchPaperArgs) {
    println!(
        "\n== agp bench paper: our figures beside the paper's (seed {}, {}) ==",
        args.seed,
        if args.in_process {
            "tasks in-process"
        } else {
            "tasks over the pipeline"
        }
    );
    let learn = &doc["learn"]["objects"];
    println!("learning, largest rotation of a single push (triangle), deg:");
    println!("    {:<8} {:>8} {:>8}", "alpha", "ours", "paper");
    for (alpha, paper) in PAPER_MAX_ROTATION_DEG {
        println!(
            "    {:<8} {:>8.2} {:>8.2}",
            format!("{alpha:>3}"),
            num(learn, &["triangle", "max_rotation_deg", alpha]),
            paper
        );
    }
    println!("learning, 200 unseen pushes predicted (median errors; the paper gives no figure):");
    println!(
        "    {:<10} {:>14} {:>18}",
        "object", "rotation deg", "displacement ratio"
    );
    // A figure the JSON holds as null (a disc's rotation, which IR cannot see) as "n/a".
    let fixed = |x: f64, decimals: usize| {
        if x.is_finite() {
            format!("{x:.decimals$}")
        } else {
            "n/a".to_owned()
        }
    };
    for object in LEARN_OBJECTS {
        println!(
            "    {:<10} {:>14} {:>18}",
            object,
            fixed(
                num(learn, &[object, "prediction", "median_rotation_error_deg"]),
                2
            ),
            fixed(
                num(
                    learn,
                    &[object, "prediction", "median_displacement_error_ratio"]
                ),
                3
            )
        );
    }
    let t = &doc["trajectory"];
    let ratio = num(t, &["ratio"]);
    println!(
        "trajectory ({TRAJECTORY_OBJECT}), mean distance of the centroid to the line per point:"
    );
    println!(
        "    ours   affordance {:.2} mm, baseline {:.2} mm, ratio {:.2}",
        num(t, &["planners", "affordance", "mean_error_mm"]),
        num(t, &["planners", "baseline", "mean_error_mm"]),
        ratio
    );
    println!(
        "    paper  affordance {PAPER_TRAJECTORY_AFFORDANCE} units, baseline {PAPER_TRAJECTORY_BASELINE} units, ratio {:.2}",
        PAPER_TRAJECTORY_AFFORDANCE / PAPER_TRAJECTORY_BASELINE
    );
    println!(
        "placement, {} episodes per planner, within the scenario's 10 mm / 10 deg (the paper shows two runs, no figure):",
        args.episodes
    );
    println!(
        "    {:<10} {:<12} {:>8} {:>14} {:>12} {:>12}",
        "object", "planner", "success", "median pushes", "pos err mm", "ori err deg"
    );
    let mut place_ok = true;
    for object in PLACE_OBJECTS {
        for planner in PlannerKind::ALL {
            let p = &doc["place"][object]["planners"][planner.name()];
            let rate = num(p, &["success_rate"]);
            if planner == PlannerKind::Affordance {
                place_ok &= rate >= TARGET_PLACE_SUCCESS;
            }
            println!(
                "    {:<10} {:<12} {:>7.0}% {:>14.1} {:>12.1} {:>12.1}",
                object,
                if planner.reads_ground_truth() {
                    "oracle (GT)"
                } else {
                    planner.name()
                },
                100.0 * rate,
                num(p, &["median_pushes"]),
                num(p, &["median_position_error_mm"]),
                num(p, &["median_orientation_error_deg"])
            );
        }
    }
    println!("    (GT) the oracle reads the object's true pose: an upper bound, not a result");
    println!("targets:");
    println!(
        "    {} trajectory ratio affordance / baseline <= {TARGET_TRAJECTORY_RATIO} (paper 0.73): {ratio:.2}",
        met(ratio <= TARGET_TRAJECTORY_RATIO)
    );
    println!(
        "    {} placement success of the affordance planner >= {:.0} % on {}",
        met(place_ok),
        100.0 * TARGET_PLACE_SUCCESS,
        PLACE_OBJECTS.join(" and ")
    );
    if let Some(missed) = doc["learn"]["targets_missed"].as_array() {
        for m in missed {
            println!("    MISSED learning: {}", m.as_str().unwrap_or_default());
        }
    }
    println!("wall time {:.1} s", num(doc, &["wall_time_s"]));
}
