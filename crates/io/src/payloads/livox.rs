//! Livox LiDARs' own point message, read as a PointCloud2: what their ROS drivers
//! publish for FAST-LIO and other LiDAR odometry in place of one.

use serde::{Deserialize, Serialize};

use travmap_formats::ros::{Header, MessageEncoding, PointCloud2, PointField, datatype};

/// `livox_ros_driver2/msg/CustomMsg` (ROS 1's `livox_ros_driver/CustomMsg` has the same
/// fields): a Livox LiDAR's points as its driver publishes them for FAST-LIO and other
/// LiDAR odometry, in place of a PointCloud2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LivoxCustomMsg {
    pub header: Header,
    /// The first point's time, ns.
    pub timebase: u64,
    pub point_num: u32,
    pub lidar_id: u8,
    pub rsvd: [u8; 3],
    pub points: Vec<LivoxPoint>,
}

/// `livox_ros_driver2/msg/CustomPoint`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LivoxPoint {
    /// After `timebase`, ns.
    pub offset_time: u32,
    pub x: f32,
    pub y: f32,
    pub z: f32,
    /// 0..255.
    pub reflectivity: u8,
    pub tag: u8,
    pub line: u8,
}

/// Livox CustomMsg's type names, of its ROS 2 and ROS 1 drivers.
pub const LIVOX_CUSTOM_MESSAGES: [&str; 2] = [
    "livox_ros_driver2/msg/CustomMsg",
    "livox_ros_driver/msg/CustomMsg",
];

/// The cloud of a message of type `type_name`: a PointCloud2, or a Livox CustomMsg's
/// points as one (x, y, z float32, the 0..255 reflectivity as a uint8 `intensity`,
/// which reads as a byte-scale remission).
pub fn decode_cloud(
    type_name: &str,
    encoding: MessageEncoding,
    data: &[u8],
) -> Result<PointCloud2, String> {
    if !LIVOX_CUSTOM_MESSAGES.contains(&type_name) {
        return encoding.decode(data);
    }
    let livox: LivoxCustomMsg = encoding.decode(data)?;
    const STEP: usize = 13;
    let mut bytes = Vec::with_capacity(livox.points.len() * STEP);
    for p in &livox.points {
        for v in [p.x, p.y, p.z] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.push(p.reflectivity);
    }
    let mut fields = PointField::xyz_float32();
    fields.push(PointField::scalar("intensity", 12, datatype::UINT8));
    Ok(PointCloud2 {
        header: livox.header,
        height: 1,
        width: livox.points.len() as u32,
        fields,
        is_bigendian: false,
        point_step: STEP as u32,
        row_step: (STEP * livox.points.len()) as u32,
        data: bytes,
        is_dense: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payloads::cloud::cloud_points;
    use travmap_core::frame::RemissionScale;

    /// A CustomMsg as rosbags 0.11.9 serialises it (fuzz/seeds/ros_point_cloud).
    #[test]
    fn a_livox_custom_msg_reads_as_a_cloud_with_byte_remission() {
        let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
            .join("fuzz/seeds/ros_point_cloud/livox_custom_msg.cdr");
        let data = std::fs::read(path).unwrap();
        let cloud = decode_cloud(LIVOX_CUSTOM_MESSAGES[0], MessageEncoding::Cdr, &data).unwrap();
        assert_eq!(cloud.header.frame_id, "livox_frame");
        assert_eq!(cloud.header.stamp.to_ns(), 5_000_000_006);
        let read = cloud_points(&cloud).unwrap();
        assert_eq!(read.remission, RemissionScale::Byte);
        let expected = [
            [1.5, -2.0, 0.25, 37.0 / 255.0],
            [3.0, 0.5, -1.0, 200.0 / 255.0],
        ];
        assert_eq!(read.points.len(), 2);
        for (point, expected) in read.points.iter().zip(expected) {
            assert_eq!(point[..3], expected[..3]);
            assert!((point[3] - expected[3]).abs() < 1e-6, "{point:?}");
        }
        // A PointCloud2's type reads as one; a cut CustomMsg is an error.
        assert!(decode_cloud("sensor_msgs/msg/PointCloud2", MessageEncoding::Cdr, &data).is_err());
        assert!(decode_cloud(LIVOX_CUSTOM_MESSAGES[1], MessageEncoding::Cdr, &data[..60]).is_err());
    }
}
