//! No process of the pipeline allocates per message in its steady state: physics,
//! `agp-estimator` and `agp-planner --mode learn` under `agp up`, each counting its heap
//! allocations (`AGP_COUNT_ALLOCS=1`, see `agp_runtime::alloc_count`), over the learning
//! phase on the triangle: a shape circling and 18 trials, some 150,000 lockstep steps, every
//! one passing through all three processes.
//!
//! What may allocate happens once in a run, not once a message or a trial: a workspace of
//! rapier's reaching its working size the first time something happens after the warm-up,
//! a notifier meeting a listener that connected late, the estimator turning its session
//! into the gradient when learning is done. Each process reports in how many of its
//! counted messages anything was allocated; the bound below is a handful in the whole run.
//! One allocation per trial (18 here) or per message (150,000) fails. The whole learning
//! phase (180 trials, 1.46 million steps) gives the same counts as this short one
//! (README, Benchmarks).

use std::time::Duration;

use agp_tests::{AgpUp, LaunchDir, alloc_counts, count_instance_files, triangle_learning_launch};

/// Safety net of the run; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(300);

const TRIALS_PER_ALPHA: u32 = 6;

/// Messages of a whole run in which a process may allocate at all (measured: physics 4,
/// planner 1, estimator 1).
const ALLOCATING_AT_MOST: u64 = 8;

#[test]
fn the_learning_pipeline_allocates_in_a_handful_of_messages_in_all() {
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
    for (process, work, unit) in [
        ("agp-physics", "simulation", "steps"),
        ("agp-planner", "planning", "frames"),
        ("agp-estimator", "learning", "frames"),
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
        if c.allocating > ALLOCATING_AT_MOST {
            failures.push(format!(
                "{process}: {} of {} {unit} allocated ({} in its work, {} in iceoryx2); at most {ALLOCATING_AT_MOST} may",
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
