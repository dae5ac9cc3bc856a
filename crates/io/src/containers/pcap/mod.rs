//! Packet captures (classic `.pcap` and pcapng, as tcpdump, Wireshark, VeloView and
//! Ouster's SDK write them) of LiDAR packets, read as a log: each UDP port whose datagrams are
//! a LiDAR's is a topic (`/udp_2368`), each datagram a message of the packet type
//! travmap reads it as: Velodyne's, Hesai's and RoboSense's (told apart by their
//! bytes) as nebula's `NebulaPackets` (a RoboSense's DIFOP port joining its data
//! port's topic), an Ouster's (larger than an Ethernet frame, so IP fragments, put
//! back together here) as ouster_ros's `PacketMsg`. Other ports (Velodyne's position
//! packets, an Ouster's IMU) and other traffic are left out.
//! The capture's time stamps each packet.

mod records;
mod udp;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use records::{Damaged, Layout};
use udp::{Fragments, ipv4};

use crate::packets::ouster::{OUSTER_PACKET_MESSAGES, PACKET_MSG_SCHEMA};
use crate::packets::robosense::RobosenseModel;
use crate::packets::{NEBULA_PACKETS, PacketModel};
use travmap_core::error::{Error, Result};
use travmap_formats::log_message::{ChunkSpan, Connection, Damage, FileMap, LogMessage};
use travmap_formats::ros::{Header, NebulaPacket, NebulaPackets, RosMessage, Time, encode};

/// An Ethernet frame's payload: a datagram past it came in IP fragments.
const ETHERNET_MTU: usize = 1500;

/// A capture, memory-mapped.
pub struct PcapFile {
    path: PathBuf,
    map: FileMap,
    layout: Layout,
    /// What was said of a cut tail.
    notice: Option<String>,
}

impl PcapFile {
    pub fn open(path: &Path) -> Result<Self> {
        let map = FileMap::open(path)?;
        let layout = records::read(map.as_ref()).map_err(|problem| Error::LogContainer {
            path: path.to_path_buf(),
            problem,
        })?;
        let notice = layout.cut.map(|at| {
            format!(
                "{}: the capture ends inside the record at byte {at} (cut short?): reading the records before it",
                path.display()
            )
        });
        Ok(Self {
            path: path.to_path_buf(),
            map,
            layout,
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
        // A RoboSense sends its DIFOP to a port of its own: they join its data's topic.
        let mut robosense: Option<Arc<Connection>> = None;
        std::iter::from_fn(move || {
            for datagram in datagrams.by_ref() {
                let Datagram {
                    at,
                    stamp_ns,
                    port,
                    payload,
                    cut_from,
                } = match datagram {
                    Ok(datagram) => datagram,
                    Err(stretch) => return Some(Err(damage(stretch))),
                };
                let connection = topics.entry(port).or_insert_with(|| {
                    let connection = connection(port, &payload);
                    if let Some(c) = connection.as_ref().filter(|_| is_robosense(&payload)) {
                        robosense.get_or_insert_with(|| c.clone());
                    }
                    connection
                });
                let connection = match (connection, &robosense) {
                    (Some(connection), _) => connection,
                    (None, Some(data)) if RobosenseModel::is_difop(&payload) => data,
                    (None, _) => continue,
                };
                // A LiDAR packet the capture holds only part of (its snap length cut
                // it) is lost, as a damaged record is: no decoder can read it.
                if let Some(whole) = cut_from {
                    return Some(Err(Damage {
                        problem: format!(
                            "the record at byte {at} holds {} of its {whole}-byte packet (the capture's snap length cut it?)",
                            payload.len()
                        ),
                        chunk: Some(ChunkSpan {
                            bytes: at..at,
                            start_ns: stamp_ns,
                            end_ns: stamp_ns,
                            lost: Vec::new(),
                        }),
                    }));
                }
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
    /// The capture's UDP datagrams in words: the ports with the most, each with
    /// its count and the sizes seen ("none" when it holds no UDP over IPv4).
    pub fn datagrams_by_port(&self) -> String {
        // Port -> (datagrams, smallest and largest payload bytes).
        let mut ports: HashMap<u16, (usize, usize, usize)> = HashMap::new();
        for Datagram { port, payload, .. } in self.datagrams().flatten() {
            let (count, smallest, largest) = ports.entry(port).or_insert((0, usize::MAX, 0));
            *count += 1;
            *smallest = (*smallest).min(payload.len());
            *largest = (*largest).max(payload.len());
        }
        let mut ports: Vec<_> = ports.into_iter().collect();
        ports.sort_by_key(|&(port, (count, _, _))| (std::cmp::Reverse(count), port));
        let said: Vec<String> = (ports.iter().take(5))
            .map(|(port, (count, smallest, largest))| {
                let sizes = match smallest == largest {
                    true => format!("{smallest} bytes"),
                    false => format!("{smallest}-{largest} bytes"),
                };
                format!("port {port}: {count} of {sizes}")
            })
            .collect();
        match ports.len() {
            0 => "none".into(),
            n if n > 5 => format!("{} and {} more ports", said.join(", "), n - 5),
            _ => said.join(", "),
        }
    }

    /// Every UDP datagram over IPv4, and the damaged stretches between them.
    fn datagrams(&self) -> impl Iterator<Item = Result<Datagram, Damaged>> + '_ {
        let mut fragments = Fragments::default();
        records::records(self.map.as_ref(), &self.layout).filter_map(move |record| {
            let Ok((at, stamp_ns, link, frame)) = record else {
                return Some(Err(record.err()?));
            };
            let (port, payload, cut_from) = fragments.add(ipv4(frame, link)?)?;
            Some(Ok(Datagram {
                at,
                stamp_ns,
                port,
                payload,
                cut_from,
            }))
        })
    }
}

/// A UDP datagram of a capture.
#[derive(Debug)]
struct Datagram {
    /// Where its (last) record begins in the file.
    at: usize,
    /// The capture's time of it, ns.
    stamp_ns: u64,
    /// Its destination port.
    port: u16,
    payload: Vec<u8>,
    /// The payload's length by its header, when the capture holds less of it.
    cut_from: Option<usize>,
}

/// A damaged stretch as a reader's damage: the records in it are lost, reading goes
/// on after it (`--keep-going`).
fn damage(stretch: Damaged) -> Damage {
    let end_ns = stretch.before_ns.unwrap_or(stretch.after_ns);
    let problem = match stretch.to_end {
        false => format!(
            "a record header no capture tool writes at byte {}: the records to byte {} are lost, read again from there",
            stretch.start, stretch.resume
        ),
        true => format!(
            "a record header no capture tool writes at byte {}, and none reads right after it: the rest of the capture is lost",
            stretch.start
        ),
    };
    Damage {
        problem,
        chunk: Some(ChunkSpan {
            bytes: stretch.start..stretch.resume,
            start_ns: stretch.after_ns.min(end_ns),
            end_ns,
            lost: Vec::new(),
        }),
    }
}

fn is_robosense(packet: &[u8]) -> bool {
    matches!(
        PacketModel::of_packet(NEBULA_PACKETS, packet),
        Ok(PacketModel::Robosense(_))
    )
}

/// A port's topic, by its first datagram: a Velodyne, Hesai or RoboSense data
/// packet's, an Ouster's (a datagram past an Ethernet frame), or none (a RoboSense's
/// DIFOP port among them).
fn connection(port: u16, first: &[u8]) -> Option<Arc<Connection>> {
    let (schema_name, schema) = if RobosenseModel::is_difop(first) {
        return None;
    } else if PacketModel::of_packet(NEBULA_PACKETS, first).is_ok() {
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
        let datagrams: Vec<_> = (pcap.datagrams().flatten())
            .map(|d| (d.stamp_ns, d.port, d.payload))
            .collect();
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
    fn reading_steps_over_a_damaged_record_header_to_where_records_read_right() {
        let small = udp(2368, &[1, 2, 3]);
        let frames: Vec<Vec<u8>> = (0..4)
            .map(|k| frame(true, 17, k, 0, false, &small))
            .collect();
        let file = capture(&frames, None);
        let whole = std::fs::read(file.path()).unwrap();
        let record = |k: usize| 24 + (0..k).map(|j| 16 + frames[j].len()).sum::<usize>();
        let (second, third) = (record(1), record(2));
        let packet = frames[1].len() as u32;
        // The second record's captured length: past the snap length, past its
        // packet's own length, or shorter than its frame (a length that reads, the
        // walk then lands inside the frame and finds a header no writer gives).
        for (damaged, found_at, after_ns) in [
            (0x7fff_ffff, second, 1_000_000_000),
            (packet + 1, second, 1_000_000_000),
            (10, second + 16 + 10, 1_001_000_000),
        ] {
            let mut bytes = whole.clone();
            bytes[second + 8..second + 12].copy_from_slice(&damaged.to_le_bytes());
            std::fs::write(file.path(), &bytes).unwrap();
            let pcap = PcapFile::open(file.path()).unwrap();
            let read: Vec<_> = pcap.datagrams().collect();
            let stamps: Vec<u64> = read.iter().flatten().map(|d| d.stamp_ns).collect();
            assert_eq!(stamps, [1_000_000_000, 1_002_000_000, 1_003_000_000]);
            let stretch = read.iter().find_map(|d| d.as_ref().err()).unwrap();
            assert_eq!((stretch.start, stretch.resume), (found_at, third));
            let damage = pcap.messages().find_map(Result::err).unwrap();
            assert!(
                damage.problem.contains(&format!("byte {found_at}")),
                "{damage:?}"
            );
            let span = damage.chunk.unwrap();
            assert_eq!((span.start_ns, span.end_ns), (after_ns, 1_002_000_000));
        }
        // In the last record, nothing after it reads: the rest is lost, named.
        let mut bytes = whole.clone();
        let last = record(3);
        bytes[last + 8..last + 12].copy_from_slice(&0x7fff_ffffu32.to_le_bytes());
        std::fs::write(file.path(), &bytes).unwrap();
        let pcap = PcapFile::open(file.path()).unwrap();
        assert_eq!(pcap.datagrams().flatten().count(), 3);
        let damage = pcap.messages().find_map(Result::err).unwrap();
        assert!(
            damage.problem.contains("the rest of the capture is lost"),
            "{damage:?}"
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
