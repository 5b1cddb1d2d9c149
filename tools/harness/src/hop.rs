//! The floor of the pipeline: one bare iceoryx2 hop between two processes.
//!
//! Two pub-sub services (`<stem>/ping`, `<stem>/pong`), each paired with an event service
//! (`<stem>/ping.ev`, `<stem>/pong.ev`) that the sender notifies after each send when the
//! [`Strategy`] blocks. The ping side stamps a sequence number and CLOCK_MONOTONIC into a
//! loaned sample; the pong side echoes both back; the ping side records half the round
//! trip as the one-way latency. The pong side announces itself with [`READY_SEQ`] before
//! the first ping, and the ping side ends a run with [`STOP_SEQ`].
//!
//! `bench-hop` runs this between itself and a re-executed copy of itself, over iceoryx2's
//! own `ipc::Service` (Unix-socket events, which a WaitSet can wait on). The pipeline's
//! floor is `agp profile`'s, over the pipeline's own service type `AgpIpc`.
//!
//! Nothing in the measured loop allocates on our side: samples are loaned from shared
//! memory, the histogram is sized before the loop. iceoryx2 0.10 itself allocates one `Rc`
//! per loaned sample (`ChunkMutSharedState::new` in `Publisher::loan_uninit`), and
//! `WaitSet::wait_and_process_once_with_timeout` about two more per wake-up (it collects
//! the woken file descriptors into a fresh `Vec`); both are part of what the figures
//! measure. `tests/hop_allocations.rs` counts them.

use std::fmt::Debug;
use std::mem::MaybeUninit;
use std::str::FromStr;
use std::time::{Duration, Instant};

use agp_runtime::shutdown_requested;
use agp_shared_types::monotonic_ns;
use hdrhistogram::Histogram;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use iceoryx2::service::port_factory::{event, publish_subscribe};

/// Sequence number of the pong side's "my ports are up" message.
pub const READY_SEQ: u64 = u64::MAX - 1;
/// Sequence number that ends the pong side's loop.
pub const STOP_SEQ: u64 = u64::MAX;

/// How a receiver waits for the next sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Strategy {
    /// Poll `receive` without pause (one core per waiting process).
    Spin,
    /// Poll `receive`, calling `std::thread::yield_now` between polls.
    Yield,
    /// The sender notifies the paired event service after each send; the receiver blocks on
    /// a WaitSet holding the listener with a deadline.
    Waitset,
    /// Spin for [`WaitConfig::spin_budget`], then block as [`Strategy::Waitset`] does.
    SpinThenBlock,
    /// Like [`Strategy::Waitset`] but blocks in `Listener::timed_wait` directly, as
    /// `agp_runtime::Waiter` does. Not in [`Strategy::DEFAULT_SET`].
    Listener,
}

impl Strategy {
    /// The strategies `bench-hop` runs when none is named, in this order.
    pub const DEFAULT_SET: [Strategy; 4] = [
        Strategy::Spin,
        Strategy::Yield,
        Strategy::Waitset,
        Strategy::SpinThenBlock,
    ];

    /// Every strategy.
    pub const ALL: [Strategy; 5] = [
        Strategy::Spin,
        Strategy::Yield,
        Strategy::Waitset,
        Strategy::SpinThenBlock,
        Strategy::Listener,
    ];

    /// The name used on the command line, in tables and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::Spin => "spin",
            Self::Yield => "yield",
            Self::Waitset => "waitset",
            Self::SpinThenBlock => "spin-then-block",
            Self::Listener => "listener",
        }
    }

    /// Whether a receiver may block, so a sender must notify the event service after each
    /// send.
    pub fn notifies(self) -> bool {
        matches!(self, Self::Waitset | Self::SpinThenBlock | Self::Listener)
    }

    /// Whether the receiver blocks on a WaitSet.
    fn uses_waitset(self) -> bool {
        matches!(self, Self::Waitset | Self::SpinThenBlock)
    }
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A strategy name that is none of [`Strategy::ALL`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownStrategy(pub String);

impl std::fmt::Display for UnknownStrategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "unknown strategy `{}`; expected one of spin, yield, waitset, spin-then-block, listener",
            self.0
        )
    }
}

impl std::error::Error for UnknownStrategy {}

impl FromStr for Strategy {
    type Err = UnknownStrategy;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownStrategy(s.to_owned()))
    }
}

/// How to wait, and when to give up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WaitConfig {
    pub strategy: Strategy,
    /// How long [`Strategy::SpinThenBlock`] spins before it blocks.
    pub spin_budget: Duration,
    /// The deadline attached to the listener: the longest single block, and how often the
    /// peer's liveness and a shutdown request are checked while waiting.
    pub deadline: Duration,
    /// A wait for one sample that lasts this long fails with [`HopError::Stalled`].
    pub stall_timeout: Duration,
}

impl WaitConfig {
    pub fn new(strategy: Strategy) -> Self {
        Self {
            strategy,
            spin_budget: Duration::from_micros(20),
            deadline: Duration::from_millis(100),
            stall_timeout: Duration::from_secs(10),
        }
    }
}

/// Why a hop failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HopError {
    /// Opening a service, creating a port or a WaitSet failed.
    Setup { step: &'static str, reason: String },
    /// Loaning, sending, notifying, receiving or waiting failed.
    Transport { step: &'static str, reason: String },
    /// No sample arrived for this long.
    Stalled { waited: Duration },
    /// The peer process is gone.
    PeerGone,
    /// SIGINT or SIGTERM arrived (see `agp_runtime::install_shutdown_handler`).
    Shutdown,
}

impl HopError {
    fn setup(step: &'static str, e: impl Debug) -> Self {
        Self::Setup {
            step,
            reason: format!("{e:?}"),
        }
    }

    fn transport(step: &'static str, e: impl Debug) -> Self {
        Self::Transport {
            step,
            reason: format!("{e:?}"),
        }
    }
}

impl std::fmt::Display for HopError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Setup { step, reason } => write!(f, "cannot {step}: {reason}"),
            Self::Transport { step, reason } => write!(f, "{step} failed: {reason}"),
            Self::Stalled { waited } => write!(f, "no sample arrived for {waited:?}"),
            Self::PeerGone => write!(f, "the peer process is gone"),
            Self::Shutdown => write!(f, "shutdown requested (SIGINT or SIGTERM)"),
        }
    }
}

impl std::error::Error for HopError {}

/// A payload that can carry a hop's sequence number and stamp.
///
/// # Safety
/// [`HopPayload::write_header`] must initialise every field of `Self` that is not a
/// `MaybeUninit`, so the sample may be treated as initialised afterwards.
pub unsafe trait HopPayload: Debug + ZeroCopySend + Sized + 'static {
    /// Writes the sequence number and the stamp into a loaned, uninitialised slot.
    fn write_header(slot: &mut MaybeUninit<Self>, seq: u64, stamp_ns: u64);
    fn seq(&self) -> u64;
    fn stamp_ns(&self) -> u64;
}

/// The small hop payload: a sequence number and a CLOCK_MONOTONIC stamp.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::HopSmall.v1")]
pub struct HopSmall {
    pub seq: u64,
    pub stamp_ns: u64,
}

const _: () = assert!(std::mem::size_of::<HopSmall>() == 16);
const _: () = assert!(std::mem::align_of::<HopSmall>() == 8);

// SAFETY: `write_header` writes the whole value.
unsafe impl HopPayload for HopSmall {
    fn write_header(slot: &mut MaybeUninit<Self>, seq: u64, stamp_ns: u64) {
        slot.write(Self { seq, stamp_ns });
    }

    fn seq(&self) -> u64 {
        self.seq
    }

    fn stamp_ns(&self) -> u64 {
        self.stamp_ns
    }
}

/// Size of [`HopGrid`]: a 128 x 128 f32 gradient grid.
pub const HOP_GRID_BYTES: usize = 64 * 1024;

/// A 64 KiB hop payload, mirroring a gradient grid. Only the header is written and read:
/// the body travels by reference, as a grid does, and is left uninitialised.
#[derive(Debug, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::HopGrid.v1")]
pub struct HopGrid {
    pub seq: u64,
    pub stamp_ns: u64,
    pub body: MaybeUninit<[u8; HOP_GRID_BYTES - 16]>,
}

const _: () = assert!(std::mem::size_of::<HopGrid>() == HOP_GRID_BYTES);
const _: () = assert!(std::mem::align_of::<HopGrid>() == 8);

// SAFETY: `write_header` writes `seq` and `stamp_ns`; `body` is a `MaybeUninit`.
unsafe impl HopPayload for HopGrid {
    fn write_header(slot: &mut MaybeUninit<Self>, seq: u64, stamp_ns: u64) {
        let p = slot.as_mut_ptr();
        // SAFETY: `p` points to a writable `HopGrid`; writing its fields through raw
        // pointers reads nothing uninitialised.
        unsafe {
            (&raw mut (*p).seq).write(seq);
            (&raw mut (*p).stamp_ns).write(stamp_ns);
        }
    }

    fn seq(&self) -> u64 {
        self.seq
    }

    fn stamp_ns(&self) -> u64 {
        self.stamp_ns
    }
}

/// Which end of the hop a process is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Sends pings, measures.
    Ping,
    /// Echoes pings.
    Pong,
}

/// The stem of a run's service names, so runs of different strategies or payloads never
/// share a service: `hop/<strategy>/<bytes>`.
pub fn service_stem<P: HopPayload>(strategy: Strategy) -> String {
    format!("hop/{}/{}", strategy.name(), std::mem::size_of::<P>())
}

/// The four services of a hop: ping, pong and their event services.
type HopServices<P> = (
    publish_subscribe::PortFactory<ipc::Service, P, ()>,
    publish_subscribe::PortFactory<ipc::Service, P, ()>,
    event::PortFactory<ipc::Service>,
    event::PortFactory<ipc::Service>,
);

/// One side's ports of a hop: it publishes on its own topic and notifies its own event
/// service, and subscribes to and listens on the other side's.
pub struct HopPorts<P: HopPayload> {
    publisher: Publisher<ipc::Service, P, ()>,
    subscriber: Subscriber<ipc::Service, P, ()>,
    notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    // Declared after the ports so they are dropped after them.
    _services: HopServices<P>,
}

impl<P: HopPayload> HopPorts<P> {
    /// Opens (or creates) the four services under `stem` and this side's ports. Both sides
    /// must use the same `stem` (see [`service_stem`]).
    pub fn open(node: &Node<ipc::Service>, stem: &str, side: Side) -> Result<Self, HopError> {
        let ping = open_topic::<P>(node, &format!("{stem}/ping"))?;
        let pong = open_topic::<P>(node, &format!("{stem}/pong"))?;
        let ping_ev = open_event(node, &format!("{stem}/ping.ev"))?;
        let pong_ev = open_event(node, &format!("{stem}/pong.ev"))?;
        let (out, inp, out_ev, in_ev) = match side {
            Side::Ping => (&ping, &pong, &ping_ev, &pong_ev),
            Side::Pong => (&pong, &ping, &pong_ev, &ping_ev),
        };
        let subscriber = inp
            .subscriber_builder()
            .buffer_size(2)
            .create()
            .map_err(|e| HopError::setup("create the subscriber", e))?;
        let listener = in_ev
            .listener_builder()
            .create()
            .map_err(|e| HopError::setup("create the listener", e))?;
        let publisher = out
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| HopError::setup("create the publisher", e))?;
        let notifier = out_ev
            .notifier_builder()
            .create()
            .map_err(|e| HopError::setup("create the notifier", e))?;
        Ok(Self {
            publisher,
            subscriber,
            notifier,
            listener,
            _services: (ping, pong, ping_ev, pong_ev),
        })
    }

    /// Loans a sample, writes `seq` and `stamp_ns` into it, sends it and, with `notify`,
    /// notifies the paired event service.
    pub fn send(&self, seq: u64, stamp_ns: u64, notify: bool) -> Result<(), HopError> {
        let mut sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| HopError::transport("loan", e))?;
        P::write_header(sample.payload_mut(), seq, stamp_ns);
        // SAFETY: `write_header` initialised every field that is not a `MaybeUninit`
        // (the contract of the unsafe trait `HopPayload`).
        let sample = unsafe { sample.assume_init() };
        sample.send().map_err(|e| HopError::transport("send", e))?;
        if notify {
            self.notifier
                .notify()
                .map_err(|e| HopError::transport("notify", e))?;
        }
        Ok(())
    }
}

fn open_topic<P: HopPayload>(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<publish_subscribe::PortFactory<ipc::Service, P, ()>, HopError> {
    let service_name: ServiceName = name
        .try_into()
        .map_err(|e| HopError::setup("name a service", e))?;
    node.service_builder(&service_name)
        .publish_subscribe::<P>()
        .history_size(0)
        .subscriber_max_buffer_size(2)
        .max_publishers(2)
        .max_subscribers(2)
        .max_nodes(4)
        .open_or_create()
        .map_err(|e| HopError::setup("open a pub-sub service", e))
}

fn open_event(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<event::PortFactory<ipc::Service>, HopError> {
    let service_name: ServiceName = name
        .try_into()
        .map_err(|e| HopError::setup("name a service", e))?;
    node.service_builder(&service_name)
        .event()
        .max_notifiers(2)
        .max_listeners(2)
        .max_nodes(4)
        .open_or_create()
        .map_err(|e| HopError::setup("open an event service", e))
}

/// Polls between two looks at the clock while spinning or yielding.
const POLLS_PER_CHECK: u32 = 1024;
/// Polls between two looks at the clock during the spin phase of spin-then-block.
const POLLS_PER_BUDGET_CHECK: u32 = 8;

/// Looks after a wait in progress: shutdown requests, the peer's liveness (every
/// [`WaitConfig::deadline`]) and the stall timeout.
struct Watch {
    deadline: Duration,
    stall_timeout: Duration,
    started: Option<Instant>,
    last_check: Option<Instant>,
}

impl Watch {
    fn new(config: &WaitConfig) -> Self {
        Self {
            deadline: config.deadline,
            stall_timeout: config.stall_timeout,
            started: None,
            last_check: None,
        }
    }

    /// Starts the clocks if not yet started.
    fn arm(&mut self) {
        if self.started.is_none() {
            let now = Instant::now();
            self.started = Some(now);
            self.last_check = Some(now);
        }
    }

    fn tick<F: FnMut() -> Result<(), HopError>>(
        &mut self,
        liveness: &mut F,
    ) -> Result<(), HopError> {
        if shutdown_requested() {
            return Err(HopError::Shutdown);
        }
        self.arm();
        let now = Instant::now();
        let (Some(started), Some(last)) = (self.started, self.last_check) else {
            return Ok(());
        };
        if now.duration_since(last) >= self.deadline {
            self.last_check = Some(now);
            liveness()?;
        }
        let waited = now.duration_since(started);
        if waited >= self.stall_timeout {
            return Err(HopError::Stalled { waited });
        }
        Ok(())
    }
}

struct BlockOn<'a, 'w, 'l> {
    waitset: &'w WaitSet<ipc::Service>,
    guard: &'a WaitSetGuard<'w, 'l, ipc::Service>,
}

/// Waits for the next sample of one subscriber with a [`WaitConfig`]. Built by
/// [`with_waiter`], which owns the WaitSet and its attachment.
pub struct Waiter<'a, 'w, 'l, P: HopPayload> {
    config: WaitConfig,
    subscriber: &'a Subscriber<ipc::Service, P, ()>,
    listener: &'l Listener<ipc::Service>,
    block: Option<BlockOn<'a, 'w, 'l>>,
}

/// Builds a [`Waiter`] on `ports`' subscriber and listener (with a WaitSet and the
/// listener attached with [`WaitConfig::deadline`], when the strategy blocks on one) and
/// hands it to `f`.
pub fn with_waiter<P: HopPayload, R>(
    config: &WaitConfig,
    ports: &HopPorts<P>,
    f: impl FnOnce(&Waiter<'_, '_, '_, P>) -> Result<R, HopError>,
) -> Result<R, HopError> {
    if config.strategy.uses_waitset() {
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| HopError::setup("create the WaitSet", e))?;
        let guard = waitset
            .attach_deadline(&ports.listener, config.deadline)
            .map_err(|e| HopError::setup("attach the listener to the WaitSet", e))?;
        let waiter = Waiter {
            config: *config,
            subscriber: &ports.subscriber,
            listener: &ports.listener,
            block: Some(BlockOn {
                waitset: &waitset,
                guard: &guard,
            }),
        };
        f(&waiter)
    } else {
        let waiter = Waiter {
            config: *config,
            subscriber: &ports.subscriber,
            listener: &ports.listener,
            block: None,
        };
        f(&waiter)
    }
}

impl<P: HopPayload> Waiter<'_, '_, '_, P> {
    pub fn config(&self) -> &WaitConfig {
        &self.config
    }

    /// Waits for the next sample. `liveness` is called about every
    /// [`WaitConfig::deadline`] while waiting; an error from it ends the wait.
    pub fn next<F: FnMut() -> Result<(), HopError>>(
        &self,
        liveness: &mut F,
    ) -> Result<Sample<ipc::Service, P, ()>, HopError> {
        let mut watch = Watch::new(&self.config);
        match self.config.strategy {
            Strategy::Spin | Strategy::Yield => {
                let spin = self.config.strategy == Strategy::Spin;
                let mut polls: u32 = 0;
                loop {
                    if let Some(s) = self.receive()? {
                        return Ok(s);
                    }
                    polls = polls.wrapping_add(1);
                    if polls.is_multiple_of(POLLS_PER_CHECK) {
                        watch.tick(liveness)?;
                    }
                    if spin {
                        std::hint::spin_loop();
                    } else {
                        std::thread::yield_now();
                    }
                }
            }
            Strategy::SpinThenBlock => {
                let start = Instant::now();
                let mut polls: u32 = 0;
                loop {
                    if let Some(s) = self.receive()? {
                        return Ok(s);
                    }
                    polls = polls.wrapping_add(1);
                    if polls.is_multiple_of(POLLS_PER_BUDGET_CHECK)
                        && start.elapsed() >= self.config.spin_budget
                    {
                        break;
                    }
                    std::hint::spin_loop();
                }
                self.block_on_waitset(&mut watch, liveness)
            }
            Strategy::Waitset => self.block_on_waitset(&mut watch, liveness),
            Strategy::Listener => self.block_on_listener(&mut watch, liveness),
        }
    }

    fn receive(&self) -> Result<Option<Sample<ipc::Service, P, ()>>, HopError> {
        self.subscriber
            .receive()
            .map_err(|e| HopError::transport("receive", e))
    }

    fn block_on_waitset<F: FnMut() -> Result<(), HopError>>(
        &self,
        watch: &mut Watch,
        liveness: &mut F,
    ) -> Result<Sample<ipc::Service, P, ()>, HopError> {
        let Some(block) = &self.block else {
            return Err(HopError::Setup {
                step: "block",
                reason: "the waiter was built without a WaitSet".to_owned(),
            });
        };
        watch.arm();
        loop {
            // A notification sent after this receive stays pending on the listener, so the
            // wait below returns at once: no wake-up is lost.
            if let Some(s) = self.receive()? {
                return Ok(s);
            }
            let mut drained = Ok(0);
            // The result tells a wake-up from an interrupting signal; either way we look
            // at the subscriber again, and the watch sees a shutdown request.
            let _ = block
                .waitset
                .wait_and_process_once_with_timeout(
                    |id| {
                        if id.has_event_from(block.guard) {
                            drained = self.listener.try_wait(|_| {});
                        }
                        CallbackProgression::Continue
                    },
                    self.config.deadline,
                )
                .map_err(|e| HopError::transport("WaitSet wait", e))?;
            drained.map_err(|e| HopError::transport("drain the listener", e))?;
            watch.tick(liveness)?;
        }
    }

    fn block_on_listener<F: FnMut() -> Result<(), HopError>>(
        &self,
        watch: &mut Watch,
        liveness: &mut F,
    ) -> Result<Sample<ipc::Service, P, ()>, HopError> {
        watch.arm();
        loop {
            if let Some(s) = self.receive()? {
                return Ok(s);
            }
            // An interrupting signal shows as an error: look again, the watch sees a
            // shutdown request.
            let _ = self.listener.timed_wait(|_| {}, self.config.deadline);
            watch.tick(liveness)?;
        }
    }
}

/// The ping side of a run: waits for the pong side's [`READY_SEQ`], sends `warmup` then
/// `round_trips` pings, recording half of each measured round trip (nanoseconds) into
/// `histogram`, and ends with [`STOP_SEQ`]. `liveness` should fail when the pong process
/// is gone.
pub fn ping_loop<P: HopPayload, F: FnMut() -> Result<(), HopError>>(
    ports: &HopPorts<P>,
    config: &WaitConfig,
    warmup: u64,
    round_trips: u64,
    histogram: &mut Histogram<u64>,
    liveness: &mut F,
) -> Result<(), HopError> {
    let notify = config.strategy.notifies();
    with_waiter(config, ports, |waiter| {
        while waiter.next(liveness)?.payload().seq() != READY_SEQ {}
        for seq in 0..warmup + round_trips {
            ports.send(seq, monotonic_ns(), notify)?;
            let round_trip_ns = loop {
                let sample = waiter.next(liveness)?;
                let echo = sample.payload();
                if echo.seq() == seq {
                    break monotonic_ns().saturating_sub(echo.stamp_ns());
                }
            };
            if seq >= warmup {
                histogram.saturating_record(round_trip_ns / 2);
            }
        }
        ports.send(STOP_SEQ, monotonic_ns(), notify)
    })
}

/// The pong side of a run: announces itself with [`READY_SEQ`], then echoes every ping
/// (its sequence number and stamp) until [`STOP_SEQ`]. Returns how many pings it echoed.
/// `liveness` should fail when the ping process is gone.
pub fn pong_loop<P: HopPayload, F: FnMut() -> Result<(), HopError>>(
    ports: &HopPorts<P>,
    config: &WaitConfig,
    liveness: &mut F,
) -> Result<u64, HopError> {
    let notify = config.strategy.notifies();
    with_waiter(config, ports, |waiter| {
        ports.send(READY_SEQ, monotonic_ns(), notify)?;
        let mut echoed = 0;
        loop {
            let (seq, stamp_ns) = {
                let sample = waiter.next(liveness)?;
                (sample.payload().seq(), sample.payload().stamp_ns())
            };
            if seq == STOP_SEQ {
                return Ok(echoed);
            }
            ports.send(seq, stamp_ns, notify)?;
            echoed += 1;
        }
    })
}

/// A histogram for one-way latencies in nanoseconds, 1 ns to 60 s at 3 significant
/// digits, allocated once up front.
pub fn new_histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 60_000_000_000, 3)
        .expect("constant bounds 1 ns..60 s at 3 digits are valid")
}

/// The one-way latency figures of one run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Summary {
    pub strategy: Strategy,
    /// The spin budget, for [`Strategy::SpinThenBlock`].
    pub spin_budget: Option<Duration>,
    pub payload_bytes: usize,
    pub round_trips: u64,
    pub p50_ns: u64,
    pub p90_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub max_ns: u64,
}

impl Summary {
    pub fn from_histogram(config: &WaitConfig, payload_bytes: usize, h: &Histogram<u64>) -> Self {
        Self {
            strategy: config.strategy,
            spin_budget: (config.strategy == Strategy::SpinThenBlock).then_some(config.spin_budget),
            payload_bytes,
            round_trips: h.len(),
            p50_ns: h.value_at_quantile(0.50),
            p90_ns: h.value_at_quantile(0.90),
            p99_ns: h.value_at_quantile(0.99),
            p999_ns: h.value_at_quantile(0.999),
            max_ns: h.max(),
        }
    }

    /// `{strategy, payload_bytes, round_trips, p50_ns, p90_ns, p99_ns, p999_ns, max_ns}`,
    /// plus `spin_budget_us` for spin-then-block.
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::json!({
            "strategy": self.strategy.name(),
            "payload_bytes": self.payload_bytes,
            "round_trips": self.round_trips,
            "p50_ns": self.p50_ns,
            "p90_ns": self.p90_ns,
            "p99_ns": self.p99_ns,
            "p999_ns": self.p999_ns,
            "max_ns": self.max_ns,
        });
        if let (Some(budget), Some(map)) = (self.spin_budget, v.as_object_mut()) {
            map.insert(
                "spin_budget_us".to_owned(),
                serde_json::json!(budget.as_micros() as u64),
            );
        }
        v
    }
}

fn payload_label(bytes: usize) -> String {
    if bytes >= 1024 && bytes.is_multiple_of(1024) {
        format!("{} KiB", bytes / 1024)
    } else {
        format!("{bytes} B")
    }
}

/// The summaries as a plain-text table, latencies in microseconds.
pub fn format_table(rows: &[Summary]) -> String {
    let mut out = format!(
        "{:<24} {:>8} {:>11} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
        "strategy", "payload", "round trips", "p50 us", "p90 us", "p99 us", "p99.9 us", "max us"
    );
    for r in rows {
        let name = match r.spin_budget {
            Some(b) => format!("{} ({} us)", r.strategy.name(), b.as_micros()),
            None => r.strategy.name().to_owned(),
        };
        let us = |ns: u64| ns as f64 / 1000.0;
        out.push_str(&format!(
            "{:<24} {:>8} {:>11} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2}\n",
            name,
            payload_label(r.payload_bytes),
            r.round_trips,
            us(r.p50_ns),
            us(r.p90_ns),
            us(r.p99_ns),
            us(r.p999_ns),
            us(r.max_ns),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_strategy_parses_back_from_its_name() {
        for s in Strategy::ALL {
            assert_eq!(s.name().parse::<Strategy>(), Ok(s));
        }
        assert!("busy".parse::<Strategy>().is_err());
    }

    #[test]
    fn only_blocking_strategies_notify() {
        assert!(!Strategy::Spin.notifies());
        assert!(!Strategy::Yield.notifies());
        assert!(Strategy::Waitset.notifies());
        assert!(Strategy::SpinThenBlock.notifies());
        assert!(Strategy::Listener.notifies());
    }

    #[test]
    fn a_summary_reads_the_quantiles_of_a_uniform_histogram_within_its_precision() {
        // 1..=1000 us, one each: p50 = 500 us, p99 = 990 us, max = 1000 us, within the
        // histogram's 3 significant digits (0.1 %).
        let mut h = new_histogram();
        for us in 1..=1000u64 {
            h.record(us * 1000).expect("in bounds");
        }
        let s = Summary::from_histogram(&WaitConfig::new(Strategy::Spin), 16, &h);
        let close = |got: u64, want: u64| (got as f64 - want as f64).abs() <= want as f64 * 1e-3;
        assert_eq!(s.round_trips, 1000);
        assert!(close(s.p50_ns, 500_000), "p50 {}", s.p50_ns);
        assert!(close(s.p90_ns, 900_000), "p90 {}", s.p90_ns);
        assert!(close(s.p99_ns, 990_000), "p99 {}", s.p99_ns);
        assert!(close(s.p999_ns, 999_000), "p99.9 {}", s.p999_ns);
        assert!(close(s.max_ns, 1_000_000), "max {}", s.max_ns);
    }

    #[test]
    fn the_json_of_a_summary_holds_the_promised_fields() {
        let s = Summary::from_histogram(
            &WaitConfig::new(Strategy::SpinThenBlock),
            16,
            &new_histogram(),
        );
        let v = s.to_json();
        for key in [
            "strategy",
            "p50_ns",
            "p90_ns",
            "p99_ns",
            "p999_ns",
            "max_ns",
            "round_trips",
            "payload_bytes",
            "spin_budget_us",
        ] {
            assert!(v.get(key).is_some(), "missing {key}");
        }
        assert_eq!(v["strategy"], "spin-then-block");
    }

    #[test]
    fn a_grid_payload_written_through_its_header_reads_back() {
        let mut slot = Box::new(MaybeUninit::<HopGrid>::uninit());
        HopGrid::write_header(&mut slot, 7, 42);
        // SAFETY: write_header initialised every field that is not a MaybeUninit.
        let grid = unsafe { slot.assume_init_ref() };
        assert_eq!((grid.seq(), grid.stamp_ns()), (7, 42));
    }
}
