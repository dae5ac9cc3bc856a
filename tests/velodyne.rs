//! A Velodyne packet log (tier4/nebula's, `fixtures/nebula/`) as a drive for every
//! command; its decoding against nebula's own points is the reader's test
//! (`crates/io/src/packets/velodyne/nebula_tests.rs`).

use crate::common::nebula_fixture;

use travmap_io::{InputFormat, Log};

#[test]
fn a_packet_log_is_a_drive_for_every_command() {
    use crate::common::{arg, assert_contains, clean_failure, json_records, success, travmap};
    let bag = nebula_fixture("vlp32/1713492677464078412");
    // The scans run cuts are the scans the library assembles (cut angle 0).
    let scans = crate::common::packet_scans(&bag);
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
