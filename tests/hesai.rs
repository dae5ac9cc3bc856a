//! Hesai packets against tier4/nebula's own decoder ground truth
//! (`fixtures/nebula/xt32`, `xt16`, see fixtures/README.md): the scan nebula's test
//! compares, cut from the same packets, point for point in nebula's order.

use crate::common::{nebula_fixture, nebula_ground_truth, point_for_point};

use travmap_io::containers::log::Log;
use travmap_io::format::InputFormat;
use travmap_io::packets::hesai::{
    HesaiAssembler, HesaiCalibration, HesaiModel, pandar_scan_message,
};

/// Decodes the bag as nebula's test does: the ground truth is the scan completed
/// while the message logged at the PCD's stamp is read. Returns (ground truth,
/// decoded scan, how many scans came before it).
fn decode_like_nebula(
    bag: &str,
    truth: &str,
    model: HesaiModel,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, usize) {
    let (truth_stamp, truth) = nebula_ground_truth(truth);
    let mut assembler = HesaiAssembler::new(model, &HesaiCalibration::builtin(model)).unwrap();
    let log = Log::open(&nebula_fixture(bag), InputFormat::Rosbag2).unwrap();
    let mut before = 0;
    for message in log.messages() {
        let message = message.unwrap();
        let encoding = message.connection.encoding().unwrap();
        let scan = pandar_scan_message(&message.data, encoding).unwrap();
        for (stamp_ns, packet) in scan.packets {
            if let Some(scan) = assembler.push(packet, stamp_ns).unwrap() {
                if message.log_time_ns == truth_stamp {
                    return (truth, scan.points.iter().map(|p| p.xyz_m).collect(), before);
                }
                before += 1;
            }
        }
    }
    panic!("no scan completed in the message logged at {truth_stamp}");
}

#[test]
fn xt32_dual_return_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "xt32/1673400677802009732",
        "xt32/1673400678101968885.pcd",
        HesaiModel::PandarXt32,
    );
    // nebula's fourth scan: the first is the part-scan from where the log began.
    assert_eq!(before, 3);
    point_for_point("Pandar XT32", &truth, &decoded, 1e-4);
}

#[test]
fn xt16_dual_return_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "xt16/1732848127890747768",
        "xt16/1732848128093928016.pcd",
        HesaiModel::PandarXt16,
    );
    assert_eq!(before, 2);
    point_for_point("Pandar XT16", &truth, &decoded, 1e-4);
}

/// nebula's XT32M bag lost packets (gaps of 414, 45 and 396 in its sequence
/// numbers): the scan compared covers about 146 degrees.
#[test]
fn pandar_xt32m_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "xt32m/1660893203042895158",
        "xt32m/1660893203292679064.pcd",
        HesaiModel::PandarXt32m,
    );
    assert_eq!(before, 3);
    point_for_point("Pandar XT32M", &truth, &decoded, 1e-4);
}

#[test]
fn pandar_40p_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "40p/1673400149412331409",
        "40p/1673400149711850138.pcd",
        HesaiModel::Pandar40p,
    );
    assert_eq!(before, 3);
    point_for_point("Pandar 40P", &truth, &decoded, 1e-4);
}

#[test]
fn pandar_64_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "64/1673403880599376836",
        "64/1673403880898440686.pcd",
        HesaiModel::Pandar64,
    );
    assert_eq!(before, 3);
    point_for_point("Pandar 64", &truth, &decoded, 1e-4);
}

#[test]
fn pandar_qt64_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "qt64/1673401195788312575",
        "qt64/1673401196087570870.pcd",
        HesaiModel::PandarQt64,
    );
    assert_eq!(before, 3);
    point_for_point("Pandar QT64", &truth, &decoded, 1e-4);
}

/// nebula's QT128 bag: two messages of 900 packets (dual return, last and strongest),
/// the firing loops alternating packet by packet.
#[test]
fn pandar_qt128_packets_decode_to_nebulas_points() {
    let (truth, decoded, before) = decode_like_nebula(
        "qt128/1730273789074637152",
        "qt128/1730273789174759609.pcd",
        HesaiModel::PandarQt128,
    );
    assert_eq!(before, 1);
    point_for_point("Pandar QT128", &truth, &decoded, 1e-4);
}

#[test]
fn the_packets_name_their_model_and_a_mismatch_is_refused() {
    let log = Log::open(
        &nebula_fixture("xt16/1732848127890747768"),
        InputFormat::Rosbag2,
    )
    .unwrap();
    let message = log.messages().next().unwrap().unwrap();
    let scan = pandar_scan_message(&message.data, message.connection.encoding().unwrap()).unwrap();
    let packet = scan.packets[0].1;
    assert_eq!(packet.len(), 568);
    assert_eq!(HesaiModel::of_packet(packet), Ok(HesaiModel::PandarXt16));
    let model = HesaiModel::PandarXt32;
    let mut xt32 = HesaiAssembler::new(model, &HesaiCalibration::builtin(model)).unwrap();
    let err = xt32.push(packet, 0).unwrap_err();
    assert!(
        err.contains("Pandar XT16 packet on a topic of Pandar XT32"),
        "{err}"
    );
    // Three returns do not divide eight blocks (the fuzzer's first find).
    let mut triple = packet.to_vec();
    triple[540 + 10] = 0x3d;
    let xt16_model = HesaiModel::PandarXt16;
    let xt16_table = HesaiCalibration::builtin(xt16_model);
    let mut xt16 = HesaiAssembler::new(xt16_model, &xt16_table).unwrap();
    let err = xt16.push(&triple, 0).unwrap_err();
    assert!(
        err.contains("0x3d (3 returns) in a packet of 8 blocks"),
        "{err}"
    );
    let err = HesaiModel::of_packet(&packet[..500]).unwrap_err();
    assert!(err.contains("500-byte Pandar XT16 packet"), "{err}");
    let err = HesaiAssembler::new(model, &xt16_table).err().unwrap();
    assert!(err.contains("16 lasers for the Pandar XT32"), "{err}");
}

#[test]
fn a_pandar_log_is_a_drive_for_every_command() {
    use crate::common::{arg, json_records, success, travmap};
    let bag = nebula_fixture("xt32/1673400677802009732");
    let model = HesaiModel::PandarXt32;
    let mut assembler = HesaiAssembler::new(model, &HesaiCalibration::builtin(model)).unwrap();
    let mut scans = Vec::new();
    let log = Log::open(&bag, InputFormat::Rosbag2).unwrap();
    for message in log.messages() {
        let message = message.unwrap();
        let encoding = message.connection.encoding().unwrap();
        for (stamp_ns, packet) in pandar_scan_message(&message.data, encoding)
            .unwrap()
            .packets
        {
            scans.extend(assembler.push(packet, stamp_ns).unwrap());
        }
    }
    assert_eq!(
        scans.iter().map(|s| s.points.len()).collect::<Vec<_>>(),
        [62_826, 63_058, 63_040, 63_021]
    );
    // Stamped in the log's clock (the sensor's says 2019): the poses are found.
    let first_packet_ns = 1_673_400_677_000_000_000;
    assert!(scans.iter().all(|s| s.stamp_ns > first_packet_ns));
    let whole = &scans[3];
    let times = whole.points.iter().map(|p| p.time_ns - whole.stamp_ns);
    assert!(times.max().unwrap() < 110_000_000, "a turn takes 0.1 s");

    let (frames, summary) = json_records(&success(travmap(&["run", arg(&bag), "--json"])));
    assert_eq!(summary["frames"], scans.len());
    for (frame, scan) in frames.iter().zip(&scans) {
        assert_eq!(frame["stamp_ns"], scan.stamp_ns);
    }
    // convert writes the scans as PointCloud2 beside the packets.
    let dir = tempfile::tempdir().unwrap();
    let converted = dir.path().join("converted.mcap");
    let doc = crate::common::json_summary(&["convert", arg(&bag), "-o", arg(&converted)]);
    assert_eq!(doc["decoded_topic"], "/pandar_points");
    assert_eq!(doc["decoded_scans"], scans.len());
    let log = Log::open(&converted, InputFormat::Mcap).unwrap();
    let clouds: Vec<travmap_formats::ros::PointCloud2> = log
        .messages()
        .map(Result::unwrap)
        .filter(|m| m.connection.topic == "/pandar_points")
        .map(|m| travmap_formats::ros::decode(&m.data).unwrap())
        .collect();
    assert_eq!(clouds.len(), scans.len());
    for (cloud, scan) in clouds.iter().zip(&scans) {
        assert_eq!(cloud.width as usize, scan.points.len());
        assert_eq!(cloud.header.frame_id, "hesai");
        assert_eq!(cloud.header.stamp.to_ns(), scan.stamp_ns);
    }
    // A table of another model is refused, naming both.
    let xt16 = dir.path().join("PandarXT16.csv");
    std::fs::write(&xt16, "Channel,Elevation,Azimuth\n1,15,0\n2,13,0\n").unwrap();
    let err = crate::common::clean_failure(travmap(&[
        "run",
        arg(&bag),
        "--lidar-calibration",
        arg(&xt16),
    ]));
    assert!(err.contains("2 lasers for the Pandar XT32"), "{err}");
}

#[test]
fn ros1_pandar_scans_are_re_encoded_as_the_ros2_ones() {
    use travmap_formats::ros::MessageEncoding;
    let seeds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/pandar_scan");
    for name in [
        "xt32_dual",
        "xt16_dual",
        "p40_dual",
        "p64_dual",
        "qt64_dual",
        "xt32m_dual",
        "qt128_dual",
    ] {
        let cdr = std::fs::read(seeds.join(format!("{name}.cdr"))).unwrap();
        let ros1 = std::fs::read(seeds.join(format!("{name}.ros1"))).unwrap();
        let (a, b) = (
            pandar_scan_message(&cdr, MessageEncoding::Cdr).unwrap(),
            pandar_scan_message(&ros1, MessageEncoding::Ros1).unwrap(),
        );
        assert_eq!(a.packets, b.packets, "{name}");
        let translated = travmap_formats::ros::ros1_to_cdr("pandar_msgs/msg/PandarScan", &ros1)
            .unwrap()
            .unwrap();
        assert_eq!(translated.data, cdr, "{name}");
    }
}

/// The log index cuts scans without decoding their points: the same scans, stamped
/// the same, as decoding them all.
#[test]
fn scans_cut_for_their_stamps_alone_are_the_decoded_scans() {
    for (bag, model) in [
        ("xt32/1673400677802009732", HesaiModel::PandarXt32),
        ("xt16/1732848127890747768", HesaiModel::PandarXt16),
        ("40p/1673400149412331409", HesaiModel::Pandar40p),
        ("64/1673403880599376836", HesaiModel::Pandar64),
        ("qt64/1673401195788312575", HesaiModel::PandarQt64),
        ("xt32m/1660893203042895158", HesaiModel::PandarXt32m),
        ("qt128/1730273789074637152", HesaiModel::PandarQt128),
    ] {
        let calibration = HesaiCalibration::builtin(model);
        let mut decoding = HesaiAssembler::new(model, &calibration).unwrap();
        let mut cutting = HesaiAssembler::new(model, &calibration)
            .unwrap()
            .stamps_only();
        let (mut decoded, mut cut) = (Vec::new(), Vec::new());
        for message in Log::open(&nebula_fixture(bag), InputFormat::Rosbag2)
            .unwrap()
            .messages()
        {
            let message = message.unwrap();
            let encoding = message.connection.encoding().unwrap();
            for (stamp_ns, packet) in pandar_scan_message(&message.data, encoding)
                .unwrap()
                .packets
            {
                decoded.extend(decoding.push(packet, stamp_ns).unwrap());
                cut.extend(cutting.push(packet, stamp_ns).unwrap());
            }
        }
        assert!(decoded.len() >= 2, "{bag}");
        assert!(decoded.iter().all(|scan| !scan.points.is_empty()));
        assert!(cut.iter().all(|scan| scan.points.is_empty()));
        let stamps = |scans: &[travmap_io::packets::PacketScan]| -> Vec<u64> {
            scans.iter().map(|scan| scan.stamp_ns).collect()
        };
        assert_eq!(stamps(&cut), stamps(&decoded), "{bag}");
    }
}

/// `bench --tools` on a packet log: its convert row is the decode row (the whole
/// log, packets cut into scans and written as PointCloud2), in times real time.
#[test]
fn bench_tools_times_decoding_a_packet_log() {
    let bag = nebula_fixture("xt32/1673400677802009732");
    let args = ["bench", crate::common::arg(&bag), "--repeats", "1"];
    let doc =
        crate::common::json_summary(&[&args[..], &["--tools", "--tool-repeats", "1"]].concat());
    let rows = doc["tools"].as_array().unwrap();
    let convert = &rows[0];
    assert_eq!(
        (&convert["tool"], &convert["input"]),
        (&"convert".into(), &"packets".into())
    );
    assert_eq!(convert["frames"], 4, "{convert}");
    assert!(convert["recorded_ms"].as_f64().unwrap() > 0.0, "{convert}");
    assert!(
        convert["one_thread"]["real_time"].as_f64().unwrap() > 0.0,
        "{convert}"
    );
    assert!(rows[3]["skipped"].is_string(), "{}", rows[3]);
}

/// A packet log whose recording began mid-turn: its first scan (4 of the 40P's
/// packets, against 360 in the next) is left out by default, said in a notice, so
/// registration starts at the first whole turn; `--frames 0..` still reads it.
#[test]
fn a_partial_first_scan_is_left_out_by_default() {
    use crate::common::{arg, json_records, stderr, success, travmap};
    let bag = nebula_fixture("40p/1673400149412331409");
    let output = travmap(&["run", arg(&bag), "--json"]);
    let notice = stderr(&output);
    assert!(
        notice.contains("frame 0 is the part of a rotation the recording began with (4 packets, against 360 in frame 1): left out (--frames 0.. reads it)"),
        "{notice}"
    );
    let (frames, _) = json_records(&success(output));
    let indices: Vec<u64> = frames
        .iter()
        .map(|f| f["frame"].as_u64().unwrap())
        .collect();
    assert_eq!(indices, [1, 2, 3]);
    // Asked for, frame 0 is read (alone: too few points to register).
    let output = travmap(&[
        "run",
        arg(&bag),
        "--json",
        "--frames",
        "0..",
        "--poses",
        "none",
    ]);
    assert!(!stderr(&output).contains("left out"));
    let (frames, _) = json_records(&success(output));
    assert_eq!(frames.len(), 4);
    // A log that began with most of a turn keeps its frame 0.
    let xt32 = nebula_fixture("xt32/1673400677802009732");
    let output = travmap(&["run", arg(&xt32), "--json"]);
    assert!(!stderr(&output).contains("left out"));
    assert_eq!(json_records(&success(output)).0.len(), 4);
}
