//! `nebula_msgs/msg/NebulaPackets`, nebula's vendor-neutral packet message: nebula's
//! Velodyne and Hesai test packets (`fixtures/nebula/`) re-wrapped as NebulaPackets
//! (same topic, stamps and bytes) read as the same packets, of the same model, and
//! give every command the same drive as the vendor's own message.

use std::path::Path;

use crate::common::{arg, json_records, nebula_fixture, success, travmap};
use travmap_formats::mcap::writer::Compression;
use travmap_formats::ros::{Header, NebulaPacket, NebulaPackets, Time};
use travmap_io::InputFormat;
use travmap_io::Log;
use travmap_io::{PacketModel, packet_message};

/// The type of nebula's own packet message.
const NEBULA_PACKETS: &str = "nebula_msgs/msg/NebulaPackets";
use travmap_outputs::writing::McapSink;

fn time(ns: u64) -> Time {
    Time {
        sec: (ns / 1_000_000_000) as i32,
        nanosec: (ns % 1_000_000_000) as u32,
    }
}

/// The packet bag `bag` with every message re-wrapped as NebulaPackets.
fn as_nebula_packets(bag: &Path, output: &Path) {
    let mut sink = McapSink::create(output, Compression::Zstd).unwrap();
    for message in Log::open(bag, InputFormat::Rosbag2).unwrap().messages() {
        let message = message.unwrap();
        let encoding = message.connection.encoding().unwrap();
        let type_name = message.connection.type_name();
        let scan =
            packet_message(&type_name, &message.data, encoding, message.log_time_ns).unwrap();
        let packets = NebulaPackets {
            header: Header {
                stamp: time(scan.stamp_ns),
                frame_id: scan.frame_id.clone(),
            },
            packets: (scan.packets.iter())
                .map(|(stamp_ns, data)| NebulaPacket {
                    stamp: time(*stamp_ns),
                    data: data.to_vec(),
                })
                .collect(),
        };
        sink.write(&message.connection.topic, message.log_time_ns, &packets)
            .unwrap();
    }
    sink.finish().unwrap();
}

/// Every message's packets, as read from a log of `bag`'s vendor message and of
/// NebulaPackets.
fn same_packets(bag: &Path, nebula: &Path, model: &str) {
    let packets = |path: &Path, format| -> Vec<(u64, Vec<u8>, String)> {
        let log = Log::open(path, format).unwrap();
        let messages = log.messages().map(Result::unwrap);
        messages
            .flat_map(|m| {
                let type_name = m.connection.type_name().into_owned();
                let scan = packet_message(
                    &type_name,
                    &m.data,
                    m.connection.encoding().unwrap(),
                    m.log_time_ns,
                )
                .unwrap();
                (scan.packets.into_iter())
                    .map(|(stamp, p)| {
                        let model = PacketModel::of_packet(&type_name, p).unwrap();
                        (stamp, p.to_vec(), model.name().to_string())
                    })
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    let (recorded, rewrapped) = (
        packets(bag, InputFormat::Rosbag2),
        packets(nebula, InputFormat::Mcap),
    );
    assert!(!recorded.is_empty());
    assert!(recorded.iter().all(|(_, _, name)| name == model));
    assert_eq!(recorded, rewrapped, "{model}");
}

fn nebula_packets_are_the_vendors_drive(bag: &str, model: &str) {
    let bag = nebula_fixture(bag);
    let dir = tempfile::tempdir().unwrap();
    let nebula = dir.path().join("nebula.mcap");
    as_nebula_packets(&bag, &nebula);
    let log = Log::open(&nebula, InputFormat::Mcap).unwrap();
    let first = log.messages().next().unwrap().unwrap();
    assert_eq!(first.connection.schema_name, NEBULA_PACKETS);
    same_packets(&bag, &nebula, model);

    // Each scan alone, every one: a log's first scan is partial (the 40P's holds 152
    // points, too few to register, and is left out unless asked for).
    let run = |log: &Path| {
        let args = ["--poses", "none", "--frames", "0..", "--json"];
        travmap(&[&["run", arg(log)][..], &args[..]].concat())
    };
    let (recorded, _) = json_records(&success(run(&bag)));
    let (rewrapped, _) = json_records(&success(run(&nebula)));
    assert!(!recorded.is_empty());
    assert_eq!(recorded.len(), rewrapped.len());
    for (a, b) in recorded.iter().zip(&rewrapped) {
        assert_eq!(a["stamp_ns"], b["stamp_ns"]);
        assert_eq!(a["cells"], b["cells"]);
    }
    let converted = dir.path().join("converted.mcap");
    let doc = crate::common::json_summary(&["convert", arg(&nebula), "-o", arg(&converted)]);
    // convert leaves the partial first scan out (it shares the next one's stamp).
    let partial = usize::from(doc["partial_first_scan_left_out"] == true);
    assert_eq!(doc["decoded_scans"], recorded.len() - partial);
    println!(
        "{model}: {} scans, as from the vendor's message",
        recorded.len()
    );
}

#[test]
fn nebula_packets_of_a_velodyne_are_its_velodyne_scans() {
    nebula_packets_are_the_vendors_drive("vlp16/1673400471837873222", "VLP-16");
}

#[test]
fn nebula_packets_of_a_pandar_are_its_pandar_scans() {
    nebula_packets_are_the_vendors_drive("xt32/1673400677802009732", "Pandar XT32");
}

/// A 40P packet begins `FF EE`, as a Velodyne block does: its length tells them apart.
#[test]
fn nebula_packets_of_a_pandar_40p_are_not_taken_for_velodyne_ones() {
    nebula_packets_are_the_vendors_drive("40p/1673400149412331409", "Pandar 40P");
}

#[test]
fn the_fuzz_seeds_are_nebula_packets_of_each_model() {
    use travmap_formats::ros::MessageEncoding;
    let seeds = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/nebula_packets");
    for (name, model) in [
        ("vlp16_dual", "VLP-16"),
        ("vlp32c", "VLP-32C"),
        ("xt16_dual", "Pandar XT16"),
        ("xt32_dual", "Pandar XT32"),
        ("p40_dual", "Pandar 40P"),
        ("p64_dual", "Pandar 64"),
        ("qt64_dual", "Pandar QT64"),
        ("xt32m_dual", "Pandar XT32M"),
        ("qt128_dual", "Pandar QT128"),
    ] {
        let data = std::fs::read(seeds.join(format!("{name}.cdr"))).unwrap();
        let message = packet_message(NEBULA_PACKETS, &data, MessageEncoding::Cdr, 0).unwrap();
        assert_eq!(message.packets.len(), 3, "{name}");
        for (_, packet) in &message.packets {
            let found = PacketModel::of_packet(NEBULA_PACKETS, packet).unwrap();
            assert_eq!(found.name(), model, "{name}");
        }
        let typed: NebulaPackets = travmap_formats::ros::decode(&data).unwrap();
        assert_eq!(typed.header.frame_id, message.frame_id);
    }
}

/// `convert` of a packet log recorded without message definitions (rosbag2 before
/// Iron): each packet channel gets travmap's definition, so that decoders (Python
/// mcap, Foxglove) read it; the part of a rotation the log began with is left out of
/// the decoded scans, whose stamps then all differ (it shared the next one's).
#[test]
fn converted_packet_channels_carry_their_definition_and_scans_their_own_stamps() {
    let dir = tempfile::tempdir().unwrap();
    let bag = std::fs::read_dir(nebula_fixture("40p"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir())
        .unwrap();
    let output = dir.path().join("40p.mcap");
    let err = crate::common::stderr(&travmap(&["convert", arg(&bag), "-o", arg(&output)]));
    assert!(
        err.contains("the part of a rotation the log began with is left out"),
        "{err}"
    );
    let bytes = std::fs::read(&output).unwrap();
    let mut point_stamps = Vec::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let schema = message.channel.schema.as_ref().unwrap();
        match message.channel.topic.as_str() {
            "/pandar_packets" => {
                assert_eq!(schema.encoding, "ros2msg");
                assert!(
                    std::str::from_utf8(&schema.data)
                        .unwrap()
                        .contains("MSG: pandar_msgs/PandarPacket")
                );
            }
            "/pandar_points" => point_stamps.push(message.log_time),
            _ => {}
        }
    }
    assert_eq!(point_stamps.len(), 3);
    assert!(
        point_stamps.windows(2).all(|pair| pair[0] < pair[1]),
        "{point_stamps:?}"
    );
}

/// `--frames 0..` asks for the part of a rotation a packet log began with: too
/// sparse to start the registration's map, it is posed where the drive starts
/// (it once stopped the run: "2 points left to register").
#[test]
fn an_explicit_partial_first_frame_is_read_not_refused() {
    for model in ["40p", "64", "qt64", "xt16", "xt32m"] {
        let bag = std::fs::read_dir(nebula_fixture(model))
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.is_dir())
            .unwrap();
        let out = success(travmap(&["run", arg(&bag), "--frames", "0..3", "--json"]));
        let (frames, _) = json_records(&out);
        assert_eq!(frames[0]["frame"], 0, "{model}");
    }
}
