//! The learning phase (benchmarks.md section 1) in-process against `agp_physics::Sim`:
//! for each object, one circling for the shape, 60 trials per alpha in {0, +15, -15},
//! then 200 unseen pushes to check the predictions and the poses from the trials'
//! circlings, against the simulator's ground truth.
//!
//! `cargo run --release -p agp-estimator --example learn_report -- [OBJECT ...]
//!  [--seed N] [--method front-ir-mean|body-sweep|heading-line] [--eval N] [--push-s S]
//!  [--alphas 0,15,-15]
//!  [--no-approach-points] [--circle-defaults] [--save-dir DIR]`

#[path = "../tests/harness/mod.rs"]
mod harness;

use std::process::ExitCode;
use std::time::Instant;

use agp_estimator::ContactMethod;

fn main() -> ExitCode {
    let mut cfg = harness::HarnessConfig::default();
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
                cfg.circle = agp_planner::CircleSettings::default();
                Ok(())
            }
            "--no-approach-points" => {
                cfg.approach_refines_shape = false;
                Ok(())
            }
            name if agp_world::BUILTIN_NAMES.contains(&name) => {
                objects.push(name.to_owned());
                Ok(())
            }
            other => Err(format!(
                "unknown argument `{other}` (objects: {})",
                agp_world::BUILTIN_NAMES.join(", ")
            )),
        };
        if let Err(e) = result {
            eprintln!("learn_report: error: {e}");
            return ExitCode::FAILURE;
        }
    }
    if objects.is_empty() {
        objects = ["triangle", "square", "lshape", "circle"]
            .map(String::from)
            .to_vec();
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
    for name in &objects {
        let r = harness::run_object(name, &cfg);
        print!("{}", harness::format_report(&r));
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
