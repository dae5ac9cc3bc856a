//! Malformed inputs give a clear error naming the file and what was expected, with
//! exit code 1 and never a panic. The sequences are synthetic, written here, so
//! these tests need no shared data.

use std::path::Path;

use crate::common::{arg, assert_contains, clean_failure, stderr, success, travmap, usage_error};

const IDENTITY_3X4: &str = "1 0 0 0 0 1 0 0 0 0 1 0";
/// Sequence 00's velodyne -> cam0.
const TR: &str = "4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01";

/// A flat ground at z = -1.73 with a 1 m wall, as a scan of `n` points per frame.
fn scene_points() -> Vec<[f32; 4]> {
    let mut points = Vec::new();
    for i in 0..60 {
        for j in 0..60 {
            let (x, y) = (-6.0 + 0.2 * i as f32, -6.0 + 0.2 * j as f32);
            points.push([x, y, -1.73, 0.3]);
            if (3.0..3.2).contains(&x) {
                for k in 0..5 {
                    points.push([x, y, -1.73 + 0.2 * k as f32, 0.5]);
                }
            }
        }
    }
    points
}

fn write_scan(path: &Path, points: &[[f32; 4]]) {
    let bytes: Vec<u8> = points
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(path, bytes).unwrap();
}

/// A valid two-frame sequence with labels (road, and building on the wall).
fn write_sequence(dir: &Path) {
    std::fs::create_dir_all(dir.join("velodyne")).unwrap();
    std::fs::create_dir_all(dir.join("labels")).unwrap();
    std::fs::write(
        dir.join("calib.txt"),
        format!("P0: {IDENTITY_3X4}\nP2: {IDENTITY_3X4}\nTr: {TR}\n"),
    )
    .unwrap();
    std::fs::write(
        dir.join("poses.txt"),
        format!("{IDENTITY_3X4}\n{IDENTITY_3X4}\n"),
    )
    .unwrap();
    std::fs::write(dir.join("times.txt"), "0.0\n0.1\n").unwrap();
    let points = scene_points();
    let labels: Vec<u8> = points
        .iter()
        .flat_map(|p| (if p[2] > -1.7 { 50u32 } else { 40 }).to_le_bytes())
        .collect();
    for frame in 0..2 {
        write_scan(&dir.join(format!("velodyne/{frame:06}.bin")), &points);
        std::fs::write(dir.join(format!("labels/{frame:06}.label")), &labels).unwrap();
    }
}

/// The valid sequence in a new temporary directory.
fn sequence() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path());
    dir
}

fn eval(dir: &Path) -> std::process::Output {
    travmap(&["eval", arg(dir)])
}

/// The error of `eval` on the valid sequence with `file` rewritten as `contents`.
fn error_with(file: &str, contents: impl AsRef<[u8]>) -> String {
    let dir = sequence();
    std::fs::write(dir.path().join(file), contents).unwrap();
    clean_failure(eval(dir.path()))
}

/// Cuts the last `bytes` bytes off the file at `path`.
fn cut_short(path: &Path, bytes: usize) {
    let mut content = std::fs::read(path).unwrap();
    content.truncate(content.len() - bytes);
    std::fs::write(path, content).unwrap();
}

#[test]
fn the_synthetic_sequence_itself_is_fine() {
    let out = success(eval(sequence().path()));
    assert_contains(&out, &["over 2 frames"]);
}

#[test]
fn scan_size_not_a_multiple_of_16() {
    let dir = sequence();
    cut_short(&dir.path().join("velodyne/000001.bin"), 5);
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["000001.bin", "not a multiple of 16"]);
}

#[test]
fn label_count_differs_from_point_count() {
    let dir = sequence();
    let labels = dir.path().join("labels/000000.label");
    let mut bytes = std::fs::read(&labels).unwrap();
    bytes.extend_from_slice(&40u32.to_le_bytes());
    std::fs::write(&labels, bytes).unwrap();
    let err = clean_failure(eval(dir.path()));
    let points = scene_points().len();
    let counts = format!("{} labels for {points} points", points + 1);
    assert_contains(&err, &["000000.label", &counts]);
}

#[test]
fn missing_pose_line() {
    let err = error_with("poses.txt", format!("{IDENTITY_3X4}\n"));
    assert_contains(&err, &["poses.txt", "no pose for frame 1"]);
}

#[test]
fn malformed_pose_line() {
    let err = error_with(
        "poses.txt",
        format!("{IDENTITY_3X4}\n1 0 0 x 0 1 0 0 0 0 1 0\n"),
    );
    assert_contains(&err, &["poses.txt:2", "`x` is not a number"]);
}

/// The frame lines of `run --json` on `dir`, without the input's name and the
/// timings, which vary from run to run.
fn run_json(dir: &Path) -> Vec<serde_json::Value> {
    crate::common::json_records(&success(travmap(&["run", arg(dir), "--json"])))
        .0
        .into_iter()
        .map(|mut value| {
            if let Some(object) = value.as_object_mut() {
                object.retain(|key, _| key != "input" && key != "timings");
            }
            value
        })
        .collect()
}

#[test]
fn points_without_a_return_are_dropped_and_counted() {
    let dir = sequence();
    let mut points = scene_points();
    points[17][1] = f32::NAN;
    points[30][2] = f32::INFINITY;
    // A beam without a return, as an Ouster scan records it.
    points[41] = [0.0, 0.0, 0.0, 0.0];
    write_scan(&dir.path().join("velodyne/000001.bin"), &points);
    let out = success(eval(dir.path()));
    assert_contains(
        &out,
        &[
            "3 points without a return (a NaN or infinite coordinate, or the sensor's origin) were dropped",
        ],
    );
    let with_bad_points = run_json(dir.path());
    assert_eq!(with_bad_points[0]["dropped_points"], 0);
    assert_eq!(with_bad_points[1]["dropped_points"], 3);

    // The same as a sequence without those points: the labels stay aligned.
    let clean = sequence();
    let kept: Vec<[f32; 4]> = (0..points.len())
        .filter(|i| ![17, 30, 41].contains(i))
        .map(|i| points[i])
        .collect();
    write_scan(&clean.path().join("velodyne/000001.bin"), &kept);
    let labels = std::fs::read(clean.path().join("labels/000001.label")).unwrap();
    let kept_labels: Vec<u8> = labels
        .chunks(4)
        .enumerate()
        .filter(|(i, _)| ![17, 30, 41].contains(i))
        .flat_map(|(_, b)| b.to_vec())
        .collect();
    std::fs::write(clean.path().join("labels/000001.label"), kept_labels).unwrap();
    let mut without = run_json(clean.path());
    without[1]["dropped_points"] = 3.into();
    assert_eq!(with_bad_points, without);
}

#[test]
fn an_all_nan_scan_is_an_error_that_keep_going_skips() {
    let dir = sequence();
    let points = vec![[f32::NAN, 0.0, 0.0, 0.5]; scene_points().len()];
    write_scan(&dir.path().join("velodyne/000001.bin"), &points);
    let err = clean_failure(eval(dir.path()));
    assert_contains(
        &err,
        &[
            "000001.bin",
            "every one of its",
            "NaN or infinite",
            "--keep-going",
        ],
    );
    let out = travmap(&["eval", arg(dir.path()), "--keep-going", "-q"]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    assert_contains(&stderr(&out), &["skipped frame 1", "000001.bin"]);
}

#[test]
fn labels_of_ids_the_label_set_does_not_define_get_a_notice() {
    let dir = sequence();
    // Ids no SemanticKITTI class has (another ontology's, or noise).
    let labels: Vec<u8> = (0..scene_points().len() as u32)
        .flat_map(|i| (1000 + i % 7).to_le_bytes())
        .collect();
    std::fs::write(dir.path().join("labels/000001.label"), labels).unwrap();
    let out_dir = tempfile::tempdir().unwrap();
    let map = out_dir.path().join("map.png");
    let annotated = out_dir.path().join("a.mcap");
    for command in [
        vec!["eval"],
        vec!["map", "-o", arg(&map)],
        vec!["annotate", "-o", arg(&annotated)],
    ] {
        let out = travmap(&[&command[..], &[arg(dir.path()), "-q"]].concat());
        let command = command[0];
        let err = stderr(&out);
        assert!(out.status.success(), "{command}: {err}");
        assert_contains(
            &err,
            &[
                "notice:",
                "in 1 frame carry ids the semantickitti label set does not define",
                "e.g. 1000, 1001, 1002, 1003, 1004",
            ],
        );
    }
    // The valid labels: no notice of them (the drive's fit is said, as always).
    let out = travmap(&["eval", arg(sequence().path()), "-q"]);
    assert!(!stderr(&out).contains("carry ids"), "{}", stderr(&out));
}

#[test]
fn a_tr_or_pose_that_is_not_rigid() {
    let err = error_with("calib.txt", "Tr: 1 2 3 0 4 5 6 0 7 8 10 0\n");
    assert_contains(&err, &["calib.txt", "Tr is not a rigid transform"]);
    let err = error_with(
        "poses.txt",
        format!("{IDENTITY_3X4}\n2 0 0 0 0 2 0 0 0 0 2 0\n"),
    );
    assert_contains(&err, &["poses.txt:2", "the pose is not a rigid transform"]);
}

#[test]
fn a_model_file_of_another_version() {
    let dir = sequence();
    let model =
        travmap_method::classifier::SvmModel::embedded(travmap_core::config::LabelRule::Road)
            .unwrap();
    let mut json: serde_json::Value = serde_json::from_slice(&model.to_json()).unwrap();
    json["version"] = 99.into();
    let path = dir.path().join("old-model.json");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let err = clean_failure(travmap(&["eval", arg(dir.path()), "--model", arg(&path)]));
    assert_contains(
        &err,
        &["old-model.json", "format `travmap-svm` version 99;"],
    );
}

#[test]
fn calibration_without_tr() {
    let err = error_with("calib.txt", format!("P0: {IDENTITY_3X4}\n"));
    assert_contains(&err, &["calib.txt", "no `Tr:` line"]);
}

#[test]
fn missing_files_and_directories() {
    let dir = sequence();
    // Without times.txt (as nuScenes-lidarseg's conversions ship), the scans are
    // stamped at a rate, said in a notice; without calib.txt the poses are the
    // LiDAR's; without poses.txt there is nothing to place the scans by.
    std::fs::remove_file(dir.path().join("times.txt")).unwrap();
    let said = stderr(&success_output(eval(dir.path())));
    assert_contains(
        &said,
        &["no times.txt: the scans stamped at 10 Hz", "--rate"],
    );
    std::fs::remove_file(dir.path().join("calib.txt")).unwrap();
    let said = stderr(&success_output(eval(dir.path())));
    assert_contains(
        &said,
        &["no calib.txt: the poses in poses.txt are taken as the LiDAR's own"],
    );
    std::fs::remove_file(dir.path().join("poses.txt")).unwrap();
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["poses.txt"]);
    let err = clean_failure(eval(&dir.path().join("nowhere")));
    assert_contains(&err, &["nowhere does not exist"]);
}

/// `output`, asserted to have ended well.
fn success_output(output: std::process::Output) -> std::process::Output {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// A model file's error names the parameter that is wrong, as the file names it.
#[test]
fn a_model_error_names_its_parameter() {
    let dir = sequence();
    let seq = arg(dir.path());
    let embedded =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/method/src/classifier/road_model.json");
    let model: serde_json::Value =
        serde_json::from_slice(&std::fs::read(embedded).unwrap()).unwrap();
    let cases: [(&str, serde_json::Value, &str); 4] = [
        (
            "/gamma",
            "x".into(),
            "`gamma`: invalid type: string \"x\", expected f64",
        ),
        (
            "/gamma",
            (-1.0).into(),
            "`gamma` must be in (0.0, 10000.0], got -1.0",
        ),
        (
            "/feature_std/3",
            0.0.into(),
            "`feature_std[3]` is 0, a positive deviation expected",
        ),
        (
            "/config/grid/size_m",
            "x".into(),
            "`config.grid.size_m`: invalid type",
        ),
    ];
    for (pointer, value, said) in cases {
        let mut broken = model.clone();
        *broken.pointer_mut(pointer).unwrap() = value;
        let file = dir.path().join("broken.json");
        std::fs::write(&file, serde_json::to_vec(&broken).unwrap()).unwrap();
        let err = clean_failure(travmap(&["eval", seq, "--model", arg(&file)]));
        assert_contains(&err, &["broken.json", said]);
    }
}

/// A database that is not rosbag2's says what it lacks in words, not in SQL.
#[test]
fn a_sqlite_file_of_other_tables_is_named_without_sql() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("other.db3");
    let database = rusqlite::Connection::open(&file).unwrap();
    database
        .execute_batch(
            "CREATE TABLE topics(id INTEGER, name TEXT); \
             CREATE TABLE messages(id INTEGER, topic_id INTEGER, timestamp INTEGER, data BLOB);",
        )
        .unwrap();
    drop(database);
    let err = clean_failure(eval(&file));
    assert_contains(
        &err,
        &[
            "other.db3: not a rosbag2 database: no such column: type",
            "(expected: rosbag2's `topics` table: id, name, type, serialization_format)",
        ],
    );
    assert!(!err.contains("SELECT"), "{err}");
}

#[test]
fn bad_frame_range_and_model_file() {
    let dir = sequence();
    let seq = arg(dir.path());
    let err = clean_failure(travmap(&["eval", seq, "--frames", "5..9"]));
    assert_contains(&err, &["no scans in frames 5..=8", "0..=1"]);
    let err = clean_failure(travmap(&["eval", seq, "--frames", "6.."]));
    assert_contains(
        &err,
        &["no scans in frames 6.. (the input has frames 0..=1)"],
    );
    // A malformed range is a usage error, refused before anything is read.
    let err = usage_error(travmap(&["eval", seq, "--frames", "3..1"]));
    assert_contains(&err, &["ends before it starts"]);
    let err = usage_error(travmap(&["eval", seq, "--frames", "2..=1"]));
    assert_contains(&err, &["A..=B is A to B"]);
    // Numbers that are no scan rate or height.
    let err = usage_error(travmap(&["eval", seq, "--rate", "1e-300"]));
    assert_contains(&err, &["a scan rate of 0.01 to 1000 Hz, got 1e-300"]);
    let out = dir.path().join("a.mcap");
    let err = usage_error(travmap(&[
        "annotate",
        seq,
        "-o",
        arg(&out),
        "--grid-height",
        "nan",
    ]));
    assert_contains(&err, &["a finite number, got nan"]);
    // Usage mistakes clap cannot see exit 2 as well.
    let err = usage_error(travmap(&["eval", seq, "--set", "grid.no_such=1"]));
    assert_contains(&err, &["--set grid.no_such=1"]);
    // A one-input command says so in its usage line, and clap refuses a second.
    let err = usage_error(travmap(&["odometry", seq, seq, "-o", arg(&out)]));
    assert_contains(
        &err,
        &[
            "unexpected argument",
            "travmap odometry [OPTIONS] --output <OUTPUT> <INPUT>\n",
        ],
    );
    let err = usage_error(travmap(&["render", seq, "-o", arg(&out)]));
    assert_contains(&err, &["required arguments were not provided"]);
    let err = usage_error(travmap(&["render", seq, "--all", "-o", "pictures.png"]));
    assert_contains(&err, &["names a PNG file"]);
    assert!(!Path::new("pictures.png").exists());
    let model = dir.path().join("broken.json");
    std::fs::write(&model, b"{\"format\": \"travmap-svm\", \"version\": 1, ").unwrap();
    let err = clean_failure(travmap(&["eval", seq, "--model", arg(&model)]));
    assert_contains(&err, &["broken.json"]);
}

#[test]
fn training_without_labels_is_an_error_and_writes_nothing() {
    let dir = sequence();
    std::fs::remove_dir_all(dir.path().join("labels")).unwrap();
    let model = dir.path().join("m.json");
    let err = clean_failure(travmap(&["train", arg(dir.path()), "-o", arg(&model)]));
    assert_contains(&err, &["no labelled cells"]);
    assert!(!model.exists());
    // Evaluation without labels is an error too: nothing to score.
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["no frame of the input has labels"]);
}

#[test]
fn an_empty_folder_or_a_folder_of_separate_logs_is_said_to_be_one() {
    let dir = tempfile::tempdir().unwrap();
    let err = clean_failure(travmap(&["run", arg(dir.path())]));
    assert_contains(&err, &["is an empty folder; travmap reads KITTI"]);
    assert!(!err.contains("poses.txt"), "not read as a sequence: {err}");
    std::fs::write(dir.path().join("notes.txt"), "x").unwrap();
    let err = clean_failure(travmap(&["run", arg(dir.path())]));
    assert_contains(&err, &["no velodyne/ folder"]);
    // Two logs of their own side by side are not one recording ...
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let logs = tempfile::tempdir().unwrap();
    for (name, frames) in [("morning.mcap", "0..2"), ("evening.mcap", "2..4")] {
        let log = logs.path().join(name);
        success(travmap(&[
            "convert",
            arg(&seq),
            "--frames",
            frames,
            "-o",
            arg(&log),
        ]));
    }
    let err = clean_failure(travmap(&["run", arg(logs.path())]));
    assert_contains(
        &err,
        &[
            "a folder of 2 separate logs",
            "evening.mcap",
            "give each log",
        ],
    );
    // ... where the splits of one are.
    for (from, to) in [
        ("morning.mcap", "drive_0.mcap"),
        ("evening.mcap", "drive_1.mcap"),
    ] {
        std::fs::rename(logs.path().join(from), logs.path().join(to)).unwrap();
    }
    let out = travmap(&["run", arg(logs.path())]);
    assert_contains(&success(out), &["frame"]);
}

#[test]
fn keep_going_skips_a_corrupt_frame_and_exits_3() {
    let dir = sequence();
    cut_short(&dir.path().join("velodyne/000001.bin"), 3);
    let seq = arg(dir.path());
    // Without --keep-going the first bad frame stops the run.
    clean_failure(travmap(&["eval", seq]));
    let out = travmap(&["eval", seq, "--keep-going"]);
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}",
        crate::common::stderr(&out)
    );
    let err = crate::common::stderr(&out);
    assert_contains(
        &err,
        &[
            "skipped frame 1",
            "000001.bin",
            "completed with 1 skipped frame",
        ],
    );
    assert_contains(&crate::common::stdout(&out), &["over 1 frame\n"]);
    // Without it, an annotation that fails at frame 1, after frame 0 was written,
    // leaves no output and no temporary file.
    let out_dir = tempfile::tempdir().unwrap();
    let stopped = out_dir.path().join("stopped.mcap");
    let err = clean_failure(travmap(&["annotate", seq, "-o", arg(&stopped)]));
    assert_contains(&err, &["000001.bin"]);
    assert_eq!(std::fs::read_dir(out_dir.path()).unwrap().count(), 0);
    // The annotated output is complete and records the skip.
    let mcap_path = dir.path().join("a.mcap");
    let out = travmap(&["annotate", seq, "-o", arg(&mcap_path), "--keep-going", "-q"]);
    assert_eq!(out.status.code(), Some(3));
    let metadata = crate::common::travmap_metadata(&std::fs::read(&mcap_path).unwrap());
    assert_contains(&metadata["skipped_frames"], &["\"frame\":1"]);
}

#[test]
fn images_without_p2_in_the_calibration() {
    let dir = sequence();
    std::fs::write(
        dir.path().join("calib.txt"),
        format!("P0: {IDENTITY_3X4}\nTr: {TR}\n"),
    )
    .unwrap();
    std::fs::create_dir_all(dir.path().join("image_2")).unwrap();
    let mut png_bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut png_bytes, 4, 2);
        encoder.set_color(png::ColorType::Rgb);
        encoder
            .write_header()
            .unwrap()
            .write_image_data(&[90u8; 24])
            .unwrap();
    }
    std::fs::write(dir.path().join("image_2/000000.png"), png_bytes).unwrap();
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["calib.txt", "no `P2:` line", "image_2"]);
    success(travmap(&[
        "eval",
        arg(dir.path()),
        "--set",
        "appearance.enabled=false",
    ]));
}

#[test]
fn an_empty_scan_file_is_an_error_not_an_empty_scan() {
    let dir = sequence();
    std::fs::remove_dir_all(dir.path().join("labels")).unwrap();
    std::fs::write(dir.path().join("velodyne/000001.bin"), b"").unwrap();
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["000001.bin: 0 bytes, no points", "--keep-going"]);
}

/// A blank line inside poses.txt shifted every later pose by one frame; now it is
/// an error naming the line (times.txt and calib.txt likewise).
#[test]
fn a_blank_line_in_a_text_input_is_an_error() {
    let err = error_with("poses.txt", format!("{IDENTITY_3X4}\n\n{IDENTITY_3X4}\n"));
    assert_contains(&err, &["poses.txt:2: a blank line"]);
    let err = error_with("times.txt", "0.0\n\n0.1\n");
    assert_contains(&err, &["times.txt:2: a blank line"]);
    let err = error_with("calib.txt", format!("P0: {IDENTITY_3X4}\n\nTr: {TR}\n"));
    assert_contains(&err, &["calib.txt:2: a blank line"]);
}

/// Pointing next to a drive says where to point instead.
#[test]
fn a_folder_that_is_no_drive_says_where_to_point() {
    let root = tempfile::tempdir().unwrap();
    let sequence = root.path().join("sequences").join("00");
    write_sequence(&sequence);
    let err = clean_failure(eval(root.path()));
    assert_contains(
        &err,
        &["a dataset root: point at one sequence", "sequences/00"],
    );
    let err = clean_failure(eval(&root.path().join("sequences")));
    assert_contains(&err, &["a folder of sequences, not one", "sequences/00"]);
    let velodyne = sequence.join("velodyne");
    let err = clean_failure(eval(&velodyne));
    assert_contains(&err, &["not its velodyne/ folder", "--poses registration"]);
    // A rosbag2 directory without metadata.yaml is read from its storage files
    // (tests/ros_logs.rs): one that is not SQLite is named.
    let bag = root.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    std::fs::write(bag.join("bag_0.db3"), b"SQLite format 3\0").unwrap();
    let err = clean_failure(eval(&bag));
    assert_contains(&err, &["bag_0.db3", "not a rosbag2 database"]);
    let pcd = root.path().join("one.pcd");
    std::fs::write(&pcd, b"# .PCD v0.7\n").unwrap();
    let err = clean_failure(eval(&pcd));
    assert_contains(
        &err,
        &["a single PCD point cloud", "folders of .pcd / .bin scans"],
    );
}

/// A start time in milliseconds (or beyond ROS 2's stamps) is a usage error with
/// the likely fix.
#[test]
fn a_start_time_in_milliseconds_is_refused_with_the_fix() {
    let dir = sequence();
    let out = dir.path().join("out.mcap");
    let convert = |start: &str| {
        travmap(&[
            "convert",
            arg(dir.path()),
            "-o",
            arg(&out),
            "--start-time",
            start,
        ])
    };
    let err = usage_error(convert("1700000000000"));
    assert_contains(
        &err,
        &["it looks like milliseconds: --start-time 1700000000"],
    );
    let err = usage_error(convert("1e30"));
    assert_contains(&err, &["ROS 2 stamps end in 2038"]);
    assert!(!out.exists());
    success(convert("1700000000"));
}

/// `run` and `odometry` need no labels: a label file one short does not stop them;
/// `eval`, which scores with them, names it.
#[test]
fn commands_that_need_no_labels_ignore_a_broken_label_file() {
    let dir = sequence();
    cut_short(&dir.path().join("labels/000001.label"), 4);
    success(travmap(&["run", arg(dir.path()), "-q"]));
    let poses = dir.path().join("poses.out.txt");
    let output = travmap(&["odometry", arg(dir.path()), "-o", arg(&poses), "-q"]);
    // The synthetic scans may not register; what matters is that labels did not stop it.
    assert!(
        !crate::common::stderr(&output).contains("labels for"),
        "{}",
        crate::common::stderr(&output)
    );
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["000001.label", "labels for"]);
}

#[test]
fn a_pipe_as_input_is_refused_at_once_not_waited_on() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("drive.mcap");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    assert!(made.unwrap().success());
    // No writer ever comes: opening the pipe would block for good.
    for command in [
        vec!["run", arg(&fifo)],
        vec!["map", arg(&fifo), "-o", "never.png"],
    ] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_travmap"))
            .args(&command)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        while child.try_wait().unwrap().is_none() {
            if std::time::Instant::now() > deadline {
                child.kill().unwrap();
                panic!("{command:?} waited on a pipe with no writer");
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let output = child.wait_with_output().unwrap();
        let err = clean_failure(output);
        assert_contains(
            &err,
            &["drive.mcap", "a pipe", "save the stream to a file first"],
        );
    }
}

#[test]
fn annotate_passes_kitti_frames_through_as_read_and_keep_going_skips_an_unreadable_image() {
    let dir = sequence();
    std::fs::create_dir_all(dir.path().join("image_2")).unwrap();
    let mut png_bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut png_bytes, 4, 2);
        encoder.set_color(png::ColorType::Rgb);
        let mut writer = encoder.write_header().unwrap();
        writer.write_image_data(&[90u8; 24]).unwrap();
    }
    std::fs::write(dir.path().join("image_2/000000.png"), png_bytes).unwrap();
    std::fs::write(dir.path().join("image_2/000001.png"), "not a png").unwrap();
    let seq = arg(dir.path());
    // The geometric model reads no image; passing frame 1 through does, and stops.
    let out_dir = tempfile::tempdir().unwrap();
    let stopped = out_dir.path().join("stopped.mcap");
    let err = clean_failure(travmap(&["annotate", seq, "-o", arg(&stopped)]));
    assert_contains(&err, &["000001.png", "not a PNG image"]);
    assert_eq!(std::fs::read_dir(out_dir.path()).unwrap().count(), 0);
    // --keep-going: both frames annotated, frame 1's input messages left out.
    let kept = out_dir.path().join("kept.mcap");
    let out = travmap(&["annotate", seq, "-o", arg(&kept), "--keep-going", "-q"]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
    let bytes = std::fs::read(&kept).unwrap();
    let mut topics = std::collections::BTreeMap::<String, Vec<u64>>::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let stamps = topics.entry(message.channel.topic.clone()).or_default();
        stamps.push(message.log_time);
    }
    assert_eq!(topics["/travmap/metrics"], [0, 100_000_000]);
    assert_eq!(topics["/velodyne_points"], [0]);
    assert_eq!(topics["/camera_2/image/compressed"], [0]);
    assert_eq!(topics["/tf_static"], [0]);
    let metadata = crate::common::travmap_metadata(&bytes);
    assert_contains(&metadata["skipped_frames"], &["\"frame\":1", "000001.png"]);
}

/// With every frame skipped there is no result: each command that writes one exits
/// 1 and leaves no output (an empty MCAP, PNG, Parquet file or trajectory was once
/// written, and a fleet script counted the drive as done).
#[test]
fn every_frame_skipped_writes_no_output() {
    let dir = sequence();
    std::fs::write(dir.path().join("poses.txt"), "").unwrap();
    let out_dir = tempfile::tempdir().unwrap();
    for (command, name) in [
        ("annotate", "a.mcap"),
        ("convert", "c.mcap"),
        ("map", "m.png"),
        ("dataset", "d.parquet"),
        ("odometry", "poses.txt"),
    ] {
        let output = out_dir.path().join(name);
        let out = travmap(&[command, arg(dir.path()), "-o", arg(&output), "--keep-going"]);
        let err = clean_failure(out);
        assert_contains(
            &err,
            &[
                "is not written: no frame of",
                "skipped; frame 0:",
                "poses.txt",
            ],
        );
        assert!(!output.exists(), "{command} wrote {}", output.display());
    }
    assert_eq!(std::fs::read_dir(out_dir.path()).unwrap().count(), 0);
}

/// Another dataset's labels scored as SemanticKITTI's: the notice names the presets
/// that define every id seen (RELLIS-3D's scan read without its label set).
#[test]
fn the_notice_of_unknown_label_ids_names_the_presets_that_fit() {
    let Some(rellis) = crate::common::shared_data("rellis3d-000104/sequences/00") else {
        return;
    };
    let out = travmap(&["eval", arg(&rellis), "-q"]);
    assert!(out.status.success());
    assert_contains(
        &stderr(&out),
        &[
            "the semantickitti label set does not define",
            "they fit the rellis3d and nuscenes label sets",
        ],
    );
}

/// A FIFO as poses.txt is refused, not opened (opening a pipe no process writes
/// blocked the run for ever).
#[test]
fn a_pipe_as_poses_txt_is_refused_not_waited_on() {
    let dir = sequence();
    let poses = dir.path().join("poses.txt");
    std::fs::remove_file(&poses).unwrap();
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&poses)
            .status()
            .unwrap()
            .success()
    );
    let err = clean_failure(eval(dir.path()));
    assert_contains(&err, &["poses.txt", "a pipe", "not a file"]);
}

#[test]
fn a_scan_whose_remission_is_nan_is_classified_without_remission_and_said() {
    let Some(sample) = crate::common::sample() else {
        return;
    };
    // The sample with frame 1's remission NaN at every point (its points intact).
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    std::fs::create_dir_all(seq.join("velodyne")).unwrap();
    for name in ["labels", "calib.txt", "times.txt", "poses.txt"] {
        std::os::unix::fs::symlink(sample.join(name), seq.join(name)).unwrap();
    }
    for frame in 0..6 {
        let name = format!("velodyne/{frame:06}.bin");
        let mut bytes = std::fs::read(sample.join(&name)).unwrap();
        if frame == 1 {
            for point in bytes.chunks_exact_mut(16) {
                point[12..].copy_from_slice(&f32::NAN.to_le_bytes());
            }
        }
        std::fs::write(seq.join(&name), bytes).unwrap();
    }
    let (frames, summary) =
        crate::common::json_records(&success(travmap(&["run", arg(&seq), "--json"])));
    // Frames 1-3 integrate scan 1: the fallback classifies them, and they still see
    // obstacles (with the NaN in the remission features every cell was traversable).
    for frame in &frames {
        let index = frame["frame"].as_u64().unwrap();
        let integrates_scan_1 = (1..=3).contains(&index);
        assert_eq!(
            frame["without_remission"], integrates_scan_1,
            "frame {index}"
        );
        let obstacles = frame["cells"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| *c == 100)
            .count();
        assert!(obstacles > 20, "frame {index}: {obstacles} obstacle cells");
    }
    assert_eq!(summary["frames_without_remission"], 3);
    // Said on stderr, as every notice of the drives is.
    let output = eval(&seq);
    success(output.clone());
    assert_contains(
        &stderr(&output),
        &[
            "notice: 3 frames had no usable remission (intensity; 124605 points' remission was NaN or infinite)",
        ],
    );
}

/// Files options name: a device is refused before a byte is read (/dev/zero filled
/// 12 GB), a FIFO no process writes is refused instead of blocking the open, and a
/// shell's <(...) still works.
#[test]
fn option_files_that_are_devices_or_pipes_without_a_writer_are_refused() {
    let dir = sequence();
    let seq = arg(dir.path());
    for (option, device) in [("--model", "/dev/zero"), ("--config", "/dev/urandom")] {
        let err = clean_failure(travmap(&["run", seq, option, device]));
        assert_contains(&err, &[device, "a device or a socket, not a file"]);
    }
    let fifo = dir.path().join("settings.toml");
    let name = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: mkfifo on a new path in this test's own folder.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(["run", seq, "--config", arg(&fifo)])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let waited = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if waited.elapsed().as_secs() > 20 {
            child.kill().unwrap();
            panic!("travmap blocked on a FIFO without a writer");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let err = clean_failure(child.wait_with_output().unwrap());
    assert_contains(&err, &["a pipe that gave nothing"]);
    // <(...): a pipe whose writer has written and gone.
    let out = std::process::Command::new("bash")
        .arg("-c")
        .arg(format!(
            "{} run {seq} --json --config <(printf '[grid]\\nsize_m = 24.0\\n') | tail -n 1",
            env!("CARGO_BIN_EXE_travmap")
        ))
        .output()
        .unwrap();
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["config"]["grid"]["size_m"], 24.0);
}

/// YAML nested 100,000 deep (200 kB) took ~40 s to refuse: the nesting is bounded
/// before the parser sees it, in a rosbag2 metadata.yaml and a Velodyne calibration.
#[test]
fn deeply_nested_yaml_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    let bag = dir.path().join("bag");
    std::fs::create_dir(&bag).unwrap();
    std::fs::write(bag.join("metadata.yaml"), format!("custom_data: {deep}\n")).unwrap();
    let calibration = dir.path().join("calibration.yaml");
    std::fs::write(&calibration, format!("lasers: {deep}\n")).unwrap();
    let vlp32 = crate::common::nebula_fixture("vlp32/1713492677464078412");
    for args in [
        vec!["run", arg(&bag)],
        vec!["run", arg(&vlp32), "--lidar-calibration", arg(&calibration)],
    ] {
        let started = std::time::Instant::now();
        let err = clean_failure(travmap(&args));
        assert_contains(&err, &["nest 100000 deep", "at most 64 expected"]);
        assert!(started.elapsed().as_secs() < 5, "{args:?}");
    }
}

/// A PLY header of 100,000 vertex properties made each chunk of records 50 GB,
/// reserved before the data was compared with what the header said (an abort under
/// an 8 GiB limit): chunks are bounded in bytes, and the short data is the error.
#[test]
fn a_ply_header_of_many_properties_is_refused_without_reserving_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let ply = dir.path().join("wide.ply");
    let properties: String = (0..100_000)
        .map(|i| format!("property double p{i}\n"))
        .collect();
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex 16000\n{properties}property float x\nproperty float y\nproperty float z\nend_header\n"
    );
    std::fs::write(&ply, [header.as_bytes(), &[0u8; 1000]].concat()).unwrap();
    let out = std::process::Command::new("bash")
        .arg("-c")
        .arg(format!(
            "ulimit -v 4000000; exec {} map {} -o {}",
            env!("CARGO_BIN_EXE_travmap"),
            arg(&ply),
            arg(&dir.path().join("map.png"))
        ))
        .output()
        .unwrap();
    let err = clean_failure(out);
    assert_contains(
        &err,
        &[
            "the header says 16000 vertices of 800012 bytes",
            "but 1000 bytes of data follow",
        ],
    );
}

/// A FIFO among the scans blocked the open for ever: it is refused by its kind,
/// named, and `--keep-going` skips it.
#[test]
fn a_fifo_among_the_scans_is_refused_not_waited_for() {
    let dir = sequence();
    let scan = dir.path().join("velodyne/000001.bin");
    std::fs::remove_file(&scan).unwrap();
    let name = std::ffi::CString::new(scan.to_str().unwrap()).unwrap();
    // SAFETY: mkfifo on a path of this test's own folder.
    assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
    let err = clean_failure(travmap(&["run", arg(dir.path())]));
    assert_contains(&err, &["000001.bin: a pipe", "not a file"]);
    let out = travmap(&["run", arg(dir.path()), "--keep-going"]);
    assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
}
