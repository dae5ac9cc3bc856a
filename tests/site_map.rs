//! `travmap map site.pcd`: a site map from one saved point cloud with no trajectory.
//! The six shipped scans merged into one world-frame PCD (with their labels) against
//! the drive map of the same scans.

use std::collections::HashMap;
use std::path::Path;

use crate::common::{arg, json_summary};
use parquet::file::reader::{FileReader, SerializedFileReader};

/// The shipped drive's scans in the world frame, as one binary PCD with labels;
/// also returns its records (float32 x y z intensity, uint32 label).
fn write_site_pcd(seq: &Path, path: &Path) -> (usize, Vec<u8>) {
    let source = travmap_io::Source::open(seq, &Default::default(), &|_| {}).unwrap();
    let mut data = Vec::new();
    let mut points = 0;
    for frame in source.read(&(0..usize::MAX)) {
        let frame = frame.unwrap();
        // Frames 3-5 have no labels: 0 is SemanticKITTI's "unlabeled", never scored.
        let n = frame.points_in_velodyne.len();
        let labels = frame.labels.clone().unwrap_or_else(|| vec![0; n]);
        for (p, label) in frame.points_in_velodyne.iter().zip(labels) {
            let q = frame.world_from_velodyne
                * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            for v in [q.x as f32, q.y as f32, q.z as f32, p[3]] {
                data.extend_from_slice(&v.to_le_bytes());
            }
            data.extend_from_slice(&label.to_le_bytes());
            points += 1;
        }
    }
    let header = format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity label\nSIZE 4 4 4 4 4\nTYPE F F F F U\nCOUNT 1 1 1 1 1\nWIDTH {points}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA binary\n"
    );
    let mut bytes = header.into_bytes();
    bytes.extend_from_slice(&data);
    std::fs::write(path, bytes).unwrap();
    (points, data)
}

/// Seen cells of a map's Parquet table: world cell -> (predicted traversable, truth).
fn seen_cells(path: &Path) -> HashMap<[i64; 2], (Option<bool>, Option<bool>)> {
    let reader = SerializedFileReader::new(std::fs::File::open(path).unwrap()).unwrap();
    let mut cells = HashMap::new();
    for row in reader.get_row_iter(None).unwrap() {
        let row = row.unwrap();
        let values: Vec<String> = row.get_column_iter().map(|(_, v)| v.to_string()).collect();
        let number = |i: usize| values[i].parse::<f64>().unwrap();
        let flag = |i: usize| values[i].parse::<bool>().ok();
        if number(4) <= 0.0 {
            continue;
        }
        let key = [
            (number(0) / 0.4).floor() as i64,
            (number(1) / 0.4).floor() as i64,
        ];
        cells.insert(key, (flag(5), flag(6)));
    }
    cells
}

#[test]
fn a_site_cloud_maps_the_drive_it_was_merged_from() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let site = dir.path().join("site.pcd");
    let (points, _) = write_site_pcd(&seq, &site);
    let drive_cells = dir.path().join("drive.parquet");
    let site_cells = dir.path().join("site.parquet");
    let out = |name: &str| dir.path().join(name);
    let drive = json_summary(&[
        "map",
        arg(&seq),
        "-o",
        arg(&out("drive.png")),
        "--cells",
        arg(&drive_cells),
    ]);
    let site_map = json_summary(&[
        "map",
        arg(&site),
        "-o",
        arg(&out("site.png")),
        "--cells",
        arg(&site_cells),
        "--nav2",
        arg(&out("site.yaml")),
    ]);
    assert!(out("site.pgm").exists());
    let (drive_seen, site_seen) = (seen_cells(&drive_cells), seen_cells(&site_cells));
    let covered = drive_seen
        .keys()
        .filter(|k| site_seen.contains_key(*k))
        .count();
    let coverage = covered as f64 / drive_seen.len() as f64;
    let common: Vec<_> = drive_seen
        .iter()
        .filter_map(|(k, d)| Some((d.0?, site_seen.get(k)?.0?)))
        .collect();
    let agree = common.iter().filter(|(a, b)| a == b).count() as f64 / common.len() as f64;
    println!(
        "{points} points, {} tiles; drive map {} seen cells, site map {}; {:.1} % of the drive map's cells covered, {:.1} % of the {} common cells agree; fused mIoU drive {:.1}, site {:.1}",
        site_map["frames"],
        drive_seen.len(),
        site_seen.len(),
        100.0 * coverage,
        100.0 * agree,
        common.len(),
        100.0 * drive["fused_scores"]["miou"].as_f64().unwrap(),
        100.0 * site_map["fused_scores"]["miou"].as_f64().unwrap(),
    );
    assert!(coverage >= 0.9, "{:.1} % covered", 100.0 * coverage);
    assert!(agree >= 0.8, "{:.1} % agree", 100.0 * agree);

    // The same cloud as ouster-cli saves one: no VERSION, no VIEWPOINT, FIELDS first.
    let bytes = std::fs::read(&site).unwrap();
    let fields = bytes.windows(7).position(|w| w == b"FIELDS ").unwrap();
    let ouster_cli: Vec<u8> = String::from_utf8_lossy(&bytes[fields..])
        .split_inclusive('\n')
        .take_while(|line| !line.starts_with("DATA"))
        .filter(|line| !line.starts_with("VIEWPOINT"))
        .flat_map(|line| line.bytes())
        .chain(
            bytes[bytes
                .windows(12)
                .position(|w| w == b"DATA binary\n")
                .unwrap()..]
                .iter()
                .copied(),
        )
        .collect();
    let headless = out("ouster-cli.pcd");
    std::fs::write(&headless, ouster_cli).unwrap();
    let headless_map = json_summary(&["map", arg(&headless), "-o", arg(&out("o.png"))]);
    assert_eq!(headless_map["frames"], site_map["frames"]);
    assert_eq!(headless_map["fused_scores"], site_map["fused_scores"]);
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn ply_files_written_by_plyfile_map_as_the_same_cloud_in_pcd_does() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let Some(python) = crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "a Python with plyfile")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let site = dir.path().join("site.pcd");
    let (_, records) = write_site_pcd(&seq, &site);
    let records_path = dir.path().join("records.bin");
    std::fs::write(&records_path, records).unwrap();
    let cells = |input: &Path, name: &str| {
        let table = dir.path().join(format!("{name}.parquet"));
        let png = dir.path().join(format!("{name}.png"));
        crate::common::success(crate::common::travmap(&[
            "map",
            arg(input),
            "-o",
            arg(&png),
            "--cells",
            arg(&table),
            "-q",
        ]));
        seen_cells(&table)
    };
    let from_pcd = cells(&site, "pcd");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/write_ply.py");
    for encoding in ["binary_little_endian", "binary_big_endian", "ascii"] {
        let ply = dir.path().join(format!("{encoding}.ply"));
        let written = std::process::Command::new(&python)
            .args([arg(&script), arg(&records_path), arg(&ply), encoding])
            .output()
            .unwrap();
        assert!(
            written.status.success(),
            "{}",
            crate::common::stderr(&written)
        );
        assert_eq!(cells(&ply, encoding), from_pcd, "{encoding}");
    }
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn las_and_laz_written_by_laspy_map_in_their_own_coordinates() {
    let Some(seq) = crate::common::sample() else {
        return;
    };
    let Some(python) =
        crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "a Python with laspy and lazrs")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let site = dir.path().join("site.pcd");
    let (_, records) = write_site_pcd(&seq, &site);
    // The local origin travmap picks: the smallest coordinate, floored to 100 m.
    let smallest = |k: usize| {
        records
            .chunks_exact(20)
            .map(|r| f32::from_le_bytes(r[4 * k..4 * k + 4].try_into().unwrap()) as f64)
            .fold(f64::INFINITY, f64::min)
    };
    let origin = [
        ((512_000.0 + smallest(0)) / 100.0).floor() * 100.0,
        ((4_100_000.0 + smallest(1)) / 100.0).floor() * 100.0,
    ];
    let records_path = dir.path().join("records.bin");
    std::fs::write(&records_path, &records).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/write_las.py");
    let map = |input: &Path, name: &str| {
        let table = dir.path().join(format!("{name}.parquet"));
        let png = dir.path().join(format!("{name}.png"));
        let yaml = dir.path().join(format!("{name}.yaml"));
        let out = crate::common::travmap(&[
            "map",
            arg(input),
            "-o",
            arg(&png),
            "--cells",
            arg(&table),
            "--nav2",
            arg(&yaml),
        ]);
        let err = crate::common::stderr(&out);
        crate::common::success(out);
        (seen_cells(&table), err)
    };
    let (from_pcd, _) = map(&site, "pcd");
    let mut from_las = Vec::new();
    for name in ["site.las", "site.laz"] {
        let path = dir.path().join(name);
        let written = std::process::Command::new(&python)
            .args([arg(&script), arg(&records_path), arg(&path)])
            .output()
            .unwrap();
        assert!(
            written.status.success(),
            "{}",
            crate::common::stderr(&written)
        );
        let (cells, notice) = map(&path, name);
        crate::common::assert_contains(
            &notice,
            &[&format!(
                "the map's frame is the file's coordinates minus ({}, {}, ",
                origin[0], origin[1]
            )],
        );
        // The world file places the map's upper-left pixel in the file's coordinates.
        let yaml = std::fs::read_to_string(dir.path().join(format!("{name}.yaml"))).unwrap();
        crate::common::assert_contains(
            &yaml,
            &["# The frame is the source file's coordinates minus"],
        );
        let origin_line = yaml.lines().find(|l| l.starts_with("origin: [")).unwrap();
        let nav2_origin: Vec<f64> = origin_line["origin: [".len()..origin_line.len() - 1]
            .split(", ")
            .map(|v| v.parse().unwrap())
            .collect();
        let world = std::fs::read_to_string(dir.path().join(format!("{name}.pgmw"))).unwrap();
        let world: Vec<f64> = world.lines().map(|l| l.parse().unwrap()).collect();
        assert_eq!(&world[..4], &[0.4, 0.0, 0.0, -0.4]);
        assert!(
            (world[4] - (origin[0] + nav2_origin[0] + 0.2)).abs() < 1e-6,
            "{world:?}"
        );
        from_las.push(cells);
    }
    assert_eq!(from_las[0], from_las[1], "LAS and LAZ of the same points");
    // Back in the drive's world frame: the origin is a whole number of cells away.
    let shift = [
        ((origin[0] - 512_000.0) / 0.4).round() as i64,
        ((origin[1] - 4_100_000.0) / 0.4).round() as i64,
    ];
    let las: HashMap<[i64; 2], Option<bool>> = from_las[0]
        .iter()
        .map(|(k, v)| ([k[0] + shift[0], k[1] + shift[1]], v.0))
        .collect();
    let covered = from_pcd.keys().filter(|k| las.contains_key(*k)).count();
    let common: Vec<(bool, bool)> = from_pcd
        .iter()
        .filter_map(|(k, v)| Some((v.0?, (*las.get(k)?)?)))
        .collect();
    let agree = common.iter().filter(|(a, b)| a == b).count() as f64 / common.len() as f64;
    let coverage = covered as f64 / from_pcd.len() as f64;
    println!(
        "LAS / LAZ site map: {:.1} % of the PCD map's {} cells covered, {:.1} % of {} common cells agree",
        100.0 * coverage,
        from_pcd.len(),
        100.0 * agree,
        common.len()
    );
    assert!(coverage >= 0.99, "{:.1} % covered", 100.0 * coverage);
    // Not all: LAS intensity is 16-bit (its ranks tie where the PCD's floats do
    // not), and the tiles lie on the local origin's lattice.
    assert!(agree >= 0.93, "{:.1} % agree", 100.0 * agree);
}
