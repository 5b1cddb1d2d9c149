//! The math at speed, each beside a straightforward reference run in the same process on
//! the same inputs: Gaussian smoothing of a 128 x 128 grid, the paper's orientation match
//! (Algorithm 3) at 1 deg, and the push search (Algorithm 5). Checks first that ours and
//! the reference agree, then prints per-call times (median, p90, max), the ratio
//! reference / ours and the heap allocations per call.
//!
//! ```text
//! cargo run --release -p agp-harness --bin bench-math -- --json math.json
//! ```

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

use agp_affordance::{
    AffordanceGradient, GaussianSmoother, MatchMethod, ShapeMatcher, ShapeMatcherConfig,
};
use agp_harness::math::{
    PaperReference, Timing, circling_points, learn_from_sim, measure, orientation_disagreement,
    perimeter, polygon_of, push_cost_disagreement, random_goals, random_grid, reference_plan,
    reference_plan_over, reference_smooth, smoothing_disagreement, start_radius_m,
};
use agp_planning::{PushChoiceSettings, PushPlanner};
use agp_runtime::alloc_count;
use agp_shared_types::Pose2;
use agp_world::{Rng, RobotDescription, Scenario};
use anyhow::{Context, Result, bail};
use clap::Parser;
use serde_json::json;

/// Counts allocations, to show that our hot paths make none.
#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

fn allocations() -> u64 {
    alloc_count::process_allocations()
}

/// Times the math of the pipeline beside straightforward references.
#[derive(Debug, Parser)]
#[command(name = "bench-math", version)]
struct Args {
    /// Built-in scenario whose (polygonal) object is learned and matched.
    #[arg(long, default_value = "lshape")]
    scenario: String,
    /// Standard deviation of the smoothing Gaussian, cells.
    #[arg(long, default_value_t = 2.0)]
    sigma_cells: f64,
    /// Measured calls of ours per case (the slow references get fewer, see --ref-calls).
    #[arg(long, default_value_t = 2000)]
    calls: usize,
    /// Measured calls of each reference.
    #[arg(long, default_value_t = 50)]
    ref_calls: usize,
    /// Border points of one circling.
    #[arg(long, default_value_t = 1000)]
    points: usize,
    /// Pushes per alpha learned against the physics to build the AG.
    #[arg(long, default_value_t = 36)]
    starts_per_alpha: usize,
    /// Also write the figures as one JSON object to this file.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Smoothing, max abs difference allowed between ours (f32, separable) and the reference
/// (f64, direct 2-D) on values in [0, 1).
const SMOOTHING_TOLERANCE: f32 = 1e-5;
/// Orientation match: largest difference allowed, degrees.
const ORIENTATION_TOLERANCE_DEG: f64 = 1.0;
/// Push search: largest difference of the chosen pushes' costs, metres.
const PUSH_COST_TOLERANCE_M: f64 = 1e-9;

struct Row {
    case: &'static str,
    ours: Timing,
    reference: Timing,
    reference_name: &'static str,
    target_us: Option<f64>,
}

/// How many calls each case warms up with and measures, for ours and for the reference.
#[derive(Debug, Clone, Copy)]
struct Calls {
    warmup: usize,
    calls: usize,
    ref_warmup: usize,
    ref_calls: usize,
}

fn main() -> Result<()> {
    alloc_count::enable();
    let args = Args::parse();
    if args.calls == 0 || args.ref_calls == 0 {
        bail!("--calls and --ref-calls must be at least 1");
    }
    let n = Calls {
        warmup: (args.calls / 10).max(10),
        calls: args.calls,
        ref_warmup: (args.ref_calls / 10).max(2),
        ref_calls: args.ref_calls,
    };
    let mut rows = Vec::new();
    let mut checks = Vec::new();
    let (load, cores) = machine_load();
    println!("load average (1, 5, 15 min) at start: {load} on {cores} cores");

    bench_smoothing(&args, n, &mut rows, &mut checks);
    let scenario = Scenario::builtin(&args.scenario)
        .with_context(|| format!("no built-in scenario `{}`", args.scenario))?;
    let ag = learned_ag(&scenario, args.starts_per_alpha)?;
    bench_orientation(&args, n, &scenario, &ag, &mut rows, &mut checks)?;
    bench_push_search(n, &scenario, &ag, &mut rows, &mut checks);

    print_table(&rows);
    let failed: Vec<_> = checks
        .iter()
        .filter(|c| c["ok"] != json!(true))
        .map(|c| c["case"].clone())
        .collect();
    if let Some(path) = &args.json {
        write_json(path, &load, cores, &checks, &rows)?;
    }
    if !failed.is_empty() {
        bail!("ours and the reference disagree beyond tolerance: {failed:?}");
    }
    Ok(())
}

/// The load average (1, 5, 15 min) and the core count: other work on the machine shows in
/// the figures, so they say how much there was.
fn machine_load() -> (String, usize) {
    let load = std::fs::read_to_string("/proc/loadavg")
        .map(|l| l.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".to_owned());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    (load, cores)
}

/// Case 1, Gaussian smoothing of a 128 x 128 grid: ours (separable, f32) against the direct
/// 2-D convolution.
fn bench_smoothing(
    args: &Args,
    n: Calls,
    rows: &mut Vec<Row>,
    checks: &mut Vec<serde_json::Value>,
) {
    let mut smoother = GaussianSmoother::new(args.sigma_cells);
    let grids: Vec<_> = (0..4).map(|s| random_grid(100 + s)).collect();
    let mut worst = 0.0_f32;
    for g in &grids {
        worst = worst.max(smoothing_disagreement(&mut smoother, g));
    }
    println!(
        "smoothing 128 x 128, sigma {} cells (radius {}), {:?}: max |ours - direct 2-D| = {worst:.2e} over {} random grids (tolerance {SMOOTHING_TOLERANCE:.0e})",
        args.sigma_cells,
        smoother.radius(),
        smoother.method(),
        grids.len()
    );
    checks.push(json!({"case": "smoothing", "max_abs_diff": worst, "tolerance": SMOOTHING_TOLERANCE, "ok": worst <= SMOOTHING_TOLERANCE}));
    let src = &grids[0];
    let mut dst = src.zeros_like();
    let ours = measure(n.warmup, n.calls, allocations, || {
        smoother.smooth(black_box(src), &mut dst);
        black_box(&dst);
    });
    let kernel = smoother.kernel().to_vec();
    let reference = measure(n.ref_warmup, n.ref_calls, allocations, || {
        reference_smooth(&kernel, black_box(src), &mut dst);
        black_box(&dst);
    });
    rows.push(Row {
        case: "smoothing 128x128",
        ours,
        reference,
        reference_name: "direct 2-D",
        target_us: Some(25.0),
    });
}

/// The AG of `scenario`'s object, learned against the physics with `starts_per_alpha`
/// pushes per alpha.
fn learned_ag(scenario: &Scenario, starts_per_alpha: usize) -> Result<AffordanceGradient> {
    let learn_start = Instant::now();
    let ag = learn_from_sim(scenario, starts_per_alpha)?;
    println!(
        "AG of `{}` learned from {} pushes against the physics in {:.1} s",
        scenario.name,
        ag.alphas_deg()
            .filter_map(|a| ag.push_count(a))
            .sum::<u64>(),
        learn_start.elapsed().as_secs_f64()
    );
    Ok(ag)
}

/// Case 2, the orientation match (Algorithm 3 at 1 deg) on points of circlings of the object
/// at random poses: ours against the brute force.
fn bench_orientation(
    args: &Args,
    n: Calls,
    scenario: &Scenario,
    ag: &AffordanceGradient,
    rows: &mut Vec<Row>,
    checks: &mut Vec<serde_json::Value>,
) -> Result<()> {
    let polygon = polygon_of(scenario)?;
    let config = ShapeMatcherConfig {
        method: MatchMethod::PaperOverlap,
        symmetry_order: scenario.object.shape.symmetry_order(),
        paper_step_deg: 1.0,
        ..ShapeMatcherConfig::default()
    };
    let shape = ag.combined_shape();
    let mut matcher = ShapeMatcher::new(&shape, config.clone()).context("cannot build matcher")?;
    let mut paper = PaperReference::new(&shape, &config);
    let spacing = perimeter(&polygon) / args.points as f64;
    let mut rng = Rng::new(7);
    let point_sets: Vec<_> = (0..16)
        .map(|_| {
            let pose = Pose2::new(
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
                rng.range(-std::f64::consts::PI, std::f64::consts::PI),
            );
            circling_points(&polygon, spacing, pose, 0.001, &mut rng)
        })
        .collect();
    let worst_deg = orientation_disagreement(&mut matcher, &mut paper, &point_sets)?.to_degrees();
    println!(
        "orientation match, Algorithm 3 at 1 deg, {} points of a circling (1 mm noise): max |ours - brute force| = {worst_deg:.2} deg over {} poses (tolerance {ORIENTATION_TOLERANCE_DEG} deg)",
        point_sets[0].len(),
        point_sets.len()
    );
    checks.push(json!({"case": "orientation", "max_diff_deg": worst_deg, "tolerance_deg": ORIENTATION_TOLERANCE_DEG, "ok": worst_deg <= ORIENTATION_TOLERANCE_DEG}));
    let mut k = 0;
    let ours = measure(n.warmup, n.calls, allocations, || {
        k = (k + 1) % point_sets.len();
        black_box(matcher.match_points(black_box(&point_sets[k])).ok());
    });
    let reference = measure(n.ref_warmup, n.ref_calls, allocations, || {
        k = (k + 1) % point_sets.len();
        black_box(paper.orientation_rad(black_box(&point_sets[k])));
    });
    rows.push(Row {
        case: "orientation match",
        ours,
        reference,
        reference_name: "brute force",
        target_us: Some(2000.0),
    });
    Ok(())
}

/// Case 3, the push search (Algorithm 5) towards random goals: ours against the plain
/// search, with and without the contacts given.
fn bench_push_search(
    n: Calls,
    scenario: &Scenario,
    ag: &AffordanceGradient,
    rows: &mut Vec<Row>,
    checks: &mut Vec<serde_json::Value>,
) {
    let robot = RobotDescription::epuck();
    let order = scenario.object.shape.symmetry_order();
    let settings = PushChoiceSettings::new(order, start_radius_m(scenario, &robot));
    let planner = PushPlanner::new(ag, settings.clone());
    // The reference predicts as the planner's own predictor does.
    let predictor = agp_affordance::PushPredictor::new(ag, settings.start_radius_m);
    let goals = random_goals(16, 11);
    let estimate = Pose2::new(0.0, 0.0, 0.0);
    let worst_cost = push_cost_disagreement(&planner, estimate, &goals);
    println!(
        "push search, {} contacts x {} deg alpha steps x {} fractions: max |cost ours - cost reference| = {:.2e} mm over {} goals (tolerance {:.0e} mm)",
        planner.contacts().len(),
        settings.alpha_step_deg,
        settings.push_fractions.len(),
        worst_cost * 1e3,
        goals.len(),
        PUSH_COST_TOLERANCE_M * 1e3
    );
    checks.push(json!({"case": "push search", "max_cost_diff_m": worst_cost, "tolerance_m": PUSH_COST_TOLERANCE_M, "ok": worst_cost <= PUSH_COST_TOLERANCE_M}));
    let push_calls = (n.calls / 4).max(1);
    let mut k = 0;
    let ours = measure(n.warmup / 4, push_calls, allocations, || {
        k = (k + 1) % goals.len();
        black_box(planner.plan(estimate, black_box(&goals[k])));
    });
    let reference = measure(n.ref_warmup, n.ref_calls, allocations, || {
        k = (k + 1) % goals.len();
        let goal = &goals[k];
        black_box(reference_plan(&predictor, &settings, |p, f| {
            planner.score(p, f, estimate, goal).2
        }));
    });
    let contacts = planner.contacts().to_vec();
    let reference_given = measure(n.ref_warmup, n.ref_calls, allocations, || {
        k = (k + 1) % goals.len();
        let goal = &goals[k];
        black_box(reference_plan_over(
            &predictor,
            &contacts,
            &settings,
            |p, f| planner.score(p, f, estimate, goal).2,
        ));
    });
    rows.push(Row {
        case: "push search",
        ours,
        reference,
        reference_name: "plain, no precompute",
        target_us: None,
    });
    rows.push(Row {
        case: "push search",
        ours,
        reference: reference_given,
        reference_name: "plain, contacts given",
        target_us: None,
    });
}

/// Writes the figures as one JSON object to `path`.
fn write_json(
    path: &std::path::Path,
    load: &str,
    cores: usize,
    checks: &[serde_json::Value],
    rows: &[Row],
) -> Result<()> {
    let doc = json!({
        "load_average_at_start": load,
        "cores": cores,
        "checks": checks,
        "cases": rows.iter().map(|r| json!({
            "case": r.case,
            "reference": r.reference_name,
            "ours": timing_json(&r.ours),
            "reference_timing": timing_json(&r.reference),
            "ratio_reference_over_ours": r.reference.median_us / r.ours.median_us,
            "target_median_us": r.target_us,
        })).collect::<Vec<_>>(),
    });
    std::fs::write(path, serde_json::to_string_pretty(&doc)?)
        .with_context(|| format!("cannot write `{}`", path.display()))
}

fn timing_json(t: &Timing) -> serde_json::Value {
    json!({
        "calls": t.calls,
        "median_us": t.median_us,
        "p90_us": t.p90_us,
        "max_us": t.max_us,
        "allocations_per_call": t.allocations_per_call,
    })
}

fn print_table(rows: &[Row]) {
    println!();
    println!(
        "{:<18} {:<22} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>8} {:>9} {:>7}",
        "case",
        "reference",
        "ours p50",
        "ours p90",
        "ours max",
        "ref p50",
        "ref p90",
        "ref max",
        "ref/ours",
        "target",
        "allocs"
    );
    for r in rows {
        let target = match r.target_us {
            Some(t) if r.ours.median_us <= t => format!("<={t:.0} ok"),
            Some(t) => format!("<={t:.0} MISS"),
            None => "-".to_owned(),
        };
        println!(
            "{:<18} {:<22} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>8.1} {:>9} {:>7.2}",
            r.case,
            r.reference_name,
            r.ours.median_us,
            r.ours.p90_us,
            r.ours.max_us,
            r.reference.median_us,
            r.reference.p90_us,
            r.reference.max_us,
            r.reference.median_us / r.ours.median_us,
            target,
            r.ours.allocations_per_call,
        );
    }
    println!("times in us per call; allocs: heap allocations per call of ours");
}
