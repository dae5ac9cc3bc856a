//! LiDAR packet topics whatever the vendor: Velodyne's `VelodyneScan`, Hesai's
//! `PandarScan`, RoboSense's `RobosenseScan`, nebula's vendor-neutral `NebulaPackets`
//! and ouster_ros's `PacketMsg`, each with its model (read from the packets; an Ouster's from its
//! metadata), its calibration and its scan assembler, behind one face for the log
//! index and the drive's frames.

pub mod hesai;
pub(crate) mod message;
pub mod ouster;
pub mod robosense;
pub(crate) mod scan;
pub mod velodyne;

pub(crate) use message::{PacketField, ScanMessage, packets_message};
pub use scan::{PacketPoint, PacketScan};

use std::path::Path;
use travmap_core::option_files::{TEXT_MAX_BYTES, read_option_text};

use crate::packets::hesai::{
    HesaiAssembler, HesaiCalibration, HesaiModel, PANDAR_SCAN, pandar_scan_message,
};
use crate::packets::ouster::{
    OUSTER_PACKET_MESSAGES, OusterAssembler, OusterMetadata, OusterModel, packet_msg_message,
};
use crate::packets::robosense::{
    ROBOSENSE_SCAN, RobosenseAssembler, RobosenseCalibration, RobosenseModel,
    robosense_scan_message,
};
use crate::packets::velodyne::{
    Decoder, DecoderSettings, ScanAssembler, VELODYNE_SCAN, VelodyneCalibration, VelodyneModel,
    scan_message,
};
use travmap_formats::ros::MessageEncoding;

/// nebula's packet message, of any sensor: `std_msgs/Header header`,
/// `NebulaPacket[] packets` of `builtin_interfaces/Time stamp`, `uint8[] data`.
pub const NEBULA_PACKETS: &str = "nebula_msgs/msg/NebulaPackets";

/// The message types that carry packets.
pub const PACKET_MESSAGES: [&str; 7] = [
    VELODYNE_SCAN,
    PANDAR_SCAN,
    ROBOSENSE_SCAN,
    NEBULA_PACKETS,
    OUSTER_PACKET_MESSAGES[0],
    OUSTER_PACKET_MESSAGES[1],
    OUSTER_PACKET_MESSAGES[2],
];

/// A LiDAR whose packets travmap decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PacketModel {
    Velodyne(VelodyneModel),
    Hesai(HesaiModel),
    Robosense(RobosenseModel),
    Ouster(OusterModel),
}

impl PacketModel {
    /// The model of a packet of a message of type `message_type`. A NebulaPackets
    /// packet is Hesai's if Hesai's header and length fit it (a Pandar 40P begins
    /// `FF EE` as Velodyne's blocks do, but is 1,262 bytes to their 1,206), else
    /// RoboSense's if its identifier is, else Velodyne's. An Ouster's packets do not
    /// tell it: its metadata does.
    pub fn of_packet(message_type: &str, packet: &[u8]) -> Result<Self, String> {
        match message_type {
            name if OUSTER_PACKET_MESSAGES.contains(&name) => {
                Err("an Ouster packet's layout is in the sensor's metadata".into())
            }
            PANDAR_SCAN => HesaiModel::of_packet(packet).map(Self::Hesai),
            ROBOSENSE_SCAN => RobosenseModel::of_packet(packet).map(Self::Robosense),
            NEBULA_PACKETS => HesaiModel::of_packet(packet)
                .map(Self::Hesai)
                .or_else(|hesai| match packet {
                    [0x55, 0xAA, ..] | [0xA5, 0xFF, ..] => {
                        RobosenseModel::of_packet(packet).map(Self::Robosense)
                    }
                    _ => VelodyneModel::of_packet(packet)
                        .map(Self::Velodyne)
                        .map_err(|velodyne| {
                            format!("neither Hesai's ({hesai}) nor Velodyne's ({velodyne})")
                        }),
                }),
            _ => VelodyneModel::of_packet(packet).map(Self::Velodyne),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Velodyne(model) => model.name(),
            Self::Hesai(model) => model.name(),
            Self::Robosense(model) => model.name(),
            Self::Ouster(model) => model.name(),
        }
    }
}

/// Reads a packet message of type `message_type`, recorded at `log_time_ns` (which
/// stamps an Ouster's packet: its message has no stamp), without copying its
/// packets.
pub fn packet_message<'a>(
    message_type: &str,
    data: &'a [u8],
    encoding: MessageEncoding,
    log_time_ns: u64,
) -> Result<ScanMessage<'a>, String> {
    match message_type {
        name if OUSTER_PACKET_MESSAGES.contains(&name) => {
            packet_msg_message(data, encoding, log_time_ns)
        }
        PANDAR_SCAN => pandar_scan_message(data, encoding),
        ROBOSENSE_SCAN => robosense_scan_message(data, encoding),
        NEBULA_PACKETS => packets_message(data, encoding, PacketField::Sequence),
        _ => scan_message(data, encoding),
    }
}

/// A packet model's calibration: the file given (`--lidar-calibration`: the
/// velodyne_pointcloud / nebula YAML, Hesai's angle-correction CSV, RoboSense's angle
/// CSV), else the
/// model's built-in table. An Ouster's is its metadata, which the log index reads
/// with its packets (`packet_topics.rs`).
#[derive(Clone, Debug)]
pub enum PacketCalibration {
    Velodyne(VelodyneCalibration),
    Hesai(HesaiCalibration),
    Robosense(RobosenseCalibration),
    Ouster(Box<OusterMetadata>),
}

impl PacketCalibration {
    pub fn for_model(model: PacketModel, file: Option<&Path>) -> Result<Self, String> {
        match model {
            PacketModel::Ouster(_) => {
                Err("an Ouster's metadata is read with its packets, by the log index".into())
            }
            PacketModel::Velodyne(model) => {
                VelodyneCalibration::for_model(model, file).map(Self::Velodyne)
            }
            // A table of another model is refused here, naming both.
            PacketModel::Hesai(model) => {
                let calibration = match file {
                    None => HesaiCalibration::builtin(model),
                    Some(file) => table_file(file, HesaiCalibration::from_csv)?,
                };
                HesaiAssembler::new(model, &calibration).map_err(|e| named(file, e))?;
                Ok(Self::Hesai(calibration))
            }
            PacketModel::Robosense(model) => {
                let calibration = match file {
                    None => RobosenseCalibration::builtin(model),
                    Some(file) => table_file(file, RobosenseCalibration::from_csv)?,
                };
                RobosenseAssembler::new(model, &calibration).map_err(|e| named(file, e))?;
                Ok(Self::Robosense(calibration))
            }
        }
    }
}

/// An angle table file read by `parse`; its errors name the file.
fn table_file<T>(file: &Path, parse: fn(&str) -> Result<T, String>) -> Result<T, String> {
    let text = read_option_text(file, TEXT_MAX_BYTES).map_err(|e| e.to_string())?;
    parse(&text).map_err(|e| named(Some(file), e))
}

/// `problem`, naming the file it is about, when there is one.
fn named(file: Option<&Path>, problem: String) -> String {
    match file {
        Some(file) => format!("{}: {problem}", file.display()),
        None => problem,
    }
}

/// Packets in, scans out, whichever vendor.
pub enum PacketAssembler {
    Velodyne(ScanAssembler),
    Hesai(Box<HesaiAssembler>),
    Robosense(Box<RobosenseAssembler>),
    Ouster(Box<OusterAssembler>),
}

impl PacketAssembler {
    pub fn new(model: PacketModel, calibration: &PacketCalibration) -> Result<Self, String> {
        Ok(match (model, calibration) {
            (PacketModel::Velodyne(model), PacketCalibration::Velodyne(calibration)) => {
                let decoder = Decoder::new(model, calibration.clone(), DecoderSettings::default())?;
                Self::Velodyne(ScanAssembler::new(decoder))
            }
            (PacketModel::Hesai(model), PacketCalibration::Hesai(calibration)) => {
                Self::Hesai(Box::new(HesaiAssembler::new(model, calibration)?))
            }
            (PacketModel::Robosense(model), PacketCalibration::Robosense(calibration)) => {
                Self::Robosense(Box::new(RobosenseAssembler::new(model, calibration)?))
            }
            (PacketModel::Ouster(model), PacketCalibration::Ouster(metadata))
                if metadata.model == model =>
            {
                Self::Ouster(Box::new(OusterAssembler::new(metadata)))
            }
            _ => {
                return Err(format!(
                    "a calibration of another vendor than the {}'s",
                    model.name()
                ));
            }
        })
    }

    /// The scan gathered at the end of a log that completed none (a capture of part
    /// of one turn), with how much of the turn it covers in words; None where there
    /// is none, and for Velodyne, Hesai and RoboSense packets, whose partial turns
    /// are not read.
    pub fn finish_partial_turn(&mut self) -> Option<(PacketScan, String)> {
        match self {
            Self::Ouster(assembler) => assembler
                .finish()
                .map(|(scan, columns, turn)| (scan, partial_turn_said(columns, turn))),
            Self::Velodyne(_) | Self::Hesai(_) | Self::Robosense(_) => None,
        }
    }

    /// Adds the packets of a message of type `message_type`, recorded at
    /// `log_time_ns`; the scans they complete.
    pub fn push_message(
        &mut self,
        message_type: &str,
        data: &[u8],
        encoding: MessageEncoding,
        log_time_ns: u64,
    ) -> Result<Vec<PacketScan>, String> {
        let message = packet_message(message_type, data, encoding, log_time_ns)?;
        let mut scans = Vec::new();
        for (stamp_ns, packet) in message.packets {
            match self {
                Self::Velodyne(assembler) => scans.extend(assembler.push(packet, stamp_ns)?),
                Self::Hesai(assembler) => scans.extend(assembler.push(packet, stamp_ns)?),
                Self::Robosense(assembler) => scans.extend(assembler.push(packet, stamp_ns)?),
                Self::Ouster(assembler) => scans.extend(assembler.push(packet, stamp_ns)?),
            }
        }
        Ok(scans)
    }
}

/// How much of a turn `columns` of a turn's `per_turn` cover, in words.
pub(crate) fn partial_turn_said(columns: u32, per_turn: u16) -> String {
    format!(
        "{columns} of the turn's {per_turn} columns, {:.0} % of a turn",
        100.0 * f64::from(columns) / f64::from(per_turn)
    )
}
