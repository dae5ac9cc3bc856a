//! Hesai Pandar XT32 and XT16 data packets (`pandar_msgs/msg/PandarScan`), decoded
//! into points and cut into scans as tier4/nebula (Autoware's driver) does, so that
//! a log gives the points Autoware gives (`tests/hesai.rs` checks nebula's own ground
//! truth point for point).
//!
//! A packet: a 12-byte header (`EE FF`, protocol 6.1, the laser count at byte 6,
//! the distance unit in mm at byte 9), 8 blocks of {azimuth u16 in 0.01 degree, one
//! {distance u16, reflectivity u8, reserved u8} per laser}, and a tail holding the
//! return mode, the UTC date (years since 1900) and the microseconds of the firing.
//! Dual-return modes put the returns of one firing in consecutive blocks.
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

use super::ros::MessageEncoding;
use super::velodyne::{PacketField, PacketScan, ScanMessage, VelodynePoint, packets_message};

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

/// Blocks per packet.
const BLOCKS: usize = 8;
/// Bytes of the header before the first block.
const HEADER_BYTES: usize = 12;
/// Bytes of a laser's return in a block.
const UNIT_BYTES: usize = 4;
/// Range nebula keeps for the XT models, metres.
const MIN_RANGE_M: f32 = 0.05;
const MAX_RANGE_M: f32 = 120.0;
/// Two returns of one firing closer than this are one surface: the first is dropped.
const DUAL_RETURN_THRESHOLD_M: f32 = 0.1;
const TWO_PI: f32 = 2.0 * std::f32::consts::PI;

/// Hesai models with a decoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HesaiModel {
    PandarXt32,
    PandarXt16,
}

impl HesaiModel {
    /// The model of a packet: its header's magic and laser count, and its length.
    pub fn of_packet(packet: &[u8]) -> Result<Self, String> {
        if packet.len() < HEADER_BYTES || packet[..2] != [0xEE, 0xFF] {
            return Err(format!(
                "a {}-byte packet without Hesai's EE FF header",
                packet.len()
            ));
        }
        let model = match (packet[2], packet[6]) {
            (6, 32) => Self::PandarXt32,
            (6, 16) => Self::PandarXt16,
            (protocol, lasers) => {
                return Err(format!(
                    "a Hesai packet of protocol {protocol}.{} with {lasers} lasers: travmap decodes the Pandar XT32 and XT16 (protocol 6, 32 and 16 lasers)",
                    packet[3]
                ));
            }
        };
        if packet.len() < model.packet_bytes() {
            return Err(format!(
                "a {}-byte {} packet; it has {} bytes",
                packet.len(),
                model.name(),
                model.packet_bytes()
            ));
        }
        Ok(model)
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::PandarXt32 => "Pandar XT32",
            Self::PandarXt16 => "Pandar XT16",
        }
    }

    pub fn lasers(self) -> usize {
        match self {
            Self::PandarXt32 => 32,
            Self::PandarXt16 => 16,
        }
    }

    fn block_bytes(self) -> usize {
        2 + UNIT_BYTES * self.lasers()
    }

    fn tail_at(self) -> usize {
        HEADER_BYTES + BLOCKS * self.block_bytes()
    }

    fn packet_bytes(self) -> usize {
        self.tail_at() + 28
    }

    /// Time between two lasers' firings, ns (the manuals' firing-time tables).
    fn laser_step_ns(self) -> i64 {
        match self {
            Self::PandarXt32 => 1_512,
            Self::PandarXt16 => 3_024,
        }
    }

    /// The factory angle table (nebula's `PandarXT32.csv` / `PandarXT16.csv`).
    fn builtin_table(self) -> &'static str {
        match self {
            Self::PandarXt32 => XT32_CSV,
            Self::PandarXt16 => XT16_CSV,
        }
    }
}

/// Per laser: elevation and azimuth offset, degrees.
#[derive(Clone, Debug, PartialEq)]
pub struct HesaiCalibration {
    pub elevation_deg: Vec<f32>,
    pub azimuth_offset_deg: Vec<f32>,
}

impl HesaiCalibration {
    /// The model's factory table.
    pub fn builtin(model: HesaiModel) -> Self {
        Self::from_csv(model.builtin_table()).expect("the built-in tables parse")
    }

    /// Hesai's angle-correction CSV: `Channel,Elevation,Azimuth`, channels from 1.
    pub fn from_csv(text: &str) -> Result<Self, String> {
        let mut rows = Vec::new();
        for (number, line) in text.lines().enumerate() {
            let fields: Vec<&str> = line
                .split(',')
                .map(str::trim)
                .filter(|f| !f.is_empty())
                .collect();
            let [channel, elevation, azimuth] = fields[..] else {
                continue;
            };
            // The header line is not a row.
            let Ok(channel) = channel.parse::<usize>() else {
                continue;
            };
            let angle = |v: &str| {
                v.parse::<f32>()
                    .map_err(|_| format!("line {}: `{v}` is not an angle", number + 1))
            };
            rows.push((channel, angle(elevation)?, angle(azimuth)?));
        }
        let lasers = rows.len();
        let mut calibration = Self {
            elevation_deg: vec![f32::NAN; lasers],
            azimuth_offset_deg: vec![f32::NAN; lasers],
        };
        for (channel, elevation, azimuth) in rows {
            let at = channel
                .checked_sub(1)
                .filter(|&at| at < lasers)
                .ok_or_else(|| format!("channel {channel} in a table of {lasers} channels"))?;
            calibration.elevation_deg[at] = elevation;
            calibration.azimuth_offset_deg[at] = azimuth;
        }
        if lasers == 0 || calibration.elevation_deg.iter().any(|e| e.is_nan()) {
            return Err("not a Hesai angle table (Channel,Elevation,Azimuth rows, each channel once from 1)".into());
        }
        Ok(calibration)
    }
}

/// The returns a packet's return mode byte says each firing has.
fn returns_of(mode: u8) -> Result<usize, String> {
    match mode {
        0x33 | 0x34 | 0x37 | 0x38 => Ok(1),
        0x39..=0x3c | 0x3e => Ok(2),
        0x3d => Ok(3),
        other => Err(format!(
            "return mode 0x{other:02x} is not one Hesai defines"
        )),
    }
}

/// The UTC time of a packet, ns: the tail's date (years since 1900) and microseconds.
fn packet_time_ns(tail: &[u8]) -> Result<u64, String> {
    let [year, month, day, hour, minute, second] = [13, 14, 15, 16, 17, 18].map(|i| tail[i]);
    if !(1..=12).contains(&month)
        || !(1..=31).contains(&day)
        || hour > 23
        || minute > 59
        || second > 60
    {
        return Err(format!(
            "a packet dated {}-{month}-{day} {hour}:{minute}:{second}",
            1900 + u32::from(year)
        ));
    }
    let microseconds = u32::from_le_bytes([tail[19], tail[20], tail[21], tail[22]]);
    // Days from the civil date (Howard Hinnant's algorithm), as timegm does.
    let (y, m) = (1900 + i64::from(year), i64::from(month));
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let year_of_era = y - era * 400;
    let day_of_year = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + i64::from(day) - 1;
    let day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
    let days = era * 146_097 + day_of_era - 719_468;
    let seconds =
        days * 86_400 + i64::from(hour) * 3_600 + i64::from(minute) * 60 + i64::from(second);
    u64::try_from(seconds)
        .map(|s| s * 1_000_000_000 + u64::from(microseconds) * 1_000)
        .map_err(|_| "a packet dated before 1970".to_string())
}

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
        let tail = &packet[model.tail_at()..model.packet_bytes()];
        let returns = returns_of(tail[10])?;
        if !BLOCKS.is_multiple_of(returns) {
            return Err(format!(
                "return mode 0x{:02x} ({returns} returns) in a packet of {BLOCKS} blocks: the {} does not fire so",
                tail[10],
                model.name()
            ));
        }
        let packet_ns = packet_time_ns(tail)?;
        let to_log_clock_ns = match stamp_ns {
            0 => 0,
            stamp_ns => (i128::from(stamp_ns) - i128::from(packet_ns)) as i64,
        };
        // In f64 then rounded, as nebula computes them.
        let unit_m = f64::from(packet[9]) / 1000.0;
        let metres = |raw: u16| (f64::from(raw) * unit_m) as f32;
        let lasers = model.lasers();
        let mut completed = None;
        for first_block in (0..BLOCKS).step_by(returns) {
            let block =
                |b: usize| &packet[HEADER_BYTES + b * model.block_bytes()..][..model.block_bytes()];
            let raw_azimuth = u16::from_le_bytes([block(first_block)[0], block(first_block)[1]]);
            let block_rad =
                (f64::from(raw_azimuth) / 100.0 * (std::f64::consts::PI / 180.0)) as f32;
            // The firing time of this group's first laser, from the packet's time.
            let offset_ns = |b: usize, laser: usize| {
                5_632 - 50_000 * ((BLOCKS - b - 1) / returns) as i64
                    + 368
                    + model.laser_step_ns() * laser as i64
            };
            let group_ns = packet_ns.saturating_add_signed(offset_ns(first_block, 0));
            if let Some(scan) = self.cut(block_rad, group_ns, to_log_clock_ns) {
                completed = Some(scan);
            }
            if !self.decode_points {
                continue;
            }
            for laser in 0..lasers {
                let azimuth = block_rad + self.azimuth_offset_rad[laser];
                let (sin, cos) = azimuth.sin_cos();
                let unit = |k: usize| {
                    let u = &block(first_block + k)[2 + UNIT_BYTES * laser..];
                    (u16::from_le_bytes([u[0], u[1]]), u[2])
                };
                for k in 0..returns {
                    let (raw, reflectivity) = unit(k);
                    let distance = metres(raw);
                    if raw == 0 || !(MIN_RANGE_M..=MAX_RANGE_M).contains(&distance) {
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
                    self.scans[self.laser_scan[laser]]
                        .points
                        .push(VelodynePoint {
                            xyz_m: [
                                horizontal * sin,
                                horizontal * cos,
                                distance * self.elevation_sin[laser],
                            ],
                            intensity: reflectivity,
                            ring: laser as u16,
                            azimuth_centideg: (corrected.to_degrees() * 100.0) as u16 % 36_000,
                            time_ns: packet_ns
                                .saturating_add_signed(offset_ns(first_block + k, laser)),
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
            let mut scan = std::mem::replace(
                &mut self.scans[current],
                PacketScan {
                    stamp_ns: 0,
                    points: Vec::new(),
                },
            );
            let shift = self.to_log_clock_ns[current];
            scan.stamp_ns = scan.stamp_ns.saturating_add_signed(shift);
            for point in &mut scan.points {
                point.time_ns = point.time_ns.saturating_add_signed(shift);
            }
            return Some(scan);
        }
        None
    }
}

/// nebula's `PandarXT32.csv` (Apache-2.0): channel, elevation, azimuth offset (degrees).
const XT32_CSV: &str = "Channel,Elevation,Azimuth
1,14.972363,0.082385
2,13.952372,0.076529
3,12.938632,0.078240
4,11.931141,0.076267
5,10.926151,0.064337
6,9.922410,0.059942
7,8.917419,0.049319
8,7.917429,0.044992
9,6.919938,0.034446
10,5.919947,0.027658
11,4.922456,0.020896
12,3.924965,0.014147
13,2.929974,0.008668
14,1.936233,-0.000548
15,0.944992,-0.007248
16,-0.047500,-0.015201
17,-1.039991,-0.025654
18,-2.036232,-0.031126
19,-3.028723,-0.037837
20,-4.024964,-0.045822
21,-5.019955,-0.061312
22,-6.016196,-0.065570
23,-7.013687,-0.068599
24,-8.013678,-0.076658
25,-9.011169,-0.088476
26,-10.011159,-0.091580
27,-11.006150,-0.098438
28,-12.003641,-0.092837
29,-12.996131,-0.102247
30,-13.997372,-0.104231
31,-15.004862,-0.118783
32,-16.023602,-0.129679
";

/// nebula's `PandarXT16.csv` (Apache-2.0).
const XT16_CSV: &str = "Channel,Elevation,Azimuth
1,15,0
2,13,0
3,11,0
4,9,0
5,7,0
6,5,0
7,3,0
8,1,0
9,-1,0
10,-3,0
11,-5,0
12,-7,0
13,-9,0
14,-11,0
15,-13,0
16,-15,0
";
