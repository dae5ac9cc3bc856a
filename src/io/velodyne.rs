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
//! with its first packet's stamp (the crossing packet's, when it starts with points
//! carried over), and each point keeps its time from that stamp.

use std::f64::consts::PI;

use serde::Deserialize;

use crate::io::ros::MessageEncoding;

pub const PACKET_BYTES: usize = 1206;
const BLOCKS: usize = 12;
const BLOCK_BYTES: usize = 100;
const RETURN_MODE_AT: usize = 1204;
const PRODUCT_AT: usize = 1205;
const DUAL_RETURN: u8 = 0x39;
/// Block flags: the upper bank, and the VLS-128's other three.
const BANK_FLAGS: [u16; 4] = [0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF];
const CENTIDEGREES: u32 = 36_000;

/// A Velodyne model, detected from the product id of its packets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum VelodyneModel {
    #[serde(rename = "HDL-32E")]
    Hdl32e,
    #[serde(rename = "VLP-16")]
    Vlp16,
    #[serde(rename = "VLP-32C")]
    Vlp32c,
    #[serde(rename = "VLS-128")]
    Vls128,
}

impl VelodyneModel {
    /// The model whose product id (byte 1205) `packet` carries.
    pub fn of_packet(packet: &[u8]) -> Result<Self, String> {
        if packet.len() != PACKET_BYTES {
            return Err(format!(
                "a Velodyne data packet is {PACKET_BYTES} bytes, this one {}",
                packet.len()
            ));
        }
        match packet[PRODUCT_AT] {
            0x21 => Ok(Self::Hdl32e),
            // The VLP-16 and the Puck Hi-Res share their geometry's layout.
            0x22 | 0x24 => Ok(Self::Vlp16),
            0x28 => Ok(Self::Vlp32c),
            0xA1 => Ok(Self::Vls128),
            id => Err(format!(
                "product id 0x{id:02X} (byte {PRODUCT_AT}) is no Velodyne model travmap decodes (HDL-32E 0x21, VLP-16 0x22, Puck Hi-Res 0x24, VLP-32C 0x28, VLS-128 0xA1)"
            )),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Hdl32e => "HDL-32E",
            Self::Vlp16 => "VLP-16",
            Self::Vlp32c => "VLP-32C",
            Self::Vls128 => "VLS-128",
        }
    }

    pub fn lasers(self) -> usize {
        match self {
            Self::Vlp16 => 16,
            Self::Hdl32e | Self::Vlp32c => 32,
            Self::Vls128 => 128,
        }
    }
}

/// One laser's corrections.
#[derive(Clone, Debug, PartialEq)]
struct Laser {
    sin_vert: f32,
    cos_vert: f32,
    /// The azimuth correction in 0.01 degree, subtracted from the firing's azimuth.
    rot_centideg: f64,
    dist_correction_m: f32,
    vert_offset_m: f32,
    horiz_offset_m: f32,
    /// Rank by elevation: ring 0 is the lowest beam.
    ring: u16,
}

/// A sensor's calibration: its lasers' angles and offsets, by laser id.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    lasers: Vec<Laser>,
    distance_resolution_m: f32,
}

/// velodyne_pointcloud's and nebula's calibration YAML.
#[derive(Deserialize)]
struct CalibrationFile {
    lasers: Vec<LaserEntry>,
    distance_resolution: Option<f64>,
}

#[derive(Deserialize)]
struct LaserEntry {
    laser_id: usize,
    rot_correction: f64,
    vert_correction: f64,
    #[serde(default)]
    dist_correction: f64,
    #[serde(default)]
    vert_offset_correction: f64,
    #[serde(default)]
    horiz_offset_correction: f64,
}

/// VLP-16 elevations by laser id, degrees (the manual's table): every 2 degrees,
/// interleaved.
const VLP16_ELEVATION_DEG: [f64; 16] = [
    -15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0,
];
/// VLP-32C elevations and azimuth offsets by laser id, degrees (the manual's table).
const VLP32C_ELEVATION_DEG: [f64; 32] = [
    -25.0, -1.0, -1.667, -15.639, -11.31, 0.0, -0.667, -8.843, -7.254, 0.333, -0.333, -6.148,
    -5.333, 1.333, 0.667, -4.0, -4.667, 1.667, 1.0, -3.667, -3.333, 3.333, 2.333, -2.667, -3.0,
    7.0, 4.667, -2.333, -2.0, 15.0, 10.333, -1.333,
];
const VLP32C_AZIMUTH_OFFSET_DEG: [f64; 32] = [
    1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4, -1.4, 4.2, -1.4, 4.2, -1.4, 1.4,
    -4.2, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4, 1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4,
];

impl Calibration {
    /// The model's own table, for the models whose geometry is fixed (VLP-16,
    /// VLP-32C); the others need a calibration file.
    pub fn builtin(model: VelodyneModel) -> Option<Self> {
        let (elevations, offsets, resolution): (&[f64], &[f64], f64) = match model {
            VelodyneModel::Vlp16 => (&VLP16_ELEVATION_DEG, &[0.0; 16], 0.002),
            VelodyneModel::Vlp32c => (&VLP32C_ELEVATION_DEG, &VLP32C_AZIMUTH_OFFSET_DEG, 0.004),
            VelodyneModel::Hdl32e | VelodyneModel::Vls128 => return None,
        };
        let entries = elevations
            .iter()
            .zip(offsets)
            .enumerate()
            .map(|(laser_id, (elevation, offset))| LaserEntry {
                laser_id,
                // The YAML's rot_correction is subtracted: minus the manual's offset.
                rot_correction: -offset.to_radians(),
                vert_correction: elevation.to_radians(),
                dist_correction: 0.0,
                vert_offset_correction: 0.0,
                horiz_offset_correction: 0.0,
            })
            .collect();
        Self::of_entries(entries, resolution).ok()
    }

    /// A velodyne_pointcloud / nebula calibration YAML (`lasers:` with `laser_id`,
    /// `rot_correction`, `vert_correction` in radians, offsets in metres;
    /// `distance_resolution`).
    pub fn from_yaml(text: &str) -> Result<Self, String> {
        let file: CalibrationFile = serde_yaml_ng::from_str(text).map_err(|e| e.to_string())?;
        Self::of_entries(file.lasers, file.distance_resolution.unwrap_or(0.002))
    }

    fn of_entries(mut entries: Vec<LaserEntry>, resolution_m: f64) -> Result<Self, String> {
        entries.sort_by_key(|e| e.laser_id);
        for (expected, entry) in entries.iter().enumerate() {
            if entry.laser_id != expected {
                return Err(format!(
                    "laser ids must run 0..{} without gaps; laser {expected} is missing",
                    entries.len()
                ));
            }
        }
        let mut by_elevation: Vec<usize> = (0..entries.len()).collect();
        by_elevation.sort_by(|&a, &b| {
            entries[a]
                .vert_correction
                .total_cmp(&entries[b].vert_correction)
        });
        let mut rings = vec![0u16; entries.len()];
        for (ring, &laser) in by_elevation.iter().enumerate() {
            rings[laser] = ring as u16;
        }
        let lasers = entries
            .iter()
            .zip(rings)
            .map(|(e, ring)| {
                let vert = e.vert_correction as f32;
                Laser {
                    sin_vert: vert.sin(),
                    cos_vert: vert.cos(),
                    rot_centideg: e.rot_correction * 180.0 / PI * 100.0,
                    dist_correction_m: e.dist_correction as f32,
                    vert_offset_m: e.vert_offset_correction as f32,
                    horiz_offset_m: e.horiz_offset_correction as f32,
                    ring,
                }
            })
            .collect();
        Ok(Self {
            lasers,
            distance_resolution_m: resolution_m as f32,
        })
    }

    pub fn lasers(&self) -> usize {
        self.lasers.len()
    }
}

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

/// One decoded return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelodynePoint {
    /// x, y, z in the sensor frame, metres.
    pub xyz_m: [f32; 3],
    pub intensity: u8,
    pub ring: u16,
    /// Azimuth after correction, 0.01 degree clockwise from +x.
    pub azimuth_centideg: u16,
    /// Time of the firing: the packet's stamp plus the firing's offset, ns.
    pub time_ns: u64,
}

/// Decodes packets of one model with one calibration.
pub struct Decoder {
    model: VelodyneModel,
    calibration: Calibration,
    settings: DecoderSettings,
    sin_table: Vec<f32>,
    cos_table: Vec<f32>,
}

impl Decoder {
    pub fn new(
        model: VelodyneModel,
        calibration: Calibration,
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
        out: &mut Vec<VelodynePoint>,
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
        let rotation = |block: usize| u32::from(u16_at(block * BLOCK_BYTES + 2));
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
                out.push(VelodynePoint {
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

/// A complete scan.
#[derive(Clone, Debug)]
pub struct PacketScan {
    pub stamp_ns: u64,
    pub points: Vec<VelodynePoint>,
}

/// Packets in, scans out: [`ScanCutter`]'s cuts, the points past the cut carried
/// into the next scan.
pub struct ScanAssembler {
    decoder: Decoder,
    cutter: ScanCutter,
    points: Vec<VelodynePoint>,
    stamp_ns: Option<u64>,
}

impl ScanAssembler {
    pub fn new(decoder: Decoder) -> Self {
        let cutter = ScanCutter::new(decoder.settings.cut_angle_deg);
        Self {
            decoder,
            cutter,
            points: Vec::new(),
            stamp_ns: None,
        }
    }

    /// Adds a packet; the scan it completes, if it does.
    pub fn push(&mut self, packet: &[u8], stamp_ns: u64) -> Result<Option<PacketScan>, String> {
        if packet.len() != PACKET_BYTES {
            return Err(format!(
                "a Velodyne data packet is {PACKET_BYTES} bytes, this one {}",
                packet.len()
            ));
        }
        let completes = self.cutter.completes(packet);
        self.stamp_ns.get_or_insert(stamp_ns);
        self.decoder.decode(packet, stamp_ns, &mut self.points)?;
        if !completes {
            return Ok(None);
        }
        // Trailing points within 90 degrees past the cut begin the next scan.
        let phase = self.cutter.phase_centideg;
        let past_cut = |p: &VelodynePoint| {
            (CENTIDEGREES + u32::from(p.azimuth_centideg) - phase) % CENTIDEGREES < 9_000
        };
        let keep = self.points.len() - self.points.iter().rev().take_while(|p| past_cut(p)).count();
        let carried = self.points.split_off(keep);
        let scan = PacketScan {
            stamp_ns: self.stamp_ns.take().unwrap_or(stamp_ns),
            points: std::mem::replace(&mut self.points, carried),
        };
        if !self.points.is_empty() {
            self.stamp_ns = Some(stamp_ns);
        }
        Ok(Some(scan))
    }
}

/// The message type that carries packets.
pub const VELODYNE_SCAN: &str = "velodyne_msgs/msg/VelodyneScan";

/// A `velodyne_msgs/msg/VelodyneScan` message: its header and its packets (each
/// stamp in ns, and the packet's bytes).
pub struct ScanMessage<'a> {
    pub frame_id: String,
    pub stamp_ns: u64,
    pub packets: Vec<(u64, &'a [u8])>,
}

/// Reads a VelodyneScan (`Header header`, `VelodynePacket[] packets` of
/// `time stamp`, `uint8[1206] data`) without copying its packets.
pub fn scan_message(data: &[u8], encoding: MessageEncoding) -> Result<ScanMessage<'_>, String> {
    let mut reader = Reader {
        data,
        at: 0,
        origin: 0,
        aligned: encoding == MessageEncoding::Cdr,
    };
    if encoding == MessageEncoding::Cdr {
        match reader.bytes(4)? {
            [0, 1, _, _] => reader.origin = 4,
            _ => return Err("only little-endian CDR is read".into()),
        }
    } else {
        reader.u32()?; // seq
    }
    let stamp_ns = reader.stamp(encoding)?;
    let length = reader.u32()? as usize;
    let name = reader.bytes(length)?;
    let name = match encoding {
        MessageEncoding::Cdr => name.strip_suffix(&[0]).unwrap_or(name),
        MessageEncoding::Ros1 => name,
    };
    let frame_id = String::from_utf8_lossy(name).into_owned();
    let count = reader.u32()? as usize;
    if count > data.len() / PACKET_BYTES {
        return Err(format!("{count} packets claimed in {} bytes", data.len()));
    }
    let mut packets = Vec::with_capacity(count);
    for _ in 0..count {
        let stamp = reader.stamp(encoding)?;
        packets.push((stamp, reader.bytes(PACKET_BYTES)?));
    }
    Ok(ScanMessage {
        frame_id,
        stamp_ns,
        packets,
    })
}

/// A cursor over a serialized message; CDR aligns each primitive to its size
/// from `origin`.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
    origin: usize,
    aligned: bool,
}

impl<'a> Reader<'a> {
    fn bytes(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&end| end <= self.data.len());
        let end = end.ok_or_else(|| {
            format!(
                "the message ends at byte {} inside a field of {n} bytes at {}",
                self.data.len(),
                self.at
            )
        })?;
        let bytes = &self.data[self.at..end];
        self.at = end;
        Ok(bytes)
    }

    fn u32(&mut self) -> Result<u32, String> {
        if self.aligned {
            self.at += (4 - (self.at - self.origin) % 4) % 4;
        }
        let b = self.bytes(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn stamp(&mut self, encoding: MessageEncoding) -> Result<u64, String> {
        let seconds = self.u32()?;
        let nanoseconds = u64::from(self.u32()?);
        // ROS 2 stamps are signed seconds, ROS 1 unsigned: before 1970 is not a drive.
        let seconds = match encoding {
            MessageEncoding::Cdr => u64::try_from(seconds as i32).unwrap_or(0),
            MessageEncoding::Ros1 => u64::from(seconds),
        };
        Ok(seconds * 1_000_000_000 + nanoseconds)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A single-return packet of `model` whose block `b` points at azimuth
    /// `first + b * step` and whose every return is `distance_raw` at intensity 100.
    fn packet(product: u8, first: u16, step: u16, distance_raw: u16) -> Vec<u8> {
        let mut p = vec![0u8; PACKET_BYTES];
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
        let calibration = Calibration::builtin(VelodyneModel::Vlp16).unwrap();
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
        let calibration = Calibration::builtin(VelodyneModel::Vlp32c).unwrap();
        assert_eq!(calibration.lasers[0].ring, 0, "-25 degrees is the lowest");
        assert_eq!(calibration.lasers[29].ring, 31, "+15 degrees the highest");
        assert!((calibration.lasers[0].rot_centideg + 140.0).abs() < 1e-9);
        assert!(Calibration::builtin(VelodyneModel::Vls128).is_none());
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
        let calibration = Calibration::builtin(VelodyneModel::Vlp32c).unwrap();
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
