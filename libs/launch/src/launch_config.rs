//! `launch.toml`: what `agp up` runs and how, parsed and validated whole before anything
//! starts.
//!
//! ```toml
//! instance = "default"          # iceoryx2 prefix `agp_default_`, root `/tmp/agp/default/`
//! scenario = "triangle"         # a built-in name, or a scenario file (relative: to this file)
//! results = "results"           # folder (relative: to this file); default "results"
//!
//! [clock]
//! mode = "lockstep"             # "lockstep" (default) or "realtime"
//! rate_hz = 640                 # physics steps per second; default 640
//!
//! [[process]]
//! name = "physics"              # unique; letters, digits, `-`, `_`
//! exec = "agp-physics"          # a binary next to `agp`, or a path (relative: to this file)
//! args = ["--seed", "7"]        # default []
//! env = { RUST_LOG = "info" }   # default {}; the `AGP_*` context variables are reserved
//! restart = { policy = "on-failure", max_restarts = 3, backoff_ms = 200 }
//! ends_run = false              # exiting with status 0 ends the run; default false
//! stop_grace_ms = 3000          # SIGTERM -> SIGKILL delay when stopping; default 3000
//! ```
//!
//! A process that runs under another supervisor (on another computer, or another instance
//! of this one) is named with `remote` instead of `exec`: `agp up` runs `agp bridge` in its
//! place, which forwards this instance's topics to the far end over Zenoh and back, with the
//! slot's epoch and token; the far supervisor runs the process itself.
//!
//! ```toml
//! [[process]]
//! name = "planner"              # the planner runs under another supervisor
//! remote = { role = "planner", listen = "tls/127.0.0.1:7447", tls = "keys" }
//! ends_run = true               # the far end stopping ends this run too
//! ```
//!
//! `role` is what the remote process is: `planner` (this instance runs physics and the
//! estimator: the bridge's robot side) or `robot` (the far instance runs them: the bridge's
//! planner side). One of `listen` and `connect` (`tls/HOST:PORT`); `tls`, the link's key
//! folder made by `agp bridge keygen DIR` (relative: to this file; its private key must be
//! 0600 and this user's), or `insecure = true` for a `tcp/HOST:PORT` endpoint (plain TCP: no
//! authentication, no encryption), and nothing else starts a remote; optional `topics` (the
//! topics carried, default all) and `link` (the Zenoh key prefix both ends share, default
//! `agp`).
//!
//! `view = true` (top level) also runs `agp view` on the instance, a Foxglove WebSocket
//! server on port 8765 (`view = PORT` for another port, 0 for any free one), as a process
//! named `view` after the others.
//!
//! `learn = "online"` (top level; default `"first"`) places an object never pushed before:
//! no learning phase and no AG file; the estimator builds the contact prior from the task's
//! first circling and learns on from its pushes (see [`LearnMode`]). The plan gives the
//! `agp-estimator` and `agp-planner` processes their flags for it.
//!
//! `record = "FILE.mcap"` (top level; relative: to this file) also records every topic of
//! the instance into FILE with `agp record`, as a process named `recorder` started before
//! the others (so it has subscribed when physics publishes), stopped with them.
//!
//! Every number has a limit, named when it is passed: `rate_hz` from 1 to 100000
//! (`RATE_HZ_RANGE`), `max_restarts` at most 1000, `backoff_ms` and `stop_grace_ms` at
//! most 60000, at most 32 processes of at most 256 arguments of 4096 bytes. The file and its
//! scenario are read only if they are regular files of at most 1 MiB.
//!
//! Every fault is reported with the file, the 1-based line and what is wrong:
//! ``launch.toml:12: unknown policy `sometimes`; expected `never`, `on-failure` or `always` ``.

use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Duration;

use agp_shared_types::{InstanceNameError, ROOT_ENV, WaitStrategy, validate_instance_name};
use serde::Deserialize;
use toml::Spanned;

pub use crate::learn_mode::LearnMode;

/// Names `scenario` may take without being a file.
pub use agp_world::BUILTIN_NAMES as BUILTIN_SCENARIOS;

pub use agp_shared_types::DEFAULT_RATE_HZ;

/// Default delay between SIGTERM and SIGKILL when a process is stopped.
pub const DEFAULT_STOP_GRACE: Duration = Duration::from_secs(3);

/// Slowest and fastest physics rate a launch file may ask for, steps per second.
pub const RATE_HZ_RANGE: (f64, f64) = (1.0, 100_000.0);
/// Most restarts a process may be allowed over a run.
pub const MAX_RESTARTS_LIMIT: u32 = 1000;
/// Longest `backoff_ms` and `stop_grace_ms`, milliseconds.
pub const MAX_DELAY_MS: u64 = 60_000;
/// Most `[[process]]` entries a launch file may hold.
pub const MAX_PROCESSES: usize = 32;
/// Most `args` and most `env` entries of a process.
pub const MAX_ARGS: usize = 256;
/// Longest argument, `env` key or `env` value, bytes.
pub const MAX_ARG_BYTES: usize = 4096;

/// The environment variables `agp up` gives every child; a launch file may not set them.
pub const CONTEXT_ENV: [&str; 6] = [
    "AGP_INSTANCE",
    "AGP_SCENARIO",
    "AGP_CLOCK",
    "AGP_RATE_HZ",
    "AGP_RESULTS",
    "AGP_PROCESS",
];

/// A validated launch file: every path absolute, every executable found.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchConfig {
    /// The launch file, as it was named.
    pub file: PathBuf,
    /// The instance name (from the file or the override), valid for `agp_runtime::Instance::new`.
    pub instance: String,
    pub scenario: ScenarioSource,
    /// Absolute folder where results go (not created by parsing).
    pub results: PathBuf,
    pub clock: ClockConfig,
    /// The processes, in the order they start.
    pub processes: Vec<ProcessConfig>,
    /// `record = "FILE"`: the recording's absolute path (its `recorder` process is the
    /// first of `processes`).
    pub record: Option<PathBuf>,
    /// `learn`: where the object's gradient comes from; `online` has given the processes
    /// their flags already.
    pub learn: LearnMode,
}

/// Where the scenario comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScenarioSource {
    /// One of [`BUILTIN_SCENARIOS`].
    Builtin(String),
    /// An existing file, absolute.
    File(PathBuf),
}

impl ScenarioSource {
    /// The value of `AGP_SCENARIO`: the built-in name or the absolute path.
    pub fn env_value(&self) -> OsString {
        match self {
            Self::Builtin(name) => OsString::from(name),
            Self::File(path) => path.clone().into_os_string(),
        }
    }
}

impl std::fmt::Display for ScenarioSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Builtin(name) => write!(f, "{name}"),
            Self::File(path) => write!(f, "{}", path.display()),
        }
    }
}

/// How simulated time advances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockConfig {
    pub mode: ClockMode,
    /// Physics steps per second, finite and positive.
    pub rate_hz: f64,
}

/// The clock modes of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockMode {
    /// Physics steps only when the command for the step has arrived: reproducible.
    Lockstep,
    /// Physics steps at `rate_hz` on the wall clock.
    Realtime,
}

impl ClockMode {
    /// The name used in the file and in `AGP_CLOCK`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Lockstep => "lockstep",
            Self::Realtime => "realtime",
        }
    }
}

/// One `[[process]]` entry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProcessConfig {
    /// Unique within the file; also the child's `AGP_PROCESS`.
    pub name: String,
    /// Absolute path of an existing executable file.
    pub exec: PathBuf,
    pub args: Vec<String>,
    /// Variables set on top of the supervisor's environment (never an `AGP_*` context one).
    pub env: BTreeMap<String, String>,
    pub restart: RestartConfig,
    /// Whether this process exiting with status 0 ends the run.
    pub ends_run: bool,
    /// Delay between SIGTERM and SIGKILL when the supervisor stops this process.
    pub stop_grace: Duration,
    /// 1-based line of its `name` in the launch file.
    pub line: usize,
}

/// What happens when a process exits on its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RestartConfig {
    pub policy: RestartPolicy,
    /// Restarts allowed over the whole run; one more exit that would restart fails the run.
    pub max_restarts: u32,
    /// Delay before the first restart; doubled for each further one (see
    /// [`RestartConfig::delay_before`]).
    pub backoff: Duration,
}

/// Longest delay between an exit and its restart, whatever the backoff doubling reaches.
pub const MAX_RESTART_DELAY: Duration = Duration::from_secs(10);

impl Default for RestartConfig {
    fn default() -> Self {
        Self {
            policy: RestartPolicy::Never,
            max_restarts: 3,
            backoff: Duration::from_millis(200),
        }
    }
}

impl ProcessConfig {
    /// Whether this process is an agp bridge ([`is_bridge`]).
    pub fn is_bridge(&self) -> bool {
        is_bridge(&self.exec, &self.args)
    }

    /// The side a bridge serves ([`bridge_side`]); `None` for any other process.
    pub fn bridge_side(&self) -> Option<&str> {
        bridge_side(&self.exec, &self.args)
    }
}

/// Whether the command `exec args` runs an agp bridge: `agp bridge ...` (what a `remote`
/// process becomes; `agp` then execs `agp-bridge` beside it) or `agp-bridge ...` written out.
/// A process swapped in with another command is asked with that command.
pub fn is_bridge(exec: &Path, args: &[String]) -> bool {
    match exec.file_name().and_then(|n| n.to_str()) {
        Some("agp") => args.first().is_some_and(|a| a == "bridge"),
        Some("agp-bridge") => true,
        _ => false,
    }
}

/// The side (`robot` or `planner`, as its `--side` says) of the bridge `exec args` runs;
/// `None` when it runs no bridge, or one without a side (`keygen`, `floor`).
pub fn bridge_side<'a>(exec: &Path, args: &'a [String]) -> Option<&'a str> {
    if !is_bridge(exec, args) {
        return None;
    }
    args.windows(2)
        .find(|w| w[0] == "--side")
        .map(|w| w[1].as_str())
}

/// When a process is restarted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestartPolicy {
    /// Never: an exit with status 0 is fine, any other exit fails the run.
    Never,
    /// After an exit with a non-zero status or by a signal; an exit with status 0 is fine.
    OnFailure,
    /// After any exit.
    Always,
}

impl RestartPolicy {
    /// The name used in the file.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Never => "never",
            Self::OnFailure => "on-failure",
            Self::Always => "always",
        }
    }
}

/// What the supervisor does after a process exited on its own (not stopped by the supervisor).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitDecision {
    /// The process is done; the run goes on without it.
    Done,
    /// Start it again after `delay`; this is restart number `nth` (1-based).
    Restart { nth: u32, delay: Duration },
    /// The process failed past its policy: stop the run.
    FailRun,
}

impl RestartConfig {
    /// Delay before restart number `nth` (1-based): `backoff × 2^(nth-1)`, at most
    /// [`MAX_RESTART_DELAY`].
    pub fn delay_before(&self, nth: u32) -> Duration {
        let factor = 1u32.checked_shl(nth.saturating_sub(1)).unwrap_or(u32::MAX);
        self.backoff
            .checked_mul(factor)
            .unwrap_or(MAX_RESTART_DELAY)
            .min(MAX_RESTART_DELAY)
    }

    /// Applies the policy to an exit: `success` is whether it exited with status 0,
    /// `restarts_so_far` how many times the process was already restarted in this run.
    pub fn decide(&self, success: bool, restarts_so_far: u32) -> ExitDecision {
        let wants_restart = match self.policy {
            RestartPolicy::Never => false,
            RestartPolicy::OnFailure => !success,
            RestartPolicy::Always => true,
        };
        if !wants_restart {
            return if success {
                ExitDecision::Done
            } else {
                ExitDecision::FailRun
            };
        }
        if restarts_so_far >= self.max_restarts {
            return ExitDecision::FailRun;
        }
        let nth = restarts_so_far + 1;
        ExitDecision::Restart {
            nth,
            delay: self.delay_before(nth),
        }
    }
}

/// What parsing needs besides the file.
#[derive(Debug, Clone, Default)]
pub struct LaunchOptions {
    /// Replaces the file's `instance` (`agp up --instance`).
    pub instance: Option<String>,
    /// Folder where bare executable names (`exec = "agp-physics"`) are looked up: the
    /// folder of the running `agp`.
    pub exe_dir: PathBuf,
    /// The bridge's own checks of a `remote` entry's endpoint, topics and keys; `None`
    /// checks a `remote` entry's shape only.
    pub remote_checks: Option<RemoteChecks>,
}

/// The checks of a `remote` entry that belong to the bridge (`agp-bridge`, which carries
/// zenoh and iceoryx2): the caller hands them in, so parsing a launch file stays pure.
/// Each returns the reason a value is refused, as the bridge words it.
#[derive(Debug, Clone, Copy)]
pub struct RemoteChecks {
    /// An endpoint, `tls/HOST:PORT` or `tcp/HOST:PORT`.
    pub endpoint: fn(&str) -> Result<(), String>,
    /// A list of topics: `all` or names joined by `,`.
    pub topics: fn(&str) -> Result<(), String>,
    /// The keys of side `side` (`robot` or `planner`) in the key folder `dir`.
    pub keys: fn(dir: &Path, side: &str) -> Result<(), String>,
    /// What an endpoint lacks, given whether the link's keys were given.
    pub security_fault: fn(endpoint: &str, tls: bool) -> Option<String>,
}

/// Why a launch file was refused: every fault found, so the user fixes them in one go.
#[derive(Debug, thiserror::Error)]
#[error("{}", self.render())]
pub struct LaunchConfigParseError {
    /// The launch file, as it was named.
    pub file: PathBuf,
    /// At least one fault, in the order of the file.
    pub faults: Vec<LaunchFault>,
}

impl LaunchConfigParseError {
    fn render(&self) -> String {
        let mut out = String::new();
        for (i, fault) in self.faults.iter().enumerate() {
            if i > 0 {
                out.push('\n');
            }
            out.push_str(&self.file.display().to_string());
            if let Some(line) = fault.line {
                out.push_str(&format!(":{line}"));
            }
            out.push_str(&format!(": {}", fault.kind));
        }
        out
    }
}

/// One thing wrong in a launch file, and where.
#[derive(Debug)]
pub struct LaunchFault {
    /// 1-based line, when the fault has a place in the file.
    pub line: Option<usize>,
    pub kind: LaunchFaultKind,
}

/// The kinds of fault a launch file can hold.
#[derive(Debug, thiserror::Error)]
pub enum LaunchFaultKind {
    /// The file could not be read.
    #[error("cannot read the launch file: {0}")]
    Read(#[source] agp_world::BoundedReadError),
    /// Not TOML, an unknown key, a missing key or a value of the wrong type (toml's words).
    #[error("{0}")]
    Toml(String),
    /// Neither the file nor `--instance` names the instance.
    #[error("no instance name: set `instance = \"NAME\"` or pass `--instance NAME`")]
    NoInstance,
    /// The instance name cannot build an iceoryx2 config.
    #[error("bad instance name `{name}`{from}: {reason}", from = if *.from_cli { " (from --instance)" } else { "" })]
    BadInstanceName {
        name: String,
        from_cli: bool,
        reason: InstanceNameError,
    },
    /// `scenario` is neither a built-in name nor an existing file.
    #[error(
        "scenario `{name}` is neither a built-in ({builtins}) nor an existing file (looked for {})",
        looked_at.display(),
        builtins = BUILTIN_SCENARIOS.join(", ")
    )]
    UnknownScenario { name: String, looked_at: PathBuf },
    /// The scenario file exists but is not a valid scenario (the message names its line).
    #[error("scenario `{name}` is refused: {reason}")]
    BadScenario { name: String, reason: String },
    /// `clock.mode` is not a clock mode.
    #[error("unknown clock mode `{0}`; expected `lockstep` or `realtime`")]
    UnknownClockMode(String),
    /// `clock.rate_hz` is not within `RATE_HZ_RANGE`.
    #[error(
        "`rate_hz` must be a positive number of steps per second from {lo} to {hi}, got {0}",
        lo = RATE_HZ_RANGE.0,
        hi = RATE_HZ_RANGE.1
    )]
    BadRate(f64),
    /// A number or a list beyond its limit.
    #[error("`{key}` must be {limit}, got {value}")]
    OutOfBounds {
        key: &'static str,
        limit: String,
        value: String,
    },
    /// No `[[process]]` entry.
    #[error("no `[[process]]` entry: a launch file starts at least one process")]
    NoProcess,
    /// A process name is empty or holds a character other than letters, digits, `-`, `_`.
    #[error("bad process name `{0}`; use letters, digits, `-` and `_`")]
    BadProcessName(String),
    /// Two processes share a name.
    #[error("duplicate process name `{name}` (first at line {first_line})")]
    DuplicateProcess { name: String, first_line: usize },
    /// `exec` names nothing runnable.
    #[error("process `{process}`: no executable `{exec}` (looked for {})", looked_at.display())]
    MissingExecutable {
        process: String,
        exec: String,
        looked_at: PathBuf,
    },
    /// A `remote` process is ill-formed: its role, endpoint, topics or link, or it also
    /// names `exec` or `args`, or a process names neither `exec` nor `remote`.
    #[error("process `{process}`: {reason}")]
    BadRemote { process: String, reason: String },
    /// An agp process refused its arguments with the launch file's clock (its own
    /// `--check`).
    #[error("process `{process}`: {reason}")]
    ProcessRefused { process: String, reason: String },
    /// `learn` is not a learn mode.
    #[error(
        "unknown learn mode `{0}`; expected `first` (learn the gradient first, or load its AG file) or `online` (an object never pushed: learn it from the task's own pushes)"
    )]
    UnknownLearnMode(String),
    /// `learn = "online"` cannot run with these processes.
    #[error("{}{reason}", .process.as_ref().map_or(String::new(), |p| format!("process `{p}`: ")))]
    LearnConflict {
        process: Option<String>,
        reason: String,
    },
    /// `restart.policy` is not a policy.
    #[error("unknown policy `{0}`; expected `never`, `on-failure` or `always`")]
    UnknownPolicy(String),
    /// An `env` key is reserved or cannot be a variable name.
    #[error("process `{process}`: cannot set `{key}` in `env`: {why}")]
    BadEnv {
        process: String,
        key: String,
        why: &'static str,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaunch {
    instance: Option<Spanned<String>>,
    scenario: Spanned<String>,
    results: Option<String>,
    clock: Option<RawClock>,
    #[serde(default)]
    process: Vec<Spanned<RawProcess>>,
    record: Option<Spanned<String>>,
    view: Option<Spanned<RawView>>,
    learn: Option<Spanned<String>>,
}

/// `view = true | false | PORT`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum RawView {
    On(bool),
    Port(i64),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawClock {
    mode: Option<Spanned<String>>,
    rate_hz: Option<Spanned<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProcess {
    name: Spanned<String>,
    exec: Option<Spanned<String>>,
    remote: Option<Spanned<RawRemote>>,
    args: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    env: BTreeMap<Spanned<String>, String>,
    restart: Option<RawRestart>,
    #[serde(default)]
    ends_run: bool,
    stop_grace_ms: Option<Spanned<u64>>,
}

/// `remote = { role = "planner" | "robot", listen | connect = "tls/HOST:PORT", tls = "DIR",
/// topics = [..], link = ".." }` (or `tcp/HOST:PORT` with `insecure = true`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRemote {
    role: String,
    listen: Option<String>,
    connect: Option<String>,
    topics: Option<Vec<String>>,
    link: Option<String>,
    tls: Option<String>,
    insecure: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRestart {
    policy: Option<Spanned<String>>,
    max_restarts: Option<Spanned<u32>>,
    backoff_ms: Option<Spanned<u64>>,
}

/// Collects faults while the whole file is checked.
struct Checker<'a> {
    text: &'a str,
    remote: Option<&'a RemoteChecks>,
    faults: Vec<LaunchFault>,
}

impl Checker<'_> {
    fn line_of(&self, span: &std::ops::Range<usize>) -> usize {
        line_at(self.text, span.start)
    }

    fn fault_at<T>(&mut self, at: &Spanned<T>, kind: LaunchFaultKind) {
        let line = Some(self.line_of(&at.span()));
        self.faults.push(LaunchFault { line, kind });
    }

    fn fault(&mut self, kind: LaunchFaultKind) {
        self.faults.push(LaunchFault { line: None, kind });
    }
}

/// 1-based line of byte `offset` in `text`.
fn line_at(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

impl LaunchConfig {
    /// Whether the planner runs under another supervisor, reached through this instance's
    /// bridge (a `remote = { role = "planner", ... }` process, or an `agp bridge --side
    /// robot` written out): the judge here then has a task only if the far planner sent one.
    pub fn planner_is_remote(&self) -> bool {
        self.processes
            .iter()
            .any(|p| p.bridge_side() == Some("robot"))
    }

    /// Whether physics and the estimator run under another supervisor, reached through this
    /// instance's bridge (a `remote = { role = "robot", ... }` process, or an `agp bridge
    /// --side planner` written out): that supervisor runs the judge beside physics and owns
    /// a live session's goals, and this one relays the goals its planner ends to it.
    pub fn robot_is_remote(&self) -> bool {
        self.processes
            .iter()
            .any(|p| p.bridge_side() == Some("planner"))
    }

    /// Reads and validates the launch file at `path`: a regular file (a FIFO or a link to
    /// a device is refused without blocking) of at most
    /// [`agp_world::MAX_CONFIG_FILE_BYTES`].
    pub fn load(path: &Path, options: &LaunchOptions) -> Result<Self, LaunchConfigParseError> {
        match agp_world::read_regular_text(path, agp_world::MAX_CONFIG_FILE_BYTES) {
            Ok(text) => Self::parse(&text, path, options),
            Err(e) => Err(LaunchConfigParseError {
                file: agp_world::lexically_normal(path),
                faults: vec![LaunchFault {
                    line: None,
                    kind: LaunchFaultKind::Read(e),
                }],
            }),
        }
    }

    /// Validates the text of the launch file `file`: `file` names it in faults, and its
    /// folder anchors relative paths. Touches nothing but the file system's metadata.
    pub fn parse(
        text: &str,
        file: &Path,
        options: &LaunchOptions,
    ) -> Result<Self, LaunchConfigParseError> {
        let refuse = |faults| LaunchConfigParseError {
            file: agp_world::lexically_normal(file),
            faults,
        };
        let raw: RawLaunch = toml::from_str(text).map_err(|e| {
            refuse(vec![LaunchFault {
                line: e.span().map(|s| line_at(text, s.start)),
                kind: LaunchFaultKind::Toml(e.message().trim_end().to_owned()),
            }])
        })?;
        let base = std::path::absolute(file)
            .ok()
            .and_then(|f| f.parent().map(agp_world::lexically_normal))
            .unwrap_or_default();
        let mut check = Checker {
            text,
            remote: options.remote_checks.as_ref(),
            faults: Vec::new(),
        };

        let instance = resolve_instance(&mut check, options, &raw);

        let scenario = resolve_scenario(&mut check, &raw.scenario, &base);
        let results =
            agp_world::lexically_normal(&base.join(raw.results.as_deref().unwrap_or("results")));
        let clock = resolve_clock(&mut check, raw.clock.as_ref());

        let (mut processes, first_lines) =
            resolve_processes(&mut check, &raw, &base, &options.exe_dir);

        if let Some(view) = &raw.view
            && let Some(p) = view_process(&mut check, view, &instance, &options.exe_dir)
        {
            if let Some(&first_line) = first_lines.get(&p.name) {
                check.fault_at(
                    view,
                    LaunchFaultKind::DuplicateProcess {
                        name: p.name.clone(),
                        first_line,
                    },
                );
            }
            processes.push(p);
        }

        let mut record = None;
        if let Some(raw_record) = &raw.record {
            let p = record_process(
                &mut check,
                raw_record,
                file,
                &base,
                &processes,
                &options.exe_dir,
            );
            if let Some(&first_line) = first_lines.get(&p.name) {
                check.fault_at(
                    raw_record,
                    LaunchFaultKind::DuplicateProcess {
                        name: p.name.clone(),
                        first_line,
                    },
                );
            }
            record = Some(agp_world::lexically_normal(&base.join(raw_record.as_ref())));
            processes.insert(0, p);
        }

        let learn = match &raw.learn {
            None => LearnMode::default(),
            Some(word) => match LearnMode::from_word(word.get_ref().as_str()) {
                Some(mode) => mode,
                None => {
                    check.fault_at(
                        word,
                        LaunchFaultKind::UnknownLearnMode(word.get_ref().clone()),
                    );
                    LearnMode::default()
                }
            },
        };
        for c in crate::learn_mode::apply(learn, &mut processes) {
            let kind = LaunchFaultKind::LearnConflict {
                process: c.process,
                reason: c.reason,
            };
            match &raw.learn {
                Some(word) => check.fault_at(word, kind),
                None => check.fault(kind),
            }
        }

        if !check.faults.is_empty() {
            check.faults.sort_by_key(|f| f.line.unwrap_or(0));
            return Err(refuse(check.faults));
        }
        Ok(Self {
            file: file.to_owned(),
            instance,
            scenario,
            results,
            clock,
            processes,
            record,
            learn,
        })
    }

    /// How the processes wait for messages: each one's `AGP_WAIT` from its `env`, else
    /// the supervisor's own (`inherited`), else the default; `mixed` when they differ.
    pub fn waiting(&self, inherited: Option<WaitStrategy>) -> String {
        let mut names = self.processes.iter().map(|p| {
            p.env
                .get(WaitStrategy::ENV)
                .and_then(|v| WaitStrategy::parse(v))
                .or(inherited)
                .unwrap_or_default()
                .name()
        });
        let first = names
            .next()
            .unwrap_or_else(|| inherited.unwrap_or_default().name());
        if names.all(|n| n == first) {
            first
        } else {
            "mixed".to_owned()
        }
    }

    /// The context every child gets as environment variables (on top of the supervisor's
    /// own environment and the process's `env`): `AGP_INSTANCE`, `AGP_SCENARIO`,
    /// `AGP_CLOCK`, `AGP_RATE_HZ`, `AGP_RESULTS`, `AGP_PROCESS`.
    pub fn context_env(&self, process: &ProcessConfig) -> [(&'static str, OsString); 6] {
        [
            ("AGP_INSTANCE", OsString::from(&self.instance)),
            ("AGP_SCENARIO", self.scenario.env_value()),
            ("AGP_CLOCK", OsString::from(self.clock.mode.as_str())),
            (
                "AGP_RATE_HZ",
                OsString::from(self.clock.rate_hz.to_string()),
            ),
            ("AGP_RESULTS", self.results.clone().into_os_string()),
            ("AGP_PROCESS", OsString::from(&process.name)),
        ]
    }
}

fn resolve_scenario(check: &mut Checker<'_>, raw: &Spanned<String>, base: &Path) -> ScenarioSource {
    let name = raw.as_ref();
    if BUILTIN_SCENARIOS.contains(&name.as_str()) {
        return ScenarioSource::Builtin(name.clone());
    }
    let path = agp_world::lexically_normal(&base.join(name));
    // Anything that exists is loaded, so that a FIFO or a device is refused as what it is.
    if name.is_empty() || !path.exists() {
        check.fault_at(
            raw,
            LaunchFaultKind::UnknownScenario {
                name: name.clone(),
                looked_at: path.clone(),
            },
        );
    } else if let Err(e) = agp_world::Scenario::load(&path) {
        // Validated whole here, so that a bad scenario starts nothing.
        check.fault_at(
            raw,
            LaunchFaultKind::BadScenario {
                name: name.clone(),
                reason: e.to_string(),
            },
        );
    }
    ScenarioSource::File(path)
}

fn resolve_clock(check: &mut Checker<'_>, raw: Option<&RawClock>) -> ClockConfig {
    let mut clock = ClockConfig {
        mode: ClockMode::Lockstep,
        rate_hz: DEFAULT_RATE_HZ,
    };
    let Some(raw) = raw else {
        return clock;
    };
    if let Some(mode) = &raw.mode {
        match mode.as_ref().as_str() {
            "lockstep" => clock.mode = ClockMode::Lockstep,
            "realtime" => clock.mode = ClockMode::Realtime,
            other => check.fault_at(mode, LaunchFaultKind::UnknownClockMode(other.to_owned())),
        }
    }
    if let Some(rate) = &raw.rate_hz {
        let r = *rate.as_ref();
        if r.is_finite() && (RATE_HZ_RANGE.0..=RATE_HZ_RANGE.1).contains(&r) {
            clock.rate_hz = r;
        } else {
            check.fault_at(rate, LaunchFaultKind::BadRate(r));
        }
    }
    clock
}

/// The process `view = true` (or `view = PORT`) adds: `agp view --instance NAME --port
/// PORT`, restarted on failure; `None` for `view = false`.
fn view_process(
    check: &mut Checker<'_>,
    raw: &Spanned<RawView>,
    instance: &str,
    exe_dir: &Path,
) -> Option<ProcessConfig> {
    let port = match raw.as_ref() {
        RawView::On(false) => return None,
        RawView::On(true) => agp_shared_types::DEFAULT_VIEW_PORT,
        RawView::Port(p) => match u16::try_from(*p) {
            Ok(p) => p,
            Err(_) => {
                check.fault_at(
                    raw,
                    LaunchFaultKind::OutOfBounds {
                        key: "view",
                        limit: "true, false or a port from 0 to 65535".to_owned(),
                        value: p.to_string(),
                    },
                );
                return None;
            }
        },
    };
    Some(ProcessConfig {
        name: "view".to_owned(),
        exec: exe_dir.join("agp"),
        args: vec![
            "view".to_owned(),
            "--instance".to_owned(),
            instance.to_owned(),
            "--port".to_owned(),
            port.to_string(),
        ],
        env: BTreeMap::new(),
        restart: RestartConfig {
            policy: RestartPolicy::OnFailure,
            ..RestartConfig::default()
        },
        ends_run: false,
        stop_grace: DEFAULT_STOP_GRACE,
        line: check.line_of(&raw.span()),
    })
}

/// The instance's name: `--instance` over the file's `instance`, checked; a fault when
/// neither names one.
fn resolve_instance(check: &mut Checker<'_>, options: &LaunchOptions, raw: &RawLaunch) -> String {
    match (&options.instance, &raw.instance) {
        (Some(name), _) => {
            if let Err(reason) = validate_instance_name(name) {
                check.fault(LaunchFaultKind::BadInstanceName {
                    name: name.clone(),
                    from_cli: true,
                    reason,
                });
            }
            name.clone()
        }
        (None, Some(name)) => {
            if let Err(reason) = validate_instance_name(name.as_ref()) {
                check.fault_at(
                    name,
                    LaunchFaultKind::BadInstanceName {
                        name: name.as_ref().clone(),
                        from_cli: false,
                        reason,
                    },
                );
            }
            name.as_ref().clone()
        }
        (None, None) => {
            check.fault(LaunchFaultKind::NoInstance);
            String::new()
        }
    }
}

/// The `[[process]]` entries, each resolved, with the line each name first appears on: at
/// least one entry, at most MAX_PROCESSES, names well formed and each once.
fn resolve_processes(
    check: &mut Checker<'_>,
    raw: &RawLaunch,
    base: &Path,
    exe_dir: &Path,
) -> (Vec<ProcessConfig>, BTreeMap<String, usize>) {
    if raw.process.is_empty() {
        check.fault(LaunchFaultKind::NoProcess);
    }
    if let Some(extra) = raw.process.get(MAX_PROCESSES) {
        check.fault_at(
            extra,
            LaunchFaultKind::OutOfBounds {
                key: "process",
                limit: format!("at most {MAX_PROCESSES} entries (MAX_PROCESSES)"),
                value: format!("{} entries", raw.process.len()),
            },
        );
    }
    let mut processes = Vec::with_capacity(raw.process.len());
    let mut first_lines: BTreeMap<String, usize> = BTreeMap::new();
    for entry in &raw.process {
        let p = entry.as_ref();
        let name = p.name.as_ref();
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            check.fault_at(&p.name, LaunchFaultKind::BadProcessName(name.clone()));
        }
        let line = check.line_of(&p.name.span());
        if let Some(&first_line) = first_lines.get(name) {
            check.fault_at(
                &p.name,
                LaunchFaultKind::DuplicateProcess {
                    name: name.clone(),
                    first_line,
                },
            );
        } else {
            first_lines.insert(name.clone(), line);
        }
        processes.push(resolve_process(check, p, base, exe_dir));
    }
    (processes, first_lines)
}

/// One `[[process]]` entry, checked: its executable (or the `agp bridge` of a `remote`),
/// environment, restart policy and the bounds of its arguments.
fn resolve_process(
    check: &mut Checker<'_>,
    p: &RawProcess,
    base: &Path,
    exe_dir: &Path,
) -> ProcessConfig {
    let name = p.name.as_ref().clone();
    let (exec, remote_args) = resolve_exec(check, p, &name, base, exe_dir);
    let env = resolve_env(check, p, &name);
    let restart = p
        .restart
        .as_ref()
        .map_or_else(RestartConfig::default, |raw| resolve_restart(check, raw));
    if let Some(ms) = &p.stop_grace_ms {
        check_delay(check, ms, "stop_grace_ms");
    }
    let args = checked_args(check, p);
    ProcessConfig {
        line: check.line_of(&p.name.span()),
        name,
        exec,
        args: remote_args.unwrap_or_else(|| args.to_vec()),
        env,
        restart,
        ends_run: p.ends_run,
        stop_grace: p
            .stop_grace_ms
            .as_ref()
            .map_or(DEFAULT_STOP_GRACE, |ms| Duration::from_millis(*ms.as_ref())),
    }
}

/// What a process runs: its `exec` (a bare name is a binary of the workspace, next to
/// `agp`; anything with a slash is a path from the launch file's folder), or for a `remote`
/// process `agp` with the `bridge` arguments, returned beside it.
fn resolve_exec(
    check: &mut Checker<'_>,
    p: &RawProcess,
    name: &str,
    base: &Path,
    exe_dir: &Path,
) -> (PathBuf, Option<Vec<String>>) {
    match (&p.exec, &p.remote) {
        (Some(raw_exec), None) => {
            let exec_str = raw_exec.as_ref();
            let exec = if exec_str.contains('/') {
                base.join(exec_str)
            } else {
                exe_dir.join(exec_str)
            };
            if exec_str.is_empty() || !is_executable_file(&exec) {
                check.fault_at(
                    raw_exec,
                    LaunchFaultKind::MissingExecutable {
                        process: name.to_owned(),
                        exec: exec_str.clone(),
                        looked_at: exec.clone(),
                    },
                );
            }
            (exec, None)
        }
        (None, Some(remote)) => {
            let exec = exe_dir.join("agp");
            if !is_executable_file(&exec) {
                check.fault_at(
                    remote,
                    LaunchFaultKind::MissingExecutable {
                        process: name.to_owned(),
                        exec: "agp".to_owned(),
                        looked_at: exec.clone(),
                    },
                );
            }
            if let Some(args) = &p.args {
                check.fault_at(
                    args,
                    LaunchFaultKind::BadRemote {
                        process: name.to_owned(),
                        reason: "a `remote` process runs `agp bridge` in its place: no `args`"
                            .to_owned(),
                    },
                );
            }
            (exec, Some(remote_bridge_args(check, name, remote, base)))
        }
        (Some(raw_exec), Some(_)) => {
            check.fault_at(
                raw_exec,
                LaunchFaultKind::BadRemote {
                    process: name.to_owned(),
                    reason: "a `remote` process runs under another supervisor: no `exec`"
                        .to_owned(),
                },
            );
            (PathBuf::new(), None)
        }
        (None, None) => {
            check.fault_at(
                &p.name,
                LaunchFaultKind::BadRemote {
                    process: name.to_owned(),
                    reason: "no `exec`: name an executable, or `remote = { ... }` for a process that runs under another supervisor".to_owned(),
                },
            );
            (PathBuf::new(), None)
        }
    }
}

/// The process's `env` table, less each entry refused (a context variable `agp up` sets
/// itself, a malformed name or value, an unknown wait strategy), each refusal a fault.
fn resolve_env(check: &mut Checker<'_>, p: &RawProcess, name: &str) -> BTreeMap<String, String> {
    let mut env = BTreeMap::new();
    for (key, value) in &p.env {
        let k = key.as_ref();
        let why = if CONTEXT_ENV.contains(&k.as_str()) || k == ROOT_ENV {
            Some("it is the context `agp up` gives every process")
        } else if k.is_empty() || k.contains('=') || k.contains('\0') {
            Some("not a variable name")
        } else if value.contains('\0') {
            Some("the value holds a NUL byte")
        } else if k.len() > MAX_ARG_BYTES || value.len() > MAX_ARG_BYTES {
            Some("longer than 4096 bytes (MAX_ARG_BYTES)")
        } else if k == WaitStrategy::ENV && WaitStrategy::parse(value).is_none() {
            Some(WaitStrategy::NOT_A_STRATEGY)
        } else {
            None
        };
        match why {
            Some(why) => check.fault_at(
                key,
                LaunchFaultKind::BadEnv {
                    process: name.to_owned(),
                    key: k.clone(),
                    why,
                },
            ),
            None => {
                env.insert(k.clone(), value.clone());
            }
        }
    }
    env
}

/// The process's `restart` table over the defaults: policy, restart count and back-off,
/// each within its bounds.
fn resolve_restart(check: &mut Checker<'_>, raw: &RawRestart) -> RestartConfig {
    let mut restart = RestartConfig::default();
    if let Some(policy) = &raw.policy {
        match policy.as_ref().as_str() {
            "never" => restart.policy = RestartPolicy::Never,
            "on-failure" => restart.policy = RestartPolicy::OnFailure,
            "always" => restart.policy = RestartPolicy::Always,
            other => check.fault_at(policy, LaunchFaultKind::UnknownPolicy(other.to_owned())),
        }
    }
    if let Some(max) = &raw.max_restarts {
        if *max.as_ref() > MAX_RESTARTS_LIMIT {
            check.fault_at(
                max,
                LaunchFaultKind::OutOfBounds {
                    key: "max_restarts",
                    limit: format!("at most {MAX_RESTARTS_LIMIT} (MAX_RESTARTS_LIMIT)"),
                    value: max.as_ref().to_string(),
                },
            );
        }
        restart.max_restarts = *max.as_ref();
    }
    if let Some(ms) = &raw.backoff_ms {
        check_delay(check, ms, "backoff_ms");
        restart.backoff = Duration::from_millis(*ms.as_ref());
    }
    restart
}

/// The process's `args`, after a fault for too many, too long or holding a NUL, and one for
/// too many `env` entries.
fn checked_args<'p>(check: &mut Checker<'_>, p: &'p RawProcess) -> &'p [String] {
    let args: &[String] = p.args.as_ref().map_or(&[], |a| a.as_ref());
    let bad_arg = args.iter().enumerate().find_map(|(k, a)| {
        if a.contains('\0') {
            Some(format!("argument {} with a NUL byte", k + 1))
        } else if a.len() > MAX_ARG_BYTES {
            Some(format!("argument {} of {} bytes", k + 1, a.len()))
        } else {
            None
        }
    });
    let too_many = (args.len() > MAX_ARGS).then(|| format!("{} arguments", args.len()));
    if let (Some(value), Some(at)) = (too_many.or(bad_arg), &p.args) {
        check.fault_at(
            at,
            LaunchFaultKind::OutOfBounds {
                key: "args",
                limit: format!(
                    "at most {MAX_ARGS} arguments (MAX_ARGS) of at most {MAX_ARG_BYTES} bytes (MAX_ARG_BYTES) without NUL"
                ),
                value,
            },
        );
    }
    if p.env.len() > MAX_ARGS {
        check.fault_at(
            &p.name,
            LaunchFaultKind::OutOfBounds {
                key: "env",
                limit: format!("at most {MAX_ARGS} entries (MAX_ARGS)"),
                value: format!("{} entries", p.env.len()),
            },
        );
    }
    args
}

/// The arguments of the `agp bridge` a `remote` process runs as (`--instance` comes from its
/// context variables, the epoch and token from the slot), once its keys are checked.
fn remote_bridge_args(
    check: &mut Checker<'_>,
    process: &str,
    raw: &Spanned<RawRemote>,
    base: &Path,
) -> Vec<String> {
    let r = raw.as_ref();
    let checks = check.remote;
    let mut faults = Vec::new();
    // The side of the bridge that runs here: the far end's role's opposite.
    let side = match r.role.as_str() {
        "planner" => "robot",
        "robot" => "planner",
        other => {
            faults.push(format!(
                "unknown remote role `{other}`; expected `planner` (the far end runs the planner) or `robot` (it runs physics and the estimator)"
            ));
            "robot"
        }
    };
    let (flag, endpoint) = match (&r.listen, &r.connect) {
        (Some(l), None) => ("--listen", l.clone()),
        (None, Some(c)) => ("--connect", c.clone()),
        _ => {
            faults
                .push("`remote` needs one of `listen` and `connect` (`tls/HOST:PORT`)".to_owned());
            ("--listen", String::new())
        }
    };
    if !endpoint.is_empty()
        && let Some(checks) = checks
        && let Err(e) = (checks.endpoint)(&endpoint)
    {
        faults.push(e);
    }
    let security = remote_security(r, side, &endpoint, base, checks, &mut faults);
    let topics = r
        .topics
        .as_ref()
        .map_or_else(|| "all".to_owned(), |t| t.join(","));
    if let Some(checks) = checks
        && let Err(e) = (checks.topics)(&topics)
    {
        faults.push(format!("`remote.topics`: {e}"));
    }
    let link = r.link.clone().unwrap_or_else(|| "agp".to_owned());
    if link.is_empty()
        || link.len() > 64
        || !link
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        faults.push(format!(
            "bad `remote.link` `{link}`: 1 to 64 letters, digits, `-` and `_`"
        ));
    }
    for reason in faults {
        check.fault_at(
            raw,
            LaunchFaultKind::BadRemote {
                process: process.to_owned(),
                reason,
            },
        );
    }
    let mut args = vec![
        "bridge".to_owned(),
        "--side".to_owned(),
        side.to_owned(),
        flag.to_owned(),
        endpoint,
        "--topics".to_owned(),
        topics,
        "--link".to_owned(),
        link,
    ];
    args.extend(security);
    args
}

/// The security arguments of a `remote`'s bridge: `--tls DIR` (the key folder, relative to
/// the launch file; the side's keys checked now, so a key open to others stops the run
/// before anything starts) or `--insecure`. A `remote` that names neither is refused.
fn remote_security(
    r: &RawRemote,
    side: &str,
    endpoint: &str,
    base: &Path,
    checks: Option<&RemoteChecks>,
    faults: &mut Vec<String>,
) -> Vec<String> {
    let args = match (&r.tls, r.insecure.unwrap_or(false)) {
        (Some(dir), false) => {
            let dir = base.join(dir);
            if let Some(checks) = checks
                && let Err(e) = (checks.keys)(&dir, side)
            {
                faults.push(format!("`remote.tls`: {e}"));
            }
            vec!["--tls".to_owned(), dir.display().to_string()]
        }
        (None, true) => vec!["--insecure".to_owned()],
        (Some(_), true) => {
            faults.push("`remote` names both `tls` and `insecure = true`: give one".to_owned());
            return Vec::new();
        }
        (None, false) => {
            faults.push(
                "`remote` needs `tls = \"DIR\"`, the link's key folder (made by `agp bridge keygen DIR`), or `insecure = true` for plain TCP: no authentication, no encryption"
                    .to_owned(),
            );
            return Vec::new();
        }
    };
    if !endpoint.is_empty()
        && let Some(checks) = checks
        && let Some(fault) = (checks.security_fault)(endpoint, r.tls.is_some())
    {
        faults.push(fault);
    }
    args
}

/// The name of the process `record = "FILE"` adds.
pub const RECORDER_PROCESS: &str = "recorder";

/// The process `record = "FILE"` adds: `agp record --launch LAUNCH [--seed N] FILE`
/// (instance, scenario, clock and rate come from its context variables), never restarted,
/// given 10 s to finish the file when stopped. The seed is physics's `--seed` or
/// `AGP_SEED`, when the file gives one.
fn record_process(
    check: &mut Checker<'_>,
    raw: &Spanned<String>,
    file: &Path,
    base: &Path,
    processes: &[ProcessConfig],
    exe_dir: &Path,
) -> ProcessConfig {
    let out = raw.as_ref();
    if out.is_empty() || out.contains('\0') || out.len() > MAX_ARG_BYTES {
        check.fault_at(
            raw,
            LaunchFaultKind::OutOfBounds {
                key: "record",
                limit: format!("a file name of 1 to {MAX_ARG_BYTES} bytes without NUL"),
                value: format!("{} bytes", out.len()),
            },
        );
    }
    let exec = exe_dir.join("agp");
    if !is_executable_file(&exec) {
        check.fault_at(
            raw,
            LaunchFaultKind::MissingExecutable {
                process: RECORDER_PROCESS.to_owned(),
                exec: "agp".to_owned(),
                looked_at: exec.clone(),
            },
        );
    }
    let physics = processes
        .iter()
        .find(|p| p.exec.file_name().is_some_and(|n| n == "agp-physics"));
    let seed = physics.and_then(|p| {
        p.args
            .windows(2)
            .find(|w| w[0] == "--seed")
            .map(|w| w[1].clone())
            .or_else(|| {
                p.args
                    .iter()
                    .find_map(|a| a.strip_prefix("--seed=").map(str::to_owned))
            })
            .or_else(|| p.env.get("AGP_SEED").cloned())
    });
    let launch = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
    let mut args = vec![
        "record".to_owned(),
        "--launch".to_owned(),
        launch.display().to_string(),
    ];
    if let Some(seed) = seed {
        args.extend(["--seed".to_owned(), seed]);
    }
    args.push(base.join(out).display().to_string());
    ProcessConfig {
        line: check.line_of(&raw.span()),
        name: RECORDER_PROCESS.to_owned(),
        exec,
        args,
        env: BTreeMap::new(),
        restart: RestartConfig {
            policy: RestartPolicy::Never,
            ..RestartConfig::default()
        },
        ends_run: false,
        stop_grace: Duration::from_secs(10),
    }
}

fn check_delay(check: &mut Checker<'_>, ms: &Spanned<u64>, key: &'static str) {
    if *ms.as_ref() > MAX_DELAY_MS {
        check.fault_at(
            ms,
            LaunchFaultKind::OutOfBounds {
                key,
                limit: format!("at most {MAX_DELAY_MS} ms (MAX_DELAY_MS)"),
                value: format!("{} ms", ms.as_ref()),
            },
        );
    }
}

fn is_executable_file(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(path).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(test)]
#[path = "../tests/fixture/mod.rs"]
mod fixture;

#[cfg(test)]
mod tests {
    use super::fixture::Fixture;
    use super::*;

    /// A folder holding a launch file's neighbours: executables `bin/agp-fake` and
    /// `tools/my-planner`, a scenario file `arena.toml` and a plain file `not-exec`; no
    /// remote checks (the bridge's are the supervisor's).
    fn new_fixture() -> Fixture {
        Fixture::new(&["bin/agp-fake", "tools/my-planner"], None)
    }

    #[test]
    fn a_bridge_is_agp_bridge_or_agp_bridge_written_out_and_its_side_is_its_side_flag() {
        let args = |a: &[&str]| a.iter().map(|s| (*s).to_owned()).collect::<Vec<_>>();
        let agp = Path::new("/opt/agp/bin/agp");
        let bridge = Path::new("/opt/agp/bin/agp-bridge");
        let planner_side = args(&["bridge", "--side", "planner", "--connect", "tls/h:7447"]);
        assert_eq!(bridge_side(agp, &planner_side), Some("planner"));
        assert_eq!(
            bridge_side(bridge, &args(&["--side", "robot", "--insecure"])),
            Some("robot")
        );
        assert!(is_bridge(agp, &args(&["bridge", "keygen", "keys"])));
        assert_eq!(bridge_side(agp, &args(&["bridge", "keygen", "keys"])), None);
        // Not a bridge: `agp` doing something else, or another program with a `--side`.
        assert!(!is_bridge(agp, &args(&["up", "launch.toml"])));
        assert_eq!(
            bridge_side(Path::new("/opt/agp/bin/agp-planner"), &planner_side),
            None
        );
    }

    #[test]
    fn a_record_key_starts_a_recorder_first_with_the_launch_file_and_physicss_seed() {
        let f = new_fixture();
        for exe in ["bin/agp", "bin/agp-physics"] {
            f.add_executable(exe);
        }
        let text = "instance = \"rec\"\nscenario = \"triangle\"\nrecord = \"out/run.mcap\"\n\
                    [[process]]\nname = \"physics\"\nexec = \"agp-physics\"\nargs = [\"--seed\", \"9\"]\n";
        let config = f.parse(text).expect("a valid file");
        let rec = &config.processes[0];
        assert_eq!(rec.name, "recorder");
        assert_eq!(rec.exec, f.path().join("bin/agp"));
        assert_eq!(rec.restart.policy, RestartPolicy::Never);
        let out = f.path().join("out/run.mcap");
        assert_eq!(config.record.as_deref(), Some(out.as_path()));
        let launch = std::path::absolute(f.file()).expect("absolute");
        let expected = [
            "record".to_owned(),
            "--launch".to_owned(),
            launch.display().to_string(),
            "--seed".to_owned(),
            "9".to_owned(),
            out.display().to_string(),
        ];
        assert_eq!(rec.args, expected);
        assert_eq!(config.processes[1].name, "physics");
    }

    #[test]
    fn a_learn_key_of_online_gives_the_estimator_and_the_planner_their_flags() {
        let f = new_fixture();
        for exe in ["bin/agp-estimator", "bin/agp-planner"] {
            f.add_executable(exe);
        }
        let text = "instance = \"onl\"\nscenario = \"triangle\"\nlearn = \"online\"\n\
                    [[process]]\nname = \"estimator\"\nexec = \"agp-estimator\"\nargs = [\"--reuse\"]\n\
                    [[process]]\nname = \"planner\"\nexec = \"agp-planner\"\n\
                    args = [\"--mode\", \"place\", \"--learn-if-missing\"]\n";
        let config = f.parse(text).expect("a valid file");
        assert_eq!(config.learn, LearnMode::Online);
        assert_eq!(config.processes[0].args, ["--learn-online", "--from-prior"]);
        assert_eq!(
            config.processes[1].args,
            ["--mode", "place", "--from-prior"]
        );
        // Any other word is refused at its line, naming both modes.
        let (line, shown, _) = f.fault(&text.replace("\"online\"", "\"later\""));
        assert_eq!(line, Some(3));
        assert!(
            shown.contains("unknown learn mode `later`") && shown.contains("`online`"),
            "{shown}"
        );
        // An estimator told to load a file cannot learn from nothing.
        let (line, shown, _) = f.fault(&text.replace("--reuse", "--perceive-only"));
        assert_eq!(line, Some(3));
        assert!(shown.contains("process `estimator`"), "{shown}");
    }

    #[test]
    fn a_record_key_beside_a_process_named_recorder_is_refused() {
        let f = new_fixture();
        f.add_executable("bin/agp");
        let text = GOOD.replace("name = \"planner\"", "name = \"recorder\"");
        let (line, shown, _) = f.fault(&format!("record = \"run.mcap\"\n{text}"));
        assert_eq!(line, Some(1));
        assert!(
            shown.contains("duplicate process name `recorder`"),
            "{shown}"
        );
    }

    const GOOD: &str = r#"
instance = "t-launch"
scenario = "triangle"

[clock]
mode = "realtime"
rate_hz = 320

[[process]]
name = "physics"
exec = "agp-fake"
args = ["--seed", "7"]
env = { RUST_LOG = "info" }
restart = { policy = "on-failure", max_restarts = 5, backoff_ms = 50 }

[[process]]
name = "planner"
exec = "tools/my-planner"
ends_run = true
stop_grace_ms = 500
"#;

    #[test]
    fn a_good_file_resolves_every_path_and_default() {
        let fx = new_fixture();
        let c = fx.parse(GOOD).expect("valid");
        assert_eq!(c.instance, "t-launch");
        assert_eq!(c.scenario, ScenarioSource::Builtin("triangle".into()));
        assert_eq!(c.results, fx.path().join("results"));
        assert_eq!(c.clock.mode, ClockMode::Realtime);
        assert_eq!(c.clock.rate_hz, 320.0);
        assert_eq!(c.processes.len(), 2);
        let physics = &c.processes[0];
        assert_eq!(physics.exec, fx.path().join("bin/agp-fake"));
        assert_eq!(physics.args, ["--seed", "7"]);
        assert_eq!(
            physics.env.get("RUST_LOG").map(String::as_str),
            Some("info")
        );
        assert_eq!(physics.restart.policy, RestartPolicy::OnFailure);
        assert_eq!(physics.restart.max_restarts, 5);
        assert_eq!(physics.restart.backoff, Duration::from_millis(50));
        assert!(!physics.ends_run);
        assert_eq!(physics.stop_grace, DEFAULT_STOP_GRACE);
        let planner = &c.processes[1];
        assert_eq!(planner.exec, fx.path().join("tools/my-planner"));
        assert_eq!(planner.restart, RestartConfig::default());
        assert!(planner.ends_run);
        assert_eq!(planner.stop_grace, Duration::from_millis(500));
    }

    #[test]
    fn a_missing_clock_means_lockstep_at_640_hz() {
        let fx = new_fixture();
        let c = fx
            .parse("instance = \"a\"\nscenario = \"square\"\n[[process]]\nname = \"p\"\nexec = \"agp-fake\"\n")
            .expect("valid");
        assert_eq!(c.clock.mode, ClockMode::Lockstep);
        assert_eq!(c.clock.rate_hz, DEFAULT_RATE_HZ);
    }

    #[test]
    fn a_scenario_file_resolves_against_the_launch_folder() {
        let fx = new_fixture();
        let c = fx
            .parse(&GOOD.replace("\"triangle\"", "\"arena.toml\""))
            .expect("valid");
        assert_eq!(
            c.scenario,
            ScenarioSource::File(fx.path().join("arena.toml"))
        );
        assert_eq!(
            c.scenario.env_value(),
            fx.path().join("arena.toml").into_os_string()
        );
    }

    #[test]
    fn a_scenario_file_that_is_not_a_valid_scenario_is_refused_with_its_own_line() {
        let fx = new_fixture();
        let bad = include_str!("../../../libs/world/scenarios/pentagon.toml").replacen(
            "mass_kg",
            "mass_kilos",
            1,
        );
        std::fs::write(fx.path().join("arena.toml"), &bad).expect("write");
        let (line, shown, kind) = fx.fault(&GOOD.replace("\"triangle\"", "\"arena.toml\""));
        assert!(
            matches!(kind, LaunchFaultKind::BadScenario { .. }),
            "{kind:?}"
        );
        assert_eq!(line, Some(3), "{shown}");
        let bad_line = bad
            .lines()
            .position(|l| l.contains("mass_kilos"))
            .expect("line")
            + 1;
        assert!(
            shown.contains(&format!("arena.toml:{bad_line}:")),
            "the scenario's own line is not named: {shown}"
        );
    }

    #[test]
    fn the_instance_override_replaces_the_files_name() {
        let fx = new_fixture();
        let options = LaunchOptions {
            instance: Some("other".into()),
            ..fx.options()
        };
        let c = LaunchConfig::parse(GOOD, &fx.file(), &options).expect("valid");
        assert_eq!(c.instance, "other");
    }

    #[test]
    fn every_child_gets_the_context_variables() {
        let fx = new_fixture();
        let c = fx.parse(GOOD).expect("valid");
        let env = c.context_env(&c.processes[1]);
        let get = |k: &str| {
            env.iter()
                .find(|(name, _)| *name == k)
                .map(|(_, v)| v.to_string_lossy().into_owned())
        };
        assert_eq!(get("AGP_INSTANCE").as_deref(), Some("t-launch"));
        assert_eq!(get("AGP_SCENARIO").as_deref(), Some("triangle"));
        assert_eq!(get("AGP_CLOCK").as_deref(), Some("realtime"));
        assert_eq!(get("AGP_RATE_HZ").as_deref(), Some("320"));
        assert_eq!(
            get("AGP_RESULTS"),
            Some(fx.path().join("results").to_string_lossy().into_owned())
        );
        assert_eq!(get("AGP_PROCESS").as_deref(), Some("planner"));
    }

    #[test]
    fn an_unknown_key_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, shown, kind) =
            fx.fault(&GOOD.replace("ends_run = true", "ends_run = true\nrestrat = 3"));
        assert_eq!(line, Some(20));
        assert!(matches!(kind, LaunchFaultKind::Toml(_)));
        assert!(
            shown.contains("launch.toml:20: unknown field `restrat`"),
            "{shown}"
        );
    }

    #[test]
    fn an_unknown_key_inside_an_inline_table_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, shown, _) = fx.fault(&GOOD.replace("max_restarts = 5", "max_restart = 5"));
        assert_eq!(line, Some(14));
        assert!(shown.contains("unknown field `max_restart`"), "{shown}");
    }

    #[test]
    fn a_toml_syntax_error_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("mode = \"realtime\"", "mode = realtime"));
        assert_eq!(line, Some(6));
        assert!(matches!(kind, LaunchFaultKind::Toml(_)));
    }

    #[test]
    fn an_unknown_policy_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, shown, kind) = fx.fault(&GOOD.replace("\"on-failure\"", "\"sometimes\""));
        assert_eq!(line, Some(14));
        assert!(matches!(kind, LaunchFaultKind::UnknownPolicy(ref p) if p == "sometimes"));
        assert!(
            shown.ends_with(
                "launch.toml:14: unknown policy `sometimes`; expected `never`, `on-failure` or `always`"
            ),
            "{shown}"
        );
    }

    #[test]
    fn a_negative_rate_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("rate_hz = 320", "rate_hz = -320"));
        assert_eq!(line, Some(7));
        assert!(matches!(kind, LaunchFaultKind::BadRate(r) if r == -320.0));
    }

    #[test]
    fn a_zero_rate_is_refused() {
        let fx = new_fixture();
        let (_, _, kind) = fx.fault(&GOOD.replace("rate_hz = 320", "rate_hz = 0.0"));
        assert!(matches!(kind, LaunchFaultKind::BadRate(_)));
    }

    #[test]
    fn an_unknown_clock_mode_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("\"realtime\"", "\"fast\""));
        assert_eq!(line, Some(6));
        assert!(matches!(kind, LaunchFaultKind::UnknownClockMode(ref m) if m == "fast"));
    }

    #[test]
    fn a_negative_max_restarts_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("max_restarts = 5", "max_restarts = -1"));
        assert_eq!(line, Some(14));
        assert!(matches!(kind, LaunchFaultKind::Toml(_)));
    }

    #[test]
    fn a_bad_instance_name_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("\"t-launch\"", "\"Bad Name\""));
        assert_eq!(line, Some(2));
        assert!(matches!(
            kind,
            LaunchFaultKind::BadInstanceName {
                from_cli: false,
                ..
            }
        ));
    }

    #[test]
    fn a_bad_instance_override_is_refused() {
        let fx = new_fixture();
        let options = LaunchOptions {
            instance: Some("x".repeat(40)),
            ..fx.options()
        };
        let err = LaunchConfig::parse(GOOD, &fx.file(), &options).expect_err("refused");
        assert!(matches!(
            err.faults[0].kind,
            LaunchFaultKind::BadInstanceName { from_cli: true, .. }
        ));
        assert!(err.to_string().contains("--instance"), "{err}");
    }

    #[test]
    fn a_file_without_instance_needs_the_override() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("instance = \"t-launch\"", ""));
        assert_eq!(line, None);
        assert!(matches!(kind, LaunchFaultKind::NoInstance));
    }

    #[test]
    fn a_duplicate_process_name_is_refused_with_both_lines() {
        let fx = new_fixture();
        let (line, shown, kind) = fx.fault(&GOOD.replace("\"planner\"", "\"physics\""));
        assert_eq!(line, Some(17));
        assert!(
            matches!(
                kind,
                LaunchFaultKind::DuplicateProcess { first_line: 10, .. }
            ),
            "{shown}"
        );
    }

    #[test]
    fn a_bad_process_name_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("\"planner\"", "\"my planner\""));
        assert_eq!(line, Some(17));
        assert!(matches!(kind, LaunchFaultKind::BadProcessName(_)));
    }

    #[test]
    fn a_file_without_process_is_refused() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault("instance = \"a\"\nscenario = \"circle\"\n");
        assert_eq!(line, None);
        assert!(matches!(kind, LaunchFaultKind::NoProcess));
    }

    #[test]
    fn a_missing_executable_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, shown, kind) = fx.fault(&GOOD.replace("\"agp-fake\"", "\"agp-nothing\""));
        assert_eq!(line, Some(11));
        assert!(matches!(kind, LaunchFaultKind::MissingExecutable { .. }));
        assert!(shown.contains("bin/agp-nothing"), "{shown}");
    }

    #[test]
    fn a_file_without_execute_permission_is_refused() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("\"tools/my-planner\"", "\"./not-exec\""));
        assert_eq!(line, Some(18));
        assert!(matches!(kind, LaunchFaultKind::MissingExecutable { .. }));
    }

    #[test]
    fn a_scenario_neither_built_in_nor_a_file_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, shown, kind) = fx.fault(&GOOD.replace("\"triangle\"", "\"hexagon\""));
        assert_eq!(line, Some(3));
        assert!(matches!(kind, LaunchFaultKind::UnknownScenario { .. }));
        assert!(
            shown.contains("square, triangle, lshape, circle"),
            "{shown}"
        );
    }

    #[test]
    fn a_reserved_env_variable_is_refused_with_its_line() {
        let fx = new_fixture();
        let (line, _, kind) = fx.fault(&GOOD.replace("RUST_LOG", "AGP_INSTANCE"));
        assert_eq!(line, Some(13));
        assert!(matches!(kind, LaunchFaultKind::BadEnv { .. }));
    }

    #[test]
    fn a_waiting_strategy_that_names_none_is_refused_with_its_line() {
        let fx = new_fixture();
        let text = GOOD.replace("RUST_LOG = \"info\"", "AGP_WAIT = \"fast\"");
        let (line, message, kind) = fx.fault(&text);
        assert_eq!(line, Some(13));
        assert!(matches!(kind, LaunchFaultKind::BadEnv { .. }));
        assert!(message.contains("not a waiting strategy"), "{message}");
    }

    #[test]
    fn the_instance_waits_as_its_processes_do_or_is_mixed() {
        let fx = new_fixture();
        let config = fx.parse(GOOD).expect("valid");
        assert_eq!(config.waiting(None), WaitStrategy::default().name());
        assert_eq!(config.waiting(Some(WaitStrategy::Block)), "block");
        let one = fx
            .parse(&GOOD.replace("RUST_LOG = \"info\"", "AGP_WAIT = \"yield\""))
            .expect("valid");
        assert_eq!(one.waiting(Some(WaitStrategy::Yield)), "yield");
        assert_eq!(one.waiting(Some(WaitStrategy::Block)), "mixed");
    }

    #[test]
    fn every_fault_of_a_file_is_reported_at_once() {
        let fx = new_fixture();
        let text = GOOD
            .replace("\"on-failure\"", "\"sometimes\"")
            .replace("rate_hz = 320", "rate_hz = -1")
            .replace("\"agp-fake\"", "\"agp-nothing\"");
        let err = fx.parse(&text).expect_err("refused");
        let lines: Vec<_> = err.faults.iter().map(|f| f.line).collect();
        assert_eq!(lines, [Some(7), Some(11), Some(14)]);
        assert_eq!(err.to_string().lines().count(), 3);
    }

    #[test]
    fn an_unreadable_file_is_refused() {
        let fx = new_fixture();
        let err =
            LaunchConfig::load(&fx.path().join("absent.toml"), &fx.options()).expect_err("refused");
        assert!(matches!(err.faults[0].kind, LaunchFaultKind::Read(_)));
        assert!(err.to_string().contains("absent.toml"));
    }

    #[test]
    fn on_failure_restarts_a_crash_until_max_restarts_then_fails_the_run() {
        let r = RestartConfig {
            policy: RestartPolicy::OnFailure,
            max_restarts: 2,
            backoff: Duration::from_millis(100),
        };
        assert_eq!(
            r.decide(false, 0),
            ExitDecision::Restart {
                nth: 1,
                delay: Duration::from_millis(100)
            }
        );
        assert_eq!(
            r.decide(false, 1),
            ExitDecision::Restart {
                nth: 2,
                delay: Duration::from_millis(200)
            }
        );
        assert_eq!(r.decide(false, 2), ExitDecision::FailRun);
        assert_eq!(r.decide(true, 0), ExitDecision::Done);
    }

    #[test]
    fn never_fails_the_run_on_a_crash_and_accepts_a_clean_exit() {
        let r = RestartConfig::default();
        assert_eq!(r.decide(false, 0), ExitDecision::FailRun);
        assert_eq!(r.decide(true, 0), ExitDecision::Done);
    }

    #[test]
    fn always_restarts_a_clean_exit_too() {
        let r = RestartConfig {
            policy: RestartPolicy::Always,
            max_restarts: 1,
            backoff: Duration::ZERO,
        };
        assert!(matches!(
            r.decide(true, 0),
            ExitDecision::Restart { nth: 1, .. }
        ));
        assert_eq!(r.decide(true, 1), ExitDecision::FailRun);
    }

    #[test]
    fn the_backoff_doubles_and_stops_at_its_cap() {
        let r = RestartConfig {
            backoff: Duration::from_millis(200),
            ..RestartConfig::default()
        };
        assert_eq!(r.delay_before(1), Duration::from_millis(200));
        assert_eq!(r.delay_before(3), Duration::from_millis(800));
        assert_eq!(r.delay_before(40), MAX_RESTART_DELAY);
    }

    #[test]
    fn view_true_adds_agp_view_on_the_instance_after_the_other_processes() {
        let f = new_fixture();
        let c = f.parse(&format!("view = true\n{GOOD}")).expect("valid");
        let view = c.processes.last().expect("a process");
        assert_eq!(c.processes.len(), 3);
        assert_eq!(view.name, "view");
        assert_eq!(view.exec, f.options().exe_dir.join("agp"));
        assert_eq!(
            view.args,
            ["view", "--instance", "t-launch", "--port", "8765"]
        );
        assert_eq!(view.restart.policy, RestartPolicy::OnFailure);
        assert!(!view.ends_run);
        assert_eq!(view.line, 1);
        let c = f.parse(&format!("view = 0\n{GOOD}")).expect("valid");
        assert_eq!(c.processes[2].args[4], "0");
        let c = f.parse(&format!("view = false\n{GOOD}")).expect("valid");
        assert_eq!(c.processes.len(), 2);
    }

    #[test]
    fn a_view_port_out_of_range_is_refused_on_its_line() {
        let f = new_fixture();
        let (line, shown, _) = f.fault(&format!("view = 70000\n{GOOD}"));
        assert_eq!(line, Some(1));
        assert!(
            shown.ends_with("`view` must be true, false or a port from 0 to 65535, got 70000"),
            "{shown}"
        );
    }
}
