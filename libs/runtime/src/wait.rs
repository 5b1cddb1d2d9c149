use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::FileDescriptorBased;

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

pub use agp_shared_types::WaitStrategy;

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
/// Blocking is a `ppoll` on the listener's Unix datagram socket (iceoryx2's stock event, see
/// `service.rs`), which ends at its timeout to the microsecond, or at the notification, or
/// at a signal (SIGTERM included: `poll` is never restarted after a handler).
/// iceoryx2's own `timed_wait` on the same socket is no substitute: its timeout is a socket
/// option the kernel counts in scheduler ticks (4 ms here), too coarse for physics pacing a
/// 640 Hz loop.
pub struct Waiter {
    listener: Listener<AgpIpc>,
    strategy: WaitStrategy,
}

/// Longest single block, so a shutdown request is seen within this even if its signal went
/// to another thread.
const BLOCK_SLICE: Duration = Duration::from_millis(50);

/// A block shorter than this is not worth the system calls (and the kernel's timer slack
/// would lengthen it): the wait yields instead.
const SHORTEST_BLOCK: Duration = Duration::from_micros(50);

impl Waiter {
    /// A waiter for `listener`, used on this thread (a listener never leaves its thread).
    pub fn new(listener: Listener<AgpIpc>, strategy: WaitStrategy) -> Self {
        Self { listener, strategy }
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

    /// Blocks until a notification or for `slice` at most. Every way out (a notification,
    /// the timeout, a signal) just means "poll again".
    ///
    /// A notifier writes to the socket only when the listener's "notified" flag is clear,
    /// and only taking the notifications clears it. So the block first takes what is
    /// pending: when that is anything, input may have come since the last poll and the block
    /// returns at once; when it is nothing, the flag is clear and the next notification
    /// will reach the socket. Notifications of input found by polling never pile up: the
    /// first block after a run of them takes them all at once.
    fn block(&self, slice: Duration) {
        if slice < SHORTEST_BLOCK {
            std::thread::yield_now();
            return;
        }
        if !matches!(self.listener.try_wait(|_| {}), Ok(0)) {
            return;
        }
        let timeout = libc::timespec {
            tv_sec: slice.as_secs() as libc::time_t,
            tv_nsec: slice.subsec_nanos() as libc::c_long,
        };
        // SAFETY: the listener's socket stays open while it lives, and it outlives this call;
        // `ppoll` only reads the pollfd and the timespec we own and keeps the signal mask.
        let woken = unsafe {
            let mut socket = libc::pollfd {
                fd: self.listener.file_descriptor().native_handle(),
                events: libc::POLLIN,
                revents: 0,
            };
            libc::ppoll(&mut socket, 1, &timeout, std::ptr::null())
        };
        if woken > 0 {
            // Take the notification now, so the next block does not return on it.
            let _ = self.listener.try_wait(|_| {});
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Instance;
    use iceoryx2::port::notifier::Notifier;
    use iceoryx2::prelude::ServiceName;
    use std::sync::Arc;
    use std::sync::atomic::AtomicU32;

    /// The tests' event service, `wait-test.ev`, opened (or created) on `node`.
    fn test_event(
        node: &iceoryx2::node::Node<AgpIpc>,
    ) -> iceoryx2::service::port_factory::event::PortFactory<AgpIpc> {
        let name: ServiceName = "wait-test.ev".try_into().expect("service name");
        node.service_builder(&name)
            .event()
            .event_id_max_value(crate::EVENT_ID_MAX_VALUE)
            .open_or_create()
            .expect("event service")
    }

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
            let service = test_event(&node);
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
            // Shorter than one block slice, and longer than two.
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
                // Blocking, not polling: a few polls per block slice at most.
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
            // Then nothing arrives: the block must wait for the timeout, not return at
            // once, again and again, on notifications already answered.
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
            // The other way out of the block is the end of its slice.
            assert!(
                start.elapsed() < BLOCK_SLICE,
                "woken after {:?}: at the slice's end, not by the notification",
                start.elapsed()
            );
        });
    }

    #[test]
    fn a_notification_from_another_node_wakes_a_block_in_progress() {
        let instance = Instance::new(&format!("wwake{}", std::process::id())).expect("name");
        instance.remove_files().expect("clean start");
        let outcome = {
            let node = instance.node("wait-listener", false).expect("node");
            let service = test_event(&node);
            let waiter = Waiter::new(
                service.listener_builder().create().expect("listener"),
                WaitStrategy::Block,
            );
            // The input: a flag the other thread raises before it notifies, a little after
            // the waiter's first poll (so the waiter is blocked by then).
            let sent = Arc::new(AtomicU32::new(0));
            let polls = Arc::new(AtomicU32::new(0));
            let notifier_thread = {
                let (sent, polls, instance) = (sent.clone(), polls.clone(), instance.clone());
                std::thread::spawn(move || {
                    let node = instance.node("wait-notifier", false).expect("node");
                    let service = test_event(&node);
                    let notifier = service.notifier_builder().create().expect("notifier");
                    while polls.load(Ordering::SeqCst) < 1 {
                        std::thread::yield_now();
                    }
                    std::thread::sleep(Duration::from_millis(5));
                    sent.store(1, Ordering::SeqCst);
                    notifier.notify().expect("notify")
                })
            };
            let start = Instant::now();
            let outcome = waiter.wait_for(Duration::from_secs(20), || {
                polls.fetch_add(1, Ordering::SeqCst);
                (sent.load(Ordering::SeqCst) == 1).then_some(())
            });
            let woken_after = start.elapsed();
            let reached = notifier_thread.join().expect("notifier thread");
            (outcome, woken_after, reached, polls.load(Ordering::SeqCst))
        };
        let _ = instance.remove_files();
        let (outcome, woken_after, reached, polls) = outcome;
        assert_eq!(outcome, WaitOutcome::Ready(()));
        assert_eq!(reached, 1, "the notification reached {reached} listeners");
        // Woken by the notification, not by the end of a block slice: a handful of polls.
        assert!(polls <= 6, "{polls} polls");
        assert!(
            woken_after < BLOCK_SLICE,
            "woken after {woken_after:?}: at the slice's end, not by the notification"
        );
        assert!(instance.files().is_empty(), "left {:?}", instance.files());
    }
}
