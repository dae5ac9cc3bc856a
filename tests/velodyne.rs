//! Velodyne packets against tier4/nebula's own decoder ground truth
//! (`fixtures/nebula/`, see fixtures/README.md): the same scan cut from the same
//! packets, and its points where nebula puts them.

use crate::common::{nebula_fixture, nebula_ground_truth};

use std::collections::HashMap;
use std::path::Path;

use travmap_io::containers::log::Log;
use travmap_io::format::InputFormat;
use travmap_io::packets::velodyne::{
    Calibration, Decoder, DecoderSettings, ScanAssembler, VelodyneModel, scan_message,
};

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
    let calibration = Calibration::builtin(model).unwrap();
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
fn a_packet_log_is_a_drive_for_every_command() {
    use crate::common::{arg, assert_contains, clean_failure, json_records, success, travmap};
    let bag = nebula_fixture("vlp32/1713492677464078412");
    // The scans run cuts are the scans the library assembles (cut angle 0).
    let calibration = Calibration::builtin(VelodyneModel::Vlp32c).unwrap();
    let decoder = Decoder::new(
        VelodyneModel::Vlp32c,
        calibration,
        DecoderSettings::default(),
    );
    let mut assembler = ScanAssembler::new(decoder.unwrap());
    let mut scans = Vec::new();
    let log = Log::open(&bag, InputFormat::Rosbag2).unwrap();
    for message in log.messages() {
        let message = message.unwrap();
        let scan = scan_message(&message.data, message.connection.encoding().unwrap()).unwrap();
        for (stamp_ns, packet) in scan.packets {
            scans.extend(assembler.push(packet, stamp_ns).unwrap());
        }
    }
    let (frames, summary) = json_records(&success(travmap(&["run", arg(&bag), "--json"])));
    assert_eq!(frames.len(), scans.len());
    assert_eq!(summary["frames"], scans.len());
    for (frame, scan) in frames.iter().zip(&scans) {
        assert_eq!(frame["stamp_ns"], scan.stamp_ns);
    }
    // A whole turn of a front-mounted sensor: its rear half sees the vehicle.
    let whole = &scans[2];
    assert!(whole.points.len() > 25_000, "{}", whole.points.len());
    let times: Vec<u64> = whole
        .points
        .iter()
        .map(|p| p.time_ns - whole.stamp_ns)
        .collect();
    assert!(
        *times.iter().max().unwrap() < 110_000_000,
        "a turn takes 0.1 s"
    );

    // map and annotate read it too.
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("map.png");
    success(travmap(&["map", arg(&bag), "-o", arg(&png), "-q"]));
    let annotated = dir.path().join("a.mcap");
    success(travmap(&[
        "annotate",
        arg(&bag),
        "-o",
        arg(&annotated),
        "-q",
    ]));

    // convert writes the scans as PointCloud2 beside the packets, and they are the
    // same frames.
    let converted = dir.path().join("converted.mcap");
    let doc = crate::common::json_summary(&["convert", arg(&bag), "-o", arg(&converted)]);
    let points_topic = "/sensing/lidar/front/velodyne_points";
    assert_eq!(doc["decoded_topic"], points_topic);
    assert_eq!(doc["decoded_scans"], scans.len());
    let run = travmap(&[
        "run",
        arg(&converted),
        "--cloud-topic",
        points_topic,
        "--json",
    ]);
    let (again, _) = json_records(&success(run));
    let stamps = |frames: &[serde_json::Value]| -> Vec<u64> {
        frames
            .iter()
            .map(|f| f["stamp_ns"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(stamps(&again), stamps(&frames));
    let log = Log::open(&converted, InputFormat::Mcap).unwrap();
    let cloud = log
        .messages()
        .map(Result::unwrap)
        .find(|m| m.connection.topic == points_topic)
        .unwrap();
    let cloud: travmap_formats::ros::PointCloud2 =
        travmap_formats::ros::decode(&cloud.data).unwrap();
    let names: Vec<&str> = cloud.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["x", "y", "z", "intensity", "ring", "t"]);
    assert_eq!(cloud.width as usize, scans[0].points.len());
    assert_eq!(cloud.header.frame_id, "velodyne_front");

    // A calibration of another sensor is refused, naming both.
    let other = dir.path().join("vlp16.yaml");
    let lasers: String = (0..16)
        .map(|i| format!("- {{laser_id: {i}, rot_correction: 0.0, vert_correction: 0.0}}\n"))
        .collect();
    std::fs::write(
        &other,
        format!("lasers:\n{lasers}distance_resolution: 0.002\n"),
    )
    .unwrap();
    let err = clean_failure(travmap(&[
        "run",
        arg(&bag),
        "--lidar-calibration",
        arg(&other),
    ]));
    assert_contains(
        &err,
        &[
            "velodyne_packets (VLP-32C packets)",
            "32 lasers",
            "the calibration has 16 lasers",
        ],
    );
}

#[test]
fn ros1_and_ros2_scan_messages_carry_the_same_packets() {
    use travmap_formats::ros::MessageEncoding;
    let seeds = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/velodyne_scan");
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
