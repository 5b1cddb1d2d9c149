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

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use agp_harness::link_proxy::LinkProxy;
use agp_tests::{
    AgpUp, LaunchDir, StepLog, assert_every_step_applied_once, assert_placed, count_instance_files,
    learned_ag, run_agp,
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
