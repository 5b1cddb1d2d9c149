//! The planner process: chooses and carries out pushes.

mod grid_link;
mod learn_mode;
mod push_service;
mod ring;
mod serve_mode;
mod task_mode;

use std::time::Duration;

use agp_planning::PlannerKind;
use agp_runtime::{Instance, alloc_count, install_shutdown_handler};
use agp_shared_types::{Pose2, TaskKind};
use agp_world::Scenario;
use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Mode {
    /// The learning phase (benchmarks.md section 1) over the real pipeline: circle the
    /// object for its shape, then push it from every side at each alpha, telling the
    /// estimator each step of the protocol; ends when the estimator reports the gradients
    /// learned and saved. Needs physics and `agp-estimator` in lockstep.
    Learn,
    /// The placement task (benchmarks.md section 3): the paper's Algorithm 5 puts the
    /// object at the goal (`--goal`, else the scenario's) within the scenario's tolerance,
    /// knowing it through IR only. The affordance and oracle planners take the gradient
    /// from the estimator's grids. Ends when the planner's estimate says it is done.
    Place,
    /// The trajectory task (benchmarks.md section 2): push the object's centroid along the
    /// scenario's path (`path_mm`, else 600 mm along +x from the object's start).
    Trajectory,
    /// A live session: pursue the goals `agp goal` queues, one after the other (place or
    /// trajectory), telling the supervisor when each ended so the judge scores it; wait
    /// with the wheels stopped between goals; serve until `agp down`. Runs on either
    /// clock (launch-live.toml: realtime).
    Serve,
}

/// Chooses pushes and drives the robot.
///
/// Every option can also come from the environment the supervisor sets (`AGP_INSTANCE`,
/// `AGP_SCENARIO`, `AGP_CLOCK`).
#[derive(Debug, Parser)]
#[command(name = "agp-planner", version)]
struct Args {
    /// Instance name, shared with the other processes of the pipeline.
    #[arg(long, env = "AGP_INSTANCE")]
    instance: String,
    /// Built-in scenario or scenario file (the same physics runs).
    #[arg(long, env = "AGP_SCENARIO", default_value = "triangle")]
    scenario: String,
    /// Clock mode of the pipeline: learning needs `lockstep`.
    #[arg(long, env = "AGP_CLOCK", default_value = "lockstep")]
    clock: String,
    /// What to do. (The scripted drive of earlier builds is the harness's
    /// `agp-scripted-drive`: it perceives, which the planner never does.)
    #[arg(long, value_enum)]
    mode: Mode,
    /// Push duration after contact, milliseconds (default: 500, the learning bench's).
    #[arg(long)]
    push_ms: Option<u64>,
    /// Learn: trials per alpha, evenly spread round the object (60: one every 6 deg).
    #[arg(long, default_value_t = 60)]
    trials_per_alpha: u32,
    /// Place, trajectory: which planner decides (`oracle` reads the object's true pose;
    /// `model`, a quasi-static pushing model, its true pose, shape, mass and frictions).
    #[arg(long, default_value = "affordance")]
    planner: PlannerKind,
    /// Place: the goal, `X_MM,Y_MM,THETA_DEG` in the world frame (default: the scenario's).
    #[arg(long, value_parser = parse_goal, allow_hyphen_values = true)]
    goal: Option<Pose2>,
    /// Trajectory: the path, `X_MM,Y_MM` points in the world frame (default: the
    /// scenario's). `agp bench trajectory` hands each episode its path this way.
    #[arg(long, num_args = 2.., value_parser = parse_point, allow_hyphen_values = true)]
    path: Vec<[f64; 2]>,
    /// Trajectory: keep the object's heading tangent to the path within this many degrees,
    /// in (0, 180] (default: the scenario's `keep_heading_deg`, else the heading is free).
    #[arg(long, value_name = "DEG", value_parser = parse_heading)]
    keep_heading: Option<f64>,
    /// Place, trajectory: run the learning phase first when the AG file
    /// `<results>/<object>.ag` is missing (run the estimator with `--reuse`, which then
    /// learns; it publishes the saved gradients when the file is there).
    #[arg(long)]
    learn_if_missing: bool,
    /// Place, trajectory: an object never pushed before. No AG file, no learning phase:
    /// the episode starts without a gradient, circles the object first, and plans on the
    /// prior the estimator builds from that circling's contact geometry, then on each set
    /// it publishes as it learns the task's pushes (run the estimator with
    /// `--learn-online --from-prior`). Needs `--planner affordance`.
    #[arg(long, conflicts_with = "learn_if_missing")]
    from_prior: bool,
    /// Folder of the AG files (`<object>.ag`).
    #[arg(long, env = "AGP_RESULTS", default_value = "results")]
    results: std::path::PathBuf,
    /// Print every estimate and push on stderr.
    #[arg(long)]
    trace: bool,
    /// Place, trajectory: also write the planner's account of the episode (how it ended,
    /// pushes, circlings, times, its last estimate; no ground truth) as JSON to this file.
    #[arg(long)]
    report: Option<std::path::PathBuf>,
    /// The epoch this planner drives at. 0: from the start. Set by the supervisor for a hot
    /// swap: the planner then tells it when it is ready, waits for its epoch to become
    /// active, and reports its first applied command.
    #[arg(long, env = "AGP_EPOCH", default_value_t = 0)]
    epoch: u64,
    /// Physics steps per second (paces the idle steps of `serve` on the lockstep clock).
    #[arg(long, env = "AGP_RATE_HZ", default_value_t = 640.0)]
    rate_hz: f64,
    /// Place, serve: a push-level planner of another process chooses every push (the
    /// `agp` Python package's `PushPlanner`, whose `agp.run` starts this planner so);
    /// this planner carries the pushes out (travel, push, circling) and asks on
    /// `agp/push_requests`, answered on `agp/push_choices`. Needs `--planner affordance`.
    #[arg(long)]
    skills: bool,
    /// Only check that these arguments fit the clock, then exit: 0 they do, 2 they do not
    /// (the reason on stderr). `agp up` runs it before it starts anything.
    #[arg(long)]
    check: bool,
}

/// Why these arguments cannot run on the pipeline's clock, if they cannot: the learning
/// phase resets the world between steps and times its pushes by steps, so it needs the
/// lockstep clock; the tasks run on either.
fn clock_refusal(args: &Args) -> Option<String> {
    if args.clock == "lockstep" {
        return None;
    }
    if args.clock != "realtime" {
        return Some(format!(
            "unknown clock `{}`; expected `lockstep` or `realtime`",
            args.clock
        ));
    }
    match args.mode {
        Mode::Learn => Some("`--mode learn` (the learning phase) needs the lockstep clock".to_owned()),
        Mode::Place | Mode::Trajectory | Mode::Serve if args.learn_if_missing => Some(
            "`--learn-if-missing` may run the learning phase, which needs the lockstep clock: learn first (`agp up` with launch.toml, or `agp bench learn`), then run without it".to_owned(),
        ),
        Mode::Place | Mode::Trajectory | Mode::Serve => None,
    }
}

/// Safety net of the waits on other processes.
const TIMEOUT: Duration = Duration::from_secs(30);

/// `X_MM,Y_MM,THETA_DEG` as a world-frame pose in metres and radians.
/// `X_MM,Y_MM` in metres.
fn parse_point(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}; expected X_MM,Y_MM"))?;
    match v[..] {
        [x, y] if x.is_finite() && y.is_finite() => Ok([x * 1e-3, y * 1e-3]),
        _ => Err(format!("`{s}`: expected two finite numbers X_MM,Y_MM")),
    }
}

fn parse_heading(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v <= 180.0 => Ok(v),
        Ok(v) => Err(format!(
            "a heading tolerance is in (0, 180] degrees, got {v}"
        )),
        Err(_) => Err(format!("`{s}` is not a number of degrees")),
    }
}

fn parse_goal(s: &str) -> Result<Pose2, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}; expected X_MM,Y_MM,THETA_DEG"))?;
    match v[..] {
        [x, y, t] if v.iter().all(|a| a.is_finite()) => {
            Ok(Pose2::new(x * 1e-3, y * 1e-3, t.to_radians()))
        }
        _ => Err(format!(
            "`{s}`: expected three finite numbers X_MM,Y_MM,THETA_DEG"
        )),
    }
}

/// Counts heap allocations by region when `AGP_COUNT_ALLOCS=1` (see
/// [`agp_runtime::alloc_count`]).
#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

fn main() {
    agp_runtime::quiet_iceoryx2();
    alloc_count::enable_from_env();
    let result = {
        // Everything but the calls into iceoryx2 (booked by the lockstep driver and the
        // estimator link) is the planner's own work.
        let _planning = alloc_count::enter(alloc_count::Region::Work);
        run()
    };
    alloc_count::report("agp-planner", "planning", "frames");
    if let Err(e) = result {
        eprintln!("agp-planner: error: {e:#}");
        std::process::exit(1);
    }
}

fn run() -> Result<()> {
    let args = Args::parse();
    if let Some(reason) = clock_refusal(&args) {
        if args.check {
            eprintln!("agp-planner: {reason} (the clock is `{}`)", args.clock);
            std::process::exit(2);
        }
        bail!("{reason}, not `{}`", args.clock);
    }
    if args.skills
        && (args.planner != PlannerKind::Affordance
            || !matches!(args.mode, Mode::Place | Mode::Serve))
    {
        bail!(
            "`--skills` serves a push-level planner with `--mode place` or `--mode serve` and `--planner affordance`"
        );
    }
    if args.from_prior
        && (args.planner != PlannerKind::Affordance
            || !matches!(args.mode, Mode::Place | Mode::Trajectory))
    {
        bail!(
            "`--from-prior` places (or pushes along a path) an object never pushed before with `--planner affordance`"
        );
    }
    if args.check {
        return Ok(());
    }
    install_shutdown_handler();
    let full = Scenario::resolve(&args.scenario)?;
    // The planner reads the brief (the name, the robot, the task), and the experimenter's
    // knowledge for the learning protocol; nothing else of the object.
    let (scenario, experimenter) = (full.brief(), full.experimenter());
    // The `model` planner reads the object's truth too (its shape, mass and frictions) for
    // its pushing model, and says so; no other planner gets it.
    let model = (args.planner == PlannerKind::Model).then(|| {
        std::sync::Arc::new(agp_planning::PushModel::from_scenario(
            &full,
            &agp_world::RobotDescription::epuck(),
        ))
    });
    drop(full);
    let instance = Instance::new(&args.instance)
        .with_context(|| format!("bad instance name `{}`", args.instance))?;
    match args.mode {
        Mode::Learn => {
            let settings = learn_mode::LearnSettings::new(
                args.trials_per_alpha,
                args.push_ms.unwrap_or(500),
                TIMEOUT,
            );
            learn_mode::run(&instance, &scenario, experimenter, args.epoch, &settings)
        }
        Mode::Place | Mode::Trajectory | Mode::Serve => {
            let ag_file = args.results.join(format!("{}.ag", scenario.name));
            if args.learn_if_missing && args.epoch == 0 && !ag_file.exists() {
                println!(
                    "planner: no AG file at {}: learning `{}` first",
                    ag_file.display(),
                    scenario.name
                );
                let settings = learn_mode::LearnSettings::new(
                    args.trials_per_alpha,
                    args.push_ms.unwrap_or(500),
                    TIMEOUT,
                );
                learn_mode::run(&instance, &scenario, experimenter, args.epoch, &settings)?;
                if agp_runtime::shutdown_requested() {
                    return Ok(());
                }
            }
            let kind = if args.mode == Mode::Trajectory {
                TaskKind::Trajectory
            } else {
                TaskKind::Place
            };
            let settings = task_mode::TaskSettings {
                planner: args.planner,
                task: match task_mode::task_of(&scenario, kind, args.goal) {
                    agp_planning::Task::Trajectory {
                        path,
                        keep_heading_rad,
                    } => agp_planning::Task::Trajectory {
                        path: if args.path.is_empty() {
                            path
                        } else {
                            args.path
                                .iter()
                                .map(|p| glam::DVec2::from_array(*p))
                                .collect()
                        },
                        keep_heading_rad: args
                            .keep_heading
                            .map(f64::to_radians)
                            .or(keep_heading_rad),
                    },
                    task => task,
                },
                epoch: args.epoch,
                realtime: args.clock == "realtime",
                timeout: TIMEOUT,
                gradient_timeout: Duration::from_secs(120),
                ag_file,
                trace: args.trace,
                skills: args.skills,
                model,
                from_prior: args.from_prior,
            };
            if args.mode == Mode::Serve {
                let paced = args.clock == "lockstep";
                return serve_mode::run(&instance, &scenario, &settings, paced, args.rate_hz);
            }
            let result = task_mode::run(&instance, &scenario, &settings)?;
            if let (Some(path), Some(r)) = (&args.report, &result) {
                task_mode::write_report(path, r)?;
            }
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(words: &[&str]) -> Args {
        Args::parse_from(
            ["agp-planner", "--instance", "t"]
                .iter()
                .chain(words)
                .copied(),
        )
    }

    #[test]
    fn the_tasks_run_on_either_clock_and_learning_needs_lockstep() {
        for clock in ["lockstep", "realtime"] {
            for mode in ["place", "trajectory"] {
                assert_eq!(
                    clock_refusal(&args(&["--clock", clock, "--mode", mode])),
                    None,
                    "{mode} on {clock}"
                );
            }
        }
        for words in [
            &["--mode", "learn"][..],
            &["--mode", "place", "--learn-if-missing"][..],
        ] {
            let mut w = vec!["--clock", "realtime"];
            w.extend_from_slice(words);
            assert!(clock_refusal(&args(&w)).is_some(), "{words:?} on realtime");
            let mut w = vec!["--clock", "lockstep"];
            w.extend_from_slice(words);
            assert_eq!(clock_refusal(&args(&w)), None, "{words:?} on lockstep");
        }
    }
}
