//! How good and how fast: [`metrics`] of a grid against ground truth, their
//! [`evaluation`] over frames, and the per-stage [`benchmark`].

pub mod benchmark;
pub mod evaluation;
pub mod metrics;
