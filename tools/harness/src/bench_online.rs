//! `agp bench online` (issue 33, item 2): place an object never pushed before. No learning phase, no AG file: each episode's estimator starts from nothing, builds the gradient from the contact prior of the episode's first circling and learns on from the episode's own pushes, while the affordance planner places the object on each set it publishes.
//!
//! The goals are `agp bench place`'s for the same scenario and seed, so its learn-first
//! figures (`agp bench place --planners affordance`) stand beside these; the JSON is the
//! place benchmark's, with `"learn": "online"`.

use std::path::PathBuf;

use agp_planning::PlannerKind;
use anyhow::Result;
use serde_json::Value;

use crate::bench_tasks::{self, BenchPlaceArgs};
use crate::seeds::SeedArgs;

/// The options of `agp bench online`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchOnlineArgs {
    /// Scenario file (or built-in) of the object never pushed before.
    #[arg(long, default_value = "libs/world/scenarios/pentagon.toml")]
    pub scenario: String,
    /// Episodes per seed: `agp bench place`'s goals, 250 to 500 mm from the start, any
    /// orientation; each episode learns from nothing.
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// Seeds of the goals and of the sensor noise.
    #[command(flatten)]
    pub seeds: SeedArgs,
    /// Also write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the first episode at the first seed to this SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Step the physics library and the estimator's perception (the same tracker, prior
    /// and online learning) in this process instead of over the pipeline: faster, for
    /// tuning; the reported figures run over the pipeline.
    #[arg(long)]
    pub in_process: bool,
}

/// Runs the benchmark: the affordance planner, learning online from the contact prior.
pub fn run(args: &BenchOnlineArgs) -> Result<Value> {
    bench_tasks::run_place_learning(
        &BenchPlaceArgs {
            scenario: args.scenario.clone(),
            episodes: args.episodes,
            seeds: args.seeds.clone(),
            planners: vec![PlannerKind::Affordance],
            ag: None,
            in_process: args.in_process,
            json: args.json.clone(),
            plot: args.plot.clone(),
        },
        true,
    )
}
