/// Names of the services of one instance. Every topic is paired with an event service its
/// publisher notifies after each send, so a reader can block instead of polling. Topics
/// read by the same waiting loop share one event service: physics waits on
/// [`ServiceNames::PHYSICS_INBOX`] for both motor commands and resets.
///
/// The names are the contract between processes; `agp_runtime::Instance` opens the
/// services under them with their quality of service.
pub struct ServiceNames;

impl ServiceNames {
    pub const IR_FRAMES: &'static str = "agp/ir_frames";
    pub const GROUND_TRUTH: &'static str = "agp/ground_truth";
    pub const MOTOR_COMMANDS: &'static str = "agp/motor_commands";
    pub const RESETS: &'static str = "agp/resets";
    pub const ESTIMATES: &'static str = "agp/estimates";
    pub const GRIDS: &'static str = "agp/grids";
    pub const TASK: &'static str = "agp/task";
    /// The goal of a live session the serving planner pursues (the supervisor publishes).
    pub const GOAL: &'static str = "agp/goal";
    /// Goals the serving planner ended, when the supervisor that judges them is across a
    /// bridge (the planner side's supervisor publishes, the bridge carries them).
    pub const GOAL_ENDS: &'static str = "agp/goal_ends";
    pub const ACTIVE_EPOCH: &'static str = "agp/active_epoch";
    /// The event service physics blocks on: notified after a motor command or a reset.
    pub const PHYSICS_INBOX: &'static str = "agp/physics_inbox.ev";
    /// Learning-protocol steps (planner to estimator) and test-push requests (benchmark to
    /// planner). Its publishers notify [`ServiceNames::IR_FRAMES`]'s event service, so the
    /// estimator, which waits for frames, wakes for both with one listener.
    pub const LEARN_EVENTS: &'static str = "agp/learn_events";
    /// The estimator's account of learning and its predictions of test pushes.
    pub const LEARN_REPORTS: &'static str = "agp/learn_reports";
    /// The supervisor's request-response service (`ControlRequest` in, `ControlResponse`
    /// out): status, down, hot swap, pause leases.
    pub const CONTROL: &'static str = "agp/control";

    /// The event service paired with a topic.
    pub fn event_of(topic: &str) -> String {
        format!("{topic}.ev")
    }
}
