//! RoboSense packets decoded into points and cut into scans as nebula does.

use std::sync::OnceLock;

use super::calibration::RobosenseCalibration;
use super::model::{
    BLOCK_BYTES, BLOCK_ID, BLOCKS, CHANNEL_FIRING_US, DISTANCE_UNIT_M, FIRING_US, HEADER_BYTES,
    LENS_OFFSET_M, RANGE_M, RobosenseModel, TIME_AT,
};
use crate::packets::scan::{PacketPoint, PacketScan, to_log_clock_ns};

const ROUND_CENTIDEG: i32 = 36_000;
/// Blocks further apart than this span the field of view's blind part.
const BLIND_GAP_CENTIDEG: i32 = 100;
/// Where the DIFOP holds what the decoder reads.
const DIFOP_RPM_AT: usize = 8;
const DIFOP_FOV_AT: usize = 32;
const DIFOP_RETURN_MODE_AT: usize = 300;
const DIFOP_VERTICAL_AT: usize = 468;
const DIFOP_HORIZONTAL_AT: usize = 564;
/// The DIFOP's return mode byte of dual return; the others are single returns.
const DUAL_RETURN: u8 = 0x00;

/// sin and cos of whole 0.01 degrees from -90 to 450 degrees, in f32 from f64, as
/// rs_driver's table holds them (an angle outside is taken as 0).
const TABLE_FROM_CENTIDEG: i32 = -9_000;
const TABLE_TO_CENTIDEG: i32 = 45_000;

fn sin_cos(centideg: i32) -> (f32, f32) {
    static TABLE: OnceLock<Vec<(f32, f32)>> = OnceLock::new();
    let table = TABLE.get_or_init(|| {
        (TABLE_FROM_CENTIDEG..TABLE_TO_CENTIDEG)
            .map(|c| {
                let (sin, cos) = (f64::from(c) * 0.01 * std::f64::consts::PI / 180.0).sin_cos();
                (sin as f32, cos as f32)
            })
            .collect()
    });
    let angle = match (TABLE_FROM_CENTIDEG..TABLE_TO_CENTIDEG).contains(&centideg) {
        true => centideg,
        false => 0,
    };
    table[(angle - TABLE_FROM_CENTIDEG) as usize]
}

/// Packets in, scans out, for one RoboSense sensor.
pub struct RobosenseAssembler {
    model: RobosenseModel,
    calibration: RobosenseCalibration,
    vertical_sin_cos: Vec<(f32, f32)>,
    rings: Vec<u16>,
    /// What the DIFOP says, and until one is read what nebula assumes: single
    /// return, 600 rpm, the whole round seen.
    dual_return: bool,
    rounds_per_s: u16,
    blind_s: f64,
    /// The last block's azimuth (unwrapped below the cut), for the cut.
    previous_azimuth: i32,
    /// The scan being filled, in the sensor's clock, and what moves it to the log's.
    scan: Option<PacketScan>,
    to_log_clock_ns: i64,
    /// False: scans are cut and stamped but hold no points (the log index's pass).
    decode_points: bool,
}

impl RobosenseAssembler {
    pub fn new(model: RobosenseModel, calibration: &RobosenseCalibration) -> Result<Self, String> {
        let lasers = calibration.vertical_centideg.len();
        if lasers != model.lasers() {
            return Err(format!(
                "an angle table of {lasers} lasers for the {} ({} lasers){}",
                model.name(),
                model.lasers(),
                match lasers {
                    32 => ": a Helios 32's? travmap decodes the Helios 16P",
                    _ => "",
                }
            ));
        }
        let mut assembler = Self {
            model,
            calibration: calibration.clone(),
            vertical_sin_cos: Vec::new(),
            rings: Vec::new(),
            dual_return: false,
            rounds_per_s: 10,
            blind_s: 0.0,
            previous_azimuth: 0,
            scan: None,
            to_log_clock_ns: 0,
            decode_points: true,
        };
        assembler.calibrate(calibration.clone());
        Ok(assembler)
    }

    /// This assembler cutting and stamping scans without decoding their points:
    /// the same scans, empty, for a pass that wants only their stamps.
    pub fn stamps_only(self) -> Self {
        Self {
            decode_points: false,
            ..self
        }
    }

    pub fn model(&self) -> RobosenseModel {
        self.model
    }

    fn calibrate(&mut self, calibration: RobosenseCalibration) {
        self.vertical_sin_cos = (calibration.vertical_centideg.iter())
            .map(|&v| sin_cos(v))
            .collect();
        self.rings = calibration.rings();
        self.calibration = calibration;
    }

    /// The azimuth a block's firing sweeps at the motor's speed.
    fn block_step(&self) -> i32 {
        let block_s = f64::from(FIRING_US / 1_000_000.0);
        (f64::from(ROUND_CENTIDEG) * f64::from(self.rounds_per_s) * block_s).round() as i32
    }

    /// Reads what a DIFOP says of the packets that follow: the return mode, the
    /// motor's speed, the field of view, and the unit's angle table (unless one was
    /// given as a file).
    fn read_difop(&mut self, packet: &[u8]) {
        let u16_at = |at: usize| u16::from_be_bytes([packet[at], packet[at + 1]]);
        self.dual_return = packet[DIFOP_RETURN_MODE_AT] == DUAL_RETURN;
        // nebula's rule: whole rounds a second, 10 when the motor reports none.
        self.rounds_per_s = match u16_at(DIFOP_RPM_AT) / 60 {
            0 => 10,
            rounds => rounds,
        };
        let (start, end) = (
            i32::from(u16_at(DIFOP_FOV_AT)),
            i32::from(u16_at(DIFOP_FOV_AT + 2)),
        );
        let seen = if start < end {
            end - start
        } else {
            end + ROUND_CENTIDEG - start
        };
        let blind = (ROUND_CENTIDEG - seen).clamp(0, ROUND_CENTIDEG);
        self.blind_s =
            f64::from(blind) / (f64::from(ROUND_CENTIDEG) * f64::from(self.rounds_per_s));
        if self.calibration.generic
            && let Some(own) = RobosenseCalibration::from_difop(
                &packet[DIFOP_VERTICAL_AT..DIFOP_HORIZONTAL_AT],
                &packet[DIFOP_HORIZONTAL_AT..DIFOP_HORIZONTAL_AT + 96],
                self.model.lasers(),
            )
        {
            self.calibrate(own);
        }
    }

    /// Each block's azimuth step to the next firing and time after the packet's, as
    /// nebula's block iterators give them: the step to the next block (its pair's,
    /// in dual return, whose two blocks are one firing); across the blind part of
    /// the field of view, and after the last block, the motor's nominal step.
    fn block_steps(&self, azimuths: &[i32; BLOCKS]) -> [(i32, f64); BLOCKS] {
        let stride = if self.dual_return { 2 } else { 1 };
        let block_s = f64::from(FIRING_US / 1_000_000.0);
        let nominal = self.block_step();
        let mut steps = [(nominal, 0.0); BLOCKS];
        let mut offset_s = 0.0;
        for first in (0..BLOCKS).step_by(stride) {
            let next = first + stride;
            let mut step = (nominal, block_s);
            if next < BLOCKS {
                let mut azimuth_step = azimuths[next] - azimuths[first];
                if azimuth_step < 0 {
                    azimuth_step += ROUND_CENTIDEG;
                }
                step = match azimuth_step > BLIND_GAP_CENTIDEG {
                    true => (nominal, self.blind_s),
                    false => (azimuth_step, block_s),
                };
            }
            steps[first..next.min(BLOCKS)].fill((step.0, offset_s));
            offset_s += step.1;
        }
        steps
    }

    /// Whether a block at `azimuth` begins a new scan: the first to reach the cut
    /// (0) after one before it, as nebula's angle cutter decides.
    fn cuts(&mut self, azimuth: i32) -> bool {
        if azimuth < self.previous_azimuth {
            self.previous_azimuth -= ROUND_CENTIDEG;
        }
        let cuts = self.previous_azimuth < 0 && 0 <= azimuth;
        self.previous_azimuth = azimuth;
        cuts
    }

    /// Adds a packet recorded at `stamp_ns` (0: unknown, the sensor's clock is the
    /// log's); the scan it completes, if it does.
    pub fn push(&mut self, packet: &[u8], stamp_ns: u64) -> Result<Option<PacketScan>, String> {
        let model = RobosenseModel::of_packet(packet)?;
        if model != self.model {
            return Err(format!(
                "a {} packet on a topic of {} packets",
                model.name(),
                self.model.name()
            ));
        }
        if RobosenseModel::is_difop(packet) {
            self.read_difop(packet);
            return Ok(None);
        }
        let time = &packet[TIME_AT..TIME_AT + 10];
        let seconds = time[..6].iter().fold(0u64, |s, &b| (s << 8) | u64::from(b));
        let micros = u64::from(u32::from_be_bytes([time[6], time[7], time[8], time[9]]));
        let packet_ns = seconds
            .saturating_mul(1_000_000_000)
            .saturating_add(micros * 1_000);
        let to_log_clock_ns = to_log_clock_ns(stamp_ns, packet_ns);
        let block = |b: usize| &packet[HEADER_BYTES + b * BLOCK_BYTES..][..BLOCK_BYTES];
        if let Some(b) = (0..BLOCKS).find(|&b| block(b)[..2] != BLOCK_ID) {
            return Err(format!(
                "block {b} of a {} packet does not begin FF EE: the packet is damaged",
                self.model.name()
            ));
        }
        let azimuths: [i32; BLOCKS] =
            std::array::from_fn(|b| i32::from(u16::from_be_bytes([block(b)[2], block(b)[3]])));
        let steps = self.block_steps(&azimuths);
        let lasers = self.model.lasers();
        let mut completed = None;
        for (b, &azimuth) in azimuths.iter().enumerate() {
            let (step_centideg, offset_s) = steps[b];
            let block_ns = packet_ns.saturating_add((offset_s * 1e9).round() as u64);
            if self.cuts(azimuth) || self.scan.is_none() {
                let next = PacketScan {
                    stamp_ns: block_ns,
                    points: Vec::new(),
                };
                let shift = std::mem::replace(&mut self.to_log_clock_ns, to_log_clock_ns);
                if let Some(scan) = self.scan.replace(next) {
                    completed = Some(scan.shifted(shift));
                }
            }
            if !self.decode_points {
                continue;
            }
            let points = &mut self.scan.as_mut().expect("begun above").points;
            for (channel, &fired_us) in CHANNEL_FIRING_US.iter().enumerate() {
                let unit = &block(b)[4 + 3 * channel..][..3];
                let distance = f32::from(u16::from_be_bytes([unit[0], unit[1]])) * DISTANCE_UNIT_M;
                if !(RANGE_M.0..=RANGE_M.1).contains(&distance) {
                    continue;
                }
                let laser = channel % lasers;
                // A dual-return block is one firing; a single-return block two.
                let firing_us = match self.dual_return {
                    true => CHANNEL_FIRING_US[laser],
                    false => fired_us,
                };
                let share = match self.dual_return {
                    true => firing_us / FIRING_US,
                    false => firing_us / (FIRING_US * 2.0),
                };
                let horizontal = azimuth + (step_centideg as f32 * share) as i32;
                let corrected = horizontal + self.calibration.horizontal_centideg[laser];
                let (sin_v, cos_v) = self.vertical_sin_cos[laser];
                let (sin_c, cos_c) = sin_cos(corrected);
                let (sin_h, cos_h) = sin_cos(horizontal);
                points.push(PacketPoint {
                    xyz_m: [
                        distance * cos_v * cos_c + LENS_OFFSET_M * cos_h,
                        -distance * cos_v * sin_c - LENS_OFFSET_M * sin_h,
                        distance * sin_v,
                    ],
                    intensity: unit[2],
                    ring: self.rings[laser],
                    azimuth_centideg: corrected.rem_euclid(ROUND_CENTIDEG) as u16,
                    time_ns: block_ns.saturating_add((f64::from(firing_us) * 1e3).round() as u64),
                });
            }
        }
        Ok(completed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An MSOP packet at `seconds` whose blocks have these azimuths and each one
    /// return: `(block, channel, distance units, intensity)`.
    fn msop(seconds: u64, azimuths: [u16; BLOCKS], returns: &[(usize, usize, u16, u8)]) -> Vec<u8> {
        let mut packet = vec![0u8; 1248];
        packet[..4].copy_from_slice(&[0x55, 0xAA, 0x05, 0x5A]);
        packet[TIME_AT..TIME_AT + 6].copy_from_slice(&seconds.to_be_bytes()[2..]);
        packet[30] = 0x06;
        for (b, azimuth) in azimuths.iter().enumerate() {
            let at = HEADER_BYTES + b * BLOCK_BYTES;
            packet[at..at + 2].copy_from_slice(&BLOCK_ID);
            packet[at + 2..at + 4].copy_from_slice(&azimuth.to_be_bytes());
        }
        for &(b, channel, distance, intensity) in returns {
            let at = HEADER_BYTES + b * BLOCK_BYTES + 4 + 3 * channel;
            packet[at..at + 2].copy_from_slice(&distance.to_be_bytes());
            packet[at + 2] = intensity;
        }
        packet
    }

    /// A DIFOP of this return mode and this unit's elevation for laser 3.
    fn difop(return_mode: u8, laser_3_centideg: u16) -> Vec<u8> {
        let mut packet = vec![0u8; 1248];
        packet[..8].copy_from_slice(&[0xA5, 0xFF, 0x00, 0x5A, 0x11, 0x11, 0x55, 0x55]);
        packet[DIFOP_RPM_AT..DIFOP_RPM_AT + 2].copy_from_slice(&600u16.to_be_bytes());
        packet[DIFOP_FOV_AT + 2..DIFOP_FOV_AT + 4].copy_from_slice(&36_000u16.to_be_bytes());
        packet[DIFOP_RETURN_MODE_AT] = return_mode;
        let generic = RobosenseCalibration::builtin(RobosenseModel::Helios16p);
        for laser in 0..16 {
            let mut vertical = generic.vertical_centideg[laser];
            if laser == 3 {
                vertical = i32::from(laser_3_centideg);
            }
            let horizontal = generic.horizontal_centideg[laser];
            for (table, value) in [
                (DIFOP_VERTICAL_AT, vertical),
                (DIFOP_HORIZONTAL_AT, horizontal),
            ] {
                let at = table + 3 * laser;
                packet[at] = u8::from(value < 0);
                packet[at + 1..at + 3]
                    .copy_from_slice(&(value.unsigned_abs() as u16).to_be_bytes());
            }
        }
        packet
    }

    fn steady(from: u16) -> [u16; BLOCKS] {
        std::array::from_fn(|b| (from + 20 * b as u16) % 36_000)
    }

    fn assembler(generic: bool) -> RobosenseAssembler {
        let model = RobosenseModel::Helios16p;
        let calibration = RobosenseCalibration {
            generic,
            ..RobosenseCalibration::builtin(model)
        };
        RobosenseAssembler::new(model, &calibration).unwrap()
    }

    /// Pushes `packets` then one that crosses the cut; the scan completed.
    fn scan_of(assembler: &mut RobosenseAssembler, packets: &[Vec<u8>]) -> PacketScan {
        for packet in packets {
            assert!(assembler.push(packet, 0).unwrap().is_none());
        }
        let crossing = msop(100, steady(35_900), &[]);
        assembler.push(&crossing, 0).unwrap().expect("the cut at 0")
    }

    #[test]
    fn a_return_lands_where_its_laser_and_firing_point() {
        // Laser 9: elevation 0, horizontal offset +3.55 degrees; channel 9 fires
        // 27.77 us into a block of two firings, so a quarter of the way to the next
        // block (20 centidegrees on): 4 centidegrees on, truncated as nebula does.
        let packet = msop(100, steady(9_000), &[(0, 9, 4_000, 77)]);
        let scan = scan_of(&mut assembler(true), &[packet]);
        let [point] = scan.points[..] else {
            panic!("one point: {:?}", scan.points);
        };
        let (distance, lens) = (10.0, f64::from(LENS_OFFSET_M));
        let (corrected, swept) = ((93.59f64).to_radians(), (90.04f64).to_radians());
        let expected = [
            distance * corrected.cos() + lens * swept.cos(),
            -distance * corrected.sin() - lens * swept.sin(),
            0.0,
        ];
        for (axis, expected) in expected.iter().enumerate() {
            assert!(
                (f64::from(point.xyz_m[axis]) - expected).abs() < 1e-5,
                "{point:?}"
            );
        }
        assert_eq!(
            (point.intensity, point.ring, point.azimuth_centideg),
            (77, 6, 9_359)
        );
        // The sensor's clock: 100 s, and the channel's 27.77 us.
        assert_eq!(point.time_ns, 100_000_000_000 + 27_770);
    }

    #[test]
    fn returns_nearer_than_the_drivers_range_are_dropped() {
        let packet = msop(100, steady(9_000), &[(0, 0, 79, 1), (0, 1, 81, 1)]);
        let scan = scan_of(&mut assembler(true), &[packet]);
        assert_eq!(scan.points.len(), 1, "0.1975 m dropped, 0.2025 m kept");
    }

    #[test]
    fn a_scan_is_cut_at_azimuth_zero_and_stamped_with_its_first_block() {
        let mut assembler = assembler(true);
        let first = msop(100, steady(35_000), &[(0, 0, 800, 1), (11, 0, 800, 1)]);
        assert!(assembler.push(&first, 7_000_000_000).unwrap().is_none());
        // Blocks 35_900 .. 36_000 + 120: the cut falls at block 5 (azimuth 0).
        let crossing = msop(100, steady(35_900), &[(4, 0, 800, 1), (5, 0, 800, 1)]);
        let scan = assembler.push(&crossing, 0).unwrap().expect("cut");
        assert_eq!(scan.points.len(), 3, "blocks up to the cut");
        // Moved to the log's clock by the first packet's stamp (7 s for 100 s).
        assert_eq!(scan.stamp_ns, 7_000_000_000);
        let next = assembler.push(&msop(100, steady(200), &[]), 0).unwrap();
        assert!(next.is_none(), "the next scan began at the cut");
    }

    #[test]
    fn the_difop_sets_the_return_mode_and_the_units_own_angles() {
        // Channel 16 of a single-return block is laser 0's second firing, half a
        // block on; of a dual-return block, laser 0's second return, no further.
        let mut single = assembler(true);
        let packet = msop(100, steady(9_000), &[(0, 16, 4_000, 1), (0, 3, 4_000, 1)]);
        let scan = scan_of(&mut single, std::slice::from_ref(&packet));
        assert_eq!(scan.points[1].azimuth_centideg, 9_000 - 405 + 10);
        let mut dual = assembler(true);
        dual.push(&difop(0x00, 890), 0).unwrap();
        let scan = scan_of(&mut dual, std::slice::from_ref(&packet));
        assert_eq!(scan.points[1].azimuth_centideg, 9_000 - 405);
        // The generic table reads 8.90 degrees as nebula does, 8.89; the unit says
        // 8.90, and replaces it, unless a table was given as a file.
        let elevation = |scan: &PacketScan| {
            // 10 m away; the lens's offset is horizontal.
            let z = scan.points.iter().find(|p| p.ring == 12).unwrap().xyz_m[2];
            (z / 10.0).asin().to_degrees()
        };
        let mut generic = assembler(true);
        let before = scan_of(&mut generic, std::slice::from_ref(&packet));
        generic.push(&difop(0x04, 890), 0).unwrap();
        let after = scan_of(&mut generic, std::slice::from_ref(&packet));
        let mut given = assembler(false);
        given.push(&difop(0x04, 890), 0).unwrap();
        let kept = scan_of(&mut given, std::slice::from_ref(&packet));
        assert!(
            (elevation(&before) - 8.89).abs() < 2e-3,
            "{}",
            elevation(&before)
        );
        assert!(
            (elevation(&after) - 8.90).abs() < 2e-3,
            "{}",
            elevation(&after)
        );
        assert!(
            (elevation(&kept) - 8.89).abs() < 2e-3,
            "{}",
            elevation(&kept)
        );
    }
}
