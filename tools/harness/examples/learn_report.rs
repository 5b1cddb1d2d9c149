//! The learning phase (benchmarks.md section 1) in-process against `agp_physics::Sim`:
//! for each object, one circling for the shape, 60 trials per alpha in {0, +15, -15},
//! then 200 unseen pushes to check the predictions and the poses from the trials'
//! circlings, against the simulator's ground truth.
//!
//! `cargo run --release -p agp-harness --example learn_report -- [OBJECT|FILE ...]
//!  [--seed N] [--trials N] [--method front-ir-mean|body-sweep|heading-line] [--eval N] [--push-s S]
//!  [--alphas 0,15,-15]
//!  [--no-approach-points] [--circle-defaults] [--save-dir DIR]`

use std::process::ExitCode;
use std::time::Instant;

use agp_harness::learn_bench::{LearnBenchConfig, format_report, run_object};
use agp_perception::ContactMethod;
use agp_world::Scenario;

fn main() -> ExitCode {
    let mut cfg = LearnBenchConfig::default();
    let mut objects = Vec::new();
    let mut save_dir: Option<std::path::PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |flag: &str| args.next().ok_or_else(|| format!("`{flag}` needs a value"));
        let result: Result<(), String> = match a.as_str() {
            "--seed" => value("--seed").and_then(|v| {
                v.parse()
                    .map(|s| cfg.seed = s)
                    .map_err(|e| format!("bad seed `{v}`: {e}"))
            }),
            "--trials" => value("--trials").and_then(|v| {
                v.parse()
                    .map(|n| cfg.trials_per_alpha = n)
                    .map_err(|e| format!("bad count `{v}`: {e}"))
            }),
            "--eval" => value("--eval").and_then(|v| {
                v.parse()
                    .map(|n| cfg.eval_pushes = n)
                    .map_err(|e| format!("bad count `{v}`: {e}"))
            }),
            "--push-s" => value("--push-s").and_then(|v| {
                v.parse()
                    .map(|t| cfg.push.push_duration = t)
                    .map_err(|e| format!("bad duration `{v}`: {e}"))
            }),
            "--alphas" => value("--alphas").and_then(|v| {
                v.split(',')
                    .map(|a| a.trim().parse::<f64>())
                    .collect::<Result<Vec<_>, _>>()
                    .map(|a| cfg.alphas_deg = a)
                    .map_err(|e| format!("bad alphas `{v}`: {e}"))
            }),
            "--method" => value("--method").and_then(|v| {
                ContactMethod::ALL
                    .iter()
                    .find(|m| m.name() == v)
                    .map(|m| cfg.contact_method = *m)
                    .ok_or_else(|| format!("unknown method `{v}`"))
            }),
            "--save-dir" => value("--save-dir").map(|v| save_dir = Some(v.into())),
            "--circle-defaults" => {
                cfg.circle = agp_planning::CircleSettings::default();
                Ok(())
            }
            "--no-approach-points" => {
                cfg.approach_refines_shape = false;
                Ok(())
            }
            flag if flag.starts_with("--") => Err(format!("unknown flag `{flag}`")),
            name_or_file => Scenario::resolve(name_or_file)
                .map(|s| objects.push(s))
                .map_err(|e| e.to_string()),
        };
        if let Err(e) = result {
            eprintln!("learn_report: error: {e}");
            return ExitCode::FAILURE;
        }
    }
    if objects.is_empty() {
        objects = ["triangle", "square", "lshape", "circle"]
            .iter()
            .filter_map(|n| Scenario::builtin(n))
            .collect();
    }
    println!(
        "learning phase: seed {}, {} trials per alpha, {} unseen pushes, push {:.1} s at {:.0} mm/s, contact method {}",
        cfg.seed,
        cfg.trials_per_alpha,
        cfg.eval_pushes,
        cfg.push.push_duration,
        cfg.push.push_speed * 1e3,
        cfg.contact_method.name()
    );
    let wall = Instant::now();
    for scenario in &objects {
        let name = &scenario.name;
        let r = match run_object(scenario, &cfg, &mut |_| {}) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("learn_report: error: {e}");
                return ExitCode::FAILURE;
            }
        };
        print!("{}", format_report(&r));
        if let Some(dir) = &save_dir {
            let path = dir.join(format!("{name}.ag"));
            if let Err(e) = r.gradient.save(&path) {
                eprintln!("learn_report: error: cannot save `{}`: {e}", path.display());
                return ExitCode::FAILURE;
            }
            println!("saved {}", path.display());
        }
    }
    println!("total wall time {:.1} s", wall.elapsed().as_secs_f64());
    ExitCode::SUCCESS
}
