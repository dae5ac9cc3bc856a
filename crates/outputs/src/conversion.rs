//! KITTI / SemanticKITTI sequence or a recorded ROS log -> ROS 2 MCAP (`travmap
//! convert`).
//!
//! A log ([`convert_log`]): every message in order, the types travmap knows
//! re-encoded as ROS 2 CDR when they were recorded in ROS 1 or as Foxglove's protobuf
//! schemas (same topics, stamps and frames), everything else copied as recorded with
//! its own encoding and schema (an MCAP file holds mixed encodings).
//!
//! A KITTI sequence:
//! Per scan: a `sensor_msgs/msg/PointCloud2` (x, y, z, intensity float32, plus a
//! `label` uint32 when SemanticKITTI labels exist) in frame `velodyne`, and `/tf` with
//! the scan's pose in the z-up `map` frame (the first scan's velodyne frame,
//! `inv(Tr) * pose_i * Tr`). Per image: the PNG passed through unchanged as a
//! `sensor_msgs/msg/CompressedImage` and a `sensor_msgs/msg/CameraInfo` from P2. Once:
//! `/tf_static` with velodyne -> camera_0 (from Tr) and camera_0 -> camera_2 (the
//! baseline in P2). Log time = header stamp = start time + times.txt. Frames are read
//! and encoded in parallel batches, written in order.

use std::borrow::Cow;
use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3};
use rayon::prelude::*;
use serde::Serialize;

use crate::writing::McapSink;
use travmap_core::error::{Error, Result};
use travmap_core::frame::Frame;
use travmap_formats::foxglove;
use travmap_formats::log_message::ros2_type_name;
use travmap_formats::mcap::writer::Compression;
use travmap_formats::ros::{
    CameraInfo, CompressedImage, Header, MessageEncoding, PointCloud2, PointField, Quaternion,
    RegionOfInterest, TfMessage, Time, Transform, TransformStamped, Vector3, datatype, encode,
    known_schema, ros1_to_cdr,
};
use travmap_io::{
    OUSTER_PACKET_MESSAGES, PACKET_MSG_SCHEMA, PacketScan, RecordedKitti, RecordedLog,
};

pub const CLOUD_TOPIC: &str = "/velodyne_points";
pub const IMAGE_TOPIC: &str = "/camera_2/image/compressed";
pub const CAMERA_INFO_TOPIC: &str = "/camera_2/camera_info";
pub const MAP_FRAME: &str = travmap_io::WORLD_FRAME;
pub const VELODYNE_FRAME: &str = "velodyne";
pub const CAMERA_0_FRAME: &str = "camera_0";
pub const CAMERA_2_FRAME: &str = "camera_2";

/// Frames encoded in parallel before they are written in order.
const BATCH: usize = 16;

#[derive(Clone, Debug, Serialize)]
pub struct ConversionSummary {
    pub frames: usize,
    pub images: usize,
    pub labelled_frames: usize,
    /// Scan points left out as no return (`io::cloud::is_return`).
    pub dropped_points: u64,
    pub output_bytes: u64,
}

/// What [`write_log_messages`] wrote.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LogCopySummary {
    pub messages: usize,
    /// ROS 1 and Foxglove messages of the types travmap knows, re-encoded as ROS 2
    /// CDR.
    pub translated_messages: usize,
    /// Topics copied as recorded, in an encoding other than ROS 2 CDR.
    pub topics_as_recorded: Vec<String>,
    /// LiDAR packet input: the first topic scans were written to as PointCloud2,
    /// every such topic (one per packet topic read), and how many scans.
    pub decoded_topic: Option<String>,
    pub decoded_topics: Vec<String>,
    pub decoded_scans: usize,
    /// Whether the part of a rotation the log began with was left out of the
    /// decoded scans (it would share the next scan's stamp).
    pub partial_first_scan_left_out: bool,
    pub output_bytes: u64,
}

/// The definition of ouster_ros's packet message (ROS 2 names).
fn ouster_schema(ros2_name: &str) -> Option<&'static str> {
    OUSTER_PACKET_MESSAGES[..2]
        .contains(&ros2_name)
        .then_some(PACKET_MSG_SCHEMA)
}

/// Every message of `drive` into `sink`, in order, as ROS 2 where travmap knows the
/// type (see the module's comment). `on_messages(topic, count)` is called before
/// messages are written.
///
/// An MCAP input with nothing to translate is copied chunk by chunk as stored, when
/// its chunks allow it ([`McapSink::copy_chunks`]; with their own compression when
/// `as_recorded`, else only when it is the sink's): the same messages with their
/// own sequence numbers, none decompressed.
pub fn write_log_messages(
    sink: &mut McapSink,
    drive: &RecordedLog,
    as_recorded: bool,
    on_messages: &dyn Fn(&str, u64),
) -> Result<LogCopySummary> {
    let mut summary = LogCopySummary::default();
    let stored = drive.stored().filter(|stored| !stored.needs_translation());
    if let Some(stored) = stored {
        let topics: HashMap<u16, String> = stored
            .channels
            .iter()
            .map(|c| (c.id, c.topic.clone()))
            .collect();
        let used = stored.chunks.iter().flat_map(|chunk| &chunk.channels);
        let used = |id| used.clone().any(|c| c.id == id && c.messages > 0);
        let as_recorded_topics = stored
            .channels
            .iter()
            .filter(|c| c.message_encoding != "cdr" && used(c.id))
            .map(|c| c.topic.clone())
            .collect();
        let messages = stored.messages() as usize;
        let copied = sink.copy_chunks(stored, as_recorded, &|chunk| {
            for channel in &chunk.channels {
                let topic = topics.get(&channel.id).map_or("", String::as_str);
                on_messages(topic, channel.messages);
            }
        })?;
        if copied {
            summary.messages = messages;
            summary.topics_as_recorded = as_recorded_topics;
            return Ok(summary);
        }
    }
    for message in drive.messages() {
        let message = message?;
        on_messages(&message.connection.topic, 1);
        let connection = &message.connection;
        let translated = match connection.encoding() {
            Some(MessageEncoding::Ros1) => ros1_to_cdr(&connection.type_name(), &message.data),
            _ => foxglove::to_ros2(
                &connection.schema_name,
                &connection.message_encoding,
                &message.data,
            ),
        };
        let (channel, data) = match translated {
            Some(Ok(ros2)) => {
                summary.translated_messages += 1;
                let id = sink.channel(
                    &connection.topic,
                    ros2.name,
                    "ros2msg",
                    ros2.schema.as_bytes(),
                    "cdr",
                )?;
                (id, ros2.data)
            }
            Some(Err(problem)) => {
                return Err(Error::UndecodableMessage {
                    path: drive.path().to_path_buf(),
                    topic: connection.topic.clone(),
                    schema: connection.schema_name.clone(),
                    log_time_ns: message.log_time_ns,
                    problem,
                });
            }
            None => {
                if connection.message_encoding != "cdr"
                    && !summary.topics_as_recorded.contains(&connection.topic)
                {
                    summary.topics_as_recorded.push(connection.topic.clone());
                }
                // A recording without the definition (rosbag2 before Iron) gets
                // travmap's, where it knows the type: decoders need one.
                let known = (connection.schema_data.is_empty()
                    && connection.message_encoding == "cdr")
                    .then(|| {
                        let type_name = ros2_type_name(&connection.schema_name);
                        known_schema(&type_name).or(ouster_schema(&type_name))
                    })
                    .flatten();
                let (schema_encoding, schema_data) = match known {
                    Some(schema) => ("ros2msg", schema.as_bytes()),
                    None => (&connection.schema_encoding[..], &connection.schema_data[..]),
                };
                let id = sink.channel(
                    &connection.topic,
                    &connection.schema_name,
                    schema_encoding,
                    schema_data,
                    &connection.message_encoding,
                )?;
                (id, message.data)
            }
        };
        sink.write_raw(channel, message.log_time_ns, message.publish_time_ns, data)?;
        summary.messages += 1;
    }
    Ok(summary)
}

/// Converts every message of `drive` into `output` (see [`write_log_messages`]).
pub fn convert_log(
    drive: &RecordedLog,
    output: &Path,
    compression: Compression,
    on_messages: &dyn Fn(&str, u64),
) -> Result<LogCopySummary> {
    let mut sink = McapSink::create(output, compression)?;
    // Converting is asked for a compression; passing through is not.
    let mut summary = write_log_messages(&mut sink, drive, false, on_messages)?;
    if let Some(scans) = drive.packet_scans() {
        let mut partial_first = drive.begins_mid_turn();
        for decoded in scans {
            let decoded = decoded?;
            if partial_first && decoded.topic == drive.cloud_topic() {
                (partial_first, summary.partial_first_scan_left_out) = (false, true);
                continue;
            }
            let topic = decoded_topic(decoded.topic);
            let cloud = packet_cloud(&decoded.scan, decoded.frame);
            sink.write(&topic, decoded.scan.stamp_ns, &cloud)?;
            summary.decoded_scans += 1;
            if !summary.decoded_topics.contains(&topic) {
                summary.decoded_topics.push(topic);
            }
        }
        summary.decoded_topic = summary.decoded_topics.first().cloned();
    }
    sink.finish()?;
    summary.output_bytes = std::fs::metadata(output)
        .map_err(|e| Error::io(output, e))?
        .len();
    Ok(summary)
}

/// Where a packet topic's scans go: `.../velodyne_packets` -> `.../velodyne_points`
/// (nebula's and velodyne_pointcloud's names), else `<topic>/points`.
fn decoded_topic(packet_topic: &str) -> String {
    match packet_topic.strip_suffix("_packets") {
        Some(stem) => format!("{stem}_points"),
        None => format!("{packet_topic}/points"),
    }
}

/// A decoded scan as PointCloud2: x, y, z float32, intensity uint8 (0-255 as the
/// sensor reports it), ring uint16 (0 the lowest beam), t uint32 (ns from the
/// header stamp: for deskewing).
fn packet_cloud(scan: &PacketScan, frame_id: &str) -> PointCloud2 {
    const STEP: usize = 20;
    let mut data = Vec::with_capacity(scan.points.len() * STEP);
    for point in &scan.points {
        for v in point.xyz_m {
            data.extend_from_slice(&v.to_le_bytes());
        }
        data.push(point.intensity);
        data.push(0);
        data.extend_from_slice(&point.ring.to_le_bytes());
        let t_ns = point.time_ns.saturating_sub(scan.stamp_ns);
        data.extend_from_slice(&(t_ns.min(u32::MAX as u64) as u32).to_le_bytes());
    }
    let mut fields = PointField::xyz_float32();
    fields.extend([
        PointField::scalar("intensity", 12, datatype::UINT8),
        PointField::scalar("ring", 14, datatype::UINT16),
        PointField::scalar("t", 16, datatype::UINT32),
    ]);
    PointCloud2 {
        header: header(scan.stamp_ns, frame_id),
        height: 1,
        width: scan.points.len() as u32,
        fields,
        is_bigendian: false,
        point_step: STEP as u32,
        row_step: (scan.points.len() * STEP) as u32,
        data,
        is_dense: true,
    }
}

/// A ROS transform from a rigid pose, its quaternion as it is.
pub fn transform_from_pose(pose: &Isometry3<f64>) -> Transform {
    let (t, q) = (pose.translation.vector, pose.rotation);
    Transform {
        translation: Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        rotation: Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

fn header(stamp_ns: u64, frame_id: &str) -> Header {
    Header {
        stamp: Time::from_ns(stamp_ns),
        frame_id: frame_id.to_string(),
    }
}

/// The PointCloud2 of a scan: x, y, z, intensity (float32) and label (uint32).
pub fn scan_to_cloud(frame: &Frame, stamp_ns: u64) -> PointCloud2 {
    scan_cloud_with(frame, stamp_ns, scan_cloud_data(frame).into_owned())
}

/// [`scan_to_cloud`]'s message with `data` as the points' bytes.
fn scan_cloud_with<Data>(frame: &Frame, stamp_ns: u64, data: Data) -> PointCloud2<Data> {
    let mut fields = PointField::xyz_float32();
    fields.push(PointField::scalar("intensity", 12, datatype::FLOAT32));
    if frame.labels.is_some() {
        fields.push(PointField::scalar("label", 16, datatype::UINT32));
    }
    let point_step = if frame.labels.is_some() { 20 } else { 16 };
    let n = frame.points_in_velodyne.len();
    PointCloud2 {
        header: header(stamp_ns, VELODYNE_FRAME),
        height: 1,
        width: n as u32,
        fields,
        is_bigendian: false,
        point_step: point_step as u32,
        row_step: (n * point_step) as u32,
        data,
        is_dense: true,
    }
}

/// The points as [`scan_to_cloud`]'s records: borrowed when they are laid out so
/// already (no labels, a little-endian machine), since copying a 2 MB scan into fresh
/// memory cost `convert` more than encoding the rest of the frame.
fn scan_cloud_data(frame: &Frame) -> Cow<'_, [u8]> {
    let points = &frame.points_in_velodyne;
    let Some(labels) = &frame.labels else {
        if cfg!(target_endian = "little") {
            return Cow::Borrowed(bytemuck::cast_slice(points));
        }
        return Cow::Owned(
            points
                .as_flattened()
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
        );
    };
    // Fixed-size copies into a sized buffer: appending value by value checked the
    // capacity four times a point and took as long as encoding the whole message.
    let point_step = 20;
    let mut data = vec![0u8; points.len() * point_step];
    let records = data.chunks_exact_mut(point_step);
    for ((record, p), label) in records.zip(points).zip(labels) {
        record[..16].copy_from_slice(p.map(f32::to_le_bytes).as_flattened());
        record[16..].copy_from_slice(&label.to_le_bytes());
    }
    Cow::Owned(data)
}

/// Width and height from a PNG's IHDR chunk.
pub fn png_size(bytes: &[u8]) -> Option<(u32, u32)> {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];
    if bytes.len() < 24 || bytes[..8] != SIGNATURE || &bytes[12..16] != b"IHDR" {
        return None;
    }
    let be =
        |at: usize| u32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    Some((be(16), be(20)))
}

/// CameraInfo of a rectified KITTI camera in its own frame: K, R identity, no
/// distortion, P = [K | 0] (the baseline is in `/tf_static`, so that P projects
/// points given in this camera's frame, as ROS defines it).
pub fn camera_info(k: &Matrix3<f64>, width: u32, height: u32, stamp_ns: u64) -> CameraInfo {
    let k9 = [
        k[(0, 0)],
        k[(0, 1)],
        k[(0, 2)],
        k[(1, 0)],
        k[(1, 1)],
        k[(1, 2)],
        k[(2, 0)],
        k[(2, 1)],
        k[(2, 2)],
    ];
    CameraInfo {
        header: header(stamp_ns, CAMERA_2_FRAME),
        height,
        width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: k9,
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [
            k9[0], k9[1], k9[2], 0.0, k9[3], k9[4], k9[5], 0.0, k9[6], k9[7], k9[8], 0.0,
        ],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

/// `/tf_static`: velodyne -> camera_0 from Tr, camera_0 -> camera_2 from P2's baseline.
fn static_transforms(sequence: &RecordedKitti, stamp_ns: u64) -> TfMessage {
    let mut transforms = vec![TransformStamped {
        header: header(stamp_ns, VELODYNE_FRAME),
        child_frame_id: CAMERA_0_FRAME.into(),
        transform: transform_from_pose(&sequence.velodyne_from_camera_0()),
    }];
    if let Some((_, camera_0_from_camera_2)) = sequence.camera_2() {
        transforms.push(TransformStamped {
            header: header(stamp_ns, CAMERA_0_FRAME),
            child_frame_id: CAMERA_2_FRAME.into(),
            transform: transform_from_pose(&camera_0_from_camera_2),
        });
    }
    TfMessage { transforms }
}

/// One KITTI frame's messages as `convert` writes them, CDR-encoded.
pub struct EncodedFrame {
    stamp_ns: u64,
    cloud: Vec<u8>,
    tf: Vec<u8>,
    image: Option<(Vec<u8>, Vec<u8>)>,
    labelled: bool,
    dropped_points: usize,
}

/// The messages of `frame`, read from `sequence` (its image from its file, as
/// recorded); None when they cannot be made and the sequence keeps going past
/// unreadable frames, which records the skip.
pub fn encode_kitti_frame(
    sequence: &RecordedKitti,
    frame: &Frame,
    start_ns: u64,
) -> Result<Option<EncodedFrame>> {
    sequence.kept(frame.index, encode_frame(sequence, frame, start_ns))
}

fn encode_frame(sequence: &RecordedKitti, frame: &Frame, start_ns: u64) -> Result<EncodedFrame> {
    let index = frame.index;
    let stamp_ns = start_ns + frame.stamp_ns;
    let cloud = scan_cloud_with(frame, stamp_ns, scan_cloud_data(frame));
    let tf = TfMessage {
        transforms: vec![TransformStamped {
            header: header(stamp_ns, MAP_FRAME),
            child_frame_id: VELODYNE_FRAME.into(),
            transform: transform_from_pose(&frame.world_from_velodyne),
        }],
    };
    let image = match (sequence.image_path(index), sequence.camera_2()) {
        (Some(path), Some((k, _))) => {
            let png = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
            let (width, height) = png_size(&png).ok_or_else(|| Error::Sequence {
                path: path.clone(),
                message: "not a PNG image (no PNG signature and IHDR header)".into(),
            })?;
            let info = camera_info(&k, width, height, stamp_ns);
            let image = CompressedImage {
                header: header(stamp_ns, CAMERA_2_FRAME),
                format: "png".into(),
                data: png,
            };
            Some((encode(&image, image.data.len() + 64), encode(&info, 512)))
        }
        _ => None,
    };
    Ok(EncodedFrame {
        stamp_ns,
        cloud: encode(&cloud, cloud.data.len() + 256),
        tf: encode(&tf, 128),
        image,
        labelled: frame.labels.is_some(),
        dropped_points: frame.dropped_points,
    })
}

/// Writes KITTI frames' messages into a sink in frame order, `/tf_static` before
/// the first, and counts them.
pub struct KittiFrameWriter<'a> {
    sequence: &'a RecordedKitti<'a>,
    pub summary: ConversionSummary,
}

impl<'a> KittiFrameWriter<'a> {
    pub fn new(sequence: &'a RecordedKitti<'a>) -> Self {
        let summary = ConversionSummary {
            frames: 0,
            images: 0,
            labelled_frames: 0,
            dropped_points: 0,
            output_bytes: 0,
        };
        Self { sequence, summary }
    }

    pub fn write(&mut self, sink: &mut McapSink, frame: EncodedFrame) -> Result<()> {
        let EncodedFrame {
            stamp_ns,
            cloud,
            tf,
            image,
            labelled,
            dropped_points,
        } = frame;
        let summary = &mut self.summary;
        if summary.frames == 0 {
            let transforms = static_transforms(self.sequence, stamp_ns);
            sink.write("/tf_static", stamp_ns, &transforms)?;
        }
        sink.write_encoded::<PointCloud2>(CLOUD_TOPIC, stamp_ns, cloud)?;
        sink.write_encoded::<TfMessage>("/tf", stamp_ns, tf)?;
        if let Some((image, info)) = image {
            sink.write_encoded::<CompressedImage>(IMAGE_TOPIC, stamp_ns, image)?;
            sink.write_encoded::<CameraInfo>(CAMERA_INFO_TOPIC, stamp_ns, info)?;
            summary.images += 1;
        }
        summary.frames += 1;
        summary.labelled_frames += labelled as usize;
        summary.dropped_points += dropped_points as u64;
        Ok(())
    }
}

/// Converts the frames of `sequence` in `frames` into `output`. `on_frame` is called
/// after each written frame.
pub fn convert_kitti(
    sequence: &RecordedKitti,
    frames: &Range<usize>,
    output: &Path,
    compression: Compression,
    start_ns: u64,
    on_frame: &(dyn Fn() + Sync),
) -> Result<ConversionSummary> {
    let mut sink = McapSink::create(output, compression)?;
    let mut writer = KittiFrameWriter::new(sequence);
    for batch in sequence.frames_in(frames).chunks(BATCH) {
        // A frame whose files are unreadable stops the conversion, unless the
        // sequence keeps going, which skips and records it.
        let encoded: Vec<Option<EncodedFrame>> = batch
            .par_iter()
            .map(|&index| {
                let frame = sequence.read_frame(index);
                let encoded = frame.and_then(|frame| encode_frame(sequence, &frame, start_ns));
                sequence.kept(index, encoded)
            })
            .collect::<Result<_>>()?;
        for frame in encoded.into_iter().flatten() {
            writer.write(&mut sink, frame)?;
            on_frame();
        }
    }
    if writer.summary.frames == 0 {
        let inputs = sequence.dir().display().to_string();
        return Err(travmap_io::nothing_read(
            output,
            inputs,
            &sequence.skips().skipped(),
        ));
    }
    sink.finish()?;
    let mut summary = writer.summary;
    summary.output_bytes = std::fs::metadata(output)
        .map_err(|e| Error::io(output, e))?
        .len();
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transform_of_a_rotation_about_z() {
        let mut m = nalgebra::Matrix4::identity();
        m[(0, 0)] = 0.0;
        m[(0, 1)] = -1.0;
        m[(1, 0)] = 1.0;
        m[(1, 1)] = 0.0;
        m[(0, 3)] = 2.0;
        let t = transform_from_pose(&travmap_core::geometry::rigid(&m));
        let half = std::f64::consts::FRAC_1_SQRT_2;
        assert!((t.rotation.z - half).abs() < 1e-12 && (t.rotation.w - half).abs() < 1e-12);
        assert_eq!(t.translation.x, 2.0);
    }

    #[test]
    fn png_size_reads_ihdr() {
        let mut png = vec![
            0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n', 0, 0, 0, 13,
        ];
        png.extend_from_slice(b"IHDR");
        png.extend_from_slice(&1242u32.to_be_bytes());
        png.extend_from_slice(&375u32.to_be_bytes());
        assert_eq!(png_size(&png), Some((1242, 375)));
        assert_eq!(png_size(b"GIF89a.................."), None);
    }
}
