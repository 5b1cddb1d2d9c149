//! The ping side's loop allocates nothing of its own on the heap once its ports are open.
//!
//! Both sides run in this process (pong on a thread of its own), under an instance name of
//! this test's own, which leaves no file behind. Only allocations made by the ping thread
//! while the flag is up are counted.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::time::Duration;

use agp_bench::hop::{
    HopPorts, HopSmall, Side, Strategy, WaitConfig, new_histogram, ping_loop, pong_loop,
    service_stem,
};
use agp_shared_types::Instance;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

/// Counts one allocation if this thread counts.
fn count() {
    if COUNTING.try_with(Cell::get).unwrap_or(false) {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
    }
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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
    ALLOCATIONS.with(|n| n.set(0));
    COUNTING.with(|c| c.set(true));
    let result = ping_loop(&ping, &config, 0, 1_000, &mut histogram, &mut || Ok(()));
    COUNTING.with(|c| c.set(false));
    result.expect("measured run");
    pong.join().expect("pong thread");
    ALLOCATIONS.with(Cell::get)
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
