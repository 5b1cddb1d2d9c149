//! The ping side's loop allocates nothing of its own on the heap once its ports are open.
//!
//! Both sides run in this process (pong on a thread of its own), under an instance name of
//! this test's own, which leaves no file behind. Only allocations made by the ping thread
//! during the measured run are counted.

use std::time::Duration;

use agp_harness::hop::{
    HopPorts, HopSmall, Side, Strategy, WaitConfig, new_histogram, ping_loop, pong_loop,
    service_stem,
};
use agp_runtime::{Instance, alloc_count};

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

/// Runs two ping-pong runs of `strategy` against a pong thread and returns how many heap
/// allocations the ping thread made during the second one.
fn allocations_of_a_warm_run(instance: &Instance, strategy: Strategy) -> u64 {
    let config = WaitConfig {
        stall_timeout: Duration::from_secs(20),
        ..WaitConfig::new(strategy)
    };
    let stem = service_stem::<HopSmall>(strategy);
    let node = instance
        .node_of::<iceoryx2::prelude::ipc::Service>("alloc-ping", false)
        .expect("ping node");
    let ping = HopPorts::<HopSmall>::open(&node, &stem, Side::Ping).expect("ping ports");

    let pong_instance = instance.clone();
    let pong_stem = stem.clone();
    let pong = std::thread::spawn(move || {
        let node = pong_instance
            .node_of::<iceoryx2::prelude::ipc::Service>("alloc-pong", false)
            .expect("pong node");
        let ports = HopPorts::<HopSmall>::open(&node, &pong_stem, Side::Pong).expect("pong ports");
        for _ in 0..2 {
            pong_loop(&ports, &config, &mut || Ok(())).expect("pong run");
        }
    });

    let mut histogram = new_histogram();
    ping_loop(&ping, &config, 100, 1_000, &mut histogram, &mut || Ok(())).expect("warm-up run");
    alloc_count::enable();
    let before = alloc_count::thread_allocations();
    let result = ping_loop(&ping, &config, 0, 1_000, &mut histogram, &mut || Ok(()));
    let made = alloc_count::thread_allocations() - before;
    result.expect("measured run");
    pong.join().expect("pong thread");
    made
}

/// Removes the instance's files when dropped, also when a test fails half-way.
struct RemoveFiles<'a>(&'a Instance);

impl Drop for RemoveFiles<'_> {
    fn drop(&mut self) {
        let _ = self.0.remove_files();
    }
}

/// Sends of a measured run of 1000 round trips: the pings and the final stop.
const SENDS: u64 = 1_000 + 1;

/// iceoryx2 0.10 allocates one `Rc` per loaned sample (`ChunkMutSharedState::new` in
/// `Publisher::loan_uninit`): that is the only allocation left in the loop, one per send.
/// (With a WaitSet, `wait_and_process_once_with_timeout` adds about two per wake-up, also
/// inside iceoryx2; not asserted here since the number of wake-ups varies.)
#[test]
fn the_ping_loop_allocates_nothing_but_iceoryx2s_one_per_loan_without_a_waitset() {
    let instance =
        Instance::new(&format!("hopalloc-{}", std::process::id())).expect("instance name");
    let cleanup = RemoveFiles(&instance);
    let counts: Vec<(Strategy, u64)> = [Strategy::Spin, Strategy::Yield, Strategy::Listener]
        .into_iter()
        .map(|s| (s, allocations_of_a_warm_run(&instance, s)))
        .collect();
    drop(cleanup);
    assert!(instance.files().is_empty(), "left: {:?}", instance.files());
    for (strategy, n) in counts {
        assert_eq!(
            n, SENDS,
            "{strategy}: {n} allocations for {SENDS} sends in 1000 round trips"
        );
    }
}
