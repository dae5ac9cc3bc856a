//! The method of METHOD.md, one module per stage, in the order
//! [`pipeline::Pipeline`] calls them: posing (0: the input's poses, or
//! [`registration`] over a [`voxel_map`]), [`integration`] (1), [`grid`] (2),
//! [`features`] (3, and [`feature_groups`]), [`appearance`] (3b), [`classifier`] (4),
//! [`filter`] (5), and for adaptation [`footprint`] (6a) and [`self_labels`] (6b);
//! beside them [`ground_truth`], and [`fusion`] of the results into one map of the
//! drive; the [`training_set`] of labelled cells a classifier learns from. Stages see flat arrays and [`Frame`](travmap_core::frame::Frame)s only: no
//! file, no MCAP, no CLI; this crate depends on `travmap-core` alone.

pub mod appearance;
pub mod asking;
pub mod classifier;
pub mod feature_groups;
pub mod features;
pub mod filter;
pub mod footprint;
pub mod fusion;
pub mod grid;
pub mod ground_truth;
pub mod integration;
pub mod layers;
pub mod pipeline;
pub mod pose_check;
pub mod registration;
pub mod self_labels;
pub mod training_set;
pub mod vehicle_points;
pub mod voxel_map;
