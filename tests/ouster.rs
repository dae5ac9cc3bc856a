//! Ouster packets against Ouster's own SDK: `tests/clients/ouster_packets.py` writes
//! RELLIS-3D's real OS1-64 scan as the packets of each UDP profile with the SDK's
//! `frame_to_packets`, recorded as ouster_ros records them (rosbag2 and ROS 1), and
//! the points the SDK's `XYZLut` makes of them; travmap must decode the same points
//! and read the logs as drives. The fixture (`fixtures/ouster/`, one profile, written
//! once) is checked in every run; the other routes need `TRAVMAP_OUSTER_PYTHON` (a
//! Python with ouster-sdk 1.0.1, which pins an older rosbags than the client venv's,
//! so it has its own venv: `.ci/clients.sh`).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{assert_contains, clean_failure, run_client, write_output};
use travmap_formats::ros::{OccupancyGrid, Time, decode};
use travmap_io::InputFormat;
use travmap_io::Log;
use travmap_io::OusterMetadata;
use travmap_io::{PacketAssembler, PacketCalibration, PacketModel};

const PROFILES: [&str; 6] = [
    "LEGACY",
    "RNG19_RFL8_SIG16_NIR16",
    "RNG19_RFL8_SIG16_NIR16_DUAL",
    "RNG15_RFL8_NIR8",
    "RNG15_RFL8_NIR8_DUAL",
    "FUSA_RNG15_RFL8_NIR8_DUAL",
];
const LOG_START_NS: u64 = 1_700_000_000_000_000_000;

/// The routes written into a temporary directory, or None without the data or the
/// SDK's Python.
fn routes() -> Option<(tempfile::TempDir, PathBuf)> {
    let scan = crate::common::shared_data("rellis3d-000104/sequences/00/velodyne/000000.bin")?;
    let python = crate::common::env_var("TRAVMAP_OUSTER_PYTHON", "a Python with ouster-sdk")?;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ouster");
    run_client(
        Command::new(python)
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/ouster_packets.py"))
            .arg(&scan)
            .arg(&out),
    );
    Some((dir, out))
}

/// The scans travmap cuts from a log's lidar packets, read with `metadata`.
fn decoded_scans(
    log: &Path,
    format: InputFormat,
    metadata: &OusterMetadata,
) -> Vec<(u64, Vec<[f32; 4]>)> {
    let calibration = PacketCalibration::Ouster(Box::new(metadata.clone()));
    let mut assembler =
        PacketAssembler::new(PacketModel::Ouster(metadata.model), &calibration).unwrap();
    let mut scans = Vec::new();
    for message in Log::open(log, format).unwrap().messages() {
        let message = message.unwrap();
        if message.connection.topic != "/ouster/lidar_packets" {
            continue;
        }
        let type_name = message.connection.type_name();
        let encoding = message.connection.encoding().unwrap();
        let completed =
            (assembler.push_message(&type_name, &message.data, encoding, message.log_time_ns))
                .unwrap();
        scans.extend(completed.into_iter().map(|scan| {
            let points = scan.points.iter().map(|p| {
                let [x, y, z] = p.xyz_m;
                [x, y, z, f32::from(p.intensity)]
            });
            (scan.stamp_ns, points.collect())
        }));
    }
    scans
}

/// The metadata a log records on `/ouster/metadata`.
fn recorded_metadata(log: &Path) -> OusterMetadata {
    let log = Log::open(log, InputFormat::Rosbag2).unwrap();
    let message = (log.messages().map(Result::unwrap))
        .find(|m| m.connection.topic == "/ouster/metadata")
        .unwrap();
    OusterMetadata::from_message(&message.data, message.connection.encoding().unwrap()).unwrap()
}

/// The scans of `log` are three, stamped with their first columns on the log's
/// clock, each the SDK's `points` within 1e-5 m, with the same reflectivity; the
/// farthest coordinate from the SDK's.
fn assert_sdks_points(
    log: &Path,
    format: InputFormat,
    metadata: &OusterMetadata,
    truth: &[[f32; 4]],
) -> f32 {
    let scans = decoded_scans(log, format, metadata);
    let stamps: Vec<u64> = scans.iter().map(|(stamp, _)| *stamp).collect();
    let expected: Vec<u64> = (0..3).map(|k| LOG_START_NS + k * 100_000_000).collect();
    assert_eq!(stamps, expected, "{}", log.display());
    let mut farthest = 0.0f32;
    for (_, points) in &scans {
        assert_eq!(points.len(), truth.len(), "{}: points", log.display());
        let worst = (truth.iter().zip(points))
            .map(|(t, p)| (0..3).map(|k| (t[k] - p[k]).abs()).fold(0.0, f32::max))
            .fold(0.0, f32::max);
        assert!(
            worst < 1e-5,
            "{}: a point {worst} m from the SDK's",
            log.display()
        );
        let reflectivity = |points: &[[f32; 4]]| points.iter().map(|p| p[3]).collect::<Vec<_>>();
        assert_eq!(
            reflectivity(points),
            reflectivity(truth),
            "{}",
            log.display()
        );
        farthest = farthest.max(worst);
    }
    println!(
        "{}: 3 scans of {} points, the farthest coordinate {farthest:e} m from the SDK's, the same reflectivity",
        log.display(),
        truth.len()
    );
    farthest
}

#[test]
fn the_fixture_decodes_to_the_sdks_points_and_is_a_drive() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ouster");
    let bag = fixtures.join("os1-64-1024x10");
    let metadata = recorded_metadata(&bag);
    assert_eq!(metadata.model.profile.name(), "RNG19_RFL8_SIG16_NIR16");
    let truth = points_file(&fixtures.join("os1-64-1024x10.points"));
    assert_sdks_points(&bag, InputFormat::Rosbag2, &metadata, &truth);
    // A drive: three frames, posed by /tf (the vehicle moves 0.5 m a frame), with no
    // notice of how it was read (an indoor Ouster scan fits the road model poorly,
    // which is said).
    let output = crate::common::travmap(&["run", bag.to_str().unwrap(), "--json"]);
    let said = crate::common::stderr(&output);
    assert!(
        said.lines()
            .all(|line| line.starts_with("notice: these drives fit the model poorly")),
        "{said}"
    );
    let (frames, summary) = crate::common::json_records(&crate::common::success(output));
    assert_eq!(frames.len(), 3, "{summary}");
    // The grid follows the vehicle along x; the reflectivity is read on the byte scale.
    let corner_x: Vec<f64> = (frames.iter())
        .map(|f| f["min_corner_in_world"][0].as_f64().unwrap())
        .collect();
    assert!(corner_x.windows(2).all(|w| w[1] > w[0]), "{corner_x:?}");
    assert!(frames.iter().all(|f| f["remission"] == "byte"));
}

fn points_file(path: &Path) -> Vec<[f32; 4]> {
    let bytes = std::fs::read(path).unwrap();
    bytes
        .chunks_exact(16)
        .map(|p| {
            std::array::from_fn(|k| f32::from_le_bytes(p[4 * k..4 * k + 4].try_into().unwrap()))
        })
        .collect()
}

#[test]
#[ignore = "needs ouster-sdk: source .ci/clients.sh && cargo test --release -- --ignored"]
fn ouster_packets_decode_to_the_sdks_points() {
    let Some((_dir, routes)) = routes() else {
        return;
    };
    let logs = PROFILES
        .map(|p| (p, routes.join(format!("ouster-{p}")), InputFormat::Rosbag2))
        .into_iter()
        .chain([("LEGACY", routes.join("ouster-legacy.bag"), InputFormat::Bag)]);
    for (profile, log, format) in logs {
        let text = std::fs::read_to_string(routes.join(format!("{profile}.json"))).unwrap();
        let metadata = OusterMetadata::from_json(&text).unwrap();
        let truth = points_file(&routes.join(format!("{profile}.points")));
        assert_sdks_points(&log, format, &metadata, &truth);
    }
}

/// The grids and clouds `annotate --no-passthrough` writes of `input`.
fn annotated(dir: &Path, input: &Path, name: &str, extra: &[&str]) -> Vec<(String, u64, Vec<u8>)> {
    annotated_on(
        dir,
        input,
        name,
        extra,
        &["/travmap/prediction", "/travmap/cloud"],
    )
}

/// The messages on `topics` that `annotate --no-passthrough` writes of `input`:
/// one a frame each.
fn annotated_on(
    dir: &Path,
    input: &Path,
    name: &str,
    extra: &[&str],
    topics: &[&str],
) -> Vec<(String, u64, Vec<u8>)> {
    let out = dir.join(format!("{name}.annotated.mcap"));
    let mut args = vec!["--no-passthrough"];
    args.extend_from_slice(extra);
    write_output("annotate", input, &out, &args);
    let log = Log::open(&out, InputFormat::Mcap).unwrap();
    let messages = log.messages().map(Result::unwrap);
    let on_grids = messages.filter(|m| topics.contains(&m.connection.topic.as_str()));
    let grids: Vec<_> = on_grids
        .map(|m| (m.connection.topic.clone(), m.log_time_ns, m.data.to_vec()))
        .collect();
    assert_eq!(
        grids.len(),
        3 * topics.len(),
        "{name}: 3 frames of {topics:?}"
    );
    grids
}

#[test]
#[ignore = "needs ouster-sdk: source .ci/clients.sh && cargo test --release -- --ignored"]
fn an_ouster_log_is_a_drive_however_it_was_recorded() {
    let Some((dir, routes)) = routes() else {
        return;
    };
    let dir = dir.path();
    let route = |name: &str| routes.join(name);
    // LEGACY and RNG19 carry the same ranges and reflectivity: the same drive.
    let rng19 = annotated(dir, &route("ouster-RNG19_RFL8_SIG16_NIR16"), "rng19", &[]);
    let same = [
        ("ouster-LEGACY", "legacy", vec![]),
        ("ouster-legacy.bag", "ros1", vec![]),
        ("ouster-late-metadata", "late", vec![]),
    ];
    for (input, name, extra) in same {
        assert_eq!(
            annotated(dir, &route(input), name, &extra),
            rng19,
            "{input}"
        );
    }
    // Without its metadata: the JSON given instead, or an error saying so.
    let json = route("RNG19_RFL8_SIG16_NIR16.json");
    let given = ["--lidar-calibration", json.to_str().unwrap()];
    assert_eq!(
        annotated(dir, &route("ouster-no-metadata"), "given", &given),
        rng19
    );
    let out = dir.join("none.mcap");
    let error = clean_failure(crate::common::travmap(&[
        "annotate",
        route("ouster-no-metadata").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]));
    assert_contains(
        &error,
        &["/ouster/lidar_packets", "metadata", "--lidar-calibration"],
    );
    assert!(!out.exists());
    // Another profile's metadata names both layouts.
    let legacy = route("LEGACY.json");
    let error = clean_failure(crate::common::travmap(&[
        "annotate",
        route("ouster-RNG19_RFL8_SIG16_NIR16").to_str().unwrap(),
        "--lidar-calibration",
        legacy.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]));
    assert_contains(
        &error,
        &[
            "/ouster/lidar_packets",
            "12544 bytes",
            "LEGACY packets are 12608",
        ],
    );
    // ouster_ros's own clouds of the same frames (the SDK's points, the reflectivity
    // beside a photon count as `intensity`): the same predictions.
    let prediction = ["/travmap/prediction"];
    let of_clouds = annotated_on(dir, &route("ouster-points"), "points", &[], &prediction);
    let rng19_predictions: Vec<_> = (rng19.iter())
        .filter(|(topic, _, _)| topic == "/travmap/prediction")
        .cloned()
        .collect();
    assert_eq!(of_clouds, rng19_predictions);
    // Two sensors, in namespaces and frames of their own, merged: the packets'
    // frames are found in the tree (front/os_sensor, rear/os_sensor) and give the
    // predictions of the same sensors' clouds.
    let all = ["--cloud-topic", "all"];
    let two = annotated_on(dir, &route("ouster-two"), "two", &all, &prediction);
    let two_clouds = annotated_on(
        dir,
        &route("ouster-two-points"),
        "two-points",
        &all,
        &prediction,
    );
    assert_eq!(two, two_clouds);
    // The SDK's own pcap of the packets (IP fragments), with the metadata given:
    // the drive as the log holds it, registered (a capture has no poses).
    let registered = ["--poses", "registration"];
    let logged = annotated_on(
        dir,
        &route("ouster-RNG19_RFL8_SIG16_NIR16"),
        "logged",
        &registered,
        &prediction,
    );
    let capture = route("RNG19_RFL8_SIG16_NIR16.pcap");
    let captured = annotated_on(dir, &capture, "captured", &given, &prediction);
    // Without the flag, the metadata saved beside the capture (the same name, .json)
    // is read, with a notice.
    let beside = annotated_on(dir, &capture, "beside", &[], &prediction);
    assert_eq!(beside, captured);
    // The SDK's capture keeps microseconds: the stamps are the log's to within one.
    let unstamped = |grids: &[(String, u64, Vec<u8>)]| -> Vec<OccupancyGrid> {
        let grid = |data: &[u8]| {
            let mut grid: OccupancyGrid = decode(data).unwrap();
            grid.header.stamp = Time { sec: 0, nanosec: 0 };
            grid.info.map_load_time = grid.header.stamp;
            grid
        };
        grids.iter().map(|(_, _, data)| grid(data)).collect()
    };
    assert_eq!(unstamped(&captured), unstamped(&logged));
    for ((_, captured_ns, _), (_, logged_ns, _)) in captured.iter().zip(&logged) {
        assert!(
            captured_ns.abs_diff(*logged_ns) < 1_000,
            "{captured_ns} for {logged_ns}"
        );
    }
    // A recording that began mid-turn: its first frame is left out, with a notice.
    let mid_turn =
        crate::common::travmap(&["run", route("ouster-mid-turn").to_str().unwrap(), "--json"]);
    assert_contains(
        &crate::common::stderr(&mid_turn),
        &[
            "frame 0 is the part of a rotation the recording began with (48 packets, against 128 in frame 1)",
        ],
    );
    let (frames, _) = crate::common::json_records(&crate::common::success(mid_turn));
    assert_eq!(
        frames
            .iter()
            .map(|f| f["frame"].as_u64().unwrap())
            .collect::<Vec<_>>(),
        [1, 2]
    );
    // The coarser and the dual-return profiles: drives of their own.
    for profile in ["RNG15_RFL8_NIR8", "RNG19_RFL8_SIG16_NIR16_DUAL"] {
        let grids = annotated(dir, &route(&format!("ouster-{profile}")), profile, &[]);
        assert_ne!(grids, rng19, "{profile}");
    }
}

/// ouster-sdk's own captures of an azimuth window (its tests/pcaps, BSD-3-Clause,
/// in fixtures/ouster-sdk with their metadata saved beside them, read without
/// --lidar-calibration): one frame each, as many points as the SDK decodes
/// (ouster-sdk 1.0.1, points of a range above 0). The second window wraps through
/// column 0 ([370, 85] of 512): its columns 368-511 come after 0-95 in the same
/// frame, and were once dropped (1,258 points of 8,447).
#[test]
fn azimuth_windows_keep_every_column_the_sdk_keeps() {
    for (capture, sdk_points) in [
        ("windowed_frame1.pcap", 9246),
        ("windowed_frame2.pcap", 8447),
    ] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures/ouster-sdk")
            .join(capture);
        let notices = std::cell::RefCell::new(Vec::new());
        let source = travmap_io::Source::open(&path, &Default::default(), &|notice| {
            notices.borrow_mut().push(notice.to_string())
        })
        .unwrap();
        let frames: Vec<_> = source.read(&(0..usize::MAX)).map(Result::unwrap).collect();
        assert_eq!(frames.len(), 1, "{capture}");
        let points = frames[0].points_in_velodyne.len() + frames[0].dropped_points;
        assert_eq!(points, sdk_points, "{capture}");
        assert!(
            notices
                .borrow()
                .iter()
                .any(|n| n.contains("_0.json, the metadata saved beside it")),
            "{:?}",
            notices.borrow()
        );
    }
}

/// ouster-sdk's metadata files of firmware 1.12 to 3.0.1 (fixtures/ouster-sdk/metadata,
/// BSD-3-Clause), flat and nested, all read: before 1.14 there is no data format
/// (nested files of 1.12 and 1.13 hold an error string in its place), and before
/// 2.0 no beam origin; each version's flat and nested files read the same.
#[test]
fn ouster_metadata_of_every_firmware_reads() {
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ouster-sdk/metadata");
    let mut names: Vec<String> = std::fs::read_dir(&folder)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names.len(), 25);
    let read = |name: &str| {
        let text = std::fs::read_to_string(folder.join(name)).unwrap();
        OusterMetadata::from_json(&text).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    for name in &names {
        let metadata = read(name);
        let model = metadata.model;
        // Firmware 1.12 and 1.13 stream 64 pixels a column whatever the beams lit.
        let pixels = match name.starts_with("1_12") || name.starts_with("1_13") {
            true => 64,
            false => metadata.beam_altitude_deg.len() as u16,
        };
        assert_eq!(model.pixels_per_column, pixels, "{name}");
        assert!(
            [512, 1024, 2048].contains(&model.columns_per_frame),
            "{name}"
        );
        assert_eq!(model.columns_per_packet, 16, "{name}");
        assert!(
            metadata.beam_to_lidar_mm[(0, 3)] > 0.0,
            "{name}: a beam origin"
        );
        let nested = (name.strip_suffix("_legacy.json")).map(|n| format!("{n}.json"));
        if let Some(nested) = nested.filter(|n| names.contains(n)) {
            assert_eq!(metadata, read(&nested), "{name}");
        }
    }
    // Before 2.0 the beam origin is the product line's, as ouster-sdk assumes it.
    let os1 = read("1_12_os1-991937000062-64_legacy.json");
    assert_eq!(os1.beam_to_lidar_mm[(0, 3)], 15.806);
    let os0 = read("1_14_6cccd_os-882002000138-128_legacy.json");
    assert_eq!(os0.beam_to_lidar_mm[(0, 3)], 27.67);
}

/// A capture holding nothing but part of one turn (ouster-sdk's FUSA dual-profile
/// test capture: the SDK returns that partial scan) is one frame, said as such with
/// how much of the turn it covers; it had no frame ("the input has no frames").
#[test]
fn a_capture_of_part_of_one_turn_is_one_frame() {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/ouster-sdk");
    let capture = fixtures.join("OS-1-128_767798045_1024x10_20230712_120049.pcap");
    // Its metadata, saved beside it as the SDK saves it, is found by its name.
    let output = crate::common::travmap(&["run", capture.to_str().unwrap(), "--json"]);
    let err = crate::common::stderr(&output);
    crate::common::assert_contains(
        &err,
        &[
            "holds nothing but part of one turn of the sensor (128 of the turn's 1024 columns, 12 % of a turn): read as one frame",
        ],
    );
    let (frames, _) = crate::common::json_records(&crate::common::success(output));
    assert_eq!(frames.len(), 1);
    // Its points: the SDK's 16,373 first returns, and the second returns apart from
    // them (travmap keeps a second return 0.1 m or more from the first).
    let source = travmap_io::Source::open(&capture, &Default::default(), &|_| {}).unwrap();
    let read: Vec<_> = source.read(&(0..usize::MAX)).map(Result::unwrap).collect();
    let points = read[0].points_in_velodyne.len() + read[0].dropped_points;
    assert!((16_373..=16_373 + 1_089).contains(&points), "{points}");
}
