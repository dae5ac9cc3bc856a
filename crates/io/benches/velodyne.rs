//! `cargo bench --bench velodyne`: LiDAR packets decoded and cut into scans on one
//! thread, on nebula's test logs (`fixtures/nebula/`: Velodyne VLP-32C and VLP-16,
//! Hesai Pandar XT32, XT16, XT32M, 40P, 64, QT64 and QT128, RoboSense Helios 16P): the median
//! time per packet and per second of
//! recording, and the real-time factor (seconds of recording decoded per second).
//! Asserts nothing about time.

use std::path::Path;
use std::time::Instant;

use travmap_formats::log_message::LogMessage;
use travmap_io::{
    InputFormat, Log, OusterMetadata, PACKET_MESSAGES, PacketAssembler, PacketCalibration,
    PacketModel, packet_message,
};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The Ouster metadata a log records, if it does.
fn ouster_metadata(messages: &[LogMessage]) -> Option<OusterMetadata> {
    let message = messages
        .iter()
        .find(|m| m.connection.topic.ends_with("/metadata"))?;
    OusterMetadata::from_message(&message.data, message.connection.encoding()?).ok()
}

fn main() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures");
    println!(
        "{:<12} {:>8} {:>10} {:>12} {:>14} {:>10}",
        "model", "packets", "points", "us/packet", "recorded s", "x realtime"
    );
    for bag in [
        "vlp32/1713492677464078412",
        "vlp16/1673400471837873222",
        "xt32/1673400677802009732",
        "xt16/1732848127890747768",
        "40p/1673400149412331409",
        "64/1673403880599376836",
        "qt64/1673401195788312575",
        "xt32m/1660893203042895158",
        "qt128/1730273789074637152",
        "helios16p/rosbag2_2023_08_03-11_02_46",
    ]
    .map(|bag| format!("nebula/{bag}"))
    .into_iter()
    .chain(["ouster/os1-64-1024x10".to_string()])
    {
        let log = Log::open(&fixtures.join(bag), InputFormat::Rosbag2).unwrap();
        let all: Vec<_> = log.messages().map(Result::unwrap).collect();
        let ouster = ouster_metadata(&all);
        let is_lidar = |m: &&LogMessage| {
            PACKET_MESSAGES.contains(&m.connection.type_name().as_ref())
                && !m.connection.topic.contains("imu")
        };
        let messages: Vec<_> = all.iter().filter(is_lidar).collect();
        let message_type = messages[0].connection.type_name().into_owned();
        let message_type = message_type.as_str();
        let stamps: Vec<u64> = messages
            .iter()
            .flat_map(|m| {
                let encoding = m.connection.encoding().unwrap();
                let scan = packet_message(message_type, &m.data, encoding, m.log_time_ns).unwrap();
                scan.packets
                    .into_iter()
                    .map(|(stamp, _)| stamp)
                    .collect::<Vec<_>>()
            })
            .collect();
        let recorded_s = (stamps.last().unwrap() - stamps.first().unwrap()) as f64 * 1e-9;
        // The model as the drive finds it: from the first packet, or an Ouster's
        // metadata.
        let (model, calibration) = match ouster {
            Some(metadata) => (
                PacketModel::Ouster(metadata.model),
                PacketCalibration::Ouster(Box::new(metadata)),
            ),
            None => {
                let encoding = messages[0].connection.encoding().unwrap();
                let first = packet_message(message_type, &messages[0].data, encoding, 0).unwrap();
                let model = PacketModel::of_packet(message_type, first.packets[0].1).unwrap();
                (model, PacketCalibration::for_model(model, None).unwrap())
            }
        };
        let mut points = 0;
        let seconds: Vec<f64> = (0..50)
            .map(|_| {
                let mut assembler = PacketAssembler::new(model, &calibration).unwrap();
                let start = Instant::now();
                points = 0;
                for m in &messages {
                    let encoding = m.connection.encoding().unwrap();
                    for scan in assembler
                        .push_message(message_type, &m.data, encoding, m.log_time_ns)
                        .unwrap()
                    {
                        points += scan.points.len();
                    }
                }
                start.elapsed().as_secs_f64()
            })
            .collect();
        let seconds = median(seconds);
        println!(
            "{:<12} {:>8} {:>10} {:>12.2} {:>14.3} {:>10.0}",
            model.name(),
            stamps.len(),
            points,
            seconds * 1e6 / stamps.len() as f64,
            recorded_s,
            recorded_s / seconds
        );
    }
}
