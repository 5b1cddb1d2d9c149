//! A counting global allocator: the proof that a process's steady-state loop allocates
//! nothing per message.
//!
//! A process binary installs it and turns it on first thing:
//!
//! ```
//! use agp_runtime::alloc_count;
//!
//! #[global_allocator]
//! static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;
//!
//! fn main() {
//!     alloc_count::enable_from_env();
//!     // ... the loop, calling `alloc_count::message_done()` once per message ...
//!     alloc_count::report("agp-example", "work", "messages");
//! }
//! ```
//!
//! Counting is off unless `AGP_COUNT_ALLOCS=1` (then every `alloc`, `alloc_zeroed` and
//! `realloc` costs a relaxed atomic add; off, one relaxed load). Each allocation is booked
//! to the [`Region`] its thread is in: inside a call into iceoryx2, inside the process's own
//! work (the simulation, the learning, the planning), or anywhere else in its loop. The loop
//! calls [`message_done`] once per message it handled (a step applied, a frame observed);
//! after the first [`WARMUP_MESSAGES`] the counts are snapshotted, and [`report`] prints, on
//! one line of stderr:
//!
//! `agp-physics: steady-state heap allocations: loop L, simulation S, iceoryx2 I, over N steps after W warm-up steps, in K of them`
//!
//! counting up to the end of the last message only (what shutdown allocates is no
//! message's). K is the number of messages during which anything was allocated: a buffer
//! growing once shows as a small K that stays put however long the run, one allocation per
//! message as K = N.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Messages before the counting starts: room for lazy first-use allocations.
pub const WARMUP_MESSAGES: u64 = 500;

/// The environment variable that turns counting on (value `1`).
pub const ENV: &str = "AGP_COUNT_ALLOCS";

/// Where an allocation happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Region {
    /// The process's loop: anything not in the two regions below.
    Loop = 0,
    /// The process's own work on a message: the simulation step, the learning session's
    /// observation, the planner's decision.
    Work = 1,
    /// A call into iceoryx2: a loan, a send, a receive, a wait.
    Iceoryx2 = 2,
}

static ENABLED: AtomicBool = AtomicBool::new(false);
static COUNTS: [AtomicU64; 3] = [AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0)];

thread_local! {
    /// The region this thread is in.
    static REGION: Cell<Region> = const { Cell::new(Region::Loop) };
    /// Allocations this thread made while counting was on.
    static THREAD_TOTAL: Cell<u64> = const { Cell::new(0) };
}

/// The counting allocator: forwards every call to the system allocator.
pub struct Counting;

impl Counting {
    #[inline]
    fn count(&self) {
        if ENABLED.load(Ordering::Relaxed) {
            let region = REGION.try_with(Cell::get).unwrap_or(Region::Loop);
            COUNTS[region as usize].fetch_add(1, Ordering::Relaxed);
            let _ = THREAD_TOTAL.try_with(|n| n.set(n.get() + 1));
        }
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting touches only
// atomics and a const-initialised thread-local, neither of which allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        self.count();
        // SAFETY: the caller's promise to `GlobalAlloc::alloc` (a layout of non-zero size)
        // is all `System.alloc` asks, and it gets the layout unchanged.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        self.count();
        // SAFETY: as for `alloc`: a non-zero-sized layout, passed on unchanged.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: every block this allocator hands out is `System`'s (each method forwards
        // to it), so `ptr` with the layout it was allocated with, as the caller promises,
        // is a block of `System`'s to free.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        self.count();
        // SAFETY: `ptr` is `System`'s block of `layout` (as for `dealloc`), and the caller
        // promises a non-zero `new_size` that does not overflow at `layout`'s alignment.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Turns counting on when `AGP_COUNT_ALLOCS=1`. Without [`Counting`] installed as the
/// global allocator the counts stay 0 and [`report`] says nothing.
pub fn enable_from_env() {
    if std::env::var(ENV).is_ok_and(|v| v == "1") {
        enable();
    }
}

/// Turns counting on whatever the environment says: for the tests and benchmarks that
/// measure allocations with [`thread_allocations`] or [`process_allocations`].
pub fn enable() {
    ENABLED.store(true, Ordering::Relaxed);
}

/// Whether counting is on.
pub fn enabled() -> bool {
    ENABLED.load(Ordering::Relaxed)
}

fn counts() -> [u64; 3] {
    [0, 1, 2].map(|i| COUNTS[i].load(Ordering::Relaxed))
}

/// Allocations this thread has made while counting was on: a test that runs beside others
/// counts its own.
pub fn thread_allocations() -> u64 {
    THREAD_TOTAL.try_with(Cell::get).unwrap_or(0)
}

/// Allocations the whole process has made while counting was on, every thread's: a
/// benchmark, or a test alone in its binary, also sees what helper threads allocate.
pub fn process_allocations() -> u64 {
    counts().iter().sum()
}

/// Books what this thread allocates to `region` until the guard is dropped.
#[inline]
pub fn enter(region: Region) -> RegionGuard {
    RegionGuard {
        before: REGION.with(|c| c.replace(region)),
    }
}

/// Puts the thread's region back as it was, when dropped.
#[must_use = "the region ends when the guard is dropped"]
pub struct RegionGuard {
    before: Region,
}

impl Drop for RegionGuard {
    #[inline]
    fn drop(&mut self) {
        REGION.with(|c| c.set(self.before));
    }
}

/// Messages handled so far, counts at the end of the warm-up and of the last message, and
/// how many counted messages allocated: the process's one message loop writes them (from
/// one thread), [`report`] reads them at exit.
static MESSAGES: AtomicU64 = AtomicU64::new(0);
static ALLOCATING: AtomicU64 = AtomicU64::new(0);
static BASE: [AtomicU64; 3] = [AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0)];
static LAST: [AtomicU64; 3] = [AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0)];

/// Called once per message the loop handled. Allocates nothing.
#[inline]
pub fn message_done() {
    if !ENABLED.load(Ordering::Relaxed) {
        return;
    }
    let n = MESSAGES.fetch_add(1, Ordering::Relaxed) + 1;
    let now = counts();
    if n == WARMUP_MESSAGES {
        for i in 0..3 {
            BASE[i].store(now[i], Ordering::Relaxed);
            LAST[i].store(now[i], Ordering::Relaxed);
        }
    } else if n > WARMUP_MESSAGES {
        let mut changed = false;
        for i in 0..3 {
            changed |= LAST[i].swap(now[i], Ordering::Relaxed) != now[i];
        }
        if changed {
            ALLOCATING.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// The steady-state counts so far: allocations per region (indexed by [`Region`]), the
/// messages counted and how many of them allocated.
pub fn steady_state() -> ([u64; 3], u64, u64) {
    let d = [0, 1, 2].map(|i| LAST[i].load(Ordering::Relaxed) - BASE[i].load(Ordering::Relaxed));
    let counted = MESSAGES
        .load(Ordering::Relaxed)
        .saturating_sub(WARMUP_MESSAGES);
    (d, counted, ALLOCATING.load(Ordering::Relaxed))
}

/// Prints the steady-state line to stderr when counting: `process` names the binary,
/// `work` the [`Region::Work`] region, `unit` the messages (plural).
pub fn report(process: &str, work: &str, unit: &str) {
    if !enabled() {
        return;
    }
    let (d, counted, allocating) = steady_state();
    eprintln!(
        "{process}: steady-state heap allocations: loop {}, {work} {}, iceoryx2 {}, over {counted} {unit} after {WARMUP_MESSAGES} warm-up {unit}, in {allocating} of them",
        d[Region::Loop as usize],
        d[Region::Work as usize],
        d[Region::Iceoryx2 as usize],
    );
}
