//! `velodyne_msgs/msg/VelodyneScan` messages, ROS 2 (CDR) and ROS 1, read in place.

use super::packet::PACKET_BYTES;
use crate::packets::message::{PacketField, ScanMessage, packets_message};
use travmap_formats::ros::MessageEncoding;

/// The message type that carries packets.
pub const VELODYNE_SCAN: &str = "velodyne_msgs/msg/VelodyneScan";

/// Reads a VelodyneScan (`Header header`, `VelodynePacket[] packets` of
/// `time stamp`, `uint8[1206] data`) without copying its packets.
pub fn scan_message(data: &[u8], encoding: MessageEncoding) -> Result<ScanMessage<'_>, String> {
    packets_message(data, encoding, PacketField::Fixed(PACKET_BYTES))
}
