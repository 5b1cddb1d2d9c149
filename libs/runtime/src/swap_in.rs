//! The swapped-in side of a hot swap (pipeline.md, "Hot-swapping the planner"): a process
//! started with an epoch says `Ready`, waits until its epoch drives, and reports the
//! handover with `Driving` from the first frame after it. The planner and the harness's
//! scripted drive share it.

use std::time::Duration;

use agp_shared_types::{ControlKind, ControlRequest, monotonic_ns};
use iceoryx2::prelude::Node;

use crate::control_client::{ControlAskError, ControlClient};
use crate::{AgpIpc, ControlOpenError, DriveError, Instance, LockstepDriver};

/// Why a swapped-in process could not take over.
#[derive(Debug, thiserror::Error)]
pub enum SwapInError {
    #[error("cannot create the swap node: {0}")]
    Node(String),
    #[error("cannot reach the supervisor for the swap: {0}")]
    Open(#[from] ControlOpenError),
    #[error("the swap's `{what}`: {source}")]
    Ask {
        what: &'static str,
        source: ControlAskError,
    },
    #[error("the swap's take-over: {0}")]
    TakeOver(#[from] DriveError),
}

/// A process swapped in (its driver's epoch is not 0), ready and driving, until it reports
/// its handover.
pub struct SwapIn {
    client: ControlClient,
    _node: Node<AgpIpc>,
    epoch: u64,
    ready_ns: u64,
}

impl SwapIn {
    /// `None` for a process started with the run (epoch 0). Otherwise tells the supervisor
    /// this process is ready, then waits (each at most `timeout`) until its epoch drives.
    pub fn start(
        instance: &Instance,
        driver: &mut LockstepDriver,
        timeout: Duration,
    ) -> Result<Option<Self>, SwapInError> {
        let epoch = driver.epoch();
        if epoch == 0 {
            return Ok(None);
        }
        let node = instance
            .node(&format!("planner-swap-{epoch}"), false)
            .map_err(|e| SwapInError::Node(format!("{e:?}")))?;
        let client = ControlClient::open(instance, &node, timeout)?;
        let ready_ns = monotonic_ns();
        let mut request = ControlRequest::new(ControlKind::Ready);
        request.epoch = epoch;
        // A restart of a swapped-in process finds its epoch active already: the supervisor
        // then refuses the `Ready`, and `take_over` returns at once.
        client
            .ask(&request, timeout)
            .map_err(|source| SwapInError::Ask {
                what: "Ready",
                source,
            })?;
        driver.take_over(timeout)?;
        Ok(Some(Self {
            client,
            _node: node,
            epoch,
            ready_ns,
        }))
    }

    /// Reports the handover (ready -> first command applied, `applied_ns` on the monotonic
    /// clock) from the first frame after it.
    pub fn driving(self, applied_ns: u64, timeout: Duration) -> Result<(), SwapInError> {
        let mut request = ControlRequest::new(ControlKind::Driving);
        request.epoch = self.epoch;
        request.value_ns = applied_ns.saturating_sub(self.ready_ns);
        self.client
            .ask(&request, timeout)
            .map_err(|source| SwapInError::Ask {
                what: "Driving",
                source,
            })?;
        Ok(())
    }
}
