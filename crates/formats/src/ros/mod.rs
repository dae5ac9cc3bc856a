//! ROS 2 message types as serde structs, CDR-encoded as in rosbag2 MCAP files, and
//! the schema texts (`schemas/`) written with them.
//!
//! Field order is wire order. Only the types travmap reads or writes are here.

pub(crate) mod fixed_array;
pub mod ros1;

use byteorder::{BigEndian, LittleEndian};
use serde::{Deserialize, Serialize, de::DeserializeOwned};

pub use crate::ros::fixed_array::FixedArray;

/// A message type: its ROS name and the `ros2msg` schema text written to MCAP.
pub trait RosMessage: Serialize + DeserializeOwned {
    const NAME: &'static str;
    /// The definition with its dependencies, as rosbag2 stores it.
    const SCHEMA: &'static str;
}

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Splits nanoseconds since the epoch; saturates past 2038 (int32 seconds).
    pub fn from_ns(stamp_ns: u64) -> Self {
        Self {
            sec: (stamp_ns / 1_000_000_000).min(i32::MAX as u64) as i32,
            nanosec: (stamp_ns % 1_000_000_000) as u32,
        }
    }

    /// Nanoseconds since the epoch; negative times clamp to 0.
    pub fn to_ns(self) -> u64 {
        (self.sec.max(0) as u64) * 1_000_000_000 + self.nanosec as u64
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `sensor_msgs/msg/PointField`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

impl PointField {
    /// A single-valued field.
    pub fn scalar(name: &str, offset: u32, datatype: u8) -> Self {
        Self {
            name: name.into(),
            offset,
            datatype,
            count: 1,
        }
    }

    /// x, y, z as float32 at offsets 0, 4, 8: how travmap writes every cloud.
    pub fn xyz_float32() -> Vec<Self> {
        ["x", "y", "z"]
            .iter()
            .zip([0, 4, 8])
            .map(|(n, o)| Self::scalar(n, o, datatype::FLOAT32))
            .collect()
    }
}

/// PointField datatypes.
pub mod datatype {
    pub const INT8: u8 = 1;
    pub const UINT8: u8 = 2;
    pub const INT16: u8 = 3;
    pub const UINT16: u8 = 4;
    pub const INT32: u8 = 5;
    pub const UINT32: u8 = 6;
    pub const FLOAT32: u8 = 7;
    pub const FLOAT64: u8 = 8;

    /// Bytes per value, None for an unknown datatype.
    pub fn size(datatype: u8) -> Option<usize> {
        match datatype {
            INT8 | UINT8 => Some(1),
            INT16 | UINT16 => Some(2),
            INT32 | UINT32 | FLOAT32 => Some(4),
            FLOAT64 => Some(8),
            _ => None,
        }
    }
}

/// `sensor_msgs/msg/PointCloud2`; `Data` is owned bytes, or borrowed ones for
/// encoding points that are already laid out as the message's (no copy first).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(bound(
    serialize = "Data: serde_bytes::Serialize",
    deserialize = "Data: serde_bytes::Deserialize<'de>"
))]
pub struct PointCloud2<Data = Vec<u8>> {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    #[serde(with = "serde_bytes")]
    pub data: Data,
    pub is_dense: bool,
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/Image`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: String,
    pub is_bigendian: u8,
    pub step: u32,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}

/// `geometry_msgs/msg/Vector3` and `geometry_msgs/msg/Point` (same wire layout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`: `header.frame_id` is the parent,
/// the transform maps child coordinates to parent coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

/// `geometry_msgs/msg/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

/// `nav_msgs/msg/MapMetaData`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    pub map_load_time: Time,
    pub resolution: f32,
    pub width: u32,
    pub height: u32,
    pub origin: Pose,
}

/// `nav_msgs/msg/OccupancyGrid`: row-major from `origin`, x fastest; 0 free,
/// 100 occupied, -1 unknown.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    pub header: Header,
    pub info: MapMetaData,
    pub data: Vec<i8>,
}

/// `grid_map_msgs/msg/GridMap` (ANYbotics grid_map): float layers over one grid,
/// each a column-major `Float32MultiArray` whose (0, 0) is the cell of largest x and
/// y, rows along -x and columns along -y of `info.pose`, NaN where a layer has no
/// value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridMap {
    pub header: Header,
    pub info: GridMapInfo,
    pub layers: Vec<String>,
    pub basic_layers: Vec<String>,
    pub data: Vec<Float32MultiArray>,
    pub outer_start_index: u16,
    pub inner_start_index: u16,
}

/// `grid_map_msgs/msg/GridMapInfo`: the cell size, the map's side lengths (metres)
/// and the pose of its centre.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridMapInfo {
    pub resolution: f64,
    pub length_x: f64,
    pub length_y: f64,
    pub pose: Pose,
}

/// `foxglove_msgs/msg/Grid`: Foxglove's grid of packed fields, which its 3D panel
/// colours with no extension. Row-major from `pose` (the grid's corner), x along a
/// row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FoxgloveGrid {
    pub timestamp: Time,
    pub frame_id: String,
    pub pose: Pose,
    pub column_count: u32,
    pub cell_size: FoxgloveVector2,
    pub row_stride: u32,
    pub cell_stride: u32,
    pub fields: Vec<PackedElementField>,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `foxglove_msgs/msg/Vector2`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FoxgloveVector2 {
    pub x: f64,
    pub y: f64,
}

/// `foxglove_msgs/msg/PackedElementField`: a field of a packed cell; `type` 7 is
/// FLOAT32.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PackedElementField {
    pub name: String,
    pub offset: u32,
    pub r#type: u8,
}

/// `std_msgs/msg/Float32MultiArray`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Float32MultiArray {
    pub layout: MultiArrayLayout,
    pub data: Vec<f32>,
}

/// `std_msgs/msg/MultiArrayLayout`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayLayout {
    pub dim: Vec<MultiArrayDimension>,
    pub data_offset: u32,
}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayDimension {
    pub label: String,
    pub size: u32,
    pub stride: u32,
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Covariance6,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Covariance6,
}

/// `nav_msgs/msg/Odometry`: the pose of `child_frame_id` in `header.frame_id`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// `geometry_msgs/msg/PoseStamped`: a pose in `header.frame_id` (a pose topic's,
/// as the readers read pose topics; Foxglove's `PoseInFrame` is read as one).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

/// A `float64[36]` (a 6 x 6 covariance, row-major).
pub type Covariance6 = FixedArray<f64, 36>;

/// `velodyne_msgs/msg/VelodyneScan`: a turn's raw packets. Read in place for
/// decoding (the readers' Velodyne scan reader); this type re-encodes ROS 1 scans as
/// ROS 2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VelodyneScan {
    pub header: Header,
    pub packets: Vec<VelodynePacket>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VelodynePacket {
    pub stamp: Time,
    pub data: FixedArray<u8, 1206>,
}

/// `pandar_msgs/msg/PandarScan`: Hesai packets, each the first `size` bytes of
/// `data` (read in place by the readers' Hesai scan reader).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PandarScan {
    pub header: Header,
    pub packets: Vec<PandarPacket>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PandarPacket {
    pub stamp: Time,
    pub data: FixedArray<u8, 1500>,
    pub size: u32,
}

/// `robosense_msgs/msg/RobosenseScan`: RoboSense packets, data and DIFOP, each the
/// first `size` bytes of `data` (read in place by
/// the readers' RoboSense scan reader); this type gives the
/// schema logs recorded without one lack.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobosenseScan {
    pub header: Header,
    pub packets: Vec<RobosensePacket>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobosensePacket {
    pub stamp: Time,
    pub is_difop: u8,
    pub data: FixedArray<u8, 1500>,
    pub size: u32,
}

/// `nebula_msgs/msg/NebulaPackets`: nebula's packets of any sensor (read in place by
/// `travmap_io::packet_message`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NebulaPackets {
    pub header: Header,
    pub packets: Vec<NebulaPacket>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NebulaPacket {
    pub stamp: Time,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `travmap_msgs/msg/FrameMetrics`: travmap's per-frame result (schema in `schemas/`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameMetrics {
    pub header: Header,
    pub frame_index: u32,
    pub predictable_cells: u32,
    pub traversable_cells: u32,
    pub non_traversable_cells: u32,
    pub has_ground_truth: bool,
    pub true_positives: u32,
    pub true_negatives: u32,
    pub false_positives: u32,
    pub false_negatives: u32,
    pub unpredictable_with_ground_truth: u32,
    pub accuracy: f32,
    pub miou: f32,
    pub f1: f32,
    pub latency_ms: f32,
    /// Points of the scan dropped as no return (a NaN or infinite coordinate, or
    /// the sensor's origin).
    pub dropped_points: u32,
    /// Predictable cells whose classifier margin lies within 1 of the boundary:
    /// cells the model was unsure of (their share says how well the drive fits it).
    pub unsure_cells: u32,
}

/// The definition (ros2msg, its dependencies with it) of a message type travmap
/// knows, by its ROS 2 name: for a channel a log recorded without one (rosbag2
/// before Iron keeps none), so that what travmap writes can be decoded.
pub fn known_schema(ros2_name: &str) -> Option<&'static str> {
    fn entry<M: RosMessage>() -> (&'static str, &'static str) {
        (M::NAME, M::SCHEMA)
    }
    let known = [
        entry::<PointCloud2>(),
        entry::<Image>(),
        entry::<CompressedImage>(),
        entry::<CameraInfo>(),
        entry::<Odometry>(),
        entry::<PoseStamped>(),
        entry::<TfMessage>(),
        entry::<OccupancyGrid>(),
        entry::<GridMap>(),
        entry::<FoxgloveGrid>(),
        entry::<VelodyneScan>(),
        entry::<PandarScan>(),
        entry::<RobosenseScan>(),
        entry::<NebulaPackets>(),
    ];
    known
        .into_iter()
        .find(|(name, _)| *name == ros2_name)
        .map(|(_, schema)| schema)
}

macro_rules! ros_message {
    ($type:ty, $name:literal, $file:literal) => {
        impl RosMessage for $type {
            const NAME: &'static str = $name;
            const SCHEMA: &'static str = include_str!(concat!("../../../../schemas/", $file));
        }
    };
}

ros_message!(
    PointCloud2,
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs__PointCloud2.msg"
);
ros_message!(Image, "sensor_msgs/msg/Image", "sensor_msgs__Image.msg");
ros_message!(Odometry, "nav_msgs/msg/Odometry", "nav_msgs__Odometry.msg");
ros_message!(
    PoseStamped,
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs__PoseStamped.msg"
);
ros_message!(
    CompressedImage,
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs__CompressedImage.msg"
);
ros_message!(
    CameraInfo,
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs__CameraInfo.msg"
);
ros_message!(
    TfMessage,
    "tf2_msgs/msg/TFMessage",
    "tf2_msgs__TFMessage.msg"
);
ros_message!(
    OccupancyGrid,
    "nav_msgs/msg/OccupancyGrid",
    "nav_msgs__OccupancyGrid.msg"
);
ros_message!(
    FoxgloveGrid,
    "foxglove_msgs/msg/Grid",
    "foxglove_msgs__Grid.msg"
);
ros_message!(
    GridMap,
    "grid_map_msgs/msg/GridMap",
    "grid_map_msgs__GridMap.msg"
);
ros_message!(
    VelodyneScan,
    "velodyne_msgs/msg/VelodyneScan",
    "velodyne_msgs__VelodyneScan.msg"
);
ros_message!(
    PandarScan,
    "pandar_msgs/msg/PandarScan",
    "pandar_msgs__PandarScan.msg"
);
ros_message!(
    RobosenseScan,
    "robosense_msgs/msg/RobosenseScan",
    "robosense_msgs__RobosenseScan.msg"
);
ros_message!(
    NebulaPackets,
    "nebula_msgs/msg/NebulaPackets",
    "nebula_msgs__NebulaPackets.msg"
);
ros_message!(
    FrameMetrics,
    "travmap_msgs/msg/FrameMetrics",
    "travmap_msgs__FrameMetrics.msg"
);

/// How a log serialises its messages: ROS 2's CDR or ROS 1's format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MessageEncoding {
    Cdr,
    Ros1,
}

impl MessageEncoding {
    /// From an MCAP `message_encoding` (rosbag2's `serialization_format`); None for
    /// encodings travmap does not read.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "cdr" => Some(Self::Cdr),
            "ros1" => Some(Self::Ros1),
            _ => None,
        }
    }

    /// Decodes a message in this encoding.
    pub fn decode<T: DeserializeOwned>(self, bytes: &[u8]) -> Result<T, String> {
        match self {
            Self::Cdr => decode(bytes),
            Self::Ros1 => crate::ros::ros1::decode(bytes),
        }
    }
}

/// A message re-encoded as ROS 2: its type, schema and CDR bytes.
pub struct Ros2Message {
    pub name: &'static str,
    pub schema: &'static str,
    pub data: Vec<u8>,
}

/// A ROS 1 message of a type travmap knows (by its ROS 2 name, see
/// `Connection::type_name`) re-encoded as ROS 2 CDR; None for other
/// types.
pub fn ros1_to_cdr(type_name: &str, data: &[u8]) -> Option<Result<Ros2Message, String>> {
    fn translate<T: RosMessage>(data: &[u8]) -> Result<Ros2Message, String> {
        let message: T = crate::ros::ros1::decode(data)?;
        Ok(Ros2Message {
            name: T::NAME,
            schema: T::SCHEMA,
            data: encode(&message, data.len()),
        })
    }
    Some(match type_name {
        "sensor_msgs/msg/PointCloud2" => translate::<PointCloud2>(data),
        "tf2_msgs/msg/TFMessage" | "tf/msg/tfMessage" => translate::<TfMessage>(data),
        "nav_msgs/msg/Odometry" => translate::<Odometry>(data),
        "sensor_msgs/msg/CameraInfo" => translate::<CameraInfo>(data),
        "sensor_msgs/msg/CompressedImage" => translate::<CompressedImage>(data),
        "sensor_msgs/msg/Image" => translate::<Image>(data),
        "velodyne_msgs/msg/VelodyneScan" => translate::<VelodyneScan>(data),
        "pandar_msgs/msg/PandarScan" => translate::<PandarScan>(data),
        _ => return None,
    })
}

/// The CDR encapsulation header of little-endian plain CDR (big-endian: 00 00 00 00).
const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Encodes a message as ROS 2 does: encapsulation header, then little-endian CDR.
pub fn encode<T: Serialize>(message: &T, size_hint: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(size_hint + 4);
    out.extend_from_slice(&CDR_LE);
    // Serialising plain structs into a Vec cannot fail.
    cdr_encoding::to_writer::<_, LittleEndian, _>(&mut out, message)
        .expect("CDR encoding of an in-memory message");
    out
}

/// Decodes a ROS 2 CDR message, either byte order; the error says what failed.
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    if bytes.len() < 4 {
        return Err(format!(
            "{} bytes, shorter than the 4-byte CDR header",
            bytes.len()
        ));
    }
    let (header, body) = bytes.split_at(4);
    let decoded = match header[..2] {
        [0x00, 0x01] => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        [0x00, 0x00] => cdr_encoding::from_bytes::<T, BigEndian>(body),
        // rosbag2's message compression: the metadata that says so was not read.
        [0x28, 0xb5] if header[2..] == [0x2f, 0xfd] => {
            return Err(
                "the message is a zstd frame (rosbag2 compresses each message in \
                 message mode): open the bag's directory, whose metadata.yaml says so"
                    .into(),
            );
        }
        _ => {
            return Err(format!(
                "CDR encapsulation {:02x} {:02x} is not plain CDR",
                header[0], header[1]
            ));
        }
    };
    decoded
        .map(|(message, _)| message)
        .map_err(|e| format!("CDR decoding failed: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_cloud_round_trips_and_has_the_ros_layout() {
        let cloud = PointCloud2 {
            header: Header {
                stamp: Time { sec: 5, nanosec: 7 },
                frame_id: "velodyne".into(),
            },
            height: 1,
            width: 1,
            fields: vec![PointField {
                name: "x".into(),
                offset: 0,
                datatype: datatype::FLOAT32,
                count: 1,
            }],
            is_bigendian: false,
            point_step: 4,
            row_step: 4,
            data: 1.5f32.to_le_bytes().to_vec(),
            is_dense: true,
        };
        let bytes = encode(&cloud, 0);
        // Header, sec, nanosec, frame_id length 9 ("velodyne\0"), ...
        assert_eq!(&bytes[..4], &CDR_LE);
        assert_eq!(&bytes[4..8], &5i32.to_le_bytes());
        assert_eq!(&bytes[12..16], &9u32.to_le_bytes());
        assert_eq!(&bytes[16..25], b"velodyne\0");
        assert_eq!(decode::<PointCloud2>(&bytes).unwrap(), cloud);
        assert!(decode::<PointCloud2>(&bytes[..bytes.len() - 3]).is_err());
        assert!(decode::<PointCloud2>(&[0, 1]).is_err());
    }

    #[test]
    fn schemas_name_their_dependencies() {
        assert!(PointCloud2::SCHEMA.contains("MSG: sensor_msgs/PointField"));
        assert!(TfMessage::SCHEMA.contains("MSG: geometry_msgs/Quaternion"));
        assert!(OccupancyGrid::SCHEMA.starts_with("std_msgs/Header header"));
    }

    #[test]
    fn times_split_nanoseconds() {
        let t = Time::from_ns(1_317_000_000_123_456_789);
        assert_eq!((t.sec, t.nanosec), (1_317_000_000, 123_456_789));
        assert_eq!(t.to_ns(), 1_317_000_000_123_456_789);
    }
}
