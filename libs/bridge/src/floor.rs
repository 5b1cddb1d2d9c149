//! The link's floor: a bare Zenoh ping-pong between two processes over the transport a
//! bridge uses (the same endpoint kind, keys, publisher options and receive path), with no
//! iceoryx2 on either side. What a bridged hop costs beyond it is the bridge's own.
//!
//! The pong end listens and echoes each sample from the ping key onto the pong key; the ping
//! end connects, sends one sample at a time, stamped, and times its round trip. A one-way
//! figure is half a round trip. The pong end answers in Zenoh's receive callback, as a
//! bridge's receiving end republishes there; the ping end waits for each answer as a
//! bridge's sending end waits for its next message, with the strategy it is given (the
//! bridge's, [`crate::BRIDGE_WAIT_ENV`]: by default blocking).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use zenoh::Wait;
use zenoh::qos::CongestionControl;

use agp_runtime::WaitStrategy;

use crate::bridge::IN_SLICE;
use crate::endpoint::Endpoint;
use crate::tls::TlsKeys;

/// Key the ping end puts on.
const PING_KEY: &str = "agp-floor/ping";
/// Key the pong end answers on.
const PONG_KEY: &str = "agp-floor/pong";
/// Longest wait for one answer, and for the far end to come up; a safety net.
pub const FLOOR_TIMEOUT: Duration = Duration::from_secs(20);
/// Round trips before the timed ones.
const WARMUP: u64 = 200;

/// Why the floor could not be measured.
#[derive(Debug, thiserror::Error)]
pub enum FloorError {
    #[error("cannot open the Zenoh session on `{endpoint}`: {detail}")]
    Session { endpoint: String, detail: String },
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("no answer from the floor's pong end within {0:?}")]
    NoAnswer(Duration),
}

fn zerr(e: impl std::fmt::Display) -> FloorError {
    FloorError::Zenoh(e.to_string())
}

fn open(endpoint: &Endpoint, tls: Option<&TlsKeys>) -> Result<zenoh::Session, FloorError> {
    let session_err = |detail: String| FloorError::Session {
        endpoint: endpoint.locator().to_owned(),
        detail,
    };
    let config = endpoint.zenoh_config(tls).map_err(session_err)?;
    zenoh::open(config)
        .wait()
        .map_err(|e| session_err(e.to_string()))
}

/// The floor's figures: one-way latency (half a round trip), nanoseconds.
#[derive(Debug, Clone, PartialEq)]
pub struct FloorFigures {
    pub round_trips: u64,
    /// Every timed one-way figure, sorted.
    pub one_way_ns: Vec<u64>,
    pub p50_ns: u64,
    pub p90_ns: u64,
    pub p99_ns: u64,
    pub max_ns: u64,
}

/// Echoes pings until `stop` says so (checked every 20 ms) or the ping end says it is done.
/// Each ping is answered in Zenoh's receive callback, as a bridge's receiving end
/// republishes a message there (and as Zenoh's own `z_pong` answers): the floor's one-way
/// figure then holds one wake-up of a waiting thread (the ping end's, half of it per way),
/// where a bridged hop holds two (its out thread's and its reader's).
pub fn floor_pong(
    endpoint: &Endpoint,
    tls: Option<&TlsKeys>,
    stop: impl Fn() -> bool,
) -> Result<(), FloorError> {
    let session = open(endpoint, tls)?;
    let publisher = session
        .declare_publisher(PONG_KEY)
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(zerr)?;
    let done = Arc::new(AtomicBool::new(false));
    let failed: Arc<Mutex<Option<String>>> = Arc::default();
    let pings = {
        let (done, failed) = (Arc::clone(&done), Arc::clone(&failed));
        session
            .declare_subscriber(PING_KEY)
            .callback(move |sample| {
                if sample.payload().is_empty() {
                    done.store(true, Ordering::SeqCst);
                } else if let Err(e) = publisher.put(sample.payload().clone()).wait() {
                    failed
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .get_or_insert(e.to_string());
                    done.store(true, Ordering::SeqCst);
                }
            })
            .wait()
            .map_err(zerr)?
    };
    while !stop() && !done.load(Ordering::SeqCst) {
        std::thread::sleep(IN_SLICE);
    }
    let _ = pings.undeclare().wait();
    let _ = session.close().wait();
    match failed.lock().unwrap_or_else(|p| p.into_inner()).take() {
        Some(e) => Err(FloorError::Zenoh(e)),
        None => Ok(()),
    }
}

/// Pings the pong end at `endpoint` for `seconds` of timed round trips of `size`-byte
/// samples (at least 16) after a warm-up, one at a time, waiting for each answer as `wait`
/// says, and tells the pong end to stop.
pub fn floor_ping(
    endpoint: &Endpoint,
    tls: Option<&TlsKeys>,
    wait: WaitStrategy,
    seconds: f64,
    size: usize,
) -> Result<FloorFigures, FloorError> {
    let session = open(endpoint, tls)?;
    let publisher = session
        .declare_publisher(PING_KEY)
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
        .map_err(zerr)?;
    let pongs = session
        .declare_subscriber(PONG_KEY)
        .with(zenoh::handlers::FifoChannel::new(64))
        .wait()
        .map_err(zerr)?;
    let size = size.max(16);
    // Until the pong end answers (it may still be opening its session), ping every 50 ms.
    let start = Instant::now();
    let mut seq: u64 = 0;
    let mut payload = vec![0u8; size];
    let send = |seq: u64, payload: &mut Vec<u8>| -> Result<(), FloorError> {
        payload[..8].copy_from_slice(&seq.to_le_bytes());
        publisher.put(payload.clone()).wait().map_err(zerr)
    };
    'up: loop {
        send(seq, &mut payload)?;
        if let Ok(Some(_)) = pongs.recv_timeout(Duration::from_millis(50)) {
            break 'up;
        }
        if start.elapsed() > FLOOR_TIMEOUT {
            return Err(FloorError::NoAnswer(FLOOR_TIMEOUT));
        }
    }
    // Drain late answers of the start-up pings.
    while let Ok(Some(_)) = pongs.try_recv() {}
    let mut one_way: Vec<u64> = Vec::with_capacity(1 << 20);
    let timed = Duration::from_secs_f64(seconds.max(0.1));
    let mut timed_from: Option<Instant> = None;
    loop {
        seq += 1;
        let sent = Instant::now();
        send(seq, &mut payload)?;
        // Answers carry the sequence number; a late start-up answer is skipped.
        let waiting = Instant::now();
        loop {
            match next_sample(&pongs, wait, sent.elapsed()) {
                Ok(None) if waiting.elapsed() < FLOOR_TIMEOUT => {}
                Ok(Some(s)) => {
                    let b = s.payload().to_bytes();
                    let got = b
                        .get(..8)
                        .and_then(|h| <[u8; 8]>::try_from(h).ok())
                        .map(u64::from_le_bytes);
                    if got == Some(seq) {
                        break;
                    }
                }
                Ok(None) => return Err(FloorError::NoAnswer(FLOOR_TIMEOUT)),
                Err(e) => return Err(zerr(e)),
            }
        }
        let rtt = sent.elapsed();
        if seq > WARMUP {
            let from = *timed_from.get_or_insert_with(Instant::now);
            one_way.push(rtt.as_nanos() as u64 / 2);
            if from.elapsed() >= timed {
                break;
            }
        }
    }
    let _ = publisher.put(Vec::<u8>::new()).wait();
    let _ = session.close().wait();
    one_way.sort_unstable();
    let at = |q: f64| one_way[((one_way.len() - 1) as f64 * q).round() as usize];
    Ok(FloorFigures {
        round_trips: one_way.len() as u64,
        p50_ns: at(0.5),
        p90_ns: at(0.9),
        p99_ns: at(0.99),
        max_ns: at(1.0),
        one_way_ns: one_way,
    })
}

/// The next answer of the pong end, waiting as `strategy` says: polling (with a yield
/// between polls) while the last message is newer than its spin, then blocking for at most
/// [`IN_SLICE`]. `Ok(None)` when none came.
fn next_sample(
    subscriber: &InSubscriber,
    strategy: WaitStrategy,
    idle: Duration,
) -> zenoh::Result<Option<zenoh::sample::Sample>> {
    let spin = match strategy {
        WaitStrategy::Spin | WaitStrategy::Yield => IN_SLICE,
        WaitStrategy::SpinThenBlock { spin } => spin.saturating_sub(idle),
        WaitStrategy::Block => Duration::ZERO,
    };
    if !spin.is_zero() {
        let until = Instant::now() + spin;
        loop {
            if let Some(s) = subscriber.try_recv()? {
                return Ok(Some(s));
            }
            if Instant::now() >= until {
                break;
            }
            if matches!(strategy, WaitStrategy::Spin) {
                core::hint::spin_loop();
            } else {
                std::thread::yield_now();
            }
        }
        if !matches!(strategy, WaitStrategy::SpinThenBlock { .. }) {
            return Ok(None);
        }
    }
    subscriber.recv_timeout(IN_SLICE)
}

/// The pong end's answers, as they come.
type InSubscriber =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;
