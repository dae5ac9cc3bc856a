//! Velodyne packets against tier4/nebula's own decoder ground truth
//! (`fixtures/nebula/`, see fixtures/README.md): the same scan cut from the same
//! packets, and its points where nebula puts them.

use std::collections::HashMap;

use super::{
    Decoder, DecoderSettings, ScanAssembler, VelodyneCalibration, VelodyneModel, scan_message,
};
use crate::containers::log::Log;
use crate::format::InputFormat;
use crate::test_data::{nebula_fixture, nebula_ground_truth, repository_file};

/// How many of `truth`'s points have a decoded point within `tolerance_m`.
fn matched(truth: &[[f32; 3]], decoded: &[[f32; 3]], tolerance_m: f32) -> usize {
    let key = |p: &[f32; 3]| p.map(|v| (v / tolerance_m).floor() as i64);
    let mut cells: HashMap<[i64; 3], Vec<[f32; 3]>> = HashMap::new();
    for p in decoded {
        cells.entry(key(p)).or_default().push(*p);
    }
    truth
        .iter()
        .filter(|t| {
            let k = key(t);
            (-1..=1).any(|dx| {
                (-1..=1).any(|dy| {
                    (-1..=1).any(|dz| {
                        cells
                            .get(&[k[0] + dx, k[1] + dy, k[2] + dz])
                            .is_some_and(|ps| {
                                ps.iter().any(|p| {
                                    let d2: f32 = (0..3).map(|i| (p[i] - t[i]).powi(2)).sum();
                                    d2 <= tolerance_m * tolerance_m
                                })
                            })
                    })
                })
            })
        })
        .count()
}

/// Decodes the bag as nebula's test does and returns (ground truth, decoded scan).
fn decode_like_nebula(
    bag: &str,
    truth: &str,
    model: VelodyneModel,
    settings: DecoderSettings,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let (truth_stamp, truth) = nebula_ground_truth(truth);
    let calibration = VelodyneCalibration::builtin(model).unwrap();
    let mut assembler = ScanAssembler::new(Decoder::new(model, calibration, settings).unwrap());
    let log = Log::open(&nebula_fixture(bag), InputFormat::Rosbag2).unwrap();
    for message in log.messages() {
        let message = message.unwrap();
        let scan = scan_message(&message.data, message.connection.encoding().unwrap()).unwrap();
        for (stamp_ns, packet) in scan.packets {
            // nebula's test hands the decoder whole seconds.
            let seconds_ns = stamp_ns / 1_000_000_000 * 1_000_000_000;
            if let Some(scan) = assembler.push(packet, seconds_ns).unwrap()
                && message.log_time_ns == truth_stamp
            {
                return (truth, scan.points.iter().map(|p| p.xyz_m).collect());
            }
        }
    }
    panic!("no scan completed in the message logged at {truth_stamp}");
}

fn conformance(name: &str, truth: &[[f32; 3]], decoded: &[[f32; 3]]) {
    let within_1cm = matched(truth, decoded, 0.01);
    let share = within_1cm as f64 / truth.len() as f64;
    println!(
        "{name}: {} ground-truth points, {} decoded, {within_1cm} within 1 cm ({:.2} %)",
        truth.len(),
        decoded.len(),
        100.0 * share
    );
    assert!(share >= 0.99, "{name}: {:.2} % within 1 cm", 100.0 * share);
    let size = decoded.len() as f64 / truth.len() as f64;
    assert!(
        (0.9..=1.1).contains(&size),
        "{name}: {} against {}",
        decoded.len(),
        truth.len()
    );
}

#[test]
fn vlp32c_packets_decode_to_nebulas_points() {
    let settings = DecoderSettings {
        cut_angle_deg: 180.0,
        min_range_m: 0.4,
        max_range_m: 50.0,
        fov_min_deg: 270,
        fov_max_deg: 90,
    };
    let (truth, decoded) = decode_like_nebula(
        "vlp32/1713492677464078412",
        "vlp32/1713492677464078412.pcd",
        VelodyneModel::Vlp32c,
        settings,
    );
    conformance("VLP-32C", &truth, &decoded);
}

#[test]
fn vlp16_dual_return_packets_decode_to_nebulas_points() {
    let settings = DecoderSettings {
        fov_max_deg: 359,
        ..Default::default()
    };
    let (truth, decoded) = decode_like_nebula(
        "vlp16/1673400471837873222",
        "vlp16/1673400472138016708.pcd",
        VelodyneModel::Vlp16,
        settings,
    );
    conformance("VLP-16", &truth, &decoded);
}

#[test]
fn the_packets_name_their_model() {
    let log = Log::open(
        &nebula_fixture("vlp32/1713492677464078412"),
        InputFormat::Rosbag2,
    )
    .unwrap();
    let message = log.messages().next().unwrap().unwrap();
    assert_eq!(
        message.connection.type_name(),
        "velodyne_msgs/msg/VelodyneScan"
    );
    let scan = scan_message(&message.data, message.connection.encoding().unwrap()).unwrap();
    assert_eq!(scan.frame_id, "velodyne_front");
    assert!(scan.packets.len() > 70, "{}", scan.packets.len());
    assert_eq!(
        VelodyneModel::of_packet(scan.packets[0].1),
        Ok(VelodyneModel::Vlp32c)
    );
}

#[test]
fn ros1_and_ros2_scan_messages_carry_the_same_packets() {
    use travmap_formats::ros::MessageEncoding;
    let seeds = repository_file("fuzz/seeds/velodyne_scan");
    let cdr = std::fs::read(seeds.join("vlp32c.cdr")).unwrap();
    let ros1 = std::fs::read(seeds.join("vlp32c.ros1")).unwrap();
    let (a, b) = (
        scan_message(&cdr, MessageEncoding::Cdr).unwrap(),
        scan_message(&ros1, MessageEncoding::Ros1).unwrap(),
    );
    assert_eq!(
        (a.frame_id.as_str(), b.frame_id.as_str()),
        ("velodyne_front", "velodyne_front")
    );
    assert_eq!(a.stamp_ns, b.stamp_ns);
    assert_eq!(a.packets, b.packets);
    assert_eq!(a.packets.len(), 3);
    // convert re-encodes the ROS 1 message as ROS 2, byte for byte the CDR one.
    let translated = travmap_formats::ros::ros1_to_cdr("velodyne_msgs/msg/VelodyneScan", &ros1)
        .unwrap()
        .unwrap();
    assert_eq!(translated.data, cdr);
    // A message cut inside a packet is an error, not a shorter packet.
    let err = scan_message(&cdr[..cdr.len() - 10], MessageEncoding::Cdr)
        .err()
        .unwrap();
    assert!(err.contains("the message ends"), "{err}");
}
