//! `agp bench adapt`: an affordance gradient that keeps learning, against a frozen one,
//! when the world changes under it.
//!
//! At each seed, the gradient learned at the scenario's floor friction (by default the
//! learning benchmark's AG file of the object learned at that seed,
//! `results/learn/seed-<S>/<object>.ag`, learned first when missing; `--ag FILE` gives one
//! file for every seed) places the object at `--warmup` goals in the scenario's world, the
//! pre-change level of its prediction error; then the world changes (`--friction`, and/or
//! `--mass-kg`, applied by physics as a scenario's `[[world_change]]` is) and it places
//! the object at `--episodes` more goals. Twice, on the same goals and seed: with the
//! gradient frozen, and with the estimator learning on from every push whose effect it
//! observes (the tracker's online learning, see `agp_perception::OnlineLearner`) and the
//! planner taking each new gradient between two pushes.
//!
//! Per push, the judge compares the prediction the planner planned the push on (the
//! gradient it held, at the announced aim point, alpha and share of a learned push) with
//! the object's true motion (ground truth, read here only): displacement error (mm) and
//! rotation error (deg). Per episode: success, pushes, median errors. `pushes_to_recover`:
//! the pushes after the change until the median displacement error of the next
//! [`RECOVERY_WINDOW`] pushes is within [`RECOVERY_FACTOR`] x the pre-change median.
//!
//! Seeds as every benchmark has them ([`SeedArgs`]: `--seeds N` from `--first-seed`,
//! `--seed S`, `--shard I/N`): each seed writes a one-seed document (the figures above,
//! every episode and push), and the run's document is assembled from them by the same
//! code [`merge`] (what `agp bench merge` calls on a sharded run's parts) runs: each
//! figure the mean over the seeds with its spread, `seeds`, `per_seed`.
//!
//! In process: the physics library and the estimator's tracker beside the planner (the
//! `--in-process` world of the other benchmarks); the pipeline carries the same learning
//! (the estimator republishes the grids, the planner's grid link takes them).

use std::path::{Path, PathBuf};
use std::time::Instant;

use agp_affordance::{
    AG_FILE_VERSION, AffordanceGradient, PushOutcome, PushPredictor, learned_border_radius_m,
};
use agp_perception::{OnlineLearningConfig, TrackerConfig};
use agp_physics::{Sim, SimConfig};
use agp_planning::{
    EpisodeConfig, PlannerKind, Senses, Task, World, WorldStepError, drive_episode,
};
use agp_shared_types::{LearnEvent, LearnEventKind, ObjectEstimate, Pose2};
use agp_world::{Pose, RobotDescription, Scenario, WorldChange};
use anyhow::{Context, Result, bail};
use glam::DVec2;
use serde_json::{Map, Value, json};

use crate::bench_learn::{self, BenchLearnArgs};
use crate::in_process::InProcessWorld;
use crate::seeds::write_json;
use crate::seeds::{
    SeedArgs, SeedParts, Shard, Spread, finish_seed_doc, finite_or_null, mean_of, merge_parts,
    number_at, run_parts, seed_list, spread_at,
};
use crate::side_by_side::side_by_side;
use crate::task_goals::{median, place_goals};

/// Pushes whose median error must be back within [`RECOVERY_FACTOR`] of the pre-change
/// level for the gradient to count as recovered.
pub const RECOVERY_WINDOW: usize = 5;
/// How close to the pre-change level the error must come back.
pub const RECOVERY_FACTOR: f64 = 1.2;

/// `agp bench adapt`.
#[derive(Debug, Clone, clap::Args)]
pub struct BenchAdaptArgs {
    /// Built-in scenario or scenario file: the object, its floor friction before the change.
    #[arg(long, default_value = "triangle")]
    pub scenario: String,
    /// The AG file learned at the scenario's friction, for every seed (default: each
    /// seed's own, the learning benchmark's `results/learn/seed-<S>/<object>.ag`, learned
    /// at that seed first when missing).
    #[arg(long)]
    pub ag: Option<PathBuf>,
    /// Floor friction after the change (0.25); with `--mass-kg` both change.
    #[arg(long)]
    pub friction: Option<f64>,
    /// The object's mass after the change, kg (none: the mass stays).
    #[arg(long)]
    pub mass_kg: Option<f64>,
    /// Placements before the change: the pre-change level.
    #[arg(long, default_value_t = 3)]
    pub warmup: usize,
    /// Placements after the change.
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// Seeds of the goals, the sensor noise and (without `--ag`) the learned AG: each seed
    /// its own goals and gradient, the same for both conditions.
    #[command(flatten)]
    pub seeds: SeedArgs,
    /// Pushes per placement at most.
    #[arg(long, default_value_t = 60)]
    pub max_pushes: u32,
    /// Write the JSON report here (`-`: stdout): per condition each figure's mean over the
    /// seeds with its spread, every seed's own document in `per_seed`.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

impl Default for BenchAdaptArgs {
    fn default() -> Self {
        Self {
            scenario: "triangle".into(),
            ag: None,
            friction: None,
            mass_kg: None,
            warmup: 3,
            episodes: 20,
            seeds: SeedArgs::default(),
            max_pushes: 60,
            json: None,
        }
    }
}

/// One push, as the judge saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PushRecord {
    /// Placement index (warm-up ones first), and whether the world had changed.
    pub episode: usize,
    pub after_change: bool,
    /// Predicted and true displacement (world frame, mm) and rotation (deg).
    pub predicted_mm: DVec2,
    pub true_mm: DVec2,
    pub predicted_deg: f64,
    pub true_deg: f64,
}

impl PushRecord {
    /// |predicted - true displacement|, mm.
    pub fn displacement_error_mm(&self) -> f64 {
        (self.predicted_mm - self.true_mm).length()
    }

    /// |predicted - true rotation|, deg.
    pub fn rotation_error_deg(&self) -> f64 {
        (self.predicted_deg - self.true_deg).abs()
    }
}

/// One placement.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRecord {
    pub after_change: bool,
    pub success: bool,
    pub pushes: u32,
    pub median_displacement_error_mm: f64,
    pub median_rotation_error_deg: f64,
    /// Pushes the estimator learned online during the episode.
    pub pushes_learned: u64,
}

/// One condition's run: every push and every placement.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ConditionRun {
    pub pushes: Vec<PushRecord>,
    pub episodes: Vec<EpisodeRecord>,
}

impl ConditionRun {
    /// Median displacement error before the change, mm.
    pub fn pre_change_error_mm(&self) -> f64 {
        median(&self.errors(false))
    }

    /// Median displacement error after the change, mm, over its first `n` pushes (all
    /// with `usize::MAX`).
    pub fn post_change_error_mm(&self, n: usize) -> f64 {
        let e = self.errors(true);
        median(&e[..n.min(e.len())])
    }

    fn errors(&self, after: bool) -> Vec<f64> {
        self.pushes
            .iter()
            .filter(|p| p.after_change == after)
            .map(PushRecord::displacement_error_mm)
            .collect()
    }

    /// Pushes after the change until the median displacement error of the next
    /// [`RECOVERY_WINDOW`] is within [`RECOVERY_FACTOR`] x the pre-change median; `None`
    /// if it never is.
    pub fn pushes_to_recover(&self) -> Option<usize> {
        let level = RECOVERY_FACTOR * self.pre_change_error_mm();
        let e = self.errors(true);
        (0..e.len().saturating_sub(RECOVERY_WINDOW - 1))
            .find(|&k| median(&e[k..k + RECOVERY_WINDOW]) <= level)
    }

    /// Success rate of the placements after the change.
    pub fn success_rate(&self) -> f64 {
        let after: Vec<_> = self.episodes.iter().filter(|e| e.after_change).collect();
        if after.is_empty() {
            return 0.0;
        }
        after.iter().filter(|e| e.success).count() as f64 / after.len() as f64
    }
}

/// The in-process world, with the judge watching each push: the prediction the planner
/// planned it on and the object's true motion.
struct JudgedWorld {
    inner: InProcessWorld,
    /// The gradient the planner plans on, and the predictor's start radius.
    planner_ag: AffordanceGradient,
    start_radius_m: f64,
    /// At a push's start: the announced plan, the object's true pose and the orientation
    /// the estimator holds (the frame the prediction is in).
    push: Option<(DVec2, f64, f64, Pose2, f64)>,
    episode: usize,
    after_change: bool,
    pushes: Vec<PushRecord>,
}

impl World for JudgedWorld {
    fn senses(&self) -> Senses {
        self.inner.senses()
    }

    fn perceived(&self) -> &ObjectEstimate {
        self.inner.perceived()
    }

    fn tell(&mut self, event: LearnEvent) -> Result<(), WorldStepError> {
        match LearnEventKind::from_u32(event.kind) {
            Some(LearnEventKind::TaskPushBegin) if event.flag == 1 => {
                self.push = Some((
                    DVec2::from_array(event.contact),
                    event.alpha_deg,
                    event.scale,
                    self.inner.sim().object_pose(),
                    self.inner.perceived().pose.theta,
                ));
            }
            Some(LearnEventKind::TaskPushEnd) => {
                if let Some((aim, alpha, scale, before, estimated_theta)) = self.push.take() {
                    let after = self.inner.sim().object_pose();
                    let (true_displacement, true_rotation) = PushOutcome::motion(before, after);
                    // Both in the world frame: the prediction is in the frame of the pose
                    // the estimator held (its orientation is known modulo the symmetry),
                    // the truth in the object's true frame.
                    let to_world = |theta: f64, d: DVec2| DVec2::from_angle(theta).rotate(d);
                    let predicted = PushPredictor::new(&self.planner_ag, self.start_radius_m)
                        .predict(aim, alpha);
                    if let Some(p) = predicted {
                        self.pushes.push(PushRecord {
                            episode: self.episode,
                            after_change: self.after_change,
                            predicted_mm: to_world(estimated_theta, p.displacement * scale) * 1e3,
                            true_mm: to_world(before.theta, true_displacement) * 1e3,
                            predicted_deg: (p.rotation_rad * scale).to_degrees(),
                            true_deg: true_rotation.to_degrees(),
                        });
                    }
                }
            }
            _ => {}
        }
        self.inner.tell(event)
    }

    fn sim_time(&self) -> f64 {
        self.inner.sim_time()
    }

    fn step_count(&self) -> u64 {
        self.inner.step_count()
    }

    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), WorldStepError> {
        self.inner.step(left_mps, right_mps)
    }

    fn object_truth(&self) -> Option<Pose> {
        self.inner.object_truth()
    }

    fn newer_gradient(&mut self) -> Option<AffordanceGradient> {
        let newer = self.inner.newer_gradient()?;
        self.planner_ag = newer.clone();
        Some(newer)
    }
}

/// What one condition runs with.
pub struct AdaptSetup<'a> {
    pub scenario: &'a Scenario,
    pub ag: &'a AffordanceGradient,
    pub change: WorldChange,
    pub warmup: usize,
    pub episodes: usize,
    pub seed: u64,
    pub max_pushes: u32,
}

/// Runs the warm-up placements, the change, and the placements after it, with online
/// learning per `online`; the goals are the same for every condition of one seed.
pub fn run_condition(setup: &AdaptSetup<'_>, online: OnlineLearningConfig) -> Result<ConditionRun> {
    let robot = RobotDescription::epuck();
    let scenario = setup.scenario;
    let shape = setup.ag.combined_shape();
    let radius = learned_border_radius_m(&shape).context("the AG's shape has no border")?;
    let mut config = EpisodeConfig::for_task(&scenario.task);
    config.max_pushes = setup.max_pushes;
    config.max_sim_time_s = 900.0;
    config.seed = setup.seed;
    let start_radius_m = radius + robot.body_radius + config.start_gap_m;
    let sim = Sim::new(
        scenario,
        &robot,
        SimConfig {
            seed: setup.seed,
            ..SimConfig::default()
        },
    )?;
    let tracker = TrackerConfig {
        online,
        ..TrackerConfig::default()
    };
    let inner = InProcessWorld::with_tracker(sim, &robot, Some(setup.ag), tracker)?;
    let mut world = JudgedWorld {
        inner,
        planner_ag: setup.ag.clone(),
        start_radius_m,
        push: None,
        episode: 0,
        after_change: false,
        pushes: Vec::new(),
    };
    let goals = place_goals(scenario, setup.warmup + setup.episodes, setup.seed);
    let order = scenario.object.shape.symmetry_order();
    let mut run = ConditionRun::default();
    for (k, goal) in goals.iter().enumerate() {
        // A stop (`agp bench` got SIGINT, SIGTERM or SIGHUP) keeps the episodes run.
        if crate::stop::requested() {
            break;
        }
        if k == setup.warmup {
            world.inner.sim_mut().apply_world_change(setup.change);
            world.after_change = true;
        }
        world.episode = k;
        world
            .inner
            .reset(scenario.object.start, scenario.robot.start);
        let ag = world
            .inner
            .tracker()
            .gradient()
            .cloned()
            .unwrap_or_else(|| setup.ag.clone());
        world.planner_ag = ag.clone();
        let learned_before = world.inner.tracker().pushes_learned();
        let first = world.pushes.len();
        let task = Task::Place { goal: *goal };
        let result = drive_episode(
            &mut world,
            &robot,
            Some(&ag),
            PlannerKind::Affordance,
            &task,
            &config,
        )?
        .judged(&task, order, &config);
        let pushes = &world.pushes[first..];
        let d: Vec<f64> = pushes
            .iter()
            .map(PushRecord::displacement_error_mm)
            .collect();
        let r: Vec<f64> = pushes.iter().map(PushRecord::rotation_error_deg).collect();
        run.episodes.push(EpisodeRecord {
            after_change: world.after_change,
            success: result.success(),
            pushes: result.pushes,
            median_displacement_error_mm: median(&d),
            median_rotation_error_deg: median(&r),
            pushes_learned: world.inner.tracker().pushes_learned() - learned_before,
        });
    }
    run.pushes = world.pushes;
    Ok(run)
}

/// A condition: its name in the report, and the tracker's online learning in it.
type Condition = (&'static str, fn() -> OnlineLearningConfig);

/// The two conditions every seed runs, in report order: the gradient frozen, and learning
/// on from every push.
const CONDITIONS: [Condition; 2] = [
    ("frozen", OnlineLearningConfig::default),
    ("updating", OnlineLearningConfig::updating),
];

/// The figures of a condition that are one number per seed: aggregated as their mean over
/// the seeds, with their spread. A seed whose gradient never recovered has a null
/// `pushes_to_recover`: left out of its mean and counted in its spread's `missing`.
const FIGURES: [&str; 6] = [
    "success_rate",
    "pushes_to_recover",
    "pre_change_median_displacement_error_mm",
    "post_change_median_displacement_error_mm",
    "post_change_first10_median_displacement_error_mm",
    "pushes_learned",
];

/// One condition's run at one seed, as its one-seed document holds it.
fn condition_json(run: &ConditionRun) -> Value {
    json!({
        "success_rate": run.success_rate(),
        "pushes_to_recover": run.pushes_to_recover(),
        "pre_change_median_displacement_error_mm": finite_or_null(run.pre_change_error_mm()),
        "post_change_median_displacement_error_mm": finite_or_null(run.post_change_error_mm(usize::MAX)),
        "post_change_first10_median_displacement_error_mm": finite_or_null(run.post_change_error_mm(10)),
        "pushes_learned": run.episodes.iter().map(|e| e.pushes_learned).sum::<u64>(),
        "episodes": run.episodes.iter().map(|e| json!({
            "after_change": e.after_change,
            "success": e.success,
            "pushes": e.pushes,
            "median_displacement_error_mm": finite_or_null(e.median_displacement_error_mm),
            "median_rotation_error_deg": finite_or_null(e.median_rotation_error_deg),
            "pushes_learned": e.pushes_learned,
        })).collect::<Vec<_>>(),
        "pushes": run.pushes.iter().map(|p| json!({
            "episode": p.episode,
            "after_change": p.after_change,
            "predicted_mm": [p.predicted_mm.x, p.predicted_mm.y],
            "true_mm": [p.true_mm.x, p.true_mm.y],
            "predicted_deg": p.predicted_deg,
            "true_deg": p.true_deg,
            "displacement_error_mm": p.displacement_error_mm(),
            "rotation_error_deg": p.rotation_error_deg(),
        })).collect::<Vec<_>>(),
    })
}

/// What every seed of one run shares, as the one-seed documents say it.
struct RunInfo<'a> {
    scenario: &'a Scenario,
    change: WorldChange,
    warmup: usize,
    episodes: usize,
    max_pushes: u32,
    /// Whether each seed's AG was learned at that seed (no `--ag`).
    ag_learned_at_seed: bool,
}

/// The document of one seed: both conditions' figures, episodes and pushes.
fn one_seed_doc(
    info: &RunInfo<'_>,
    seed: u64,
    ag_file: &Path,
    runs: [&ConditionRun; 2],
    wall_time_s: f64,
) -> Value {
    let object = &info.scenario.object;
    let mut doc = Map::new();
    doc.insert("benchmark".into(), json!("adapt"));
    doc.insert("scenario".into(), json!(info.scenario.name));
    doc.insert("seed".into(), json!(seed));
    doc.insert("ag_file".into(), json!(ag_file.display().to_string()));
    doc.insert("ag_learned_at_seed".into(), json!(info.ag_learned_at_seed));
    doc.insert(
        "before".into(),
        json!({ "floor_friction": object.floor_friction, "mass_kg": object.mass }),
    );
    doc.insert(
        "after".into(),
        json!({
            "floor_friction": info.change.floor_friction.unwrap_or(object.floor_friction),
            "mass_kg": info.change.mass_kg.unwrap_or(object.mass),
        }),
    );
    doc.insert("warmup_episodes".into(), json!(info.warmup));
    doc.insert("episodes".into(), json!(info.episodes));
    doc.insert("max_pushes".into(), json!(info.max_pushes));
    doc.insert(
        "recovery".into(),
        json!({ "window_pushes": RECOVERY_WINDOW, "factor": RECOVERY_FACTOR }),
    );
    doc.insert(
        "online_learning".into(),
        json!({
            "forgetting": OnlineLearningConfig::updating().forgetting,
            "gain_step": OnlineLearningConfig::updating().gain_step,
        }),
    );
    for ((name, _), run) in CONDITIONS.iter().zip(runs) {
        doc.insert((*name).into(), condition_json(run));
    }
    doc.insert("wall_time_s".into(), json!(wall_time_s));
    Value::Object(doc)
}

/// The fields of a one-seed document that are the same at every seed of one run.
const RUN_FIELDS: [&str; 8] = [
    "scenario",
    "before",
    "after",
    "warmup_episodes",
    "episodes",
    "max_pushes",
    "recovery",
    "online_learning",
];

/// What must be alike in every seed of one adapt run: the run's fields, and the AG's
/// source (learned at each seed, or the one file given).
fn adapt_signature(doc: &Value) -> Value {
    let mut sig: Map<String, Value> = RUN_FIELDS
        .iter()
        .map(|k| ((*k).to_owned(), doc[*k].clone()))
        .collect();
    let ag = if doc["ag_learned_at_seed"] == true {
        json!("learned at each seed")
    } else {
        doc["ag_file"].clone()
    };
    sig.insert("ag".into(), ag);
    Value::Object(sig)
}

/// One condition over the seeds: each figure's mean over the seeds (`pushes_to_recover`
/// over the seeds that recovered, null when none did; the others listed in
/// `not_recovered_seeds`), its `spread`, the figures per seed in `by_seed` (seed order,
/// null where a seed has none), and every seed's episodes tagged with their seed.
fn condition_over_seeds(parts: &SeedParts, name: &str) -> Value {
    let docs: Vec<&Value> = parts.docs().collect();
    let own: Vec<u64> = parts.per_seed.iter().map(|(s, _, _)| *s).collect();
    let mut out = Map::new();
    let mut spread = Map::new();
    let mut by_seed = Map::new();
    by_seed.insert("seed".into(), json!(own));
    for figure in FIGURES {
        let values: Vec<f64> = docs.iter().map(|d| number_at(d, &[name, figure])).collect();
        out.insert(figure.into(), finite_or_null(mean_of(&values)));
        spread.insert(
            figure.into(),
            spread_at(docs.iter().copied(), &[name, figure]),
        );
        by_seed.insert(
            figure.into(),
            Value::Array(values.iter().map(|&v| finite_or_null(v)).collect()),
        );
    }
    let never: Vec<u64> = parts
        .per_seed
        .iter()
        .filter(|(_, _, d)| !number_at(d, &[name, "pushes_to_recover"]).is_finite())
        .map(|(s, _, _)| *s)
        .collect();
    out.insert("recovered_seeds".into(), json!(own.len() - never.len()));
    out.insert("not_recovered_seeds".into(), json!(never));
    out.insert("spread".into(), Value::Object(spread));
    out.insert("by_seed".into(), Value::Object(by_seed));
    let episodes: Vec<Value> = parts
        .per_seed
        .iter()
        .flat_map(|(seed, _, d)| {
            d[name]["episodes"]
                .as_array()
                .cloned()
                .unwrap_or_default()
                .into_iter()
                .map(move |mut e| {
                    if let Some(m) = e.as_object_mut() {
                        m.insert("seed".into(), json!(seed));
                    }
                    e
                })
        })
        .collect();
    out.insert("episodes".into(), Value::Array(episodes));
    Value::Object(out)
}

/// The adapt document of `parts`: the run's fields, per condition each figure over the
/// seeds ([`condition_over_seeds`]), `ag_file` (the one file every seed used, else null:
/// each seed's is in its `per_seed` document), `seeds`, `per_seed` (and `shard`). Its
/// `wall_time_s` is the longest seed's; the caller sets the run's own.
fn assemble(parts: &SeedParts, shard: Option<Shard>) -> Value {
    let docs: Vec<&Value> = parts.docs().collect();
    let first = docs[0];
    let mut doc = Map::new();
    doc.insert("benchmark".into(), json!("adapt"));
    doc.insert("seed".into(), first["seed"].clone());
    for key in RUN_FIELDS {
        doc.insert(key.into(), first[key].clone());
    }
    let ag_file = if docs.iter().all(|d| d["ag_file"] == first["ag_file"]) {
        first["ag_file"].clone()
    } else {
        Value::Null
    };
    doc.insert("ag_file".into(), ag_file);
    doc.insert(
        "ag_learned_at_seed".into(),
        first["ag_learned_at_seed"].clone(),
    );
    for (name, _) in CONDITIONS {
        doc.insert(name.into(), condition_over_seeds(parts, name));
    }
    finish_seed_doc(doc, parts, shard)
}

/// The document of a run (or of its shard) over `all_seeds`, from the one-seed documents
/// of the seeds it ran: what [`run`] writes.
fn assemble_run(docs: &[Value], all_seeds: Vec<u64>, shard: Option<Shard>) -> Result<Value> {
    Ok(assemble(
        &run_parts(docs, "adapt", adapt_signature, all_seeds)?,
        shard,
    ))
}

/// Merges adapt documents of disjoint seed sets (one-seed documents, whole runs or a run's
/// shards) into the document one run over all their seeds writes, but for `wall_time_s`:
/// the longest part's. A part of another benchmark, of another run (scenario, change,
/// episodes, AG source...) or a seed twice is refused naming the part.
pub fn merge(parts: &[Value]) -> Result<Value> {
    Ok(merge_parts(parts, "adapt", adapt_signature, assemble)?)
}

/// The human summary of an adapt document: per condition one line, each figure as one
/// seed's value or `mean (min-max)` over the seeds; the seeds that never recovered named.
pub fn print_adapt(doc: &Value) {
    let lists = crate::seeds::SeedLists::of(doc);
    let docs = &lists.docs;
    let many = lists.own.len() > 1;
    crate::say(format_args!(
        "adapt `{}`: {} placements, then friction {} and mass {} kg, {} placements; {}; physics in-process",
        doc["scenario"].as_str().unwrap_or("?"),
        number_at(doc, &["warmup_episodes"]),
        number_at(doc, &["after", "floor_friction"]),
        number_at(doc, &["after", "mass_kg"]),
        number_at(doc, &["episodes"]),
        lists.describe(),
    ));
    if many {
        crate::say(format_args!(
            "each figure: mean (min-max) over the seeds; pushes to recover over the seeds that recovered"
        ));
    }
    for (name, _) in CONDITIONS {
        let shown = |key: &str, scale: f64, decimals: usize| {
            let values: Vec<f64> = docs
                .iter()
                .map(|d| scale * number_at(d, &[name, key]))
                .collect();
            Spread::of(&values).map_or_else(|| "-".to_owned(), |s| s.show(decimals))
        };
        let never: Vec<u64> = docs
            .iter()
            .filter(|d| !number_at(d, &[name, "pushes_to_recover"]).is_finite())
            .filter_map(|d| d["seed"].as_u64())
            .collect();
        let recover = match (never.is_empty(), never.len() == lists.own.len()) {
            (true, _) => shown("pushes_to_recover", 1.0, usize::from(many)),
            (false, true) => "never".to_owned(),
            (false, false) => format!(
                "{} (never at {} {})",
                shown("pushes_to_recover", 1.0, usize::from(many)),
                if never.len() == 1 { "seed" } else { "seeds" },
                seed_list(&never)
            ),
        };
        crate::say(format_args!(
            "{name:>9}: success {} %, displacement error {} mm before the change, {} mm after (first 10 pushes {} mm), pushes to recover {recover}, pushes learned {}",
            shown("success_rate", 100.0, 0),
            shown("pre_change_median_displacement_error_mm", 1.0, 1),
            shown("post_change_median_displacement_error_mm", 1.0, 1),
            shown("post_change_first10_median_displacement_error_mm", 1.0, 1),
            shown("pushes_learned", 1.0, 0),
        ));
    }
}

/// The AG file of `seed`: `--ag`, or the learning benchmark's file of the object learned at
/// that seed, `results/learn/seed-<S>/<object>.ag`, learned first (and said so) when missing.
fn ag_file_of(args: &BenchAdaptArgs, scenario: &Scenario, seed: u64) -> Result<PathBuf> {
    if let Some(path) = &args.ag {
        return Ok(path.clone());
    }
    let dir = Path::new(bench_learn::DEFAULT_OUT).join(format!("seed-{seed}"));
    let path = bench_learn::ag_path(&dir, scenario);
    let why = if !path.is_file() {
        Some(format!(
            "no affordance gradient of `{}` learned at seed {seed} at {}",
            scenario.name,
            path.display()
        ))
    } else {
        let version = AffordanceGradient::file_version(&path)?;
        (version != AG_FILE_VERSION).then(|| {
            format!(
                "{} was learned by an older build (AG file version {version}, this build writes {AG_FILE_VERSION})",
                path.display()
            )
        })
    };
    if let Some(why) = why {
        crate::say(format_args!(
            "{why}: learning it first (agp bench learn --scenario {} --seed {seed} --out {})",
            args.scenario,
            dir.display()
        ));
        bench_learn::learn(&BenchLearnArgs {
            seeds: SeedArgs::one(seed),
            ..BenchLearnArgs::for_scenarios(&[&args.scenario], dir.clone())
        })
        .with_context(|| format!("cannot learn `{}` at seed {seed}", scenario.name))?;
    }
    Ok(path)
}

/// `agp bench adapt`: at every seed of this run (its shard's share with `--shard`) both
/// conditions, every (seed, condition) side by side on the cores; the one-seed documents
/// assembled into the run's, the summary, the JSON.
pub fn run(args: &BenchAdaptArgs) -> Result<Value> {
    let wall = Instant::now();
    let scenario = Scenario::resolve(&args.scenario)
        .with_context(|| format!("cannot load scenario `{}`", args.scenario))?;
    let friction = match (args.friction, args.mass_kg) {
        (None, None) => Some(0.25),
        (f, _) => f,
    };
    if friction.is_some_and(|f| !(f.is_finite() && (0.0..=2.0).contains(&f))) {
        bail!("`--friction` must be from 0 to 2");
    }
    if args
        .mass_kg
        .is_some_and(|m| !(m.is_finite() && (0.001..=10.0).contains(&m)))
    {
        bail!("`--mass-kg` must be from 0.001 to 10 kg");
    }
    if args.episodes == 0 {
        bail!("`--episodes` must be at least 1");
    }
    if let Some(path) = args.ag.as_deref().filter(|p| !p.is_file()) {
        bail!("--ag {}: no such file", path.display());
    }
    let change = WorldChange {
        at_s: 0.0,
        floor_friction: friction,
        mass_kg: args.mass_kg,
    };
    let all_seeds = args.seeds.all();
    let seeds = args.seeds.mine();
    crate::say(format_args!(
        "bench adapt: `{}` learned at floor friction {} and {} kg ({}); {} placements, then friction {} and mass {} kg, {} placements; frozen and updating; {} {}{}",
        scenario.name,
        scenario.object.floor_friction,
        scenario.object.mass,
        args.ag.as_ref().map_or_else(
            || format!(
                "each seed's AG learned at that seed, {}/seed-<S>/",
                bench_learn::DEFAULT_OUT
            ),
            |p| p.display().to_string()
        ),
        args.warmup,
        friction.unwrap_or(scenario.object.floor_friction),
        args.mass_kg.unwrap_or(scenario.object.mass),
        args.episodes,
        if seeds.len() == 1 { "seed" } else { "seeds" },
        seed_list(&seeds),
        args.seeds.shard_note()
    ));
    let ag_files: Vec<PathBuf> = seeds
        .iter()
        .map(|&seed| ag_file_of(args, &scenario, seed))
        .collect::<Result<_>>()?;
    let ags: Vec<AffordanceGradient> = ag_files
        .iter()
        .map(|path| {
            AffordanceGradient::load_for(path, &scenario.name).with_context(|| {
                format!(
                    "cannot load the AG file {} (learn it first: agp bench learn --scenario {})",
                    path.display(),
                    scenario.name
                )
            })
        })
        .collect::<Result<_>>()?;
    let setups: Vec<AdaptSetup<'_>> = seeds
        .iter()
        .zip(&ags)
        .map(|(&seed, ag)| AdaptSetup {
            scenario: &scenario,
            ag,
            change,
            warmup: args.warmup,
            episodes: args.episodes,
            seed,
            max_pushes: args.max_pushes,
        })
        .collect();
    let work: Vec<(usize, usize)> = (0..setups.len())
        .flat_map(|k| (0..CONDITIONS.len()).map(move |c| (k, c)))
        .collect();
    // From here on the episode loops poll the stop flag.
    let _checked = crate::stop::checked();
    let runs = side_by_side(&work, |&(k, c)| {
        let started = Instant::now();
        let (name, online) = CONDITIONS[c];
        let run = run_condition(&setups[k], online())
            .with_context(|| format!("seed {}, {name}", setups[k].seed))?;
        Ok((run, started.elapsed().as_secs_f64()))
    })
    .into_iter()
    .collect::<Result<Vec<(ConditionRun, f64)>>>()?;
    let info = RunInfo {
        scenario: &scenario,
        change,
        warmup: args.warmup,
        episodes: args.episodes,
        max_pushes: args.max_pushes,
        ag_learned_at_seed: args.ag.is_none(),
    };
    let docs: Vec<Value> = seeds
        .iter()
        .zip(&ag_files)
        .zip(runs.chunks(CONDITIONS.len()))
        .map(|((&seed, ag_file), pair)| {
            let wall_s = pair.iter().map(|(_, w)| *w).fold(0.0, f64::max);
            one_seed_doc(&info, seed, ag_file, [&pair[0].0, &pair[1].0], wall_s)
        })
        .collect();
    if crate::stop::requested() {
        // The episodes run so far, seeds of fewer episodes included.
        let mut doc = assemble(
            &run_parts(&docs, "adapt", |_| Value::Null, all_seeds)?,
            args.seeds.shard,
        );
        doc["wall_time_s"] = json!(wall.elapsed().as_secs_f64());
        let finished = runs.iter().map(|(r, _)| r.episodes.len()).sum();
        let planned = work.len() * (args.warmup + args.episodes);
        return Err(crate::stop::write_partial(
            doc,
            args.json.as_deref(),
            "adapt",
            finished,
            planned,
        ));
    }
    let mut doc = assemble_run(&docs, all_seeds, args.seeds.shard)?;
    let wall_time_s = wall.elapsed().as_secs_f64();
    doc["wall_time_s"] = json!(wall_time_s);
    print_adapt(&doc);
    crate::say(format_args!("wall time {wall_time_s:.1} s"));
    if let Some(out) = &args.json {
        if out.as_os_str() == "-" {
            let text = serde_json::to_string_pretty(&doc)?;
            crate::say(format_args!("{text}"));
        } else {
            write_json(out, &doc)?;
            crate::say(format_args!("JSON     {}", out.display()));
        }
    }
    Ok(doc)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A condition of a hand-made one-seed document: `recover` None when it never
    /// recovered.
    fn condition(success: f64, recover: Option<usize>, after_mm: f64, learned: u64) -> Value {
        json!({
            "success_rate": success,
            "pushes_to_recover": recover,
            "pre_change_median_displacement_error_mm": 2.0,
            "post_change_median_displacement_error_mm": after_mm,
            "post_change_first10_median_displacement_error_mm": after_mm + 1.0,
            "pushes_learned": learned,
            "episodes": [
                { "after_change": false, "success": true, "pushes": 4 },
                { "after_change": true, "success": success > 0.5, "pushes": 9 },
            ],
            "pushes": [],
        })
    }

    /// A one-seed document as a run writes it, with made-up figures.
    fn seed_doc(seed: u64, frozen: Value, updating: Value) -> Value {
        json!({
            "benchmark": "adapt",
            "scenario": "triangle",
            "seed": seed,
            "ag_file": format!("results/learn/seed-{seed}/triangle.ag"),
            "ag_learned_at_seed": true,
            "before": { "floor_friction": 0.4, "mass_kg": 0.1 },
            "after": { "floor_friction": 0.4, "mass_kg": 0.3 },
            "warmup_episodes": 1,
            "episodes": 1,
            "max_pushes": 60,
            "recovery": { "window_pushes": RECOVERY_WINDOW, "factor": RECOVERY_FACTOR },
            "online_learning": { "forgetting": 0.9, "gain_step": 0.1 },
            "frozen": frozen,
            "updating": updating,
            "wall_time_s": seed as f64 - 99.0,
        })
    }

    /// Seeds 100-102: the frozen gradient recovers at 100 only, the updating one at all.
    fn three_seeds() -> Vec<Value> {
        vec![
            seed_doc(
                100,
                condition(0.0, Some(12), 9.0, 0),
                condition(1.0, Some(4), 3.0, 10),
            ),
            seed_doc(
                101,
                condition(0.0, None, 11.0, 0),
                condition(1.0, Some(6), 4.0, 12),
            ),
            seed_doc(
                102,
                condition(1.0, None, 10.0, 0),
                condition(0.0, Some(8), 5.0, 14),
            ),
        ]
    }

    /// A part as `agp bench adapt --seeds 3 --shard I/2` writes it.
    fn shard_part(docs: &[Value], all: &[u64], index: u64) -> Value {
        let shard = Shard { index, count: 2 };
        let mine = shard.pick(all);
        let own: Vec<Value> = docs
            .iter()
            .filter(|d| d["seed"].as_u64().is_some_and(|s| mine.contains(&s)))
            .cloned()
            .collect();
        assemble_run(&own, all.to_vec(), Some(shard)).expect("a shard's part")
    }

    #[test]
    fn two_shard_partials_merged_equal_the_run_over_every_seed() {
        let docs = three_seeds();
        let all = [100, 101, 102];
        let whole = assemble_run(&docs, all.to_vec(), None).expect("the run");
        let first = shard_part(&docs, &all, 1);
        let second = shard_part(&docs, &all, 2);
        assert_eq!(first["per_seed"].as_array().map(Vec::len), Some(2));
        assert_eq!(first["shard"], json!("1/2"));
        // In either order, the merge is the one-run document (wall time: the longest
        // seed's, 3 s, in both).
        assert_eq!(
            merge(&[second.clone(), first.clone()]).expect("merge"),
            whole
        );
        assert_eq!(merge(&[first, second]).expect("merge"), whole);
        // The one-seed documents merged directly give it too.
        assert_eq!(merge(&docs).expect("merge"), whole);
        assert_eq!(whole["seeds"], json!(all));
        assert_eq!(whole["per_seed"], json!(docs));
    }

    #[test]
    fn each_figure_is_the_mean_over_the_seeds_and_a_seed_that_never_recovered_stays_visible() {
        let whole = assemble_run(&three_seeds(), vec![100, 101, 102], None).expect("the run");
        let frozen = &whole["frozen"];
        let updating = &whole["updating"];
        let close = |v: &Value, want: f64| (v.as_f64().unwrap_or(f64::NAN) - want).abs() < 1e-12;
        assert!(close(&frozen["success_rate"], 1.0 / 3.0), "{frozen}");
        assert!(close(&updating["success_rate"], 2.0 / 3.0), "{updating}");
        assert!(close(&updating["pushes_to_recover"], 6.0), "{updating}");
        assert!(close(&updating["pushes_learned"], 12.0), "{updating}");
        assert!(close(
            &frozen["post_change_median_displacement_error_mm"],
            10.0
        ));
        // The frozen gradient recovered at seed 100 only: its mean is over that seed, the
        // two others are named, null per seed and counted missing in the spread.
        assert!(close(&frozen["pushes_to_recover"], 12.0), "{frozen}");
        assert_eq!(frozen["recovered_seeds"], json!(1));
        assert_eq!(frozen["not_recovered_seeds"], json!([101, 102]));
        assert_eq!(
            frozen["by_seed"]["pushes_to_recover"],
            json!([12.0, null, null])
        );
        assert_eq!(frozen["spread"]["pushes_to_recover"]["n"], json!(1));
        assert_eq!(frozen["spread"]["pushes_to_recover"]["missing"], json!(2));
        assert_eq!(updating["not_recovered_seeds"], json!([]));
        let spread: Spread =
            serde_json::from_value(updating["spread"]["success_rate"].clone()).expect("a spread");
        assert_eq!((spread.min, spread.max, spread.n), (0.0, 1.0, 3));
        // Every seed's episodes, tagged with their seed; every seed's AG file in its own
        // document, none shared.
        assert_eq!(frozen["episodes"].as_array().map(Vec::len), Some(6));
        assert_eq!(frozen["episodes"][5]["seed"], json!(102));
        assert_eq!(whole["ag_file"], Value::Null);
        assert_eq!(whole["seed"], json!(100));
        assert_eq!(whole["wall_time_s"], json!(3.0));
    }

    /// `agp bench merge` on `parts` written to files named `names`: its error.
    fn merge_files(parts: &[Value], names: &[&str]) -> String {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let files: Vec<PathBuf> = parts
            .iter()
            .zip(names)
            .map(|(part, name)| {
                let file = dir.path().join(name);
                write_json(&file, part).expect("written");
                file
            })
            .collect();
        let args = crate::bench_merge::BenchMergeArgs {
            parts: files,
            json: dir.path().join("merged.json"),
            plot: None,
            allow_partial: false,
        };
        let err = crate::bench_merge::run(&args).expect_err("refused");
        assert!(!dir.path().join("merged.json").exists());
        format!("{err:#}")
    }

    #[test]
    fn a_merge_refuses_a_part_of_another_benchmark_naming_its_file() {
        let docs = three_seeds();
        let place = json!({"benchmark": "place", "seed": 103, "scenario": "triangle"});
        let err = merge_files(&[docs[0].clone(), place], &["adapt-100.json", "place.json"]);
        assert!(
            err.contains("place.json`: a `place` result, not `adapt`"),
            "{err}"
        );
    }

    #[test]
    fn a_merge_refuses_a_seed_given_twice_naming_both_files() {
        let docs = three_seeds();
        let all = [100, 101, 102];
        let first = shard_part(&docs, &all, 1);
        let again = shard_part(&docs, &all, 1);
        let mut relabelled = again.clone();
        relabelled["shard"] = json!("2/2");
        let err = merge_files(&[first, relabelled], &["part-1.json", "part-2.json"]);
        assert!(
            err.contains("part-2.json`: seed 100 is also in `") && err.contains("part-1.json`"),
            "{err}"
        );
    }

    #[test]
    fn a_merge_refuses_a_seed_of_another_change_or_ag_source() {
        let docs = three_seeds();
        let mut heavier = docs[1].clone();
        heavier["after"]["mass_kg"] = json!(0.5);
        let err = merge(&[docs[0].clone(), heavier]).expect_err("refused");
        assert!(err.to_string().contains("`after`"), "{err}");
        let mut given = docs[1].clone();
        given["ag_learned_at_seed"] = json!(false);
        let err = merge(&[docs[0].clone(), given]).expect_err("refused");
        assert!(err.to_string().contains("`ag`"), "{err}");
    }

    #[test]
    fn the_command_line_takes_the_seed_options_of_every_benchmark() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            adapt: BenchAdaptArgs,
        }
        let cli = Cli::try_parse_from(["adapt"]).expect("defaults");
        assert_eq!(cli.adapt.seeds.all(), vec![200, 201, 202, 203, 204]);
        let cli = Cli::try_parse_from([
            "adapt",
            "--seeds",
            "3",
            "--first-seed",
            "7",
            "--shard",
            "2/2",
        ])
        .expect("parses");
        assert_eq!(cli.adapt.seeds.all(), vec![7, 8, 9]);
        assert_eq!(cli.adapt.seeds.mine(), vec![9]);
        let cli = Cli::try_parse_from(["adapt", "--seed", "7"]).expect("parses");
        assert_eq!(cli.adapt.seeds.mine(), vec![7]);
        assert!(Cli::try_parse_from(["adapt", "--seed", "7", "--seeds", "2"]).is_err());
    }
}
