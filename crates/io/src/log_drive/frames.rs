//! A drive's frames, streamed in one pass over its log ([`LogDrive::read`]): clouds
//! (PointCloud2 messages, or scans cut from LiDAR packets) handed on when the next
//! one arrives, with the camera image and the other sensors' clouds nearest in time.

use std::collections::{BTreeSet, VecDeque};
use std::ops::Range;

use super::log_index::HeaderOnly;
use super::merged_clouds::{MergedCloud, MergedContent, merge};
use crate::log_drive::{IMAGE_PAIRING_NS, LogDrive};
use crate::packets::{PacketAssembler, PacketCalibration, PacketModel};
use crate::packets::{PacketPoint, PacketScan};
use crate::payloads::cloud::{CloudPoints, check_some_finite, cloud_points};
use crate::payloads::livox::decode_cloud;
use crate::skips::SkipLog;
use travmap_core::error::{Error, LostMessage, Result};
use travmap_core::frame::{Frame, RemissionScale};
use travmap_formats::log_message::{LogMessage, Part};

/// A scan cut from a packet topic's packets.
pub struct DecodedScan<'a> {
    /// The packet topic, and the frame its points are in.
    pub topic: &'a str,
    pub frame: &'a str,
    pub scan: PacketScan,
}

impl LogDrive {
    /// The scans of every packet topic read (the cloud topic's and the merged
    /// ones'), cut and decoded in one pass (no poses), in log order; the cloud
    /// topic's with the stamps the index gave them. None without a packet topic.
    pub fn packet_scans<'a>(
        &'a self,
        skips: &'a SkipLog,
    ) -> Option<impl Iterator<Item = Result<DecodedScan<'a>>> + 'a> {
        let own = (self.assembler()).map(|a| (self.cloud_topic.as_str(), self.cloud_frame(), a));
        let merged = (self.merged.iter()).filter_map(|sensor| {
            let assembler = assembler(sensor.packets.as_ref())?;
            Some((sensor.topic.as_str(), sensor.frame.as_str(), assembler))
        });
        let mut topics: Vec<_> = own.into_iter().chain(merged).collect();
        if topics.is_empty() {
            return None;
        }
        let mut next = 0;
        let scans = self.messages(skips).flat_map(move |message| {
            let message = match message {
                Ok(message) => message,
                Err(error) => return vec![Err(error)],
            };
            let Some((topic, frame, assembler)) =
                (topics.iter_mut()).find(|(topic, _, _)| *topic == message.connection.topic)
            else {
                return Vec::new();
            };
            let own = *topic == self.cloud_topic;
            match push_message(assembler, &message) {
                Ok(scans) => (scans.into_iter())
                    .map(|mut scan| {
                        if own {
                            scan.stamp_ns = self.stamps_ns.get(next).copied().unwrap_or_default();
                            next += 1;
                        }
                        Ok(DecodedScan { topic, frame, scan })
                    })
                    .collect(),
                Err(problem) => vec![Err(self.cloud_error_on(topic, next, problem))],
            }
        });
        Some(scans)
    }

    /// A fresh scan assembler for the cloud topic, when it carries packets.
    fn assembler(&self) -> Option<PacketAssembler> {
        assembler(self.packets.as_ref())
    }

    /// The frames in `frames`, streamed in one pass over the file, each with the
    /// camera image nearest in time (within 50 ms) when the drive has a camera. With
    /// `--keep-going` (`skips`), unreadable frames are recorded and left out. With
    /// `only`, just those of them: the others' clouds are passed over undecoded.
    pub fn read<'a>(
        &'a self,
        frames: &Range<usize>,
        only: Option<BTreeSet<usize>>,
        skips: &'a SkipLog,
    ) -> DriveFrames<'a> {
        // Only the topics frames are made of are read: a log's other cameras, say,
        // are not copied (nor, from SQLite, read).
        let camera = (self.camera.as_ref()).filter(|_| self.read_images);
        let wanted: Vec<String> = std::iter::once(self.cloud_topic.clone())
            .chain(self.merged.iter().map(|sensor| sensor.topic.clone()))
            .chain(camera.map(|camera| camera.topic.clone()))
            .collect();
        // Messages of other topics the index pass lost are not met again: reported
        // before the first frame.
        let unreported = (self.lost_messages.iter())
            .filter(|lost| !wanted.contains(&lost.topic))
            .cloned()
            .collect();
        let parts = move |topic: &str, _: &str| match wanted.iter().any(|w| w == topic) {
            true => Part::Whole,
            false => Part::Nothing,
        };
        // A few frames picked from many are read before the method runs (a survey),
        // while the cores are free; every frame, beside the method's work.
        let threads = match only {
            Some(_) => rayon::current_num_threads(),
            None => 1,
        };
        DriveFrames {
            drive: self,
            skips,
            unreported,
            stream: Box::new(
                self.log
                    .messages_in_parts(threads, std::sync::Arc::new(parts)),
            ),
            // Clouds the index left out (past a cut end) are not frames.
            frames: frames.start..frames.end.min(self.frame_count()),
            only,
            pending: None,
            ready: VecDeque::new(),
            assembler: self.assembler(),
            merged_assemblers: (self.merged.iter())
                .map(|sensor| assembler(sensor.packets.as_ref()))
                .collect(),
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
                let type_name = message.connection.type_name();
                let cloud = decode_cloud(&type_name, encoding, &message.data).map_err(fail)?;
                let points = cloud_points(&cloud).map_err(fail)?;
                check_some_finite(points.points.len(), points.dropped).map_err(fail)?;
                points
            }
            Cloud::Packets(points) => packet_points(points),
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
        self.cloud_error_on(&self.cloud_topic, cloud, problem)
    }

    /// A problem with a cloud of `topic` (the cloud topic's or a merged one's),
    /// read while frame `cloud` was being made.
    fn cloud_error_on(&self, topic: &str, cloud: usize, problem: String) -> Error {
        Error::LogCloud {
            path: self.path.clone(),
            topic: topic.into(),
            cloud,
            problem,
        }
    }
}

/// A fresh scan assembler for a packet topic's model and calibration.
fn assembler(packets: Option<&(PacketModel, PacketCalibration)>) -> Option<PacketAssembler> {
    let (model, calibration) = packets?;
    // The calibration was checked against the model at open.
    Some(PacketAssembler::new(*model, calibration).expect("a calibration of the model"))
}

/// A scan cut from packets as a cloud: intensity on the 0..1 byte scale.
fn packet_points(points: &[PacketPoint]) -> CloudPoints {
    CloudPoints {
        points: (points.iter())
            .map(|p| {
                let [x, y, z] = p.xyz_m;
                [x, y, z, p.intensity as f32 / 255.0]
            })
            .collect(),
        remission: RemissionScale::Byte,
        labels: None,
        dropped: 0,
    }
}

/// A cloud as the log holds it: a PointCloud2 message, or a scan cut from packets.
enum Cloud {
    Message(LogMessage),
    Packets(Vec<PacketPoint>),
}

/// The frames of a drive, streamed: see [`LogDrive::read`]. A cloud is handed on
/// when the next one arrives, so that an image written just after its cloud is
/// found too.
pub struct DriveFrames<'a> {
    drive: &'a LogDrive,
    skips: &'a SkipLog,
    /// Lost messages of topics this pass does not read, to report first.
    unreported: Vec<LostMessage>,
    stream: Box<dyn Iterator<Item = Result<LogMessage>> + 'a>,
    frames: Range<usize>,
    /// The frames of `frames` wanted, when not all are.
    only: Option<BTreeSet<usize>>,
    /// The cloud waiting for the next one: (frame number, cloud).
    pending: Option<(usize, Cloud)>,
    /// Clouds to hand on, in order (a packet message can complete several scans).
    ready: VecDeque<(usize, Cloud)>,
    /// Packets into scans, for a packet topic.
    assembler: Option<PacketAssembler>,
    /// Likewise for each merged topic, in [`LogDrive`]'s `merged` order.
    merged_assemblers: Vec<Option<PacketAssembler>>,
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
            Err(error) => self.skips.handle(index, error).err().map(Err),
        }
    }

    /// Holds a message of merged topic `topic` (its place in `merged`) until a scan
    /// takes it: a cloud as it is, packets as the scans they complete.
    fn hold_merged(&mut self, topic: usize, message: LogMessage) -> Result<()> {
        let Some(assembler) = &mut self.merged_assemblers[topic] else {
            let stamp = (message.connection.encoding())
                .and_then(|encoding| encoding.decode::<HeaderOnly>(&message.data).ok());
            let stamp_ns = match stamp.map(|h| h.header.stamp.to_ns()) {
                Some(0) | None => message.log_time_ns,
                Some(ns) => ns,
            };
            self.merged_clouds.push(MergedCloud {
                stamp_ns,
                topic,
                cloud: MergedContent::Message(message),
            });
            return Ok(());
        };
        let scans = push_message(assembler, &message).map_err(|problem| {
            let sensor = &self.drive.merged[topic].topic;
            self.drive.cloud_error_on(sensor, self.next_cloud, problem)
        })?;
        self.merged_clouds
            .extend(scans.into_iter().map(|scan| MergedCloud {
                stamp_ns: scan.stamp_ns,
                topic,
                cloud: MergedContent::Scan(packet_points(&scan.points)),
            }));
        Ok(())
    }
}

impl DriveFrames<'_> {
    /// The clouds of the drive's topic a damaged chunk lost, as the file's index
    /// lists them (the index pass numbered them as frames); none where it lists none,
    /// and for packets, whose scans cannot be counted so.
    fn lost_clouds(&self, error: &Error) -> usize {
        match error {
            Error::LogChunk { lost, .. } if self.assembler.is_none() => (lost.iter())
                .filter(|(topic, _)| *topic == self.drive.cloud_topic)
                .count(),
            _ => 0,
        }
    }
}

/// The damage of a chunk, as the error of one cloud it lost.
fn cloud_lost_in(error: &Error) -> Error {
    match error {
        Error::LogChunk {
            path,
            offset,
            start_s,
            end_s,
            problem,
            ..
        } => Error::LogChunk {
            path: path.clone(),
            offset: *offset,
            start_s: *start_s,
            end_s: *end_s,
            problem: problem.clone(),
            lost: Vec::new(),
        },
        other => Error::Sequence {
            path: other
                .path()
                .map(std::path::Path::to_path_buf)
                .unwrap_or_default(),
            message: other.to_string(),
        },
    }
}

impl Iterator for DriveFrames<'_> {
    type Item = Result<Frame>;

    fn next(&mut self) -> Option<Result<Frame>> {
        for lost in std::mem::take(&mut self.unreported) {
            // At the cloud that follows it, as a damaged chunk is.
            let stamps_ns = &self.drive.stamps_ns;
            let cloud = stamps_ns.partition_point(|&stamp_ns| stamp_ns <= lost.log_time_ns);
            if let Err(error) = self.skips.handle(cloud, Error::LogMessageLost(lost)) {
                self.stream_ended = true;
                self.ready.clear();
                return Some(Err(error));
            }
        }
        let camera = (self.drive.camera.as_ref()).filter(|_| self.drive.read_images);
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
                // A damaged chunk whose clouds the file's index lists: each is a frame
                // of its own, skipped (the index pass numbered them); else the damage
                // is skipped at the cloud that follows it.
                Some(Err(error)) if error.is_lost_stretch() => {
                    let lost = self.lost_clouds(&error);
                    let skipped = match lost {
                        0 => self.skips.handle(self.next_cloud, error),
                        _ => {
                            let frames = self.next_cloud..self.next_cloud + lost;
                            self.next_cloud += lost;
                            (frames.filter(|frame| self.frames.contains(frame))).try_for_each(
                                |frame| self.skips.handle(frame, cloud_lost_in(&error)),
                            )
                        }
                    };
                    if let Err(error) = skipped {
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
                    if let Err(error) = self.skips.handle(self.next_cloud, error) {
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
            if let Some(topic) = (self.drive.merged.iter())
                .position(|sensor| sensor.topic == message.connection.topic)
            {
                if let Err(error) = self.hold_merged(topic, message)
                    && let Err(error) = self.skips.handle(self.next_cloud, error)
                {
                    self.stream_ended = true;
                    return Some(Err(error));
                }
                continue;
            }
            if message.connection.topic != self.drive.cloud_topic {
                continue;
            }
            let clouds = match &mut self.assembler {
                None => vec![Cloud::Message(message)],
                Some(assembler) => match push_message(assembler, &message) {
                    Ok(scans) => (scans.into_iter())
                        .map(|scan| Cloud::Packets(scan.points))
                        .collect(),
                    Err(problem) => {
                        let error = self.drive.cloud_error(self.next_cloud, problem);
                        if let Err(error) = self.skips.handle(self.next_cloud, error) {
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
                } else if current >= self.frames.start
                    && self
                        .only
                        .as_ref()
                        .is_none_or(|only| only.contains(&current))
                {
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
        // A log of part of one turn: the index made that part its one frame.
        if self.next_cloud == 0
            && self.drive.partial_turn.is_some()
            && self.frames.contains(&0)
            && let Some((scan, _)) = self
                .assembler
                .as_mut()
                .and_then(|a| a.finish_partial_turn())
        {
            self.next_cloud = 1;
            self.pending = Some((0, Cloud::Packets(scan.points)));
        }
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
) -> std::result::Result<Vec<PacketScan>, String> {
    let encoding = message
        .connection
        .encoding()
        .ok_or_else(|| format!("message encoding `{}`", message.connection.message_encoding))?;
    assembler.push_message(
        &message.connection.type_name(),
        &message.data,
        encoding,
        message.log_time_ns,
    )
}
