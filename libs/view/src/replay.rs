//! `agp view FILE.mcap`: a recording served over the same WebSocket, paced by its log times.
//!
//! The recording's format (libs/recording): one MCAP channel per iceoryx2 topic, its topic
//! the service name (`agp/ir_frames`), its schema name the payload's iceoryx2 type name
//! (`agp::IrFrame.v2`), each message the payload's raw `#[repr(C)]` bytes. The view reads
//! the topics it shows and skips every other one; a channel whose schema is not the
//! payload type this build knows (another version of the layout) is skipped with a
//! warning, never misread. Ground truth, when a recording holds it, is never shown.

use std::collections::BTreeMap;
use std::io::BufReader;
use std::path::Path;
use std::time::{Duration, Instant};

use agp_recording::{grid_from_bytes, payload_from_bytes, type_name_of};
use agp_runtime::shutdown_requested;
use agp_shared_types::{Goal, GradientGrid, IrFrame, ObjectEstimate, ServiceNames, Task};
use mcap::sans_io::LinearReaderOptions;

use crate::server::Viewer;
use crate::state::ViewState;
use crate::{ViewError, ViewOptions, ViewSummary};

/// Longest MCAP record the view reads (a chunk holds many messages): 256 MiB.
pub const MAX_RECORD_BYTES: usize = 256 << 20;

/// The topics a recording may hold that the view shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Shown {
    Estimate,
    Frame,
    Grid,
    Task,
    Goal,
}

impl Shown {
    fn of(topic: &str) -> Option<(Self, &'static str)> {
        Some(match topic {
            ServiceNames::ESTIMATES => (Self::Estimate, type_name_of::<ObjectEstimate>()),
            ServiceNames::IR_FRAMES => (Self::Frame, type_name_of::<IrFrame>()),
            ServiceNames::GRIDS => (Self::Grid, type_name_of::<GradientGrid>()),
            ServiceNames::TASK => (Self::Task, type_name_of::<Task>()),
            ServiceNames::GOAL => (Self::Goal, type_name_of::<Goal>()),
            _ => return None,
        })
    }
}

/// Opens the recording at `path` for reading, without blocking on a FIFO or a device: a
/// regular file that starts with MCAP's magic, or an error that says which it is not.
pub fn open_recording(path: &Path) -> Result<std::fs::File, ViewError> {
    use std::io::{Read, Seek};
    use std::os::unix::fs::OpenOptionsExt;
    let bad = |reason: String| ViewError::Recording {
        path: path.to_owned(),
        reason,
    };
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(path)
        .map_err(|e| bad(e.to_string()))?;
    let meta = file.metadata().map_err(|e| bad(e.to_string()))?;
    if !meta.is_file() {
        return Err(bad("not a regular file".to_owned()));
    }
    let mut magic = [0u8; 8];
    let starts = file.read_exact(&mut magic).is_ok() && magic == mcap::MAGIC;
    if !starts {
        return Err(bad(
            "not an MCAP file (no MCAP magic at its start)".to_owned()
        ));
    }
    file.rewind().map_err(|e| bad(e.to_string()))?;
    Ok(file)
}

/// Serves the recording at `path` on `viewer`: each message applied at its log time, the
/// scene published every period of log time, paced so that one second of log time takes
/// `1 / options.speed` seconds. At the end the last scene stays served (published again
/// each period) until SIGTERM/SIGINT, or it starts over with `options.loop_playback`.
pub fn serve_recording(
    viewer: &mut Viewer,
    path: &Path,
    options: &ViewOptions,
    mut warn: impl FnMut(&str),
) -> Result<ViewSummary, ViewError> {
    let period_ns = u64::try_from(options.period().as_nanos())
        .unwrap_or(u64::MAX)
        .max(1);
    let speed = if options.speed.is_finite() && options.speed > 0.0 {
        options.speed
    } else {
        1.0
    };
    let mut summary = ViewSummary::default();
    loop {
        let file = open_recording(path)?;
        let bad = |reason: String| ViewError::Recording {
            path: path.to_owned(),
            reason,
        };
        let reader = mcap::io::MessageReader::new_with_options(
            BufReader::new(file),
            LinearReaderOptions::default().with_record_length_limit(MAX_RECORD_BYTES),
        );
        let mut state = ViewState::new(options.alpha_deg);
        // Per channel id: what it is, or `None` when the view skips it.
        let mut channels: BTreeMap<u16, Option<Shown>> = BTreeMap::new();
        let mut start: Option<(u64, Instant)> = None;
        let mut next_pub = 0u64;
        let mut last_time = 0u64;
        for message in reader {
            let message = message.map_err(|e| bad(e.to_string()))?;
            let t = message.log_time;
            let (t0, wall0) = *start.get_or_insert_with(|| (t, Instant::now()));
            if next_pub == 0 {
                next_pub = t;
            }
            // Publish every period of log time up to this message, each at its wall time.
            while next_pub <= t {
                if !wait_until(wall0 + scaled(next_pub.saturating_sub(t0), speed)) {
                    summary.stopped_by_signal = true;
                    summary.published = viewer.published();
                    return Ok(summary);
                }
                viewer.broadcast_time(next_pub);
                viewer.publish(&state, next_pub);
                next_pub = next_pub.saturating_add(period_ns);
            }
            last_time = t;
            let channel = &message.channel;
            let shown = *channels.entry(channel.id).or_insert_with(|| {
                let (shown, expected) = Shown::of(&channel.topic)?;
                let schema = channel.schema.as_ref().map(|s| s.name.as_str());
                if schema != Some(expected) {
                    warn(&format!(
                        "channel `{}` has schema `{}`, this build reads `{expected}`: skipped",
                        channel.topic,
                        schema.unwrap_or("(none)")
                    ));
                    return None;
                }
                Some(shown)
            });
            let data: &[u8] = &message.data;
            let applied = match shown {
                None => continue,
                Some(Shown::Estimate) => {
                    payload_from_bytes::<ObjectEstimate>(data).map(|p| state.on_estimate(&p))
                }
                Some(Shown::Frame) => {
                    payload_from_bytes::<IrFrame>(data).map(|p| state.on_frame(&p))
                }
                Some(Shown::Grid) => grid_from_bytes(data).map(|p| state.on_grid(&p)),
                Some(Shown::Task) => payload_from_bytes::<Task>(data).map(|p| state.on_task(&p)),
                Some(Shown::Goal) => payload_from_bytes::<Goal>(data).map(|p| state.on_goal(&p)),
            };
            match (applied, shown) {
                (None, _) => summary.refused += 1,
                (Some(()), Some(Shown::Estimate)) => summary.estimates += 1,
                (Some(()), Some(Shown::Frame)) => summary.frames += 1,
                (Some(()), Some(Shown::Grid)) => summary.grids += 1,
                _ => {}
            }
        }
        // The recording's end: its last state, published once more at its last log time.
        viewer.broadcast_time(last_time);
        viewer.publish(&state, last_time);
        summary.recording_ended = true;
        if options.loop_playback && start.is_some() {
            continue;
        }
        // Hold: the last scene, again each period, for clients that come later.
        let period = options.period();
        while !shutdown_requested() {
            std::thread::sleep(period);
            viewer.publish(&state, last_time);
        }
        summary.stopped_by_signal = true;
        summary.published = viewer.published();
        return Ok(summary);
    }
}

fn scaled(log_ns: u64, speed: f64) -> Duration {
    Duration::from_secs_f64(log_ns as f64 * 1e-9 / speed)
}

/// Sleeps until `at`; `false` when a stop was asked first.
fn wait_until(at: Instant) -> bool {
    loop {
        if shutdown_requested() {
            return false;
        }
        let now = Instant::now();
        if now >= at {
            return true;
        }
        std::thread::sleep((at - now).min(Duration::from_millis(20)));
    }
}
