//! Episodes of the benchmark tasks in-process against the physics library: the paper's
//! Algorithm 5 with the three planners, judged by ground truth.
//!
//! The gradient is learned from ground truth (true poses, true aim points) with the
//! paper's protocol and the episodes' own push, so that these tests isolate the planner
//! and its IR-only pose estimates from the estimator's learning (tested in
//! `agp-estimator`).

mod common;

use agp_affordance::AffordanceGradient;
use agp_harness::{place_goals, run_episode, trajectory_error};
use agp_physics::{Sim, SimConfig};
use agp_planning::{
    EpisodeConfig, EpisodeEnd, PlannerKind, Senses, Task, World, WorldStepError, drive_episode,
};
use agp_shared_types::Pose2;
use agp_world::{RobotDescription, Scenario};
use glam::DVec2;

fn setup(name: &str) -> (Scenario, RobotDescription, AffordanceGradient) {
    let scenario = Scenario::builtin(name).expect("built-in");
    let robot = RobotDescription::epuck();
    let ag = common::learn_from_truth(&scenario, &robot);
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

#[test]
fn the_oracle_places_the_triangle_at_every_goal() {
    let (scenario, robot, ag) = setup("triangle");
    let goals = place_goals(&scenario, 4, 11);
    let n = placed(&scenario, &robot, &ag, PlannerKind::Oracle, &goals);
    assert_eq!(n, goals.len(), "the oracle placed {n} of {}", goals.len());
}

#[test]
fn with_ir_only_estimates_the_affordance_planner_places_the_triangle_in_five_of_six_episodes() {
    let (scenario, robot, ag) = setup("triangle");
    let goals = place_goals(&scenario, 6, 5);
    let n = placed(&scenario, &robot, &ag, PlannerKind::Affordance, &goals);
    assert!(n >= 5, "placed {n} of {}", goals.len());
}

#[test]
fn with_ir_only_estimates_the_affordance_planner_places_the_l_in_three_of_four_episodes() {
    let (scenario, robot, ag) = setup("lshape");
    let goals = place_goals(&scenario, 4, 5);
    let n = placed(&scenario, &robot, &ag, PlannerKind::Affordance, &goals);
    assert!(n >= 3, "placed {n} of {}", goals.len());
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

#[test]
fn along_the_default_line_the_gradient_keeps_the_l_nearer_than_the_baseline_does() {
    let (scenario, robot, ag) = setup("lshape");
    let path = scenario.task.path.clone();
    let config = EpisodeConfig::for_task(&scenario.task);
    let task = Task::Trajectory {
        path: path.clone(),
        keep_heading_rad: None,
    };
    let mut errors = Vec::new();
    for planner in [PlannerKind::Affordance, PlannerKind::Baseline] {
        let r = run_episode(&scenario, &robot, Some(&ag), planner, &task, &config)
            .expect("the episode runs");
        let judged = r
            .evaluation
            .clone()
            .expect("in-process episodes are judged");
        let poses: Vec<Pose2> = judged.samples.iter().map(|s| s.pose).collect();
        let e = trajectory_error(&path, &poses).expect("recorded poses");
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
        // The object is recorded while it is pushed, about every 50 ms: a 600 mm line at
        // about 45 mm per push is over 50 points.
        assert!(poses.len() > 50, "{planner}: {} points", poses.len());
        assert!(e < 0.005, "{planner}: mean error {:.1} mm", e * 1e3);
        errors.push(e);
    }
    assert!(
        errors[0] < errors[1],
        "affordance {:.2} mm, baseline {:.2} mm per point",
        errors[0] * 1e3,
        errors[1] * 1e3
    );
}

#[test]
fn around_a_90_degree_bend_the_gradients_pushes_keep_the_l_nearer_than_the_baselines() {
    let (scenario, robot, ag) = setup("lshape");
    let path = agp_harness::task_goals::NamedPath::Bend90.points(&scenario);
    let config = EpisodeConfig::for_task(&scenario.task);
    let task = Task::Trajectory {
        path: path.clone(),
        keep_heading_rad: None,
    };
    let mut errors = Vec::new();
    for planner in [PlannerKind::Affordance, PlannerKind::Baseline] {
        let r = run_episode(&scenario, &robot, Some(&ag), planner, &task, &config)
            .expect("the episode runs");
        let judged = r
            .evaluation
            .clone()
            .expect("in-process episodes are judged");
        assert!(
            judged.success,
            "{planner} did not reach the end: {:?}",
            r.end
        );
        let poses: Vec<Pose2> = judged.samples.iter().map(|s| s.pose).collect();
        errors.push(trajectory_error(&path, &poses).expect("recorded poses"));
    }
    // On the tuning seeds the gradient's pushes kept within 0.4 of the baseline's error
    // round this bend; a margin of 0.8 leaves room for one seed's noise.
    assert!(
        errors[0] < 0.8 * errors[1],
        "affordance {:.2} mm, baseline {:.2} mm per point",
        errors[0] * 1e3,
        errors[1] * 1e3
    );
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
