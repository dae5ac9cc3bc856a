//! Each Hesai model's packet: its [`Layout`], how it is told from its bytes, when
//! its lasers fire, and the packet's time.

/// Hesai models with a decoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HesaiModel {
    PandarXt32,
    PandarXt16,
    PandarXt32m,
    Pandar40p,
    Pandar64,
    PandarQt64,
    PandarQt128,
}

/// Where a model's distance unit is: a header byte (mm), or fixed.
#[derive(Clone, Copy)]
pub(super) enum DistanceUnit {
    HeaderByte(usize),
    FixedMm(u8),
}

/// A model's packet, as nebula's packet structs lay it out (offsets in bytes).
pub(super) struct Layout {
    pub(super) lasers: usize,
    pub(super) blocks: usize,
    /// Bytes before the first block.
    pub(super) header: usize,
    /// Bytes of a block before its units; the azimuth is the last two of them.
    pub(super) block_prefix: usize,
    /// Bytes of one laser's return.
    pub(super) unit: usize,
    /// The least length nebula reads (some firmware appends a sequence number).
    pub(super) packet: usize,
    /// In the tail: the return mode, the date (6 bytes: year, month, day, hour,
    /// minute, second) and the microseconds (u32).
    pub(super) mode_at: usize,
    pub(super) date_at: usize,
    pub(super) micros_at: usize,
    /// What the date's year counts from.
    pub(super) year_base: i64,
    pub(super) unit_mm: DistanceUnit,
    /// In the tail: the mode flag, whose low bit says which of its two firing loops
    /// a dual-return QT128 packet holds.
    pub(super) loop_flag_at: Option<usize>,
    /// The range nebula keeps, metres.
    pub(super) range_m: (f32, f32),
}

impl Layout {
    pub(super) fn block_bytes(&self) -> usize {
        self.block_prefix + self.unit * self.lasers
    }

    pub(super) fn tail_at(&self) -> usize {
        self.header + self.blocks * self.block_bytes()
    }
}

const XT_TAIL: (usize, usize, usize) = (10, 13, 19);
/// The QT128's packet without its optional 32 bytes of cyber security.
const QT128_PACKET: usize = 12 + 2 * (2 + 4 * 128) + 4 + 17 + 34;

impl HesaiModel {
    /// The model of a packet, from its first bytes: a 40P's blocks begin `FF EE`;
    /// the others begin `EE FF`, then the XT's and QT64's protocol (6.1, 3.1) and
    /// laser count, or the 64's laser and block counts. Then its length.
    pub fn of_packet(packet: &[u8]) -> Result<Self, String> {
        let model = match packet {
            [0xFF, 0xEE, ..] => Self::Pandar40p,
            [0xEE, 0xFF, 6, _, _, _, 32, 8, ..] => Self::PandarXt32,
            [0xEE, 0xFF, 6, _, _, _, 16, 8, ..] => Self::PandarXt16,
            [0xEE, 0xFF, 6, _, _, _, 32, 6, ..] => Self::PandarXt32m,
            [0xEE, 0xFF, 3, _, _, _, 64, 4, ..] => Self::PandarQt64,
            [0xEE, 0xFF, 64, 6, ..] => Self::Pandar64,
            [0xEE, 0xFF, 3, 2, _, _, 128, 2, ..] => Self::PandarQt128,
            [0xEE, 0xFF, a, b, _, _, c, d, ..] => {
                return Err(format!(
                    "a Hesai packet of header bytes {a} {b} .. {c} {d}: travmap decodes the Pandar XT32 and XT16 (protocol 6.1, 32 / 16 lasers, 8 blocks), XT32M (6.1, 32 lasers, 6 blocks), QT64 (protocol 3.1, 64 lasers, 4 blocks), QT128 (protocol 3.2, 128 lasers, 2 blocks), 64 (64 lasers, 6 blocks) and 40P; not the OT128 or AT128"
                ));
            }
            _ => {
                return Err(format!(
                    "a {}-byte packet without Hesai's EE FF header (or a Pandar 40P's FF EE block)",
                    packet.len()
                ));
            }
        };
        let layout = model.layout();
        if packet.len() < layout.packet {
            return Err(format!(
                "a {}-byte {} packet; it has {} bytes",
                packet.len(),
                model.name(),
                layout.packet
            ));
        }
        Ok(model)
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::PandarXt32 => "Pandar XT32",
            Self::PandarXt16 => "Pandar XT16",
            Self::PandarXt32m => "Pandar XT32M",
            Self::Pandar40p => "Pandar 40P",
            Self::Pandar64 => "Pandar 64",
            Self::PandarQt64 => "Pandar QT64",
            Self::PandarQt128 => "Pandar QT128",
        }
    }

    pub fn lasers(self) -> usize {
        self.layout().lasers
    }

    pub(super) fn layout(self) -> Layout {
        let xt = |lasers, blocks, range_m| Layout {
            lasers,
            blocks,
            header: 12,
            block_prefix: 2,
            unit: 4,
            packet: 12 + blocks * (2 + 4 * lasers) + 28,
            mode_at: XT_TAIL.0,
            date_at: XT_TAIL.1,
            micros_at: XT_TAIL.2,
            year_base: 1900,
            unit_mm: DistanceUnit::HeaderByte(9),
            loop_flag_at: None,
            range_m,
        };
        match self {
            Self::PandarXt32 => xt(32, 8, (0.05, 120.0)),
            Self::PandarXt16 => xt(16, 8, (0.05, 120.0)),
            Self::PandarXt32m => xt(32, 6, (0.5, 300.0)),
            Self::Pandar40p => Layout {
                lasers: 40,
                blocks: 10,
                header: 0,
                block_prefix: 4,
                unit: 3,
                packet: 1262,
                mode_at: 14,
                date_at: 16,
                micros_at: 10,
                year_base: 2000,
                unit_mm: DistanceUnit::FixedMm(4),
                loop_flag_at: None,
                range_m: (0.3, 200.0),
            },
            Self::Pandar64 => Layout {
                lasers: 64,
                blocks: 6,
                header: 8,
                block_prefix: 2,
                unit: 3,
                packet: 1194,
                mode_at: 14,
                date_at: 16,
                micros_at: 10,
                year_base: 2000,
                unit_mm: DistanceUnit::HeaderByte(5),
                loop_flag_at: None,
                range_m: (0.3, 200.0),
            },
            Self::PandarQt64 => Layout {
                lasers: 64,
                blocks: 4,
                header: 12,
                block_prefix: 2,
                unit: 4,
                packet: 1072,
                mode_at: 16,
                date_at: 18,
                micros_at: 12,
                year_base: 1900,
                unit_mm: DistanceUnit::HeaderByte(9),
                loop_flag_at: None,
                range_m: (0.1, 60.0),
            },
            // After the blocks: a CRC (4 bytes) and the functional safety part (17),
            // then the tail (nebula's `pandar_qt128.hpp`).
            Self::PandarQt128 => Layout {
                lasers: 128,
                blocks: 2,
                header: 12,
                block_prefix: 2,
                unit: 4,
                packet: QT128_PACKET,
                mode_at: 21 + 12,
                date_at: 21 + 15,
                micros_at: 21 + 21,
                year_base: 1900,
                unit_mm: DistanceUnit::HeaderByte(9),
                loop_flag_at: Some(21 + 5),
                range_m: (0.3, 300.0),
            },
        }
    }

    /// When laser `laser` of block `block` of `blocks` (its layout's) fires, ns from
    /// the packet's time, with `returns` returns per firing and the tail's
    /// `loop_flag` (nebula's firing-time tables, which follow the manuals).
    pub(super) fn firing_offset_ns(
        self,
        blocks: usize,
        block: usize,
        returns: usize,
        loop_flag: u8,
        laser: usize,
    ) -> i64 {
        let before_last = ((blocks - block - 1) / returns) as i64;
        match self {
            Self::PandarXt32 => 5_632 - 50_000 * before_last + 368 + 1_512 * laser as i64,
            Self::PandarXt16 => 5_632 - 50_000 * before_last + 368 + 3_024 * laser as i64,
            // nebula counts the XT32M's groups as the XT32's 8 blocks, but for triple returns.
            Self::PandarXt32m => {
                let before_last = match returns {
                    3 => (blocks - block - 1) / 3,
                    _ => (8 - block - 1) / returns,
                } as i64;
                5_632 - 50_000 * before_last + 368 + 2_888 * (laser % 16) as i64
            }
            Self::Pandar40p => -28_580 - 55_560 * before_last + P40_FIRING_NS[laser],
            Self::Pandar64 => -42_580 - 55_560 * before_last + P64_FIRING_NS[laser],
            Self::PandarQt64 => {
                25_710 + 500_000 * (block / returns) as i64 / 3 + QT64_FIRING_NS[laser]
            }
            // Two firing loops take turns: by block in single return, by packet (the
            // tail's flag) in dual. Each fires only some of the lasers.
            Self::PandarQt128 => {
                let first_loop = match returns {
                    1 => block.is_multiple_of(2),
                    _ => loop_flag & 1 == 1,
                };
                let table = if first_loop {
                    &QT128_LOOP1_NS
                } else {
                    &QT128_LOOP2_NS
                };
                9_000 + 111_110 * (blocks - block - 1) as i64 / returns as i64 + table[laser]
            }
        }
    }
}

/// The returns a packet's return mode byte says each firing has.
pub(super) fn returns_of(mode: u8) -> Result<usize, String> {
    match mode {
        0x33 | 0x34 | 0x37 | 0x38 => Ok(1),
        0x39..=0x3c | 0x3e => Ok(2),
        0x3d => Ok(3),
        other => Err(format!(
            "return mode 0x{other:02x} is not one Hesai defines"
        )),
    }
}

/// The UTC time of a packet, ns: the tail's date and microseconds.
pub(super) fn packet_time_ns(tail: &[u8], layout: &Layout) -> Result<u64, String> {
    let date = &tail[layout.date_at..layout.date_at + 6];
    let [year, month, day, hour, minute, second] = [0, 1, 2, 3, 4, 5].map(|i| date[i]);
    if !(1..=12).contains(&month)
        || !(1..=31).contains(&day)
        || hour > 23
        || minute > 59
        || second > 60
    {
        return Err(format!(
            "a packet dated {}-{month}-{day} {hour}:{minute}:{second}",
            layout.year_base + i64::from(year)
        ));
    }
    let at = layout.micros_at;
    let microseconds = u32::from_le_bytes([tail[at], tail[at + 1], tail[at + 2], tail[at + 3]]);
    // Days from the civil date (Howard Hinnant's algorithm), as timegm does.
    let (y, m) = (layout.year_base + i64::from(year), i64::from(month));
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

/// The Pandar 40P's firing time of each laser, ns (nebula's `pandar_40.hpp`).
const P40_FIRING_NS: [i64; 40] = [
    -42_220, -28_470, -16_040, -3_620, -45_490, -31_740, -47_460, -54_670, -20_620, -33_710,
    -40_910, -8_190, -20_620, -27_160, -50_730, -8_190, -14_740, -36_980, -45_490, -52_700,
    -23_890, -31_740, -38_950, -11_470, -18_650, -25_190, -48_760, -6_230, -12_770, -35_010,
    -21_920, -9_500, -43_520, -29_770, -17_350, -4_920, -42_220, -28_470, -16_040, -3_620,
];

/// The Pandar 64's (`pandar_64.hpp`).
const P64_FIRING_NS: [i64; 64] = [
    -23_180, -21_876, -20_572, -19_268, -17_964, -16_660, -11_444, -46_796, -7_532, -36_956,
    -50_732, -54_668, -40_892, -44_828, -31_052, -34_988, -48_764, -52_700, -38_924, -42_860,
    -29_084, -33_020, -46_796, -25_148, -36_956, -50_732, -27_116, -40_892, -44_828, -31_052,
    -34_988, -48_764, -25_148, -38_924, -42_860, -29_084, -33_020, -52_700, -6_228, -54_668,
    -15_356, -27_116, -10_140, -23_180, -4_924, -21_876, -14_052, -17_964, -8_836, -19_268, -3_620,
    -20_572, -12_748, -16_660, -7_532, -11_444, -6_228, -15_356, -10_140, -4_924, -3_620, -14_052,
    -8_836, -12_748,
];

/// The Pandar QT64's (`pandar_qt64.hpp`). Laser 55's 12,960 is nebula's, a digit short
/// of its neighbours; kept, since it moves only that laser's point times.
const QT64_FIRING_NS: [i64; 64] = [
    12_310, 14_370, 16_430, 18_490, 20_540, 22_600, 24_660, 26_710, 29_160, 31_220, 33_280, 35_340,
    37_390, 39_450, 41_500, 43_560, 46_610, 48_670, 50_730, 52_780, 54_840, 56_900, 58_950, 61_010,
    63_450, 65_520, 67_580, 69_630, 71_690, 73_740, 75_800, 77_860, 80_900, 82_970, 85_020, 87_080,
    89_140, 91_190, 93_250, 95_300, 97_750, 99_820, 101_870, 103_930, 105_980, 108_040, 110_100,
    112_150, 115_200, 117_260, 119_320, 121_380, 123_430, 125_490, 127_540, 12_960, 132_050,
    134_110, 136_170, 138_220, 140_280, 142_340, 144_390, 146_450,
];

/// The QT128's firing times by laser in its two loops, ns (`pandar_qt128.hpp`; 0 for
/// the lasers a loop does not fire).
const QT128_LOOP1_NS: [i64; 128] = [
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    27_656, 53_000, 2_312, 78_344, 81_512, 5_480, 56_168, 30_824, 33_992, 59_336, 8_648, 84_680,
    87_848, 11_816, 62_504, 37_160, 40_328, 65_672, 14_984, 91_016, 94_184, 18_152, 68_840, 43_496,
    46_664, 72_008, 21_320, 97_352, 100_520, 24_488, 75_176, 49_832, 1_456, 77_488, 26_800, 52_144,
    55_312, 29_968, 80_656, 4_624, 7_792, 83_824, 33_136, 58_480, 61_648, 36_304, 86_992, 10_960,
    14_128, 90_160, 39_472, 64_816, 67_984, 42_640, 93_328, 17_296, 20_464, 96_496, 45_808, 71_152,
    74_320, 48_976, 99_664, 23_632, 25_944, 51_288, 600, 76_632, 79_800, 3_768, 54_456, 29_112,
    32_280, 57_624, 6_936, 82_968, 86_136, 10_104, 60_792, 35_448, 38_616, 63_960, 13_272, 89_304,
    92_472, 16_440, 67_128, 41_784, 44_952, 70_296, 19_608, 95_640, 98_808, 22_776, 73_464, 48_120,
];
const QT128_LOOP2_NS: [i64; 128] = [
    2_312, 78_344, 27_656, 53_000, 56_168, 30_824, 81_512, 5_480, 8_648, 84_680, 33_992, 59_336,
    62_504, 37_160, 87_848, 11_816, 14_984, 91_016, 40_328, 65_672, 68_840, 43_496, 94_184, 18_152,
    21_320, 97_352, 46_664, 72_008, 75_176, 49_832, 100_520, 24_488, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 600, 76_632, 25_944, 51_288,
    54_456, 29_112, 79_800, 3_768, 6_936, 82_968, 32_280, 57_624, 60_792, 35_448, 86_136, 10_104,
    13_272, 89_304, 38_616, 63_960, 67_128, 41_784, 92_472, 16_440, 19_608, 95_640, 44_952, 70_296,
    73_464, 48_120, 98_808, 22_776, 26_800, 52_144, 1_456, 77_488, 80_656, 4_624, 55_312, 29_968,
    33_136, 58_480, 7_792, 83_824, 86_992, 10_960, 61_648, 36_304, 39_472, 64_816, 14_128, 90_160,
    93_328, 17_296, 67_984, 42_640, 45_808, 71_152, 20_464, 96_496, 99_664, 23_632, 74_320, 48_976,
];
