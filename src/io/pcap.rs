//! Packet captures (classic `.pcap`, as tcpdump, Wireshark, VeloView and Ouster's
//! SDK write them) of LiDAR packets, read as a log: each UDP port whose datagrams are
//! a LiDAR's is a topic (`/udp_2368`), each datagram a message of the packet type
//! travmap reads it as: Velodyne's and Hesai's (told apart by their bytes) as
//! nebula's `NebulaPackets`, an Ouster's (larger than an Ethernet frame, so IP
//! fragments, put back together here) as ouster_ros's `PacketMsg`. Other ports
//! (Velodyne's position packets, an Ouster's IMU) and other traffic are left out.
//! The capture's time stamps each packet.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::log_message::{Connection, Damage, FileMap, LogMessage};
use super::ouster::{OUSTER_PACKET_MESSAGES, PACKET_MSG_SCHEMA};
use super::packets::{NEBULA_PACKETS, PacketModel};
use super::ros::{Header, NebulaPacket, NebulaPackets, RosMessage, Time, encode};
use crate::error::{Error, Result};

const GLOBAL_HEADER: usize = 24;
const RECORD_HEADER: usize = 16;
/// An Ethernet frame's payload: a datagram past it came in IP fragments.
const ETHERNET_MTU: usize = 1500;

/// How a capture's frames begin (its link type).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Link {
    Ethernet,
    /// Linux "cooked" capture (tcpdump -i any).
    LinuxSll,
    /// IPv4 packets with no link header.
    Ipv4,
}

/// A capture, memory-mapped.
pub struct PcapFile {
    path: PathBuf,
    map: FileMap,
    big_endian: bool,
    /// Time stamps in nanoseconds (else microseconds).
    nanoseconds: bool,
    link: Link,
    /// Where its last whole record ends, and what was said of a cut tail.
    end: usize,
    notice: Option<String>,
}

impl PcapFile {
    pub fn open(path: &Path) -> Result<Self> {
        let map = FileMap::open(path)?;
        let bytes = map.as_ref();
        let problem = |problem: String| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        };
        let magic = bytes
            .get(..4)
            .ok_or_else(|| problem("shorter than a pcap header".into()))?;
        let (big_endian, nanoseconds) = match magic {
            [0xd4, 0xc3, 0xb2, 0xa1] => (false, false),
            [0xa1, 0xb2, 0xc3, 0xd4] => (true, false),
            [0x4d, 0x3c, 0xb2, 0xa1] => (false, true),
            [0xa1, 0xb2, 0x3c, 0x4d] => (true, true),
            _ => return Err(problem("not a pcap capture".into())),
        };
        if bytes.len() < GLOBAL_HEADER {
            return Err(problem("shorter than a pcap header".into()));
        }
        let link = match read_u32(bytes, 20, big_endian) & 0x0FFF_FFFF {
            1 => Link::Ethernet,
            113 => Link::LinuxSll,
            101 | 228 => Link::Ipv4,
            other => {
                return Err(problem(format!(
                    "link type {other}: travmap reads Ethernet, Linux cooked and raw IPv4 captures"
                )));
            }
        };
        let (end, notice) = whole_records(bytes, big_endian);
        let notice = notice.map(|at| {
            format!(
                "{}: the capture ends inside the record at byte {at} (cut short?): reading the records before it",
                path.display()
            )
        });
        Ok(Self {
            path: path.to_path_buf(),
            map,
            big_endian,
            nanoseconds,
            link,
            end,
            notice,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn notice(&self) -> Option<&str> {
        self.notice.as_deref()
    }

    /// The LiDAR packets, in the capture's order.
    pub fn messages(&self) -> impl Iterator<Item = std::result::Result<LogMessage, Damage>> + '_ {
        let mut datagrams = self.datagrams();
        let mut topics: HashMap<u16, Option<Arc<Connection>>> = HashMap::new();
        std::iter::from_fn(move || {
            for (stamp_ns, port, payload) in datagrams.by_ref() {
                let connection = topics
                    .entry(port)
                    .or_insert_with(|| connection(port, &payload));
                let Some(connection) = connection else {
                    continue;
                };
                let data = match connection.schema_name.as_str() {
                    NEBULA_PACKETS => encode(
                        &NebulaPackets {
                            header: Header {
                                stamp: time(stamp_ns),
                                frame_id: connection.topic[1..].to_string(),
                            },
                            packets: vec![NebulaPacket {
                                stamp: time(stamp_ns),
                                data: payload,
                            }],
                        },
                        0,
                    ),
                    _ => packet_msg(&payload),
                };
                return Some(Ok(LogMessage {
                    connection: connection.clone(),
                    log_time_ns: stamp_ns,
                    publish_time_ns: stamp_ns,
                    data,
                }));
            }
            None
        })
    }

    /// Every UDP datagram over IPv4: (capture time, destination port, payload).
    fn datagrams(&self) -> impl Iterator<Item = (u64, u16, Vec<u8>)> + '_ {
        let bytes = &self.map.as_ref()[..self.end];
        let mut at = GLOBAL_HEADER;
        let mut fragments = Fragments::default();
        std::iter::from_fn(move || {
            while at + RECORD_HEADER <= bytes.len() {
                let seconds = u64::from(read_u32(bytes, at, self.big_endian));
                let fraction = u64::from(read_u32(bytes, at + 4, self.big_endian));
                let captured = read_u32(bytes, at + 8, self.big_endian) as usize;
                let frame = &bytes[at + RECORD_HEADER..at + RECORD_HEADER + captured];
                at += RECORD_HEADER + captured;
                let stamp_ns =
                    seconds * 1_000_000_000 + fraction * if self.nanoseconds { 1 } else { 1_000 };
                if let Some((port, payload)) =
                    ipv4(frame, self.link).and_then(|ip| fragments.add(ip))
                {
                    return Some((stamp_ns, port, payload));
                }
            }
            None
        })
    }
}

/// Where the last whole record ends, and where a cut one begins (if one is).
fn whole_records(bytes: &[u8], big_endian: bool) -> (usize, Option<usize>) {
    let mut at = GLOBAL_HEADER;
    while at < bytes.len() {
        if at + RECORD_HEADER > bytes.len() {
            return (at, Some(at));
        }
        let captured = read_u32(bytes, at + 8, big_endian) as usize;
        match (at + RECORD_HEADER).checked_add(captured) {
            Some(next) if next <= bytes.len() => at = next,
            _ => return (at, Some(at)),
        }
    }
    (at, None)
}

/// A port's topic, by its first datagram: a Velodyne or Hesai packet's, an
/// Ouster's (a datagram past an Ethernet frame), or none.
fn connection(port: u16, first: &[u8]) -> Option<Arc<Connection>> {
    let (schema_name, schema) = if PacketModel::of_packet(NEBULA_PACKETS, first).is_ok() {
        (NEBULA_PACKETS, NebulaPackets::SCHEMA)
    } else if first.len() > ETHERNET_MTU {
        (OUSTER_PACKET_MESSAGES[0], PACKET_MSG_SCHEMA)
    } else {
        return None;
    };
    Some(Arc::new(Connection {
        topic: format!("/udp_{port}"),
        schema_name: schema_name.to_string(),
        schema_encoding: "ros2msg".into(),
        schema_data: schema.as_bytes().to_vec(),
        message_encoding: "cdr".into(),
    }))
}

/// An ouster_ros `PacketMsg` (`uint8[] buf`) in CDR.
fn packet_msg(packet: &[u8]) -> Vec<u8> {
    let mut data = Vec::with_capacity(8 + packet.len());
    data.extend_from_slice(&[0, 1, 0, 0]);
    data.extend_from_slice(&(packet.len() as u32).to_le_bytes());
    data.extend_from_slice(packet);
    data
}

fn time(ns: u64) -> Time {
    Time {
        sec: (ns / 1_000_000_000) as i32,
        nanosec: (ns % 1_000_000_000) as u32,
    }
}

fn read_u32(bytes: &[u8], at: usize, big_endian: bool) -> u32 {
    let word = [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]];
    match big_endian {
        true => u32::from_be_bytes(word),
        false => u32::from_le_bytes(word),
    }
}

/// Source, destination and identification: which datagram a fragment is of.
type DatagramKey = ([u8; 4], [u8; 4], u16);

/// A datagram's pieces by offset, and its length once the last is in.
type Pieces = (BTreeMap<usize, Vec<u8>>, Option<usize>);

/// An IPv4 packet of a captured frame.
struct Ipv4<'a> {
    key: DatagramKey,
    protocol: u8,
    /// Where the payload lies in the datagram, in bytes, and whether more follow.
    offset: usize,
    more: bool,
    payload: &'a [u8],
}

/// The IPv4 packet a captured frame carries, if it does.
fn ipv4(frame: &[u8], link: Link) -> Option<Ipv4<'_>> {
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
struct Fragments {
    partial: HashMap<DatagramKey, Pieces>,
}

/// Datagrams missing fragments are dropped past this many in flight.
const PARTIAL_DATAGRAMS: usize = 64;

impl Fragments {
    /// Adds a packet; a whole UDP datagram, once it is: (destination port, payload).
    fn add(&mut self, ip: Ipv4<'_>) -> Option<(u16, Vec<u8>)> {
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
        Some((port, payload.to_vec()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An Ethernet frame (with a VLAN tag when asked) of an IPv4 packet: protocol,
    /// identification, fragment offset in bytes, more fragments, payload.
    fn frame(
        vlan: bool,
        protocol: u8,
        id: u16,
        offset: usize,
        more: bool,
        payload: &[u8],
    ) -> Vec<u8> {
        let mut out = vec![0xFF; 12];
        if vlan {
            out.extend([0x81, 0x00, 0x00, 0x07]);
        }
        out.extend([0x08, 0x00]);
        let total = (20 + payload.len()) as u16;
        let flags = (offset / 8) as u16 | if more { 0x2000 } else { 0 };
        out.extend([0x45, 0]);
        out.extend(total.to_be_bytes());
        out.extend(id.to_be_bytes());
        out.extend(flags.to_be_bytes());
        out.extend([64, protocol, 0, 0, 10, 0, 0, 1, 10, 0, 0, 2]);
        out.extend_from_slice(payload);
        out
    }

    /// A UDP datagram to `port`.
    fn udp(port: u16, payload: &[u8]) -> Vec<u8> {
        let mut out = vec![0x1F, 0x90];
        out.extend(port.to_be_bytes());
        out.extend(((8 + payload.len()) as u16).to_be_bytes());
        out.extend([0, 0]);
        out.extend_from_slice(payload);
        out
    }

    /// A little-endian microsecond capture of `frames` at 1 s + k ms, its last
    /// record cut after `cut` bytes of its frame.
    fn capture(frames: &[Vec<u8>], cut: Option<usize>) -> tempfile::NamedTempFile {
        let mut out = vec![0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0];
        out.extend([0; 8]);
        out.extend(65535u32.to_le_bytes());
        out.extend(1u32.to_le_bytes());
        for (k, frame) in frames.iter().enumerate() {
            out.extend(1u32.to_le_bytes());
            out.extend((k as u32 * 1_000).to_le_bytes());
            out.extend((frame.len() as u32).to_le_bytes());
            out.extend((frame.len() as u32).to_le_bytes());
            out.extend(frame);
        }
        if let Some(cut) = cut {
            out.truncate(out.len() - frames.last().unwrap().len() + cut);
        }
        let file = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(file.path(), out).unwrap();
        file
    }

    #[test]
    fn udp_datagrams_are_read_through_vlan_tags_and_fragments() {
        let small = udp(2368, &[1, 2, 3]);
        let large: Vec<u8> = udp(7502, &(0..3000).map(|i| i as u8).collect::<Vec<_>>());
        let (first, second) = large.split_at(1480);
        let frames = [
            frame(true, 17, 1, 0, false, &small),
            // TCP is not a LiDAR's.
            frame(false, 6, 2, 0, false, &small),
            // The large datagram's fragments, the last first.
            frame(false, 17, 3, 1480, false, second),
            frame(false, 17, 3, 0, true, first),
            frame(false, 17, 4, 0, false, &small),
        ];
        let file = capture(&frames, Some(10));
        let pcap = PcapFile::open(file.path()).unwrap();
        assert!(
            pcap.notice()
                .unwrap()
                .contains("ends inside the record at byte")
        );
        let datagrams: Vec<_> = pcap.datagrams().collect();
        assert_eq!(datagrams.len(), 2);
        assert_eq!(datagrams[0], (1_000_000_000, 2368, vec![1, 2, 3]));
        let (stamp_ns, port, payload) = &datagrams[1];
        assert_eq!(
            (*stamp_ns, *port, payload.len()),
            (1_003_000_000, 7502, 3000)
        );
        assert_eq!(payload[..], large[8..]);
        // The large port reads as an Ouster's packets; the small one as no LiDAR's.
        let topics: Vec<_> = (pcap.messages().map(Result::unwrap))
            .map(|m| (m.connection.topic.clone(), m.connection.schema_name.clone()))
            .collect();
        assert_eq!(
            topics,
            [("/udp_7502".into(), OUSTER_PACKET_MESSAGES[0].to_string())]
        );
    }

    #[test]
    fn what_is_not_a_capture_travmap_reads_is_named() {
        let file = tempfile::NamedTempFile::new().unwrap();
        let mut header = vec![0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0];
        header.extend([0; 12]);
        header.extend(105u32.to_le_bytes());
        std::fs::write(file.path(), &header).unwrap();
        let problem = PcapFile::open(file.path()).err().unwrap().to_string();
        assert!(problem.contains("link type 105"), "{problem}");
        std::fs::write(file.path(), &header[..10]).unwrap();
        let problem = PcapFile::open(file.path()).err().unwrap().to_string();
        assert!(problem.contains("shorter than a pcap header"), "{problem}");
    }
}
