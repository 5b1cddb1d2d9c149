//! The in-process world: the physics library stepped in this process and the estimator's
//! perception ([`ObjectTracker`]) beside it, for the benchmarks' `--in-process` runs, the
//! tests and the examples. The planner sees what it sees over the pipeline: the estimate
//! of each frame, made before the planner acts on the frame, and its events taken before
//! the next frame. It offers ground truth, so episodes run against it are judged; the
//! planner reads it only as the `oracle`.

use agp_affordance::{AffordanceGradient, ContactPriorConfig};
use agp_perception::{ObjectTracker, OnlineLearningConfig, TrackerConfig, TrackerError};
use agp_physics::{Sim, SimBuildError, SimConfig};
use agp_planning::{
    EpisodeConfig, EpisodeResult, EpisodeRunError, PlannerKind, Senses, Task, World,
    WorldStepError, drive_episode,
};
use agp_shared_types::{LearnEvent, ObjectEstimate};
use agp_world::{Pose, RobotDescription, Scenario};

/// The physics library as a [`World`], perceived by an [`ObjectTracker`].
pub struct InProcessWorld {
    sim: Sim,
    tracker: ObjectTracker,
    /// The tracker's estimate of the latest frame.
    estimate: ObjectEstimate,
    /// The tracker's gradient generation the planner has (online learning).
    served_generation: u64,
}

impl InProcessWorld {
    /// The world of `sim`, perceived for a robot of `robot`'s description; with `ag` the
    /// tracker also locates the object (as the estimator does once it has gradients).
    pub fn new(
        sim: Sim,
        robot: &RobotDescription,
        ag: Option<&AffordanceGradient>,
    ) -> Result<Self, TrackerError> {
        Self::with_tracker(sim, robot, ag, TrackerConfig::default())
    }

    /// [`InProcessWorld::new`] with a tracker of `config` (e.g. online learning on: the
    /// planner then gets each gradient the tracker learns, between two pushes).
    pub fn with_tracker(
        sim: Sim,
        robot: &RobotDescription,
        ag: Option<&AffordanceGradient>,
        config: TrackerConfig,
    ) -> Result<Self, TrackerError> {
        let mut tracker = ObjectTracker::try_new(robot, config)?;
        if let Some(ag) = ag {
            tracker.set_gradient(ag)?;
        }
        let served_generation = tracker.gradient_generation();
        let mut world = Self {
            sim,
            tracker,
            estimate: ObjectEstimate::default(),
            served_generation,
        };
        world.perceive();
        Ok(world)
    }

    /// The tracker observes the latest frame and writes its estimate.
    fn perceive(&mut self) {
        let s = self.sim.sensors();
        self.tracker
            .observe(s.ir_sample, &s.ir_raw, s.odometry, s.fix, s.fix_seq);
        self.estimate = ObjectEstimate {
            step: self.sim.step_count(),
            // The set the estimator would have published, one per gradient version: a
            // version the events before this frame made (a circling's end) shows from
            // this frame on, as the estimator publishes the grids before the frame's
            // estimate.
            grids_seq: self.tracker.gradient_generation(),
            ..ObjectEstimate::default()
        };
        self.tracker.write_estimate(&mut self.estimate);
    }

    /// The simulation, for ground truth.
    pub fn sim(&self) -> &Sim {
        &self.sim
    }

    /// The simulation, to move things by hand (tests).
    pub fn sim_mut(&mut self) -> &mut Sim {
        &mut self.sim
    }

    /// The estimator's perception (its gradient, as learned on online).
    pub fn tracker(&self) -> &ObjectTracker {
        &self.tracker
    }

    /// The estimator's perception, to set it up (an object never pushed:
    /// [`ObjectTracker::start_from_prior`]).
    pub fn tracker_mut(&mut self) -> &mut ObjectTracker {
        &mut self.tracker
    }

    /// The world is put back for a new episode: the object and the robot at the given
    /// poses, the tracker forgetting the object (as the estimator does at a reset) but
    /// keeping its gradient, as learned on: the next episode starts with it (take it
    /// from [`InProcessWorld::tracker`]), and [`World::newer_gradient`] offers only what
    /// is learned from here on.
    pub fn reset(&mut self, object: Pose, robot: Pose) {
        self.sim.reset(object, robot);
        self.tracker.reset();
        self.served_generation = self.tracker.gradient_generation();
        self.perceive();
    }
}

impl World for InProcessWorld {
    fn senses(&self) -> Senses {
        let s = self.sim.sensors();
        Senses {
            ir_raw: s.ir_raw,
            ir_sample: s.ir_sample,
            odometry: s.odometry,
            fix: s.fix,
            fix_seq: s.fix_seq,
        }
    }

    fn perceived(&self) -> &ObjectEstimate {
        &self.estimate
    }

    fn tell(&mut self, event: LearnEvent) -> Result<(), WorldStepError> {
        self.tracker.handle(&event);
        Ok(())
    }

    fn sim_time(&self) -> f64 {
        self.sim.sim_time()
    }

    fn step_count(&self) -> u64 {
        self.sim.step_count()
    }

    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), WorldStepError> {
        self.sim.step(left_mps, right_mps);
        self.perceive();
        Ok(())
    }

    fn object_truth(&self) -> Option<Pose> {
        Some(self.sim.object_pose())
    }

    fn newer_gradient(&mut self) -> Option<AffordanceGradient> {
        let generation = self.tracker.gradient_generation();
        if generation == self.served_generation {
            return None;
        }
        self.served_generation = generation;
        self.tracker.gradient().cloned()
    }
}

/// Why an in-process episode could not run.
#[derive(Debug, thiserror::Error)]
pub enum InProcessEpisodeError {
    #[error(transparent)]
    Sim(#[from] SimBuildError),
    #[error(transparent)]
    Tracker(#[from] TrackerError),
    #[error(transparent)]
    Episode(#[from] EpisodeRunError),
}

/// Runs one episode of `task` with `planner` on `scenario` against the in-process physics
/// library (the object and robot at the scenario's start poses, sensor noise seeded by
/// `config.seed`), judged by its ground truth. `ag` is required by the affordance and
/// oracle planners; the `model` planner gets its pushing model of the scenario's object
/// here when `config` holds none.
pub fn run_episode(
    scenario: &Scenario,
    robot: &RobotDescription,
    ag: Option<&AffordanceGradient>,
    planner: PlannerKind,
    task: &Task,
    config: &EpisodeConfig,
) -> Result<EpisodeResult, InProcessEpisodeError> {
    let sim = seeded_sim(scenario, robot, config.seed)?;
    let mut world = InProcessWorld::new(sim, robot, ag)?;
    let modelled;
    let config = if planner == PlannerKind::Model && config.model.is_none() {
        modelled = EpisodeConfig {
            model: Some(std::sync::Arc::new(agp_planning::PushModel::from_scenario(
                scenario, robot,
            ))),
            ..config.clone()
        };
        &modelled
    } else {
        config
    };
    let result = drive_episode(&mut world, robot, ag, planner, task, config)?;
    // The judge: orientation modulo the object's true symmetry, which only it may read.
    Ok(result.judged(task, scenario.object.shape.symmetry_order(), config))
}

/// The physics of one episode: `scenario` with `robot`, its noise drawn from `seed`.
fn seeded_sim(
    scenario: &Scenario,
    robot: &RobotDescription,
    seed: u64,
) -> Result<Sim, SimBuildError> {
    Sim::new(
        scenario,
        robot,
        SimConfig {
            seed,
            ..SimConfig::default()
        },
    )
}

/// Runs one episode of an object never pushed before (`agp bench online --in-process`):
/// as [`run_episode`], but the tracker starts without a gradient, builds the contact prior
/// from the episode's first circling and learns on from every push
/// ([`OnlineLearningConfig::updating`]), as `agp-estimator --learn-online --from-prior`
/// does; the planner waits for the prior ([`EpisodeConfig::await_gradient`]) and plans on
/// each gradient the tracker learns.
pub fn run_online_episode(
    scenario: &Scenario,
    robot: &RobotDescription,
    planner: PlannerKind,
    task: &Task,
    config: &EpisodeConfig,
) -> Result<EpisodeResult, InProcessEpisodeError> {
    run_online_episode_with(
        scenario,
        robot,
        planner,
        task,
        config,
        OnlineLearningConfig::updating(),
        ContactPriorConfig::default(),
    )
}

/// [`run_online_episode`] with the tracker's online learning and prior of `online` and
/// `prior` (tuning: the estimator's are the defaults).
pub fn run_online_episode_with(
    scenario: &Scenario,
    robot: &RobotDescription,
    planner: PlannerKind,
    task: &Task,
    config: &EpisodeConfig,
    online: OnlineLearningConfig,
    prior: ContactPriorConfig,
) -> Result<EpisodeResult, InProcessEpisodeError> {
    let sim = seeded_sim(scenario, robot, config.seed)?;
    let mut world = InProcessWorld::with_tracker(
        sim,
        robot,
        None,
        TrackerConfig {
            online,
            ..TrackerConfig::default()
        },
    )?;
    world.tracker_mut().start_from_prior(&scenario.name, prior);
    let config = EpisodeConfig {
        await_gradient: true,
        ..config.clone()
    };
    let result = drive_episode(&mut world, robot, None, planner, task, &config)?;
    Ok(result.judged(task, scenario.object.shape.symmetry_order(), &config))
}
