//! A planner that commands before the far end of its bridge has joined: in lockstep the
//! first command is the one physics waits for, so the bridge keeps what was sent before the
//! far end joined and hands it over, in order, once it has. (Its own test binary: stopping
//! a bridge is process-wide.)

mod common;

use common::{TIMEOUT, config, instance, start};

use std::time::{Duration, Instant};

use agp_bridge::{BridgeReport, Endpoint, Side};
use agp_shared_types::{ActiveEpoch, GoalEnd, MotorCommand, write_str};

#[test]
fn commands_and_goal_ends_sent_before_the_far_end_joined_reach_it_in_order() {
    let (a, node_a, control_a) = instance("t-brlate-rob");
    let (b, node_b, control_b) = instance("t-brlate-pla");
    let port = 27_472;

    // B: its supervisor made epoch 1 active; its planner will command.
    let epochs_b = b.active_epoch(&node_b).expect("epochs");
    let epoch_pub = epochs_b
        .data
        .publisher_builder()
        .create()
        .expect("publisher");
    epoch_pub
        .send_copy(ActiveEpoch { epoch: 1, seq: 1 })
        .expect("send");
    let commands_b = b.motor_commands(&node_b).expect("commands");
    let command_pub = commands_b
        .data
        .publisher_builder()
        .create()
        .expect("publisher");
    let ends_b = b.goal_ends(&node_b).expect("goal ends");
    let end_pub = ends_b.data.publisher_builder().create().expect("publisher");

    // B's end of the bridge first, connecting to a port nobody listens on yet.
    let planner = start(
        &b,
        config(
            Side::Planner,
            Endpoint::connect(&format!("tcp/127.0.0.1:{port}")).expect("endpoint"),
            "t-late",
            0,
            0,
        ),
    );
    use iceoryx2::port::update_connections::UpdateConnections;
    let _ = epoch_pub.update_connections();
    // The planner commands steps 1 to 3 and ends goal 4 while the far end is not there.
    for step in 1..=3 {
        command_pub
            .send_copy(MotorCommand {
                step,
                epoch: 1,
                left_mps: 0.01 * step as f64,
                ..MotorCommand::default()
            })
            .expect("send");
    }
    let mut end = GoalEnd {
        id: 4,
        sim_time_ns: 12_000_000_000,
        ..GoalEnd::default()
    };
    write_str(&mut end.end, "done");
    end_pub.send_copy(end).expect("send");

    // Then A: physics's command subscriber and the supervisor's goal-end subscriber, and
    // A's end of the bridge, listening.
    let commands_a = a.motor_commands(&node_a).expect("commands");
    let command_sub = commands_a
        .data
        .subscriber_builder()
        .create()
        .expect("subscriber");
    let ends_a = a.goal_ends(&node_a).expect("goal ends");
    let end_sub = ends_a
        .data
        .subscriber_builder()
        .create()
        .expect("subscriber");
    let robot = start(
        &a,
        config(
            Side::Robot,
            Endpoint::listen(&format!("tcp/127.0.0.1:{port}")).expect("endpoint"),
            "t-late",
            5,
            77,
        ),
    );

    let deadline = Instant::now() + TIMEOUT;
    let (mut got, mut ends) = (Vec::new(), Vec::new());
    while (got.len() < 3 || ends.is_empty()) && Instant::now() < deadline {
        while let Ok(Some(c)) = command_sub.receive() {
            got.push((c.step, c.epoch, c.token));
        }
        while let Ok(Some(e)) = end_sub.receive() {
            ends.push(*e);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(
        got,
        [(1, 5, 77), (2, 5, 77), (3, 5, 77)],
        "every command, in order, with A's epoch and token"
    );
    assert_eq!(ends, [end], "the goal's end, once");

    agp_runtime::request_shutdown();
    let robot = robot.join().expect("robot end").expect("robot report");
    let planner = planner
        .join()
        .expect("planner end")
        .expect("planner report");
    let count = |r: &BridgeReport, n: &str| r.topics.iter().find(|t| t.0 == n).map(|t| (t.1, t.2));
    assert_eq!(count(&planner, "motor_commands"), Some((3, 0)));
    assert_eq!(count(&robot, "motor_commands"), Some((0, 3)));
    assert_eq!(count(&robot, "goal_ends"), Some((0, 1)));

    drop((command_sub, end_sub, commands_a, ends_a, control_a));
    drop((
        epoch_pub,
        command_pub,
        end_pub,
        epochs_b,
        commands_b,
        ends_b,
    ));
    drop((control_b, node_a, node_b));
    for i in [&a, &b] {
        i.remove_files().expect("remove");
        assert!(i.files().is_empty(), "files of `{}` remain", i.name());
    }
}
