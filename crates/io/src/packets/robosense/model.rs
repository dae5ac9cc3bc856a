//! The RoboSense models travmap decodes: how a packet is told, its layout, when its
//! lasers fire.

/// Both kinds of packet are this long.
pub(super) const PACKET_BYTES: usize = 1248;
const MSOP_ID: [u8; 4] = [0x55, 0xAA, 0x05, 0x5A];
const DIFOP_ID: [u8; 8] = [0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55];
/// Every block begins so.
pub(super) const BLOCK_ID: [u8; 2] = [0xFF, 0xEE];
pub(super) const HEADER_BYTES: usize = 42;
pub(super) const BLOCKS: usize = 12;
pub(super) const CHANNELS: usize = 32;
pub(super) const BLOCK_BYTES: usize = 4 + 3 * CHANNELS;
/// The sensor's UTC seconds (6 bytes) and microseconds (4) in an MSOP header.
pub(super) const TIME_AT: usize = 20;
/// The LiDAR type byte of an MSOP header: a Helios's.
const LIDAR_TYPE_AT: usize = 30;
const HELIOS_TYPE: u8 = 0x06;

/// One distance step, metres, and the range nebula's driver keeps.
pub(super) const DISTANCE_UNIT_M: f32 = 0.0025;
pub(super) const RANGE_M: (f32, f32) = (0.2, 200.0);
/// The receiving lens's distance from the axis, metres.
pub(super) const LENS_OFFSET_M: f32 = 0.03498;
/// One firing of the 16 lasers, microseconds, and when each channel of a block
/// fires (the Helios 16P's table, as rs_driver has it).
pub(super) const FIRING_US: f32 = 55.56;
pub(super) const CHANNEL_FIRING_US: [f32; CHANNELS] = [
    0.00, 3.15, 6.30, 9.45, 13.26, 17.08, 20.56, 23.71, 26.53, 27.77, 31.49, 32.73, 36.46, 38.94,
    41.42, 43.91, 55.56, 58.70, 61.85, 65.00, 68.82, 72.64, 76.12, 79.27, 82.08, 83.32, 87.05,
    88.29, 92.01, 94.50, 96.98, 99.46,
];

/// RoboSense models with a decoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobosenseModel {
    Helios16p,
}

impl RobosenseModel {
    /// The model of a packet, data (MSOP) or device information (DIFOP), from its
    /// identifier and length; an MSOP's first block and LiDAR type too (RoboSense's
    /// 128-beam Ruby shares the identifier and the length).
    pub fn of_packet(packet: &[u8]) -> Result<Self, String> {
        let supported = "travmap decodes the RoboSense Helios 16P (1,248-byte packets: data \
                         beginning 55 AA 05 5A, device information A5 FF 00 5A 11 11 55 55)";
        let difop = packet.starts_with(&DIFOP_ID);
        if !packet.starts_with(&MSOP_ID) && !difop {
            let start: Vec<String> = (packet.iter().take(4))
                .map(|b| format!("{b:02X}"))
                .collect();
            return Err(format!(
                "a packet beginning {}: {supported}",
                start.join(" ")
            ));
        }
        if packet.len() != PACKET_BYTES {
            return Err(format!(
                "a RoboSense packet of {} bytes: {supported}",
                packet.len()
            ));
        }
        if difop {
            return Ok(Self::Helios16p);
        }
        let lidar_type = packet[LIDAR_TYPE_AT];
        if packet[HEADER_BYTES..HEADER_BYTES + 2] != BLOCK_ID || lidar_type != HELIOS_TYPE {
            return Err(format!(
                "a RoboSense data packet of LiDAR type 0x{lidar_type:02X} whose blocks do not begin FF EE \
                 where a Helios's do: {supported}"
            ));
        }
        Ok(Self::Helios16p)
    }

    /// Whether a packet of this model is device information rather than points.
    pub fn is_difop(packet: &[u8]) -> bool {
        packet.starts_with(&DIFOP_ID)
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Helios16p => "RoboSense Helios 16P",
        }
    }

    pub fn lasers(self) -> usize {
        match self {
            Self::Helios16p => 16,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_helios_is_told_from_its_identifier_length_blocks_and_type() {
        let mut msop = vec![0u8; PACKET_BYTES];
        msop[..4].copy_from_slice(&MSOP_ID);
        msop[LIDAR_TYPE_AT] = HELIOS_TYPE;
        msop[HEADER_BYTES..HEADER_BYTES + 2].copy_from_slice(&BLOCK_ID);
        assert_eq!(
            RobosenseModel::of_packet(&msop),
            Ok(RobosenseModel::Helios16p)
        );
        let mut difop = vec![0u8; PACKET_BYTES];
        difop[..8].copy_from_slice(&DIFOP_ID);
        assert_eq!(
            RobosenseModel::of_packet(&difop),
            Ok(RobosenseModel::Helios16p)
        );
        assert!(RobosenseModel::is_difop(&difop) && !RobosenseModel::is_difop(&msop));
        // A Ruby's data packet: the same identifier and length, its blocks elsewhere.
        let mut ruby = msop.clone();
        ruby[HEADER_BYTES..HEADER_BYTES + 2].copy_from_slice(&[0xFE, 0x01]);
        let error = RobosenseModel::of_packet(&ruby).unwrap_err();
        assert!(error.contains("do not begin FF EE"), "{error}");
        let error = RobosenseModel::of_packet(&msop[..1206]).unwrap_err();
        assert!(error.contains("of 1206 bytes"), "{error}");
        let error = RobosenseModel::of_packet(&[0xFF, 0xEE, 0, 0]).unwrap_err();
        assert!(error.contains("beginning FF EE 00 00"), "{error}");
    }
}
