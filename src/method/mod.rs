//! The method of METHOD.md, one module per stage, in the order
//! [`pipeline::Pipeline::process_frame`] calls them: [`integration`] (1), [`grid`] (2),
//! [`features`] (3), [`appearance`] (3b), [`classifier`] (4), [`filter`] (5); beside
//! them [`ground_truth`]. Stages see flat arrays and [`crate::frame::Frame`]s only:
//! no file, no MCAP, no CLI.

pub mod appearance;
pub mod classifier;
pub mod feature_groups;
pub mod features;
pub mod filter;
pub mod fusion;
pub mod grid;
pub mod ground_truth;
pub mod integration;
pub mod pipeline;
pub mod registration;
