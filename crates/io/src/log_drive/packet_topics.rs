//! The log index's packet topics: each one's model, its scans cut (for their
//! stamps, as the drive's frames will cut them) and how many packets its first two
//! scans took; an Ouster's metadata (`ouster/`), read from its metadata topic or
//! from `--lidar-calibration`, before its packets can be cut.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};
use travmap_core::option_files::{TEXT_MAX_BYTES, read_option_text};

use super::by_topic::LidarCalibrations;
use crate::packets::hesai::{HesaiAssembler, HesaiCalibration};
use crate::packets::ouster::{
    METADATA_MESSAGE, METADATA_TOPIC_NAME, OUSTER_FRAME, OUSTER_PACKET_MESSAGES, OusterAssembler,
    OusterMetadata, metadata_topic_of, string_message,
};
use crate::packets::robosense::{RobosenseAssembler, RobosenseCalibration};
use crate::packets::velodyne::{DecoderSettings, ScanCutter};
use crate::packets::{PacketCalibration, PacketModel, packet_message, partial_turn_said};
use travmap_formats::ros::MessageEncoding;

/// Ouster packets held while no metadata says how to read them: at most this many
/// bytes (a second of a 128-beam sensor's), then the log is refused.
const WAITING_BYTES: usize = 64 << 20;

/// Where a packet topic's scans are cut, for their stamps: Velodyne's cut is on the
/// packets' azimuths alone; Hesai's is per laser, on the points' corrected azimuths;
/// RoboSense's on its blocks' azimuths, after the packet's DIFOP; an Ouster's on the
/// frame ids of the packets.
enum PacketCut {
    Velodyne(ScanCutter),
    Hesai(Box<HesaiAssembler>),
    Robosense(Box<RobosenseAssembler>),
    Ouster(Box<OusterAssembler>),
}

/// What the index pass learns of packet topics.
#[derive(Default)]
pub(crate) struct PacketTopics {
    /// The packets' calibration files (`--lidar-calibration`).
    calibrations: LidarCalibrations,
    /// An Ouster metadata file found beside a capture ([`ouster_metadata_beside`]),
    /// and whether a topic was read with it.
    beside: Option<(PathBuf, OusterMetadata)>,
    beside_used: bool,
    /// Packet topic -> the model and where its scans are cut.
    topics: HashMap<String, (PacketModel, PacketCut)>,
    /// Velodyne packet topic -> the stamp of the scan being cut.
    scan_start: HashMap<String, u64>,
    /// Packet topic -> how many packets its first scans took (the first two), and
    /// the scan being cut so far.
    per_scan: HashMap<String, (Vec<usize>, usize)>,
    /// Metadata topic -> the Ouster metadata it holds (or why it does not read).
    ouster_metadata: BTreeMap<String, Result<OusterMetadata, String>>,
    /// Ouster topic -> the metadata its packets are read with.
    ouster_calibrations: HashMap<String, OusterMetadata>,
    /// Ouster packet topics that are an IMU's.
    imu_topics: HashSet<String>,
    /// Ouster packets before any metadata: (topic, log time, packet).
    waiting: Vec<(String, u64, Vec<u8>)>,
    waiting_bytes: usize,
}

impl PacketTopics {
    /// `beside`: the metadata found beside a capture, for Ouster topics that have
    /// no calibration file and no metadata topic.
    pub(crate) fn new(
        calibrations: LidarCalibrations,
        beside: Option<(PathBuf, OusterMetadata)>,
    ) -> Self {
        Self {
            calibrations,
            beside,
            ..Default::default()
        }
    }

    /// The metadata file found beside the capture, when a topic was read with it.
    pub(crate) fn metadata_beside_used(&self) -> Option<&Path> {
        let (file, _) = self.beside.as_ref().filter(|_| self.beside_used)?;
        Some(file)
    }

    /// Whether the index reads messages of type `type_name` on `topic` whole.
    pub(crate) fn reads(topic: &str, type_name: &str) -> bool {
        type_name == METADATA_MESSAGE && topic.ends_with(METADATA_TOPIC_NAME)
    }

    /// Takes note of a metadata message (a `std_msgs/String` on a `.../metadata`
    /// topic); other strings are not the index's. The first one of a topic counts.
    pub(crate) fn add_metadata(
        &mut self,
        topic: &str,
        data: &[u8],
        encoding: MessageEncoding,
        cloud_stamps: &mut HashMap<String, (String, Vec<u64>)>,
    ) -> Result<(), String> {
        if self.ouster_metadata.contains_key(topic) {
            return Ok(());
        }
        let text = string_message(data, encoding)?;
        // Another node's metadata string is not an Ouster's: left alone unless a
        // packet topic needs it.
        let metadata = OusterMetadata::from_json(&text);
        self.ouster_metadata.insert(topic.to_string(), metadata);
        for (topic, log_time_ns, packet) in std::mem::take(&mut self.waiting) {
            self.add_packets(
                &topic,
                OUSTER_PACKET_MESSAGES[0],
                &[(log_time_ns, &packet)],
                OUSTER_FRAME,
                cloud_stamps,
            )?;
        }
        self.waiting_bytes = 0;
        Ok(())
    }

    /// Takes note of a packet message of type `type_name` on `topic`, recorded at
    /// `log_time_ns`: its scans' stamps go to `cloud_stamps`.
    pub(crate) fn add(
        &mut self,
        topic: &str,
        type_name: &str,
        data: &[u8],
        encoding: MessageEncoding,
        log_time_ns: u64,
        cloud_stamps: &mut HashMap<String, (String, Vec<u64>)>,
    ) -> Result<(), String> {
        let message = packet_message(type_name, data, encoding, log_time_ns)?;
        self.add_packets(
            topic,
            type_name,
            &message.packets,
            &message.frame_id,
            cloud_stamps,
        )
    }

    fn add_packets(
        &mut self,
        topic: &str,
        type_name: &str,
        packets: &[(u64, &[u8])],
        frame_id: &str,
        cloud_stamps: &mut HashMap<String, (String, Vec<u64>)>,
    ) -> Result<(), String> {
        let Some(first) = packets.first() else {
            return Ok(());
        };
        let ouster = OUSTER_PACKET_MESSAGES.contains(&type_name);
        if self.imu_topics.contains(topic) {
            return Ok(());
        }
        if !self.topics.contains_key(topic) {
            let cut = match ouster {
                true => match self.ouster_metadata_for(topic)? {
                    Some(metadata) => {
                        // An IMU's packets (`/ouster/imu_packets`) are not a lidar's.
                        if first.1.len() != metadata.model.packet_bytes() && topic.contains("imu") {
                            self.imu_topics.insert(topic.to_string());
                            return Ok(());
                        }
                        let model = PacketModel::Ouster(metadata.model);
                        let cut = PacketCut::Ouster(Box::new(
                            OusterAssembler::new(&metadata).stamps_only(),
                        ));
                        self.ouster_calibrations.insert(topic.to_string(), metadata);
                        (model, cut)
                    }
                    None => return self.wait(topic, first),
                },
                false => self.cut_of(topic, type_name, first.1)?,
            };
            self.topics.insert(topic.to_string(), cut);
        }
        let (model, cut) = self.topics.get_mut(topic).expect("inserted above");
        let stamps = &mut cloud_stamps
            .entry(topic.to_string())
            .or_insert_with(|| (frame_id.to_string(), Vec::new()))
            .1;
        let counts = self.per_scan.entry(topic.to_string()).or_default();
        for (stamp_ns, packet) in packets {
            counts.1 += 1;
            let scans_before = stamps.len();
            match cut {
                PacketCut::Velodyne(cutter) => {
                    check_model(*model, type_name, packet)?;
                    // A scan is stamped as ScanAssembler stamps it: the first scan
                    // with its first packet, the others with the packet that cut the
                    // scan before (it carries points past the cut into them).
                    let scan_start = self.scan_start.entry(topic.to_string());
                    let start = *scan_start.or_insert(*stamp_ns);
                    if cutter.completes(packet) {
                        stamps.push(start);
                        self.scan_start.insert(topic.to_string(), *stamp_ns);
                    }
                }
                // Stamped as the drive's frames are: by the same assembler.
                PacketCut::Hesai(assembler) => {
                    check_model(*model, type_name, packet)?;
                    if let Some(scan) = assembler.push(packet, *stamp_ns)? {
                        stamps.push(scan.stamp_ns);
                    }
                }
                PacketCut::Robosense(assembler) => {
                    check_model(*model, type_name, packet)?;
                    if let Some(scan) = assembler.push(packet, *stamp_ns)? {
                        stamps.push(scan.stamp_ns);
                    }
                }
                PacketCut::Ouster(assembler) => {
                    stamps.extend(
                        assembler
                            .push(packet, *stamp_ns)?
                            .iter()
                            .map(|s| s.stamp_ns),
                    );
                }
            }
            if stamps.len() > scans_before && counts.0.len() < 2 {
                counts.0.push(std::mem::take(&mut counts.1));
            }
        }
        Ok(())
    }

    /// A Velodyne, Hesai or RoboSense topic's model, from its first packet, and its
    /// cut.
    fn cut_of(
        &self,
        topic: &str,
        type_name: &str,
        packet: &[u8],
    ) -> Result<(PacketModel, PacketCut), String> {
        let model = PacketModel::of_packet(type_name, packet)?;
        let cut = match model {
            PacketModel::Hesai(hesai) => {
                // A file that does not fit is refused by name when the drive opens;
                // the factory table cuts until then.
                let file = self.calibrations.for_topic(topic).map(|f| f.as_path());
                let calibration = match PacketCalibration::for_model(model, file) {
                    Ok(PacketCalibration::Hesai(calibration)) => calibration,
                    _ => HesaiCalibration::builtin(hesai),
                };
                let assembler = HesaiAssembler::new(hesai, &calibration)?;
                PacketCut::Hesai(Box::new(assembler.stamps_only()))
            }
            PacketModel::Robosense(robosense) => {
                let file = self.calibrations.for_topic(topic).map(|f| f.as_path());
                let calibration = match PacketCalibration::for_model(model, file) {
                    Ok(PacketCalibration::Robosense(calibration)) => calibration,
                    _ => RobosenseCalibration::builtin(robosense),
                };
                let assembler = RobosenseAssembler::new(robosense, &calibration)?;
                PacketCut::Robosense(Box::new(assembler.stamps_only()))
            }
            _ => PacketCut::Velodyne(ScanCutter::new(DecoderSettings::default().cut_angle_deg)),
        };
        Ok((model, cut))
    }

    /// The metadata an Ouster topic's packets are read with: the file given for
    /// it, else its metadata topic's, else the file beside the capture; None while
    /// the log has shown none.
    fn ouster_metadata_for(&mut self, topic: &str) -> Result<Option<OusterMetadata>, String> {
        if let Some(file) = self.calibrations.for_topic(topic) {
            return ouster_metadata_file(file).map(Some);
        }
        let ouster = || {
            self.ouster_metadata
                .iter()
                .filter(|(_, m)| m.is_ok())
                .map(|(t, _)| t)
        };
        let metadata_topic = metadata_topic_of(topic, ouster())
            .or_else(|| metadata_topic_of(topic, self.ouster_metadata.keys()));
        match metadata_topic.map(|t| (t, &self.ouster_metadata[t])) {
            Some((_, Ok(metadata))) => Ok(Some(metadata.clone())),
            Some((metadata_topic, Err(problem))) => {
                Err(format!("its metadata on {metadata_topic}: {problem}"))
            }
            None => {
                self.beside_used |= self.beside.is_some();
                Ok(self.beside.as_ref().map(|(_, metadata)| metadata.clone()))
            }
        }
    }

    fn wait(&mut self, topic: &str, (log_time_ns, packet): &(u64, &[u8])) -> Result<(), String> {
        self.waiting_bytes += packet.len();
        if self.waiting_bytes > WAITING_BYTES {
            return Err(format!(
                "{} MB of Ouster packets before any metadata: record the sensor's metadata topic \
                 (ouster_ros's /ouster/metadata), or give its JSON with --lidar-calibration",
                WAITING_BYTES >> 20
            ));
        }
        self.waiting
            .push((topic.to_string(), *log_time_ns, packet.to_vec()));
        Ok(())
    }

    /// Ouster packets still waiting at the end of the log: the topic and why.
    pub(crate) fn unread(&self) -> Option<(String, String)> {
        // A lidar's topic rather than an IMU's, when both wait.
        let topics = self.waiting.iter().map(|(topic, _, _)| topic);
        let topic = (topics.clone().find(|t| !t.contains("imu"))).or(topics.clone().next())?;
        let metadata_topics: Vec<&String> = self.ouster_metadata.keys().collect();
        Some((
            topic.clone(),
            format!(
                "Ouster packets without the sensor's metadata (metadata topics: {metadata_topics:?}): \
                 give its JSON with --lidar-calibration (ouster_ros records it on /ouster/metadata; \
                 beside a pcap, NAME.json or NAME_0.json as the SDK saves it is read without asking)"
            ),
        ))
    }

    /// Names the frame of each Ouster topic's points in `cloud_stamps`: ouster_ros's
    /// `os_sensor`, unless the log names its sensors' frames apart (several
    /// sensors, or the older driver's `os1_sensor`): then the one frame of `frames`
    /// holding both `os_sensor` and a part of the topic's namespace
    /// (`/front/lidar_packets` -> `front/os_sensor`), or the only frame holding
    /// `os_sensor`.
    pub(crate) fn name_ouster_frames<'a>(
        &self,
        frames: impl Iterator<Item = &'a str> + Clone,
        cloud_stamps: &mut HashMap<String, (String, Vec<u64>)>,
    ) {
        // ouster_ros 0.8 and before named it `os1_sensor`.
        let sensors = frames.filter(|f| f.contains(OUSTER_FRAME) || f.contains("os1_sensor"));
        for topic in self.ouster_calibrations.keys() {
            let Some((frame, _)) = cloud_stamps.get_mut(topic) else {
                continue;
            };
            let namespace: Vec<&str> = topic.split('/').filter(|p| !p.is_empty()).collect();
            let namespace = &namespace[..namespace.len().saturating_sub(1)];
            let of_namespace: Vec<&str> = (sensors.clone())
                .filter(|f| namespace.iter().any(|part| f.contains(part)))
                .collect();
            let all: Vec<&str> = sensors.clone().collect();
            *frame = match (of_namespace.as_slice(), all.as_slice()) {
                ([one], _) => one.to_string(),
                _ if all.contains(&OUSTER_FRAME) => OUSTER_FRAME.to_string(),
                (_, [one]) => one.to_string(),
                _ => OUSTER_FRAME.to_string(),
            };
        }
    }

    pub(crate) fn model(&self, topic: &str) -> Option<PacketModel> {
        self.topics.get(topic).map(|(model, _)| *model)
    }

    /// The calibration an Ouster topic was cut with (its metadata).
    pub(crate) fn recorded_calibration(&self, topic: &str) -> Option<PacketCalibration> {
        (self.ouster_calibrations.get(topic))
            .map(|m| PacketCalibration::Ouster(Box::new(m.clone())))
    }

    /// The scan each Ouster topic that completed none was gathering when the log
    /// ended (a capture of part of one turn), stamped into `cloud_stamps` as its
    /// one frame: (topic, how much of the turn it covers, in words). The frames'
    /// pass reads it as such ([`crate::packets::PacketAssembler::finish_partial_turn`]).
    pub(crate) fn partial_turns(
        &mut self,
        cloud_stamps: &mut HashMap<String, (String, Vec<u64>)>,
    ) -> Vec<(String, String)> {
        let mut partial = Vec::new();
        for (topic, (_, cut)) in &mut self.topics {
            let Some((_, stamps)) = cloud_stamps.get_mut(topic).filter(|(_, s)| s.is_empty())
            else {
                continue;
            };
            if let PacketCut::Ouster(assembler) = cut
                && let Some((scan, columns, turn)) = assembler.finish()
            {
                stamps.push(scan.stamp_ns);
                partial.push((topic.clone(), partial_turn_said(columns, turn)));
            }
        }
        partial
    }

    /// The packets of the first and second scans, when the first took fewer than
    /// half the second's (the recording began mid-turn).
    pub(crate) fn partial_first_scan(&self, topic: &str) -> Option<(usize, usize)> {
        match self.per_scan.get(topic) {
            Some((counts, _)) if counts.len() == 2 && 2 * counts[0] < counts[1] => {
                Some((counts[0], counts[1]))
            }
            _ => None,
        }
    }
}

/// The Ouster metadata JSON saved beside a capture, found as ouster-sdk finds it: of
/// the folder's `.json` files that read as Ouster metadata, the one whose name shares
/// the longest start with the capture's name up to its extension's dot
/// (`drive.pcap`: `drive.json` before `drive_0.json`, the SDK's own name). None when
/// there is none, or two share the longest start (two sensors: give each with
/// `--lidar-calibration TOPIC=FILE`).
pub(crate) fn ouster_metadata_beside(capture: &Path) -> Option<(PathBuf, OusterMetadata)> {
    let name = capture.file_name()?.to_str()?;
    let stem = name.rfind('.').map_or(name, |dot| &name[..=dot]);
    let folder = capture.parent().filter(|p| !p.as_os_str().is_empty());
    let shared = |other: &str| {
        stem.bytes()
            .zip(other.bytes())
            .take_while(|(a, b)| a == b)
            .count()
    };
    let mut best: Vec<(usize, PathBuf, OusterMetadata)> = Vec::new();
    for entry in std::fs::read_dir(folder.unwrap_or(Path::new(".")))
        .ok()?
        .flatten()
    {
        let file_name = entry.file_name();
        let Some(other) = file_name.to_str() else {
            continue;
        };
        let path = folder.map_or_else(|| PathBuf::from(other), |f| f.join(other));
        let score = shared(other);
        let worse = best.first().is_some_and(|(top, _, _)| score < *top);
        if score == 0 || worse || !other.ends_with(".json") {
            continue;
        }
        let Ok(metadata) = ouster_metadata_file(&path) else {
            continue;
        };
        if best.first().is_some_and(|(top, _, _)| score > *top) {
            best.clear();
        }
        best.push((score, path, metadata));
    }
    match <[_; 1]>::try_from(best) {
        Ok([(_, path, metadata)]) => Some((path, metadata)),
        Err(_) => None,
    }
}

/// An Ouster's metadata JSON file (`--lidar-calibration`).
fn ouster_metadata_file(file: &std::path::Path) -> Result<OusterMetadata, String> {
    let text = read_option_text(file, TEXT_MAX_BYTES).map_err(|e| e.to_string())?;
    OusterMetadata::from_json(&text).map_err(|e| format!("{}: {e}", file.display()))
}

/// Every packet of a topic is of the model its first one was.
fn check_model(model: PacketModel, type_name: &str, packet: &[u8]) -> Result<(), String> {
    let packet_model = PacketModel::of_packet(type_name, packet)?;
    match packet_model == model {
        true => Ok(()),
        false => Err(format!(
            "a {} packet on a topic of {} packets",
            packet_model.name(),
            model.name()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Metadata of a two-beam Ouster, as flat metadata names it.
    const TWO_BEAMS: &str = r#"{"beam_altitude_angles": [1, -1], "beam_azimuth_angles": [0, 0],
        "lidar_origin_to_beam_origin_mm": 0,
        "lidar_to_sensor_transform": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1],
        "data_format": {"columns_per_frame": 512, "columns_per_packet": 16,
                        "pixels_per_column": 2}}"#;

    #[test]
    fn the_metadata_saved_beside_a_capture_is_the_one_its_name_starts() {
        let dir = tempfile::tempdir().unwrap();
        let capture = dir.path().join("drive.pcap");
        assert!(ouster_metadata_beside(&capture).is_none());
        for name in ["drive_0.json", "other.json"] {
            std::fs::write(dir.path().join(name), TWO_BEAMS).unwrap();
        }
        std::fs::write(dir.path().join("drive.notes.json"), "{}").unwrap();
        let (found, _) = ouster_metadata_beside(&capture).unwrap();
        assert_eq!(found, dir.path().join("drive_0.json"));
        // The SDK's order: the whole stem first.
        std::fs::write(dir.path().join("drive.json"), TWO_BEAMS).unwrap();
        let (found, _) = ouster_metadata_beside(&capture).unwrap();
        assert_eq!(found, dir.path().join("drive.json"));
        // Two of one score are two sensors' metadata: neither is chosen.
        std::fs::write(dir.path().join("drive.2.json"), TWO_BEAMS).unwrap();
        std::fs::remove_file(dir.path().join("drive.json")).unwrap();
        std::fs::write(dir.path().join("drive.1.json"), TWO_BEAMS).unwrap();
        assert!(ouster_metadata_beside(&capture).is_none());
    }

    #[test]
    fn an_ouster_topics_frame_is_found_in_the_transform_tree() {
        let metadata = OusterMetadata::from_json(TWO_BEAMS).unwrap();
        let mut topics = PacketTopics::default();
        for topic in [
            "/front/lidar_packets",
            "/rear/lidar_packets",
            "/os1_node/lidar_packets",
        ] {
            (topics.ouster_calibrations).insert(topic.into(), metadata.clone());
        }
        let frame_of = |frames: &[&str], topic: &str| {
            let mut stamps = HashMap::from([(topic.to_string(), (OUSTER_FRAME.into(), vec![]))]);
            topics.name_ouster_frames(frames.iter().copied(), &mut stamps);
            stamps[topic].0.clone()
        };
        let two = [
            "front/os_sensor",
            "front/os_lidar",
            "rear/os_sensor",
            "base_link",
        ];
        assert_eq!(frame_of(&two, "/front/lidar_packets"), "front/os_sensor");
        assert_eq!(frame_of(&two, "/rear/lidar_packets"), "rear/os_sensor");
        let suffixed = ["os_sensor_rear", "os_sensor_front"];
        assert_eq!(frame_of(&suffixed, "/rear/lidar_packets"), "os_sensor_rear");
        // One sensor: ouster_ros's own name, the older driver's, or the only one.
        assert_eq!(
            frame_of(&["os_sensor", "os_lidar"], "/front/lidar_packets"),
            "os_sensor"
        );
        assert_eq!(
            frame_of(&["os1_sensor", "os1_lidar"], "/os1_node/lidar_packets"),
            "os1_sensor"
        );
        assert_eq!(
            frame_of(&["top/os_sensor"], "/front/lidar_packets"),
            "top/os_sensor"
        );
        // Nothing in the tree: `os_sensor`, which the posing then finds unposed.
        assert_eq!(
            frame_of(&["base_link"], "/front/lidar_packets"),
            OUSTER_FRAME
        );
    }
}
