use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;

use crate::AgpIpc;

static SHUTDOWN: AtomicBool = AtomicBool::new(false);

extern "C" fn on_termination(_: libc::c_int) {
    SHUTDOWN.store(true, Ordering::SeqCst);
}

/// Installs a SIGTERM/SIGINT handler that only sets a flag ([`shutdown_requested`]), so a
/// process stops at its next loop turn, drops its ports and exits cleanly. Processes create
/// their nodes with iceoryx2's own signal handling disabled and call this instead: checking
/// the flag costs one atomic load, where iceoryx2's check is a system call.
pub fn install_shutdown_handler() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = on_termination as extern "C" fn(libc::c_int) as usize;
        libc::sigemptyset(&mut action.sa_mask);
        action.sa_flags = 0;
        libc::sigaction(libc::SIGTERM, &action, std::ptr::null_mut());
        libc::sigaction(libc::SIGINT, &action, std::ptr::null_mut());
    }
}

/// Whether SIGTERM or SIGINT arrived since [`install_shutdown_handler`].
pub fn shutdown_requested() -> bool {
    SHUTDOWN.load(Ordering::Relaxed)
}

/// Asks the loops of this process to stop, as a signal would.
pub fn request_shutdown() {
    SHUTDOWN.store(true, Ordering::SeqCst);
}

/// How a process waits for its next input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitStrategy {
    /// Poll without pause: the lowest latency, one core per waiting process.
    Spin,
    /// Poll, yielding the core between polls: near-spin latency while others can run.
    Yield,
    /// Block on the event service at once.
    Block,
    /// Poll with yields for `spin`, then block.
    SpinThenBlock { spin: Duration },
}

impl WaitStrategy {
    /// The strategy named in `AGP_WAIT` (`spin`, `yield`, `block`, `spin-then-block` with an
    /// optional `:<microseconds>`), or the default.
    /// A value that names none is said on stderr and the default is used: `agp up` refuses
    /// such a value before anything starts ([`WaitStrategy::from_env_checked`]).
    pub fn from_env() -> Self {
        match Self::from_env_checked() {
            Ok(strategy) => strategy.unwrap_or_default(),
            Err(why) => {
                let default = Self::default();
                eprintln!("{why}: waiting `{}`", default.name());
                default
            }
        }
    }

    /// The environment variable that names the strategy.
    pub const ENV: &'static str = "AGP_WAIT";

    /// Why a value of [`WaitStrategy::ENV`] is refused, and what it may hold.
    pub const NOT_A_STRATEGY: &'static str =
        "not a waiting strategy: `spin`, `yield`, `block` or `spin-then-block[:<microseconds>]`";

    /// The strategy `AGP_WAIT` names; `Ok(None)` when it is unset, an error that names the
    /// value when it names no strategy.
    pub fn from_env_checked() -> Result<Option<Self>, String> {
        match std::env::var(Self::ENV) {
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(std::env::VarError::NotUnicode(v)) => {
                Err(format!("{}={v:?} is {}", Self::ENV, Self::NOT_A_STRATEGY))
            }
            Ok(v) => Self::parse(&v)
                .map(Some)
                .ok_or_else(|| format!("{}=`{v}` is {}", Self::ENV, Self::NOT_A_STRATEGY)),
        }
    }

    /// Parses a strategy name.
    pub fn parse(s: &str) -> Option<Self> {
        let (name, arg) = s.split_once(':').unwrap_or((s, ""));
        match name {
            "spin" => Some(Self::Spin),
            "yield" => Some(Self::Yield),
            "block" => Some(Self::Block),
            "spin-then-block" => {
                let us = if arg.is_empty() {
                    200
                } else {
                    arg.parse().ok()?
                };
                Some(Self::SpinThenBlock {
                    spin: Duration::from_micros(us),
                })
            }
            _ => None,
        }
    }

    /// Whether a waiter with this strategy ever blocks on its listener (and so needs a
    /// timer to end a block, and must take the notifications of input it found by polling).
    pub fn blocks(&self) -> bool {
        matches!(self, Self::Block | Self::SpinThenBlock { .. })
    }

    pub fn name(&self) -> String {
        match self {
            Self::Spin => "spin".into(),
            Self::Yield => "yield".into(),
            Self::Block => "block".into(),
            Self::SpinThenBlock { spin } => format!("spin-then-block:{}", spin.as_micros()),
        }
    }
}

impl Default for WaitStrategy {
    fn default() -> Self {
        Self::SpinThenBlock {
            spin: Duration::from_micros(200),
        }
    }
}

/// What ended a wait.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitOutcome<T> {
    Ready(T),
    TimedOut,
    Shutdown,
}

/// Waits for input on one event service with a [`WaitStrategy`]; never blocks longer than
/// the timeout it is given, and returns at once when shutdown is requested.
///
/// Blocking is a `sem_wait` on the listener's futex (see `service.rs`), which has no
/// timeout of its own: a timer of this thread (`DeadlineTimer`) sends it a signal at the
/// end of each block, and that signal is unblocked only while the thread sits in `sem_wait`,
/// so it never interrupts anything else.
pub struct Waiter {
    listener: Listener<AgpIpc>,
    strategy: WaitStrategy,
    timer: Option<DeadlineTimer>,
    /// Inputs found since the last [`Waiter::drain`].
    polled_since_drain: std::cell::Cell<u32>,
}

/// Inputs found by polling between two takes of the notifications that came with them
/// (one take sweeps the listener's counters: about 0.4 us here).
const DRAIN_EVERY: u32 = 64;

/// Longest single block, so a shutdown request is seen within this even if no signal
/// interrupts the wait.
const BLOCK_SLICE: Duration = Duration::from_millis(50);

/// A block shorter than this is not worth a timer: the wait yields instead.
const SHORTEST_BLOCK: Duration = Duration::from_micros(50);

impl Waiter {
    /// A waiter for `listener`, used on this thread (a listener never leaves its thread).
    pub fn new(listener: Listener<AgpIpc>, strategy: WaitStrategy) -> Self {
        let timer = if strategy.blocks() {
            DeadlineTimer::new()
        } else {
            None
        };
        Self {
            listener,
            strategy,
            timer,
            polled_since_drain: std::cell::Cell::new(0),
        }
    }

    pub fn strategy(&self) -> WaitStrategy {
        self.strategy
    }

    /// Calls `poll` until it returns `Some`, waiting between calls as the strategy says.
    pub fn wait_for<T>(
        &self,
        timeout: Duration,
        mut poll: impl FnMut() -> Option<T>,
    ) -> WaitOutcome<T> {
        let start = Instant::now();
        loop {
            if let Some(v) = poll() {
                if self.strategy.blocks() {
                    // Senders notify every send, and a receiver that found its input by
                    // polling took no notification: the semaphore would count them all, and
                    // the first block after a long run would return at once and then take
                    // them one by one. Taking them every DRAIN_EVERY inputs keeps the count
                    // small at a fraction of the cost of a take per input. Each taken one
                    // stands for input sent before now, which the next poll sees: no
                    // wake-up is lost.
                    let polled = self.polled_since_drain.get() + 1;
                    if polled >= DRAIN_EVERY {
                        self.drain();
                        self.polled_since_drain.set(0);
                    } else {
                        self.polled_since_drain.set(polled);
                    }
                }
                return WaitOutcome::Ready(v);
            }
            if shutdown_requested() {
                return WaitOutcome::Shutdown;
            }
            let elapsed = start.elapsed();
            if elapsed >= timeout {
                return WaitOutcome::TimedOut;
            }
            match self.strategy {
                WaitStrategy::Spin => core::hint::spin_loop(),
                WaitStrategy::Yield => std::thread::yield_now(),
                WaitStrategy::SpinThenBlock { spin } if elapsed < spin => std::thread::yield_now(),
                WaitStrategy::Block | WaitStrategy::SpinThenBlock { .. } => {
                    self.block((timeout - elapsed).min(BLOCK_SLICE));
                }
            }
        }
    }

    /// Blocks until a notification or for `slice` at most. A notification sent between the
    /// last poll and here stays counted in the semaphore, so this returns at once: no wake-up
    /// is lost. Every way out (a notification, the timer, SIGTERM) just means "poll again".
    fn block(&self, slice: Duration) {
        match &self.timer {
            _ if slice < SHORTEST_BLOCK => std::thread::yield_now(),
            Some(timer) => {
                // The timer ticks every BLOCK_SLICE anyway: set it only for a shorter block.
                if slice < BLOCK_SLICE {
                    timer.arm(slice);
                }
                timer.unmask();
                let _ = self.listener.blocking_wait(|_| {});
                timer.mask();
            }
            // No timer for this thread: iceoryx2's own timed wait, which polls.
            None => {
                let _ = self.listener.timed_wait(|_| {}, slice);
            }
        }
    }

    /// Consumes pending notifications without blocking.
    pub fn drain(&self) {
        let _ = self.listener.try_wait(|_| {});
    }
}

/// The signal that ends a block at its deadline. Real-time signals above the few glibc
/// keeps for itself are free for applications.
fn wake_signal() -> libc::c_int {
    libc::SIGRTMIN() + 6
}

extern "C" fn on_wake_signal(_: libc::c_int) {}

/// The set holding only [`wake_signal`].
fn wake_set() -> libc::sigset_t {
    // SAFETY: sigemptyset/sigaddset initialise the set we own.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, wake_signal());
        set
    }
}

/// A POSIX timer that signals the thread that made it every [`BLOCK_SLICE`], or sooner
/// when a block must end sooner (then again every [`BLOCK_SLICE`]: a tick that fell just
/// before the block began is followed by another), its signal unmasked only while the
/// thread blocks. A block of [`BLOCK_SLICE`] may so end early, at the next tick: the waiter
/// polls and blocks again.
struct DeadlineTimer {
    id: libc::timer_t,
    set: libc::sigset_t,
}

impl DeadlineTimer {
    /// Installs the signal's handler (once per process, without `SA_RESTART`, so the signal
    /// ends `sem_wait`), masks the signal on this thread and makes its timer; `None` if the
    /// system refuses one, and the waiter falls back to iceoryx2's timed wait.
    fn new() -> Option<Self> {
        static HANDLER: std::sync::Once = std::sync::Once::new();
        HANDLER.call_once(|| {
            // SAFETY: the handler does nothing, which is async-signal-safe.
            unsafe {
                let mut action: libc::sigaction = std::mem::zeroed();
                action.sa_sigaction = on_wake_signal as extern "C" fn(libc::c_int) as usize;
                libc::sigemptyset(&mut action.sa_mask);
                action.sa_flags = 0;
                libc::sigaction(wake_signal(), &action, std::ptr::null_mut());
            }
        });
        let set = wake_set();
        // SAFETY: plain system calls on values we own; the sigevent names this thread.
        unsafe {
            if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
                return None;
            }
            let mut event: libc::sigevent = std::mem::zeroed();
            event.sigev_notify = libc::SIGEV_THREAD_ID;
            event.sigev_signo = wake_signal();
            event.sigev_notify_thread_id = libc::gettid();
            let mut id: libc::timer_t = std::ptr::null_mut();
            if libc::timer_create(libc::CLOCK_MONOTONIC, &mut event, &mut id) != 0 {
                return None;
            }
            let timer = Self { id, set };
            timer.arm(BLOCK_SLICE);
            Some(timer)
        }
    }

    fn arm(&self, first: Duration) {
        let spec = |d: Duration| libc::timespec {
            tv_sec: d.as_secs() as libc::time_t,
            tv_nsec: d.subsec_nanos() as libc::c_long,
        };
        let value = libc::itimerspec {
            it_value: spec(first),
            it_interval: spec(BLOCK_SLICE),
        };
        // SAFETY: our own timer, a value we own.
        unsafe { libc::timer_settime(self.id, 0, &value, std::ptr::null_mut()) };
    }

    fn unmask(&self) {
        // SAFETY: changes this thread's mask only.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &self.set, std::ptr::null_mut()) };
    }

    fn mask(&self) {
        // SAFETY: changes this thread's mask only.
        unsafe { libc::pthread_sigmask(libc::SIG_BLOCK, &self.set, std::ptr::null_mut()) };
    }
}

impl Drop for DeadlineTimer {
    fn drop(&mut self) {
        // SAFETY: our own timer, deleted once. A tick still pending stays masked.
        unsafe { libc::timer_delete(self.id) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Instance;
    use iceoryx2::port::notifier::Notifier;
    use iceoryx2::prelude::ServiceName;

    /// Runs `f` with a listener and a notifier of one event service of a private instance,
    /// then checks the instance left no file behind.
    fn with_event(tag: &str, f: impl FnOnce(Listener<AgpIpc>, &Notifier<AgpIpc>)) {
        /// Removes the instance's files however the test ends, a failed assertion included.
        struct Cleanup<'a>(&'a Instance);
        impl Drop for Cleanup<'_> {
            fn drop(&mut self) {
                let _ = self.0.remove_files();
            }
        }
        let instance = Instance::new(&format!("w{tag}{}", std::process::id())).expect("name");
        instance.remove_files().expect("clean start");
        let cleanup = Cleanup(&instance);
        {
            let node = instance.node("wait-test", false).expect("node");
            let name: ServiceName = "wait-test.ev".try_into().expect("service name");
            let service = node
                .service_builder(&name)
                .event()
                .event_id_max_value(crate::EVENT_ID_MAX_VALUE)
                .open_or_create()
                .expect("event service");
            let listener = service.listener_builder().create().expect("listener");
            let notifier = service.notifier_builder().create().expect("notifier");
            f(listener, &notifier);
        }
        drop(cleanup);
        assert!(instance.files().is_empty(), "left {:?}", instance.files());
    }

    #[test]
    fn a_block_with_nothing_to_wake_it_ends_at_the_timeout_not_before() {
        with_event("to", |listener, _| {
            let waiter = Waiter::new(listener, WaitStrategy::Block);
            // Shorter than one timer period, and longer than two.
            for timeout in [
                Duration::from_millis(20),
                BLOCK_SLICE * 2 + Duration::from_millis(10),
            ] {
                let start = Instant::now();
                let mut polls = 0;
                let outcome = waiter.wait_for(timeout, || {
                    polls += 1;
                    None::<()>
                });
                assert_eq!(outcome, WaitOutcome::TimedOut);
                assert!(
                    start.elapsed() >= timeout,
                    "returned after {:?} of {timeout:?}",
                    start.elapsed()
                );
                // Blocking, not polling: a few polls per timer period at most.
                assert!(
                    polls <= 4 * (timeout.as_millis() / BLOCK_SLICE.as_millis() + 2),
                    "{polls} polls in {timeout:?}"
                );
            }
        });
    }

    #[test]
    fn notifications_of_input_found_by_polling_do_not_pile_up() {
        with_event("pile", |listener, notifier| {
            let waiter = Waiter::new(listener, WaitStrategy::Block);
            // A long run in which every input was there at the first poll, as when the
            // receiver spins: each came with its notification.
            for i in 0..10_000 {
                notifier.notify().expect("notify");
                assert_eq!(
                    waiter.wait_for(Duration::from_secs(20), || Some(i)),
                    WaitOutcome::Ready(i)
                );
            }
            let pending = waiter.listener.try_wait(|_| {}).expect("try_wait");
            assert!(
                pending <= u64::from(DRAIN_EVERY),
                "{pending} notifications still counted"
            );
            // Then nothing arrives: the block must wait for the timeout, not return at
            // once on a notification already answered.
            let mut polls = 0;
            let outcome = waiter.wait_for(Duration::from_millis(20), || {
                polls += 1;
                None::<()>
            });
            assert_eq!(outcome, WaitOutcome::TimedOut);
            assert!(
                polls <= 4,
                "{polls} polls: the block returned on stale notifications"
            );
        });
    }

    #[test]
    fn a_notification_sent_before_the_block_ends_it_at_once() {
        with_event("nt", |listener, notifier| {
            let waiter = Waiter::new(listener, WaitStrategy::Block);
            let mut polls = 0;
            let start = Instant::now();
            let outcome = waiter.wait_for(Duration::from_secs(20), || {
                polls += 1;
                if polls == 1 {
                    // The sample "arrives" between this poll and the block, with its
                    // notification: the block must not miss it.
                    notifier.notify().expect("notify");
                    None
                } else {
                    Some(polls)
                }
            });
            assert_eq!(outcome, WaitOutcome::Ready(2));
            // The other way out of the block is the timer's next tick.
            assert!(
                start.elapsed() < BLOCK_SLICE,
                "woken after {:?}: by the timer, not the notification",
                start.elapsed()
            );
        });
    }
}
