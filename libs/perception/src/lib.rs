//! The estimator's logic, free of shared memory: the learning phase of affordance gradients from IR frames (contact point, shape, pose by circling).

#![warn(missing_docs)]

mod approach_contact;
mod contact_estimator;
mod contact_sense;
mod ir_view;
mod learn_events;
mod learning_session;
mod object_tracker;
mod online_learner;
mod robot_localizer;
mod trial_recorder;

pub use approach_contact::{
    ApproachContact, STALL_MAX_GAP, STALL_MIN_TRAVEL, STALL_SAMPLES, STALL_SHARE,
};
pub use contact_estimator::{ContactEstimates, ContactEstimator, ContactMethod, LearnedShape};
pub use contact_sense::ContactSense;
pub use ir_view::IrView;
pub use learn_events::{LearnProblem, LearnReply, ProtocolLearner};
pub use learning_session::{
    LearningConfig, LearningSession, SessionBuildError, ShapeLearnError, TrialLearnError,
    TrialStartError,
};
pub use object_tracker::{
    BORDER_SECTORS, ObjectTracker, TrackerConfig, TrackerError, border_centroid,
};
pub use online_learner::{LearnedPush, OnlineLearner, OnlineLearningConfig};
pub use robot_localizer::RobotLocalizer;
pub use trial_recorder::{
    TrialFinishError, TrialOrderError, TrialPhase, TrialRecord, TrialRecorder,
};
