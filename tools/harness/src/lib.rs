//! The harness: everything that runs the system to measure or judge it, and never runs
//! inside the pipeline. The benchmarks of `agp bench` (`bench_learn` with `learn_curve`,
//! `bench_tasks`, `bench_trajectory`, `bench_adapt`, `bench_online`, `bench_paper`, their
//! seeds in `seeds`, and `bench_merge`, which merges the parts of a run split into shards;
//! over private pipelines of real processes by `pipeline_bench` or in
//! process by `in_process`), the judge that scores a task by ground truth (`evaluation`),
//! `agp probe` (`probe`), the learning benchmark against the physics library
//! (`learn_bench`), the goals and paths of the task benchmarks (`task_goals`), and the
//! pieces of the benchmark binaries in `src/bin` (`hop`, `math`, `pipeline`, and `link_proxy`,
//! which cuts a bridge's link and restores it, and `watchdog_stops`, physics's watchdog stops
//! as its log says them), and
//! `side_by_side`, which spreads independent benchmark work over the cores, and `stop`, how a
//! bench stops on a signal (partial JSON, no file left) and sweeps what dead benches left.
//!
//! Ground truth is read here and in the physics library only (and by the `oracle` and
//! `model` planners, which say so).

pub mod bench_adapt;
pub mod bench_learn;
pub mod bench_merge;
pub mod bench_online;
pub mod bench_paper;
pub mod bench_tasks;
pub mod bench_trajectory;
pub mod evaluation;
pub mod hop;
pub mod in_process;
pub mod learn_bench;
pub mod learn_curve;
pub mod link_proxy;
pub mod math;
pub mod pipeline;
pub mod pipeline_bench;
pub mod probe;
pub mod seeds;
pub mod side_by_side;
pub mod stop;
pub mod task_goals;
mod task_plot;
pub mod watchdog_stops;

pub use in_process::{InProcessEpisodeError, InProcessWorld, run_episode, run_online_episode};
pub use task_goals::{PlannerSummary, median, place_goals, trajectory_error};

/// Writes one line to stdout; a closed stdout is no reason to panic (the SIGPIPE it raises
/// stops `agp` cleanly).
pub fn say(line: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}
