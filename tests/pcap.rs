//! Packet captures of LiDAR packets: nebula's packet logs (`fixtures/nebula/`)
//! written again as pcap (and pcapng) files by scapy (Ethernet, IPv4, UDP, each packet stamped
//! with its recorded time, as tcpdump or Wireshark capture a sensor) read as the same
//! drive, frame for frame and cell for cell. Ouster's SDK's own pcap writer is
//! checked in `tests/ouster.rs`. Needs `TRAVMAP_CLIENT_PYTHON` (scapy).

use std::path::Path;
use std::process::Command;

use crate::common::{arg, assert_contains, nebula_fixture, run_client};
use travmap_io::InputFormat;
use travmap_io::Log;
use travmap_io::packet_message;

/// Every packet of a packet log, as `write_pcap.py` reads them.
fn packets_file(log: &Path, out: &Path) {
    let mut bytes = Vec::new();
    for message in Log::open(log, InputFormat::Rosbag2).unwrap().messages() {
        let message = message.unwrap();
        let type_name = message.connection.type_name().into_owned();
        let encoding = message.connection.encoding().unwrap();
        for (stamp_ns, packet) in
            packet_message(&type_name, &message.data, encoding, message.log_time_ns)
                .unwrap()
                .packets
        {
            bytes.extend(stamp_ns.to_le_bytes());
            bytes.extend((packet.len() as u32).to_le_bytes());
            bytes.extend_from_slice(packet);
        }
    }
    std::fs::write(out, bytes).unwrap();
}

/// What `run --json` says of each frame: its stamp and its cells.
fn frames(input: &Path) -> Vec<(serde_json::Value, serde_json::Value)> {
    let output = crate::common::travmap(&["run", input.to_str().unwrap(), "--json"]);
    let (frames, _) = crate::common::json_records(&crate::common::success(output));
    frames
        .into_iter()
        .map(|f| (f["stamp_ns"].clone(), f["cells"].clone()))
        .collect()
}

fn a_capture_is_its_packet_log(bag: &str, extra: &[&str]) {
    let Some(python) = crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "the client venv's python")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let log = nebula_fixture(bag);
    let packets = dir.path().join("packets.bin");
    packets_file(&log, &packets);
    let capture = dir.path().join("capture.pcap");
    run_client(
        Command::new(python)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/write_pcap.py"))
            .args([&packets, &capture])
            .arg("2368")
            .args(extra),
    );
    let expected = frames(&log);
    assert!(expected.len() >= 2, "{bag}: {} frames", expected.len());
    let read = frames(&capture);
    assert_eq!(read.len(), expected.len(), "{bag}: frames");
    // A capture in microseconds stamps a packet to its microsecond.
    let tolerance_ns = if extra.contains(&"--nanoseconds") {
        0
    } else {
        999
    };
    for (k, ((stamp, cells), (expected_stamp, expected_cells))) in
        read.iter().zip(&expected).enumerate()
    {
        let (stamp, expected_stamp) = (stamp.as_u64().unwrap(), expected_stamp.as_u64().unwrap());
        assert!(
            stamp.abs_diff(expected_stamp) <= tolerance_ns,
            "{bag} frame {k}: stamp {stamp} for {expected_stamp}"
        );
        assert!(cells == expected_cells, "{bag} frame {k}: other cells");
    }
}

#[test]
#[ignore = "needs scapy: source .ci/clients.sh && cargo test --release -- --ignored"]
fn a_velodyne_capture_reads_as_its_packet_log() {
    a_capture_is_its_packet_log("vlp16/1673400471837873222", &[]);
}

#[test]
#[ignore = "needs scapy: source .ci/clients.sh && cargo test --release -- --ignored"]
fn a_pcapng_capture_reads_as_its_packet_log() {
    a_capture_is_its_packet_log("vlp16/1673400471837873222", &["--pcapng"]);
}

#[test]
#[ignore = "needs scapy: source .ci/clients.sh && cargo test --release -- --ignored"]
fn a_hesai_capture_with_vlan_tags_and_nanosecond_stamps_reads_as_its_packet_log() {
    a_capture_is_its_packet_log("xt32/1673400677802009732", &["--nanoseconds", "--vlan"]);
}

/// A classic Ethernet pcap of UDP datagrams: (destination port, payload bytes) each,
/// a second apart.
fn udp_capture(datagrams: &[(u16, usize)]) -> Vec<u8> {
    let payloads: Vec<(u64, u16, Vec<u8>)> = (datagrams.iter().enumerate())
        .map(|(n, &(port, bytes))| (n as u64 * 1_000_000_000, port, vec![7u8; bytes]))
        .collect();
    udp_capture_of(&payloads)
}

/// A classic Ethernet pcap (microseconds) of UDP datagrams: (capture time in ns,
/// destination port, payload) each.
fn udp_capture_of(datagrams: &[(u64, u16, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    for word in [0xa1b2_c3d4u32.to_le_bytes(), [2, 0, 4, 0], [0; 4], [0; 4]] {
        out.extend(word);
    }
    out.extend(65_535u32.to_le_bytes());
    out.extend(1u32.to_le_bytes());
    for (n, (stamp_ns, port, payload)) in datagrams.iter().enumerate() {
        let mut frame = vec![0u8; 12];
        frame.extend([0x08, 0x00]);
        let ip_length = (20 + 8 + payload.len()) as u16;
        frame.extend([0x45, 0]);
        frame.extend(ip_length.to_be_bytes());
        frame.extend([0, n as u8, 0, 0, 64, 17, 0, 0, 10, 0, 0, 1, 10, 0, 0, 2]);
        frame.extend(40_000u16.to_be_bytes());
        frame.extend(port.to_be_bytes());
        frame.extend(((8 + payload.len()) as u16).to_be_bytes());
        frame.extend([0, 0]);
        frame.extend(payload);
        let (seconds, micros) = (stamp_ns / 1_000_000_000, stamp_ns % 1_000_000_000 / 1_000);
        for value in [
            seconds as u32,
            micros as u32,
            frame.len() as u32,
            frame.len() as u32,
        ] {
            out.extend(value.to_le_bytes());
        }
        out.extend(frame);
    }
    out
}

/// A RoboSense's capture, its data sent to port 6699 and its DIFOP to 7788 as the
/// sensor sends them, reads as its packet log: the same frames, the same cells (the
/// DIFOP, on a port of its own, still reaches the data's decoder).
#[test]
fn a_robosense_capture_with_its_difop_port_reads_as_its_packet_log() {
    let log = nebula_fixture("helios16p/rosbag2_2023_08_03-11_02_46");
    let mut datagrams = Vec::new();
    for message in Log::open(&log, InputFormat::Rosbag2).unwrap().messages() {
        let message = message.unwrap();
        let type_name = message.connection.type_name().into_owned();
        let encoding = message.connection.encoding().unwrap();
        let scan = packet_message(&type_name, &message.data, encoding, message.log_time_ns);
        for (stamp_ns, packet) in scan.unwrap().packets {
            let port = if packet.starts_with(&[0xA5, 0xFF]) {
                7788
            } else {
                6699
            };
            datagrams.push((stamp_ns, port, packet.to_vec()));
        }
    }
    assert!(
        datagrams.iter().any(|d| d.1 == 7788),
        "the log holds a DIFOP"
    );
    let dir = tempfile::tempdir().unwrap();
    let capture = dir.path().join("helios.pcap");
    std::fs::write(&capture, udp_capture_of(&datagrams)).unwrap();
    let mut topics = std::collections::BTreeMap::new();
    for message in Log::open(&capture, InputFormat::Pcap).unwrap().messages() {
        let message = message.unwrap();
        let encoding = message.connection.encoding().unwrap();
        let type_name = message.connection.type_name().into_owned();
        let scan = packet_message(&type_name, &message.data, encoding, message.log_time_ns);
        let difop = scan.unwrap().packets[0].1.starts_with(&[0xA5, 0xFF]);
        *topics
            .entry((message.connection.topic.clone(), difop))
            .or_insert(0) += 1;
    }
    assert_eq!(
        topics.into_iter().collect::<Vec<_>>(),
        [
            (("/udp_6699".to_string(), false), 750),
            (("/udp_6699".to_string(), true), 1)
        ],
        "one topic, the DIFOP on it"
    );
    let (expected, read) = (frames(&log), frames(&capture));
    assert_eq!(read.len(), expected.len(), "frames");
    assert!(expected.len() >= 4, "{} frames", expected.len());
    for (k, ((stamp, cells), (expected_stamp, expected_cells))) in
        read.iter().zip(&expected).enumerate()
    {
        let (stamp, expected_stamp) = (stamp.as_u64().unwrap(), expected_stamp.as_u64().unwrap());
        assert!(
            stamp.abs_diff(expected_stamp) <= 999,
            "frame {k}: stamp {stamp} for {expected_stamp}"
        );
        assert!(cells == expected_cells, "frame {k}: other cells");
    }

    // A record length that still reads, but is wrong (1,400 bytes of a 1,290-byte
    // frame, the packet's own length made to agree): the walk lands inside the next
    // packet, on a header no writer gives. Without --keep-going, an error naming
    // the byte; with it, the records from there to where they read right again are
    // stepped over, the frames around them skipped and reported (exit 3), every
    // other frame as before.
    let mut bytes = std::fs::read(&capture).unwrap();
    let record = |k: usize| 24 + k * (16 + 42 + 1248);
    let damaged = record(300);
    for field in [8, 12] {
        bytes[damaged + field..damaged + field + 4].copy_from_slice(&1400u32.to_le_bytes());
    }
    let broken = dir.path().join("broken.pcap");
    std::fs::write(&broken, &bytes).unwrap();
    let lands = damaged + 16 + 1400;
    let said = format!("record header no capture tool writes at byte {lands}");
    let err = crate::common::clean_failure(crate::common::travmap(&["run", arg(&broken)]));
    assert_contains(&err, &[&said, "read again from there"]);
    let (kept, summary) = kept_going(&broken);
    assert_eq!(summary["skipped"].as_array().unwrap().len(), 1, "{summary}");
    assert!(kept.len() <= expected.len(), "{summary}");
    assert!(
        kept.len() + 2 >= expected.len(),
        "{} of {} frames",
        kept.len(),
        expected.len()
    );
    for frame in &kept {
        let same = expected
            .iter()
            .find(|(stamp, _)| *stamp == frame["stamp_ns"]);
        if let Some((_, cells)) = same {
            assert!(
                *cells == frame["cells"],
                "frame at {}: other cells",
                frame["stamp_ns"]
            );
        }
    }

    // A record the capture holds only part of (its snap length cut the packet to
    // 100 of 1,290 bytes), the records after it whole: that packet is lost, named;
    // --keep-going reads on.
    let mut bytes = std::fs::read(&capture).unwrap();
    let cut = record(300);
    bytes[cut + 8..cut + 12].copy_from_slice(&100u32.to_le_bytes());
    bytes.drain(cut + 16 + 100..cut + 16 + 42 + 1248);
    std::fs::write(&broken, &bytes).unwrap();
    let err = crate::common::clean_failure(crate::common::travmap(&["run", arg(&broken)]));
    assert_contains(
        &err,
        &[&format!(
            "the record at byte {cut} holds 58 of its 1248-byte packet"
        )],
    );
    let (_, summary) = kept_going(&broken);
    assert_eq!(summary["skipped"].as_array().unwrap().len(), 1, "{summary}");
}

/// `run --json --keep-going` of a damaged capture: exit 3, its frames and summary.
fn kept_going(capture: &Path) -> (Vec<serde_json::Value>, serde_json::Value) {
    let output = crate::common::travmap(&["run", arg(capture), "--json", "--keep-going"]);
    let err = crate::common::stderr(&output);
    assert_eq!(output.status.code(), Some(3), "{err}");
    crate::common::json_records(&crate::common::stdout(&output))
}

/// A capture without LiDAR traffic says what it holds: each port's datagrams and
/// their sizes (it once said "no PointCloud2 topic; all topics: []").
#[test]
fn a_capture_without_lidar_packets_names_its_ports_and_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let capture = dir.path().join("dns.pcap");
    let datagrams = [(5353, 100), (5353, 180), (123, 48), (5353, 100)];
    std::fs::write(&capture, udp_capture(&datagrams)).unwrap();
    let err = crate::common::clean_failure(crate::common::travmap(&[
        "run",
        crate::common::arg(&capture),
    ]));
    crate::common::assert_contains(
        &err,
        &[
            "dns.pcap: no LiDAR packets among its UDP datagrams",
            "port 5353: 3 of 100-180 bytes, port 123: 1 of 48 bytes",
        ],
    );
}
