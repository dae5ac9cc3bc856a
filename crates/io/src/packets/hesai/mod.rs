//! Hesai Pandar XT32, XT16, XT32M, 40P, 64, QT64 and QT128 data packets
//! (`pandar_msgs/msg/PandarScan`), decoded into points and cut into scans as
//! tier4/nebula (Autoware's driver) does, so that a log gives the points Autoware
//! gives (`tests/hesai.rs` checks nebula's own ground truth point for point).
//!
//! A packet: a header (XT and QT64: 12 bytes, `EE FF`, the protocol, the laser and
//! block counts, the distance unit in mm; the 64: 8 bytes with the counts and the
//! unit; the 40P: none, its blocks start with `FF EE` and its unit is 4 mm), blocks
//! of {azimuth u16 in 0.01 degree, one {distance u16, reflectivity u8 (XT, QT64: and
//! a reserved byte)} per laser}, and a tail holding the return mode, the UTC date and
//! the microseconds of the packet. Dual-return modes put the returns of one firing in
//! consecutive blocks. `Layout` holds each model's sizes and offsets.
//!
//! Points are in Hesai's frame as nebula writes it: +y at azimuth 0 (forward), +x at
//! 90 degrees (clockwise seen from above), z up. A channel's azimuth is its block's
//! plus the calibration's offset; its elevation is the calibration's.
//!
//! Scans are cut at azimuth 0 channel by channel, as nebula's cutter does: each
//! laser moves to the next scan at the first firing whose corrected azimuth passes
//! the cut, and a scan is handed on once its last laser has moved on. A scan is
//! stamped with its first firing; every point keeps its own firing time. Times are
//! the sensor's (the packet's date and microseconds) moved to the log's clock by
//! the packet's recorded stamp where the scan began: a sensor without time
//! synchronisation still finds its poses, and the firings keep their spacing.

mod assembler;
mod calibration;
mod model;

pub use assembler::HesaiAssembler;
pub use calibration::HesaiCalibration;
pub use model::HesaiModel;

use super::message::{PacketField, ScanMessage, packets_message};
use travmap_formats::ros::MessageEncoding;

/// The message type that carries Hesai packets.
pub const PANDAR_SCAN: &str = "pandar_msgs/msg/PandarScan";
/// Bytes of `PandarPacket::data`; the packet is its first `size`.
const PANDAR_PACKET_DATA_BYTES: usize = 1500;

/// Reads a PandarScan (`Header header`, `PandarPacket[] packets` of `time stamp`,
/// `uint8[1500] data`, `uint32 size`) without copying its packets.
pub fn pandar_scan_message(
    data: &[u8],
    encoding: MessageEncoding,
) -> Result<ScanMessage<'_>, String> {
    packets_message(
        data,
        encoding,
        PacketField::FixedSized(PANDAR_PACKET_DATA_BYTES),
    )
}

#[cfg(test)]
mod nebula_tests;
