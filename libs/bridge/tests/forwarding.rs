//! Two instances of this machine joined only by two bridges over Zenoh on the loopback,
//! each end in a thread of this test: what one side publishes the other gets, in order,
//! restamped for its own supervisor, the latched state included for an end that joins late.

mod common;

use common::{TIMEOUT, config, instance, start};

use std::time::{Duration, Instant};

use agp_bridge::{BridgeEnd, BridgeReport, Endpoint, Side};
use agp_shared_types::{
    ActiveEpoch, GRIDS_PER_ALPHA, GradientGrid, IrFrame, MotorCommand, ServiceNames,
};
use iceoryx2::port::update_connections::UpdateConnections;

/// Polls `f` until it gives something.
#[track_caller]
fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + TIMEOUT;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < deadline, "{what} never came");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn frames_grids_and_commands_cross_in_order_restamped_and_a_late_end_gets_the_latest() {
    let (a, node_a, control_a) = instance("t-brl-rob");
    let (b, node_b, control_b) = instance("t-brl-pla");
    let port = 27_471;

    // A's side: frames and grids published before any far end exists.
    let frames_a = a.ir_frames(&node_a).expect("frames");
    let frame_pub = frames_a
        .data
        .publisher_builder()
        .create()
        .expect("publisher");
    let grids_a = a.grids(&node_a).expect("grids");
    let grid_pub = grids_a
        .data
        .publisher_builder()
        .create()
        .expect("publisher");
    let commands_a = a.motor_commands(&node_a).expect("commands");
    let command_sub = commands_a
        .data
        .subscriber_builder()
        .create()
        .expect("subscriber");
    let send_frame = |step: u64| {
        let s = frame_pub.loan_uninit().expect("loan");
        s.write_payload(IrFrame {
            step,
            active_epoch: 99,
            ..IrFrame::default()
        })
        .send()
        .expect("send");
    };
    send_frame(1);
    for k in 0..GRIDS_PER_ALPHA {
        let mut s = grid_pub.loan_uninit().expect("loan");
        // SAFETY: a grid is integers and floats only: zeroed bytes are a valid grid.
        let mut s = unsafe {
            std::ptr::write_bytes(s.payload_mut().as_mut_ptr(), 0, 1);
            s.assume_init()
        };
        let g: &mut GradientGrid = s.payload_mut();
        g.header.seq = 7;
        g.header.alpha_count = 1;
        g.header.kind = k as u32;
        g.cells[k] = k as f32 + 0.5;
        s.send().expect("send");
    }

    // B's supervisor made epoch 2 active.
    let epochs_b = b.active_epoch(&node_b).expect("epochs");
    let epoch_pub = epochs_b
        .data
        .publisher_builder()
        .create()
        .expect("publisher");
    epoch_pub
        .send_copy(ActiveEpoch { epoch: 2, seq: 1 })
        .expect("send");
    let frames_b = b.ir_frames(&node_b).expect("frames");
    let frame_sub = frames_b
        .data
        .subscriber_builder()
        .create()
        .expect("subscriber");
    let grids_b = b.grids(&node_b).expect("grids");
    let grid_sub = grids_b
        .data
        .subscriber_builder()
        .create()
        .expect("subscriber");
    let commands_b = b.motor_commands(&node_b).expect("commands");
    let command_pub = commands_b
        .data
        .publisher_builder()
        .create()
        .expect("publisher");

    let robot = start(
        &a,
        config(
            Side::Robot,
            Endpoint::listen(&format!("tcp/127.0.0.1:{port}")).expect("endpoint"),
            "t-forwarding",
            5,
            77,
        ),
    );
    let planner = start(
        &b,
        config(
            Side::Planner,
            Endpoint::connect(&format!("tcp/127.0.0.1:{port}")).expect("endpoint"),
            "t-forwarding",
            0,
            0,
        ),
    );

    // The late end gets the latest frame, restamped with its own active epoch, and the
    // whole grid set, once. (A publisher hands its history to a new subscriber when it
    // next updates its connections, as physics and the estimator do while they wait.)
    let first = until("the latched frame", || {
        let _ = frame_pub.update_connections();
        let _ = grid_pub.update_connections();
        let _ = epoch_pub.update_connections();
        frame_sub.receive().ok().flatten().map(|f| *f)
    });
    assert_eq!(first.step, 1);
    let mut grids = Vec::new();
    until("the grid set", || {
        while let Ok(Some(g)) = grid_sub.receive() {
            grids.push((g.header.seq, g.header.kind, g.cells[g.header.kind as usize]));
        }
        (grids.len() >= GRIDS_PER_ALPHA).then_some(())
    });
    std::thread::sleep(Duration::from_millis(200));
    while let Ok(Some(g)) = grid_sub.receive() {
        grids.push((g.header.seq, g.header.kind, g.cells[g.header.kind as usize]));
    }
    let expected: Vec<_> = (0..GRIDS_PER_ALPHA)
        .map(|k| (7, k as u32, k as f32 + 0.5))
        .collect();
    assert_eq!(grids, expected, "each grid of the set once, in order");

    // Commands: the active epoch's cross with A's epoch and token; another epoch's do not.
    let notifier = commands_b
        .event
        .notifier_builder()
        .create()
        .expect("notifier");
    for (step, epoch) in [(10, 1), (11, 2), (12, 3), (13, 2)] {
        command_pub
            .send_copy(MotorCommand {
                step,
                epoch,
                token: 1234,
                left_mps: 0.1,
                ..MotorCommand::default()
            })
            .expect("send");
        let _ = notifier.notify();
    }
    let mut got = Vec::new();
    until("the commands", || {
        while let Ok(Some(c)) = command_sub.receive() {
            got.push((c.step, c.epoch, c.token));
        }
        (got.len() >= 2).then_some(())
    });
    assert_eq!(got, [(11, 5, 77), (13, 5, 77)]);

    // A burst of live frames: every one, in order, restamped with B's active epoch (read
    // by now: a command of that epoch crossed).
    for step in 2..=200 {
        send_frame(step);
    }
    let mut steps = Vec::new();
    until("the burst", || {
        while let Ok(Some(f)) = frame_sub.receive() {
            steps.push((f.step, f.active_epoch));
        }
        (steps.last().map(|s| s.0) == Some(200)).then_some(())
    });
    let expected: Vec<_> = (2..=200).map(|s| (s, 2)).collect();
    assert_eq!(
        steps, expected,
        "no frame lost or reordered, each with B's active epoch"
    );

    // Stopping one end ends the other: it says bye.
    agp_runtime::request_shutdown();
    let robot = robot.join().expect("robot end").expect("robot report");
    let planner = planner
        .join()
        .expect("planner end")
        .expect("planner report");
    assert!(matches!(
        robot.end,
        BridgeEnd::Stopped | BridgeEnd::FarEnded
    ));
    assert!(matches!(
        planner.end,
        BridgeEnd::Stopped | BridgeEnd::FarEnded
    ));
    let sent = |r: &BridgeReport, n: &str| r.topics.iter().find(|t| t.0 == n).map(|t| (t.1, t.2));
    assert_eq!(sent(&robot, "grids"), Some((GRIDS_PER_ALPHA as u64, 0)));
    assert_eq!(sent(&robot, "ir_frames"), Some((200, 0)));
    assert_eq!(sent(&planner, "motor_commands"), Some((2, 0)));
    assert_eq!(planner.stale, 2);

    drop((
        frame_pub,
        grid_pub,
        command_sub,
        frames_a,
        grids_a,
        commands_a,
        control_a,
    ));
    drop((notifier, epoch_pub, frame_sub, grid_sub, command_pub));
    drop((epochs_b, frames_b, grids_b, commands_b));
    drop((control_b, node_a, node_b));
    for i in [&a, &b] {
        i.remove_files().expect("remove");
        assert!(i.files().is_empty(), "files of `{}` remain", i.name());
    }
    assert_eq!(ServiceNames::IR_FRAMES, "agp/ir_frames");
}
