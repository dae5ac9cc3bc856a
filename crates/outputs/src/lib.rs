//! What travmap writes: MCAP ([`writing`], used by [`conversion`] and
//! [`annotation`]), Parquet cell tables ([`dataset`]), pictures ([`rendering`]) and
//! nav2 maps ([`nav2_map`]).
//! Every file goes through [`atomic::AtomicFile`]: a temporary beside the output,
//! renamed when complete.

pub mod annotation;
pub mod atomic;
pub mod conversion;
pub mod dataset;
pub mod drive_map;
pub mod figure;
pub mod labels;
pub mod nav2_map;
pub mod palette;
pub mod preflight;
pub mod rendering;
pub mod trajectory;
pub mod writing;
