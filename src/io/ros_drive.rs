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

use std::collections::VecDeque;
use std::ops::Range;
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use super::cloud::{CloudPoints, cloud_points};
use super::image::image_pixels;
use super::log::Log;
pub use super::log_index::DriveOptions;
use super::log_index::{CameraSource, HeaderOnly, LogIndex};
use super::log_message::LogMessage;
use super::ros::PointCloud2;
use super::skips::SkipLog;
use super::transforms::TransformTree;
use super::velodyne::{
    Calibration, Decoder, DecoderSettings, PacketScan, ScanAssembler, VelodyneModel, VelodynePoint,
    scan_message,
};
use crate::error::{Error, Result};
use crate::frame::{CameraImage, Frame, RemissionScale};
use crate::posing::{Posing, decide};

/// An image is paired with a cloud when their stamps are at most this far apart.
const IMAGE_PAIRING_NS: u64 = 50_000_000;

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
    /// Chunks the index pass could not read: their messages are lost.
    damaged_chunks: usize,
    /// When the cloud topic carries Velodyne packets: their model and calibration.
    packets: Option<(VelodyneModel, Calibration)>,
    pub(super) skips: SkipLog,
}

impl RosDrive {
    /// Reads `log`'s topics, cloud stamps and transforms in one pass
    /// ([`LogIndex`]), and poses the clouds as [`decide`] says.
    pub fn open(log: Log, options: &DriveOptions) -> Result<Self> {
        let index = LogIndex::read(&log, options)?;
        let packets = index
            .packets
            .map(|model| {
                let file = options.lidar_calibration.as_deref();
                packet_calibration(log.path(), &index.cloud_topic, model, file)
                    .map(|calibration| (model, calibration))
            })
            .transpose()?;
        let decision = decide(log.path(), options.poses, &index.pose_record(options))?;
        let world_frame = match (&options.world_frame, decision.posing) {
            (Some(frame), _) => frame.clone(),
            (None, Posing::Recorded) => index.root_frame,
            // Estimated poses: `map` is the first scan's frame.
            (None, Posing::Registration) => "map".to_string(),
            (None, Posing::Alone) => index.cloud_frame.clone(),
        };
        let mut drive = Self {
            path: log.path().to_path_buf(),
            log,
            posing: decision.posing,
            notice: decision.notice,
            cloud_topic: index.cloud_topic,
            cloud_frame: index.cloud_frame,
            world_frame,
            stamps_ns: index.stamps_ns,
            transforms: index.transforms,
            camera: index.camera,
            damaged_chunks: index.damaged_chunks,
            packets,
            skips: SkipLog::default(),
        };
        drive.trim_cut_end();
        Ok(drive)
    }

    /// In a file cut short, the last clouds may have lost their poses with the rest
    /// of the file: they are left out, and said so.
    fn trim_cut_end(&mut self) {
        if !self.log.is_cut() || self.posing != Posing::Recorded {
            return;
        }
        let mut dropped = 0;
        while let Some(&stamp_ns) = self.stamps_ns.last()
            && self.world_from_cloud(stamp_ns).is_err()
        {
            self.stamps_ns.pop();
            dropped += 1;
        }
        if dropped > 0 {
            let said = self
                .notice
                .take()
                .map(|n| format!("{n}; "))
                .unwrap_or_default();
            self.notice = Some(format!(
                "{said}{}: the last {dropped} clouds have no pose before the file ends: left out",
                self.path.display()
            ));
        }
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

    /// The pose of every cloud of the log, in order (none when the poses are not
    /// recorded); clouds whose pose the transforms do not give are left out.
    pub fn recorded_poses(&self) -> Vec<(usize, Isometry3<f64>)> {
        if self.posing != Posing::Recorded {
            return Vec::new();
        }
        let pose = |(index, stamp_ns): (usize, &u64)| {
            Some((index, self.world_from_cloud(*stamp_ns).ok()?))
        };
        self.stamps_ns.iter().enumerate().filter_map(pose).collect()
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
    /// message and none is damaged (for passthrough without decoding).
    pub fn stored(&self) -> Option<crate::io::mcap_stored::StoredLog> {
        (self.damaged_chunks == 0).then(|| self.log.stored())?
    }

    /// Every message of the log in order, undecoded (for passthrough); with
    /// `--keep-going` the messages of damaged chunks are left out (reading the
    /// frames records them), else the first is an error.
    pub fn messages(&self) -> impl Iterator<Item = Result<LogMessage>> + '_ {
        let mut clouds = 0;
        self.log
            .messages()
            .filter_map(move |message| match message {
                Ok(message) => {
                    clouds += (message.connection.topic == self.cloud_topic) as usize;
                    Some(Ok(message))
                }
                // Recorded as reading the frames records it: at the cloud that follows.
                Err(error @ Error::LogChunk { .. }) => {
                    self.skips.handle(clouds, error).err().map(Err)
                }
                Err(error) => Some(Err(error)),
            })
    }

    /// When the cloud topic carries Velodyne packets: its scans, cut and decoded in
    /// one pass (no poses), each with the stamp the index gave it.
    pub fn packet_scans(&self) -> Option<impl Iterator<Item = Result<PacketScan>> + '_> {
        let mut assembler = self.assembler()?;
        let mut next = 0;
        let scans = self
            .messages()
            .filter(|message| !matches!(message, Ok(m) if m.connection.topic != self.cloud_topic))
            .flat_map(move |message| {
                let scans = message.and_then(|message| {
                    scans_of(&mut assembler, &message)
                        .map_err(|problem| self.cloud_error(next, problem))
                });
                let scans: Vec<Result<PacketScan>> = match scans {
                    Ok(scans) => scans
                        .into_iter()
                        .map(|points| {
                            let stamp_ns = self.stamps_ns.get(next).copied().unwrap_or_default();
                            next += 1;
                            Ok(PacketScan { stamp_ns, points })
                        })
                        .collect(),
                    Err(error) => vec![Err(error)],
                };
                scans
            });
        Some(scans)
    }

    /// A fresh scan assembler for a packet topic.
    fn assembler(&self) -> Option<ScanAssembler> {
        let (model, calibration) = self.packets.as_ref()?;
        let decoder = Decoder::new(*model, calibration.clone(), DecoderSettings::default());
        // The calibration was checked against the model at open.
        Some(ScanAssembler::new(
            decoder.expect("a calibration of the model"),
        ))
    }

    /// The frames in `frames`, streamed in one pass over the file, each with the
    /// camera image nearest in time (within 50 ms) when the drive has a camera. With
    /// `--keep-going`, unreadable frames are recorded in the skip log and left out.
    pub fn read(&self, frames: &Range<usize>) -> DriveFrames<'_> {
        DriveFrames {
            drive: self,
            stream: Box::new(self.log.messages()),
            // Clouds the index left out (past a cut end) are not frames.
            frames: frames.start..frames.end.min(self.frame_count()),
            pending: None,
            ready: VecDeque::new(),
            assembler: self.assembler(),
            images: Vec::new(),
            next_cloud: 0,
            stream_ended: false,
        }
    }

    /// Frame `current` from its cloud message and the candidate images.
    fn frame(&self, current: usize, cloud: &Cloud, images: &[(u64, Vec<u8>)]) -> Result<Frame> {
        let fail = |problem: String| self.cloud_error(current, problem);
        let points = match cloud {
            Cloud::Message(message) => {
                let encoding = message.connection.encoding().ok_or_else(|| {
                    fail(format!(
                        "message encoding `{}`",
                        message.connection.message_encoding
                    ))
                })?;
                let cloud: PointCloud2 = encoding.decode(&message.data).map_err(fail)?;
                cloud_points(&cloud).map_err(fail)?
            }
            Cloud::Packets(points) => CloudPoints {
                points: points
                    .iter()
                    .map(|p| {
                        let [x, y, z] = p.xyz_m;
                        [x, y, z, p.intensity as f32 / 255.0]
                    })
                    .collect(),
                remission: RemissionScale::Byte,
                labels: None,
                dropped: 0,
            },
        };
        let stamp_ns = self.stamps_ns[current];
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

impl RosDrive {
    fn cloud_error(&self, cloud: usize, problem: String) -> Error {
        Error::LogCloud {
            path: self.path.clone(),
            topic: self.cloud_topic.clone(),
            cloud,
            problem,
        }
    }
}

/// The calibration of a packet topic's `model`: the file given, else the model's
/// own table.
fn packet_calibration(
    path: &Path,
    topic: &str,
    model: VelodyneModel,
    file: Option<&Path>,
) -> Result<Calibration> {
    let fail = |problem: String| Error::LogContainer {
        path: path.to_path_buf(),
        problem: format!("{topic} ({} packets): {problem}", model.name()),
    };
    let calibration = match file {
        Some(file) => {
            let text = std::fs::read_to_string(file).map_err(|e| Error::io(file, e))?;
            Calibration::from_yaml(&text)
                .map_err(|e| fail(format!("--lidar-calibration {}: {e}", file.display())))?
        }
        None => Calibration::builtin(model).ok_or_else(|| {
            fail(format!(
                "the {} has no built-in angle table: pass its calibration with --lidar-calibration FILE (velodyne_pointcloud / nebula YAML)",
                model.name()
            ))
        })?,
    };
    if calibration.lasers() != model.lasers() {
        return Err(fail(format!(
            "the packets are from a {} ({} lasers), the calibration has {} lasers",
            model.name(),
            model.lasers(),
            calibration.lasers()
        )));
    }
    Ok(calibration)
}

/// A cloud as the log holds it: a PointCloud2 message, or a scan cut from packets.
enum Cloud {
    Message(LogMessage),
    Packets(Vec<VelodynePoint>),
}

/// The frames of a drive, streamed: see [`RosDrive::read`]. A cloud is handed on
/// when the next one arrives, so that an image written just after its cloud is
/// found too.
pub struct DriveFrames<'a> {
    drive: &'a RosDrive,
    stream: Box<dyn Iterator<Item = Result<LogMessage>> + 'a>,
    frames: Range<usize>,
    /// The cloud waiting for the next one: (frame number, cloud).
    pending: Option<(usize, Cloud)>,
    /// Clouds to hand on, in order (a packet message can complete several scans).
    ready: VecDeque<(usize, Cloud)>,
    /// Packets into scans, for a packet topic.
    assembler: Option<ScanAssembler>,
    /// Images since the cloud before the pending one: (stamp, message data).
    images: Vec<(u64, Vec<u8>)>,
    next_cloud: usize,
    stream_ended: bool,
}

impl DriveFrames<'_> {
    /// The frame of a cloud, or its error; None when the error was skipped.
    fn hand_on(&mut self, index: usize, cloud: &Cloud) -> Option<Result<Frame>> {
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
        while let Some((index, cloud)) = self.ready.pop_front() {
            if let Some(frame) = self.hand_on(index, &cloud) {
                return Some(frame);
            }
        }
        while !self.stream_ended {
            let message = match self.stream.next() {
                Some(Ok(message)) => message,
                None => break,
                // A corrupt stretch of the file: with --keep-going, what came before counts.
                // A damaged chunk: its clouds were never indexed, the rest follows.
                Some(Err(error @ Error::LogChunk { .. })) => {
                    if let Err(error) = self.drive.skips.handle(self.next_cloud, error) {
                        self.stream_ended = true;
                        return Some(Err(error));
                    }
                    continue;
                }
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
            let clouds = match &mut self.assembler {
                None => vec![Cloud::Message(message)],
                Some(assembler) => match scans_of(assembler, &message) {
                    Ok(scans) => scans.into_iter().map(Cloud::Packets).collect(),
                    Err(problem) => {
                        let error = self.drive.cloud_error(self.next_cloud, problem);
                        if let Err(error) = self.drive.skips.handle(self.next_cloud, error) {
                            self.stream_ended = true;
                            return Some(Err(error));
                        }
                        continue;
                    }
                },
            };
            for cloud in clouds {
                let finished = self.pending.take();
                let current = self.next_cloud;
                self.next_cloud += 1;
                if current >= self.frames.end {
                    self.stream_ended = true;
                } else if current >= self.frames.start {
                    self.pending = Some((current, cloud));
                }
                self.ready.extend(finished);
            }
            while let Some((index, cloud)) = self.ready.pop_front() {
                if let Some(frame) = self.hand_on(index, &cloud) {
                    return Some(frame);
                }
            }
        }
        self.stream_ended = true;
        let pending = self.pending.take();
        self.ready.extend(pending);
        while let Some((index, cloud)) = self.ready.pop_front() {
            if let Some(frame) = self.hand_on(index, &cloud) {
                return Some(frame);
            }
        }
        None
    }
}

/// The scans a packet message completes.
fn scans_of(
    assembler: &mut ScanAssembler,
    message: &LogMessage,
) -> std::result::Result<Vec<Vec<VelodynePoint>>, String> {
    let encoding = message
        .connection
        .encoding()
        .ok_or_else(|| format!("message encoding `{}`", message.connection.message_encoding))?;
    let scan = scan_message(&message.data, encoding)?;
    let mut scans = Vec::new();
    for (stamp_ns, packet) in scan.packets {
        scans.extend(assembler.push(packet, stamp_ns)?.map(|scan| scan.points));
    }
    Ok(scans)
}
