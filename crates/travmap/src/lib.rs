//! travmap: traversability maps from recorded drives, after Fusaro et al.,
//! "Pushing the Limits of Learning-based Traversability Analysis for Autonomous
//! Driving on CPU" (specified in METHOD.md).
//!
//! This crate joins the layers below it (ARCHITECTURE.md): [`drive`] is where a
//! source's frames (`travmap-io`) meet the method (`travmap-method`); [`training`],
//! [`scoring`] and [`outputs`] are what is made of the results.

pub mod drive;
#[cfg(feature = "fuzzing")]
pub mod fuzzing;
pub mod outputs;
pub mod scoring;
pub mod training;
