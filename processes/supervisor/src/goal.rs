//! `agp goal`: queue a goal on a live session's supervisor and say where it stands.

use agp_runtime::control_client;
use agp_supervisor::GoalSpec;
use anyhow::Result;

use crate::{control, goals};

/// Give a live session a goal (a placement or a path).
#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("what").required(true).args(["place", "path"])))]
pub struct GoalArgs {
    /// Place the object at X_MM Y_MM (world frame, millimetres) turned THETA_DEG degrees.
    #[arg(long, num_args = 3, value_names = ["X_MM", "Y_MM", "THETA_DEG"], allow_hyphen_values = true)]
    place: Option<Vec<f64>>,
    /// Push the object's centroid along this path: 2 to 32 points X,Y in millimetres.
    #[arg(long, num_args = 2.., value_name = "X,Y", allow_hyphen_values = true)]
    path: Option<Vec<String>>,
    /// With --path: keep the object's heading (its frame's x axis) tangent to the path
    /// within DEG degrees, in (0, 180]; the affordance planner weighs it in every push.
    #[arg(long, value_name = "DEG", requires = "path")]
    keep_heading: Option<f64>,
    #[command(flatten)]
    target: control::InstanceArg,
    /// Print JSON: the goal's id and the goals so far.
    #[arg(long)]
    json: bool,
}

pub fn run(args: &GoalArgs) -> Result<u8> {
    let spec = match (&args.place, &args.path) {
        (Some(p), _) => GoalSpec::place(p[0], p[1], p[2]),
        (None, Some(words)) => GoalSpec::path(words, args.keep_heading),
        (None, None) => unreachable!("clap requires --place or --path"),
    }
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let name = args.target.name()?;
    let mut request = agp_shared_types::ControlRequest::new(agp_shared_types::ControlKind::Goal);
    request.goal = spec.to_goal();
    let r = control_client::ask_with(&name, request, control_client::ANSWER_TIMEOUT)?;
    if r.ok == 0 {
        anyhow::bail!(
            "instance `{name}` refused the goal: {}",
            agp_shared_types::read_str(&r.message)
        );
    }
    let report = control::StatusReport::new(&name, &r);
    if args.json {
        let doc = serde_json::json!({
            "instance": name,
            "goal_id": r.goal_id,
            "goals": report.goals,
        });
        println!("{doc:#}");
    } else {
        let ahead = report
            .goals
            .iter()
            .filter(|g| g.id < r.goal_id && g.state != "done")
            .count();
        let what = report
            .goals
            .iter()
            .find(|g| g.id == r.goal_id)
            .map_or_else(String::new, goals::GoalReport::what);
        println!(
            "goal {} queued on `{name}`: {what} ({})",
            r.goal_id,
            match ahead {
                0 => "pursued now".to_owned(),
                1 => "after 1 goal".to_owned(),
                n => format!("after {n} goals"),
            }
        );
    }
    Ok(0)
}
