//! The estimator's logic, free of shared memory: the learning phase of affordance gradients from IR frames (contact point, shape, pose by circling).

#![warn(missing_docs)]

mod contact_estimator;
mod ir_view;
#[cfg(feature = "learn-bench")]
mod learn_bench;
mod learning_session;
mod trial_recorder;

pub use contact_estimator::{ContactEstimates, ContactEstimator, ContactMethod, LearnedShape};
pub use ir_view::IrView;
#[cfg(feature = "learn-bench")]
pub use learn_bench::{
    LearnBenchConfig, LearnBenchError, LearnProgress, LearnStage, MIN_EVAL_PUSHES, ObjectReport,
    PAPER_TRIANGLE_MAX_ROTATION_DEG, PredictionStats, ShapeQuality, Spread,
    TARGET_DISPLACEMENT_ERROR_RATIO, TARGET_POSE_ORIENTATION_DEG, TARGET_POSE_POSITION_MM,
    TARGET_ROTATION_ERROR_DEG, TargetCheck, check_object, format_report, run_object,
};
pub use learning_session::{
    LearningConfig, LearningSession, SessionBuildError, ShapeLearnError, TrialLearnError,
    TrialStartError,
};
pub use trial_recorder::{
    TrialFinishError, TrialOrderError, TrialPhase, TrialRecord, TrialRecorder,
};
