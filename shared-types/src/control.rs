//! The payloads of the supervisor's control service: `agp status` and `agp down` ask the
//! running `agp up` of an instance through iceoryx2 request-response, never through files
//! or signals. `agp profile` holds a pause lease through it: the supervisor pauses the
//! pipeline until the lease's deadline, so a profiler that dies leaves it paused no longer
//! than that. The service itself and its client are `agp_runtime`'s.

use iceoryx2_bb_derive_macros::ZeroCopySend;

use crate::{Goal, Pose2};
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// Most processes a status reply lists.
pub const MAX_STATUS_PROCESSES: usize = 16;
/// Longest process name or executable path a status reply carries, bytes (longer ones
/// are cut at a character boundary and end in `...`).
pub const STATUS_NAME_LEN: usize = 32;
pub const STATUS_PATH_LEN: usize = 256;
/// Longest topic name of a status reply's message rate, bytes.
pub const STATUS_TOPIC_LEN: usize = 16;
/// Room for a swap's planner arguments, NUL-separated, bytes.
pub const SWAP_ARGS_LEN: usize = 1024;
/// Most strangers (live nodes of the instance the supervisor did not start) a status reply
/// names.
pub const MAX_STATUS_STRANGERS: usize = 8;
/// Longest node name a status reply carries for a stranger, bytes.
pub const STATUS_NODE_NAME_LEN: usize = 64;
/// Longest pause lease the supervisor grants at once; a holder that needs longer renews.
pub const MAX_PAUSE_LEASE: std::time::Duration = std::time::Duration::from_secs(60);

/// What the client asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ControlKind {
    /// Each process's state.
    Status = 1,
    /// Stop every process, clean the instance, end `agp up`.
    Down = 2,
    /// Hot-swap the planner (`exec` and `args` of the request; empty: the same again).
    SwapPlanner = 3,
    /// From a planner started for a swap: it has its inputs and will drive at `epoch`.
    Ready = 4,
    /// From a swapped-in planner: its first command was applied, `value_ns` after its
    /// `Ready` (the handover time).
    Driving = 5,
    /// Pause the pipeline's processes (SIGSTOP to each one's process group) for `value_ns`
    /// from now (at most [`MAX_PAUSE_LEASE`]): a lease held by `pid`. Asked again by its
    /// holder, it renews the deadline. The supervisor resumes them (SIGCONT) at the
    /// deadline, on [`ControlKind::Resume`] or at the end of the run, whichever comes first.
    Pause = 6,
    /// Release the pause lease held by `pid`: the processes run again.
    Resume = 7,
    /// Queue `goal` (its id is set by the supervisor) for the session's serving planner
    /// (`agp goal`).
    Goal = 8,
    /// From the serving planner: goal `goal.id` ended, as `name` says (`done`, `lost`, ...);
    /// the supervisor judges it by ground truth before it answers.
    GoalDone = 9,
}

impl ControlKind {
    pub fn from_u32(v: u32) -> Option<Self> {
        [
            Self::Status,
            Self::Down,
            Self::SwapPlanner,
            Self::Ready,
            Self::Driving,
            Self::Pause,
            Self::Resume,
            Self::Goal,
            Self::GoalDone,
        ]
        .into_iter()
        .find(|k| *k as u32 == v)
    }
}

/// A request to the supervisor.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::ControlRequest.v2")]
pub struct ControlRequest {
    /// A [`ControlKind`] as u32.
    pub kind: u32,
    /// [`ControlKind::Pause`], [`ControlKind::Resume`]: the lease holder's process id.
    pub pid: u32,
    /// [`ControlKind::Ready`], [`ControlKind::Driving`]: the planner's epoch.
    pub epoch: u64,
    /// [`ControlKind::Driving`]: the handover time; [`ControlKind::SwapPlanner`]: how
    /// long the new planner may take to become ready and drive (0: the default);
    /// [`ControlKind::Pause`]: how long the lease lasts from now.
    pub value_ns: u64,
    /// [`ControlKind::SwapPlanner`]: the process to swap (UTF-8, zero-padded).
    pub name: [u8; STATUS_NAME_LEN],
    /// [`ControlKind::SwapPlanner`]: the new planner's executable (UTF-8, zero-padded;
    /// empty: the launch file's).
    pub exec: [u8; STATUS_PATH_LEN],
    /// [`ControlKind::SwapPlanner`]: its arguments, each ended by a NUL.
    pub args: [u8; SWAP_ARGS_LEN],
    /// 0 keeps the launch file's arguments; otherwise the number of arguments + 1.
    pub args_set: u32,
    pub _pad2: u32,
    /// [`ControlKind::Goal`]: the goal to queue; [`ControlKind::GoalDone`]: the goal that
    /// ended (its id).
    pub goal: Goal,
}

impl Default for ControlRequest {
    fn default() -> Self {
        Self {
            kind: 0,
            pid: 0,
            epoch: 0,
            value_ns: 0,
            name: [0; STATUS_NAME_LEN],
            exec: [0; STATUS_PATH_LEN],
            args: [0; SWAP_ARGS_LEN],
            args_set: 0,
            _pad2: 0,
            goal: Goal::default(),
        }
    }
}

impl ControlRequest {
    pub fn new(kind: ControlKind) -> Self {
        Self {
            kind: kind as u32,
            ..Self::default()
        }
    }

    /// Stores `args` NUL-separated; `false` if they do not fit (or hold a NUL).
    pub fn set_args(&mut self, args: &[String]) -> bool {
        let total: usize = args.iter().map(|a| a.len() + 1).sum();
        if total > SWAP_ARGS_LEN || args.iter().any(|a| a.contains('\0')) {
            return false;
        }
        self.args.fill(0);
        let mut at = 0;
        for a in args {
            self.args[at..at + a.len()].copy_from_slice(a.as_bytes());
            at += a.len() + 1;
        }
        self.args_set = u32::try_from(args.len() + 1).unwrap_or(u32::MAX);
        true
    }

    /// The arguments, if the request sets them.
    pub fn get_args(&self) -> Option<Vec<String>> {
        let n = (self.args_set as usize).checked_sub(1)?;
        Some(
            self.args
                .split(|b| *b == 0)
                .take(n)
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect(),
        )
    }
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
#[type_name("agp::ProcessStatus.v2")]
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
    /// The planner epoch it runs at (`AGP_EPOCH`).
    pub epoch: u64,
    /// Messages per second it publishes on `rate_topic`, times 1000 (0: not measured).
    pub rate_mhz: u64,
    /// The topic of `rate_mhz` (UTF-8, zero-padded; empty: none).
    pub rate_topic: [u8; STATUS_TOPIC_LEN],
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
            epoch: 0,
            rate_mhz: 0,
            rate_topic: [0; STATUS_TOPIC_LEN],
        }
    }
}

/// A live node of the instance that is neither the supervisor's nor one of its
/// processes' nor a client's (`agp status`, `agp profile`): a process that joined the
/// instance on its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::StrangerStatus.v1")]
pub struct StrangerStatus {
    pub pid: u32,
    pub _pad: u32,
    /// The node's name (UTF-8, zero-padded; empty: the node has none).
    pub name: [u8; STATUS_NODE_NAME_LEN],
}

impl Default for StrangerStatus {
    fn default() -> Self {
        Self {
            pid: 0,
            _pad: 0,
            name: [0; STATUS_NODE_NAME_LEN],
        }
    }
}

/// Most goals a status reply lists: the latest ones.
pub const MAX_STATUS_GOALS: usize = 16;

/// Where a goal of a live session stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum GoalState {
    /// Waiting for the goals queued before it.
    Queued = 0,
    /// The serving planner pursues it.
    Pursued = 1,
    /// Ended and judged.
    Done = 2,
}

impl GoalState {
    pub fn from_u32(v: u32) -> Option<Self> {
        [Self::Queued, Self::Pursued, Self::Done]
            .into_iter()
            .find(|k| *k as u32 == v)
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Queued => "queued",
            Self::Pursued => "pursued",
            Self::Done => "done",
        }
    }
}

/// One goal of a live session in a status reply. Errors are NaN until it is judged.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::GoalStatus.v1")]
pub struct GoalStatus {
    pub id: u64,
    /// A [`GoalState`] as u32.
    pub state: u32,
    /// A [`crate::TaskKind`] as u32.
    pub kind: u32,
    /// Place: the goal pose; trajectory: the path's end (theta 0).
    pub target: Pose2,
    /// Points of a trajectory's path (0 for a placement).
    pub path_len: u32,
    /// 1 if the judge says the goal was reached (place: within the tolerance; trajectory:
    /// the path's end reached).
    pub success: u32,
    /// The judge's final errors: place, from the goal (mm, deg); trajectory, from the
    /// path's end (mm) and the mean distance to the path (mm, in `mean_path_error_mm`).
    pub position_error_mm: f64,
    pub orientation_error_deg: f64,
    pub mean_path_error_mm: f64,
    /// The last estimate against the final true pose (mm, deg; NaN: none valid).
    pub estimate_position_error_mm: f64,
    pub estimate_orientation_error_deg: f64,
    /// Simulated seconds from its start to its end (NaN until done).
    pub sim_time_s: f64,
    /// How the planner says it ended (`done`, `lost`, `max_pushes`, ...; UTF-8,
    /// zero-padded; empty until done).
    pub end: [u8; STATUS_TOPIC_LEN],
}

impl Default for GoalStatus {
    fn default() -> Self {
        Self {
            id: 0,
            state: 0,
            kind: 0,
            target: Pose2::default(),
            path_len: 0,
            success: 0,
            position_error_mm: f64::NAN,
            orientation_error_deg: f64::NAN,
            mean_path_error_mm: f64::NAN,
            estimate_position_error_mm: f64::NAN,
            estimate_orientation_error_deg: f64::NAN,
            sim_time_s: f64::NAN,
            end: [0; STATUS_TOPIC_LEN],
        }
    }
}

/// The supervisor's answer.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::ControlResponse.v5")]
pub struct ControlResponse {
    /// The [`ControlKind`] answered.
    pub kind: u32,
    /// 1 if the request was accepted.
    pub ok: u32,
    pub supervisor_pid: u32,
    pub process_count: u32,
    /// Since `agp up` started.
    pub uptime_ms: u64,
    /// The epoch of the planner that drives.
    pub active_epoch: u64,
    /// Swap: the new planner's ready -> its epoch active, ns (0 if not swapped).
    pub handover_ns: u64,
    /// Why a request was refused (UTF-8, zero-padded).
    pub message: [u8; STATUS_PATH_LEN],
    /// How the instance's processes wait for messages (`AGP_WAIT`, as
    /// `agp_runtime::WaitStrategy::name` writes it), or `mixed` when launch.toml gives its
    /// processes different ones (UTF-8, zero-padded).
    pub waiting: [u8; STATUS_NAME_LEN],
    pub processes: [ProcessStatus; MAX_STATUS_PROCESSES],
    /// Processes paused by a pause lease now (0: none).
    pub paused: u32,
    /// How many entries of `strangers` are set.
    pub stranger_count: u32,
    /// Time left of the pause lease, ms (0: no lease).
    pub pause_left_ms: u64,
    /// [`ControlKind::Status`]: the strangers on the instance.
    pub strangers: [StrangerStatus; MAX_STATUS_STRANGERS],
    /// [`ControlKind::Goal`]: the id of the goal queued.
    pub goal_id: u64,
    /// Goals queued to this session so far; the latest `goal_count` of them are in
    /// `goals`, oldest first.
    pub goals_total: u32,
    pub goal_count: u32,
    pub goals: [GoalStatus; MAX_STATUS_GOALS],
}

impl Default for ControlResponse {
    fn default() -> Self {
        Self {
            kind: 0,
            ok: 0,
            supervisor_pid: 0,
            process_count: 0,
            uptime_ms: 0,
            active_epoch: 0,
            handover_ns: 0,
            message: [0; STATUS_PATH_LEN],
            waiting: [0; STATUS_NAME_LEN],
            processes: [ProcessStatus::default(); MAX_STATUS_PROCESSES],
            paused: 0,
            stranger_count: 0,
            pause_left_ms: 0,
            strangers: [StrangerStatus::default(); MAX_STATUS_STRANGERS],
            goal_id: 0,
            goals_total: 0,
            goal_count: 0,
            goals: [GoalStatus::default(); MAX_STATUS_GOALS],
        }
    }
}

const _: () = {
    assert!(
        core::mem::size_of::<ControlRequest>()
            == 24 + 32 + 256 + 1024 + 8 + core::mem::size_of::<Goal>()
    );
    assert!(core::mem::size_of::<GoalStatus>() == 16 + 24 + 8 + 48 + STATUS_TOPIC_LEN);
    assert!(core::mem::size_of::<ActiveEpoch>() == 16);
    assert!(core::mem::size_of::<ProcessStatus>() == 344);
    assert!(core::mem::align_of::<ProcessStatus>() == 8);
    assert!(core::mem::size_of::<StrangerStatus>() == 8 + STATUS_NODE_NAME_LEN);
    assert!(
        core::mem::size_of::<ControlResponse>()
            == 24
                + 16
                + 256
                + 32
                + 344 * MAX_STATUS_PROCESSES
                + 16
                + (8 + STATUS_NODE_NAME_LEN) * MAX_STATUS_STRANGERS
                + 16
                + core::mem::size_of::<GoalStatus>() * MAX_STATUS_GOALS
    );
};

/// Which planner drives: physics applies only motor commands of this epoch. Published by
/// the supervisor (latched: a late subscriber gets it at once); the flip of a hot swap.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
#[type_name("agp::ActiveEpoch.v1")]
pub struct ActiveEpoch {
    pub epoch: u64,
    /// Bumped with every publication.
    pub seq: u64,
}

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

#[cfg(test)]
mod request_tests {
    use super::*;

    #[test]
    fn swap_arguments_round_trip_and_none_differs_from_empty() {
        let mut r = ControlRequest::new(ControlKind::SwapPlanner);
        assert_eq!(r.get_args(), None);
        assert!(r.set_args(&[]));
        assert_eq!(r.get_args(), Some(vec![]));
        let args = vec!["--mode".to_owned(), "script".to_owned(), String::new()];
        assert!(r.set_args(&args));
        assert_eq!(r.get_args(), Some(args));
        assert!(!r.set_args(&["x".repeat(SWAP_ARGS_LEN)]));
    }
}
