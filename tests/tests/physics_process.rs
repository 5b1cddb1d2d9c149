//! The physics process over real shared memory: a test client drives it through iceoryx2
//! exactly as the planner would.

use std::path::PathBuf;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use agp_runtime::{Instance, LockstepDriver, TruthAccess};
use agp_shared_types::{GroundTruth, IrFrame, Pose2};

/// target/debug (or release) of the running test: the README's test command builds every
/// binary of the workspace there first.
fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe
        .parent()
        .and_then(|d| d.parent())
        .expect("target folder");
    let path = dir.join(name);
    assert!(
        path.exists(),
        "`{}` is missing: run `cargo build --workspace --bins` first",
        path.display()
    );
    path
}

/// One physics process of a private instance; stopped and checked clean on drop.
struct Physics {
    instance: Instance,
    child: Child,
}

impl Physics {
    fn start(tag: &str, scenario: &str, seed: u64) -> Self {
        let instance = Instance::new(&format!("{tag}-{}", std::process::id())).expect("name");
        instance.remove_files().expect("clean start");
        let child = Command::new(bin("agp-physics"))
            .env("AGP_INSTANCE", instance.name())
            .env("AGP_SCENARIO", scenario)
            .env("AGP_CLOCK", "lockstep")
            .args(["--seed", &seed.to_string(), "--idle-timeout-s", "60"])
            .spawn()
            .expect("start agp-physics");
        Self { instance, child }
    }

    fn driver(&self) -> LockstepDriver {
        LockstepDriver::connect(
            &self.instance,
            "test",
            0,
            TruthAccess::GroundTruth,
            Duration::from_secs(30),
        )
        .expect("physics answers")
    }

    /// SIGTERM, then wait: physics must exit 0 on its own and leave no shared memory.
    fn stop(mut self) {
        // SAFETY: kill on our own child's pid.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        let deadline = Instant::now() + Duration::from_secs(20);
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("wait") {
                break s;
            }
            assert!(
                Instant::now() < deadline,
                "physics ignored SIGTERM for 20 s"
            );
            std::thread::sleep(Duration::from_millis(10));
        };
        assert!(status.success(), "physics exited with {status}");
        // Every service and port is gone with the processes that used them. iceoryx2 keeps
        // one global management segment per prefix, which the instance's owner (here the
        // test, in a run `agp`) removes with the root folder.
        let shm: Vec<_> = self
            .instance
            .files()
            .into_iter()
            .filter(|p| p.starts_with("/dev/shm") && !p.to_string_lossy().ends_with(".global_mgmt"))
            .collect();
        let name = self.instance.name().to_owned();
        self.instance
            .remove_files()
            .expect("remove the instance's files");
        assert!(shm.is_empty(), "instance `{name}` left {shm:?} in /dev/shm");
        let left = self.instance.files();
        assert!(left.is_empty(), "instance `{name}` still has {left:?}");
    }
}

impl Drop for Physics {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = self.instance.remove_files();
    }
}

fn front(f: &IrFrame) -> f32 {
    // IR1 (+17 deg) and IR8 (-17 deg): the two sensors facing forward.
    f.ir_raw[0].max(f.ir_raw[7])
}

#[test]
fn a_robot_driven_into_the_object_sees_its_front_ir_rise_and_then_moves_it() {
    let physics = Physics::start("tpdrive", "square", 3);
    {
        let mut d = physics.driver();
        // The square (60 mm side) at the origin; the robot 150 mm to its left, facing it:
        // 150 - 30 - 37 = 83 mm between shell and face, beyond the IR range (70 mm).
        d.reset(Pose2::new(0.0, 0.0, 0.0), Pose2::new(-0.15, 0.0, 0.0))
            .expect("reset");
        assert_eq!(front(d.frame()), 0.0, "nothing in range at the start");
        let start = d.truth().object;

        let mut first_seen = None;
        let mut first_moved = None;
        let mut readings = Vec::new();
        for k in 0..(640 * 3) {
            let f = *d.step(0.1, 0.1).expect("step");
            readings.push(front(&f));
            if first_seen.is_none() && front(&f) > 0.0 {
                first_seen = Some(k);
            }
            let o = d.truth().object;
            if first_moved.is_none() && (o.x - start.x).abs() > 0.001 {
                first_moved = Some(k);
            }
        }
        let seen = first_seen.expect("the front IR never saw the object");
        let moved = first_moved.expect("the object never moved");
        assert!(
            seen < moved,
            "IR saw it at step {seen}, it moved at step {moved}"
        );
        // Approaching from 83 mm at 0.1 m/s: the readings climb. Compare means of the
        // first and last quarter of the approach (noise is at most a few % of a reading).
        let approach = &readings[seen..moved];
        let q = (approach.len() / 4).max(1);
        let early: f32 = approach[..q].iter().sum::<f32>() / q as f32;
        let late: f32 = approach[approach.len() - q..].iter().sum::<f32>() / q as f32;
        assert!(
            late > 2.0 * early,
            "front IR did not rise: {early} -> {late}"
        );
        // Pushed straight through its centre for the rest of the 3 s: it went forward.
        let end: GroundTruth = *d.truth();
        assert!(
            end.object.x - start.x > 0.05,
            "object moved only {} m",
            end.object.x - start.x
        );
        assert!(end.contact == 1, "the robot is still pushing at the end");
    }
    physics.stop();
}

/// Drives one scripted run and returns every frame's readings and true poses.
fn recorded_run(tag: &str, seed: u64) -> Vec<(IrFrame, GroundTruth)> {
    let physics = Physics::start(tag, "lshape", seed);
    let mut out = Vec::new();
    {
        let mut d = physics.driver();
        d.reset(Pose2::new(0.0, 0.0, 0.3), Pose2::new(-0.14, 0.02, 0.1))
            .expect("reset");
        for k in 0..1500u32 {
            // A push with a turn in it, so the object both slides and spins.
            let (l, r) = if k < 900 { (0.1, 0.09) } else { (0.05, 0.1) };
            let f = *d.step(l, r).expect("step");
            out.push((f, *d.truth()));
        }
    }
    physics.stop();
    out
}

#[test]
fn the_same_seed_gives_bit_identical_trajectories_in_lockstep() {
    let a = recorded_run("tpseed-a", 11);
    let b = recorded_run("tpseed-b", 11);
    assert_eq!(a.len(), b.len());
    for (k, ((fa, ta), (fb, tb))) in a.iter().zip(&b).enumerate() {
        let bits = |p: &Pose2| [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()];
        assert_eq!(
            bits(&ta.object),
            bits(&tb.object),
            "object differs at step {k}"
        );
        assert_eq!(
            bits(&ta.robot),
            bits(&tb.robot),
            "robot differs at step {k}"
        );
        assert_eq!(
            fa.ir_raw.map(f32::to_bits),
            fb.ir_raw.map(f32::to_bits),
            "IR differs at step {k}"
        );
        assert_eq!(
            bits(&fa.odometry),
            bits(&fb.odometry),
            "odometry differs at step {k}"
        );
    }
    let moved = a.last().unwrap().1.object;
    assert!(
        moved.x.hypot(moved.y) > 0.01,
        "the run must push the object to mean anything"
    );

    let c = recorded_run("tpseed-c", 12);
    assert!(
        a.iter()
            .zip(&c)
            .any(|((fa, _), (fc, _))| fa.ir_raw != fc.ir_raw),
        "another seed must give other IR noise"
    );
}
