//! `--mode place` and `--mode trajectory`: the paper's Algorithm 5 over the pipeline.
//!
//! The planner drives lockstep physics through [`LockstepDriver`] and runs one episode of
//! [`agp_planning::drive_episode`] from wherever the robot and the object are: it finds the
//! object, estimates its pose by circling it (IR and odometry only), plans each push on the
//! affordance gradient, pushes, carries the estimate on with the gradient's prediction and
//! circles again when the estimate has drifted. The gradient comes from the estimator's
//! `grids` topic, rebuilt from the published grids (the estimator learned it, or loaded an
//! AG file); the task goes out on the latched `task` topic, for the evaluation. Only the
//! `oracle` and the `model` read ground truth, and say so.
//!
//! A hot-swapped planner (epoch > 0) takes the world as it finds it: it finds the object
//! again and pushes on towards the same goal. So does a restarted one. The robot may then
//! have the object beside or behind it (its predecessor was travelling round the object or
//! circling it), while the episode's first step drives straight ahead to find it: a planner
//! that takes over a world under way first turns in place to face what its IR sees
//! ([`face_object`]). On the realtime clock physics steps before any planner comes: a
//! planner started on a world no planner drove faces the object as in lockstep and turns
//! not ([`under_way`]).

use std::time::Duration;

use agp_affordance::AffordanceGradient;
use agp_planning::{
    EpisodeConfig, EpisodeResult, ExternalPush, PlannerKind, PushQuery, Senses, Task, World,
    WorldStepError, drive_episode,
};
use agp_runtime::{AgpIpc, DriveError, Instance, LockstepDriver, SwapIn, TruthAccess};
use agp_shared_types::{LearnEvent, MAX_PATH_POINTS, ObjectEstimate, Pose2, TaskKind, stage};
use agp_world::{Pose, RobotDescription, ScenarioBrief};
use anyhow::{Context, Result, anyhow, bail};
use glam::DVec2;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::Node;

use crate::grid_link::GridLink;
use crate::push_service::{Pending, PushService};
use crate::ring::{EstimatorLink, EstimatorRestarted, Ring};

/// What `--mode place` and `--mode trajectory` were asked to do.
#[derive(Debug, Clone)]
pub struct TaskSettings {
    pub planner: PlannerKind,
    pub task: Task,
    pub epoch: u64,
    /// Physics steps on the wall clock (`AGP_CLOCK=realtime`): it has stepped before any
    /// planner came, so its step count says nothing of whether a planner drove.
    pub realtime: bool,
    /// Safety net of every wait on another process.
    pub timeout: Duration,
    /// How long the estimator may take to publish the gradients (it may be learning).
    pub gradient_timeout: Duration,
    /// Where the estimator looks for the AG file (`<results>/<object>.ag`), for messages.
    pub ag_file: std::path::PathBuf,
    /// Print every estimate and push.
    pub trace: bool,
    /// A push-level planner of another process chooses the pushes (`--skills`).
    pub skills: bool,
    /// The `model` planner's pushing model of the true object (ground truth); `None` for
    /// every other planner.
    pub model: Option<std::sync::Arc<agp_planning::PushModel>>,
    /// An object never pushed (`--from-prior`): no gradient to wait for; the first
    /// circling's prior comes as the estimator's first set.
    pub from_prior: bool,
}

/// The robot through the ring: one command per physics step, each frame acted on once the
/// estimator's estimate of it is in.
struct PipelineWorld {
    ring: Ring,
    /// Ground truth is read only for the oracle.
    oracle: bool,
    swap_in: Option<SwapIn>,
    /// This planner's epoch: its events supersede those of an older planner still running
    /// during a swap.
    epoch: u64,
    /// The estimator's grids, for the gradients it publishes again as it learns on
    /// (online learning); `None` for a planner that needs no gradient.
    grids: Option<GridLink>,
    /// The grids seq of the gradient the episode plans on.
    served_seq: u64,
    /// The object's name and where its AG file is (for the grid link's messages).
    object: String,
    ag_file: std::path::PathBuf,
    /// `--skills`: the push-level planner's service, and the live goal under way.
    push_service: Option<PushService>,
    goal_id: u64,
    realtime: bool,
}

impl World for PipelineWorld {
    fn senses(&self) -> Senses {
        let f = self.ring.driver.frame();
        Senses {
            ir_raw: f.ir_raw,
            ir_sample: f.ir_sample,
            odometry: f.odometry,
            fix: f.fix,
            fix_seq: f.fix_seq,
        }
    }

    fn perceived(&self) -> &ObjectEstimate {
        self.ring.estimate()
    }

    fn tell(&mut self, mut event: LearnEvent) -> Result<(), WorldStepError> {
        event.session = self.epoch + 1;
        self.ring
            .send(event)
            .map_err(|e| WorldStepError::Link(format!("{e:#}")))
    }

    fn sim_time(&self) -> f64 {
        self.ring.driver.frame().sim_time_s
    }

    fn step_count(&self) -> u64 {
        self.ring.driver.frame().step
    }

    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), WorldStepError> {
        let next = self.ring.step(left_mps, right_mps).map_err(|e| {
            match e.downcast_ref::<DriveError>() {
                Some(DriveError::Shutdown) => WorldStepError::Shutdown,
                Some(DriveError::PhysicsRestarted) => WorldStepError::Restarted,
                _ if e.is::<EstimatorRestarted>() => WorldStepError::EstimatorRestarted,
                _ => WorldStepError::Link(format!("{e:#}")),
            }
        })?;
        if let Some(s) = self.swap_in.take() {
            let applied = next.timing.stamps_ns[stage::COMMAND_APPLIED];
            s.driving(applied, crate::TIMEOUT)
                .map_err(|e| WorldStepError::Link(format!("{e:#}")))?;
        }
        Ok(())
    }

    fn external_push(&mut self, query: &PushQuery) -> Result<ExternalPush, WorldStepError> {
        let link = |e: anyhow::Error| WorldStepError::Link(format!("{e:#}"));
        let robot = self.ring.estimate().robot;
        let t = self.ring.driver.frame().sim_time_s;
        let goal_id = self.goal_id;
        let Some(service) = self.push_service.as_mut() else {
            return Ok(ExternalPush::Internal);
        };
        service.ask(query, goal_id, robot, t).map_err(link)?;
        if !self.realtime {
            // Lockstep: physics waits for the next command, and so does the run.
            return service
                .wait()
                .map_err(link)?
                .ok_or(WorldStepError::Shutdown);
        }
        // Realtime: the ring goes on with the wheels stopped until the answer is in.
        let start = std::time::Instant::now();
        loop {
            let Some(service) = self.push_service.as_mut() else {
                return Ok(ExternalPush::Internal);
            };
            if let Pending::Answer(a) = service.poll().map_err(link)? {
                return Ok(a);
            }
            if agp_runtime::shutdown_requested() {
                return Err(WorldStepError::Shutdown);
            }
            if start.elapsed() > crate::push_service::ANSWER_TIMEOUT {
                return Err(WorldStepError::Link(
                    "the push-level planner did not answer within 60 s".into(),
                ));
            }
            self.step(0.0, 0.0)?;
        }
    }

    fn object_truth(&self) -> Option<Pose> {
        self.oracle.then(|| self.ring.driver.truth().object)
    }

    /// A newer set of grids than the one the episode plans on: the estimator learned on
    /// (its estimates carry the newer seq) and the whole set is in. Between two pushes;
    /// the rebuild allocates, the frames do not.
    fn newer_gradient(&mut self) -> Option<AffordanceGradient> {
        let seq = self.ring.estimate().grids_seq;
        let link = self.grids.as_mut()?;
        if seq <= self.served_seq {
            return None;
        }
        match link.newer_available() {
            Ok(true) => {}
            Ok(false) => return None,
            Err(e) => {
                eprintln!("planner: the estimator's newer grids: {e:#}");
                return None;
            }
        }
        match link.wait_gradient(&self.object, Duration::from_secs(1), &self.ag_file) {
            Ok(g) => {
                self.served_seq = seq;
                println!("planner: planning on the estimator's grids seq {seq} (learned online)");
                Some(g)
            }
            Err(e) => {
                eprintln!("planner: the estimator's newer grids: {e:#}");
                None
            }
        }
    }
}

/// The task of `scenario` as `--mode` names it, with `--goal` in place of the scenario's.
pub fn task_of(scenario: &ScenarioBrief, kind: TaskKind, goal: Option<Pose2>) -> Task {
    match kind {
        TaskKind::Trajectory => Task::Trajectory {
            path: scenario.task.path.clone(),
            keep_heading_rad: scenario.task.keep_heading_rad,
        },
        _ => {
            let g = scenario.task.goal;
            Task::Place {
                goal: goal.unwrap_or(g),
            }
        }
    }
}

/// Runs one episode; returns when it ended (or on shutdown, with `Ok(None)`).
pub fn run(
    instance: &Instance,
    scenario: &ScenarioBrief,
    settings: &TaskSettings,
) -> Result<Option<EpisodeResult>> {
    let Some(mut session) = Session::open(instance, scenario, settings)? else {
        return Ok(None);
    };
    // A planner drove before this one came: it takes over a world under way.
    let taking_over = session.under_way(scenario, settings);
    session.pursue(scenario, &settings.task, taking_over)
}

/// A planner's hold on the ring for one task or many: the gradient, the ring to physics
/// and the estimator, and the task topic the judge reads.
pub struct Session {
    world: PipelineWorld,
    gradient: Option<AffordanceGradient>,
    robot: RobotDescription,
    tasks: TaskPublication,
    planner: PlannerKind,
    trace: bool,
    /// The `model` planner's pushing model of the true object.
    model: Option<std::sync::Arc<agp_planning::PushModel>>,
    /// The episode starts without a gradient and waits for the first circling's prior.
    from_prior: bool,
}

impl Session {
    /// Waits for the gradient (if the planner needs one), connects to physics and the
    /// estimator and, for a swapped-in planner, takes over the drive. `None` on shutdown.
    pub fn open(
        instance: &Instance,
        scenario: &ScenarioBrief,
        settings: &TaskSettings,
    ) -> Result<Option<Self>> {
        if let Task::Trajectory { path, .. } = &settings.task
            && path.len() > MAX_PATH_POINTS
        {
            bail!(
                "the trajectory has {} points; at most {MAX_PATH_POINTS} fit the task message",
                path.len()
            );
        }
        let robot = RobotDescription::epuck();
        let mut grids = None;
        let gradient = if settings.from_prior {
            grids = Some(GridLink::open(instance).context("cannot open the gradient grids")?);
            println!(
                "planner: `{}` was never pushed: circling it first for the estimator's prior",
                scenario.name
            );
            None
        } else if settings.planner.needs_gradient() {
            let link =
                grids.insert(GridLink::open(instance).context("cannot open the gradient grids")?);
            match link.wait_gradient(&scenario.name, settings.gradient_timeout, &settings.ag_file) {
                Ok(g) => Some(g),
                Err(e) if agp_runtime::shutdown_requested() => {
                    let _ = e;
                    return Ok(None);
                }
                Err(e) if e.is::<crate::grid_link::EstimatorWaitsToLearn>() => return Err(e),
                Err(e) => return Err(e).context("no affordance gradient from the estimator"),
            }
        } else {
            None
        };
        if let Some(g) = &gradient {
            describe(g);
        }
        let driver = match LockstepDriver::connect(
            instance,
            "planner",
            settings.epoch,
            if settings.planner.reads_ground_truth() {
                TruthAccess::GroundTruth
            } else {
                TruthAccess::SensesOnly
            },
            settings.timeout,
        ) {
            Ok(d) => d,
            Err(DriveError::Shutdown) => return Ok(None),
            Err(e) => return Err(e).context("cannot reach physics"),
        };
        let tasks = TaskPublication::open(instance)?;
        let link = EstimatorLink::open(instance, settings.timeout)?;
        // The ring first, then the swap: once this planner says it is ready, it has
        // everything to answer the next frame.
        let mut ring = match Ring::new(driver, link) {
            Ok(r) => r,
            Err(e) if agp_runtime::shutdown_requested() => {
                let _ = e;
                return Ok(None);
            }
            Err(e) => return Err(e).context("waiting for the estimator's first estimate"),
        };
        let swap_in = match SwapIn::start(instance, &mut ring.driver, crate::TIMEOUT) {
            Ok(s) => s,
            Err(e) if agp_runtime::shutdown_requested() => {
                let _ = e;
                return Ok(None);
            }
            Err(e) => return Err(e.into()),
        };
        let served_seq = ring.estimate().grids_seq;
        let mut world = PipelineWorld {
            ring,
            oracle: settings.planner.reads_ground_truth(),
            swap_in,
            epoch: settings.epoch,
            grids,
            served_seq,
            object: scenario.name.clone(),
            ag_file: settings.ag_file.clone(),
            push_service: if settings.skills {
                Some(PushService::open(instance, settings.epoch)?)
            } else {
                None
            },
            goal_id: 0,
            realtime: settings.realtime,
        };
        if world.swap_in.is_some() {
            // A swapped-in planner answers the first frame of its epoch at once, wheels
            // stopped: it starts its episode over from where the robot is, and the
            // handover costs physics no more than the period it takes.
            match world.step(0.0, 0.0) {
                Ok(()) => {}
                Err(WorldStepError::Shutdown) => return Ok(None),
                Err(e) => return Err(anyhow!(e)).context("the first command after the swap"),
            }
        }
        Ok(Some(Self {
            world,
            gradient,
            robot,
            tasks,
            planner: settings.planner,
            trace: settings.trace,
            model: settings.model.clone(),
            from_prior: settings.from_prior,
        }))
    }

    /// Whether a planner drove this world before this one came ([`under_way`]).
    pub fn under_way(&self, scenario: &ScenarioBrief, settings: &TaskSettings) -> bool {
        under_way(&self.world, settings, &scenario.robot.start)
    }

    /// The live session's goal under way (0: the scenario's task), for the push-level
    /// planner's requests.
    pub fn set_goal_id(&mut self, id: u64) {
        self.world.goal_id = id;
    }

    /// The world, for a planner that waits between goals.
    pub fn world(&mut self) -> &mut impl World {
        &mut self.world
    }

    /// Publishes `task` for the judge and runs one episode of it from wherever the robot
    /// and the object are; `taking_over`: the world is under way (another planner drove
    /// it, or an earlier goal), so the robot first turns to face the object. Returns when
    /// the episode ended (or on shutdown, with `Ok(None)`). A restarted physics or
    /// estimator starts the episode over.
    pub fn pursue(
        &mut self,
        scenario: &ScenarioBrief,
        task: &Task,
        taking_over: bool,
    ) -> Result<Option<EpisodeResult>> {
        self.tasks.send(scenario, task)?;
        let mut config = EpisodeConfig {
            trace: self.trace,
            model: self.model.clone(),
            await_gradient: self.from_prior && self.gradient.is_none(),
            ..EpisodeConfig::for_task(&scenario.task)
        };
        let planner = self.planner;
        let world = &mut self.world;
        // The oracle knows where the object is and needs no finding.
        let mut taking_over = taking_over && !planner.reads_ground_truth();
        println!(
            "planner `{}`{}: {} of `{}`",
            planner,
            match planner {
                PlannerKind::Oracle =>
                    " (reads the object's true pose: an upper bound, not a result)",
                PlannerKind::Model => {
                    " (reads the object's true pose, shape, mass and frictions: the classical model, not a result)"
                }
                _ => "",
            },
            describe_task(task),
            scenario.name
        );
        loop {
            if taking_over && world.step_count() > 0 {
                match face_object(world, &self.robot) {
                    Ok(facing) => println!(
                        "planner: taking over at step {}: {facing}",
                        world.step_count()
                    ),
                    Err(WorldStepError::Shutdown) => return Ok(None),
                    // A new world from the scenario's start: the robot faces the object.
                    Err(WorldStepError::Restarted) => {
                        println!("planner: physics restarted: the episode starts over");
                    }
                    Err(WorldStepError::EstimatorRestarted) => {
                        println!("planner: the estimator restarted: the episode starts over");
                    }
                    Err(e) => return Err(anyhow!(e)),
                }
            }
            config.start_from_estimate = taking_over;
            let outcome = drive_episode(
                world,
                &self.robot,
                self.gradient.as_ref(),
                planner,
                task,
                &config,
            );
            match outcome {
                Ok(r) => {
                    println!(
                        "planner `{}`: {} after {} pushes and {} circlings, {:.1} s simulated, {:.2} s wall{}",
                        r.planner,
                        r.end.name(),
                        r.pushes,
                        r.circlings,
                        r.sim_time_s,
                        r.wall_time_s,
                        r.final_estimate.map_or(String::new(), |p| format!(
                            "; the object estimated at ({:.1}, {:.1}) mm, {:.1} deg",
                            p.x * 1e3,
                            p.y * 1e3,
                            p.theta.to_degrees()
                        ))
                    );
                    return Ok(Some(r));
                }
                Err(agp_planning::EpisodeRunError::World(WorldStepError::Shutdown)) => {
                    return Ok(None);
                }
                Err(agp_planning::EpisodeRunError::World(WorldStepError::Restarted)) => {
                    // A new world from the scenario's start: the episode starts over,
                    // finding the object first, straight ahead.
                    println!("planner: physics restarted: the episode starts over");
                    taking_over = false;
                }
                Err(agp_planning::EpisodeRunError::World(WorldStepError::EstimatorRestarted)) => {
                    // The same world, but what the estimator perceived is gone: the
                    // episode starts over, finding the object first from wherever the
                    // robot is.
                    println!("planner: the estimator restarted: the episode starts over");
                    taking_over = !planner.reads_ground_truth();
                }
                Err(e) => return Err(anyhow!(e)),
            }
        }
    }
}

/// Whether a planner drove this world before this one came. In lockstep physics steps only
/// on commands: any step was a planner's. In realtime it steps from its start whether
/// commanded or not, so the steps say nothing: a planner swapped in (epoch > 0) takes over
/// a world under way, and so does one started again on a world whose robot has left its
/// start (odometry, noiseless while the wheels stand still). A fresh realtime start faces
/// the object as a fresh lockstep start does: no turn in place to find it.
fn under_way(world: &PipelineWorld, settings: &TaskSettings, start: &Pose) -> bool {
    if !settings.realtime {
        return world.step_count() > 0;
    }
    if settings.epoch > 0 {
        return true;
    }
    let odometry = world.senses().odometry;
    let moved = (odometry.position() - start.position()).length();
    let turned = agp_shared_types::angle::wrap_angle(odometry.theta - start.theta).abs();
    moved > 1e-4 || turned > 1e-3
}

/// How [`face_object`] left the robot.
enum Facing {
    /// A front ray saw the object at the start: nothing to do.
    Ahead,
    /// Turned `turned_rad` in place until a front ray gave the strongest reading.
    Turned { turned_rad: f64 },
    /// No ray saw anything within a full turn: the robot is back at its heading.
    NotSeen,
    /// The estimator holds the object's pose: the episode turns towards it.
    Estimated,
}

impl std::fmt::Display for Facing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Ahead => write!(f, "the object is ahead"),
            Self::Turned { turned_rad } => write!(
                f,
                "turned {:+.0} deg in place to face the object",
                turned_rad.to_degrees()
            ),
            Self::NotSeen => write!(f, "no IR sees the object within a full turn"),
            Self::Estimated => write!(f, "the estimator holds the object's pose"),
        }
    }
}

/// Wheel speed of the turn in place, as a fraction of the fastest: about 1 deg of turn
/// per IR sample.
const FACE_TURN_FRACTION: f64 = 0.25;

/// The sensor with the strongest reading among those that see something in range.
fn strongest(
    robot: &RobotDescription,
    ir_raw: &[f32; agp_shared_types::IR_SENSOR_COUNT],
) -> Option<usize> {
    ir_raw
        .iter()
        .enumerate()
        .filter(|&(_, &raw)| robot.response.distance(f64::from(raw)).is_some())
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
}

/// findObj for a planner that takes over a world under way: turns in place towards the
/// sensor with the strongest IR reading until it is one of the two front rays (IR1, IR8 at
/// +-17 deg), so the episode's approach, straight ahead, meets the object. At most one
/// full turn; the robot does not move from its place.
fn face_object(
    world: &mut PipelineWorld,
    robot: &RobotDescription,
) -> Result<Facing, WorldStepError> {
    let front = |i: usize| robot.ir_sensors[i].angle_rad.abs() < 20f64.to_radians();
    let senses = world.senses();
    if strongest(robot, &senses.ir_raw).is_some_and(front) {
        return Ok(Facing::Ahead);
    }
    let e = world.perceived();
    if e.valid == 1 && e.sigma_xy.is_finite() {
        // The episode faces the object where the estimator holds it.
        return Ok(Facing::Estimated);
    }
    let v = FACE_TURN_FRACTION * robot.max_wheel_speed;
    let rate = 2.0 * v / robot.axle_length;
    let limit = std::f64::consts::TAU / rate * 1.05;
    let t0 = world.sim_time();
    let mut heading = senses.odometry.theta;
    let mut turned = 0f64;
    let mut sample = senses.ir_sample;
    // Towards the strongest reading; left (counter-clockwise) when nothing is seen.
    let mut left =
        strongest(robot, &senses.ir_raw).is_none_or(|i| robot.ir_sensors[i].angle_rad > 0.0);
    while world.sim_time() - t0 < limit && turned.abs() < std::f64::consts::TAU {
        let (l, r) = if left { (-v, v) } else { (v, -v) };
        world.step(l, r)?;
        let s = world.senses();
        turned += agp_shared_types::angle::wrap_angle(s.odometry.theta - heading);
        heading = s.odometry.theta;
        if s.ir_sample == sample {
            continue;
        }
        sample = s.ir_sample;
        if let Some(i) = strongest(robot, &s.ir_raw) {
            if front(i) {
                return Ok(Facing::Turned { turned_rad: turned });
            }
            left = robot.ir_sensors[i].angle_rad > 0.0;
        }
    }
    Ok(Facing::NotSeen)
}

fn describe(g: &AffordanceGradient) {
    let alphas: Vec<String> = g.alphas_deg().map(|a| format!("{a:+.0}")).collect();
    println!(
        "planner: affordance gradient of `{}` from the estimator's grids: alphas {} deg, {} pushes",
        g.object_name(),
        alphas.join(", "),
        g.alphas_deg().filter_map(|a| g.push_count(a)).sum::<u64>()
    );
}

fn describe_task(task: &Task) -> String {
    match task {
        Task::Place { goal } => format!(
            "place at ({:.0}, {:.0}) mm, {:.0} deg",
            goal.x * 1e3,
            goal.y * 1e3,
            goal.theta.to_degrees()
        ),
        Task::Trajectory {
            path,
            keep_heading_rad,
        } => match keep_heading_rad {
            Some(h) => format!(
                "push along a {}-point path, heading within {:.0} deg of its tangent",
                path.len(),
                h.to_degrees()
            ),
            None => format!("push along a {}-point path", path.len()),
        },
    }
}

/// The instance's latched `task` topic, as this planner publishes it: the task under way,
/// what the judge scores. The publisher's history hands it to late readers while it lives.
struct TaskPublication {
    publisher: Publisher<AgpIpc, agp_shared_types::Task, ()>,
    _node: Node<AgpIpc>,
}

impl TaskPublication {
    fn open(instance: &Instance) -> Result<Self> {
        let node = instance
            .node("planner-task", false)
            .map_err(|e| anyhow!("cannot create the task node: {e:?}"))?;
        let topic = instance
            .task(&node)
            .map_err(|e| anyhow!("cannot open the task topic: {e:?}"))?;
        let publisher = topic
            .data
            .publisher_builder()
            .create()
            .map_err(|e| anyhow!("cannot publish the task: {e:?}"))?;
        Ok(Self {
            publisher,
            _node: node,
        })
    }

    /// Publishes `task` with the scenario's tolerances.
    fn send(&self, scenario: &ScenarioBrief, task: &Task) -> Result<()> {
        let t = &scenario.task;
        let mut msg = agp_shared_types::Task {
            kind: TaskKind::Place as u32,
            path_len: 0,
            goal: Pose2::default(),
            tolerance_m: t.tolerance_m,
            tolerance_rad: t.tolerance_rad,
            path: [[0.0; 2]; MAX_PATH_POINTS],
            max_pushes: t.max_pushes,
            _pad: 0,
            seed: t.seed,
            heading_tolerance_rad: 0.0,
        };
        match task {
            Task::Place { goal } => msg.goal = *goal,
            Task::Trajectory {
                path,
                keep_heading_rad,
            } => {
                msg.kind = TaskKind::Trajectory as u32;
                msg.heading_tolerance_rad = keep_heading_rad.unwrap_or(0.0);
                msg.path_len = path.len().min(MAX_PATH_POINTS) as u32;
                for (slot, p) in msg.path.iter_mut().zip(path.iter().copied()) {
                    *slot = DVec2::to_array(&p);
                }
            }
        }
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| anyhow!("cannot loan the task sample: {e:?}"))?;
        sample
            .write_payload(msg)
            .send()
            .map_err(|e| anyhow!("cannot send the task: {e:?}"))?;
        Ok(())
    }
}

/// Writes the planner's account of `r` (no ground truth in it) as one JSON object.
pub fn write_report(path: &std::path::Path, r: &EpisodeResult) -> Result<()> {
    let estimate = r.final_estimate.map(|p| {
        serde_json::json!({
            "x_mm": p.x * 1e3,
            "y_mm": p.y * 1e3,
            "theta_deg": p.theta.to_degrees(),
        })
    });
    let v = serde_json::json!({
        "planner": r.planner.name(),
        "end": r.end.name(),
        "pushes": r.pushes,
        "circlings": r.circlings,
        "sim_time_s": r.sim_time_s,
        "wall_time_s": r.wall_time_s,
        "final_estimate": estimate,
    });
    std::fs::write(path, format!("{v}\n"))
        .with_context(|| format!("cannot write the report {}", path.display()))
}
