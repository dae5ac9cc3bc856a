//! The words every travmap crate shares: the one [`Config`] (nested per stage), the
//! one [`Error`], a [`frame::Frame`] (what readers produce and the method consumes)
//! with its camera [`lens`], [`posing`] (how a source's scans are posed, decided
//! once), small [`geometry`], the files options name ([`option_files`]), a seeded [`random`] generator, stage timing
//! ([`stopwatch`]) and the run's [`temporaries`]. It knows no file format and no stage of the method.

pub mod config;
pub mod config_sources;
pub mod error;
pub mod frame;
pub mod geometry;
pub mod lens;
pub mod option_files;
pub mod posing;
pub mod random;
pub mod stopwatch;
pub mod temporaries;

pub use config::Config;
pub use error::{Error, Result};
