//! The live view: a subscriber of its own on an instance's topics (its own iceoryx2 node),
//! the latest of each sampled at the view's rate and published. It never writes to the
//! instance and never waits on the ring: its subscribers' buffers overflow, oldest first,
//! when it falls behind, and the publishers never wait for it.

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use agp_runtime::{AgpIpc, Instance, shutdown_requested};
use agp_shared_types::{GRIDS_PER_ALPHA, MAX_GRID_ALPHAS};
use iceoryx2::port::subscriber::Subscriber;

use crate::server::Viewer;
use crate::state::ViewState;
use crate::{ViewError, ViewOptions, ViewSummary};

/// The node name of a live view.
pub const NODE_NAME: &str = "agp-view";

/// The buffer of the view's subscribers on the state topics: it keeps only the latest, and
/// a full buffer drops its oldest sample, never holding a publisher up. The grids'
/// buffer holds a whole set.
const LATEST: usize = 2;

/// How often the view checks that the instance is still up.
const ALIVE_CHECK: Duration = Duration::from_millis(500);

fn open<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> ViewError {
    move |e| ViewError::Open {
        what,
        reason: format!("{e:?}"),
    }
}

/// Drains `sub`, handing each sample to `f`; returns how many there were.
fn drain<T: std::fmt::Debug + iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>(
    sub: &Subscriber<AgpIpc, T, ()>,
    mut f: impl FnMut(&T),
) -> Result<u64, ViewError> {
    let mut n = 0;
    while let Some(sample) = sub
        .receive()
        .map_err(|e| ViewError::Receive(format!("{e:?}")))?
    {
        f(sample.payload());
        n += 1;
    }
    Ok(n)
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// Serves `instance` on `viewer` until SIGTERM/SIGINT ([`agp_runtime::shutdown_requested`])
/// or until the instance's supervisor is gone. The instance must be up (its supervisor's
/// control service exists): the view never creates an instance's services for a pipeline
/// that is not there.
pub fn serve_instance(
    viewer: &mut Viewer,
    instance: &Instance,
    options: &ViewOptions,
) -> Result<ViewSummary, ViewError> {
    if !instance.control_exists() {
        return Err(ViewError::NotUp(instance.name().to_owned()));
    }
    let node = instance
        .node(NODE_NAME, false)
        .map_err(open("the view's node"))?;
    let estimates = instance
        .estimates(&node)
        .map_err(open("the estimates topic"))?
        .data
        .subscriber_builder()
        .buffer_size(LATEST)
        .create()
        .map_err(open("an estimate subscriber"))?;
    let frames = instance
        .ir_frames(&node)
        .map_err(open("the IR frames topic"))?
        .data
        .subscriber_builder()
        .buffer_size(LATEST)
        .create()
        .map_err(open("an IR frame subscriber"))?;
    let grids = instance
        .grids(&node)
        .map_err(open("the grids topic"))?
        .data
        .subscriber_builder()
        .buffer_size(GRIDS_PER_ALPHA * MAX_GRID_ALPHAS)
        .create()
        .map_err(open("a grid subscriber"))?;
    let task = instance
        .task(&node)
        .map_err(open("the task topic"))?
        .data
        .subscriber_builder()
        .buffer_size(LATEST)
        .create()
        .map_err(open("a task subscriber"))?;
    let goal = instance
        .goal(&node)
        .map_err(open("the goal topic"))?
        .data
        .subscriber_builder()
        .buffer_size(LATEST)
        .create()
        .map_err(open("a goal subscriber"))?;

    let mut state = ViewState::new(options.alpha_deg);
    let mut summary = ViewSummary::default();
    let period = options.period();
    let mut next = Instant::now();
    let mut alive_checked = Instant::now();
    loop {
        if shutdown_requested() {
            summary.stopped_by_signal = true;
            break;
        }
        summary.estimates += drain(&estimates, |e| state.on_estimate(e))?;
        summary.frames += drain(&frames, |f| state.on_frame(f))?;
        summary.grids += drain(&grids, |g| state.on_grid(g))?;
        drain(&task, |t| state.on_task(t))?;
        drain(&goal, |g| state.on_goal(g))?;
        let now = Instant::now();
        if now >= next {
            viewer.publish(&state, now_ns());
            next += period;
            if next < now {
                next = now + period;
            }
        }
        if now - alive_checked >= ALIVE_CHECK {
            alive_checked = now;
            if !instance.control_exists() {
                summary.instance_went_down = true;
                break;
            }
        }
        std::thread::sleep(
            next.saturating_duration_since(Instant::now())
                .min(Duration::from_millis(5)),
        );
    }
    summary.published = viewer.published();
    Ok(summary)
}
