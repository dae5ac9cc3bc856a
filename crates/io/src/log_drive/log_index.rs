//! The one pass over a recorded log that [`crate::log_drive::LogDrive`] opens with:
//! the topics, the chosen cloud topic's stamps, every transform (/tf, /tf_static,
//! Odometry, a pose topic (`pose_topics.rs`), as `--poses` lets them count), camera
//! intrinsics and image topics.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::camera_model::Projection;
use super::options::{LogOptions, MergedTopics};
use super::packet_topics::{PacketTopics, ouster_metadata_beside};
use super::pose_topics::{
    POSE_MESSAGES, PoseTopic, VehiclePoses, add_vehicle_poses, named_pose_topic, unposed,
};
use super::transforms::{TransformTree, isometry};
use crate::containers::log::Log;
use crate::packets::ouster::OUSTER_PACKET_MESSAGES;
use crate::packets::{PACKET_MESSAGES, PacketCalibration, PacketModel};
use crate::payloads::livox::LIVOX_CUSTOM_MESSAGES;
use travmap_core::config::PoseSource;
use travmap_core::error::{CloudTopicProblem, Error, LostMessage, Result};
use travmap_core::posing::PoseRecord;
use travmap_formats::foxglove;
use travmap_formats::log_message::{LogMessage, Part, ros2_type_name};
use travmap_formats::ros::{CameraInfo, Header, MessageEncoding, Odometry, TfMessage, Transform};

const POINT_CLOUD: &str = "sensor_msgs/msg/PointCloud2";
const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
/// ROS 1's older `tf/tfMessage`: the same fields.
const TF1_MESSAGE: &str = "tf/msg/tfMessage";
const ODOMETRY: &str = "nav_msgs/msg/Odometry";
const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
const COMPRESSED_IMAGE: &str = "sensor_msgs/msg/CompressedImage";
const RAW_IMAGE: &str = "sensor_msgs/msg/Image";

/// Another sensor's topic, merged into the frames' scans.
pub(crate) struct MergedTopic {
    pub(crate) topic: String,
    /// The frame its clouds are in.
    pub(crate) frame: String,
    /// The model, when it carries LiDAR packets.
    pub(crate) packets: Option<PacketModel>,
}

/// The camera the appearance features come from.
#[derive(Clone, Debug)]
pub(crate) struct CameraSource {
    pub(crate) topic: String,
    pub(crate) compressed: bool,
    pub(crate) encoding: MessageEncoding,
    pub(crate) frame: String,
    pub(crate) projection: Projection,
    /// Width and height the CameraInfo gives; images must match.
    pub(crate) size: (u32, u32),
    /// Said once when the CameraInfo's lens cannot be modelled.
    pub(crate) notice: Option<String>,
}

/// Only the header of a message, decoded without the rest.
#[derive(Deserialize)]
pub(crate) struct HeaderOnly {
    pub(crate) header: Header,
}

/// What one pass over a drive finds: topics, cloud stamps, transforms, cameras.
#[derive(Default)]
pub(crate) struct Contents {
    /// Topic -> schema name, of every channel.
    topics: BTreeMap<String, String>,
    /// Cloud topic -> (frame, stamps).
    cloud_stamps: HashMap<String, (String, Vec<u64>)>,
    transforms: TransformTree,
    /// Pose topic -> its poses (PoseStamped, PoseWithCovarianceStamped): every one,
    /// or the one `--pose-topic` names.
    pose_topics: BTreeMap<String, PoseTopic>,
    pose_topic: Option<String>,
    /// Per camera frame: its first CameraInfo.
    camera_infos: HashMap<String, CameraInfo>,
    /// Which recorded poses count (`--poses`).
    poses: PoseSource,
    /// The image topics, by name.
    image_topics: BTreeMap<String, ImageTopic>,
    /// Packet topics: models, cuts, an Ouster's metadata.
    packets: PacketTopics,
}

/// An image topic as its first message shows it.
struct ImageTopic {
    /// CompressedImage (else a raw Image).
    compressed: bool,
    encoding: MessageEncoding,
    /// The camera frame its images are in (`header.frame_id`).
    frame: String,
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
        let known = PACKET_MESSAGES.contains(&schema.as_ref())
            || LIVOX_CUSTOM_MESSAGES.contains(&schema.as_ref())
            || foxglove::ros_equivalent(&schema).is_some()
            || matches!(
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
            name if name == POINT_CLOUD || LIVOX_CUSTOM_MESSAGES.contains(&name) => {
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
            name if PACKET_MESSAGES.contains(&name) => {
                let topic = &connection.topic;
                (self.packets)
                    .add(
                        topic,
                        name,
                        data,
                        encoding,
                        message.log_time_ns,
                        &mut self.cloud_stamps,
                    )
                    .map_err(problem)?;
            }
            name if PacketTopics::reads(&connection.topic, name) => {
                (self.packets)
                    .add_metadata(&connection.topic, data, encoding, &mut self.cloud_stamps)
                    .map_err(problem)?;
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
            name if POSE_MESSAGES.contains(&name)
                && matches!(self.poses, PoseSource::Auto | PoseSource::Odometry)
                && (self.pose_topic.as_ref()).is_none_or(|t| *t == connection.topic) =>
            {
                (self
                    .pose_topics
                    .entry(connection.topic.clone())
                    .or_default())
                .add(name, data, encoding)
                .map_err(problem)?;
            }
            CAMERA_INFO => {
                let info: CameraInfo = encoding.decode(data).map_err(problem)?;
                self.camera_infos
                    .entry(info.header.frame_id.clone())
                    .or_insert(info);
            }
            COMPRESSED_IMAGE | RAW_IMAGE if !self.image_topics.contains_key(&connection.topic) => {
                let header: HeaderOnly = encoding.decode(data).map_err(problem)?;
                self.image_topics.insert(
                    connection.topic.clone(),
                    ImageTopic {
                        compressed: schema == COMPRESSED_IMAGE,
                        encoding,
                        frame: header.header.frame_id,
                    },
                );
            }
            _ => {}
        }
        Ok(())
    }

    /// The PointCloud2 topic asked for, or the only one; merging every topic
    /// (`--cloud-topic all`), the one with the most clouds (then by name).
    fn cloud_topic(&self, path: &Path, options: &LogOptions) -> Result<String> {
        let most_clouds = || {
            self.cloud_stamps
                .iter()
                .max_by(|a, b| a.1.1.len().cmp(&b.1.1.len()).then(b.0.cmp(a.0)))
                .map(|(topic, _)| topic.clone())
        };
        let problem = match &options.cloud_topic {
            Some(topic) if self.cloud_stamps.contains_key(topic) => return Ok(topic.clone()),
            Some(topic) => CloudTopicProblem::NotFound(topic.clone()),
            None => match self.cloud_stamps.keys().collect::<Vec<_>>().as_slice() {
                [only] => return Ok((*only).clone()),
                [] => CloudTopicProblem::None,
                _ if options.merged_topics == MergedTopics::All => {
                    return Ok(most_clouds().unwrap_or_default());
                }
                _ => CloudTopicProblem::Several,
            },
        };
        Err(self.topic_error(path, problem))
    }

    /// The topics merged into `cloud_topic`'s scans, with their frames and, for
    /// packet topics, their models.
    fn merged_topics(
        &self,
        path: &Path,
        options: &LogOptions,
        cloud_topic: &str,
    ) -> Result<Vec<MergedTopic>> {
        let topics: Vec<String> = match &options.merged_topics {
            MergedTopics::None => return Ok(Vec::new()),
            MergedTopics::All => {
                let mut all: Vec<String> = self.cloud_stamps.keys().cloned().collect();
                all.sort();
                all
            }
            MergedTopics::Topics(topics) => topics.clone(),
        };
        let mut merged = Vec::new();
        for topic in topics.into_iter().filter(|t| t != cloud_topic) {
            let Some((frame, _)) = self.cloud_stamps.get(&topic) else {
                return Err(self.topic_error(path, CloudTopicProblem::NotFound(topic)));
            };
            merged.push(MergedTopic {
                frame: frame.clone(),
                packets: self.packets.model(&topic),
                topic,
            });
        }
        Ok(merged)
    }

    fn topic_error(&self, path: &Path, problem: CloudTopicProblem) -> Error {
        Error::LogCloudTopic {
            path: path.to_path_buf(),
            problem,
            cloud_topics: self
                .topics
                .iter()
                .filter(|(topic, s)| {
                    let type_name = ros2_type_name(s);
                    let type_name = type_name.as_ref();
                    // An Ouster's IMU packets share its lidar packets' type.
                    let imu = OUSTER_PACKET_MESSAGES.contains(&type_name)
                        && !self.cloud_stamps.contains_key(*topic);
                    type_name == POINT_CLOUD
                        || (PACKET_MESSAGES.contains(&type_name) && !imu)
                        || LIVOX_CUSTOM_MESSAGES.contains(&type_name)
                })
                .map(|(t, _)| t.clone())
                .collect(),
            all_topics: self
                .topics
                .iter()
                .map(|(t, s)| format!("{t} ({s})"))
                .collect(),
        }
    }

    /// The camera: the image topic asked for, or the only one whose frame has a
    /// CameraInfo; None without one.
    fn camera(&self, options: &LogOptions) -> Result<Option<CameraSource>, String> {
        let source = |topic: &str, image: &ImageTopic| {
            let (compressed, encoding, frame) = (image.compressed, image.encoding, &image.frame);
            let info = self
                .camera_infos
                .get(frame)
                .ok_or_else(|| format!("no CameraInfo for frame `{frame}` of {topic}"))?;
            let (projection, notice) = Projection::of(topic, info);
            Ok(Some(CameraSource {
                topic: topic.to_string(),
                compressed,
                encoding,
                frame: frame.to_string(),
                projection,
                size: (info.width, info.height),
                notice,
            }))
        };
        if let Some(topic) = &options.camera_topic {
            let image = self.image_topics.get(topic).ok_or_else(|| {
                format!(
                    "no Image or CompressedImage messages on {topic}; image topics: [{}]",
                    self.image_topics
                        .keys()
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })?;
            return source(topic, image);
        }
        let usable: Vec<(&String, &ImageTopic)> = (self.image_topics.iter())
            .filter(|(_, image)| self.camera_infos.contains_key(&image.frame))
            .collect();
        match usable.as_slice() {
            [(topic, image)] => source(topic, image),
            _ => Ok(None),
        }
    }
}

/// What [`crate::log_drive::LogDrive`] needs of a log, from one pass over it.
pub(crate) struct LogIndex {
    pub(crate) cloud_topic: String,
    /// The clouds' frame (`header.frame_id`).
    pub(crate) cloud_frame: String,
    pub(crate) stamps_ns: Vec<u64>,
    pub(crate) transforms: TransformTree,
    pub(crate) camera: Option<CameraSource>,
    /// The root of the transform tree above the clouds' frame.
    pub(crate) root_frame: String,
    /// Whether a pose topic poses the clouds, and what the user is told.
    pub(crate) vehicle_poses: VehiclePoses,
    /// The model, when the cloud topic carries LiDAR packets.
    pub(crate) packets: Option<PacketModel>,
    /// Other sensors' topics merged into each scan.
    pub(crate) merged: Vec<MergedTopic>,
    /// Chunks or messages that could not be read ([`Error::is_lost_stretch`]).
    pub(crate) damaged_chunks: usize,
    /// Of those, the single messages: the frames' pass meets again only those of the
    /// topics it reads, and reports the others from here.
    pub(crate) lost_messages: Vec<LostMessage>,
    /// For a packet topic: the packets of its first and second scans, when the
    /// first took fewer than half the second's (the recording began mid-turn).
    pub(crate) partial_first_scan: Option<(usize, usize)>,
    /// When the cloud topic's packets hold nothing but part of one turn: how much of
    /// the turn, in words (its one frame is that part).
    pub(crate) partial_turn: Option<String>,
    /// Packet topics' calibrations recorded in the log (an Ouster's metadata).
    pub(crate) recorded_calibrations: HashMap<String, PacketCalibration>,
    /// The Ouster metadata file found beside a capture, when packets were read with it.
    pub(crate) ouster_metadata_beside: Option<PathBuf>,
}

impl LogIndex {
    /// Reads `log`'s topics, cloud stamps and transforms in one pass, and chooses
    /// the cloud topic and the camera.
    pub(crate) fn read(log: &Log, options: &LogOptions, poses: PoseSource) -> Result<Self> {
        let path = log.path();
        let mut contents = Contents {
            poses,
            pose_topic: options.pose_topic.clone(),
            packets: PacketTopics::new(
                options.lidar_calibrations.clone(),
                log.is_capture()
                    .then(|| ouster_metadata_beside(path))
                    .flatten(),
            ),
            ..Default::default()
        };
        let (mut damaged_chunks, mut first_damage, mut lost_messages) = (0, None, Vec::new());
        // Messages damaged chunks lost, where the file lists them: (topic, the
        // messages of the topic indexed before them, log time).
        let mut lost_in_chunks: Vec<(String, usize, u64)> = Vec::new();
        // Of clouds and images this pass reads the header alone, of the types it does
        // not decode nothing.
        let parts = |topic: &str, schema_name: &str| match ros2_type_name(schema_name).as_ref() {
            POINT_CLOUD | COMPRESSED_IMAGE | RAW_IMAGE => Part::Header,
            name if LIVOX_CUSTOM_MESSAGES.contains(&name) => Part::Header,
            TF_MESSAGE | TF1_MESSAGE | ODOMETRY | CAMERA_INFO => Part::Whole,
            name if PACKET_MESSAGES.contains(&name) || POSE_MESSAGES.contains(&name) => Part::Whole,
            name if PacketTopics::reads(topic, name) => Part::Whole,
            _ => Part::Nothing,
        };
        let threads = rayon::current_num_threads();
        for message in log.messages_in_parts(threads, std::sync::Arc::new(parts)) {
            match message {
                Ok(message) => contents.add(path, &message)?,
                // Its clouds are not indexed; reading the frames says so (or stops).
                Err(error) if error.is_lost_stretch() => {
                    damaged_chunks += 1;
                    if let Error::LogMessageLost(lost) = &error {
                        lost_messages.push(lost.clone());
                    }
                    if let Error::LogChunk { lost, .. } = &error {
                        for (topic, log_time_ns) in lost {
                            let indexed = contents.cloud_stamps.get(topic).map_or(0, |c| c.1.len());
                            lost_in_chunks.push((topic.clone(), indexed, *log_time_ns));
                        }
                    }
                    first_damage.get_or_insert(error);
                }
                Err(error) => return Err(error),
            }
        }
        contents.transforms.sort();
        let partial_turns = contents.packets.partial_turns(&mut contents.cloud_stamps);
        (contents.packets)
            .name_ouster_frames(contents.transforms.children(), &mut contents.cloud_stamps);
        // Without the clouds the damage took, the damage is the error to report.
        let cloud_topic = contents.cloud_topic(path, options).map_err(|error| {
            // Ouster packets that could not be read are why no cloud topic is.
            match (first_damage, contents.packets.unread()) {
                (Some(damage), _) => damage,
                (None, Some((topic, problem))) => Error::LogContainer {
                    path: path.to_path_buf(),
                    problem: format!("{topic}: {problem}"),
                },
                // A recording cut before its first complete chunk lists no topics.
                (None, None) if log.is_cut() => Error::LogContainer {
                    path: path.to_path_buf(),
                    problem: "cut short (no summary, no closing magic) before the first complete message of a LiDAR topic: nothing complete to read".into(),
                },
                // A capture has no topics to list: what it holds is its datagrams.
                (None, None) => match log.capture_datagrams() {
                    Some(datagrams) if contents.cloud_stamps.is_empty() => Error::LogContainer {
                        path: path.to_path_buf(),
                        problem: format!(
                            "no LiDAR packets among its UDP datagrams ({datagrams}): travmap reads Velodyne's (1,206 bytes), Hesai's, RoboSense's (1,248) and Ouster's (the metadata's size); a capture of another port or sensor?"
                        ),
                    },
                    _ => error,
                },
            }
        })?;
        let mut merged = contents.merged_topics(path, options, &cloud_topic)?;
        let (mut cloud_frame, mut stamps_ns) = contents
            .cloud_stamps
            .remove(&cloud_topic)
            .unwrap_or_default();
        // The clouds damaged chunks lost keep their places among the frames, so that
        // frame numbers are the intact file's (packets' scans cannot be counted so).
        if contents.packets.model(&cloud_topic).is_none() {
            let lost = lost_in_chunks
                .iter()
                .filter(|(topic, ..)| *topic == cloud_topic);
            for (inserted, (_, indexed, log_time_ns)) in lost.enumerate() {
                let at = indexed + inserted;
                // Stamps stay in order whatever clock the others came from.
                let low = at.checked_sub(1).map_or(0, |i| stamps_ns[i]);
                let high = stamps_ns.get(at).copied().unwrap_or(u64::MAX);
                stamps_ns.insert(at, (*log_time_ns).clamp(low, high.max(low)));
            }
        }
        let read: Vec<&str> = (std::iter::once(cloud_topic.as_str()))
            .chain(merged.iter().map(|m| m.topic.as_str()))
            .collect();
        let frames =
            (options.lidar_frames.frames_for(&read)).map_err(|problem| Error::LogLidarFrame {
                path: path.to_path_buf(),
                problem,
            })?;
        let recorded =
            (std::iter::once(&mut cloud_frame)).chain(merged.iter_mut().map(|m| &mut m.frame));
        for (frame, given) in recorded.zip(frames) {
            if let Some(given) = given {
                *frame = given;
            }
        }
        if matches!(poses, PoseSource::Auto | PoseSource::Odometry) {
            let named = options.pose_topic.as_deref();
            (named_pose_topic(named, &contents.pose_topics, &contents.topics)).map_err(
                |problem| Error::LogPoseTopic {
                    path: path.to_path_buf(),
                    problem,
                },
            )?;
        }
        let vehicle_poses = add_vehicle_poses(
            &mut contents.transforms,
            &cloud_frame,
            &contents.pose_topics,
            &stamps_ns,
            options.pose_topic.is_some(),
        )
        .map_err(|problem| Error::Transform {
            path: path.to_path_buf(),
            problem,
        })?;
        let root_frame = contents
            .transforms
            .root_above(&cloud_frame)
            .map_err(|problem| Error::Transform {
                path: path.to_path_buf(),
                problem,
            })?;
        let camera = contents
            .camera(options)
            .map_err(|problem| Error::LogCamera {
                path: path.to_path_buf(),
                problem,
            })?;
        let packets = contents.packets.model(&cloud_topic);
        let partial_first_scan = contents.packets.partial_first_scan(&cloud_topic);
        let partial_turn = (partial_turns.into_iter())
            .find(|(topic, _)| *topic == cloud_topic)
            .map(|(_, said)| said);
        let recorded_calibrations = (std::iter::once(&cloud_topic)
            .chain(merged.iter().map(|m| &m.topic)))
        .filter_map(|t| Some((t.clone(), contents.packets.recorded_calibration(t)?)))
        .collect();
        Ok(Self {
            merged,
            cloud_topic,
            cloud_frame,
            stamps_ns,
            transforms: contents.transforms,
            camera,
            root_frame,
            vehicle_poses,
            packets,
            damaged_chunks,
            lost_messages,
            partial_first_scan,
            partial_turn,
            recorded_calibrations,
            ouster_metadata_beside: contents
                .packets
                .metadata_beside_used()
                .map(Path::to_path_buf),
        })
    }

    /// Whether the log's poses reach the clouds: a world frame named, or a moving
    /// transform above their frame (fixed mounts alone would give every scan the
    /// same pose).
    pub(crate) fn pose_record(&self, options: &LogOptions) -> PoseRecord {
        // A cycle was refused when the root was found.
        let moves = self.transforms.moves(&self.cloud_frame).unwrap_or(false);
        if options.world_frame.is_some() || moves {
            return PoseRecord::Reaches;
        }
        PoseRecord::Missing(unposed(
            &self.cloud_frame,
            &self.root_frame,
            &self.vehicle_poses,
            self.transforms.children().next().is_some(),
        ))
    }
}
