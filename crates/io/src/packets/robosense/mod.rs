//! RoboSense Helios 16P packets (`robosense_msgs/msg/RobosenseScan`, or nebula's
//! `NebulaPackets`, or a capture's UDP), decoded into points and cut into scans as
//! tier4/nebula decodes them (its RoboSense decoders are RoboSense's rs_driver), so
//! that a log gives the points Autoware gives (`tests/robosense.rs` checks nebula's
//! own ground truth point for point).
//!
//! Two kinds of packet, both 1,248 bytes, big-endian:
//! - MSOP (`55 AA 05 5A`): a 42-byte header (the sensor's UTC seconds, 6 bytes, and
//!   microseconds, 4, at byte 20; the LiDAR type at 30), then 12 blocks of {`FF EE`,
//!   azimuth u16 in 0.01 degree, 32 channels of {distance u16 in 2.5 mm,
//!   intensity u8}}. A block's channels are the 16 lasers fired twice (single
//!   return) or one firing's two returns (dual).
//! - DIFOP (`A5 FF 00 5A 11 11 55 55`), about once a second: the motor's speed, the
//!   field of view, the return mode and the unit's own angle table.
//!
//! Points are in the sensor's frame as nebula writes it: x forward (azimuth 0),
//! azimuth clockwise seen from above, y left, z up; the receiving lens sits 34.98 mm
//! from the axis. A channel's azimuth is its block's, plus the share of the way to the
//! next block its firing time says, plus the calibration's horizontal offset.
//!
//! Scans are cut at azimuth 0 on the blocks' azimuths, as nebula's cutter does; a
//! scan is stamped with its first block, and every point keeps its own firing time.
//! Times are the sensor's moved to the log's clock by the packet's recorded stamp
//! where the scan began, as a Hesai's are.
//!
//! The Helios 32 sends packets of the same form and LiDAR type; travmap reads them as
//! a 16P's and says so (its table has 16 rows: a 32-row table given with
//! `--lidar-calibration` is refused).

mod assembler;
mod calibration;
mod model;

pub use assembler::RobosenseAssembler;
pub use calibration::RobosenseCalibration;
pub use model::RobosenseModel;

use super::message::{PacketField, ScanMessage, packets_message};
use travmap_formats::ros::MessageEncoding;

/// The message type that carries RoboSense packets.
pub const ROBOSENSE_SCAN: &str = "robosense_msgs/msg/RobosenseScan";
/// Bytes of `RobosensePacket::data`; the packet is its first `size`.
const ROBOSENSE_PACKET_DATA_BYTES: usize = 1500;

/// Reads a RobosenseScan (`Header header`, `RobosensePacket[] packets` of
/// `time stamp`, `uint8 is_difop`, `uint8[1500] data`, `uint32 size`) without
/// copying its packets. A packet's kind is read from its first bytes, as nebula
/// reads it, not from `is_difop`.
pub fn robosense_scan_message(
    data: &[u8],
    encoding: MessageEncoding,
) -> Result<ScanMessage<'_>, String> {
    packets_message(
        data,
        encoding,
        PacketField::FlagThenFixedSized(ROBOSENSE_PACKET_DATA_BYTES),
    )
}

#[cfg(test)]
mod nebula_tests;
