//! No process of the pipeline allocates per message in its steady state: physics,
//! `agp-estimator` and `agp-planner --mode learn` under `agp up`, each counting its heap
//! allocations (`AGP_COUNT_ALLOCS=1`, see `agp_shared_types::alloc_count`), over the learning
//! phase on the triangle: a shape circling and 18 trials, some 150,000 lockstep steps, every
//! one passing through all three processes.
//!
//! What may allocate is what happens a few times a trial, never once a message: physics when
//! a contact begins or ends (rapier's new pair), the planner when a trial begins (its routines
//! for the trial), iceoryx2 when a port connects to a new listener, the estimator when
//! learning is done. Each process reports how many of its counted messages allocated at all;
//! the bounds below are per trial, so one allocation per message (150,000 of them) fails by
//! three orders of magnitude.

use std::time::Duration;

use agp_tests::{AgpUp, LaunchDir, alloc_counts, count_instance_files, triangle_learning_launch};

/// Safety net of the run; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(300);

const TRIALS_PER_ALPHA: u32 = 6;
const TRIALS: u64 = 3 * TRIALS_PER_ALPHA as u64;

#[test]
fn the_learning_pipeline_allocates_per_trial_never_per_message() {
    let name = format!("t-palloc-{}", std::process::id());
    let dir = LaunchDir::new(&triangle_learning_launch(
        &name,
        TRIALS_PER_ALPHA,
        "env = { AGP_COUNT_ALLOCS = \"1\" }",
    ));
    let up = AgpUp::start(&dir.launch(), &[]);
    let run = up.wait(TIMEOUT);
    let output = format!("{}\n{}", run.stdout, run.stderr);
    assert!(run.status.success(), "the learning run failed:\n{output}");
    assert_eq!(count_instance_files(&name), 0, "the run left files behind");

    let mut failures = Vec::new();
    for (process, work, unit, per_trial) in [
        // A push's contact begins and ends, the circling's too (about 7 a trial measured).
        ("agp-physics", "simulation", "steps", 12),
        // A new trial's routines and plan (about 2 frames a trial measured).
        ("agp-planner", "planning", "frames", 4),
        // Learning done, a listener connecting (1 frame in the whole run measured).
        ("agp-estimator", "learning", "frames", 1),
    ] {
        let Some(c) = alloc_counts(&output, process, work) else {
            failures.push(format!("{process} printed no steady-state line"));
            continue;
        };
        eprintln!("{process}: {c:?}");
        if c.messages < 100_000 {
            failures.push(format!("{process}: only {} {unit} counted", c.messages));
        }
        if c.looping != 0 {
            failures.push(format!(
                "{process}: its loop allocated {} times in {} {unit}",
                c.looping, c.messages
            ));
        }
        let bound = per_trial * (TRIALS + 1);
        if c.allocating > bound {
            failures.push(format!(
                "{process}: {} of {} {unit} allocated ({} in its work, {} in iceoryx2); at most {bound} may, {per_trial} per trial",
                c.allocating, c.messages, c.work, c.iceoryx2
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{}\n\nthe run printed:\n{output}",
        failures.join("\n")
    );
}
