//! An affordance gradient that keeps learning, over the real pipeline: the object grows
//! heavier one second into a placement (a scenario's `[[world_change]]`, applied by
//! physics alone), the estimator run with `--learn-online` learns from the task's pushes
//! and publishes the grids again after each (the next seq), and the planner takes each new
//! set between two pushes and places the object.

use std::time::Duration;

use agp_tests::{LaunchDir, assert_placed, count_instance_files, learned_ag, run_agp};

#[test]
fn the_planner_plans_on_the_grids_the_estimator_learned_online_after_the_object_grew_heavier() {
    let instance = "onlinelearn";
    let ag = learned_ag("triangle");
    let scenario = format!(
        "{}\n[[world_change]]\nat_s = 1.0\nmass_kg = 0.3\n",
        include_str!("../../libs/world/scenarios/triangle.toml")
    );
    let launch = format!(
        "instance = \"{instance}\"\nscenario = \"heavier.toml\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\n\
         args = [\"--load\", \"{}\", \"--learn-online\"]\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"place\", \"--planner\", \"affordance\"]\nends_run = true\n",
        ag.display()
    );
    let dir = LaunchDir::new(&launch);
    std::fs::write(dir.path().join("heavier.toml"), scenario).expect("write the scenario");
    let launch_file = dir.launch();
    let run = run_agp(
        dir.path(),
        &["up", launch_file.to_str().expect("UTF-8")],
        Duration::from_secs(600),
    );
    run.assert_success("`agp up` of a placement with online learning");
    // The estimator published the learned gradient again: seq 1 is the file's, 2 the
    // first push learned.
    assert!(
        run.stdout
            .contains("agp-estimator: learned a push online (1 since the gradient was given): grids seq 2 published"),
        "{}",
        run.stdout
    );
    // The planner took a newer set between two pushes.
    let taken: Vec<u64> = run
        .stdout
        .lines()
        .filter_map(|l| {
            l.strip_prefix("planner: planning on the estimator's grids seq ")
                .and_then(|r| r.split(' ').next())
                .and_then(|n| n.parse().ok())
        })
        .collect();
    assert!(!taken.is_empty(), "no newer grids taken:\n{}", run.stdout);
    assert!(
        taken.windows(2).all(|w| w[0] < w[1]) && taken[0] >= 2,
        "{taken:?}"
    );
    assert_placed(&dir.results(), instance, "triangle", &run.stdout);
    assert_eq!(
        count_instance_files(instance),
        0,
        "files of the instance remain"
    );
}
