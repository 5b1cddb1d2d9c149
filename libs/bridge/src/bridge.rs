//! A running bridge: the topics of one side of a split pipeline, forwarded to a Zenoh
//! session and back.
//!
//! Two threads, one per direction, each with its own iceoryx2 node (iceoryx2 ports never
//! leave their thread):
//! - *out* (this instance to the far one): drains the subscribers of the topics this side
//!   publishes, in [`crate::BRIDGED_TOPICS`] order, and puts each message on the link's one
//!   key for that direction. It waits on the listeners of those topics' event services (a
//!   `ppoll` on their sockets with a deadline), never on a sleep. It keeps the latched state
//!   ([`Latch`]) and sends it when a far end says hello, before any live message.
//! - *in* (the far instance to this one): the link's messages are taken in Zenoh's receive
//!   callback, in the order they were put (one key, one publisher, reliable, congestion
//!   control `Block`: nothing is dropped or reordered; Zenoh calls one subscriber's callback
//!   for one link's messages one after the other): it checks each header, writes the bytes
//!   once into a loaned sample and notifies the topic's event service, on the thread that
//!   read them off the socket. The in thread itself only says hello, hears the far end's
//!   welcome and `bye`, and watches the far end and this instance.
//!
//! So a bridged hop wakes two threads besides Zenoh's own: the out thread at the sending
//! end (on the iceoryx2 event) and the reader at the far end (physics, the planner). With
//! `AGP_BRIDGE_TRACE` set, each end says where the hops' time went ([`crate::trace`]).
//!
//! The far end may go and come back (a link cut, its bridge restarted): the in thread watches
//! the Zenoh peers of the session. When the far peer is lost or replaced, this end says hello
//! again with a new nonce (a far bridge that restarted owes it the latched state, one that
//! only lost the link owes what it latched since), and the out thread holds what it drains
//! until the far end's next hello, as it did before the first. A far end gone longer than
//! [`BridgeConfig::far_timeout`] after it had joined ends the bridge
//! ([`BridgeEnd::FarGone`]): a planner side that stopped before it could say `bye`, or a
//! robot side that is no more, never leaves the other waiting for ever. A far end that never
//! joined is waited for as long as it takes (either side may start first).
//!
//! Epochs and tokens belong to each instance's supervisor. The planner side forwards the
//! commands and resets of its own active epoch only (and, if its supervisor handed it the
//! session key, only those carrying that epoch's token); the robot side republishes them
//! with the epoch and token its own supervisor handed it, as it would hand a planner. The
//! planner side republishes each frame with its own active epoch.

use std::os::fd::RawFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use agp_runtime::{AgpIpc, Instance, WaitStrategy, shutdown_requested};
use agp_shared_types::{GridHeader, SessionKey};
use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::FileDescriptorBased;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::qos::CongestionControl;

use crate::endpoint::Endpoint;
use crate::ports::{Auth, InPort, OutPort, Restamp, in_port, out_port};
use crate::route::{BRIDGED_TOPICS, BridgedTopic, Latch, Side};
use crate::tls::TlsKeys;
use crate::trace::{Point, Trace};
use crate::wire::{self, Header, WireDecodeError};

/// How a bridge runs.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    pub side: Side,
    pub endpoint: Endpoint,
    /// This side's keys of the link (a `tls/` endpoint: mutual TLS); `None` for a `tcp/`
    /// endpoint, plain TCP with no authentication.
    pub tls: Option<TlsKeys>,
    /// The topics carried, both ways (each goes the way [`BridgedTopic::from`] says); both
    /// ends must carry the same.
    pub topics: Vec<BridgedTopic>,
    /// The Zenoh key prefix both ends share (`agp` by default): two links on one Zenoh
    /// network keep apart by it.
    pub link: String,
    /// Robot side: the epoch and token every forwarded command and reset carries (what this
    /// instance's supervisor handed the bridge in `AGP_EPOCH` and `AGP_TOKEN`).
    pub epoch: u64,
    pub token: u64,
    /// Planner side: this instance's session key, when its supervisor handed it: commands
    /// and resets without their epoch's token are not forwarded.
    pub key: Option<SessionKey>,
    /// Prefix of the bridge's two iceoryx2 node names (`<prefix>-out`, `<prefix>-in`).
    pub node_name: String,
    /// How the out thread waits for the next message to send (`agp bridge` gives `block`
    /// unless [`crate::BRIDGE_WAIT_ENV`] or `--wait` says otherwise); the far end's messages are
    /// taken in Zenoh's receive callback, which waits for nothing.
    pub wait: WaitStrategy,
    /// How long the far end may be gone (no peer on the link) once it had joined before
    /// this end gives up ([`BridgeEnd::FarGone`]); a cut or a restart of the far bridge
    /// shorter than this is ridden out.
    pub far_timeout: Duration,
    /// Planner side, lockstep only: the last motor command sent goes again to a far end
    /// that joins again after it was lost (a cut may swallow it, and the ring then waits
    /// for ever for the frame it makes). Physics drops a command of a step that passed, so
    /// the repeat is harmless in lockstep; on the realtime clock it would drive the wheels
    /// with a stale command, and is never sent.
    pub redeliver_command: bool,
}

/// The default of [`BridgeConfig::far_timeout`]: longer than a far bridge's restart, or a
/// far supervisor's `agp up` again after it was killed, on a loaded machine.
pub const FAR_TIMEOUT: Duration = Duration::from_secs(15);

/// Why a bridge stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BridgeEnd {
    /// The far end said it stopped (its run is over).
    FarEnded,
    /// This process was asked to stop (SIGTERM, SIGINT).
    Stopped,
    /// This instance's supervisor is gone (its control service with it).
    InstanceDown,
    /// The far end joined, then was gone for this long without saying `bye` (killed, its
    /// computer or the link down): this end gives up.
    FarGone(Duration),
}

/// What a bridge did, at its end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BridgeReport {
    pub end: BridgeEnd,
    /// Per carried topic: its name, messages sent to the far end, messages received from it.
    pub topics: Vec<(&'static str, u64, u64)>,
    /// Commands and resets of another epoch than the active one, not forwarded.
    pub stale: u64,
    /// Commands and resets without their epoch's token, not forwarded.
    pub refused: u64,
    /// Times the far end was lost (or replaced by another) after it had joined.
    pub far_lost: u64,
}

/// Why a bridge failed.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("bad link name `{0}`: use letters, digits, `-` and `_`")]
    LinkName(String),
    #[error("cannot open the Zenoh session on `{endpoint}`: {detail}")]
    Session { endpoint: String, detail: String },
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("cannot create the bridge's iceoryx2 node: {0}")]
    Node(String),
    #[error("cannot open `{topic}`: {detail}")]
    Open { topic: &'static str, detail: String },
    #[error("cannot forward `{topic}`: {detail}")]
    Forward { topic: &'static str, detail: String },
    #[error(transparent)]
    Wire(#[from] WireDecodeError),
    #[error("the bridge's out thread could not start or panicked")]
    Thread,
}

/// Longest single block of the out thread, so a hello or a stop is seen within it.
const OUT_SLICE: Duration = Duration::from_millis(20);
/// Longest single wait of the in thread (and of the floor's ping end).
pub(crate) const IN_SLICE: Duration = Duration::from_millis(20);
/// How often a receiving end repeats its hello until it is welcomed.
const HELLO_EVERY: Duration = Duration::from_millis(100);
/// How long a stopping end waits for a far end to be there to hear its `bye` (under a
/// supervisor's stop grace, 3 s by default).
const BYE_WAIT: Duration = Duration::from_millis(1500);
/// How often the in thread looks at the session's peers (is the far end still there?).
const PEER_CHECK_EVERY: Duration = Duration::from_millis(20);
/// How often the in thread looks whether this instance's supervisor still runs.
const INSTANCE_CHECK_EVERY: Duration = Duration::from_millis(250);
/// How often the in thread's publishers hand their history to new subscribers (physics and
/// the estimator do it as often while they wait).
const UPDATE_CONNECTIONS_EVERY: Duration = Duration::from_millis(20);
/// Unlatched messages (commands, resets, events) this side sent before the far end joined,
/// kept for it: a planner that has its grids and first frame may command step 1 before the
/// far end's hello has come back, and in lockstep a lost command stops the run. Past this
/// many the oldest go (a far end that never joins is not owed a backlog).
const PENDING_MAX: usize = 4096;

struct Shared {
    stop: AtomicBool,
    /// Planner side: its supervisor's active epoch, read by the out thread.
    active_epoch: AtomicU64,
    sent: [AtomicU64; BRIDGED_TOPICS.len()],
    received: [AtomicU64; BRIDGED_TOPICS.len()],
    stale: AtomicU64,
    refused: AtomicU64,
    /// Bumped by the in thread each time the far end is lost or replaced: the out thread
    /// then holds what it drains until the next hello.
    far_lost: AtomicU64,
    /// The far end said `bye` or is gone for good: nobody is there to hear this end's.
    far_over: AtomicBool,
}

fn slot(topic: &BridgedTopic) -> usize {
    BRIDGED_TOPICS
        .iter()
        .position(|n| *n == topic.name)
        .unwrap_or(0)
}

fn direction_key(link: &str, to: Side) -> String {
    format!("{link}/to_{}", to.name())
}

fn hello_key(link: &str, to: Side) -> String {
    format!("{link}/hello/to_{}", to.name())
}

fn zenoh_err(e: impl std::fmt::Display) -> BridgeError {
    BridgeError::Zenoh(e.to_string())
}

/// Runs a bridge on `instance` until the far end ends or this process is asked to stop
/// (`agp_runtime::shutdown_requested`); `on_ready` is called once every port of both
/// directions is open. Connecting waits for the far end as long as it takes.
pub fn run_bridge(
    instance: &Instance,
    config: &BridgeConfig,
    on_ready: impl FnOnce(),
) -> Result<BridgeReport, BridgeError> {
    if config.link.is_empty()
        || !config
            .link
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(BridgeError::LinkName(config.link.clone()));
    }
    let zconfig = config
        .endpoint
        .zenoh_config(config.tls.as_ref())
        .map_err(|detail| BridgeError::Session {
            endpoint: config.endpoint.locator().to_owned(),
            detail,
        })?;
    let session = zenoh::open(zconfig)
        .wait()
        .map_err(|e| BridgeError::Session {
            endpoint: config.endpoint.locator().to_owned(),
            detail: e.to_string(),
        })?;
    let shared = Arc::new(Shared {
        stop: AtomicBool::new(false),
        active_epoch: AtomicU64::new(0),
        sent: Default::default(),
        received: Default::default(),
        stale: AtomicU64::new(0),
        refused: AtomicU64::new(0),
        far_lost: AtomicU64::new(0),
        far_over: AtomicBool::new(false),
    });
    let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<(), BridgeError>>(1);
    let out = {
        let instance = instance.clone();
        let config = config.clone();
        let session = session.clone();
        let shared = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("agp-bridge-out".into())
            .spawn(move || {
                let r = out_loop(&instance, &config, &session, &shared, &ready_tx);
                shared.stop.store(true, Ordering::SeqCst);
                r
            })
            .map_err(|_| BridgeError::Thread)?
    };
    let end = match ready_rx.recv() {
        Ok(Ok(())) => in_loop(instance, config, &session, &shared, on_ready),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(BridgeError::Thread),
    };
    shared.stop.store(true, Ordering::SeqCst);
    let out = out.join().map_err(|_| BridgeError::Thread);
    let _ = session.close().wait();
    let end = end?;
    out??;
    Ok(BridgeReport {
        end,
        topics: config
            .topics
            .iter()
            .map(|t| {
                let i = slot(t);
                (
                    t.name,
                    shared.sent[i].load(Ordering::Relaxed),
                    shared.received[i].load(Ordering::Relaxed),
                )
            })
            .collect(),
        stale: shared.stale.load(Ordering::Relaxed),
        refused: shared.refused.load(Ordering::Relaxed),
        far_lost: shared.far_lost.load(Ordering::Relaxed),
    })
}

/// What the out thread keeps of one topic for a far end that joins late.
enum Cache {
    None,
    Latest(Option<Vec<u8>>),
    GridSet { seq: u64, grids: Vec<Vec<u8>> },
}

impl Cache {
    fn of(latch: Latch) -> Self {
        match latch {
            Latch::None => Self::None,
            Latch::Latest => Self::Latest(None),
            Latch::GridSet => Self::GridSet {
                seq: 0,
                grids: Vec::new(),
            },
        }
    }

    fn keep(&mut self, bytes: &[u8]) {
        match self {
            Self::None => {}
            Self::Latest(slot) => {
                let v = slot.get_or_insert_with(|| Vec::with_capacity(bytes.len()));
                v.clear();
                v.extend_from_slice(bytes);
            }
            Self::GridSet { seq, grids } => {
                let header: Option<GridHeader> = bytes
                    .get(..size_of::<GridHeader>())
                    .and_then(agp_recording::payload_from_bytes);
                let s = header.map_or(0, |h| h.seq);
                if s != *seq {
                    *seq = s;
                    grids.clear();
                }
                grids.push(bytes.to_vec());
            }
        }
    }

    fn each(&self, mut f: impl FnMut(&[u8]) -> Result<(), BridgeError>) -> Result<(), BridgeError> {
        match self {
            Self::None | Self::Latest(None) => Ok(()),
            Self::Latest(Some(v)) => f(v),
            Self::GridSet { grids, .. } => grids.iter().try_for_each(|g| f(g)),
        }
    }
}

/// One topic this side sends.
struct Outgoing {
    topic: BridgedTopic,
    slot: usize,
    port: Box<dyn OutPort>,
    cache: Cache,
    header: ZBytes,
    /// The last message sent, kept when it goes again to a far end that joins again
    /// ([`BridgeConfig::redeliver_command`]).
    last: Option<Vec<u8>>,
    /// Motor commands on the realtime clock: those drained while a far end that had joined
    /// is away are stale by the time it is back, and are dropped, not held for it.
    stale_when_held: bool,
}

fn out_loop(
    instance: &Instance,
    config: &BridgeConfig,
    session: &zenoh::Session,
    shared: &Shared,
    ready: &std::sync::mpsc::SyncSender<Result<(), BridgeError>>,
) -> Result<(), BridgeError> {
    let opened = open_out(instance, config, session);
    let (node, mut outgoing, listeners, epochs, publisher, hellos) = match opened {
        Ok(o) => {
            let _ = ready.send(Ok(()));
            o
        }
        Err(e) => {
            let _ = ready.send(Err(BridgeError::Thread));
            return Err(e);
        }
    };
    let _node = node;
    let fds: Vec<RawFd> = listeners
        .iter()
        // SAFETY: the descriptors are only polled while their listeners live (this thread
        // owns both), never closed or handed out.
        .map(|l| unsafe { l.file_descriptor().native_handle() })
        .collect();
    let put = |bytes: &[u8], header: &ZBytes| -> Result<(), BridgeError> {
        publisher
            .put(bytes.to_vec())
            .attachment(header.clone())
            .wait()
            .map_err(zenoh_err)
    };
    let mut state = OutState {
        served: None,
        live: false,
        joined_once: false,
        pending: std::collections::VecDeque::new(),
        active: shared.active_epoch.load(Ordering::Relaxed),
    };
    let mut far_lost_seen = 0;
    let mut last_activity = Instant::now();
    let mut trace = Trace::from_env();
    loop {
        if shared.stop.load(Ordering::SeqCst) || shutdown_requested() {
            trace.report(&format!("{} side, sending", config.side.name()));
            if shared.far_over.load(Ordering::SeqCst) {
                return Ok(());
            }
            // Said whether or not a far end was welcomed: one that joined a moment ago, whose
            // hello this thread had not answered yet, must not wait for this end (it would
            // only notice after its far timeout). A far end that is connecting (this end
            // stopped a moment after it started) gets a moment to be there to hear it.
            let deadline = Instant::now() + BYE_WAIT;
            while !publisher
                .matching_status()
                .wait()
                .is_ok_and(|m| m.matching())
                && Instant::now() < deadline
            {
                std::thread::sleep(Duration::from_millis(10));
            }
            let _ = publisher
                .put(Vec::<u8>::new())
                .attachment(ZBytes::from(Header::Bye.encode()))
                .wait();
            return Ok(());
        }
        let lost = shared.far_lost.load(Ordering::SeqCst);
        if lost != far_lost_seen {
            // The far end is gone (or another took its place): what is drained from now on
            // waits for its next hello, as before the first.
            far_lost_seen = lost;
            state.live = false;
            state.served = None;
        }
        greet_far_ends(&hellos, &outgoing, &mut state, shared, &put)?;
        if let Some(epochs) = &epochs {
            take_active_epoch(epochs, &mut state.active, shared);
        }
        let moved = forward_outgoing(
            &mut outgoing,
            &mut state,
            &epochs,
            config,
            shared,
            &put,
            &mut trace,
        )?;
        if moved > 0 {
            last_activity = Instant::now();
            continue;
        }
        wait_for_any(&listeners, &fds, config.wait, last_activity.elapsed());
    }
}

/// What the sending loop keeps from one round to the next.
struct OutState {
    /// The nonce of the far end's hello last answered.
    served: Option<u64>,
    /// A far end joined: messages go out as they are drained.
    live: bool,
    /// A far end joined once (it may be away now).
    joined_once: bool,
    /// (outgoing index, bytes) of unlatched messages drained before the far end joined.
    pending: std::collections::VecDeque<(usize, Vec<u8>)>,
    /// The epoch the supervisor made active, as last read.
    active: u64,
}

/// Sends one message's bytes with its header over Zenoh.
type Put<'a> = dyn Fn(&[u8], &ZBytes) -> Result<(), BridgeError> + 'a;

/// The supervisor's active epochs, on the planner side.
type EpochSubscriber =
    iceoryx2::port::subscriber::Subscriber<AgpIpc, agp_shared_types::ActiveEpoch, ()>;

/// Reads the newest active epoch into `active`, and shares it.
fn take_active_epoch(epochs: &EpochSubscriber, active: &mut u64, shared: &Shared) {
    while let Ok(Some(e)) = epochs.receive() {
        *active = e.epoch;
    }
    shared.active_epoch.store(*active, Ordering::Relaxed);
}

/// Answers each far end that just joined (a hello with a nonce not answered yet): the
/// latched state first, then what was drained before it joined, in that order, then a
/// welcome naming its nonce. From then on messages go out live.
fn greet_far_ends(
    hellos: &HelloSubscriber,
    outgoing: &[Outgoing],
    state: &mut OutState,
    shared: &Shared,
    put: &Put<'_>,
) -> Result<(), BridgeError> {
    while let Ok(Some(hello)) = hellos.try_recv() {
        let nonce = match hello.attachment().map(|a| a.to_bytes()) {
            Some(text) => match wire::decode(&text)? {
                Header::Hello { nonce } => nonce,
                _ => continue,
            },
            None => continue,
        };
        if state.served == Some(nonce) {
            continue;
        }
        for o in outgoing {
            o.cache.each(|bytes| {
                put(bytes, &o.header)?;
                shared.sent[o.slot].fetch_add(1, Ordering::Relaxed);
                Ok(())
            })?;
        }
        // A far end that joins again gets the last command sent again, unless a newer one
        // waits in `pending` (it may not have arrived before the link went).
        for (i, o) in outgoing.iter().enumerate() {
            if let Some(last) = o.last.as_ref().filter(|l| !l.is_empty())
                && !state.pending.iter().any(|(j, _)| *j == i)
            {
                put(last, &o.header)?;
                shared.sent[o.slot].fetch_add(1, Ordering::Relaxed);
            }
        }
        // Then what was sent before it joined, in the order it was drained.
        for (i, bytes) in state.pending.drain(..) {
            let o = &outgoing[i];
            put(&bytes, &o.header)?;
            shared.sent[o.slot].fetch_add(1, Ordering::Relaxed);
        }
        put(&[], &ZBytes::from(Header::Welcome { nonce }.encode()))?;
        state.served = Some(nonce);
        state.live = true;
        state.joined_once = true;
    }
    Ok(())
}

/// Drains every outgoing port once. Each message is kept in its topic's cache, then sent
/// when a far end is live, or else held in `pending` (unless its topic is latched: the
/// cache holds it). On the planner side a message of an epoch that is not the active one,
/// or whose token the link's key refuses, is dropped and counted. Returns how many
/// messages the ports gave.
fn forward_outgoing(
    outgoing: &mut [Outgoing],
    state: &mut OutState,
    epochs: &Option<EpochSubscriber>,
    config: &BridgeConfig,
    shared: &Shared,
    put: &Put<'_>,
    trace: &mut Trace,
) -> Result<usize, BridgeError> {
    let (side, key) = (config.side, config.key);
    let OutState {
        live,
        joined_once,
        pending,
        active,
        ..
    } = state;
    let mut moved = 0;
    for (index, o) in outgoing.iter_mut().enumerate() {
        let mut failed = None;
        let topic = o.topic;
        let latched = topic.latch != Latch::None;
        let cache = &mut o.cache;
        let header = &o.header;
        let slot = o.slot;
        let last = &mut o.last;
        let dropped_when_held = o.stale_when_held && *joined_once;
        let drained = o.port.drain(&mut |bytes, auth| {
            if failed.is_some() {
                return;
            }
            if let (Side::Planner, Some(Auth { epoch, token })) = (side, auth) {
                if epoch > *active {
                    // The supervisor made a newer epoch active before its planner sent.
                    if let Some(epochs) = epochs {
                        take_active_epoch(epochs, active, shared);
                    }
                }
                if epoch != *active {
                    shared.stale.fetch_add(1, Ordering::Relaxed);
                    return;
                }
                if key.is_some_and(|k| k.token(epoch) != token) {
                    shared.refused.fetch_add(1, Ordering::Relaxed);
                    return;
                }
            }
            cache.keep(bytes);
            if let Some(l) = last.as_mut() {
                l.clear();
                l.extend_from_slice(bytes);
            }
            if *live {
                trace.mark(topic.service, bytes, Point::Woke);
                match put(bytes, header) {
                    Ok(()) => {
                        trace.mark(topic.service, bytes, Point::Put);
                        shared.sent[slot].fetch_add(1, Ordering::Relaxed);
                    }
                    Err(e) => failed = Some(e),
                }
            } else if !latched && !dropped_when_held {
                if pending.len() >= PENDING_MAX {
                    pending.pop_front();
                }
                pending.push_back((index, bytes.to_vec()));
            }
        });
        match drained {
            Ok(n) => moved += n,
            Err(detail) => {
                return Err(BridgeError::Forward {
                    topic: topic.name,
                    detail,
                });
            }
        }
        if let Some(e) = failed {
            return Err(e);
        }
    }
    Ok(moved)
}

/// The far ends' hellos.
type HelloSubscriber =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

type OutPorts = (
    iceoryx2::prelude::Node<AgpIpc>,
    Vec<Outgoing>,
    Vec<Listener<AgpIpc>>,
    Option<EpochSubscriber>,
    zenoh::pubsub::Publisher<'static>,
    HelloSubscriber,
);

fn open_out(
    instance: &Instance,
    config: &BridgeConfig,
    session: &zenoh::Session,
) -> Result<OutPorts, BridgeError> {
    let node = instance
        .node(&format!("{}-out", config.node_name), false)
        .map_err(|e| BridgeError::Node(format!("{e:?}")))?;
    let mut outgoing = Vec::new();
    let mut listeners = Vec::new();
    for topic in config.topics.iter().filter(|t| t.from == config.side) {
        let (port, listener) =
            out_port(instance, &node, topic).map_err(|detail| BridgeError::Open {
                topic: topic.name,
                detail,
            })?;
        listeners.push(listener);
        outgoing.push(Outgoing {
            topic: *topic,
            slot: slot(topic),
            port,
            cache: Cache::of(topic.latch),
            last: (config.redeliver_command
                && config.side == Side::Planner
                && topic.service == agp_shared_types::ServiceNames::MOTOR_COMMANDS)
                .then(Vec::new),
            stale_when_held: !config.redeliver_command
                && config.side == Side::Planner
                && topic.service == agp_shared_types::ServiceNames::MOTOR_COMMANDS,
            header: ZBytes::from(
                Header::Data {
                    service: topic.service,
                    type_name: topic.type_name,
                }
                .encode(),
            ),
        });
    }
    // The planner side forwards the commands of its supervisor's active epoch only.
    let epochs = match config.side {
        Side::Robot => None,
        Side::Planner => {
            let t = instance
                .active_epoch(&node)
                .map_err(|e| BridgeError::Open {
                    topic: "active_epoch",
                    detail: e.to_string(),
                })?;
            Some(t.subscriber().create().map_err(|e| BridgeError::Open {
                topic: "active_epoch",
                detail: format!("{e:?}"),
            })?)
        }
    };
    let to = config.side.far();
    let publisher = session
        .declare_publisher(direction_key(&config.link, to))
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(zenoh_err)?;
    let hellos = session
        .declare_subscriber(hello_key(&config.link, to))
        .wait()
        .map_err(zenoh_err)?;
    Ok((node, outgoing, listeners, epochs, publisher, hellos))
}

/// Waits for a notification on any listener, as `strategy` says: polling with yields for
/// its spin (counted from the last message), then blocking in `ppoll` on the listeners'
/// sockets for at most [`OUT_SLICE`]. A notification found pending returns at once.
///
/// Only the listeners `ppoll` found readable are read (one `recv` each, and one that says
/// there is no more): a wake-up costs the poll and those, not two reads of every listener
/// (the sending end of each bridged hop passes here once).
fn wait_for_any(
    listeners: &[Listener<AgpIpc>],
    fds: &[RawFd],
    strategy: WaitStrategy,
    idle: Duration,
) {
    let block = match strategy {
        WaitStrategy::Spin => {
            core::hint::spin_loop();
            false
        }
        WaitStrategy::Yield => {
            std::thread::yield_now();
            false
        }
        WaitStrategy::SpinThenBlock { spin } if idle < spin => {
            std::thread::yield_now();
            false
        }
        WaitStrategy::Block | WaitStrategy::SpinThenBlock { .. } => true,
    };
    if !block {
        return;
    }
    let mut polled: [libc::pollfd; BRIDGED_TOPICS.len()] = [libc::pollfd {
        fd: -1,
        events: libc::POLLIN,
        revents: 0,
    }; BRIDGED_TOPICS.len()];
    for (p, fd) in polled.iter_mut().zip(fds) {
        p.fd = *fd;
    }
    let timeout = libc::timespec {
        tv_sec: 0,
        tv_nsec: OUT_SLICE.subsec_nanos() as libc::c_long,
    };
    // SAFETY: the listeners' sockets stay open while they live, and they outlive this call;
    // `ppoll` only reads the pollfds and the timespec we own and keeps the signal mask.
    // Unused entries have fd -1, which ppoll ignores.
    let woken = unsafe {
        libc::ppoll(
            polled.as_mut_ptr(),
            polled.len() as libc::nfds_t,
            &timeout,
            std::ptr::null(),
        )
    };
    if woken > 0 {
        for (l, p) in listeners.iter().zip(&polled) {
            if p.revents != 0 {
                let _ = l.try_wait(|_| {});
            }
        }
    }
}

/// This end's hello to the far end: said every [`HELLO_EVERY`] until a welcome names its
/// nonce, and again under a new nonce when the far end was lost or replaced.
struct Greeting {
    nonce: u64,
    hello: ZBytes,
    welcomed: bool,
    last: Option<Instant>,
}

impl Greeting {
    fn new() -> Self {
        let nonce = agp_shared_types::monotonic_ns() ^ (u64::from(std::process::id()) << 40);
        Self {
            nonce,
            hello: ZBytes::from(Header::Hello { nonce }.encode()),
            welcomed: false,
            last: None,
        }
    }

    /// Says hello when it is due.
    fn say(&mut self, publisher: &zenoh::pubsub::Publisher<'_>) -> Result<(), BridgeError> {
        if !self.welcomed && self.last.is_none_or(|t| t.elapsed() >= HELLO_EVERY) {
            publisher
                .put(Vec::<u8>::new())
                .attachment(self.hello.clone())
                .wait()
                .map_err(zenoh_err)?;
            self.last = Some(Instant::now());
        }
        Ok(())
    }
}

/// Looks at the session's peers: a far end lost or replaced is counted (the out thread
/// then holds what it drains) and will be greeted again, under a new nonce; one gone for
/// the far timeout ends the bridge.
fn watch_far(
    session: &zenoh::Session,
    far: &mut FarPeer,
    greeting: &mut Greeting,
    shared: &Shared,
    config: &BridgeConfig,
) -> Option<BridgeEnd> {
    let peers: Vec<zenoh::session::ZenohId> = session.info().peers_zid().wait().collect();
    match far.look(&peers) {
        FarChange::None => {}
        FarChange::Lost | FarChange::Replaced => {
            shared.far_lost.fetch_add(1, Ordering::SeqCst);
            *greeting = Greeting::new();
        }
    }
    let gone = far.gone_for()?;
    (gone >= config.far_timeout).then(|| {
        shared.far_over.store(true, Ordering::SeqCst);
        BridgeEnd::FarGone(gone)
    })
}

/// The far end as the session's peers show it.
#[derive(Debug, Default)]
struct FarPeer {
    /// The far end's Zenoh id while it is there.
    id: Option<zenoh::session::ZenohId>,
    /// A far end joined once.
    joined: bool,
    /// Since when no far end is there, once one had joined.
    gone_since: Option<Instant>,
}

/// What became of the far end since the last look.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FarChange {
    None,
    /// No peer any more.
    Lost,
    /// Another peer in its place (it restarted between two looks).
    Replaced,
}

impl FarPeer {
    fn look(&mut self, peers: &[zenoh::session::ZenohId]) -> FarChange {
        match (self.id, peers.first()) {
            (Some(id), _) if peers.contains(&id) => FarChange::None,
            (Some(_), Some(p)) => {
                self.id = Some(*p);
                FarChange::Replaced
            }
            (Some(_), None) => {
                self.id = None;
                self.gone_since = Some(Instant::now());
                FarChange::Lost
            }
            (None, Some(p)) => {
                self.id = Some(*p);
                self.joined = true;
                self.gone_since = None;
                FarChange::None
            }
            (None, None) => FarChange::None,
        }
    }

    /// How long the far end has been gone, once it had joined.
    fn gone_for(&self) -> Option<Duration> {
        self.gone_since
            .filter(|_| self.joined && self.id.is_none())
            .map(|t| t.elapsed())
    }
}

/// What the in side's Zenoh callback hands the in thread: the far end's replies to this
/// end's hello, and its `bye`. Its data never goes through the thread.
enum Control {
    Welcome(u64),
    Bye,
}

/// The in side's iceoryx2 ports (a publisher and a notifier per topic the far end sends),
/// with the node they were opened on and the trace of what they republished.
struct Receiving {
    /// Declared before the node: dropped first.
    incoming: Vec<(usize, Box<dyn InPort>)>,
    trace: Trace,
    _node: iceoryx2::prelude::Node<AgpIpc>,
}

// SAFETY: `Receiving` is not `Send` only because the iceoryx2 ports and node of `AgpIpc`
// share their state through `PooledRc` (a non-atomic reference count, like `Rc`). Every
// clone of those counts is held inside this one value: its ports were opened on its own
// node, and nothing else of the bridge holds any of them (the out thread has its own node;
// the `Instance` holds only configuration). A `Receiving` is only ever reached through the
// `Mutex` of [`Republisher::ports`], so no two threads touch any of those counts, or the
// ports, at once, and the mutex orders each thread's use after the previous one's: the
// counts are never raced. `PooledRc` takes and gives its blocks from the calling thread's
// pool; a block given back on another thread than the one it came from joins that
// thread's pool, which is ordinary heap memory either way. iceoryx2's thread-safe service
// type does the same behind a mutex of its own.
unsafe impl Send for Receiving {}

/// The far end's messages, republished in this instance from Zenoh's receive callback: the
/// thread that read them off the link writes them into shared memory and wakes their
/// readers, with no hand-off to another thread on the way (one wake-up less per hop).
struct Republisher {
    /// `None` once the in thread took them back to close them.
    ports: std::sync::Mutex<Option<Receiving>>,
    carried: Vec<BridgedTopic>,
    /// For each carried topic, its index in `Receiving::incoming` (`None`: this side sends it).
    index_of: Vec<Option<usize>>,
    side: Side,
    /// Robot side: the epoch and token every command and reset is republished with.
    robot_stamp: Restamp,
    shared: Arc<Shared>,
    control: std::sync::mpsc::Sender<Control>,
    /// The first error the callback met; the bridge ends with it.
    failed: std::sync::Mutex<Option<BridgeError>>,
}

impl Republisher {
    /// Zenoh's receive callback: republishes one message of the far end, or hands a control
    /// message to the in thread. An error stops the bridge (it is kept for the in thread).
    fn take(&self, sample: &zenoh::sample::Sample) {
        if self.shared.stop.load(Ordering::Relaxed) {
            return;
        }
        if let Err(e) = self.republish(sample) {
            let mut failed = self.failed.lock().unwrap_or_else(|p| p.into_inner());
            failed.get_or_insert(e);
            self.shared.stop.store(true, Ordering::SeqCst);
        }
    }

    fn republish(&self, sample: &zenoh::sample::Sample) -> Result<(), BridgeError> {
        let text = sample
            .attachment()
            .map(|a| a.to_bytes())
            .unwrap_or_default();
        match wire::decode(&text)? {
            Header::Data { service, type_name } => {
                let payload = sample.payload().to_bytes();
                let at =
                    wire::check_data(&self.carried, self.side, service, type_name, payload.len())?;
                let Some(i) = self.index_of[at] else {
                    return Ok(());
                };
                let restamp = match self.side {
                    Side::Robot => self.robot_stamp,
                    Side::Planner => Restamp {
                        epoch: self.shared.active_epoch.load(Ordering::Relaxed),
                        token: 0,
                    },
                };
                let mut ports = self.ports.lock().unwrap_or_else(|p| p.into_inner());
                let Some(r) = ports.as_mut() else {
                    return Ok(());
                };
                r.trace.mark(service, &payload, Point::Arrived);
                let (s, port) = &mut r.incoming[i];
                port.publish(&payload, restamp)
                    .map_err(|detail| BridgeError::Forward {
                        topic: self.carried[at].name,
                        detail,
                    })?;
                self.shared.received[*s].fetch_add(1, Ordering::Relaxed);
                r.trace.mark(service, &payload, Point::Republished);
            }
            Header::Welcome { nonce } => {
                let _ = self.control.send(Control::Welcome(nonce));
            }
            Header::Bye => {
                let _ = self.control.send(Control::Bye);
            }
            Header::Hello { .. } => {}
        }
        Ok(())
    }

    /// Hands the latched topics' history to readers that came since.
    fn update_connections(&self, latched: &[bool; BRIDGED_TOPICS.len()]) {
        let ports = self.ports.lock().unwrap_or_else(|p| p.into_inner());
        for (s, port) in ports.iter().flat_map(|r| &r.incoming) {
            if latched[*s] {
                port.update_connections();
            }
        }
    }
}

/// The in side: opens this end's publishers of what the far end sends and hands them to
/// Zenoh's receive callback ([`Republisher`]); this thread says hello, watches the far end
/// and this instance, and ends the bridge. At its end the callback is undeclared and the
/// ports are closed here, on the thread that opened them.
fn in_loop(
    instance: &Instance,
    config: &BridgeConfig,
    session: &zenoh::Session,
    shared: &Arc<Shared>,
    on_ready: impl FnOnce(),
) -> Result<BridgeEnd, BridgeError> {
    let node = instance
        .node(&format!("{}-in", config.node_name), false)
        .map_err(|e| BridgeError::Node(format!("{e:?}")))?;
    let mut incoming: Vec<(usize, Box<dyn InPort>)> = Vec::new();
    let mut carried = Vec::new();
    for topic in &config.topics {
        if topic.from != config.side {
            let port = in_port(instance, &node, topic).map_err(|detail| BridgeError::Open {
                topic: topic.name,
                detail,
            })?;
            incoming.push((slot(topic), port));
        }
        carried.push(*topic);
    }
    let mut latched = [false; BRIDGED_TOPICS.len()];
    for t in &carried {
        latched[slot(t)] = t.latch != Latch::None;
    }
    let index_of: Vec<Option<usize>> = carried
        .iter()
        .map(|t| incoming.iter().position(|(s, _)| *s == slot(t)))
        .collect();
    let (control, controls) = std::sync::mpsc::channel();
    let republisher = Arc::new(Republisher {
        ports: std::sync::Mutex::new(Some(Receiving {
            incoming,
            trace: Trace::from_env(),
            _node: node,
        })),
        carried,
        index_of,
        side: config.side,
        robot_stamp: Restamp {
            epoch: config.epoch,
            token: config.token,
        },
        shared: Arc::clone(shared),
        control,
        failed: std::sync::Mutex::new(None),
    });
    let subscriber = {
        let r = Arc::clone(&republisher);
        session
            .declare_subscriber(direction_key(&config.link, config.side))
            .callback(move |sample| r.take(&sample))
            .wait()
            .map_err(zenoh_err)?
    };
    let end = watch_link(
        instance,
        config,
        session,
        shared,
        &republisher,
        &controls,
        &latched,
        on_ready,
    );
    // No callback runs after the undeclaration; one under way holds the ports' lock, so
    // taking them waits for it.
    let _ = subscriber.undeclare().wait();
    let receiving = republisher
        .ports
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take();
    if let Some(mut r) = receiving {
        r.trace
            .report(&format!("{} side, receiving", config.side.name()));
    }
    let failed = republisher
        .failed
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take();
    match failed {
        Some(e) => Err(e),
        None => end,
    }
}

/// The in thread's loop: hellos until welcomed, the far end's comings and goings, this
/// instance's supervisor, the latched topics' late readers; ends on the far end's `bye`,
/// a stop, or the far end gone too long.
#[allow(clippy::too_many_arguments)]
fn watch_link(
    instance: &Instance,
    config: &BridgeConfig,
    session: &zenoh::Session,
    shared: &Shared,
    republisher: &Republisher,
    controls: &std::sync::mpsc::Receiver<Control>,
    latched: &[bool; BRIDGED_TOPICS.len()],
    on_ready: impl FnOnce(),
) -> Result<BridgeEnd, BridgeError> {
    let hello_pub = session
        .declare_publisher(hello_key(&config.link, config.side))
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(zenoh_err)?;
    on_ready();
    let mut greeting = Greeting::new();
    let mut last_check = Instant::now();
    let mut last_update = Instant::now();
    let mut far = FarPeer::default();
    let mut last_peers = Instant::now();
    loop {
        if shared.stop.load(Ordering::SeqCst) || shutdown_requested() {
            return Ok(BridgeEnd::Stopped);
        }
        if last_check.elapsed() >= INSTANCE_CHECK_EVERY {
            if !instance.control_exists() {
                return Ok(BridgeEnd::InstanceDown);
            }
            last_check = Instant::now();
        }
        if last_peers.elapsed() >= PEER_CHECK_EVERY {
            last_peers = Instant::now();
            if let Some(end) = watch_far(session, &mut far, &mut greeting, shared, config) {
                return Ok(end);
            }
        }
        greeting.say(&hello_pub)?;
        if last_update.elapsed() >= UPDATE_CONNECTIONS_EVERY {
            republisher.update_connections(latched);
            last_update = Instant::now();
        }
        match controls.recv_timeout(IN_SLICE) {
            Ok(Control::Welcome(n)) if n == greeting.nonce => greeting.welcomed = true,
            Ok(Control::Welcome(_)) | Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Ok(Control::Bye) => {
                shared.far_over.store(true, Ordering::SeqCst);
                return Ok(BridgeEnd::FarEnded);
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(BridgeError::Zenoh(
                    "the link's receive callback is gone".to_owned(),
                ));
            }
        }
    }
}
