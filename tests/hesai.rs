//! Hesai packet logs (tier4/nebula's, `fixtures/nebula/`) through the commands; their
//! decoding against nebula's points is the reader's test
//! (`crates/io/src/packets/hesai/nebula_tests.rs`).

use crate::common::nebula_fixture;

use travmap_io::{InputFormat, Log};

#[test]
fn a_pandar_log_is_a_drive_for_every_command() {
    use crate::common::{arg, json_records, success, travmap};
    let bag = nebula_fixture("xt32/1673400677802009732");
    let scans = crate::common::packet_scans(&bag);
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
        convert["one_thread"]["recorded_s_per_wall_s"]
            .as_f64()
            .unwrap()
            > 0.0,
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
