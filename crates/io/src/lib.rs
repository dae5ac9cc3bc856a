//! Stage 0, reading: a drive into [`Frame`](travmap_core::frame::Frame)s (METHOD.md
//! section 1). A [`Source`] is whatever holds a drive, told apart by content
//! ([`format`](mod@format)): a KITTI / SemanticKITTI sequence ([`kitti`]), a recorded log
//! ([`ros_drive`] over the [`containers`]: MCAP, ROS 1 bag, rosbag2, pcap), a folder
//! of scans or one saved cloud ([`cloud_files`]). LiDAR [`packets`] become scans;
//! [`payloads`] turn cloud and image messages into points and pixels. Nothing here
//! knows the method.

pub mod cloud_files;
pub mod containers;
pub mod format;
#[cfg(feature = "fuzzing")]
pub mod fuzzing;
pub mod kitti;
pub mod packets;
pub mod payloads;
pub mod ros_drive;
mod skips;
mod source;
mod yaml;

pub use kitti::KittiSequence;
pub use skips::{Skip, SkipLog, nothing_read};
pub use source::{Georeference, Source, SourceKind, SourceOptions, WORLD_FRAME};
