//! A drive's frames, streamed in one pass over its log ([`RosDrive::read`]): clouds
//! (PointCloud2 messages, or scans cut from LiDAR packets) handed on when the next
//! one arrives, with the camera image and the other sensors' clouds nearest in time.

use std::collections::VecDeque;
use std::ops::Range;

use super::cloud::{CloudPoints, check_some_finite, cloud_points};
use super::log_index::HeaderOnly;
use super::log_message::LogMessage;
use super::merged_clouds::{MergedCloud, merge};
use super::packets::PacketAssembler;
use super::ros::PointCloud2;
use super::ros_drive::{IMAGE_PAIRING_NS, RosDrive};
use super::velodyne::{PacketScan, VelodynePoint};
use crate::error::{Error, Result};
use crate::frame::{Frame, RemissionScale};

impl RosDrive {
    /// When the cloud topic carries LiDAR packets: its scans, cut and decoded in
    /// one pass (no poses), each with the stamp the index gave it.
    pub fn packet_scans(&self) -> Option<impl Iterator<Item = Result<PacketScan>> + '_> {
        let mut assembler = self.assembler()?;
        let mut next = 0;
        let scans = self
            .messages()
            .filter(|message| !matches!(message, Ok(m) if m.connection.topic != self.cloud_topic))
            .flat_map(move |message| {
                let scans = message.and_then(|message| {
                    push_message(&mut assembler, &message)
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
    fn assembler(&self) -> Option<PacketAssembler> {
        let (model, calibration) = self.packets.as_ref()?;
        // The calibration was checked against the model at open.
        Some(PacketAssembler::new(*model, calibration).expect("a calibration of the model"))
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
            merged_clouds: Vec::new(),
            images: Vec::new(),
            next_cloud: 0,
            stream_ended: false,
        }
    }

    /// Frame `current` from its cloud message and the candidate images.
    fn frame(
        &self,
        current: usize,
        cloud: &Cloud,
        images: &[(u64, Vec<u8>)],
        merged_clouds: &[MergedCloud],
    ) -> Result<Frame> {
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
                let points = cloud_points(&cloud).map_err(fail)?;
                check_some_finite(points.points.len(), points.dropped).map_err(fail)?;
                points
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
        let (points, sensors) = merge(
            points,
            stamp_ns,
            self.period_ns,
            &self.merged,
            merged_clouds,
            &|topic, problem| Error::LogCloud {
                path: self.path.clone(),
                topic: topic.into(),
                cloud: current,
                problem,
            },
            &|frame, frame_stamp_ns| self.cloud_from_frame(frame, frame_stamp_ns, stamp_ns),
        )?;
        // With sensors merged, the frame names the ones it holds, its own first.
        let sensors = match self.merged.is_empty() {
            true => Vec::new(),
            false => [vec![self.cloud_topic.clone()], sensors].concat(),
        };
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
            sensors,
        })
    }

    fn cloud_error(&self, cloud: usize, problem: String) -> Error {
        Error::LogCloud {
            path: self.path.clone(),
            topic: self.cloud_topic.clone(),
            cloud,
            problem,
        }
    }
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
    assembler: Option<PacketAssembler>,
    /// Clouds of merged topics since a period before the pending cloud.
    merged_clouds: Vec<MergedCloud>,
    /// Images since the cloud before the pending one: (stamp, message data).
    images: Vec<(u64, Vec<u8>)>,
    next_cloud: usize,
    stream_ended: bool,
}

impl DriveFrames<'_> {
    /// The frame of a cloud, or its error; None when the error was skipped.
    fn hand_on(&mut self, index: usize, cloud: &Cloud) -> Option<Result<Frame>> {
        let frame = self
            .drive
            .frame(index, cloud, &self.images, &self.merged_clouds);
        let keep_merged_after = self.drive.stamps_ns[index].saturating_sub(self.drive.period_ns);
        self.merged_clouds
            .retain(|c| c.stamp_ns >= keep_merged_after);
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
                            problem: format!("after message {ordinal} of the file: {problem}"),
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
            if let Some(topic) =
                (self.drive.merged.iter()).position(|(topic, _)| *topic == message.connection.topic)
            {
                let stamp = message
                    .connection
                    .encoding()
                    .and_then(|encoding| encoding.decode::<HeaderOnly>(&message.data).ok());
                let stamp_ns = match stamp.map(|h| h.header.stamp.to_ns()) {
                    Some(0) | None => message.log_time_ns,
                    Some(ns) => ns,
                };
                self.merged_clouds.push(MergedCloud {
                    stamp_ns,
                    topic,
                    message,
                });
                continue;
            }
            if message.connection.topic != self.drive.cloud_topic {
                continue;
            }
            let clouds = match &mut self.assembler {
                None => vec![Cloud::Message(message)],
                Some(assembler) => match push_message(assembler, &message) {
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
fn push_message(
    assembler: &mut PacketAssembler,
    message: &LogMessage,
) -> std::result::Result<Vec<Vec<VelodynePoint>>, String> {
    let encoding = message
        .connection
        .encoding()
        .ok_or_else(|| format!("message encoding `{}`", message.connection.message_encoding))?;
    let scans = assembler.push_message(&message.data, encoding)?;
    Ok(scans.into_iter().map(|scan| scan.points).collect())
}
