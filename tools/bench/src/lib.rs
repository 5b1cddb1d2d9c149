//! Shared pieces of the benchmark binaries.

pub mod hop;
pub mod math;
pub mod pipeline;
