//! An Ouster lidar packet's layout, as each UDP profile lays it out (the sensor
//! documentation's "Lidar Data Packet Format"; `tests/ouster.rs` checks it against
//! packets the official SDK writes).
//!
//! LEGACY: columns of {timestamp u64 ns, measurement id u16, frame id u16, encoder
//! count u32}, a pixel per beam, and a status u32 (all ones when valid). The other
//! profiles: a 32-byte packet header (packet type u16, frame id u16, ...), columns of
//! {timestamp u64, measurement id u16, status u16 (bit 0: valid)} and pixels, and a
//! 32-byte footer; the FUSA profile's header holds a frame id of 32 bits at byte 4.
//! Everything little-endian.

/// The packet layout a sensor streams (`udp_profile_lidar`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// 12-byte pixels: range u32 (20 bits, mm), reflectivity, signal, near-IR u16.
    Legacy,
    /// 12-byte pixels: range u32 (19 bits, mm), reflectivity u8, signal and
    /// near-IR u16 (the default since firmware 2.2).
    Rng19Rfl8Sig16Nir16,
    /// 16-byte pixels: two returns of range (19 bits) and reflectivity (the top
    /// byte) each, then signals and near-IR.
    Rng19Rfl8Sig16Nir16Dual,
    /// 4-byte pixels ("low data rate"): range u16 (15 bits, in 8 mm), reflectivity
    /// u8, near-IR u8.
    Rng15Rfl8Nir8,
    /// 8-byte pixels: two returns of range u16 (15 bits, in 8 mm) and reflectivity
    /// u8 each, near-IR and window bytes between.
    Rng15Rfl8Nir8Dual,
    /// The same pixels in the functional-safety packet, whose header differs.
    FusaRng15Rfl8Nir8Dual,
}

/// Every profile travmap reads, by its name.
const PROFILES: [(Profile, &str); 6] = [
    (Profile::Legacy, "LEGACY"),
    (Profile::Rng19Rfl8Sig16Nir16, "RNG19_RFL8_SIG16_NIR16"),
    (
        Profile::Rng19Rfl8Sig16Nir16Dual,
        "RNG19_RFL8_SIG16_NIR16_DUAL",
    ),
    (Profile::Rng15Rfl8Nir8, "RNG15_RFL8_NIR8"),
    (Profile::Rng15Rfl8Nir8Dual, "RNG15_RFL8_NIR8_DUAL"),
    (Profile::FusaRng15Rfl8Nir8Dual, "FUSA_RNG15_RFL8_NIR8_DUAL"),
];

impl Profile {
    pub fn from_name(name: &str) -> Result<Self, String> {
        match PROFILES.iter().find(|(_, n)| *n == name) {
            Some((profile, _)) => Ok(*profile),
            None => {
                let names: Vec<&str> = PROFILES.iter().map(|(_, n)| *n).collect();
                Err(format!(
                    "UDP profile `{name}`: travmap reads {}",
                    names.join(", ")
                ))
            }
        }
    }

    pub fn name(self) -> &'static str {
        let (_, name) = PROFILES
            .iter()
            .find(|(p, _)| *p == self)
            .expect("every profile is listed");
        name
    }

    /// Whether its packets have the functional-safety header.
    pub fn is_fusa(self) -> bool {
        self == Self::FusaRng15Rfl8Nir8Dual
    }

    fn pixel_bytes(self) -> usize {
        match self {
            Self::Legacy | Self::Rng19Rfl8Sig16Nir16 => 12,
            Self::Rng19Rfl8Sig16Nir16Dual => 16,
            Self::Rng15Rfl8Nir8 => 4,
            Self::Rng15Rfl8Nir8Dual | Self::FusaRng15Rfl8Nir8Dual => 8,
        }
    }

    /// Bytes before the first column, and after the last.
    fn packet_header_footer(self) -> (usize, usize) {
        match self {
            Self::Legacy => (0, 0),
            _ => (32, 32),
        }
    }

    /// Bytes before a column's pixels, and after them.
    fn column_header_footer(self) -> (usize, usize) {
        match self {
            Self::Legacy => (16, 4),
            _ => (12, 0),
        }
    }

    /// A pixel's returns: (range mm, reflectivity), the second 0 when there is
    /// none.
    #[inline]
    pub(super) fn returns(self, pixel: &[u8]) -> [(u32, u8); 2] {
        let word = |at: usize| {
            u32::from_le_bytes([pixel[at], pixel[at + 1], pixel[at + 2], pixel[at + 3]])
        };
        // 15 bits of range in units of 8 mm.
        let coarse = |at: usize| (u32::from(pixel[at]) | u32::from(pixel[at + 1] & 0x7F) << 8) * 8;
        match self {
            Self::Legacy => [(word(0) & 0xF_FFFF, pixel[4]), (0, 0)],
            Self::Rng19Rfl8Sig16Nir16 => [(word(0) & 0x7_FFFF, pixel[4]), (0, 0)],
            Self::Rng19Rfl8Sig16Nir16Dual => [
                (word(0) & 0x7_FFFF, pixel[3]),
                (word(4) & 0x7_FFFF, pixel[7]),
            ],
            Self::Rng15Rfl8Nir8 => [(coarse(0), pixel[2]), (0, 0)],
            Self::Rng15Rfl8Nir8Dual | Self::FusaRng15Rfl8Nir8Dual => {
                [(coarse(0), pixel[2]), (coarse(4), pixel[6])]
            }
        }
    }
}

/// A sensor's packet layout, from its metadata (the packets alone do not tell it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OusterModel {
    pub profile: Profile,
    pub pixels_per_column: u16,
    pub columns_per_packet: u16,
    pub columns_per_frame: u16,
}

/// One column of a packet.
pub(super) struct Column<'a> {
    pub(super) timestamp_ns: u64,
    pub(super) measurement_id: u16,
    pub(super) valid: bool,
    /// The pixels, `pixel_bytes` each, beam by beam.
    pub(super) pixels: &'a [u8],
}

impl OusterModel {
    pub fn name(self) -> &'static str {
        match self.pixels_per_column {
            16 => "Ouster (16 beams)",
            32 => "Ouster (32 beams)",
            64 => "Ouster (64 beams)",
            128 => "Ouster (128 beams)",
            _ => "Ouster",
        }
    }

    fn column_bytes(self) -> usize {
        let (header, footer) = self.profile.column_header_footer();
        header + usize::from(self.pixels_per_column) * self.profile.pixel_bytes() + footer
    }

    pub fn packet_bytes(self) -> usize {
        let (header, footer) = self.profile.packet_header_footer();
        header + usize::from(self.columns_per_packet) * self.column_bytes() + footer
    }

    pub(super) fn pixel_bytes(self) -> usize {
        self.profile.pixel_bytes()
    }

    /// The packet's length checked; its frame id.
    pub(super) fn frame_id(self, packet: &[u8]) -> Result<u32, String> {
        let expected = self.packet_bytes();
        if packet.len() != expected {
            return Err(format!(
                "a packet of {} bytes where the metadata's {} {} packets are {expected}",
                packet.len(),
                self.name(),
                self.profile.name()
            ));
        }
        let u16_at = |at: usize| u32::from(u16::from_le_bytes([packet[at], packet[at + 1]]));
        Ok(match self.profile {
            // LEGACY repeats it in every column; the first one's counts.
            Profile::Legacy => u16_at(10),
            profile if profile.is_fusa() => {
                u32::from_le_bytes([packet[4], packet[5], packet[6], packet[7]])
            }
            _ => u16_at(2),
        })
    }

    /// The columns of a packet whose length [`Self::frame_id`] checked.
    pub(super) fn columns(self, packet: &[u8]) -> impl Iterator<Item = Column<'_>> {
        let (header, _) = self.profile.packet_header_footer();
        let (column_header, column_footer) = self.profile.column_header_footer();
        let bytes = self.column_bytes();
        let legacy = self.profile == Profile::Legacy;
        packet[header..]
            .chunks_exact(bytes)
            .take(usize::from(self.columns_per_packet))
            .map(move |column| {
                let u16_at = |at: usize| u16::from_le_bytes([column[at], column[at + 1]]);
                let valid = match legacy {
                    true => column[bytes - 4..].iter().all(|&b| b == 0xFF),
                    false => u16_at(10) & 1 == 1,
                };
                Column {
                    timestamp_ns: u64::from_le_bytes(column[..8].try_into().expect("8 bytes")),
                    measurement_id: u16_at(8),
                    valid,
                    pixels: &column[column_header..bytes - column_footer],
                }
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Pixels as the SDK 1.0.1 wrote them for range 1000 mm and every other field 3
    // (tests/ouster.rs checks whole packets against it).
    #[test]
    fn each_profile_reads_range_and_reflectivity_where_the_sdk_writes_them() {
        type Returns = [(u32, u8); 2];
        let cases: [(Profile, &str, Returns); 4] = [
            (
                Profile::Legacy,
                "e80300300300030003000000",
                [(1000, 3), (0, 0)],
            ),
            (
                Profile::Rng19Rfl8Sig16Nir16,
                "e80318000300030003000000",
                [(1000, 3), (0, 0)],
            ),
            (
                Profile::Rng19Rfl8Sig16Nir16Dual,
                "e8031803030018030300030003000000",
                [(1000, 3), (3, 3)],
            ),
            (Profile::Rng15Rfl8Nir8, "7d800300", [(1000, 3), (0, 0)]),
        ];
        for (profile, hex, returns) in cases {
            let bytes: Vec<u8> = (0..hex.len() / 2)
                .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                .collect();
            assert_eq!(profile.returns(&bytes), returns, "{}", profile.name());
        }
    }

    #[test]
    fn packet_sizes_are_the_sdks() {
        // PacketFormat.lidar_packet_size of an OS1-64 at 1024x10, SDK 1.0.1.
        let size = |profile| {
            OusterModel {
                profile,
                pixels_per_column: 64,
                columns_per_packet: 16,
                columns_per_frame: 1024,
            }
            .packet_bytes()
        };
        assert_eq!(size(Profile::Legacy), 12_608);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16), 12_544);
        assert_eq!(size(Profile::Rng19Rfl8Sig16Nir16Dual), 16_640);
        assert_eq!(size(Profile::Rng15Rfl8Nir8), 4_352);
    }
}
