//! Where a bridged hop spends its time: with [`TRACE_ENV`] set, each end of a bridge keeps,
//! for the frames, estimates and commands it carries, how long after its publisher stamped
//! it (the payload's own `TimingHeader`, `CLOCK_MONOTONIC`, comparable between the two ends
//! on one machine) each message reached four points, and says their quantiles when the
//! bridge ends (on stderr, which the supervisor keeps in the bridge's log):
//!
//! - *woke*: the sending end's out thread, woken on the iceoryx2 event, holds it;
//! - *put*: Zenoh's `put` of it returned there;
//! - *arrived*: Zenoh's receive callback at the far end was handed it;
//! - *republished*: the far end sent it in shared memory and notified its readers.
//!
//! From *republished* to the reader's receipt is the reader's wake-up, which `agp profile`
//! shows as the rest of the hop. Off (the default), a point costs one branch.

use agp_shared_types::{ServiceNames, monotonic_ns, stage};

/// Set (to anything) to trace a bridge's hops.
pub const TRACE_ENV: &str = "AGP_BRIDGE_TRACE";

/// The points of a hop a bridge sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Point {
    Woke = 0,
    Put = 1,
    Arrived = 2,
    Republished = 3,
}

const POINTS: [&str; 4] = ["woke", "put", "arrived", "republished"];
/// The traced topics and the stage of their publisher's stamp.
const TRACED: [(&str, usize); 3] = [
    (ServiceNames::IR_FRAMES, stage::FRAME_PUBLISHED),
    (ServiceNames::ESTIMATES, stage::ESTIMATE_PUBLISHED),
    (ServiceNames::MOTOR_COMMANDS, stage::COMMAND_PUBLISHED),
];
/// Samples kept per topic and point (the first ones; about 4 minutes of a lockstep run's
/// commands at the bridged rate).
const KEPT: usize = 1 << 18;

/// The delays of one end, ns, per traced topic and point; empty when tracing is off.
pub(crate) struct Trace {
    delays: Vec<Vec<u32>>,
}

impl Trace {
    /// On when [`TRACE_ENV`] is set.
    pub(crate) fn from_env() -> Self {
        let on = std::env::var_os(TRACE_ENV).is_some();
        Self {
            delays: if on {
                (0..TRACED.len() * POINTS.len())
                    .map(|_| Vec::with_capacity(KEPT))
                    .collect()
            } else {
                Vec::new()
            },
        }
    }

    /// Books the delay from `bytes`' publish stamp (a message of `service`) to now.
    #[inline]
    pub(crate) fn mark(&mut self, service: &str, bytes: &[u8], point: Point) {
        if self.delays.is_empty() {
            return;
        }
        let Some((t, (_, at))) = TRACED.iter().enumerate().find(|(_, (s, _))| *s == service) else {
            return;
        };
        // The TimingHeader leads each traced payload: trace id, then the stamps.
        let from = 8 + 8 * at;
        let Some(stamp) = bytes
            .get(from..from + 8)
            .and_then(|b| <[u8; 8]>::try_from(b).ok())
            .map(u64::from_le_bytes)
            .filter(|s| *s != 0)
        else {
            return;
        };
        let d = &mut self.delays[t * POINTS.len() + point as usize];
        if d.len() < KEPT {
            d.push(u32::try_from(monotonic_ns().saturating_sub(stamp)).unwrap_or(u32::MAX));
        }
    }

    /// Says the quantiles of every point that saw a message, one line per topic.
    pub(crate) fn report(&mut self, who: &str) {
        if self.delays.is_empty() {
            return;
        }
        for (t, (service, _)) in TRACED.iter().enumerate() {
            let mut parts = Vec::new();
            for (p, name) in POINTS.iter().enumerate() {
                let d = &mut self.delays[t * POINTS.len() + p];
                if d.is_empty() {
                    continue;
                }
                d.sort_unstable();
                let q = |x: f64| d[((d.len() - 1) as f64 * x).round() as usize] as f64 * 1e-3;
                parts.push(format!(
                    "{name} p50 {:.1} us p90 {:.1} us ({} msgs)",
                    q(0.5),
                    q(0.9),
                    d.len()
                ));
            }
            if !parts.is_empty() {
                eprintln!(
                    "agp bridge trace ({who}), {service} since published: {}",
                    parts.join(", ")
                );
            }
        }
    }
}
