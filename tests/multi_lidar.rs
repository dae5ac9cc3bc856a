//! Several LiDARs merged into one scan per period (`--cloud-topic all`): a log made
//! from the shipped real scans, each split into two sensors' clouds (the first half
//! of its points as `/front_points` in the scanner's frame, the second half as
//! `/rear_points` in a rear sensor's frame, turned around and mounted 1.5 m back
//! and 0.25 m up on /tf_static), must give the same scans and grids as the scans
//! themselves.

use std::path::Path;

use crate::common::{
    arg, assert_contains, clean_failure, json_records, stderr, success, tf, travmap, usage_error,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use travmap_formats::mcap::writer::Compression;
use travmap_io::InputFormat;
use travmap_io::Log;
use travmap_io::{LogOptions, MergedTopics};
use travmap_io::{Source, SourceOptions};
use travmap_outputs::conversion::scan_to_cloud;
use travmap_outputs::writing::McapSink;

fn rear_from_velodyne() -> Isometry3<f64> {
    let velodyne_from_rear = Isometry3::from_parts(
        Translation3::new(-1.5, 0.0, 0.25),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::PI),
    );
    velodyne_from_rear.inverse()
}

/// The shipped drive as a two-sensor log; the rear sensor falls silent for the
/// last scan. The clouds name `frame_ids` (front, rear) as their frames; the
/// transforms are those of `velodyne` and `rear`. Returns the number of points of
/// each scan.
fn write_two_sensor_log(seq: &Path, path: &Path, frame_ids: [&str; 2]) -> Vec<usize> {
    let source = travmap_io::Source::open(seq, &Default::default(), &|_| {}).unwrap();
    let mut sink = McapSink::create(path, Compression::Zstd).unwrap();
    sink.write(
        "/tf_static",
        0,
        &tf(0, "velodyne", "rear", &rear_from_velodyne().inverse()),
    )
    .unwrap();
    let frames: Vec<_> = source.read(&(0..usize::MAX)).map(Result::unwrap).collect();
    let mut sizes = Vec::new();
    for (i, frame) in frames.iter().enumerate() {
        let stamp = 1_600_000_000_000_000_000 + frame.stamp_ns;
        sink.write(
            "/tf",
            stamp,
            &tf(stamp, "map", "velodyne", &frame.world_from_velodyne),
        )
        .unwrap();
        let half = frame.points_in_velodyne.len() / 2;
        let front = travmap_core::frame::Frame {
            points_in_velodyne: frame.points_in_velodyne[..half].to_vec(),
            labels: frame.labels.as_ref().map(|l| l[..half].to_vec()),
            ..frame.clone()
        };
        let rear_pose = rear_from_velodyne();
        let rear = travmap_core::frame::Frame {
            points_in_velodyne: frame.points_in_velodyne[half..]
                .iter()
                .map(|p| {
                    let q =
                        rear_pose * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                    [q.x as f32, q.y as f32, q.z as f32, p[3]]
                })
                .collect(),
            labels: frame.labels.as_ref().map(|l| l[half..].to_vec()),
            ..frame.clone()
        };
        let mut front_cloud = scan_to_cloud(&front, stamp);
        front_cloud.header.frame_id = frame_ids[0].into();
        sink.write("/front_points", stamp, &front_cloud).unwrap();
        let mut rear_cloud = scan_to_cloud(&rear, stamp);
        rear_cloud.header.frame_id = frame_ids[1].into();
        // 20 ms after the front: within half a period.
        if i + 1 < frames.len() {
            sink.write("/rear_points", stamp + 20_000_000, &rear_cloud)
                .unwrap();
        }
        sizes.push(frame.points_in_velodyne.len());
    }
    sink.finish().unwrap();
    sizes
}

#[test]
fn two_sensors_merge_into_the_scans_they_were_cut_from() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let log_path = dir.path().join("two.mcap");
    let sizes = write_two_sensor_log(&seq, &log_path, ["velodyne", "rear"]);

    // Without a choice: the two topics are named, with the hint for `all`.
    let err = clean_failure(travmap(&["run", arg(&log_path)]));
    assert_contains(
        &err,
        &[
            "several PointCloud2 topics",
            "--cloud-topic all",
            "/rear_points",
        ],
    );

    // The library: every scan holds both sensors but the last, all points in the
    // front sensor's frame, back where they were.
    let merged = Source::open(&log_path, &merging_every_topic(), &|_| {}).unwrap();
    assert_eq!(cloud_topic(&merged), "/front_points");
    let source = Source::open(&seq, &Default::default(), &|_| {}).unwrap();
    let originals: Vec<_> = source.read(&(0..usize::MAX)).map(Result::unwrap).collect();
    let frames: Vec<_> = merged.read(&(0..usize::MAX)).map(Result::unwrap).collect();
    assert_eq!(frames.len(), sizes.len());
    for (i, (frame, original)) in frames.iter().zip(&originals).enumerate() {
        let last = i + 1 == frames.len();
        let sensors: Vec<&str> = frame.sensors.iter().map(String::as_str).collect();
        if last {
            assert_eq!(sensors, ["/front_points"], "the rear fell silent");
            assert_eq!(frame.points_in_velodyne.len(), sizes[i] / 2);
            continue;
        }
        assert_eq!(sensors, ["/front_points", "/rear_points"]);
        assert_eq!(frame.points_in_velodyne.len(), sizes[i]);
        let worst = frame
            .points_in_velodyne
            .iter()
            .zip(&original.points_in_velodyne)
            .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0f32, f32::max))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "frame {i}: a point moved {worst} m");
        assert_eq!(frame.labels, original.labels, "labels follow their points");
    }

    // The command line: the merged drive's grids are the scans' own.
    let merged = success(travmap(&[
        "run",
        arg(&log_path),
        "--cloud-topic",
        "all",
        "--json",
    ]));
    let (merged, _) = json_records(&merged);
    let (own, _) = json_records(&success(travmap(&["run", arg(&seq), "--json"])));
    let cells = |f: &serde_json::Value| f["cells"].as_array().unwrap().clone();
    for i in 0..own.len() - 1 {
        let (a, b) = (cells(&merged[i]), cells(&own[i]));
        let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
        println!("frame {i}: {same} of {} cells as the scan's own", a.len());
        assert!(
            same * 1000 >= a.len() * 998,
            "frame {i}: {same} of {} cells",
            a.len()
        );
    }
    // Naming the topics does the same as `all`.
    let named = travmap(&[
        "run",
        arg(&log_path),
        "--cloud-topic",
        "/front_points",
        "--cloud-topic",
        "/rear_points",
        "--json",
    ]);
    let (named, _) = json_records(&success(named));
    assert_eq!(cells(&named[0]), cells(&merged[0]));
}

/// Drivers that leave `frame_id` empty (or at a default that is not the sensor's
/// frame on /tf): `--lidar-frame` names each topic's frame, and the drive reads as
/// the log that named them.
#[test]
fn lidar_frame_places_clouds_that_name_no_frame() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (named, unnamed) = (
        dir.path().join("named.mcap"),
        dir.path().join("unnamed.mcap"),
    );
    write_two_sensor_log(&seq, &named, ["velodyne", "rear"]);
    write_two_sensor_log(&seq, &unnamed, ["", "laser"]);
    let run = |log: &Path, more: &[&str]| {
        travmap(&[&["run", arg(log), "--cloud-topic", "all", "--json"], more].concat())
    };
    let cells = |output| -> Vec<serde_json::Value> {
        let (records, _) = json_records(&success(output));
        records.iter().map(|r| r["cells"].clone()).collect()
    };
    let expected = cells(run(&named, &[]));
    let frames = [
        "--lidar-frame",
        "velodyne",
        "--lidar-frame",
        "/rear_points=rear",
    ];
    assert_eq!(cells(run(&unnamed, &frames)), expected);
    // A topic of its own for each works as well; the log's own frames can be named
    // again without changing anything.
    let each = [
        "--lidar-frame",
        "/front_points=velodyne",
        "--lidar-frame",
        "/rear_points=rear",
    ];
    assert_eq!(cells(run(&unnamed, &each)), expected);
    assert_eq!(cells(run(&named, &each)), expected);
    // The errors (without --json: said on stderr).
    let fail = |log: &Path, more: &[&str]| {
        clean_failure(travmap(
            &[&["run", arg(log), "--cloud-topic", "all"], more].concat(),
        ))
    };
    // One frame for two sensors would merge them as if mounted in one place.
    assert_contains(
        &fail(&unnamed, &["--lidar-frame", "velodyne"]),
        &[
            "--lidar-frame velodyne would place 2 LiDAR topics (/front_points, /rear_points) in one frame",
        ],
    );
    // Unplaced, the rear sensor's frame is not on /tf: said so, with the flag.
    assert_contains(
        &fail(&unnamed, &["--lidar-frame", "/front_points=velodyne"]),
        &["no transform links `laser`", "--lidar-frame TOPIC=FRAME"],
    );
    // One sensor: the empty frame is not on /tf, and the notice says what to do.
    let front_only = travmap(&["run", arg(&unnamed), "--cloud-topic", "/front_points"]);
    assert_contains(
        &stderr(&front_only),
        &["the clouds' frame_id is empty: --lidar-frame names the LiDAR's frame"],
    );
    // A topic that is not read is named with those that are.
    assert_contains(
        &fail(&named, &["--lidar-frame", "/points=velodyne"]),
        &[
            "--lidar-frame /points=...",
            "those are /front_points, /rear_points",
        ],
    );
    let twice = [
        "run",
        arg(&named),
        "--lidar-frame",
        "a",
        "--lidar-frame",
        "b",
    ];
    assert_contains(
        &usage_error(travmap(&twice)),
        &["two frames without a topic: give them as TOPIC=FRAME"],
    );
}

/// Nebula's Pandar XT32 test packets on two topics, as two sensors would record
/// them: `/front/pandar_packets` as recorded, `/rear/pandar_packets` the same
/// packets in frame `hrear`, mounted as the rear sensor above. Both are cut into
/// scans and merged as clouds are; convert decodes both.
#[test]
fn packet_topics_merge_as_clouds_do() {
    let bag = crate::common::nebula_fixture("xt32/1673400677802009732");
    let dir = tempfile::tempdir().unwrap();
    let log_path = dir.path().join("two_pandars.mcap");
    let mut sink = McapSink::create(&log_path, Compression::Zstd).unwrap();
    let velodyne_from_rear = rear_from_velodyne().inverse();
    sink.write(
        "/tf_static",
        0,
        &tf(0, "hesai", "hrear", &velodyne_from_rear),
    )
    .unwrap();
    for message in Log::open(&bag, InputFormat::Rosbag2).unwrap().messages() {
        let message = message.unwrap();
        let c = &message.connection;
        for (topic, frame) in [
            ("/front/pandar_packets", b"hesai"),
            ("/rear/pandar_packets", b"hrear"),
        ] {
            let id = sink
                .channel(
                    topic,
                    &c.schema_name,
                    &c.schema_encoding,
                    &c.schema_data,
                    &c.message_encoding,
                )
                .unwrap();
            // The header's frame_id: as long as the recorded one, so nothing moves.
            let mut data = message.data.clone();
            assert_eq!(&data[16..22], b"hesai\0");
            data[16..21].copy_from_slice(frame);
            sink.write_raw(id, message.log_time_ns, message.publish_time_ns, data)
                .unwrap();
        }
    }
    sink.finish().unwrap();

    let merged = Source::open(&log_path, &merging_every_topic(), &|_| {}).unwrap();
    assert_eq!(cloud_topic(&merged), "/front/pandar_packets");
    let frames: Vec<_> = merged.read(&(0..usize::MAX)).map(Result::unwrap).collect();
    assert_eq!(frames.len(), 4);
    for frame in &frames {
        let sensors: Vec<&str> = frame.sensors.iter().map(String::as_str).collect();
        assert_eq!(sensors, ["/front/pandar_packets", "/rear/pandar_packets"]);
        let (front, rear) = frame
            .points_in_velodyne
            .split_at(frame.points_in_velodyne.len() / 2);
        // The rear sensor saw what the front did, from where it is mounted.
        let worst = front
            .iter()
            .zip(rear)
            .map(|(f, r)| {
                let moved = velodyne_from_rear
                    * nalgebra::Point3::new(f[0] as f64, f[1] as f64, f[2] as f64);
                let r = [r[0] as f64, r[1] as f64, r[2] as f64];
                (0..3).map(|k| (moved[k] - r[k]).abs()).fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-4,
            "frame {}: a rear point {worst} m off",
            frame.index
        );
        assert!(
            front.iter().zip(rear).all(|(f, r)| f[3] == r[3]),
            "intensity"
        );
    }
    let sizes: Vec<usize> = frames
        .iter()
        .map(|f| f.points_in_velodyne.len() / 2)
        .collect();
    assert_eq!(sizes, [62_826, 63_058, 63_040, 63_021]);

    // convert decodes every packet topic read, each in its own frame.
    let converted = dir.path().join("converted.mcap");
    let doc = crate::common::json_summary(&[
        "convert",
        arg(&log_path),
        "--cloud-topic",
        "all",
        "-o",
        arg(&converted),
    ]);
    assert_eq!(
        doc["decoded_topics"],
        serde_json::json!(["/front/pandar_points", "/rear/pandar_points"])
    );
    assert_eq!(doc["decoded_scans"], 8);
    let log = Log::open(&converted, InputFormat::Mcap).unwrap();
    let frames_of = |topic: &str| -> Vec<String> {
        (log.messages().map(Result::unwrap))
            .filter(|m| m.connection.topic == topic)
            .map(|m| {
                travmap_formats::ros::decode::<travmap_formats::ros::PointCloud2>(&m.data).unwrap()
            })
            .map(|cloud| cloud.header.frame_id)
            .collect()
    };
    assert_eq!(frames_of("/front/pandar_points"), ["hesai"; 4]);
    assert_eq!(frames_of("/rear/pandar_points"), ["hrear"; 4]);

    // One calibration file for two sensors: refused at the one it does not fit,
    // with the way to give each its own; a file per topic is taken.
    let xt16 = dir.path().join("PandarXT16.csv");
    std::fs::write(&xt16, "Channel,Elevation,Azimuth\n1,15,0\n2,13,0\n").unwrap();
    let all = ["run", arg(&log_path), "--cloud-topic", "all"];
    let err = clean_failure(travmap(
        &[&all[..], &["--lidar-calibration", arg(&xt16)]].concat(),
    ));
    assert_contains(
        &err,
        &[
            "/front/pandar_packets (Pandar XT32 packets)",
            "2 lasers for the Pandar XT32",
            "--lidar-calibration /front/pandar_packets=FILE",
        ],
    );
    let rear_only = format!("/rear/pandar_packets={}", xt16.display());
    let err = clean_failure(travmap(
        &[&all[..], &["--lidar-calibration", &rear_only]].concat(),
    ));
    assert_contains(
        &err,
        &["/rear/pandar_packets (Pandar XT32 packets)", "2 lasers"],
    );
    assert!(
        !err.contains("TOPIC=FILE") && !err.contains("=FILE"),
        "{err}"
    );
}

/// Reading a log with every cloud or packet topic merged into the scans
/// (`--cloud-topic all`).
/// The topic a log's frames' scans come from.
fn cloud_topic(source: &Source) -> String {
    match source.recorded() {
        travmap_io::Recorded::Log(log) => log.cloud_topic().to_string(),
        _ => panic!("{} is not a log", source.path().display()),
    }
}

fn merging_every_topic() -> SourceOptions {
    SourceOptions {
        log: LogOptions {
            merged_topics: MergedTopics::All,
            ..Default::default()
        },
        ..Default::default()
    }
}
