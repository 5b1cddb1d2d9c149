//! `agp bench adapt`: an affordance gradient that keeps learning, against a frozen one,
//! when the world changes under it.
//!
//! The gradient learned at the scenario's floor friction (the learning benchmark's AG
//! file of the object) places the object at `--warmup` goals in the scenario's world, the
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
//! In process: the physics library and the estimator's tracker beside the planner (the
//! `--in-process` world of the other benchmarks); the pipeline carries the same learning
//! (the estimator republishes the grids, the planner's grid link takes them).

use std::path::PathBuf;
use std::time::Instant;

use agp_affordance::{AffordanceGradient, PushOutcome, PushPredictor, learned_border_radius_m};
use agp_perception::{OnlineLearningConfig, TrackerConfig};
use agp_physics::{Sim, SimConfig};
use agp_planning::{
    EpisodeConfig, PlannerKind, Senses, Task, World, WorldStepError, drive_episode,
};
use agp_shared_types::{LearnEvent, LearnEventKind, ObjectEstimate, Pose2};
use agp_world::{Pose, RobotDescription, Scenario, WorldChange};
use anyhow::{Context, Result, bail};
use glam::DVec2;
use serde_json::json;

use crate::in_process::InProcessWorld;
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
    /// The AG file learned at the scenario's friction (default: the learning benchmark's,
    /// `results/learn/<name>.ag`).
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
    /// Seed of the goals and of the sensor noise.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Pushes per placement at most.
    #[arg(long, default_value_t = 60)]
    pub max_pushes: u32,
    /// Write the JSON report here (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
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
                    let truth = PushOutcome::from_poses(before, after, before.position());
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
                            true_mm: to_world(before.theta, truth.displacement_obj) * 1e3,
                            predicted_deg: (p.rotation_rad * scale).to_degrees(),
                            true_deg: truth.rotation_rad.to_degrees(),
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

fn condition_json(run: &ConditionRun) -> serde_json::Value {
    let num = |x: f64| if x.is_finite() { json!(x) } else { json!(null) };
    json!({
        "success_rate": run.success_rate(),
        "pushes_to_recover": run.pushes_to_recover(),
        "pre_change_median_displacement_error_mm": num(run.pre_change_error_mm()),
        "post_change_median_displacement_error_mm": num(run.post_change_error_mm(usize::MAX)),
        "post_change_first10_median_displacement_error_mm": num(run.post_change_error_mm(10)),
        "pushes_learned": run.episodes.iter().map(|e| e.pushes_learned).sum::<u64>(),
        "episodes": run.episodes.iter().map(|e| json!({
            "after_change": e.after_change,
            "success": e.success,
            "pushes": e.pushes,
            "median_displacement_error_mm": num(e.median_displacement_error_mm),
            "median_rotation_error_deg": num(e.median_rotation_error_deg),
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

/// `agp bench adapt`: both conditions side by side (two threads), the table, the JSON.
pub fn run(args: &BenchAdaptArgs) -> Result<serde_json::Value> {
    let wall = Instant::now();
    let scenario = Scenario::resolve(&args.scenario)?;
    let path = args
        .ag
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("results/learn/{}.ag", scenario.name)));
    let ag = AffordanceGradient::load_for(&path, &scenario.name).with_context(|| {
        format!(
            "cannot load the AG file {} (learn it first: agp bench learn --scenario {})",
            path.display(),
            scenario.name
        )
    })?;
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
    let change = WorldChange {
        at_s: 0.0,
        floor_friction: friction,
        mass_kg: args.mass_kg,
    };
    let setup = AdaptSetup {
        scenario: &scenario,
        ag: &ag,
        change,
        warmup: args.warmup,
        episodes: args.episodes,
        seed: args.seed,
        max_pushes: args.max_pushes,
    };
    crate::say(format_args!(
        "bench adapt: `{}` learned at floor friction {} and {} kg ({}); {} placements, then friction {} and mass {} kg, {} placements; frozen and updating",
        scenario.name,
        scenario.object.floor_friction,
        scenario.object.mass,
        path.display(),
        args.warmup,
        friction.unwrap_or(scenario.object.floor_friction),
        args.mass_kg.unwrap_or(scenario.object.mass),
        args.episodes
    ));
    let (frozen, updating) = std::thread::scope(|s| {
        let frozen = s.spawn(|| run_condition(&setup, OnlineLearningConfig::default()));
        let updating = run_condition(&setup, OnlineLearningConfig::updating());
        (
            frozen
                .join()
                .unwrap_or_else(|_| Err(anyhow::anyhow!("the frozen run panicked"))),
            updating,
        )
    });
    let (frozen, updating) = (frozen?, updating?);
    for (name, r) in [("frozen", &frozen), ("updating", &updating)] {
        crate::say(format_args!(
            "{name:>9}: success {:.0} %, displacement error {:.1} mm before the change, {:.1} mm after (first 10 pushes {:.1} mm), pushes to recover {}, pushes learned {}",
            100.0 * r.success_rate(),
            r.pre_change_error_mm(),
            r.post_change_error_mm(usize::MAX),
            r.post_change_error_mm(10),
            r.pushes_to_recover()
                .map_or("never".to_owned(), |k| k.to_string()),
            r.episodes.iter().map(|e| e.pushes_learned).sum::<u64>()
        ));
    }
    let report = json!({
        "benchmark": "adapt",
        "scenario": scenario.name,
        "seed": args.seed,
        "ag_file": path.display().to_string(),
        "before": { "floor_friction": scenario.object.floor_friction, "mass_kg": scenario.object.mass },
        "after": {
            "floor_friction": friction.unwrap_or(scenario.object.floor_friction),
            "mass_kg": args.mass_kg.unwrap_or(scenario.object.mass),
        },
        "warmup_episodes": args.warmup,
        "episodes": args.episodes,
        "recovery": { "window_pushes": RECOVERY_WINDOW, "factor": RECOVERY_FACTOR },
        "online_learning": {
            "forgetting": OnlineLearningConfig::updating().forgetting,
            "gain_step": OnlineLearningConfig::updating().gain_step,
        },
        "frozen": condition_json(&frozen),
        "updating": condition_json(&updating),
        "wall_time_s": wall.elapsed().as_secs_f64(),
    });
    if let Some(out) = &args.json {
        let text = serde_json::to_string_pretty(&report)?;
        if out.as_os_str() == "-" {
            crate::say(format_args!("{text}"));
        } else {
            std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))?;
        }
    }
    Ok(report)
}
