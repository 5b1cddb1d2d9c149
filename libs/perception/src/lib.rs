//! The estimator's logic, free of shared memory: the learning phase of affordance gradients from IR frames (contact point, shape, pose by circling).

#![warn(missing_docs)]

mod contact_estimator;
mod contact_sense;
mod ir_view;
mod learning_session;
mod object_tracker;
mod robot_localizer;
mod trial_recorder;

pub use contact_estimator::{ContactEstimates, ContactEstimator, ContactMethod, LearnedShape};
pub use contact_sense::ContactSense;
pub use ir_view::IrView;
pub use learning_session::{
    LearningConfig, LearningSession, SessionBuildError, ShapeLearnError, TrialLearnError,
    TrialStartError,
};
pub use object_tracker::{
    BORDER_SECTORS, ObjectTracker, TrackerConfig, TrackerError, border_centroid,
};
pub use robot_localizer::RobotLocalizer;
pub use trial_recorder::{
    TrialFinishError, TrialOrderError, TrialPhase, TrialRecord, TrialRecorder,
};
