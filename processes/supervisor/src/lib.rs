//! The supervisor's pure logic: the launch file and the restart policy, testable without shared memory.

mod goal_spec;
mod launch;

pub use goal_spec::{GoalSpec, GoalSpecError, check_goal};

pub use launch::{
    BUILTIN_SCENARIOS, CONTEXT_ENV, ClockConfig, ClockMode, DEFAULT_RATE_HZ, DEFAULT_STOP_GRACE,
    ExitDecision, LaunchConfig, LaunchConfigParseError, LaunchFault, LaunchFaultKind,
    LaunchOptions, MAX_RESTART_DELAY, ProcessConfig, RECORDER_PROCESS, RestartConfig,
    RestartPolicy, ScenarioSource,
};
