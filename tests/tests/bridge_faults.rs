//! Faults across a bridge's link, between two instances on this machine (A runs physics and
//! the estimator, B the planner, joined only over Zenoh on the loopback), all in lockstep so
//! every outcome is the same whatever the machine's load:
//! - the link cut twice during a placement (a TCP proxy between the two ends closes every
//!   connection, then lets them through again): the placement goes on where it was, every
//!   step applied exactly once;
//! - B killed with -9 (its supervisor, and with it its bridge and planner: nothing says
//!   `bye`): A's bridge gives up once the far end has been gone for its far timeout, and A's
//!   run ends non-zero, saying so in one line;
//! - B's planner failing before it published a task: B's bridge says `bye`, and A's run ends
//!   1 saying nothing was judged (it once waited for ever when B stopped before its bridge
//!   had answered A's hello).
//!
//! And one live session on the realtime clock, B's planner pursuing a goal A's supervisor
//! owns: the link cut for several watchdog periods stops the robot by physics's watchdog,
//! physics's own account shows that no command drove it and that it did not move while the
//! link was down, and the session goes on once the link is back. Its checks are physics's
//! account of the cut, not how long anything took.

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use agp_harness::link_proxy::LinkProxy;
use agp_harness::watchdog_stops::{LoggedStop, stop_of_fault};
use agp_shared_types::monotonic_ns;
use agp_tests::{
    AgpUp, LaunchDir, StepLog, assert_every_step_applied_once, assert_placed, count_instance_files,
    learned_ag, run_agp, status_json,
};

/// Safety net of the short waits; the checks never depend on it.
const TIMEOUT: Duration = Duration::from_secs(60);

/// Safety net of a placement across the bridge.
const PLACE_TIMEOUT: Duration = Duration::from_secs(600);

/// An instance name of this test process's own: `bf`, `what` (at most 8 letters) and the
/// pid's last five digits (at most 16 characters).
fn instance(what: &str) -> String {
    format!("bf{what}-{}", std::process::id() % 100_000)
}

/// A port of the loopback that was free a moment ago.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// Instance A: physics (logging every applied step) and the estimator serving `ag` (none:
/// `--reuse`, which waits for a planner to learn when A's results hold no AG file); the
/// planner is remote, reached through the bridge listening on `port` (plain TCP: the link's
/// security is `bridge_tls.rs`'s), which gives up on a far end gone for `far_timeout_s`.
/// A's run ends when B's does.
fn robot_launch(name: &str, ag: Option<&Path>, port: u16, far_timeout_s: f64) -> String {
    let estimator = ag.map_or_else(
        || "\"--reuse\"".to_owned(),
        |ag| format!("\"--load\", \"{}\"", ag.display()),
    );
    format!(
        "instance = \"{name}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--step-log\", \"steps.log\"]\n\n\
         [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [{estimator}]\n\n\
         [[process]]\nname = \"planner\"\n\
         remote = {{ role = \"planner\", listen = \"tcp/127.0.0.1:{port}\", insecure = true }}\n\
         env = {{ AGP_BRIDGE_FAR_TIMEOUT_S = \"{far_timeout_s}\" }}\nends_run = true\n"
    )
}

/// Instance B: the affordance planner placing the triangle at the scenario's goal, physics
/// and the estimator remote, reached by connecting to `port`.
fn planner_launch(name: &str, port: u16) -> String {
    let args = "\"--mode\", \"place\", \"--planner\", \"affordance\"";
    format!(
        "instance = \"{name}\"\nscenario = \"triangle\"\n\n[clock]\nmode = \"lockstep\"\n\n\
         [[process]]\nname = \"robot\"\n\
         remote = {{ role = \"robot\", connect = \"tcp/127.0.0.1:{port}\", insecure = true }}\n\n\
         [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\nargs = [{args}]\nends_run = true\n"
    )
}

/// Everything both runs printed, for a failed assertion.
fn both(a: &agp_tests::Finished, b: &agp_tests::Finished) -> String {
    format!(
        "A:\n{}\n{}\nB:\n{}\n{}",
        a.stdout, a.stderr, b.stdout, b.stderr
    )
}

/// Steps physics applies before each cut: A is circling the object (about 7,000 steps) and
/// then pushing it, far from placing it.
const CUT_AT_STEPS: [usize; 2] = [3_000, 9_000];

/// How long each cut lasts: longer than Zenoh takes to notice it (the proxy closes the
/// connections, so at once), shorter than the far timeout.
const CUT: Duration = Duration::from_millis(1_500);

#[test]
fn a_placement_across_the_bridge_rides_out_two_link_cuts_with_every_step_applied_once() {
    let ag = learned_ag("triangle");
    let (a, b) = (instance("cutrob"), instance("cutpla"));
    let port = free_port();
    let proxy = LinkProxy::start(SocketAddr::from(([127, 0, 0, 1], port))).expect("the proxy");
    let robot = LaunchDir::new(&robot_launch(&a, Some(&ag), port, 30.0));
    let planner = LaunchDir::new(&planner_launch(&b, proxy.port()));
    let up_a = AgpUp::start(&robot.launch(), &[]);
    let mut up_b = AgpUp::start(&planner.launch(), &[]);
    let mut log = StepLog::new(robot.path().join("steps.log"));
    for at in CUT_AT_STEPS {
        up_b.until("the steps before a cut", PLACE_TIMEOUT, || log.len() >= at);
        proxy.cut();
        std::thread::sleep(CUT);
        proxy.restore();
    }
    let end_b = up_b.wait(PLACE_TIMEOUT);
    let end_a = up_a.wait(TIMEOUT);
    let all = both(&end_a, &end_b);
    println!("{all}");
    assert!(
        end_b.stdout.contains("run over: `planner` finished it"),
        "{all}"
    );
    assert_eq!(end_a.status.code(), Some(0), "{all}");
    // Both ends saw the link go twice (the robot side's count is its own bridge's).
    assert!(
        end_a.stdout.contains("the far end was lost 2 time(s)"),
        "{all}"
    );
    let (mm, deg) = assert_placed(&robot.results(), &a, "triangle", &end_a.stdout);
    // Lockstep across two cuts: no step lost or applied twice.
    let log = log.poll().to_vec();
    assert_every_step_applied_once(&log);
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
    assert_eq!(count_instance_files(&b), 0, "files of `{b}` remain");
    let (connections, refused) = proxy.counts();
    println!(
        "placed across two cuts: {} steps, {mm:.1} mm, {deg:.1} deg; the proxy forwarded {connections} connection(s) and closed {refused} during the cuts",
        log.len()
    );
}

#[test]
fn a_robot_side_whose_far_end_was_killed_with_9_ends_non_zero_once_it_is_gone_for_its_far_timeout()
{
    let ag = learned_ag("triangle");
    let (a, b) = (instance("gonerob"), instance("gonepla"));
    let port = free_port();
    let robot = LaunchDir::new(&robot_launch(&a, Some(&ag), port, 2.0));
    let planner = LaunchDir::new(&planner_launch(&b, port));
    let up_a = AgpUp::start(&robot.launch(), &[]);
    let mut up_b = AgpUp::start(&planner.launch(), &[]);
    // The link is up once physics steps on B's commands.
    let mut log = StepLog::new(robot.path().join("steps.log"));
    up_b.until("B's first commands", PLACE_TIMEOUT, || log.len() >= 200);
    // B's supervisor killed: its children die with it (their parent-death signal is
    // SIGKILL), so B's bridge never says `bye`.
    up_b.signal(libc::SIGKILL);
    let end_b = up_b.wait(TIMEOUT);
    let end_a = up_a.wait(TIMEOUT);
    let all = both(&end_a, &end_b);
    println!("{all}");
    assert_ne!(end_a.status.code(), Some(0), "{all}");
    let said: Vec<&str> = end_a
        .stderr
        .lines()
        .filter(|l| l.contains("the far end is gone"))
        .collect();
    assert_eq!(said.len(), 1, "one line says why: {all}");
    assert!(
        said[0].starts_with(&format!("agp: error: bridge of instance `{a}`: ")),
        "{all}"
    );
    // B's files, left by its dead supervisor, go with `agp down`.
    run_agp(planner.path(), &["down", "--instance", &b], TIMEOUT);
    assert_every_step_applied_once(log.poll());
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
    assert_eq!(count_instance_files(&b), 0, "files of `{b}` remain");
}

#[test]
fn a_robot_side_whose_far_planner_failed_before_a_task_exits_1_saying_nothing_was_judged() {
    let (a, b) = (instance("failrob"), instance("failpla"));
    let port = free_port();
    // No AG file on A's side: its estimator waits for a planner to learn, which B's planner
    // hears across the link and fails at once (it cannot learn by itself). A far timeout
    // beyond the safety net: A must end on B's `bye`, not on its absence.
    let robot = LaunchDir::new(&robot_launch(&a, None, port, 3_600.0));
    let planner = LaunchDir::new(&planner_launch(&b, port));
    let mut up_a = AgpUp::start(&robot.launch(), &[]);
    up_a.wait_for_lines(&format!("listening on tcp/127.0.0.1:{port}"), 1, TIMEOUT);
    let up_b = AgpUp::start(&planner.launch(), &[]);
    let end_b = up_b.wait(TIMEOUT);
    let end_a = up_a.wait(TIMEOUT);
    let all = both(&end_a, &end_b);
    println!("{all}");
    assert_ne!(end_b.status.code(), Some(0), "{all}");
    assert_eq!(end_a.status.code(), Some(1), "{all}");
    assert!(
        end_a.stdout.contains("ended: the far end stopped"),
        "B's bridge said `bye`: {all}"
    );
    assert!(
        end_a.stderr.contains("nothing was judged"),
        "A says why it failed: {all}"
    );
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
    assert_eq!(count_instance_files(&b), 0, "files of `{b}` remain");
}

/// A launch file of this module's as a live session on the realtime clock: no step log
/// (lockstep's), no end of the run but `agp down`, B's planner serving the goals that A's
/// supervisor owns.
fn live_session(launch: String) -> String {
    launch
        .replace("mode = \"lockstep\"", "mode = \"realtime\"")
        .replace("args = [\"--step-log\", \"steps.log\"]\n", "")
        .replace("\nends_run = true\n", "\n")
        .replace("\"--mode\", \"place\"", "\"--mode\", \"serve\"")
}

/// The cut of the live session: several of physics's watchdog periods (250 ms), so the
/// watchdog must stop the robot during it.
const LIVE_CUT: Duration = Duration::from_millis(1_500);

/// Commands already on their way when the link was cut (in a socket, in Zenoh's queues) may
/// still reach physics this long after the cut; none may after.
const IN_FLIGHT_NS: u64 = 500_000_000;

/// The most a robot stopped by the watchdog may move from one watchdog period after the
/// stop on (it does not move at all: anything is a command that drove it), mm and deg.
const STILL: f64 = 0.1;

#[test]
fn a_live_session_across_a_cut_link_stops_the_robot_by_the_watchdog_moves_it_not_and_goes_on() {
    let ag = learned_ag("triangle");
    let (a, b) = (instance("rtcutrob"), instance("rtcutpla"));
    let port = free_port();
    let proxy = LinkProxy::start(SocketAddr::from(([127, 0, 0, 1], port))).expect("the proxy");
    let robot = LaunchDir::new(&live_session(robot_launch(&a, Some(&ag), port, 30.0)));
    let planner = LaunchDir::new(&live_session(planner_launch(&b, proxy.port())));
    let mut up_a = AgpUp::start(&robot.launch(), &[]);
    let mut up_b = AgpUp::start(&planner.launch(), &[]);
    up_b.wait_for_lines("serving the goals", 1, PLACE_TIMEOUT);
    run_agp(
        robot.path(),
        &["goal", "--instance", &a, "--place", "0", "0", "0"],
        TIMEOUT,
    )
    .assert_success("a goal queued on the robot side");
    // B's planner took the goal across the link: its commands drive the robot.
    up_b.until("the goal taken across the link", PLACE_TIMEOUT, || {
        status_json(robot.path(), &a, TIMEOUT)["goals"][0]["state"] != "queued"
    });
    let cut_ns = monotonic_ns();
    proxy.cut();
    let cut_done_ns = monotonic_ns();
    std::thread::sleep(LIVE_CUT);
    proxy.restore();
    let restored_ns = monotonic_ns();
    // Physics says a stop when a command ends it: the stop that spans the cut ends once
    // the link is back and B's commands come again.
    let mut seen = 1;
    let stop = loop {
        let lines = up_a.wait_for_lines("watchdog stop:", seen, PLACE_TIMEOUT);
        let stops: Vec<LoggedStop> = lines.iter().filter_map(|l| LoggedStop::parse(l)).collect();
        if let Some(stop) = stop_of_fault(&stops, cut_ns + IN_FLIGHT_NS, restored_ns) {
            break stop;
        }
        seen = lines.len() + 1;
    };
    let goal = status_json(robot.path(), &a, TIMEOUT)["goals"][0].clone();
    for (dir, name) in [(planner.path(), &b), (robot.path(), &a)] {
        run_agp(dir, &["down", "--instance", name], TIMEOUT).assert_success("`agp down`");
    }
    let end_b = up_b.wait(TIMEOUT);
    let end_a = up_a.wait(TIMEOUT);
    let all = format!("{}\nstop: {stop:?}", both(&end_a, &end_b));
    println!("{all}");
    // Physics's own account: no command drove the robot from the cut (but what was on its
    // way) until the link was back; the watchdog stopped the wheels; from one watchdog
    // period after that on, the robot did not move.
    assert!(stop.last_command_ns <= cut_ns + IN_FLIGHT_NS, "{all}");
    // The last command answered a frame physics published before the link was cut (one
    // on its way), and the wheels turned on it one watchdog period of physics's ticks at
    // most: physics refuses a command whose frame is older, and stops the wheels in the
    // tick one period after the last one it applied.
    assert!(
        stop.last_frame_ns != 0 && stop.last_frame_ns <= cut_done_ns,
        "{all}"
    );
    assert_eq!(stop.stopped_late(), Some(false), "{all}");
    let resumed = stop.resumed_ns.expect("a command ended the stop");
    assert!(
        resumed >= restored_ns,
        "a command before the link was back: {all}"
    );
    assert!(stop.accounted, "{all}");
    assert!(stop.motion_mm <= STILL && stop.turn_deg <= STILL, "{all}");
    // The session went on: B's commands came again, and the goal was still pursued (or
    // done: reached, or ended by the planner with its reason) when it was brought down.
    assert!(
        goal["state"] == "pursued" || goal["end"].as_str().is_some_and(|e| !e.is_empty()),
        "{goal}"
    );
    assert_eq!(end_b.status.code(), Some(0), "{all}");
    assert_eq!(end_a.status.code(), Some(0), "{all}");
    assert!(
        end_a.stdout.contains("watchdog (250 ms, 160 ticks): "),
        "physics's summary: {all}"
    );
    assert_eq!(count_instance_files(&a), 0, "files of `{a}` remain");
    assert_eq!(count_instance_files(&b), 0, "files of `{b}` remain");
}
