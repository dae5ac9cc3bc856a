//! Mutation tests on stable Rust (cargo fuzz needs a nightly toolchain, which this
//! project's machines do not have): seeded random corruptions of real inputs (bit
//! flips, byte overwrites, truncations, insertions) go through every parser. Each
//! must return a value or an error, never panic. `TRAVMAP_FUZZ_ITERATIONS` raises the
//! count per target for a long local run (default 300).

mod common;

use std::path::Path;

use travmap::classifier::SvmModel;
use travmap::random::SplitMix64;
use travmap::reading::mcap_drive::{DriveOptions, McapDrive, cloud_points};
use travmap::reading::{read_calibration, read_labels, read_poses, read_scan, read_times};
use travmap::ros::{CameraInfo, PointCloud2, TfMessage, decode};

fn iterations() -> usize {
    std::env::var("TRAVMAP_FUZZ_ITERATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300)
}

/// One random corruption of `input`.
fn mutate(input: &[u8], rng: &mut SplitMix64) -> Vec<u8> {
    let mut out = input.to_vec();
    let pick = |rng: &mut SplitMix64, n: usize| (rng.next_u64() % n.max(1) as u64) as usize;
    for _ in 0..1 + pick(rng, 4) {
        match pick(rng, 5) {
            0 if !out.is_empty() => {
                let at = pick(rng, out.len());
                out[at] ^= 1 << pick(rng, 8);
            }
            1 if !out.is_empty() => {
                let at = pick(rng, out.len());
                out[at] = [0x00, 0xff, 0x7f, 0x80, b'-', b'e', b' ', b'\n'][pick(rng, 8)];
            }
            2 => out.truncate(pick(rng, out.len() + 1)),
            3 => {
                let at = pick(rng, out.len() + 1);
                let bytes: Vec<u8> = (0..1 + pick(rng, 8))
                    .map(|_| rng.next_u64() as u8)
                    .collect();
                out.splice(at..at, bytes);
            }
            _ if out.len() >= 8 => {
                // A length-like field set huge: allocation must follow the bytes present.
                let at = pick(rng, out.len() - 4);
                out[at..at + 4].copy_from_slice(&0xfff0_0000u32.to_le_bytes());
            }
            _ => {}
        }
    }
    out
}

/// Runs `check` on `iterations()` mutations of `seed`.
fn fuzz(seed: &[u8], salt: u64, mut check: impl FnMut(&[u8])) {
    let mut rng = SplitMix64(salt);
    for _ in 0..iterations() {
        check(&mutate(seed, &mut rng));
    }
}

fn with_file(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn kitti_parsers_survive_corrupt_files() {
    let Some(seq) = common::semantickitti_00() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let calib = std::fs::read(seq.join("calib.txt")).unwrap();
    fuzz(&calib, 1, |b| {
        let _ = read_calibration(&with_file(dir.path(), "calib.txt", b));
    });
    let poses: Vec<u8> = std::fs::read(seq.join("poses.txt"))
        .unwrap()
        .into_iter()
        .take(2000)
        .collect();
    fuzz(&poses, 2, |b| {
        let _ = read_poses(&with_file(dir.path(), "poses.txt", b));
    });
    let times: Vec<u8> = std::fs::read(seq.join("times.txt"))
        .unwrap()
        .into_iter()
        .take(500)
        .collect();
    fuzz(&times, 3, |b| {
        let _ = read_times(&with_file(dir.path(), "times.txt", b));
    });
    let scan: Vec<u8> = std::fs::read(seq.join("velodyne/000000.bin"))
        .unwrap()
        .into_iter()
        .take(16 * 500)
        .collect();
    fuzz(&scan, 4, |b| {
        let _ = read_scan(&with_file(dir.path(), "000000.bin", b));
    });
    let labels: Vec<u8> = std::fs::read(seq.join("labels/000000.label"))
        .unwrap()
        .into_iter()
        .take(4 * 500)
        .collect();
    fuzz(&labels, 5, |b| {
        let _ = read_labels(
            &with_file(dir.path(), "000000.label", b),
            Path::new("000000.bin"),
            500,
        );
    });
}

/// The shipped frames in `frames` as an uncompressed MCAP in `dir`.
fn converted(seq: &Path, dir: &Path, frames: &str) -> std::path::PathBuf {
    let drive = dir.join("d.mcap");
    let out = common::travmap(&[
        "convert",
        seq.to_str().unwrap(),
        "-o",
        drive.to_str().unwrap(),
        "--frames",
        frames,
        "--compression",
        "none",
        "-q",
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    drive
}

#[test]
fn message_decoders_survive_corrupt_cdr() {
    let Some(seq) = common::semantickitti_00() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let drive = converted(&seq, dir.path(), "0");
    let bytes = std::fs::read(&drive).unwrap();
    let messages: Vec<(String, Vec<u8>)> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .map(|m| (m.channel.topic.clone(), m.data.to_vec()))
        .collect();
    for (topic, data) in &messages {
        // A small cloud keeps each mutation cheap; the layout is the real one.
        let seed = if topic == "/velodyne_points" {
            data[..data.len().min(4096)].to_vec()
        } else {
            data.clone()
        };
        fuzz(&seed, 6, |b| {
            if let Ok(cloud) = decode::<PointCloud2>(b) {
                let _ = cloud_points(&cloud);
            }
            let _ = decode::<TfMessage>(b);
            let _ = decode::<CameraInfo>(b);
        });
    }
}

#[test]
fn mcap_reader_survives_corrupt_files() {
    let Some(seq) = common::semantickitti_00() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let drive = converted(&seq, dir.path(), "0..2");
    let bytes = std::fs::read(&drive).unwrap();
    let mut rng = SplitMix64(7);
    for _ in 0..iterations() / 3 {
        let mutated = mutate(&bytes, &mut rng);
        let path = with_file(dir.path(), "m.mcap", &mutated);
        if let Ok(drive) = McapDrive::open(&path, &DriveOptions::default()) {
            let _ = drive.for_each_frame::<travmap::Error>(&(0..2), |_| Ok(()));
        }
    }
}

#[test]
fn model_loader_survives_corrupt_models() {
    let model = SvmModel::embedded_default().unwrap();
    let json = model.to_json();
    // The header and first support vectors: where the structure is.
    let seed = &json[..json.len().min(20_000)];
    fuzz(seed, 8, |b| {
        let _ = SvmModel::from_json(b, "fuzzed");
    });
    fuzz(&json, 9, |b| {
        if let Ok(model) = SvmModel::from_json(b, "fuzzed") {
            let mut scratch = model.scratch();
            let _ = model.decision_value(&[0.5; 20], &mut scratch);
        }
    });
}
