pub mod bag;
pub mod bag_messages;
pub mod log;
pub mod pcap;
pub mod rosbag2;
pub mod sqlite;
pub(crate) mod sqlite_wal;
