//! A launch file, read and validated whole into the plan `agp up` runs (processes, clock, restart policies): pure, it starts nothing and opens no shared memory.

mod launch_config;
mod learn_mode;

pub use launch_config::{
    BUILTIN_SCENARIOS, CONTEXT_ENV, ClockConfig, ClockMode, DEFAULT_RATE_HZ, DEFAULT_STOP_GRACE,
    ExitDecision, LaunchConfig, LaunchConfigParseError, LaunchFault, LaunchFaultKind,
    LaunchOptions, LearnMode, MAX_RESTART_DELAY, ProcessConfig, RECORDER_PROCESS, RemoteChecks,
    RestartConfig, RestartPolicy, ScenarioSource, bridge_side, is_bridge,
};
