//! Tuning the active learning protocol's constants (issue 33, item 1) on the tuning seeds:
//! every (object, seed) learned with the given protocol and trials, side by side on the
//! cores; per object and seed the unseen pushes' median rotation error and displacement
//! ratio, and whether every target was met.
//!
//! `cargo run --release -p agp-harness --example active_tuning -- [--protocol paper|active]
//!  [--trials N] [--seeds 1-10] [--objects triangle,square,lshape,circle] [--eval N]
//!  [--spread-weight W] [--prior-weight W] [--reach-mm R] [--starts N]`

use std::process::ExitCode;

use agp_harness::learn_bench::{LearnBenchConfig, TrialProtocol, run_object};
use agp_harness::side_by_side::side_by_side;
use agp_world::Scenario;

fn parse<T: std::str::FromStr>(flag: &str, v: Option<String>) -> Result<T, String> {
    let v = v.ok_or_else(|| format!("`{flag}` needs a value"))?;
    v.parse().map_err(|_| format!("`{flag}`: bad value `{v}`"))
}

/// Takes flag `a` (and its value from `args`) into the run's settings.
fn apply(
    a: &str,
    args: &mut impl Iterator<Item = String>,
    cfg: &mut LearnBenchConfig,
    trials: &mut usize,
    seeds: &mut Vec<u64>,
    objects: &mut Vec<String>,
) -> Result<(), String> {
    match a {
        "--protocol" => {
            cfg.protocol = match args.next().as_deref() {
                Some("paper") => TrialProtocol::Paper,
                Some("active") => TrialProtocol::Active,
                other => return Err(format!("--protocol: `{other:?}`")),
            }
        }
        "--trials" => *trials = parse(a, args.next())?,
        "--eval" => cfg.eval_pushes = parse(a, args.next())?,
        "--spread-weight" => cfg.active.spread_weight = parse(a, args.next())?,
        "--prior-weight" => cfg.active.prior_weight = parse(a, args.next())?,
        "--reach-mm" => cfg.active.reach_m = parse::<f64>(a, args.next())? * 1e-3,
        "--starts" => cfg.active.starts_per_alpha = parse(a, args.next())?,
        "--seeds" => {
            let v: String = parse(a, args.next())?;
            let (lo, hi) = v.split_once('-').ok_or("--seeds: FIRST-LAST")?;
            let lo: u64 = lo.parse().map_err(|_| "--seeds")?;
            let hi: u64 = hi.parse().map_err(|_| "--seeds")?;
            *seeds = (lo..=hi).collect();
        }
        "--objects" => {
            let v: String = parse(a, args.next())?;
            *objects = v.split(',').map(String::from).collect();
        }
        other => return Err(format!("unknown argument `{other}`")),
    }
    Ok(())
}

fn main() -> ExitCode {
    let mut cfg = LearnBenchConfig::default();
    let mut trials = 90usize;
    let mut seeds: Vec<u64> = (1..=10).collect();
    let mut objects: Vec<String> = ["triangle", "square", "lshape", "circle"]
        .map(String::from)
        .to_vec();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let r = apply(
            &a,
            &mut args,
            &mut cfg,
            &mut trials,
            &mut seeds,
            &mut objects,
        );
        if let Err(e) = r {
            eprintln!("active_tuning: {e}");
            return ExitCode::FAILURE;
        }
    }
    cfg.trials_per_alpha = trials / cfg.alphas_deg.len();
    cfg.active_trials = trials;
    let mut work = Vec::new();
    for name in &objects {
        let Ok(scenario) = Scenario::resolve(name) else {
            eprintln!("active_tuning: no scenario `{name}`");
            return ExitCode::FAILURE;
        };
        for &seed in &seeds {
            let mut c = cfg.clone();
            c.seed = seed;
            work.push((scenario.clone(), c));
        }
    }
    println!(
        "protocol {:?}, {trials} trials, {:?}, seeds {seeds:?}",
        cfg.protocol, cfg.active
    );
    let results = side_by_side(&work, |(scenario, c)| {
        run_object(scenario, c, &mut |_| {}).map(|r| {
            let met = r.targets().iter().all(|t| t.met);
            (
                r.prediction.rotation_error_deg.median,
                r.prediction.displacement_error_ratio.median,
                r.prediction.unpredicted,
                met,
                r.learning_wall_s + r.eval_wall_s,
            )
        })
    });
    let mut by_object: Vec<(String, f64, f64, usize, usize)> = Vec::new();
    for ((scenario, c), r) in work.iter().zip(results) {
        match r {
            Ok((rot, ratio, unpredicted, met, wall)) => {
                println!(
                    "{:<9} seed {:>3}: rotation {rot:5.2} deg, ratio {ratio:.3}, unpredicted {unpredicted}, {} ({wall:.1} s)",
                    scenario.name,
                    c.seed,
                    if met { "met" } else { "MISSED" }
                );
                match by_object.iter_mut().find(|o| o.0 == scenario.name) {
                    Some(o) => {
                        o.1 += if rot.is_finite() { rot } else { 0.0 };
                        o.2 += ratio;
                        o.3 += usize::from(met);
                        o.4 += 1;
                    }
                    None => by_object.push((
                        scenario.name.clone(),
                        if rot.is_finite() { rot } else { 0.0 },
                        ratio,
                        usize::from(met),
                        1,
                    )),
                }
            }
            Err(e) => println!("{} seed {}: {e}", scenario.name, c.seed),
        }
    }
    for (name, rot, ratio, met, n) in by_object {
        println!(
            "MEAN {name:<9} rotation {:5.2} deg, ratio {:.3}, every target met on {met} of {n}",
            rot / n as f64,
            ratio / n as f64
        );
    }
    ExitCode::SUCCESS
}
