//! MCAP in and out: convert, read back, annotate, round trip, and real clients
//! (Python mcap + mcap-ros2-support, rosbags) decoding what travmap writes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{
    arg, assert_contains, clean_failure, json_summary, messages, success, travmap, write_output,
};
use serde_json::Value;
use travmap_formats::mcap::writer::Compression;
use travmap_formats::ros::{OccupancyGrid, PointCloud2, decode};
use travmap_io::LogOptions;
use travmap_io::{Source, SourceOptions};
use travmap_outputs::writing::McapSink;

#[test]
fn converted_drive_gives_the_same_frames_and_grids_as_the_kitti_directory() {
    let dir = tempfile::tempdir().unwrap();
    let Some((seq, drive)) = crate::common::sample_as_mcap(dir.path(), &[]) else {
        return;
    };

    // The frames read back: same points, labels, stamps and poses, bit for bit.
    let kitti = crate::common::read_frames(&seq);
    let source = Source::open(&drive, &SourceOptions::default(), &|_| {}).unwrap();
    assert_eq!(source.frames().len(), 6);
    assert_eq!(source.world_frame(), "map");
    let mut index = 0;
    for frame in source.read(&(0..6)) {
        let frame = frame.unwrap();
        let expected = &kitti[index];
        assert_eq!(frame.index, expected.index);
        assert_eq!(frame.stamp_ns, expected.stamp_ns);
        assert_eq!(frame.points_in_velodyne, expected.points_in_velodyne);
        assert_eq!(frame.labels, expected.labels);
        assert_eq!(
            frame.world_from_velodyne, expected.world_from_velodyne,
            "frame {index}"
        );
        index += 1;
    }
    assert_eq!(index, 6);

    // Annotating either input gives the same grids, to the last cell, and the same metrics.
    let from_kitti = dir.path().join("a.mcap");
    let from_mcap = dir.path().join("b.mcap");
    let a = json_summary(&["annotate", arg(&seq), "-o", arg(&from_kitti)]);
    let b = json_summary(&["annotate", arg(&drive), "-o", arg(&from_mcap)]);
    assert_eq!(a["confusion"], b["confusion"]);
    for topic in ["/travmap/prediction", "/travmap/ground_truth"] {
        let (x, y) = (
            messages::<OccupancyGrid>(&from_kitti, topic),
            messages::<OccupancyGrid>(&from_mcap, topic),
        );
        assert!(!x.is_empty());
        assert_eq!(x, y, "{topic}");
    }
    assert_eq!(
        messages::<OccupancyGrid>(&from_kitti, "/travmap/prediction").len(),
        6
    );
    assert_eq!(
        messages::<OccupancyGrid>(&from_kitti, "/travmap/ground_truth").len(),
        3
    );
}

#[test]
fn annotated_grid_matches_run_and_carries_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let flags = ["--frames", "1..4", "--no-passthrough"];
    let Some((seq, out)) = crate::common::sample_annotated(dir.path(), &flags) else {
        return;
    };
    let run = success(travmap(&["run", arg(&seq), "--frames", "1..4", "--json"]));
    let (runs, _) = crate::common::json_records(&run);
    let grids = messages::<OccupancyGrid>(&out, "/travmap/prediction");
    assert_eq!(grids.len(), 3);
    for ((log_time, grid), run) in grids.iter().zip(&runs) {
        let cells: Vec<i8> = run["cells"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_i64().unwrap() as i8)
            .collect();
        assert_eq!(grid.data, cells);
        assert_eq!(*log_time, run["stamp_ns"].as_u64().unwrap());
        assert_eq!(grid.info.width, 30);
        assert_eq!(grid.header.frame_id, "map");
        let corner = run["min_corner_in_world"].as_array().unwrap();
        assert_eq!(grid.info.origin.position.x, corner[0].as_f64().unwrap());
    }
    // No passthrough: only travmap's own topics.
    let bytes = std::fs::read(&out).unwrap();
    let topics: std::collections::BTreeSet<String> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap().channel.topic.clone())
        .collect();
    assert!(
        topics.iter().all(|t| t.starts_with("/travmap/")),
        "{topics:?}"
    );
    let metadata = crate::common::travmap_metadata(&bytes);
    assert_eq!(metadata["travmap_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(metadata["model_sha256"].len(), 64);
    let config: Value = serde_json::from_str(&metadata["config"]).unwrap();
    assert_eq!(config["grid"]["size_m"], 12.0);
}

#[test]
fn the_cloud_is_the_scan_in_the_grid_the_whole_scan_or_none() {
    let dir = tempfile::tempdir().unwrap();
    let annotated = |cloud: &str| {
        let flags = ["--frames", "0..4", "--no-passthrough", "--cloud", cloud];
        let out = dir.path().join(format!("{cloud}.mcap"));
        let seq = crate::common::sample()?;
        write_output("annotate", &seq, &out, &flags);
        Some((seq, out))
    };
    let Some((seq, grid_file)) = annotated("grid") else {
        return;
    };
    let (_, all_file) = annotated("all").unwrap();
    let (_, none_file) = annotated("none").unwrap();
    assert!(messages::<PointCloud2>(&none_file, "/travmap/cloud").is_empty());
    let grids = messages::<OccupancyGrid>(&grid_file, "/travmap/prediction");
    let truths = messages::<OccupancyGrid>(&grid_file, "/travmap/ground_truth");
    let in_grid = messages::<PointCloud2>(&grid_file, "/travmap/cloud");
    let whole = messages::<PointCloud2>(&all_file, "/travmap/cloud");
    assert_eq!((in_grid.len(), whole.len()), (4, 4));
    let sequence = crate::common::read_frames(&seq);
    for (frame, (((_, grid), (_, truth)), ((_, in_grid), (_, whole)))) in grids
        .iter()
        .zip(&truths)
        .zip(in_grid.iter().zip(&whole))
        .enumerate()
    {
        let scan_points = sequence[frame].points_in_velodyne.len();
        assert_eq!(whole.width as usize, scan_points, "frame {frame}");
        // Each point with the values of its cell, -1 outside the grid.
        let (origin, r, side) = (&grid.info.origin.position, grid.info.resolution as f64, 30);
        let cell_of = |point: &[u8]| {
            let v = |at: usize| f64::from_le_bytes(point[at..at + 8].try_into().unwrap());
            let (col, row) = ((v(0) - origin.x) / r, (v(8) - origin.y) / r);
            (col >= 0.0 && row >= 0.0 && col < side as f64 && row < side as f64)
                .then(|| row as usize * side + col as usize)
        };
        let check = |cloud: &PointCloud2| {
            let mut inside = 0;
            for point in cloud.data.chunks_exact(cloud.point_step as usize) {
                let cell = cell_of(point);
                let expected = cell.map_or([-1, -1], |c| [grid.data[c], truth.data[c]]);
                assert_eq!(
                    [point[24] as i8, point[25] as i8],
                    expected,
                    "frame {frame}"
                );
                inside += usize::from(cell.is_some());
            }
            inside
        };
        let whole_inside = check(whole);
        // The grid cloud is exactly the scan's points inside the grid.
        assert_eq!(check(in_grid), in_grid.width as usize);
        assert_eq!(in_grid.width as usize, whole_inside, "frame {frame}");
        assert!(whole_inside > 10_000 && whole_inside < scan_points / 2);
    }
}

/// Checks one client's summary of an annotated file of the whole sample against
/// travmap's own values: message counts, point counts, first and last points,
/// stamps, and grid cells as `travmap run` prints them.
fn check_client_summary(client: &str, entries: &[Value], seq: &Path, runs: &[Value]) {
    let on = |topic: &str| {
        entries
            .iter()
            .filter(|e| e["topic"] == topic)
            .collect::<Vec<_>>()
    };
    assert_eq!(on("/tf_static").len(), 1, "{client}");
    assert_eq!(on("/tf").len(), 6, "{client}");
    assert_eq!(on("/travmap/metrics").len(), 6, "{client}");
    assert_eq!(on("/travmap/ground_truth").len(), 3, "{client}");
    let sequence = crate::common::read_frames(seq);
    for (cloud, frame) in on("/velodyne_points").iter().zip(&sequence) {
        assert_eq!(cloud["points"], frame.points_in_velodyne.len(), "{client}");
        // Clients print each float32 as its shortest double; compare as float32.
        let as_f32 = |v: &Value| -> Vec<f32> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect()
        };
        assert_eq!(
            as_f32(&cloud["first"]),
            frame.points_in_velodyne[0][..3],
            "{client}"
        );
        assert_eq!(
            as_f32(&cloud["last"]),
            frame.points_in_velodyne.last().unwrap()[..3],
            "{client}"
        );
        assert_eq!(cloud["stamp"], frame.stamp_ns, "{client}");
        assert_eq!(cloud["log_time"], frame.stamp_ns, "{client}");
        let fields: Vec<&str> = cloud["fields"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f.as_str().unwrap())
            .collect();
        let expected = if frame.labels.is_some() {
            vec!["x", "y", "z", "intensity", "label"]
        } else {
            vec!["x", "y", "z", "intensity"]
        };
        assert_eq!(fields, expected, "{client}");
    }
    // The float layers: grid_map's geometry and order, placed where the
    // OccupancyGrids are; the ground-truth layer the same cells as theirs.
    let layers = on("/travmap/grid_map");
    let truths = on("/travmap/ground_truth");
    assert_eq!(layers.len(), runs.len(), "{client}");
    for (frame, layer) in layers.iter().enumerate() {
        let grid = &on("/travmap/prediction")[frame];
        assert_eq!(
            layer["resolution"].as_f64().unwrap() as f32,
            grid["resolution"].as_f64().unwrap() as f32,
            "{client}"
        );
        let length: Vec<f64> = (layer["length"].as_array().unwrap().iter())
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(length, [12.0, 12.0], "{client}");
        for axis in 0..2 {
            let centre = layer["centre"][axis].as_f64().unwrap();
            let origin = grid["origin"][axis].as_f64().unwrap();
            assert!(
                (centre - (origin + 6.0)).abs() < 1e-9,
                "{client}: {centre} {origin}"
            );
        }
        let names: Vec<&str> = layer["layers"]
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        let expected = if frame < 3 { 5 } else { 4 };
        assert_eq!(names.len(), expected, "{client}: {names:?}");
        let traversability = layer["layers"]["traversability"]["values"]
            .as_array()
            .unwrap();
        assert_eq!(traversability.len(), 900, "{client}");
        assert!(
            traversability
                .iter()
                .filter_map(Value::as_f64)
                .all(|p| (0.0..=1.0).contains(&p))
        );
        assert_eq!(
            layer["layers"]["traversability"]["dims"],
            serde_json::json!([["column_index", 30, 900], ["row_index", 30, 30]]),
            "{client}"
        );
        if let Some(truth) = truths.get(frame) {
            // grid_map (i, j) along -x, -y, column-major; the OccupancyGrid row-major
            // from its min corner.
            let values = layer["layers"]["ground_truth"]["values"]
                .as_array()
                .unwrap();
            let cells = truth["cells"].as_array().unwrap();
            for j in 0..30 {
                for i in 0..30 {
                    let cell = &cells[(29 - j) * 30 + (29 - i)];
                    let expected = match cell.as_i64().unwrap() {
                        0 => Some(1.0),
                        100 => Some(0.0),
                        _ => None,
                    };
                    assert_eq!(
                        values[j * 30 + i].as_f64(),
                        expected,
                        "{client}: i {i} j {j}"
                    );
                }
            }
        }
    }
    // The same layers for Foxglove: row-major from the OccupancyGrid's corner.
    let foxglove = on("/travmap/grid");
    assert_eq!(foxglove.len(), runs.len(), "{client}");
    for (frame, grid) in foxglove.iter().enumerate() {
        let occupancy = &on("/travmap/prediction")[frame];
        assert_eq!(grid["column_count"], 30, "{client}");
        assert_eq!(grid["origin"], occupancy["origin"], "{client}");
        let layer = &layers[frame]["layers"];
        for (name, values) in grid["layers"].as_object().unwrap() {
            let by_grid_map = layer[name]["values"].as_array().unwrap();
            for j in 0..30 {
                for i in 0..30 {
                    let (col, row) = (29 - i, 29 - j);
                    assert_eq!(
                        values[row * 30 + col].as_f64().map(|v| v as f32),
                        by_grid_map[j * 30 + i].as_f64().map(|v| v as f32),
                        "{client}: {name} cell ({col}, {row})"
                    );
                }
            }
        }
    }
    let grids = on("/travmap/prediction");
    assert_eq!(grids.len(), runs.len(), "{client}");
    for (grid, run) in grids.iter().zip(runs) {
        assert_eq!(grid["cells"], run["cells"], "{client}");
        assert_eq!(grid["stamp"], run["stamp_ns"], "{client}");
        assert_eq!(grid["width"], 30, "{client}");
    }
    let with_truth: Vec<bool> = on("/travmap/metrics")
        .iter()
        .map(|m| m["accuracy"].is_number())
        .collect();
    assert_eq!(
        with_truth,
        [true, true, true, false, false, false],
        "{client}"
    );
}

/// Each client's entries, sorted by topic and time (clients differ in reading order).
fn sorted(entries: &Value) -> Vec<Value> {
    let mut v = entries.as_array().unwrap().clone();
    v.sort_by_key(|e| {
        (
            e["topic"].as_str().unwrap().to_string(),
            e["log_time"].as_u64().unwrap(),
        )
    });
    v
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn real_clients_decode_what_travmap_writes() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let python = std::env::var("TRAVMAP_CLIENT_PYTHON").ok();
    let node_modules = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/node_modules");
    if python.is_none() && !node_modules.is_dir() {
        crate::common::skip::<()>(
            "no client installed (.ci/run sets TRAVMAP_CLIENT_PYTHON to a venv with mcap, \
             mcap-ros2-support and rosbags, and runs npm ci in tests/clients)",
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let run = success(travmap(&["run", arg(&seq), "--json"]));
    let (runs, _) = crate::common::json_records(&run);
    for out in annotated_both_ways(dir.path(), &seq) {
        decode_with_every_client(&out, &seq, &runs, python.as_deref(), &node_modules);
    }
}

/// The shipped sample annotated from its directory, and from its MCAP conversion,
/// whose messages annotate copies chunk by chunk as stored (checked here).
fn annotated_both_ways(dir: &Path, seq: &Path) -> [std::path::PathBuf; 2] {
    let (from_kitti, drive, from_mcap) = (
        dir.join("from-kitti.mcap"),
        dir.join("drive.mcap"),
        dir.join("from-mcap.mcap"),
    );
    write_output("annotate", seq, &from_kitti, &[]);
    write_output("convert", seq, &drive, &[]);
    write_output("annotate", &drive, &from_mcap, &[]);
    let (input, output) = (
        std::fs::read(&drive).unwrap(),
        std::fs::read(&from_mcap).unwrap(),
    );
    let summary = mcap::Summary::read(&input).unwrap().unwrap();
    for chunk in &summary.chunk_indexes {
        let start = chunk.chunk_start_offset as usize;
        let stored = &input[start..start + chunk.chunk_length as usize];
        assert!(
            output.windows(stored.len()).any(|w| w == stored),
            "the input's chunk at {start} is not in the annotated file as stored"
        );
    }
    [from_kitti, from_mcap]
}

fn decode_with_every_client(
    out: &Path,
    seq: &Path,
    runs: &[Value],
    python: Option<&str>,
    node_modules: &Path,
) {
    let clients = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients");
    let decode = |program: &str, script: &str| -> Value {
        let decoded =
            crate::common::run_client(Command::new(program).arg(clients.join(script)).arg(out));
        serde_json::from_slice(&decoded.stdout).unwrap()
    };
    let mut summaries = Vec::new();
    if let Some(python) = python {
        let doc = decode(python, "decode_mcap.py");
        summaries.push(("python mcap-ros2-support", sorted(&doc["mcap"])));
        summaries.push(("python rosbags", sorted(&doc["rosbags"])));
    } else {
        crate::common::skip::<()>("the Python clients: TRAVMAP_CLIENT_PYTHON is not set");
    }
    if node_modules.is_dir() {
        summaries.push((
            "node @mcap/core + rosmsg2-serialization",
            sorted(&decode("node", "decode_mcap.mjs")),
        ));
    } else {
        crate::common::skip::<()>("the Node client: run npm ci in tests/clients");
    }
    for (client, entries) in &summaries {
        check_client_summary(client, entries, seq, runs);
        // 6 clouds, 6 /tf, 1 /tf_static, 6 + 3 grids, 6 grid maps, 6 Foxglove
        // grids, 6 classified clouds, 6 metrics, 1 drive map.
        assert_eq!(
            entries.len(),
            47,
            "{client}: every message decoded in {out:?}"
        );
    }
}

/// Every message of an MCAP file in log-time order: (topic, log time, sequence-free
/// content), read through its index by the mcap crate.
fn decoded(path: &Path) -> Vec<(String, u64, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let mut messages: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| {
            let m = m.unwrap();
            (m.channel.topic.clone(), m.log_time, m.data.to_vec())
        })
        .collect();
    messages.sort_by(|a, b| (&a.0, a.1).cmp(&(&b.0, b.1)));
    messages
}

#[test]
fn convert_copies_a_ros2_mcap_chunk_by_chunk_unless_asked_for_another_compression() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_, drive)) = crate::common::sample_as_mcap(dir.path(), &[]) else {
        return;
    };
    let (same, none) = (dir.path().join("same.mcap"), dir.path().join("none.mcap"));
    write_output("convert", &drive, &same, &[]);
    write_output("convert", &drive, &none, &["--compression", "none"]);
    let chunks = |path: &Path| {
        let bytes = std::fs::read(path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let chunks: Vec<Vec<u8>> = summary
            .chunk_indexes
            .iter()
            .map(|c| {
                let start = c.chunk_start_offset as usize;
                bytes[start..start + c.chunk_length as usize].to_vec()
            })
            .collect();
        let compressions = summary.chunk_indexes.iter().map(|c| c.compression.clone());
        (chunks, compressions.collect::<Vec<_>>())
    };
    let (input_chunks, _) = chunks(&drive);
    assert_eq!(chunks(&same).0, input_chunks, "copied as stored");
    assert!(
        chunks(&none).1.iter().all(String::is_empty),
        "re-chunked uncompressed"
    );
    assert_eq!(decoded(&same), decoded(&drive));
    assert_eq!(decoded(&none), decoded(&drive));
}

#[test]
fn compression_options_all_round_trip() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let mut sizes = BTreeMap::new();
    for compression in ["zstd", "lz4", "none"] {
        let out = dir.path().join(format!("{compression}.mcap"));
        let (seq, out) = (arg(&seq), arg(&out));
        let doc = json_summary(&[
            "convert",
            seq,
            "-o",
            out,
            "--frames",
            "0..2",
            "--compression",
            compression,
        ]);
        assert_eq!(doc["frames"], 2);
        sizes.insert(compression, doc["output_bytes"].as_u64().unwrap());
        let eval = success(travmap(&["eval", out]));
        assert!(eval.contains("over 2 frames"), "{eval}");
    }
    assert!(
        sizes["zstd"] < sizes["lz4"] && sizes["lz4"] < sizes["none"],
        "{sizes:?}"
    );
    // No temporary files are left beside the outputs.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
}

/// A drive of two synthetic clouds in frame `lidar`, posed by Odometry of `base`
/// in `odom` and a static `base -> lidar`, with a second cloud topic.
fn write_odometry_drive(path: &Path) {
    use travmap_formats::ros::*;
    let mut sink = McapSink::create(path, Compression::None).unwrap();
    let covariance = FixedArray(vec![0.0; 36]);
    for (i, x) in [(0u64, 0.0), (1, 2.0)] {
        let stamp = 1_000_000_000 + i * 100_000_000;
        let odometry = Odometry {
            header: Header {
                stamp: Time::from_ns(stamp),
                frame_id: "odom".into(),
            },
            child_frame_id: "base".into(),
            pose: PoseWithCovariance {
                pose: Pose {
                    position: Vector3 { x, y: 0.0, z: 0.0 },
                    orientation: Quaternion::default(),
                },
                covariance: covariance.clone(),
            },
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: Vector3::default(),
                    angular: Vector3::default(),
                },
                covariance: covariance.clone(),
            },
        };
        let bytes = encode(&odometry, 0);
        let channel = sink
            .channel("/odom", "nav_msgs/msg/Odometry", "ros2msg", b"", "cdr")
            .unwrap();
        sink.write_raw(channel, stamp, stamp, bytes).unwrap();
    }
    let lidar = TfMessage {
        transforms: vec![TransformStamped {
            header: Header {
                stamp: Time::from_ns(0),
                frame_id: "base".into(),
            },
            child_frame_id: "lidar".into(),
            transform: Transform {
                translation: Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: 1.5,
                },
                rotation: Quaternion::default(),
            },
        }],
    };
    sink.write("/tf_static", 1_000_000_000, &lidar).unwrap();
    // The cloud at 1.05 s: float64 coordinates, big-endian, with an extra field
    // between them, and a NaN point.
    let mut data = Vec::new();
    for p in [[1.0f64, 2.0, 3.0], [f64::NAN, 0.0, 0.0], [4.0, 5.0, 6.0]] {
        data.extend_from_slice(&p[0].to_be_bytes());
        data.extend_from_slice(&7u16.to_be_bytes()); // ring
        data.extend_from_slice(&p[1].to_be_bytes());
        data.extend_from_slice(&p[2].to_be_bytes());
    }
    let field = PointField::scalar;
    let cloud = PointCloud2 {
        header: Header {
            stamp: Time::from_ns(1_050_000_000),
            frame_id: "lidar".into(),
        },
        height: 1,
        width: 3,
        fields: vec![
            field("ring", 8, datatype::UINT16),
            field("z", 18, datatype::FLOAT64),
            field("x", 0, datatype::FLOAT64),
            field("y", 10, datatype::FLOAT64),
        ],
        is_bigendian: true,
        point_step: 26,
        row_step: 78,
        data,
        is_dense: false,
    };
    sink.write("/points", 1_050_000_000, &cloud).unwrap();
    sink.write("/other_points", 1_050_000_000, &cloud).unwrap();
    sink.finish().unwrap();
}

#[test]
fn any_cloud_layout_posed_by_odometry_and_static_tf() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("odom.mcap");
    write_odometry_drive(&path);
    // Two cloud topics: ambiguous, and the error lists them.
    let err = match Source::open(&path, &SourceOptions::default(), &|_| {}) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("two cloud topics must be ambiguous"),
    };
    assert_contains(
        &err,
        &["several PointCloud2 topics", "/other_points", "/points"],
    );
    let err = clean_failure(travmap(&["run", arg(&path), "--cloud-topic", "/nope"]));
    assert_contains(
        &err,
        &[
            "no PointCloud2 messages on topic /nope",
            "/odom (nav_msgs/msg/Odometry)",
        ],
    );

    let options = SourceOptions {
        log: LogOptions {
            cloud_topic: Some("/points".into()),
            ..Default::default()
        },
        ..Default::default()
    };
    let source = Source::open(&path, &options, &|_| {}).unwrap();
    assert_eq!(source.world_frame(), "odom");
    let frames: Vec<_> = source.read(&(0..1)).map(Result::unwrap).collect();
    let frame = &frames[0];
    // The NaN point is dropped; the others read through float64 big-endian fields.
    assert_eq!(
        frame.points_in_velodyne,
        vec![[1.0, 2.0, 3.0, 0.0], [4.0, 5.0, 6.0, 0.0]]
    );
    // Halfway between odometry x = 0 and x = 2, plus the static 1.5 m up.
    let t = frame.world_from_velodyne.translation;
    assert!(
        (t.x - 1.0).abs() < 1e-12 && (t.z - 1.5).abs() < 1e-12,
        "{t}"
    );
    assert_eq!(frame.stamp_ns, 1_050_000_000);
    assert_eq!(frame.dropped_points, 1, "the NaN point is counted");
    let run = success(travmap(&[
        "run",
        arg(&path),
        "--cloud-topic",
        "/points",
        "--json",
    ]));
    let line: Value = serde_json::from_str(run.lines().nth(1).unwrap()).unwrap();
    assert_eq!(line["dropped_points"], 1);
    // convert takes the flag its error asks for, and converts every topic.
    let out = dir.path().join("converted.mcap");
    let err = clean_failure(travmap(&["convert", arg(&path), "-o", arg(&out)]));
    assert_contains(&err, &["several PointCloud2 topics", "--cloud-topic"]);
    let doc = json_summary(&[
        "convert",
        arg(&path),
        "-o",
        arg(&out),
        "--cloud-topic",
        "/points",
    ]);
    assert!(doc["messages"].as_u64().unwrap() > 2);
    for topic in ["/points", "/other_points"] {
        let clouds = messages::<travmap_formats::ros::PointCloud2>(&out, topic);
        assert_eq!(clouds.len(), 1, "{topic}");
    }
}

/// A zstd MCAP of the shipped drive whose second chunk (frames 4 and 5, and frame
/// 3's pose) has one byte flipped: the chunk at `offset`.
fn drive_with_a_damaged_chunk(dir: &Path) -> Option<(PathBuf, usize)> {
    let (_, good) = crate::common::sample_as_mcap(dir, &[])?;
    let mut bytes = std::fs::read(&good).unwrap();
    let mut chunks = Vec::new();
    let mut at = 8;
    while bytes[at] != 0x0F {
        let length = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if bytes[at] == 0x06 {
            chunks.push((at, length));
        }
        at += 9 + length;
    }
    assert_eq!(chunks.len(), 2, "the drive fills two 8 MB chunks");
    let (offset, length) = chunks[1];
    bytes[offset + 9 + length / 2] ^= 0x55;
    let path = dir.join("damaged.mcap");
    std::fs::write(&path, bytes).unwrap();
    Some((path, offset))
}

#[test]
fn a_damaged_chunk_stops_with_its_offset_or_is_stepped_over_with_keep_going() {
    let dir = tempfile::tempdir().unwrap();
    let Some((damaged, offset)) = drive_with_a_damaged_chunk(dir.path()) else {
        return;
    };
    let chunk = format!("the chunk at byte {offset} (log time 0.311 to 0.518 s) is damaged");
    let err = clean_failure(travmap(&["eval", arg(&damaged)]));
    assert_contains(
        &err,
        &[&chunk, "Chunk CRC failed", "--keep-going", "mcap recover"],
    );
    // --keep-going: the intact chunk's frames are read and scored, the damage named.
    let output = travmap(&["eval", arg(&damaged), "--keep-going", "--json"]);
    assert_eq!(
        output.status.code(),
        Some(3),
        "{}",
        crate::common::stderr(&output)
    );
    let doc: Value =
        serde_json::from_str(crate::common::stdout(&output).lines().last().unwrap()).unwrap();
    assert_eq!(doc["scored_frames"], 3, "frames 0-2 carry ground truth");
    let reasons: Vec<&str> = doc["skipped"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["reason"].as_str().unwrap())
        .collect();
    assert!(reasons.iter().any(|r| r.contains(&chunk)), "{reasons:?}");
    // Frame 3's cloud is whole, but its pose was in the damaged chunk.
    assert!(
        reasons.iter().any(|r| r.contains("no transform")),
        "{reasons:?}"
    );
    // One skip per lost scan, each under its number in the intact file (the chunk's
    // message index lists its clouds): frames 4 and 5 were one skip at the next
    // cloud, and the numbers after a lost stretch shifted down.
    let skipped: Vec<(u64, bool)> = (doc["skipped"].as_array().unwrap().iter())
        .map(|s| {
            (
                s["frame"].as_u64().unwrap(),
                s["reason"].as_str().unwrap().contains(&chunk),
            )
        })
        .collect();
    assert_eq!(skipped, [(3, false), (4, true), (5, true)]);
    // The report agrees with itself: the frames read include those skipped, in order.
    assert_eq!(
        doc["inputs"][0]["frames"],
        serde_json::json!({"start": 0, "end": 5, "count": 6})
    );
    let frames = |input: &Path| -> Vec<(u64, u64)> {
        let out = travmap(&["run", arg(input), "--json", "--keep-going"]);
        let (frames, _) = crate::common::json_records(&crate::common::stdout(&out));
        (frames.iter())
            .map(|f| {
                (
                    f["frame"].as_u64().unwrap(),
                    f["stamp_ns"].as_u64().unwrap(),
                )
            })
            .collect()
    };
    let intact = frames(&dir.path().join("drive.mcap"));
    let read = frames(&damaged);
    assert_eq!(
        read,
        intact[..3],
        "the frames read keep the intact file's numbers and stamps"
    );
    let only_five = travmap(&[
        "run",
        arg(&damaged),
        "--json",
        "--keep-going",
        "--frames",
        "5",
    ]);
    let (frames_five, summary) = crate::common::json_records(&crate::common::stdout(&only_five));
    assert!(frames_five.is_empty());
    let skipped_five = (summary["skipped"].as_array().unwrap().iter())
        .any(|s| s["frame"] == 5 && s["reason"].as_str().unwrap().contains(&chunk));
    assert!(skipped_five, "--frames and the report agree: {summary}");
    // annotate and convert read on past it too, and write a whole file.
    for command in ["annotate", "convert"] {
        let out = dir.path().join(format!("{command}.mcap"));
        let output = travmap(&[
            command,
            arg(&damaged),
            "-o",
            arg(&out),
            "--keep-going",
            "-q",
        ]);
        assert_eq!(
            output.status.code(),
            Some(3),
            "{}",
            crate::common::stderr(&output)
        );
        assert_contains(&crate::common::stderr(&output), &[&chunk]);
        let topic = ["--cloud-topic", "/velodyne_points", "--poses", "none"];
        success(travmap(&[&["run", arg(&out), "-q"][..], &topic].concat()));
    }
}

#[test]
fn shared_mcap_files_give_clear_errors() {
    let Some(dir) = crate::common::shared_data("mcap") else {
        return;
    };
    let all_types = dir.join("rosbags_rs_all_std_types.mcap");
    let err = clean_failure(travmap(&["eval", arg(&dir.join("rosbag2_cdr_test.mcap"))]));
    assert_contains(
        &err,
        &[
            "no PointCloud2 topic",
            "/test_topic (test_msgs/msg/BasicTypes)",
        ],
    );
    // Every TF and Odometry message of the all-types file decodes; its cloud has no
    // pose, and its three points are all at the origin: no return.
    let err = clean_failure(travmap(&["eval", arg(&all_types)]));
    assert_contains(
        &err,
        &[
            "no recorded pose moves the clouds' frame `test_frame`",
            "poses estimated by scan registration",
            "cloud 0: every one of its 3 points",
            "lies at the sensor's origin (no return)",
        ],
    );
    let err = clean_failure(travmap(&["eval", arg(&all_types), "--poses", "tf"]));
    assert_contains(
        &err,
        &[
            "--poses tf: no recorded pose moves the clouds' frame `test_frame`",
            "--poses registration estimates poses from the scans",
        ],
    );
    // A truncated copy is a clear error, not a panic.
    let bytes = std::fs::read(&all_types).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let cut = tmp.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let err = clean_failure(travmap(&["eval", arg(&cut)]));
    assert!(err.contains("cut.mcap"), "{err}");
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn rerun_converts_the_annotated_file_into_points_and_grid_maps() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let Some(rerun) =
        crate::common::env_var("TRAVMAP_RERUN", ".ci/run points it at rerun-sdk's `rerun`")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for mcap_path in annotated_both_ways(dir.path(), &seq) {
        rerun_finds_points_and_grid_maps(&rerun, &mcap_path, &seq);
    }
}

fn rerun_finds_points_and_grid_maps(rerun: &str, mcap_path: &Path, seq: &Path) {
    let rrd = mcap_path.with_extension("rrd");
    let rerun_mcap = ["mcap", "convert", arg(mcap_path), "-o", arg(&rrd)];
    crate::common::run_client(Command::new(rerun).args(rerun_mcap));
    // `rerun mcap convert` exits 0 even on bad input: check what the .rrd holds.
    let printed =
        crate::common::run_client(Command::new(rerun).args(["rrd", "print", "-v"]).arg(&rrd));
    let text = String::from_utf8_lossy(&printed.stdout);
    // Chunk headers read "... with N rows (size) - /entity - data columns: [...]".
    let rows = |entity: &str, column: &str| -> usize {
        text.lines()
            .filter(|l| {
                l.contains(&format!(" - {entity} - ")) && l.contains(&format!("{entity}@{column}"))
            })
            .filter_map(|l| {
                l.split(" with ")
                    .nth(1)?
                    .split(' ')
                    .next()?
                    .parse::<usize>()
                    .ok()
            })
            .sum()
    };
    assert_eq!(
        rows("/travmap/prediction", "GridMap:data"),
        6,
        "{mcap_path:?}: {text}"
    );
    assert_eq!(rows("/travmap/ground_truth", "GridMap:data"), 3);
    assert_eq!(rows("/travmap/cloud", "Points3D:positions"), 6);
    assert_eq!(rows("/velodyne_points", "Points3D:positions"), 6);
    // The grids' size and the first grid's corner, in the data itself.
    let data = Command::new(rerun)
        .args(["rrd", "print", "-vvv"])
        .arg(&rrd)
        .output()
        .unwrap();
    let data = String::from_utf8_lossy(&data.stdout);
    assert!(
        data.contains("width: 30, height: 30"),
        "no 30 x 30 GridMap in the .rrd"
    );
    let run = success(travmap(&["run", arg(seq), "--frames", "0", "--json"]));
    let first = crate::common::json_records(&run).0.remove(0);
    let corner = first["min_corner_in_world"].as_array().unwrap();
    let expected = format!(
        "[[{:?}, {:?}, ",
        corner[0].as_f64().unwrap() as f32,
        corner[1].as_f64().unwrap() as f32
    );
    assert!(
        data.contains(&expected),
        "no GridMap translation starting {expected}"
    );
}

/// A one-frame KITTI sequence in `<temporary directory>/seq` with the real image and
/// camera-cropped scan of kitti-object-000008 and sequence 03's calibration (the
/// same 2011_09_26 cameras): the directory and the sequence; None without the shared
/// data.
#[test]
fn convert_passes_png_images_through_with_camera_info() {
    let Some((dir, seq)) = crate::common::one_frame_with_image() else {
        return;
    };
    let out = dir.path().join("d.mcap");
    let start = ["--start-time", "1317000000"];
    let doc = json_summary(&[&["convert", arg(&seq), "-o", arg(&out)][..], &start].concat());
    assert_eq!(doc["images"], 1);
    let png = std::fs::read(seq.join("image_2/000000.png")).unwrap();
    let images =
        messages::<travmap_formats::ros::CompressedImage>(&out, "/camera_2/image/compressed");
    assert_eq!(images.len(), 1);
    let (log_time, image) = &images[0];
    assert_eq!(image.data, png, "the PNG bytes pass through unchanged");
    assert_eq!(image.format, "png");
    assert_eq!(image.header.frame_id, "camera_2");
    assert_eq!(*log_time, 1_317_000_000_000_000_000);
    let infos = messages::<travmap_formats::ros::CameraInfo>(&out, "/camera_2/camera_info");
    let info = &infos[0].1;
    assert_eq!((info.width, info.height), (1242, 375));
    assert_eq!(info.k[0], 721.5377);
    // P = [K | 0] in camera_2's own frame; the baseline is in /tf_static.
    assert_eq!((info.p[0], info.p[3]), (721.5377, 0.0));
    let statics = messages::<travmap_formats::ros::TfMessage>(&out, "/tf_static");
    let frames: Vec<(&str, &str)> = statics[0]
        .1
        .transforms
        .iter()
        .map(|t| (t.header.frame_id.as_str(), t.child_frame_id.as_str()))
        .collect();
    assert_eq!(frames, [("velodyne", "camera_0"), ("camera_0", "camera_2")]);
    // camera_2 sits 6 cm left of camera_0 (P2 = K [I | t], t_x = 44.857 / 721.54).
    let baseline = statics[0].1.transforms[1].transform.translation.x;
    assert!((baseline + 44.85728 / 721.5377).abs() < 1e-12, "{baseline}");
}

#[test]
fn an_output_in_a_missing_directory_is_a_clear_error() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("missing/drive.mcap");
    let (seq, out_arg) = (arg(&seq), arg(&out));
    let err = clean_failure(travmap(&["convert", seq, "-o", out_arg, "--frames", "0"]));
    assert_contains(&err, &["cannot write", "missing/drive.mcap"]);
    assert!(!out.exists());
    let err = clean_failure(travmap(&["annotate", seq, "-o", out_arg, "--frames", "0"]));
    assert_contains(&err, &["cannot write"]);
}

#[test]
fn corrupt_mcap_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let flags = ["--frames", "0..2", "--compression", "none"];
    let Some((_, good)) = crate::common::sample_as_mcap(dir.path(), &flags) else {
        return;
    };
    let bytes = std::fs::read(&good).unwrap();
    let write = |name: &str, data: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, data).unwrap();
        arg(&path).to_string()
    };
    // Bad magic.
    let mut bad_magic = bytes.clone();
    bad_magic[1] = b'X';
    let err = clean_failure(travmap(&["eval", &write("magic.mcap", &bad_magic)]));
    assert_contains(&err, &["magic.mcap"]);
    assert_contains(&err.to_lowercase(), &["magic"]);
    // A flipped byte inside a chunk's records: the chunk CRC no longer matches.
    let mut flipped = bytes.clone();
    let middle = bytes.len() / 3;
    flipped[middle] ^= 0x55;
    let err = clean_failure(travmap(&["eval", &write("crc.mcap", &flipped)]));
    assert_contains(&err, &["crc.mcap", "Chunk CRC failed"]);
    // Cut a few bytes into the first chunk, or inside the first record's opcode and
    // length: nothing complete was recorded, and it says so (not that the log has no
    // cloud topic).
    for (name, end, complete) in [("cut.mcap", 100, 42), ("head.mcap", 12, 8)] {
        let err = clean_failure(travmap(&["eval", &write(name, &bytes[..end])]));
        let read_to = format!("up to byte {complete}");
        assert_contains(
            &err,
            &[
                name,
                "without its summary",
                &read_to,
                "nothing complete to read",
            ],
        );
    }
    // Cut inside the summary: the data section is whole, and every frame is read.
    let tail = write("tail.mcap", &bytes[..bytes.len() - 30]);
    let output = travmap(&["run", &tail, "-q"]);
    assert_contains(&crate::common::stderr(&output), &["without its summary"]);
    success(output);
    // A chunk claiming a terabyte uncompressed: refused before anything is reserved.
    let mut chunk = 8;
    while bytes[chunk] != 0x06 {
        chunk += 9 + u64::from_le_bytes(bytes[chunk + 1..chunk + 9].try_into().unwrap()) as usize;
    }
    let mut huge = bytes.clone();
    huge[chunk + 25..chunk + 33].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let err = clean_failure(travmap(&["eval", &write("huge.mcap", &huge)]));
    let declared = format!("chunk at byte {chunk} declares 1099511627776 bytes");
    assert_contains(&err, &["huge.mcap", &declared]);
}

#[test]
fn an_image_that_disagrees_with_its_camera_info_and_a_non_cdr_cloud_are_errors() {
    use travmap_formats::ros::{CameraInfo, PointCloud2, RosMessage, encode};
    let Some((dir, seq)) = crate::common::one_frame_with_image() else {
        return;
    };
    let good = dir.path().join("good.mcap");
    write_output("convert", &seq, &good, &[]);
    success(travmap(&["run", arg(&good), "-q"]));

    // The same file with a CameraInfo that claims another width.
    let bytes = std::fs::read(&good).unwrap();
    let bad = dir.path().join("bad.mcap");
    let mut sink = McapSink::create(&bad, Compression::None).unwrap();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let schema = message.channel.schema.as_ref().unwrap();
        let id = sink
            .channel(
                &message.channel.topic,
                &schema.name,
                &schema.encoding,
                &schema.data,
                "cdr",
            )
            .unwrap();
        let mut data = message.data.to_vec();
        if schema.name == CameraInfo::NAME {
            let mut info: CameraInfo = decode(&data).unwrap();
            info.width = 1000;
            data = encode(&info, 0);
        }
        sink.write_raw(id, message.log_time, message.publish_time, data)
            .unwrap();
    }
    sink.finish().unwrap();
    // eval reads the images; run, with the embedded geometry-only model, needs none.
    let err = clean_failure(travmap(&["eval", arg(&bad)]));
    assert_contains(
        &err,
        &["the image is 1242x375 but its CameraInfo says 1000x375"],
    );
    success(travmap(&["run", arg(&bad), "-q"]));

    // A PointCloud2 channel whose messages are not CDR.
    let json = dir.path().join("json.mcap");
    let mut sink = McapSink::create(&json, Compression::None).unwrap();
    let id = sink
        .channel(
            "/points",
            PointCloud2::NAME,
            "ros2msg",
            PointCloud2::SCHEMA.as_bytes(),
            "json",
        )
        .unwrap();
    sink.write_raw(id, 1, 1, b"{}".to_vec()).unwrap();
    sink.finish().unwrap();
    let err = clean_failure(travmap(&["eval", arg(&json)]));
    assert_contains(
        &err,
        &["channel /points (sensor_msgs/msg/PointCloud2) has message encoding `json`"],
    );
}

/// An MCAP whose recorder was killed is read as far as it goes, with a notice that
/// says where it ends and that `mcap recover` rewrites it: before the summary, every
/// frame; inside a chunk, the frames of the complete chunks.
#[test]
fn a_recording_cut_short_is_read_as_far_as_it_goes() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_, drive)) = crate::common::sample_as_mcap(dir.path(), &[]) else {
        return;
    };
    let whole = std::fs::read(&drive).unwrap();
    let footer = whole.len() - 8 - 29;
    let summary_start = u64::from_le_bytes(whole[footer + 9..footer + 17].try_into().unwrap());
    // Frames read, the exit code and what the summary counts as lost.
    let read = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let output = travmap(&["run", arg(&path), "--json"]);
        let err = crate::common::stderr(&output);
        assert_contains(
            &err,
            &["without its summary and closing magic", "mcap recover"],
        );
        let (frames, summary) = crate::common::json_records(&crate::common::stdout(&output));
        (frames.len(), output.status.code(), summary["lost"].clone())
    };
    // Cut after its data section: the summary alone is lost, none of the drive.
    let (frames, code, lost) = read("no-summary.mcap", &whole[..summary_start as usize]);
    assert_eq!((frames, code, lost), (6, Some(0), serde_json::json!([])));
    // Cut inside a chunk: the complete chunks' frames, the rest counted as lost.
    let (frames, code, lost) = read("cut.mcap", &whole[..whole.len() * 4 / 5]);
    assert!((1..6).contains(&frames), "{frames} frames");
    assert_eq!(code, Some(3), "completed with a part of the input lost");
    assert_contains(
        lost[0]["reason"].as_str().unwrap(),
        &["cut short at byte", "is lost"],
    );
    // Cut before its first complete chunk: nothing complete, said so.
    let path = dir.path().join("half.mcap");
    std::fs::write(&path, &whole[..whole.len() / 2]).unwrap();
    let err = clean_failure(travmap(&["run", arg(&path)]));
    assert_contains(&err, &["nothing complete to read"]);
}

/// The first chunk damaged (it holds the schemas and channels, as every chunk
/// after it does not): --keep-going reads the channels from the summary and the
/// frames of the intact chunk, as it does for damage further on.
#[test]
fn a_damaged_first_chunk_is_stepped_over_with_keep_going() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_, good)) = crate::common::sample_as_mcap(dir.path(), &[]) else {
        return;
    };
    let mut bytes = std::fs::read(&good).unwrap();
    // The first record after the magic and the header is the first chunk.
    let header = 8 + 9 + u64::from_le_bytes(bytes[9..17].try_into().unwrap()) as usize;
    assert_eq!(bytes[header], 0x06, "a chunk");
    bytes[header + 2000] ^= 0x55;
    let damaged = dir.path().join("first.mcap");
    std::fs::write(&damaged, bytes).unwrap();
    let err = clean_failure(travmap(&["run", arg(&damaged)]));
    assert_contains(
        &err,
        &["the chunk at byte", "--keep-going reads on past it"],
    );
    let output = travmap(&["run", arg(&damaged), "--keep-going", "--json"]);
    assert_eq!(
        output.status.code(),
        Some(3),
        "{}",
        crate::common::stderr(&output)
    );
    let (frames, summary) = crate::common::json_records(&crate::common::stdout(&output));
    let read: Vec<u64> = (frames.iter())
        .map(|f| f["frame"].as_u64().unwrap())
        .collect();
    let skipped: Vec<u64> = (summary["skipped"].as_array().unwrap().iter())
        .map(|s| s["frame"].as_u64().unwrap())
        .collect();
    assert!(!read.is_empty(), "the intact chunk's frames are read");
    assert_eq!(read.len() + skipped.len(), 6, "{read:?} {skipped:?}");
    assert!(skipped.contains(&0), "{skipped:?}");
}

/// A record damaged in the middle of a complete MCAP (its summary and closing magic
/// intact) is damage, not the end of a cut recording (it was read as a cut: 7 frames
/// of 30, exit 0): a clear error naming the chunk; with --keep-going its messages are
/// left out, named, and reading resumes at the next chunk the summary indexes (or its
/// end), the channels read from the summary (the first chunk holds them).
#[test]
fn a_damaged_record_in_a_complete_file_is_stepped_over_by_keep_going() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_, mcap)) = crate::common::sample_as_mcap(dir.path(), &["--compression", "none"])
    else {
        return;
    };
    let bytes = std::fs::read(&mcap).unwrap();
    let mut offset = 8;
    let mut chunks = Vec::new();
    while bytes[offset] != 0x0F {
        let length = u64::from_le_bytes(bytes[offset + 1..offset + 9].try_into().unwrap());
        if bytes[offset] == 0x06 {
            chunks.push(offset);
        }
        offset += 9 + length as usize;
    }
    assert!(chunks.len() >= 2, "{chunks:?}");
    let frames = |output: &std::process::Output| {
        let (frames, _) = crate::common::json_records(&String::from_utf8_lossy(&output.stdout));
        frames.len()
    };
    for (chunk, length) in [(0, 0x7fff_ffffu64), (1, 40), (1, 0x7fff_ffff)] {
        let mut damaged = bytes.clone();
        let at = chunks[chunk];
        damaged[at + 1..at + 9].copy_from_slice(&length.to_le_bytes());
        let path = dir.path().join(format!("damaged-{chunk}-{length}.mcap"));
        std::fs::write(&path, damaged).unwrap();
        let named = format!("the chunk at byte {at} ");
        let err = clean_failure(travmap(&["run", arg(&path)]));
        crate::common::assert_contains(
            &err,
            &[&named, "is damaged", "--keep-going reads on past it"],
        );
        let output = travmap(&["run", arg(&path), "--keep-going", "--json"]);
        let err = crate::common::stderr(&output);
        assert_eq!(
            output.status.code(),
            Some(3),
            "chunk {chunk}, length {length}: {err}"
        );
        assert!(err.contains(&named), "{err}");
        let read = frames(&output);
        assert!(
            (1..6).contains(&read),
            "chunk {chunk}, length {length}: {read} frames"
        );
    }
}
