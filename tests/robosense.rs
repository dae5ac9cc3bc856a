//! A RoboSense packet log (tier4/nebula's Helios 16P, `fixtures/nebula/helios16p`)
//! through the commands; its decoding against nebula's points is the reader's test
//! (`crates/io/src/packets/robosense/nebula_tests.rs`).

use crate::common::nebula_fixture;

const BAG: &str = "helios16p/rosbag2_2023_08_03-11_02_46";

/// `convert` of the Helios 16P bag (recorded without message definitions, as
/// rosbag2 before Iron records): the packet channel gets RobosenseScan's definition,
/// whose messages decode as that type to the packets read in place, and each
/// completed scan is a PointCloud2 beside them; the model it was read as is said.
#[test]
fn a_converted_robosense_log_carries_its_packets_definition_and_its_clouds() {
    use travmap_formats::ros::{MessageEncoding, RobosenseScan, decode};
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("helios.mcap");
    let bag = nebula_fixture(BAG);
    let bag = bag.to_str().unwrap();
    let out = crate::common::travmap(&["convert", bag, "-o", output.to_str().unwrap()]);
    // Which model the packets were read as is said (a Helios 32's look the same).
    let said = crate::common::stderr(&out);
    assert!(said.contains("read as a RoboSense Helios 16P's"), "{said}");
    crate::common::success(out);
    let bytes = std::fs::read(&output).unwrap();
    let (mut packet_messages, mut clouds) = (0, 0);
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let schema = message.channel.schema.as_ref().unwrap();
        match message.channel.topic.as_str() {
            "/robosense_packets" => {
                let definition = std::str::from_utf8(&schema.data).unwrap();
                assert!(definition.contains("MSG: robosense_msgs/RobosensePacket"));
                let typed: RobosenseScan = decode(&message.data).unwrap();
                let in_place = travmap_io::packet_message(
                    "robosense_msgs/msg/RobosenseScan",
                    &message.data,
                    MessageEncoding::Cdr,
                    0,
                )
                .unwrap();
                let typed = typed.packets.iter().map(|p| &p.data.0[..p.size as usize]);
                assert!(typed.eq(in_place.packets.iter().map(|(_, p)| *p)));
                packet_messages += 1;
            }
            "/robosense_points" => clouds += 1,
            other => panic!("a channel {other}"),
        }
    }
    assert_eq!((packet_messages, clouds), (5, 5));
}

/// A Helios 32 sends packets of the same form: a 32-row angle table given for the
/// bag is refused, naming the file, both laser counts and why.
#[test]
fn a_helios_32_table_is_refused_for_the_16ps_packets() {
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("RobosenseHelios.csv");
    let rows: Vec<String> = (0..32).map(|k| format!("{}.5,0.1", 15 - k)).collect();
    std::fs::write(&table, rows.join("\n")).unwrap();
    let bag = nebula_fixture(BAG);
    let out = crate::common::travmap(&[
        "run",
        bag.to_str().unwrap(),
        "--lidar-calibration",
        table.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = crate::common::stderr(&out);
    assert!(
        err.contains("RobosenseHelios.csv: an angle table of 32 lasers for the RoboSense Helios 16P (16 lasers): a Helios 32's?"),
        "{err}"
    );
}
