//! The planner's subscription to the estimator's gradient grids: the affordance gradient rebuilt from the newest complete set.

use std::path::Path;
use std::time::{Duration, Instant};

use agp_affordance::{AffordanceGradient, GridSetAssembler};
use agp_runtime::{AgpIpc, DriveError, Instance, WaitOutcome, WaitStrategy, Waiter};
use agp_shared_types::{EstimatorLearning, GradientGrid, ObjectEstimate};
use anyhow::{Context, Result, anyhow, bail};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;

/// Reads the instance's `grids` topic and rebuilds the estimator's [`AffordanceGradient`]
/// from the newest complete set of grids (every kind of every alpha of one seq).
///
/// Each sample is read in place and released at once: its cells go straight into the
/// gradient being rebuilt ([`GridSetAssembler`]), so the subscriber never borrows more than
/// one grid and nothing is copied on the way but the rebuild itself.
///
/// A grid of another seq than the set being gathered starts a new set: one publisher sends
/// in order, so the last seq received is the newest, even from an estimator restarted since
/// (its seq counts from 1 again). The topic's history hands a late subscriber the last
/// publications, oldest first, so it ends on the newest set as well.
pub struct GridLink {
    subscriber: Subscriber<AgpIpc, GradientGrid, ()>,
    /// The estimator's estimates: the latest says whether it waits for a planner to drive
    /// its learning (then no grid will come unless one does).
    estimates: Subscriber<AgpIpc, ObjectEstimate, ()>,
    /// Woken by the estimator once per published set.
    waiter: Waiter,
    set: GridSetAssembler,
    _node: Node<AgpIpc>,
}

fn open_err<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> anyhow::Error {
    move |e| anyhow!("cannot open {what}: {e:?}")
}

impl GridLink {
    /// Subscribes to the grids of `instance` (with a node of its own).
    pub fn open(instance: &Instance) -> Result<Self> {
        let node = instance
            .node("planner-grids", false)
            .map_err(open_err("the grids node"))?;
        let topic = instance.grids(&node).map_err(open_err("the grids topic"))?;
        let subscriber = topic
            .subscriber()
            .create()
            .map_err(open_err("the grid subscriber"))?;
        let listener = topic
            .event
            .listener_builder()
            .create()
            .map_err(open_err("the grid listener"))?;
        let estimates = instance
            .estimates(&node)
            .map_err(open_err("the estimates"))?
            .subscriber()
            .create()
            .map_err(open_err("the estimate subscriber"))?;
        Ok(Self {
            subscriber,
            estimates,
            waiter: Waiter::new(listener, WaitStrategy::Block),
            set: GridSetAssembler::new(),
            _node: node,
        })
    }

    /// Waits up to `timeout` for a complete set of grids and rebuilds from it the gradient
    /// of `object_name` (the grids do not carry the name). Takes every grid that arrived
    /// before deciding, so the set is the newest one present; a set a previous call
    /// returned is not returned again.
    ///
    /// Says once on stdout what it waits for when the grids are not there at once. Fails
    /// on shutdown ([`DriveError::Shutdown`]), at the deadline, when a grid is refused (the
    /// set under way is then dropped), and with [`EstimatorWaitsToLearn`] when the
    /// estimator has no gradients and waits for a planner to learn them (`ag_file`, where
    /// the estimator looks for them, is named in that error).
    pub fn wait_gradient(
        &mut self,
        object_name: &str,
        timeout: Duration,
        ag_file: &Path,
    ) -> Result<AffordanceGradient> {
        let Self {
            subscriber,
            estimates,
            waiter,
            set,
            ..
        } = self;
        drain(subscriber, set)?;
        if !set.is_complete() {
            println!(
                "planner: waiting up to {} s for the estimator's gradient grids of `{object_name}` (it loads them from an AG file such as {}, or learns them from a learning planner)",
                timeout.as_secs(),
                ag_file.display()
            );
        }
        let start = Instant::now();
        let mut waiting_to_learn = false;
        let outcome = loop {
            let left = timeout.saturating_sub(start.elapsed());
            if left.is_zero() {
                break WaitOutcome::TimedOut;
            }
            let outcome =
                waiter.wait_for(left.min(ESTIMATOR_LOOK), || match drain(subscriber, set) {
                    Ok(()) => set.is_complete().then_some(Ok(())),
                    Err(e) => Some(Err(e)),
                });
            if !matches!(outcome, WaitOutcome::TimedOut) {
                break outcome;
            }
            while let Ok(Some(e)) = estimates.receive() {
                waiting_to_learn =
                    EstimatorLearning::from_u8(e.learning) == Some(EstimatorLearning::Waiting);
            }
            if waiting_to_learn {
                return Err(EstimatorWaitsToLearn {
                    object: object_name.to_owned(),
                    ag_file: ag_file.to_owned(),
                    file_exists: ag_file.is_file(),
                }
                .into());
            }
        };
        match outcome {
            WaitOutcome::Ready(r) => r?,
            WaitOutcome::Shutdown => return Err(DriveError::Shutdown.into()),
            WaitOutcome::TimedOut => {
                let progress = match (set.seq(), set.expected_grid_count()) {
                    (Some(seq), Some(expected)) => {
                        format!("{} of the {expected} grids of seq {seq}", set.grid_count())
                    }
                    _ => "no grid".to_owned(),
                };
                bail!(
                    "no complete set of gradient grids within {timeout:?} ({progress} arrived): is `agp-estimator` running on this instance, and has it learned or loaded the gradients?"
                );
            }
        }
        let seq = set.seq().unwrap_or_default();
        set.finish(object_name)
            .with_context(|| format!("cannot rebuild the gradient from the grids of seq {seq}"))
    }

    /// Whether a complete set arrived since the last [`GridLink::wait_gradient`] (the
    /// estimator published its gradients again): the next call returns it at once. Never
    /// blocks.
    pub fn newer_available(&mut self) -> Result<bool> {
        drain(&self.subscriber, &mut self.set)?;
        Ok(self.set.is_complete())
    }
}

/// How often a wait for the grids looks at the estimator's latest estimate.
const ESTIMATOR_LOOK: Duration = Duration::from_millis(50);

/// The estimator has no gradients to serve and waits for a planner to drive its learning,
/// which a planner of a task does not do (without `--learn-if-missing`).
#[derive(Debug)]
pub struct EstimatorWaitsToLearn {
    object: String,
    ag_file: std::path::PathBuf,
    file_exists: bool,
}

impl std::fmt::Display for EstimatorWaitsToLearn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.file_exists {
            write!(
                f,
                "the estimator waits to learn `{}` instead of serving the AG file {}: run it with `--reuse` or `--load {}`",
                self.object,
                self.ag_file.display(),
                self.ag_file.display()
            )
        } else {
            write!(
                f,
                "no AG file at {} and the estimator waits for a planner to learn `{}`: learn it first (`agp up` with launch.toml, or `agp bench learn`), or on the lockstep clock give this planner `--learn-if-missing` (the estimator `--reuse`)",
                self.ag_file.display(),
                self.object
            )
        }
    }
}

impl std::error::Error for EstimatorWaitsToLearn {}

/// Feeds every grid that arrived into `set`, each read in place and released at once; a
/// grid of another seq drops the set under way and starts its own, and so does a grid the
/// set under way already holds (the same set sent again, as a bridge does on reconnecting).
fn drain(
    subscriber: &Subscriber<AgpIpc, GradientGrid, ()>,
    set: &mut GridSetAssembler,
) -> Result<()> {
    while let Some(sample) = subscriber
        .receive()
        .map_err(|e| anyhow!("cannot receive a grid: {e:?}"))?
    {
        let grid: &GradientGrid = &sample;
        let seq = grid.header.seq;
        if set.seq().is_some_and(|s| s != seq) {
            set.clear();
        }
        if let Err(e) = set.add_or_start_over(grid) {
            set.clear();
            return Err(e).with_context(|| format!("a grid of seq {seq} was refused"));
        }
    }
    Ok(())
}
