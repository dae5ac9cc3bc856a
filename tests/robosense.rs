//! RoboSense packets against tier4/nebula's own decoder ground truth
//! (`fixtures/nebula/helios16p`, see fixtures/README.md): the scans nebula's test
//! compares, cut from the same packets, point for point in nebula's order.

use crate::common::{nebula_fixture, nebula_ground_truth, point_for_point};

use travmap_io::containers::log::Log;
use travmap_io::format::InputFormat;
use travmap_io::packets::robosense::{
    RobosenseAssembler, RobosenseCalibration, RobosenseModel, robosense_scan_message,
};

const BAG: &str = "helios16p/rosbag2_2023_08_03-11_02_46";

/// Decodes the bag as nebula's test does: each message's packets in turn, the
/// scan completed during it compared with the PCD named for its log time, point for
/// point.
fn decodes_like_nebula(truths: &[&str]) {
    let model = RobosenseModel::Helios16p;
    // nebula's test gives the generic table as a file: the DIFOP's does not replace it.
    let calibration = RobosenseCalibration {
        generic: false,
        ..RobosenseCalibration::builtin(model)
    };
    let mut assembler = RobosenseAssembler::new(model, &calibration).unwrap();
    let truths: Vec<(u64, Vec<[f32; 3]>, &str)> = (truths.iter())
        .map(|name| {
            let (stamp, points) = nebula_ground_truth(name);
            (stamp, points, *name)
        })
        .collect();
    let log = Log::open(&nebula_fixture(BAG), InputFormat::Rosbag2).unwrap();
    let mut compared = 0;
    for message in log.messages() {
        let message = message.unwrap();
        let encoding = message.connection.encoding().unwrap();
        let scan = robosense_scan_message(&message.data, encoding).unwrap();
        let mut completed = None;
        for (stamp_ns, packet) in scan.packets {
            completed = assembler.push(packet, stamp_ns).unwrap().or(completed);
        }
        if let Some((_, truth, name)) = truths.iter().find(|t| t.0 == message.log_time_ns) {
            let scan = completed.expect("nebula completed a scan in this message");
            let decoded: Vec<[f32; 3]> = scan.points.iter().map(|p| p.xyz_m).collect();
            point_for_point(&format!("Helios 16P {name}"), truth, &decoded, 1e-4);
            compared += 1;
        }
    }
    assert_eq!(compared, truths.len(), "every ground truth met");
}

/// The first scan (the part-turn from where the log began, decoded before any DIFOP
/// said how the sensor runs) and the fourth (read across the log's one DIFOP).
#[test]
fn helios_16p_packets_decode_to_nebulas_points() {
    decodes_like_nebula(&[
        "helios16p/1691031766781547066.pcd",
        "helios16p/1691031767081713313.pcd",
    ]);
}

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
                let in_place = robosense_scan_message(&message.data, MessageEncoding::Cdr).unwrap();
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
