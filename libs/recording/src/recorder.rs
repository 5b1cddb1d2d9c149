//! The recorder: a subscriber of its own on every topic of an instance, drained on one
//! thread, written to MCAP on another.
//!
//! The ring never waits for it. Its subscribers take the deepest buffer each service allows
//! (`agp_runtime::TAP_DEPTH` messages on the streams and commands; iceoryx2's safe overflow: when the recorder falls behind, the publisher overwrites the
//! recorder's oldest sample, never blocks); the draining thread copies each sample into a
//! preallocated batch and hands full batches to the writing thread through a bounded queue
//! of [`RecorderOptions::batches`] batches. When the disk is slower than the pipeline and
//! every batch is queued, messages are dropped and counted per topic
//! ([`TopicStats::dropped`]); samples overwritten in iceoryx2's buffer before the drain
//! reached them show as gaps in the topics that count every message (frames by step, the
//! learning events and reports and the active epoch by sequence number:
//! [`TopicStats::lost`]).

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use agp_runtime::{AgpIpc, Instance, OpenError, Topic};
use agp_shared_types::{
    ActiveEpoch, Goal, GoalEnd, GradientGrid, IrFrame, LearnEvent, LearnReport, MotorCommand,
    ObjectEstimate, Reset, Task, monotonic_ns, stage,
};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{Node, ZeroCopySend};

use crate::tap::Tap;
use crate::topics::{TOPIC_COUNT, TopicSpec, bytes_of, recorded_topics};
use crate::{MESSAGE_ENCODING, RECORDING_METADATA, RUN_METADATA, SCHEMA_ENCODING};

/// Why recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("cannot create {}: {source}", path.display())]
    Create {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write the MCAP file: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("cannot subscribe to `{topic}`: {detail}")]
    Subscribe { topic: &'static str, detail: String },
    #[error("cannot create the recorder's iceoryx2 node: {0}")]
    Node(String),
    #[error("iceoryx2: cannot receive from `{topic}`: {detail}")]
    Receive { topic: &'static str, detail: String },
    #[error("the recorder's {0} thread could not start or panicked")]
    Thread(&'static str),
}

/// How the recorder runs.
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    /// The recorder's iceoryx2 node name.
    pub node_name: String,
    /// Bytes of one batch (messages are copied into batches on the draining thread).
    pub batch_bytes: usize,
    /// Batches in all: what may wait for the disk is `batches * batch_bytes`.
    pub batches: usize,
    /// The draining thread's sleep after a pass that found nothing (it listens to no
    /// event of the ring: its buffers of `agp_runtime::TAP_DEPTH` cover the sleep).
    pub idle_poll: Duration,
    /// A batch holding anything goes to the writer at least this often.
    pub flush_every: Duration,
    /// lz4-compress the MCAP chunks.
    pub compress: bool,
    /// What replay needs and a reader wants to know of the run (stored as the MCAP metadata
    /// record [`RUN_METADATA`]): see [`crate::RunInfo`].
    pub run: BTreeMap<String, String>,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            node_name: "agp-recorder".to_owned(),
            batch_bytes: 1 << 20,
            batches: 64,
            idle_poll: Duration::from_millis(2),
            flush_every: Duration::from_millis(20),
            compress: true,
            run: BTreeMap::new(),
        }
    }
}

/// What was recorded of one topic.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TopicStats {
    pub topic: &'static str,
    pub type_name: &'static str,
    /// Messages taken from iceoryx2.
    pub received: u64,
    /// Messages written to the file.
    pub written: u64,
    /// Messages received but dropped because every batch waited for the disk.
    pub dropped: u64,
    /// Messages the recorder never saw, from gaps in the counter the topic carries (frames:
    /// step; learning events, reports, active epoch: sequence number); 0 for the others.
    pub lost: u64,
}

/// What a recording holds, at its end.
#[derive(Debug, Clone, Default)]
pub struct RecordStats {
    pub path: PathBuf,
    pub topics: Vec<TopicStats>,
    /// Wall time from the first subscription to the end.
    pub duration: Duration,
    /// Size of the file, bytes.
    pub file_bytes: u64,
}

impl RecordStats {
    pub fn dropped(&self) -> u64 {
        self.topics.iter().map(|t| t.dropped).sum()
    }
    pub fn lost(&self) -> u64 {
        self.topics.iter().map(|t| t.lost).sum()
    }
    pub fn written(&self) -> u64 {
        self.topics.iter().map(|t| t.written).sum()
    }
}

#[derive(Default)]
struct Counters {
    received: [AtomicU64; TOPIC_COUNT],
    written: [AtomicU64; TOPIC_COUNT],
    dropped: [AtomicU64; TOPIC_COUNT],
    lost: [AtomicU64; TOPIC_COUNT],
}

/// A running recording; [`Recorder::finish`] ends it and completes the file.
pub struct Recorder {
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    drain: Option<JoinHandle<Result<(), RecordError>>>,
    writer: Option<JoinHandle<Result<u64, RecordError>>>,
    path: PathBuf,
    start: Instant,
}

/// Bytes before each message in a batch: topic (u16), padding (u16), length (u32),
/// log time (u64), publish time (u64).
const RECORD_HEADER: usize = 24;

impl Recorder {
    /// Starts recording every topic of `instance` into a new file at `path`; returns once
    /// every subscriber is in place (a message published from then on is recorded). The
    /// file is created only then: once it exists, the recorder listens.
    pub fn start(
        instance: &Instance,
        path: &Path,
        options: RecorderOptions,
    ) -> Result<Self, RecordError> {
        Self::start_with_tap(instance, path, options, None)
    }

    /// [`Recorder::start`], with `tap` adding channels derived from the recorded messages
    /// (see [`Tap`]): it runs on the writing thread, never on the draining one.
    pub fn start_with_tap(
        instance: &Instance,
        path: &Path,
        options: RecorderOptions,
        tap: Option<Box<dyn Tap>>,
    ) -> Result<Self, RecordError> {
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(Counters::default());
        let batches = options.batches.max(2);
        let (full_tx, full_rx) = sync_channel::<Vec<u8>>(batches);
        let (free_tx, free_rx) = sync_channel::<Vec<u8>>(batches);
        for _ in 0..batches {
            let _ = free_tx.try_send(Vec::with_capacity(options.batch_bytes.max(1 << 17)));
        }
        let offset = unix_minus_monotonic_ns();

        let (ready_tx, ready_rx) = sync_channel::<Result<(), RecordError>>(1);
        let drain = {
            let stop = Arc::clone(&stop);
            let counters = Arc::clone(&counters);
            let instance = instance.clone();
            let options = options.clone();
            std::thread::Builder::new()
                .name("agp-rec-drain".into())
                .spawn(move || {
                    drain_loop(
                        &instance, &options, offset, &stop, &counters, full_tx, free_rx, &ready_tx,
                    )
                })
                .map_err(|_| RecordError::Thread("draining"))?
        };
        let mut rec = Self {
            stop,
            counters,
            drain: Some(drain),
            writer: None,
            path: path.to_path_buf(),
            start: Instant::now(),
        };
        let ready = match ready_rx.recv() {
            Ok(r) => r,
            Err(_) => Err(RecordError::Thread("draining")),
        };
        if let Err(e) = ready {
            let _ = rec.end();
            return Err(e);
        }
        let file = match std::fs::File::create(path) {
            Ok(f) => f,
            Err(source) => {
                let _ = rec.end();
                return Err(RecordError::Create {
                    path: path.to_path_buf(),
                    source,
                });
            }
        };
        let counters = Arc::clone(&rec.counters);
        match std::thread::Builder::new()
            .name("agp-rec-write".into())
            .spawn(move || write_loop(file, &options, &full_rx, &free_tx, &counters, tap))
        {
            Ok(w) => rec.writer = Some(w),
            Err(_) => {
                let _ = rec.end();
                return Err(RecordError::Thread("writer"));
            }
        }
        Ok(rec)
    }

    /// The counts so far (written lags received by what waits for the disk).
    pub fn stats(&self) -> RecordStats {
        self.snapshot(0)
    }

    fn snapshot(&self, file_bytes: u64) -> RecordStats {
        let c = &self.counters;
        RecordStats {
            path: self.path.clone(),
            topics: recorded_topics()
                .iter()
                .enumerate()
                .map(|(i, t)| TopicStats {
                    topic: t.service,
                    type_name: t.type_name,
                    received: c.received[i].load(Ordering::Relaxed),
                    written: c.written[i].load(Ordering::Relaxed),
                    dropped: c.dropped[i].load(Ordering::Relaxed),
                    lost: c.lost[i].load(Ordering::Relaxed),
                })
                .collect(),
            duration: self.start.elapsed(),
            file_bytes,
        }
    }

    /// Stops taking messages, writes what is queued and completes the file (its summary
    /// and the [`RECORDING_METADATA`] record with these counts).
    pub fn finish(mut self) -> Result<RecordStats, RecordError> {
        let bytes = self.end()?;
        Ok(self.snapshot(bytes))
    }

    fn end(&mut self) -> Result<u64, RecordError> {
        self.stop.store(true, Ordering::Relaxed);
        let drained = match self.drain.take() {
            Some(t) => t.join().map_err(|_| RecordError::Thread("draining"))?,
            None => Ok(()),
        };
        let written = match self.writer.take() {
            Some(t) => t.join().map_err(|_| RecordError::Thread("writer"))?,
            None => Ok(0),
        };
        drained?;
        written
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        let _ = self.end();
    }
}

/// CLOCK_REALTIME minus CLOCK_MONOTONIC, ns: added to a monotonic stamp gives Unix time.
fn unix_minus_monotonic_ns() -> i128 {
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as i128)
        .unwrap_or(0);
    unix - i128::from(monotonic_ns())
}

fn to_unix(mono_ns: u64, offset: i128) -> u64 {
    u64::try_from(i128::from(mono_ns) + offset).unwrap_or(0)
}

/// One subscriber and what the recorder reads of its payload.
trait Drain {
    /// Takes every sample waiting; `sink` gets its bytes, its publish stamp
    /// (CLOCK_MONOTONIC, 0 when it has none) and its counter (for gaps).
    fn drain(&mut self, sink: &mut Sink<'_>) -> Result<usize, String>;
}

/// What [`Drain::drain`] hands each sample to: its bytes, publish stamp and counter.
type Sink<'a> = dyn FnMut(&[u8], u64, Option<u64>) + 'a;

struct Sub<T: std::fmt::Debug + ZeroCopySend + 'static> {
    sub: Subscriber<AgpIpc, T, ()>,
    stamp: fn(&T) -> u64,
    counter: fn(&T) -> Option<u64>,
}

impl<T: std::fmt::Debug + ZeroCopySend + 'static> Drain for Sub<T> {
    fn drain(&mut self, sink: &mut Sink<'_>) -> Result<usize, String> {
        let mut n = 0;
        loop {
            match self.sub.receive() {
                Ok(Some(s)) => {
                    let p: &T = s.payload();
                    sink(bytes_of(p), (self.stamp)(p), (self.counter)(p));
                    n += 1;
                }
                Ok(None) => return Ok(n),
                Err(e) => return Err(format!("{e:?}")),
            }
        }
    }
}

fn no_stamp<T>(_: &T) -> u64 {
    0
}
fn no_counter<T>(_: &T) -> Option<u64> {
    None
}

fn open<T: std::fmt::Debug + ZeroCopySend + 'static>(
    instance: &Instance,
    node: &Node<AgpIpc>,
    topic: &'static str,
    open: fn(&Instance, &Node<AgpIpc>) -> Result<Topic<T>, OpenError>,
    stamp: fn(&T) -> u64,
    counter: fn(&T) -> Option<u64>,
) -> Result<Box<dyn Drain>, RecordError> {
    let err = |detail: String| RecordError::Subscribe { topic, detail };
    let t = open(instance, node).map_err(|e| err(e.to_string()))?;
    // No buffer size: the deepest the service allows.
    let sub = t
        .data
        .subscriber_builder()
        .create()
        .map_err(|e| err(format!("{e:?}")))?;
    Ok(Box::new(Sub {
        sub,
        stamp,
        counter,
    }))
}

/// The subscribers, in [`recorded_topics`] order.
fn subscribe(instance: &Instance, node: &Node<AgpIpc>) -> Result<Vec<Box<dyn Drain>>, RecordError> {
    let t = recorded_topics();
    Ok(vec![
        open::<IrFrame>(
            instance,
            node,
            t[0].service,
            Instance::ir_frames,
            |f| f.timing.stamps_ns[stage::FRAME_PUBLISHED],
            |f| Some(f.step),
        )?,
        open::<MotorCommand>(
            instance,
            node,
            t[1].service,
            Instance::motor_commands,
            |c| c.timing.stamps_ns[stage::COMMAND_PUBLISHED],
            no_counter,
        )?,
        open::<Reset>(
            instance,
            node,
            t[2].service,
            Instance::resets,
            no_stamp,
            no_counter,
        )?,
        open::<ObjectEstimate>(
            instance,
            node,
            t[3].service,
            Instance::estimates,
            |e| e.timing.stamps_ns[stage::ESTIMATE_PUBLISHED],
            no_counter,
        )?,
        open::<GradientGrid>(
            instance,
            node,
            t[4].service,
            Instance::grids,
            no_stamp,
            no_counter,
        )?,
        open::<Task>(
            instance,
            node,
            t[5].service,
            Instance::task,
            no_stamp,
            no_counter,
        )?,
        open::<Goal>(
            instance,
            node,
            t[6].service,
            Instance::goal,
            no_stamp,
            no_counter,
        )?,
        open::<ActiveEpoch>(
            instance,
            node,
            t[7].service,
            Instance::active_epoch,
            no_stamp,
            |e| Some(e.seq),
        )?,
        open::<LearnEvent>(
            instance,
            node,
            t[8].service,
            Instance::learn_events,
            no_stamp,
            |e| Some(e.seq),
        )?,
        open::<LearnReport>(
            instance,
            node,
            t[9].service,
            Instance::learn_reports,
            no_stamp,
            |r| Some(r.seq),
        )?,
        open::<GoalEnd>(
            instance,
            node,
            t[10].service,
            Instance::goal_ends,
            no_stamp,
            no_counter,
        )?,
    ])
}

/// Where the draining thread puts messages: the batch being filled, the queue to the
/// writer and the free batches coming back.
struct Batches {
    current: Option<Vec<u8>>,
    full: SyncSender<Vec<u8>>,
    free: Receiver<Vec<u8>>,
    last_ship: Instant,
}

impl Batches {
    /// Appends one message; `false` when no batch has room (the message is dropped).
    fn push(&mut self, topic: usize, bytes: &[u8], log: u64, publish: u64) -> bool {
        let need = RECORD_HEADER + bytes.len();
        for _ in 0..2 {
            if self.current.is_none() {
                self.current = self.free.try_recv().ok();
            }
            let Some(b) = &mut self.current else {
                return false;
            };
            if b.len() + need <= b.capacity() {
                b.extend_from_slice(&(topic as u16).to_le_bytes());
                b.extend_from_slice(&[0, 0]);
                b.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
                b.extend_from_slice(&log.to_le_bytes());
                b.extend_from_slice(&publish.to_le_bytes());
                b.extend_from_slice(bytes);
                return true;
            }
            if b.is_empty() {
                // A message larger than a whole batch: it cannot be taken.
                return false;
            }
            self.ship();
        }
        false
    }

    /// Hands the current batch, if it holds anything, to the writer.
    fn ship(&mut self) {
        self.last_ship = Instant::now();
        if let Some(b) = self.current.take() {
            if b.is_empty() {
                self.current = Some(b);
                return;
            }
            // The queue holds as many batches as exist: it is never full.
            if let Err(TrySendError::Full(b) | TrySendError::Disconnected(b)) =
                self.full.try_send(b)
            {
                let mut b = b;
                b.clear();
                self.current = Some(b);
            }
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn drain_loop(
    instance: &Instance,
    options: &RecorderOptions,
    offset: i128,
    stop: &AtomicBool,
    counters: &Counters,
    full: SyncSender<Vec<u8>>,
    free: Receiver<Vec<u8>>,
    ready: &SyncSender<Result<(), RecordError>>,
) -> Result<(), RecordError> {
    let node = match instance.node(&options.node_name, false) {
        Ok(n) => n,
        Err(e) => {
            let _ = ready.send(Err(RecordError::Node(format!("{e:?}"))));
            return Ok(());
        }
    };
    let subs = match subscribe(instance, &node) {
        Ok(s) => s,
        Err(e) => {
            let _ = ready.send(Err(e));
            return Ok(());
        }
    };
    let _ = ready.send(Ok(()));
    let mut d = Drainer {
        subs,
        batches: Batches {
            current: None,
            full,
            free,
            last_ship: Instant::now(),
        },
        last_counter: [None; TOPIC_COUNT],
        topics: recorded_topics(),
        counters,
        offset,
    };
    loop {
        let stopping = stop.load(Ordering::Relaxed);
        let found = d.drain_all()?;
        if stopping {
            d.batches.ship();
            return Ok(());
        }
        if d.batches.last_ship.elapsed() >= options.flush_every
            || d.batches
                .current
                .as_ref()
                .is_some_and(|b| b.len() * 2 > b.capacity())
        {
            d.batches.ship();
        }
        if found == 0 {
            // No listener of the ring's events: a wake-up per command would cost the ring
            // a notification and the cores a switch. The buffers (`TAP_DEPTH` messages per
            // topic) hold tens of milliseconds even at full lockstep speed.
            std::thread::sleep(options.idle_poll);
        }
    }
}

/// The draining thread's state: the subscribers, the batches, the last counter seen per
/// topic.
struct Drainer<'a> {
    subs: Vec<Box<dyn Drain>>,
    batches: Batches,
    last_counter: [Option<u64>; TOPIC_COUNT],
    topics: [TopicSpec; TOPIC_COUNT],
    counters: &'a Counters,
    offset: i128,
}

impl Drainer<'_> {
    /// Takes every waiting message of every topic; how many.
    fn drain_all(&mut self) -> Result<usize, RecordError> {
        let mut found = 0;
        let (counters, offset, batches) = (self.counters, self.offset, &mut self.batches);
        for (i, sub) in self.subs.iter_mut().enumerate() {
            let last = &mut self.last_counter[i];
            let n = sub
                .drain(&mut |bytes, stamp, counter| {
                    let log = to_unix(monotonic_ns(), offset);
                    let publish = if stamp == 0 {
                        log
                    } else {
                        to_unix(stamp, offset)
                    };
                    counters.received[i].fetch_add(1, Ordering::Relaxed);
                    if let Some(c) = counter {
                        if let Some(l) = *last
                            && c > l + 1
                        {
                            counters.lost[i].fetch_add(c - l - 1, Ordering::Relaxed);
                        }
                        // A counter that goes back started over (a restarted publisher).
                        *last = Some(c);
                    }
                    if !batches.push(i, bytes, log, publish) {
                        counters.dropped[i].fetch_add(1, Ordering::Relaxed);
                    }
                })
                .map_err(|detail| RecordError::Receive {
                    topic: self.topics[i].service,
                    detail,
                })?;
            found += n;
        }
        Ok(found)
    }
}

fn write_loop(
    file: std::fs::File,
    options: &RecorderOptions,
    full: &Receiver<Vec<u8>>,
    free: &SyncSender<Vec<u8>>,
    counters: &Counters,
    mut tap: Option<Box<dyn Tap>>,
) -> Result<u64, RecordError> {
    let write_options = mcap::WriteOptions::new()
        .profile("agp")
        .library(format!("agp-recording {}", env!("CARGO_PKG_VERSION")))
        .compression(options.compress.then_some(mcap::Compression::Lz4));
    let mut out = write_options.create(BufWriter::with_capacity(1 << 20, file))?;
    let mut run = options.run.clone();
    run.insert("message_encoding".into(), MESSAGE_ENCODING.into());
    run.insert(
        "log_time".into(),
        "Unix time (ns) when the recorder took the message; publish_time: the payload's own publish stamp (CLOCK_MONOTONIC moved to Unix time) where it has one, else the log time".into(),
    );
    out.write_metadata(&mcap::records::Metadata {
        name: RUN_METADATA.into(),
        metadata: run,
    })?;
    let topics = recorded_topics();
    let mut channels = [0u16; TOPIC_COUNT];
    for (i, t) in topics.iter().enumerate() {
        let schema = out.add_schema(
            t.type_name,
            SCHEMA_ENCODING,
            t.layout().schema_text().as_bytes(),
        )?;
        let meta = BTreeMap::from([
            ("agp.type_name".to_owned(), t.type_name.to_owned()),
            ("agp.size".to_owned(), t.size.to_string()),
        ]);
        channels[i] = out.add_channel(schema, t.service, MESSAGE_ENCODING, &meta)?;
    }
    if let Some(tap) = tap.as_mut() {
        tap.begin(&mut out)?;
    }
    let mut sequence = [0u32; TOPIC_COUNT];
    let mut failure = None;
    while let Ok(mut batch) = full.recv() {
        if failure.is_none() {
            let mut at = 0;
            while at + RECORD_HEADER <= batch.len() {
                let h = &batch[at..at + RECORD_HEADER];
                let topic = usize::from(u16::from_le_bytes([h[0], h[1]]));
                let len = u32::from_le_bytes([h[4], h[5], h[6], h[7]]) as usize;
                let log = u64::from_le_bytes(h[8..16].try_into().unwrap_or_default());
                let publish = u64::from_le_bytes(h[16..24].try_into().unwrap_or_default());
                let data = &batch[at + RECORD_HEADER..at + RECORD_HEADER + len];
                at += RECORD_HEADER + len;
                let header = mcap::records::MessageHeader {
                    channel_id: channels[topic],
                    sequence: sequence[topic],
                    log_time: log,
                    publish_time: publish,
                };
                sequence[topic] = sequence[topic].wrapping_add(1);
                if let Err(e) = out.write_to_known_channel(&header, data) {
                    failure = Some(e);
                    break;
                }
                counters.written[topic].fetch_add(1, Ordering::Relaxed);
                if let Some(tap) = tap.as_mut()
                    && let Err(e) = tap.message(&mut out, topics[topic].service, data, log)
                {
                    failure = Some(e);
                    break;
                }
            }
        }
        batch.clear();
        let _ = free.try_send(batch);
    }
    if let Some(e) = failure {
        return Err(e.into());
    }
    // The draining thread has ended (the queue closed): the counts are final.
    let mut stats = BTreeMap::new();
    for (i, t) in topics.iter().enumerate() {
        for (what, c) in [
            ("received", &counters.received),
            ("written", &counters.written),
            ("dropped", &counters.dropped),
            ("lost", &counters.lost),
        ] {
            stats.insert(
                format!("{}.{what}", t.service),
                c[i].load(Ordering::Relaxed).to_string(),
            );
        }
    }
    out.write_metadata(&mcap::records::Metadata {
        name: RECORDING_METADATA.into(),
        metadata: stats,
    })?;
    if let Some(tap) = tap.as_mut() {
        tap.end(&mut out)?;
    }
    out.finish()?;
    let file = out.into_inner();
    let file = file.into_inner().map_err(|e| RecordError::Create {
        path: PathBuf::new(),
        source: e.into_error(),
    })?;
    file.sync_all().map_err(|source| RecordError::Create {
        path: PathBuf::new(),
        source,
    })?;
    Ok(file.metadata().map(|m| m.len()).unwrap_or(0))
}
