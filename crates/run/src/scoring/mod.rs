//! How good and how fast: [`metrics`] of a grid against ground truth, their
//! [`evaluation`] over frames, the per-stage [`benchmark`], and the [`remarks`] a
//! run makes of the drives.

pub mod benchmark;
pub mod evaluation;
pub mod metrics;
pub mod remarks;
