//! Which topics a bridge carries, in which direction, and what a late far end is owed.

use agp_recording::recorded_topics;
use agp_shared_types::ServiceNames;

/// The part of a split pipeline a bridge serves: the instance it is started on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The instance that runs physics and the estimator (the robot, or the simulator):
    /// it sends frames, estimates and grids, and takes the planner's commands.
    Robot,
    /// The instance that runs the planner: it takes frames, estimates and grids, and sends
    /// commands, resets, the planner's events and the task.
    Planner,
}

impl Side {
    /// `robot` or `planner`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Robot => "robot",
            Self::Planner => "planner",
        }
    }

    /// The side named `robot` or `planner`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "robot" => Some(Self::Robot),
            "planner" => Some(Self::Planner),
            _ => None,
        }
    }

    /// The side at the far end of the link.
    pub fn far(self) -> Self {
        match self {
            Self::Robot => Self::Planner,
            Self::Planner => Self::Robot,
        }
    }
}

/// What the sending end keeps of a topic so that a far end that joins late (or joins again)
/// starts from the same state a late local subscriber would: iceoryx2's history, carried
/// across.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Latch {
    /// Nothing: events and commands matter when they are sent, never later.
    None,
    /// The latest message (frames, estimates, the task).
    Latest,
    /// The latest whole set of gradient grids (a new `seq` starts a new set).
    GridSet,
}

/// One topic a bridge can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BridgedTopic {
    /// The name `--topics` takes (the service name without `agp/`).
    pub name: &'static str,
    /// The iceoryx2 service name.
    pub service: &'static str,
    /// The payload's iceoryx2 type name, which the far end checks against its own.
    pub type_name: &'static str,
    /// The payload's size in bytes, which the far end checks too.
    pub size: usize,
    /// The side that publishes it; the other side's bridge republishes it.
    pub from: Side,
    pub latch: Latch,
}

/// Every topic a bridge can carry, in the order a sending end drains them each pass: a
/// message is drained after every message its publisher sent before it on another topic
/// of this list (frames before the estimates derived from them; the planner's events
/// before the command that follows them), so the far end sees them in that order too.
///
/// The goals of a live session cross too: the robot side's supervisor, which runs the judge
/// beside physics, owns them; its `goal` goes to the serving planner, and the goals that
/// planner ended come back as `goal_ends` (its own supervisor relays its `GoalDone`).
///
/// Not carried: ground truth (the judge runs beside physics), the active epoch (each
/// instance's supervisor owns its own) and the control service (request-response, each
/// supervisor answers for its own instance).
pub const BRIDGED_TOPICS: [&str; 10] = [
    "grids",
    "ir_frames",
    "estimates",
    "learn_reports",
    "goal",
    "learn_events",
    "task",
    "resets",
    "motor_commands",
    "goal_ends",
];

/// The description of topic `name` (one of [`BRIDGED_TOPICS`]).
pub fn bridged_topic(name: &str) -> Option<BridgedTopic> {
    let (service, from, latch) = match name {
        "grids" => (ServiceNames::GRIDS, Side::Robot, Latch::GridSet),
        "ir_frames" => (ServiceNames::IR_FRAMES, Side::Robot, Latch::Latest),
        "estimates" => (ServiceNames::ESTIMATES, Side::Robot, Latch::Latest),
        "learn_reports" => (ServiceNames::LEARN_REPORTS, Side::Robot, Latch::None),
        "goal" => (ServiceNames::GOAL, Side::Robot, Latch::Latest),
        "learn_events" => (ServiceNames::LEARN_EVENTS, Side::Planner, Latch::None),
        "task" => (ServiceNames::TASK, Side::Planner, Latch::Latest),
        "resets" => (ServiceNames::RESETS, Side::Planner, Latch::None),
        "motor_commands" => (ServiceNames::MOTOR_COMMANDS, Side::Planner, Latch::None),
        "goal_ends" => (ServiceNames::GOAL_ENDS, Side::Planner, Latch::None),
        _ => return None,
    };
    let spec = recorded_topics()
        .into_iter()
        .find(|t| t.service == service)?;
    Some(BridgedTopic {
        name: BRIDGED_TOPICS.iter().find(|n| **n == name)?,
        service,
        type_name: spec.type_name,
        size: spec.size,
        from,
        latch,
    })
}

/// Why a `--topics` list was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TopicListParseError {
    #[error("unknown topic `{0}`; a bridge carries {list}", list = BRIDGED_TOPICS.join(", "))]
    Unknown(String),
    #[error("topic `{0}` is named twice")]
    Duplicate(String),
    #[error("no topic: name at least one of {list}", list = BRIDGED_TOPICS.join(", "))]
    Empty,
}

/// The topics of a comma-separated list (`ir_frames,estimates,...`; `all` for every one),
/// in [`BRIDGED_TOPICS`] order whatever the order of the list.
pub fn parse_topics(list: &str) -> Result<Vec<BridgedTopic>, TopicListParseError> {
    let mut names: Vec<&str> = Vec::new();
    for raw in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        if raw == "all" {
            names.extend(BRIDGED_TOPICS);
            continue;
        }
        if bridged_topic(raw).is_none() {
            return Err(TopicListParseError::Unknown(raw.to_owned()));
        }
        if names.contains(&raw) {
            return Err(TopicListParseError::Duplicate(raw.to_owned()));
        }
        names.push(raw);
    }
    if names.is_empty() {
        return Err(TopicListParseError::Empty);
    }
    Ok(BRIDGED_TOPICS
        .iter()
        .filter(|n| names.contains(n))
        .filter_map(|n| bridged_topic(n))
        .collect())
}

/// Every topic a bridge can carry (what `--topics all` names).
pub fn all_topics() -> Vec<BridgedTopic> {
    BRIDGED_TOPICS
        .iter()
        .filter_map(|n| bridged_topic(n))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bridged_topic_names_a_recorded_payload_with_its_versioned_type() {
        for t in all_topics() {
            assert!(t.type_name.starts_with("agp::") && t.type_name.contains(".v"));
            assert!(t.size > 0);
            assert_eq!(format!("agp/{}", t.name), t.service);
        }
        assert_eq!(all_topics().len(), BRIDGED_TOPICS.len());
    }

    #[test]
    fn frames_and_grids_flow_to_the_planner_and_commands_to_the_robot() {
        let from = |n| bridged_topic(n).map(|t| t.from);
        assert_eq!(from("ir_frames"), Some(Side::Robot));
        assert_eq!(from("grids"), Some(Side::Robot));
        assert_eq!(from("motor_commands"), Some(Side::Planner));
        assert_eq!(from("learn_events"), Some(Side::Planner));
        assert_eq!(from("task"), Some(Side::Planner));
        assert_eq!(from("goal"), Some(Side::Robot));
        assert_eq!(from("goal_ends"), Some(Side::Planner));
    }

    #[test]
    fn a_topic_list_keeps_the_drain_order_whatever_order_it_is_given_in() {
        let t = parse_topics("motor_commands, ir_frames,estimates").expect("valid");
        let names: Vec<_> = t.iter().map(|t| t.name).collect();
        assert_eq!(names, ["ir_frames", "estimates", "motor_commands"]);
        assert_eq!(
            parse_topics("all").map(|t| t.len()),
            Ok(BRIDGED_TOPICS.len())
        );
    }

    #[test]
    fn an_unknown_or_repeated_topic_or_an_empty_list_is_refused() {
        assert_eq!(
            parse_topics("ir_frames,ground_truth"),
            Err(TopicListParseError::Unknown("ground_truth".into()))
        );
        assert_eq!(
            parse_topics("task,task"),
            Err(TopicListParseError::Duplicate("task".into()))
        );
        assert_eq!(parse_topics(" , "), Err(TopicListParseError::Empty));
    }
}
