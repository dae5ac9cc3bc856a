//! Hesai packets decoded into points and cut into scans as nebula does.

use super::calibration::HesaiCalibration;
use super::model::{DistanceUnit, HesaiModel, Layout, packet_time_ns, returns_of};
use crate::packets::scan::{PacketPoint, PacketScan, to_log_clock_ns};

/// Two returns of one firing closer than this are one surface: the first is dropped.
const DUAL_RETURN_THRESHOLD_M: f32 = 0.1;
const TWO_PI: f32 = 2.0 * std::f32::consts::PI;

/// `a` in [0, 2 pi).
fn normalised(a: f32) -> f32 {
    a - (a / TWO_PI).floor() * TWO_PI
}

/// Whether `angle` lies on the arc from `start` to `end` (clockwise in azimuth), the
/// ends included as asked; an arc from an angle to itself is the whole circle.
fn on_arc(start: f32, end: f32, angle: f32, start_included: bool, end_included: bool) -> bool {
    if start == end {
        return start != angle || start_included || end_included;
    }
    if (!start_included && angle == start) || (!end_included && angle == end) {
        return false;
    }
    if end < start {
        angle <= end || start <= angle
    } else {
        start <= angle && angle <= end
    }
}

/// Packets in, scans out, for one Hesai sensor.
pub struct HesaiAssembler {
    model: HesaiModel,
    layout: Layout,
    elevation_cos: Vec<f32>,
    elevation_sin: Vec<f32>,
    azimuth_offset_rad: Vec<f32>,
    /// The lasers with the smallest and the largest azimuth offset: a scan is
    /// complete when both have moved past the cut.
    first_laser: usize,
    last_laser: usize,
    /// The two scans being filled (this one and the next), in the sensor's clock,
    /// and what moves each to the log's clock.
    scans: [PacketScan; 2],
    to_log_clock_ns: [i64; 2],
    /// The scan each laser is filling, and its last corrected azimuth.
    laser_scan: Vec<usize>,
    last_azimuth: Vec<f32>,
    current: usize,
    started: bool,
    /// False: scans are cut and stamped but hold no points (the log index's pass).
    decode_points: bool,
}

impl HesaiAssembler {
    pub fn new(model: HesaiModel, calibration: &HesaiCalibration) -> Result<Self, String> {
        let lasers = model.lasers();
        if calibration.elevation_deg.len() != lasers {
            return Err(format!(
                "a calibration of {} lasers for the {} ({lasers} lasers)",
                calibration.elevation_deg.len(),
                model.name()
            ));
        }
        let radians = |deg: f32| deg * (std::f32::consts::PI / 180.0);
        let elevation: Vec<f32> = calibration
            .elevation_deg
            .iter()
            .map(|&e| radians(e))
            .collect();
        let offsets: Vec<f32> = calibration
            .azimuth_offset_deg
            .iter()
            .map(|&a| radians(a))
            .collect();
        let extreme = |better: fn(f32, f32) -> bool| {
            (0..lasers).fold(0, |best, l| {
                if better(offsets[l], offsets[best]) {
                    l
                } else {
                    best
                }
            })
        };
        let empty = || PacketScan {
            stamp_ns: 0,
            points: Vec::new(),
        };
        Ok(Self {
            model,
            layout: model.layout(),
            elevation_cos: elevation.iter().map(|e| e.cos()).collect(),
            elevation_sin: elevation.iter().map(|e| e.sin()).collect(),
            first_laser: extreme(|a, b| a < b),
            last_laser: extreme(|a, b| a > b),
            azimuth_offset_rad: offsets,
            scans: [empty(), empty()],
            to_log_clock_ns: [0; 2],
            laser_scan: vec![0; lasers],
            last_azimuth: vec![0.0; lasers],
            current: 0,
            started: false,
            decode_points: true,
        })
    }

    /// This assembler cutting and stamping scans without decoding their points:
    /// the same scans, empty, for a pass that wants only their stamps.
    pub fn stamps_only(self) -> Self {
        Self {
            decode_points: false,
            ..self
        }
    }

    pub fn model(&self) -> HesaiModel {
        self.model
    }

    /// Adds a packet recorded at `stamp_ns` (0: unknown, the sensor's clock is the
    /// log's); the scan it completes, if it does.
    pub fn push(&mut self, packet: &[u8], stamp_ns: u64) -> Result<Option<PacketScan>, String> {
        let model = HesaiModel::of_packet(packet)?;
        if model != self.model {
            return Err(format!(
                "a {} packet on a topic of {} packets",
                model.name(),
                self.model.name()
            ));
        }
        let layout = &self.layout;
        let tail = &packet[layout.tail_at()..layout.packet];
        let mode = tail[layout.mode_at];
        let returns = returns_of(mode)?;
        if !layout.blocks.is_multiple_of(returns) {
            return Err(format!(
                "return mode 0x{mode:02x} ({returns} returns) in a packet of {} blocks: the {} does not fire so",
                layout.blocks,
                model.name()
            ));
        }
        let packet_ns = packet_time_ns(tail, layout)?;
        let loop_flag = layout.loop_flag_at.map_or(0, |at| tail[at]);
        let to_log_clock_ns = to_log_clock_ns(stamp_ns, packet_ns);
        // In f64 then rounded, as nebula computes them.
        let unit_m = match layout.unit_mm {
            DistanceUnit::HeaderByte(at) => f64::from(packet[at]),
            DistanceUnit::FixedMm(mm) => f64::from(mm),
        } / 1000.0;
        let metres = |raw: u16| (f64::from(raw) * unit_m) as f32;
        let (lasers, block_bytes, prefix) =
            (layout.lasers, layout.block_bytes(), layout.block_prefix);
        let (min_range_m, max_range_m) = layout.range_m;
        let (header, blocks, unit_bytes) = (layout.header, layout.blocks, layout.unit);
        let mut completed = None;
        for first_block in (0..blocks).step_by(returns) {
            let block = |b: usize| &packet[header + b * block_bytes..][..block_bytes];
            let azimuth_bytes = &block(first_block)[prefix - 2..prefix];
            let raw_azimuth = u16::from_le_bytes([azimuth_bytes[0], azimuth_bytes[1]]);
            let block_rad =
                (f64::from(raw_azimuth) / 100.0 * (std::f64::consts::PI / 180.0)) as f32;
            let offset_ns = |b: usize, laser: usize| {
                model.firing_offset_ns(blocks, b, returns, loop_flag, laser)
            };
            // A scan is stamped with its first firing: the group's earliest laser in
            // any of its blocks (the QT128 times a group's two blocks apart).
            let first_ns = (first_block..first_block + returns)
                .flat_map(|b| (0..lasers).map(move |laser| (b, laser)))
                .map(|(b, laser)| offset_ns(b, laser))
                .min();
            let group_ns = packet_ns.saturating_add_signed(first_ns.unwrap_or(0));
            if let Some(scan) = self.cut(block_rad, group_ns, to_log_clock_ns) {
                completed = Some(scan);
            }
            if !self.decode_points {
                continue;
            }
            for laser in 0..lasers {
                let unit = |k: usize| {
                    let u = &block(first_block + k)[prefix + unit_bytes * laser..];
                    (u16::from_le_bytes([u[0], u[1]]), u[2])
                };
                // Lasers that saw nothing (the sky; half the QT128's, which fire in
                // turns) cost no trigonometry.
                if (0..returns).all(|k| unit(k).0 == 0) {
                    continue;
                }
                let azimuth = block_rad + self.azimuth_offset_rad[laser];
                let (sin, cos) = azimuth.sin_cos();
                for k in 0..returns {
                    let (raw, reflectivity) = unit(k);
                    let distance = metres(raw);
                    if raw == 0 || !(min_range_m..=max_range_m).contains(&distance) {
                        continue;
                    }
                    let last = k + 1 == returns;
                    // An identical return is kept once (its last copy); a first
                    // return close to another is the same surface.
                    let others = (0..returns).filter(|&i| i != k).map(unit);
                    if !last
                        && others.clone().any(|(r, i)| {
                            (r == raw && i == reflectivity)
                                || (metres(r) - distance).abs() < DUAL_RETURN_THRESHOLD_M
                        })
                    {
                        continue;
                    }
                    let horizontal = distance * self.elevation_cos[laser];
                    let corrected = normalised(azimuth);
                    self.scans[self.laser_scan[laser]].points.push(PacketPoint {
                        xyz_m: [
                            horizontal * sin,
                            horizontal * cos,
                            distance * self.elevation_sin[laser],
                        ],
                        intensity: reflectivity,
                        ring: laser as u16,
                        azimuth_centideg: (corrected.to_degrees() * 100.0) as u16 % 36_000,
                        time_ns: packet_ns.saturating_add_signed(offset_ns(first_block + k, laser)),
                    });
                }
            }
        }
        Ok(completed)
    }

    /// Moves each laser whose azimuth passed the cut (0) to the other scan; the
    /// scan its lasers have all left, once they have.
    fn cut(&mut self, block_rad: f32, group_ns: u64, to_log_clock_ns: i64) -> Option<PacketScan> {
        let lasers = self.laser_scan.len();
        let azimuth = |laser: usize| normalised(block_rad + self.azimuth_offset_rad[laser]);
        let (cut, half) = (0.0, std::f32::consts::PI);
        let ahead = |a: f32| on_arc(cut, half, a, false, true);
        if !self.started {
            // The first firing: lasers already past the cut begin the next scan.
            self.started = true;
            let quarter = std::f32::consts::FRAC_PI_2;
            let ends = [azimuth(self.first_laser), azimuth(self.last_laser)];
            let near = ends
                .iter()
                .all(|&a| on_arc(TWO_PI - quarter, quarter, a, true, true));
            let straddles = near && ends.iter().filter(|&&a| ahead(a)).count() == 1;
            for laser in 0..lasers {
                self.last_azimuth[laser] = azimuth(laser);
                self.laser_scan[laser] = usize::from(straddles && ahead(azimuth(laser)));
            }
            for scan in 0..2 {
                if self.laser_scan.contains(&scan) {
                    self.scans[scan].stamp_ns = group_ns;
                    self.to_log_clock_ns[scan] = to_log_clock_ns;
                }
            }
            return None;
        }
        let state = |this: &Self| {
            let (a, b) = (
                this.laser_scan[this.first_laser],
                this.laser_scan[this.last_laser],
            );
            (a == b).then_some(a)
        };
        let before = state(self);
        for laser in 0..lasers {
            let now = azimuth(laser);
            if on_arc(self.last_azimuth[laser], now, cut, true, false) {
                self.laser_scan[laser] ^= 1;
            }
            self.last_azimuth[laser] = now;
        }
        let after = state(self);
        let (current, next) = (self.current, self.current ^ 1);
        // Lasers began the next scan: it is stamped here. Every laser has left the
        // current scan: it is complete.
        if before == Some(current) && after != Some(current) {
            self.scans[next].stamp_ns = group_ns;
            self.to_log_clock_ns[next] = to_log_clock_ns;
        }
        if before != Some(next) && after == Some(next) {
            self.current = next;
            let scan = std::mem::replace(
                &mut self.scans[current],
                PacketScan {
                    stamp_ns: 0,
                    points: Vec::new(),
                },
            );
            return Some(scan.shifted(self.to_log_clock_ns[current]));
        }
        None
    }
}
