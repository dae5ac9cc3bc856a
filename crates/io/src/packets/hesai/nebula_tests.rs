//! Hesai packets against tier4/nebula's own decoder ground truth
//! (`fixtures/nebula/xt32`, `xt16`, ..., see fixtures/README.md): the scan nebula's
//! test compares, cut from the same packets, point for point in nebula's order.

use super::{HesaiAssembler, HesaiCalibration, HesaiModel, pandar_scan_message};
use crate::containers::log::Log;
use crate::format::InputFormat;
use crate::test_data::{nebula_fixture, nebula_ground_truth, point_for_point, repository_file};

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
fn ros1_pandar_scans_are_re_encoded_as_the_ros2_ones() {
    use travmap_formats::ros::MessageEncoding;
    let seeds = repository_file("fuzz/seeds/pandar_scan");
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
        let stamps = |scans: &[crate::packets::PacketScan]| -> Vec<u64> {
            scans.iter().map(|scan| scan.stamp_ns).collect()
        };
        assert_eq!(stamps(&cut), stamps(&decoded), "{bag}");
    }
}
