//! Affordance gradients.
