//! `cargo bench --bench velodyne`: Velodyne packets decoded and cut into scans on one
//! thread, on nebula's VLP-32C and VLP-16 test logs (`fixtures/nebula/`): the median
//! time per packet and per second of recording, and the real-time factor (seconds of
//! recording decoded per second). Asserts nothing about time.

use std::path::Path;
use std::time::Instant;

use travmap::io::format::InputFormat;
use travmap::io::log::Log;
use travmap::io::velodyne::{
    Calibration, Decoder, DecoderSettings, ScanAssembler, VelodyneModel, scan_message,
};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/nebula");
    println!(
        "{:<8} {:>8} {:>10} {:>12} {:>14} {:>10}",
        "model", "packets", "points", "us/packet", "recorded s", "x realtime"
    );
    for (model, bag) in [
        (VelodyneModel::Vlp32c, "vlp32/1713492677464078412"),
        (VelodyneModel::Vlp16, "vlp16/1673400471837873222"),
    ] {
        let log = Log::open(&fixtures.join(bag), InputFormat::Rosbag2).unwrap();
        let messages: Vec<_> = log.messages().map(Result::unwrap).collect();
        let packets: Vec<(u64, Vec<u8>)> = messages
            .iter()
            .flat_map(|m| {
                let scan = scan_message(&m.data, m.connection.encoding().unwrap()).unwrap();
                scan.packets
                    .into_iter()
                    .map(|(stamp, p)| (stamp, p.to_vec()))
                    .collect::<Vec<_>>()
            })
            .collect();
        let recorded_s = (packets.last().unwrap().0 - packets.first().unwrap().0) as f64 * 1e-9;
        let mut points = 0;
        let seconds: Vec<f64> = (0..50)
            .map(|_| {
                let calibration = Calibration::builtin(model).unwrap();
                let decoder = Decoder::new(model, calibration, DecoderSettings::default());
                let mut assembler = ScanAssembler::new(decoder.unwrap());
                let start = Instant::now();
                points = 0;
                for (stamp, packet) in &packets {
                    if let Some(scan) = assembler.push(packet, *stamp).unwrap() {
                        points += scan.points.len();
                    }
                }
                start.elapsed().as_secs_f64()
            })
            .collect();
        let seconds = median(seconds);
        println!(
            "{:<8} {:>8} {:>10} {:>12.2} {:>14.3} {:>10.0}",
            model.name(),
            packets.len(),
            points,
            seconds * 1e6 / packets.len() as f64,
            recorded_s,
            recorded_s / seconds
        );
    }
}
