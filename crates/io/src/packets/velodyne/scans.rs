//! A stream of Velodyne packets cut into scans at a cut angle.

use super::decoder::Decoder;
use super::packet::{BLOCK_BYTES, BLOCKS, CENTIDEGREES, VelodyneModel};
use crate::packets::scan::{PacketPoint, PacketScan};

/// Where a stream of packets is cut into scans: nebula's rule, on the azimuths of
/// each packet's first and last block only (the index pass needs no points).
#[derive(Clone, Debug, Default)]
pub struct ScanCutter {
    phase_centideg: u32,
    packets_in_scan: usize,
    previous_first: u32,
    completed: bool,
}

impl ScanCutter {
    pub fn new(cut_angle_deg: f64) -> Self {
        Self {
            phase_centideg: ((cut_angle_deg * 100.0).round() as i64).rem_euclid(CENTIDEGREES as i64)
                as u32,
            ..Default::default()
        }
    }

    /// Whether `packet` completes the scan it belongs to.
    pub fn completes(&mut self, packet: &[u8]) -> bool {
        if self.completed {
            self.packets_in_scan = 0;
        }
        self.packets_in_scan += 1;
        let phased = |at: usize| {
            let azimuth = u32::from(u16::from_le_bytes([packet[at], packet[at + 1]]));
            (CENTIDEGREES + azimuth % CENTIDEGREES - self.phase_centideg) % CENTIDEGREES
        };
        let (first, last) = (phased(2), phased((BLOCKS - 1) * BLOCK_BYTES + 2));
        self.completed = self.packets_in_scan > 1 && (last < first || first < self.previous_first);
        self.previous_first = first;
        self.completed
    }
}

/// Packets in, scans out: [`ScanCutter`]'s cuts, the points past the cut carried
/// into the next scan.
pub struct ScanAssembler {
    decoder: Decoder,
    cutter: ScanCutter,
    points: Vec<PacketPoint>,
    stamp_ns: Option<u64>,
}

impl ScanAssembler {
    pub fn new(decoder: Decoder) -> Self {
        let cutter = ScanCutter::new(decoder.settings().cut_angle_deg);
        Self {
            decoder,
            cutter,
            points: Vec::new(),
            stamp_ns: None,
        }
    }

    /// Adds a packet; the scan it completes, if it does.
    pub fn push(&mut self, packet: &[u8], stamp_ns: u64) -> Result<Option<PacketScan>, String> {
        // The cut reads the packet's azimuths: its length is checked first.
        VelodyneModel::of_packet(packet)?;
        let completes = self.cutter.completes(packet);
        self.stamp_ns.get_or_insert(stamp_ns);
        self.decoder.decode(packet, stamp_ns, &mut self.points)?;
        if !completes {
            return Ok(None);
        }
        // Trailing points within 90 degrees past the cut begin the next scan.
        let phase = self.cutter.phase_centideg;
        let past_cut = |p: &PacketPoint| {
            (CENTIDEGREES + u32::from(p.azimuth_centideg) - phase) % CENTIDEGREES < 9_000
        };
        let keep = self.points.len() - self.points.iter().rev().take_while(|p| past_cut(p)).count();
        let carried = self.points.split_off(keep);
        let scan = PacketScan {
            stamp_ns: self.stamp_ns.take().unwrap_or(stamp_ns),
            points: std::mem::replace(&mut self.points, carried),
        };
        // The next scan begins with this packet, whether or not it carried points
        // (the index pass stamps scans by the cut alone).
        self.stamp_ns = Some(stamp_ns);
        Ok(Some(scan))
    }
}
