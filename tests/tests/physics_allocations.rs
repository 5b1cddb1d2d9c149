//! Physics's lockstep loop allocates nothing per step in the steady state: its counting
//! allocator (`AGP_COUNT_ALLOCS=1`) says so at exit, after a few thousand steps of a push
//! driven over real shared memory as the planner drives them, the contact holding in every
//! counted step. (Rapier grows a few workspaces the first time a contact begins or a pair
//! leaves its broad phase; `tests/tests/pipeline_allocations.rs` covers whole trials.)

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use agp_runtime::alloc_count::WARMUP_MESSAGES;
use agp_runtime::{Instance, LockstepDriver, TruthAccess};
use agp_shared_types::Pose2;
use agp_tests::{AllocCounts, alloc_counts, bin_path};

/// Steps driven; physics counts those after its first `WARMUP_MESSAGES`.
const STEPS: u64 = 3000;

/// Runs a private lockstep physics with counting on, drives `STEPS` steps of a push as the
/// planner would (checking, by the ground truth, that the robot touches the object in
/// every counted step), stops it, and returns its counts.
fn drive_and_count(tag: &str) -> AllocCounts {
    let instance = Instance::new(&format!("{tag}-{}", std::process::id())).expect("name");
    instance.remove_files().expect("clean start");
    let mut child = Command::new(bin_path("agp-physics"))
        .env("AGP_INSTANCE", instance.name())
        .env("AGP_SCENARIO", "square")
        .env("AGP_CLOCK", "lockstep")
        .env("AGP_COUNT_ALLOCS", "1")
        .args(["--idle-timeout-s", "60"])
        .stderr(Stdio::piped())
        .spawn()
        .expect("start agp-physics");
    let mut stderr = child.stderr.take().expect("piped stderr");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });

    // Checked after physics is stopped and its files removed, so a failure leaves nothing
    // behind.
    let mut lost_contact = None;
    {
        let mut driver = LockstepDriver::connect(
            &instance,
            "test",
            0,
            TruthAccess::GroundTruth,
            Duration::from_secs(30),
        )
        .expect("physics answers");
        // A push into the object, turning a little one way then the other: the contact
        // point, IR readings and odometry all change as the steps go, the contact holds.
        driver
            .reset(Pose2::new(0.0, 0.0, 0.0), Pose2::new(-0.09, 0.0, 0.0))
            .expect("reset");
        for k in 0..STEPS {
            let turn = if (k / 400) % 2 == 0 { 0.004 } else { -0.004 };
            driver.step(0.08 + turn, 0.08 - turn).expect("a step");
            let truth = driver.truth();
            if k + 1 >= WARMUP_MESSAGES && truth.contact != 1 {
                lost_contact = Some(format!(
                    "the robot lost the object at step {k}: robot {:?}, object {:?}",
                    truth.robot, truth.object
                ));
                break;
            }
        }
    }

    // SAFETY: kill(2) of our own child, not yet reaped.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let deadline = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        assert!(Instant::now() < deadline, "physics ignored SIGTERM");
        std::thread::sleep(Duration::from_millis(10));
    };
    let text = reader.join().expect("stderr reader");
    instance
        .remove_files()
        .expect("remove the instance's files");
    assert!(status.success(), "physics exited with {status}: {text}");
    if let Some(lost) = lost_contact {
        panic!("{lost}");
    }
    eprintln!("{}", text.trim());
    let counts = alloc_counts(&text, "agp-physics", "simulation")
        .unwrap_or_else(|| panic!("no allocation count from physics: {text}"));
    assert!(
        counts.messages >= STEPS - 600,
        "only {} steps counted of {STEPS}",
        counts.messages
    );
    counts
}

#[test]
fn physics_loop_and_iceoryx2_allocate_nothing_per_lockstep_step() {
    let c = drive_and_count("t-alloc");
    assert_eq!(
        c.looping, 0,
        "physics's loop allocated {} times in {} steady-state steps",
        c.looping, c.messages
    );
    // Two loans a step (the IR frame, the ground truth), a command received, the wait: the
    // loans' bookkeeping comes from the pool of `AgpIpc`'s policy, not the heap.
    assert_eq!(
        c.iceoryx2, 0,
        "iceoryx2 allocated {} times in {} steady-state steps",
        c.iceoryx2, c.messages
    );
}

/// Rapier as vendored (vendor/rapier2d/PATCHES.md), and one collider per convex piece of the
/// object: unpatched rapier 0.36 allocated twice a step here.
#[test]
fn the_simulation_step_allocates_nothing_per_lockstep_step() {
    let c = drive_and_count("t-alloc-sim");
    assert_eq!(
        c.work,
        0,
        "Sim::step allocated {} times in {} steady-state steps ({:.2} per step)",
        c.work,
        c.messages,
        c.work as f64 / c.messages.max(1) as f64
    );
}
