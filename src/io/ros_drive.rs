//! Reading a recorded ROS drive (any [`Log`]: MCAP, ROS 1 bag, rosbag2; ROS 2 or
//! ROS 1 messages): the clouds of one PointCloud2 topic, each with its pose in the
//! world frame from `/tf` + `/tf_static` (interpolated at the cloud's stamp) or from a
//! `nav_msgs/Odometry` topic.
//!
//! The log is streamed: one pass at open collects the topics, the cloud stamps and
//! every transform; [`RosDrive::read`] streams again and decodes only the clouds
//! asked for. Any PointCloud2 layout is accepted: fields at any
//! offset and order, float32 or float64 coordinates, extra fields, big-endian data,
//! organised clouds; points with a non-finite coordinate are dropped.

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;
use serde::Deserialize;

use super::Posing;
use super::image::image_pixels;
use super::log::{Log, LogMessage};
use crate::config::PoseSource;
use crate::error::{CloudTopicProblem, Error, Result};
use crate::frame::{CameraImage, Frame};
use crate::io::cloud::cloud_points;
use crate::io::ros::{Header, MessageEncoding, Odometry, PointCloud2, TfMessage, Transform};
use crate::io::transforms::{TransformTree, isometry};

const POINT_CLOUD: &str = "sensor_msgs/msg/PointCloud2";
const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
/// ROS 1's older `tf/tfMessage`: the same fields.
const TF1_MESSAGE: &str = "tf/msg/tfMessage";
const ODOMETRY: &str = "nav_msgs/msg/Odometry";
const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
const RAW_IMAGE: &str = "sensor_msgs/msg/Image";

/// An image is paired with a cloud when their stamps are at most this far apart.
const IMAGE_PAIRING_NS: u64 = 50_000_000;

/// What to read from the drive; everything found by itself when None.
#[derive(Clone, Debug, Default)]
pub struct DriveOptions {
    pub cloud_topic: Option<String>,
    pub world_frame: Option<String>,
    /// The image topic (Image or CompressedImage) whose frame has a CameraInfo; found
    /// by itself when there is exactly one.
    pub camera_topic: Option<String>,
    /// Where the clouds' poses come from.
    pub poses: PoseSource,
    /// Folders of scans: the rate stamps are made at when the file names are not
    /// times (10 Hz when None).
    pub rate_hz: Option<f64>,
}

/// The camera the appearance features come from.
#[derive(Clone, Debug)]
struct CameraSource {
    topic: String,
    compressed: bool,
    encoding: MessageEncoding,
    frame: String,
    intrinsics: nalgebra::Matrix3<f64>,
    /// Width and height the CameraInfo gives; images must match.
    size: (u32, u32),
}

/// An opened drive.
pub struct RosDrive {
    path: PathBuf,
    log: Log,
    posing: Posing,
    /// Said when the poses are not what was asked for by default.
    notice: Option<String>,
    cloud_topic: String,
    cloud_frame: String,
    world_frame: String,
    stamps_ns: Vec<u64>,
    transforms: TransformTree,
    camera: Option<CameraSource>,
    pub(super) skips: super::SkipLog,
}

/// Only the header of a message, decoded without the rest.
#[derive(Deserialize)]
struct HeaderOnly {
    header: Header,
}

/// What one pass over a drive finds: topics, cloud stamps, transforms, cameras.
#[derive(Default)]
struct Contents {
    /// Topic -> schema name, of every channel.
    topics: BTreeMap<String, String>,
    /// Cloud topic -> (frame, stamps).
    cloud_stamps: HashMap<String, (String, Vec<u64>)>,
    transforms: TransformTree,
    /// Per camera frame: K and the image size (width, height).
    intrinsics: HashMap<String, (nalgebra::Matrix3<f64>, (u32, u32))>,
    /// Which recorded poses count (`--poses`).
    poses: PoseSource,
    /// Image topic -> (compressed, encoding, frame).
    image_topics: BTreeMap<String, (bool, MessageEncoding, String)>,
}

impl Contents {
    /// Takes note of one message of the drive at `path`.
    fn add(&mut self, path: &Path, message: &LogMessage) -> Result<()> {
        let connection = &message.connection;
        let schema = connection.type_name();
        self.topics
            .entry(connection.topic.clone())
            .or_insert_with(|| connection.schema_name.clone());
        let problem = |problem: String| Error::UndecodableMessage {
            path: path.to_path_buf(),
            topic: connection.topic.clone(),
            schema: connection.schema_name.clone(),
            log_time_ns: message.log_time_ns,
            problem,
        };
        let known = matches!(
            schema.as_ref(),
            POINT_CLOUD
                | TF_MESSAGE
                | TF1_MESSAGE
                | ODOMETRY
                | CAMERA_INFO
                | COMPRESSED_IMAGE
                | RAW_IMAGE
        );
        let encoding = match connection.encoding() {
            Some(encoding) => encoding,
            None if known => {
                return Err(Error::LogEncoding {
                    path: path.to_path_buf(),
                    topic: connection.topic.clone(),
                    schema: connection.schema_name.clone(),
                    encoding: connection.message_encoding.clone(),
                });
            }
            // Other channels are not the method's input.
            None => return Ok(()),
        };
        let data = &message.data;
        match schema.as_ref() {
            POINT_CLOUD => {
                let header: HeaderOnly = encoding.decode(data).map_err(problem)?;
                let stamp = match header.header.stamp.to_ns() {
                    0 => message.log_time_ns,
                    ns => ns,
                };
                let entry = self
                    .cloud_stamps
                    .entry(connection.topic.clone())
                    .or_insert_with(|| (header.header.frame_id.clone(), Vec::new()));
                entry.1.push(stamp);
            }
            TF_MESSAGE | TF1_MESSAGE => {
                let is_static = connection.topic == "/tf_static";
                // The static chain (sensor mounts) counts whatever the pose source.
                let dynamic = matches!(self.poses, PoseSource::Auto | PoseSource::Tf);
                if !(is_static || dynamic) {
                    return Ok(());
                }
                let tf: TfMessage = encoding.decode(data).map_err(problem)?;
                for t in tf.transforms {
                    let (parent, child) = (&t.header.frame_id, &t.child_frame_id);
                    let pose = isometry(&t.transform)
                        .map_err(|e| problem(format!("{parent} -> {child}: {e}")))?;
                    self.transforms
                        .add(parent, child, t.header.stamp.to_ns(), pose, is_static);
                }
            }
            ODOMETRY if matches!(self.poses, PoseSource::Auto | PoseSource::Odometry) => {
                let odometry: Odometry = encoding.decode(data).map_err(problem)?;
                let pose = odometry.pose.pose;
                let transform = Transform {
                    translation: pose.position,
                    rotation: pose.orientation,
                };
                let pose = isometry(&transform).map_err(|e| problem(e.to_string()))?;
                self.transforms.add(
                    &odometry.header.frame_id,
                    &odometry.child_frame_id,
                    odometry.header.stamp.to_ns(),
                    pose,
                    false,
                );
            }
            CAMERA_INFO => {
                let info: crate::io::ros::CameraInfo = encoding.decode(data).map_err(problem)?;
                self.intrinsics
                    .entry(info.header.frame_id.clone())
                    .or_insert_with(|| {
                        (
                            nalgebra::Matrix3::from_row_slice(&info.k),
                            (info.width, info.height),
                        )
                    });
            }
            COMPRESSED_IMAGE | RAW_IMAGE if !self.image_topics.contains_key(&connection.topic) => {
                let header: HeaderOnly = encoding.decode(data).map_err(problem)?;
                self.image_topics.insert(
                    connection.topic.clone(),
                    (schema == COMPRESSED_IMAGE, encoding, header.header.frame_id),
                );
            }
            _ => {}
        }
        Ok(())
    }

    /// The PointCloud2 topic asked for, or the only one.
    fn cloud_topic(&self, path: &Path, options: &DriveOptions) -> Result<String> {
        let problem = match &options.cloud_topic {
            Some(topic) if self.cloud_stamps.contains_key(topic) => return Ok(topic.clone()),
            Some(topic) => CloudTopicProblem::NotFound(topic.clone()),
            None => match self.cloud_stamps.keys().collect::<Vec<_>>().as_slice() {
                [only] => return Ok((*only).clone()),
                [] => CloudTopicProblem::None,
                _ => CloudTopicProblem::Several,
            },
        };
        Err(Error::LogCloudTopic {
            path: path.to_path_buf(),
            problem,
            cloud_topics: self
                .topics
                .iter()
                .filter(|(_, s)| *s == POINT_CLOUD)
                .map(|(t, _)| t.clone())
                .collect(),
            all_topics: self
                .topics
                .iter()
                .map(|(t, s)| format!("{t} ({s})"))
                .collect(),
        })
    }

    /// The camera: the image topic asked for, or the only one whose frame has a
    /// CameraInfo; None without one.
    fn camera(&self, options: &DriveOptions) -> Result<Option<CameraSource>, String> {
        let source = |topic: &str, compressed: bool, encoding: MessageEncoding, frame: &str| {
            let (k, size) = self
                .intrinsics
                .get(frame)
                .ok_or_else(|| format!("no CameraInfo for frame `{frame}` of {topic}"))?;
            Ok(Some(CameraSource {
                topic: topic.to_string(),
                compressed,
                encoding,
                frame: frame.to_string(),
                intrinsics: *k,
                size: *size,
            }))
        };
        if let Some(topic) = &options.camera_topic {
            let (compressed, encoding, frame) = self.image_topics.get(topic).ok_or_else(|| {
                format!(
                    "no Image or CompressedImage messages on {topic}; image topics: [{}]",
                    self.image_topics
                        .keys()
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
            return source(topic, *compressed, *encoding, frame);
        }
        let usable: Vec<(&String, &(bool, MessageEncoding, String))> = self
            .image_topics
            .iter()
            .filter(|(_, (_, _, frame))| self.intrinsics.contains_key(frame))
            .collect();
        match usable.as_slice() {
            [(topic, (compressed, encoding, frame))] => {
                source(topic, *compressed, *encoding, frame)
            }
            _ => Ok(None),
        }
    }
}

impl RosDrive {
    /// Reads `log`'s topics, cloud stamps and transforms in one pass.
    pub fn open(log: Log, options: &DriveOptions) -> Result<Self> {
        let path = log.path().to_path_buf();
        let path = path.as_path();
        let mut contents = Contents {
            poses: options.poses,
            ..Default::default()
        };
        for message in log.messages() {
            contents.add(path, &message?)?;
        }
        contents.transforms.sort();
        let cloud_topic = contents.cloud_topic(path, options)?;
        let (cloud_frame, stamps_ns) = contents
            .cloud_stamps
            .remove(&cloud_topic)
            .unwrap_or_default();
        // The world is the root of the tree above the cloud's frame, unless named.
        let root = contents
            .transforms
            .root_above(&cloud_frame)
            .map_err(|problem| Error::Transform {
                path: path.to_path_buf(),
                problem,
            })?;
        let recorded = options.world_frame.is_some() || root != cloud_frame;
        let posing = match options.poses {
            PoseSource::Registration => Posing::Registration,
            PoseSource::None => Posing::Alone,
            PoseSource::Auto if !recorded => Posing::Registration,
            PoseSource::Auto | PoseSource::Tf | PoseSource::Odometry if recorded => {
                Posing::Recorded
            }
            source => {
                return Err(Error::LogNoPose {
                    path: path.to_path_buf(),
                    frame: cloud_frame,
                    pose_source: source.name(),
                });
            }
        };
        let notice = (options.poses == PoseSource::Auto && posing == Posing::Registration)
            .then(|| {
                format!(
                    "{}: no recorded pose reaches the clouds' frame `{cloud_frame}`: poses estimated by scan registration (--poses to choose)",
                    path.display()
                )
            });
        let world_frame = match (&options.world_frame, posing) {
            (Some(frame), _) => frame.clone(),
            (None, Posing::Recorded) => root,
            // Estimated poses: `map` is the first scan's frame.
            (None, Posing::Registration) => "map".to_string(),
            (None, _) => cloud_frame.clone(),
        };
        let camera = contents
            .camera(options)
            .map_err(|problem| Error::LogCamera {
                path: path.to_path_buf(),
                problem,
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            log,
            posing,
            notice,
            cloud_topic,
            cloud_frame,
            world_frame,
            stamps_ns,
            transforms: contents.transforms,
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

    /// The clouds' frame (`header.frame_id`).
    pub fn cloud_frame(&self) -> &str {
        &self.cloud_frame
    }

    pub fn world_frame(&self) -> &str {
        &self.world_frame
    }

    /// Frame numbers: the clouds' order on their topic.
    pub fn frame_count(&self) -> usize {
        self.stamps_ns.len()
    }

    /// How the clouds are posed.
    pub fn posing(&self) -> Posing {
        self.posing
    }

    /// Said when the poses are estimated without being asked for.
    pub fn notice(&self) -> Option<&str> {
        self.notice.as_deref()
    }

    /// `world_from_cloud` at `stamp_ns`, composed up the transform tree; the
    /// identity when the poses are not recorded (registration poses the frame).
    pub fn world_from_cloud(&self, stamp_ns: u64) -> Result<Isometry3<f64>> {
        if self.posing != Posing::Recorded {
            return Ok(Isometry3::identity());
        }
        self.ancestor_from(&self.world_frame, &self.cloud_frame, stamp_ns)?
            .ok_or_else(|| Error::LogNotBelowWorld {
                path: self.path.clone(),
                frame: self.cloud_frame.clone(),
                world_frame: self.world_frame.clone(),
            })
    }

    /// `ancestor_from_frame` at `stamp_ns`; None when `ancestor` is not above `frame`.
    fn ancestor_from(
        &self,
        ancestor: &str,
        frame: &str,
        stamp_ns: u64,
    ) -> Result<Option<Isometry3<f64>>> {
        self.transforms
            .ancestor_from(ancestor, frame, stamp_ns)
            .map_err(|problem| Error::Transform {
                path: self.path.clone(),
                problem,
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
        let fail = |problem: String| Error::LogImage {
            path: self.path.clone(),
            topic: camera.topic.clone(),
            stamp_ns: image_stamp_ns,
            problem,
        };
        let image = image_pixels(data, camera.compressed, camera.encoding).map_err(fail)?;
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
                        .ok_or_else(|| Error::LogNotBelowWorld {
                            path: self.path.clone(),
                            frame: camera.frame.clone(),
                            world_frame: self.world_frame.clone(),
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

    /// The log's chunks as stored, when it is one MCAP file whose chunks hold every
    /// message (for passthrough without decoding).
    pub fn stored(&self) -> Option<crate::io::mcap_records::StoredLog> {
        self.log.stored()
    }

    /// Every message of the log in order, undecoded (for passthrough).
    pub fn messages(&self) -> impl Iterator<Item = Result<LogMessage>> + '_ {
        self.log.messages()
    }

    /// The frames in `frames`, streamed in one pass over the file, each with the
    /// camera image nearest in time (within 50 ms) when the drive has a camera. With
    /// `--keep-going`, unreadable frames are recorded in the skip log and left out.
    pub fn read(&self, frames: &Range<usize>) -> DriveFrames<'_> {
        DriveFrames {
            drive: self,
            stream: Box::new(self.log.messages()),
            frames: frames.clone(),
            pending: None,
            images: Vec::new(),
            next_cloud: 0,
            stream_ended: false,
        }
    }

    /// Frame `current` from its cloud message and the candidate images.
    fn frame(
        &self,
        current: usize,
        cloud: &LogMessage,
        images: &[(u64, Vec<u8>)],
    ) -> Result<Frame> {
        let fail = |problem: String| Error::LogCloud {
            path: self.path.clone(),
            topic: self.cloud_topic.clone(),
            cloud: current,
            problem,
        };
        let encoding = cloud.connection.encoding().ok_or_else(|| {
            fail(format!(
                "message encoding `{}`",
                cloud.connection.message_encoding
            ))
        })?;
        let cloud: PointCloud2 = encoding.decode(&cloud.data).map_err(fail)?;
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
            remission: points.remission,
            dropped_points: points.dropped,
            camera,
        })
    }
}

/// The frames of a drive, streamed: see [`RosDrive::read`]. A cloud is handed on
/// when the next one arrives, so that an image written just after its cloud is
/// found too.
pub struct DriveFrames<'a> {
    drive: &'a RosDrive,
    stream: Box<dyn Iterator<Item = Result<LogMessage>> + 'a>,
    frames: Range<usize>,
    /// The cloud waiting for the next one: (frame number, message).
    pending: Option<(usize, LogMessage)>,
    /// Images since the cloud before the pending one: (stamp, message data).
    images: Vec<(u64, Vec<u8>)>,
    next_cloud: usize,
    stream_ended: bool,
}

impl DriveFrames<'_> {
    /// The frame of a cloud, or its error; None when the error was skipped.
    fn hand_on(&mut self, index: usize, cloud: &LogMessage) -> Option<Result<Frame>> {
        let frame = self.drive.frame(index, cloud, &self.images);
        let keep_after = self.drive.stamps_ns[index].saturating_sub(IMAGE_PAIRING_NS);
        self.images.retain(|(stamp, _)| *stamp >= keep_after);
        match frame {
            Ok(frame) => Some(Ok(frame)),
            Err(error) => self.drive.skips.handle(index, error).err().map(Err),
        }
    }
}

impl Iterator for DriveFrames<'_> {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        let camera = self.drive.camera.as_ref();
        while !self.stream_ended {
            let message = match self.stream.next() {
                Some(Ok(message)) => message,
                None => break,
                // A corrupt stretch of the file: with --keep-going, what came before counts.
                Some(Err(error)) => {
                    self.stream_ended = true;
                    let error = match error {
                        Error::LogRecord {
                            path,
                            ordinal,
                            problem,
                        } => Error::LogUnreadableFrom {
                            path,
                            cloud: self.next_cloud,
                            problem: format!("message {ordinal}: {problem}"),
                        },
                        other => other,
                    };
                    if let Err(error) = self.drive.skips.handle(self.next_cloud, error) {
                        return Some(Err(error));
                    }
                    break;
                }
            };
            if let Some(camera) = camera
                && message.connection.topic == camera.topic
            {
                match camera.encoding.decode::<HeaderOnly>(&message.data) {
                    Ok(header) => self
                        .images
                        .push((header.header.stamp.to_ns(), message.data)),
                    Err(problem) => {
                        return Some(Err(Error::LogImage {
                            path: self.drive.path.clone(),
                            topic: message.connection.topic.clone(),
                            stamp_ns: message.log_time_ns,
                            problem,
                        }));
                    }
                }
                continue;
            }
            if message.connection.topic != self.drive.cloud_topic {
                continue;
            }
            let finished = self.pending.take();
            let current = self.next_cloud;
            self.next_cloud += 1;
            if current >= self.frames.end {
                self.stream_ended = true;
            } else if current >= self.frames.start {
                self.pending = Some((current, message));
            }
            if let Some((index, cloud)) = finished
                && let Some(frame) = self.hand_on(index, &cloud)
            {
                return Some(frame);
            }
        }
        self.stream_ended = true;
        let (index, cloud) = self.pending.take()?;
        match self.hand_on(index, &cloud) {
            Some(frame) => Some(frame),
            None => self.next(),
        }
    }
}
