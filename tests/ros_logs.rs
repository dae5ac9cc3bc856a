//! Every recorded-log format travmap reads, written by real tools (rosbags, Python
//! mcap, rosbags-convert; `tests/clients/ros_routes.py`) from the shipped drive as
//! travmap converts it: each route must give the ROS 2 MCAP's grids cell for cell and
//! its scores, `convert` must bring each back to ROS 2, and broken logs must be
//! one-line errors.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{
    arg, assert_contains, clean_failure, run_client, success, travmap, write_output,
};
use serde_json::Value;
use travmap_formats::ros::{OccupancyGrid, PointCloud2, decode};
use travmap_io::Log;
use travmap_io::{InputFormat, detect};

/// The routes `ros_routes.py` writes, by name.
const ROUTES: [&str; 14] = [
    "ros1-none.bag",
    "ros1-bz2.bag",
    "ros1-lz4.bag",
    "ros1.mcap",
    "rosbag2-sqlite3",
    "rosbag2-mcap",
    "rosbag2-sqlite3-zstd",
    "rosbag2-mcap-zstd",
    "rosbag2-sqlite3-zstd-file",
    "rosbag2-mcap-zstd-file",
    "rosbag2-from-bag",
    "rosbag2-sqlite3/rosbag2-sqlite3.db3",
    // Their compression read from the metadata each file keeps itself.
    "rosbag2-sqlite3-zstd/rosbag2-sqlite3-zstd.db3",
    "rosbag2-mcap-zstd/rosbag2-mcap-zstd.mcap",
];

/// `drive` (a ROS 2 MCAP) written in every other format into `dir/routes`, or None
/// without the client venv.
fn routes(drive: &Path, dir: &Path) -> Option<PathBuf> {
    let python = crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "the client venv's python")?;
    let convert = Path::new(&python).with_file_name("rosbags-convert");
    let out = dir.join("routes");
    run_client(
        Command::new(&python)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/ros_routes.py"))
            .args([drive, &out, &convert]),
    );
    Some(out)
}

/// The shipped drive (six frames, three labelled) converted by travmap (in the
/// directory's `drive.mcap`) and written in every other format; None without the data
/// or the client venv.
fn sample_routes() -> Option<(tempfile::TempDir, PathBuf, PathBuf)> {
    let dir = tempfile::tempdir().unwrap();
    let (_, drive) = crate::common::sample_as_mcap(dir.path(), &[])?;
    let routes = routes(&drive, dir.path())?;
    Some((dir, drive, routes))
}

/// The grids and clouds `annotate --no-passthrough` writes of `input` (into `dir`,
/// named after `name`): (topic, log time, bytes).
fn annotated_grids(dir: &Path, input: &Path, name: &str) -> Vec<(String, u64, Vec<u8>)> {
    let out = dir.join(format!("{name}.annotated.mcap"));
    write_output("annotate", input, &out, &["--no-passthrough"]);
    let grids = [
        "/travmap/prediction",
        "/travmap/ground_truth",
        "/travmap/cloud",
    ];
    messages_on(&out, &grids)
}

/// The KITTI frame with its camera image, converted by travmap (in the directory's
/// `drive.mcap`) and written in every other format; None without the data or the
/// client venv.
fn one_frame_routes() -> Option<(tempfile::TempDir, PathBuf, PathBuf)> {
    let (dir, seq) = crate::common::one_frame_with_image()?;
    let drive = dir.path().join("drive.mcap");
    write_output("convert", &seq, &drive, &[]);
    let routes = routes(&drive, dir.path())?;
    Some((dir, drive, routes))
}

/// What reaches the method of `input`'s camera (read for a model that uses it: the
/// off-road model has a hybrid part): frames with an image, and cells with
/// appearance values.
fn images(input: &Path) -> (Value, Value) {
    let out = crate::common::success(travmap(&[
        "run",
        arg(input),
        "--model",
        "offroad",
        "--json",
    ]));
    let (_, report) = crate::common::json_records(&out);
    (
        report["frames_with_images"].clone(),
        report["cells_with_appearance"].clone(),
    )
}

/// Every message of `topics` in a file travmap wrote: (topic, log time, bytes).
fn messages_on(path: &Path, topics: &[&str]) -> Vec<(String, u64, Vec<u8>)> {
    let format = detect(path).unwrap();
    Log::open(path, format)
        .unwrap()
        .messages()
        .map(Result::unwrap)
        .filter(|m| topics.contains(&m.connection.topic.as_str()))
        .map(|m| (m.connection.topic.clone(), m.log_time_ns, m.data))
        .collect()
}

/// The scores of `eval --json` on `input`: confusion and filtered / unfiltered scores.
fn scores(input: &Path) -> Value {
    let report = crate::common::json_summary(&["eval", arg(input)]);
    serde_json::json!([
        report["confusion"],
        report["scores"],
        report["unfiltered_scores"]
    ])
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn every_route_gives_the_ros2_grids_cell_for_cell_and_the_same_scores() {
    let Some((dir, drive, routes)) = sample_routes() else {
        return;
    };
    let annotated = |input: &Path, name: &str| annotated_grids(dir.path(), input, name);
    let reference = annotated(&drive, "ros2");
    assert_eq!(reference.len(), 6 + 3 + 6);
    let reference_scores = scores(&drive);
    for route in ROUTES {
        let input = routes.join(route);
        let name = route.replace('/', "_");
        assert!(
            annotated(&input, &name) == reference,
            "{route}: other grids"
        );
        assert_eq!(scores(&input), reference_scores, "{route}");
    }
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn convert_brings_every_route_back_to_the_same_ros2_messages() {
    let Some((dir, drive, routes)) = one_frame_routes() else {
        return;
    };
    let known = [
        "/velodyne_points",
        "/tf",
        "/tf_static",
        "/camera_2/image/compressed",
        "/camera_2/camera_info",
    ];
    let original = messages_on(&drive, &known);
    assert_eq!(original.len(), 5);
    // The zstd route's chunks hold compressed messages: they are not copied as stored.
    for route in [
        "ros1-lz4.bag",
        "ros1.mcap",
        "rosbag2-sqlite3",
        "rosbag2-mcap-zstd",
        "rosbag2-sqlite3-zstd-file",
    ] {
        let out = dir.path().join(format!("{route}.converted.mcap"));
        let json =
            crate::common::json_summary(&["convert", arg(&routes.join(route)), "-o", arg(&out)]);
        // Byte for byte the messages travmap wrote from the KITTI frame.
        assert!(messages_on(&out, &known) == original, "{route}");
        let summary = &json;
        assert_eq!(summary["messages"], 6, "{route}: {summary}");
        let ros1 = route.starts_with("ros1");
        assert_eq!(summary["translated_messages"], if ros1 { 5 } else { 0 });
        let as_recorded: &[&str] = if ros1 { &["/chatter"] } else { &[] };
        assert_eq!(
            summary["topics_as_recorded"],
            serde_json::json!(as_recorded)
        );

        // The type travmap does not read is copied with its own encoding and schema.
        let bytes = std::fs::read(&out).unwrap();
        let chatter = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .find(|m| m.channel.topic == "/chatter")
            .unwrap();
        let schema = chatter.channel.schema.as_ref().unwrap();
        let expected = if ros1 {
            ("ros1", "std_msgs/String", "ros1msg")
        } else {
            ("cdr", "std_msgs/msg/String", "ros2msg")
        };
        assert_eq!(
            (
                chatter.channel.message_encoding.as_str(),
                schema.name.as_str(),
                schema.encoding.as_str()
            ),
            expected,
            "{route}"
        );
        assert!(String::from_utf8_lossy(&schema.data).contains("string data"));
    }
    // And the image reaches the method through a ROS 1 bag as through ROS 2.
    let through_ros2 = images(&drive);
    assert_eq!(through_ros2.0, 1);
    assert_eq!(images(&routes.join("ros1-bz2.bag")), through_ros2);
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_livox_custom_msg_reads_as_the_pointcloud2_of_its_points() {
    let Some((dir, _, routes)) = sample_routes() else {
        return;
    };
    let livox = routes.join("rosbag2-mcap-livox");
    // Written as FAST-LIO's users record a Livox: no PointCloud2 at all.
    let schemas: Vec<String> = Log::open(&livox, detect(&livox).unwrap())
        .unwrap()
        .messages()
        .map(|m| m.unwrap().connection.schema_name.clone())
        .collect();
    assert!(schemas.contains(&"livox_ros_driver2/msg/CustomMsg".to_string()));
    assert!(!schemas.iter().any(|s| s.contains("PointCloud2")));
    // The grids and clouds of the same points, each reflectivity as a uint8
    // intensity of a PointCloud2 (a byte-scale remission, as the Livox's).
    let annotated = |input: &Path, name: &str| {
        let out = dir.path().join(format!("{name}.annotated.mcap"));
        let json = crate::common::json_summary(&[
            "annotate",
            arg(input),
            "-o",
            arg(&out),
            "--no-passthrough",
        ]);
        assert_eq!(json["frames"], 6, "{name}: {json}");
        messages_on(&out, &["/travmap/prediction", "/travmap/cloud"])
    };
    let reference = annotated(&routes.join("rosbag2-mcap-uint8"), "uint8");
    assert_eq!(reference.len(), 12);
    assert!(annotated(&livox, "livox") == reference);
    // And from a ROS 1 bag of livox_ros_driver/CustomMsg, as FAST-LIO's users record.
    let ros1 = routes.join("ros1-livox.bag");
    let types: Vec<String> = Log::open(&ros1, detect(&ros1).unwrap())
        .unwrap()
        .messages()
        .map(|m| m.unwrap().connection.schema_name.clone())
        .collect();
    assert!(
        types.contains(&"livox_ros_driver/CustomMsg".to_string()),
        "{types:?}"
    );
    assert!(annotated(&ros1, "ros1-livox") == reference);
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_foxglove_protobuf_log_reads_as_its_ros2_original() {
    let Some((dir, drive, routes)) = sample_routes() else {
        return;
    };
    let foxglove = routes.join("foxglove.mcap");
    // Written as nuScenes' MCAPs are: Foxglove's schemas in protobuf, no ROS type.
    let channels: Vec<(String, String)> = Log::open(&foxglove, detect(&foxglove).unwrap())
        .unwrap()
        .messages()
        .map(|m| m.unwrap().connection)
        .map(|c| (c.schema_name.clone(), c.message_encoding.clone()))
        .collect();
    assert!(channels.contains(&("foxglove.PointCloud".into(), "protobuf".into())));
    assert!(channels.contains(&("foxglove.FrameTransforms".into(), "protobuf".into())));
    assert!(channels.iter().all(|(_, encoding)| encoding == "protobuf"));
    // The same grids, cell for cell, and the same scores (labels are a field of
    // the points).
    let annotated = |input: &Path, name: &str| annotated_grids(dir.path(), input, name);
    let reference = annotated(&drive, "ros2");
    assert_eq!(reference.len(), 6 + 3 + 6);
    assert!(annotated(&foxglove, "foxglove") == reference);
    assert_eq!(scores(&foxglove), scores(&drive));
    // convert makes ROS 2 of it: the same clouds and transforms as the original,
    // up to what Foxglove's schemas do not carry (is_dense) and /tf_static's stamp.
    let converted = dir.path().join("converted.mcap");
    let json = crate::common::json_summary(&["convert", arg(&foxglove), "-o", arg(&converted)]);
    assert_eq!(json["translated_messages"], json["messages"], "{json}");
    assert_eq!(json["topics_as_recorded"], serde_json::json!([]));
    let clouds = |path: &Path| -> Vec<(u64, travmap_formats::ros::PointCloud2)> {
        (messages_on(path, &["/velodyne_points"]).into_iter())
            .map(|(_, t, data)| (t, travmap_formats::ros::decode(&data).unwrap()))
            .map(|(t, mut cloud): (u64, travmap_formats::ros::PointCloud2)| {
                cloud.is_dense = false;
                (t, cloud)
            })
            .collect()
    };
    assert_eq!(clouds(&converted), clouds(&drive));
    assert!(messages_on(&converted, &["/tf"]) == messages_on(&drive, &["/tf"]));
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_log_laid_out_as_nuscenes_reads_with_its_mounts_on_tf() {
    let Some((_dir, drive, routes)) = sample_routes() else {
        return;
    };
    let nuscenes = routes.join("foxglove-nuscenes.mcap");
    // A LiDAR and a radar: the LiDAR is to be named, and the error names both.
    let err = clean_failure(travmap(&["eval", arg(&nuscenes)]));
    assert_contains(
        &err,
        &["several PointCloud2 topics", "/lidar_top", "/radar_front"],
    );
    // The mounts are on /tf at the second and fourth clouds only, the same each
    // time: held as static ones are, so the first and last clouds keep their pose,
    // and the scores are the original's.
    let chosen = ["--cloud-topic", "/lidar_top"];
    let summary = crate::common::json_summary(&[&["eval", arg(&nuscenes)][..], &chosen].concat());
    let original = crate::common::json_summary(&["eval", arg(&drive)]);
    assert_eq!(summary["scored_frames"], 3);
    assert_eq!(summary["confusion"], original["confusion"]);
    assert_eq!(summary["scores"], original["scores"]);
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn foxglove_schemas_in_json_read_as_in_protobuf() {
    let Some((dir, drive, routes)) = sample_routes() else {
        return;
    };
    let annotated = |input: &Path, name: &str| annotated_grids(dir.path(), input, name);
    let json = routes.join("foxglove-json.mcap");
    let reference = annotated(&drive, "ros2");
    assert_eq!(reference.len(), 6 + 3 + 6);
    assert!(annotated(&json, "json") == reference);
    assert_eq!(scores(&json), scores(&drive));
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_foxglove_camera_reads_as_its_ros2_original() {
    let Some((_dir, drive, routes)) = one_frame_routes() else {
        return;
    };
    let through_ros2 = images(&drive);
    assert_eq!(through_ros2.0, 1);
    let cells = appearance_of(&drive);
    for route in ["foxglove.mcap", "foxglove-json.mcap"] {
        let foxglove = routes.join(route);
        let camera = messages_on(&foxglove, &["/camera_2/image/compressed"]);
        assert_eq!(camera.len(), 1);
        assert_eq!(images(&foxglove), through_ros2, "{route}");
        assert!(appearance_of(&foxglove) == cells, "{route}");
    }
}

/// A copy of `from` in `dir` with `edit` applied to its bytes.
fn edited(from: &Path, dir: &Path, name: &str, edit: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
    let mut bytes = std::fs::read(from).unwrap();
    edit(&mut bytes);
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Where a bag header field's value starts.
fn field_value(bytes: &[u8], name: &[u8]) -> usize {
    bytes.windows(name.len()).position(|w| w == name).unwrap() + name.len()
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn broken_logs_are_one_line_errors_and_an_unindexed_bag_is_read_with_a_notice() {
    let dir = tempfile::tempdir().unwrap();
    let Some((_, drive)) = crate::common::sample_as_mcap(dir.path(), &["--frames", "0..3"]) else {
        return;
    };
    let Some(routes) = routes(&drive, dir.path()) else {
        return;
    };
    let bag = routes.join("ros1-none.bag");
    let length = std::fs::metadata(&bag).unwrap().len() as usize;

    // Cut inside its index, and before it: the header points into or past the end.
    let bytes = std::fs::read(&bag).unwrap();
    let at = field_value(&bytes, b"index_pos=");
    let index_pos = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) as usize;
    for (cut_at, expected) in [
        (length - 100, "is damaged or cut off"),
        (index_pos - 10, "the bag was cut off"),
    ] {
        let cut = edited(&bag, dir.path(), "cut.bag", |b| b.truncate(cut_at));
        let err = clean_failure(travmap(&["run", arg(&cut)]));
        assert_contains(&err, &["cut.bag", "its index", expected]);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }

    // A recording that stopped before writing its index: index_pos 0, read by a scan.
    let unindexed = edited(&bag, dir.path(), "unindexed.bag", |b| {
        let at = field_value(b, b"index_pos=");
        b[at..at + 8].fill(0);
    });
    let output = travmap(&["run", arg(&unindexed)]);
    let stderr = crate::common::stderr(&output);
    success(output);
    assert_contains(
        &stderr,
        &["notice:", "unindexed.bag", "no index", "linear scan"],
    );
    let run_frames = |input: &Path| {
        crate::common::json_records(&success(travmap(&["run", arg(input), "--json"])))
            .0
            .iter()
            .map(|f| (f["frame"].clone(), f["cells"].clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(run_frames(&unindexed), run_frames(&bag));
    // ... and the same cut short inside a chunk: the complete chunks are read and the
    // notice says what was left out (here the pose of the last whole cloud, too).
    let unindexed_cut = edited(&unindexed, dir.path(), "unindexed-cut.bag", |b| {
        b.truncate(length / 2)
    });
    let output = travmap(&["run", arg(&unindexed_cut), "--keep-going"]);
    assert_contains(
        &crate::common::stderr(&output),
        &["notice:", "left out the last"],
    );

    // A chunk whose compressed bytes are damaged.
    let lz4 = routes.join("ros1-lz4.bag");
    let damaged = edited(&lz4, dir.path(), "damaged.bag", |b| {
        let at = field_value(b, b"compression=lz4") + 200;
        for byte in &mut b[at..at + 64] {
            *byte ^= 0x5a;
        }
    });
    let err = clean_failure(travmap(&["run", arg(&damaged)]));
    assert_contains(&err, &["damaged.bag", "chunk at byte", "is damaged"]);
    // Its chunk alone is lost: the index gives its log times, and the chunks after
    // it are read.
    let output = travmap(&["run", arg(&damaged), "--keep-going", "--json"]);
    assert_eq!(
        output.status.code(),
        Some(3),
        "{}",
        crate::common::stderr(&output)
    );
    let (frames, summary) = crate::common::json_records(&crate::common::stdout(&output));
    let all = run_frames(&lz4);
    assert!(!frames.is_empty() && frames.len() < all.len(), "{summary}");
    assert_contains(
        &summary["skipped"].to_string(),
        &["damaged.bag", "log time"],
    );

    // A .db3 whose pages are garbage after the SQLite header.
    let db3 = routes.join("rosbag2-sqlite3/rosbag2-sqlite3.db3");
    let corrupt = edited(&db3, dir.path(), "corrupt.db3", |b| {
        for (i, byte) in b[100..].iter_mut().enumerate() {
            *byte = (i * 7 + 3) as u8;
        }
    });
    let err = clean_failure(travmap(&["run", arg(&corrupt)]));
    assert_contains(&err, &["corrupt.db3"]);

    // A storage file compressed whole and cut short: named, and its partial
    // decompression removed.
    let zstd_file = dir.path().join("cut-zstd-file");
    std::fs::create_dir(&zstd_file).unwrap();
    let from = routes.join("rosbag2-sqlite3-zstd-file");
    std::fs::copy(from.join("metadata.yaml"), zstd_file.join("metadata.yaml")).unwrap();
    let compressed = "rosbag2-sqlite3-zstd-file.db3.zstd";
    let bytes = std::fs::read(from.join(compressed)).unwrap();
    std::fs::write(zstd_file.join(compressed), &bytes[..bytes.len() / 2]).unwrap();
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["run", arg(&zstd_file)])
        .env("TMPDIR", &temp)
        .output()
        .unwrap();
    let err = clean_failure(output);
    assert_contains(&err, &[compressed, "does not decompress (zstd)"]);
    assert_eq!(std::fs::read_dir(&temp).unwrap().count(), 0, "{err}");

    // A message compressed on its own whose frame is cut.
    let zstd_messages = routes.join("rosbag2-sqlite3-zstd/rosbag2-sqlite3-zstd.db3");
    let cut_message = dir.path().join("cut-message.db3");
    std::fs::copy(&zstd_messages, &cut_message).unwrap();
    let database = rusqlite::Connection::open(&cut_message).unwrap();
    // The second cloud's frame, and a String, which `run` does not read.
    // And a transform, which the first pass reads and the frames' pass does not.
    for topic in ["/velodyne_points", "/chatter", "/tf"] {
        let cut = "UPDATE messages SET data = substr(data, 1, 8) WHERE id = (SELECT id FROM
             messages WHERE topic_id = (SELECT id FROM topics WHERE name = ?1) ORDER BY id
             LIMIT 1 OFFSET 1)";
        assert_eq!(database.execute(cut, [topic]).unwrap(), 1, "{topic}");
    }
    drop(database);
    let err = clean_failure(travmap(&["run", arg(&cut_message)]));
    assert_contains(
        &err,
        &[
            "cut-message.db3",
            "is damaged",
            "does not decompress (zstd)",
        ],
    );
    // Read on past them: the damaged cloud's frame is left out, and named; `run`
    // does not read the String, annotate's passthrough does and names it too.
    let output = travmap(&["run", arg(&cut_message), "--keep-going", "--json"]);
    assert_eq!(
        output.status.code(),
        Some(3),
        "{}",
        crate::common::stderr(&output)
    );
    let (frames, summary) = crate::common::json_records(&crate::common::stdout(&output));
    assert_eq!(frames.len(), 2, "{summary}");
    let skipped = summary["skipped"].to_string();
    assert_contains(
        &skipped,
        &["(on /velodyne_points", "is damaged", "(on /tf,"],
    );
    let annotated = dir.path().join("cut-message.mcap");
    let args = ["annotate", arg(&cut_message), "-o", arg(&annotated)];
    let output = travmap(&[&args[..], &["--keep-going", "--json"]].concat());
    assert_eq!(
        output.status.code(),
        Some(3),
        "{}",
        crate::common::stderr(&output)
    );
    let summary = crate::common::json_records(&crate::common::stdout(&output)).1;
    assert_eq!(summary["frames"], 2, "{summary}");
    let skipped = summary["skipped"].to_string();
    assert_contains(&skipped, &["on /velodyne_points", "on /chatter"]);

    // A recording that was not closed: its last messages still in the write-ahead
    // log beside the file. All are read, from a copy; the input stays as it was.
    let killed = dir.path().join("killed");
    std::fs::create_dir(&killed).unwrap();
    let (closed, open) = (dir.path().join("closed.db3"), killed.join("killed.db3"));
    std::fs::copy(&db3, &closed).unwrap();
    let database = rusqlite::Connection::open(&closed).unwrap();
    let rows: i64 =
        (database.query_row("SELECT count(*) FROM messages", [], |r| r.get(0))).unwrap();
    database
        .execute_batch(
            "CREATE TABLE later AS SELECT * FROM messages WHERE id > 2;
             DELETE FROM messages WHERE id > 2; VACUUM;
             PRAGMA journal_mode = WAL; PRAGMA wal_autocheckpoint = 0;
             INSERT INTO messages SELECT * FROM later; DROP TABLE later;",
        )
        .unwrap();
    // Copied while the writer holds them: as a killed recorder leaves them.
    std::fs::copy(&closed, &open).unwrap();
    std::fs::copy(
        dir.path().join("closed.db3-wal"),
        killed.join("killed.db3-wal"),
    )
    .unwrap();
    drop(database);
    let input_bytes = |dir: &Path| {
        let mut files: Vec<_> = (std::fs::read_dir(dir).unwrap())
            .map(|entry| std::fs::read(entry.unwrap().path()).unwrap())
            .collect();
        files.sort();
        files
    };
    let before = input_bytes(&killed);
    assert!(
        std::fs::metadata(killed.join("killed.db3-wal"))
            .unwrap()
            .len()
            > 0
    );
    let output = travmap(&["run", arg(&open)]);
    let stderr = crate::common::stderr(&output);
    success(output);
    assert_contains(
        &stderr,
        &["notice:", "killed.db3-wal", "not yet in the file"],
    );
    assert_eq!(run_frames(&open), run_frames(&db3), "{rows} messages");
    assert_eq!(input_bytes(&killed), before, "the input is left as it was");

    // A bag directory without metadata.yaml: its storage files read, with a notice.
    let unlisted = dir.path().join("unlisted");
    std::fs::create_dir(&unlisted).unwrap();
    std::fs::copy(&db3, unlisted.join("unlisted_0.db3")).unwrap();
    let output = travmap(&["run", arg(&unlisted)]);
    let stderr = crate::common::stderr(&output);
    success(output);
    assert_contains(
        &stderr,
        &["notice:", "no metadata.yaml", "unlisted_0.db3", "reindex"],
    );
    assert_eq!(run_frames(&unlisted), run_frames(&db3));
    // ... and one compressed whole (file mode), decompressed first.
    let unlisted_zstd = dir.path().join("unlisted-zstd");
    std::fs::create_dir(&unlisted_zstd).unwrap();
    let compressed = "rosbag2-sqlite3-zstd-file.db3.zstd";
    let from = routes.join("rosbag2-sqlite3-zstd-file").join(compressed);
    std::fs::copy(from, unlisted_zstd.join(compressed)).unwrap();
    assert_eq!(run_frames(&unlisted_zstd), run_frames(&db3));

    // metadata.yaml naming a file that is not there.
    let rosbag2 = dir.path().join("missing-file");
    std::fs::create_dir(&rosbag2).unwrap();
    let metadata = std::fs::read_to_string(routes.join("rosbag2-sqlite3/metadata.yaml")).unwrap();
    std::fs::write(rosbag2.join("metadata.yaml"), metadata).unwrap();
    let err = clean_failure(travmap(&["run", arg(&rosbag2)]));
    assert_contains(
        &err,
        &[
            "metadata.yaml",
            "lists the storage file `rosbag2-sqlite3.db3`, which is missing",
        ],
    );
}

#[test]
fn files_travmap_does_not_read_are_named_not_misdiagnosed() {
    let dir = tempfile::tempdir().unwrap();
    let Some(sample) = crate::common::sample() else {
        return;
    };
    let Some(object) = crate::common::shared_data("kitti-object-000008/training") else {
        return;
    };
    let pcd = dir.path().join("scan.pcd");
    std::fs::write(&pcd, "# .PCD v0.7 - Point Cloud Data\nVERSION 0.7\n").unwrap();
    let ply = dir.path().join("scan.ply");
    std::fs::write(&ply, "ply\nformat ascii 1.0\n").unwrap();
    let parquet = dir.path().join("cells.parquet");
    write_output("dataset", &sample, &parquet, &["--frames", "0..1"]);
    let text = dir.path().join("notes.mcap");
    std::fs::write(&text, "not a drive\n").unwrap();
    for (input, what) in [
        (pcd, "is a single PCD point cloud"),
        (ply, "is a single PLY point cloud"),
        (parquet, "is a Parquet file"),
        (object.join("image_2/000008.png"), "is a PNG image"),
        (text, "is a text file"),
        (dir.path().join("missing.mcap"), "does not exist"),
    ] {
        let err = clean_failure(travmap(&["run", arg(&input)]));
        assert_contains(&err, &[arg(&input), what]);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    assert_eq!(detect(&sample).unwrap(), InputFormat::Kitti);
}

/// Every cell's appearance values (None where no image covers it) of each frame of
/// `input`, on the training grid, through the library.
fn appearance_of(input: &Path) -> Vec<Option<Vec<f32>>> {
    let mut config = travmap_core::Config::default();
    config.grid.size_m = config.training.grid_size_m;
    let model =
        travmap_method::classifier::SvmModel::embedded(travmap_core::config::LabelRule::Road)
            .unwrap();
    let source = travmap_io::Source::open(input, &Default::default(), &|_| {}).unwrap();
    let selection = travmap_run::DriveRun::new(source, 0..usize::MAX);
    let mut cells = Vec::new();
    selection
        .run::<travmap_core::Error>(&config, Some(&model), |result| {
            let features = &result.features;
            cells.extend(
                (0..result.layout.cell_count())
                    .map(|c| features.appearance(c).map(<[f32]>::to_vec)),
            );
            Ok(())
        })
        .unwrap();
    cells
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_jpeg_camera_is_read_as_its_png_original_less_the_jpeg_loss() {
    let Some((_dir, drive, routes)) = one_frame_routes() else {
        return;
    };
    let jpeg = routes.join("rosbag2-mcap-jpeg");
    // The route's camera is what fleets record: JPEG, named as image_transport names it.
    let camera = messages_on(&jpeg, &["/camera_2/image/compressed"]);
    assert_eq!(camera.len(), 1);
    let message: travmap_formats::ros::CompressedImage =
        travmap_formats::ros::decode(&camera[0].2).unwrap();
    assert_eq!(message.format, "rgb8; jpeg compressed bgr8");
    assert!(message.data.starts_with(&[0xFF, 0xD8, 0xFF]));

    assert_eq!(images(&jpeg), images(&drive));
    assert_eq!(images(&drive).0, 1);

    // The same cells are seen; their HSV histograms move by JPEG's loss (hue is
    // unsteady in the road's grey pixels), far less than from one cell to another.
    let (png_cells, jpeg_cells) = (appearance_of(&drive), appearance_of(&jpeg));
    assert_eq!(png_cells.len(), jpeg_cells.len());
    let l1 = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs() as f64)
            .sum::<f64>()
    };
    let seen: Vec<(&[f32], &[f32])> = png_cells
        .iter()
        .zip(&jpeg_cells)
        .filter_map(|(p, j)| {
            assert_eq!(p.is_some(), j.is_some(), "a cell seen in one camera only");
            Some((p.as_deref()?, j.as_deref()?))
        })
        .collect();
    assert!(seen.len() > 500, "{} cells seen", seen.len());
    let mean = |pairs: &mut dyn Iterator<Item = f64>| {
        let values: Vec<f64> = pairs.collect();
        values.iter().sum::<f64>() / values.len() as f64
    };
    let jpeg_loss = mean(&mut seen.iter().map(|(p, j)| l1(p, j)));
    let between_cells = mean(
        &mut seen
            .iter()
            .zip(seen.iter().skip(7))
            .map(|(a, b)| l1(a.0, b.0)),
    );
    // Measured: 1.59 against 3.00 (L1 over the 88 values, 644 cells).
    assert!(
        jpeg_loss < 0.6 * between_cells,
        "JPEG against PNG {jpeg_loss:.3}, between cells {between_cells:.3}"
    );
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_pose_topic_poses_a_log_without_moving_tf() {
    let Some((dir, drive, routes)) = sample_routes() else {
        return;
    };
    let reference = annotated_grids(dir.path(), &drive, "ros2");
    // PoseStamped (rosbag2) and PoseWithCovarianceStamped (ROS 1): the pose of
    // base_link, which carries the LiDAR on /tf_static, and no moving /tf.
    // And a Foxglove PoseInFrame (the Foxglove SDK), read as a PoseStamped.
    for (route, message_type) in [
        ("rosbag2-mcap-pose", "PoseStamped"),
        ("ros1-pose.bag", "PoseWithCovarianceStamped"),
        ("foxglove-pose.mcap", "PoseStamped"),
    ] {
        let input = routes.join(route);
        let out = travmap(&["eval", arg(&input)]);
        assert!(out.status.success(), "{}", crate::common::stderr(&out));
        assert_contains(
            &crate::common::stderr(&out),
            &[
                "poses from /pose",
                message_type,
                "the pose of `base_link`",
                "in `map`",
            ],
        );
        let annotated = annotated_grids(dir.path(), &input, route);
        assert_eq!(annotated.len(), reference.len(), "{route}");
        for ((topic, time, bytes), (_, reference_time, reference_bytes)) in
            annotated.iter().zip(&reference)
        {
            assert_eq!(time, reference_time, "{route} {topic}");
            if topic == "/travmap/cloud" {
                // The same points and classes; their float64 world coordinates may
                // differ in the last bits, the vehicle's pose composed with the mount.
                let (cloud, expected): (PointCloud2, PointCloud2) =
                    (decode(bytes).unwrap(), decode(reference_bytes).unwrap());
                assert_eq!(cloud.fields, expected.fields, "{route} at {time}");
                let points = |c: &PointCloud2| -> Vec<Vec<u8>> {
                    c.data
                        .chunks_exact(c.point_step as usize)
                        .map(<[u8]>::to_vec)
                        .collect()
                };
                for (p, q) in points(&cloud).iter().zip(points(&expected)) {
                    assert_eq!(p[24..], q[24..], "{route} classes at {time}");
                    for at in [0, 8, 16] {
                        let v = |b: &[u8]| f64::from_le_bytes(b[at..at + 8].try_into().unwrap());
                        assert!((v(p) - v(&q)).abs() < 1e-6, "{route} at {time}");
                    }
                }
                continue;
            }
            if topic != "/travmap/prediction" {
                assert!(bytes == reference_bytes, "{route} {topic} at {time}");
                continue;
            }
            // The same cells; the grid's height may differ in the last bit, the
            // vehicle's pose composed with the mount.
            let (grid, expected): (OccupancyGrid, OccupancyGrid) =
                (decode(bytes).unwrap(), decode(reference_bytes).unwrap());
            assert_eq!(grid.data, expected.data, "{route} at {time}");
            let (z, expected_z) = (grid.info.origin.position.z, expected.info.origin.position.z);
            assert!((z - expected_z).abs() < 1e-9, "{route}: {z} {expected_z}");
        }
        assert_eq!(scores(&input), scores(&drive), "{route}");
    }
    // Asked for /tf alone, the log has none that moves the clouds.
    let input = routes.join("rosbag2-mcap-pose");
    let err = clean_failure(travmap(&["eval", arg(&input), "--poses", "tf"]));
    assert_contains(&err, &["--poses tf", "PoseStamped"]);
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn several_pose_topics_are_chosen_between_by_name() {
    let Some((_dir, drive, routes)) = sample_routes() else {
        return;
    };
    let two = routes.join("rosbag2-mcap-two-poses");
    // Not guessed: registration, saying why.
    let out = travmap(&["eval", arg(&two)]);
    assert_contains(
        &crate::common::stderr(&out),
        &[
            "2 pose topics (/pose, /vision_pose)",
            "poses estimated by scan registration",
        ],
    );
    success(out);
    // Named: the original's scores.
    let out = travmap(&["eval", arg(&two), "--pose-topic", "/pose", "--json"]);
    assert_contains(&crate::common::stderr(&out), &["poses from /pose"]);
    let (_, summary) = crate::common::json_records(&success(out));
    assert_eq!(
        summary["scores"],
        crate::common::json_summary(&["eval", arg(&drive)])["scores"]
    );
    let err = clean_failure(travmap(&["eval", arg(&two), "--pose-topic", "/gnss"]));
    assert_contains(
        &err,
        &[
            "--pose-topic /gnss: no PoseStamped or PoseWithCovarianceStamped topic of that name",
            "/pose (geometry_msgs/msg/PoseStamped), /vision_pose (geometry_msgs/msg/PoseStamped)",
        ],
    );
    // A moving /tf poses the clouds, whatever the pose topics; naming one says so.
    let with_tf = routes.join("rosbag2-mcap-poses-and-tf");
    assert_eq!(scores(&with_tf), scores(&drive));
    let out = travmap(&["eval", arg(&with_tf), "--pose-topic", "/pose"]);
    assert_contains(
        &crate::common::stderr(&out),
        &["--pose-topic /pose is not used: a moving /tf or an Odometry already poses the clouds"],
    );
    success(out);
}
