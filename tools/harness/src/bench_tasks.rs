//! `agp bench place` and `agp bench trajectory`: the paper's two tasks (benchmarks.md
//! sections 2 and 3) over many episodes, each planner on the same goals and seeds.
//!
//! Episodes run over the real pipeline by default ([`PipelineBench`]: lockstep
//! `agp-physics`, `agp-estimator` serving the AG file, an `agp-planner` process per
//! episode, ground truth read by the benchmark only); `--in-process` steps the physics
//! library directly instead (the same planner logic and simulator, no transport), and every
//! output says which.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::seeds::Spread;
use crate::{median, place_goals, run_episode, run_online_episode};
use agp_affordance::AffordanceGradient;
use agp_planning::{EpisodeConfig, EpisodeResult, Evaluation, PlannerKind, Task};
use agp_shared_types::Pose2;
use agp_world::{RobotDescription, Scenario};
use anyhow::{Context, Result, bail};

use crate::bench_learn;
use crate::pipeline_bench::{PipelineBench, SLOTS_ENV};
use crate::side_by_side::side_by_side;
use crate::stop;
use crate::task_plot::{Overlay, Panel, plot_runs};
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{Map, Value, json};

use crate::seeds::{
    SeedArgs, SeedParts, Shard, finish_seed_doc, finite_or_null, merge_parts, number_at, run_parts,
    seed_list, spread_at, write_json,
};

/// What every bench output says about where the physics ran.
const PIPELINE_NOTE: &str =
    "over the pipeline (agp-physics, agp-estimator, one agp-planner per episode, iceoryx2)";
const IN_PROCESS_NOTE: &str = "physics in-process (agp_physics library, no iceoryx2)";
const ORACLE_NOTE: &str = "`oracle` reads the object's true pose (ground truth): an upper bound";
pub(crate) const MODEL_NOTE: &str = "`model` reads the object's true pose, shape, mass and frictions (ground truth): a quasi-static pushing model with an ellipsoidal limit surface, the classical method";

/// The options of `agp bench place`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchPlaceArgs {
    /// Built-in scenario (triangle, lshape, square, circle) or a scenario file.
    #[arg(long, default_value = "triangle")]
    pub scenario: String,
    /// Episodes per planner: random goals 250 to 500 mm from the start, any orientation.
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// Seeds of the goals and of the sensor noise: each seed its own goals and episodes.
    #[command(flatten)]
    pub seeds: SeedArgs,
    /// Planners to run, comma-separated: affordance, baseline, oracle, model.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "affordance,baseline,oracle,model"
    )]
    pub planners: Vec<PlannerKind>,
    /// Affordance gradient file learned from IR (default: `results/learn/<object>.ag`,
    /// learned first with `agp bench learn` when missing).
    #[arg(long)]
    pub ag: Option<PathBuf>,
    /// Step the physics library in-process instead of running the pipeline's processes
    /// (the same planner logic and simulator; faster, no transport).
    #[arg(long)]
    pub in_process: bool,
    /// Also write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Also draw the first episode of each planner at the first seed (object every few
    /// steps, goal outline, as the paper's Fig. 7) to this SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// The AG file the affordance and oracle planners use: `path`, or the learning
/// benchmark's file for the object, learned first (and said so) when it is missing.
/// `None` when no planner of `needed_by` needs one.
pub fn resolve_ag(
    path: Option<&Path>,
    scenario_arg: &str,
    scenario: &Scenario,
    needed_by: &[PlannerKind],
) -> Result<Option<PathBuf>> {
    if !needed_by.iter().any(|k| k.needs_gradient()) {
        return Ok(None);
    }
    if let Some(path) = path {
        if !path.is_file() {
            bail!("--ag {}: no such file", path.display());
        }
        return Ok(Some(path.to_owned()));
    }
    let out = PathBuf::from(bench_learn::DEFAULT_OUT);
    let learned = bench_learn::ag_path(&out, scenario);
    if !learned.is_file() {
        eprintln!(
            "no affordance gradient of `{}` at {}: learning it first (agp bench learn --scenario {scenario_arg})",
            scenario.name,
            learned.display()
        );
        bench_learn::run(&bench_learn::BenchLearnArgs::for_scenarios(
            &[scenario_arg],
            out,
        ))?;
    }
    Ok(Some(learned))
}

/// Where episodes run.
#[expect(
    clippy::large_enum_variant,
    reason = "one per benchmark run; boxing buys nothing"
)]
pub(crate) enum Runner<'a> {
    InProcess {
        scenario: &'a Scenario,
        robot: RobotDescription,
        ag: Option<AffordanceGradient>,
        /// An object never pushed: each episode's tracker starts from the contact prior
        /// ([`run_online_episode`]).
        online: bool,
    },
    Pipeline(PipelineBench),
}

impl<'a> Runner<'a> {
    /// A runner for `planner`'s episodes: each (planner, seed) gets a fresh physics seeded
    /// with `seed`, so its results do not depend on what ran before it. Over the pipeline
    /// its instance is `bench-<pid>-<tag>`: short (iceoryx2's socket paths), and telling
    /// apart the pipelines that run at once.
    /// `cost`: the pair's expected work ([`expected_sim_s`] summed over its episodes), its
    /// place in the queue when pipelines share slots.
    pub(crate) fn start_tagged(
        plan: &EpisodePlan<'a>,
        planner: PlannerKind,
        seed: u64,
        tag: &str,
        cost: u64,
    ) -> Result<Self> {
        let EpisodePlan {
            in_process,
            scenario_arg,
            scenario,
            ag,
            online,
            ..
        } = *plan;
        let ag = ag.filter(|_| planner.needs_gradient());
        if online && !in_process {
            return Ok(Self::Pipeline(PipelineBench::start_online(
                scenario_arg,
                seed,
                tag,
                cost,
            )?));
        }
        if in_process {
            let ag = ag
                .map(|p| {
                    AffordanceGradient::load_for(p, &scenario.name).with_context(|| {
                        format!("cannot load the affordance gradient `{}`", p.display())
                    })
                })
                .transpose()?;
            Ok(Self::InProcess {
                scenario,
                robot: RobotDescription::epuck(),
                ag,
                online,
            })
        } else {
            Ok(Self::Pipeline(PipelineBench::start(
                scenario_arg,
                ag,
                seed,
                tag,
                cost,
            )?))
        }
    }

    pub(crate) fn episode(
        &mut self,
        planner: PlannerKind,
        task: &Task,
        config: &EpisodeConfig,
    ) -> Result<EpisodeResult> {
        match self {
            Self::InProcess {
                scenario,
                robot,
                online: true,
                ..
            } => Ok(run_online_episode(scenario, robot, planner, task, config)?),
            Self::InProcess {
                scenario,
                robot,
                ag,
                online: false,
            } => Ok(run_episode(
                scenario,
                robot,
                ag.as_ref(),
                planner,
                task,
                config,
            )?),
            Self::Pipeline(bench) => bench.episode(planner, task, config),
        }
    }

    pub(crate) fn finish(self) -> Result<()> {
        match self {
            Self::InProcess { .. } => Ok(()),
            Self::Pipeline(bench) => {
                if bench.truth_gaps > 0 {
                    eprintln!(
                        "note: the evaluation missed {} ground-truth samples (its buffer overflowed); the recorded paths have gaps there",
                        bench.truth_gaps
                    );
                }
                bench.stop()
            }
        }
    }
}

/// What the episode loop of `agp bench place` and `agp bench trajectory` needs to run its
/// (seed, planner) pairs ([`run_episodes`]).
pub(crate) struct EpisodePlan<'a> {
    /// `place` or `trajectory`, for the progress lines.
    pub benchmark: &'static str,
    pub in_process: bool,
    pub scenario_arg: &'a str,
    pub scenario: &'a Scenario,
    pub ag: Option<&'a Path>,
    /// Whether several seeds run side by side (each pipeline's tag then holds its seed).
    pub several_seeds: bool,
    /// An object never pushed: each episode's estimator starts from nothing and the
    /// affordance planner plans on its contact prior ([`PipelineBench::start_online`]).
    pub online: bool,
    pub bar: &'a ProgressBar,
}

/// One (seed, planner) pair's episodes: every one of them, or those finished before a stop.
pub(crate) struct PairRun {
    pub results: Vec<EpisodeResult>,
    /// Its wall time, s.
    pub wall_s: f64,
}

/// The episode loop of the task benchmarks: each (seed, planner) of `work` gets a runner
/// of its own (a freshly seeded pipeline, side by side on the cores) and runs the episodes
/// `episodes(seed)` gives (a label for errors, the task, its config), in order.
///
/// A stop ([`stop::requested`]) is checked between episodes and ends the episode under
/// way early (its planner is stopped); the pair then keeps the episodes it finished, its
/// pipeline is stopped and its files removed, and the outcome is `Ok`: the caller writes
/// the partial result. After each episode `progress` gets what every pair finished so far
/// (in the order of `work`, with its wall time) and how many episodes that is: the
/// benchmark's checkpoint. When the progress bar is hidden (stderr is not a terminal), each
/// finished episode is said on one line of stderr instead.
pub(crate) fn run_episodes(
    plan: &EpisodePlan<'_>,
    work: &[(u64, PlannerKind)],
    episodes: impl Fn(u64) -> Vec<(String, Task, EpisodeConfig)> + Sync,
    progress: impl Fn(&[(&[EpisodeResult], f64)], usize) + Sync,
) -> Result<Vec<PairRun>> {
    let done: std::sync::Mutex<Vec<(Vec<EpisodeResult>, f64)>> =
        std::sync::Mutex::new(vec![(Vec::new(), 0.0); work.len()]);
    let note_done = |index: usize, r: &EpisodeResult, wall_s: f64| {
        let mut done = done
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(slot) = done.get_mut(index) {
            slot.0.push(r.clone());
            slot.1 = wall_s;
        }
        let view: Vec<(&[EpisodeResult], f64)> =
            done.iter().map(|(r, w)| (r.as_slice(), *w)).collect();
        let finished = done.iter().map(|(r, _)| r.len()).sum();
        progress(&view, finished);
    };
    let run_pair = |&(seed, planner): &(u64, PlannerKind)| -> Result<PairRun> {
        let index = work.iter().position(|&w| w == (seed, planner)).unwrap_or(0);
        let started = Instant::now();
        let tasks = episodes(seed);
        let cost: f64 = tasks
            .iter()
            .map(|(_, task, _)| expected_sim_s(planner, task))
            .sum();
        let mut results = Vec::with_capacity(tasks.len());
        if stop::requested() {
            return Ok(PairRun {
                results,
                wall_s: 0.0,
            });
        }
        let tag = instance_tag(planner, seed, plan.several_seeds);
        let mut runner = match Runner::start_tagged(plan, planner, seed, &tag, cost as u64) {
            Ok(r) => r,
            Err(_) if stop::requested() => {
                return Ok(PairRun {
                    results,
                    wall_s: started.elapsed().as_secs_f64(),
                });
            }
            Err(e) => return Err(e),
        };
        let outcome = (|| -> Result<()> {
            for (k, (label, task, config)) in tasks.iter().enumerate() {
                if stop::requested() {
                    break;
                }
                match runner.episode(planner, task, config) {
                    Ok(r) => {
                        // Checkpointed first: once the line says an episode is done, the
                        // JSON on disk holds it.
                        note_done(index, &r, started.elapsed().as_secs_f64());
                        if plan.bar.is_hidden() {
                            eprintln!(
                                "bench {}: planner {planner}, seed {seed}: {label} done ({} of {}, {})",
                                plan.benchmark,
                                k + 1,
                                tasks.len(),
                                r.end.name()
                            );
                        }
                        results.push(r);
                        plan.bar.inc(1);
                    }
                    Err(_) if stop::requested() => break,
                    Err(e) => {
                        return Err(e.context(format!("planner `{planner}`, seed {seed}, {label}")));
                    }
                }
            }
            Ok(())
        })();
        // Stopped and cleaned up whatever happened: a failed episode leaves no file.
        let finished = runner.finish();
        outcome?;
        finished?;
        Ok(PairRun {
            results,
            wall_s: started.elapsed().as_secs_f64(),
        })
    };
    let shared_slots = !plan.in_process && std::env::var_os(SLOTS_ENV).is_some();
    let outcomes = if shared_slots {
        // The slots bound the pipelines at once, over every bench sharing them: each pair
        // waits in their queue at once, the one of most work taking the next free slot.
        std::thread::scope(|scope| {
            let run_pair = &run_pair;
            let pairs: Vec<_> = work
                .iter()
                .map(|w| scope.spawn(move || run_pair(w)))
                .collect();
            pairs
                .into_iter()
                .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .collect::<Vec<_>>()
        })
    } else {
        side_by_side(work, run_pair)
    };
    outcomes.into_iter().collect()
}

/// The simulated seconds an episode of `task` typically takes with `planner`: what ranks
/// the (seed, planner) pairs waiting for a pipeline slot ([`PipelineBench::start`]). A
/// pinned pipeline's CPU time goes with its simulated time, at 11.6-12.9 ms a simulated
/// second for every planner and both tasks (`agp bench paper --seeds 5`, release, 8ff68ca,
/// the pairs no learning ran beside), so simulated seconds rank the pairs by their CPU
/// time. The figures: each planner's mean per episode (per path of the trajectory set) on
/// the tuning seeds, `agp bench paper` on seeds 1-4 (2026-11-27); that run had no model
/// planner, whose figures come from the 8ff68ca run (0.9 x the oracle's simulated time in
/// the placements, 138 s a path). Only the order in which pairs start depends on them,
/// never a result.
pub(crate) fn expected_sim_s(planner: PlannerKind, task: &Task) -> f64 {
    match (task, planner) {
        (Task::Trajectory { .. }, PlannerKind::Affordance) => 530.0,
        (Task::Trajectory { .. }, PlannerKind::Baseline) => 185.0,
        (Task::Trajectory { .. }, PlannerKind::Oracle | PlannerKind::Model) => 140.0,
        (Task::Place { .. }, PlannerKind::Affordance) => 140.0,
        (Task::Place { .. }, PlannerKind::Baseline) => 100.0,
        (Task::Place { .. }, PlannerKind::Oracle | PlannerKind::Model) => 53.0,
    }
}

/// The instance tag of `planner`'s pipeline: three letters, and the seed when several
/// seeds run side by side (two pipelines of one planner may then run at once).
pub(crate) fn instance_tag(planner: PlannerKind, seed: u64, several_seeds: bool) -> String {
    let short = planner.name().get(..3).unwrap_or(planner.name());
    if several_seeds {
        format!("{short}{seed}")
    } else {
        short.to_owned()
    }
}

/// The progress bar's label for planners that run side by side.
pub(crate) fn prefix_of(planners: &[PlannerKind]) -> String {
    planners
        .iter()
        .map(|p| p.name())
        .collect::<Vec<_>>()
        .join("+")
}

/// The evaluation of an episode both runners judged.
pub(crate) fn judged(r: &EpisodeResult) -> &Evaluation {
    r.evaluation
        .as_ref()
        .expect("both runners judge every episode against ground truth")
}

/// The JSON's `physics` field.
pub(crate) fn physics_label(in_process: bool) -> &'static str {
    if in_process { "in-process" } else { "pipeline" }
}

pub(crate) fn physics_note(in_process: bool) -> &'static str {
    if in_process {
        IN_PROCESS_NOTE
    } else {
        PIPELINE_NOTE
    }
}

pub(crate) fn progress(total: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    if let Ok(style) =
        ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} episodes {elapsed}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Runs `agp bench place`: every seed of this run (its shard's share with `--shard`), each
/// seed its own goals, each (seed, planner) its own freshly seeded pipeline side by side on
/// the cores; the one-seed documents merged by [`merge`] into the result.
pub fn run_place(args: &BenchPlaceArgs) -> Result<Value> {
    run_place_learning(args, false)
}

/// `agp bench place`, or with `online` `agp bench online` (issue 33): the same goals per
/// seed, each episode's estimator starting from nothing (no AG file) and the affordance
/// planner placing the object on the gradient it learns from the episode's own pushes.
/// The JSON says `"learn": "online"`.
pub(crate) fn run_place_learning(args: &BenchPlaceArgs, online: bool) -> Result<Value> {
    let wall = Instant::now();
    if args.episodes == 0 {
        bail!("`--episodes` must be at least 1");
    }
    if args.planners.is_empty() {
        bail!("`--planners` names no planner");
    }
    let scenario = Scenario::resolve(&args.scenario)
        .with_context(|| format!("cannot load scenario `{}`", args.scenario))?;
    let ag = if online {
        None
    } else {
        resolve_ag(
            args.ag.as_deref(),
            &args.scenario,
            &scenario,
            &args.planners,
        )?
    };
    // From here on the episode loops poll the stop flag.
    let _checked = stop::checked();
    let mut planners = args.planners.clone();
    planners.sort();
    planners.dedup();
    let place = PlaceRun {
        args,
        base: EpisodeConfig::for_task(&scenario.task),
        scenario: &scenario,
        seeds: args.seeds.mine(),
        planners,
        wall,
    };
    place.announce();
    let work: Vec<(u64, PlannerKind)> = place
        .seeds
        .iter()
        .flat_map(|&seed| place.planners.iter().map(move |&p| (seed, p)))
        .collect();
    let bar = progress((args.episodes * work.len()) as u64);
    bar.set_prefix(prefix_of(&place.planners));
    let plan = EpisodePlan {
        benchmark: "place",
        in_process: args.in_process,
        scenario_arg: &args.scenario,
        scenario: &scenario,
        ag: ag.as_deref(),
        several_seeds: place.seeds.len() > 1,
        online,
        bar: &bar,
    };
    let planned = args.episodes * work.len();
    let runs = run_episodes(
        &plan,
        &work,
        |seed| place.episodes(seed),
        |runs, finished| {
            if let Ok(doc) = place.partial_doc(runs) {
                stop::checkpoint(doc, args.json.as_deref(), "place", finished, planned);
            }
        },
    )?;
    bar.finish_and_clear();
    let runs: Vec<(&[EpisodeResult], f64)> = runs
        .iter()
        .map(|r| (r.results.as_slice(), r.wall_s))
        .collect();
    if stop::requested() {
        let finished: usize = runs.iter().map(|(r, _)| r.len()).sum();
        return Err(stop::write_partial(
            place.partial_doc(&runs)?,
            args.json.as_deref(),
            "place",
            finished,
            planned,
        ));
    }
    stop::end_checkpoints(args.json.as_deref(), "place");
    let mut doc = place.final_doc(&runs)?;
    if online {
        doc["learn"] = json!("online");
    }
    place.report(&doc, &runs)?;
    Ok(doc)
}

/// One run of `agp bench place` (or `agp bench online`): what its parts share.
struct PlaceRun<'a> {
    args: &'a BenchPlaceArgs,
    scenario: &'a Scenario,
    /// The episode config of the scenario's task, each episode's seed apart.
    base: EpisodeConfig,
    /// The seeds this run (its shard) runs.
    seeds: Vec<u64>,
    /// The planners, sorted, each once.
    planners: Vec<PlannerKind>,
    /// When the run started.
    wall: Instant,
}

impl PlaceRun<'_> {
    /// Says on stderr what runs, and what reads ground truth.
    fn announce(&self) {
        eprintln!(
            "bench place: scenario `{}`, {} episodes per planner and seed, seeds {}{}; {}",
            self.scenario.name,
            self.args.episodes,
            seed_list(&self.seeds),
            self.args.seeds.shard_note(),
            physics_note(self.args.in_process)
        );
        if self.planners.contains(&PlannerKind::Oracle) {
            eprintln!("{ORACLE_NOTE}");
        }
        if self.planners.contains(&PlannerKind::Model) {
            eprintln!("{MODEL_NOTE}");
        }
    }

    /// The episodes of `seed`: its goals, episode k seeded `seed + k`.
    fn episodes(&self, seed: u64) -> Vec<(String, Task, EpisodeConfig)> {
        place_goals(self.scenario, self.args.episodes, seed)
            .into_iter()
            .enumerate()
            .map(|(k, goal)| {
                let config = EpisodeConfig {
                    seed: seed.wrapping_add(k as u64),
                    ..self.base.clone()
                };
                (format!("episode {k}"), Task::Place { goal }, config)
            })
            .collect()
    }

    /// The one-seed documents of `runs` (the pairs of the work in order, each with the
    /// episodes it finished).
    fn seed_docs(&self, runs: &[(&[EpisodeResult], f64)]) -> Vec<Value> {
        self.seeds
            .iter()
            .zip(runs.chunks(self.planners.len()))
            .map(|(&seed, pairs)| {
                let goals = place_goals(self.scenario, self.args.episodes, seed);
                let mut planners_json = Map::new();
                let mut wall_s: f64 = 0.0;
                for (&planner, &(results, planner_wall_s)) in self.planners.iter().zip(pairs) {
                    wall_s = wall_s.max(planner_wall_s);
                    planners_json.insert(
                        planner.name().to_owned(),
                        planner_json(planner, seed, results, &goals),
                    );
                }
                json!({
                    "benchmark": "place",
                    "scenario": self.scenario.name,
                    "seed": seed,
                    "physics": physics_label(self.args.in_process),
                    "tolerance_mm": self.base.tolerance_m * 1e3,
                    "tolerance_deg": self.base.tolerance_rad.to_degrees(),
                    "planners": planners_json,
                    "wall_time_s": wall_s,
                })
            })
            .collect()
    }

    /// What finished, seeds of fewer episodes included: the checkpoints and a stop's JSON.
    fn partial_doc(&self, runs: &[(&[EpisodeResult], f64)]) -> Result<Value> {
        let parts = run_parts(
            &self.seed_docs(runs),
            "place",
            |_| Value::Null,
            self.args.seeds.all(),
        )?;
        let mut doc = assemble(&parts, self.args.seeds.shard);
        doc["wall_time_s"] = json!(self.wall.elapsed().as_secs_f64());
        Ok(doc)
    }

    /// Every seed finished: the run's document, its seeds checked alike.
    fn final_doc(&self, runs: &[(&[EpisodeResult], f64)]) -> Result<Value> {
        let parts = run_parts(
            &self.seed_docs(runs),
            "place",
            place_signature,
            self.args.seeds.all(),
        )?;
        let mut doc = assemble(&parts, self.args.seeds.shard);
        doc["wall_time_s"] = json!(self.wall.elapsed().as_secs_f64());
        Ok(doc)
    }

    /// Prints the table, writes the JSON and the plot, as asked.
    fn report(&self, doc: &Value, runs: &[(&[EpisodeResult], f64)]) -> Result<()> {
        print_place(doc, physics_note(self.args.in_process));
        let wall_time_s = doc["wall_time_s"]
            .as_f64()
            .unwrap_or_else(|| self.wall.elapsed().as_secs_f64());
        println!("wall time {wall_time_s:.1} s");
        if let Some(path) = &self.args.json {
            write_json(path, doc)?;
            println!("JSON     {}", path.display());
        }
        if let Some(path) = &self.args.plot {
            self.plot_first_episodes(path, runs)?;
            println!("plot     {}", path.display());
        }
        Ok(())
    }

    /// Draws the first episode of each planner at the first seed to `path`.
    fn plot_first_episodes(&self, path: &Path, runs: &[(&[EpisodeResult], f64)]) -> Result<()> {
        let seed = self.seeds[0];
        let first_seed_runs: BTreeMap<PlannerKind, &[EpisodeResult]> = self
            .planners
            .iter()
            .zip(runs)
            .map(|(&p, &(r, _))| (p, r))
            .collect();
        let panels: Vec<Panel> = first_seed_runs
            .iter()
            .filter_map(|(planner, runs)| {
                let r = runs.first()?;
                Some(Panel {
                    title: format!(
                        "{}{}: {} in {} pushes, {:.1} mm / {:.1} deg",
                        planner,
                        if planner.reads_ground_truth() {
                            " (ground truth)"
                        } else {
                            ""
                        },
                        if r.success() { "placed" } else { "not placed" },
                        r.pushes,
                        judged(r).position_error_mm,
                        judged(r).orientation_error_deg
                    ),
                    samples: &judged(r).samples,
                })
            })
            .collect();
        let goal = place_goals(self.scenario, 1, seed)[0];
        let title = format!(
            "place `{}`: first episode per planner at seed {seed}, goal outline in red ({})",
            self.scenario.name,
            physics_note(self.args.in_process)
        );
        plot_runs(
            path,
            &title,
            &self.scenario.object.shape,
            &panels,
            Overlay::Goal(goal),
        )
    }
}

/// One planner's episodes at one seed, as the JSON holds them: each run, and the figures
/// computed from the runs alone (as [`merge`] computes them over seeds).
fn planner_json(
    planner: PlannerKind,
    seed: u64,
    results: &[EpisodeResult],
    goals: &[Pose2],
) -> Value {
    let runs: Vec<Value> = results
        .iter()
        .zip(goals)
        .map(|(r, g)| {
            json!({
                "seed": seed,
                "goal_x_mm": g.x * 1e3,
                "goal_y_mm": g.y * 1e3,
                "goal_theta_deg": g.theta.to_degrees(),
                "success": r.success(),
                "end": r.end.name(),
                "position_error_mm": finite_or_null(judged(r).position_error_mm),
                "orientation_error_deg": finite_or_null(judged(r).orientation_error_deg),
                "pushes": r.pushes,
                "circlings": r.circlings,
                "sim_time_s": r.sim_time_s,
                "wall_time_s": r.wall_time_s,
                "estimate": r.estimate_verdict,
            })
        })
        .collect();
    summarise_runs(planner.reads_ground_truth(), runs)
}

/// The planner figures of the contract over `runs` (episodes of one or many seeds):
/// success rate, median errors and pushes (`median`: NaN-free values; none is null), sim
/// and wall time summed in the runs' order.
fn summarise_runs(reads_ground_truth: bool, runs: Vec<Value>) -> Value {
    let pick = |key: &str| {
        runs.iter()
            .map(|r| number_at(r, &[key]))
            .collect::<Vec<_>>()
    };
    let n = runs.len();
    let successes = runs.iter().filter(|r| r["success"] == true).count();
    let sum = |key: &str| pick(key).iter().filter(|v| v.is_finite()).sum::<f64>();
    json!({
        "episodes": n,
        "success_rate": if n == 0 { 0.0 } else { successes as f64 / n as f64 },
        "median_position_error_mm": finite_or_null(median(&pick("position_error_mm"))),
        "median_orientation_error_deg": finite_or_null(median(&pick("orientation_error_deg"))),
        "median_pushes": finite_or_null(median(&pick("pushes"))),
        "sim_time_s": sum("sim_time_s"),
        "wall_time_s": sum("wall_time_s"),
        "reads_ground_truth": reads_ground_truth,
        "runs": runs,
    })
}

/// The figures of the place JSON that get a spread over seeds.
const PLACE_FIGURES: [&str; 5] = [
    "success_rate",
    "median_position_error_mm",
    "median_orientation_error_deg",
    "median_pushes",
    "sim_time_s",
];

/// What must be alike in every seed of one place run.
fn place_signature(doc: &Value) -> Value {
    let planners: Map<String, Value> = doc["planners"]
        .as_object()
        .map(|m| {
            m.iter()
                .map(|(k, p)| (k.clone(), p["episodes"].clone()))
                .collect()
        })
        .unwrap_or_default();
    json!({
        "scenario": doc["scenario"],
        "physics": doc["physics"],
        "tolerance_mm": doc["tolerance_mm"],
        "tolerance_deg": doc["tolerance_deg"],
        "episodes per planner": planners,
    })
}

/// The place document of `parts`: every planner's figures over all episodes of all seeds,
/// each figure's spread over the seeds, `seeds`, `per_seed` (and `shard`). Its
/// `wall_time_s` is the longest seed's; the caller sets the run's own.
fn assemble(parts: &SeedParts, shard: Option<Shard>) -> Value {
    let docs: Vec<&Value> = parts.docs().collect();
    let first = docs[0];
    let mut planners = Map::new();
    if let Some(names) = first["planners"].as_object() {
        for (name, p) in names {
            let runs: Vec<Value> = docs
                .iter()
                .flat_map(|d| {
                    d["planners"][name]["runs"]
                        .as_array()
                        .cloned()
                        .unwrap_or_default()
                })
                .collect();
            let mut summary = summarise_runs(p["reads_ground_truth"] == true, runs);
            let spread: Map<String, Value> = PLACE_FIGURES
                .iter()
                .map(|f| {
                    (
                        (*f).to_owned(),
                        spread_at(docs.iter().copied(), &["planners", name, f]),
                    )
                })
                .collect();
            summary["spread"] = Value::Object(spread);
            planners.insert(name.clone(), summary);
        }
    }
    let mut doc = Map::new();
    doc.insert("benchmark".into(), json!("place"));
    doc.insert("scenario".into(), first["scenario"].clone());
    doc.insert("seed".into(), first["seed"].clone());
    doc.insert("physics".into(), first["physics"].clone());
    doc.insert("tolerance_mm".into(), first["tolerance_mm"].clone());
    doc.insert("tolerance_deg".into(), first["tolerance_deg"].clone());
    doc.insert("planners".into(), Value::Object(planners));
    finish_seed_doc(doc, parts, shard)
}

/// Merges place documents of disjoint seed sets (one-seed documents, whole runs or a run's
/// shards) into the document one run over all their seeds writes, seeds in order. Every
/// figure is recomputed from the episodes; `wall_time_s` is the longest part's.
pub fn merge(parts: &[Value]) -> Result<Value> {
    Ok(merge_parts(parts, "place", place_signature, assemble)?)
}

/// The human table of a place document: one row per planner, each figure as one seed's
/// value or `mean (min-max)` over the seeds.
pub fn print_place(doc: &Value, note: &str) {
    let lists = crate::seeds::SeedLists::of(doc);
    let docs = &lists.docs;
    let many = lists.own.len() > 1;
    let first = docs.first().copied().unwrap_or(doc);
    let episodes = first["planners"]
        .as_object()
        .and_then(|m| m.values().next())
        .map_or(0.0, |p| number_at(p, &["episodes"]));
    println!(
        "place `{}`: {episodes} episodes per planner and seed, {}, tolerance {:.0} mm / {:.0} deg; {note}",
        doc["scenario"].as_str().unwrap_or("?"),
        lists.describe(),
        number_at(doc, &["tolerance_mm"]),
        number_at(doc, &["tolerance_deg"])
    );
    if many {
        println!("each figure: mean (min-max) over the seeds");
    }
    let w = if many { 20 } else { 12 };
    println!(
        "{:<12} {:>8} {:>w$} {:>w$} {:>w$} {:>w$} {:>w$} {:>8}",
        "planner",
        "episodes",
        "success %",
        "pos err mm",
        "ori err deg",
        "pushes",
        "sim s",
        "wall s"
    );
    let shown = |name: &str, key: &str, scale: f64, decimals: usize| {
        let values: Vec<f64> = docs
            .iter()
            .map(|d| scale * number_at(d, &["planners", name, key]))
            .collect();
        Spread::of(&values).map_or_else(|| "-".to_owned(), |s| s.show(decimals))
    };
    let mut any_oracle = false;
    if let Some(planners) = doc["planners"].as_object() {
        for (name, p) in planners {
            let gt = p["reads_ground_truth"] == true;
            any_oracle |= gt;
            println!(
                "{:<12} {:>8} {:>w$} {:>w$} {:>w$} {:>w$} {:>w$} {:>8.1}",
                if gt {
                    format!("{name} (GT)")
                } else {
                    name.clone()
                },
                number_at(p, &["episodes"]),
                shown(name, "success_rate", 100.0, 0),
                shown(name, "median_position_error_mm", 1.0, 1),
                shown(name, "median_orientation_error_deg", 1.0, 1),
                shown(name, "median_pushes", 1.0, 1),
                shown(name, "sim_time_s", 1.0, 0),
                number_at(p, &["wall_time_s"]),
            );
        }
        if many {
            println!("over all episodes of all seeds:");
            for (name, p) in planners {
                println!(
                    "{:<12} {:>8} {:>w$.0} {:>w$.1} {:>w$.1} {:>w$.1} {:>w$.0}",
                    name,
                    number_at(p, &["episodes"]),
                    100.0 * number_at(p, &["success_rate"]),
                    number_at(p, &["median_position_error_mm"]),
                    number_at(p, &["median_orientation_error_deg"]),
                    number_at(p, &["median_pushes"]),
                    number_at(p, &["sim_time_s"]),
                );
            }
        }
    }
    if any_oracle {
        let has = |name: &str| doc["planners"].get(name).is_some();
        if has("oracle") {
            println!("(GT) {ORACLE_NOTE}");
        }
        if has("model") {
            println!("(GT) {MODEL_NOTE}");
        }
    }
}
