//! travmap: traversability maps from recorded drives, after Fusaro et al.,
//! "Pushing the Limits of Learning-based Traversability Analysis for Autonomous
//! Driving on CPU" (specified in METHOD.md).
//!
//! The stages, in the order [`pipeline::Pipeline::process_frame`] calls them:
//! [`reading`] (0), [`integration`] (1), [`grid`] (2), [`features`] (3),
//! [`appearance`] (3b), [`classifier`] (4), [`filter`] (5); beside them
//! [`ground_truth`], [`metrics`] and [`evaluation`]. Around the method: [`writing`]
//! (MCAP output, with [`ros`] messages), [`conversion`] (KITTI -> MCAP),
//! [`annotation`] (the annotated MCAP), [`dataset`] (Parquet cell tables),
//! [`rendering`] (pictures) and [`benchmark`].
//! [`commands`] holds one function per subcommand of the binary; [`fuzzing`] the
//! entry points of the fuzz targets.

pub mod annotation;
pub mod appearance;
pub mod benchmark;
pub mod classifier;
pub mod commands;
pub mod config;
pub mod conversion;
pub mod dataset;
pub mod error;
pub mod evaluation;
pub mod features;
pub mod filter;
pub mod fuzzing;
pub mod geometry;
pub mod grid;
pub mod ground_truth;
pub mod integration;
pub mod metrics;
pub mod pipeline;
pub mod random;
pub mod reading;
pub mod rendering;
pub mod ros;
pub mod writing;

pub use config::Config;
pub use error::{Error, Result};
