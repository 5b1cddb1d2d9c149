//! The supervisor's control service: `agp status` and `agp down` ask the running `agp up`
//! of an instance through iceoryx2 request-response, never through files or signals.

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::request_response;

use crate::instance::Instance;

/// Most processes a status reply lists.
pub const MAX_STATUS_PROCESSES: usize = 16;
/// Longest process name or executable path a status reply carries, bytes (longer ones
/// are cut at a character boundary and end in `...`).
pub const STATUS_NAME_LEN: usize = 32;
pub const STATUS_PATH_LEN: usize = 256;

/// What the client asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ControlKind {
    /// Each process's state.
    Status = 1,
    /// Stop every process, clean the instance, end `agp up`.
    Down = 2,
}

impl ControlKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Status, Self::Down]
            .into_iter()
            .find(|k| *k as u32 == v)
    }
}

/// A request to the supervisor.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::ControlRequest.v1")]
pub struct ControlRequest {
    /// A [`ControlKind`] as u32.
    pub kind: u32,
    pub _pad: u32,
}

/// State of one process in a status reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ProcessState {
    /// Not started yet, or waiting for its restart backoff.
    Pending = 0,
    Running = 1,
    /// Exited and not restarted.
    Exited = 2,
}

impl ProcessState {
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Pending, Self::Running, Self::Exited]
            .into_iter()
            .find(|k| *k as u32 == v)
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Pending => "pending",
            Self::Running => "running",
            Self::Exited => "exited",
        }
    }
}

/// One process of a status reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::ProcessStatus.v1")]
pub struct ProcessStatus {
    /// UTF-8, zero-padded.
    pub name: [u8; STATUS_NAME_LEN],
    /// UTF-8, zero-padded.
    pub exec: [u8; STATUS_PATH_LEN],
    /// 0 when not running.
    pub pid: u32,
    /// A [`ProcessState`] as u32.
    pub state: u32,
    pub restarts: u32,
    pub _pad: u32,
    /// Since the current (or last) start; 0 when never started.
    pub uptime_ms: u64,
}

impl Default for ProcessStatus {
    fn default() -> Self {
        Self {
            name: [0; STATUS_NAME_LEN],
            exec: [0; STATUS_PATH_LEN],
            pid: 0,
            state: 0,
            restarts: 0,
            _pad: 0,
            uptime_ms: 0,
        }
    }
}

/// The supervisor's answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::ControlResponse.v1")]
pub struct ControlResponse {
    /// The [`ControlKind`] answered.
    pub kind: u32,
    /// 1 if the request was accepted.
    pub ok: u32,
    pub supervisor_pid: u32,
    pub process_count: u32,
    /// Since `agp up` started.
    pub uptime_ms: u64,
    pub processes: [ProcessStatus; MAX_STATUS_PROCESSES],
}

impl Default for ControlResponse {
    fn default() -> Self {
        Self {
            kind: 0,
            ok: 0,
            supervisor_pid: 0,
            process_count: 0,
            uptime_ms: 0,
            processes: [ProcessStatus::default(); MAX_STATUS_PROCESSES],
        }
    }
}

const _: () = {
    assert!(core::mem::size_of::<ControlRequest>() == 8);
    assert!(core::mem::size_of::<ProcessStatus>() == 312);
    assert!(core::mem::align_of::<ProcessStatus>() == 8);
    assert!(core::mem::size_of::<ControlResponse>() == 24 + 312 * MAX_STATUS_PROCESSES);
};

/// Writes `s` into a zero-padded byte field, cut at a character boundary with `...` when
/// it does not fit.
pub fn write_str(field: &mut [u8], s: &str) {
    field.fill(0);
    if s.len() <= field.len() {
        field[..s.len()].copy_from_slice(s.as_bytes());
        return;
    }
    let mut end = field.len().saturating_sub(3);
    while end > 0 && !s.is_char_boundary(end) {
        end -= 1;
    }
    field[..end].copy_from_slice(&s.as_bytes()[..end]);
    field[end..end + 3].copy_from_slice(b"...");
}

/// The text of a zero-padded byte field (invalid UTF-8 replaced).
pub fn read_str(field: &[u8]) -> String {
    let end = field.iter().position(|b| *b == 0).unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end]).into_owned()
}

/// The control service of an instance.
pub type ControlService =
    request_response::PortFactory<ipc::Service, ControlRequest, (), ControlResponse, ()>;

/// Why the control service could not be reached.
#[derive(Debug, thiserror::Error)]
pub enum ControlOpenError {
    #[error("the control service name is invalid")]
    Name,
    #[error("cannot create the control service: {0}")]
    Create(String),
    #[error("no supervisor answers on instance `{0}`")]
    NotRunning(String),
}

const CONTROL_SERVICE: &str = "agp/control";

impl Instance {
    /// Creates the control service (the supervisor, once per run).
    pub fn create_control(
        &self,
        node: &Node<ipc::Service>,
    ) -> Result<ControlService, ControlOpenError> {
        let name: ServiceName = CONTROL_SERVICE
            .try_into()
            .map_err(|_| ControlOpenError::Name)?;
        node.service_builder(&name)
            .request_response::<ControlRequest, ControlResponse>()
            .max_clients(8)
            .max_servers(1)
            .max_nodes(16)
            .create()
            .map_err(|e| ControlOpenError::Create(format!("{e:?}")))
    }

    /// Opens the control service of a running supervisor (a client).
    pub fn open_control(
        &self,
        node: &Node<ipc::Service>,
    ) -> Result<ControlService, ControlOpenError> {
        let name: ServiceName = CONTROL_SERVICE
            .try_into()
            .map_err(|_| ControlOpenError::Name)?;
        node.service_builder(&name)
            .request_response::<ControlRequest, ControlResponse>()
            .open()
            .map_err(|_| ControlOpenError::NotRunning(self.name().to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_name_is_cut_at_a_character_boundary_with_an_ellipsis() {
        let mut f = [0u8; 8];
        write_str(&mut f, "planner");
        assert_eq!(read_str(&f), "planner");
        write_str(&mut f, "ééééé");
        assert_eq!(read_str(&f), "éé...");
        write_str(&mut f, "abcdefghij");
        assert_eq!(read_str(&f), "abcde...");
    }
}
