//! RoboSense packets against tier4/nebula's own decoder ground truth
//! (`fixtures/nebula/helios16p`, see fixtures/README.md), point for point.

use super::{RobosenseAssembler, RobosenseCalibration, RobosenseModel, robosense_scan_message};
use crate::containers::log::Log;
use crate::format::InputFormat;
use crate::test_data::{nebula_fixture, nebula_ground_truth, point_for_point};

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
