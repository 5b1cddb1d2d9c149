//! An object never pushed before, over the real pipeline (issue 33, item 2): `agp up` with
//! `learn = "online"` and a scenario that has no AG file. The planner circles the object
//! first; the estimator builds the gradient from that circling's contact prior, publishes
//! it (grids seq 1) and learns on from the task's pushes; the planner places the object on
//! the sets it publishes, and the judge says it is placed.

use std::time::Duration;

use agp_tests::{LaunchDir, assert_placed, count_instance_files, run_agp};

#[test]
fn an_object_never_pushed_is_placed_on_the_gradient_its_first_circling_gave() {
    let instance = "neverpushed";
    let launch = format!(
        "instance = \"{instance}\"\nscenario = \"shape.toml\"\nlearn = \"online\"\n\n\
         [clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
         args = [\"--mode\", \"place\", \"--planner\", \"affordance\"]\nends_run = true\n"
    );
    let dir = LaunchDir::new(&launch);
    std::fs::write(
        dir.path().join("shape.toml"),
        include_str!("../../examples/shapes/trapezoid.toml"),
    )
    .expect("write the scenario");
    let launch_file = dir.launch();
    let run = run_agp(
        dir.path(),
        &["up", launch_file.to_str().expect("UTF-8")],
        Duration::from_secs(600),
    );
    run.assert_success("`agp up` of an object never pushed, learning online");
    assert!(
        run.stdout.contains(
            "agp-estimator: built the contact prior of `trapezoid` from the first circling: grids seq 1 published"
        ),
        "{}",
        run.stdout
    );
    assert!(
        run.stdout
            .contains("planner: planning on the estimator's grids seq 1 "),
        "the planner never planned on the prior:\n{}",
        run.stdout
    );
    // No AG file was learned or written: the object was never learned first.
    assert!(!dir.results().join("trapezoid.ag").exists());
    let scenario = dir.path().join("shape.toml");
    assert_placed(
        &dir.results(),
        instance,
        scenario.to_str().expect("UTF-8"),
        &run.stdout,
    );
    assert_eq!(
        count_instance_files(instance),
        0,
        "files of the instance remain"
    );
}
