//! Who reads ground truth, asked of iceoryx2 itself while a placement runs over the whole
//! pipeline: the supervisor's judge, and the planner only when it is the `oracle` or the
//! `model` (which also reads the object's shape, mass and frictions from the scenario, for
//! its pushing model). The estimator and the `affordance` and `baseline` planners never
//! subscribe to it.

use std::collections::BTreeSet;
use std::time::Duration;

use agp_runtime::{AgpIpc, Instance};
use agp_tests::{AgpUp, LaunchDir, count_instance_files, learned_ag, triangle_ring_launch};
use iceoryx2::node::{NodeState, NodeView};
use iceoryx2::prelude::{CallbackProgression, Node, NodeBuilder};
use iceoryx2::service::port_factory::PortFactory;

/// Safety net of every wait; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(120);

/// The triangle's ring with `planner` placing the triangle; its end ends the run.
fn launch(instance: &str, planner: &str, ag: &std::path::Path) -> String {
    triangle_ring_launch(
        instance,
        ag,
        "",
        &format!(r#""--mode", "place", "--planner", "{planner}""#),
        true,
    )
}

/// The names of the nodes that hold a subscriber of the instance's ground truth, and
/// whether the planner has published its task (it does once it drives physics).
fn readers(instance: &Instance, observer: &Node<AgpIpc>) -> (BTreeSet<String>, bool) {
    let truth = instance
        .ground_truth(observer)
        .expect("open the ground truth");
    let mut ids = Vec::new();
    truth.data.dynamic_config().list_subscribers(|d| {
        ids.push(d.node_id);
        CallbackProgression::Continue
    });
    let mut names = BTreeSet::new();
    Node::<AgpIpc>::list(instance.config(), |state| {
        if let NodeState::Alive(view) = &state
            && ids.contains(view.id())
            && let Some(details) = view.details().as_ref()
        {
            names.insert(details.name().to_string());
        }
        CallbackProgression::Continue
    })
    .expect("list the instance's nodes");
    let task = instance.task(observer).expect("open the task topic");
    let published = task.data.dynamic_config().number_of_publishers() > 0;
    (names, published)
}

fn check(planner: &str, expected: &[&str]) {
    let instance_name = format!("gt-{planner}-{}", std::process::id() % 100_000);
    let ag = learned_ag("triangle");
    let dir = LaunchDir::new(&launch(&instance_name, planner, &ag));
    assert_eq!(count_instance_files(&instance_name), 0);
    let mut up = AgpUp::start(&dir.launch(), &[]);
    // A node of ours before the supervisor's would be a stranger it refuses to start
    // beside: look once it has started the planner.
    up.wait_for_lines("planner: started", 1, TIMEOUT);
    let instance = Instance::new(&instance_name).expect("a valid name");
    let observer = NodeBuilder::new()
        .config(instance.config())
        .create::<AgpIpc>()
        .expect("an observer node");
    let mut seen = BTreeSet::new();
    up.until("the planner drives", TIMEOUT, || {
        let (names, published) = readers(&instance, &observer);
        seen = names;
        published
    });
    // The planner's ports are all open once it has published its task.
    let (names, _) = readers(&instance, &observer);
    seen.extend(names);
    let expected: BTreeSet<String> = expected.iter().map(|s| (*s).to_owned()).collect();
    assert_eq!(
        seen, expected,
        "planner `{planner}`: the ground truth's readers"
    );
    drop(observer);
    let done = up.wait(TIMEOUT);
    assert!(done.status.success(), "{}\n{}", done.stdout, done.stderr);
    assert_eq!(
        count_instance_files(&instance_name),
        0,
        "files of `{instance_name}` left"
    );
}

#[test]
fn only_the_judge_reads_ground_truth_while_the_affordance_planner_places_the_object() {
    check("affordance", &["agp-judge"]);
}

#[test]
fn the_oracle_planner_reads_ground_truth_and_the_estimator_still_does_not() {
    check("oracle", &["agp-judge", "planner"]);
}

#[test]
fn the_model_planner_reads_ground_truth_and_the_estimator_still_does_not() {
    check("model", &["agp-judge", "planner"]);
}
