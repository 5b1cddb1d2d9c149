//! Episodes of the benchmark tasks in-process against the physics library: the paper's
//! Algorithm 5 with the three planners, judged by ground truth.
//!
//! The gradient is learned from ground truth (true poses, true aim points) with the
//! paper's protocol and the episodes' own push, so that these tests isolate the planner
//! and its IR-only pose estimates from the estimator's learning (tested in
//! `agp-estimator`).

mod common;

use std::sync::OnceLock;

use agp_affordance::AffordanceGradient;
use agp_harness::{place_goals, run_episode, trajectory_error};
use agp_physics::{Sim, SimConfig};
use agp_planning::{
    EpisodeConfig, EpisodeEnd, PlannerKind, Senses, Task, World, WorldStepError, drive_episode,
};
use agp_shared_types::Pose2;
use agp_world::{RobotDescription, Scenario};
use glam::DVec2;

/// The built-in `name` (`triangle` or `lshape`), the E-puck and the object's gradient
/// learned from ground truth, learned once per test run and shared by the tests (the
/// learning is deterministic: each test would learn the same gradient).
fn setup(name: &str) -> (Scenario, RobotDescription, &'static AffordanceGradient) {
    static TRIANGLE: OnceLock<AffordanceGradient> = OnceLock::new();
    static LSHAPE: OnceLock<AffordanceGradient> = OnceLock::new();
    let scenario = Scenario::builtin(name).expect("built-in");
    let robot = RobotDescription::epuck();
    let learned = match name {
        "triangle" => &TRIANGLE,
        "lshape" => &LSHAPE,
        other => panic!("no gradient kept for `{other}`"),
    };
    let ag = learned.get_or_init(|| common::learn_from_truth(&scenario, &robot));
    (scenario, robot, ag)
}

/// Runs `planner` on `goals` (sensor noise seeded per episode); how many were placed.
fn placed(
    scenario: &Scenario,
    robot: &RobotDescription,
    ag: &AffordanceGradient,
    planner: PlannerKind,
    goals: &[Pose2],
) -> usize {
    let base = EpisodeConfig::for_task(&scenario.task);
    goals
        .iter()
        .enumerate()
        .filter(|(k, goal)| {
            let config = EpisodeConfig {
                seed: base.seed + *k as u64,
                ..base.clone()
            };
            let task = Task::Place { goal: **goal };
            let r = run_episode(scenario, robot, Some(ag), planner, &task, &config)
                .expect("the episode runs");
            let e = r
                .evaluation
                .clone()
                .expect("in-process episodes are judged");
            println!(
                "{planner} to ({:.0}, {:.0}) mm, {:.0} deg: {} ({}) after {} pushes, {} circlings, \
                 error {:.1} mm, {:.1} deg",
                goal.x * 1e3,
                goal.y * 1e3,
                goal.theta.to_degrees(),
                if e.success { "placed" } else { "NOT placed" },
                r.end.name(),
                r.pushes,
                r.circlings,
                e.position_error_mm,
                e.orientation_error_deg
            );
            e.success
        })
        .count()
}

/// Runs `planner` on `count` goals of built-in `name` (drawn with `goal_seed`) and fails
/// unless it places the object at every one. The episodes are deterministic for their seeds
/// (in-process physics, seeded noise), so there is no margin: the README reports that the
/// affordance planner places both objects at every goal (100 % on the held-out seeds), and
/// one goal missed here is a change of what we claim.
#[track_caller]
fn assert_places_every_goal(name: &str, planner: PlannerKind, count: usize, goal_seed: u64) {
    let (scenario, robot, ag) = setup(name);
    let goals = place_goals(&scenario, count, goal_seed);
    let n = placed(&scenario, &robot, ag, planner, &goals);
    assert_eq!(n, goals.len(), "{planner} placed {n} of {}", goals.len());
}

#[test]
fn the_oracle_places_the_triangle_at_every_goal() {
    assert_places_every_goal("triangle", PlannerKind::Oracle, 4, 11);
}

#[test]
fn with_ir_only_estimates_the_affordance_planner_places_the_triangle_at_every_goal() {
    assert_places_every_goal("triangle", PlannerKind::Affordance, 6, 5);
}

#[test]
fn with_ir_only_estimates_the_affordance_planner_places_the_l_at_every_goal() {
    assert_places_every_goal("lshape", PlannerKind::Affordance, 4, 5);
}

#[test]
fn the_baselines_centroid_pushes_bring_the_object_towards_the_goal_without_a_gradient() {
    let scenario = Scenario::builtin("triangle").expect("built-in");
    let robot = RobotDescription::epuck();
    let goal = Pose2::new(0.3, 0.2, 1.0);
    let config = EpisodeConfig {
        max_pushes: 3,
        ..EpisodeConfig::for_task(&scenario.task)
    };
    // No gradient at all: the baseline does not need one.
    let r = run_episode(
        &scenario,
        &robot,
        None,
        PlannerKind::Baseline,
        &Task::Place { goal },
        &config,
    )
    .expect("the baseline runs without a gradient");
    let e = r.evaluation.expect("in-process episodes are judged");
    assert_eq!(r.end, EpisodeEnd::MaxPushes);
    let start = DVec2::new(goal.x, goal.y).length();
    let end = e.position_error_mm * 1e-3;
    // Three pushes of about 45 mm each, through the centroid towards the goal.
    assert!(
        start - end > 0.1,
        "the object came {:.0} mm nearer, from {:.0} to {:.0} mm",
        (start - end) * 1e3,
        start * 1e3,
        end * 1e3
    );
}

#[test]
fn the_affordance_and_oracle_planners_refuse_to_run_without_a_gradient() {
    let scenario = Scenario::builtin("triangle").expect("built-in");
    let robot = RobotDescription::epuck();
    let config = EpisodeConfig::for_task(&scenario.task);
    let task = Task::Place {
        goal: Pose2::new(0.3, 0.0, 0.0),
    };
    for planner in [PlannerKind::Affordance, PlannerKind::Oracle] {
        assert!(run_episode(&scenario, &robot, None, planner, &task, &config).is_err());
    }
}

/// The affordance planner and the baseline along `path` from the L's start: each one's
/// mean distance of the centroid to the path per recorded point (m), in that order. Fails
/// unless both reached the path's end.
fn trajectory_errors(
    scenario: &Scenario,
    robot: &RobotDescription,
    ag: &AffordanceGradient,
    path: &[DVec2],
) -> [f64; 2] {
    let config = EpisodeConfig::for_task(&scenario.task);
    let task = Task::Trajectory {
        path: path.to_vec(),
        keep_heading_rad: None,
    };
    [PlannerKind::Affordance, PlannerKind::Baseline].map(|planner| {
        let r = run_episode(scenario, robot, Some(ag), planner, &task, &config)
            .expect("the episode runs");
        let judged = r
            .evaluation
            .clone()
            .expect("in-process episodes are judged");
        let poses: Vec<Pose2> = judged.samples.iter().map(|s| s.pose).collect();
        let e = trajectory_error(path, &poses).expect("recorded poses");
        println!(
            "{planner}: mean error {:.2} mm over {} points, {} pushes, end {:.1} mm off",
            e * 1e3,
            poses.len(),
            r.pushes,
            judged.position_error_mm
        );
        assert!(
            judged.success,
            "{planner} did not reach the end: {:?}",
            r.end
        );
        // The object is recorded while it is pushed, about every 50 ms: a 550-600 mm path
        // at about 45 mm per push is over 50 points.
        assert!(poses.len() > 50, "{planner}: {} points", poses.len());
        e
    })
}

/// The project's trajectory target: the affordance planner's mean error at most 0.6 of the
/// baseline's on every path (README, The paper's tasks).
const TARGET_TRAJECTORY_RATIO: f64 = 0.6;

#[track_caller]
fn assert_ratio_within_target(affordance: f64, baseline: f64) {
    assert!(
        affordance < TARGET_TRAJECTORY_RATIO * baseline,
        "affordance {:.2} mm, baseline {:.2} mm per point: ratio {:.2}",
        affordance * 1e3,
        baseline * 1e3,
        affordance / baseline
    );
}

#[test]
fn along_the_default_line_the_gradient_keeps_the_l_nearer_than_the_baseline_does() {
    let (scenario, robot, ag) = setup("lshape");
    let path = scenario.task.path.clone();
    let [affordance, baseline] = trajectory_errors(&scenario, &robot, ag, &path);
    for (planner, e) in [("affordance", affordance), ("baseline", baseline)] {
        assert!(e < 0.005, "{planner}: mean error {:.1} mm", e * 1e3);
    }
    // The project's target is a ratio of at most 0.6 on every path (README, The paper's
    // tasks); this deterministic episode measured 0.47 (2.03 / 4.32 mm) when the assertion
    // was set, so 0.6 leaves 0.13 for a change of the planner that moves this one episode.
    // (The README's 0.35 is the ratio of the mean errors over seeds 200-219: one seed cannot
    // hold a mean.)
    assert_ratio_within_target(affordance, baseline);
}

#[test]
fn around_a_90_degree_bend_the_gradients_pushes_keep_the_l_nearer_than_the_baselines() {
    let (scenario, robot, ag) = setup("lshape");
    let path = agp_harness::task_goals::NamedPath::Bend90.points(&scenario);
    let [affordance, baseline] = trajectory_errors(&scenario, &robot, ag, &path);
    // The README reports 0.42 for this bend, the ratio of the mean errors over seeds
    // 200-219, within the project's target of 0.6 per path. This deterministic episode
    // measured 0.58 (2.25 / 3.86 mm) when the assertion was set: it is held to the target,
    // with 0.02 to spare. Single seeds of that sweep spread widely (seed 216's 45 deg bend
    // is above 1), so a change of the planner can move this one episode past it: then run
    // `agp bench trajectory --seeds 20 --first-seed 200` before moving the bound.
    assert_ratio_within_target(affordance, baseline);
}

#[test]
fn an_episodes_time_limit_counts_from_its_own_start_not_from_the_worlds() {
    // Regression: the limit was checked against the world's clock, so a world that had
    // run for longer than the limit (one physics process serving many episodes) and that
    // offers no ground truth (the pipeline) ended every later episode at once.
    let scenario = Scenario::builtin("triangle").expect("built-in");
    let robot = RobotDescription::epuck();
    let config = EpisodeConfig {
        max_pushes: 1,
        max_sim_time_s: 60.0,
        ..EpisodeConfig::for_task(&scenario.task)
    };
    let mut sim = Sim::new(&scenario, &robot, SimConfig::default()).expect("sim");
    while sim.sim_time() < 2.0 * config.max_sim_time_s {
        sim.step(0.0, 0.0);
    }
    let mut world =
        WithoutTruth(agp_harness::InProcessWorld::new(sim, &robot, None).expect("tracker"));
    let r = drive_episode(
        &mut world,
        &robot,
        None,
        PlannerKind::Baseline,
        &Task::Place {
            goal: Pose2::new(0.3, 0.0, 0.0),
        },
        &config,
    )
    .expect("the episode runs");
    assert_eq!(r.end, EpisodeEnd::MaxPushes, "{r:?}");
    assert!(r.sim_time_s < config.max_sim_time_s, "{} s", r.sim_time_s);
}

/// The in-process physics as the pipeline's planner sees it: no ground truth.
struct WithoutTruth(agp_harness::InProcessWorld);

impl World for WithoutTruth {
    fn senses(&self) -> Senses {
        World::senses(&self.0)
    }
    fn perceived(&self) -> &agp_shared_types::ObjectEstimate {
        World::perceived(&self.0)
    }
    fn tell(&mut self, event: agp_shared_types::LearnEvent) -> Result<(), WorldStepError> {
        World::tell(&mut self.0, event)
    }
    fn sim_time(&self) -> f64 {
        World::sim_time(&self.0)
    }
    fn step_count(&self) -> u64 {
        World::step_count(&self.0)
    }
    fn step(&mut self, left_mps: f64, right_mps: f64) -> Result<(), WorldStepError> {
        World::step(&mut self.0, left_mps, right_mps)
    }
    fn object_truth(&self) -> Option<agp_world::Pose> {
        None
    }
}
