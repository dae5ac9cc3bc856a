//! Ouster lidar packets as ouster_ros records them: one UDP packet per
//! `ouster_sensor_msgs/msg/PacketMsg` (`uint8[] buf`, no header) on
//! `/ouster/lidar_packets`, and the sensor's metadata JSON (`std_msgs/String`) on
//! `/ouster/metadata`. Unlike Velodyne's and Hesai's, the packets do not say how
//! they are laid out: the metadata does ([`OusterMetadata`]: the UDP profile, beams
//! per column, columns per packet and per frame, and the beams' angles), read from
//! the log or from `--lidar-calibration`.
//!
//! Points are in the sensor frame of Ouster's documentation (`os_sensor`, as
//! ouster_ros names it): x forward, z up, the lidar frame turned half a turn about
//! z and lifted to the window. A point is the beam's origin plus its range along
//! the beam, with the documentation's (and the SDK's `XYZLut`'s) formula.

mod assembler;
mod metadata;
mod packet;

pub use assembler::OusterAssembler;
pub use metadata::{OusterMetadata, string_message};
pub use packet::OusterModel;

use super::message::ScanMessage;
use travmap_formats::ros::MessageEncoding;

/// ouster_ros's packet message: ROS 2 (`ouster_sensor_msgs`, `ouster_msgs` before
/// 0.11) and ROS 1.
pub const OUSTER_PACKET_MESSAGES: [&str; 3] = [
    "ouster_sensor_msgs/msg/PacketMsg",
    "ouster_msgs/msg/PacketMsg",
    "ouster_ros/msg/PacketMsg",
];

/// `PacketMsg`'s definition, for the packets of a capture (`crate::containers::pcap`).
pub const PACKET_MSG_SCHEMA: &str =
    include_str!("../../../../../schemas/ouster_sensor_msgs__PacketMsg.msg");

/// The frame the points are in.
pub const OUSTER_FRAME: &str = "os_sensor";

/// The message type of the metadata, and the last part of its topic's name.
pub const METADATA_MESSAGE: &str = "std_msgs/msg/String";
pub const METADATA_TOPIC_NAME: &str = "metadata";

/// Reads a PacketMsg recorded at `log_time_ns`: its one packet, stamped with that
/// time (the message has no stamp of its own).
pub fn packet_msg_message(
    data: &[u8],
    encoding: MessageEncoding,
    log_time_ns: u64,
) -> Result<ScanMessage<'_>, String> {
    let body = match encoding {
        MessageEncoding::Cdr => match data {
            [0, 1, _, _, body @ ..] => body,
            _ => return Err("only little-endian CDR is read".into()),
        },
        MessageEncoding::Ros1 => data,
    };
    let (length, packet) = body
        .split_first_chunk::<4>()
        .ok_or("a packet message of fewer than 4 bytes")?;
    let length = u32::from_le_bytes(*length) as usize;
    let packet = packet.get(..length).ok_or_else(|| {
        format!(
            "a packet of {length} bytes claimed in {} bytes",
            packet.len()
        )
    })?;
    Ok(ScanMessage {
        frame_id: OUSTER_FRAME.to_string(),
        stamp_ns: log_time_ns,
        packets: vec![(log_time_ns, packet)],
    })
}

/// The metadata topic of packet topic `topic`: the one in its namespace
/// (`/ouster/lidar_packets` -> `/ouster/metadata`), else the log's only one.
pub fn metadata_topic_of<'a>(
    topic: &str,
    metadata_topics: impl Iterator<Item = &'a String> + Clone,
) -> Option<&'a String> {
    let namespace = |t: &str| t.rsplit_once('/').map_or("", |(ns, _)| ns).to_string();
    let own = namespace(topic);
    (metadata_topics.clone())
        .find(|m| namespace(m) == own)
        .or_else(|| {
            let mut all = metadata_topics;
            let only = all.next();
            only.filter(|_| all.next().is_none())
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packet_message_is_its_bytes_in_ros_2_and_ros_1() {
        let cdr = [0, 1, 0, 0, 3, 0, 0, 0, 7, 8, 9];
        let message = packet_msg_message(&cdr, MessageEncoding::Cdr, 5).unwrap();
        assert_eq!(message.packets, vec![(5, &[7u8, 8, 9][..])]);
        assert_eq!(message.frame_id, OUSTER_FRAME);
        let ros1 = [3, 0, 0, 0, 7, 8, 9];
        let message = packet_msg_message(&ros1, MessageEncoding::Ros1, 5).unwrap();
        assert_eq!(message.packets, vec![(5, &[7u8, 8, 9][..])]);
        let short = [0, 1, 0, 0, 9, 0, 0, 0, 7];
        let problem = packet_msg_message(&short, MessageEncoding::Cdr, 5)
            .err()
            .unwrap();
        assert!(problem.contains("9 bytes claimed in 1"), "{problem}");
    }

    #[test]
    fn a_packet_topic_takes_the_metadata_of_its_namespace() {
        let topics: Vec<String> = ["/front/metadata", "/rear/metadata"]
            .map(String::from)
            .into();
        let of = |topic| metadata_topic_of(topic, topics.iter()).map(String::as_str);
        assert_eq!(of("/rear/lidar_packets"), Some("/rear/metadata"));
        assert_eq!(of("/top/lidar_packets"), None);
        let one: Vec<String> = vec!["/ouster/metadata".into()];
        assert_eq!(
            metadata_topic_of("/lidar_packets", one.iter()).map(String::as_str),
            Some("/ouster/metadata")
        );
    }
}
