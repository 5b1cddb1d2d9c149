//! The estimator's per-frame work allocates nothing: a shape circling and a whole trial
//! (approach, contact, push with tracking, circling) against the physics, counting the
//! allocations made inside the session's per-frame calls only.

use agp_perception::{ApproachContact, ContactSense, IrView, LearningConfig, LearningSession};
use agp_physics::{Sim, SimConfig};
use agp_planning::{
    CirclePhase, CircleRoutine, CircleSettings, PushPhase, PushRoutine, PushSettings,
};
use agp_runtime::alloc_count;
use agp_world::{Pose, RobotDescription, Scenario};

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

/// Allocations made by this thread: tests run in parallel, each counts its own.
fn allocations() -> u64 {
    alloc_count::thread_allocations()
}

fn view(sim: &Sim) -> IrView {
    let s = sim.sensors();
    IrView::new(s.ir_sample, s.ir_raw, s.odometry)
}

/// Runs `f` and adds the allocations it made to `total`.
fn counted<T>(total: &mut u64, f: impl FnOnce() -> T) -> T {
    let before = allocations();
    let out = f();
    *total += allocations() - before;
    out
}

fn circle(sim: &mut Sim, robot: &RobotDescription, session: &mut LearningSession, own: &mut u64) {
    let mut routine = CircleRoutine::new(CircleSettings::default(), robot, sim.sim_time());
    let t0 = sim.sim_time();
    while sim.sim_time() - t0 < 30.0 {
        let v = view(sim);
        counted(own, || session.observe(&v));
        let (l, r) = routine.update(sim.sim_time(), v.ir_sample, v.odometry, &v.ir_raw);
        if let CirclePhase::Done { .. } = routine.phase() {
            return;
        }
        sim.step(l, r);
    }
}

#[test]
fn observing_frames_through_a_shape_circling_and_a_trial_allocates_nothing() {
    alloc_count::enable();
    let scenario = Scenario::builtin("triangle").expect("built-in");
    let robot = RobotDescription::epuck();
    let mut sim = Sim::new(&scenario, &robot, SimConfig::default()).expect("builds");
    let sense = ContactSense::new(&robot);
    let object = scenario.object.start;
    let mut session = LearningSession::new("triangle", &robot, LearningConfig::for_symmetry(3))
        .expect("valid config");
    let mut own = 0;

    // The shape: start 10 mm off the left face, facing it.
    sim.reset(
        object,
        Pose::new(-0.0289 - robot.body_radius - 0.010, 0.0, 0.0),
    );
    session.begin_shape_circling(object);
    circle(&mut sim, &robot, &mut session, &mut own);
    session.finish_shape_circling().expect("a shape");
    assert_eq!(own, 0, "observing the shape circling allocated {own} times");

    // One trial from the right, facing the centroid.
    sim.reset(object, Pose::new(0.12, 0.0, std::f64::consts::PI));
    session.begin_trial(0.0, object).expect("shape learned");
    let mut push = PushRoutine::new(PushSettings::default(), sim.sim_time());
    let mut approach = ApproachContact::new();
    loop {
        let v = view(&sim);
        counted(&mut own, || session.observe(&v));
        let was_approaching = matches!(push.phase(), PushPhase::Approach { .. });
        let gap = sense.front_gap(&v.ir_raw);
        approach.observe(v.ir_sample, gap, v.odometry);
        let (l, r) = push.step(gap, approach.stalled(), sim.sim_time(), v.ir_sample);
        if was_approaching && matches!(push.phase(), PushPhase::Push { .. }) {
            counted(&mut own, || session.infer_contact(&v)).expect("approaching");
        }
        if let PushPhase::Done { contact } = push.phase() {
            assert!(contact, "the push reached the triangle");
            counted(&mut own, || session.end_push(&v)).expect("pushing");
            break;
        }
        sim.step(l, r);
    }
    for _ in 0..96 {
        let v = view(&sim);
        counted(&mut own, || session.observe(&v));
        sim.step(-0.08, -0.08);
    }
    circle(&mut sim, &robot, &mut session, &mut own);
    let record = counted(&mut own, || session.finish_trial()).expect("a pose");
    assert!(record.track_updates > 0, "the push was tracked");
    assert_eq!(own, 0, "the trial's per-frame work allocated {own} times");
}
