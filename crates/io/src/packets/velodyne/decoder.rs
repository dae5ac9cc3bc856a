//! One Velodyne packet into points: nebula's azimuth interpolation, range and field
//! of view (see the module above for where it departs from the manuals).

use super::calibration::VelodyneCalibration;
use super::packet::{
    BANK_FLAGS, BLOCK_BYTES, BLOCKS, CENTIDEGREES, DUAL_RETURN, RETURN_MODE_AT, VelodyneModel,
};
use crate::packets::scan::PacketPoint;

/// Which returns and angles make points.
#[derive(Clone, Debug, PartialEq)]
pub struct DecoderSettings {
    /// Scans are cut where the azimuth crosses this angle, degrees.
    pub cut_angle_deg: f64,
    /// Distances kept: strictly between these, metres.
    pub min_range_m: f32,
    pub max_range_m: f32,
    /// The field of view kept, degrees clockwise from +x; wraps when min > max.
    pub fov_min_deg: u32,
    pub fov_max_deg: u32,
}

impl Default for DecoderSettings {
    /// nebula's defaults.
    fn default() -> Self {
        Self {
            cut_angle_deg: 0.0,
            min_range_m: 0.3,
            max_range_m: 300.0,
            fov_min_deg: 0,
            fov_max_deg: 360,
        }
    }
}

impl DecoderSettings {
    /// Whether an azimuth (0.01 degree) is inside the field of view.
    fn sees(&self, centideg: u32) -> bool {
        let (min, max) = (self.fov_min_deg * 100, self.fov_max_deg * 100);
        if min <= max {
            centideg >= min && centideg <= max
        } else {
            centideg >= min || centideg <= max
        }
    }
}

/// Decodes packets of one model with one calibration.
pub struct Decoder {
    model: VelodyneModel,
    calibration: VelodyneCalibration,
    settings: DecoderSettings,
    sin_table: Vec<f32>,
    cos_table: Vec<f32>,
}

impl Decoder {
    pub fn new(
        model: VelodyneModel,
        calibration: VelodyneCalibration,
        settings: DecoderSettings,
    ) -> Result<Self, String> {
        if calibration.lasers() != model.lasers() {
            return Err(format!(
                "the calibration has {} lasers, the {} has {}",
                calibration.lasers(),
                model.name(),
                model.lasers()
            ));
        }
        let angle = |i: u32| (i as f32 * 0.01).to_radians();
        Ok(Self {
            model,
            calibration,
            settings,
            sin_table: (0..CENTIDEGREES).map(|i| angle(i).sin()).collect(),
            cos_table: (0..CENTIDEGREES).map(|i| angle(i).cos()).collect(),
        })
    }

    pub fn model(&self) -> VelodyneModel {
        self.model
    }

    pub fn settings(&self) -> &DecoderSettings {
        &self.settings
    }

    /// The laser, the share of the block's azimuth step and the time offset (s) of
    /// return `j` of block `block` (bank `bank`).
    fn firing(&self, block: usize, bank: usize, j: usize) -> (usize, f32, f64) {
        match self.model {
            VelodyneModel::Vlp16 => {
                let (firing, dsr) = (j / 16, j % 16);
                let share = (dsr as f32 * 2.304 + firing as f32 * 55.296) / 110.592;
                let time = 55.296e-6 * (2 * block + firing) as f64 + 2.304e-6 * dsr as f64;
                (dsr, share, time)
            }
            VelodyneModel::Vlp32c | VelodyneModel::Hdl32e => {
                let share = 2.304f32 / 55.296 * j as f32;
                let time = 55.296e-6 * block as f64 + 2.304e-6 * (j / 2) as f64;
                (j, share, time)
            }
            VelodyneModel::Vls128 => {
                let laser = bank * 32 + j;
                let group = laser / 8;
                let share = 2.665f32 / 53.3 * (group + group / 8) as f32;
                let time =
                    53.3e-6 * (block / 4) as f64 + 2.665e-6 * (group + laser / 64) as f64 - 8.7e-6;
                (laser, share, time)
            }
        }
    }

    /// The points of one packet stamped `stamp_ns`, appended to `out`.
    pub fn decode(
        &self,
        packet: &[u8],
        stamp_ns: u64,
        out: &mut Vec<PacketPoint>,
    ) -> Result<(), String> {
        let model = VelodyneModel::of_packet(packet)?;
        if model != self.model {
            return Err(format!(
                "a {} packet among {} packets",
                model.name(),
                self.model.name()
            ));
        }
        let dual = packet[RETURN_MODE_AT] == DUAL_RETURN;
        let u16_at = |at: usize| u16::from_le_bytes([packet[at], packet[at + 1]]);
        // A corrupt azimuth past 359.99 degrees wraps like a real one.
        let rotation = |block: usize| u32::from(u16_at(block * BLOCK_BYTES + 2)) % CENTIDEGREES;
        let step = 1 + dual as usize;
        let blocks = match self.model {
            VelodyneModel::Vls128 => BLOCKS - 4 * dual as usize,
            _ => BLOCKS,
        };
        let not_interpolated = match self.model {
            VelodyneModel::Vlp16 => BLOCKS - dual as usize - 1,
            _ => BLOCKS - 4 * dual as usize - 1,
        };
        let (mut azimuth_next, mut last_diff) = (0u32, 0f32);
        for block in 0..blocks {
            let at = block * BLOCK_BYTES;
            let bank = match (self.model, BANK_FLAGS.iter().position(|&f| f == u16_at(at))) {
                (VelodyneModel::Vls128, Some(bank)) => bank,
                (_, Some(0)) => 0,
                // nebula reads a VLP-32C's lower bank as laser 0-31 again.
                (VelodyneModel::Vlp32c | VelodyneModel::Hdl32e, Some(_)) => 0,
                // A block that is no data: the rest of the packet is not either.
                _ => break,
            };
            let azimuth = if block == 0 {
                rotation(0)
            } else {
                azimuth_next
            };
            let diff = if block < BLOCKS - step {
                azimuth_next = rotation(block + step);
                last_diff = ((CENTIDEGREES + azimuth_next - azimuth) % CENTIDEGREES) as f32;
                last_diff
            } else if block == not_interpolated {
                0.0
            } else {
                last_diff
            };
            let block_azimuth_in_view = match self.model {
                VelodyneModel::Vlp32c | VelodyneModel::Hdl32e => {
                    self.settings.sees(rotation(block))
                }
                _ => {
                    self.settings.fov_min_deg > self.settings.fov_max_deg
                        || self.settings.sees(azimuth)
                }
            };
            if !block_azimuth_in_view {
                continue;
            }
            for j in 0..32 {
                let k = at + 4 + 3 * j;
                let raw = u16_at(k);
                if raw == 0 {
                    continue;
                }
                if dual && block % 2 == 1 {
                    // The second return of a pair, identical to the first: once.
                    let other = (block - 1) * BLOCK_BYTES + 4 + 3 * j;
                    if u16_at(other) == raw {
                        continue;
                    }
                }
                let (laser_id, share, time_s) = self.firing(block, bank, j);
                let laser = &self.calibration.lasers[laser_id];
                let mut distance = raw as f32 * self.resolution_m();
                if distance > 1e-6 {
                    distance += laser.dist_correction_m;
                }
                if !(distance > self.settings.min_range_m && distance < self.settings.max_range_m) {
                    continue;
                }
                let mut corrected = (azimuth as f32 + diff * share) as f64 - laser.rot_centideg;
                if corrected < 0.0 {
                    corrected += CENTIDEGREES as f64;
                }
                let corrected = (corrected.round() as u32) % CENTIDEGREES;
                let in_view = match self.model {
                    VelodyneModel::Vlp32c | VelodyneModel::Hdl32e => true,
                    _ => self.settings.sees(corrected),
                };
                if !in_view {
                    continue;
                }
                let (sin_rot, cos_rot) = (
                    self.sin_table[corrected as usize],
                    self.cos_table[corrected as usize],
                );
                let xy = distance * laser.cos_vert - laser.vert_offset_m * laser.sin_vert;
                let x = xy * cos_rot + laser.horiz_offset_m * sin_rot;
                let y = -(xy * sin_rot - laser.horiz_offset_m * cos_rot);
                let z = distance * laser.sin_vert + laser.vert_offset_m * laser.cos_vert;
                out.push(PacketPoint {
                    xyz_m: [x, y, z],
                    intensity: packet[k + 2],
                    ring: laser.ring,
                    azimuth_centideg: corrected as u16,
                    time_ns: stamp_ns.saturating_add_signed((time_s * 1e9).round() as i64),
                });
            }
        }
        Ok(())
    }

    /// The VLS-128's distance step is 4 mm whatever its file says (as nebula reads it).
    fn resolution_m(&self) -> f32 {
        match self.model {
            VelodyneModel::Vls128 => 0.004,
            _ => self.calibration.distance_resolution_m,
        }
    }
}
