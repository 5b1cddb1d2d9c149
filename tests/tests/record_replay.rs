//! Recording a lockstep run in MCAP (a launch file's `record` key) and replaying it: every
//! topic a channel with the counts physics and the planner published, and `agp replay`
//! ending in the object's final true pose to the bit, every recorded frame reproduced.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agp_recording::{Plain, Recording, TOPIC_COUNT, recorded_topics};
use agp_runtime::Instance;
use agp_shared_types::{
    GRIDS_PER_ALPHA, GroundTruth, IrFrame, LearnEvent, ObjectEstimate, ServiceNames,
};
use agp_tests::{AgpUp, LaunchDir, count_instance_files, learned_ag, run_agp};

/// Safety net only: the run takes well under a second.
const TIMEOUT: Duration = Duration::from_secs(120);

/// One pipeline at a time: the scripted run's counts should not depend on a placement
/// running beside it on the two cores.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A short lockstep run recorded into `run.mcap`: physics, the estimator serving a learned
/// triangle, and a planner: the scripted drive (two pushes, each from a reset) or a task. `agp up` starts the
/// recorder first and the others once it has subscribed (its file exists); the planner
/// (through `sh`) also waits for the test's own ground-truth reader (`truth.ready`).
/// Nothing runs at another priority: the recorder's buffers (`agp_runtime::TAP_DEPTH`)
/// hold seconds of the ring at full lockstep speed.
fn launch(instance: &str, ag: &std::path::Path, planner: &str, planner_args: &str) -> String {
    agp_tests::gated_triangle_launch(
        instance,
        ag,
        "record = \"run.mcap\"\n",
        "truth.ready",
        planner,
        planner_args,
    )
}

/// Reads the instance's ground truth (as the judge does) from when its supervisor is up
/// until `stop`; the latest sample. Says it listens, and that the estimator published its
/// grids, by creating `ready`.
fn truth_reader(
    name: String,
    ready: std::path::PathBuf,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<Option<GroundTruth>> {
    std::thread::spawn(move || {
        let instance = Instance::new(&name).expect("a valid name");
        let deadline = Instant::now() + TIMEOUT;
        while !instance.control_exists() {
            assert!(Instant::now() < deadline, "the supervisor never came up");
            std::thread::sleep(Duration::from_millis(5));
        }
        let node = instance.node("test-truth", false).expect("a node");
        let sub = instance
            .ground_truth(&node)
            .expect("the ground truth topic")
            .data
            .subscriber_builder()
            .create()
            .expect("a ground truth subscriber");
        // The planner starts once the estimator published its whole grid set: the scripted
        // drive is over in a fraction of a second, and on a loaded machine it ended before
        // the estimator had loaded and published the set (43 of 51 recorded, then).
        let grids = instance
            .grids(&node)
            .expect("the grids topic")
            .data
            .subscriber_builder()
            .create()
            .expect("a grids subscriber");
        let mut seen = 0;
        while seen < 3 * GRIDS_PER_ALPHA {
            assert!(Instant::now() < deadline, "{seen} grids published");
            while let Ok(Some(_)) = grids.receive() {
                seen += 1;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        drop(grids);
        std::fs::write(&ready, b"").expect("write the ready marker");
        let mut last: Option<GroundTruth> = None;
        loop {
            let stopping = stop.load(Ordering::Relaxed);
            while let Ok(Some(t)) = sub.receive() {
                if last.is_none_or(|l| t.step >= l.step) {
                    last = Some(*t);
                }
            }
            if stopping {
                return last;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    })
}

/// Every message of `topic` in the recording, as its payload.
fn payloads<T: Plain>(rec: &Recording, topic: &str) -> Vec<T> {
    rec.topic_messages(topic)
        .expect("messages")
        .map(|m| agp_recording::payload_from_bytes::<T>(&m.data).expect("a whole payload"))
        .collect()
}

fn bits(v: f64) -> String {
    format!("{:#018x}", v.to_bits())
}

#[test]
fn a_recorded_lockstep_run_holds_every_topic_and_replays_to_the_same_final_pose_bit_for_bit() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let ag = learned_ag("triangle");
    let name = format!("rec{}", std::process::id() % 100_000);
    let replay_name = format!("rpl{}", std::process::id() % 100_000);
    let dir = LaunchDir::new(&launch(
        &name,
        &ag,
        "agp-scripted-drive",
        "--pushes 2 --push-ms 300",
    ));
    let stop = Arc::new(AtomicBool::new(false));
    let reader = truth_reader(
        name.clone(),
        dir.path().join("truth.ready"),
        Arc::clone(&stop),
    );
    let run = AgpUp::start(&dir.launch(), &[]).wait(TIMEOUT);
    stop.store(true, Ordering::Relaxed);
    let truth = reader
        .join()
        .expect("the truth reader")
        .expect("some ground truth");
    run.assert_success("`agp up`");
    let rec = Recording::open(&dir.path().join("run.mcap")).expect("a readable recording");

    // The file: every topic a channel, named by its service, its schema by the payload's
    // iceoryx2 type name; beside them the scene in Foxglove's schemas (tests/foxglove_recording.rs).
    assert!(!rec.truncated, "the recorder completed the file");
    let raw = rec
        .channels
        .iter()
        .filter(|c| c.message_encoding == "agp-repr-c")
        .count();
    assert_eq!(raw, TOPIC_COUNT);
    assert!(
        rec.channels
            .iter()
            .filter(|c| c.message_encoding != "agp-repr-c")
            .all(|c| c.message_encoding == "protobuf" && c.schema_name.starts_with("foxglove.")),
        "{:?}",
        rec.channels
    );
    for t in recorded_topics() {
        let c = rec
            .channel(t.service)
            .unwrap_or_else(|| panic!("no channel `{}`", t.service));
        assert_eq!(c.schema_name, t.type_name);
        assert_eq!(c.message_encoding, "agp-repr-c");
    }
    assert!(rec.channel(ServiceNames::GROUND_TRUTH).is_none());
    let run_meta = rec.run();
    assert_eq!(run_meta["instance"], name);
    assert_eq!(run_meta["clock"], "lockstep");
    assert_eq!(run_meta["scenario"], "triangle");
    assert!(run_meta["launch_toml"].contains("record = \"run.mcap\""));

    // The counts: physics published one frame at the start, one per applied command and
    // one per reset; the planner one command per step and two resets; the estimator a
    // whole set of 3 alphas x `GRIDS_PER_ALPHA` grids. The recorder dropped nothing and lost nothing.
    let count = |topic: &str| rec.channel(topic).map_or(0, |c| c.messages);
    let frames: Vec<IrFrame> = payloads(&rec, ServiceNames::IR_FRAMES);
    let last_step = frames.last().expect("frames").step;
    assert_eq!(frames[0].step, 0, "the recording starts with the run");
    assert_eq!(last_step, truth.step, "the last frame is the final state's");
    assert_eq!(count(ServiceNames::RESETS), 2);
    assert_eq!(count(ServiceNames::MOTOR_COMMANDS), last_step);
    let stats = rec.recorder_stats();
    assert_eq!(
        count(ServiceNames::IR_FRAMES),
        1 + last_step + count(ServiceNames::RESETS),
        "every frame recorded"
    );
    assert_eq!(count(ServiceNames::GRIDS), 3 * GRIDS_PER_ALPHA as u64);
    assert!(count(ServiceNames::ESTIMATES) > 0);

    for t in recorded_topics() {
        for what in ["dropped", "lost"] {
            assert_eq!(
                stats[&format!("{}.{what}", t.service)],
                "0",
                "{} {what}",
                t.service
            );
        }
    }

    // The replay: every recorded frame again to the bit, and the same final true pose.
    let json = dir.path().join("replay.json");
    let replay = run_agp(
        dir.path(),
        &[
            "replay",
            "run.mcap",
            "--instance",
            &replay_name,
            "--json",
            json.to_str().expect("a UTF-8 path"),
        ],
        TIMEOUT,
    );
    replay.assert_success("`agp replay`");
    let account: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the replay's account"))
            .expect("JSON");
    assert_eq!(account["complete"], true);
    assert_eq!(account["frames_compared"], frames.len() as u64);
    assert_eq!(account["frames_unrecorded"], 0);
    assert_eq!(account["frames_equal"], frames.len() as u64);
    let fin = &account["final"];
    assert_eq!(fin["step"], truth.step);
    for (key, v) in [
        ("x_bits", truth.object.x),
        ("y_bits", truth.object.y),
        ("theta_bits", truth.object.theta),
    ] {
        assert_eq!(fin["object"][key], bits(v), "object {key}");
    }
    for (key, v) in [
        ("x_bits", truth.robot.x),
        ("y_bits", truth.robot.y),
        ("theta_bits", truth.robot.theta),
    ] {
        assert_eq!(fin["robot"][key], bits(v), "robot {key}");
    }

    assert_eq!(count_instance_files(&name), 0, "files of `{name}` remain");
    assert_eq!(
        count_instance_files(&replay_name),
        0,
        "files of `{replay_name}` remain"
    );
}

/// A placement by the affordance planner, recorded: the estimator's answer to each of the
/// planner's events is in the recording.
#[test]
fn each_estimate_names_the_newest_planner_event_the_estimator_took_in() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let ag = learned_ag("triangle");
    let name = format!("rev{}", std::process::id() % 100_000);
    let launch = launch(
        &name,
        &ag,
        "agp-planner",
        "--mode place --planner affordance",
    );
    let dir = LaunchDir::new(&launch);
    std::fs::write(dir.path().join("truth.ready"), b"").expect("the ready marker");
    let run = AgpUp::start(&dir.launch(), &[]).wait(TIMEOUT);
    run.assert_success("`agp up`");
    let rec = Recording::open(&dir.path().join("run.mcap")).expect("a readable recording");
    // Each planner event shows in the estimate of the next frame: its session and seq, the
    // planner's proof that the estimate took the event in (a circling matched, a push
    // carried on) without comparing clocks.
    let events: Vec<LearnEvent> = payloads(&rec, ServiceNames::LEARN_EVENTS);
    let estimates: Vec<ObjectEstimate> = payloads(&rec, ServiceNames::ESTIMATES);
    println!("{} events, {} estimates", events.len(), estimates.len());
    assert!(
        events.len() >= 4,
        "circlings and pushes: {} events",
        events.len()
    );
    for e in &events {
        let next = estimates
            .iter()
            .find(|est| est.step > e.step)
            .unwrap_or_else(|| panic!("no estimate after the event of step {}", e.step));
        assert_eq!(
            next.event_session, e.session,
            "event {} of step {}",
            e.seq, e.step
        );
        assert!(
            next.event_seq >= e.seq,
            "event {} of step {}: {}",
            e.seq,
            e.step,
            next.event_seq
        );
    }
    let (first, last) = (&estimates[0], estimates.last().expect("estimates"));
    assert_eq!(
        (first.event_session, first.event_seq),
        (0, 0),
        "none before the first"
    );
    let newest = events.last().expect("events");
    assert_eq!(
        (last.event_session, last.event_seq),
        (newest.session, newest.seq)
    );
    assert_eq!(count_instance_files(&name), 0, "files of `{name}` remain");
}
