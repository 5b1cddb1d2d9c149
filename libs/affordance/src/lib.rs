//! Affordance gradients as math: grids, Gaussian smoothing, learning and prediction (per contact, and along the protocol's pushes), shape matching (Algorithm 3), the AG file and the rebuild from published grids; no IPC, no physics.

#![warn(missing_docs)]

mod affordance_gradient;
mod affordance_learner;
mod ag_file;
mod contact_prior;
mod gaussian_smoother;
mod grid;
mod grid_set_assembler;
mod push_predictor;
mod shape_matcher;
mod simd;
mod symmetry;

pub use affordance_gradient::{
    AIM_BORDER_THRESHOLD, AffordanceGradient, CONTACT_BORDER_THRESHOLD, MIN_PREDICTION_EVIDENCE,
    Prediction, UnknownAlphaError, meets_past_centroid,
};
pub use affordance_learner::{
    AffordanceLearner, LearnerBuildError, LearnerConfig, PushOutcome, SampleAddError,
};
pub use ag_file::{
    AG_FILE_MAGIC, AG_FILE_VERSION, AgFileLoadError, AgFileSaveError, CELL_SIZE_M,
    MAX_AG_FILE_BYTES, MAX_ALPHA_DEG, MAX_ALPHAS, MAX_CELL_MAGNITUDE, MAX_LAYER_COUNT,
    MAX_NAME_LEN, MAX_PUSH_ROTATION_RAD,
};
pub use contact_prior::{
    ContactPriorBuildError, ContactPriorConfig, PushMechanics, angle_ring, contact_prior,
};
pub use gaussian_smoother::{GaussianSmoother, SmoothingMethod};
pub use grid::{DEFAULT_CELL_SIZE_M, Grid, GridPayloadReadError};
pub use grid_set_assembler::{GradientFromGridsError, GridSetAssembler};
pub use push_predictor::{PushPredictor, approach_start, border_crossing};
pub use shape_matcher::{
    MIN_MATCH_POINTS, MatchMethod, MatchedPose, ShapeMatch, ShapeMatchError, ShapeMatcher,
    ShapeMatcherBuildError, ShapeMatcherConfig, learned_border_radius_m,
};
pub use symmetry::{
    DISC_RADIUS_RMS_M, MAX_SYMMETRY_ORDER, MIN_BORDER_COVERAGE, MIN_ROTATION_OVERLAP,
    SYMMETRY_MATCH_THRESHOLD, SYMMETRY_SHIFT_TOLERANCE_M, SymmetryEstimate, estimate_symmetry,
    shape_radius_m, symmetry_order_of,
};
