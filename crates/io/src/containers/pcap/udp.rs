//! UDP datagrams over IPv4 in a captured frame, put back together from their IP
//! fragments.

use std::collections::{BTreeMap, HashMap};

use super::records::Link;

/// Source, destination and identification: which datagram a fragment is of.
type DatagramKey = ([u8; 4], [u8; 4], u16);

/// A datagram's pieces by offset, and its length once the last is in.
type Pieces = (BTreeMap<usize, Vec<u8>>, Option<usize>);

/// An IPv4 packet of a captured frame.
pub(super) struct Ipv4<'a> {
    key: DatagramKey,
    protocol: u8,
    /// Where the payload lies in the datagram, in bytes, and whether more follow.
    offset: usize,
    more: bool,
    payload: &'a [u8],
}

/// The IPv4 packet a captured frame carries, if it does.
pub(super) fn ipv4(frame: &[u8], link: Link) -> Option<Ipv4<'_>> {
    let be16 = |b: &[u8], at: usize| Some(u16::from_be_bytes([*b.get(at)?, *b.get(at + 1)?]));
    let packet = match link {
        Link::Ipv4 => frame,
        Link::Ethernet => {
            let mut at = 12;
            // 802.1Q and 802.1ad tags before the type.
            while matches!(be16(frame, at)?, 0x8100 | 0x88A8) {
                at += 4;
            }
            (be16(frame, at)? == 0x0800).then_some(())?;
            frame.get(at + 2..)?
        }
        Link::LinuxSll => {
            (be16(frame, 14)? == 0x0800).then_some(())?;
            frame.get(16..)?
        }
    };
    let header = usize::from(packet.first()? & 0x0F) * 4;
    if packet[0] >> 4 != 4 || header < 20 {
        return None;
    }
    let total = usize::from(be16(packet, 2)?).min(packet.len());
    let flags_offset = be16(packet, 6)?;
    Some(Ipv4 {
        key: (
            packet.get(12..16)?.try_into().ok()?,
            packet.get(16..20)?.try_into().ok()?,
            be16(packet, 4)?,
        ),
        protocol: *packet.get(9)?,
        offset: usize::from(flags_offset & 0x1FFF) * 8,
        more: flags_offset & 0x2000 != 0,
        payload: packet.get(header..total)?,
    })
}

/// IPv4 datagrams being put back together from their fragments.
#[derive(Default)]
pub(super) struct Fragments {
    partial: HashMap<DatagramKey, Pieces>,
}

/// Datagrams missing fragments are dropped past this many in flight.
const PARTIAL_DATAGRAMS: usize = 64;

impl Fragments {
    /// Adds a packet; a whole UDP datagram, once it is: (destination port, payload,
    /// and the payload's length its header gives when the capture holds less).
    pub(super) fn add(&mut self, ip: Ipv4<'_>) -> Option<(u16, Vec<u8>, Option<usize>)> {
        if ip.protocol != 17 {
            return None;
        }
        let datagram = if ip.offset == 0 && !ip.more {
            ip.payload.to_vec()
        } else {
            if self.partial.len() >= PARTIAL_DATAGRAMS && !self.partial.contains_key(&ip.key) {
                self.partial.clear();
            }
            let (pieces, length) = self.partial.entry(ip.key).or_default();
            pieces.insert(ip.offset, ip.payload.to_vec());
            if !ip.more {
                *length = Some(ip.offset + ip.payload.len());
            }
            let length = (*length)?;
            let mut whole = Vec::with_capacity(length);
            for (&offset, piece) in pieces.iter() {
                if offset != whole.len() {
                    return None;
                }
                whole.extend_from_slice(piece);
            }
            if whole.len() != length {
                return None;
            }
            self.partial.remove(&ip.key);
            whole
        };
        // The UDP header: ports, length, checksum.
        let port = u16::from_be_bytes([*datagram.get(2)?, *datagram.get(3)?]);
        let length = usize::from(u16::from_be_bytes([*datagram.get(4)?, *datagram.get(5)?]));
        let payload = datagram.get(8..length.clamp(8, datagram.len()))?;
        let cut = (length > datagram.len()).then(|| length - 8);
        Some((port, payload.to_vec(), cut))
    }
}
