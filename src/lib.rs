//! travmap: traversability maps from recorded drives, after Fusaro et al.,
//! "Pushing the Limits of Learning-based Traversability Analysis for Autonomous
//! Driving on CPU" (specified in METHOD.md).
//!
//! Layers, each importing only those above it (ARCHITECTURE.md):
//! - shared: [`config`], [`error`], [`geometry`], [`random`], [`stopwatch`],
//!   [`frame`] (what readers produce and the method consumes) and [`posing`] (how a
//!   source's scans are posed, decided once);
//! - [`io`]: drives (KITTI directories, ROS 2 MCAP) into [`frame::Frame`]s;
//! - [`method`]: the stages in the order [`method::pipeline::Pipeline`] calls them;
//! - [`drive`]: where the two meet: a source's selected frames run through the method;
//! - [`training`], [`scoring`] and [`outputs`]: what is made of the results.
//!
//! [`fuzzing`] holds the entry points of the fuzz targets.

pub mod config;
pub mod drive;
pub mod error;
pub mod frame;
pub mod fuzzing;
pub mod geometry;
pub mod io;
pub mod lens;
pub mod method;
pub mod outputs;
pub mod posing;
pub mod random;
pub mod scoring;
pub mod stopwatch;
pub mod training;

pub use config::Config;
pub use error::{Error, Result};
