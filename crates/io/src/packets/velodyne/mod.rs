//! Velodyne data packets (`velodyne_msgs/msg/VelodyneScan`, ROS 1 and ROS 2): the
//! 1206-byte UDP packets of the VLP-16 (and Puck Hi-Res), VLP-32C, HDL-32E and VLS-128,
//! decoded into points and cut into scans at a cut angle.
//!
//! A packet holds 12 blocks of 100 bytes (flag u16, azimuth u16 in 0.01 degree, 32 x
//! {distance u16, reflectivity u8}), a 4-byte timestamp, the return mode (byte 1204:
//! 0x37 strongest, 0x38 last, 0x39 dual) and the product id (byte 1205), from which
//! the model is detected. Points come out in the ROS sensor frame (x forward, y left,
//! z up); the sensor's azimuth runs clockwise from +x.
//!
//! Decoding follows tier4/nebula, Autoware's driver, so that a log replayed through
//! either gives the same points (`tests/velodyne.rs` checks nebula's own ground
//! truth). Two of nebula's choices differ from Velodyne's manuals and are kept for
//! that parity: the last block of a packet is not interpolated in azimuth (single
//! return), and a VLP-32C channel is interpolated by its index, not by its firing
//! pair; each moves a point by at most 0.26 degree. The FOV test of the 32-laser
//! models is on the block's azimuth, as nebula's.
//!
//! Scans: a scan is complete with the packet whose azimuths cross the cut angle (or
//! that starts before the previous one did: the sensor wrapped); the points of that
//! packet past the cut begin the next scan (nebula's overflow). A scan is stamped
//! with the stamp of the packet that cut the scan before it (the first scan: its
//! first packet's), and each point keeps its own firing time.

mod calibration;
mod decoder;
mod message;
mod packet;
mod scans;

pub use calibration::VelodyneCalibration;
pub use decoder::{Decoder, DecoderSettings};
pub use message::{VELODYNE_SCAN, scan_message};
pub use packet::VelodyneModel;
pub use scans::{ScanAssembler, ScanCutter};

#[cfg(test)]
mod tests {
    use super::packet::{BLOCK_BYTES, BLOCKS, CENTIDEGREES, PRODUCT_AT, RETURN_MODE_AT};
    use super::*;

    /// A single-return packet of `model` whose block `b` points at azimuth
    /// `first + b * step` and whose every return is `distance_raw` at intensity 100.
    fn packet(product: u8, first: u16, step: u16, distance_raw: u16) -> Vec<u8> {
        let mut p = vec![0u8; packet::PACKET_BYTES];
        for b in 0..BLOCKS {
            let at = b * BLOCK_BYTES;
            p[at..at + 2].copy_from_slice(&0xEEFFu16.to_le_bytes());
            let azimuth = (first as u32 + b as u32 * step as u32) % CENTIDEGREES;
            p[at + 2..at + 4].copy_from_slice(&(azimuth as u16).to_le_bytes());
            for j in 0..32 {
                let k = at + 4 + 3 * j;
                p[k..k + 2].copy_from_slice(&distance_raw.to_le_bytes());
                p[k + 2] = 100;
            }
        }
        p[RETURN_MODE_AT] = 0x37;
        p[PRODUCT_AT] = product;
        p
    }

    #[test]
    fn the_model_comes_from_the_product_id() {
        assert_eq!(
            VelodyneModel::of_packet(&packet(0x28, 0, 20, 1)),
            Ok(VelodyneModel::Vlp32c)
        );
        assert_eq!(
            VelodyneModel::of_packet(&packet(0x24, 0, 20, 1)),
            Ok(VelodyneModel::Vlp16)
        );
        let err = VelodyneModel::of_packet(&packet(0x99, 0, 20, 1)).unwrap_err();
        assert!(err.contains("0x99"), "{err}");
        assert!(
            VelodyneModel::of_packet(&[0; 100])
                .unwrap_err()
                .contains("1206 bytes")
        );
    }

    #[test]
    fn a_vlp16_return_lands_at_its_range_elevation_and_azimuth() {
        let calibration = VelodyneCalibration::builtin(VelodyneModel::Vlp16).unwrap();
        let decoder = Decoder::new(
            VelodyneModel::Vlp16,
            calibration,
            DecoderSettings::default(),
        )
        .unwrap();
        // 5000 x 2 mm = 10 m; block 0 points at 90 degrees clockwise: -y.
        let mut points = Vec::new();
        decoder
            .decode(&packet(0x22, 9_000, 40, 5_000), 1_000, &mut points)
            .unwrap();
        assert_eq!(points.len(), BLOCKS * 32);
        let first = points[0];
        let elevation = (-15.0f32).to_radians();
        assert!((first.xyz_m[0]).abs() < 1e-3, "{first:?}");
        assert!(
            (first.xyz_m[1] + 10.0 * elevation.cos()).abs() < 1e-4,
            "{first:?}"
        );
        assert!(
            (first.xyz_m[2] - 10.0 * elevation.sin()).abs() < 1e-4,
            "{first:?}"
        );
        assert_eq!(first.ring, 0, "the lowest beam is ring 0");
        assert_eq!(first.time_ns, 1_000);
        // Every point is 10 m from the sensor.
        for p in &points {
            let r = p.xyz_m.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((r - 10.0).abs() < 1e-3, "{p:?}");
        }
        // The second firing of a block is half a block step further on.
        assert_eq!(points[16].azimuth_centideg, 9_020);
    }

    #[test]
    fn the_builtin_vlp32c_table_ranks_its_rings_by_elevation() {
        let calibration = VelodyneCalibration::builtin(VelodyneModel::Vlp32c).unwrap();
        assert_eq!(calibration.lasers[0].ring, 0, "-25 degrees is the lowest");
        assert_eq!(calibration.lasers[29].ring, 31, "+15 degrees the highest");
        assert!((calibration.lasers[0].rot_centideg + 140.0).abs() < 1e-9);
        assert!(VelodyneCalibration::builtin(VelodyneModel::Vls128).is_none());
        assert!(
            Decoder::new(
                VelodyneModel::Vlp16,
                calibration,
                DecoderSettings::default()
            )
            .is_err()
        );
    }

    #[test]
    fn scans_are_cut_where_the_azimuth_crosses_the_cut_angle() {
        let calibration = VelodyneCalibration::builtin(VelodyneModel::Vlp32c).unwrap();
        let decoder = Decoder::new(
            VelodyneModel::Vlp32c,
            calibration,
            DecoderSettings::default(),
        )
        .unwrap();
        let mut assembler = ScanAssembler::new(decoder);
        let mut scans = Vec::new();
        // Packets of 12 blocks x 0.2 degrees, 2.4 degrees each: 150 per turn, 2 turns.
        for i in 0..320u32 {
            let first = (i * 240 % CENTIDEGREES) as u16;
            let stamp = 1_000_000 * i as u64;
            if let Some(scan) = assembler
                .push(&packet(0x28, first, 20, 2_500), stamp)
                .unwrap()
            {
                scans.push(scan);
            }
        }
        assert_eq!(scans.len(), 2);
        assert_eq!(scans[0].stamp_ns, 0);
        // The second scan starts with the points the crossing packet carried.
        assert_eq!(scans[1].stamp_ns, 150_000_000);
        let turn = 150 * BLOCKS * 32;
        for scan in &scans[1..] {
            assert!(
                scan.points.len().abs_diff(turn) <= 2 * BLOCKS * 32,
                "{}",
                scan.points.len()
            );
        }
    }
}

#[cfg(test)]
mod nebula_tests;
