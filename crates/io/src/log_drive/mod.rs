//! Reading a recorded ROS drive (any [`Log`]: MCAP, ROS 1 bag, rosbag2; ROS 2 or
//! ROS 1 messages): the clouds of one PointCloud2 topic, each with its pose in the
//! world frame from `/tf` + `/tf_static` (interpolated at the cloud's stamp) or from a
//! `nav_msgs/Odometry` topic.
//!
//! The log is streamed: one pass at open collects the topics, the cloud stamps and
//! every transform; [`LogDrive::read`] (`drive_frames.rs`) streams again and decodes
//! only the clouds asked for. Any PointCloud2 layout is accepted: fields at any
//! offset and order, float32 or float64 coordinates, extra fields, big-endian data,
//! organised clouds; points that are no return (a NaN or infinite coordinate, or
//! the sensor's origin) are dropped.

pub mod by_topic;
pub(crate) mod camera_model;
pub mod frames;
pub mod log_index;
pub(crate) mod merged_clouds;
mod options;
pub(crate) mod packet_topics;
pub mod pose_topics;
pub mod transforms;

use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use super::packets::{PacketCalibration, PacketModel};
use super::skips::SkipLog;
use crate::containers::log::Log;
pub use crate::log_drive::by_topic::{LidarCalibrations, LidarFrames};
use crate::log_drive::camera_model::Projection;
use crate::log_drive::log_index::{CameraSource, LogIndex};
use crate::log_drive::merged_clouds::{MergedSensor, median_period_ns};
pub use crate::log_drive::options::{LogOptions, MergedTopics};
use crate::log_drive::pose_topics::VehiclePoses;
use crate::log_drive::transforms::TransformTree;
use crate::payloads::image::image_pixels;
use travmap_core::config::PoseSource;
use travmap_core::error::{Error, LostMessage, Result};
use travmap_core::frame::CameraImage;
use travmap_core::posing::{Posing, decide};
use travmap_formats::log_message::LogMessage;

/// An image is paired with a cloud when their stamps are at most this far apart.
pub(crate) const IMAGE_PAIRING_NS: u64 = 50_000_000;

/// Frames that place a drive on the Earth: `utm` (robot_localization's
/// navsat_transform; planar metres of a zone) and `earth` (REP 105; ECEF).
pub const GEO_FRAMES: [&str; 2] = ["utm", "earth"];

/// `geo_from_world` for the first frame of [`GEO_FRAMES`] that the tree links to
/// `world_frame` at `stamp_ns`, above it or below it.
fn place_on_earth(
    transforms: &TransformTree,
    world_frame: &str,
    stamp_ns: u64,
) -> Option<(String, Isometry3<f64>)> {
    GEO_FRAMES
        .iter()
        .filter(|geo| **geo != world_frame)
        .find_map(|geo| {
            let above = transforms
                .ancestor_from(geo, world_frame, stamp_ns)
                .ok()
                .flatten();
            let below = || {
                (transforms
                    .ancestor_from(world_frame, geo, stamp_ns)
                    .ok()
                    .flatten())
                .map(|world_from_geo| world_from_geo.inverse())
            };
            above
                .or_else(below)
                .map(|geo_from_world| (geo.to_string(), geo_from_world))
        })
}

/// An opened drive.
pub struct LogDrive {
    pub(crate) path: PathBuf,
    pub(crate) log: Log,
    posing: Posing,
    /// Said when the poses are not what was asked for by default.
    notice: Option<String>,
    pub(crate) cloud_topic: String,
    cloud_frame: String,
    world_frame: String,
    pub(crate) stamps_ns: Vec<u64>,
    /// See [`LogIndex`]: the packets of the first two scans, the first partial.
    partial_first_scan: Option<(usize, usize)>,
    /// See [`LogIndex`]: the packets hold nothing but part of one turn, its frame.
    pub(crate) partial_turn: Option<String>,
    transforms: TransformTree,
    pub(crate) camera: Option<CameraSource>,
    /// Whether frames carry the camera's images (default true): see
    /// [`LogDrive::set_read_images`].
    pub(crate) read_images: bool,
    /// Chunks the index pass could not read: their messages are lost.
    damaged_chunks: usize,
    /// Single messages the index pass could not read (see [`LogIndex`]).
    pub(crate) lost_messages: Vec<LostMessage>,
    /// When the cloud topic carries LiDAR packets: their model and calibration.
    pub(crate) packets: Option<(PacketModel, PacketCalibration)>,
    /// Where the world frame lies on the Earth: a frame of [`GEO_FRAMES`] and
    /// `geo_from_world` at the first scan.
    georeference: Option<(String, Isometry3<f64>)>,
    /// Other sensors' topics merged into each scan.
    pub(crate) merged: Vec<MergedSensor>,
    /// The clouds' median period: a merged cloud within half of it joins a scan.
    pub(crate) period_ns: u64,
}

impl LogDrive {
    /// Reads `log`'s topics, cloud stamps and transforms in one pass
    /// (`LogIndex`), and poses the clouds as [`decide`] says, from `poses`.
    pub fn open(log: Log, options: &LogOptions, poses: PoseSource) -> Result<Self> {
        let mut index = LogIndex::read(&log, options, poses)?;
        let packet_topics = usize::from(index.packets.is_some())
            + (index.merged.iter())
                .filter(|m| m.packets.is_some())
                .count();
        let calibrated = |topic: &str, model: Option<PacketModel>| {
            (model.map(|model| {
                // An Ouster's metadata was chosen (log or file) by the index.
                if let Some(recorded) = index.recorded_calibrations.get(topic) {
                    return Ok((model, recorded.clone()));
                }
                let calibrations = &options.lidar_calibrations;
                packet_calibration(log.path(), topic, model, calibrations, packet_topics)
                    .map(|c| (model, c))
            }))
            .transpose()
        };
        let packets = calibrated(&index.cloud_topic, index.packets)?;
        let merged = (std::mem::take(&mut index.merged).into_iter())
            .map(|merged| {
                Ok(MergedSensor {
                    packets: calibrated(&merged.topic, merged.packets)?,
                    topic: merged.topic,
                    frame: merged.frame,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let decision = decide(log.path(), poses, &index.pose_record(options))?;
        let mut notice = decision.notice;
        match (&index.vehicle_poses, decision.posing, &options.pose_topic) {
            (VehiclePoses::Used(said), Posing::Recorded, _) => {
                notice = Some(format!("{}: {said}", log.path().display()));
            }
            (VehiclePoses::NotUsed, Posing::Recorded, Some(topic)) => {
                notice = Some(format!(
                    "{}: --pose-topic {topic} is not used: a moving /tf or an Odometry already poses the clouds (a frame has one parent; --poses odometry leaves /tf's moving transforms out)",
                    log.path().display()
                ));
            }
            _ => {}
        }
        let world_frame = match (&options.world_frame, decision.posing) {
            (Some(frame), _) => frame.clone(),
            // A tree rooted on the Earth: the drive is mapped in the frame below
            // the root, where coordinates are small enough for float32's
            // centimetres, and the root places the map.
            (None, Posing::Recorded) => match GEO_FRAMES
                .contains(&index.root_frame.as_str())
                .then(|| {
                    index
                        .transforms
                        .child_below(&index.root_frame, &index.cloud_frame)
                })
                .flatten()
            {
                Some(below) => {
                    let said = notice.take().map(|n| format!("{n}; ")).unwrap_or_default();
                    notice = Some(format!(
                        "{said}{}: the transform tree's root is `{}`: the drive is mapped in `{below}`, the frame below it (small coordinates keep float32's centimetres), and placed in `{}` by its transform",
                        log.path().display(),
                        index.root_frame,
                        index.root_frame
                    ));
                    below
                }
                None => index.root_frame,
            },
            // Estimated poses: `map` is the first scan's frame.
            (None, Posing::Registration) => "map".to_string(),
            (None, Posing::Alone) => index.cloud_frame.clone(),
        };
        let georeference = place_on_earth(
            &index.transforms,
            &world_frame,
            index.stamps_ns.first().copied().unwrap_or(0),
        );
        let period_ns = median_period_ns(&index.stamps_ns);
        if let Some(file) = &index.ouster_metadata_beside {
            let said = notice.take().map(|n| format!("{n}; ")).unwrap_or_default();
            notice = Some(format!(
                "{said}{}: its Ouster packets are read with {}, the metadata saved beside it (--lidar-calibration gives another)",
                log.path().display(),
                file.display()
            ));
        }
        if let Some(lens) = index.camera.as_ref().and_then(|c| c.notice.as_ref()) {
            let said = notice.take().map(|n| format!("{n}; ")).unwrap_or_default();
            notice = Some(format!("{said}{}: {lens}", log.path().display()));
        }
        if let Some(covered) = &index.partial_turn {
            let said = notice.take().map(|n| format!("{n}; ")).unwrap_or_default();
            notice = Some(format!(
                "{said}{}: {} holds nothing but part of one turn of the sensor ({covered}): read as one frame",
                log.path().display(),
                index.cloud_topic
            ));
        }
        // A Helios 32 sends packets of the same form: the reading is said.
        if let Some((PacketModel::Robosense(model), _)) = &packets {
            let said = notice.take().map(|n| format!("{n}; ")).unwrap_or_default();
            notice = Some(format!(
                "{said}{}: its RoboSense Helios packets are read as a {}'s (a Helios 32 sends packets of the same form, which travmap does not decode yet)",
                log.path().display(),
                model.name()
            ));
        }
        let mut drive = Self {
            path: log.path().to_path_buf(),
            log,
            posing: decision.posing,
            notice,
            georeference,
            cloud_topic: index.cloud_topic,
            cloud_frame: index.cloud_frame,
            world_frame,
            stamps_ns: index.stamps_ns,
            partial_first_scan: index.partial_first_scan,
            partial_turn: index.partial_turn,
            transforms: index.transforms,
            camera: index.camera,
            read_images: true,
            damaged_chunks: index.damaged_chunks,
            lost_messages: index.lost_messages,
            packets,
            period_ns,
            merged,
        };
        drive.trim_cut_end();
        Ok(drive)
    }

    /// Whether frames carry the camera's images, decoded and posed (default true).
    /// Without, a drive with a camera reads as one without: its image messages are
    /// not even parsed.
    pub fn set_read_images(&mut self, read_images: bool) {
        self.read_images = read_images;
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

    /// Where the world frame lies on the Earth, when the transform tree links it
    /// to `utm` or `earth`: that frame and `geo_from_world` at the first scan.
    pub fn georeference(&self) -> Option<&(String, Isometry3<f64>)> {
        self.georeference.as_ref()
    }

    /// Frame numbers: the clouds' order on their topic.
    /// The model of the cloud topic's LiDAR, when it carries packets.
    pub fn packet_model(&self) -> Option<PacketModel> {
        self.packets.as_ref().map(|(model, _)| *model)
    }

    /// The stamp of cloud `index`, when the drive has it.
    pub fn stamp_ns(&self, index: usize) -> Option<u64> {
        self.stamps_ns.get(index).copied()
    }

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

    /// The pose of another sensor's `frame` (at `frame_stamp_ns`) in the clouds' frame
    /// (at `cloud_stamp_ns`), through the root of the tree above both: a static mount,
    /// or the vehicle's motion between the two stamps as well.
    pub(crate) fn cloud_from_frame(
        &self,
        frame: &str,
        frame_stamp_ns: u64,
        cloud_stamp_ns: u64,
    ) -> Result<Isometry3<f64>> {
        let root = self
            .transforms
            .root_above(&self.cloud_frame)
            .map_err(|problem| Error::Transform {
                path: self.path.clone(),
                problem,
            })?;
        let unlinked = || Error::LogContainer {
            path: self.path.clone(),
            problem: format!(
                "merging clouds: no transform links `{frame}` to the clouds' frame `{}` (the sensors' mounts belong on /tf_static; --lidar-frame TOPIC=FRAME names a sensor's frame when its clouds name another)",
                self.cloud_frame
            ),
        };
        let root_from_cloud = self
            .ancestor_from(&root, &self.cloud_frame, cloud_stamp_ns)?
            .ok_or_else(unlinked)?;
        let root_from_frame = self
            .ancestor_from(&root, frame, frame_stamp_ns)?
            .ok_or_else(unlinked)?;
        Ok(root_from_cloud.inverse() * root_from_frame)
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
    pub(crate) fn camera_image(
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
        let camera_from_velodyne = velodyne_from_camera.inverse();
        Ok(match &camera.projection {
            Projection::Raw { k, distortion } => {
                CameraImage::from_intrinsics(k, distortion.clone(), &camera_from_velodyne, image)
            }
            Projection::Rectified(projection) => {
                CameraImage::new(projection, &camera_from_velodyne.to_homogeneous(), image)
            }
        })
    }

    /// The log's chunks as stored, when it is one MCAP file whose chunks hold every
    /// message and none is damaged (for passthrough without decoding).
    pub fn stored(&self) -> Option<travmap_formats::mcap::stored::StoredLog> {
        (self.damaged_chunks == 0).then(|| self.log.stored())?
    }

    /// When the cloud topic carries packets and the recording began mid-turn: the
    /// packets of frame 0 (a part of a rotation) and of frame 1.
    pub fn partial_first_scan(&self) -> Option<(usize, usize)> {
        self.partial_first_scan
    }

    /// Every message of the log in order, undecoded (for passthrough); with
    /// `--keep-going` (`skips`) the messages of damaged chunks are left out and
    /// recorded at the cloud that follows, else the first is an error.
    pub fn messages<'a>(
        &'a self,
        skips: &'a SkipLog,
    ) -> impl Iterator<Item = Result<LogMessage>> + 'a {
        let mut clouds = 0;
        self.log
            .messages()
            .filter_map(move |message| match message {
                Ok(message) => {
                    clouds += (message.connection.topic == self.cloud_topic) as usize;
                    Some(Ok(message))
                }
                // Recorded as reading the frames records it: at the cloud that follows.
                Err(error) if error.is_lost_stretch() => skips.handle(clouds, error).err().map(Err),
                Err(error) => Some(Err(error)),
            })
    }
}

/// The calibration of a packet topic's `model` (see [`PacketCalibration::for_model`]).
fn packet_calibration(
    path: &Path,
    topic: &str,
    model: PacketModel,
    calibrations: &LidarCalibrations,
    packet_topics: usize,
) -> Result<PacketCalibration> {
    let file = calibrations.for_topic(topic).map(|f| f.as_path());
    PacketCalibration::for_model(model, file).map_err(|problem| {
        // A file given for every packet topic may fit only one of several.
        let shared =
            packet_topics > 1 && file.is_some() && file == calibrations.any_topic.as_deref();
        let hint = match shared {
            true => format!(" (a file for one topic only: --lidar-calibration {topic}=FILE)"),
            false => String::new(),
        };
        Error::LogContainer {
            path: path.to_path_buf(),
            problem: format!("{topic} ({} packets): {problem}{hint}", model.name()),
        }
    })
}
