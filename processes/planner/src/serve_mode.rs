//! `--mode serve`: the planner of a live session. It pursues the goals the supervisor
//! publishes on the latched `goal` topic (queued with `agp goal`), one after the other,
//! each an episode of Algorithm 5 from wherever the last one left the robot and the
//! object, and tells the supervisor when each ended (`GoalDone`), which has the judge
//! score it. Between goals it keeps the ring going with the wheels stopped, so physics,
//! the estimator and a hot swap see a planner that drives; it serves until `agp down`.
//!
//! A planner swapped in or restarted mid-goal takes the goal under way from the topic's
//! history and pursues it from where the world is.

use std::time::Duration;

use agp_planning::{Task, World, WorldStepError};
use agp_runtime::control_client::ControlClient;
use agp_runtime::{Instance, shutdown_requested};
use agp_shared_types::{ControlKind, ControlRequest, Goal, read_str, write_str};
use agp_world::ScenarioBrief;
use anyhow::{Context, Result, anyhow};

use crate::task_mode::{Session, TaskSettings};

/// Serves goals until shutdown. `paced`: on the lockstep clock, idle steps are spaced one
/// physics period apart on the wall clock (the realtime clock paces them itself).
pub fn run(
    instance: &Instance,
    scenario: &ScenarioBrief,
    settings: &TaskSettings,
    paced: bool,
    rate_hz: f64,
) -> Result<()> {
    let Some(mut session) = Session::open(instance, scenario, settings)? else {
        return Ok(());
    };
    let node = instance
        .node("planner-goals", false)
        .map_err(|e| anyhow!("cannot create the goals node: {e:?}"))?;
    let goals = instance
        .goal(&node)
        .map_err(|e| anyhow!("cannot open the goal topic: {e:?}"))?
        .subscriber()
        .create()
        .map_err(|e| anyhow!("cannot subscribe to the goals: {e:?}"))?;
    let client = ControlClient::open(instance, &node, settings.timeout)
        .context("cannot reach the supervisor for the goals")?;
    println!(
        "planner `{}`: serving the goals of `{}` (agp goal --instance {} --place X Y THETA; \
         across a bridge, on the instance that runs physics)",
        settings.planner,
        scenario.name,
        instance.name()
    );
    let period = Duration::from_secs_f64(1.0 / rate_hz.max(1.0));
    let mut latest = Goal::default();
    // The last goal this planner ended: the topic still holds it until the next one.
    let mut ended = 0;
    // A swapped-in or restarted planner finds the world under way; so does every goal
    // after the first.
    let mut under_way = session.under_way(scenario, settings);
    loop {
        if shutdown_requested() {
            return Ok(());
        }
        while let Ok(Some(g)) = goals.receive() {
            latest = *g;
        }
        if latest.id != 0 && latest.id != ended {
            let Some(task) = Task::from_message(&latest.task) else {
                return Err(anyhow!(
                    "goal {} has an unknown task kind {}",
                    latest.id,
                    latest.task.kind
                ));
            };
            println!("planner: goal {}", latest.id);
            session.set_goal_id(latest.id);
            let Some(result) = session.pursue(scenario, &task, under_way)? else {
                return Ok(());
            };
            under_way = true;
            ended = latest.id;
            let mut request = ControlRequest::new(ControlKind::GoalDone);
            request.goal.id = latest.id;
            write_str(&mut request.name, result.end.name());
            request.value_ns = (result.sim_time_s * 1e9) as u64;
            let answer = client.ask(&request, settings.timeout)?;
            if answer.ok == 0 {
                // Another planner (a swap's predecessor) ended it first.
                println!(
                    "planner: the supervisor did not take goal {} as ended: {}",
                    latest.id,
                    read_str(&answer.message)
                );
            }
            continue;
        }
        // No goal: wheels stopped, the ring kept going.
        match session.world().step(0.0, 0.0) {
            Ok(()) => {}
            Err(WorldStepError::Shutdown) => return Ok(()),
            Err(WorldStepError::Restarted | WorldStepError::EstimatorRestarted) => {}
            Err(e) => return Err(anyhow!(e)),
        }
        if paced {
            std::thread::sleep(period);
        }
    }
}
