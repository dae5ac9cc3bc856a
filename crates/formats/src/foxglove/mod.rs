//! Foxglove's message schemas (`foxglove.PointCloud`, `foxglove.FrameTransform`, ...)
//! in protobuf, as the Foxglove SDK and `mcap-protobuf-support` write them (nuScenes
//! and many fleets' MCAPs), and in JSON (`json.rs`), read as the ROS 2 messages they
//! stand for: [`to_cdr`] gives the CDR bytes of the equivalent, so everything past the
//! log reads a Foxglove log as a ROS 2 one.

mod basics;
mod cameras;
mod json;
mod point_cloud;

use super::log_message::Part;
use super::protobuf::fields;
use super::ros::{
    CameraInfo, CompressedImage, Header, Image, Odometry, PointCloud2, Pose, PoseStamped,
    Ros2Message, RosMessage, TfMessage, Transform, TransformStamped, encode,
};
use basics::{each_field, odometry_of, pose, quaternion, timestamp, vector3};
use cameras::{camera_calibration, compressed_image, raw_image};
use point_cloud::point_cloud;

/// The message encodings of the schemas read here.
pub const PROTOBUF: &str = "protobuf";
pub const JSON: &str = "json";

/// Whether travmap reads Foxglove's schemas in `message_encoding`.
pub fn reads(message_encoding: &str) -> bool {
    message_encoding == PROTOBUF || message_encoding == JSON
}

/// Each Foxglove schema read, with its ROS 2 equivalent's name and schema text.
const EQUIVALENTS: [(&str, &str, &str); 8] = [
    (
        "foxglove.PointCloud",
        PointCloud2::NAME,
        PointCloud2::SCHEMA,
    ),
    (
        "foxglove.FrameTransform",
        TfMessage::NAME,
        TfMessage::SCHEMA,
    ),
    (
        "foxglove.FrameTransforms",
        TfMessage::NAME,
        TfMessage::SCHEMA,
    ),
    (
        "foxglove.CompressedImage",
        CompressedImage::NAME,
        CompressedImage::SCHEMA,
    ),
    ("foxglove.RawImage", Image::NAME, Image::SCHEMA),
    (
        "foxglove.CameraCalibration",
        CameraInfo::NAME,
        CameraInfo::SCHEMA,
    ),
    ("foxglove.Odometry", Odometry::NAME, Odometry::SCHEMA),
    (
        "foxglove.PoseInFrame",
        PoseStamped::NAME,
        PoseStamped::SCHEMA,
    ),
];

/// The Foxglove schemas read.
pub const SCHEMAS: [&str; EQUIVALENTS.len()] = {
    let mut names = [""; EQUIVALENTS.len()];
    let mut i = 0;
    while i < names.len() {
        names[i] = EQUIVALENTS[i].0;
        i += 1;
    }
    names
};

/// The ROS 2 equivalent of a Foxglove schema: its type name and schema text.
pub fn ros_equivalent(schema_name: &str) -> Option<(&'static str, &'static str)> {
    (EQUIVALENTS.iter())
        .find(|(name, ..)| *name == schema_name)
        .map(|&(_, ros, schema)| (ros, schema))
}

/// A message of a Foxglove schema travmap reads (`schema_name`, in
/// `message_encoding`) re-encoded as its ROS 2 equivalent; None for other messages.
pub fn to_ros2(
    schema_name: &str,
    message_encoding: &str,
    data: &[u8],
) -> Option<Result<Ros2Message, String>> {
    let (name, schema) = ros_equivalent(schema_name).filter(|_| reads(message_encoding))?;
    let data = to_cdr(schema_name, message_encoding, data, Part::Whole);
    Some(data.map(|data| Ros2Message { name, schema, data }))
}

/// `data`, a message of the Foxglove schema `schema_name` in `message_encoding`
/// (protobuf or JSON), as the CDR bytes of its ROS 2 equivalent; with
/// [`Part::Header`] without its payload (points, pixels), which the pass does not
/// read.
pub fn to_cdr(
    schema_name: &str,
    message_encoding: &str,
    data: &[u8],
    part: Part,
) -> Result<Vec<u8>, String> {
    let whole = part == Part::Whole;
    let read = match message_encoding {
        PROTOBUF => from_protobuf(schema_name, data, whole),
        JSON => json::to_cdr(schema_name, data, whole),
        other => Err(format!(
            "travmap reads these in {PROTOBUF} and {JSON}, not {other}"
        )),
    };
    read.map_err(|problem| format!("{schema_name} ({message_encoding}): {problem}"))
}

/// [`to_cdr`] of a protobuf message.
fn from_protobuf(schema_name: &str, data: &[u8], whole: bool) -> Result<Vec<u8>, String> {
    Ok(match schema_name {
        "foxglove.PointCloud" => point_cloud(data, whole)?,
        "foxglove.FrameTransform" => encode(
            &TfMessage {
                transforms: vec![frame_transform(data)?],
            },
            256,
        ),
        "foxglove.FrameTransforms" => {
            let mut transforms = Vec::new();
            for field in fields(data) {
                if let (1, value) = field? {
                    transforms.push(frame_transform(value.bytes(1)?)?);
                }
            }
            encode(&TfMessage { transforms }, 256)
        }
        "foxglove.CompressedImage" => {
            let image = compressed_image(data, whole)?;
            encode(&image, image.data.len())
        }
        "foxglove.RawImage" => {
            let image = raw_image(data, whole)?;
            encode(&image, image.data.len())
        }
        "foxglove.CameraCalibration" => encode(&camera_calibration(data)?, 512),
        "foxglove.Odometry" => encode(&odometry(data)?, 512),
        "foxglove.PoseInFrame" => encode(&pose_in_frame(data)?, 128),
        other => return Err(format!("{other} is not a schema travmap reads")),
    })
}

/// `foxglove.FrameTransform`: the pose of `child_frame_id` in `parent_frame_id`,
/// as ROS's TransformStamped says it; without a rotation, none.
fn frame_transform(message: &[u8]) -> Result<TransformStamped, String> {
    let mut t = TransformStamped {
        header: Header::default(),
        child_frame_id: String::new(),
        transform: Transform::default(),
    };
    each_field(message, |n, value| {
        match n {
            1 => t.header.stamp = timestamp(value.bytes(n)?)?,
            2 => t.header.frame_id = value.string(n)?,
            3 => t.child_frame_id = value.string(n)?,
            4 => t.transform.translation = vector3(value.bytes(n)?)?,
            5 => t.transform.rotation = quaternion(value.bytes(n)?)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(t)
}

/// `foxglove.Odometry`: the pose of `body_frame_id` in `frame_id`.
fn odometry(message: &[u8]) -> Result<Odometry, String> {
    let (mut header, mut body, mut body_pose) = (Header::default(), String::new(), Pose::default());
    each_field(message, |n, value| {
        match n {
            1 => header.stamp = timestamp(value.bytes(n)?)?,
            2 => header.frame_id = value.string(n)?,
            3 => body = value.string(n)?,
            4 => body_pose = pose(value.bytes(n)?)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(odometry_of(header, body, body_pose))
}

/// `foxglove.PoseInFrame`: a pose in `frame_id`, read as a PoseStamped (a pose
/// topic, `pose_topics.rs`).
fn pose_in_frame(message: &[u8]) -> Result<PoseStamped, String> {
    let mut stamped = PoseStamped {
        header: Header::default(),
        pose: Pose::default(),
    };
    each_field(message, |n, value| {
        match n {
            1 => stamped.header.stamp = timestamp(value.bytes(n)?)?,
            2 => stamped.header.frame_id = value.string(n)?,
            3 => stamped.pose = pose(value.bytes(n)?)?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(stamped)
}

#[cfg(test)]
mod tests {
    use super::basics::wire::*;
    use super::*;
    use crate::ros::{Quaternion, Vector3, decode};

    #[test]
    fn frame_transforms_read_as_a_tf_message() {
        let moved = message(|m| {
            bytes(1, &stamp(9, 0), m);
            bytes(2, b"map", m);
            bytes(3, b"base_link", m);
            bytes(4, &vector(1.0, -2.0, 0.5), m);
            bytes(5, &message(|q| double(4, 1.0, q)), m);
        });
        let unturned = message(|m| {
            bytes(2, b"base_link", m);
            bytes(3, b"lidar", m);
        });
        let both = message(|m| {
            bytes(1, &moved, m);
            bytes(1, &unturned, m);
        });
        let read: TfMessage =
            decode(&to_cdr("foxglove.FrameTransforms", PROTOBUF, &both, Part::Whole).unwrap())
                .unwrap();
        let [first, second] = &read.transforms[..] else {
            panic!("{read:?}")
        };
        assert_eq!(
            (
                first.header.frame_id.as_str(),
                first.child_frame_id.as_str()
            ),
            ("map", "base_link")
        );
        assert_eq!(first.header.stamp.sec, 9);
        assert_eq!(
            first.transform.translation,
            Vector3 {
                x: 1.0,
                y: -2.0,
                z: 0.5
            }
        );
        assert_eq!(
            second.transform,
            Transform::default(),
            "no rotation written: none"
        );
        let one: TfMessage =
            decode(&to_cdr("foxglove.FrameTransform", PROTOBUF, &moved, Part::Whole).unwrap())
                .unwrap();
        assert_eq!(one.transforms, std::slice::from_ref(first));
    }

    #[test]
    fn odometry_reads_as_the_pose_of_its_body() {
        let odometry = message(|m| {
            bytes(1, &stamp(2, 0), m);
            bytes(2, b"odom", m);
            bytes(3, b"base_link", m);
            bytes(4, &message(|p| bytes(1, &vector(4.0, 5.0, 6.0), p)), m);
        });
        let read: Odometry =
            decode(&to_cdr("foxglove.Odometry", PROTOBUF, &odometry, Part::Whole).unwrap())
                .unwrap();
        assert_eq!(
            (read.header.frame_id.as_str(), read.child_frame_id.as_str()),
            ("odom", "base_link")
        );
        assert_eq!(
            read.pose.pose.position,
            Vector3 {
                x: 4.0,
                y: 5.0,
                z: 6.0
            }
        );
        assert_eq!(read.pose.pose.orientation, Quaternion::default());
        // A PoseInFrame names no body: a PoseStamped, read as a pose topic.
        let in_frame = message(|m| {
            bytes(1, &stamp(3, 5), m);
            bytes(2, b"map", m);
            bytes(3, &message(|p| bytes(1, &vector(7.0, 8.0, 9.0), p)), m);
        });
        let read: PoseStamped =
            decode(&to_cdr("foxglove.PoseInFrame", PROTOBUF, &in_frame, Part::Whole).unwrap())
                .unwrap();
        assert_eq!(
            (read.header.frame_id.as_str(), read.header.stamp.nanosec),
            ("map", 5)
        );
        assert_eq!(read.pose.position.z, 9.0);
    }

    #[test]
    fn messages_that_do_not_read_say_why() {
        let error =
            |schema: &str, data: &[u8]| to_cdr(schema, PROTOBUF, data, Part::Whole).unwrap_err();
        let late = message(|m| bytes(1, &stamp(1, 1_000_000_000), m));
        assert!(
            error("foxglove.FrameTransform", &late).contains("a timestamp's nanos of 1000000000")
        );
        let wrong_type = message(|m| fixed32(2, 1, m));
        assert!(error("foxglove.FrameTransform", &wrong_type).contains("field 2: expected bytes"));
        assert_eq!(
            ros_equivalent("foxglove.PointCloud"),
            Some((PointCloud2::NAME, PointCloud2::SCHEMA))
        );
        assert_eq!(ros_equivalent("foxglove.SceneUpdate"), None);
    }
}
