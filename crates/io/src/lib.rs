//! Stage 0, reading: a drive into [`Frame`](travmap_core::frame::Frame)s (METHOD.md
//! section 1). A [`Source`] is whatever holds a drive, told apart by content
//! ([`InputFormat`]): a KITTI / SemanticKITTI sequence, a recorded log over its
//! container ([`Log`]: MCAP, ROS 1 bag, rosbag2, pcap), a folder of scans or one saved
//! cloud. LiDAR packets become scans and message payloads points and pixels inside.
//! Nothing here knows the method.
//!
//! The face is the names below; the modules behind them are this crate's own.

mod cloud_files;
mod containers;
mod format;
#[cfg(feature = "fuzzing")]
pub mod fuzzing;
mod kitti;
mod log_drive;
mod packets;
mod payloads;
mod recorded;
mod skips;
mod source;
#[cfg(test)]
mod test_data;
mod yaml;

/// A recorded log's messages in order, whatever its container.
pub use containers::log::Log;
/// The files a rosbag2 directory lists (an output must replace none of them).
pub use containers::rosbag2::listed_storage_files;
/// What an input is, by its content.
pub use format::{InputFormat, detect};
/// A recorded log's options: its LiDAR topics, their calibrations and frames.
pub use log_drive::{LidarCalibrations, LidarFrames, LogOptions, MergedTopics};
/// LiDAR packets decoded into scans, every vendor behind one face: the packet
/// messages read, the model told from the packets (or an Ouster's metadata), its
/// calibration, and the assembler that cuts scans; the Ouster packet messages a
/// conversion keeps.
pub use packets::ouster::{OUSTER_PACKET_MESSAGES, OusterMetadata, PACKET_MSG_SCHEMA};
pub use packets::{
    PACKET_MESSAGES, PacketAssembler, PacketCalibration, PacketModel, PacketScan, packet_message,
};
/// What an input recorded beside its frames, for the outputs that copy or convert it.
pub use recorded::{Recorded, RecordedKitti, RecordedLog};
/// Frames left out as unreadable (`--keep-going`), and the error when none was read.
pub use skips::{Skip, SkipLog, nothing_read};
/// Where a drive lies on the Earth, when its log says (a UTM or ECEF root).
pub use source::Georeference;
/// How a drive is read: the poses, `--keep-going`, a log's topics and frames.
pub use source::SourceOptions;
/// The world frame a drive's poses are in, named when its input names none.
pub use source::WORLD_FRAME;
/// A drive, opened: its frames in order, how they are posed, what was skipped.
pub use source::{Source, SourceKind};
