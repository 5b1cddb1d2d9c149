//! A reset with a seed: the world's noise from then on is that of a fresh world of that
//! seed, whatever ran before (what makes a benchmark episode over the pipeline draw the
//! same noise as the in-process episode of the same seed).

mod common;

use agp_world::Pose;
use common::*;

/// What `steps` steps driving towards the object sensed: each step's IR readings and
/// odometry, and the overhead fix at the steps a new one came (a fix from before a reset
/// stays readable until the next one, with its old sequence number).
type Sensed = Vec<([f32; 8], Pose, Option<Pose>)>;

fn sensed(sim: &mut agp_physics::Sim, steps: usize) -> Sensed {
    let mut seq = sim.sensors().fix_seq;
    (0..steps)
        .map(|_| {
            sim.step(0.05, 0.05);
            let s = sim.sensors();
            let fix = (s.fix_seq != seq).then_some(s.fix);
            seq = s.fix_seq;
            (s.ir_raw, s.odometry, fix)
        })
        .collect()
}

/// Where two runs first differ, for a message shorter than both runs.
fn first_difference(a: &Sensed, b: &Sensed) -> Option<usize> {
    a.iter().zip(b).position(|(x, y)| x != y)
}

#[test]
fn a_reseeded_reset_draws_the_noise_of_a_fresh_world_of_that_seed() {
    // The built-in scenario's noise: IR, odometry and the overhead fix all on.
    let sc = builtin("triangle");
    let (object, robot) = (sc.object.start, sc.robot.start);

    // A fresh world starts with the object and the robot at the scenario's starts.
    let mut fresh = sim_with_seed(&sc, 42);
    let want = sensed(&mut fresh, 1500);

    // Another seed, and a while of driving with it, before the reseeded reset.
    let mut reused = sim_with_seed(&sc, 7);
    sensed(&mut reused, 900);
    reused.reseed(42);
    reused.reset(object, robot);
    let got = sensed(&mut reused, 1500);

    // Bit for bit: the same draws from the same streams, at the same times of the epoch.
    assert_eq!(
        first_difference(&got, &want),
        None,
        "the reseeded world sensed otherwise than a fresh one"
    );
    assert!(want.iter().any(|(_, _, fix)| fix.is_some()), "a fix came");
    assert!(
        want.iter().any(|(ir, _, _)| ir.iter().any(|&r| r > 0.0)),
        "the IR saw the object"
    );
    // And the noise is there to be matched: another seed draws otherwise.
    let mut other = sim_with_seed(&sc, 43);
    assert!(first_difference(&sensed(&mut other, 1500), &want).is_some());
}
