//! Reading a recorded ROS 2 drive from MCAP: the clouds of one PointCloud2 topic,
//! each with its pose in the world frame from `/tf` + `/tf_static` (interpolated at
//! the cloud's stamp) or from a `nav_msgs/msg/Odometry` topic.
//!
//! The file is memory-mapped and streamed: one pass at open collects the topics, the
//! cloud stamps and every transform; [`McapDrive::read`] streams again and
//! decodes only the clouds asked for. Any PointCloud2 layout is accepted: fields at any
//! offset and order, float32 or float64 coordinates, extra fields, big-endian data,
//! organised clouds; points with a non-finite coordinate are dropped.

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Quaternion as NQuaternion, Translation3, UnitQuaternion};
use serde::Deserialize;

use super::image::image_pixels;
use super::mcap_records::{Messages, check_chunk_sizes};
use crate::frame::{CameraImage, Frame};
use crate::error::{Error, Result};
use crate::io::cloud::cloud_points;
use crate::io::ros::{Header, Odometry, PointCloud2, TfMessage, Transform, decode};

const POINT_CLOUD: &str = "sensor_msgs/msg/PointCloud2";
const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
const ODOMETRY: &str = "nav_msgs/msg/Odometry";
const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
const RAW_IMAGE: &str = "sensor_msgs/msg/Image";

/// An image is paired with a cloud when their stamps are at most this far apart.
const IMAGE_PAIRING_NS: u64 = 50_000_000;

/// A transform sample is used up to this far past either end of its edge's record.
const TF_EXTRAPOLATION_NS: u64 = 100_000_000;

/// What to read from the drive; everything found by itself when None.
#[derive(Clone, Debug, Default)]
pub struct DriveOptions {
    pub cloud_topic: Option<String>,
    pub world_frame: Option<String>,
    /// The image topic (Image or CompressedImage) whose frame has a CameraInfo; found
    /// by itself when there is exactly one.
    pub camera_topic: Option<String>,
}

/// The camera the appearance features come from.
#[derive(Clone, Debug)]
struct CameraSource {
    topic: String,
    compressed: bool,
    frame: String,
    intrinsics: nalgebra::Matrix3<f64>,
    /// Width and height the CameraInfo gives; images must match.
    size: (u32, u32),
}

/// Parent and transform samples of one frame in the transform tree.
#[derive(Clone, Debug, Default)]
struct Edge {
    parent: String,
    /// (stamp, parent_from_child), sorted by stamp; one sample for static edges.
    samples: Vec<(u64, Isometry3<f64>)>,
    is_static: bool,
}

/// An opened MCAP drive.
pub struct McapDrive {
    path: PathBuf,
    map: memmap2::Mmap,
    /// See [`check_chunk_sizes`]: no record of the file is longer.
    longest_record: usize,
    cloud_topic: String,
    cloud_frame: String,
    world_frame: String,
    stamps_ns: Vec<u64>,
    edges: HashMap<String, Edge>,
    camera: Option<CameraSource>,
    pub(super) skips: super::SkipLog,
}

/// The rigid pose of a ROS transform; an error for non-finite values or a
/// quaternion too short to normalise, which would turn every point into NaN.
pub fn isometry(t: &Transform) -> Result<Isometry3<f64>, String> {
    let (p, r) = (&t.translation, &t.rotation);
    let q = NQuaternion::new(r.w, r.x, r.y, r.z);
    let finite = [p.x, p.y, p.z, r.w, r.x, r.y, r.z]
        .iter()
        .all(|v| v.is_finite());
    if !finite || q.norm() < 1e-6 {
        return Err(format!(
            "transform ({}, {}, {}), rotation (w {}, x {}, y {}, z {}): expected finite values and a unit quaternion",
            p.x, p.y, p.z, r.w, r.x, r.y, r.z
        ));
    }
    // Unit quaternions as written (travmap's own) are used as they are, so that a
    // converted KITTI pose comes back bit-identical.
    let rotation = if (q.norm() - 1.0).abs() < 1e-12 {
        UnitQuaternion::new_unchecked(q)
    } else {
        UnitQuaternion::new_normalize(q)
    };
    Ok(Isometry3::from_parts(
        Translation3::new(p.x, p.y, p.z),
        rotation,
    ))
}

/// More frames than any real transform tree stacks: a longer chain is a cycle.
const MAX_TF_DEPTH: usize = 64;

/// Only the header of a message, decoded without the rest.
#[derive(Deserialize)]
struct HeaderOnly {
    header: Header,
}

impl McapDrive {
    pub fn open(path: &Path, options: &DriveOptions) -> Result<Self> {
        let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        // SAFETY: the file is opened read-only and not modified while mapped by travmap;
        // another process truncating it under us is outside what any reader can guard.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
        let fail = |message: String| Error::Mcap {
            path: path.to_path_buf(),
            message,
        };
        let mut topics: BTreeMap<String, String> = BTreeMap::new();
        let mut cloud_stamps: HashMap<String, (String, Vec<u64>)> = HashMap::new();
        let mut edges: HashMap<String, Edge> = HashMap::new();
        // Per camera frame: K and the image size (width, height).
        let mut intrinsics: HashMap<String, (nalgebra::Matrix3<f64>, (u32, u32))> = HashMap::new();
        let mut image_topics: BTreeMap<String, (bool, String)> = BTreeMap::new();
        let longest_record = check_chunk_sizes(&map).map_err(fail)?;
        let stream = Messages::new(&map, longest_record);
        for (ordinal, message) in stream.enumerate() {
            let message = message.map_err(|e| fail(format!("message {ordinal}: {e}")))?;
            let channel = &message.channel;
            let schema = channel
                .schema
                .as_ref()
                .map(|s| s.name.clone())
                .unwrap_or_default();
            topics
                .entry(channel.topic.clone())
                .or_insert_with(|| schema.clone());
            let decode_failure = |e: String| {
                fail(format!(
                    "channel {} ({schema}), message at log time {} ns: {e}",
                    channel.topic, message.log_time
                ))
            };
            let known = matches!(
                schema.as_str(),
                POINT_CLOUD | TF_MESSAGE | ODOMETRY | CAMERA_INFO | COMPRESSED_IMAGE | RAW_IMAGE
            );
            if known && channel.message_encoding != "cdr" {
                return Err(fail(format!(
                    "channel {} ({schema}) has message encoding `{}`; travmap reads `cdr` (ROS 2)",
                    channel.topic, channel.message_encoding
                )));
            }
            match schema.as_str() {
                POINT_CLOUD => {
                    let header: HeaderOnly = decode(&message.data).map_err(decode_failure)?;
                    let stamp = match header.header.stamp.to_ns() {
                        0 => message.log_time,
                        ns => ns,
                    };
                    let entry = cloud_stamps
                        .entry(channel.topic.clone())
                        .or_insert_with(|| (header.header.frame_id.clone(), Vec::new()));
                    entry.1.push(stamp);
                }
                TF_MESSAGE => {
                    let tf: TfMessage = decode(&message.data).map_err(decode_failure)?;
                    let is_static = channel.topic == "/tf_static";
                    for t in tf.transforms {
                        let edge = edges.entry(t.child_frame_id.clone()).or_default();
                        edge.parent = t.header.frame_id.clone();
                        edge.is_static = is_static;
                        let pose = isometry(&t.transform).map_err(|e| {
                            decode_failure(format!("{} -> {}: {e}", edge.parent, t.child_frame_id))
                        })?;
                        edge.samples.push((t.header.stamp.to_ns(), pose));
                    }
                }
                ODOMETRY => {
                    let odometry: Odometry = decode(&message.data).map_err(decode_failure)?;
                    let edge = edges.entry(odometry.child_frame_id.clone()).or_default();
                    edge.parent = odometry.header.frame_id.clone();
                    let pose = odometry.pose.pose;
                    let transform = Transform {
                        translation: pose.position,
                        rotation: pose.orientation,
                    };
                    edge.samples.push((
                        odometry.header.stamp.to_ns(),
                        isometry(&transform).map_err(decode_failure)?,
                    ));
                }
                CAMERA_INFO => {
                    let info: crate::io::ros::CameraInfo =
                        decode(&message.data).map_err(decode_failure)?;
                    intrinsics
                        .entry(info.header.frame_id.clone())
                        .or_insert_with(|| {
                            (
                                nalgebra::Matrix3::from_row_slice(&info.k),
                                (info.width, info.height),
                            )
                        });
                }
                COMPRESSED_IMAGE | RAW_IMAGE if !image_topics.contains_key(&channel.topic) => {
                    let header: HeaderOnly = decode(&message.data).map_err(decode_failure)?;
                    image_topics.insert(
                        channel.topic.clone(),
                        (schema == COMPRESSED_IMAGE, header.header.frame_id),
                    );
                }
                // Other channels are not the method's input.
                _ => {}
            }
        }
        for edge in edges.values_mut() {
            edge.samples.sort_by_key(|s| s.0);
        }
        let list_clouds = || {
            let clouds: Vec<&str> = topics
                .iter()
                .filter(|(_, s)| *s == POINT_CLOUD)
                .map(|(t, _)| t.as_str())
                .collect();
            let all: Vec<String> = topics.iter().map(|(t, s)| format!("{t} ({s})")).collect();
            format!(
                "PointCloud2 topics: [{}]; all topics: [{}]",
                clouds.join(", "),
                all.join(", ")
            )
        };
        let cloud_topic = match &options.cloud_topic {
            Some(topic) if cloud_stamps.contains_key(topic) => topic.clone(),
            Some(topic) => {
                return Err(fail(format!(
                    "no PointCloud2 messages on topic {topic}; {}",
                    list_clouds()
                )));
            }
            None => match cloud_stamps.keys().collect::<Vec<_>>().as_slice() {
                [only] => (*only).clone(),
                [] => return Err(fail(format!("no PointCloud2 topic; {}", list_clouds()))),
                _ => {
                    return Err(fail(format!(
                        "several PointCloud2 topics, choose one with --cloud-topic; {}",
                        list_clouds()
                    )));
                }
            },
        };
        let (cloud_frame, stamps_ns) = cloud_stamps.remove(&cloud_topic).unwrap_or_default();
        // The world is the root of the tree above the cloud's frame, unless named.
        let world_frame = match &options.world_frame {
            Some(frame) => frame.clone(),
            None => {
                let mut frame = cloud_frame.clone();
                let mut hops = 0;
                while let Some(edge) = edges.get(&frame) {
                    frame = edge.parent.clone();
                    hops += 1;
                    if hops > MAX_TF_DEPTH {
                        return Err(fail(format!(
                            "the transform tree above {cloud_frame} has a cycle"
                        )));
                    }
                }
                if frame == cloud_frame {
                    return Err(fail(format!(
                        "no pose for the clouds' frame `{cloud_frame}`: travmap needs /tf (and /tf_static) or an Odometry topic linking it to a world frame"
                    )));
                }
                frame
            }
        };
        // The camera: an image topic whose frame has intrinsics.
        let usable: Vec<(&String, &(bool, String))> = image_topics
            .iter()
            .filter(|(_, (_, frame))| intrinsics.contains_key(frame))
            .collect();
        let camera = match (&options.camera_topic, usable.as_slice()) {
            (Some(topic), _) => {
                let (compressed, frame) = image_topics.get(topic).ok_or_else(|| {
                    fail(format!(
                        "no Image or CompressedImage messages on {topic}; image topics: [{}]",
                        image_topics.keys().cloned().collect::<Vec<_>>().join(", ")
                    ))
                })?;
                let (k, size) = intrinsics
                    .get(frame)
                    .ok_or_else(|| fail(format!("no CameraInfo for frame `{frame}` of {topic}")))?;
                Some(CameraSource {
                    topic: topic.clone(),
                    compressed: *compressed,
                    frame: frame.clone(),
                    intrinsics: *k,
                    size: *size,
                })
            }
            (None, [(topic, (compressed, frame))]) => Some(CameraSource {
                topic: (*topic).clone(),
                compressed: *compressed,
                frame: frame.clone(),
                intrinsics: intrinsics[frame].0,
                size: intrinsics[frame].1,
            }),
            _ => None,
        };
        Ok(Self {
            path: path.to_path_buf(),
            map,
            longest_record,
            cloud_topic,
            cloud_frame,
            world_frame,
            stamps_ns,
            edges,
            camera,
            skips: super::SkipLog::default(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn cloud_topic(&self) -> &str {
        &self.cloud_topic
    }

    pub fn world_frame(&self) -> &str {
        &self.world_frame
    }

    /// Frame numbers: the clouds' order on their topic.
    pub fn frame_count(&self) -> usize {
        self.stamps_ns.len()
    }

    /// `parent_from_child` of one edge at `stamp_ns`: the sample at that stamp, or
    /// interpolated between the two around it (linear, slerp).
    fn edge_at(&self, child: &str, edge: &Edge, stamp_ns: u64) -> Result<Isometry3<f64>> {
        let samples = &edge.samples;
        if (edge.is_static || samples.len() == 1)
            && let Some((t, pose)) = samples.first()
            && (edge.is_static || t.abs_diff(stamp_ns) <= TF_EXTRAPOLATION_NS)
        {
            return Ok(*pose);
        }
        let after = samples.partition_point(|s| s.0 < stamp_ns);
        if let Some(&(t, pose)) = samples.get(after)
            && t == stamp_ns
        {
            return Ok(pose);
        }
        match (after.checked_sub(1).map(|i| samples[i]), samples.get(after)) {
            (Some((t0, p0)), Some(&(t1, p1))) => {
                let s = (stamp_ns - t0) as f64 / (t1 - t0) as f64;
                Ok(p0.lerp_slerp(&p1, s))
            }
            (Some((t0, p0)), None) if stamp_ns - t0 <= TF_EXTRAPOLATION_NS => Ok(p0),
            (None, Some(&(t1, p1))) if t1 - stamp_ns <= TF_EXTRAPOLATION_NS => Ok(p1),
            _ => Err(Error::Mcap {
                path: self.path.clone(),
                message: format!(
                    "no transform {} -> {child} near {stamp_ns} ns (recorded {}..{} ns)",
                    edge.parent,
                    samples.first().map_or(0, |s| s.0),
                    samples.last().map_or(0, |s| s.0)
                ),
            }),
        }
    }

    /// `world_from_cloud` at `stamp_ns`, composed up the transform tree.
    pub fn world_from_cloud(&self, stamp_ns: u64) -> Result<Isometry3<f64>> {
        self.ancestor_from(&self.world_frame, &self.cloud_frame, stamp_ns)?
            .ok_or_else(|| Error::Mcap {
                path: self.path.clone(),
                message: format!(
                    "no transform from `{}` up to the world frame `{}`",
                    self.cloud_frame, self.world_frame
                ),
            })
    }

    /// `ancestor_from_frame` at `stamp_ns`, composed up the tree; None when
    /// `ancestor` is not above `frame`.
    fn ancestor_from(
        &self,
        ancestor: &str,
        frame: &str,
        stamp_ns: u64,
    ) -> Result<Option<Isometry3<f64>>> {
        let mut current = frame;
        let mut pose = Isometry3::identity();
        for _ in 0..=MAX_TF_DEPTH {
            if current == ancestor {
                return Ok(Some(pose));
            }
            let Some(edge) = self.edges.get(current) else {
                return Ok(None);
            };
            pose = self.edge_at(current, edge, stamp_ns)? * pose;
            current = &edge.parent;
        }
        Err(Error::Mcap {
            path: self.path.clone(),
            message: format!("the transform tree above {frame} has a cycle"),
        })
    }

    /// The camera image of a cloud from a raw message, posed for the cloud's frame:
    /// through the static chain when the camera hangs below the cloud's frame, else
    /// through the world at each one's stamp.
    fn camera_image(
        &self,
        camera: &CameraSource,
        data: &[u8],
        image_stamp_ns: u64,
        cloud_stamp_ns: u64,
    ) -> Result<CameraImage> {
        let fail = |message: String| Error::Mcap {
            path: self.path.clone(),
            message: format!("{} at {image_stamp_ns} ns: {message}", camera.topic),
        };
        let image = image_pixels(data, camera.compressed).map_err(fail)?;
        if (image.width, image.height) != camera.size {
            return Err(fail(format!(
                "the image is {}x{} but its CameraInfo says {}x{}",
                image.width, image.height, camera.size.0, camera.size.1
            )));
        }
        let velodyne_from_camera =
            match self.ancestor_from(&self.cloud_frame, &camera.frame, image_stamp_ns)? {
                Some(pose) => pose,
                None => {
                    let world_from_camera = self
                        .ancestor_from(&self.world_frame, &camera.frame, image_stamp_ns)?
                        .ok_or_else(|| {
                            fail(format!("no transform from `{}` to the world", camera.frame))
                        })?;
                    self.world_from_cloud(cloud_stamp_ns)?.inverse() * world_from_camera
                }
            };
        Ok(CameraImage::from_intrinsics(
            &camera.intrinsics,
            &velodyne_from_camera.inverse(),
            image,
        ))
    }

    /// Every message of the file in file order, undecoded (for passthrough).
    pub fn for_each_message(
        &self,
        mut on_message: impl FnMut(&mcap::Message) -> Result<()>,
    ) -> Result<()> {
        let fail = |message: String| Error::Mcap {
            path: self.path.clone(),
            message,
        };
        for message in Messages::new(&self.map, self.longest_record) {
            on_message(&message.map_err(fail)?)?;
        }
        Ok(())
    }

    /// The frames in `frames`, streamed in one pass over the file, each with the
    /// camera image nearest in time (within 50 ms) when the drive has a camera. With
    /// `--keep-going`, unreadable frames are recorded in the skip log and left out.
    pub fn read(&self, frames: &Range<usize>) -> McapFrames<'_> {
        McapFrames {
            drive: self,
            stream: Messages::new(&self.map, self.longest_record),
            frames: frames.clone(),
            pending: None,
            images: Vec::new(),
            next_cloud: 0,
            stream_ended: false,
        }
    }

    /// Frame `current` from its cloud message and the candidate images.
    fn frame(&self, current: usize, data: &[u8], images: &[(u64, Vec<u8>)]) -> Result<Frame> {
        let fail = |message: String| Error::Mcap {
            path: self.path.clone(),
            message: format!("{} cloud {current}: {message}", self.cloud_topic),
        };
        let cloud: PointCloud2 = decode(data).map_err(fail)?;
        let stamp_ns = self.stamps_ns[current];
        let points = cloud_points(&cloud).map_err(fail)?;
        let nearest = images
            .iter()
            .min_by_key(|(stamp, _)| stamp.abs_diff(stamp_ns))
            .filter(|(stamp, _)| stamp.abs_diff(stamp_ns) <= IMAGE_PAIRING_NS);
        let camera = match (&self.camera, nearest) {
            (Some(camera), Some((image_stamp, image))) => {
                Some(self.camera_image(camera, image, *image_stamp, stamp_ns)?)
            }
            _ => None,
        };
        Ok(Frame {
            index: current,
            stamp_ns,
            world_from_velodyne: self.world_from_cloud(stamp_ns)?,
            points_in_velodyne: points.points,
            labels: points.labels,
            dropped_points: points.dropped,
            camera,
        })
    }
}

/// The frames of a drive, streamed: see [`McapDrive::read`]. A cloud is handed on
/// when the next one arrives, so that an image written just after its cloud is
/// found too.
pub struct McapFrames<'a> {
    drive: &'a McapDrive,
    stream: Messages<'a>,
    frames: Range<usize>,
    /// The cloud waiting for the next one: (frame number, CDR message).
    pending: Option<(usize, Vec<u8>)>,
    /// Images since the cloud before the pending one: (stamp, CDR message).
    images: Vec<(u64, Vec<u8>)>,
    next_cloud: usize,
    stream_ended: bool,
}

impl McapFrames<'_> {
    /// The frame of a cloud, or its error; None when the error was skipped.
    fn hand_on(&mut self, index: usize, data: &[u8]) -> Option<Result<Frame>> {
        let frame = self.drive.frame(index, data, &self.images);
        let keep_after = self.drive.stamps_ns[index].saturating_sub(IMAGE_PAIRING_NS);
        self.images.retain(|(stamp, _)| *stamp >= keep_after);
        match frame {
            Ok(frame) => Some(Ok(frame)),
            Err(error) => self.drive.skips.handle(index, error).err().map(Err),
        }
    }
}

impl Iterator for McapFrames<'_> {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        let camera_topic = self.drive.camera.as_ref().map(|c| c.topic.as_str());
        while !self.stream_ended {
            let message = match self.stream.next() {
                Some(Ok(message)) => message,
                None => break,
                // A corrupt stretch of the file: with --keep-going, what came before counts.
                Some(Err(e)) => {
                    self.stream_ended = true;
                    let error = Error::Mcap {
                        path: self.drive.path.clone(),
                        message: format!("unreadable from cloud {} on: {e}", self.next_cloud),
                    };
                    if let Err(error) = self.drive.skips.handle(self.next_cloud, error) {
                        return Some(Err(error));
                    }
                    break;
                }
            };
            if Some(message.channel.topic.as_str()) == camera_topic {
                match decode::<HeaderOnly>(&message.data) {
                    Ok(header) => self
                        .images
                        .push((header.header.stamp.to_ns(), message.data.to_vec())),
                    Err(e) => {
                        return Some(Err(Error::Mcap {
                            path: self.drive.path.clone(),
                            message: format!("{}: {e}", message.channel.topic),
                        }));
                    }
                }
                continue;
            }
            if message.channel.topic != self.drive.cloud_topic {
                continue;
            }
            let finished = self.pending.take();
            let current = self.next_cloud;
            self.next_cloud += 1;
            if current >= self.frames.end {
                self.stream_ended = true;
            } else if current >= self.frames.start {
                self.pending = Some((current, message.data.to_vec()));
            }
            if let Some((index, data)) = finished
                && let Some(frame) = self.hand_on(index, &data)
            {
                return Some(frame);
            }
        }
        self.stream_ended = true;
        let (index, data) = self.pending.take()?;
        match self.hand_on(index, &data) {
            Some(frame) => Some(frame),
            None => self.next(),
        }
    }
}
