//! How to read a recorded log: the topics, frames and sensors a user names, each
//! found by itself where none is named.

use super::by_topic::{LidarCalibrations, LidarFrames};

/// How to read a recorded log; everything found by itself where None.
#[derive(Clone, Debug, Default)]
pub struct LogOptions {
    pub cloud_topic: Option<String>,
    /// Cloud topics merged into `cloud_topic`'s scans (several LiDARs).
    pub merged_topics: MergedTopics,
    pub world_frame: Option<String>,
    /// The image topic (Image or CompressedImage) whose frame has a CameraInfo; found
    /// by itself when there is exactly one.
    pub camera_topic: Option<String>,
    /// The pose topic (PoseStamped / PoseWithCovarianceStamped) that poses the
    /// vehicle, when there are several.
    pub pose_topic: Option<String>,
    /// Packet topics' calibration files (`--lidar-calibration`).
    pub lidar_calibrations: LidarCalibrations,
    /// The frames LiDAR topics' points are in, where the log's are missing or
    /// wrong (`--lidar-frame`).
    pub lidar_frames: LidarFrames,
}

/// Which other cloud topics are merged into the frames' scans.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum MergedTopics {
    /// One sensor.
    #[default]
    None,
    /// These cloud or packet topics.
    Topics(Vec<String>),
    /// Every cloud or packet topic but the frames' own.
    All,
}

impl MergedTopics {
    /// The frames' own topic and the topics merged into its scans, from the LiDAR
    /// topics named (`--cloud-topic`, repeated): the first, with the others merged
    /// in; `all` merges every cloud and packet topic.
    pub fn from_arguments(topics: &[String]) -> (Option<String>, MergedTopics) {
        match topics {
            [] => (None, MergedTopics::None),
            [all] if all == "all" => (None, MergedTopics::All),
            [one] => (Some(one.clone()), MergedTopics::None),
            [first, more @ ..] => (Some(first.clone()), MergedTopics::Topics(more.to_vec())),
        }
    }
}
