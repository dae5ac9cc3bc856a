//! The messages every vendor's packets travel in, ROS 2 (CDR) and ROS 1, read in
//! place: a header, then the packets, each after its stamp.

use travmap_formats::ros::MessageEncoding;

/// A message of LiDAR packets (Velodyne's VelodyneScan, Hesai's PandarScan,
/// RoboSense's, Ouster's, nebula's): its header and its packets (each stamp in ns,
/// and the packet's bytes).
pub struct ScanMessage<'a> {
    pub frame_id: String,
    pub stamp_ns: u64,
    pub packets: Vec<(u64, &'a [u8])>,
}

/// How a packet message holds each packet's bytes, after its `time stamp`.
#[derive(Clone, Copy)]
pub(crate) enum PacketField {
    /// `uint8[N] data`: the packet (Velodyne's).
    Fixed(usize),
    /// `uint8[N] data`, `uint32 size`: the packet is the first `size` bytes (Hesai's).
    FixedSized(usize),
    /// `uint8 flag`, then as `FixedSized` (RoboSense's).
    FlagThenFixedSized(usize),
    /// `uint8[] data` (nebula's).
    Sequence,
}

/// Reads a message of a header and packets (`time stamp`, then the packet as
/// `field` says), as Velodyne's, Hesai's, RoboSense's and nebula's packet messages are, without
/// copying the packets.
pub(crate) fn packets_message(
    data: &[u8],
    encoding: MessageEncoding,
    field: PacketField,
) -> Result<ScanMessage<'_>, String> {
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
    // A packet takes at least its stamp and its length.
    let least_bytes = match field {
        PacketField::Fixed(bytes)
        | PacketField::FixedSized(bytes)
        | PacketField::FlagThenFixedSized(bytes) => bytes,
        PacketField::Sequence => 12,
    };
    if count > data.len() / least_bytes {
        return Err(format!("{count} packets claimed in {} bytes", data.len()));
    }
    let mut packets = Vec::with_capacity(count);
    for _ in 0..count {
        let stamp = reader.stamp(encoding)?;
        let packet = match field {
            PacketField::Fixed(bytes) => reader.bytes(bytes)?,
            PacketField::FixedSized(bytes) | PacketField::FlagThenFixedSized(bytes) => {
                if matches!(field, PacketField::FlagThenFixedSized(_)) {
                    reader.bytes(1)?;
                }
                let packet = reader.bytes(bytes)?;
                let size = reader.u32()? as usize;
                packet
                    .get(..size)
                    .ok_or_else(|| format!("a packet of size {size} in a field of {bytes} bytes"))?
            }
            PacketField::Sequence => {
                let length = reader.u32()? as usize;
                reader.bytes(length)?
            }
        };
        packets.push((stamp, packet));
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
