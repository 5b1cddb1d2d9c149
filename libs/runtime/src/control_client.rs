//! The requesting side of a supervisor's control service (`agp/control`): any process or
//! tool can ask the running `agp up` of an instance for its status, to stop, to swap a
//! planner, or for a pause lease.
//!
//! [`ask`] and [`ask_with`] are one whole conversation: they check that a supervisor holds
//! the instance and has created its service before they make a node of their own (a node
//! made earlier would be a stranger in the way of a supervisor still cleaning what a
//! previous run left), then send one request and wait for its answer. A process that asks
//! many times (a planner started for a hot swap, `agp profile`'s lease) keeps a
//! [`ControlClient`] on its own node instead.

use std::time::Duration;

use agp_shared_types::{ControlKind, ControlRequest, ControlResponse};
use iceoryx2::prelude::Node;

use crate::AgpIpc;
use crate::instance::{ControlOpenError, ControlService, Instance, InstanceNameError};
use crate::instance_lock::InstanceLock;

/// How long [`ask`] waits for the supervisor's answer (a safety net: it answers within
/// its 10 ms poll).
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);

/// Why [`ask`] or [`ask_with`] got no answer from an instance's supervisor.
#[derive(Debug, thiserror::Error)]
pub enum InstanceAskError {
    #[error("bad instance name `{name}`: {source}")]
    BadName {
        name: String,
        #[source]
        source: InstanceNameError,
    },
    /// No supervisor holds the instance's lock.
    #[error("instance `{0}` is not up (no supervisor holds it)")]
    NotUp(String),
    /// A supervisor holds the lock but has not created the control service yet.
    #[error("instance `{0}` is starting: its supervisor does not answer yet")]
    Starting(String),
    #[error("cannot create an iceoryx2 node on instance `{name}`: {detail}")]
    Node { name: String, detail: String },
    #[error(transparent)]
    Open(#[from] ControlOpenError),
    #[error(transparent)]
    Ask(#[from] ControlAskError),
}

/// Sends one request of `kind` to the supervisor of instance `name` and returns its
/// answer, waiting up to [`ANSWER_TIMEOUT`].
pub fn ask(name: &str, kind: ControlKind) -> Result<ControlResponse, InstanceAskError> {
    ask_with(name, ControlRequest::new(kind), ANSWER_TIMEOUT)
}

/// Sends `request` to the supervisor of instance `name` and waits up to `timeout` for the
/// answer.
pub fn ask_with(
    name: &str,
    request: ControlRequest,
    timeout: Duration,
) -> Result<ControlResponse, InstanceAskError> {
    let instance = Instance::new(name).map_err(|source| InstanceAskError::BadName {
        name: name.to_owned(),
        source,
    })?;
    if !InstanceLock::is_held(&instance) {
        return Err(InstanceAskError::NotUp(name.to_owned()));
    }
    let Some(supervisor) = InstanceLock::holder_pid(&instance) else {
        return Err(InstanceAskError::Starting(name.to_owned()));
    };
    // Until then the supervisor is still starting (it may be cleaning what a previous run
    // left): a node of ours would be a stranger in its way.
    if !instance.control_exists() {
        return Err(InstanceAskError::Starting(name.to_owned()));
    }
    let node = instance
        .node(&format!("agp-cli-{}", std::process::id()), false)
        .map_err(|e| InstanceAskError::Node {
            name: name.to_owned(),
            detail: format!("{e:?}"),
        })?;
    let client = ControlClient::open(&instance, &node, ANSWER_TIMEOUT)?;
    // A supervisor killed while we wait never answers: stop waiting when it is gone, so
    // no client of a dead supervisor lingers in the way of the next `agp up`.
    let alive = || process_alive(supervisor);
    Ok(client.ask_while(&request, timeout, &alive)?)
}

/// Whether process `pid` exists (a zombie counts: its parent has yet to reap it).
fn process_alive(pid: u32) -> bool {
    let Ok(p) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill(2) with signal 0 sends nothing; it only checks that the pid exists.
    unsafe { libc::kill(p, 0) == 0 || *libc::__errno_location() == libc::EPERM }
}

/// Whether node `name` of process `pid` is an `agp` client's (`agp status`, `agp down`,
/// `agp swap`, `agp profile`): named `agp-cli-<pid>` or `agp-profile-<pid>` after its own
/// pid, by an `agp` executable. Such a node holds nothing a pipeline needs and goes when
/// its one request is answered, or its supervisor is gone.
pub fn is_client_node(name: &str, pid: u32) -> bool {
    let own_name = ["agp-cli-", "agp-profile-"]
        .iter()
        .any(|p| name.strip_prefix(p) == Some(pid.to_string().as_str()));
    if !own_name {
        return false;
    }
    let Ok(exe) = std::fs::read_link(format!("/proc/{pid}/exe")) else {
        return false;
    };
    // A rebuilt `agp` still running shows as `agp (deleted)`.
    exe.file_name()
        .map(|n| {
            n.to_string_lossy()
                .trim_end_matches(" (deleted)")
                .to_owned()
        })
        .is_some_and(|n| n == "agp")
}

/// Why a request got no answer.
#[derive(Debug, thiserror::Error)]
pub enum ControlAskError {
    #[error("cannot create a control client: {0}")]
    Client(String),
    #[error("cannot send the request: {0}")]
    Send(String),
    #[error("cannot receive the answer: {0}")]
    Receive(String),
    #[error("the supervisor did not answer within {0:?}")]
    Timeout(std::time::Duration),
    #[error("shutdown requested")]
    Shutdown,
    #[error("the supervisor died before it answered")]
    SupervisorGone,
}

/// A client of the supervisor's control service.
pub struct ControlClient {
    _service: ControlService,
    client: iceoryx2::port::client::Client<AgpIpc, ControlRequest, (), ControlResponse, ()>,
}

impl ControlClient {
    /// Opens the service, retrying for up to `wait` (a supervisor creates it a moment after
    /// it takes its instance).
    pub fn open(
        instance: &Instance,
        node: &Node<AgpIpc>,
        wait: std::time::Duration,
    ) -> Result<Self, ControlOpenError> {
        let start = std::time::Instant::now();
        let service = loop {
            match instance.open_control(node) {
                Ok(s) => break s,
                Err(e) if start.elapsed() >= wait => return Err(e),
                Err(_) => std::thread::sleep(std::time::Duration::from_millis(20)),
            }
        };
        let client = service
            .client_builder()
            .create()
            .map_err(|e| ControlOpenError::Create(format!("{e:?}")))?;
        Ok(Self {
            _service: service,
            client,
        })
    }

    /// Sends `request` and waits up to `timeout` for the answer.
    pub fn ask(
        &self,
        request: &ControlRequest,
        timeout: std::time::Duration,
    ) -> Result<ControlResponse, ControlAskError> {
        self.ask_while(request, timeout, &|| true)
    }

    /// [`ControlClient::ask`], giving up as soon as `supervisor_alive` says no (asked every
    /// 20 ms).
    pub fn ask_while(
        &self,
        request: &ControlRequest,
        timeout: std::time::Duration,
        supervisor_alive: &dyn Fn() -> bool,
    ) -> Result<ControlResponse, ControlAskError> {
        let pending = self
            .client
            .send_copy(*request)
            .map_err(|e| ControlAskError::Send(format!("{e:?}")))?;
        let start = std::time::Instant::now();
        let mut next_check = start;
        loop {
            if let Some(response) = pending
                .receive()
                .map_err(|e| ControlAskError::Receive(format!("{e:?}")))?
            {
                return Ok(*response.payload());
            }
            if crate::shutdown_requested() {
                return Err(ControlAskError::Shutdown);
            }
            if start.elapsed() >= timeout {
                return Err(ControlAskError::Timeout(timeout));
            }
            let now = std::time::Instant::now();
            if now >= next_check {
                if !supervisor_alive() {
                    return Err(ControlAskError::SupervisorGone);
                }
                next_check = now + std::time::Duration::from_millis(20);
            }
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
    }
}
