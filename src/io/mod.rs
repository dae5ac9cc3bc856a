//! Stage 0, reading: a drive into [`Frame`]s (METHOD.md section 1). A [`Source`] is
//! a KITTI odometry / SemanticKITTI sequence directory ([`kitti`]) or a recorded ROS
//! log ([`ros_drive`] over a [`log::Log`]: MCAP, ROS 1 bag, rosbag2), told apart by
//! content ([`format`]). [`ros`] holds the message types (CDR; [`ros1`] reads ROS 1's
//! format into the same types), [`cloud`] and [`image`] decode their payloads.
//! Nothing here knows the method.

pub mod bag;
pub mod bag_messages;
mod bucket_store;
pub mod by_topic;
mod camera_model;
pub mod cloud;
pub mod drive_frames;
mod fixed_array;
pub mod format;
pub mod foxglove;
pub mod hesai;
pub mod image;
pub mod kitti;
mod kitti_text;
pub mod las;
pub mod livox;
pub mod log;
pub mod log_index;
pub mod log_message;
pub mod mcap_messages;
pub mod mcap_records;
pub mod mcap_stored;
mod merged_clouds;
pub mod ouster;
mod packet_topics;
pub mod packets;
pub mod pcap;
pub mod pcd;
pub mod ply;
mod point_rows;
pub mod pose_topics;
pub mod protobuf;
pub mod ros;
pub mod ros1;
pub mod ros_drive;
pub mod rosbag2;
pub mod scan_folder;
pub mod site_cloud;
mod skips;
mod source;
pub mod sqlite;
mod sqlite_wal;
pub mod transforms;
pub mod velodyne;

pub use kitti::KittiSequence;
pub use skips::{Skip, SkipLog};
pub use source::{Recording, Source, WORLD_FRAME};
