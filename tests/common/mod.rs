//! Helpers shared by the integration tests.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The shipped SemanticKITTI sample (semantickitti-00, sequence 00), or None (with
/// the reason printed) when `../shared/data` is not beside the repository.
pub fn sample() -> Option<PathBuf> {
    shared_data("semantickitti-00/sequences/00")
}

/// The shipped sample under its data set's name: the same as [`sample`].
pub fn semantickitti_00() -> Option<PathBuf> {
    sample()
}

pub fn shared_data(relative: &str) -> Option<PathBuf> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(relative);
    if path.exists() {
        Some(path)
    } else {
        skip(&format!(
            "{} not found (../shared/data is not beside the repository)",
            path.display()
        ))
    }
}

/// An environment variable a test needs (a client's path), or None with the
/// reason printed.
pub fn env_var(name: &str, what: &str) -> Option<String> {
    match std::env::var(name) {
        Ok(value) => Some(value),
        Err(_) => skip(&format!("{name} ({what}) is not set")),
    }
}

/// Skips a test for a missing prerequisite with the reason printed; in CI (`CI`
/// set) a missing prerequisite fails the test instead, so a green CI run is one
/// that ran everything.
pub fn skip<T>(reason: &str) -> Option<T> {
    if std::env::var_os("CI").is_some() {
        panic!("CI must run this test, but {reason}");
    }
    eprintln!("skipping: {reason}");
    None
}

/// The KITTI sequence `sequence` without its labels: its scans and text files
/// linked into `dir/unlabelled`.
pub fn without_labels(sequence: &Path, dir: &Path) -> PathBuf {
    let unlabelled = dir.join("unlabelled");
    std::fs::create_dir(&unlabelled).unwrap();
    for item in ["velodyne", "calib.txt", "times.txt", "poses.txt"] {
        std::os::unix::fs::symlink(sequence.join(item), unlabelled.join(item)).unwrap();
    }
    unlabelled
}

/// Runs the travmap binary with `args` from the repository root.
pub fn travmap(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_travmap"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("travmap runs")
}

/// A path as a command-line argument (the tests' paths are UTF-8).
pub fn arg(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Runs `travmap <command> <input> -o <output> <extra...> -q` and asserts success:
/// how the tests make the files they read back (MCAPs, models, pictures, tables).
pub fn write_output(command: &str, input: impl AsRef<Path>, output: &Path, extra: &[&str]) {
    let mut args = vec![command, arg(input.as_ref()), "-o", arg(output)];
    args.extend_from_slice(extra);
    args.push("-q");
    success(travmap(&args));
}

/// The shipped sample converted to `dir/drive.mcap` (with `extra` flags): the
/// sample's path and the drive's, or None without the shared data.
pub fn sample_as_mcap(dir: &Path, extra: &[&str]) -> Option<(PathBuf, PathBuf)> {
    let sample = sample()?;
    let drive = dir.join("drive.mcap");
    write_output("convert", &sample, &drive, extra);
    Some((sample, drive))
}

/// The shipped sample annotated into `dir/a.mcap` (with `extra` flags): the
/// sample's path and the annotated file's, or None without the shared data.
pub fn sample_annotated(dir: &Path, extra: &[&str]) -> Option<(PathBuf, PathBuf)> {
    let sample = sample()?;
    let annotated = dir.join("a.mcap");
    write_output("annotate", &sample, &annotated, extra);
    Some((sample, annotated))
}

/// `args` followed by `--set <setting>` for each of `settings`.
pub fn with_settings<'a>(args: &[&'a str], settings: &[&'a str]) -> Vec<&'a str> {
    let mut all = args.to_vec();
    for setting in settings {
        all.extend(["--set", setting]);
    }
    all
}

/// Runs travmap with `args` and `--json`, asserts success, and returns what it
/// printed: a single `summary` record, no `frame` records.
pub fn json_summary(args: &[&str]) -> serde_json::Value {
    let args = [args, &["--json"]].concat();
    let (frames, summary) = json_records(&success(travmap(&args)));
    assert!(
        frames.is_empty(),
        "{args:?}: {} frame records",
        frames.len()
    );
    summary
}

/// Every message of `topic` in an MCAP, decoded by travmap's own reader: (log time,
/// message).
pub fn messages<T: serde::de::DeserializeOwned>(path: &Path, topic: &str) -> Vec<(u64, T)> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == topic)
        .map(|m| (m.log_time, travmap_formats::ros::decode(&m.data).unwrap()))
        .collect()
}

/// Runs another program (a client, a converter) and asserts it succeeded, with
/// its stderr as the message.
pub fn run_client(command: &mut Command) -> Output {
    let output = command.output().unwrap();
    assert!(
        output.status.success(),
        "{:?}: {}",
        command,
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// Asserts that `text` contains every one of `parts`, and shows `text` if not.
#[track_caller]
pub fn assert_contains(text: &str, parts: &[&str]) {
    for part in parts {
        assert!(text.contains(part), "{part:?} not in:\n{text}");
    }
}

/// The `travmap` metadata record of an MCAP file (its bytes): version, model
/// hash, configuration, skipped frames.
pub fn travmap_metadata(mcap_bytes: &[u8]) -> BTreeMap<String, String> {
    let summary = mcap::Summary::read(mcap_bytes).unwrap().unwrap();
    let index = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == "travmap")
        .expect("a travmap metadata record");
    mcap::read::metadata(mcap_bytes, index).unwrap().metadata
}

pub fn stdout(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

pub fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// Asserts success and returns stdout.
pub fn success(output: Output) -> String {
    assert!(
        output.status.success(),
        "travmap failed: {}\n{}",
        stderr(&output),
        stdout(&output)
    );
    stdout(&output)
}

/// Asserts a clean failure: exit code 1, an `error:` line, no panic. Returns stderr.
pub fn clean_failure(output: Output) -> String {
    failure_with_code(output, 1)
}

/// Asserts a usage error (a malformed argument): exit code 2, an `error:` line.
pub fn usage_error(output: Output) -> String {
    failure_with_code(output, 2)
}

fn failure_with_code(output: Output, code: i32) -> String {
    let err = stderr(&output);
    assert_eq!(
        output.status.code(),
        Some(code),
        "expected exit {code}, stderr: {err}"
    );
    // Notices (what the reader worked around) may come first.
    let said = err
        .lines()
        .skip_while(|line| line.starts_with("notice: "))
        .collect::<Vec<_>>()
        .join("\n");
    assert!(said.starts_with("error: "), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// A sequence of `frames` scans in `dir`: the shipped scans over and over (as
/// links), with the sample's calibration, poses and times; long enough to interrupt.
pub fn long_sequence(sample: &Path, dir: &Path, frames: usize) -> PathBuf {
    let long = dir.join("long");
    std::fs::create_dir_all(long.join("velodyne")).unwrap();
    std::fs::copy(sample.join("calib.txt"), long.join("calib.txt")).unwrap();
    let head = |name: &str| -> String {
        std::fs::read_to_string(sample.join(name))
            .unwrap()
            .lines()
            .take(frames)
            .map(|l| format!("{l}\n"))
            .collect()
    };
    std::fs::write(long.join("poses.txt"), head("poses.txt")).unwrap();
    std::fs::write(long.join("times.txt"), head("times.txt")).unwrap();
    for i in 0..frames {
        std::os::unix::fs::symlink(
            sample.join(format!("velodyne/{:06}.bin", i % 6)),
            long.join(format!("velodyne/{i:06}.bin")),
        )
        .unwrap();
    }
    long
}

/// `--json` output: the `frame` records and the closing `summary` record (the
/// convention of every command).
pub fn json_records(stdout: &str) -> (Vec<serde_json::Value>, serde_json::Value) {
    let mut records: Vec<serde_json::Value> = stdout
        .lines()
        .map(|line| serde_json::from_str(line).expect("one JSON object per line"))
        .collect();
    let summary = records.pop().expect("a summary record");
    assert_eq!(summary["type"], "summary", "{summary}");
    assert!(records.iter().all(|r| r["type"] == "frame"));
    (records, summary)
}

/// One real KITTI frame with its camera image (kitti-object 000008, calib of
/// odometry sequence 03) as a one-frame sequence directory.
pub fn one_frame_with_image() -> Option<(tempfile::TempDir, PathBuf)> {
    let object = shared_data("kitti-object-000008/training")?;
    let meta = shared_data("kitti-odometry-meta/sequences/03")?;
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    for sub in ["velodyne", "image_2"] {
        std::fs::create_dir_all(seq.join(sub)).unwrap();
    }
    std::fs::copy(
        object.join("velodyne_reduced/000008.bin"),
        seq.join("velodyne/000000.bin"),
    )
    .unwrap();
    std::fs::copy(
        object.join("image_2/000008.png"),
        seq.join("image_2/000000.png"),
    )
    .unwrap();
    std::fs::copy(meta.join("calib.txt"), seq.join("calib.txt")).unwrap();
    let first_line = |name: &str| {
        std::fs::read_to_string(meta.join(name))
            .unwrap()
            .lines()
            .next()
            .unwrap()
            .to_string()
            + "\n"
    };
    std::fs::write(seq.join("poses.txt"), first_line("poses.txt")).unwrap();
    std::fs::write(seq.join("times.txt"), first_line("times.txt")).unwrap();
    Some((dir, seq))
}

/// The drive at `seq` fused by the library with the embedded model, as `map` fuses it.
pub fn fused_drive(seq: &Path) -> Vec<travmap_method::fusion::FusedCell> {
    let config = travmap_core::Config::default();
    let model =
        travmap_method::classifier::SvmModel::embedded(travmap_core::config::LabelRule::Road)
            .unwrap();
    let source = travmap_io::Source::open(seq, &Default::default(), &|_| {}).unwrap();
    let drive = source.drive_frame();
    let selection = travmap_run::DriveRun::new(source, 0..usize::MAX);
    let mut map = travmap_method::fusion::DriveMap::new(config.grid.cell_size_m, drive);
    selection
        .run::<travmap_core::Error>(&config, Some(&model), |result| {
            map.add_result(&result);
            Ok(())
        })
        .unwrap();
    map.cells()
}

/// A /tf message of one transform, `parent_from_child` at `stamp_ns`.
pub fn tf(
    stamp_ns: u64,
    parent: &str,
    child: &str,
    pose: &nalgebra::Isometry3<f64>,
) -> travmap_formats::ros::TfMessage {
    use travmap_formats::ros::{Header, TfMessage, Time, TransformStamped};
    TfMessage {
        transforms: vec![TransformStamped {
            header: Header {
                stamp: Time::from_ns(stamp_ns),
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            transform: travmap_outputs::conversion::transform_from_pose(pose),
        }],
    }
}

/// A file of tier4/nebula's decoder tests staged in `fixtures/nebula/`.
pub fn nebula_fixture(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/nebula")
        .join(relative)
}

/// The scans a packet log's LiDAR packets make through the library's packet face:
/// the model told from the first packet, its built-in calibration, the scans cut
/// as every command cuts them.
pub fn packet_scans(log_path: &Path) -> Vec<travmap_io::PacketScan> {
    use travmap_io::{
        Log, PACKET_MESSAGES, PacketAssembler, PacketCalibration, PacketModel, detect,
        packet_message,
    };
    let log = Log::open(log_path, detect(log_path).unwrap()).unwrap();
    let mut assembler = None;
    let mut scans = Vec::new();
    for message in log.messages() {
        let message = message.unwrap();
        let type_name = message.connection.type_name().into_owned();
        if !PACKET_MESSAGES.contains(&type_name.as_str()) {
            continue;
        }
        let encoding = message.connection.encoding().unwrap();
        let assembler = assembler.get_or_insert_with(|| {
            let first = packet_message(&type_name, &message.data, encoding, 0).unwrap();
            let model = PacketModel::of_packet(&type_name, first.packets[0].1).unwrap();
            let calibration = PacketCalibration::for_model(model, None).unwrap();
            PacketAssembler::new(model, &calibration).unwrap()
        });
        let cut = assembler.push_message(&type_name, &message.data, encoding, message.log_time_ns);
        scans.extend(cut.unwrap());
    }
    scans
}

/// An 8-bit RGB PNG (travmap's pictures, KITTI's camera images), read with the png
/// crate: its pixels, row by row.
pub fn read_png(path: &Path) -> travmap_core::frame::RgbImage {
    let bytes = std::fs::read(path).unwrap();
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buffer).unwrap();
    assert_eq!(
        (info.color_type, info.bit_depth),
        (png::ColorType::Rgb, png::BitDepth::Eight),
        "{}",
        path.display()
    );
    buffer.truncate(info.buffer_size());
    travmap_core::frame::RgbImage {
        width: info.width,
        height: info.height,
        rgb: buffer,
    }
}

/// The poses of a KITTI-format trajectory file (`poses.txt`, `odometry` output),
/// read by hand.
pub fn read_trajectory(path: &Path) -> Vec<nalgebra::Isometry3<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|line| {
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|x| x.parse().unwrap())
                .collect();
            let m = nalgebra::Matrix4::new(
                v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11], 0.0, 0.0,
                0.0, 1.0,
            );
            travmap_core::geometry::rigid(&m)
        })
        .collect()
}

/// A KITTI `.bin` scan read by hand: x, y, z, remission a point.
pub fn kitti_scan(path: &Path) -> Vec<[f32; 4]> {
    let bytes = std::fs::read(path).unwrap();
    let value = |b: &[u8]| f32::from_le_bytes(b.try_into().unwrap());
    let point = |p: &[u8]| [0, 4, 8, 12].map(|at| value(&p[at..at + 4]));
    bytes.chunks_exact(16).map(point).collect()
}

/// A SemanticKITTI `.label` file read by hand: a u32 a point.
pub fn kitti_labels(path: &Path) -> Vec<u32> {
    let bytes = std::fs::read(path).unwrap();
    let label = |b: &[u8]| u32::from_le_bytes(b.try_into().unwrap());
    bytes.chunks_exact(4).map(label).collect()
}

/// Every frame of an input, read through the library's face as the commands read
/// them (default options).
pub fn read_frames(input: &Path) -> Vec<travmap_core::frame::Frame> {
    let source = travmap_io::Source::open(input, &Default::default(), &|_| {}).unwrap();
    source.read(&(0..usize::MAX)).map(Result::unwrap).collect()
}
