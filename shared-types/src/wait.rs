use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::ipc;

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
pub struct Waiter {
    listener: Listener<ipc::Service>,
    strategy: WaitStrategy,
}

/// Longest single block, so a shutdown request is seen within this even if no signal
/// interrupts the wait.
const BLOCK_SLICE: Duration = Duration::from_millis(50);

impl Waiter {
    pub fn new(listener: Listener<ipc::Service>, strategy: WaitStrategy) -> Self {
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
                    let slice = (timeout - elapsed).min(BLOCK_SLICE);
                    // A notification sent between `poll` and here stays pending, so this
                    // returns at once: no wake-up is lost. An error (an interrupting signal)
                    // just means "poll again".
                    let _ = self.listener.timed_wait(|_| {}, slice);
                }
            }
        }
    }

    /// Consumes pending notifications without blocking.
    pub fn drain(&self) {
        let _ = self.listener.try_wait(|_| {});
    }
}
