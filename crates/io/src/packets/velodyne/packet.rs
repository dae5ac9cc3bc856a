//! The layout of a Velodyne data packet and the model it names.

pub const PACKET_BYTES: usize = 1206;
pub(super) const BLOCKS: usize = 12;
pub(super) const BLOCK_BYTES: usize = 100;
pub(super) const RETURN_MODE_AT: usize = 1204;
pub(super) const PRODUCT_AT: usize = 1205;
pub(super) const DUAL_RETURN: u8 = 0x39;
/// Block flags: the upper bank, and the VLS-128's other three.
pub(super) const BANK_FLAGS: [u16; 4] = [0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF];
pub(super) const CENTIDEGREES: u32 = 36_000;

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
