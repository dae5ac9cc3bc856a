//! Packet captures of LiDAR packets: nebula's packet logs (`fixtures/nebula/`)
//! written again as pcap (and pcapng) files by scapy (Ethernet, IPv4, UDP, each packet stamped
//! with its recorded time, as tcpdump or Wireshark capture a sensor) read as the same
//! drive, frame for frame and cell for cell. Ouster's SDK's own pcap writer is
//! checked in `tests/ouster.rs`. Needs `TRAVMAP_CLIENT_PYTHON` (scapy).

use std::path::Path;
use std::process::Command;

use crate::common::{nebula_fixture, run_client};
use travmap_io::containers::log::Log;
use travmap_io::format::InputFormat;
use travmap_io::packets::packet_message;

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

/// A classic Ethernet pcap of UDP datagrams: (destination port, payload bytes) each.
fn udp_capture(datagrams: &[(u16, usize)]) -> Vec<u8> {
    let mut out = Vec::new();
    for word in [0xa1b2_c3d4u32.to_le_bytes(), [2, 0, 4, 0], [0; 4], [0; 4]] {
        out.extend(word);
    }
    out.extend(65_535u32.to_le_bytes());
    out.extend(1u32.to_le_bytes());
    for (n, &(port, bytes)) in datagrams.iter().enumerate() {
        let mut frame = vec![0u8; 12];
        frame.extend([0x08, 0x00]);
        let ip_length = (20 + 8 + bytes) as u16;
        frame.extend([0x45, 0]);
        frame.extend(ip_length.to_be_bytes());
        frame.extend([0, n as u8, 0, 0, 64, 17, 0, 0, 10, 0, 0, 1, 10, 0, 0, 2]);
        frame.extend(40_000u16.to_be_bytes());
        frame.extend(port.to_be_bytes());
        frame.extend(((8 + bytes) as u16).to_be_bytes());
        frame.extend([0, 0]);
        frame.extend(std::iter::repeat_n(7u8, bytes));
        for value in [n as u32, 0, frame.len() as u32, frame.len() as u32] {
            out.extend(value.to_le_bytes());
        }
        out.extend(frame);
    }
    out
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
